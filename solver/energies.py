"""Energies of the rod and the power put in at its ends (numerics-notes §4.1).

All integrals are trapezoid sums over the nodes with the local section properties.

* bending   U_b = ½ ∫ (EJ1 κ1² + EJ2 κ2²) ds
* torsion   U_t = ½ ∫ GJ3 κ3² ds
* kinetic   T   = ½ ∫ (ρA |v|² + ωᵀ I ω) ds      (the rod's own)
* fluid     T_f = ½ ∫ C_a ρ_f A |v_n|² ds        (the added mass's share, reported apart)
* total     E   = U_b + U_t + T + T_f
* end power P = f(L)·v(L) + q(L)·ω(L) − f(0)·v(0) − q(0)·ω(0)  (W; f, q: internal force and
  moment exerted by the part beyond s on the part before it, see solver.boundary)

Units: J and W. Y is (N+1, 12) = (v, ω, f, κ) per node in the body frame.
"""
from __future__ import annotations

import numpy as np

__all__ = ["energies", "end_power", "distributed_power"]


def energies(Y: np.ndarray, props) -> dict:
    """Energies (J) of the state Y (N+1, 12): keys energy_bending, energy_torsion,
    energy_kinetic, energy_kinetic_fluid, energy_total."""
    w = props.quad_weights
    v, om, k = Y[:, 0:3], Y[:, 3:6], Y[:, 9:12]
    B = props.stiffness
    ub = 0.5 * np.dot(w, B[:, 0] * k[:, 0] ** 2 + B[:, 1] * k[:, 1] ** 2)
    ut = 0.5 * np.dot(w, B[:, 2] * k[:, 2] ** 2)
    tk = 0.5 * np.dot(w, props.rho_a * np.einsum("ni,ni->n", v, v)
                      + np.einsum("ni,ni->n", props.inertia * om, om))
    tf = 0.5 * np.dot(w, props.added_mass * (v[:, 0] ** 2 + v[:, 1] ** 2))
    return {
        "energy_bending": float(ub),
        "energy_torsion": float(ut),
        "energy_kinetic": float(tk),
        "energy_kinetic_fluid": float(tf),
        "energy_total": float(ub + ut + tk + tf),
    }


def end_power(Y: np.ndarray, props) -> float:
    """Power (W) put into the rod at its two ends by the end loads."""
    q0 = props.stiffness[0] * Y[0, 9:12]
    qn = props.stiffness[-1] * Y[-1, 9:12]
    p_end = np.dot(Y[-1, 6:9], Y[-1, 0:3]) + np.dot(qn, Y[-1, 3:6])
    p_start = -np.dot(Y[0, 6:9], Y[0, 0:3]) - np.dot(q0, Y[0, 3:6])
    return float(p_end + p_start)


def distributed_power(Y: np.ndarray, body_force: np.ndarray | None, props) -> float:
    """Power (W) of a distributed body-frame force (N+1, 3) N/m on the velocities of Y."""
    if body_force is None:
        return 0.0
    return float(np.dot(props.quad_weights, np.einsum("ni,ni->n", body_force, Y[:, 0:3])))
