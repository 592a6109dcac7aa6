"""The space-time difference equations of the rod and their Newton solution.

Continuous model (Goyal, Perkins & Lee, seed eqs. 2-5), body frame, a3 = (0, 0, 1):

    E1  ω' + κ×ω − ∂κ/∂t                                   = 0   (compatibility)
    E2  v' + κ×v − ω×a3                                    = 0   (inextensibility)
    E3  f' + κ×f − M_t (∂v/∂t + ω×v) + B                   = 0   (linear momentum)
    E4  q' + κ×q − I ∂ω/∂t − ω×(Iω) − f×a3 + Q             = 0   (angular momentum)

with q = diag(EJ1, EJ2, GJ3) κ (seed eq. 1) and M_t = ρA + C_a ρ_f A on a1, a2 (Morison
added mass). Written as M Ẏ + (K Y)' + F(Y) = 0 per node with Y = (v, ω, f, κ) ∈ R¹².

Discretisation (docs/numerics.md): the box (centred) difference in arclength on each cell
[s_{k-1}, s_k] and generalized-α in time as Gobat & Grosenbaugh (2001) apply Chung &
Hulbert (1993), with the weights on the old level (WHOI Cable's convention):

    R_cell = ⟨M Ẏ^{n+1-αm}⟩ + [(KY)_k − (KY)_{k-1}]^{n+1-αf}/Δs + ⟨F⟩^{n+1-αf} = 0
    Ẏ^{n+1} = (Y^{n+1} − Y^n)/(γΔt) − (1−γ)/γ · Ẏ^n
    αf = ρ∞/(1+ρ∞),  αm = (3ρ∞−1)/(2(1+ρ∞)),  γ = ½ + αf − αm

where Z^{n+1-α} = (1−α) Z^{n+1} + α Z^n and ⟨Z⟩ = ½(Z_{k-1} + Z_k). The difference of
the flux (KY) = (ω, v, f, q) keeps q continuous where the stiffness changes. The 12
boundary rows (6 per end) are imposed at the new level, unweighted.

Each step is one nonlinear system for all 12(N+1) unknowns, solved by Newton with the
analytic Jacobian in LAPACK band storage (kl = ku = 17), equilibrated by a column scale
(characteristic size of each unknown) and a row scale (size of the terms of each row);
the LU factor is reused across iterations (chord) and refactored when convergence slows.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from .banded import NV
from .kinematics import (_exp_one, _matrix_into, _right_jacobian_into, quat_exp,
                         quat_multiply, quat_to_matrix, right_jacobian, skew, space_route)

__all__ = ["alpha_parameters", "StepParameters", "RodSystem", "BACKWARD_EULER"]

# column offsets of the unknowns in a node's 12-vector, and row offsets of E1..E4
V, W, F, K = 0, 3, 6, 9
E1, E2, E3, E4 = 0, 3, 6, 9


@dataclass(frozen=True)
class StepParameters:
    """Generalized-α weights with the weights on the OLD level (WHOI Cable convention).

    alpha_m, alpha_f: weights of the old level in the inertia and in the other terms;
    gamma: weight of the new-level derivative in the generalized trapezoid relation.
    """

    alpha_m: float
    alpha_f: float
    gamma: float


BACKWARD_EULER = StepParameters(0.0, 0.0, 1.0)


def alpha_parameters(rho_inf: float) -> StepParameters:
    """Generalized-α parameters from the spectral radius at infinite frequency ρ∞.

    αf = ρ∞/(1+ρ∞), αm = (3ρ∞−1)/(2(1+ρ∞)), γ = ½ + αf − αm: Chung & Hulbert (1993) for
    first-order systems as in Jansen, Whiting & Hulbert (2000) with the weights moved to
    the old level (Gobat & Grosenbaugh 2001; numerics-notes §1.2). Second order for every
    ρ∞ and unconditionally stable for ρ∞ in [0, 1]; ρ∞ = 1 is the trapezoidal rule.

    Raises ValueError outside [0, 1].
    """
    if not 0.0 <= rho_inf <= 1.0:
        raise ValueError(f"rho_inf must lie in [0, 1], got {rho_inf}")
    af = rho_inf / (1.0 + rho_inf)
    am = (3.0 * rho_inf - 1.0) / (2.0 * (1.0 + rho_inf))
    return StepParameters(am, af, 0.5 + af - am)


@numba.njit(cache=True, inline="always")
def _skew_into(d, k, r0, c0, a0, a1, a2, rs, cs, sign):
    """d[k, r0:r0+3, c0:c0+3] += sign · diag(rs) [a]× diag(cs) for one node."""
    d[k, r0, c0 + 1] -= sign * a2 * rs[0] * cs[1]
    d[k, r0, c0 + 2] += sign * a1 * rs[0] * cs[2]
    d[k, r0 + 1, c0] += sign * a2 * rs[1] * cs[0]
    d[k, r0 + 1, c0 + 2] -= sign * a0 * rs[1] * cs[2]
    d[k, r0 + 2, c0] -= sign * a1 * rs[2] * cs[0]
    d[k, r0 + 2, c0 + 1] += sign * a0 * rs[2] * cs[1]


@numba.njit(cache=True)
def _node_jacobian_kernel(Y, mass_t, stiffness, inertia, d):
    """∂F/∂Y (N+1, 12, 12) of the node terms without loads (:meth:`RodSystem.node_terms`),
    written into d: the cross products of seed eqs. 2-5 per node."""
    one = np.ones(3)
    for k in range(Y.shape[0]):
        for i in range(12):
            for j in range(12):
                d[k, i, j] = 0.0
        v0, v1, v2 = Y[k, V], Y[k, V + 1], Y[k, V + 2]
        w0, w1, w2 = Y[k, W], Y[k, W + 1], Y[k, W + 2]
        f0, f1, f2 = Y[k, F], Y[k, F + 1], Y[k, F + 2]
        k0, k1, k2 = Y[k, K], Y[k, K + 1], Y[k, K + 2]
        m = mass_t[k]
        B = stiffness[k]
        I = inertia[k]
        # E1: κ×ω
        _skew_into(d, k, E1, W, k0, k1, k2, one, one, 1.0)
        _skew_into(d, k, E1, K, w0, w1, w2, one, one, -1.0)
        # E2: κ×v + a3×ω
        _skew_into(d, k, E2, V, k0, k1, k2, one, one, 1.0)
        _skew_into(d, k, E2, K, v0, v1, v2, one, one, -1.0)
        d[k, E2, W + 1] -= 1.0
        d[k, E2 + 1, W] += 1.0
        # E3: κ×f − M_t(ω×v)
        _skew_into(d, k, E3, F, k0, k1, k2, one, one, 1.0)
        _skew_into(d, k, E3, K, f0, f1, f2, one, one, -1.0)
        _skew_into(d, k, E3, W, v0, v1, v2, m, one, 1.0)
        _skew_into(d, k, E3, V, w0, w1, w2, m, one, -1.0)
        # E4: κ×Bκ − ω×Iω + a3×f
        _skew_into(d, k, E4, K, k0, k1, k2, one, B, 1.0)
        _skew_into(d, k, E4, K, B[0] * k0, B[1] * k1, B[2] * k2, one, one, -1.0)
        _skew_into(d, k, E4, W, w0, w1, w2, one, I, -1.0)
        _skew_into(d, k, E4, W, I[0] * w0, I[1] * w1, I[2] * w2, one, one, 1.0)
        d[k, E4, F + 1] -= 1.0
        d[k, E4 + 1, F] += 1.0


@numba.njit(cache=True)
def _node_forces_kernel(Y, mass_t, stiffness, inertia, Fv):
    """F(Y) per node (N+1, 12) without loads (:meth:`RodSystem.node_terms`), written into
    Fv: E1 κ×ω, E2 κ×v + a3×ω, E3 κ×f − M_t(ω×v), E4 κ×Bκ − ω×Iω + a3×f (seed eqs. 2-5).
    The operations in numpy's order (the cross products component by component), so the
    values are those of the array expressions it replaces, bit for bit."""
    for k in range(Y.shape[0]):
        v0, v1, v2 = Y[k, V], Y[k, V + 1], Y[k, V + 2]
        w0, w1, w2 = Y[k, W], Y[k, W + 1], Y[k, W + 2]
        f0, f1, f2 = Y[k, F], Y[k, F + 1], Y[k, F + 2]
        k0, k1, k2 = Y[k, K], Y[k, K + 1], Y[k, K + 2]
        B = stiffness[k]
        I = inertia[k]
        m = mass_t[k]
        q0, q1, q2 = B[0] * k0, B[1] * k1, B[2] * k2
        i0, i1, i2 = I[0] * w0, I[1] * w1, I[2] * w2
        Fv[k, E1] = k1 * w2 - k2 * w1
        Fv[k, E1 + 1] = k2 * w0 - k0 * w2
        Fv[k, E1 + 2] = k0 * w1 - k1 * w0
        Fv[k, E2] = (k1 * v2 - k2 * v1) - w1
        Fv[k, E2 + 1] = (k2 * v0 - k0 * v2) + w0
        Fv[k, E2 + 2] = k0 * v1 - k1 * v0
        Fv[k, E3] = (k1 * f2 - k2 * f1) - m[0] * (w1 * v2 - w2 * v1)
        Fv[k, E3 + 1] = (k2 * f0 - k0 * f2) - m[1] * (w2 * v0 - w0 * v2)
        Fv[k, E3 + 2] = (k0 * f1 - k1 * f0) - m[2] * (w0 * v1 - w1 * v0)
        Fv[k, E4] = ((k1 * q2 - k2 * q1) - (w1 * i2 - w2 * i1)) - f1
        Fv[k, E4 + 1] = ((k2 * q0 - k0 * q2) - (w2 * i0 - w0 * i2)) + f0
        Fv[k, E4 + 2] = (k0 * q1 - k1 * q0) - (w0 * i1 - w1 * i0)


@numba.njit(cache=True, inline="always")
def _mass_row(Y, k, i, mass_t, inertia, out):
    """(M Y)_k component i of E1..E4 into out (4,): −κ_i, 0, −M_t,i v_i, −I_i ω_i (the
    mass operator of the module docstring, its one home)."""
    out[0] = -Y[k, K + i]
    out[1] = 0.0
    out[2] = -mass_t[k, i] * Y[k, V + i]
    out[3] = -inertia[k, i] * Y[k, W + i]


@numba.njit(cache=True, inline="always")
def _flux_row(Y, k, i, stiffness, out):
    """(K Y)_k component i of E1..E4 into out (4,): ω_i, v_i, f_i, q_i = B_i κ_i."""
    out[0] = Y[k, W + i]
    out[1] = Y[k, V + i]
    out[2] = Y[k, F + i]
    out[3] = stiffness[k, i] * Y[k, K + i]


@numba.njit(cache=True)
def _apply_M_kernel(Y, mass_t, inertia, out):
    """M Y per node (N+1, 12) into out (:meth:`RodSystem._apply_M`)."""
    row = np.empty(4)
    for k in range(Y.shape[0]):
        for i in range(3):
            _mass_row(Y, k, i, mass_t, inertia, row)
            for e in range(4):
                out[k, 3 * e + i] = row[e]


@numba.njit(cache=True)
def _flux_kernel(Y, stiffness, out):
    """K Y per node (N+1, 12) into out (:meth:`RodSystem._flux`)."""
    row = np.empty(4)
    for k in range(Y.shape[0]):
        for i in range(3):
            _flux_row(Y, k, i, stiffness, row)
            for e in range(4):
                out[k, 3 * e + i] = row[e]


@numba.njit(cache=True)
def _cells_kernel(Y, Fn, zconst, flux_const, mass_t, stiffness, inertia, cm, af, ds, out):
    """The cell rows of the residual (N, 12) into out: ⟨M Ẏ^{n+1−αm}⟩ + [(KY)_k −
    (KY)_{k−1}]^{n+1−αf}/Δs + ⟨F⟩^{n+1−αf} (module docstring), from the node values
    Z = ½c_m M Y + ½(1 − αf) F + Z_const and flux (1 − αf) K Y + flux_const. In the
    order of the array expressions it replaces (the same values, bit for bit)."""
    hc = 0.5 * cm
    hf = 0.5 * (1.0 - af)
    gf = 1.0 - af
    n_cells = Y.shape[0] - 1
    z_prev = np.empty(NV)
    z_next = np.empty(NV)
    x_prev = np.empty(NV)
    x_next = np.empty(NV)
    mrow = np.empty(4)
    krow = np.empty(4)
    for k in range(n_cells + 1):
        for i in range(3):
            _mass_row(Y, k, i, mass_t, inertia, mrow)
            _flux_row(Y, k, i, stiffness, krow)
            for e in range(4):
                z_next[3 * e + i] = (hc * mrow[e] + hf * Fn[k, 3 * e + i]) + zconst[k, 3 * e + i]
                x_next[3 * e + i] = gf * krow[e] + flux_const[k, 3 * e + i]
        if k > 0:
            for j in range(NV):
                out[k - 1, j] = (z_prev[j] + z_next[j]) + (x_next[j] - x_prev[j]) / ds
        for j in range(NV):
            z_prev[j] = z_next[j]
            x_prev[j] = x_next[j]


@numba.njit(cache=True)
def _add_inertia_kernel(blocks, c, mass_t, inertia):
    """c·∂⟨M Y⟩/∂Y added to the cell blocks (N, 12, 24) in place (:meth:`RodSystem.
    add_inertia`)."""
    hc = 0.5 * c
    for k in range(blocks.shape[0]):
        for off, node in ((0, k), (NV, k + 1)):
            for i in range(3):
                blocks[k, E1 + i, off + K + i] -= hc
                blocks[k, E3 + i, off + V + i] -= hc * mass_t[node, i]
                blocks[k, E4 + i, off + W + i] -= hc * inertia[node, i]


@numba.njit(cache=True)
def _cell_blocks_kernel(dF, mass_t, stiffness, inertia, cm, af, ds, blocks):
    """The cell blocks (N, 12, 24) of the step's Jacobian on [node k−1 | node k] into
    blocks: ½(1 − αf) ∂F/∂Y of both nodes, the inertia c_m ∂⟨M Y⟩/∂Y and the flux
    difference ±(1 − αf)/Δs ∂(KY)/∂Y. The same values as the array expressions it
    replaces, bit for bit."""
    hf = 0.5 * (1.0 - af)
    qf = (1.0 - af) / ds
    n_cells = blocks.shape[0]
    for k in range(n_cells):
        for i in range(NV):
            for j in range(NV):
                blocks[k, i, j] = hf * dF[k, i, j]
                blocks[k, i, NV + j] = hf * dF[k + 1, i, j]
    _add_inertia_kernel(blocks, cm, mass_t, inertia)
    for k in range(n_cells):
        for off, sgn, node in ((0, -1.0, k), (NV, 1.0, k + 1)):
            for i in range(3):
                blocks[k, E1 + i, off + W + i] += sgn * qf
                blocks[k, E2 + i, off + V + i] += sgn * qf
                blocks[k, E3 + i, off + F + i] += sgn * qf
                blocks[k, E4 + i, off + K + i] += sgn * qf * stiffness[node, i]


@numba.njit(cache=True)
def _contact_loads_kernel(nodes, weights, force, out):
    """Node loads (N+1, 3) N/m added into out: node nodes[p, a] receives
    weights[p, a] · force[p] (:class:`solver.contact.ContactEvaluation`)."""
    for p in range(nodes.shape[0]):
        for a in range(nodes.shape[1]):
            b = nodes[p, a]
            w = weights[p, a]
            for c in range(3):
                out[b, c] += w * force[p, c]


@numba.njit(cache=True)
def _contact_band_kernel(nodes, weights, d_dr, d_dv, R, Y, Jr, dt, diag):
    """The node-local approximation of the contact loads' Jacobian (the band
    preconditioner's part, :meth:`RodSystem._contact_terms`) added into diag (N+1, 3, 6):
    positions advanced per node in time, r_b ≈ r_b^n + ½Δt(ṙ_b^n + R_b v_b), so with
    H_b = ½Δt ∂F/∂r_b + ∂F/∂ṙ_b, ∂F/∂v_b ≈ H_b R_b and ∂F/∂ω_b ≈ −½Δt H_b R_b [v_b]×
    J_r(θ_b), rotated to node b's body frame (R_bᵀ) and weighted by its load weight.
    R (N+1, 3, 3), Y (N+1, 12), Jr (N+1, 3, 3) the right Jacobians of the time-route
    rotations θ, dt s."""
    HR = np.empty((3, 3))
    S = np.empty((3, 3))
    HW = np.empty((3, 3))
    for p in range(nodes.shape[0]):
        for a in range(nodes.shape[1]):
            b = nodes[p, a]
            for i in range(3):
                for j in range(3):
                    acc = 0.0
                    for k in range(3):
                        acc += (0.5 * dt * d_dr[p, a, i, k] + d_dv[p, a, i, k]) * R[b, k, j]
                    HR[i, j] = acc
            # S = [v_b]× J_r(θ_b)
            v0, v1, v2 = Y[b, V], Y[b, V + 1], Y[b, V + 2]
            for j in range(3):
                S[0, j] = -v2 * Jr[b, 1, j] + v1 * Jr[b, 2, j]
                S[1, j] = v2 * Jr[b, 0, j] - v0 * Jr[b, 2, j]
                S[2, j] = -v1 * Jr[b, 0, j] + v0 * Jr[b, 1, j]
            for i in range(3):
                for j in range(3):
                    HW[i, j] = -0.5 * dt * (HR[i, 0] * S[0, j] + HR[i, 1] * S[1, j]
                                            + HR[i, 2] * S[2, j])
            w = weights[p, a]
            for i in range(3):
                for j in range(3):
                    acc_v = R[b, 0, i] * HR[0, j] + R[b, 1, i] * HR[1, j] + R[b, 2, i] * HR[2, j]
                    acc_w = R[b, 0, i] * HW[0, j] + R[b, 1, i] * HW[1, j] + R[b, 2, i] * HW[2, j]
                    diag[b, i, j] += w * acc_v
                    diag[b, i, 3 + j] += w * acc_w


@numba.njit(cache=True, inline="always")
def _mat3(A, a, B, b, scale, out, o):
    """out[o] = scale · A[a] B[b] for stacks of (3, 3) matrices."""
    for i in range(3):
        for j in range(3):
            out[o, i, j] = scale * (A[a, i, 0] * B[b, 0, j] + A[a, i, 1] * B[b, 1, j]
                                    + A[a, i, 2] * B[b, 2, j])


@numba.njit(cache=True)
def _exact_frames_kernel(R, Y, theta, ds, dt, C, D, tmid, rdot, A0):
    """The pose data of :meth:`RodSystem._exact_loads` (its docstring has the formulas),
    per cell k (N,): κ̄_k = ½(κ_{k−1} + κ_k), the mid-cell frame M_k = R_{k−1} exp(½Δs κ̄_k)
    (its a3 into tmid (N, 3)), C_k = Δs R_k J_r(Δs κ̄_k), D_k = ½Δs M_k J_r(½Δs κ̄_k)
    (N, 3, 3); per node ṙ = R v (N+1, 3); A0 (3, 3) = ½Δt R_0 J_r(θ_0)."""
    n1 = Y.shape[0]
    H = np.empty((1, 3, 3))
    M = np.empty((1, 3, 3))
    J = np.empty((1, 3, 3))
    for k in range(1, n1):
        c = k - 1
        kx = 0.5 * (Y[k, K] + Y[c, K])
        ky = 0.5 * (Y[k, K + 1] + Y[c, K + 1])
        kz = 0.5 * (Y[k, K + 2] + Y[c, K + 2])
        w, x, y, z = _exp_one(0.5 * ds * kx, 0.5 * ds * ky, 0.5 * ds * kz)
        _matrix_into(w, x, y, z, H, 0)
        _mat3(R, c, H, 0, 1.0, M, 0)
        for i in range(3):
            tmid[c, i] = M[0, i, 2]
        _right_jacobian_into(ds * kx, ds * ky, ds * kz, J, 0)
        _mat3(R, k, J, 0, ds, C, c)
        _right_jacobian_into(0.5 * ds * kx, 0.5 * ds * ky, 0.5 * ds * kz, J, 0)
        _mat3(M, 0, J, 0, 0.5 * ds, D, c)
    for k in range(n1):
        for i in range(3):
            rdot[k, i] = (R[k, i, 0] * Y[k, V] + R[k, i, 1] * Y[k, V + 1]
                          + R[k, i, 2] * Y[k, V + 2])
    _right_jacobian_into(theta[0, 0], theta[0, 1], theta[0, 2], J, 0)
    for i in range(3):
        for j in range(3):
            A0[i, j] = 0.5 * dt * (R[0, i, 0] * J[0, 0, j] + R[0, i, 1] * J[0, 1, j]
                                   + R[0, i, 2] * J[0, 2, j])


#: the contact arguments of _exact_loads_kernel when no pair is active
_NO_PAIRS = (np.zeros((0, 5), np.intp), np.zeros((0, 3, 30)), np.zeros((0, 15)),
             np.zeros((0, 3)), np.zeros((0, 5)), np.zeros((0, 5)))


@numba.njit(cache=True)
def _exact_loads_kernel(dY, A0, C, D, R, rdot, tmid, G, L, ds, dt, nodes, A, dtdr, Fp, w,
                        dwdt):
    """Compiled body of :meth:`RodSystem._exact_loads` (its docstring has the formulas):
    the prefix sums along the rod, the pairs' load changes and the body-frame rotation
    in one pass each; returns dB (N+1, 3)."""
    n1 = dY.shape[0]
    dphi = np.empty((n1, 3))
    dr = np.empty((n1, 3))
    dG = np.empty((n1, 3))
    for i in range(3):
        dphi[0, i] = A0[i, 0] * dY[0, W] + A0[i, 1] * dY[0, W + 1] + A0[i, 2] * dY[0, W + 2]
    # dr_0 = ½Δt(δφ_0 × ṙ_0 + R_0 δv_0)
    p0, p1, p2 = dphi[0, 0], dphi[0, 1], dphi[0, 2]
    c0 = p1 * rdot[0, 2] - p2 * rdot[0, 1]
    c1 = p2 * rdot[0, 0] - p0 * rdot[0, 2]
    c2 = p0 * rdot[0, 1] - p1 * rdot[0, 0]
    dv0, dv1, dv2 = dY[0, V], dY[0, V + 1], dY[0, V + 2]
    dr[0, 0] = 0.5 * dt * (c0 + R[0, 0, 0] * dv0 + R[0, 0, 1] * dv1 + R[0, 0, 2] * dv2)
    dr[0, 1] = 0.5 * dt * (c1 + R[0, 1, 0] * dv0 + R[0, 1, 1] * dv1 + R[0, 1, 2] * dv2)
    dr[0, 2] = 0.5 * dt * (c2 + R[0, 2, 0] * dv0 + R[0, 2, 1] * dv1 + R[0, 2, 2] * dv2)
    for k in range(1, n1):
        c = k - 1
        k0 = 0.5 * (dY[k, K] + dY[c, K])
        k1 = 0.5 * (dY[k, K + 1] + dY[c, K + 1])
        k2 = 0.5 * (dY[k, K + 2] + dY[c, K + 2])
        # δψ (mid-cell rotation) from δφ_{k−1}, then δφ_k
        s0 = dphi[c, 0] + D[c, 0, 0] * k0 + D[c, 0, 1] * k1 + D[c, 0, 2] * k2
        s1 = dphi[c, 1] + D[c, 1, 0] * k0 + D[c, 1, 1] * k1 + D[c, 1, 2] * k2
        s2 = dphi[c, 2] + D[c, 2, 0] * k0 + D[c, 2, 1] * k1 + D[c, 2, 2] * k2
        for i in range(3):
            dphi[k, i] = dphi[c, i] + C[c, i, 0] * k0 + C[c, i, 1] * k1 + C[c, i, 2] * k2
        t0, t1, t2 = tmid[c, 0], tmid[c, 1], tmid[c, 2]
        dr[k, 0] = dr[c, 0] + ds * (s1 * t2 - s2 * t1)
        dr[k, 1] = dr[c, 1] + ds * (s2 * t0 - s0 * t2)
        dr[k, 2] = dr[c, 2] + ds * (s0 * t1 - s1 * t0)
    for k in range(n1):
        dG[k, 0] = G[k, 1] * dphi[k, 2] - G[k, 2] * dphi[k, 1]
        dG[k, 1] = G[k, 2] * dphi[k, 0] - G[k, 0] * dphi[k, 2]
        dG[k, 2] = G[k, 0] * dphi[k, 1] - G[k, 1] * dphi[k, 0]
    n_p = nodes.shape[0]
    n_b = nodes.shape[1]
    z = np.empty(6 * n_b)
    for p in range(n_p):
        for b in range(n_b):
            a = nodes[p, b]
            # δr_b and δṙ_b = δφ × ṙ + R δv
            for i in range(3):
                z[3 * b + i] = dr[a, i]
            q0, q1, q2 = dphi[a, 0], dphi[a, 1], dphi[a, 2]
            o = 3 * n_b + 3 * b
            z[o] = q1 * rdot[a, 2] - q2 * rdot[a, 1]
            z[o + 1] = q2 * rdot[a, 0] - q0 * rdot[a, 2]
            z[o + 2] = q0 * rdot[a, 1] - q1 * rdot[a, 0]
            for i in range(3):
                z[o + i] += (R[a, i, 0] * dY[a, V] + R[a, i, 1] * dY[a, V + 1]
                             + R[a, i, 2] * dY[a, V + 2])
        dtp = 0.0
        for m in range(3 * n_b):
            dtp += dtdr[p, m] * z[m]
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        for m in range(6 * n_b):
            f0 += A[p, 0, m] * z[m]
            f1 += A[p, 1, m] * z[m]
            f2 += A[p, 2, m] * z[m]
        for b in range(n_b):
            a = nodes[p, b]
            wb = w[p, b]
            tb = dwdt[p, b] * dtp
            dG[a, 0] += wb * f0 + tb * Fp[p, 0]
            dG[a, 1] += wb * f1 + tb * Fp[p, 1]
            dG[a, 2] += wb * f2 + tb * Fp[p, 2]
    out = np.empty((n1, 3))
    for k in range(n1):
        for i in range(3):
            acc = R[k, 0, i] * dG[k, 0] + R[k, 1, i] * dG[k, 1] + R[k, 2, i] * dG[k, 2]
            for j in range(6):
                acc -= L[k, i, j] * dY[k, j]
            out[k, i] = acc
    return out



class RodSystem:
    """Residual and Jacobian of one time step of the box/generalized-α scheme.

    Parameters
    ----------
    props : RodProperties
    loads : LoadModel
    contact : optional self-contact model (see :mod:`solver.contact`) or None

    Newton's method for the step (iteration, line search, linear solver) is
    :class:`solver.newton.Newton`.
    """

    def __init__(self, props, loads, contact=None):
        self.p = props
        self.loads = loads
        self.contact = contact
        self.n_nodes = props.s.size
        self.n_cells = self.n_nodes - 1
        self.n = NV * self.n_nodes
        self.needs_pose = loads.has_global or contact is not None
        # characteristic sizes of the unknowns (floors of the column scale)
        length = props.s[-1]
        b0 = float(np.max(props.stiffness[:, :2]))
        m0 = float(np.max(props.rho_a))
        tc = length**2 * np.sqrt(m0 / b0)
        self.tc = float(tc)       # bending time scale L²√(ρA/EJ), s
        self.floor = np.repeat([length / tc, 1.0 / tc, b0 / length**2, 1.0 / length], 3)
        self.step_key = None
        # buffers
        n1 = self.n_nodes
        self._dF = np.zeros((n1, NV, NV))
        self.candidates = None
        self._blocks = np.empty((self.n_cells, NV, 2 * NV))
        self._exact = None
        self.contact_band = None
        self._load_rotation = None        # node_terms' ½Δt [Rᵀ G]× J_r(θ) (N+1, 3, 3)

    # ------------------------------------------------------------------ per step setup
    def begin_step(self, dt, params: StepParameters, t_new, Y_old, Ydot_old, F_old,
                   bc, q_old=None, r_old=None, v_old_global=None, candidates=None,
                   left_limit=False):
        """Freeze the old-level data of a step n -> n+1 of size dt (s) ending at t_new.

        Y_old, Ydot_old, F_old: (N+1, 12); bc: a BoundaryRows for t_new; q_old (N+1, 4) and
        r_old (N+1, 3) the old pose (needed for orientation-dependent loads and contact);
        v_old_global (N+1, 3) old global velocities (contact, position update);
        candidates: the contact candidates (:class:`solver.contact.ContactCandidates`)
        searched during this step's Newton iterations, or None. The closest points and
        the active contacts are re-selected at every iterate. left_limit: the step ends
        on a breakpoint, so the loads are taken as their left limit at t_new.
        """
        am, af, g = params.alpha_m, params.alpha_f, params.gamma
        self.dt, self.params, self.t_new, self.bc = dt, params, t_new, bc
        self.cm = (1.0 - am) / (g * dt)
        self.Y_old, self.Ydot_old = Y_old, Ydot_old
        # M Ẏ^{n+1-αm} = cm M Y + M·cY with cY = −cm Y^n + (αm − (1−αm)(1−γ)/γ) Ẏ^n
        cY = -self.cm * Y_old + (am - (1.0 - am) * (1.0 - g) / g) * Ydot_old
        zc = 0.5 * self._apply_M(cY) + 0.5 * af * F_old
        self._zconst = zc
        self._flux_const = af * self._flux(Y_old)
        self.q_old, self.r_old, self.v_old_global = q_old, r_old, v_old_global
        self._glob_force = (self.loads.global_force(t_new, left=left_limit)
                             if self.loads.has_global else None)
        self.candidates = candidates if (candidates is not None and candidates.runs > 0) else None
        self.last_contact = None
        self.frozen_selection = None      # set by Newton (see SelfContact.closest)
        self._pose_memo = None            # (Y, pose) of the last pose_new call this step
        self.selection = None
        # what the Jacobian's band part depends on besides the iterate (solver.newton
        # keeps a factorisation across steps while this is unchanged)
        self.step_key = (dt, params, bc.key)

    # ------------------------------------------------------------------ node pieces
    def _apply_M(self, Y):
        """M Y per node (N+1, 12): E1 −κ, E2 0, E3 −M_t v, E4 −I ω (compiled,
        :func:`_mass_row`)."""
        out = np.empty_like(Y, dtype=float)
        _apply_M_kernel(np.ascontiguousarray(Y, dtype=float), self.p.mass_t, self.p.inertia,
                        out)
        return out

    def cell_inertia(self, e):
        """The cell rows of the averaged inertia term, ⟨M e⟩ = ½(M e_{k−1} + M e_k), for
        e (N+1, 12), as a vector (n,) in the residual's row order (boundary rows 0): the
        part of the step's Jacobian proportional to c = (1 − αm)/(γΔt), per unit c."""
        Me = self._apply_M(e)
        out = np.zeros(self.n)
        out[6:6 + NV * self.n_cells] = (0.5 * (Me[:-1] + Me[1:])).ravel()
        return out

    def add_inertia(self, blocks, c):
        """Add c·∂⟨M Y⟩/∂Y to cell blocks (N, 12, 24) on [node k−1 | node k] in place:
        −½c on E1/κ, −½c·M_t on E3/v, −½c·I on E4/ω of each node (M of
        :meth:`_apply_M`). ``c`` is the coefficient of the generalized-α relation,
        (1 − αm)/(γΔt) in 1/s, or any shift of it."""
        _add_inertia_kernel(blocks, float(c), self.p.mass_t, self.p.inertia)

    def _flux(self, Y):
        """K Y per node (N+1, 12): (ω, v, f, q = Bκ) for E1..E4 (compiled,
        :func:`_flux_row`)."""
        out = np.empty_like(Y, dtype=float)
        _flux_kernel(np.ascontiguousarray(Y, dtype=float), self.p.stiffness, out)
        return out

    def pose_new(self, Y):
        """Orientation and position at the new level from the old pose and the rates.

        Without self-contact, per node (the time route): q^{n+1} = q^n ⊗ exp(θ),
        θ = ½Δt(ω^n + ω^{n+1}); r^{n+1} = r^n + ½Δt(R^n v^n + R^{n+1} v^{n+1}).
        With self-contact configured, the pose is the shape integrated along s from
        κ^{n+1} (the space route, :func:`solver.kinematics.space_route`), anchored at
        node 0's time-route pose: the one centreline that is carried forward, output and
        checked, so the contact forces act on it (docs/contact.md, "One geometry").
        Returns (q (N+1, 4), R (N+1, 3, 3), r (N+1, 3) or None, θ (N+1, 3)); θ is the
        time-route rotation increment in both cases (used by the Jacobian).
        """
        memo = getattr(self, "_pose_memo", None)
        if memo is not None and np.array_equal(memo[0], Y):
            # the same iterate again (the feasibility filter and the residual of one trial
            # point): the space route is integrated once
            return memo[1]
        pose = self._pose_new(Y)
        self._pose_memo = (Y.copy(), pose)
        return pose

    def _pose_new(self, Y):
        theta = 0.5 * self.dt * (self.Y_old[:, W:W + 3] + Y[:, W:W + 3])
        if self.contact is not None and self.r_old is not None:
            q0 = quat_multiply(self.q_old[:1], quat_exp(theta[:1]))
            q0 /= np.linalg.norm(q0)
            R0 = quat_to_matrix(q0)[0]
            r0 = self.r_old[0] + 0.5 * self.dt * (self.v_old_global[0] + R0 @ Y[0, V:V + 3])
            q, r = space_route(q0[0], r0, Y[:, K:K + 3], self.p.ds)
            return q, quat_to_matrix(q), r, theta
        q = quat_multiply(self.q_old, quat_exp(theta))
        R = quat_to_matrix(q)
        r = None
        if self.r_old is not None and self.v_old_global is not None:
            vg = np.einsum("nij,nj->ni", R, Y[:, V:V + 3])
            r = self.r_old + 0.5 * self.dt * (self.v_old_global + vg)
        return q, R, r, theta

    def node_terms(self, Y, want_jacobian, pose=None, glob_force=None, extra=None):
        """F(Y) per node (N+1, 12) and, if asked, its Jacobian (N+1, 12, 12).

        pose: (R (N+1, 3, 3), θ (N+1, 3), c) for orientation-dependent loads: R the
        new-level rotation R^n exp(θ) and c = ∂θ/∂ω^{n+1} = ½Δt; None when the case has
        none. The load B = Rᵀ F_global then has ∂B/∂ω^{n+1} = c [B]× J_r(θ).
        glob_force: (N+1, 3) global-frame distributed force (N/m) or None.
        extra: (B (N+1, 3), dB/d(v, ω) (N+1, 3, 6)) an additional body-frame load and its
        node-local Jacobian in (v, ω) (self-contact), or None.
        """
        p = self.p
        Y = np.ascontiguousarray(Y)
        Fv = np.empty_like(Y)
        _node_forces_kernel(Y, p.mass_t, p.stiffness, p.inertia, Fv)
        dB_dv = None
        if self.loads.has_drag:
            bd, dB_dv = self.loads.drag(Y[:, V:V + 3], want_jacobian)
            Fv[:, E3:E3 + 3] += bd
        b_rot = None
        if pose is not None and glob_force is not None:
            R = pose[0]
            b_rot = np.einsum("nji,nj->ni", R, glob_force)
            Fv[:, E3:E3 + 3] += b_rot
        if extra is not None and extra[0] is not None:
            Fv[:, E3:E3 + 3] += extra[0]
        if not want_jacobian:
            return Fv, None
        d = self._dF
        # E1 κ×ω, E2 κ×v + a3×ω, E3 κ×f − M_t(ω×v), E4 κ×Bκ − ω×Iω + a3×f (compiled)
        _node_jacobian_kernel(Y, p.mass_t, p.stiffness, p.inertia, d)
        # E3: + B (drag, contact, rotated global loads)
        if dB_dv is not None:
            d[:, E3:E3 + 3, V:V + 3] += dB_dv
        if extra is not None and extra[1] is not None:
            d[:, E3:E3 + 3, V:V + 6] += extra[1]
        # the rotated loads' node-local block, kept for the exact load product
        # (:meth:`_exact_data`, which the band's node-local part is subtracted from)
        self._load_rotation = None
        if b_rot is not None:
            self._load_rotation = pose[2] * (skew(b_rot) @ right_jacobian(pose[1]))
            d[:, E3:E3 + 3, W:W + 3] += self._load_rotation
        return Fv, d

    # ------------------------------------------------------------------ global system
    def residual(self, Y, want_jacobian=False):
        """Residual (n,) of the step's difference equations at the iterate Y (N+1, 12).

        Returns (R, F_nodes, blocks or None, pose or None); blocks (N, 12, 24) are the
        unscaled cell Jacobian blocks on [node k-1 | node k].
        """
        p = self.p
        af = self.params.alpha_f
        pose = None
        pose_arg = None
        # the new-level pose is needed inside Newton only by global-frame loads and by
        # active contact pairs; with contact configured but no pair in this step it is
        # computed once after convergence (RodRun.try_step), not at every iterate
        if self.loads.has_global or self.candidates is not None:
            pose = self.pose_new(Y)
            pose_arg = (pose[1], pose[3], 0.5 * self.dt)
        extra = None
        glob = self._glob_force
        ev = None
        if self.candidates is not None:
            contact_global, diag, ev = self._contact_terms(Y, pose, want_jacobian)
            glob = contact_global if glob is None else glob + contact_global
            extra = (None, diag)
        Fn, dF = self.node_terms(Y, want_jacobian, pose_arg, glob, extra)
        if want_jacobian:
            # the node-local contact blocks (N+1, 3, 6) now in the band, or None: Newton
            # weights them in its preconditioner (Newton.CONTACT_BAND_WEIGHT)
            self.contact_band = extra[1] if extra is not None else None
            self._exact = None
            if self.contact is not None and pose is not None and glob is not None:
                self._exact = self._exact_data(Y, pose, glob, ev, self.contact_band)
        R = np.empty(self.n)
        cells = R[6:6 + NV * self.n_cells].reshape(self.n_cells, NV)   # a view
        Y = np.ascontiguousarray(Y)
        _cells_kernel(Y, Fn, self._zconst, self._flux_const, p.mass_t, p.stiffness,
                      p.inertia, float(self.cm), float(af), float(p.ds), cells)
        self.bc.residual(Y, R)
        blocks = None
        if want_jacobian:
            blocks = self._blocks
            _cell_blocks_kernel(dF, p.mass_t, p.stiffness, p.inertia, float(self.cm),
                                float(af), float(p.ds), blocks)
        return R, Fn, blocks, pose

    def _contact_terms(self, Y, pose, want_jacobian):
        """Self-contact load at the new level (global frame, N/m) and the node-local
        approximation of its Jacobian (the band preconditioner's part).

        The contacts are re-selected from the step's candidates on this iterate's pose
        (the space route). The exact Jacobian of the load, which is not banded, is applied
        matrix-free by :meth:`_exact_loads`; the band holds the approximation in which a
        node moves by its own time route, r_a ≈ r_a^n + ½Δt(ṙ_a^n + R_a v_a).
        Returns (F (N+1, 3) global, ∂(RᵀF)/∂(v, ω) (N+1, 3, 6) body frame or None,
        the ContactEvaluation or None).
        """
        q, R, r, theta = pose
        vg = np.einsum("nij,nj->ni", R, Y[:, V:V + 3])
        n1 = self.n_nodes
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(vg))):
            # a diverging iterate: make the residual non-finite so that Δt is cut
            return np.full((n1, 3), np.nan), None, None
        try:
            ev = self.contact.evaluate(self.candidates, r, vg, self.frozen_selection)
            self.selection = ev.selection
        except ValueError:
            return np.full((n1, 3), np.nan), None, None
        self.last_contact = ev
        force = np.zeros((n1, 3))
        if ev.count == 0:
            return force, None, ev
        if not want_jacobian:
            _contact_loads_kernel(ev.nodes, ev.weights, ev.force, force)
            return force, None, ev
        diag = np.zeros((n1, 3, 6))
        _contact_loads_kernel(ev.nodes, ev.weights, ev.force, force)
        _contact_band_kernel(ev.nodes, ev.weights, ev.d_force_d_r, ev.d_force_d_v, R,
                             np.ascontiguousarray(Y), right_jacobian(theta), float(self.dt),
                             diag)
        return force, diag, ev

    def _exact_data(self, Y, pose, glob, ev, diag):
        """What the exact Jacobian-vector product of the load terms needs (self-contact
        configured: the pose is the space route, so every node's position and frame
        depends on κ upstream of it and on node 0's motion; see :meth:`_exact_loads`)."""
        q, R, r, theta = pose
        n1, n_cells = self.n_nodes, self.n_cells
        glob = np.ascontiguousarray(glob, dtype=float)
        C = np.empty((n_cells, 3, 3))
        D = np.empty((n_cells, 3, 3))
        tmid = np.empty((n_cells, 3))
        rdot = np.empty((n1, 3))
        A0 = np.empty((3, 3))
        _exact_frames_kernel(R, np.ascontiguousarray(Y), np.ascontiguousarray(theta),
                             float(self.p.ds), float(self.dt), C, D, tmid, rdot, A0)
        # the node-local terms the band holds (subtracted in the operator): the contact
        # approximation and node_terms' rotation of the global load (computed there)
        L = np.zeros((n1, 3, 6)) if diag is None else diag.copy()
        L[:, :, 3:] += self._load_rotation
        out = dict(R=R, C=C, D=D, tmid=tmid, A0=A0, rdot=rdot, G=glob, L=L)
        if ev is not None and ev.count:
            n_p, n_b = ev.nodes.shape
            # dF_p = A_p [δr_b; δṙ_b]_(b = 1..K): (P, 3, 6K)
            A = np.concatenate([ev.d_force_d_r.transpose(0, 2, 1, 3).reshape(n_p, 3, 3 * n_b),
                                ev.d_force_d_v.transpose(0, 2, 1, 3).reshape(n_p, 3, 3 * n_b)],
                               axis=2)
            out.update(nodes=np.ascontiguousarray(ev.nodes), A=np.ascontiguousarray(A),
                       F=np.ascontiguousarray(ev.force),
                       dtdr=np.ascontiguousarray(ev.d_t_d_r.reshape(n_p, 3 * n_b)),
                       w=np.ascontiguousarray(ev.weights),
                       dwdt=np.ascontiguousarray(ev.d_weights_d_t))
        return out

    def _exact_loads(self, ex, dY):
        """Body-frame load change (N+1, 3) for a change dY (N+1, 12) of the unknowns,
        exact for the space-route pose, minus the node-local part the band holds.

        With δφ_k the global rotation of frame k (space route: R_k = R_{k−1} exp(Δs κ̄_k),
        mid-cell frame M_k = R_{k−1} exp(½Δs κ̄_k), r_k = r_{k−1} + Δs M_k a3):
        δφ_0 = R_0 J_r(θ_0) ½Δt δω_0, δφ_k = δφ_{k−1} + R_k J_r(Δs κ̄_k) Δs δκ̄_k,
        δr_0 = ½Δt(δφ_0 × ṙ_0 + R_0 δv_0), δr_k = δr_{k−1} + Δs (δφ_{k−1} +
        M_k J_r(½Δs κ̄_k) ½Δs δκ̄_k) × M_k a3, δṙ_k = δφ_k × ṙ_k + R_k δv_k (prefix
        sums: O(N)). The contact force F_p of each pair changes by Σ_b ∂F/∂r_b δr_b +
        ∂F/∂ṙ_b δṙ_b, its load w_a F_p on node a by w_a δF_p + F_p (∂w_a/∂t) δt, and the
        body-frame load B_a = R_aᵀ G_a (G the global force on a) by R_aᵀ(δG_a + G_a × δφ_a).
        """
        if "nodes" in ex:
            nodes, A, dtdr, F, w, dwdt = (ex["nodes"], ex["A"], ex["dtdr"], ex["F"], ex["w"],
                                          ex["dwdt"])
        else:
            nodes, A, dtdr, F, w, dwdt = _NO_PAIRS
        return _exact_loads_kernel(np.ascontiguousarray(dY), ex["A0"], ex["C"], ex["D"],
                                   ex["R"], ex["rdot"], ex["tmid"], ex["G"], ex["L"],
                                   float(self.p.ds), float(self.dt), nodes, A, dtdr, F, w,
                                   dwdt)

    def column_scale(self, Y):
        """Scale of each unknown (n,): max(|Y| of its kind over the grid, its floor)."""
        mags = np.abs(Y).reshape(-1, 4, 3).max(axis=(0, 2))
        s12 = np.maximum(np.repeat(mags, 3), self.floor)
        return s12

    def candidate_gaps(self, Y):
        """Surface gaps (R,) m of the closest points of the step's contact candidates at
        the iterate Y (new level), inf for run edges; empty without candidates."""
        if self.candidates is None:
            return np.zeros(0)
        r = self.pose_new(Y)[2]
        if not np.all(np.isfinite(r)):
            return np.full(self.candidates.runs, -np.inf)
        return self.contact.gaps(self.candidates, r)

