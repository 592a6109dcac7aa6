"""The sea floor on the centreline scheme (solver/centreline.py, ``seabed_terms``): the
law of solver/seabed.py at each node of the one centreline, the statics' nodal spring
with the damper and Coulomb friction added. Its oracles: an exact Jacobian, a static
equilibrium on the bottom as a dynamic rest, the submerged weight carried, axial
friction μ w L, and rolling without slip down a slope at (2/3) g sin θ."""
import math
from dataclasses import replace

import numpy as np
import pytest

from solver import statics
from solver.case import Case
from solver.centreline import CentrelineRod
from solver.centreline_run import CentrelineRun
from test_centreline import jacobian_error
from test_seabed import D, FRICTION, G, NO_DRAG, W, _drag_case, _spec


def centreline(spec) -> Case:
    spec["numerics"]["formulation"] = "centreline"
    return Case.model_validate(spec)


def run_to(case, t_end) -> CentrelineRun:
    run = CentrelineRun(case)
    dt = case.numerics.dt
    for k in range(1, int(round(t_end / dt)) + 1):
        run.advance(k * dt)
    return run


def test_the_jacobian_with_the_sea_floor_is_exact():
    """The band Jacobian (static band, inertia blocks, the law's partials chained to
    each node's r and quaternion) against central differences of the residual, for a
    twisted cable pressed 0.1 mm into the bottom, sliding and spinning (the damper on
    its free branch, friction on its regularised slope and beyond it)."""
    spec = _spec({"elevation": -D / 2 + 1e-4, "friction": FRICTION}, n=8)
    spec["initial"]["twist_rate"] = 1.0
    rod = CentrelineRod.from_case(centreline(spec))
    state = rod.rest_state()
    state.X[:, 0] = np.linspace(0.0, 3e-3, rod.n)       # slip across v_s = 1 mm/s
    state.X[:, 1] = 4e-4
    state.X[:, 2] = -0.01
    state.X[:, 3:6] = 0.3
    h = 0.01
    co = rod.coefficients(state, h)
    _, split, _ = rod.seabed_terms(rod.predict(state, h), state, co, False)
    assert np.all(split[3] > 0) and np.abs(split[1]).max() > 1.0   # touching, sliding
    err, size = jacobian_error(rod, state, h)
    assert err < 1e-7 * size, err


def test_a_static_equilibrium_on_the_bottom_is_a_dynamic_rest():
    """A cable clamped 0.1 m above the bottom and lying on it beyond a touchdown: the
    statics' equilibrium (the nodal spring N = k p, :func:`solver.statics.seabed_loads`)
    handed over as it is starts a run that stays there, to rounding: the dynamic law at
    rest is the static spring (the damper and friction vanish at zero velocity), on the
    same nodes and rows."""
    xs = np.linspace(0.0, 0.4, 81)
    zs = 0.1 * (1.0 - xs / 0.4) ** 2
    arc = float(np.sum(np.hypot(np.diff(xs), np.diff(zs))))
    flat = np.linspace(0.4, 0.4 + 1.0 - arc, 61)[1:]
    points = ([[float(x), 0.0, float(z)] for x, z in zip(xs, zs)]
              + [[float(x), 0.0, 0.0] for x in flat])
    held = {"translation": [{"velocity": 0}] * 3, "rotation": [{"angular_velocity": 0}] * 3}
    spec = _spec({"elevation": -D / 2, "friction": FRICTION}, n=40, start=held)
    spec["initial"] = {"normal": [0.447214, 0.0, 0.894427], "centreline": {"points": points}}
    rod = CentrelineRod.from_case(centreline(spec))
    sol = statics.solve(replace(rod.problem(0.0), seabed=rod.seabed), rod.rest_state().Y)
    pen = rod.seabed_terms(sol.Y, rod.rest_state(), rod.coefficients(rod.rest_state(), 0.01),
                           False)[1][3]
    assert 10 < np.count_nonzero(pen > 0) < rod.n - 10          # a touchdown between
    state = rod.start(sol.Y)
    for _ in range(20):
        state, _, _ = rod.step(state, 0.01)
    assert np.abs(state.Y[:, 0:3] - sol.Y[:, 0:3]).max() < 1e-12
    assert np.abs(state.Y[:, 7:13] - sol.Y[:, 7:13]).max() < 1e-9


def test_a_cable_at_rest_on_a_flat_bottom_carries_its_submerged_weight():
    run = run_to(centreline(_spec(t_end=2.0)), 2.0)
    Fn, Ff, _, pen = run.seabed_loads()
    total = Fn.T @ run.props.quad_weights
    assert abs(total[2] / W - 1.0) < 1e-9, total
    assert np.allclose(total[:2], 0.0, atol=1e-12) and np.all(Ff == 0.0)
    # every node at the same penetration: no odd-even mode under the nodal law
    assert np.allclose(pen, W / 3e6, rtol=1e-6), (pen, W / 3e6)


def test_a_cable_dragged_along_its_axis_pulls_with_mu_w_l():
    """The seed scheme's drag test (tests/solver/test_seabed.py) on the centreline: the
    s = L end pulled at 2 cm/s (20 slip velocities): the pull is μ w L and the seabed's
    work account the friction over the distance slid."""
    spec = _drag_case("axial").model_dump(mode="json", exclude_none=True)
    # the cable starts touching the bottom with no penetration and settles onto the
    # spring (w/k) in the first steps: the work account counts from 0.05 s, when the
    # pull has moved the end 10 µm
    settled = run_to(centreline(spec), 0.05).state.seabed_work
    run = run_to(centreline(spec), 1.5)
    from solver.loads import end_reactions

    assert np.allclose(run.state.v_global_time[:, 0], 0.02, rtol=1e-9)
    re = end_reactions(run.state.Y, run.state.q, run.props.stiffness)
    pull = re["reaction_force_start"][0] + re["reaction_force_end"][0]
    assert abs(pull / (0.3 * W) - 1.0) < 1e-6, (pull, 0.3 * W)
    slid = 0.02 * (1.5 - 0.25)
    work = run.state.seabed_work - settled
    assert -work / (0.3 * W * slid) == pytest.approx(1.0, abs=0.005)


def test_a_cable_rolls_down_a_slope_at_two_thirds_g_sin_theta():
    """A free 1-m cable lying across a 14° slope (a bathymetry grid, μ = 0.5 with a
    1 mm/s slip velocity, vacuum, E = 5e8 Pa) rolls without slip: a solid cylinder's
    a = (2/3) g sin θ, ½ a t² = 0.7911 m along the slope in 1 s. Measured ratios
    1.0000354, 1.0000354, 1.0000359 at Δt = 0.01, 0.005, 0.0025 s: the start's
    accelerations are the consistent ones (Taylor steps with the contact set held); the
    seed scheme travels 8 % less (issue 79)."""
    th = math.radians(14.0)
    xs = [-5.0, 5.0]
    grid = {"x": xs, "y": [-5.0, 5.0], "z": [[-math.tan(th) * x] * 2 for x in xs]}
    spec = _spec({"bathymetry": grid, "friction": {"axial": 0.5, "lateral": 0.5,
                                                   "slip_velocity": 1e-3}})
    spec.pop("fluid")
    spec["rod"].update(youngs_modulus=5e8, shear_modulus=2e8)
    z0 = D / 2 / math.cos(th)
    spec["initial"] = {"normal": [math.sin(th), 0.0, math.cos(th)],
                       "centreline": {"points": [[0.0, -0.5, z0], [0.0, 0.5, z0]]}}
    run = run_to(centreline(spec), 1.0)
    along = float(np.mean(run.state.r[:, 0])) / math.cos(th)
    expected = 0.5 * (2.0 / 3.0) * G * math.sin(th)
    assert abs(along / expected - 1.0) < 2e-4, (along, expected)
    # it rolls: the spin about the axis is the speed over the radius
    spin = run.state.Y[:, 5]
    speed = np.linalg.norm(run.state.v_global_time, axis=1)
    assert np.allclose(np.abs(spin) * D / 2, speed, rtol=5e-3)


def test_a_twisted_plane_curve_starts_in_its_plane():
    """``cases/seabed-hockle.yaml``'s start (a half-sine lay on the bottom, 6 turns of
    twist): the centreline the box rule builds from each node's own frame of the curve
    (:func:`solver.initial.node_frames`) lies in the bottom's plane to rounding and ends at
    the curve's last point to O(Δs²); the seed scheme's start (κ integrated along s) ends
    0.17 mm above it on 160 segments (2.5 mm on 40, 0.043 mm on 320)."""
    from pathlib import Path

    from solver.initial import initial_pose

    spec = Case.from_file(Path(__file__).resolve().parents[2] / "cases"
                          / "seabed-hockle.yaml").model_dump(mode="json")
    spec["contact"] = None
    rod = CentrelineRod.from_case(centreline(spec))
    assert np.abs(rod.r0[:, 2]).max() < 1e-15
    last = np.array(spec["initial"]["centreline"]["points"][-1])
    assert np.linalg.norm(rod.r0[-1] - last) < 1e-5
    seed_r = initial_pose(rod.case, rod.props.s)[1]
    assert 1.6e-4 < seed_r[-1, 2] < 1.8e-4


def test_the_hockle_case_pushed_in_lifts_off_the_bottom():
    """cases/seabed-hockle.yaml without its contact block on 80 segments at its Δt: from
    1 s the far end pushes the twisted cable in, the friction's regularised slope (stiff
    against Δt) makes Newton's first steps from rest overshoot, and the cable leaves the
    bottom near the pushed end. The run gets through (Newton backtracks along its steps
    and accepts a residual at its rounding level, :meth:`CentrelineRod.newton`), the held
    end on its path and the centreline inextensible to Newton's tolerance."""
    from pathlib import Path

    spec = Case.from_file(Path(__file__).parents[2] / "cases" / "seabed-hockle.yaml"
                          ).model_dump(mode="json")
    spec["contact"] = None
    spec["numerics"].update(formulation="centreline", n_segments=80, t_end=1.6)
    spec["numerics"].pop("ds", None)
    run = run_to(Case.model_validate(spec), 1.6)
    assert run.state.t == pytest.approx(1.6)
    touching = np.count_nonzero(run.seabed_loads()[3] > 0.0)
    assert touching < 40                                 # lifted off: 81 nodes lay flat
    pushed = 0.266667 * 0.6 ** 2 / 2                      # ∫ v dt, v ramping 1 -> 2 s
    assert run.level.Y[-1, 0] == pytest.approx(run.rod.r0[-1, 0] - pushed, abs=1e-9)
    a3 = statics._rot(run.level.Y[:, 3:7])[:, :, 2]
    gap = np.diff(run.level.Y[:, 0:3], axis=0) - 0.5 * run.rod.h * (a3[:-1] + a3[1:])
    assert np.abs(gap).max() < 1e-9                       # r' = a3, the box rule's


def test_loose_rounds_of_the_contact_set_reach_the_same_steps():
    """The sea floor's contact-set rounds before the first that pulls no held node stop
    at REDECIDE_AT (0.1) instead of converging (:meth:`CentrelineRod._held_solve`): on
    the hockle case of the test above at its lift-off (1.05-1.2 s, the held set shrinking
    from 67 to 26 nodes), a step from the same level with the same Δt reaches the same
    centreline as with every round converged to TOLERANCE, to 1e-10 m, in fewer Newton
    iterations (measured: 22-35 against 38-65, the same to 3e-15 m). A whole run may
    still part from the other where one refuses a step the other takes (different cut
    steps), so the steps are compared one by one from shared levels."""
    from pathlib import Path

    from solver.centreline import StepFailure

    spec = Case.from_file(Path(__file__).parents[2] / "cases" / "seabed-hockle.yaml"
                          ).model_dump(mode="json")
    spec["contact"] = None
    spec["numerics"].update(formulation="centreline", n_segments=80, t_end=1.2)
    spec["numerics"].pop("ds", None)
    case = Case.model_validate(spec)
    run = run_to(case, 1.0)
    rod, dt = run.rod, case.numerics.dt
    compared = 0
    for k in range(21, 25):
        run.advance(k * dt)
        for h in (0.5 * dt, 0.25 * dt):
            steps = []
            for tol in (rod.REDECIDE_AT, rod.TOLERANCE):
                rod.REDECIDE_AT = tol
                try:
                    steps.append(rod.step(run.level, h)[:2])
                except StepFailure:
                    steps.append(None)
            rod.REDECIDE_AT = CentrelineRod.REDECIDE_AT
            if None in steps:
                continue
            (loose, its_loose), (tight, its_tight) = steps
            assert np.abs(loose.Y[:, 0:3] - tight.Y[:, 0:3]).max() < 1e-10
            assert its_loose < its_tight
            compared += 1
    assert compared >= 2


def test_next_branches_take_the_laws_or_the_free_branch_between_two_bounds():
    """The damper's branches after a round (−1 none, 0: N = 0, 1 free, 2: N = 2kp): the
    law's, except that a node held at one bound whose law gives the other goes to the
    free branch between them (the seed scheme's rule, solver.seabed._next_mode)."""
    from solver.centreline import next_branches
    from solver.seabed import _next_mode

    modes = np.array([-1.0, 0.0, 0.0, 2.0, 2.0, 1.0, 1.0, 0.0, 2.0, 1.0])
    laws = np.array([2.0, 2.0, 1.0, 0.0, 2.0, 0.0, 2.0, -1.0, -1.0, 1.0])
    assert next_branches(modes, laws).tolist() == [2.0, 1.0, 1.0, 1.0, 2.0, 0.0, 2.0, -1.0,
                                                   -1.0, 1.0]
    touching = laws >= 0
    assert all(next_branches(modes, laws)[touching]
               == [_next_mode(int(m), int(w)) for m, w in zip(modes[touching], laws[touching])])


def test_a_soft_catenary_on_a_damped_bottom_steps_without_refusals():
    """cases/catenary-touchdown.yaml (the default damping, c/k = 0.1 s, at Δt = 0.05 s:
    the damper's slope in a step is 3× the spring's) to 0.5 s: with each touching node's
    damper branch held through Newton's rounds no step is refused (with the law's clamp
    at every iterate every step was cut 3-4 times: the clamp's bounds swapped between
    iterates), and the lying cable, pulled away from the pin by its start's 1 N (a
    ``force`` item: the internal force there), holds still within a millimetre. The
    energy check is off here: it refuses the first fall onto the spring, whose cut steps
    Newton meets afresh (tests/solver/test_centreline_energy.py)."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    spec = Case.from_file(root / "cases" / "catenary-touchdown.yaml").model_dump(mode="json")
    spec["numerics"].update(formulation="centreline", t_end=0.5, energy_tolerance=None)
    run = run_to(Case.model_validate(spec), 0.5)
    assert run.control.refusals == {}
    assert abs(run.level.Y[0, 0]) < 1e-3
    assert run.rod.seabed_modes is None and run.rod.seabed_hold is None
