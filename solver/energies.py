"""Energies of the rod and the power put in at its ends (numerics-notes §4.1).

Integrals are sums over cells of the cell averages ⟨Z⟩ = ½(Z_{k-1} + Z_k), the same
averages the box scheme's cell equations use, so at ρ∞ = 1 without loads the discrete
total is conserved to round-off and Newton tolerance rather than to O(Δs²) (a trapezoid
sum over nodes fluctuates by about Δs²). Quadratic terms are ½⟨B κ⟩·⟨κ⟩, ½⟨m v⟩·⟨v⟩, so
q is averaged, not κ, where the stiffness varies.

* bending   U_b = ½ ∫ (EJ1 (κ1 − κ⁰1)² + EJ2 (κ2 − κ⁰2)²) ds
* torsion   U_t = ½ ∫ GJ3 (κ3 − κ⁰3)² ds
  (κ⁰ the intrinsic curvature, ``props.intrinsic_curvature``, zero where none is given)
* kinetic   T   = ½ ∫ (ρA |v|² + ωᵀ I ω) ds      (the rod's own)
* fluid     T_f = ½ ∫ C_a ρ_f A |v_n|² ds        (the added mass's share, reported apart)
* total     E   = U_b + U_t + T + T_f
* end power P = f(L)·v(L) + q(L)·ω(L) − f(0)·v(0) − q(0)·ω(0)  (W; f, q: internal force and
  moment exerted by the part beyond s on the part before it, see solver.boundary)

Units: J and W. Y is (N+1, 12) = (v, ω, f, κ) per node in the body frame.
"""
from __future__ import annotations

import numba
import numpy as np

__all__ = ["energies", "total_and_kinetic", "end_power", "distributed_power"]


@numba.njit(cache=True)
def _energies_kernel(Y, stiffness, rho_a, inertia, added_mass, ds, out):
    """The energies of :func:`energies` into out (4,): bending, torsion, kinetic, fluid
    (J), each ½ Σ_cells Δs ⟨a⟩·⟨b⟩ of its node fields (one pass over the cells)."""
    ub = ut = tk = tf = 0.0
    for c in range(Y.shape[0] - 1):
        for i in range(3):
            qm = 0.5 * (stiffness[c, i] * Y[c, 9 + i] + stiffness[c + 1, i] * Y[c + 1, 9 + i])
            km = 0.5 * (Y[c, 9 + i] + Y[c + 1, 9 + i])
            if i < 2:
                ub += qm * km
            else:
                ut += qm * km
            vm = 0.5 * (Y[c, i] + Y[c + 1, i])
            mvm = 0.5 * (rho_a[c] * Y[c, i] + rho_a[c + 1] * Y[c + 1, i])
            om = 0.5 * (Y[c, 3 + i] + Y[c + 1, 3 + i])
            iom = 0.5 * (inertia[c, i] * Y[c, 3 + i] + inertia[c + 1, i] * Y[c + 1, 3 + i])
            tk += mvm * vm + iom * om
            if i < 2:
                tf += 0.5 * (added_mass[c] * Y[c, i] + added_mass[c + 1] * Y[c + 1, i]) * vm
    out[0] = 0.5 * ds * ub
    out[1] = 0.5 * ds * ut
    out[2] = 0.5 * ds * tk
    out[3] = 0.5 * ds * tf


def _elastic_strain(Y: np.ndarray, props) -> np.ndarray:
    """Y (N+1, 12) with κ replaced by κ − κ⁰ (a copy where the rod has an intrinsic
    curvature, Y itself where it has none)."""
    kappa0 = getattr(props, "intrinsic_curvature", None)
    if kappa0 is None:
        return Y
    Z = np.array(Y, dtype=float)
    Z[:, 9:12] -= kappa0
    return Z


def _energy_parts(Y: np.ndarray, props) -> np.ndarray:
    """Bending, torsion, kinetic and fluid energy (4,), J, of the state Y (N+1, 12)
    (:func:`_energies_kernel`)."""
    e = np.empty(4)
    Y = _elastic_strain(Y, props)
    _energies_kernel(np.ascontiguousarray(Y, dtype=float), props.stiffness, props.rho_a,
                     props.inertia, props.added_mass, float(props.ds), e)
    return e


def energies(Y: np.ndarray, props) -> dict:
    """Energies (J) of the state Y (N+1, 12): keys energy_bending, energy_torsion,
    energy_kinetic, energy_kinetic_fluid, energy_total (module docstring; compiled,
    :func:`_energies_kernel`). Raises nothing for a well-formed Y; non-finite fields give
    non-finite energies."""
    ub, ut, tk, tf = (float(x) for x in _energy_parts(Y, props))
    return {
        "energy_bending": ub,
        "energy_torsion": ut,
        "energy_kinetic": tk,
        "energy_kinetic_fluid": tf,
        "energy_total": ub + ut + tk + tf,
    }


def total_and_kinetic(Y: np.ndarray, props) -> tuple[float, float]:
    """The total energy E = U_b + U_t + T + T_f and the kinetic part T + T_f (J, J) of the
    state Y (N+1, 12) (module docstring; the per-step energy check's figures,
    :class:`solver.balance.EnergyBalance`, without building :func:`energies`' dict).
    Raises nothing for a well-formed Y."""
    e = _energy_parts(Y, props)
    return float(e[0] + e[1] + e[2] + e[3]), float(e[2] + e[3])


def end_loads(Y: np.ndarray, props) -> np.ndarray:
    """Loads (2, 6) on the rod at s = 0 and s = L, conjugate to (v, ω) of the end nodes
    in the body frame: −(f, q) at s = 0 and +(f, q) at s = L, f in N and q = diag(EJ1,
    EJ2, GJ3)·(κ − κ⁰) in N·m (seed eqs. 2-5, boundary terms of the box scheme's flux).

    Y : (N+1, 12) state (v, ω, f, κ); props : RodProperties. Raises nothing.
    """
    Y = _elastic_strain(Y, props)
    out = np.empty((2, 6))
    out[0, 0:3] = -Y[0, 6:9]
    out[0, 3:6] = -props.stiffness[0] * Y[0, 9:12]
    out[1, 0:3] = Y[-1, 6:9]
    out[1, 3:6] = props.stiffness[-1] * Y[-1, 9:12]
    return out


def end_power(Y: np.ndarray, props, loads: np.ndarray | None = None) -> float:
    """Power (W) put into the rod at its two ends by the end loads: Σ end_loads·(v, ω)
    at the end nodes. ``loads`` (2, 6), if given, are :func:`end_loads` of Y."""
    if loads is None:
        loads = end_loads(Y, props)
    return float(np.sum(loads * Y[[0, -1], 0:6]))


def distributed_power(Y: np.ndarray, body_force: np.ndarray | None, props) -> float:
    """Power (W) of a distributed body-frame force (N+1, 3) N/m on the velocities of Y."""
    if body_force is None:
        return 0.0
    return float(np.dot(props.quad_weights, np.einsum("ni,ni->n", body_force, Y[:, 0:3])))


@numba.njit(cache=True)
def end_work_into(Y, Y_old, h, gamma, am, af, xdot_old, load_old, stiffness, xdot, loads):
    """One accepted step's bookkeeping at the two end sections: the end loads (2, 6) of
    Y into ``loads`` (:func:`end_loads`), the displacement rates (2, 6) of the end
    sections by the scheme's generalized-α relation, ẋ^{n+1} = ((1 − αf) y^{n+1} +
    αf y^n − αm ẋ^n)/(1 − αm) with y the end nodes' (v, ω), into ``xdot``, and their
    increments Δx = h((1 − γ) ẋ^n + γ ẋ^{n+1}). Returns (the work put in over the step,
    Σ ½(F^n + F^{n+1})·Δx (J); the end power Σ F^{n+1}·y^{n+1} (W); Δφ at s = 0 and at
    s = L (rad), the a3 components of Δx). Y, Y_old (N+1, 12); stiffness (N+1, 3).
    The one home of the end terms of :meth:`solver.run.RodRun.try_step`."""
    work = 0.0
    power = 0.0
    dphi0 = 0.0
    dphi1 = 0.0
    for e in range(2):
        k = 0 if e == 0 else Y.shape[0] - 1
        sign = -1.0 if e == 0 else 1.0
        for i in range(3):
            loads[e, i] = sign * Y[k, 6 + i]
            loads[e, 3 + i] = sign * stiffness[k, i] * Y[k, 9 + i]
        for i in range(6):
            rate = (1.0 - af) * Y[k, i] + af * Y_old[k, i]
            xdot[e, i] = (rate - am * xdot_old[e, i]) / (1.0 - am)
            dx = h * ((1.0 - gamma) * xdot_old[e, i] + gamma * xdot[e, i])
            work += 0.5 * (load_old[e, i] + loads[e, i]) * dx
            power += loads[e, i] * Y[k, i]
            if i == 5:
                if e == 0:
                    dphi0 = dx
                else:
                    dphi1 = dx
    return work, power, dphi0, dphi1


@numba.njit(cache=True)
def distributed_work_into(Y, Y_old, h, gamma, am, af, vdot_old, body_old, has_old, body,
                          has_new, weights, vdot):
    """The same bookkeeping for distributed body-frame loads (N+1, 3) N/m at every node
    (nodal quadrature weights (N+1,) m): the nodes' rates by the generalized-α relation
    into ``vdot``, and (the work Σ_n w_n ½(B^n + B^{n+1})·Δx_n over the step, a load
    absent at one level counting as zero (J); the power Σ_n w_n B^{n+1}·v_n (W))."""
    work = 0.0
    power = 0.0
    for k in range(Y.shape[0]):
        acc = 0.0
        pk = 0.0
        for i in range(3):
            rate = (1.0 - af) * Y[k, i] + af * Y_old[k, i]
            vdot[k, i] = (rate - am * vdot_old[k, i]) / (1.0 - am)
            dx = h * ((1.0 - gamma) * vdot_old[k, i] + gamma * vdot[k, i])
            b = 0.0
            if has_old:
                b += body_old[k, i]
            if has_new:
                b += body[k, i]
                pk += body[k, i] * Y[k, i]
            acc += 0.5 * b * dx
        work += weights[k] * acc
        power += weights[k] * pk
    return work, power
