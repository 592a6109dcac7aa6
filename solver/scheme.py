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

import math
from dataclasses import dataclass

import numba
import numpy as np

from .banded import NV, copy_into, fill
from .contact.model import evaluate_into, evaluation_arrays, evaluation_potential
from .kinematics import (_exp_one, _matrix_into, _right_jacobian_into, _space_route_kernel,
                         quat_to_matrix)
from .loads import _drag_kernel, point_loads_into
from .kernel_data import CandidateArrays, ContactData, ResidualBuffers, RodData, StepData
from .seabed import NO_SEABED, seabed_into

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
def _old_level_kernel(Y_old, Ydot_old, F_old, cm, cv, af, mass_t, inertia, stiffness, cY,
                      zc, flux):
    """The old level's constant parts of a step's equations (:meth:`RodSystem.begin_step`),
    (N+1, 12) each: cY = −cm Y^n + cv Ẏ^n (scratch), zc = ½ M cY + ½αf F^n and
    flux = αf K Y^n (:func:`_apply_M_kernel`, :func:`_flux_kernel`), each product in the
    order of the array expressions it stands for."""
    n1, nv = Y_old.shape
    for k in range(n1):
        for j in range(nv):
            cY[k, j] = -cm * Y_old[k, j] + cv * Ydot_old[k, j]
    _apply_M_kernel(cY, mass_t, inertia, zc)
    half_af = 0.5 * af
    for k in range(n1):
        for j in range(nv):
            zc[k, j] = 0.5 * zc[k, j] + half_af * F_old[k, j]
    _flux_kernel(Y_old, stiffness, flux)
    for k in range(n1):
        for j in range(nv):
            flux[k, j] = af * flux[k, j]


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
    """K Y per node (N+1, 12) into out: (ω, v, f, q = Bκ) for E1..E4 (:func:`_flux_row`;
    the old level's αf K Y^n of :func:`_old_level_kernel`)."""
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


@numba.njit(cache=True, inline="always")
def _add_inertia_cell(blocks, k, hc, mass_t, inertia):
    """c·∂⟨M Y⟩/∂Y (hc = ½c) added to cell k's block (12, 24) of blocks (N, 12, 24) in
    place: hc times the mass operator's diagonal (:func:`_mass_row`: −1 on κ in E1,
    −M_t on v in E3, −I on ω in E4) at nodes k and k + 1."""
    for off, node in ((0, k), (NV, k + 1)):
        for i in range(3):
            blocks[k, E1 + i, off + K + i] -= hc
            blocks[k, E3 + i, off + V + i] -= hc * mass_t[node, i]
            blocks[k, E4 + i, off + W + i] -= hc * inertia[node, i]


@numba.njit(cache=True)
def _add_inertia_kernel(blocks, c, mass_t, inertia):
    """c·∂⟨M Y⟩/∂Y added to the cell blocks (N, 12, 24) in place (:meth:`RodSystem.
    add_inertia`)."""
    hc = 0.5 * c
    for k in range(blocks.shape[0]):
        _add_inertia_cell(blocks, k, hc, mass_t, inertia)


@numba.njit(cache=True)
def _cell_blocks_kernel(dF, mass_t, stiffness, inertia, cm, af, ds, blocks):
    """The cell blocks (N, 12, 24) of the step's Jacobian on [node k−1 | node k] into
    blocks: ½(1 − αf) ∂F/∂Y of both nodes, the inertia c_m ∂⟨M Y⟩/∂Y and the flux
    difference ±(1 − αf)/Δs ∂(KY)/∂Y. One pass over the cells, each block finished while
    it is in cache; the inertia and flux terms fall on different entries, each added
    once to ½(1 − αf) ∂F/∂Y, so the values are those of the array expressions it
    replaces, bit for bit."""
    hf = 0.5 * (1.0 - af)
    qf = (1.0 - af) / ds
    hc = 0.5 * cm
    n_cells = blocks.shape[0]
    for k in range(n_cells):
        for i in range(NV):
            for j in range(NV):
                blocks[k, i, j] = hf * dF[k, i, j]
                blocks[k, i, NV + j] = hf * dF[k + 1, i, j]
        _add_inertia_cell(blocks, k, hc, mass_t, inertia)
        for off, sgn, node in ((0, -1.0, k), (NV, 1.0, k + 1)):
            for i in range(3):
                blocks[k, E1 + i, off + W + i] += sgn * qf
                blocks[k, E2 + i, off + V + i] += sgn * qf
                blocks[k, E3 + i, off + F + i] += sgn * qf
                blocks[k, E4 + i, off + K + i] += sgn * qf * stiffness[node, i]


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


@numba.njit(cache=True)
def exact_loads_product(dY, op, P, dB, dS):
    """The body-frame load change dB (N+1, 3) for a change dY (N+1, 12) of the unknowns,
    exact for the space-route pose, minus the node-local part the band holds, and the
    same for the seabed's cell loads, dS (N, 6) (the E3 and E4 cell rows' change, unscaled;
    only the rows of touching cells are written); ``op``: the pose, contact and seabed
    data of :func:`residual_into` at the linearisation point, the first P contacts
    valid (:class:`solver.kernel_data.ExactProduct`).

    The pose's change is integrated along s (δφ_k, δr_k: the spatial rotation and the
    displacement of node k, through κ upstream and node 0's time route): the contact
    forces' change at the pairs' nodes and the global load's rotation give dB. For the
    seabed only the difference from the band's linearisation is formed: per node
    Δφ = δφ − ½Δt R J_r δω and Δr = δr − ½Δt(δφ_b × ṙ + R δv) (the band's time-route
    change, :func:`solver.seabed._seeds_into`), Δṙ = Δφ × ṙ (R δv cancels); at a touching
    cell's midpoint δx, δu = the means of Δr, Δṙ, δΩ = the mean of Δφ × Rω, δt = the mean
    of Δφ × R a3; then [δF; δM] = ∂(F, M)/∂(x, u, Ω, t)·(δx, δu, δΩ, δt) and the cell rows
    change by ½(1 − αf) Σ_k R_kᵀ(δF + F × Δφ_k) and ½(1 − αf) Σ_k R_kᵀ(δM + M × Δφ_k)
    (δ(Rᵀ F) = Rᵀ(F × δφ) for δR = [δφ]× R). Prefix sums along the rod, the pairs' load
    changes, the touching cells and the body-frame rotation in one pass each:
    O(N + P)."""
    R, C, D, tmid, rdot, A0, G, L = op.R, op.C, op.D, op.tmid, op.rdot, op.A0, op.G, op.L
    nodes, w, Fp, d_dr, d_dv = op.nodes, op.weights, op.force, op.dF_dr, op.dF_dv
    dtdr, dwdt, scal, dphi, dr, dG = op.dt_dr, op.dw_dt, op.scalars, op.dphi, op.dr, op.dG
    sbn = op.seabed_count
    n1 = dY.shape[0]
    dt = scal[0]
    ds = scal[1]
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
    for p in range(P):
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        dtp = 0.0
        for b in range(5):
            a = nodes[p, b]
            # δr_b and δṙ_b = δφ × ṙ + R δv
            q0, q1, q2 = dphi[a, 0], dphi[a, 1], dphi[a, 2]
            z0 = q1 * rdot[a, 2] - q2 * rdot[a, 1]
            z1 = q2 * rdot[a, 0] - q0 * rdot[a, 2]
            z2 = q0 * rdot[a, 1] - q1 * rdot[a, 0]
            va0, va1, va2 = dY[a, V], dY[a, V + 1], dY[a, V + 2]
            z0 += R[a, 0, 0] * va0 + R[a, 0, 1] * va1 + R[a, 0, 2] * va2
            z1 += R[a, 1, 0] * va0 + R[a, 1, 1] * va1 + R[a, 1, 2] * va2
            z2 += R[a, 2, 0] * va0 + R[a, 2, 1] * va1 + R[a, 2, 2] * va2
            r0, r1, r2 = dr[a, 0], dr[a, 1], dr[a, 2]
            dtp += dtdr[p, b, 0] * r0 + dtdr[p, b, 1] * r1 + dtdr[p, b, 2] * r2
            f0 += (d_dr[p, b, 0, 0] * r0 + d_dr[p, b, 0, 1] * r1 + d_dr[p, b, 0, 2] * r2
                   + d_dv[p, b, 0, 0] * z0 + d_dv[p, b, 0, 1] * z1 + d_dv[p, b, 0, 2] * z2)
            f1 += (d_dr[p, b, 1, 0] * r0 + d_dr[p, b, 1, 1] * r1 + d_dr[p, b, 1, 2] * r2
                   + d_dv[p, b, 1, 0] * z0 + d_dv[p, b, 1, 1] * z1 + d_dv[p, b, 1, 2] * z2)
            f2 += (d_dr[p, b, 2, 0] * r0 + d_dr[p, b, 2, 1] * r1 + d_dr[p, b, 2, 2] * r2
                   + d_dv[p, b, 2, 0] * z0 + d_dv[p, b, 2, 1] * z1 + d_dv[p, b, 2, 2] * z2)
        for b in range(5):
            a = nodes[p, b]
            wb = w[p, b]
            tb = dwdt[p, b] * dtp
            dG[a, 0] += wb * f0 + tb * Fp[p, 0]
            dG[a, 1] += wb * f1 + tb * Fp[p, 1]
            dG[a, 2] += wb * f2 + tb * Fp[p, 2]
    for k in range(n1):
        for i in range(3):
            acc = R[k, 0, i] * dG[k, 0] + R[k, 1, i] * dG[k, 1] + R[k, 2, i] * dG[k, 2]
            for j in range(6):
                acc -= L[k, i, j] * dY[k, j]
            dB[k, i] = acc
    if sbn[0] > 0:
        _seabed_product(dY, R, rdot, op.Romega, op.Aphi, dphi, dr, op.seabed_cells, sbn[0],
                        op.seabed_partials, op.seabed_loads,
                        0.5 * dt, 0.5 * (1.0 - scal[2]), dS)


@numba.njit(cache=True)
def _seabed_product(dY, R, rdot, Og, Aphi, dphi, dr, cells, count, J, FM, hdt, half_gf, dS):
    """The seabed's part of :func:`exact_loads_product` (its docstring has the formulas)
    into dS (N, 6) for the ``count`` touching cells listed in ``cells``: the space route's
    change of each touching cell's E3 and E4 rows minus the band's. hdt = ½Δt (s),
    half_gf = ½(1 − αf)."""
    Dphi = np.empty((2, 3))
    Dr = np.empty((2, 3))
    z = np.empty(12)
    d = np.empty(6)
    for j in range(count):
        c = cells[j]
        for e in range(2):
            k = c + e
            # the band's δφ_b = ½Δt R J_r δω and δṙ_b = δφ_b × ṙ + R δv
            b0 = Aphi[k, 0, 0] * dY[k, W] + Aphi[k, 0, 1] * dY[k, W + 1] + Aphi[k, 0, 2] * dY[k, W + 2]
            b1 = Aphi[k, 1, 0] * dY[k, W] + Aphi[k, 1, 1] * dY[k, W + 1] + Aphi[k, 1, 2] * dY[k, W + 2]
            b2 = Aphi[k, 2, 0] * dY[k, W] + Aphi[k, 2, 1] * dY[k, W + 1] + Aphi[k, 2, 2] * dY[k, W + 2]
            v0, v1, v2 = dY[k, V], dY[k, V + 1], dY[k, V + 2]
            u0 = b1 * rdot[k, 2] - b2 * rdot[k, 1] + R[k, 0, 0] * v0 + R[k, 0, 1] * v1 + R[k, 0, 2] * v2
            u1 = b2 * rdot[k, 0] - b0 * rdot[k, 2] + R[k, 1, 0] * v0 + R[k, 1, 1] * v1 + R[k, 1, 2] * v2
            u2 = b0 * rdot[k, 1] - b1 * rdot[k, 0] + R[k, 2, 0] * v0 + R[k, 2, 1] * v1 + R[k, 2, 2] * v2
            Dphi[e, 0] = dphi[k, 0] - b0
            Dphi[e, 1] = dphi[k, 1] - b1
            Dphi[e, 2] = dphi[k, 2] - b2
            Dr[e, 0] = dr[k, 0] - hdt * u0
            Dr[e, 1] = dr[k, 1] - hdt * u1
            Dr[e, 2] = dr[k, 2] - hdt * u2
        for i in range(12):
            z[i] = 0.0
        for e in range(2):
            k = c + e
            p0, p1, p2 = Dphi[e, 0], Dphi[e, 1], Dphi[e, 2]
            for i in range(3):
                z[i] += 0.5 * Dr[e, i]
            # Δṙ = Δφ × ṙ, Δφ × Rω, Δφ × R a3 (halved: the midpoint's means)
            z[3] += 0.5 * (p1 * rdot[k, 2] - p2 * rdot[k, 1])
            z[4] += 0.5 * (p2 * rdot[k, 0] - p0 * rdot[k, 2])
            z[5] += 0.5 * (p0 * rdot[k, 1] - p1 * rdot[k, 0])
            z[6] += 0.5 * (p1 * Og[k, 2] - p2 * Og[k, 1])
            z[7] += 0.5 * (p2 * Og[k, 0] - p0 * Og[k, 2])
            z[8] += 0.5 * (p0 * Og[k, 1] - p1 * Og[k, 0])
            z[9] += 0.5 * (p1 * R[k, 2, 2] - p2 * R[k, 1, 2])
            z[10] += 0.5 * (p2 * R[k, 0, 2] - p0 * R[k, 2, 2])
            z[11] += 0.5 * (p0 * R[k, 1, 2] - p1 * R[k, 0, 2])
        for i in range(6):
            acc = 0.0
            for m in range(12):
                acc += J[c, i, m] * z[m]
            d[i] = acc
        for i in range(6):
            dS[c, i] = 0.0
        for e in range(2):
            k = c + e
            p0, p1, p2 = Dphi[e, 0], Dphi[e, 1], Dphi[e, 2]
            for h in range(2):
                o = 3 * h
                # δF + F × Δφ (h = 0), δM + M × Δφ (h = 1), then Rᵀ
                g0 = d[o] + FM[c, o + 1] * p2 - FM[c, o + 2] * p1
                g1 = d[o + 1] + FM[c, o + 2] * p0 - FM[c, o] * p2
                g2 = d[o + 2] + FM[c, o] * p1 - FM[c, o + 1] * p0
                for i in range(3):
                    dS[c, o + i] += half_gf * (R[k, 0, i] * g0 + R[k, 1, i] * g1
                                               + R[k, 2, i] * g2)


@numba.njit(cache=True, inline="always")
def _qmul(pw, px, py, pz, qw, qx, qy, qz):
    """Hamilton product p ⊗ q of two quaternions (w, x, y, z), as four floats."""
    return (pw * qw - px * qx - py * qy - pz * qz, pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx, pw * qz + px * qy - py * qx + pz * qw)


@numba.njit(cache=True)
def pose_into(Y, Y_old, dt, space, q_old, r_old, vg_old, with_r, ds, q, Rm, r, theta, vg):
    """The new-level pose of an iterate Y (N+1, 12) (:meth:`RodSystem.pose_new`) into
    q (N+1, 4), Rm (N+1, 3, 3), r (N+1, 3), θ (N+1, 3) and the global velocities
    ṙ = R v (N+1, 3) into vg: θ = ½Δt(ω^n + ω^{n+1}) per node; with ``space`` the shape
    integrated along s from κ (:func:`space_route`) anchored at node 0's time-route pose,
    else each node's time route q^n ⊗ exp(θ), r^n + ½Δt(ṙ^n + R v) (r only ``with_r``)."""
    n1 = Y.shape[0]
    for k in range(n1):
        for c in range(3):
            theta[k, c] = 0.5 * dt * (Y_old[k, W + c] + Y[k, W + c])
    if space:
        hw, hx, hy, hz = _exp_one(theta[0, 0], theta[0, 1], theta[0, 2])
        w0, x0, y0, z0 = _qmul(q_old[0, 0], q_old[0, 1], q_old[0, 2], q_old[0, 3],
                               hw, hx, hy, hz)
        nrm = np.sqrt(w0 * w0 + x0 * x0 + y0 * y0 + z0 * z0)
        q0 = np.empty(4)
        q0[0], q0[1], q0[2], q0[3] = w0 / nrm, x0 / nrm, y0 / nrm, z0 / nrm
        _matrix_into(q0[0], q0[1], q0[2], q0[3], Rm, 0)
        r0 = np.empty(3)
        for i in range(3):
            r0[i] = r_old[0, i] + 0.5 * dt * (vg_old[0, i] + (
                Rm[0, i, 0] * Y[0, V] + Rm[0, i, 1] * Y[0, V + 1] + Rm[0, i, 2] * Y[0, V + 2]))
        _space_route_kernel(q0, r0, Y[:, K:K + 3], ds, q, r)
        for k in range(n1):
            _matrix_into(q[k, 0], q[k, 1], q[k, 2], q[k, 3], Rm, k)
    else:
        for k in range(n1):
            hw, hx, hy, hz = _exp_one(theta[k, 0], theta[k, 1], theta[k, 2])
            q[k, 0], q[k, 1], q[k, 2], q[k, 3] = _qmul(q_old[k, 0], q_old[k, 1], q_old[k, 2],
                                                       q_old[k, 3], hw, hx, hy, hz)
            _matrix_into(q[k, 0], q[k, 1], q[k, 2], q[k, 3], Rm, k)
    for k in range(n1):
        for i in range(3):
            vg[k, i] = (Rm[k, i, 0] * Y[k, V] + Rm[k, i, 1] * Y[k, V + 1]
                        + Rm[k, i, 2] * Y[k, V + 2])
    if with_r and not space:
        for k in range(n1):
            for i in range(3):
                r[k, i] = r_old[k, i] + 0.5 * dt * (vg_old[k, i] + vg[k, i])


@numba.njit(cache=True)
def node_terms_into(Y, want_jac, mass_t, stiffness, inertia, has_drag, cdn, cdt, rotate,
                    Rm, theta, half_dt, G, add_diag, diag, Fn, dF, loadrot, brot, drag_b,
                    drag_j, Jr):
    """F(Y) per node (N+1, 12) into Fn with the loads, and with ``want_jac`` its
    Jacobian (N+1, 12, 12) into dF (:meth:`RodSystem.node_terms` has the terms): seed
    eqs. 2-5's node terms, the Morison drag (``has_drag``), the global load G (N+1, 3)
    rotated to the body frame B = Rᵀ G (``rotate``; into brot) with ∂B/∂ω^{n+1} =
    ½Δt [B]× J_r(θ) (into loadrot), and the node-local contact block diag (N+1, 3, 6)
    (``add_diag``). drag_b, drag_j, Jr: scratch (N+1, 3), (N+1, 3, 3) ×2."""
    n1 = Y.shape[0]
    _node_forces_kernel(Y, mass_t, stiffness, inertia, Fn)
    if has_drag:
        if want_jac:
            fill(drag_j, 0.0)
        _drag_kernel(Y[:, V:V + 3], cdn, cdt, drag_b, drag_j, want_jac)
        for k in range(n1):
            for c in range(3):
                Fn[k, E3 + c] += drag_b[k, c]
    if rotate:
        for k in range(n1):
            for i in range(3):
                brot[k, i] = Rm[k, 0, i] * G[k, 0] + Rm[k, 1, i] * G[k, 1] + Rm[k, 2, i] * G[k, 2]
            for c in range(3):
                Fn[k, E3 + c] += brot[k, c]
    if not want_jac:
        return
    _node_jacobian_kernel(Y, mass_t, stiffness, inertia, dF)
    if has_drag:
        for k in range(n1):
            for a in range(3):
                for b in range(3):
                    dF[k, E3 + a, V + b] += drag_j[k, a, b]
    if add_diag:
        for k in range(n1):
            for a in range(3):
                for b in range(6):
                    dF[k, E3 + a, V + b] += diag[k, a, b]
    if rotate:
        for k in range(n1):
            _right_jacobian_into(theta[k, 0], theta[k, 1], theta[k, 2], Jr, k)
            b0, b1, b2 = brot[k, 0], brot[k, 1], brot[k, 2]
            for j in range(3):
                # [b]× J_r column j, times ½Δt
                loadrot[k, 0, j] = half_dt * (-b2 * Jr[k, 1, j] + b1 * Jr[k, 2, j])
                loadrot[k, 1, j] = half_dt * (b2 * Jr[k, 0, j] - b0 * Jr[k, 2, j])
                loadrot[k, 2, j] = half_dt * (-b1 * Jr[k, 0, j] + b0 * Jr[k, 1, j])
            for a in range(3):
                for b in range(3):
                    dF[k, E3 + a, W + b] += loadrot[k, a, b]


@numba.njit(cache=True)
def residual_into(Y, want_jac, rod, step, cand, frozen, cdata, buf, ev):
    """The residual (n,) of a step's difference equations at the iterate Y (N+1, 12),
    and with ``want_jac`` its Jacobian's cell blocks (N, 12, 24), the node-local contact
    block and the data of the exact load product (:func:`exact_loads_product`), written
    into the buffers of :meth:`RodSystem.buffers` (module docstring for the equations;
    :meth:`RodSystem.residual` for what is computed when). rod, step: the run's and the
    step's constant data (:meth:`RodSystem.kernel_args`; :class:`~solver.kernel_data.RodData`,
    :class:`~solver.kernel_data.StepData`); cand: the step's contact
    candidates (:attr:`solver.contact.ContactCandidates.arrays`, a
    :class:`~solver.kernel_data.CandidateArrays`, empty without);
    frozen: each run's frozen combination or empty; cdata: the contact model's
    :attr:`~solver.contact.SelfContact.kernel_data`; ev: the contact evaluation arrays
    (:class:`~solver.kernel_data.EvaluationArrays`);
    buf: :class:`~solver.kernel_data.ResidualBuffers`. Writes flags (4,): [0: 0 ok, 1 non-finite positions, 2 coincident contact points
    (the residual is NaN then), 1: active contacts P, 2: pose computed, 3: exact load
    data computed (with ``want_jac`` on the space route, where global or contact loads
    act or a seabed cell touches)]. The one implementation of the residual: Newton's compiled
    iterations and the Python method both call it."""
    mass_t, stiffness, inertia, cdn, cdt = rod.mass_t, rod.stiffness, rod.inertia, rod.cdn, rod.cdt
    seabed = rod.seabed
    ds = rod.ds
    has_seabed = seabed.scalars[0] != 0.0
    has_drag = rod.has_drag
    space = rod.space
    Y_old, zconst, flux_const, glob = step.Y_old, step.zconst, step.flux_const, step.glob
    q_old, r_old, vg_old = step.q_old, step.r_old, step.vg_old
    bc_rows, bc_cols, bc_coef, bc_vals = step.bc_rows, step.bc_cols, step.bc_coef, step.bc_vals
    dt, cm, af = step.dt, step.cm, step.af
    has_glob = step.has_glob
    has_r_old = step.has_r_old
    pl_nodes = step.pl_nodes
    has_points = pl_nodes.shape[0] > 0
    R, cells, Fn, dF, blocks = buf.R, buf.cells, buf.Fn, buf.dF, buf.blocks
    q, Rm, r, theta, vg, G = buf.q, buf.Rm, buf.r, buf.theta, buf.vg, buf.G
    diag, loadrot, brot, C, D, tmid = buf.diag, buf.loadrot, buf.brot, buf.C, buf.D, buf.tmid
    rdot, A0, L, drag_b, drag_j, Jr = buf.rdot, buf.A0, buf.L, buf.drag_b, buf.drag_j, buf.Jr
    sbc, sbn, sbj, sbl = buf.seabed_cells, buf.seabed_count, buf.seabed_partials, buf.seabed_loads
    Og, Aphi, bcj, flags = buf.Romega, buf.Aphi, buf.bc_jac, buf.flags
    n1 = Y.shape[0]
    contact = cand.run_start.shape[0] > 0
    turning = step.turning_start or step.turning_end
    need_pose = (has_glob or contact or (has_points and step.needs_pose) or turning
                 or has_seabed)
    for i in range(4):
        flags[i] = 0
    P = 0
    if need_pose:
        pose_into(Y, Y_old, dt, space and has_r_old, q_old, r_old, vg_old, has_r_old, ds,
                  q, Rm, r, theta, vg)
        flags[2] = 1
    have_G = False
    if contact:
        finite = True
        for k in range(n1):
            for i in range(3):
                if not (np.isfinite(vg[k, i]) and np.isfinite(r[k, i])):
                    finite = False
        if finite:
            P = evaluate_into(r, vg, cand, frozen, cdata, ev)
        if not finite or P < 0:
            # a diverging iterate: a non-finite residual, so that Δt is cut
            fill(R, np.nan)
            flags[0] = 1 if not finite else 2
            return
        nodes, weights, force = ev.nodes, ev.weights, ev.force
        fill(G, 0.0)
        for p in range(P):
            for a in range(5):
                b = nodes[p, a]
                wa = weights[p, a]
                for c in range(3):
                    G[b, c] += wa * force[p, c]
        if has_glob:
            for k in range(n1):
                for c in range(3):
                    G[k, c] = G[k, c] + glob[k, c]
        have_G = True
        if want_jac and P > 0:
            fill(diag, 0.0)
            for k in range(n1):
                _right_jacobian_into(theta[k, 0], theta[k, 1], theta[k, 2], Jr, k)
            _contact_band_kernel(nodes[:P], weights[:P], ev.dF_dr[:P], ev.dF_dv[:P], Rm, Y, Jr,
                                 dt, diag)
    elif has_glob:
        copy_into(G, glob)
        have_G = True
    rotate = need_pose and have_G
    add_diag = contact and want_jac and P > 0
    node_terms_into(Y, want_jac, mass_t, stiffness, inertia, has_drag, cdn, cdt, rotate, Rm,
                    theta, 0.5 * dt, G, add_diag, diag, Fn, dF, loadrot, brot, drag_b, drag_j,
                    Jr)
    _cells_kernel(Y, Fn, zconst, flux_const, mass_t, stiffness, inertia, cm, af, ds, cells)
    for m in range(bc_rows.shape[0]):
        col = bc_cols[m]
        R[bc_rows[m]] = bc_coef[m] * Y[col // NV, col % NV] - bc_vals[m]
    if turning:
        # an end towed in the global frame with its rotation free: v − b, b = R^{n+1}ᵀ V
        # with the end's new-level frame R^n exp(θ) of pose_into (values m0..m0+2: V,
        # m/s), and with ``want_jac`` its block on ω^{n+1}: −½Δt [b]× J_r(θ) into bcj[e]
        # (the rotated load's derivative of node_terms_into)
        for e in range(2):
            if step.turning_start if e == 0 else step.turning_end:
                m0 = 6 * e
                k = 0 if e == 0 else n1 - 1
                b = np.empty(3)
                for i in range(3):
                    b[i] = (Rm[k, 0, i] * bc_vals[m0] + Rm[k, 1, i] * bc_vals[m0 + 1]
                            + Rm[k, 2, i] * bc_vals[m0 + 2])
                    R[bc_rows[m0 + i]] = Y[k, V + i] - b[i]
                if want_jac:
                    _right_jacobian_into(theta[k, 0], theta[k, 1], theta[k, 2], Jr, k)
                    c = -0.5 * dt
                    for j in range(3):
                        bcj[e, 0, j] = c * (-b[2] * Jr[k, 1, j] + b[1] * Jr[k, 2, j])
                        bcj[e, 1, j] = c * (b[2] * Jr[k, 0, j] - b[0] * Jr[k, 2, j])
                        bcj[e, 2, j] = c * (-b[1] * Jr[k, 0, j] + b[0] * Jr[k, 1, j])
    if want_jac:
        _cell_blocks_kernel(dF, mass_t, stiffness, inertia, cm, af, ds, blocks)
    exact = want_jac and space and has_r_old and need_pose
    sbn[0] = 0
    if has_seabed:
        # the sea floor's loads per cell, at its midpoint on the new-level pose, and the
        # old level's share frozen by begin_step (solver.seabed), into the cell rows and
        # blocks: exact for the time route; on the space route the law's linearisation
        # is kept for the exact product
        seabed_into(Y, Rm, r, vg, theta, dt, af, seabed, want_jac, cells, blocks, exact,
                    (sbc, sbn, sbj, sbl))
    if exact and (have_G or sbn[0] > 0):
        # the exact load product's data (self-contact configured: the pose is the space
        # route, so every node's position and frame depends on κ upstream of it)
        _exact_frames_kernel(Rm, Y, theta, ds, dt, C, D, tmid, rdot, A0)
        if not have_G:
            fill(G, 0.0)
        for k in range(n1):
            for a in range(3):
                for b in range(6):
                    L[k, a, b] = diag[k, a, b] if add_diag else 0.0
                if rotate:
                    for b in range(3):
                        L[k, a, 3 + b] += loadrot[k, a, b]
        if sbn[0] > 0:
            # the seabed's: each node's global angular velocity R ω and the band's
            # (time-route) frame change per unit ω^{n+1}, ½Δt R J_r(θ)
            for k in range(n1):
                _right_jacobian_into(theta[k, 0], theta[k, 1], theta[k, 2], Jr, k)
                for i in range(3):
                    Og[k, i] = (Rm[k, i, 0] * Y[k, W] + Rm[k, i, 1] * Y[k, W + 1]
                                + Rm[k, i, 2] * Y[k, W + 2])
                    for j in range(3):
                        Aphi[k, i, j] = 0.5 * dt * (Rm[k, i, 0] * Jr[k, 0, j]
                                                    + Rm[k, i, 1] * Jr[k, 1, j]
                                                    + Rm[k, i, 2] * Jr[k, 2, j])
        flags[3] = 1
    if has_points:
        point_loads_into(Y, Rm, theta, 0.5 * dt, ds, af, want_jac, pl_nodes, step.pl_cells,
                         step.pl_side, step.pl_vals, step.pl_dead, step.pl_old, cells, blocks, Jr)
    flags[1] = P


@dataclass
class StepTerms:
    """The data of one time step n -> n+1 that the residual and Newton read: built by
    :meth:`RodSystem.begin_step` and held as ``RodSystem.step`` until the next step.

    dt (s) the step, params the time scheme (:class:`StepParameters`), t_new (s) its
    end, bc the boundary rows at t_new (:class:`solver.boundary.BoundaryRows`),
    cm = (1 − αm)/(γΔt) (1/s) the coefficient of the generalized-α relation, Y_old and
    Ydot_old (N+1, 12) the old level, zconst (N+1, 12) the old level's part of the cell
    rows ½(M·cY + αf F^n), flux_const (N+1, 12) αf K Y^n, q_old (N+1, 4), r_old and
    v_old_global (N+1, 3) the old pose and global velocities (or None), glob_force
    (N+1, 3) N/m the global-frame load at t_new (or None), candidates the contact
    candidates (:class:`solver.contact.ContactCandidates`, None without any) and
    cand_arrays their kernel arrays, frozen_selection the frozen closest-point selection
    (None: selected afresh at every iterate), data the step's
    :class:`~solver.kernel_data.StepData` for :func:`residual_into`, key what the Jacobian's band part depends on besides the
    iterate (:class:`solver.newton.NewtonSolver` keeps a factorisation while it is unchanged).
    The fields left None are those of a system before its first step.
    """
    cand_arrays: tuple
    dt: float | None = None
    params: StepParameters | None = None
    t_new: float | None = None
    bc: object = None
    cm: float | None = None
    Y_old: np.ndarray | None = None
    Ydot_old: np.ndarray | None = None
    zconst: np.ndarray | None = None
    flux_const: np.ndarray | None = None
    q_old: np.ndarray | None = None
    r_old: np.ndarray | None = None
    v_old_global: np.ndarray | None = None
    glob_force: np.ndarray | None = None
    candidates: object = None
    frozen_selection: np.ndarray | None = None
    data: StepData | None = None
    key: tuple | None = None


def _named_step_data(old) -> StepData:
    """A step's data pickled before :mod:`solver.kernel_data` (a plain tuple: eleven
    arrays, the scalars (8,) (Δt, cm, αf, has glob, has r_old, needs pose, the two ends
    turning), the six point-load arrays) as a :class:`StepData`."""
    old = tuple(old)
    sc = old[11]
    return StepData(*old[:11], dt=float(sc[0]), cm=float(sc[1]), af=float(sc[2]),
                    has_glob=bool(sc[3]), has_r_old=bool(sc[4]), needs_pose=bool(sc[5]),
                    turning_start=bool(sc[6]), turning_end=bool(sc[7]), pl_nodes=old[12],
                    pl_cells=old[13], pl_side=old[14], pl_vals=old[15], pl_dead=old[16],
                    pl_old=old[17])


#: the attributes a pickled RodSystem held before :class:`StepTerms`, by field
_OLD_STEP_NAMES = {"dt": "dt", "params": "params", "t_new": "t_new", "bc": "bc", "cm": "cm",
                   "Y_old": "Y_old", "Ydot_old": "Ydot_old", "_zconst": "zconst",
                   "_flux_const": "flux_const", "q_old": "q_old", "r_old": "r_old",
                   "v_old_global": "v_old_global", "_glob_force": "glob_force",
                   "candidates": "candidates", "cand_arrays": "cand_arrays",
                   "frozen_selection": "frozen_selection", "step_data": "data",
                   "step_key": "key"}


class RodSystem:
    """Residual and Jacobian of one time step of the box/generalized-α scheme.

    The residual is one compiled kernel (:func:`residual_into`); Newton's method for the
    step (iteration, line search, linear solver) is :class:`solver.newton.NewtonSolver`, which
    calls that kernel from its own compiled iterations with :meth:`kernel_args`.

    Parameters
    ----------
    props : RodProperties
    loads : LoadModel
    contact : SelfContact or None
        The self-contact model (:mod:`solver.contact`); None without self-contact.
    seabed : solver.seabed.SeabedContact or None
        The sea floor (:mod:`solver.seabed`); None without one.
    """

    def __init__(self, props, loads, contact=None, seabed=None):
        self.p = props
        self.loads = loads
        self.contact = contact
        self.seabed = seabed
        self.n_nodes = props.s.size
        self.n_cells = self.n_nodes - 1
        self.n = NV * self.n_nodes
        self.needs_pose = (loads.has_global or contact is not None or seabed is not None
                           or (loads.points is not None and loads.points.any_dead))
        # characteristic sizes of the unknowns (floors of the column scale)
        length = props.s[-1]
        b0 = float(np.max(props.stiffness[:, :2]))
        m0 = float(np.max(props.rho_a))
        tc = length**2 * np.sqrt(m0 / b0)
        self.tc = float(tc)       # bending time scale L²√(ρA/EJ), s
        self.floor = np.repeat([length / tc, 1.0 / tc, b0 / length**2, 1.0 / length], 3)
        cdn = loads.cdn if loads.has_drag else np.zeros(self.n_nodes)
        cdt = loads.cdt if loads.has_drag else np.zeros(self.n_nodes)
        #: the run's constant data as the compiled kernels take it (:func:`residual_into`)
        self.rod_data = RodData(mass_t=props.mass_t, stiffness=props.stiffness,
                                inertia=props.inertia, cdn=np.ascontiguousarray(cdn, dtype=float),
                                cdt=np.ascontiguousarray(cdt, dtype=float), floor=self.floor,
                                ds=float(props.ds), has_drag=bool(loads.has_drag),
                                space=contact is not None,
                                seabed=NO_SEABED if seabed is None else seabed.data)
        if contact is not None:
            self.contact_data = contact.kernel_data
        else:
            z = np.zeros(0)
            self.contact_data = ContactData(np.zeros((0, 4), np.intp), np.zeros((0, 4, 4)), z,
                                            z.copy(), z.copy(), np.zeros(9))
        self.buf = self.buffers()
        self.ev = evaluation_arrays(0)
        self._no_candidates = CandidateArrays(np.zeros(0, np.intp), np.zeros(0, np.intp),
                                              np.zeros(0, np.intp), np.zeros(0, np.bool_),
                                              np.zeros(0, np.bool_))
        self._no_frozen = np.zeros(0, np.intp)
        #: the current step's data (:class:`StepTerms`), set by :meth:`begin_step`
        self.step = StepTerms(cand_arrays=self._no_candidates)

    def __getstate__(self):
        # the buffers (one of them a view of another) are made afresh on loading
        state = self.__dict__.copy()
        state.pop("buf", None)
        state.pop("ev", None)
        return state

    def __setstate__(self, state):
        state = dict(state)
        if "step" not in state:
            # a checkpoint pickled before the step's data were one StepTerms
            old = {new: state.pop(name) for name, new in _OLD_STEP_NAMES.items()
                   if name in state}
            old.setdefault("cand_arrays", state["_no_candidates"])
            state["step"] = StepTerms(**old)
        self.__dict__.update(state)
        # the seabed's kernel data as it is now (a checkpoint from before its last arrays)
        seabed = state.get("seabed")
        sb = NO_SEABED if seabed is None else seabed.data
        if isinstance(self.rod_data, RodData):
            self.rod_data = self.rod_data._replace(seabed=sb)
        else:
            # a checkpoint from before the data were named: a plain tuple whose seventh
            # entry held (Δs, has drag, space route)
            old = tuple(self.rod_data)
            self.rod_data = RodData(*old[:6], ds=float(old[6][0]), has_drag=bool(old[6][1]),
                                    space=bool(old[6][2]), seabed=sb)
        # ... and the contact model's, the candidates' and the step's data
        if not isinstance(self.contact_data, ContactData):
            self.contact_data = ContactData(*self.contact_data)
            if self.contact is not None:
                self.contact.kernel_data = self.contact_data
        if not isinstance(self._no_candidates, CandidateArrays):
            self._no_candidates = CandidateArrays(*self._no_candidates)
        step = self.step
        if not isinstance(step.cand_arrays, CandidateArrays):
            step.cand_arrays = CandidateArrays(*step.cand_arrays)
        if step.data is not None and not isinstance(step.data, StepData):
            step.data = _named_step_data(step.data)
        self.buf = self.buffers()
        cand = self.step.candidates
        self.ev = evaluation_arrays(cand.runs if cand is not None else 0)

    def buffers(self):
        """Fresh output buffers of :func:`residual_into` for this grid: R (n,) and its cell
        rows as an (N, 12) view, F (N+1, 12), ∂F/∂Y (N+1, 12, 12), cell blocks
        (N, 12, 24), the pose q (N+1, 4), R (N+1, 3, 3), r, θ, ṙ (N+1, 3), the global
        load G (N+1, 3), the node-local contact block (N+1, 3, 6), the load rotation's
        block (N+1, 3, 3), the body-frame load (N+1, 3), the exact product's C, D
        (N, 3, 3), mid-cell tangents (N, 3), ṙ (N+1, 3), A0 (3, 3), L (N+1, 3, 6), scratch
        (N+1, 3), (N+1, 3, 3) ×2, the seabed's linearisation for the exact product
        (:func:`solver.seabed.seabed_into`'s ``lin``: cells (N,) int, count (1,) int,
        partials (N, 6, 12), loads (N, 6)), R ω (N+1, 3), ½Δt R J_r(θ) (N+1, 3, 3), the
        towed ends' ∂(v − RᵀV)/∂ω blocks (2, 3, 3) and the flags (4,) int."""
        n1, nc = self.n_nodes, self.n_cells
        R = np.zeros(self.n)
        return ResidualBuffers(
            R=R, cells=R[6:6 + NV * nc].reshape(nc, NV), Fn=np.zeros((n1, NV)),
            dF=np.zeros((n1, NV, NV)), blocks=np.zeros((nc, NV, 2 * NV)), q=np.zeros((n1, 4)),
            Rm=np.zeros((n1, 3, 3)), r=np.zeros((n1, 3)), theta=np.zeros((n1, 3)),
            vg=np.zeros((n1, 3)), G=np.zeros((n1, 3)), diag=np.zeros((n1, 3, 6)),
            loadrot=np.zeros((n1, 3, 3)), brot=np.zeros((n1, 3)), C=np.zeros((nc, 3, 3)),
            D=np.zeros((nc, 3, 3)), tmid=np.zeros((nc, 3)), rdot=np.zeros((n1, 3)),
            A0=np.zeros((3, 3)), L=np.zeros((n1, 3, 6)), drag_b=np.zeros((n1, 3)),
            drag_j=np.zeros((n1, 3, 3)), Jr=np.zeros((n1, 3, 3)),
            seabed_cells=np.zeros(nc, np.int64), seabed_count=np.zeros(1, np.int64),
            seabed_partials=np.zeros((nc, 6, 12)), seabed_loads=np.zeros((nc, 6)),
            Romega=np.zeros((n1, 3)), Aphi=np.zeros((n1, 3, 3)), bc_jac=np.zeros((2, 3, 3)),
            flags=np.zeros(4, np.int64))

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
        cm = (1.0 - am) / (g * dt)
        # M Ẏ^{n+1-αm} = cm M Y + M·cY with cY = −cm Y^n + (αm − (1−αm)(1−γ)/γ) Ẏ^n;
        # zc = ½ M cY + ½αf F^n and αf K Y^n in one compiled pass (_old_level_kernel)
        Y_old = np.ascontiguousarray(Y_old, dtype=float)
        zc, flux_const = np.empty_like(Y_old), np.empty_like(Y_old)
        _old_level_kernel(Y_old, np.ascontiguousarray(Ydot_old, dtype=float),
                          np.ascontiguousarray(F_old, dtype=float), cm,
                          am - (1.0 - am) * (1.0 - g) / g, af, self.p.mass_t,
                          self.p.inertia, self.p.stiffness, np.empty_like(Y_old), zc,
                          flux_const)
        glob = self.loads.global_force(t_new, left=left_limit) if self.loads.has_global else None
        candidates = candidates if (candidates is not None and candidates.runs > 0) else None
        if candidates is not None:
            cand_arrays = candidates.arrays
            if self.ev.selection.shape[0] < candidates.runs:
                self.ev = evaluation_arrays(2 * candidates.runs)
        else:
            cand_arrays = self._no_candidates
        n1 = self.n_nodes
        has_r = r_old is not None and v_old_global is not None
        if self.seabed is not None:
            self.seabed.begin_step(af, Y_old, q_old, r_old, v_old_global)
        pl_nodes, pl_cells, pl_side, pl_vals, pl_dead, pl_old = self._point_data(
            t_new, dt, left_limit, Y_old, q_old, af)
        data = StepData(
            Y_old=Y_old, zconst=zc, flux_const=flux_const,
            glob=np.zeros((0, 3)) if glob is None else np.ascontiguousarray(glob, dtype=float),
            q_old=np.zeros((n1, 4)) if q_old is None else np.ascontiguousarray(q_old, dtype=float),
            r_old=np.ascontiguousarray(r_old, dtype=float) if has_r else np.zeros((n1, 3)),
            vg_old=(np.ascontiguousarray(v_old_global, dtype=float) if has_r
                    else np.zeros((n1, 3))),
            # BoundaryRows makes these (12,) arrays intp and float
            bc_rows=bc.rows, bc_cols=bc.cols, bc_coef=bc.coef, bc_vals=bc.values,
            dt=float(dt), cm=float(cm), af=float(af), has_glob=glob is not None,
            has_r_old=bool(has_r), needs_pose=bool(self.needs_pose),
            turning_start=bool(bc.turning[0]), turning_end=bool(bc.turning[1]),
            pl_nodes=pl_nodes, pl_cells=pl_cells, pl_side=pl_side, pl_vals=pl_vals,
            pl_dead=pl_dead, pl_old=pl_old)
        # frozen_selection None: set by Newton (see SelfContact.closest); key: what the
        # Jacobian's band part depends on besides the iterate (solver.newton keeps a
        # factorisation across steps while this is unchanged)
        self._summary = None     # contact_summary of this step (summary_potential)
        self.step = StepTerms(
            cand_arrays=cand_arrays, dt=dt, params=params, t_new=t_new, bc=bc, cm=cm,
            Y_old=Y_old, Ydot_old=Ydot_old, zconst=zc, flux_const=flux_const, q_old=q_old,
            r_old=r_old, v_old_global=v_old_global, glob_force=glob, candidates=candidates,
            frozen_selection=None, data=data, key=(dt, params, bc.key))

    _NO_POINTS = (np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros(0), np.zeros((0, 3)),
                  np.zeros(0, np.bool_), np.zeros((0, NV)))

    def _point_data(self, t_new, dt, left_limit, Y_old, q_old, af):
        """The point loads' part of the step data (:func:`solver.loads.point_loads_into`):
        (nodes, cells, side, values at t_new (m, 3) N, dead, the old level's share
        (m, 12)), empty arrays without point loads. The old level takes the loads at
        t_new − dt (its right limit: a step after a breakpoint is a backward-Euler
        restart, αf = 0) in the old frames q_old."""
        pts = self.loads.points
        if pts is None:
            return self._NO_POINTS
        vals = pts.values(t_new, left=left_limit)
        old = np.zeros((len(pts), NV))
        if af != 0.0:
            body_old = pts.body_values(pts.values(t_new - dt), q=q_old)
            old = pts.old_level(Y_old, body_old, float(self.p.ds), af)
        return (pts.nodes, pts.cells, pts.side, vals, pts.dead, old)

    def kernel_args(self):
        """(rod, step, candidates, contact data): what :func:`residual_into` takes of this
        run and step (:meth:`begin_step` must have been called)."""
        step = self.step
        return self.rod_data, step.data, step.cand_arrays, self.contact_data

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

    def pose_new(self, Y):
        """Orientation and position at the new level from the old pose and the rates.

        Without self-contact, per node (the time route): q^{n+1} = q^n ⊗ exp(θ),
        θ = ½Δt(ω^n + ω^{n+1}); r^{n+1} = r^n + ½Δt(R^n v^n + R^{n+1} v^{n+1}).
        With self-contact configured, the pose is the shape integrated along s from
        κ^{n+1} (the space route, :func:`solver.kinematics.space_route`), anchored at
        node 0's time-route pose: the one centreline that is carried forward, output and
        checked, so the contact forces act on it (docs/contact.md, "One geometry").
        Returns (q (N+1, 4), R (N+1, 3, 3), r (N+1, 3) or None, θ (N+1, 3)); θ is the
        time-route rotation increment in both cases (used by the Jacobian). Compiled
        (:func:`pose_into`).
        """
        n1 = self.n_nodes
        q, R, r, theta = np.empty((n1, 4)), np.empty((n1, 3, 3)), np.empty((n1, 3)), np.empty((n1, 3))
        step = self.step
        data = step.data
        has_r = data.has_r_old
        space = self.contact is not None and step.r_old is not None
        pose_into(np.ascontiguousarray(Y, dtype=float), data.Y_old, float(step.dt), space,
                  data.q_old, data.r_old, data.vg_old, has_r,
                  float(self.p.ds), q, R, r, theta, np.empty((n1, 3)))
        return q, R, (r if (space or has_r) else None), theta

    def node_terms(self, Y, want_jacobian, pose=None, glob_force=None):
        """F(Y) per node (N+1, 12) and, if asked, its Jacobian (N+1, 12, 12) (a copy).

        The node terms of seed eqs. 2-5 (E1 κ×ω, E2 κ×v + a3×ω, E3 κ×f − M_t(ω×v) + B,
        E4 κ×Bκ − ω×Iω + a3×f) with the distributed load B: the Morison drag, and the
        global-frame force glob_force (N+1, 3) N/m rotated into the body frame,
        B = Rᵀ F_global, with ∂B/∂ω^{n+1} = c [B]× J_r(θ).
        pose: (R (N+1, 3, 3), θ (N+1, 3), c) for orientation-dependent loads: R the
        new-level rotation R^n exp(θ) and c = ∂θ/∂ω^{n+1} = ½Δt; None when the case has
        none. Compiled (:func:`node_terms_into`, which the residual uses too).
        """
        p = self.p
        Y = np.ascontiguousarray(Y, dtype=float)
        buf = self.buf
        n1 = self.n_nodes
        rotate = pose is not None and glob_force is not None
        if rotate:
            Rm = np.ascontiguousarray(pose[0], dtype=float)
            theta = np.ascontiguousarray(pose[1], dtype=float)
            half = float(pose[2])
            G = np.ascontiguousarray(glob_force, dtype=float)
        else:
            Rm, theta, half, G = np.zeros((n1, 3, 3)), np.zeros((n1, 3)), 0.0, np.zeros((n1, 3))
        Fn = np.empty((n1, NV))
        dF = np.empty((n1, NV, NV))
        node_terms_into(Y, bool(want_jacobian), p.mass_t, p.stiffness, p.inertia,
                        bool(self.loads.has_drag), self.rod_data.cdn, self.rod_data.cdt, rotate,
                        Rm, theta, half, G, False, buf.diag, Fn, dF, np.empty((n1, 3, 3)),
                        np.empty((n1, 3)), np.empty((n1, 3)), np.empty((n1, 3, 3)),
                        np.empty((n1, 3, 3)))
        return Fn, (dF if want_jacobian else None)

    # ------------------------------------------------------------------ global system
    def evaluate(self, Y, want_jacobian=False, frozen=None, buf=None):
        """Run :func:`residual_into` at the iterate Y (N+1, 12) into ``buf`` (default the
        system's own buffers) and return the flags (4,) (its docstring)."""
        buf = self.buf if buf is None else buf
        fz = self._no_frozen if frozen is None else np.ascontiguousarray(frozen, np.intp)
        residual_into(np.ascontiguousarray(Y, dtype=float), bool(want_jacobian), self.rod_data,
                      self.step.data, self.step.cand_arrays, fz, self.contact_data, buf,
                      self.ev)
        return buf.flags

    def residual(self, Y, want_jacobian=False):
        """Residual (n,) of the step's difference equations at the iterate Y (N+1, 12).

        Returns (R, F_nodes, blocks or None, pose or None); blocks (N, 12, 24) are the
        unscaled cell Jacobian blocks on [node k-1 | node k] (a buffer reused by the next
        call). The new-level pose (:meth:`pose_new`) is computed when global-frame loads
        or contact candidates need it; with contact candidates the contacts are
        re-selected and evaluated at this iterate (with the frozen selection, if Newton
        has set one). One compiled call (:func:`residual_into`).
        """
        buf = self.buf
        flags = self.evaluate(Y, want_jacobian, self.step.frozen_selection)
        pose = None
        if flags[2]:
            has_r = self.contact is not None or self.step.data.has_r_old
            pose = (buf.q.copy(), buf.Rm.copy(), buf.r.copy() if has_r else None,
                    buf.theta.copy())
        return buf.R.copy(), buf.Fn.copy(), (buf.blocks if want_jacobian else None), pose

    def contact_summary(self, r, v, fresh: bool):
        """(number of active contacts, smallest surface gap (m), inf without any) at the
        positions r and global velocities v (N+1, 3) of the last :meth:`evaluate`, or
        None without candidates. ``fresh``: that evaluation selected the closest points
        afresh, and its own numbers are returned; else (a frozen selection, see
        :meth:`solver.contact.SelfContact.closest`) the contacts are evaluated again with
        a fresh selection (:func:`solver.contact.model.evaluate_into`, into this step's
        arrays). Coincident centreline points in a pair give a gap of −inf. The fresh
        evaluation is kept for :meth:`summary_potential` at the same positions r."""
        self._summary = None
        if self.step.candidates is None:
            return None
        if fresh:
            p = int(self.buf.flags[1])
        else:
            p = evaluate_into(np.ascontiguousarray(r, dtype=float),
                              np.ascontiguousarray(v, dtype=float), self.step.cand_arrays,
                              np.full(0, -1, np.intp), self.contact_data, self.ev)
            if p < 0:
                return 0, -math.inf
        self._summary = (r, p)
        return p, (float(self.ev.gap[:p].min()) if p else math.inf)

    def summary_potential(self, r):
        """The contact law's stored energy (J) at the positions r (N+1, 3) m of the last
        :meth:`contact_summary`, from its fresh evaluation
        (:func:`solver.contact.model.evaluation_potential`: the value of
        :meth:`solver.contact.SelfContact.potential` at r, bit for bit, without finding
        the closest points again); None unless r is the very array that summary was
        given, in this step. Raises nothing. (``getattr``: a system restored from a
        checkpoint written before this attribute existed has none until its next step.)"""
        summary = getattr(self, "_summary", None)
        if summary is None or summary[0] is not r:
            return None
        return float(evaluation_potential(self.ev, summary[1], self.contact_data))

    def column_scale(self, Y):
        """Scale of each unknown (n,): max(|Y| of its kind over the grid, its floor)."""
        mags = np.abs(Y).reshape(-1, 4, 3).max(axis=(0, 2))
        s12 = np.maximum(np.repeat(mags, 3), self.floor)
        return s12

    def candidate_gaps(self, Y):
        """Surface gaps (R,) m of the closest points of the step's contact candidates at
        the iterate Y (new level), inf for run edges; empty without candidates."""
        cand = self.step.candidates
        if cand is None:
            return np.zeros(0)
        r = self.pose_new(Y)[2]
        if not np.all(np.isfinite(r)):
            return np.full(cand.runs, -np.inf)
        return self.contact.gaps(cand, r)
