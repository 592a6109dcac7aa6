"""Thermal fluctuations (``thermal``) on the centreline scheme (solver/thermal.py): the
random loads' covariance against the drag's (fluctuation–dissipation), their seed, the
Brownian bridge of cut steps, the analysis of the temperature generalized-α samples on
one linear mode against a simulation of the same relations, the diffusion of a free DNA
rod against kT/ζ, and the case's refusals naming the field. The free chain's statistics
(tangent correlation, twist, bending modes) are printed by benchmarks/thermal_chain.py
(docs/thermal.md § 4)."""
import math

import numpy as np
import pytest

from rodcases import free_end, refused
from solver.case import Case
from solver.centreline import AlphaParameters, CentrelineError, CentrelineRod
from solver.resistive_force import resistive_force_coefficients
from solver.thermal import (BOLTZMANN, ThermalForcing, check_step,
                            stationary_variance_ratio, temperature_error)

T = 298.0
KT = BOLTZMANN * T
MU = 8.9e-4


def dna_spec(*, length=5e-8, n=5, dt=1e-9, steps=100, rho_inf=0.5, seed=1, **sections):
    """DNA in SI units (B = 50 nm kT, C = 100 nm kT at 298 K, radius 1 nm, 1700 kg/m³)
    free at both ends in water (8.9e-4 Pa s), straight along z, with thermal
    fluctuations at 298 K."""
    d = 2e-9
    bend, twist = 50e-9 * KT, 100e-9 * KT
    spec = {"schema_version": 1, "name": "thermal",
            "rod": {"length": length, "youngs_modulus": bend / (math.pi * d**4 / 64),
                    "shear_modulus": twist / (math.pi * d**4 / 32), "density": 1700.0,
                    "diameter": d},
            "fluid": {"density": 1000.0, "viscosity": MU, "drag_coefficient_normal": 0.0},
            "boundary": {"start": free_end(), "end": free_end()},
            "thermal": {"temperature": T, "seed": seed},
            "numerics": {"n_segments": n, "dt": dt, "t_end": steps * dt, "rho_inf": rho_inf,
                         "formulation": "centreline"}}
    spec.update(sections)
    return spec


def test_the_random_loads_have_the_drags_covariance():
    """Over 20000 draws at one node with a tilted tangent a3: Cov f = 2kT Z/(w h) with
    Z = ζ_n (I − a3a3ᵀ) + ζ_t a3a3ᵀ, and Var(m·a3) = 2kT ζ_r/(w h), m along a3; each
    entry within 4 standard errors of a sample covariance (√(2/n) of the diagonal's
    scale, 1 %)."""
    zn, zt, zr = 2.0, 1.0, 0.5
    w, h, n = np.array([0.5, 1.0, 0.5]), 1e-3, 20000
    th = ThermalForcing(1e20, 7, (np.full(3, zn), np.full(3, zt), np.full(3, zr)), w)
    a3 = np.tile(np.array([1.0, 2.0, 2.0]) / 3.0, (3, 1))
    loads = []
    for i in range(n):
        loads.append(th.prepare(i * h, h, a3))                  # (3, 6) per step
        th.accept()
    loads = np.array(loads)
    for k in range(3):
        f = loads[:, k, 0:3]
        scale = 2.0 * th.kT / (w[k] * h)
        Z = zn * (np.eye(3) - np.outer(a3[k], a3[k])) + zt * np.outer(a3[k], a3[k])
        cov = f.T @ f / n
        assert np.abs(cov / scale - Z).max() < 4 * math.sqrt(2.0 / n) * zn
        m = loads[:, k, 3:6]
        assert np.abs(np.cross(m, a3[k])).max() < 1e-12 * np.abs(m).max()
        axial = m @ a3[k]
        assert axial @ axial / n / scale == pytest.approx(zr, rel=4 * math.sqrt(2.0 / n))


def test_the_same_seed_draws_the_same_loads_and_cut_steps_keep_the_steps_impulse():
    """Two forcings of one seed draw the same loads bit for bit; another seed others. A
    nominal step [0, h] cut into h/2 + h/4 + h/4 (a refused attempt of h/2 first, then
    the cut steps accepted) takes sub-impulses that sum to the nominal step's own (the
    Brownian bridge), whatever the refused attempt drew."""
    args = ((np.ones(4), np.ones(4), np.ones(4)), np.full(4, 0.25))
    a3 = np.tile([0.0, 0.0, 1.0], (4, 1))
    one, two, other = (ThermalForcing(300.0, s, *args) for s in (5, 5, 6))
    for th in (one, two, other):
        th.begin(0.0, 1e-3)
    whole = one.prepare(0.0, 1e-3, a3).copy()
    assert np.array_equal(whole, two.prepare(0.0, 1e-3, a3))
    assert not np.array_equal(whole, other.prepare(0.0, 1e-3, a3))
    cut = ThermalForcing(300.0, 5, *args)  # the same nominal impulses as ``one``
    cut.begin(0.0, 1e-3)
    impulse = np.zeros((4, 6))
    cut.prepare(0.0, 5e-4, a3)             # refused: not accepted
    for t, h in ((0.0, 5e-4), (5e-4, 2.5e-4), (7.5e-4, 2.5e-4)):
        impulse += h * cut.prepare(t, h, a3)
        cut.accept()
    assert np.allclose(impulse, 1e-3 * whole, rtol=0, atol=1e-12 * np.abs(whole).max() * 1e-3)


def _simulate_mode(rho_inf, lam_h, inertia, n_paths=4000, steps=400, seed=0):
    """The stationary variance over kT/k of m ẍ + ζ ẋ + k x = f by generalized-α's own
    relations (CentrelineRod.coefficients and step, on a scalar; ζ = h = kT = 1), the
    force held over each step with variance 2/h, over n_paths independent paths after
    ``steps`` steps."""
    p = AlphaParameters.from_rho_inf(rho_inf)
    rng = np.random.Generator(np.random.PCG64(seed))
    x = v = acc = a = np.zeros(n_paths)
    k, m = lam_h, inertia
    for _ in range(steps):
        cA = 1.0 / p.beta
        dA = -(v + (0.5 - p.beta) * a) * cA
        cXd = (1 - p.alpha_m) / (1 - p.alpha_f) * cA
        dXd = ((1 - p.alpha_m) * dA + p.alpha_m * a - p.alpha_f * acc) / (1 - p.alpha_f)
        cX, dX = p.gamma * cA, v + (1 - p.gamma) * a + p.gamma * dA
        f = math.sqrt(2.0) * rng.standard_normal(n_paths)
        D = (f - m * dXd - dX - k * x) / (m * cXd + cX + k)
        x, v, acc, a = x + D, cX * D + dX, cXd * D + dXd, cA * D + dA
    return float(np.mean(x * x) * k)


@pytest.mark.parametrize("rho_inf,lam_h", [(0.5, 0.05), (0.5, 1.0), (0.9, 10.0), (0.0, 1.0)])
def test_the_stationary_variance_of_one_mode_is_the_schemes(rho_inf, lam_h):
    """The analysis (:func:`solver.thermal.stationary_variance_ratio`, the discrete
    Lyapunov equation) against 4000 simulated paths of the same relations (standard
    error √(2/4000) = 2.2 %, asserted within 4 of it), at overdamped steps
    (m/(ζΔt) = 1e-3); and it is at most backward Euler's 2/(2 + λΔt), by a factor
    0.90 to 1 (ρ∞ 0 at λΔt = 1: 0.900; ρ∞ 0.5: 0.961; ρ∞ 0.9 at λΔt = 10: 0.992): the
    noise held over the step cools a stiff mode at any ρ∞, least at ρ∞ near 1."""
    predicted = stationary_variance_ratio(AlphaParameters.from_rho_inf(rho_inf), lam_h, 1e-3)
    measured = _simulate_mode(rho_inf, lam_h, 1e-3)
    assert measured == pytest.approx(predicted, rel=4 * math.sqrt(2.0 / 4000))
    euler = 2.0 / (2.0 + lam_h)
    assert 0.89 * euler < predicted < 1.0001 * euler
    if rho_inf == 0.9:
        assert predicted > 0.99 * euler


def test_the_resolved_modes_hold_their_temperature_and_rho_inf_1_is_refused():
    """Modes with λΔt up to 0.05 are within 3.6 % of their temperature at every ρ∞
    below 1 and any m/(ζΔt) (measured 3.59 % at ρ∞ 0, 2.73 % at 0.5, at most); ρ∞ = 1 does
    not damp the overdamped steps' inertial mode, whose variance grows without bound."""
    for rho in (0.0, 0.5, 0.9):
        for inertia in (1e-6, 1e-2, 1.0, 100.0):
            assert temperature_error(AlphaParameters.from_rho_inf(rho), inertia) < 0.036
    one = AlphaParameters.from_rho_inf(1.0)
    assert temperature_error(one, 1e-3) == math.inf
    field, why = check_step(one, 1e-9, 1e-12, None)
    assert field == "numerics.rho_inf" and "does not damp" in why


def test_a_free_rod_diffuses_at_kt_over_its_drag():
    """50 nm of DNA (5 segments) free in water at 298 K, Δt = 1 ns (325 inertial times),
    1500 steps: the mean
    square displacement of its centre of mass over 20 steps, summed over the three axes,
    is 2 kT t (2/ζ_n + 1/ζ_t)/L (the translational diffusion of a slender rod of drag
    ζ_n L across and ζ_t L along, in any orientation); and the mean square of its mean
    spin angle, 2 kT t/(ζ_r L). A run's time average over about 75 independent windows:
    standard error about 16 % for one axis, 10 % for the sum, asserted within 30 %
    (measured 1.07 and 1.20)."""
    L, dt, steps, lag = 5e-8, 1e-9, 1500, 20
    rod = CentrelineRod.from_case(Case.model_validate(dna_spec(steps=steps)))
    zn, zt, zr = (float(z[0]) for z in resistive_force_coefficients(MU, np.array([2e-9]), L))
    w = rod.props.quad_weights
    state = rod.start()
    com, spin, phi = [], [], 0.0
    for _ in range(steps):
        new, _, _ = rod.step(state, dt)
        phi += 0.5 * dt * float(w @ (state.X[:, 5] + new.X[:, 5])) / L
        com.append(w @ new.Y[:, 0:3] / L)
        spin.append(phi)
        state = new
    com, spin = np.array(com), np.array(spin)
    msd = float(np.mean(np.sum((com[lag:] - com[:-lag]) ** 2, axis=1)))
    assert msd / (2 * KT * lag * dt * (2 / zn + 1 / zt) / L) == pytest.approx(1.0, abs=0.3)
    msd_spin = float(np.mean((spin[lag:] - spin[:-lag]) ** 2))
    assert msd_spin / (2 * KT * lag * dt / (zr * L)) == pytest.approx(1.0, abs=0.3)


def test_the_same_seed_gives_the_same_run():
    """Two runs of one case agree bit for bit over 10 steps; another seed differs."""
    from solver.centreline_run import CentrelineRun

    def positions(seed):
        run = CentrelineRun(Case.model_validate(dna_spec(seed=seed, steps=10)))
        for k in range(10):
            run.advance((k + 1) * 1e-9)
        return run.level.Y.copy()

    first = positions(3)
    assert np.array_equal(first, positions(3))
    assert not np.array_equal(first, positions(4))


def test_integrate_runs_a_thermal_case_the_same_twice():
    """Through the time loop (solver.simulation.integrate) and its recorder: 20 steps of
    the free DNA rod complete, the summary names the temperature and seed, the positions
    move, and a second run of the same case writes the same positions bit for bit."""
    from solver.simulation import integrate

    spec = dna_spec(steps=20)
    spec["output"] = {"every": 10, "fields": ["position"]}
    runs = [integrate(Case.model_validate(spec)) for _ in range(2)]
    assert all(ds.attrs["hockle_status"] == "completed" for ds in runs)
    assert "with thermal fluctuations at 298 K (seed 1)" in runs[0].attrs["summary"]
    first, second = (np.asarray(ds["position"].values) for ds in runs)
    assert np.array_equal(first, second)
    assert np.abs(first[-1] - first[0]).max() > 0.0


def test_a_thermal_case_needs_viscosity_and_the_centreline_scheme():
    spec = dna_spec()
    del spec["fluid"]["viscosity"]
    refused(spec, ("thermal",), "need fluid.viscosity")
    spec = dna_spec()
    del spec["numerics"]["formulation"]
    spec["fluid"] = {"density": 1000.0}                # goyal takes no viscosity
    refused(spec, ("thermal",), "numerics.formulation: centreline")
    spec = dna_spec()
    spec["thermal"]["temperature"] = 0.0
    refused(spec, ("thermal", "temperature"), "greater than 0")
    spec = dna_spec()
    spec["thermal"]["seed"] = -1
    refused(spec, ("thermal", "seed"), "greater than or equal to 0")


def test_a_step_that_cannot_hold_the_temperature_is_refused_naming_the_field():
    """ρ∞ = 1 (at numerics.rho_inf), and a step of a fifth of the lowest bending mode's
    relaxation time (pinned ends, ζ_n/(B (π/L)⁴): the mode sampled more than 5 % below its
    temperature; at numerics.dt) are refused when the run is built, with the reason; a
    fiftieth is taken."""
    with pytest.raises(CentrelineError, match="numerics.rho_inf: .*rho_inf 1 does not damp"):
        CentrelineRod.from_case(Case.model_validate(dna_spec(rho_inf=1.0)))
    from solver.plausibility import lowest_bending_relaxation_time

    tau = lowest_bending_relaxation_time(Case.model_validate(dna_spec()))
    with pytest.raises(CentrelineError, match="numerics.dt: .*lowest bending mode"):
        CentrelineRod.from_case(Case.model_validate(dna_spec(dt=0.2 * tau, steps=10)))
    CentrelineRod.from_case(Case.model_validate(dna_spec(dt=0.02 * tau, steps=10)))


def test_a_case_without_thermal_keeps_its_canonical_json():
    plain = dna_spec()
    del plain["thermal"]
    assert "thermal" not in Case.model_validate(plain).model_dump(mode="json")
    case = Case.model_validate(dna_spec(seed=12))
    assert case.model_dump(mode="json")["thermal"] == {"temperature": T, "seed": 12}
    again = Case.model_validate(case.model_dump(mode="json"))
    assert again.spec_hash() == case.spec_hash()


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="the short scales are sampled cold at steps beyond "
                   "their relaxation times (docs/thermal.md § 3): the issue's aims are not met")
def test_a_free_chain_has_the_worm_like_chains_short_scale_statistics():
    """The issue's aims at Δt = 1e-9 s (18 forward-Euler limits) on 100 nm of DNA in
    40 segments (benchmarks/thermal_chain.py's chain): the tangent correlation at 2.5, 5
    and 10 nm within 3 % of exp(−s/ℓp) and the twist's variance over 10 nm within 3 % of
    ℓ kT/C. Expected to fail (strict): the benchmark measured 1.039, 1.056, 1.056 and 0.52
    (docs/thermal.md § 4). 1000 steps of 10 ns to equilibrate, then 1500 of 1 ns."""
    from benchmarks.thermal_chain import chain_case, figures, sample
    from solver.centreline_run import CentrelineRun

    run = CentrelineRun(chain_case(dt=1e-9))
    sample(run, 1e-8, 1000)
    tangents, curv = sample(run, 1e-9, 1500)
    f = figures(run.rod, tangents[300:], curv[300:], 1e-9)
    for s, ratio, _ in f["tangent"][:3]:
        assert ratio == pytest.approx(1.0, abs=0.03), (s, ratio)
    assert f["twist"][1][1] == pytest.approx(1.0, abs=0.03), f["twist"][1]


def test_a_thermal_run_resumed_from_a_checkpoint_repeats_it_bit_for_bit():
    """The generator's state travels with the checkpoint (the run is pickled whole, its
    ThermalForcing with it): a run resumed at 20 of its 40 steps draws the same random
    loads as the uninterrupted one and writes the same positions to the last bit."""
    from solver.checkpoint import Checkpoint
    from solver.simulation import integrate
    from test_checkpoint import assert_identical, run_with_checkpoint_at

    spec = dna_spec(steps=40)
    spec["output"] = {"every": 5, "fields": ["position"]}
    case = Case.model_validate(spec)
    full, data = run_with_checkpoint_at(case, 20e-9)
    ck = Checkpoint.loads(data, case)
    assert 0.0 < ck.t < 40e-9
    assert_identical(full, integrate(case, resume=ck))
