"""The energy check on the centreline scheme (``numerics.energy_tolerance``,
:class:`solver.balance.CentrelineBalance`): right runs are not refused, a step that puts
in energy no load gave is, and the discrete work it compares with is the scheme's."""
import math
from pathlib import Path

import numpy as np
import pytest

from solver.case import Case
from solver.simulation import integrate
from test_centreline import _column_spec
from test_energy_check import X_TIP, cantilever
from test_verification import CLAMPED, CLAMPED_SLIDING, VIB_D, force_pulse, make_spec

ROOT = Path(__file__).resolve().parents[2]


def _centreline(case_or_spec, **numerics) -> Case:
    spec = (case_or_spec.model_dump(mode="json") if isinstance(case_or_spec, Case)
            else case_or_spec)
    spec["numerics"].update(formulation="centreline", **numerics)
    return Case.model_validate(spec)


@pytest.mark.parametrize("dt", [0.2, 0.04])
def test_the_dead_load_cantilever_settles_at_every_step_without_a_refusal(dt):
    """Issue 41's cantilever (P L²/EI = 10 ramped on over 2 s, ρ∞ = 0, 20 segments), whose
    large steps pump energy into the seed scheme (at Δt = 0.2 s its tip ends 47 % off
    without the check): on the centreline every Δt settles on the elastica's tip
    (measured 0.13 % off on 20 segments, 0.004 % on 100, at Δt 0.02-0.2 s) with no step
    refused, the check measuring every step (largest ε/scale 0.4 on 100 segments)."""
    ds = integrate(_centreline(cantilever(dt)))
    assert ds.attrs["hockle_status"] == "completed"
    assert ds.attrs["hockle_refused_attempts"] == ""
    assert np.all(np.isfinite(ds.step_energy_error.values))
    assert abs(ds.position.values[-1, -1, 2] / X_TIP - 1) < 2e-3
    assert ds.energy_kinetic.values[-1] < 1e-8 * ds.energy_total.values[-1]


def test_a_growth_within_a_step_is_refused_without_the_guard():
    """The clamped column at 1.5 P_cr at Δt = 1 s (σΔt = 3.7), ρ∞ 0, without the growth
    guard: unchecked the run ends straight (the silent failure of
    tests/solver/test_centreline.py); with the check the steps whose buckle starts are
    refused for energy and cut, and the column buckles."""
    spec = _column_spec(20, 0.0, guard=None)
    checked = integrate(Case.model_validate(spec))
    assert checked.attrs["hockle_status"] == "completed"
    assert "energy" in checked.attrs["hockle_refused_attempts"]
    assert np.abs(checked.position.values[:, :, 0]).max() > 0.3
    spec["numerics"]["energy_tolerance"] = None
    off = integrate(Case.model_validate(spec))
    assert np.abs(off.position.values[:, :, 0]).max() < 2e-3


def test_the_first_fall_onto_the_spring_at_a_large_step_is_refused():
    """cases/catenary-touchdown.yaml (laid at zero penetration, ρ∞ 0, Δt 0.05 s): its first
    step lands the lying cable on the bottom's spring, a mode far beyond the step, and
    generalized-α's first-step velocity overshoot leaves 9.3e-4 J of kinetic energy at
    0.05 s where Δt/4 and Δt/16 give 3.7e-6 and 4.1e-6 J (measured). The check refuses it
    and the nominal step's cut steps end with the resolved one."""
    case = Case.from_file(ROOT / "cases" / "catenary-touchdown.yaml")
    t = {}
    for tol in (0.5, None):
        spec = case.model_dump(mode="json")
        spec["output"]["every"] = 1
        ds = integrate(_centreline(spec, t_end=0.1, energy_tolerance=tol))
        t[tol] = ds.energy_kinetic.values[1] + ds.energy_kinetic_fluid.values[1]
        if tol is not None:
            assert ds.attrs["hockle_refused_attempts"].startswith("energy")
    assert t[None] > 5e-4
    assert t[0.5] < 1e-5


def test_the_work_of_a_load_switched_off_at_a_breakpoint_is_not_counted_after_it():
    """A sin² pulse of distributed force made of windows [(k−½)Δt, (k+½)Δt] on the
    clamped-sliding beam of tests/solver/test_verification.py (ρ∞ 1, linear amplitude):
    the work's old level takes the load's right limit; read at the breakpoint (where the
    static rows took a window's end as inside it, next test) it counted each window's
    load over the following half step (work_in 26 % above the energy). What is
    left (0.5 %) is the restarts', whose Taylor steps re-solve n and m at each
    breakpoint (not measured by the check)."""
    spec = make_spec(start=CLAMPED, end=CLAMPED_SLIDING, n_segments=100, dt=2e-3,
                     t_end=0.06, rho_inf=1.0, diameter=VIB_D,
                     forces=force_pulse(2e-3, 0.05, 2e-3, direction=(0.8, 0.6, 0.0)),
                     fields=("energies",))
    ds = integrate(_centreline(spec))
    e, w = ds.energy_total.values[-1], ds.work_in.values[-1]
    assert abs(e / w - 1) < 1e-2
    assert ds.attrs["hockle_refused_attempts"] == ""


def test_a_twisted_rod_is_not_refused_for_the_box_rules_energy():
    """A clamped rod turned by 2 rad at one end over a second in water (the twisted case
    of tests/solver/test_centreline.py, 20 segments, hκ3 = 0.1 at the end): the
    trapezoid's torsion energy and the end moment's work along the Cayley map's turns
    part at O((hκ)²) of each step's ΔU_el, more than 1e-5 E, which the check's scale
    allows; the end's work is the torsion energy at rest within 1e-3."""
    from test_centreline import _twisted_spec

    ds = integrate(Case.model_validate(_twisted_spec()))
    assert ds.attrs["hockle_status"] == "completed"
    assert "energy" not in ds.attrs["hockle_refused_attempts"]
    assert np.nanmax(ds.step_energy_error.values) < 0.5
    assert math.isclose(ds.energy_total.values[-1], ds.work_in.values[-1], rel_tol=1e-3)


def test_a_load_window_is_off_at_its_end_in_the_static_rows():
    """A distributed force and a point load for start <= t < end (the case language's
    window, solver.case.DistributedForce.is_active) in the rows the centreline scheme
    and the statics read (solver.statics.problem_at): on just before the end, off at
    it (the rows took the end as inside the window)."""
    from solver.centreline import CentrelineRod

    spec = make_spec(start=CLAMPED, end=CLAMPED_SLIDING, n_segments=10, dt=2e-3,
                     t_end=0.06, rho_inf=1.0, diameter=VIB_D,
                     forces=[{"value": [1.6e-3, 1.2e-3, 0.0], "start": 0.01, "end": 0.025}])
    spec["point_loads"] = [{"s": 0.5 * spec["rod"]["length"], "value": [0.0, 0.0, 1.0],
                            "start": 0.01, "end": 0.025}]
    rod = CentrelineRod.from_case(_centreline(spec))
    on, at_end = rod.problem(0.0249).load, rod.problem(0.025).load
    assert np.abs(on).max() > 1e-3
    assert not at_end.any()
    assert np.abs(rod.problem(0.01).load).max() > 1e-3        # on from its start
