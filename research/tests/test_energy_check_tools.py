"""The energy check's study tools (research/energy_check.py): the per-step accounts of
PyElastica's plectoneme read the accepted steps' balances (a few seconds of runs)."""
from __future__ import annotations

import numpy as np
import pytest

from research import energy_check as ec


def test_plectoneme_accounts_are_the_accepted_steps_and_close_before_contact():
    """Without contact yet (to 7 s: the twist loads the rod, it buckles at ~6.7 s) only
    the end moment puts energy in, and ε is the scheme's and the drag's dissipation: a
    few per cent of the end's work, never a gain (measured at N = 25, Δt = 0.1 s,
    ρ∞ = 0.5: ε = −0.50 J against 14.6 J). The rows are the accepted steps, one per
    step in time order up to t_end, and each row's ε is its ΔE less its accounts."""
    status, rows = ec.plectoneme_accounts(25, 0.1, 0.5, t_end=7.0)
    assert status == "completed"
    t = rows[:, 0]
    assert np.all(np.diff(t) > 0) and t[-1] == pytest.approx(7.0)
    assert np.allclose(rows[:, 5] - rows[:, 1:5].sum(axis=1), rows[:, 6], atol=1e-12)
    ends, eps = rows[:, 1].sum(), rows[:, 6].sum()
    assert ends > 10.0                                # J: the turned end's work
    assert -0.1 * ends < eps < 0.0
    assert np.all(rows[:, 8] == pytest.approx(0.0, abs=1e-2))   # no drift to correct


def test_without_the_end_correction_the_end_velocities_do_no_work():
    """With the s = L end's drift correction off, the held end's prescribed velocities
    are the case's (zero laterally, the axial force zero), so the end forces' work on
    the end velocities vanishes; the setting is restored after the run."""
    from solver.step_problem import ProblemAssembly
    gain = ProblemAssembly.DRIFT_GAIN
    status, rows = ec.plectoneme_accounts(25, 0.1, 0.5, correction=False, t_end=7.5)
    assert ProblemAssembly.DRIFT_GAIN == gain
    assert status == "completed"
    assert np.all(np.abs(rows[:, 8]) < 1e-9)
