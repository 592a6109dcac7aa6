"""Regression tests of solver details: linking number bookkeeping, failure reasons."""
import json
from pathlib import Path

import numpy as np
import pydantic
import pytest

from rodcases import make_case
from solver import Case, integrate

TWIST_START = {"translation": [{"velocity": 0.0}] * 3,
               "rotation": [{"angular_velocity": 0.0}, {"angular_velocity": 0.0},
                            {"angular_velocity": 1.0}]}       # a sudden start at t = 0
SLIDING_END = {"translation": [{"velocity": 0.0}, {"velocity": 0.0}, {"force": 0.0}],
               "rotation": [{"angular_velocity": 0.0}] * 3}


@pytest.mark.parametrize("rho_inf", [0.0, 0.5, 1.0])
def test_linking_number_equals_discrete_twist_of_a_straight_rod(rho_inf):
    # a straight rod has Wr = 0, so Lk (from the end rotations) must equal Tw (from κ3)
    # step by step, also after a sudden start of the end rotation
    case = make_case(n_segments=8, dt=0.01, t_end=0.05, rho_inf=rho_inf, start=TWIST_START,
                     end=SLIDING_END, fields=("kappa", "position", "topology"))
    ds = integrate(case)
    assert np.all(np.abs(ds.writhe.values) < 1e-12)
    np.testing.assert_allclose(ds.linking_number, ds.twist, atol=1e-12)
    assert float(ds.linking_number[-1]) < 0.0          # +ω3 at s = 0 gives Lk < 0


def test_singular_boundary_conditions_are_named():
    # a straight inextensible rod held axially at both ends: the tension is undetermined.
    # Refused at validation, at the end's axial item, with the reason (it used to run and
    # fail after all Δt cuts); a spec that switches to it later (the seed's end at 30 s,
    # when the rod is curved) is accepted
    held = {"translation": [{"velocity": 0.0}] * 3, "rotation": [{"angular_velocity": 0.0}] * 3}
    with pytest.raises(pydantic.ValidationError) as info:
        make_case(n_segments=8, dt=0.01, t_end=0.02, start=TWIST_START, end=held,
                  fields=("kappa",), max_dt_cuts=1)
    err = info.value.errors()[0]
    assert err["loc"] == ("boundary", "end", "translation", 2) and err["type"] == "ill_posed"
    assert "tension undetermined" in err["msg"]
    Case.from_file("cases/goyal-writhing.yaml")


RAMPED_TWIST = {"translation": [{"velocity": 0.0}] * 3,
                "rotation": [{"angular_velocity": 0.0}, {"angular_velocity": 0.0},
                             {"angular_velocity": {"t": [0.0, 0.3, 1.3, 1.6],
                                                   "value": [0.0, 2.0, 2.0, 0.0]}}]}
TENSIONED_END = {"translation": [{"velocity": 0.0}, {"velocity": 0.0}, {"force": 1.0}],
                 "rotation": [{"angular_velocity": 0.0}] * 3}


@pytest.mark.parametrize("rho_inf", [0.0, 0.5, 1.0])
def test_work_in_is_the_schemes_discrete_work_at_large_dt(rho_inf):
    # a straight rod twisted by a rate table whose corners fall inside Δt = 1 s steps (the
    # steps land on them: breakpoints): its energy is exactly the discrete work
    # Σ ½(qⁿ + qⁿ⁺¹)·Δφ of the scheme; a trapezoid of the power q·ω at the levels missed it
    # by 5-11 % here (docs/numerics.md § 6). ρ∞ < 1 dissipates: 1.0e-4 of the work at
    # ρ∞ = 0 with the restarts at the corners.
    case = make_case(n_segments=20, dt=1.0, t_end=3.0, rho_inf=rho_inf, start=RAMPED_TWIST,
                     end=TENSIONED_END, fields=("kappa", "energies"))
    ds = integrate(case)
    e, w = ds.energy_total.values, ds.work_in.values
    assert w[-1] > 0.1
    if rho_inf == 1.0:                               # no numerical dissipation
        np.testing.assert_allclose(e, w, rtol=1e-6, atol=1e-9 * w[-1])
    else:                                            # ρ∞ < 1 only ever removes energy
        assert np.all(e <= w + 1e-9 * w[-1])
        assert np.all(w - e <= 3e-4 * w[-1])


def test_work_of_gravity_balances_energy_to_second_order_in_ds():
    # a cantilever falling under gravity in vacuum at ρ∞ = 1 (no numerical dissipation),
    # through large rotations: the energy (elastic + kinetic; gravity's potential is not
    # in it) equals the work of gravity up to the box rule's O(Δs²) error for a load that
    # follows the pose (measured 2.9 %, 0.80 %, 0.25 % at 20, 40, 80 segments; the same
    # with Δt halved)
    free = {"translation": [{"force": 0.0}] * 3, "rotation": [{"moment": 0.0}] * 3}
    gaps = []
    for n in (20, 40, 80):
        case = make_case(n_segments=n, dt=0.01, t_end=1.0, rho_inf=1.0, end=free,
                         gravity=[9.81, 0.0, 0.0], fields=("position", "energies"), every=5)
        ds = integrate(case)
        e, w = ds.energy_total.values, ds.work_in.values
        assert float(np.abs(ds.position.values[-1, -1, 0])) > 0.1      # large deflection
        gaps.append(float(np.max(np.abs(e - w))) / float(w[-1]))
    assert gaps[-1] < 5e-3
    assert gaps[0] / gaps[1] > 2.8 and gaps[1] / gaps[2] > 2.8


# ------------------------------------------------------------------ the Newton start
def test_newton_starts_extrapolate_the_accepted_levels_exactly():
    """ProblemAssembly._predictions: the line through the last two levels and the parabola through
    the last three (unequal steps) reproduce a state that is linear / quadratic in t."""
    from solver.simulation import RodRun
    run = RodRun(make_case(n_segments=4, end=SLIDING_END))
    base = np.random.default_rng(1).standard_normal((2, 5, 12))
    t2, t1, t0, h = -0.5, -0.2, 0.0, 0.3                  # levels at t0 − h1 − h2, t0 − h1, t0
    quad = lambda t: base[0] + base[1] * t + 0.7 * t * t      # noqa: E731
    lin = lambda t: base[0] + base[1] * t                     # noqa: E731
    for state, kinds in ((quad, ("quadratic",)), (lin, ("linear", "quadratic"))):
        st = run.state
        st.Y_prev2, st.Y_prev, st.Y = state(t2), state(t1), state(t0)
        st.h_prev2, st.h_prev = t1 - t2, t0 - t1
        pred = run.assembly._predictions(st, h)
        for kind in kinds:
            np.testing.assert_allclose(pred[kind], state(h), atol=1e-12)
    assert np.abs(pred["linear"] - quad(h)).max() > 0.01
    st.Y_prev2 = None                                        # after a restart: the line only
    assert set(run.assembly._predictions(st, h)) == {"linear"}


def test_kappa_distance_is_the_sum_of_squares_of_the_curvature_difference():
    """solver.stepping.kappa_distance: Σ |κ(Y) − κ(G)|² over the nodes (columns 9-11),
    blind to the other nine unknowns."""
    from solver.stepping import kappa_distance
    rng = np.random.default_rng(3)
    Y, G = rng.standard_normal((2, 7, 12))
    expected = float(np.sum((Y[:, 9:12] - G[:, 9:12]) ** 2))
    assert kappa_distance(Y, G) == pytest.approx(expected, rel=1e-14)
    G[:, 0:9] += 5.0
    assert kappa_distance(Y, G) == pytest.approx(expected, rel=1e-14)
    assert kappa_distance(Y, Y) == 0.0


def test_total_and_kinetic_are_the_energies_total_and_its_kinetic_parts():
    """solver.energies.total_and_kinetic (the energy check's figures) gives energies()'s
    total and the sum of its two kinetic parts (the rod's and the added mass's), for a
    tapered rod in water."""
    from solver import simulation as sim
    from solver.energies import energies, total_and_kinetic
    run = sim.RodRun(make_case(n_segments=6, end=SLIDING_END,
                               diameter={"s": [0.0, 1.0], "value": [0.02, 0.01]},
                               fluid={"density": 1000.0, "added_mass_coefficient": 1.0}))
    Y = np.random.default_rng(5).standard_normal((7, 12))
    e = energies(Y, run.props)
    total, kinetic = total_and_kinetic(Y, run.props)
    assert total == pytest.approx(e["energy_total"], rel=1e-14)
    assert kinetic == pytest.approx(e["energy_kinetic"] + e["energy_kinetic_fluid"],
                                    rel=1e-14)
    assert e["energy_kinetic_fluid"] > 0.0 and kinetic > e["energy_kinetic_fluid"]


def test_the_newton_start_follows_the_predictor_that_placed_kappa_better():
    """The next step starts from whichever extrapolation put the last accepted step's κ
    nearer (κ sets the centreline and every contact gap), whatever the other unknowns
    do; on a smoothly swung cantilever the choice saves Newton iterations against the
    line alone (114 against 123 measured) and converges to the same motion."""
    from solver import simulation as sim
    from rodcases import smooth_pulse_table
    run = sim.RodRun(make_case(n_segments=4, end=SLIDING_END))
    Y = np.zeros((5, 12))
    near_kappa, near_rest = Y.copy(), Y.copy()
    near_kappa[:, 9:12] = 1e-6
    near_kappa[:, 0:9] = 1.0                                  # far in v, ω, f
    near_rest[:, 9:12] = 1e-3
    assert run.assembly._better_predictor(Y, {"linear": near_rest, "quadratic": near_kappa}) == "quadratic"
    assert run.assembly._better_predictor(Y, {"linear": near_kappa, "quadratic": near_rest}) == "linear"

    end = {"translation": [{"force": smooth_pulse_table(0.02, 1.0)}, {"force": 0.0},
                           {"force": 0.0}], "rotation": [{"moment": 0.0}] * 3}
    case = make_case(n_segments=20, dt=0.02, t_end=1.0, end=end, fields=("position",))
    chosen = integrate(case)
    from solver.step_problem import ProblemAssembly
    original = vars(ProblemAssembly)["_better_predictor"]        # the staticmethod itself
    ProblemAssembly._better_predictor = staticmethod(lambda Y, predictions: "linear")
    try:
        line = integrate(case)
    finally:
        ProblemAssembly._better_predictor = original
    its_chosen = int(chosen.step_newton_iterations.sum())
    its_line = int(line.step_newton_iterations.sum())
    assert its_chosen < its_line, (its_chosen, its_line)
    np.testing.assert_allclose(chosen.position.values, line.position.values, atol=1e-9)


def test_warm_up_loads_every_compiled_kernel():
    """solver.warm_up calls each numba kernel of the solver (found by scanning its
    modules), so a timed run after it pays no compilation or cache loading. Checked in a
    fresh interpreter: in this one, earlier tests may have called the kernels already."""
    import subprocess
    import sys
    import textwrap

    script = textwrap.dedent("""
        import importlib, json
        from numba.core.registry import CPUDispatcher
        from solver import warm_up
        warm_up()
        kernels = []
        for name in ("solver.topology", "solver.kinematics", "solver.scheme", "solver.loads",
                     "solver.newton", "solver.contact.geometry", "solver.contact.model",
                     "solver.contact.laws", "solver.banded", "solver.energies",
                     "solver.static_band", "solver.centreline_loads"):
            module = importlib.import_module(name)
            kernels += [(name, k, bool(v.signatures)) for k, v in vars(module).items()
                        if isinstance(v, CPUDispatcher) and v.py_func.__module__ == name]
        print(json.dumps(kernels))
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True, cwd=str(Path(__file__).resolve().parents[2]))
    kernels = json.loads(out.stdout.strip().splitlines()[-1])
    # kernels called only from other kernels (compiled into their callers; loaded from
    # the cache they have no signatures of their own); Newton's linear-algebra kernels
    # are called from Python only by its test hooks (NewtonSolver.linearize, operator, gmres)
    helpers = {"solver.topology._pair_setup", "solver.topology._distance_row",
               "solver.topology._row_far", "solver.topology._pair_direct",
               "solver.topology._rows", "solver.topology._chunk_bounds",
               "solver.scheme._skew_into", "solver.scheme._mass_row", "solver.scheme._flux_row",
               "solver.scheme._flux_kernel",
               "solver.scheme._mat3", "solver.scheme._qmul", "solver.scheme._node_jacobian_kernel",
               "solver.scheme._node_forces_kernel", "solver.scheme._cells_kernel",
               "solver.scheme._cell_blocks_kernel", "solver.scheme._add_inertia_cell",
               "solver.scheme._contact_band_kernel",
               "solver.scheme._exact_frames_kernel", "solver.scheme.exact_loads_product",
               "solver.scheme._seabed_product",
               "solver.kinematics._exp_one", "solver.kinematics._matrix_into",
               "solver.kinematics._right_jacobian_into", "solver.loads._drag_kernel",
               "solver.loads.point_loads_into",
               "solver.contact.laws.law_potential", "solver.contact.laws._repulsion_integral",
               "solver.centreline_loads._node_load", "solver.centreline_loads._node_motion",
               "solver.centreline_loads._increment",
               "solver.newton._matvec_kernel", "solver.newton._set_operator",
               "solver.newton._factor", "solver.newton._matvec", "solver.newton._dot",
               "solver.newton._turning_entries",
               "solver.newton._gmres", "solver.newton._back_substitute",
               "solver.newton._norm_scaled", "solver.newton._max_scaled",
               "solver.newton._trial_gaps", "solver.newton._feasible_fraction",
               "solver.newton._current_gaps", "solver.newton._gaps_kept",
               "solver.newton._position_converged",
               "solver.contact.geometry._project", "solver.contact.geometry._run_minimum",
               "solver.contact.geometry._curve_point", "solver.contact.geometry._run_point",
               "solver.contact.model._run_bounds", "solver.contact.model._at_contact",
               "solver.contact.model._separation", "solver.contact.model._segment_distance",
               "solver.contact.model._relative_move",
               "solver.contact.model._swept_segments_within",
               "solver.contact.model._pairs_that_may_meet",
               "solver.contact.laws._smoothstep", "solver.contact.laws._barrier_p",
               "solver.contact.laws._repulsion", "solver.contact.laws.law_cutoff",
               "solver.contact.laws.law_force", "solver.banded.copy_into",
               "solver.banded.fill", "solver.banded.true_at_run_time",
               "solver.banded.int_at_run_time",
               "solver.banded._eliminate", "solver.banded._window",
               "solver.banded._pivot",
               "solver.static_band._rotation", "solver.static_band._cell"}
    names = {f"{m}.{k}" for m, k, _ in kernels}
    assert helpers <= names and len(names - helpers) >= 14, names
    missing = [f"{m}.{k}" for m, k, loaded in kernels
               if f"{m}.{k}" not in helpers and not loaded]
    assert not missing, missing
