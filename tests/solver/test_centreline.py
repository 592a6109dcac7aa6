"""The centreline scheme (solver/centreline.py): the statics' rows with inertia, stepped
by Lie-group generalized-α. Its oracles: a static equilibrium is a dynamic rest, the
orders in time and s on the project's tip case, the order through a load switched on
from rest (consistent start), Galilean invariance of a towed pendulum, the energy of a
conservative swing at ρ∞ = 1, an exact Jacobian, and refusals that name the field."""
import math
from pathlib import Path

import numpy as np
import pytest

from rodcases import free_end, make_case
from solver import statics
from solver.case import Case
from solver.centreline import (CentrelineError, CentrelineRod, box_centreline,
                               cayley_quaternion, cayley_vector)
from test_convergence_order import fitted_order, tip_case

FREE_ROT = [{"moment": 0.0}] * 3


ROOT = Path(__file__).resolve().parents[2]


def run(rod, state, dt, t_end):
    for _ in range(int(round((t_end - state.t) / dt))):
        state, _, _ = rod.step(state, dt)
    return state


def cantilever(n=20, dt=0.01, t_end=0.5, rho_inf=0.5):
    """A 1-m cantilever along z, clamped at s = 0, its weight across it (−x)."""
    return make_case(n_segments=n, dt=dt, t_end=t_end, end=free_end(),
                     gravity=(-9.81, 0.0, 0.0), rho_inf=rho_inf)


def test_cayley_map_and_its_inverse():
    rng = np.random.default_rng(1)
    p = rng.normal(size=(5, 4))
    p /= np.linalg.norm(p, axis=1)[:, None]
    c = rng.normal(size=(5, 3))
    q = statics._qmul(p, cayley_quaternion(c))
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)
    assert np.abs(cayley_vector(p, q) - c).max() < 1e-13
    # the rotation angle of cay(c) is 2 atan(|c|/2): exp's to O(|c|³)
    small = np.array([[1e-3, 0.0, 0.0]])
    angle = 2.0 * math.acos(cayley_quaternion(small)[0, 0])
    assert abs(angle - 1e-3) < 1e-9


def jacobian_error(rod, state, h):
    """(largest |J − J_fd|, largest |J|) of the band Jacobian of a step of h from state
    at the predictor, J_fd by central differences (1e-7) of the residual."""
    from solver.static_band import KL, KU

    co = rod.coefficients(state, h)
    prob = rod.problem(state.t + h)
    Y = rod.predict(state, h)
    ab = rod.jacobian(Y, state, co, prob)
    n = Y.size
    J = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - KL), min(n, i + KU + 1)):
            J[i, j] = ab[KL + KU + i - j, j]
    eps = 1e-7
    Jfd = np.empty_like(J)
    for j in range(n):
        Yp, Ym = Y.copy().ravel(), Y.copy().ravel()
        Yp[j] += eps
        Ym[j] -= eps
        Jfd[:, j] = (rod.residual(Yp.reshape(Y.shape), state, co, prob)
                     - rod.residual(Ym.reshape(Y.shape), state, co, prob)) / (2 * eps)
    return float(np.abs(J - Jfd).max()), float(np.abs(J).max())


def test_the_jacobian_is_exact():
    """The band Jacobian (static band + the nodal inertia blocks) against central
    differences of the residual, in the middle of a large swing."""
    rod = CentrelineRod.from_case(cantilever(n=6))
    err, size = jacobian_error(rod, run(rod, rod.start(), 0.01, 0.2), 0.01)
    assert err < 1e-5 * size, err


def test_a_static_equilibrium_is_a_dynamic_rest():
    """The statics' equilibrium of the cantilever under its weight, handed over as it is
    (same unknowns, same rows), starts a run that stays there: the consistent start
    finds no acceleration and ten steps move nothing beyond Newton's tolerance."""
    case = cantilever()
    rod = CentrelineRod.from_case(case)
    sol = statics.solve(rod.problem(0.0))
    state = rod.start(sol.Y)
    assert np.abs(state.Xd).max() < 1e-6
    end = run(rod, state, 0.01, 0.1)
    assert np.abs(end.Y[:, 0:3] - sol.Y[:, 0:3]).max() < 1e-9
    assert np.abs(end.Y[-1, 0] - sol.Y[-1, 0]) < 1e-9
    assert abs(sol.Y[-1, 0]) > 0.1                # it sags: not the straight rod


def tip_positions(n, dt, rho_inf):
    rod = CentrelineRod.from_case(tip_case(n, dt, rho_inf))
    return run(rod, rod.start(), dt, 1.0).Y[:, 0:3]


def test_second_order_in_time_on_the_tip_case():
    """The project's order study (tests/solver/test_convergence_order.py): the base swung
    through about a radian about a normal (a path-dependent frame, integrated by
    :class:`solver.centreline.EndPath`) in water. Measured: errors 1.68e-4, 4.44e-5,
    1.13e-5, 2.52e-6 m, order 2.02 (the seed's scheme: 2.00)."""
    ref = tip_positions(40, 1.0 / 1280, 0.5)
    dts = [1.0 / 40, 1.0 / 80, 1.0 / 160, 1.0 / 320]
    errors = [np.abs(tip_positions(40, dt, 0.5) - ref).max() for dt in dts]
    assert abs(fitted_order(dts, errors) - 2.0) <= 0.2, errors
    assert errors[-1] < 5e-6
    assert np.linalg.norm(ref[-1] - [0.0, 0.0, 1.0]) > 0.1


@pytest.mark.slow
@pytest.mark.parametrize("rho_inf", [0.0, 1.0])
def test_second_order_in_time_other_rho_inf(rho_inf):
    """Measured: ρ∞ = 0 order 1.80, ρ∞ = 1 order 2.05."""
    ref = tip_positions(40, 1.0 / 1280, rho_inf)
    dts = [1.0 / 40, 1.0 / 80, 1.0 / 160, 1.0 / 320]
    errors = [np.abs(tip_positions(40, dt, rho_inf) - ref).max() for dt in dts]
    assert abs(fitted_order(dts, errors) - 2.0) <= 0.21, errors


def test_second_order_in_arclength_on_the_tip_case():
    """Measured: errors 2.57e-3, 6.84e-4, 1.71e-4, 4.09e-5 m on 10-80 segments against
    320, order 1.99."""
    dt = 1.0 / 200
    ref = tip_positions(320, dt, 0.5)
    ns = [10, 20, 40, 80]
    errors = [np.abs(tip_positions(n, dt, 0.5) - ref[:: 320 // n]).max() for n in ns]
    assert abs(fitted_order([1.0 / n for n in ns], errors) - 2.0) <= 0.2, errors


def test_second_order_through_a_load_switched_on_from_rest():
    """A cantilever on 2 segments under a weight (1 % of g: the effect is linear) that
    acts from t = 0 on the rod at rest, so Ẋ(0) ≠ 0. With the consistent start (two
    Taylor steps, Richardson) the tip's order is 2 (measured 2.36); started with Ẋ = 0 it
    drops to 1 (measured 1.09; Arnold & Brüls 2007), the seed scheme's defect. On finer
    grids the jump excites grid modes faster than the Taylor steps resolve (4 segments:
    1.18 and 1.01); docs/numerics.md § 9."""
    def tip(dt, consistent):
        case = make_case(n_segments=2, dt=dt, t_end=0.4, end=free_end(),
                         gravity=(-0.0981, 0.0, 0.0), rho_inf=0.5)
        rod = CentrelineRod.from_case(case)
        state = rod.start() if consistent else rod.rest_state()
        return run(rod, state, dt, 0.4).Y[:, 0:3]

    dts = [0.04, 0.02, 0.01, 0.005]
    orders = {}
    for consistent in (True, False):
        ref = tip(0.0003125, consistent)
        errors = [np.abs(tip(dt, consistent) - ref).max() for dt in dts]
        orders[consistent] = fitted_order(dts, errors)
    assert orders[True] > 1.8 and orders[False] < 1.3, orders


def _pendulum(V, dt, n=10, t_end=1.0):
    """tests/solver/test_global_ends.py's pendulum: a 1-m rod pinned at s = 0 (frame
    global, moment 0) under gravity 0.5 rad off its axis, the pin moving at V (m/s) and
    the rod starting with it."""
    spec = {"schema_version": 1, "name": "pendulum",
            "rod": {"length": 1.0, "youngs_modulus": 1.25e7, "shear_modulus": 5e6,
                    "density": 1500.0, "diameter": 0.02},
            "gravity": [9.81 * math.sin(0.5), 0.0, 9.81 * math.cos(0.5)],
            "boundary": {"start": {"frame": "global",
                                   "translation": [{"velocity": float(x)} for x in V],
                                   "rotation": FREE_ROT},
                         "end": free_end()},
            "numerics": {"n_segments": n, "dt": dt, "t_end": t_end, "rho_inf": 0.5}}
    rod = CentrelineRod.from_case(Case.model_validate(spec))
    X = np.zeros((n + 1, 6))
    X[:, 0:3] = V
    state = rod.start(X=X)
    times, positions = [], []
    for _ in range(int(round(t_end / dt))):
        state, _, _ = rod.step(state, dt)
        times.append(state.t)
        positions.append(state.Y[:, 0:3].copy())
    return np.array(times), np.array(positions)


def test_a_towed_pendulum_is_the_pinned_one_moved_along():
    """Galilean invariance holds to rounding: positions and global velocities are the
    unknowns, so V t adds to every position and nothing else changes (the seed's
    scheme: 1.0e-4 m at Δt = 0.02 s, its body-frame inertia is not invariant)."""
    V = np.array([0.7, -0.3, 0.2])
    t, pinned = _pendulum(np.zeros(3), 0.02)
    _, towed = _pendulum(V, 0.02)
    assert np.abs(towed[:, 0] - t[:, None] * V).max() < 1e-12
    assert np.abs(towed - t[:, None, None] * V - pinned).max() < 1e-11
    assert np.ptp(pinned[:, -1, 0]) > 0.5                      # it swings


def test_a_conservative_swing_keeps_its_energy_at_rho_inf_1():
    """The cantilever released under 1 % of g in vacuum at ρ∞ = 1 (no numerical
    dissipation): the total energy (kinetic + elastic + the weight's potential, each by
    the trapezoid in s) stays at its start (0) to within the quadrature's O(Δs²), whatever
    Δt. Measured over 1 s at Δt = 0.01 s: |E|/max K = 3.46 %, 0.91 %, 0.23 % on 10, 20,
    40 segments (3.45 % at Δt = 0.005 s on 10)."""
    def worst(n):
        rod = CentrelineRod.from_case(make_case(n_segments=n, dt=0.01, t_end=1.0,
                                                end=free_end(), gravity=(-0.0981, 0, 0),
                                                rho_inf=1.0))
        state = rod.start()
        totals, kin = [], []
        for _ in range(100):
            state, _, _ = rod.step(state, 0.01)
            e = rod.energies(state)
            totals.append(e["kinetic"] + e["elastic"] + e["potential"])
            kin.append(e["kinetic"])
        return np.abs(totals).max() / max(kin)

    errors = [worst(n) for n in (10, 20, 40)]
    assert errors[-1] < 3e-3, errors
    assert 3.5 < errors[0] / errors[1] < 4.5 and 3.5 < errors[1] / errors[2] < 4.5, errors


def test_what_the_scheme_does_not_take_is_refused_with_its_field():
    twisting_load = make_case(end={"translation": [{"force": 1.0}, {"force": 0.0},
                                                   {"force": 0.0}],
                                   "rotation": FREE_ROT})
    with pytest.raises(CentrelineError, match="boundary.end.translation.0"):
        CentrelineRod.from_case(twisting_load)


# --------------------------------------------------------------- through integrate

def _twisted_spec(formulation="centreline", **numerics):
    """A 1-m rod clamped at both ends, its s = 0 end turned about its axis by 2 rad over
    the first second, in water (the seed's rod; straight: no writhe)."""
    table = {"t": [0.0, 1.0, 2.0], "value": [0.0, 2.0, 2.0]}
    return {"schema_version": 1, "name": "twisted",
            "rod": {"length": 1.0, "youngs_modulus": 1.25e7, "shear_modulus": 5e6,
                    "density": 1500.0, "diameter": 0.02},
            "fluid": {"density": 1000.0},
            "boundary": {"start": {"translation": [{"velocity": 0.0}] * 3,
                                   "rotation": [{"angular_velocity": 0.0}] * 2
                                   + [{"angular_velocity": table}]},
                         "end": {"translation": [{"velocity": 0.0}] * 2 + [{"force": 0.0}],
                                 "rotation": [{"angular_velocity": 0.0}] * 3}},
            "numerics": {"n_segments": 20, "dt": 0.05, "t_end": 1.5,
                         "formulation": formulation, **numerics},
            "output": {"fields": ["position", "kappa", "energies", "topology"]}}


def test_integrate_runs_the_centreline_scheme_with_the_common_outputs():
    from solver.simulation import integrate

    ds = integrate(Case.model_validate(_twisted_spec()))
    assert ds.attrs["hockle_status"] == "completed"
    # one centreline: the routes and the held end agree by construction
    assert not ds["position_route_difference"].values.any()
    assert not ds["end_drift"].values.any()
    # the held s = 0 end turned by 2 rad (∫ω3 dt to 1.5 s): Lk = −2/2π exactly (the
    # start turned by +φ gives −φ/2π, docs/topology.md), Tw the same, no writhe
    assert abs(float(ds.linking_number[-1]) + 2.0 / (2 * math.pi)) < 1e-12
    # Tw = ∫κ3 ds/2π by the trapezoid, the frames turned by the box rule's Cayley map
    # (angle 4 atan(Δs κ̄3/4) per cell): they part at O(Δs²), measured 6.6e-5 turns at
    # 20 segments, 1.7e-5 at 40; the start is consistent (Tw = 0 to rounding)
    err = ds.topology_error.values
    assert err[0] < 1e-12 and err.max() < 1e-4, err
    assert np.abs(ds.position.values[:, :, :2]).max() < 1e-12
    # at rest again, the torsion energy is GJ φ²/2L (φ = 2 rad)
    gj = 5e6 * math.pi * 0.02**4 / 32
    assert abs(float(ds.energy_torsion[-1]) / (0.5 * gj * 4.0) - 1.0) < 1e-3


def test_the_formulation_is_checked_and_kept_out_of_the_canonical_json():
    from pydantic import ValidationError

    goyal = Case.model_validate(_twisted_spec("goyal"))
    assert "formulation" not in goyal.model_dump(mode="json")["numerics"]
    centre = Case.model_validate(_twisted_spec())
    assert centre.model_dump(mode="json")["numerics"]["formulation"] == "centreline"
    Case.model_validate(_twisted_spec(tolerance={"relative": 1e-3}))
    spec = _twisted_spec(tolerance={"relative": 1e-3})
    spec["fluid"]["viscosity"] = 1e-3
    spec["thermal"] = {"temperature": 300.0, "seed": 1}
    with pytest.raises(ValidationError) as info:
        Case.model_validate(spec)
    err = info.value.errors()[0]
    assert err["loc"] == ("numerics", "tolerance")
    assert "thermal" in err["msg"]


def test_an_end_held_after_a_load_phase_stays_where_the_phase_left_it():
    """The seed example's s = L end slides freely along the rod, then is held (``until``):
    the static rows cannot know where it stopped; the run lands a step on the switch (here
    0.25 s, between steps of 0.1 s), records where the end is and holds it there."""
    from solver.centreline_run import CentrelineRun

    sliding = {"translation": [{"velocity": 0.0}, {"velocity": 0.0},
                               [{"until": 0.25, "force": 0.0}, {"velocity": 0.0}]],
               "rotation": [{"angular_velocity": 0.0}] * 3}
    # a 1-m rod along z clamped at s = 0, its far end held across (x, y) and free along
    # z: the weight (−x) bows the rod, which draws the free end in along z
    case = make_case(n_segments=10, dt=0.1, t_end=0.6, end=sliding,
                     gravity=(-9.81, 0.0, 0.0))
    run = CentrelineRun(case)
    z0 = run.level.Y[-1, 2]
    ends = {}
    for k in range(1, 7):
        run.advance(0.1 * k)
        ends[round(run.level.t, 12)] = run.level.Y[-1, 2]
    ((where, t_a), r_a), = run.rod.anchors.items()
    assert where == "boundary.end.translation.2" and t_a == 0.25
    assert z0 - r_a[2] > 1e-3                        # it slid before the switch
    for t in (0.3, 0.4, 0.5, 0.6):
        assert abs(ends[t] - r_a[2]) < 1e-12, (t, ends[t] - r_a[2])


@pytest.mark.parametrize("rho_inf", [1.0, 0.5])
def test_second_order_through_a_load_switched_on_mid_run(rho_inf, monkeypatch):
    """The seed scheme's switch case (tests/solver/test_step_control.py: a 2-segment
    cantilever in water under 0.05 N/m switched on at 0.3 s, Δt 0.0125 -> 0.0016 s
    against 2e-4 s) on this scheme: the step lands on the switch with the loads' left
    limit and the level is restarted there with the start's Taylor steps. Without them
    the observed order was 1.03 (the load acted from the step ending at the switch, and
    generalized-α carried the accelerations of before)."""
    from solver import simulation
    from solver.centreline_run import CentrelineRun
    from test_step_control import switched_load_positions

    monkeypatch.setattr(simulation, "make_run", CentrelineRun)
    ref = switched_load_positions(0.05 / 256, rho_inf, 0.3)
    dts = [0.0125, 0.00625, 0.003125, 0.0015625]
    errors = [np.abs(switched_load_positions(dt, rho_inf, 0.3) - ref).max() for dt in dts]
    order = fitted_order(dts, errors)
    assert abs(order - 2.0) <= 0.2, (order, errors)


@pytest.mark.parametrize("rho_inf", [1.0, 0.5])
def test_an_end_held_after_sliding_stops_the_rod_without_ringing(rho_inf, monkeypatch):
    """The seed scheme's sliding-then-held rod (tests/solver/test_step_control.py: pushed
    along its axis by 0.5 N/m, both ends free along it until its start is held at 0.2 s):
    the held end stops the inextensible rod at once, its velocity 0 and its end force the
    static 0.5 N from the next output on. Without the impact's velocities the jump rang
    undamped at ρ∞ = 1 (v = ±0.212 m/s, the end force growing to −64 N by 0.6 s)."""
    from solver import simulation
    from solver.centreline_run import CentrelineRun
    from solver.simulation import integrate
    from rodcases import RHO
    from test_step_control import sliding_then_held_case

    monkeypatch.setattr(simulation, "make_run", CentrelineRun)
    ds = integrate(sliding_then_held_case(rho_inf, t_end=0.6))
    t = ds.time.values
    v_end, f_end = ds.v.values[:, 0, 2], ds.f.values[:, 0, 2]
    sliding = t < 0.2 + 1e-9
    np.testing.assert_allclose(v_end[sliding], 0.5 / (RHO * np.pi * 1e-4) * t[sliding],
                               rtol=1e-6)
    np.testing.assert_allclose(v_end[~sliding], 0.0, atol=1e-9)
    np.testing.assert_allclose(f_end[~sliding], 0.5, rtol=1e-6)


def test_an_end_held_at_a_position_starts_on_its_hold():
    """The box rule's centreline built from the case's frames misses an end held at a
    given position by the rule's O(Δs²) error (cases/catenary-touchdown.yaml, pinned
    1 m above the bottom, on 80 segments: 66 µm); the start turns the frames so that the
    end sits on its hold, the box rows still exact, the frames turned by about the miss
    over the length, and the consistent start converges (it did not: the Taylor steps
    had to move the end onto its hold within Δt/4, with n ∝ 1/δ²)."""
    from solver.initial import node_frames

    spec = Case.from_file(ROOT / "cases" / "catenary-touchdown.yaml").model_dump(mode="json")
    spec["numerics"]["formulation"] = "centreline"
    case = Case.model_validate(spec)
    rod = CentrelineRod.from_case(case)
    hold = np.array([3.512378, 0.0, 1.0])
    assert np.abs(rod.r0[-1] - hold).max() < 1e-12
    assert np.abs(rod.r0 - box_centreline(rod.q0, rod.r0[0], rod.h)).max() < 1e-14
    q = node_frames(case, rod.props.s)
    q = q / np.linalg.norm(q, axis=1)[:, None]
    missed = np.abs(box_centreline(q, rod.r0[0], rod.h)[-1] - hold).max()
    assert 1e-5 < missed < 1e-4
    turn = np.linalg.norm(cayley_vector(q, rod.q0), axis=1).max()
    assert turn < 10.0 * missed / case.rod.length
    state = rod.start()
    assert np.abs(state.Y[-1, 0:3] - hold).max() < 1e-12
    # the pull on the pin: the suspended weight's share, not an impulse
    assert np.abs(state.Y[-1, 7:10]).max() < 5.0


def test_an_end_held_beyond_a_straight_rods_reach_is_refused():
    """A straight rod cannot lengthen: turning its frames cannot take its end 1 cm beyond
    it (case validation refuses such a case on its own check; the start's refusal names
    the field too)."""
    from solver.centreline import meet_held_ends

    s = np.linspace(0.0, 1.0, 21)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (21, 1))                  # a3 = z
    r = box_centreline(q, np.zeros(3), 0.05)
    start = statics.clamp(np.zeros(3), q[0])
    beyond = statics.clamp(np.array([0.0, 0.0, 1.01]), q[-1])
    beyond = statics.EndSpec(beyond.axes, beyond.held, beyond.position, beyond.force,
                             False, beyond.quaternion)
    with pytest.raises(CentrelineError, match="boundary.end.translation"):
        meet_held_ends(q, r, s, start, beyond)
    # on its hold already: the same arrays back
    there = statics.clamp(r[-1], q[-1])
    q2, r2 = meet_held_ends(q, r, s, start, there)
    assert q2 is q and r2 is r


def test_a_start_force_item_is_the_internal_force_there():
    """A ``force`` item gives the internal force n there, the part beyond on the part
    before (docs/case-spec.md, "Frames and signs"): the load applied at s = 0 is −n. A
    weightless rod along z held at s = L with 1 N along z at s = 0 is in 1 N of tension
    (n = +1 N along z) in the statics and stays so at rest on the centreline scheme; the
    end path of a start turned about a normal (:class:`solver.centreline.EndPath`)
    applies −n too. (The statics' end rows had taken the item as the applied load at
    s = 0: 1 N of compression, and cases/catenary-touchdown.yaml's lying cable slid 2.8 m
    towards the pin in 3 s instead of holding still.)"""
    start = {"translation": [{"velocity": 0.0}, {"velocity": 0.0}, {"force": 1.0}],
             "rotation": [{"angular_velocity": 0.0}] * 3}            # along a3 = z
    case = make_case(start=start, n_segments=10, dt=0.01, t_end=0.05)
    prob = statics.static_problem(case, 0.0)
    assert np.abs(prob.start.force - [0.0, 0.0, -1.0]).max() == 0.0
    sol = statics.solve(prob)
    assert np.abs(sol.Y[:, 7:10] - [0.0, 0.0, 1.0]).max() < 1e-9
    rod = CentrelineRod.from_case(case)
    state = run(rod, rod.start(), 0.01, 0.05)
    assert np.abs(state.Y[:, 7:10] - [0.0, 0.0, 1.0]).max() < 1e-9
    assert np.abs(state.Y[:, 0:3] - rod.r0).max() < 1e-12
    turned = {"translation": [{"velocity": 0.0}, {"velocity": 0.0}, {"force": 1.0}],
              "rotation": [{"angular_velocity": 0.1}, {"angular_velocity": 0.0},
                           {"angular_velocity": 0.0}]}
    rod = CentrelineRod.from_case(make_case(start=turned, n_segments=10))
    spec = rod.paths["start"].spec(0.02, np.zeros(3))
    assert np.abs(spec.force + spec.axes[:, 2]).max() < 1e-15


COLUMN = dict(n_segments=20, dt=1.0, t_end=4.0, diameter=0.01,
              start={"translation": [{"velocity": 0.0}] * 3, "rotation": [{"angular_velocity": 0.0}] * 3})


def _column_spec(n, rho_inf=0.0, dt=1.0, guard=1.0, imperfection=True):
    """The steel column of tests/solver/test_stability.py (L = 1 m, D = 1 cm), clamped at
    s = 0 and, at s = L, held laterally and in rotation with an axial thrust of 1.5 P_cr
    (P_cr = 4π²B/L²), at rest straight; a small lateral force on its middle."""
    from rodcases import E

    B = E * math.pi * 0.01**4 / 64
    pcr = 4.0 * math.pi**2 * B
    held = {"translation": [{"velocity": 0.0}] * 2 + [{"force": -1.5 * pcr}],
            "rotation": [{"angular_velocity": 0.0}] * 3}
    kw = dict(COLUMN, n_segments=n, dt=dt, rho_inf=rho_inf, end=held,
              fields=("position",))
    if imperfection:
        kw["forces"] = [{"value": [1e-4 * pcr, 0.0, 0.0], "start": 0.0, "s_range": [0.3, 0.7]}]
    spec = make_case(**kw).model_dump()
    spec["numerics"]["formulation"] = "centreline"
    spec["numerics"]["growth_guard"] = guard
    return spec


def _euler_bernoulli_growth(thrust_ratio=1.5, points=800):
    """The continuum's growth rate (1/s) of that column: the largest σ with
    B w'''' + P w'' + ρA σ² w = 0, w = w' = 0 at both ends, by central differences on
    ``points`` intervals (its error here 2e-5 of σ)."""
    from rodcases import E, RHO

    B, m = E * math.pi * 0.01**4 / 64, RHO * math.pi * 0.01**2 / 4
    P = thrust_ratio * 4.0 * math.pi**2 * B
    h = 1.0 / points
    n = points - 1
    d2 = (np.diag(-2.0 * np.ones(n)) + np.diag(np.ones(n - 1), 1) + np.diag(np.ones(n - 1), -1))
    d4 = d2 @ d2                         # 5 at the corners, where the ghost node
    d4[0, 0] += 2.0                      # mirroring the first (clamped) makes it 7
    d4[-1, -1] += 2.0
    A = B * d4 / h**4 + P * d2 / h**2
    return math.sqrt(-np.linalg.eigvalsh(A).min() / m)


def test_the_growth_rate_of_a_column_beyond_euler_converges_at_second_order():
    """σ of the dynamics linearised about the straight column (CentrelineRod.growth_rate,
    the quadratic pencil's shift-invert Arnoldi) on 10-80 segments against the
    continuum's 3.728 1/s: second order in s (measured errors 7.7, 1.8, 0.45, 0.12 %)."""
    from solver.centreline_run import CentrelineRun

    exact = _euler_bernoulli_growth()
    assert abs(exact - 3.728) < 1e-3
    errors = []
    for n in (10, 20, 40, 80):
        run_ = CentrelineRun(Case.model_validate(_column_spec(n, imperfection=False)))
        sigma, _ = run_.rod.growth_rate(run_.level, 2.0)
        errors.append(exact - sigma)
    assert all(e > 0.0 for e in errors)
    assert errors[2] < 5e-3 * exact
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 3.4) & (ratios < 4.6)), ratios


@pytest.mark.parametrize("rho_inf", [0.0, 0.5, 1.0])
def test_the_growth_guard_cuts_a_step_that_would_hold_a_column_straight(rho_inf):
    """The column at Δt = 1 s (σΔt = 3.7): without the guard every ρ∞ damps the growing
    mode and the run completes straight (largest deflection 1.9e-5, 2.3e-4 and 1.1e-3 L
    at 4 s, measured, without the energy check too: at ρ∞ 0 the check alone refuses two
    steps and the column buckles, at 0.5 and 1 it stays straight); with it (numerics.growth_guard 1) the first step is refused, Δt
    cut to 0.25 s ≤ 1/σ, σ recorded, and the column buckles."""
    from solver.simulation import integrate

    ds = integrate(Case.model_validate(_column_spec(20, rho_inf)))
    assert ds.attrs["hockle_status"] == "completed"
    sigma = ds.step_growth_rate.values
    assert abs(sigma[0] - 3.6596) < 1e-3                       # 20 segments' σ
    assert ds.step_dt.values[0] <= 1.0 / sigma[0]
    assert "growth 1" in ds.attrs["hockle_refused_attempts"]
    assert np.abs(ds.position.values[:, :, 0]).max() > 0.3
    spec = _column_spec(20, rho_inf, guard=None)
    spec["numerics"]["energy_tolerance"] = None
    off = integrate(Case.model_validate(spec))
    assert np.abs(off.position.values[:, :, 0]).max() < 2e-3
    assert np.all(np.isnan(off.step_growth_rate.values))


def test_the_growth_guard_catches_a_twist_that_crosses_greenhill_within_a_step(monkeypatch):
    """The stability map's rod (tests/solver/test_step_control.py: 0.5 m, 40 segments,
    5 N of tension, twisted at 10 rad/s to 1.1 × Greenhill's critical twist, an
    imperfection load) at Δt = 0.3 s: at 1.2 s (0.85 of the critical twist) there is no
    growth, at 1.5 s σ ≈ 16 1/s, beyond the near disc (4g/Δt = 13.3 1/s); the guard
    looks further where the near disc holds none, cuts the step and the rod buckles
    (measured writhe −0.247 at 1.8 s against the reference's −0.166; without the far
    look −0.004)."""
    import test_step_control
    from solver.simulation import integrate

    class Captured(Exception):
        pass

    def capture(case, *args, **kwargs):
        raise Captured(case.model_dump())

    monkeypatch.setattr(test_step_control, "integrate", capture)
    with pytest.raises(Captured) as info:
        test_step_control.test_the_guard_looks_further_when_a_known_growth_leaves_its_disc()
    spec = info.value.args[0]
    spec["numerics"]["formulation"] = "centreline"
    ds = integrate(Case.model_validate(spec))
    sigma = ds.step_growth_rate.values
    assert np.all(sigma[:3] == 0.0)                  # checked, none below the critical twist
    assert 10.0 < np.nanmax(sigma) < 30.0
    assert "growth" in ds.attrs["hockle_refused_attempts"]
    assert "energy" not in ds.attrs["hockle_refused_attempts"]     # the box rule's term
    assert abs(float(ds.writhe.values[-1])) > 0.5 * 0.166


def test_the_guard_estimates_only_near_a_static_balance():
    """CentrelineRod.dynamic_share: 0 at rest, where the growth rate is estimated; a
    swinging cantilever (its weight across it, 0.3 s after release: inertia carries the
    weight) is far from a balance, and growth_rate declines (None), as it does in a
    viscous fluid."""
    spec = cantilever().model_dump()
    spec["numerics"]["formulation"] = "centreline"
    rod = CentrelineRod.from_case(Case.model_validate(spec))
    rest = rod.rest_state()
    assert rod.dynamic_share(rest, rod.problem(0.0)) == 0.0
    assert rod.growth_rate(rest, 200.0) is not None
    state = rod.start()
    for _ in range(30):
        state = rod.step(state, 0.01)[0]
    assert rod.dynamic_share(state, rod.problem(state.t)) > 0.5
    assert rod.growth_rate(state, 200.0) is None
    # nor in a viscous fluid (docs/numerics.md § 9: its rates are not trusted yet)
    from test_viscous import viscous_spec

    viscous = CentrelineRod.from_case(Case.model_validate(viscous_spec()))
    assert viscous.growth_rate(viscous.rest_state(), 200.0) is None


@pytest.mark.parametrize("rho_inf", [0.5, 1.0])
def test_a_step_turning_a_node_past_a_quarter_turn_is_cut(rho_inf):
    """tests/solver/test_solver_misc.py's rod twisted 2.6 rad by a rate table at Δt = 1 s:
    a step turning a node's frame by more than π/2 is refused and cut (Newton had turned
    the middle node by 3.13 rad, a full turn of twist too many: elastic energy 12 times
    the work). The energy then equals work_in, the discrete work with the ends' turns as
    rotation vectors, to the box rule's O(Δs²) (measured 5.1e-4 and 4.7e-4; the Cayley
    vector 2 tan(θ/2) of a 1.7-rad step had overstated it by 34 %)."""
    from solver.simulation import integrate
    from test_solver_misc import RAMPED_TWIST, TENSIONED_END

    spec = make_case(n_segments=20, dt=1.0, t_end=3.0, rho_inf=rho_inf, start=RAMPED_TWIST,
                     end=TENSIONED_END, fields=("kappa", "energies")).model_dump()
    spec["numerics"]["formulation"] = "centreline"
    ds = integrate(Case.model_validate(spec))
    assert "turn" in ds.attrs["hockle_refused_attempts"]
    e, w = ds.energy_total.values, ds.work_in.values
    torsion = 5.0e6 * math.pi * 0.02**4 / 32 * 2.6**2 / 2.0          # GJφ²/2L, L = 1 m
    assert abs(w[-1] / torsion - 1.0) < 1e-3
    assert np.abs(e - w).max() < 1e-3 * w[-1]
