"""Observed order of accuracy of the box / generalized-α scheme (docs/numerics.md).

A smooth, strongly nonlinear case: a cantilever in water whose clamped base is swung
through about one radian about a1 (and twisted about a3) by a sin² angular-velocity
pulse, so the free end travels along a large arc. Errors are measured on the positions
at t = 1 s against a reference with the same Δs (time refinement) or the same Δt
(space refinement), so each study sees one discretisation error only. The order is the
slope of a least-squares fit of log error against log step over four refinements.
"""
import numpy as np
import pytest

from rodcases import free_end, make_case, smooth_pulse_table
from solver.simulation import integrate

FLUID = {"density": 1000.0, "added_mass_coefficient": 1.0,
         "drag_coefficient_normal": 1.0, "drag_coefficient_tangential": 0.05}


def tip_case(n_segments, dt, rho_inf):
    start = {"translation": [{"velocity": 0.0}] * 3,
             "rotation": [{"angular_velocity": smooth_pulse_table(2.0, 1.0)},
                          {"angular_velocity": 0.0},
                          {"angular_velocity": smooth_pulse_table(1.0, 1.0)}]}
    return make_case(n_segments=n_segments, dt=dt, t_end=1.0, rho_inf=rho_inf,
                     start=start, end=free_end(), fluid=FLUID, fields=("position",),
                     every=max(1, round(1.0 / dt)), tolerance=1e-12)  # the ends only


def final_positions(n_segments, dt, rho_inf):
    ds = integrate(tip_case(n_segments, dt, rho_inf))
    assert ds.attrs["hockle_status"] == "completed"
    return ds.position.isel(time=-1).values


def fitted_order(steps, errors):
    return np.polyfit(np.log(steps), np.log(errors), 1)[0]


@pytest.mark.parametrize("rho_inf", [0.0, 0.5, 1.0])
def test_second_order_in_time(rho_inf):
    n = 40
    ref = final_positions(n, 1.0 / 1280, rho_inf)
    dts = [1.0 / 40, 1.0 / 80, 1.0 / 160, 1.0 / 320]
    errors = [np.abs(final_positions(n, dt, rho_inf) - ref).max() for dt in dts]
    order = fitted_order(dts, errors)
    assert abs(order - 2.0) <= 0.2, (order, errors)
    # the motion is large: the tip moves by about 0.4 m, so this is not a linear test
    assert np.linalg.norm(ref[-1] - [0.0, 0.0, 1.0]) > 0.1


@pytest.mark.parametrize("rho_inf", [0.0, 0.5, 1.0])
def test_second_order_in_arclength(rho_inf):
    dt = 1.0 / 200
    ref = final_positions(320, dt, rho_inf)
    ns = [10, 20, 40, 80]
    errors = [np.abs(final_positions(n, dt, rho_inf) - ref[:: 320 // n]).max() for n in ns]
    order = fitted_order([1.0 / n for n in ns], errors)
    assert abs(order - 2.0) <= 0.2, (order, errors)
