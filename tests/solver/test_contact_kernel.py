"""Tests of solver.contact: closest points, the laws, forces per unit length, search."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from solver.contact import (
    BarrierLaw,
    ContactCandidates,
    SeedLaw,
    SelfContact,
    assemble_nodal,
    nodal_weights,
    point_segment,
    smoothstep_off,
    swept_min_distance,
)

DS = 1.0e-3
DIAM = 0.02


def spec(**kw):
    base = dict(aperture=90.0, tolerance=0.03, k1=1.0e-7, k2=3.0, k3=1.0e-6, k4=1.0,
                exclusion=None)
    base.update(kw)
    return SimpleNamespace(**base)


def make(sp, s, diameter=DIAM, rho_a=0.5):
    n = s.size
    return SelfContact(sp, s, np.broadcast_to(diameter, (n,)).astype(float),
                       np.broadcast_to(rho_a, (n,)).astype(float))


def tangents_of(r):
    t = np.gradient(r, axis=0)
    return t / np.linalg.norm(t, axis=1)[:, None]


def strands(length, ds_a, ds_b, sep, shift=0.0):
    """Strand A along +x at y = 0 with spacing ds_a, strand B back along −x at y = sep with
    spacing ds_b, its nodes shifted by ``shift`` (a hairpin without its bend). Returns
    (s, r, t, n_a)."""
    xa = np.arange(0.0, length + 1e-12, ds_a)
    xb = np.arange(0.0, length + 1e-12, ds_b)[::-1] + shift
    ra = np.c_[xa, np.zeros_like(xa), np.zeros_like(xa)]
    rb = np.c_[xb, np.full_like(xb, sep), np.zeros_like(xb)]
    r = np.vstack([ra, rb])
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(r, axis=0), axis=1))]
    # the jump between the strands is long: keep s increasing with the true spacing
    t = np.vstack([np.tile([1.0, 0, 0], (xa.size, 1)), np.tile([-1.0, 0, 0], (xb.size, 1))])
    return s, r, t, xa.size


# ----------------------------------------------------------------- the law per unit length

def pressure_on_a(sc, s, r, t, n_a, middle):
    """Mean contact force per unit length on the middle of strand A (N/m, +y: toward B
    is negative), and its spread over the nodes there."""
    cand = sc.candidates(r, t)
    ev = sc.evaluate(cand, r, np.zeros_like(r))
    nodal = assemble_nodal(ev, s.size)
    fy = -nodal[:n_a][middle, 1]
    return fy.mean(), fy.max() - fy.min(), ev


@pytest.mark.parametrize("law", ["seed", "barrier"])
@pytest.mark.parametrize("ds_a, ds_b, shift", [(1.0e-3, 1.0e-3, 0.37e-3),
                                                (2.5e-3, 1.7e-3, 0.9e-3)])
def test_pressed_strands_reach_the_equilibrium_gap_of_the_law(law, ds_a, ds_b, shift):
    """Two strands pressed together by a known force per unit length p sit at the gap
    where the law's pressure equals p: g* = P⁻¹(p/ρA). The separation where the contact
    force per unit length on a strand balances p is found by bisection and must match
    the law's inverse within 1 %, at two grid spacings and with staggered nodes (one
    contact per closest approach: a node holding two partners would double the force
    and move the gap by 26 %)."""
    rho_a = 0.47
    sp = spec(aperture=90.0, tolerance=0.04, law=law, barrier_gap=0.005,
              barrier_stiffness=1.5e5)
    s, r0, t, n_a = strands(0.3, ds_a, ds_b, 0.03, shift)
    sc = make(sp, s, rho_a=rho_a)
    xa = r0[:n_a, 0]
    middle = (xa > 0.1) & (xa < 0.2)
    # N/m: 2 m/s² of pressure for the seed's law (gap 0.37 mm), the barrier's pressure
    # at a 2 mm gap for the barrier
    p = rho_a * (2.0 if law == "seed" else float(sc.law.repulsion(np.array([2e-3]))[0][0]))
    target = sc.law.equilibrium_gap(p / rho_a)
    if law == "seed":
        assert target == pytest.approx((1e-7 / 2.0) ** (1 / 3), rel=1e-12)
    else:
        assert target == pytest.approx(2e-3, rel=1e-9)
    lo, hi = 0.2 * target, 3.0 * target
    for _ in range(60):
        gap = 0.5 * (lo + hi)
        r = r0.copy()
        r[n_a:, 1] = DIAM + gap
        f, spread, ev = pressure_on_a(sc, s, r, t, n_a, middle)
        if f > p:
            lo = gap
        else:
            hi = gap
    assert gap == pytest.approx(target, rel=1e-2)
    # uniform along the strand when the strands share a spacing, whatever the
    # staggering; with different spacings the lumped transfer of the reactions to the
    # segment ends makes the nodal density fluctuate (docs/contact.md) about the mean
    assert spread < (1e-2 if ds_a == ds_b else 0.15) * p
    # one contact per owner node
    assert np.all(np.bincount(ev.i) <= 1)


def test_momentum_closes_and_each_strand_receives_the_law_per_unit_length():
    s, r, t, n_a = strands(0.2, 1.3e-3, 0.8e-3, DIAM + 0.001, 0.2e-3)
    sc = make(spec(), s, rho_a=0.5)
    ev = sc.evaluate(sc.candidates(r, t), r, np.zeros_like(r))
    nodal = assemble_nodal(ev, s.size)
    w = nodal_weights(s)
    total = (w[:, None] * nodal).sum(axis=0)
    assert np.abs(total).max() < 1e-9 * np.abs(w[:, None] * nodal).sum()
    law = 0.5 * 1e-7 / 0.001**3
    mid_a = (r[:n_a, 0] > 0.05) & (r[:n_a, 0] < 0.15)
    mid_b = (r[n_a:, 0] > 0.05) & (r[n_a:, 0] < 0.15)
    wa, wb = w[:n_a][mid_a], w[n_a:][mid_b]
    # the mean force per unit length on each strand is the law (not twice it)
    assert np.dot(wa, -nodal[:n_a][mid_a, 1]) / wa.sum() == pytest.approx(law, rel=2e-3)
    assert np.dot(wb, nodal[n_a:][mid_b, 1]) / wb.sum() == pytest.approx(law, rel=2e-3)
    np.testing.assert_allclose(-nodal[:n_a][mid_a, 1], law, rtol=0.1)


def test_laws_are_c2_at_their_cutoff_and_continued_linearly_below_the_floor():
    seed = SeedLaw(1e-7, 3.0, 0.0, 1.0, tolerance=0.04, gap_floor=2e-5)
    d = np.linspace(0.0301, 0.0399, 7)
    phi, dphi = smoothstep_off(d, np.full_like(d, 0.03), np.full_like(d, 0.04))
    assert np.all((phi > 0) & (phi < 1)) and np.all(dphi < 0)
    # value and slope vanish at the tolerance; below d_on the seed law is untouched
    eps = 1e-9
    f, f_d, _, _ = seed(np.array([0.04 - eps, 0.04 + eps]), np.zeros(2), np.full(2, DIAM),
                        np.ones(2))
    assert np.all(np.abs(f) < 1e-12) and np.all(np.abs(f_d) < 1e-6)
    f, _, _, gap = seed(np.array([0.0205]), np.zeros(1), np.full(1, DIAM), np.ones(1))
    assert f[0] == pytest.approx(1e-7 / 0.0005**3, rel=1e-12)
    val, slope = seed.repulsion(np.array([2e-5, 1e-5, 0.0, -2e-5]))
    f0 = 1e-7 / 2e-5**3
    np.testing.assert_allclose(val, f0 * np.array([1.0, 2.5, 4.0, 7.0]), rtol=1e-12)
    barrier = BarrierLaw(0.005, 1.5e5, 0.0, 1.0, gap_floor=2e-5)
    # the energy is C² at ĝ: the pressure and its slope go to zero there (P' ≈ −6κδ/ĝ)
    val, slope = barrier.repulsion(np.array([0.005 - 1e-7, 0.005, 0.006]))
    assert np.all(np.abs(val) < 1e-6)
    np.testing.assert_allclose(slope, [-6 * 1.5e5 * 1e-7 / 0.005, 0.0, 0.0], rtol=1e-4)
    # its derivative matches the value's central difference
    g = np.array([1e-4, 1e-3, 3e-3])
    h = 1e-9
    fd = (barrier.repulsion(g + h)[0] - barrier.repulsion(g - h)[0]) / (2 * h)
    np.testing.assert_allclose(barrier.repulsion(g)[1], fd, rtol=1e-5)
    assert barrier.equilibrium_gap(float(barrier.repulsion(np.array([1e-3]))[0][0])) == \
        pytest.approx(1e-3, rel=1e-9)


# ----------------------------------------------------------------- geometry and selection

def test_point_segment_closest_points():
    p = np.array([[0.5, 1.0, 0.0], [-1.0, 0.0, 0.0], [3.0, 0.5, 0.0]])
    a = np.zeros((3, 3))
    b = np.tile([2.0, 0.0, 0.0], (3, 1))
    t, x, d, tau = point_segment(p, a, b)
    np.testing.assert_allclose(t, [0.25, 0.0, 1.0])
    np.testing.assert_allclose(d, [1.0, 1.0, np.hypot(1.0, 0.5)])
    np.testing.assert_allclose(tau, np.tile([1.0, 0, 0], (3, 1)))


def test_run_minima_is_the_first_closest_segment_of_each_run():
    """The compiled search of each run's closest polyline segment against point_segment
    over every combination, on a random ply with runs of 1-9 segments and an exact tie."""
    from solver.contact.geometry import run_minima

    rng = np.random.default_rng(7)
    r = np.cumsum(rng.normal(scale=0.01, size=(300, 3)), axis=0)
    sizes = rng.integers(1, 10, size=40)
    start = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    owner = np.repeat(rng.integers(0, 300, size=40), sizes)
    segment = np.concatenate([rng.integers(0, 299 - k) + np.arange(k) for k in sizes])
    # a tie: the owner at the shared node of two segments of its run (distance 0 to both)
    owner[start[3]:start[3] + sizes[3]] = segment[start[3]] + (1 if sizes[3] > 1 else 0)
    d = point_segment(r[owner], r[segment], r[segment + 1])[2]
    expected = [lo + int(np.argmin(d[lo:lo + k])) for lo, k in zip(start, sizes)]
    np.testing.assert_array_equal(run_minima(r, owner, segment, start), expected)


def test_run_closest_is_the_nearest_curve_point_of_the_polyline_minimum_and_neighbours():
    """The compiled per-run selection against point_curve on each run's polyline minimum
    and its two neighbours (clipped to the run; the first on a tie), and with a frozen
    selection, on a random ply whose runs touch both rod ends."""
    from solver.contact.geometry import point_curve, run_closest, run_minima

    rng = np.random.default_rng(5)
    n = 200
    r = np.cumsum(rng.normal(scale=0.01, size=(n, 3)), axis=0)
    sizes = rng.integers(1, 8, size=30)
    start = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    owner = np.repeat(rng.integers(0, n, size=30), sizes)
    first = rng.integers(0, n - 1 - sizes)
    first[0], first[1] = 0, n - 1 - sizes[1]           # runs at both ends of the rod
    segment = np.concatenate([f + np.arange(k) for f, k in zip(first, sizes)])
    last = np.append(start[1:], owner.size) - 1
    k0 = run_minima(r, owner, segment, start)
    trio = np.clip(k0[:, None] + np.arange(-1, 2)[None, :], start[:, None],
                   last[:, None]).ravel()
    geo = point_curve(r[owner[trio]], r, segment[trio])
    sel = np.arange(start.size) * 3 + np.argmin(geo[2].reshape(-1, 3), axis=1)
    got = run_closest(r, owner, segment, start)
    np.testing.assert_array_equal(got[0], trio[sel])
    for a, b in zip(got[1:], geo):
        np.testing.assert_array_equal(a, b[sel])
    frozen = start + rng.integers(0, sizes)
    got = run_closest(r, owner, segment, start, frozen)
    geo = point_curve(r[owner[frozen]], r, segment[frozen])
    np.testing.assert_array_equal(got[0], frozen)
    for a, b in zip(got[1:], geo):
        np.testing.assert_array_equal(a, b)


def test_candidate_pairs_are_the_k_d_tree_pairs_beyond_the_exclusion_in_both_cones():
    """The compiled filter of the k-d tree's pairs (exclusion, aperture cones, both
    orders, sorted by owner and partner) against the numpy filters and deduplication it
    replaced, on random coiled curves, with and without the cones, with a pair at
    exactly the search radius and with one node far away."""
    from scipy.spatial import cKDTree

    from solver.contact.geometry import candidate_pairs

    def reference(r, t, radius, s, cut, lim):
        pairs = cKDTree(r).query_pairs(r=radius, output_type="ndarray").astype(np.intp)
        a, b = pairs[:, 0], pairs[:, 1]
        keep = np.abs(s[a] - s[b]) > cut
        a, b = a[keep], b[keep]
        if lim < 1.0:
            n = r[a] - r[b]
            n /= np.linalg.norm(n, axis=1)[:, None]
            keep = ((np.abs(np.einsum("ij,ij->i", t[a], n)) <= lim)
                    & (np.abs(np.einsum("ij,ij->i", t[b], n)) <= lim))
            a, b = a[keep], b[keep]
        key = np.unique(np.concatenate([a, b]) * len(r) + np.concatenate([b, a]))
        return key // len(r), key % len(r)

    rng = np.random.default_rng(11)
    for trial in range(12):
        n = int(rng.integers(30, 400))
        steps = rng.normal(size=(n - 1, 3)) + [0.0, 0.0, 0.3 * (trial % 3)]
        steps /= np.linalg.norm(steps, axis=1)[:, None]
        r = np.vstack([np.zeros(3), np.cumsum(0.01 * steps, axis=0)])
        s = 0.01 * np.arange(n)
        t = np.vstack([steps, steps[-1:]])
        radius = float(rng.uniform(0.02, 0.15))
        if trial == 0:                 # two nodes exactly one radius apart
            radius = float(np.linalg.norm(r[0] - r[-1]))
        if trial == 1:                 # a node 1e5 km away
            r[-1] += [1e8, 0.0, 0.0]
        for lim in (1.0, np.sin(np.radians(45.0))):
            owner, partner = candidate_pairs(r, t, radius, s, 0.05, lim)
            a, b = reference(r, t, radius, s, 0.05, lim)
            np.testing.assert_array_equal(owner, a)
            np.testing.assert_array_equal(partner, b)
            assert owner.size > 0 or trial % 3


def test_swept_test_sees_a_pass_through_that_both_ends_of_the_step_miss():
    r0 = np.array([[0.0, -0.05, 0.0], [0.0, 0.05, 0.0]])
    r1 = np.array([[0.0, 0.05, 0.0], [0.0, -0.05, 0.0]])
    a, b = np.array([0]), np.array([1])
    assert swept_min_distance(r0, r1, a, b)[0] == pytest.approx(0.0, abs=1e-15)
    assert np.linalg.norm(r1[0] - r1[1]) == pytest.approx(0.1)


def hairpin(n_straight=150, d0=0.025):
    """Two straight legs d0 apart joined by a semicircular bend."""
    rad = d0 / 2
    n_bend = int(round(np.pi * rad / DS))
    x = np.arange(n_straight) * DS
    leg_a = np.c_[x[::-1], np.zeros(n_straight), np.zeros(n_straight)] + [DS, 0, 0]
    th = np.linspace(0, np.pi, n_bend + 1)[:-1]
    bend = np.c_[-rad * np.sin(th), rad - rad * np.cos(th), np.zeros(n_bend)]
    leg_b = np.c_[x, np.full(n_straight, d0), np.zeros(n_straight)]
    r = np.vstack([leg_a, bend, leg_b])
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(r, axis=0), axis=1))]
    return s, r, tangents_of(r)


def test_hairpin_contacts_face_each_other_beyond_the_exclusion():
    s, r, t = hairpin()
    sc = make(spec(aperture=180.0), s)
    ev = sc.evaluate(sc.candidates(r, t), r, np.zeros_like(r))
    assert ev.count > 0
    partner_s = (1 - ev.t) * s[ev.j] + ev.t * s[ev.j + 1]
    assert np.all(np.abs(s[ev.i] - partner_s) > 2 * DIAM)
    # no oblique force from the edge of the exclusion: every force is across the legs
    n_dir = ev.force / np.linalg.norm(ev.force, axis=1)[:, None]
    assert np.abs(n_dir[:, 0]).max() < 0.05
    assert np.all(np.bincount(ev.i) <= 1)
    wide = make(spec(aperture=180.0, exclusion=0.12), s)
    ev_w = wide.evaluate(wide.candidates(r, t), r, np.zeros_like(r))
    assert 0 < ev_w.count < ev.count
    none = make(spec(aperture=180.0, exclusion=s[-1]), s)
    assert none.candidates(r, t).runs == 0


def test_a_node_between_two_strands_keeps_one_contact_on_each():
    n, d0 = 100, 0.025
    x = np.arange(n) * DS
    ra = np.c_[x, np.zeros(n), np.zeros(n)]
    rb = np.c_[x[::-1], np.full(n, d0), np.zeros(n)]
    rc = np.c_[x, np.full(n, -d0), np.zeros(n)]
    bridge = np.array([[0.0, 0.0, 0.5]])          # B to C far from A
    r = np.vstack([ra, rb, bridge, rc])
    t = np.vstack([np.tile([1.0, 0, 0], (n, 1)), np.tile([-1.0, 0, 0], (n, 1)),
                   [[0.0, 0.0, 1.0]], np.tile([1.0, 0, 0], (n, 1))])
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(r, axis=0), axis=1))]
    sc = make(spec(), s)
    ev = sc.evaluate(sc.candidates(r, t), r, np.zeros_like(r))
    mid = ev.i == 50
    assert mid.sum() == 2
    nodal = assemble_nodal(ev, s.size)
    assert abs(nodal[50, 1]) < 1e-9 * abs(nodal[2 * n - 1 - 50, 1])


def test_selection_is_continuous_as_a_strand_slides():
    """The force on a node varies smoothly while the other strand slides past it by a
    fraction of a cell (node-to-node partners would switch and jump)."""
    s, r0, t, n_a = strands(0.1, 1e-3, 1e-3, DIAM + 0.0005)
    sc = make(spec(aperture=180.0), s)
    cand = sc.candidates(r0, t, reach=0.002)
    forces = []
    for shift in np.linspace(0.0, 1e-3, 11):
        r = r0.copy()
        r[n_a:, 0] += shift
        r[n_a:, 1] += 0.0002 * np.sin(40 * r[n_a:, 0])        # a gently wavy partner
        forces.append(assemble_nodal(sc.evaluate(cand, r, np.zeros_like(r)), s.size)[50, 1])
    jumps = np.abs(np.diff(forces))
    assert jumps.max() < 0.2 * np.abs(forces).max()


@pytest.mark.parametrize("law", ["seed", "barrier"])
def test_analytic_derivatives_match_central_differences(law):
    """One owner node and one partner segment, closest point inside the segment; the
    partner curve spans nodes 1-3 and a ghost beyond the rod end (node 3 twice)."""
    s = np.array([0.0, 0.05, 0.1, 0.15])
    sp = spec(aperture=180.0, tolerance=0.04, k3=1e-3, exclusion=0.01, law=law,
              barrier_gap=0.005, barrier_stiffness=1.5e5)
    # properties differ between owner and partner; along the partner segment they are
    # uniform (the Jacobian leaves out how D̄ and ρĀ move with t: docs/contact.md)
    sc = make(sp, s, rho_a=np.array([0.4, 0.5, 0.6, 0.6]),
              diameter=np.array([0.021, 0.02, 0.019, 0.019]))
    rng = np.random.default_rng(3)
    r = np.zeros((4, 3))
    r[0] = [0.0205, 0.0, 0.0025]
    r[2] = [0.0, 0.0, 0.0]
    r[3] = [0.0002, 0.0003, 0.005]
    r[1] = [-0.0003, 0.0002, -0.005]
    v = 0.01 * rng.standard_normal((4, 3))
    cand = ContactCandidates(np.array([0]), np.array([2]), np.array([0]),
                             np.array([True]), np.array([True]))
    ev = sc.evaluate(cand, r, v)
    assert ev.count == 1 and 0.0 < ev.t[0] < 1.0
    assert list(ev.nodes[0]) == [0, 1, 2, 3, 3]
    for node in np.unique(ev.nodes[0]):
        slots = ev.nodes[0] == node               # a node in two slots: their sum
        for k in range(3):
            # the damping ḋ|ḋ| is only C¹ at ḋ = 0: a wider tolerance for its difference
            for arr, jac, h, tol in ((r, ev.d_force_d_r, 1e-9, 1e-5),
                                     (v, ev.d_force_d_v, 1e-7, 2e-2)):
                plus, minus = arr.copy(), arr.copy()
                plus[node, k] += h
                minus[node, k] -= h
                args_p = (plus, v) if arr is r else (r, plus)
                args_m = (minus, v) if arr is r else (r, minus)
                fd = (sc.evaluate(cand, *args_p).force[0] - sc.evaluate(cand, *args_m).force[0]) / (2 * h)
                scale = np.abs(jac[0]).max()
                np.testing.assert_allclose(jac[0, slots].sum(axis=0)[:, k], fd,
                                           atol=tol * scale, rtol=10 * tol)


def test_damping_opposes_relative_normal_motion():
    s, r, t, n_a = strands(0.1, 1e-3, 1e-3, DIAM + 0.005)
    sc = make(spec(k3=1e-3), s, rho_a=1.0)
    cand = sc.candidates(r, t)
    v0 = np.zeros_like(r)
    approach, separate = v0.copy(), v0.copy()
    approach[n_a:, 1] = -0.1
    separate[n_a:, 1] = 0.1
    f_static = sc.evaluate(cand, r, v0).force[:, 1]
    f_app = sc.evaluate(cand, r, approach).force[:, 1]
    f_sep = sc.evaluate(cand, r, separate).force[:, 1]
    on_a = sc.evaluate(cand, r, v0).i < n_a
    assert np.all(np.abs(f_app) > np.abs(f_static)) and np.all(np.abs(f_sep) < np.abs(f_static))
    d = DIAM + 0.005
    np.testing.assert_allclose(np.abs(f_app[on_a]) - np.abs(f_static[on_a]), 1e-3 / d * 0.01,
                               rtol=1e-9)


# ----------------------------------------------------------------- may_touch and search

def test_may_touch_straight_rod_false_closed_loop_true():
    n = 1001
    s = np.linspace(0.0, 1.0, n)
    sc = make(spec(), s)
    straight = np.c_[np.zeros(n), np.zeros(n), s]
    assert sc.may_touch(straight, tangents_of(straight)) is False
    assert sc.may_touch(straight, tangents_of(straight), reach=2.0) is True
    turns, rise = 1.1, 0.025
    radius = np.sqrt((1.0 / turns) ** 2 - rise**2) / (2 * np.pi)
    phi = 2 * np.pi * turns * s
    coil = np.c_[radius * np.cos(phi), radius * np.sin(phi), rise * turns * s]
    assert sc.may_touch(coil, tangents_of(coil)) is True
    ev = sc.evaluate(sc.candidates(coil, tangents_of(coil)), coil, np.zeros_like(coil))
    assert ev.count > 0
    assert np.median(ev.distance) == pytest.approx(rise, rel=2e-3)


def test_may_touch_false_is_rigorous():
    rng = np.random.default_rng(8)
    n = 400
    s = np.arange(n) * DS
    sc = make(spec(aperture=180.0), s)
    false_seen = 0
    for _ in range(30):
        amp = rng.uniform(0.0, 0.8)
        th = amp * np.sin(2 * np.pi * s / 0.4 * rng.uniform(0.5, 3) + rng.uniform(0, 6))
        ph = rng.uniform(0, 2 * np.pi) + rng.uniform(-3, 3) * s
        tang = np.c_[np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)]
        r = np.vstack([np.zeros(3), np.cumsum(tang[:-1] * DS, axis=0)])
        if not sc.may_touch(r, tang):
            false_seen += 1
            assert sc.candidates(r, tang).runs == 0
    assert false_seen >= 5


def two_strand_ply(n_total, pitch=0.08, radius=0.0105):
    m = n_total // 2
    phi = np.arange(m) * DS / np.hypot(radius, pitch / (2 * np.pi))
    z = pitch * phi / (2 * np.pi)
    a = np.c_[radius * np.cos(phi), radius * np.sin(phi), z]
    b = np.c_[-radius * np.cos(phi), -radius * np.sin(phi), z][::-1]
    r = np.vstack([a, b])
    t = np.vstack([tangents_of(a), tangents_of(b)])
    return np.arange(2 * m) * DS, r, t, m


def test_search_on_a_2000_point_ply():
    s, r, t, m = two_strand_ply(2000)
    sc = make(spec(), s)
    ev = sc.evaluate(sc.candidates(r, t), r, np.zeros_like(r))
    assert ev.count > 1000
    assert np.all(np.bincount(ev.i) <= 1)
    assert ev.min_gap == pytest.approx(2 * 0.0105 - DIAM, rel=2e-2)


def test_candidates_merge_and_cover():
    s, r, t, m = two_strand_ply(600)
    sc = make(spec(), s)
    c1 = sc.candidates(r, t)
    r2 = r.copy()
    r2[:, 2] *= 0.9
    c2 = sc.candidates(r2, tangents_of(r2))
    both = sc.merge(c1, c2)
    assert sc.covers(both, c1) and sc.covers(both, c2)
    assert sc.covers(c1, c1)
    narrow = make(spec(tolerance=0.0215), s).candidates(r, t)
    assert 0 < narrow.owner.size < c1.owner.size
    assert sc.covers(c1, narrow) and not sc.covers(narrow, c1)


def test_invalid_construction_and_inputs():
    s = np.arange(10) * DS
    with pytest.raises(ValueError, match="tolerance"):
        make(spec(tolerance=0.02), s)
    with pytest.raises(ValueError, match="aperture"):
        make(spec(aperture=0.0), s)
    with pytest.raises(ValueError, match="law"):
        make(spec(law="hertz"), s)
    with pytest.raises(ValueError, match="barrier_gap"):
        make(spec(law="barrier", barrier_stiffness=1.0), s)
    with pytest.raises(ValueError, match="barrier_gap"):
        make(spec(law="barrier", barrier_gap=0.02, barrier_stiffness=1.0), s)
    sc = make(spec(), s)
    with pytest.raises(ValueError, match="positions"):
        sc.candidates(np.zeros((3, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="finite"):
        bad = np.zeros((10, 3))
        bad[0, 0] = np.nan
        sc.evaluate(sc.candidates(np.c_[s, 0 * s, 0 * s], np.tile([1.0, 0, 0], (10, 1))),
                    bad, np.zeros((10, 3)))


def test_closest_point_is_continuous_on_the_concave_side_of_a_bend():
    """A node inside a bent partner strand (the plies of a plectoneme, each on the concave
    side of the other) sliding along it: the closest point of the polyline jumps between
    segments there (the two feet differ by ~0.14 Δs at this bend), that of the C¹ partner
    curve moves continuously, so the loads on the partner's nodes change smoothly."""
    n_b = 200
    rho = 0.03                                      # bend radius of the partner, m
    phi = (np.arange(n_b) - n_b / 2) * 1e-3 / rho
    partner = np.stack([rho * np.sin(phi), rho * (1.0 - np.cos(phi)), np.zeros(n_b)], axis=1)
    n_a = 101                                       # a straight owner strand far away ...
    own = np.stack([np.zeros(n_a), np.full(n_a, 0.3), (np.arange(n_a) - 50) * 1e-3], axis=1)
    r0 = np.vstack([own, partner])
    s = np.arange(n_a + n_b) * 1e-3
    s[n_a:] += 1.0                                  # ... beyond the exclusion
    sc = make(spec(aperture=180.0, tolerance=0.04), s)
    gap_target = 0.0004
    samples, feet = [], []
    for x in np.linspace(-0.002, 0.002, 161):       # 0.025 mm steps across 4 cells
        ang = x / rho
        centre = np.array([0.0, rho, 0.0])
        r = r0.copy()
        # node 50 of the owner on the concave side, at a fixed distance from the arc
        r[50] = centre + (rho - DIAM - gap_target) * np.array([np.sin(ang), -np.cos(ang), 0.0])
        t = np.zeros_like(r)
        t[:, 2] = 1.0
        cand = sc.candidates(r, t)
        ev = sc.evaluate(cand, r, np.zeros_like(r))
        mine = ev.i == 50
        assert mine.sum() == 1
        feet.append(float(ev.j[mine][0] + ev.t[mine][0]))
        samples.append(assemble_nodal(ev, s.size)[n_a:, :2].copy())
    samples = np.array(samples)
    jumps = np.abs(np.diff(samples, axis=0)).max()
    assert jumps < 0.02 * np.abs(samples).max()
    # the foot advances monotonically by about one cell per millimetre
    assert np.all(np.diff(feet) > 0.0) and np.diff(feet).max() < 0.1


def _reference_runs(sc, own, par):
    """Runs of node pairs as sets: per owner, the partners sorted and split where they
    jump by more than 3, each run widened by one node where that node is in the rod and
    beyond the exclusion; (owner, first node, last node) triples."""
    n = sc.n_nodes
    pairs = sorted(set(zip(own.tolist(), par.tolist())))
    runs = []
    for o in sorted({p[0] for p in pairs}):
        mine = [p for q, p in pairs if q == o]
        groups = [[mine[0]]]
        for p in mine[1:]:
            if p > groups[-1][-1] + 3:
                groups.append([p])
            else:
                groups[-1].append(p)
        for g in groups:
            lo, hi = g[0], g[-1]
            if lo - 1 >= 0 and abs(sc.s[o] - sc.s[lo - 1]) > sc.separation_cut:
                lo -= 1
            if hi + 1 < n and abs(sc.s[o] - sc.s[hi + 1]) > sc.separation_cut:
                hi += 1
            if hi > lo:
                runs.append((o, lo, hi))
    return runs


def _runs_of(cand):
    out = []
    bounds = list(cand.run_start) + [cand.owner.size]
    for q in range(cand.runs):
        seg = cand.segment[bounds[q]:bounds[q + 1]]
        assert np.all(cand.owner[bounds[q]:bounds[q + 1]] == cand.owner[bounds[q]])
        assert np.array_equal(seg, np.arange(seg[0], seg[-1] + 1))
        out.append((int(cand.owner[bounds[q]]), int(seg[0]), int(seg[-1]) + 1))
        assert cand.first_vertex_is_end[q] == (seg[0] == 0)
        assert cand.last_vertex_is_end[q] == (seg[-1] + 1 == _N_REF - 1)
    return out


_N_REF = 60


def test_runs_merge_and_covers_against_set_reference():
    """The compiled run building (deduplication, splitting, widening), merging and the
    coverage test against a plain set-based reference on random node pairs."""
    n = _N_REF
    s = np.linspace(0.0, 1.0, n)
    sc = SelfContact(dict(aperture=90.0, tolerance=0.04, k1=1e-7, k2=3.0, k3=0.0, k4=0.0),
                     s, np.full(n, 0.01), np.full(n, 0.1))
    rng = np.random.default_rng(3)
    made = []
    for _ in range(200):
        m = int(rng.integers(0, 40))
        own, par = rng.integers(0, n, m), rng.integers(0, n, m)
        ok = np.abs(s[own] - s[par]) > sc.separation_cut
        own, par = own[ok], par[ok]
        cand = sc._runs(own, par)
        assert _runs_of(cand) == _reference_runs(sc, own, par)
        made.append(cand)
    for a, b in zip(made[::2], made[1::2]):
        merged = sc.merge(a, b)
        combos = set(zip(merged.owner.tolist(), merged.segment.tolist()))
        for c in (a, b):
            assert set(zip(c.owner.tolist(), c.segment.tolist())) <= combos
            assert sc.covers(merged, c)
        extra = combos - set(zip(a.owner.tolist(), a.segment.tolist()))
        assert sc.covers(a, merged) == (not extra)


def _tree_pairs(r, radius, s, cut):
    """The reference: scipy's k-d tree on the nodes, filtered by the arclength rule."""
    from scipy.spatial import cKDTree
    p = cKDTree(r).query_pairs(r=radius, output_type="ndarray")
    keep = np.abs(s[p[:, 0]] - s[p[:, 1]]) > cut
    return {(int(a), int(b)) for a, b in p[keep]}


@pytest.mark.parametrize("n, radius, cut, path", [
    (1001, 0.04, 0.04, "blocks"), (2001, 0.045, 0.04, "blocks"), (400, 0.02, 0.005, "blocks"),
    (400, 0.1, 0.3, "blocks"), (300, 0.013, 0.01, "nodes"), (100, 0.05, 0.05, "all pairs"),
    (21, 0.2, 0.1, "all pairs")])
def test_blocked_tree_search_finds_the_pairs_of_a_tree_on_the_nodes(n, radius, cut, path):
    """close_node_pairs over blocks of radius/Δs nodes (with fewer than BLOCK_MIN_NODES
    per block, a tree on the nodes; on small grids, the compiled loop over all pairs)
    returns exactly the pairs of a k-d tree built on every node, on a tight helix whose turns lie within the radius of each
    other (pairs across turns and, for the long radius, across two and three turns),
    with a non-uniform grid and a last block shorter than the others."""
    from solver.contact.geometry import ALL_PAIRS_NODES, BLOCK_MIN_NODES, close_node_pairs
    rng = np.random.default_rng(n)
    s = np.sort(np.concatenate([[0.0, 1.0], rng.uniform(0.0, 1.0, n - 2)]))
    turns = 25.0
    r = np.column_stack([0.015 * np.cos(2 * np.pi * turns * s),
                         0.015 * np.sin(2 * np.pi * turns * s), 0.3 * s])
    r += 1e-4 * rng.standard_normal(r.shape)
    a, b = close_node_pairs(r, radius, s, cut)
    assert np.all(a < b)
    got = {(int(i), int(j)) for i, j in zip(a, b)}
    assert len(got) == len(a)            # no pair twice
    want = _tree_pairs(r, radius, s, cut)
    assert want and got == want
    # each path is exercised
    if path == "all pairs":
        assert n <= ALL_PAIRS_NODES
    else:
        assert n > ALL_PAIRS_NODES
        assert (int(radius * (n - 1)) >= BLOCK_MIN_NODES) == (path == "blocks")


def test_blocked_tree_search_with_a_non_finite_node_raises_like_the_tree():
    """A non-finite position is refused by scipy's tree as before (callers test
    finiteness first: SelfContact.search)."""
    from solver.contact.geometry import close_node_pairs
    s = np.linspace(0.0, 1.0, 500)
    r = np.column_stack([s, np.zeros(500), np.zeros(500)])
    r[250, 0] = np.nan
    with pytest.raises(ValueError):
        close_node_pairs(r, 0.05, s, 0.1)


def test_passes_through_tells_a_strand_crossing_another_within_a_step():
    """SelfContact.passes_through: a leg of a hairpin moved through the other leg in
    one step is caught (its nodes sweep within a quarter of the two diameters of the
    other leg's nodes), while the same leg moved away, or the whole rod translated far,
    is not; the O(N) pre-test alone rules out a straight rod moving sideways."""
    s, r, _ = hairpin(n_straight=60)
    sc = make(spec(aperture=180.0), s)
    leg_b = r[:, 1] > 0.02                        # the leg at y = d0 = 0.025 m
    through = r.copy()
    through[leg_b, 1] = -0.025                    # across leg a (y = 0) to y = −d0
    away = r.copy()
    away[leg_b, 1] = 0.05
    assert sc.passes_through(r, through)
    assert not sc.passes_through(r, away)
    assert not sc.passes_through(r, r + [1.0, 0.5, 0.0])
    # a straight rod moved sideways by many diameters: nothing to check
    s2 = np.arange(200) * DS
    line = np.c_[s2, np.zeros(200), np.zeros(200)]
    sc2 = make(spec(aperture=180.0), s2)
    assert not sc2.passes_through(line, line + [0.0, 0.3, 0.0])


def test_passes_through_tells_strands_crossing_between_their_nodes():
    """Two straight strands of segments three diameters long (h = 0.06 m, D = 0.02 m),
    one above the other and crossed at right angles, the upper one moved down through
    the lower in one step so that it crosses it midway between nodes: no node comes
    within D/2 of another node at any time (the nearest pass is h/√2 = 2.1 D), so only
    the segments' sweep tells it (at sub-times, SWEPT_SUBSTEPS at most); stopping one
    diameter short of the other strand is no passage."""
    h, n = 0.06, 21
    s = np.arange(2 * n) * h
    x = (np.arange(n) - n // 2 + 0.5) * h          # crossing midway between nodes
    lower = np.c_[x, np.zeros(n), np.zeros(n)]
    upper = np.c_[np.zeros(n), x[::-1], np.full(n, 0.05)]
    # one rod: the lower strand, then (one long segment on) the upper strand
    r0 = np.vstack([lower, upper])
    sc = make(spec(aperture=180.0, tolerance=0.03), s)
    down = r0.copy()
    down[n:, 2] = -0.05
    short = r0.copy()
    short[n:, 2] = 0.021
    nodes = np.linalg.norm(r0[:n, None, :2] - r0[None, n:, :2], axis=2).min()
    assert nodes > 2.0 * DIAM                       # the nodes never meet
    assert sc.passes_through(r0, down)
    assert not sc.passes_through(r0, short)


def test_swept_pair_filter_keeps_every_pair_that_meets():
    """_pairs_that_may_meet drops only pairs that cannot come within ½ D_max over the
    step: on random wiggles of a folded strand (nodes moved by up to 4 diameters, so the
    reach of _swept_reach covers many pairs), every node pair whose swept node distance or
    whose segments' sampled distance falls below ½ D_max is kept, and the collision
    verdict with the filter equals the verdict on all the pairs."""
    from solver.contact.geometry import close_node_pairs, swept_min_distance
    from solver.contact.model import (_pairs_that_may_meet, _swept_any_within,
                                      _swept_segments_within)

    rng = np.random.default_rng(7)
    s, r, _ = hairpin(n_straight=40)
    diameter = np.full(len(s), DIAM)
    cut = 2.0 * DIAM
    verdicts = kept_total = 0
    for trial in range(40):
        scale = DIAM * (0.2 if trial % 2 else 4.0)
        r1 = r + scale * rng.standard_normal(r.shape) + rng.standard_normal(3) * 0.1
        a, b = close_node_pairs(r1, 1.0, s, cut, np.inf)
        ka, kb = _pairs_that_may_meet(r, r1, a, b, diameter, False)
        kept = set(zip(ka.tolist(), kb.tolist()))
        kept_total += len(kept)
        near = swept_min_distance(r, r1, a, b) < 0.5 * DIAM
        for p in np.flatnonzero(near):
            assert (a[p], b[p]) in kept
        for p in range(a.size):
            if (a[p], b[p]) not in kept:
                one = np.array([a[p]]), np.array([b[p]])
                assert not _swept_segments_within(r, r1, *one, diameter, s, cut, np.inf)
        full = bool(np.any(swept_min_distance(r, r1, a, b) < 0.5 * DIAM)
                    or _swept_segments_within(r, r1, a, b, diameter, s, cut, np.inf))
        assert _swept_any_within(r, r1, a, b, diameter, s, cut, np.inf) == full
        verdicts += full
    assert 0 < verdicts < 40 and kept_total > 0
