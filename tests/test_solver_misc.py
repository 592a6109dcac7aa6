"""Regression tests of solver details: linking number bookkeeping, failure reasons."""
import numpy as np
import pytest

from rodcases import make_case
from solver import SolverDivergence, simulate

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
    ds = simulate(case)
    assert np.all(np.abs(ds.writhe.values) < 1e-12)
    np.testing.assert_allclose(ds.linking_number, ds.twist, atol=1e-12)
    assert float(ds.linking_number[-1]) < 0.0          # +ω3 at s = 0 gives Lk < 0


def test_singular_boundary_conditions_are_named():
    # a straight inextensible rod held axially at both ends: the tension is undetermined
    held = {"translation": [{"velocity": 0.0}] * 3, "rotation": [{"angular_velocity": 0.0}] * 3}
    case = make_case(n_segments=8, dt=0.01, t_end=0.02, start=TWIST_START, end=held,
                     fields=("kappa",), max_dt_cuts=1)
    with pytest.raises(SolverDivergence) as info:
        simulate(case)
    assert info.value.reason == "solver_diverged"
    assert "singular Jacobian" in str(info.value)
    assert info.value.partial is not None and info.value.partial.attrs["hockle_status"] == "failed"
