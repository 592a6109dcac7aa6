"""Thermal fluctuations on the centreline scheme: Langevin forces and moments whose
covariance matches resistive-force theory's Stokes drag (fluctuation–dissipation), drawn
from a seeded generator the run owns; and the analysis of the temperature generalized-α
samples at a step Δt (docs/thermal.md).

The drag per length at node k (:mod:`solver.resistive_force`) is −Z_k ṙ_k with
Z_k = ζ_n (I − a3a3ᵀ) + ζ_t a3a3ᵀ, and −ζ_r W3 a3 about the axis. The cell rows take
the trapezoid of the nodal loads, so node k stands for w_k = Δs (Δs/2 at the ends of an
open rod) of rod, and the drag on it is w_k Z_k. Fluctuation–dissipation (the
Einstein relation of a Langevin equation, Kubo, Rep. Prog. Phys. 29, 255, 1966) asks for
a white random force of covariance 2 kT w_k Z_k δ(t − t'); held constant over a step of h,
its impulse w_k h f_k has covariance 2 kT w_k Z_k h, so the force per length of a step is

    f_k = √(2kT/(w_k h)) (√ζ_n (I − a3a3ᵀ) + √ζ_t a3a3ᵀ) ξ_k,   ξ_k ~ N(0, I3)
    m_k = √(2kT ζ_r/(w_k h)) η_k a3,                           η_k ~ N(0, 1)

with Cov f_k = 2kT Z_k/(w_k h) and Var(m_k·a3) = 2kT ζ_r/(w_k h). a3 is the node's
tangent at the step's start (the old level): the random load is a constant of the step's
Newton solve and its Jacobian is the deterministic one.

At a large step the scheme cools the stiff modes. On one linear mode
m ẍ + ζ ẋ + k x = f with the force held at t_n+1, generalized-α's relations give a
stationary variance (kT/k)·r(λΔt, ρ∞, m/(ζΔt)) (:func:`stationary_variance_ratio`, from
the discrete Lyapunov equation); at overdamped steps (m/(ζΔt) ≪ 1) r is at most backward
Euler's 2/(2 + λΔt), by a factor 0.90 to 1 that depends on ρ∞ (docs/thermal.md § 2): a
mode is within 3.6 % of its temperature where λΔt ≤ RESOLVED_LAM_H = 0.05, i.e. where
the step resolves its relaxation time 1/λ, and colder beyond. A thermal case whose step
does not resolve the lowest bending mode so, or whose ρ∞ (1) does not damp the inertial
mode, is refused (:func:`check_step`).

Cut steps: a nominal step's force impulses are drawn once, at its start
(:meth:`ThermalForcing.begin`); a sub-step of it takes its part by the Brownian bridge
(the impulse over [t, t + h] of one over [t, T] with W known is Gaussian, mean W h/(T − t),
variance (T − t − h) h/(T − t) per unit; Karatzas & Shreve, *Brownian Motion and
Stochastic Calculus*, 1991, § 5.6.B), so a refused attempt does not redraw the step's
total and the sub-steps sum to it.

Pure: no I/O, no module state; the generator (numpy ``Generator(PCG64(seed))``) belongs
to the :class:`ThermalForcing`, so the same seed and the same steps give the same loads
bit for bit.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["BOLTZMANN", "RESOLVED_LAM_H", "TEMPERATURE_TOLERANCE", "ThermalForcing",
           "check_step", "stationary_variance_ratio", "temperature_error"]

#: the Boltzmann constant, J/K (exact in the SI since 2019)
BOLTZMANN = 1.380649e-23
#: the largest error of the sampled temperature of a resolved linear mode that a thermal
#: run takes (:func:`check_step`)
TEMPERATURE_TOLERANCE = 0.05


class ThermalForcing:
    """The random loads of a thermal run, one step at a time.

    Parameters
    ----------
    temperature : K (> 0)
    seed : int (>= 0), numpy ``Generator(PCG64(seed))``
    stokes : (ζ_n, ζ_t, ζ_r), each (N+1,): N s/m², N s/m², N s
        (:func:`solver.resistive_force.resistive_force_coefficients`)
    weights : (N+1,) m, the trapezoid weights w_k of the nodes

    Attributes: ``kT`` (J), ``rng`` (the generator), ``load`` (N+1, 6) the step's force
    (N/m) and moment (N m/m) per length, global, None before :meth:`prepare`. Raises
    :class:`ValueError` for a temperature or weights not positive.
    """

    def __init__(self, temperature, seed, stokes, weights):
        if not temperature > 0 or not np.all(np.asarray(weights) > 0):
            raise ValueError("ThermalForcing: temperature and weights must be positive")
        self.kT = BOLTZMANN * float(temperature)
        self.rng = np.random.Generator(np.random.PCG64(int(seed)))
        zn, zt, zr = (np.asarray(z, float) for z in stokes)
        w = np.asarray(weights, float)
        self._amplitude = np.sqrt(2.0 * self.kT / w)[:, None] * np.stack(
            [np.sqrt(zn), np.sqrt(zt), np.sqrt(zr)], axis=1)            # (N+1, 3)
        self._pending = None           # (t0, t1, W (N+1, 4)): the nominal step's impulses
        self._proposal = None
        self.load = None

    def begin(self, t0: float, t1: float) -> None:
        """Draw the nominal step [t0, t1] (s): standard Wiener increments W (N+1, 4),
        variance t1 − t0 each (3 force components, 1 axial moment per node)."""
        n = self._amplitude.shape[0]
        self._pending = (float(t0), float(t1),
                         math.sqrt(t1 - t0) * self.rng.standard_normal((n, 4)))

    def prepare(self, t: float, h: float, a3) -> np.ndarray:
        """The loads of an attempt from t over h (s) with the old level's tangents a3
        (N+1, 3): this sub-interval's Wiener increments by the Brownian bridge from the
        pending nominal step (a step not inside it, or none pending, draws its own), the
        force and moment per length (N+1, 6) (module docstring) in ``load``. Returns
        ``load``."""
        p = self._pending
        if p is None or abs(t - p[0]) > 1e-12 * max(abs(t), p[1] - p[0]) \
                or t + h > p[1] + 1e-12 * max(abs(p[1]), 1.0):
            self.begin(t, t + h)
            p = self._pending
        rest = p[1] - p[0]
        if h >= rest * (1.0 - 1e-12):
            w = p[2]
        else:
            frac = h / rest
            sd = math.sqrt(h * (1.0 - frac))
            w = frac * p[2] + sd * self.rng.standard_normal(p[2].shape)
        self._proposal = (t + h, w)
        a3 = np.asarray(a3, float)
        xi = w[:, 0:3]
        along = np.sum(a3 * xi, axis=1, keepdims=True) * a3
        amp = self._amplitude / h
        force = amp[:, 0:1] * (xi - along) + amp[:, 1:2] * along
        moment = (amp[:, 2] * w[:, 3])[:, None] * a3
        self.load = np.concatenate([force, moment], axis=1)
        return self.load

    def accept(self) -> None:
        """The attempt was taken: the pending step keeps what is left of it."""
        t1, w = self._proposal
        t0, end, W = self._pending
        self._pending = None if t1 >= end * (1.0 - 1e-15) - 1e-300 else (t1, end, W - w)
        self._proposal = None


def _mode_transition(params, lam_h: float, inertia: float):
    """Generalized-α of ``params`` on one linear mode m ẍ + ζ ẋ + k x = f_n held at
    t_n+1, in units ζ = 1, h = 1 (k = λh, m = inertia = m/(ζh)): the state
    (x, v, ẍ, a) -> (A (4, 4), b (4,)) with s_n+1 = A s_n + b f_n."""
    am, af, g, be = params.alpha_m, params.alpha_f, params.gamma, params.beta
    cA = 1.0 / be
    dA = np.array([-cA, -cA, 0.0, -(0.5 - be) / be])           # a_n+1 = cA x' + dA·s
    cV, dV = g * cA, np.array([0.0, 1.0, 0.0, 1.0 - g]) + g * dA
    cXd = (1.0 - am) / (1.0 - af) * cA
    dXd = ((1.0 - am) * dA + np.array([0.0, 0.0, -af, am])) / (1.0 - af)
    den = inertia * cXd + cV + lam_h
    xs, xf = -(inertia * dXd + dV) / den, 1.0 / den
    A = np.array([xs, cV * xs + dV, cXd * xs + dXd, cA * xs + dA])
    b = np.array([xf, cV * xf, cXd * xf, cA * xf])
    return A, b


def stationary_variance_ratio(params, lam_h: float, inertia: float = 0.0) -> float:
    """The stationary variance of one linear mode under the scheme, over kT/k
    (1: the right temperature): generalized-α of ``params`` (α_m, α_f, γ, β:
    :class:`solver.centreline.AlphaParameters`) on m ẍ + ζ ẋ + k x = f,
    λΔt = ``lam_h`` = kΔt/ζ, ``inertia`` = m/(ζΔt) (0 is taken as 1e-12; DNA's
    overdamped steps have 1e-2 or less), the force held over each step at t_n+1 with
    variance 2kTζ/Δt (:class:`ThermalForcing`). From the discrete Lyapunov equation
    Σ = A Σ Aᵀ + b bᵀ Var f of the scheme's linear map s_n+1 = A s_n + b f_n on the state
    (x, ẋ, ẍ, a) (scipy's ``solve_discrete_lyapunov``; the relations of
    :class:`solver.centreline.CentrelineRod.coefficients`). Backward Euler's is
    2/(2 + λΔt), the trapezoid rule's (with white increments) 1. Raises
    :class:`ValueError` where the scheme does not damp the mode."""
    from scipy.linalg import solve_discrete_lyapunov

    A, b = _mode_transition(params, lam_h, max(float(inertia), 1e-12))
    if np.max(np.abs(np.linalg.eigvals(A))) >= 1.0 - 1e-12:
        raise ValueError(f"generalized-α {params} does not damp the mode "
                         f"(λΔt = {lam_h}, m/(ζΔt) = {inertia})")
    S = solve_discrete_lyapunov(A, 2.0 * np.outer(b, b))       # kT = ζ = Δt = 1
    return float(S[0, 0] * lam_h)


#: the largest λΔt of a mode the step resolves: backward Euler's 2/(2 + λΔt) is 0.976
RESOLVED_LAM_H = 0.05
#: the λΔt over which :func:`temperature_error` looks: 1e-4 to RESOLVED_LAM_H
_LAM_H = np.logspace(-4, math.log10(RESOLVED_LAM_H), 13)


def temperature_error(params, inertia: float = 0.0) -> float:
    """The largest |r − 1| of :func:`stationary_variance_ratio` over the modes the step
    resolves, λΔt from 1e-4 to RESOLVED_LAM_H (13 points, logarithmic), for generalized-α
    of ``params`` at m/(ζΔt); inf where the scheme does not damp some mode."""
    try:
        return max(abs(stationary_variance_ratio(params, x, inertia) - 1.0) for x in _LAM_H)
    except ValueError:
        return math.inf


def check_step(params, dt: float, inertial_time: float,
               relaxation_time: float | None) -> tuple[str, str] | None:
    """(the field, why) a thermal run of generalized-α ``params`` at Δt (s) cannot hold
    its temperature, or None: ``numerics.rho_inf`` where the scheme does not damp some
    mode (ρ∞ = 1); ``numerics.dt`` where the modes the step resolves
    (λΔt ≤ RESOLVED_LAM_H) are off by more than TEMPERATURE_TOLERANCE at
    m/(ζΔt) = inertial_time/Δt (:func:`temperature_error`: steps near the inertial time
    τ = m/ζ), or the lowest bending mode's (relaxation time ``relaxation_time`` s,
    :func:`solver.plausibility.lowest_bending_relaxation_time`; None: not overdamped,
    not checked) temperature off by more than it."""
    inertia = inertial_time / dt
    err = temperature_error(params, inertia)
    if err == math.inf:
        return ("numerics.rho_inf", "generalized-alpha at rho_inf 1 does not damp the "
                "overdamped steps' inertial mode, which the random loads then drive without "
                "bound: take rho_inf below 1 (0.5 is the one verified; docs/thermal.md)")
    if err > TEMPERATURE_TOLERANCE:
        return ("numerics.dt",
                f"at this rho_inf and dt = {dt:g} s ({dt / inertial_time:.3g} times the "
                f"inertial time m/zeta, {inertial_time:.3g} s) generalized-alpha samples the "
                f"resolved modes' temperature up to {100 * err:.3g} % off (more than "
                f"{100 * TEMPERATURE_TOLERANCE:g} %; docs/thermal.md)")
    if relaxation_time is not None:
        lam_h = dt / relaxation_time
        r = stationary_variance_ratio(params, lam_h, inertia)
        if abs(r - 1.0) > TEMPERATURE_TOLERANCE:
            return ("numerics.dt",
                    f"dt = {dt:g} s is {lam_h:.3g} relaxation times of the rod's lowest "
                    f"bending mode ({relaxation_time:.3g} s): the scheme samples it at "
                    f"{100 * r:.3g} % of its temperature (more than "
                    f"{100 * TEMPERATURE_TOLERANCE:g} % off); take dt at most "
                    f"{RESOLVED_LAM_H:g} of that time (docs/thermal.md)")
    return None
