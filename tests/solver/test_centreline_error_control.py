"""Error-controlled steps on the centreline scheme (``numerics.tolerance`` with
``numerics.formulation: centreline``; :class:`solver.stepping.DisplacementErrorControl`,
:meth:`solver.centreline_run.CentrelineRun.step_adaptive`; docs/numerics.md § 9)."""
import numpy as np
import pytest

from solver import Case, integrate
from solver.centreline_run import CentrelineRun, interpolated_level
from solver.stepping import error_constant
from test_step_control import pulse_case


def _centreline(case_or_spec, **numerics):
    spec = case_or_spec.model_dump() if isinstance(case_or_spec, Case) else case_or_spec
    spec["numerics"].update(formulation="centreline", **numerics)
    return Case.model_validate(spec)


@pytest.mark.parametrize("rho_inf", [0.0, 0.5, 1.0])
def test_the_estimate_is_the_local_error_of_a_step(rho_inf):
    """C(ρ∞) h² (a_n+1 − a_n) against the positions' true local error (one step of h
    against 64 of h/64 from the same level of the swung cantilever, 0.3 s into its swing).
    Measured: the largest estimate 0.66-1.17 of the largest error at h = 0.02 and 0.01 s,
    ρ∞ 0, 0.5, 1; the error falls by 6.8-7.4 per halving (h³: 8)."""
    run = CentrelineRun(_centreline(pulse_case(None, 0.01), rho_inf=rho_inf))
    rod, level = run.rod, run.level
    for _ in range(60):
        level = rod.step(level, 0.005)[0]
    errors = []
    for h in (0.02, 0.01):
        one = rod.step(level, h)[0]
        fine = level
        for _ in range(64):
            fine = rod.step(fine, h / 64)[0]
        true = np.abs(one.Y[:, 0:3] - fine.Y[:, 0:3]).max()
        est = np.abs(error_constant(rho_inf) * h * h * (one.a[:, 0:3] - level.a[:, 0:3])).max()
        assert 0.5 < est / true < 1.5, (h, est, true)
        errors.append(true)
    assert 5.5 < errors[0] / errors[1] < 10.0, errors


def test_achieved_error_follows_the_tolerance():
    """The swung cantilever (tip travels ~0.4 m): final positions against a fixed
    Δt = 1/1280 s run. Measured: tolerance 1e-2 -> 1.05e-2, 1e-3 -> 2.5e-3, 1e-4 ->
    7.6e-4 of the travel in 10, 18 and 34 steps (fixed steps of 1/40 s: 4.2e-4 in 40):
    a local error per step, so the global error falls as tol^(2/3) with a second-order
    scheme."""
    ref = integrate(_centreline(pulse_case(dt=1.0 / 1280))).position.isel(time=-1).values
    errors, steps = [], []
    for tol in (1e-2, 1e-3, 1e-4):
        ds = integrate(_centreline(pulse_case(tol)))
        assert ds.attrs["hockle_status"] == "completed"
        errors.append(np.abs(ds.position.isel(time=-1).values - ref).max() / 0.4)
        steps.append(ds.sizes["step"])
        assert 0.1 * tol < errors[-1] < 10 * tol, (tol, errors)
    assert errors[0] > 3 * errors[1] > 9 * errors[2]
    assert steps[0] < steps[1] < steps[2]


def test_dense_output_agrees_with_landing_within_the_tolerance():
    """The swung cantilever at tolerance 1e-3 with the state every 1/16 s: dense output
    (not bounded by the outputs) against steps landing on them; both against a fixed
    Δt = 1/1280 s run at every output. Measured: 5.0e-3 and 4.7e-3 of the travel, in 18
    and 19 steps."""
    ref = integrate(_centreline(pulse_case(dt=1.0 / 1280)))
    at = ref.position.values[np.arange(17) * 80]
    steps = {}
    for interpolate in (True, False):
        spec = pulse_case(1e-3).model_dump()
        spec["output"].update(interval=1.0 / 16, interpolate=interpolate)
        ds = integrate(_centreline(spec))
        assert ds.attrs["hockle_status"] == "completed"
        steps[interpolate] = ds.sizes["step"]
        np.testing.assert_allclose(ds.time.values, np.arange(17) / 16, atol=1e-12)
        err = np.abs(ds.position.values - at).max() / 0.4
        assert err < 1e-2, (interpolate, err)
    assert steps[True] < steps[False]


def test_the_interpolated_level_is_exact_for_a_steady_spin_and_a_uniform_fall():
    """A frame turning at a constant body angular velocity W and a node falling at a
    constant acceleration: the dense output's frames p_n ⊗ exp(ψ(t)) and positions are
    exact (ψ(t) = W (t − t_n), the inverse right Jacobian leaving W unchanged)."""
    from solver.centreline import CentrelineState
    from solver.centreline_run import _quaternion_exp
    from solver.statics import _qmul

    W = np.array([[0.3, -1.2, 2.0]])
    p0 = _quaternion_exp(np.array([[0.4, 0.1, -0.7]]))
    g = np.array([0.0, 0.0, -9.81])
    r0, v0 = np.array([[1.0, 2.0, 3.0]]), np.array([[0.5, 0.0, 1.0]])

    def level(t):
        Y = np.zeros((1, 13))
        Y[:, 0:3] = r0 + v0 * t + 0.5 * g * t * t
        Y[:, 3:7] = _qmul(p0, _quaternion_exp(W * t))
        X = np.concatenate([v0 + g * t, W], axis=1)
        Xd = np.concatenate([g[None, :], np.zeros((1, 3))], axis=1)
        return CentrelineState(t, Y, X, Xd, Xd.copy())

    mid = interpolated_level(level(0.0), level(0.8), 0.3)
    want = level(0.3)
    np.testing.assert_allclose(mid.Y[:, 0:3], want.Y[:, 0:3], atol=1e-12)
    np.testing.assert_allclose(mid.Y[:, 3:7] * np.sign(mid.Y[0, 0] * want.Y[0, 0]),
                               want.Y[:, 3:7], atol=1e-12)
    np.testing.assert_allclose(mid.X, want.X, atol=1e-12)


def test_a_twist_error_is_measured_against_the_twist_the_rod_holds():
    """The turns' sizes are at least the bending and twist the rod holds (∫|κ| ds): a
    uniform twist error of 5e-3 rad is half the tolerance of a rod holding 10 rad of
    twist at relative 1e-3, fifty times it with 0.1 rad; positions are measured against
    their own displacement, a lateral one of 1e-5 m before a buckling at absolute 1e-6."""
    from solver.stepping import DisplacementErrorControl

    s = np.linspace(0.0, 1.0, 21)
    ctl = DisplacementErrorControl(1e-3, 1e-6, 1.0, 0.5, s)
    moved = np.zeros((21, 6))
    error = np.zeros((21, 6))
    error[:, 5] = 5e-3
    assert ctl.ratio(error, ctl.sizes(moved, np.array([0.0, 10.0]))) == pytest.approx(0.5, rel=1e-3)
    assert ctl.ratio(error, ctl.sizes(moved, np.array([0.0, 0.1]))) == pytest.approx(50.0, rel=1e-2)
    moved[:, 0] = 1e-5
    error[:] = 0.0
    error[:, 0] = 1e-6
    assert ctl.ratio(error, ctl.sizes(moved, np.zeros(2))) == pytest.approx(1e-6 / (1e-6 + 1e-8))
    ctl.push(ctl.sizes(moved, np.array([0.0, 10.0])))
    error[:] = 0.0
    error[:, 5] = 5e-3
    # the peak stays once the twist is released
    assert ctl.ratio(error, ctl.sizes(0.0 * moved, np.zeros(2))) == pytest.approx(0.5, rel=1e-3)


def test_dense_output_keeps_the_linking_number_identity():
    """The clamped rod of test_centreline twisted by a rate rising to 2 rad/s, every 0.1 s
    interpolated: Tw (from the interpolated m) and Lk (the ends' angles, cubic Hermite
    with W3) agree as at the steps. Measured: |Lk − Tw − Wr| at most 2.7e-4 turns with n,
    m on the parabola through three levels (3.5e-3 with m linear across the step; the
    same run landing on the outputs: 6.6e-5, the box rule's O(Δs²))."""
    from test_centreline import _twisted_spec

    spec = _twisted_spec(tolerance={"relative": 1e-3, "absolute": 1e-5})
    spec["output"]["interval"] = 0.1
    ds = integrate(Case.model_validate(spec))
    assert ds.attrs["hockle_status"] == "completed"
    assert ds.sizes["step"] < 50
    assert ds.topology_error.max() < 1e-3
    assert abs(float(ds.linking_number[-1]) + 2.0 / (2 * np.pi)) < 1e-12
