"""The resolution study of cases/seabed-hockle.yaml (research/hockle_resolution.py):
its members are the case on other grids, the start pose's distance from the given
centreline that docs/case-spec.md quotes (no run), and the untwisted lay's study cut
short (a few seconds of runs)."""
from __future__ import annotations

import pytest

from research import hockle_resolution as hr

from solver.case import Case


@pytest.mark.parametrize("segments, dt, every", [(160, 0.05, 1), (320, 0.0125, 4)])
def test_members_are_the_case_on_another_grid(segments, dt, every):
    case = Case.model_validate(hr.spec_for(segments, dt, 4.5))
    base = Case.from_file(hr.CASE)
    assert (case.numerics.n_segments, case.numerics.dt, case.numerics.t_end) == (segments, dt, 4.5)
    assert case.output.every == every                  # an output every 0.05 s
    assert case.seabed.friction == base.seabed.friction
    assert case.initial.twist_rate == base.initial.twist_rate
    smooth = Case.model_validate(hr.spec_for(segments, dt, 5.0, friction=False))
    assert smooth.seabed.friction is None
    twisted = Case.model_validate(hr.spec_for(segments, dt, 4.5, change=hr.CHANGES["twist rate × 1.001"]))
    assert twisted.initial.twist_rate == pytest.approx(1.001 * base.initial.twist_rate)
    damped = Case.model_validate(hr.spec_for(segments, dt, 4.5, change=hr.CHANGES["ρ∞ 0.45"]))
    assert damped.numerics.rho_inf == 0.45


def _offsets(segments):
    """(Δs·τ0, twisted end offset mm, twisted height mm, untwisted end mm, height mm)."""
    phi, end, height = hr.start_pose_offsets(segments)
    _, flat_end, flat_height = hr.start_pose_offsets(segments, twist=False)
    return phi, end * 1e3, height * 1e3, flat_end * 1e3, flat_height * 1e3


def test_the_twisted_start_is_second_order_with_a_constant_set_by_the_twist():
    """The half-sine lay with 9.42 rad/m: its start pose's s = L end is off the
    centreline's last point by ~1.5 mm at 160 segments, 4x less at twice the segments,
    and by a few µm without the twist (docs/case-spec.md)."""
    phi80, end80, z80, flat80, _ = _offsets(80)
    phi160, end160, z160, flat160, zflat160 = _offsets(160)
    assert phi160 == pytest.approx(0.236, abs=1e-3) and phi80 == pytest.approx(2 * phi160, abs=2e-3)
    assert end160 == pytest.approx(1.46, rel=0.02)
    assert end80 / end160 == pytest.approx(4.0, rel=0.05)
    assert z80 / z160 == pytest.approx(4.0, rel=0.05)
    assert flat80 < 0.01 and flat160 < 0.01 and zflat160 < 1e-6   # mm


def test_the_untwisted_lay_study_measures_against_the_finest_run_and_the_unscaled_start():
    """hockle_resolution.untwisted_lay (docs/contact.md, "Where the correction fed the
    drift"), cut short: each run's largest node distance at 1.5 s from the finest run's
    (0 for the finest itself, millimetres for the coarser), and the scaled imperfection's
    from the unscaled run's, which at ρ∞ = 0 grows with the change (observed at
    Δt = 0.05 s: 1.1 µm for 1 + 10⁻⁶, 2.5 mm for 1 + 10⁻³)."""
    import re

    lines = hr.untwisted_lay(steps=(0.05, 0.025), t_end=1.6, rho_inf=0.0,
                             sensitivity_dt=0.05)
    assert len(lines) == 4
    assert all(": completed, " in line for line in lines)
    at = [float(re.search(r"1\.5 s ([0-9.e+-]+) mm", line).group(1)) for line in lines]
    coarse, finest, small, large = at
    assert finest == 0.0
    assert coarse > 1.0
    assert small < 0.01
    assert large > 100 * small


def test_the_route_difference_study_shrinks_with_the_grid():
    """hockle_resolution.route_difference (docs/contact.md, "Where the correction fed the
    drift"), cut short to 1.6 s on coarse grids: each line reports a completed run, and
    the two routes part about four times less on twice the segments (observed: 2.88 mm on
    40, 0.97 mm on 80 segments at Δt = 5 ms)."""
    import re

    lines = hr.route_difference(grids=((40, 0.005), (80, 0.005)), t_end=1.6)
    assert len(lines) == 2 and all(": completed, " in line for line in lines)
    apart = [float(re.search(r"routes apart ≤ ([0-9.e+-]+) mm", line).group(1))
             for line in lines]
    assert apart[0] > 1.0
    assert apart[0] / apart[1] > 2.5


def test_the_correction_time_holds_the_rate_floor_for_the_run_and_restores_it(monkeypatch):
    """``correction_time`` sets ProblemAssembly.DRIFT_STEP_FLOOR to T/Δt for each run (the
    rate g/max(h, T, T_w) whatever Δt) and puts the code's floor back after; ``segments``
    sets every run's grid."""
    from solver.step_problem import ProblemAssembly

    seen = []
    real = hr._run

    def spy(spec):
        seen.append((spec["numerics"]["dt"], ProblemAssembly.DRIFT_STEP_FLOOR,
                     spec["numerics"]["n_segments"]))
        return real(spec)

    floor = ProblemAssembly.DRIFT_STEP_FLOOR
    monkeypatch.setattr(hr, "_run", spy)
    lines = hr.untwisted_lay(steps=(0.05, 0.025), t_end=0.1, rho_inf=0.0,
                             sensitivity_dt=0.05, correction_time=0.002, segments=80)
    assert ProblemAssembly.DRIFT_STEP_FLOOR == floor
    assert len(lines) == 4
    assert len(seen) == 4
    for dt, used, segments in seen:
        assert used * dt == pytest.approx(0.002)
        assert segments == 80
