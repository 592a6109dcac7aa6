"""Tests of solver.topology: twist (seed eq. 7), writhe (Klenin & Langowski), Lk."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from solver.topology import (
    linking_number,
    twist,
    writhe,
    writhe_closed,
    writhe_polyline,
)

TWO_PI = 2.0 * np.pi


# ----------------------------------------------------------------- helpers

def rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def random_fourier_curve(rng, n_points, n_modes=3):
    """A smooth random closed curve (sampled without repeating the first point)."""
    u = np.linspace(0.0, TWO_PI, n_points, endpoint=False)
    pts = np.zeros((n_points, 3))
    for m in range(1, n_modes + 1):
        a = rng.normal(size=3) / m
        b = rng.normal(size=3) / m
        pts += np.outer(np.cos(m * u), a) + np.outer(np.sin(m * u), b)
    return pts


def trefoil(u):
    r = np.c_[np.sin(u) + 2 * np.sin(2 * u), np.cos(u) - 2 * np.cos(2 * u), -np.sin(3 * u)]
    dr = np.c_[np.cos(u) + 4 * np.cos(2 * u), -np.sin(u) + 4 * np.sin(2 * u), -3 * np.cos(3 * u)]
    return r, dr


def gauss_double_integral(curve, n):
    """Independent reference: Gauss writhe integral of a smooth closed parametric curve,
    (1/4π) ∬ (r'(u) × r'(v))·(r(u) − r(v)) / |r(u) − r(v)|³ du dv, by the periodic
    midpoint (trapezoid) rule with the diagonal left out (the integrand is bounded there)."""
    u = (np.arange(n) + 0.5) * TWO_PI / n
    r, dr = curve(u)
    h = TWO_PI / n
    total = 0.0
    for i in range(n):
        diff = r[i] - r
        cr = np.cross(dr[i], dr)
        dist = np.linalg.norm(diff, axis=1)
        dist[i] = np.inf
        total += np.sum(np.einsum("ij,ij->i", cr, diff) / dist**3)
    return total * h * h / (4 * np.pi)


def helix_with_axial_leads(n_turns, radius, pitch_per_rad, n_seg, lead=0.5):
    t = np.linspace(0.0, TWO_PI * n_turns, n_seg + 1)
    h = np.c_[radius * np.cos(t), radius * np.sin(t), pitch_per_rad * t]
    return np.vstack([h[0] - [0, 0, lead], h, h[-1] + [0, 0, lead]])


# ----------------------------------------------------------------- twist / Lk

def test_twist_of_uniformly_twisted_straight_rod_is_exact():
    length, phi = 1.3, 7.5  # start rotated by +phi, end held
    s = np.linspace(0.0, length, 1001)
    kappa3 = np.full_like(s, -phi / length)
    assert twist(kappa3, s) == pytest.approx(-phi / TWO_PI, rel=1e-14)
    # Lk from the end rotations agrees, and a straight rod has no writhe
    lk = linking_number(phi, 0.0)
    assert lk == pytest.approx(-phi / TWO_PI, rel=1e-14)
    pts = np.c_[np.zeros_like(s), np.zeros_like(s), s]
    wr = writhe(pts)
    assert abs(wr) < 1e-12
    assert twist(kappa3, s) + wr == pytest.approx(lk, abs=1e-12)


def test_twist_trapezoid_exact_for_linear_kappa3_on_nonuniform_grid():
    rng = np.random.default_rng(3)
    s = np.sort(rng.uniform(0.0, 2.0, 50))
    kappa3 = 3.0 - 2.0 * s
    exact = (3.0 * (s[-1] - s[0]) - (s[-1] ** 2 - s[0] ** 2)) / TWO_PI
    assert twist(kappa3, s) == pytest.approx(exact, rel=1e-13)
    assert twist([2.0], [0.0]) == 0.0


@pytest.mark.parametrize(
    "kappa3, s",
    [
        (np.ones(3), np.arange(4.0)),           # length mismatch
        (np.ones((3, 1)), np.arange(3.0)),      # not 1-D
        (np.ones(3), np.array([0.0, 1.0, 1.0])),  # not strictly increasing
        (np.array([1.0, np.nan, 1.0]), np.arange(3.0)),
        (np.ones(0), np.ones(0)),
    ],
)
def test_twist_rejects_bad_input(kappa3, s):
    with pytest.raises(ValueError):
        twist(kappa3, s)


def test_linking_number_arrays_and_errors():
    phi_end = np.array([0.0, np.pi, 4 * np.pi])
    np.testing.assert_allclose(linking_number(0.0, phi_end), [0.0, 0.5, 2.0])
    assert isinstance(linking_number(0.0, TWO_PI), float)
    with pytest.raises(ValueError):
        linking_number(np.zeros(2), np.zeros(3))
    with pytest.raises(ValueError):
        linking_number(0.0, np.inf)


# ----------------------------------------------------------------- writhe: zero cases

def test_planar_curves_have_zero_writhe():
    rng = np.random.default_rng(11)
    rot = rotation([0.3, -1.0, 0.7], 0.9)
    # open planar random walk, then rotated out of the coordinate planes
    xy = np.cumsum(rng.normal(size=(300, 2)), axis=0)
    open_pts = np.c_[xy, np.zeros(300)] @ rot.T + [1.0, 2.0, -3.0]
    assert abs(writhe(open_pts)) < 1e-9
    assert abs(writhe_polyline(open_pts)) < 1e-9
    # closed planar (self-intersecting) star polygon and a circle
    ang = np.linspace(0, TWO_PI, 7, endpoint=False) * 3
    star = np.c_[np.cos(ang), np.sin(ang), np.zeros(7)] @ rot.T
    assert abs(writhe_closed(star)) < 1e-12
    u = np.linspace(0, TWO_PI, 500, endpoint=False)
    circle = np.c_[np.cos(u), np.sin(u), np.zeros_like(u)] @ rot.T
    assert abs(writhe_closed(circle)) < 1e-10
    # a planar curve is not a control that cannot fail: lifting it out of plane does change Wr
    lifted = np.c_[np.cos(u), np.sin(u), 0.3 * np.sin(2 * u + 0.4) + 0.2 * np.cos(3 * u)]
    assert abs(writhe_closed(lifted)) > 1e-3


def test_degenerate_segments_give_finite_results():
    # repeated points, collinear overlapping pieces, zero-length segments, all coincident
    rng = np.random.default_rng(5)
    base = random_fourier_curve(rng, 80)
    rep = np.repeat(base, 2, axis=0)  # every point doubled: zero-length segments
    w0 = writhe_closed(base)
    w1 = writhe_closed(rep)
    assert np.isfinite(w1)
    assert w1 == pytest.approx(w0, abs=1e-12)
    line = np.c_[np.zeros(20), np.zeros(20), np.r_[np.arange(10.0), np.arange(10.0)[::-1]]]
    assert writhe(line) == 0.0  # folds back on itself: collinear, overlapping
    assert writhe(np.zeros((10, 3))) == 0.0
    assert writhe(np.array([[0.0, 0, 0], [1.0, 0, 0]])) == 0.0
    open_rep = np.repeat(helix_with_axial_leads(1, 1.0, 0.3, 60), 2, axis=0)
    assert writhe(open_rep) == pytest.approx(writhe(helix_with_axial_leads(1, 1.0, 0.3, 60)),
                                             abs=1e-12)


@pytest.mark.parametrize("bad", [np.zeros((5, 2)), np.zeros(3), np.zeros((1, 3)),
                                 np.array([[0, 0, 0], [1, np.nan, 0]])])
def test_writhe_rejects_bad_shapes(bad):
    with pytest.raises(ValueError):
        writhe(bad)


def test_writhe_closed_and_extension_argument_validation():
    with pytest.raises(ValueError):
        writhe_closed(np.zeros((2, 3)))
    with pytest.raises(ValueError):
        writhe(np.eye(3), extension=-1.0)
    with pytest.raises(ValueError):
        writhe(np.eye(3), extension=np.nan)


# ----------------------------------------------------------------- writhe: analytic values

def test_open_helix_matches_fuller_value_and_converges():
    """Helix of n turns between axial lead-in/out lines, closed by the axis at infinity.

    Fuller (1971): Wr = (1/2π) × area swept on the unit sphere by the tangent relative to
    the axis direction e.  The tangent circles the cap of colatitude θ (the helix angle
    from the axis) n times, and the two meridian arcs to and from e cancel for integer n:
    Wr = n (1 − cos θ), positive for a right-handed helix.
    """
    n_turns, radius, c = 2, 1.0, 0.5
    exact = n_turns * (1.0 - c / np.hypot(radius, c))
    w1 = writhe(helix_with_axial_leads(n_turns, radius, c, 1000))
    w2 = writhe(helix_with_axial_leads(n_turns, radius, c, 2000))
    e1, e2 = abs(w1 - exact), abs(w2 - exact)
    assert e2 < 1e-3
    assert 1.8 < e1 / e2 < 2.2  # first order: end chords sit half a step off the meridian
    assert abs(2 * w2 - w1 - exact) < 1e-4  # Richardson extrapolation
    # handedness: the mirror image (left-handed helix) has the opposite writhe
    mirror = helix_with_axial_leads(n_turns, radius, c, 2000) * [1, -1, 1]
    assert writhe(mirror) == pytest.approx(-w2, abs=1e-12)


def test_extension_error_decays_like_inverse_length():
    # end tangents on one axis: error ~ (L/ℓ)^2
    pts = helix_with_axial_leads(2, 1.0, 0.5, 400)
    length = np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1))
    ref = writhe(pts, extension=1e7 * length)
    errs = [writhe(pts, extension=f * length) - ref for f in (10, 20, 40)]
    assert abs(errs[0]) > 1e-6
    for a, b in zip(errs, errs[1:]):
        assert 3.5 < a / b < 4.5
    # general end tangents: error ~ L/ℓ
    u = np.linspace(0, TWO_PI * 1.3, 401)
    gen = np.c_[np.cos(u), np.sin(u), 0.5 * u]
    length = np.sum(np.linalg.norm(np.diff(gen, axis=0), axis=1))
    w = {f: writhe(gen, extension=f * length) for f in (10, 20, 40, 80)}
    ref = writhe(gen, extension=1e8 * length)
    for a, b in ((10, 20), (20, 40), (40, 80)):
        assert 1.9 < (w[a] - ref) / (w[b] - ref) < 2.1
    # the default (1e6 × length) is converged to 1e-6
    assert abs(writhe(gen) - ref) < 1e-6
    assert abs(writhe(pts) - writhe(pts, extension=1e7 * np.sum(
        np.linalg.norm(np.diff(pts, axis=0), axis=1)))) < 1e-10


def test_closed_writhe_matches_brute_force_gauss_integral():
    ref_fine = gauss_double_integral(trefoil, 800)
    ref_coarse = gauss_double_integral(trefoil, 400)
    assert abs(ref_fine - ref_coarse) < 1e-6  # the reference itself converges (~h^2)
    ref = (4 * ref_fine - ref_coarse) / 3
    u = np.linspace(0, TWO_PI, 1000, endpoint=False)
    wr = writhe_closed(trefoil(u)[0])
    assert abs(wr) > 1.0  # a trefoil writhes; not a trivially-zero comparison
    assert wr == pytest.approx(ref, abs=2e-6)
    # second-order convergence of the polygon to the smooth curve
    u2 = np.linspace(0, TWO_PI, 500, endpoint=False)
    e_fine, e_coarse = abs(wr - ref), abs(writhe_closed(trefoil(u2)[0]) - ref)
    assert 3.5 < e_coarse / e_fine < 4.5


def test_closed_writhe_invariances():
    rng = np.random.default_rng(42)
    pts = random_fourier_curve(rng, 200)
    w = writhe_closed(pts)
    assert abs(w) > 1e-2
    rot = rotation([1.0, 2.0, -0.5], 2.1)
    moved = 3.7 * pts @ rot.T + [10.0, -4.0, 2.5]
    assert writhe_closed(moved) == pytest.approx(w, abs=1e-11)
    assert writhe_closed(pts * [1, 1, -1]) == pytest.approx(-w, abs=1e-12)   # mirror
    assert writhe_closed(pts[::-1]) == pytest.approx(w, abs=1e-12)          # reversed
    assert writhe_closed(np.roll(pts, 37, axis=0)) == pytest.approx(w, abs=1e-12)  # start


def test_open_writhe_invariances():
    rng = np.random.default_rng(7)
    pts = np.cumsum(rng.normal(size=(150, 3)), axis=0) * 0.1
    w = writhe(pts)
    rot = rotation([0.2, 0.1, 1.0], -1.1)
    assert writhe(0.01 * pts @ rot.T - [1, 2, 3]) == pytest.approx(w, abs=1e-9)
    assert writhe(pts * [-1, 1, 1]) == pytest.approx(-w, abs=1e-12)
    assert writhe(pts[::-1]) == pytest.approx(w, abs=1e-8)


# ----------------------------------------------------------------- pair sum: both forms

def direct_pair_sum(q):
    """Independent numpy reference: Σ_{i<j, j≥i+2} Ω_ij of the open polyline q (M+1, 3),
    each pair's solid angle from the vectors r13, r14, r24, r23 themselves (Van Oosterom-
    Strackee triangles, the K&L sign), no law of cosines, no series."""
    q = np.asarray(q, float) - np.mean(q, axis=0)
    m = len(q) - 1
    total = 0.0
    for i in range(m - 2):
        j = np.arange(i + 2, m)
        a, b = q[j] - q[i], q[j + 1] - q[i]
        c, d = q[j + 1] - q[i + 1], q[j] - q[i + 1]
        na, nb, nc, nd = (np.linalg.norm(v, axis=1) for v in (a, b, c, d))
        dot = lambda u, v: np.einsum("ij,ij->i", u, v)  # noqa: E731
        t = np.einsum("ij,ij->i", np.cross(q[j + 1] - q[j], q[i + 1] - q[i]), a)
        d1 = na * nb * nc + dot(a, b) * nc + dot(a, c) * nb + dot(b, c) * na
        d2 = na * nc * nd + dot(a, c) * nd + dot(a, d) * nc + dot(c, d) * na
        total += np.sum(np.arctan2(t, d1) + np.arctan2(t, d2))
    return 2.0 * total


def plectoneme(n_seg, radius=0.02, pitch=0.1, length=0.3, tail=0.5):
    """Two strands interwound about the x axis (separation 2·radius, one turn per
    pitch, over length), joined by a half-circle end loop, with straight tails along z;
    n_seg segments of equal length."""
    x = np.linspace(0.0, length, 4000)
    k = TWO_PI / pitch
    strand = np.c_[x, radius * np.cos(k * x), radius * np.sin(k * x)]
    v = strand[-1] - [length, 0.0, 0.0]
    phi = np.linspace(0.0, np.pi, 400)[1:-1, None]
    loop = [length, 0.0, 0.0] + np.cos(phi) * v + np.sin(phi) * [radius, 0.0, 0.0]
    back = (strand * [1, -1, -1])[::-1]
    tail_in = strand[0] + np.linspace(-tail, 0.0, 500, endpoint=False)[:, None] * [0, 0, 1]
    tail_out = back[-1] + np.linspace(0.0, tail, 500)[1:, None] * [0, 0, 1]
    dense = np.vstack([tail_in, strand, loop, back, tail_out])
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))]
    u = np.linspace(0.0, s[-1], n_seg + 1)
    return np.column_stack([np.interp(u, s, dense[:, c]) for c in range(3)])


def extended(points, factor=1e6):
    """writhe()'s closure: one straight segment of factor × length at each end."""
    p = np.asarray(points, float)
    seg = np.diff(p, axis=0)
    ell = factor * np.sum(np.linalg.norm(seg, axis=1))
    t0, t1 = seg[0] / np.linalg.norm(seg[0]), seg[-1] / np.linalg.norm(seg[-1])
    return np.vstack([p[0] - ell * t0, p, p[-1] + ell * t1])


def test_pair_sum_matches_direct_evaluation_on_plectoneme_and_closed_curves():
    """The compiled sum takes most pairs in the law-of-cosines form (module docstring):
    the same closed form, so it must agree with the direct evaluation to rounding."""
    pts = plectoneme(1000)
    wr = writhe(pts)
    assert abs(wr) > 1.0  # interwound strands writhe
    assert wr == pytest.approx(direct_pair_sum(extended(pts)) / TWO_PI, abs=1e-11)
    assert writhe_polyline(pts) == pytest.approx(direct_pair_sum(pts) / TWO_PI, abs=1e-11)
    u = np.linspace(0, TWO_PI, 700, endpoint=False)
    tre = trefoil(u)[0]
    closed = np.vstack([tre, tre[:1]])
    # the closing pair (0, M−1) is adjacent: take it out of the reference
    ref = direct_pair_sum(closed) - 2.0 * _one_pair(closed, 0, len(closed) - 2)
    assert writhe_closed(tre) == pytest.approx(ref / TWO_PI, abs=1e-11)


def _one_pair(q, i, j):
    """Ω_ij of one pair, as in direct_pair_sum."""
    q = np.asarray(q, float) - np.mean(q, axis=0)
    a, b, c, d = q[j] - q[i], q[j + 1] - q[i], q[j + 1] - q[i + 1], q[j] - q[i + 1]
    na, nb, nc, nd = (np.linalg.norm(v) for v in (a, b, c, d))
    t = np.dot(np.cross(q[j + 1] - q[j], q[i + 1] - q[i]), a)
    d1 = na * nb * nc + a @ b * nc + a @ c * nb + b @ c * na
    d2 = na * nc * nd + a @ c * nd + a @ d * nc + c @ d * na
    return np.arctan2(t, d1) + np.arctan2(t, d2)


@pytest.mark.parametrize("seed", range(4))
def test_pair_sum_matches_direct_evaluation_on_random_curves(seed):
    """Random walks with segment lengths spread over six decades: pairs on either side
    of the well-separated test (every vertex distance at least the longer segment)."""
    rng = np.random.default_rng(seed)
    steps = rng.normal(size=(600, 3))
    steps *= 10.0 ** rng.uniform(-3, 3, size=(600, 1)) / np.linalg.norm(steps, axis=1)[:, None]
    pts = np.cumsum(steps, axis=0)
    ref = direct_pair_sum(pts) / TWO_PI
    scale = 1e-13 * len(pts) ** 2 / TWO_PI  # rounding of ~N²/2 terms, each |Ω| ≤ 2π
    assert writhe_polyline(pts) == pytest.approx(ref, abs=scale)
    smooth = random_fourier_curve(rng, 900, n_modes=5)
    ref = direct_pair_sum(smooth) / TWO_PI
    assert abs(ref) > 1e-3
    assert writhe_polyline(smooth) == pytest.approx(ref, abs=1e-11)


def test_parallel_pair_sum_is_the_serial_number():
    """The parallel sum adds the same runs of rows in the same order as the serial one."""
    from solver.topology import _pair_sum_kernel, _pair_sum_parallel

    pts = plectoneme(700)
    q = np.ascontiguousarray(extended(pts) - np.mean(pts, axis=0))
    assert _pair_sum_parallel(q, False) == _pair_sum_kernel(q, False)


# ----------------------------------------------------------------- independent library

def _pyknotid_closed_writhe(integral, pts):
    """pyknotid's writhing integral (K&L arcsine form) sums non-adjacent pairs of the open
    polyline it is given and leaves out the closing segment (its ``closed`` flag is not
    used).  Add the closing segment's pairs one at a time through 4-point polylines."""
    n = len(pts)
    w = integral(pts)[0]
    for k in range(1, n - 2):
        w += integral(np.array([pts[k], pts[k + 1], pts[n - 1], pts[0]]))[0]
    return w


def test_against_pyknotid_on_random_closed_curves():
    complexity = pytest.importorskip("pyknotid.spacecurves.complexity")
    integral = complexity.writhe_and_acn_integral
    rng = np.random.default_rng(2024)
    for _ in range(10):
        pts = random_fourier_curve(rng, 60, n_modes=4) + 0.05 * rng.normal(size=(60, 3))
        ours = writhe_closed(pts)
        theirs = _pyknotid_closed_writhe(integral, pts)
        assert ours == pytest.approx(theirs, abs=1e-6)
        # open polylines, no closure: the same pair sum
        assert writhe_polyline(pts) == pytest.approx(integral(pts)[0], abs=1e-6)


# ----------------------------------------------------------------- cost

def test_writhe_of_1000_segments_is_fast():
    u = np.linspace(0, TWO_PI * 3, 1001)
    pts = np.c_[np.cos(u), np.sin(u), 0.3 * u]
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        writhe(pts)
        times.append(time.perf_counter() - t0)
    assert min(times) < 0.1


def _writhe_in_child(points, queue):
    queue.put(writhe(points))


def test_parallel_writhe_in_a_process_forked_after_it():
    """The writhe's pair sum runs on all cores from PARALLEL_SEGMENTS segments; a process
    forked after the parent ran it (the service's Celery pool, the sweeps' process pool)
    must run it too. With GNU OpenMP as numba's threading layer the child aborted
    ("fork() called from a process already using GNU OpenMP"); solver sets numba's own
    work queue, which survives a fork."""
    import multiprocessing

    from solver.topology import PARALLEL_SEGMENTS

    k = np.arange(PARALLEL_SEGMENTS + 50, dtype=float)
    points = np.column_stack([np.cos(0.3 * k), np.sin(0.3 * k), 0.05 * k])
    here = writhe(points)
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_writhe_in_child, args=(points, queue))
    child.start()
    child.join(60)
    assert child.exitcode == 0
    assert queue.get(timeout=5) == pytest.approx(here, rel=1e-12)


def _two_ply(height, radius, theta, ds=5e-4):
    """A two-ply of pitch angle θ (rad, from the superhelix axis) and superhelix radius R
    (m) rising to ``height`` (m): one strand up, a small end loop, the other strand back
    down, half a turn apart; (points (M, 3), rod length of the two strands, m)."""
    length = height / np.cos(theta)
    s = np.arange(0.0, length, ds)
    phi = s * np.sin(theta) / radius
    up = np.stack([radius * np.cos(phi), radius * np.sin(phi), s * np.cos(theta)], 1)
    down = np.stack([-radius * np.cos(phi), -radius * np.sin(phi), s * np.cos(theta)], 1)
    ang = np.linspace(0.0, np.pi, 40)[1:-1]
    top = up[-1]
    centre = np.array([0.0, 0.0, top[2]])
    loop = (centre + np.cos(ang)[:, None] * (top - centre)
            + np.sin(ang)[:, None] * np.array([0.0, 0.0, radius]))
    return np.vstack([up, loop, down[::-1]]), 2.0 * length


def test_a_plys_writhe_per_length_of_rod_is_sin_2theta_over_4_pi_r():
    """The writhe a plectoneme's ply adds per unit length of rod is sin 2θ/(4πR)
    (Clauvelin, Audoly & Neukirch, Biophys. J. 96, 3716, 2009; Neukirch & Marko, PRL
    106, 138104, 2011), not sin 2θ/(8πR): the writhe of two plies of different heights,
    differenced so that their end loops cancel, over the rod length between them."""
    radius, theta = 0.01, 0.4
    short, l1 = _two_ply(0.3, radius, theta)
    tall, l2 = _two_ply(0.6, radius, theta)
    per_length = abs(writhe_polyline(tall) - writhe_polyline(short)) / (l2 - l1)
    expected = math.sin(2 * theta) / (4 * math.pi * radius)
    assert abs(per_length / expected - 1.0) < 1e-3, (per_length, expected)
