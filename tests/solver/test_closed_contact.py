"""Self-contact and screened electrostatics on a closed rod (``rod.closed``): the pair
machinery periodic (solver/contact, ``SelfContact(..., closed=True)``; solver/
electrostatics.py, ``ScreenedElectrostatics(..., closed=True)``). Oracles: the loads do
not depend on which material point is node 0 (the ring's numbering turned by k nodes
gives the same loads turned by k, to rounding), also where the pairs sit on the join;
neighbours across the join and node N with node 0 never pair, where an open rod's
arclength rule would pair them; the step's Jacobian with the pairs and the join is the
residual's derivative; a ring twisted beyond Michell's bound collapses with its strands
held apart, Tw + Wr = Lk kept, where without contact they pass through each other."""
import math

import numpy as np
import pytest

from rodcases import step_jacobian_fd
from solver import statics
from solver.case import Case
from solver.centreline import CentrelineRod
from solver.contact import SelfContact, assemble_nodal, assemble_nodal_jacobian
from solver.electrostatics import ScreenedElectrostatics
from solver.simulation import integrate
from solver.static_band import KL, band_to_sparse

from test_closed_rod import E, ring

D = 0.02
CONTACT = {"aperture": 180.0, "tolerance": 0.04, "k1": 1e-7, "k2": 3.0, "k3": 1e-3,
           "k4": 1.0, "law": "barrier", "barrier_gap": 0.012, "barrier_stiffness": 1e4}


def figure_eight(n, gap=1.1, turn=0):
    """Nodes (n+1, 3) m at equal arclength (to a dense polygon's) on a closed
    figure-eight about 1 m long, its lobes crossing over each other at 53° at node 0 (the
    join) and node n/2, their centrelines ``gap`` × D apart there (z = ±gap D/2); node n
    is node 0 again. ``turn``: the numbering turned by that many nodes (node k of the
    result is node k + turn of the unturned ring), so the crossing moves off the join."""
    th = np.linspace(0.0, 2.0 * np.pi, 40001)
    c = np.stack([0.2 * np.sin(th), 0.05 * np.sin(2.0 * th), 0.5 * gap * D * np.cos(th)], 1)
    sa = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
    su = np.linspace(0.0, sa[-1], n + 1)[:-1]
    r = np.roll(np.stack([np.interp(su, sa, c[:, i]) for i in range(3)], 1), -turn, axis=0)
    return np.concatenate([r, r[:1]])


def ring_contact(n, spec=CONTACT):
    s = np.linspace(0.0, 1.0, n + 1)
    return SelfContact(spec, s, np.full(n + 1, D), np.full(n + 1, 0.5), closed=True)


def contact_loads(contact, r, v=None):
    """(loads (N+1, 3) N/m, the evaluation, ∂L/∂r) of the contact at positions r."""
    tangents = np.roll(r[:-1], -1, axis=0) - np.roll(r[:-1], 1, axis=0)
    tangents = np.concatenate([tangents, tangents[:1]])
    cand = contact.search(r, tangents)
    ev = contact.evaluate(cand, r, np.zeros_like(r) if v is None else v)
    n1 = r.shape[0]
    return assemble_nodal(ev, n1), ev, assemble_nodal_jacobian(ev, n1)


@pytest.mark.parametrize("n", [60, 200])
def test_contact_loads_do_not_depend_on_which_point_is_node_0(n):
    """The figure-eight's crossing at the join (node 0) and, numbered again, 7 and 20
    nodes away from it: the same pairs, the loads the same loads renumbered (1e-12 of the
    largest), node N's those of node 0, the momentum balanced over the ring's nodes; a
    run on each crossing runs across the join (segments N − 1 then 0). On 60 segments
    the search tests all node pairs at once, on 200 the blocked k-d tree's."""
    contact = ring_contact(n)
    L, ev, _ = contact_loads(contact, figure_eight(n))
    assert ev.count >= 4 and ev.min_gap < CONTACT["barrier_gap"]
    # the partners of the owners at the crossing n/2 lie on the curve across the join
    assert {0, n - 1} & set(ev.j[np.abs(ev.i - n // 2) <= 1].tolist())
    assert np.all(ev.i < n)                               # node N owns nothing
    r = figure_eight(n)
    tangents = np.gradient(r, axis=0)
    cand, wider = contact.candidates(r, tangents), contact.candidates(r, tangents, 0.02)
    merged = contact.merge(cand, wider)
    assert contact.covers(merged, cand) and contact.covers(merged, wider)
    assert merged.runs == wider.runs and not contact.covers(cand, wider)
    assert np.array_equal(L[0], L[-1]) and np.abs(L).max() > 1.0
    w = contact.weights[:-1, None]
    assert np.abs((w * L[:-1]).sum(0)).max() < 1e-12 * np.abs(w * L[:-1]).sum()
    for turn in (7, 20):
        Lt, evt, _ = contact_loads(contact, figure_eight(n, turn=turn))
        assert evt.count == ev.count
        assert np.abs(Lt[:-1] - np.roll(L[:-1], -turn, axis=0)).max() < 1e-12 * np.abs(L).max()
        assert np.array_equal(Lt[0], Lt[-1])


def test_no_pair_across_the_join_or_between_node_0_and_node_n():
    """A circle of circumference 1 m whose chords h = 25 mm are within the tolerance
    (40 mm) of its neighbours: the exclusion (2D = 40 mm) keeps every neighbour out, also
    node N − 1 with node 0 and node N (node 0 again, at distance 0) with node 0. An open
    rod's rule on the same nodes (|s_i − s_j| > exclusion) pairs them, so this can fail."""
    n = 40
    th = 2.0 * np.pi * np.arange(n + 1) / n
    r = np.stack([np.cos(th), np.sin(th), 0.0 * th], 1) / (2.0 * np.pi)
    r[-1] = r[0]
    tangents = np.stack([-np.sin(th), np.cos(th), 0.0 * th], 1)
    assert ring_contact(n).search(r, tangents) is None
    cand = ring_contact(n).candidates(r, tangents)
    assert cand.runs == 0
    s = np.linspace(0.0, 1.0, n + 1)
    open_rod = SelfContact(CONTACT, s, np.full(n + 1, D), np.full(n + 1, 0.5))
    found = open_rod.candidates(r, tangents)
    assert found.runs and {0, n}.issubset(set(found.owner.tolist()))
    # electrostatics (segments 25 mm, exclusion 30 mm): the kept segment pairs are those
    # of an endless ring, the same turned by one segment; none 0 with N − 1 or N − 2
    es = dict(charge_per_length=1e-9, debye_length=0.01, cutoff=6.0, exclusion=0.03)
    pairs = ScreenedElectrostatics(s, closed=True, **es).pairs(r)
    assert pairs.shape[0] > 0 and pairs.shape[0] % n == 0
    kept = {tuple(p) for p in pairs.tolist()}
    assert kept == {tuple(sorted(((k + 1) % n, (m + 1) % n))) for k, m in kept}
    assert np.all(np.minimum(pairs[:, 1] - pairs[:, 0], n - (pairs[:, 1] - pairs[:, 0])) >= 3)
    assert [0, n - 2] in ScreenedElectrostatics(s, **es).pairs(r).tolist()


@pytest.mark.parametrize("n", [60, 200])
def test_the_swept_test_sees_strands_pass_through_each_other_on_the_join(n):
    """SelfContact.passes_through on the figure-eight whose crossing is the join: the
    lobes swapping over and under there (z → −z) is a pass-through; moving apart, or the
    whole ring moving 10 mm, is not (node N, at node 0's place, is no partner of it:
    an open rod's rule would see the two pass through each other at every step)."""
    contact = ring_contact(n)
    r = figure_eight(n)
    assert contact.passes_through(r, figure_eight(n, gap=-1.1))
    assert not contact.passes_through(r, figure_eight(n, gap=3.0))
    assert not contact.passes_through(r, r + [0.01, 0.0, 0.0])
    s = np.linspace(0.0, 1.0, n + 1)
    open_rod = SelfContact(CONTACT, s, np.full(n + 1, D), np.full(n + 1, 0.5))
    assert open_rod.passes_through(r, r + [0.01, 0.0, 0.0])


def test_the_step_jacobian_with_contact_on_a_closed_rod_is_exact():
    """A closed case with contact moved onto the figure-eight, its strands approaching
    at the crossing on the join: the step's Jacobian (band, the join's coupling and the
    pairs' blocks, the damper's ∂F/∂ṙ chained by c_X) against central differences of the
    residual, 1e-7 of the largest entry."""
    n = 31                      # odd: the closest points fall inside segments
    spec = ring(link=1, n=n, fluid=False)
    spec["contact"] = dict(CONTACT, barrier_stiffness=1e2)
    rod = CentrelineRod.from_case(Case.model_validate(spec))
    Y = rod.start().Y.copy()
    Y[:, 0:3] = figure_eight(n, gap=1.15)
    Y[:-1, 0:3] += 1e-4 * np.random.default_rng(2).standard_normal((n, 3))
    Y[-1, 0:3] = Y[0, 0:3]
    state = rod.rest_state(Y=Y)
    state.X[:, 2] = -0.05 * np.sign(Y[:, 2])          # the strands approach at the crossings
    h = 0.01
    co, prob = rod.coefficients(state, h), rod.problem(h)
    Y = rod.predict(state, h)
    _, ev, dL = rod.contact_terms(Y, state, co, want=True)
    assert ev.count >= 2 and {0, n - 1} & set(ev.j.tolist())
    assert np.all((ev.t > 0.05) & (ev.t < 0.95))
    J = (band_to_sparse(rod.jacobian(Y, state, co, prob)[KL:]) + statics.join_coupling(Y, prob)
         + statics._load_rows(prob) @ dL @ statics._position_columns(prob)).toarray()
    Jfd = step_jacobian_fd(rod, Y, state, co, prob)
    assert np.abs(J - Jfd).max() < 1e-7 * np.abs(J).max()


@pytest.mark.parametrize("n", [40, 200])
def test_electrostatic_loads_on_a_ring_do_not_depend_on_which_point_is_node_0(n):
    """Debye–Hückel between the figure-eight's lobes (exclusion 0.1 m): the same segment
    pairs and energy, the loads renumbered with the ring (1e-12 of the largest), node N's
    node 0's, the momentum balanced (on 200 segments through the blocked k-d tree); on
    40, the Jacobian (node N's rows folded into node 0's) the loads' derivative by
    central differences."""
    s = np.linspace(0.0, 1.0, n + 1)
    es = ScreenedElectrostatics(s, 1e-9, 0.01, cutoff=6.0, exclusion=0.1, closed=True)
    base = es.evaluate(figure_eight(n, gap=2.0))
    assert base.pairs.shape[0] > 0 and base.energy > 0.0
    assert np.array_equal(base.loads[0], base.loads[-1])
    w = es.weights[:-1, None]
    assert np.abs((w * base.loads[:-1]).sum(0)).max() < 1e-12 * np.abs(w * base.loads[:-1]).sum()
    for turn in (5, 13):
        ev = es.evaluate(figure_eight(n, gap=2.0, turn=turn))
        moved = {tuple(sorted(((k - turn) % n, (m - turn) % n))) for k, m in base.pairs}
        assert {tuple(p) for p in ev.pairs.tolist()} == moved
        assert ev.energy == pytest.approx(base.energy, rel=1e-12)
        assert np.abs(ev.loads[:-1] - np.roll(base.loads[:-1], -turn, axis=0)).max() < (
            1e-12 * np.abs(base.loads).max())
    if n > 40:
        return
    r = figure_eight(n, gap=2.0, turn=3)
    J = es.evaluate(r).jacobian.toarray()
    fd = np.empty_like(J)
    eps = 1e-7
    for j in range(r.size):
        d = np.zeros(r.size)
        d[j] = eps
        fd[:, j] = (es.evaluate(r + d.reshape(r.shape), False).loads
                    - es.evaluate(r - d.reshape(r.shape), False).loads).ravel() / (2 * eps)
    assert np.abs(J - fd).max() < 1e-6 * np.abs(J).max()


MICHELL_CONTACT = {"aperture": 150.0, "tolerance": 0.03, "k1": 1e-7, "k2": 3.0, "k3": 1e-3,
                   "k4": 1.0, "law": "barrier", "barrier_gap": 0.005,
                   "barrier_stiffness": 1e5}


def michell_collapse(contact, nudge_at=0.25):
    """An Lk = 2 ring (40 segments) twisted to 1.05 × Michell's √3 EJ/GJ in water with
    5× Morison's normal drag (so that the collapse settles instead of whipping), nudged
    by 1 mN at s = ``nudge_at`` for 0.2 s, run to 2.4 s at Δt 0.05 s; with
    ``contact``, MICHELL_CONTACT's barrier law."""
    spec = ring(link=2, n=40, t_end=2.4, dt=0.05, shear=1.05 * math.sqrt(3) * E / 4,
                point_loads=[{"s": nudge_at, "value": [0.0, 1e-3, 0.0], "start": 0.0,
                              "end": 0.2}])
    spec["numerics"]["rho_inf"] = 0.8
    spec["fluid"]["drag_coefficient_normal"] = 5.0
    spec["output"] = {"fields": ["position", "topology"] + (["contact"] if contact else [])}
    if contact:
        spec["contact"] = MICHELL_CONTACT
    ds = integrate(Case.model_validate(spec))
    assert ds.attrs["hockle_status"] == "completed"
    return ds


def test_a_supercritical_ring_collapses_with_its_strands_held_apart():
    """Without contact the ring's strands pass through each other at 1.2 s and
    Tw + Wr − Lk jumps by 2 (measured 2.003; the ring returns to a circle, Wr 0). With
    contact it settles into a figure-eight, Wr 1.07, the strands 2 mm apart at the
    crossing (1.25 mm at the least), |Tw + Wr − Lk| ≤ 0.0068 throughout (its largest
    during the collapse, as without contact before the strands cross; 0.004 settled). Nudged 5 nodes earlier the crossing
    sits on the join (nodes 0 and 20) and the run is the same run numbered again up to
    the first contact (1.2 s): node distances within 1.9e-11 m (measured). In the
    collapse's next steps the two cut different steps (one the step to 1.25 s, the
    other the step to 1.3 s; the damped Newton's choices are decided by norms that
    differ by rounding) and part by 20 mm at 1.25 s, 58 mm at the most, the writhe by
    up to 0.035;
    both settle into the figure-eight (Wr 1.071 and 1.065 at 2.4 s), Tw + Wr − Lk the
    same to 1e-12."""
    free = michell_collapse(contact=False)
    assert free.topology_error.max() > 1.9
    held = michell_collapse(contact=True)
    assert float(held.topology_error.max()) < 0.01
    assert float(held.writhe[-1]) > 0.9 and int(held.contact_count[-1]) >= 2
    gap = held.min_surface_gap.values
    assert np.isfinite(gap).sum() > 10 and 0.0 < np.nanmin(gap[np.isfinite(gap)]) < 0.005
    joined = michell_collapse(contact=True, nudge_at=0.125)
    r = joined.position.values[-1]
    _, ev, _ = contact_loads(SelfContact(MICHELL_CONTACT, np.linspace(0.0, 1.0, 41),
                                         np.full(41, D), np.full(41, 0.5), closed=True), r)
    assert 0 in ev.i.tolist() and {0, 39} & set(ev.j.tolist())
    a, b = held.position.values[:, :-1], np.roll(joined.position.values[:, :-1], 5, axis=1)
    dist = [np.linalg.norm(x[:, :, None] - x[:, None, :], axis=-1) for x in (a, b)]
    first = held.time.values <= 1.2 + 1e-9
    assert held.contact_count.values[first].max() > 0
    assert np.abs(dist[0] - dist[1])[first].max() < 1e-8
    assert np.abs(held.writhe.values - joined.writhe.values)[first].max() < 1e-8
    assert np.abs(held.writhe.values - joined.writhe.values).max() < 0.05
    assert abs(float(held.topology_error.max()) - float(joined.topology_error.max())) < 1e-9


def test_a_charged_ring_stays_round():
    """An Lk = 1 ring carrying 1e-4 C/m in water (λ = 10 mm, exclusion 30 mm: every
    segment repels those 3 to 5 segments on, 40 pairs, the same all round) stays its
    circle to rounding (radius spread 7e-15 m measured) for 0.3 s: nothing singles out the
    join. Measured on the open rod's rule (segments N − 1 and 0 kept, node N's loads
    apart from node 0's): a spread of 3.7e-7 m at 1e-5 C/m."""
    spec = ring(link=1, n=40, t_end=0.3, dt=0.01,
                electrostatics={"charge_per_length": 1e-4, "debye_length": 0.01,
                                "exclusion": 0.03})
    case = Case.model_validate(spec)
    rod = CentrelineRod.from_case(case)
    es = rod.problem(0.0).electrostatics
    assert es.closed and es.pairs(rod.start().Y[:, 0:3]).shape[0] == 40
    ds = integrate(case)
    assert ds.attrs["hockle_status"] == "completed"
    r = ds.position.values
    radius = np.linalg.norm(r[:, :-1] - r[:, :-1].mean(axis=1, keepdims=True), axis=2)
    assert (radius.max(axis=1) - radius.min(axis=1)).max() < 1e-12
    assert np.abs(r[:, -1] - r[:, 0]).max() < 1e-14


def test_the_dna_minicircle_supercoils_with_its_strands_held_apart():
    """cases/dna-minicircle.yaml: 100 nm of DNA with ΔLk = 2 (Michell's bound 0.87)
    nudged out of its plane writhes into an interwound figure-eight within 1 µs and stays
    there: measured Wr 1.607 and Tw 0.392 at 2 µs, |Tw + Wr − Lk| at most 0.018 (during
    the collapse; 0.0018 after), 10 contact pairs, the smallest surface gap 0.31 nm."""
    from pathlib import Path

    case = Case.from_file(Path(__file__).resolve().parents[2] / "cases" / "dna-minicircle.yaml")
    ds = integrate(case)
    assert ds.attrs["hockle_status"] == "completed"
    assert 1.5 < float(ds.writhe[-1]) < 1.7
    assert float(ds.topology_error.max()) < 0.03 and float(ds.topology_error[-1]) < 0.003
    assert int(ds.contact_count[-1]) >= 5
    assert 0.0 < float(ds.min_surface_gap[-1]) < 5e-10
    assert np.all(ds.linking_number.values == 2.0)
