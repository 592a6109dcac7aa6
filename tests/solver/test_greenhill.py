"""Greenhill buckling of a twisted clamped-clamped rod (numerics-notes §5 V1).

Linearised about the straight rod under end torque M and axial force T, the lateral
deflection w = x + iy obeys B w'''' − iM w''' − T w'' = 0; with w = w' = 0 at both ends
(axial sliding, T prescribed) the critical torque solves

    2b [cos(bL) − cos(aL)] = (T L / B) sin(bL),  a = M/2B,  b = √(M² − 4BT)/2B,

which reduces at T = 0 to tan(ML/2B) = ML/2B: M_cr L/B = 8.9868; T L²/B = 10 gives
10.429. The oracle is computed below from these formulas, not taken from a run.

Growth-rate test (two-sided bracket): twist the start end quickly (sin² rate, 2 s) to
M = 0.97 M_cr or 1.03 M_cr, hold the twist, then push the rod sideways with a tiny force
pulse. Below critical the straight twisted rod is stable (the lateral deflection
oscillates with a bounded amplitude); above it the deflection grows exponentially.
Both sides at once show that the solver's M_cr lies within 3 % of the analytic value.
In water (added mass, normal drag) as in the application; drag is quadratic and plays no
role at these amplitudes. B = EJ, torque M = GJ3 Φ/L for a uniform rod.

Boundary conditions: start v = 0, ω1 = ω2 = 0, ω3 prescribed; end v1 = v2 = 0, axial
force f3 = T (f3 > 0 is tension), ω = 0.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

from solver.case import Case
from solver.simulation import integrate

E, G, RHO, RHO_F = 1.25e7, 5.0e6, 1500.0, 1000.0
L, D = 1.0, 0.01
B = E * np.pi * D**4 / 64
GJ3 = G * np.pi * D**4 / 32


def critical_torque(t):
    """m_cr = M_cr L/B of the clamped-clamped rod for t = T L²/B ≥ 0 (smallest root)."""
    if t == 0.0:
        return 2.0 * brentq(lambda x: np.tan(x) - x, 4.0, 4.6, xtol=1e-14)

    def det(m):
        a = m / 2
        b = np.sqrt(m * m - 4 * t) / 2
        return 2 * b * (np.cos(b) - np.cos(a)) - t * np.sin(b)

    m = np.linspace(2 * np.sqrt(t) + 1e-9, 2 * np.sqrt(t) + 40.0, 80001)
    f = det(m)
    i = np.nonzero(np.sign(f[1:]) != np.sign(f[:-1]))[0][0]
    return brentq(det, m[i], m[i + 1], xtol=1e-14)


def test_critical_torque_formula():
    # the oracle against the table of numerics-notes V1 and the classical limits
    assert critical_torque(0.0) == pytest.approx(8.9868, abs=1e-4)
    assert critical_torque(10.0) == pytest.approx(10.429, abs=1e-3)
    assert critical_torque(1.0) == pytest.approx(9.135, abs=1e-3)
    assert critical_torque(1000.0) == pytest.approx(63.559, abs=2e-3)


RAMP, PUSH_AT, PUSH = 2.0, 2.5, 0.2          # s: twist ramp, start and length of the push


def twisted_rod(tension_ratio, factor, n_segments=50, dt=0.01, t_end=10.0, push=1e-5):
    """Run the hold-and-push case at M = factor·M_cr; returns (t, lateral deflection)."""
    m_cr = critical_torque(tension_ratio)
    M = factor * m_cr * B / L
    phi = M * L / GJ3                         # end rotation giving torque M
    tt = np.linspace(0.0, RAMP, 401)
    rate = (phi / RAMP) * (1 - np.cos(2 * np.pi * tt / RAMP))
    n = int(round(PUSH / dt))
    forces = [{"value": [push * np.sin(np.pi * k / n) ** 2, 0.0, 0.0],
               "start": PUSH_AT + (k - 0.5) * dt, "end": PUSH_AT + (k + 0.5) * dt,
               "s_range": [0.2 * L, 0.45 * L]} for k in range(1, n)]
    zero = {"velocity": 0.0}
    rot0 = {"angular_velocity": 0.0}
    spec = {
        "schema_version": 1, "name": "greenhill",
        "rod": {"length": L, "youngs_modulus": E, "shear_modulus": G, "density": RHO,
                "diameter": D},
        "fluid": {"density": RHO_F, "added_mass_coefficient": 1.0,
                  "drag_coefficient_normal": 1.0},
        "boundary": {
            "start": {"translation": [zero, zero, zero],
                      "rotation": [rot0, rot0, {"angular_velocity":
                                                {"t": tt.tolist(), "value": rate.tolist()}}]},
            "end": {"translation": [zero, zero, {"force": tension_ratio * B / L**2}],
                    "rotation": [rot0, rot0, rot0]}},
        "distributed_forces": forces,
        "numerics": {"n_segments": n_segments, "dt": dt, "t_end": t_end, "rho_inf": 0.5,
                     "newton": {"tolerance": 1e-11, "max_iterations": 30}},
        "output": {"every": 1, "fields": ["position", "moment"]},
    }
    ds = integrate(Case.model_validate(spec))
    assert ds.attrs["hockle_status"] == "completed"
    t = ds.time.values
    lateral = np.linalg.norm(ds.position.values[:, :, :2], axis=2).max(axis=1)
    # before the push the twisted rod is straight, and the torque is the one aimed at
    before = (t > RAMP + 0.2) & (t < PUSH_AT)
    assert lateral[before].max() < 1e-9 * L
    q3 = ds.moment.values[before][-1, :, 2]
    assert np.all(np.abs(q3 / -M - 1) < 1e-4)
    return t, lateral


def window_maxima(t, lateral, start, width=1.0):
    edges = np.arange(start, t[-1] + 1e-9, width)
    return np.array([lateral[(t >= a) & (t < a + width)].max() for a in edges[:-1]])


@pytest.mark.parametrize("tension_ratio", [0.0, 10.0], ids=["T=0", "TL2/B=10"])
def test_greenhill_bracket(tension_ratio):
    t, stable = twisted_rod(tension_ratio, 0.97)
    w = window_maxima(t, stable, PUSH_AT + PUSH)
    # bounded: the response to the push neither grows nor needs damping to stay put
    assert w.max() < 3.0 * w[0], w
    assert w.max() < 1e-4 * L

    t, unstable = twisted_rod(tension_ratio, 1.03)
    w = window_maxima(t, unstable, PUSH_AT + PUSH)
    linear = w < 1e-3 * L                     # exponential phase, before saturation
    assert linear.sum() >= 5, w
    growth = w[linear][1:] / w[linear][:-1]
    assert np.all(growth > 1.5), w            # grows every second ...
    assert w.max() > 300 * w[0], w            # ... by orders of magnitude
    # ... at a steady rate: log(window maxima) is straight
    k = np.arange(linear.sum())
    slope, icpt = np.polyfit(k, np.log(w[linear]), 1)
    assert np.abs(np.log(w[linear]) - (slope * k + icpt)).max() < 0.3


def growth_rate(t, lateral, t0):
    m = (t > t0) & (lateral < 2e-4 * L)
    return np.polyfit(t[m], np.log(lateral[m]), 1)[0]


@pytest.mark.slow
@pytest.mark.parametrize("tension_ratio", [0.0, 10.0], ids=["T=0", "TL2/B=10"])
def test_greenhill_sharp(tension_ratio):
    """N = 100: ±1 % bracket, and M_cr from the growth rates σ above critical
    (σ² is linear in M near M_cr; extrapolate to σ = 0). Measured: the solver's M_cr
    converges to the analytic value at second order (+2.2 %, +0.6 %, +0.1 % at
    N = 25, 50, 100)."""
    t, stable = twisted_rod(tension_ratio, 0.99, n_segments=100, t_end=12.0)
    w = window_maxima(t, stable, PUSH_AT + PUSH)
    assert w.max() < 3.0 * w[0], w
    factors, sigmas = [1.01, 1.02, 1.03], []
    for f in factors:
        t, lat = twisted_rod(tension_ratio, f, n_segments=100, t_end=12.0)
        sigmas.append(growth_rate(t, lat, PUSH_AT + PUSH + 1.0))
    assert min(sigmas) > 0.2, sigmas
    m_ratio = np.polyfit(np.square(sigmas), factors, 1)[1]
    assert abs(m_ratio - 1) < 5e-3, m_ratio
