"""Tests of solver.contact: the seed's eq.-6 self-contact kernel and pair selection."""
from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np
import pytest

from solver.contact import (
    ContactPairs,
    SelfContact,
    assemble_nodal,
    nodal_weights,
)

DS = 1.0e-3
DIAM = 0.02


def spec(**kw):
    base = dict(aperture=90.0, tolerance=0.03, k1=1.0e-7, k2=3.0, k3=1.0e-6, k4=1.0,
                exclusion=None)
    base.update(kw)
    return SimpleNamespace(**base)


def parallel_strands(n=100, d0=0.025, offset=0.0):
    """Strand A along +x at y = 0 (nodes 0..n-1), strand B back along −x at y = d0
    (nodes n..2n-1, node n+k directly above node n-1-k), a hairpin without its bend."""
    x = np.arange(n) * DS
    ra = np.c_[x, np.zeros(n), np.zeros(n)]
    rb = np.c_[x[::-1] + offset, np.full(n, d0), np.zeros(n)]
    r = np.vstack([ra, rb])
    t = np.vstack([np.tile([1.0, 0, 0], (n, 1)), np.tile([-1.0, 0, 0], (n, 1))])
    s = np.arange(2 * n) * DS
    return s, r, t


def make(sp, s, diameter=DIAM, rho_a=0.5):
    n = s.size
    return SelfContact(sp, s, np.broadcast_to(diameter, (n,)).astype(float),
                       np.broadcast_to(rho_a, (n,)).astype(float))


def tangents_of(r):
    t = np.gradient(r, axis=0)
    return t / np.linalg.norm(t, axis=1)[:, None]


# ----------------------------------------------------------------- parallel strands

def test_parallel_strands_forces_equal_opposite_apart_and_match_the_law():
    n, d0 = 100, 0.025
    s, r, t = parallel_strands(n, d0)
    sp = spec()
    sc = make(sp, s, rho_a=0.5)
    pairs = sc.find_pairs(r, t)
    assert pairs.count > 0
    ev = sc.evaluate(pairs, r, np.zeros_like(r))
    nodal = assemble_nodal(ev, 2 * n)
    # momentum balance of the pairs
    total = (sc.weights[:, None] * nodal).sum(axis=0)
    assert np.abs(total).max() < 1e-15 * np.abs(nodal).max()
    # directed apart: strand A pushed to −y, strand B to +y, nothing along x or z
    loaded = np.abs(nodal).sum(axis=1) > 0
    assert np.all(nodal[:n][loaded[:n], 1] < 0)
    assert np.all(nodal[n:][loaded[n:], 1] > 0)
    assert np.abs(nodal[:, [0, 2]]).max() == 0.0
    # magnitude: interior nodes receive the law at the local distance, ρA k1/gap^k2
    law = 0.5 * sp.k1 / (d0 - DIAM) ** sp.k2
    np.testing.assert_allclose(nodal[20:60, 1], -law, rtol=1e-12)
    np.testing.assert_allclose(nodal[n + 40:n + 80, 1], law, rtol=1e-12)
    assert ev.min_gap == pytest.approx(d0 - DIAM, rel=1e-12)
    assert ev.count == pairs.count == ev.force.shape[0]


def test_non_uniform_properties_use_mean_diameter_and_mean_rho_a():
    n, d0 = 60, 0.026
    s, r, t = parallel_strands(n, d0)
    diameter = np.r_[np.full(n, 0.02), np.full(n, 0.022)]
    rho_a = np.r_[np.full(n, 0.4), np.full(n, 0.6)]
    sc = SelfContact(spec(), s, diameter, rho_a)
    ev = sc.evaluate(sc.find_pairs(r, t), r, np.zeros_like(r))
    gap = d0 - 0.021
    np.testing.assert_allclose(np.linalg.norm(ev.force, axis=1), 0.5 * 1e-7 / gap**3,
                               rtol=1e-12)
    np.testing.assert_allclose(ev.gap, gap, rtol=1e-12)


def test_momentum_closes_on_a_non_uniform_grid():
    rng = np.random.default_rng(0)
    s, r, t, _ = two_strand_ply(600)
    s = np.cumsum(rng.uniform(0.5, 1.5, s.size)) * DS  # non-uniform weights
    sc = make(spec(aperture=180.0), s)
    pairs = sc.find_pairs(r, t)
    v = rng.normal(scale=0.01, size=r.shape)
    ev = sc.evaluate(pairs, r, v)
    assert pairs.count > 100
    assert not np.allclose(ev.wj, 0.5)
    np.testing.assert_allclose(sc.weights[ev.i] * ev.wi, sc.weights[ev.j] * ev.wj, rtol=1e-15)
    nodal = assemble_nodal(ev, s.size)
    total = (sc.weights[:, None] * nodal).sum(axis=0)
    scale = (sc.weights[:, None] * np.abs(nodal)).sum(axis=0).max()
    assert np.abs(total).max() < 1e-14 * scale


def test_nodal_weights_are_half_cells_at_the_ends():
    s = np.array([0.0, 1.0, 3.0, 4.0])
    np.testing.assert_allclose(nodal_weights(s), [0.5, 1.5, 1.5, 0.5])


# ----------------------------------------------------------------- selection

def test_no_force_outside_tolerance():
    s, r, t = parallel_strands(100, d0=0.0305)
    sc = make(spec(), s)
    assert sc.find_pairs(r, t).count == 0
    s, r, t = parallel_strands(100, d0=0.0295)
    assert sc.find_pairs(r, t).count > 0  # control


def test_no_force_outside_the_aperture():
    """Two strands in one plane converging at 20°: a pair direction cannot lie within
    5° of both cross-section planes, so an aperture of 10° admits nothing."""
    n = 80
    alpha = np.radians(20.0)
    x = np.arange(n) * DS
    ra = np.c_[x, np.zeros(n), np.zeros(n)]
    rb = np.c_[x * np.cos(alpha), 0.022 + x * np.sin(alpha), np.zeros(n)][::-1]
    r = np.vstack([ra, rb])
    t = np.vstack([np.tile([1.0, 0, 0], (n, 1)),
                   np.tile([-np.cos(alpha), -np.sin(alpha), 0], (n, 1))])
    s = np.arange(2 * n) * DS
    assert make(spec(aperture=10.0), s).find_pairs(r, t).count == 0
    assert make(spec(aperture=90.0), s).find_pairs(r, t).count > 0  # control
    # the cone test applies at both ends: 30° admits directions within 15° of both planes
    pairs = make(spec(aperture=30.0), s).find_pairs(r, t)
    if pairs.count:
        n_dir = r[pairs.i] - r[pairs.j]
        n_dir /= np.linalg.norm(n_dir, axis=1)[:, None]
        for side in (pairs.i, pairs.j):
            assert np.all(np.abs(np.einsum("ij,ij->i", t[side], n_dir))
                          <= np.sin(np.radians(15.0)) + 1e-12)


def hairpin(n_straight=150, d0=0.025):
    """A real hairpin: two straight legs d0 apart joined by a semicircular bend."""
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


def test_no_pairs_between_near_neighbours_along_one_strand():
    s, r, t = hairpin()
    # aperture 180° (all space): only the exclusion and the local-minimum rule can reject
    default = make(spec(aperture=180.0), s).find_pairs(r, t)
    assert default.count > 0
    assert np.all(np.abs(s[default.i] - s[default.j]) > 2 * DIAM)
    # a larger exclusion removes the pairs nearest the bend, an exclusion beyond the
    # longest |Δs| removes everything
    wide = make(spec(aperture=180.0, exclusion=0.12), s).find_pairs(r, t)
    assert 0 < wide.count < default.count
    assert np.all(np.abs(s[wide.i] - s[wide.j]) > 0.12)
    assert make(spec(aperture=180.0, exclusion=s[-1]), s).find_pairs(r, t).count == 0
    # and no oblique pairs at the exclusion edge: all kept pairs face each other across
    n_dir = r[wide.i] - r[wide.j]
    n_dir /= np.linalg.norm(n_dir, axis=1)[:, None]
    assert np.abs(n_dir[:, 0]).max() < 0.05
    # a straight rod has no pair whatever the exclusion
    n = 200
    line = np.c_[np.arange(n) * DS, np.zeros(n), np.zeros(n)]
    tl = np.tile([1.0, 0, 0], (n, 1))
    assert make(spec(aperture=180.0, exclusion=0.0015), np.arange(n) * DS).find_pairs(line, tl).count == 0


def test_local_minimum_selection_keeps_one_partner_per_node_per_strand():
    n, d0 = 100, 0.025
    s, r, t = parallel_strands(n, d0)
    sc = make(spec(), s)
    pairs = sc.find_pairs(r, t)
    # without selection every node would see ~33 partners within tolerance
    d_all = np.linalg.norm(r[:n, None] - r[None, n:], axis=2)
    assert (d_all[50] < 0.03).sum() > 30
    owners, counts = np.unique(pairs.i, return_counts=True)
    assert np.all(counts == 1)
    # the partner is the node directly across: node n + k sits above node n - 1 - k
    on_a = pairs.i < n
    np.testing.assert_array_equal(pairs.j[on_a], 2 * n - 1 - pairs.i[on_a])
    np.testing.assert_allclose(pairs.distance, d0, rtol=1e-12)
    # both orientations are owned
    assert np.any(pairs.i >= n) and np.any(on_a)


def test_a_node_between_two_strands_keeps_one_partner_on_each():
    n, d0 = 100, 0.025
    x = np.arange(n) * DS
    ra = np.c_[x, np.zeros(n), np.zeros(n)]
    rb = np.c_[x[::-1], np.full(n, d0), np.zeros(n)]
    rc = np.c_[x, np.full(n, -d0), np.zeros(n)]
    r = np.vstack([ra, rb, rc])
    t = np.vstack([np.tile([1.0, 0, 0], (n, 1)), np.tile([-1.0, 0, 0], (n, 1)),
                   np.tile([1.0, 0, 0], (n, 1))])
    s = np.arange(3 * n) * DS
    sc = make(spec(), s)
    pairs = sc.find_pairs(r, t)
    mid = pairs.i == 50
    assert sorted(pairs.j[mid].tolist()) == [2 * n - 1 - 50, 2 * n + 50]
    ev = sc.evaluate(pairs, r, np.zeros_like(r))
    nodal = assemble_nodal(ev, 3 * n)
    assert abs(nodal[50, 1]) < 1e-12 * abs(nodal[2 * n - 1 - 50, 1])  # balanced from both sides
    assert np.all(np.bincount(pairs.i, minlength=3 * n)[n:2 * n] <= 1)


# ----------------------------------------------------------------- derivatives

@pytest.mark.parametrize("k2, k4", [(3.0, 1.0), (2.0, 0.5), (3.0, 0.0)])
def test_analytic_derivatives_match_central_differences(k2, k4):
    rng = np.random.default_rng(int(10 * k2 + 10 * k4))
    sp = spec(k2=k2, k4=k4, k3=2e-3)
    n = 8
    s = np.arange(n) * 0.1
    sc = make(sp, s, rho_a=np.linspace(0.4, 0.6, n), diameter=np.linspace(0.019, 0.021, n))
    pairs = ContactPairs(np.array([0, 1, 2, 3]), np.array([4, 5, 6, 7]), np.zeros(4))
    r = rng.normal(scale=0.1, size=(n, 3))
    dia = sc.diameter
    # gaps: regular, small, below the floor, penetrating
    for (a, b), gap in zip([(0, 4), (1, 5), (2, 6), (3, 7)],
                           [0.004, 0.0007, 0.3 * sc.gap_floor, -0.5 * sc.gap_floor]):
        dirn = rng.normal(size=3)
        dirn /= np.linalg.norm(dirn)
        r[a] = r[b] + (0.5 * (dia[a] + dia[b]) + gap) * dirn
    v = rng.normal(scale=0.05, size=(n, 3))
    ev = sc.evaluate(pairs, r, v)
    # ∂F/∂(v_i − v_j) does not depend on the repulsion; near the floor the repulsion is so
    # large (~1e7 N/m) that differences in v drown in its round-off, so the velocity
    # derivative is differenced on the same kernel with k1 = 0
    sc_damp = make(spec(k2=k2, k4=k4, k3=2e-3, k1=0.0), s, rho_a=sc.rho_a, diameter=dia)
    np.testing.assert_array_equal(sc_damp.evaluate(pairs, r, v).d_force_d_dv, ev.d_force_d_dv)

    def central(name, k, h):
        field = r if name == "dr" else v
        plus, minus = field.copy(), field.copy()
        plus[pairs.i, k] += h
        minus[pairs.i, k] -= h
        if name == "dr":
            return (sc.evaluate(pairs, plus, v).force - sc.evaluate(pairs, minus, v).force) / (2 * h)
        return (sc_damp.evaluate(pairs, r, plus).force
                - sc_damp.evaluate(pairs, r, minus).force) / (2 * h)

    for k in range(3):
        for name, h in (("dr", 1e-7), ("dv", 1e-4)):
            # Richardson-extrapolated central differences, error O(h^4)
            fd = (4 * central(name, k, h / 2) - central(name, k, h)) / 3
            ana = getattr(ev, "d_force_d_" + name)[:, :, k]
            for p in range(4):
                scale = np.linalg.norm(getattr(ev, "d_force_d_" + name)[p])
                assert np.linalg.norm(fd[p] - ana[p]) <= 1e-6 * scale, (name, k, p)


def test_repulsion_is_continued_linearly_below_the_floor():
    sc = make(spec(), np.arange(5) * 0.1)
    gf = sc.gap_floor
    assert gf == pytest.approx(1e-3 * DIAM)
    val, slope = sc.repulsion(np.array([gf, 0.5 * gf, 0.0, -gf]))
    f0 = 1e-7 / gf**3
    np.testing.assert_allclose(val, f0 * np.array([1.0, 2.5, 4.0, 7.0]), rtol=1e-12)
    np.testing.assert_allclose(slope, -3 * f0 / gf, rtol=1e-12)
    assert np.all(np.isfinite(val))


# ----------------------------------------------------------------- damping

def two_nodes(sp, gap, approach_speed=0.0):
    s = np.array([0.0, 1.0])
    sc = make(sp, s, rho_a=1.0)
    r = np.array([[0.0, 0, 0], [DIAM + gap, 0, 0]])
    t = np.array([[0.0, 0, 1], [0.0, 0, 1]])
    v = np.array([[approach_speed / 2, 0, 0], [-approach_speed / 2, 0, 0]])
    return sc, r, t, v


def test_damping_opposes_relative_normal_motion():
    sp = spec(k3=1e-3)
    sc, r, t, v = two_nodes(sp, 0.005)
    pairs = sc.find_pairs(r, t)
    assert pairs.count == 2  # each node owns the pair
    static = sc.evaluate(pairs, r, np.zeros_like(v)).force[:, 0]
    approach = sc.evaluate(pairs, r, v * 0 + [[0.05, 0, 0], [-0.05, 0, 0]]).force[:, 0]
    separate = sc.evaluate(pairs, r, v * 0 + [[-0.05, 0, 0], [0.05, 0, 0]]).force[:, 0]
    # node 0 is on the −x side: repulsion pushes it to −x
    assert static[0] < 0 and static[1] > 0
    assert abs(approach[0]) > abs(static[0]) > abs(separate[0])
    d = DIAM + 0.005
    expected_extra = sp.k3 / d * 0.1 * 0.1  # ḋ = −0.1, |ḋ|^k4 = 0.1
    assert abs(approach[0]) - abs(static[0]) == pytest.approx(expected_extra, rel=1e-12)
    # the printed law is odd in ḋ: separation reduces the repulsion by the same amount
    assert abs(static[0]) - abs(separate[0]) == pytest.approx(expected_extra, rel=1e-12)


def simulate_two_particles(k3, steps=1400, dt=1e-4):
    """Two point masses (nodes of a 2-node grid, Δs = ½ each, ρA = 1) colliding along x
    under the kernel, velocity Verlet (damping evaluated with the half-step velocity)."""
    sp = spec(k3=k3, k4=1.0)
    sc, r, t, _ = two_nodes(sp, 0.008)
    v = np.array([[0.05, 0, 0], [-0.05, 0, 0]])
    pairs = sc.find_pairs(r, t)
    mass = sc.rho_a * sc.weights

    def accel(r, v):
        ev = sc.evaluate(pairs, r, v)
        return assemble_nodal(ev, 2) * sc.weights[:, None] / mass[:, None], ev.min_gap

    def energy(r, v):
        gap = np.linalg.norm(r[1] - r[0]) - DIAM
        # force on node 0 is Δs_0 ρA k1/gap^k2 along n: potential ½ k1 gap^(1−k2)/(k2−1)
        pot = 0.5 * sp.k1 * gap ** (1 - sp.k2) / (sp.k2 - 1)
        return 0.5 * np.sum(mass[:, None] * v**2) + pot

    e0 = energy(r, v)
    a, _ = accel(r, v)
    min_gap = np.inf
    for _ in range(steps):
        v_half = v + 0.5 * dt * a
        r = r + dt * v_half
        a, g = accel(r, v_half)
        min_gap = min(min_gap, g)
        v = v_half + 0.5 * dt * a
    d = np.linalg.norm(r[1] - r[0])
    assert d < sp.tolerance  # still inside the tolerance: the potential above holds
    assert v[1, 0] - v[0, 0] > 0  # bounced: separating again
    return e0, energy(r, v), min_gap


def test_two_particle_collision_conserves_energy_without_damping_and_loses_it_with():
    e0, e1, min_gap = simulate_two_particles(k3=0.0)
    assert min_gap < 0.005  # a real collision, far above the floor
    assert abs(e1 - e0) < 1e-4 * e0
    e0d, e1d, _ = simulate_two_particles(k3=0.1)
    assert e0d == pytest.approx(e0)
    assert e1d < 0.95 * e0d


# ----------------------------------------------------------------- may_touch

def test_may_touch_straight_rod_false_closed_loop_true():
    n = 1001
    s = np.linspace(0.0, 1.0, n)
    sc = make(spec(), s)
    straight = np.c_[np.zeros(n), np.zeros(n), s]
    assert sc.may_touch(straight, tangents_of(straight)) is False
    phi = 2 * np.pi * s * (n - 1) / n
    loop = np.c_[np.cos(phi), np.sin(phi), np.zeros(n)] / (2 * np.pi)
    assert sc.may_touch(loop, tangents_of(loop)) is True
    assert sc.find_pairs(loop, tangents_of(loop)).count == 0  # a circle touches nowhere
    # 1.1 turns with the turns 2.5 cm apart: the overlap does touch
    turns, rise = 1.1, 0.025
    radius = np.sqrt((1.0 / turns) ** 2 - rise**2) / (2 * np.pi)
    phi = 2 * np.pi * turns * s
    coil = np.c_[radius * np.cos(phi), radius * np.sin(phi), rise * turns * s]
    assert sc.may_touch(coil, tangents_of(coil)) is True
    pairs = sc.find_pairs(coil, tangents_of(coil))
    assert pairs.count > 0
    # the turns face each other at the rise; pairs at the rod's ends are a bit oblique
    assert np.median(pairs.distance) == pytest.approx(rise, rel=2e-3)
    assert pairs.distance.min() == pytest.approx(rise, rel=2e-3)


def test_may_touch_false_is_rigorous():
    """Whenever may_touch says False, find_pairs (aperture 180°, the most permissive)
    finds nothing; the False branch is exercised by gently curved rods."""
    rng = np.random.default_rng(8)
    n = 400
    s = np.arange(n) * DS
    sc = make(spec(aperture=180.0), s)
    false_seen = 0
    for trial in range(30):
        amp = rng.uniform(0.0, 0.8)
        # planar/3-D wiggles of the tangent direction, unit speed
        th = amp * np.sin(2 * np.pi * s / 0.4 * rng.uniform(0.5, 3) + rng.uniform(0, 6))
        ph = rng.uniform(0, 2 * np.pi) + rng.uniform(-3, 3) * s
        tang = np.c_[np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)]
        r = np.vstack([np.zeros(3), np.cumsum(tang[:-1] * DS, axis=0)])
        may = sc.may_touch(r, tang)
        if not may:
            false_seen += 1
            assert sc.find_pairs(r, tang).count == 0
    assert false_seen >= 5
    # a 60° arc: chords within 30° of the mean tangent, c·exclusion = 0.0346 > 0.03
    phi = np.linspace(-np.pi / 6, np.pi / 6, n)
    rad = (s[-1] - s[0]) / (np.pi / 3)
    arc = np.c_[rad * np.sin(phi), rad * (1 - np.cos(phi)), np.zeros(n)]
    assert sc.may_touch(arc, tangents_of(arc)) is False
    small_excl = make(spec(aperture=180.0, exclusion=0.031), s)
    assert small_excl.may_touch(arc, tangents_of(arc)) is True


# ----------------------------------------------------------------- scale

def two_strand_ply(n_total, pitch=0.08, radius=0.0105):
    """Two strands wound round each other (a plectoneme without its end loop)."""
    m = n_total // 2
    phi = np.arange(m) * DS / np.hypot(radius, pitch / (2 * np.pi))
    z = pitch * phi / (2 * np.pi)
    a = np.c_[radius * np.cos(phi), radius * np.sin(phi), z]
    b = np.c_[-radius * np.cos(phi), -radius * np.sin(phi), z][::-1]
    r = np.vstack([a, b])
    t = np.vstack([tangents_of(a), tangents_of(b)])
    s = np.arange(2 * m) * DS
    return s, r, t, m


def test_find_pairs_on_2000_points_with_kdtree():
    s, r, t, m = two_strand_ply(2000)
    sc = make(spec(), s)
    t0 = time.perf_counter()
    pairs = sc.find_pairs(r, t)
    elapsed = time.perf_counter() - t0
    print(f"find_pairs on {s.size} points: {pairs.count} pairs in {elapsed * 1e3:.1f} ms")
    assert pairs.count > 1000
    # one partner per owner: the strands are 2.1 cm apart, the loops 8 cm: one strand each
    assert np.all(np.bincount(pairs.i) <= 1)
    ev = sc.evaluate(pairs, r, np.zeros_like(r))
    assert ev.min_gap == pytest.approx(2 * 0.0105 - DIAM, rel=1e-2)


# ----------------------------------------------------------------- errors

def test_invalid_construction_and_inputs():
    s = np.arange(10) * DS
    with pytest.raises(ValueError):
        make(spec(tolerance=0.02), s)  # tolerance must exceed the diameter
    with pytest.raises(ValueError):
        make(spec(aperture=0.0), s)
    with pytest.raises(ValueError):
        make(spec(k2=-1.0), s)
    with pytest.raises(ValueError):
        make(spec(exclusion=-0.01), s)
    assert make(spec(exclusion=0.0), s).exclusion == 0.0  # as the case spec allows
    with pytest.raises(ValueError):
        SelfContact(spec(), s, np.full(9, DIAM), np.full(10, 1.0))
    with pytest.raises(ValueError):
        SelfContact(spec(), s[::-1], np.full(10, DIAM), np.full(10, 1.0))
    sc = make(spec(), s)
    with pytest.raises(ValueError):
        sc.find_pairs(np.zeros((9, 3)), np.zeros((9, 3)))
    with pytest.raises(ValueError):
        sc.may_touch(np.zeros((10, 2)), np.zeros((10, 2)))
    ev = sc.evaluate(ContactPairs(np.zeros(0, int), np.zeros(0, int), np.zeros(0)),
                     np.zeros((10, 3)), np.zeros((10, 3)))
    assert ev.count == 0 and ev.min_gap == np.inf
    assert assemble_nodal(ev, 10).shape == (10, 3)
    with pytest.raises(ValueError):
        sc.evaluate(ContactPairs(np.array([0]), np.array([12]), np.zeros(1)),
                    np.zeros((10, 3)), np.zeros((10, 3)))
