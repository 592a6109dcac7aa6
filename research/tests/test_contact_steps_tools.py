"""The Newton-start report of research/contact_steps.py (``--starts``) and the feasible
start's blend factor it reads (:meth:`solver.newton.NewtonSolver.feasible_start`): distances
with a known answer, and the blend on a contact step of a hairpin whose strands face
each other."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from research.contact_steps import (correction_cuts, residual_groups, start_distances,
                           start_summary)
from rodcases import hairpin


def test_a_start_is_measured_against_the_step_it_had_to_cover():
    """Y_old = 0, the solution 1 in every unknown: the solution itself is 0 away, the old
    level 1, a start halfway 0.5; a group the step left unchanged reads NaN."""
    y_old = np.zeros((5, 12))
    y = np.ones((5, 12))
    y[:, 6:9] = 0.0                               # f unchanged by the step
    d = start_distances(y_old, y, {"exact": y, "old": y_old, "half": 0.5 * y})
    assert d["exact"]["v"] == 0.0 and d["exact"]["κ"] == 0.0
    assert d["old"]["ω"] == pytest.approx(1.0)
    assert d["half"]["v"] == pytest.approx(0.5) and d["half"]["κ"] == pytest.approx(0.5)
    assert math.isnan(d["half"]["f"])


def test_the_start_report_counts_the_blended_starts_and_the_iterations():
    solves = [dict(start_distances(np.zeros((3, 12)), np.ones((3, 12)),
                                   {"start": np.full((3, 12), a)}), blend=b)
              for a, b in ((0.5, 1.0), (0.25, 0.25), (0.0, 0.5))]
    lines = start_summary(solves, [2, 2, 3])
    assert "v  0.75" in lines[0]                  # median of 0.5, 0.75, 1
    assert "2 of 3 contact solves (median factor 0.375)" in lines[1]
    assert lines[2].endswith("2: 2, 3: 1")
    assert len(lines) == 3                        # no correction counts given: no line


def test_the_corrections_are_counted_by_what_cut_them():
    """NewtonSolver.last_trace rows (residual, filter's fraction, line search's fraction,
    GMRES): a whole correction, one the filter halved (the line search too: the filter's
    count), one only the line search halved, a whole one, and the final iterate's row,
    which made no correction and is not counted."""
    trace = np.array([[1.0, 1.0, 1.0, 5], [0.5, 0.5, 0.5, 6], [0.3, 1.0, 0.25, 6],
                      [0.1, 1.0, 1.0, 4], [1e-9, 1.0, 1.0, 0]])
    assert correction_cuts(trace).tolist() == [2, 1, 1]
    lines = start_summary([], [3], [correction_cuts(trace), np.array([3, 0, 0])])
    assert lines[-1].endswith("5 of 7 taken whole, 1 cut by the feasibility filter, 1 by "
                              "the line search alone")


def test_the_residual_is_located_by_row_group_and_cell():
    """3 cells (6 + 36 + 6 rows): an axial momentum entry of cell 2, a lateral one of
    cell 0, an E4 one of cell 1 and an s = L boundary row; each group reports its largest
    entry and that entry's cell."""
    r = np.zeros(48)
    r[6 + 12 * 2 + 8] = -0.07                     # E3 axial, cell 2 (sign ignored)
    r[6 + 12 * 0 + 7] = 0.05                      # E3 lateral (component 2), cell 0
    r[6 + 12 * 0 + 6] = 0.01
    r[6 + 12 * 1 + 10] = 1e-3                     # E4, cell 1
    r[-2] = 2e-3                                  # a boundary row at s = L
    g = residual_groups(r)
    assert g["E3 axial"] == (0.07, 2) and g["E3 lateral"] == (0.05, 0)
    assert g["E4"] == (1e-3, 1) and g["E1"] == (0.0, 0) and g["ends"] == (2e-3, -2)


@pytest.fixture(scope="module")
def contact_step():
    """A hairpin at rest, its strands ~2 cm apart (surface to surface), with self-contact:
    a step of 0.01 s set up as the run sets it up, with the candidates its search finds
    (their gaps finite)."""
    from solver.case import Case
    from solver.compiled import _warm_up_spec
    from solver.run import RodRun

    spec = _warm_up_spec()
    spec["numerics"]["n_segments"] = 100
    # the half circle is 6 cells of the 100-segment grid, nodes 47 to 53
    spec["initial"] = {"centreline": {"points": hairpin(0.06 / math.pi).tolist()}}
    spec["boundary"]["start"]["rotation"][2] = {"angular_velocity": 0.0}
    run = RodRun(Case.model_validate(spec))
    prob = run.assembly.step_problem(run.state, 0.01)
    assert prob.candidates is not None and prob.candidates.runs > 0
    run.system.begin_step(prob.h, prob.params, prob.t_new, run.state.Y, run.state.Ydot, run.state.F_old,
                          prob.bc, q_old=run.state.q, r_old=run.state.r, v_old_global=run.state.v_global,
                          candidates=prob.candidates)
    gaps = run.system.candidate_gaps(run.state.Y)
    assert np.isfinite(gaps).sum() > 50 and np.all(gaps[np.isfinite(gaps)] > 0.01)
    return run


def test_a_start_that_keeps_every_gap_is_the_guess(contact_step, monkeypatch):
    """START_GAP_KEEP = 0 asks only that no gap be closed: the old level's guess passes
    whole (blend 1, the guess to rounding)."""
    newton = contact_step.newton
    monkeypatch.setattr(type(newton), "START_GAP_KEEP", 0.0)
    guess = contact_step.state.Y.copy()
    out = newton.feasible_start(guess)
    assert newton.last_start_blend == 1.0
    np.testing.assert_allclose(out, guess, rtol=0, atol=1e-12 * np.abs(guess).max())


def test_a_start_no_blend_can_make_feasible_is_the_zero_displacement_state(contact_step,
                                                                           monkeypatch):
    """START_GAP_KEEP = 2 asks every gap to double, which no blend does: the start is the
    zero-displacement state, (v, ω) = −(vⁿ, ωⁿ) with f and κ of the old level (blend 0)."""
    newton = contact_step.newton
    monkeypatch.setattr(type(newton), "START_GAP_KEEP", 2.0)
    y_old = contact_step.state.Y
    out = newton.feasible_start(y_old + 0.01)
    assert newton.last_start_blend == 0.0
    np.testing.assert_array_equal(out[:, :6], -y_old[:, :6])
    np.testing.assert_array_equal(out[:, 6:], y_old[:, 6:])


def test_a_start_that_closes_a_gap_is_blended_back_until_it_keeps_half(contact_step):
    """The guess bends the hairpin's half circle 20 % tighter, so its far strand swings
    onto the near one: the start is blended toward the zero-displacement state by the
    largest 2^−k that keeps every gap at least START_GAP_KEEP (½) of its old value."""
    newton, system = contact_step.newton, contact_step.system
    y_old = contact_step.state.Y
    guess = y_old.copy()
    guess[:, 9:11] *= 1.2                         # bending curvatures κ1, κ2
    g_old = system.candidate_gaps(y_old)
    ok = np.isfinite(g_old)
    assert np.any(system.candidate_gaps(guess)[ok] < 0.5 * g_old[ok])
    out = newton.feasible_start(guess)
    beta = newton.last_start_blend
    assert 0.0 < beta < 1.0 and math.log2(beta) == round(math.log2(beta))
    assert np.all(system.candidate_gaps(out)[ok] >= 0.5 * g_old[ok])
    still = np.concatenate([-y_old[:, :6], y_old[:, 6:]], axis=1)
    np.testing.assert_allclose(out, still + beta * (guess - still), rtol=0, atol=1e-12)
    twice = still + min(1.0, 2.0 * beta) * (guess - still)
    assert np.any(system.candidate_gaps(twice)[ok] < 0.5 * g_old[ok])


def test_the_probe_reports_a_resting_cables_seabed_cells():
    """``--seabed-cells``: a 1-m cable (D = 2 cm, 1500 kg/m³ in water) settled on a flat
    bottom for 0.5 s: at each iterate of the next step the listed cells' penetration,
    normal force and E3 residual; at the last iterate each interior cell carries the
    cable's submerged weight w = 1.54 N/m (within 5 %) at the penetration w/k of the
    default stiffness k = 3·10⁶ Pa, and its E3 rows balance to 10⁻⁶ w."""
    import pickle

    from research.contact_steps import _iterates_residuals
    from solver.case import Case
    from solver.run import RodRun

    d, free = 0.02, {"translation": [{"force": 0}] * 3, "rotation": [{"moment": 0}] * 3}
    spec = {"schema_version": 1, "name": "resting",
            "rod": {"length": 1.0, "youngs_modulus": 1.25e7, "shear_modulus": 5e6,
                    "density": 1500.0, "diameter": d},
            "fluid": {"density": 1000.0}, "gravity": [0, 0, -9.81],
            "initial": {"tangent": [1, 0, 0], "normal": [0, 0, 1]},
            "seabed": {"elevation": -d / 2}, "boundary": {"start": free, "end": free},
            "numerics": {"n_segments": 20, "dt": 0.01, "t_end": 1.0}}
    run = RodRun(Case.model_validate(spec))
    for k in range(1, 51):
        run.advance(0.01 * k)
    rows = _iterates_residuals(pickle.dumps(run), 0.01, 3, range(8, 12))
    assert len(rows) == 4 and all(len(r["seabed"]) == 4 for r in rows)
    w = 500.0 * math.pi * d**2 / 4 * 9.81
    for cell, p, force, e3 in rows[-1]["seabed"]:
        assert 8 <= cell < 12
        assert force == pytest.approx(w, rel=0.05)
        assert p == pytest.approx(w / 3e6, rel=0.05)
        assert e3 < 1e-6 * w


def test_a_cell_held_free_across_the_bottom_does_not_stall_the_step(capsys):
    """seabed-hockle's twisted lay on the bare bottom (no friction, no self-contact): a
    step of 12.5 ms from 2.2 s. Before a cell held on the damper's free branch was
    released to the law's clamp when an iterate lifts it clear (solver.seabed), the cell
    where the cable lifted off arrived at the bottom at about 1 cm/s, its held force
    jumped at p = 0 by c·|n·ṙ| (27 N/m), and Newton cycled across the jump until this
    step was refused after 25 iterations (docs/seabed.md, "What a refused step looks
    like"). Now it is accepted (measured: 9 iterations)."""
    from research.contact_steps import probe

    probe(str(Path(__file__).resolve().parents[2] / "cases" / "seabed-hockle.yaml"), 2.2,
          [0.0125], sets=["contact=null", "seabed.friction=null"])
    line = capsys.readouterr().out.splitlines()[-1]
    assert "accepted" in line, line


def _bow(amplitude):
    """A steel rod (1 m, D = 1 cm, 20 segments, in vacuum, no gravity) at rest, bowed
    in its plane as a half sine of the given amplitude (m); both ends held in
    translation, the start held in rotation too and the end free to turn."""
    s = np.linspace(0.0, 1.0, 201)
    x, y = s, amplitude * np.sin(math.pi * s)
    arc = np.hypot(np.diff(x), np.diff(y)).sum()
    held = {"translation": [{"velocity": 0}] * 3, "rotation": [{"angular_velocity": 0}] * 3}
    pinned = {"translation": [{"velocity": 0}] * 3, "rotation": [{"moment": 0}] * 3}
    return {"schema_version": 1, "name": "bow",
            "rod": {"length": 1.0, "youngs_modulus": 2e11, "shear_modulus": 8e10,
                    "density": 7800.0, "diameter": 0.01},
            "initial": {"normal": [0, 0, 1],
                        "centreline": {"points": np.c_[x / arc, y / arc, 0 * x].tolist()}},
            "boundary": {"start": held, "end": pinned},
            "numerics": {"n_segments": 20, "dt": 0.01, "t_end": 1.0}}


def test_the_modes_show_that_an_inextensible_rod_shortens_through_its_curvature():
    """``--modes`` (:func:`contact_steps.jacobian_modes`) on a bowed rod whose ends are
    held in place: the rod is inextensible, so its tension is set only through the
    curvature (a tension T bows it sideways by a load T κ, and the sideways motion
    shortens it by ∫ κ w ds): the smallest singular value of a step's Jacobian belongs to
    the axial force, lies far below the next, and scales with the bow's square (κ ∝
    amplitude; measured 3.6e-8 at a tenth of the larger bow; a straight rod held so is
    refused as ill-posed, its tension undetermined). This is the mode that dominates the
    first correction of seabed-hockle's untwisted lay (docs/seabed.md)."""
    import pickle

    from research.contact_steps import jacobian_modes
    from solver.case import Case
    from solver.run import RodRun

    sigma = []
    for amplitude in (0.01, 0.005):
        run = RodRun(Case.model_validate(_bow(amplitude)))
        m = jacobian_modes(pickle.dumps(run), 0.01, 2)
        vec = m["modes"][0]["vector"]
        assert max(vec, key=lambda c: vec[c][0]) == "f3", vec
        # measured: 3.6e-6 and 9.0e-7 against 4.0e-3 for the next (scaled)
        assert m["sigma"][0] < 1e-2 * m["sigma"][1]
        sigma.append(m["sigma"][0])
    assert sigma[0] / sigma[1] == pytest.approx(4.0, rel=0.02)


def test_the_alternation_reads_a_stiff_modes_flip_and_not_a_smooth_motion():
    """``--watch`` (:func:`contact_steps.alternation`): a straight line 0; a sine sampled
    every φ = 2π/50 over two whole periods 2 sin(φ/2); a stiff mode damped by
    generalized-α's ρ∞ per step, c + a(−ρ∞)^n, exactly 1 + ρ∞ (1.5 at seabed-hockle's
    ρ∞ = 0.5, whose untwisted lay's spin flips so, docs/seabed.md); a constant series or
    fewer than three values NaN."""
    from research.contact_steps import alternation

    n = np.arange(40)
    assert alternation(3.0 + 0.2 * n) == pytest.approx(0.0, abs=1e-12)
    phi = 2 * math.pi / 50
    assert alternation(np.sin(phi * np.arange(102))) == pytest.approx(2 * math.sin(phi / 2),
                                                                      rel=1e-9)
    for rho in (0.5, 0.8, 1.0):
        assert alternation(2.0 + 7.0 * (-rho) ** n[:25]) == pytest.approx(1 + rho, rel=1e-9)
    # the smooth part does not hide the flip where the flip dominates the changes
    mixed = 0.01 * n + 0.5 * (-0.5) ** (n % 2)
    assert alternation(mixed) > 1.9
    assert math.isnan(alternation(np.ones(10)))
    assert math.isnan(alternation([1.0, 2.0]))


def test_contact_rho_inf_sets_the_scheme_only_in_steps_where_strands_may_meet():
    """``numerics.contact_rho_inf``: a step whose search finds contact candidates (the
    hairpin's facing strands) takes the generalized-α weights of that ρ∞; a step without
    (the same rod straight) and a run without the field take ``numerics.rho_inf``'s."""
    from solver.case import Case
    from solver.compiled import _warm_up_spec
    from solver.run import RodRun
    from solver.scheme import alpha_parameters

    def first_step(points, contact_rho_inf):
        spec = _warm_up_spec()
        spec["numerics"]["n_segments"] = 100
        spec["numerics"]["contact_rho_inf"] = contact_rho_inf
        spec["contact"]["aperture"] = 90.0   # the seed's: a straight rod has no candidates
        spec["initial"] = {"centreline": {"points": points.tolist()}}
        spec["boundary"]["start"]["rotation"][2] = {"angular_velocity": 0.0}
        run = RodRun(Case.model_validate(spec))
        return run, run.assembly.step_problem(run.state, 0.01)

    bent = hairpin(0.06 / math.pi)
    run, prob = first_step(bent, 0.0)
    assert prob.candidates is not None
    assert prob.params == alpha_parameters(0.0) != run.assembly.params == alpha_parameters(0.5)
    run, prob = first_step(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), 0.0)
    assert prob.candidates is None and prob.params == alpha_parameters(0.5)
    run, prob = first_step(bent, None)
    assert prob.candidates is not None and prob.params == alpha_parameters(0.5)


def test_the_writhe_readings_name_the_first_loop_the_largest_writhe_and_the_tightest_bend():
    """``--writhe`` (:func:`contact_steps.writhe_readings`) on a dataset with a known
    answer: |Wr| reaches 1 first at 0.3 s, is largest (2.0) at 0.5 s, Wr at the output
    nearest 0.42 s is the 0.4-s value, the tightest radius 0.01 m at 0.2 s; without the
    topology output it says so."""
    import xarray as xr
    from research.contact_steps import writhe_readings

    t = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
    ds = xr.Dataset({"writhe": ("time", [0.0, 0.5, -0.9, -1.2, 1.5, -2.0]),
                     "bend_radius_min": ("time", [1.0, 0.5, 0.01, 0.2, 0.3, 0.4])},
                    coords={"time": t})
    line = writhe_readings(ds, [0.42])
    assert "through 1 at 0.30 s" in line and "largest |Wr| 2.000 at 0.5 s" in line
    assert "Wr(0.4 s) 1.5000" in line and "tightest bend radius 0.0100 m at 0.2 s" in line
    assert "does not output" in writhe_readings(xr.Dataset(coords={"time": t}), [0.1])


def _arc_in_rigid_motion(n, V, Omega, kappa=(0.0, 2.0, 0.0), length=1.0):
    """A rod bent to a uniform curvature κ (rad/m, body frame) on n cells, moving as a
    rigid body with velocity V at node 0 and angular velocity Omega (global): the run
    attributes :func:`contact_steps.semi_discrete_route_rate` reads."""
    from types import SimpleNamespace

    from solver.kinematics import quat_to_matrix, space_route

    s = np.linspace(0.0, length, n + 1)
    k = np.tile(np.asarray(kappa, float), (n + 1, 1))
    q0, r0 = np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3)
    q, r = space_route(q0, r0, k, length / n)
    R = quat_to_matrix(q)
    vel = np.asarray(V, float) + np.cross(np.asarray(Omega, float), r - r0)
    Y = np.zeros((n + 1, 12))
    Y[:, 0:3] = np.einsum("nji,nj->ni", R, vel)                  # Rᵀ(V + Ω×(r − r0))
    Y[:, 3:6] = np.einsum("nji,j->ni", R, np.asarray(Omega, float))
    Y[:, 9:12] = k
    return SimpleNamespace(state=SimpleNamespace(Y=Y, q_time=q0[None], r_time=r0[None]),
                           props=SimpleNamespace(s=s))


def test_the_box_rules_route_rate_vanishes_for_a_translation_and_is_second_order_in_s():
    """A rigid motion keeps the centreline on the nodes' velocities in the continuous
    model. Translated, the discrete arc does too (to rounding). Turning, the box rule's
    κ̄ rate from E1 is the exact one to O(Δs²) only: the rate falls four-fold per
    halving of Δs."""
    from research.contact_steps import semi_discrete_route_rate

    moved = semi_discrete_route_rate(_arc_in_rigid_motion(20, (0.3, -0.1, 0.2), (0, 0, 0)))
    assert np.abs(moved).max() < 1e-8
    rates = [np.linalg.norm(semi_discrete_route_rate(
        _arc_in_rigid_motion(n, (0.0, 0.0, 0.0), (0.5, 1.0, 0.2))), axis=1).max()
        for n in (10, 20, 40)]
    assert rates[0] > 1e-4                       # m/s: the turning arc's rate is no rounding
    for coarse, fine in zip(rates, rates[1:]):
        assert 3.6 < coarse / fine < 4.4


@pytest.mark.parametrize("rho_inf", [0.5, 0.0])
def test_a_short_step_after_long_ones_reads_the_carried_generalized_alpha_rates(rho_inf):
    """The warm-up case (solver.compiled: a twisted rod in water under a side load, with
    self-contact) on 40 cells, ten 10-ms steps, then one step of 10 µs: its route
    difference over Δt is the limit :func:`contact_steps.step_route_rate` gives, the box
    rule's rate plus c = 1 − γ/(1 − αm) (1/5 at ρ∞ = ½, 1/3 at 0) times what the carried
    κ̇ⁿ add (to 1 %; measured 0.08 and 0.09 %), where the carried part is most of it.
    After that step the carried rates' part has shrunk by |αm|/(1 − αm) (1/5 and 1/3;
    measured 0.199 and 0.334): the step's new rates satisfy the equations at its level
    n + 1 − αm, a hair from n."""
    import pickle

    from research.contact_steps import carried_rate_weight, semi_discrete_route_rate, step_route_rate
    from solver.case import Case
    from solver.compiled import _warm_up_spec
    from solver.run import RodRun

    spec = _warm_up_spec()
    spec["numerics"].update(n_segments=40, rho_inf=rho_inf, t_end=1.0)
    spec["distributed_forces"][0]["value"] = [0.1, 0.0, 0.0]
    run = RodRun(Case.model_validate(spec))
    for k in range(1, 11):
        run.advance(0.01 * k)
    p = run.assembly.params
    c = carried_rate_weight(p)
    assert c == pytest.approx({0.5: 0.2, 0.0: 1.0 / 3.0}[rho_inf])
    limit, carried = step_route_rate(run)
    box = semi_discrete_route_rate(run)
    assert np.linalg.norm(limit - box, axis=1).max() > 5 * np.linalg.norm(box, axis=1).max()
    np.testing.assert_allclose(limit, box + c * (carried - box), rtol=0, atol=1e-15)
    trial = pickle.loads(pickle.dumps(run))
    h = 1e-5
    assert trial.try_step(h).ok
    measured = trial.last_step_error / h
    assert measured == pytest.approx(np.linalg.norm(limit, axis=1).max(), rel=0.01)
    after, _ = step_route_rate(trial)
    part = np.linalg.norm(after - semi_discrete_route_rate(trial), axis=1).max()
    before = np.linalg.norm(limit - box, axis=1).max()
    assert part / before == pytest.approx(abs(p.alpha_m) / (1.0 - p.alpha_m), rel=0.05)
