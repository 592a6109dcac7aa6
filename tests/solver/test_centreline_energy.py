"""The work put in on the centreline scheme (``work_in``) is the scheme's discrete work."""
from pathlib import Path

import numpy as np

from solver.case import Case
from solver.simulation import integrate
from test_verification import CLAMPED, CLAMPED_SLIDING, VIB_D, force_pulse, make_spec

ROOT = Path(__file__).resolve().parents[2]


def _centreline(case_or_spec, **numerics) -> Case:
    spec = (case_or_spec.model_dump(mode="json") if isinstance(case_or_spec, Case)
            else case_or_spec)
    spec["numerics"].update(formulation="centreline", **numerics)
    return Case.model_validate(spec)


def test_the_work_of_a_load_switched_off_at_a_breakpoint_is_not_counted_after_it():
    """A sin² pulse of distributed force made of windows [(k−½)Δt, (k+½)Δt] on the
    clamped-sliding beam of tests/solver/test_verification.py (ρ∞ 1, linear amplitude):
    a window is in force at its end, where the step after it has none, so the work's old
    level takes the load's right limit there; read at the breakpoint it counted each
    window's load over the following half step (work_in 26 % above the energy). What is
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
