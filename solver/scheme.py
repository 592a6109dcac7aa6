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

import numpy as np
from scipy.sparse import csr_matrix

from .banded import BandFactorError, BandLayout, NV
from .kinematics import quat_exp, quat_multiply, quat_to_matrix, right_jacobian, skew

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


def _cross(a: np.ndarray, b: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Row-wise cross product of (n, 3) arrays (faster than np.cross for small rows)."""
    if out is None:
        out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def _add_skew(out, r0, c0, a, rscale=None, cscale=None, sign=1.0):
    """out[:, r0:r0+3, c0:c0+3] += sign · diag(rscale) [a]× diag(cscale), vectorised."""
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    entries = ((0, 1, -a2), (0, 2, a1), (1, 0, a2), (1, 2, -a0), (2, 0, -a1), (2, 1, a0))
    for r, c, val in entries:
        term = sign * val
        if rscale is not None:
            term = term * rscale[:, r]
        if cscale is not None:
            term = term * cscale[:, c]
        out[:, r0 + r, c0 + c] += term


class RodSystem:
    """Residual and Jacobian of one time step of the box/generalized-α scheme.

    Parameters
    ----------
    props : RodProperties
    loads : LoadModel
    contact : optional self-contact model (see :mod:`solver.contact`) or None
    newton_tolerance : float
        Convergence when the scaled residual max_i |R_i| / Σ_j |J_ij| y_j (each row's
        residual relative to the size of its terms) is below it.
    max_iterations : int
    """

    def __init__(self, props, loads, newton_tolerance=1e-9, max_iterations=25, contact=None):
        self.p = props
        self.loads = loads
        self.contact = contact
        self.tol = float(newton_tolerance)
        self.max_iterations = int(max_iterations)
        self.n_nodes = props.s.size
        self.n_cells = self.n_nodes - 1
        self.layout = BandLayout(self.n_cells)
        self.n = self.layout.n
        self.needs_pose = loads.has_global or contact is not None
        # characteristic sizes of the unknowns (floors of the column scale)
        length = props.s[-1]
        b0 = float(np.max(props.stiffness[:, :2]))
        m0 = float(np.max(props.rho_a))
        tc = length**2 * np.sqrt(m0 / b0)
        self.floor = np.repeat([length / tc, 1.0 / tc, b0 / length**2, 1.0 / length], 3)
        self.factor_valid = False
        self.factor_key = None
        self.factorizations = 0
        self._row_scale = None
        # buffers
        n1 = self.n_nodes
        self._dF = np.zeros((n1, NV, NV))
        self.pairs = None
        self._coupled = None
        self.last_failure = None
        self.gmres_failures = 0
        self.gmres_iterations = 0
        self._blocks = np.empty((self.n_cells, NV, 2 * NV))

    # ------------------------------------------------------------------ per step setup
    def begin_step(self, dt, params: StepParameters, t_new, Y_old, Ydot_old, F_old,
                   bc, q_old=None, r_old=None, v_old_global=None, pairs=None):
        """Freeze the old-level data of a step n -> n+1 of size dt (s) ending at t_new.

        Y_old, Ydot_old, F_old: (N+1, 12); bc: a BoundaryRows for t_new; q_old (N+1, 4) and
        r_old (N+1, 3) the old pose (needed for orientation-dependent loads and contact);
        v_old_global (N+1, 3) old global velocities (contact, position update);
        pairs: the contact pairs held fixed during this step's Newton iterations, or None.
        """
        p = self.p
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
        self._glob_force = self.loads.global_force(t_new) if self.loads.has_global else None
        self.pairs = pairs if (pairs is not None and len(pairs.i) > 0) else None
        if self.pairs is not None:
            self._pair_radii = 0.5 * (self.p.diameter[self.pairs.i]
                                      + self.p.diameter[self.pairs.j])
            margin = self.contact.tolerance - float(np.max(self.p.diameter))
            self._trust_radius = 0.5 * max(margin, 0.25 * float(np.max(self.p.diameter)))
        key = (dt, params, bc.key)
        # contact stiffness changes fast with the gaps: a fresh Jacobian every contact step
        if (key != self.factor_key or self.pairs is not None
                or (self.pairs is None) != (self._coupled is None)):
            self.factor_valid = False
        self.factor_key = key

    # ------------------------------------------------------------------ node pieces
    def _apply_M(self, Y):
        """M Y per node (N+1, 12): E1 −κ, E2 0, E3 −M_t v, E4 −I ω."""
        p = self.p
        out = np.zeros_like(Y)
        out[:, E1:E1 + 3] = -Y[:, K:K + 3]
        out[:, E3:E3 + 3] = -p.mass_t * Y[:, V:V + 3]
        out[:, E4:E4 + 3] = -p.inertia * Y[:, W:W + 3]
        return out

    def _flux(self, Y):
        """K Y per node (N+1, 12): (ω, v, f, q = Bκ) for E1..E4."""
        out = np.empty_like(Y)
        out[:, E1:E1 + 3] = Y[:, W:W + 3]
        out[:, E2:E2 + 3] = Y[:, V:V + 3]
        out[:, E3:E3 + 3] = Y[:, F:F + 3]
        out[:, E4:E4 + 3] = self.p.stiffness * Y[:, K:K + 3]
        return out

    def pose_new(self, Y):
        """Orientation and position at the new level from the old pose and the rates.

        q^{n+1} = q^n ⊗ exp(θ), θ = ½Δt(ω^n + ω^{n+1}); r^{n+1} = r^n + ½Δt(R^n v^n +
        R^{n+1} v^{n+1}). Returns (q (N+1, 4), R (N+1, 3, 3), r (N+1, 3) or None,
        θ (N+1, 3)).
        """
        theta = 0.5 * self.dt * (self.Y_old[:, W:W + 3] + Y[:, W:W + 3])
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
        extra: (B (N+1, 3), dB/dv (N+1, 3, 3)) an additional body-frame load and its
        node-local velocity Jacobian (self-contact), or None.
        """
        p = self.p
        v, w, f, k = Y[:, V:V + 3], Y[:, W:W + 3], Y[:, F:F + 3], Y[:, K:K + 3]
        q = p.stiffness * k
        Iw = p.inertia * w
        Fv = np.empty_like(Y)
        _cross(k, w, Fv[:, E1:E1 + 3])
        _cross(k, v, Fv[:, E2:E2 + 3])
        Fv[:, E2] -= w[:, 1]
        Fv[:, E2 + 1] += w[:, 0]
        wxv = _cross(w, v)
        _cross(k, f, Fv[:, E3:E3 + 3])
        Fv[:, E3:E3 + 3] -= p.mass_t * wxv
        _cross(k, q, Fv[:, E4:E4 + 3])
        Fv[:, E4:E4 + 3] -= _cross(w, Iw)
        Fv[:, E4] -= f[:, 1]
        Fv[:, E4 + 1] += f[:, 0]
        dB_dv = None
        if self.loads.has_drag:
            bd, dB_dv = self.loads.drag(v, want_jacobian)
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
        d.fill(0.0)
        # E1: κ×ω
        _add_skew(d, E1, W, k)
        _add_skew(d, E1, K, w, sign=-1.0)
        # E2: κ×v + a3×ω
        _add_skew(d, E2, V, k)
        _add_skew(d, E2, K, v, sign=-1.0)
        d[:, E2, W + 1] -= 1.0
        d[:, E2 + 1, W] += 1.0
        # E3: κ×f − M_t(ω×v) + B
        _add_skew(d, E3, F, k)
        _add_skew(d, E3, K, f, sign=-1.0)
        _add_skew(d, E3, W, v, rscale=p.mass_t)
        _add_skew(d, E3, V, w, rscale=p.mass_t, sign=-1.0)
        if dB_dv is not None:
            d[:, E3:E3 + 3, V:V + 3] += dB_dv
        if extra is not None and extra[1] is not None:
            d[:, E3:E3 + 3, V:V + 3] += extra[1]
        if b_rot is not None:
            d[:, E3:E3 + 3, W:W + 3] += pose[2] * (skew(b_rot) @ right_jacobian(pose[1]))
        # E4: κ×Bκ − ω×Iω + a3×f
        _add_skew(d, E4, K, k, cscale=p.stiffness)
        _add_skew(d, E4, K, q, sign=-1.0)
        _add_skew(d, E4, W, w, cscale=p.inertia, sign=-1.0)
        _add_skew(d, E4, W, Iw)
        d[:, E4, F + 1] -= 1.0
        d[:, E4 + 1, F] += 1.0
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
        if self.loads.has_global or self.pairs is not None:
            pose = self.pose_new(Y)
            pose_arg = (pose[1], pose[3], 0.5 * self.dt)
        extra = None
        glob = self._glob_force
        self._offband = None
        if self.pairs is not None:
            contact_global, diag = self._contact_terms(Y, pose, want_jacobian)
            glob = contact_global if glob is None else glob + contact_global
            extra = (None, diag)
        Fn, dF = self.node_terms(Y, want_jacobian, pose_arg, glob, extra)
        Z = 0.5 * self.cm * self._apply_M(Y) + 0.5 * (1.0 - af) * Fn + self._zconst
        flux = (1.0 - af) * self._flux(Y) + self._flux_const
        R = np.empty(self.n)
        cells = Z[:-1] + Z[1:] + (flux[1:] - flux[:-1]) / p.ds
        R[6:6 + NV * self.n_cells] = cells.ravel()
        self.bc.residual(Y, R)
        blocks = None
        if want_jacobian:
            P = 0.5 * (1.0 - af) * dF
            c = 0.5 * self.cm
            P[:, E1:E1 + 3, K:K + 3] -= c * np.eye(3)
            idx = np.arange(3)
            P[:, E3 + idx, V + idx] -= c * p.mass_t
            P[:, E4 + idx, W + idx] -= c * p.inertia
            qf = (1.0 - af) / p.ds
            blocks = self._blocks
            blocks[:, :, :NV] = P[:-1]
            blocks[:, :, NV:] = P[1:]
            for off, sgn in ((0, -1.0), (NV, 1.0)):
                nodes = slice(0, -1) if off == 0 else slice(1, None)
                blocks[:, E1 + idx, off + W + idx] += sgn * qf
                blocks[:, E2 + idx, off + V + idx] += sgn * qf
                blocks[:, E3 + idx, off + F + idx] += sgn * qf
                blocks[:, E4 + idx, off + K + idx] += sgn * qf * p.stiffness[nodes]
        return R, Fn, blocks, pose

    def _contact_terms(self, Y, pose, want_jacobian):
        """Self-contact load at the new level (global frame, N/m) and its Jacobian.

        The pair force depends on r_i − r_j and ṙ_i − ṙ_j at the new level, with
        r^{n+1} = r^n + ½Δt(ṙ^n + R^{n+1} v^{n+1}) and ṙ^{n+1} = R^{n+1} v^{n+1}, so
        ∂F_p/∂v_i = (½Δt G_r + G_v) R_i =: H_p R_i (the rotation's dependence on ω is left
        out here: the body-frame load Rᵀ F is differentiated in ω with the other global
        loads in :meth:`node_terms`). Node-local blocks go into the band; the blocks
        coupling i and j are kept in ``self._offband`` for the coupled solve.
        Returns (F (N+1, 3) global, ∂(RᵀF)/∂v (N+1, 3, 3) body frame, or None).
        """
        q, R, r, theta = pose
        vg = np.einsum("nij,nj->ni", R, Y[:, V:V + 3])
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(vg))):
            # a diverging iterate: make the residual non-finite so that Δt is cut
            return np.full((self.n_nodes, 3), np.nan), None
        ev = self.contact.evaluate(self.pairs, r, vg)
        n1 = self.n_nodes
        force = np.zeros((n1, 3))
        np.add.at(force, ev.i, ev.wi[:, None] * ev.force)
        np.add.at(force, ev.j, -ev.wj[:, None] * ev.force)
        if not want_jacobian:
            return force, None
        H = 0.5 * self.dt * ev.d_force_d_dr + ev.d_force_d_dv          # (P, 3, 3)
        Ri, Rj = R[ev.i], R[ev.j]
        RiT_H = np.einsum("pki,pkl->pil", Ri, H)                        # R_iᵀ H
        RjT_H = np.einsum("pki,pkl->pil", Rj, H)
        diag = np.zeros((n1, 3, 3))
        np.add.at(diag, ev.i, ev.wi[:, None, None] * (RiT_H @ Ri))
        np.add.at(diag, ev.j, ev.wj[:, None, None] * (RjT_H @ Rj))
        off_ij = -ev.wi[:, None, None] * (RiT_H @ Rj)                   # ∂B_i/∂v_j
        off_ji = -ev.wj[:, None, None] * (RjT_H @ Ri)                   # ∂B_j/∂v_i
        self._offband = (np.concatenate([ev.i, ev.j]), np.concatenate([ev.j, ev.i]),
                         np.concatenate([off_ij, off_ji]))
        return force, diag

    def _offband_entries(self):
        """(rows, cols, values) of the contact coupling between distant nodes.

        Node a's load enters the cells on both sides of it with weight ½(1−αf).
        """
        a, b, blocks = self._offband
        w = 0.5 * (1.0 - self.params.alpha_f)
        rows, cols, vals = [], [], []
        r3 = np.arange(3)
        for side in (-1, 0):
            cell = a + side
            ok = (cell >= 0) & (cell < self.n_cells)
            rr = 6 + NV * cell[ok][:, None, None] + E3 + r3[None, :, None]
            cc = NV * b[ok][:, None, None] + V + r3[None, None, :]
            rows.append(np.broadcast_to(rr, (ok.sum(), 3, 3)).ravel())
            cols.append(np.broadcast_to(cc, (ok.sum(), 3, 3)).ravel())
            vals.append((w * blocks[ok]).ravel())
        return np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)

    def _coupled_matvec(self, x):
        """Scaled Jacobian (band cells + boundary rows + distant contact coupling) times x."""
        blocks, bc_rows, bc_cols, bc_vals, off = self._coupled
        X = x.reshape(self.n_nodes, NV)
        out = np.empty(self.n)
        pairs = np.concatenate([X[:-1], X[1:]], axis=1)
        out[6:6 + NV * self.n_cells] = np.einsum("cij,cj->ci", blocks, pairs).ravel()
        out[bc_rows] = bc_vals * x[bc_cols]
        out += off @ x
        return out

    def _coupled_solve(self, rhs, rtol=1e-7, max_iterations=40):
        """Solve the contact-coupled (scaled) system by right-preconditioned GMRES.

        The preconditioner is the band LU (band cells with the node-local contact
        blocks); the coupling of distant nodes is a low-rank change of that matrix, so
        few iterations are needed. Arnoldi with classical Gram-Schmidt and one
        reorthogonalisation (two matrix-vector products with the basis per iteration);
        the small least-squares problem is solved directly. Stops at a relative residual
        rtol (an inexact Newton step; Newton's own test is on the nonlinear residual).
        Source: Saad & Schultz, SIAM J. Sci. Stat. Comput. 7 (1986) 856-869.
        """
        n = self.n
        precond = self.layout.solve
        x0 = precond(rhs)
        r = rhs - self._coupled_matvec(x0)
        bnorm = float(np.linalg.norm(rhs))
        beta = float(np.linalg.norm(r))
        if beta <= rtol * bnorm or beta == 0.0:
            return x0
        m = max_iterations
        V = np.empty((m + 1, n))
        Z = np.empty((m, n))
        H = np.zeros((m + 1, m))
        V[0] = r / beta
        y = np.zeros(0)
        k = 0
        for k in range(m):
            Z[k] = precond(V[k])
            w = self._coupled_matvec(Z[k])
            h = V[:k + 1] @ w
            w -= h @ V[:k + 1]
            h2 = V[:k + 1] @ w
            w -= h2 @ V[:k + 1]
            H[:k + 1, k] = h + h2
            H[k + 1, k] = float(np.linalg.norm(w))
            e = np.zeros(k + 2)
            e[0] = beta
            y = np.linalg.lstsq(H[:k + 2, :k + 1], e, rcond=None)[0]
            resid = float(np.linalg.norm(e - H[:k + 2, :k + 1] @ y))
            if resid <= rtol * bnorm or H[k + 1, k] <= 1e-14 * beta:
                break
            V[k + 1] = w / H[k + 1, k]
        else:
            self.gmres_failures += 1
        self.gmres_iterations += k + 1
        return x0 + y @ Z[:k + 1]

    def column_scale(self, Y):
        """Scale of each unknown (n,): max(|Y| of its kind over the grid, its floor)."""
        mags = np.abs(Y).reshape(-1, 4, 3).max(axis=(0, 2))
        s12 = np.maximum(np.repeat(mags, 3), self.floor)
        return s12

    def factor(self, Y, blocks):
        """Scale, assemble and factorise the Jacobian at Y. Sets the row scale."""
        s12 = self.column_scale(Y)
        s24 = np.tile(s12, 2)
        bc_rows, bc_cols, bc_vals = self.bc.jacobian_entries()
        cell_rowsum = np.abs(blocks) @ s24                      # (N, 12)
        node_of_col = bc_cols // NV
        bc_rowsum = np.abs(bc_vals) * s12[bc_cols - NV * node_of_col]
        rs = np.empty(self.n)
        rs[6:6 + NV * self.n_cells] = cell_rowsum.ravel()
        rs[bc_rows] = bc_rowsum
        rs = 1.0 / np.where(rs > 0, rs, 1.0)
        scaled = blocks * (rs[self.layout.cell_rows][:, :, None] * s24[None, None, :])
        col_scale = np.tile(s12, self.n_nodes)
        bc_scaled = bc_vals * rs[bc_rows] * s12[bc_cols % NV]
        # the band part (with the node-local contact blocks) is always LU-factorised;
        # contact coupling between distant nodes, when present, is kept as a sparse
        # matrix and the correction is solved by GMRES preconditioned with the band LU.
        self.layout.factor(scaled, bc_rows, bc_cols, bc_scaled)
        if self._offband is None:
            self._coupled = None
        else:
            o_rows, o_cols, o_vals = self._offband_entries()
            off = csr_matrix((o_vals * rs[o_rows] * col_scale[o_cols], (o_rows, o_cols)),
                             shape=(self.n, self.n))
            self._coupled = (scaled.copy(), bc_rows, bc_cols, bc_scaled, off)
        self._row_scale = rs
        self._col_scale = col_scale
        self.factor_valid = True
        self.factorizations += 1

    def solve_step(self, Y_guess):
        """Newton iterations for the step set up by :meth:`begin_step`.

        Returns (Y, F_nodes, iterations, residual_norm, converged, pose). The scaled
        residual norm is max_i |R_i| r_i with r_i the row scale of the last factorisation.
        """
        # a trial step that blows up is an expected event (the caller cuts Δt): no warnings
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            return self._newton(Y_guess)

    def _newton(self, Y_guess):
        self.last_failure = None
        Y = Y_guess.copy()
        res_prev = np.inf
        refactor = not self.factor_valid
        res = np.inf
        pose = None
        tiny = 0
        history = []
        for it in range(self.max_iterations + 1):
            R, Fn, blocks, pose = self.residual(Y, want_jacobian=refactor)
            if not np.all(np.isfinite(R)):
                return Y, Fn, it, np.inf, False, pose
            fresh = refactor
            if refactor:
                try:
                    self.factor(Y, blocks)
                except BandFactorError:
                    self.last_failure = "singular"
                    return Y, Fn, it, np.inf, False, pose
                refactor = False
            res = float(np.max(np.abs(R) * self._row_scale))
            if res <= self.tol:
                return Y, Fn, it, res, True, pose
            if it == self.max_iterations:
                break
            history.append(res)
            if self.pairs is not None and it >= 6 and res > 0.5 * history[-5]:
                # contact step: less than a halving in four iterations (typically the
                # trust region holding every correction back at a Δt that is too large)
                self.last_failure = "stalled"
                return Y, Fn, it, res, False, pose
            if not fresh and res > 0.25 * res_prev:
                # the reused factor converges slowly: refactor at this iterate
                R, Fn, blocks, pose = self.residual(Y, want_jacobian=True)
                try:
                    self.factor(Y, blocks)
                except BandFactorError:
                    self.last_failure = "singular"
                    return Y, Fn, it, np.inf, False, pose
                res = float(np.max(np.abs(R) * self._row_scale))
            res_prev = res
            rhs = -R * self._row_scale
            if self._coupled is not None:
                failures = self.gmres_failures
                delta = self._coupled_solve(rhs) * self._col_scale
                if self.gmres_failures > failures:
                    # the contact coupling is too strong for the band preconditioner at
                    # this Δt: the correction is unreliable and the iteration would only
                    # stall (measured: 25 iterations x 40 GMRES iterations per failed
                    # attempt). Fail now; the caller cuts Δt.
                    self.last_failure = "gmres"
                    return Y, Fn, it + 1, res, False, pose
            else:
                delta = self.layout.solve(rhs) * self._col_scale
            delta = delta.reshape(Y.shape)
            if self.pairs is not None:
                delta, alpha = self._limit_gap_step(Y, delta)
                # corrections cut to 1/64 or less three times in a row: the iterate
                # sits against the barrier or the trust region and Newton stalls
                tiny = tiny + 1 if alpha <= 1.0 / 64.0 else 0
                if tiny >= 3:
                    self.last_failure = "stalled"
                    return Y, Fn, it + 1, res, False, pose
                delta = self._line_search(Y, delta, R)
                # the barrier k1/gap^k2 changes the Jacobian much between iterates: a
                # frozen (chord) Jacobian converges only linearly, so contact steps use
                # full Newton (measured on the seed example: 11-20 iterations per
                # accepted step with the chord, see docs/contact.md)
                refactor = True
            Y = Y + delta
        return Y, Fn, self.max_iterations, res, False, pose

    def _line_search(self, Y, delta, R0):
        """Backtracking on the row-scaled residual 2-norm (contact steps only): halve the
        correction, at most 4 times, until the residual decreases (Armijo, c = 1e-4)."""
        f0 = float(np.linalg.norm(R0 * self._row_scale))
        alpha = 1.0
        for _ in range(4):
            R1 = self.residual(Y + alpha * delta, want_jacobian=False)[0]
            f1 = float(np.linalg.norm(R1 * self._row_scale))
            if np.isfinite(f1) and f1 <= (1.0 - 1e-4 * alpha) * f0:
                break
            alpha *= 0.5
        return alpha * delta

    def _pair_positions(self, Y):
        """New-level positions (2P, 3) m of the step's pair nodes (i then j) at iterate Y."""
        pr = self.pairs
        idx = np.concatenate([pr.i, pr.j])
        theta = 0.5 * self.dt * (self.Y_old[idx, W:W + 3] + Y[idx, W:W + 3])
        R = quat_to_matrix(quat_multiply(self.q_old[idx], quat_exp(theta)))
        vg = np.einsum("nij,nj->ni", R, Y[idx, V:V + 3])
        return self.r_old[idx] + 0.5 * self.dt * (self.v_old_global[idx] + vg)

    def pair_gaps(self, Y):
        """Surface gaps (P,) m of the step's contact pairs at the iterate Y (new level)."""
        pr = self.pairs
        r = self._pair_positions(Y)
        p = pr.i.size
        d = np.linalg.norm(r[:p] - r[p:], axis=1)
        return d - 0.5 * (self.p.diameter[pr.i] + self.p.diameter[pr.j])

    def _limit_gap_step(self, Y, delta):
        """Safeguards of a Newton correction while contact pairs are active.

        (1) Fraction to the boundary for the k1/gap^k2 barrier: no pair may close to less
        than 30 % of its current gap; (2) trust region: no pair node may move by more
        than half the contact margin (tolerance − D) in one iteration, so an iterate
        cannot leave the neighbourhood in which the pairs were found. The correction is
        halved (at most 10 times) until both hold. Returns (limited correction, factor).
        """
        r0 = self._pair_positions(Y)
        p = self.pairs.i.size
        g0 = np.linalg.norm(r0[:p] - r0[p:], axis=1) - self._pair_radii
        if not (np.all(np.isfinite(r0)) and np.all(np.isfinite(g0))):
            return delta, 1.0
        # a closing gap keeps 30 % of itself; a penetrating pair may not double its depth
        floor = np.where(g0 > 0.0, 0.3 * g0, 2.0 * g0)
        alpha = 1.0
        for _ in range(10):
            r1 = self._pair_positions(Y + alpha * delta)
            g1 = np.linalg.norm(r1[:p] - r1[p:], axis=1) - self._pair_radii
            step = np.max(np.linalg.norm(r1 - r0, axis=1)) if r1.size else 0.0
            if (np.all(np.isfinite(g1)) and np.all(g1 >= floor)
                    and step <= self._trust_radius):
                break
            alpha *= 0.5
        return alpha * delta, alpha
