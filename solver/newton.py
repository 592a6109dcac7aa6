"""Newton's method for one time step: iteration, safeguards and the linear solver.

The difference equations of a step (:class:`solver.scheme.RodSystem`) are solved for all
12(N+1) unknowns at once. The strategy, in one place:

* **Jacobian and factorisation.** The analytic Jacobian in LAPACK band storage
  (kl = ku = 17, :mod:`solver.banded`), equilibrated by a column scale (characteristic
  size of each unknown) and a row scale (size of the terms of each row). Without contact
  the LU is reused across iterations and steps (chord) while the step size, the scheme's
  weights and the boundary rows are unchanged, and refactored when the residual falls
  by less than 4× in an iteration.
* **Self-contact.** The pose is the space route (:meth:`RodSystem.pose_new`), so the
  contact forces depend on κ upstream of each node: the exact Jacobian is not banded.
  GMRES (right-preconditioned, Saad & Schultz 1986) solves with the exact operator
  applied matrix-free (:meth:`RodSystem._exact_loads`), preconditioned by the band LU
  of the node-local (time-route) approximation with its contact blocks weighted by
  ``CONTACT_BAND_WEIGHT`` (:meth:`_preconditioner_band`). That LU is kept across iterates while
  GMRES converges in at most ``GMRES_REFACTOR`` iterations and refactored when it needs
  more: about one factorisation per contact step (docs/contact.md).
* **Feasible iterates.** A correction may close no candidate gap to less than
  ``GAP_KEEP`` of itself (halving; an IPC-like filter), then an Armijo backtracking on
  the scaled residual, whose evaluation with its Jacobian is reused as the next iterate.
* **Fail fast.** A contact step that halves its residual less than once in four
  iterations, whose corrections are cut to 1/64 three times, or whose GMRES does not
  converge even with a fresh factorisation, fails at once: the step control
  (:mod:`solver.simulation`) cuts Δt.
"""
from __future__ import annotations

import math

import numba
import numpy as np
from scipy.linalg import lapack

from .banded import BandFactorError, BandLayout, NV
from .scheme import E3

__all__ = ["Newton", "equilibrate", "scale_blocks"]


def equilibrate(system, Y, blocks):
    """Row and column scales of the step's Jacobian at the iterate Y (N+1, 12).

    Columns: the characteristic size of each kind of unknown (``RodSystem.column_scale``,
    (12,) per node); rows: 1 / Σ_j |J_ij| s_j over the row's entries (cell blocks
    (N, 12, 24) and the boundary rows), 1 where a row is empty. Returns
    (row_scale (n,), s12 (12,)). docs/numerics.md § 3 ("Scaling").
    """
    s12 = system.column_scale(Y)
    bc_rows, bc_cols, bc_vals = system.bc.jacobian_entries()
    rs = np.empty(system.n)
    rs[6:6 + NV * system.n_cells] = (np.abs(blocks) @ np.tile(s12, 2)).ravel()
    rs[bc_rows] = np.abs(bc_vals) * s12[bc_cols % NV]
    return 1.0 / np.where(rs > 0, rs, 1.0), s12


@numba.njit(cache=True)
def _scale_blocks_kernel(blocks, row_scale, s12, out):
    """out[c, i, j] = blocks[c, i, j] · (r_{6 + 12c + i} s_{j mod 12}) for cell blocks
    (N, 12, 24): the product of :func:`scale_blocks` in one pass, without numpy's
    broadcast temporaries (0.49 → ~0.05 ms at 1000 cells), the same values."""
    for c in range(blocks.shape[0]):
        for i in range(NV):
            r = row_scale[6 + NV * c + i]
            for j in range(2 * NV):
                out[c, i, j] = blocks[c, i, j] * (r * s12[j % NV])


def scale_blocks(system, blocks, row_scale, s12):
    """The cell blocks (N, 12, 24) and boundary values (12,) of the Jacobian in the
    scales of :func:`equilibrate` (row scale (n,), column scale s12 (12,) per node; the
    cell blocks hold rows 6 + 12c + i, :mod:`solver.banded`). Returns a fresh
    (N, 12, 24) array and (12,)."""
    bc_rows, bc_cols, bc_vals = system.bc.jacobian_entries()
    scaled = np.empty_like(blocks)
    _scale_blocks_kernel(np.ascontiguousarray(blocks), row_scale, np.ascontiguousarray(s12),
                         scaled)
    return scaled, bc_vals * row_scale[bc_rows] * s12[bc_cols % NV]


#: the load arguments of _matvec_kernel without exact load terms
_NO_LOAD_ROWS = np.zeros((0, 3))


@numba.njit(cache=True)
def _matvec_kernel(blocks, x, load_weight, dB, out):
    """The cell rows of a scaled Jacobian-vector product into out (n,): cell c's rows
    6 + 12c + i are blocks[c] (12, 24) times x on nodes (c, c + 1); with loads (dB
    (N+1, 3) non-empty) its E3 rows also get load_weight[c] (N, 3) times dB_c + dB_{c+1}
    (the cell average of a node load). One pass, no (N, 12) temporaries (0.24 → ~0.16 ms
    at 1000 cells with the loads). The boundary rows are left to the caller."""
    add_loads = dB.shape[0] > 0
    for c in range(blocks.shape[0]):
        base = NV * c
        for i in range(NV):
            # four partial sums (independent chains the processor overlaps)
            a0 = 0.0
            a1 = 0.0
            a2 = 0.0
            a3 = 0.0
            for j in range(0, 2 * NV, 4):
                a0 += blocks[c, i, j] * x[base + j]
                a1 += blocks[c, i, j + 1] * x[base + j + 1]
                a2 += blocks[c, i, j + 2] * x[base + j + 2]
                a3 += blocks[c, i, j + 3] * x[base + j + 3]
            out[6 + base + i] = (a0 + a1) + (a2 + a3)
        if add_loads:
            for i in range(3):
                out[6 + base + E3 + i] += load_weight[c, i] * (dB[c, i] + dB[c + 1, i])


def _back_substitute(R, g):
    """y with R y = g for the upper triangular (k, k) R of GMRES's rotated Hessenberg
    matrix (a zero pivot, a breakdown, gives the least-squares solution instead).
    LAPACK's ``dtrtrs`` directly (what scipy's solve_triangular calls, without its
    ~6 µs of argument handling, once per GMRES solve)."""
    if R.shape[0] == 0:
        return np.zeros(0)
    y, info = lapack.dtrtrs(R, g)
    if info == 0:
        return y
    return np.linalg.lstsq(R, g, rcond=None)[0]


def _norm(x):
    """2-norm of a vector (n,); inf or NaN where x has one (a diverging trial point)."""
    return math.sqrt(float(x @ x))


class Newton:
    """Newton iterations for the steps of one :class:`solver.scheme.RodSystem`.

    Parameters
    ----------
    system : RodSystem
    tolerance : float
        Convergence when the scaled residual max_i |R_i| / Σ_j |J_ij| y_j (each row's
        residual relative to the size of its terms) is below it.
    max_iterations : int

    Attributes
    ----------
    min_iterations : iterations taken even when the start passes the test (0; the run
        sets 1 under error control, docs/numerics.md § 7 "Newton's noise").
    factorizations, gmres_iterations, gmres_failures : counters over the run.
    last_failure : None, "singular", "stalled" or "gmres" (why the last solve failed).
    """

    #: contact steps: refactor the band LU when the last GMRES solve needed more
    #: iterations than this (else the LU of an earlier iterate preconditions the
    #: current Jacobian)
    GMRES_REFACTOR = 20

    #: contact steps: the share of the node-local contact blocks that the band LU
    #: preconditioning GMRES holds (the operator stays exact). With all of them GMRES
    #: needs more iterations (each touching node is tied to a fixed partner); without
    #: any, Newton's steps were worse late in the seed example's plies (measured on
    #: replayed seed steps: docs/contact.md § 4)
    CONTACT_BAND_WEIGHT = 0.05

    #: contact steps: from this iterate on, the closest-point selection is frozen
    FREEZE_AFTER = 6

    #: iterations taken even when the start passes the test (a class default, so that
    #: runs pickled before it existed resume; the run sets 1 under error control)
    min_iterations = 0

    def __init__(self, system, tolerance=1e-9, max_iterations=25):
        self.system = system
        self.tol = float(tolerance)
        self.max_iterations = int(max_iterations)
        self.layout = BandLayout(system.n_cells)
        self.factor_valid = False
        self.factor_key = None
        self.factorizations = 0
        self.gmres_failures = 0
        self.gmres_iterations = 0
        self.last_failure = None
        self._row_scale = None
        self._col_scale = None
        self._coupled = None
        self._factored_with_contact = False

    def _coupled_matvec(self, x):
        """Scaled Jacobian times x: band cells and boundary rows, plus (self-contact
        configured) the exact load terms of the space-route pose in place of their
        node-local approximation (:meth:`_exact_loads`)."""
        blocks, bc_rows, bc_cols, bc_vals, ex = self._coupled
        system = self.system
        out = np.empty(system.n)
        x = np.ascontiguousarray(x)
        if ex is not None:
            dB = system._exact_loads(ex, (x * self._col_scale).reshape(system.n_nodes, NV))
            _matvec_kernel(blocks, x, self._load_row_weight(), dB, out)
        else:
            _matvec_kernel(blocks, x, _NO_LOAD_ROWS, _NO_LOAD_ROWS, out)
        out[bc_rows] = bc_vals * x[bc_cols]
        return out

    def _load_row_weight(self):
        """The weight (N, 3) of a node load in the scaled E3 rows of its two cells,
        ½(1 − αf)·row scale (the cell average of the loads at the α-level)."""
        n_cells = self.system.n_cells
        rs = self._row_scale[6:6 + NV * n_cells].reshape(n_cells, NV)[:, E3:E3 + 3]
        return (0.5 * (1.0 - self.system.params.alpha_f)) * rs

    def _coupled_solve(self, rhs, rtol=1e-3, max_iterations=40):
        """Solve the contact-coupled (scaled) system by right-preconditioned GMRES.

        The operator is :meth:`_coupled_matvec` (the exact Jacobian); the preconditioner
        the band LU of the node-local approximation, possibly from an earlier iterate.
        Arnoldi with classical Gram-Schmidt and one reorthogonalisation (two products
        with the basis per iteration); the Hessenberg matrix is reduced by Givens
        rotations as it grows, so the least-squares residual is known at every
        iteration without solving for it (Saad & Schultz 1986, § 3). Stops at a relative
        residual rtol (an inexact Newton step; Newton's own test is on the nonlinear
        residual; 1e-4 took the same Newton iterations as 1e-7 and 14 % fewer GMRES
        iterations on the seed example at 30 s; 1e-3 against 1e-4, replayed from the seed's
        states at 18 and 32 s over 3 s each: Newton iterations 547 / 568 and 144 / 143,
        GMRES iterations −21 % and −18 %; 1e-2 took 15-20 % more Newton iterations).
        Source: Saad & Schultz, SIAM J. Sci. Stat. Comput. 7 (1986) 856-869.
        """
        n = self.system.n
        precond = self.layout.solve
        x0 = precond(rhs)
        r = rhs - self._coupled_matvec(x0)
        bnorm = _norm(rhs)
        beta = _norm(r)
        if beta <= rtol * bnorm or beta == 0.0:
            return x0
        m = max_iterations
        V, Z = self._krylov_basis(m, n)
        H = np.zeros((m + 1, m))
        cs = np.zeros(m)
        sn = np.zeros(m)
        g = np.zeros(m + 1)            # the rotated right-hand side β e1
        g[0] = beta
        V[0] = r / beta
        k = 0
        for k in range(m):
            Z[k] = precond(V[k])
            w = self._coupled_matvec(Z[k])
            h = V[:k + 1] @ w
            w -= h @ V[:k + 1]
            h2 = V[:k + 1] @ w
            w -= h2 @ V[:k + 1]
            col = h + h2
            hnext = _norm(w)
            H[:k + 1, k] = col
            # apply the earlier rotations to the new column, then annihilate H[k+1, k]
            for i in range(k):
                a, b = H[i, k], H[i + 1, k]
                H[i, k] = cs[i] * a + sn[i] * b
                H[i + 1, k] = -sn[i] * a + cs[i] * b
            a = H[k, k]
            rho = float(np.hypot(a, hnext))
            cs[k], sn[k] = (1.0, 0.0) if rho == 0.0 else (a / rho, hnext / rho)
            H[k, k] = rho
            g[k + 1] = -sn[k] * g[k]
            g[k] = cs[k] * g[k]
            if abs(g[k + 1]) <= rtol * bnorm or hnext <= 1e-14 * beta:
                break
            V[k + 1] = w / hnext
        else:
            self.gmres_failures += 1
        self.gmres_iterations += k + 1
        y = _back_substitute(H[:k + 1, :k + 1], g[:k + 1])
        return x0 + y @ Z[:k + 1]

    def _krylov_basis(self, m, n):
        """GMRES's work arrays V (m+1, n) and Z (m, n), allocated once and kept between
        solves instead of afresh at every solve (8 MB at 1000 segments, m = 40). Not
        pickled (:meth:`__getstate__`)."""
        work = getattr(self, "_work", None)
        if work is None or work[0].shape != (m + 1, n):
            work = (np.empty((m + 1, n)), np.empty((m, n)))
            self._work = work
        return work

    def __getstate__(self):
        state = self.__dict__.copy()
        state.pop("_work", None)
        return state

    def factor(self, Y, blocks):
        """Scale, assemble and factorise the Jacobian at Y (N+1, 12) from its cell blocks
        (N, 12, 24) (sets the row and column scales), and set the operator for the
        coupled solve when self-contact is configured. Raises BandFactorError when the
        band LU meets a zero pivot (a singular Jacobian)."""
        rs, s12 = equilibrate(self.system, Y, blocks)
        self._row_scale = rs
        self._col_scale = np.tile(s12, self.system.n_nodes)
        self._s12 = s12
        bc_rows, bc_cols, _ = self.system.bc.jacobian_entries()
        # the band part (with a share of the node-local contact blocks) is always
        # LU-factorised; with self-contact the correction is solved by GMRES with the
        # exact operator, preconditioned by the band LU
        scaled, bc_scaled, ex = self._preconditioner_band(blocks)
        self.layout.factor(scaled, bc_rows, bc_cols, bc_scaled)
        self._set_operator(scaled, bc_scaled, ex)
        self.factor_valid = True
        self._factored_with_contact = self.system.candidates is not None
        self.factorizations += 1

    def _scaled(self, blocks):
        """Cell blocks and boundary values in the scales of the last factorisation."""
        return scale_blocks(self.system, blocks, self._row_scale, self._s12)

    def _preconditioner_band(self, blocks):
        """The scaled cell blocks (N, 12, 24) and boundary values of the band that
        preconditions GMRES, and the exact load data of the operator that goes with it.

        The band holds the node-local contact blocks (``RodSystem.contact_band``) only with
        the weight CONTACT_BAND_WEIGHT; the operator's node-local part is weighted alike,
        so band + exact product is still the exact Jacobian. The row scale is that of the
        full blocks (:func:`equilibrate`), so the residual test does not change."""
        system = self.system
        ex = system._exact if system.contact is not None else None
        scaled, bc_scaled = self._scaled(blocks)
        diag = getattr(system, "contact_band", None)
        if diag is None or ex is None or self.CONTACT_BAND_WEIGHT == 1.0:
            return scaled, bc_scaled, ex
        cut = 1.0 - self.CONTACT_BAND_WEIGHT
        rows = cut * self._load_row_weight()
        cols = self._s12[0:6]
        scaled[:, E3:E3 + 3, 0:6] -= rows[:, :, None] * diag[:-1] * cols
        scaled[:, E3:E3 + 3, NV:NV + 6] -= rows[:, :, None] * diag[1:] * cols
        return scaled, bc_scaled, dict(ex, L=ex["L"] - cut * diag)

    def _set_operator(self, scaled, bc_scaled, ex, stale=False):
        """The (scaled) Jacobian for GMRES: band cells, boundary rows and the exact load
        terms ``ex`` of the space-route pose (:meth:`_preconditioner_band`); None when
        the band LU is the exact Jacobian."""
        if ex is None and not stale:
            self._coupled = None
            return
        bc_rows, bc_cols, _ = self.system.bc.jacobian_entries()
        # ``scaled`` is a fresh array (scale_blocks), used by nothing else afterwards
        self._coupled = (scaled, bc_rows, bc_cols, bc_scaled, ex)

    def update_operator(self, blocks):
        """Contact steps between factorisations: the GMRES operator becomes the Jacobian
        at the current iterate (cell blocks (N, 12, 24) and the system's exact load data)
        while the (older) band LU stays the preconditioner."""
        scaled, bc_scaled, ex = self._preconditioner_band(blocks)
        self._set_operator(scaled, bc_scaled, ex, stale=True)

    def solve(self, Y_guess):
        """Newton iterations for the step set up by :meth:`RodSystem.begin_step`.

        Y_guess: (N+1, 12) start. Returns (Y (N+1, 12), F_nodes (N+1, 12), iterations,
        residual_norm, converged, pose or None); the scaled residual norm is
        max_i |R_i| r_i with r_i the row scale of the last factorisation. A failure is
        returned, not raised (``last_failure`` says why); floating-point warnings of a
        diverging trial are silenced. The module docstring gives the strategy.
        """
        system = self.system
        contact = system.candidates is not None
        if (system.step_key != self.factor_key or contact or self._factored_with_contact):
            self.factor_valid = False
        self.factor_key = system.step_key
        # a trial step that blows up is an expected event (the caller cuts Δt): no warnings
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            return self._newton(Y_guess)

    def _newton(self, Y_guess):
        self.last_failure = None
        Y = Y_guess.copy()
        contact = self.system.candidates is not None
        res_prev = np.inf
        refactor = not self.factor_valid or contact
        res = np.inf
        pose = None
        tiny = 0
        history = []
        stall_scale = None
        cached = None
        gmres_last = 0
        for it in range(self.max_iterations + 1):
            if cached is not None:
                R, Fn, blocks, pose = cached
                cached = None
            else:
                R, Fn, blocks, pose = self.system.residual(Y, want_jacobian=refactor or contact)
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
            elif contact:
                self.update_operator(blocks)
            res = float(np.max(np.abs(R) * self._row_scale))
            if res <= self.tol and it >= self.min_iterations:
                return Y, Fn, it, res, True, pose
            if it == self.max_iterations:
                break
            if contact:
                # stalls are judged in one scale (the row scale changes with the contact
                # stiffness from one factorisation to the next)
                if stall_scale is None:
                    stall_scale = self._row_scale.copy()
                history.append(float(np.max(np.abs(R) * stall_scale)))
                if it >= 6 and history[-1] > 0.5 * history[-5]:
                    # less than a halving in four iterations: Δt is too large
                    self.last_failure = "stalled"
                    return Y, Fn, it, res, False, pose
            elif not fresh and res > 0.25 * res_prev:
                # the reused factor converges slowly: refactor at this iterate
                R, Fn, blocks, pose = self.system.residual(Y, want_jacobian=True)
                try:
                    self.factor(Y, blocks)
                except BandFactorError:
                    self.last_failure = "singular"
                    return Y, Fn, it, np.inf, False, pose
                res = float(np.max(np.abs(R) * self._row_scale))
            res_prev = res
            rhs = -R * self._row_scale
            if self._coupled is not None:
                failures, g0 = self.gmres_failures, self.gmres_iterations
                delta = self._coupled_solve(rhs) * self._col_scale
                gmres_last = self.gmres_iterations - g0
                if self.gmres_failures > failures:
                    if not fresh:
                        # a stale preconditioner: refactor here and solve again
                        try:
                            self.factor(Y, blocks)
                        except BandFactorError:
                            self.last_failure = "singular"
                            return Y, Fn, it, np.inf, False, pose
                        rhs = -R * self._row_scale
                        failures = self.gmres_failures
                        if self._coupled is None:
                            delta = self.layout.solve(rhs) * self._col_scale
                        else:
                            delta = self._coupled_solve(rhs) * self._col_scale
                    if self.gmres_failures > failures:
                        # the contact coupling is too strong for the band preconditioner
                        # at this Δt: the correction is unreliable. Fail now; the caller
                        # cuts Δt.
                        self.last_failure = "gmres"
                        return Y, Fn, it + 1, res, False, pose
            else:
                delta = self.layout.solve(rhs) * self._col_scale
            delta = delta.reshape(Y.shape)
            if contact:
                if it + 1 == self.FREEZE_AFTER and self.system.selection is not None:
                    # from here on each contact keeps its partner segment (see
                    # SelfContact.closest): no switching between iterates
                    self.system.frozen_selection = self.system.selection
                delta, alpha = self._feasible_step(Y, delta)
                # corrections cut to 1/64 or less three times in a row: the iterate
                # sits against the barrier and Newton stalls
                tiny = tiny + 1 if alpha <= 1.0 / 64.0 else 0
                if tiny >= 3:
                    self.last_failure = "stalled"
                    return Y, Fn, it + 1, res, False, pose
                delta, cached = self._line_search(Y, delta, R)
                refactor = gmres_last > self.GMRES_REFACTOR
            Y = Y + delta
        return Y, Fn, self.max_iterations, res, False, pose

    def filtered(self, e):
        """The error filter of stiff integrators, J⁻¹(c M_b e) (Shampine's for RADAU5,
        Hairer & Wanner, *Solving ODEs II*, § IV.8; Hosea & Shampine, Appl. Numer. Math.
        20 (1996) 21-37, for the trapezoid): e (N+1, 12) is mapped through the step's last
        band LU, J = c M_b + (1 − αf) A_b. Components that the step resolves (|λΔt| small)
        pass unchanged; stiff ones, which the scheme damps and an error estimate should
        not chase (contact oscillations, checkerboard modes), are divided by about λ/c.
        The result satisfies the linearised constraints (its f and E2 rows are
        consistent). Returns (N+1, 12); needs a factorisation of the current step."""
        rhs = self.system.cm * self.system.cell_inertia(e)
        x = self.layout.solve(rhs * self._row_scale) * self._col_scale
        return x.reshape(e.shape)

    def _line_search(self, Y, delta, R0):
        """Backtracking on the row-scaled residual 2-norm (contact steps only): halve the
        correction, at most 4 times, until the residual decreases (Armijo, c = 1e-4).
        Returns (correction, the residual tuple with Jacobian at the accepted point, to be
        reused as the next iterate's)."""
        f0 = _norm(R0 * self._row_scale)
        alpha = 1.0
        out = None
        for _ in range(4):
            out = self.system.residual(Y + alpha * delta, want_jacobian=True)
            f1 = _norm(out[0] * self._row_scale)
            if np.isfinite(f1) and f1 <= (1.0 - 1e-4 * alpha) * f0:
                return alpha * delta, out
            alpha *= 0.5
        return 2.0 * alpha * delta, out

    #: a Newton correction may close no candidate gap to less than this fraction of itself
    GAP_KEEP = 0.2

    def _feasible_step(self, Y, delta):
        """Largest fraction 2^−k (k ≤ 10) of a Newton correction that keeps every
        candidate gap at least GAP_KEEP of its current value (a filter in the manner of
        IPC's CCD-bounded line search: Li et al., ACM TOG 39(4), 2020, §4). Gaps are the
        closest-point gaps of the step's candidates re-selected at each trial, so a
        correction cannot carry a strand through one it was not pressed against.
        Returns (limited correction, fraction)."""
        g0 = self.system.candidate_gaps(Y)
        if g0.size == 0 or np.any(np.isnan(g0)) or np.any(g0 == -np.inf):
            return delta, 1.0
        finite = np.isfinite(g0)
        floor = np.where(g0 > 0.0, self.GAP_KEEP * g0, 2.0 * g0)
        alpha = 1.0
        for _ in range(10):
            g1 = self.system.candidate_gaps(Y + alpha * delta)
            ok = ~finite | (g1 >= floor)
            if np.all(ok) and not np.any(np.isnan(g1)):
                break
            alpha *= 0.5
        return alpha * delta, alpha
