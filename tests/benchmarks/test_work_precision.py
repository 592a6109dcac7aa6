"""The work-precision benchmark's own machinery (benchmarks/work_precision.py): the
analytic oracle against classical closed forms, the measurement of event times and peaks,
the order estimate and the "cheapest setting" rule, on inputs with known answers. The
solver runs of the benchmark are not repeated here (the quick mode is the smoke test)."""
from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from benchmarks import work_precision as wp

BETA_L1 = 4.730040744862704          # cos x cosh x = 1, first root


def test_oracle_euler_bernoulli_clamped_clamped():
    # without rotary inertia and twist, the first eigenvalue is ω = (βL)² √(B/ρA) / L²
    s2 = wp.lateral_eigenvalue(0.0, -520 / wp.T_C**2, -480 / wp.T_C**2, rho_j=0.0)
    omega_eb = BETA_L1**2 * np.sqrt(wp.B / wp.RHO_A) / wp.L**2
    assert np.sqrt(-s2) == pytest.approx(omega_eb, rel=1e-7)   # root found to ~1e-9


def test_oracle_rotary_inertia_lowers_frequency_by_rayleigh_amount():
    # Rayleigh quotient: ω²(1 + r²∫φ'²/∫φ²) = ω_EB² to first order in r² = J/A; for the
    # clamped-clamped first mode ∫φ'²/∫φ² = 12.3 / L² (numerical quadrature of the mode)
    vib = wp.Vibration()
    x = np.linspace(0, 1, 20001)
    sig = (np.cosh(BETA_L1) - np.cos(BETA_L1)) / (np.sinh(BETA_L1) - np.sin(BETA_L1))
    phi = np.cosh(BETA_L1 * x) - np.cos(BETA_L1 * x) - sig * (np.sinh(BETA_L1 * x)
                                                               - np.sin(BETA_L1 * x))
    ratio = np.trapezoid(np.gradient(phi, x) ** 2, x) / np.trapezoid(phi**2, x)
    expected = -0.5 * (wp.J / wp.AREA) * ratio
    assert vib.omega / vib.omega_eb - 1 == pytest.approx(expected, rel=2e-2)


def test_oracle_growth_rate_vanishes_at_greenhill_moment():
    # σ² is about linear in M just above M_cr; its zero extrapolated from 1.01 and 1.02
    # M_cr lands on M_cr L/B = 8.9868 (tan x = x)
    mcr = wp.critical_moment()
    assert mcr == pytest.approx(8.9868, abs=1e-4)
    fs, s2 = [1.01, 1.02], []
    for f in fs:
        s2.append(wp.lateral_eigenvalue(f * mcr * wp.B / wp.L, 1 / wp.T_C**2,
                                        60 / wp.T_C**2, n=600))
    slope = (s2[1] - s2[0]) / (fs[1] - fs[0])
    f0 = fs[0] - s2[0] / slope
    assert f0 == pytest.approx(1.0, abs=1e-3)
    # below critical the lowest mode oscillates (σ² < 0): no root on the positive side
    with pytest.raises(RuntimeError):
        wp.lateral_eigenvalue(0.99 * mcr * wp.B / wp.L, 1 / wp.T_C**2, 60 / wp.T_C**2, n=300)


def test_seed_observables_interpolate_onset_and_peak():
    # bending energy e^{σt}: the 1 % crossing is found between outputs exactly;
    # torsional energy a parabola with its vertex between outputs: found exactly
    t = np.arange(0.0, 20.0, 0.4)
    ut = 5.0 - 0.3 * (t - 17.13) ** 2
    t_b = 16.77
    ub = 0.01 * ut * np.exp(7.0 * (t - t_b))
    ds = xr.Dataset({"energy_bending": ("time", ub), "energy_torsion": ("time", ut)},
                    coords={"time": t})
    obs = wp.seed_observables(ds)
    assert obs["t_b"] == pytest.approx(t_b, abs=1e-9)
    assert obs["U_peak"] == pytest.approx(5.0, rel=1e-12)
    assert obs["t_peak"] == pytest.approx(17.13, abs=1e-9)


def test_observed_order_from_successive_differences():
    h = 0.1 / 2.0 ** np.arange(6)
    v = 1.0 + 0.3 + 2.0 * h**2 + 5.0 * h**3        # fixed offset (other direction) cancels
    o = wp.observed_order(h.tolist(), v.tolist())
    assert o["order"] == pytest.approx(2.0, abs=0.05)
    assert len(o["local_orders"]) == 4


def _run(n, dt, err, wall, rho=0.5):
    return {"n_segments": n, "dt": dt, "rho_inf": rho, "error": err, "wall_s": wall}


def test_cheapest_ignores_lucky_cancellation():
    runs = [_run(10, 0.1, 5e-4, 0.1),        # lucky: its refinements are worse
            _run(20, 0.1, 3e-3, 0.2), _run(10, 0.05, 2e-3, 0.2),
            _run(20, 0.05, 8e-4, 0.4)]
    best = wp.cheapest(runs, 1e-3)
    assert (best["n_segments"], best["dt"]) == (20, 0.05)
    assert wp.cheapest(runs, 1e-4) is None
    assert wp.cheapest(runs, 1e-2)["wall_s"] == 0.1
