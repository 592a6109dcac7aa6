"""What GMRES's iterations in a contact step are spent on: the spectrum of the Jacobian
preconditioned by the contact-free band LU, and what deflating its outlying eigenvalues
would save (docs/contact.md § 4, "What GMRES still takes").

The case (default the tension variant, ``cases/goyal-writhing-tension.yaml``, 1000
segments, ~640 contacts at 21 s) is run to ``--at`` s and a contact step of ``--dt`` s is
set up from that state as the run would set it up. Newton solves it; its iterates are
recovered (the same solve stopped after 1, 2, ... iterations). At each iterate the
operator is the one GMRES sees there (the scaled exact Jacobian J, :func:`solver.newton.
_matvec`) and the preconditioner M the band LU factored at the step's start (as the
solver keeps it, :func:`solver.newton._set_operator`). Printed:

1. the ``--k`` eigenvalues of J M⁻¹ farthest from 1 at the start (ARPACK through
   :func:`scipy.sparse.linalg.eigs` on J M⁻¹ − I), the time and operator applications
   it took to find them, and for each eigenvector's state-space direction M⁻¹u how many
   nodes hold 90 % of its squared norm, its largest unknown (v, ω, f or κ) and its two
   largest peaks at least 50 nodes apart;
2. GMRES's iterations to the solver's relative residual (1e-3) on each iterate's system,
   plain and right-deflated by an orthonormal basis U of those eigenvectors:
   M⁻¹ P with P = I + U(T⁻¹ − I)Uᵀ, T = Uᵀ J M⁻¹ U (Erhel, Burrage & Pohl, J. Comput.
   Appl. Math. 69 (1996) 303-318), U found (a) at that very iterate, (b) at the iterate
   before it, (c) at the step's start, and (d) at the start of the step before (the next
   ``--steps`` steps of the run);
3. the same with U built without an eigensolver, from the Arnoldi basis of the last
   GMRES solve of the step (its Ritz vectors with Ritz values more than ``--gap`` from 1,
   merged with the last U, at most ``--k`` of them, T carried from the last solve's
   Hessenberg matrix: a recycling of the Krylov subspaces in the manner of Parks et al.,
   SIAM J. Sci. Comput. 28 (2006) 1651-1674, at no extra operator product).

4. with ``--coarse`` (instead of 1-3), what a coarse space built without an eigensolver
   holds: Q (n, k) orthonormal, the indicators of aggregates of b consecutive contact
   cells (cells next to a node of a contact pair, split where they are not consecutive)
   on chosen residual rows of each cell (the lateral linear momentum rows E3₁, E3₂, all
   three E3 rows, or the compatibility rows E1 and E2), and the right preconditioner
   M⁻¹B with B = I − X(QᵀY)⁻¹Qᵀ, Y = J M⁻¹ Q, X = Y − Q: the Woodbury inverse of
   J M⁻¹ where J M⁻¹ − I vanishes off span(Q) (Woodbury 1950; a two-level correction of
   the kind compared by Tang, Nabben, Vuik & Erlangga, J. Sci. Comput. 39 (2009)
   340-370). It costs k operator applications to build. GMRES's iterations with B built
   at each iterate, with B built at the step's first iterate (the same factorisation),
   and at the next step's start with the last step's B.

5. with ``--augmented`` (instead of 1-3), what holding the whole contact coupling would
   cost: the exact Jacobian J as a sparse matrix with the space route's linearised pose
   as auxiliary unknowns (per node δφ_k, δr_k, the prefix sums of
   :func:`solver.scheme.exact_loads_product` written as its recurrence rows, so that a
   pair couples only its own nodes: :func:`augmented_matrix`), factorised by SuperLU
   (COLAMD) as GMRES's preconditioner. Per iterate: GMRES's iterations plain, with that
   LU fresh, with the LU of the step's start (of the last step's start at a step's first
   iterate), the factorisation's and a solve's time against the band LU's solve (and, at
   a step's first iterate, against the band factorisation), and the LU's nonzeros; at the first iterate also SuperLU with the MMD_ATA ordering and an
   incomplete LU (SuperLU's ILUTP, rows equilibrated, drop tolerance 1e-3 and 1e-4, fill
   factor 4) as the preconditioner.

GMRES here is a plain Arnoldi in numpy (two Gram-Schmidt passes), started from zero: its
counts are comparable with each other, not to the microsecond with the solver's kernel.

Run: ``PYTHONPATH=$PWD python -m research.gmres_spectrum [--case CASE.yaml] [--at 21]
[--dt 0.003] [--k 12] [--steps 3] [--gap 0.3] [--coarse | --augmented]`` (about 2 min to
reach 21 s of the tension variant, then ~20 s; ``--coarse`` ~2 min more, ``--augmented``
~10 s per iterate).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sparse
from scipy.sparse.linalg import LinearOperator, eigs, spilu, splu
from threadpoolctl import threadpool_limits

import solver.newton as newton_mod
from solver import Case
from solver.banded import block_solve
from solver.kinematics import skew
from solver.run import RodRun
from solver.scheme import E3, K, V, W, residual_into

from research.contact_iteration_cost import _advance_to, _median_ms  # beside this script

ROOT = Path(__file__).resolve().parents[1]
TENSION = ROOT / "cases" / "goyal-writhing-tension.yaml"
RTOL = 1e-3            # the solver's GMRES relative residual (NewtonSolver.GMRES_RTOL)
COMPONENTS = ("v", "ω", "f", "κ")


class StepSystems:
    """The linear systems GMRES meets in one contact step of ``run``: set up a step of h
    (s), solve it with the run's Newton, recover its iterates (N+1, 12) and, per iterate,
    the scaled operator, preconditioner and right-hand side (n,) as the kernel has them.
    Raises RuntimeError when Newton does not converge at that Δt."""

    def __init__(self, run: RodRun, h: float):
        self.run, self.h = run, h
        self.prob = run.assembly.step_problem(run.state, h, predictor=run.predictor, after=run.last_reject)
        self.guess = run.assembly.begin_solve(run.state, self.prob)
        newton = run.newton
        Y, _, its, _, ok, _ = newton.solve(self.guess)
        if not ok:
            raise RuntimeError(f"Newton failed at t = {run.state.t} s with Δt = {h} s")
        self.iterates = [self.guess.copy()]
        saved = newton.max_iterations
        try:
            for m in range(1, its):
                newton.max_iterations = m
                self._begin()
                newton.solve(self.guess)
                self.iterates.append(newton._state["ws"].Y.copy())
        finally:
            newton.max_iterations = saved
        self._begin()
        st = newton._state
        self.lin, self.op, self.gm = st["lin"], st["op"], st["gm"]
        self.n = self.lin.row_scale.size

    def _begin(self) -> None:
        # the step set up again as the run does, from the start already made
        self.run.assembly.begin_solve(self.run.state, self.prob, self.guess, first=False)

    def at(self, k: int) -> np.ndarray:
        """Set the operator to iterate k's Jacobian (the band LU factored at iterate 0);
        returns its scaled right-hand side (n,)."""
        system, newton = self.run.system, self.run.newton
        st = newton._state
        rod, step, cand, cdata = system.kernel_args()
        Y = self.iterates[k]
        residual_into(Y, True, rod, step, cand, st["ws"].frozen[:0], cdata, system.buf, system.ev)
        if k == 0:
            newton_mod._factor(Y, system.buf, system.ev, self.lin, self.op, rod, step,
                               newton.CONTACT_BAND_WEIGHT, st["ctr"])
        else:
            newton_mod._set_operator(system.buf, system.ev, self.lin, self.op, step,
                                     newton.CONTACT_BAND_WEIGHT, step.af)
        return -system.buf.R * self.lin.row_scale

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """J x (n,), the operator as last set by :meth:`at`."""
        out = np.empty(self.n)
        step = self.run.system.kernel_args()[1]
        newton_mod._matvec(np.ascontiguousarray(x, dtype=float), out, self.lin, self.op,
                           step, self.gm)
        return out

    def precondition(self, x: np.ndarray) -> np.ndarray:
        """M⁻¹ x (n,): the band LU's solve."""
        y = np.array(x, dtype=float)
        block_solve(self.lin.lu, y)
        return y


def gmres(sys_: StepSystems, rhs, U=None, T=None, m: int = 80, P=None):
    """Right-preconditioned GMRES on J M⁻¹ P y = rhs (P the deflation of U, T; identity
    without U; or the callable ``P`` (n,) -> (n,)) from zero to RTOL. Returns (iterations,
    Arnoldi basis V (n, j+1), Hessenberg matrix H (j+1, j))."""
    if P is None and U is not None:
        shift = np.linalg.inv(T) - np.eye(U.shape[1])

        def P(y):
            return y + U @ (shift @ (U.T @ y))
    elif P is None:
        def P(y):
            return y
    beta = np.linalg.norm(rhs)
    V = np.zeros((rhs.size, m + 1))
    H = np.zeros((m + 1, m))
    V[:, 0] = rhs / beta
    for j in range(m):
        w = sys_.matvec(sys_.precondition(P(V[:, j])))
        for _ in range(2):
            c = V[:, :j + 1].T @ w
            H[:j + 1, j] += c
            w -= V[:, :j + 1] @ c
        H[j + 1, j] = np.linalg.norm(w)
        V[:, j + 1] = w / H[j + 1, j]
        e1 = np.zeros(j + 2)
        e1[0] = beta
        y = np.linalg.lstsq(H[:j + 2, :j + 1], e1, rcond=None)[0]
        if np.linalg.norm(e1 - H[:j + 2, :j + 1] @ y) <= RTOL * beta:
            break
    return j + 1, V[:, :j + 2], H[:j + 2, :j + 1]


def _real_basis(vectors: np.ndarray) -> np.ndarray:
    """An orthonormal real basis (n, r) of the span of complex vectors (n, k)."""
    q, r = np.linalg.qr(np.column_stack([vectors.real, vectors.imag]))
    d = np.abs(np.diag(r))
    return q[:, d > 1e-10 * d.max()]


def eigen_basis(sys_: StepSystems, k: int):
    """The k eigenvalues of J M⁻¹ farthest from 1 (ARPACK), an orthonormal basis U of
    their eigenvectors and T = Uᵀ J M⁻¹ U; (values, vectors, U, T, (seconds, operator
    applications))."""
    n = sys_.n
    applied = [0]

    def shifted(x):
        applied[0] += 1
        x = np.real(x).ravel()
        return sys_.matvec(sys_.precondition(x)) - x

    E = LinearOperator((n, n), dtype=float, matvec=shifted)
    t0 = time.perf_counter()
    values, vectors = eigs(E, k=k, which="LM", maxiter=5000, tol=1e-4)
    seconds = time.perf_counter() - t0
    U = _real_basis(vectors)
    return values + 1.0, vectors, U, _projected(sys_, U), (seconds, applied[0])


def _projected(sys_: StepSystems, U: np.ndarray) -> np.ndarray:
    """T = Uᵀ J M⁻¹ U (r, r) at the current operator."""
    return U.T @ np.column_stack([sys_.matvec(sys_.precondition(U[:, j]))
                                  for j in range(U.shape[1])])


def recycled_basis(U, T, V, H, k: int, gap: float):
    """The deflation basis after a GMRES solve on J M⁻¹ P (P from U, T; identity without
    U): its Ritz vectors W = V S with Ritz values more than ``gap`` from 1, merged with U,
    J M⁻¹ on the merged basis from the Arnoldi relation J M⁻¹ P V_j = V_{j+1} H and the
    carried J M⁻¹ U ≈ U T (no operator product), cut to the k directions whose values are
    farthest from 1. Returns (U, T)."""
    j = H.shape[1]
    theta, S = np.linalg.eig(H[:j, :j])
    sel = np.flatnonzero(np.abs(theta - 1.0) > gap)
    if sel.size == 0:
        return U, T
    Sr = _real_basis(S[:, sel])
    W = V[:, :j] @ Sr
    BPW = V @ (H @ Sr)
    if U is None:
        Q, BQ = W, BPW
    else:
        r = U.shape[1]
        BW = BPW - U @ ((np.eye(r) - T) @ (U.T @ W))   # P W = W + U(T⁻¹ − I)UᵀW
        q, rr = np.linalg.qr(np.column_stack([U, W]))
        keep = np.flatnonzero(np.abs(np.diag(rr)) > 1e-8 * np.abs(rr).max())
        Rinv = np.linalg.inv(rr[np.ix_(keep, keep)])
        Q = np.column_stack([U, W])[:, keep] @ Rinv
        BQ = np.column_stack([U @ T, BW])[:, keep] @ Rinv
    Tq = Q.T @ BQ
    if Q.shape[1] > k:
        values, vectors = np.linalg.eig(Tq)
        order = np.argsort(-np.abs(values - 1.0))[:k]
        G = _real_basis(vectors[:, order])[:, :k]
        Q, BQ = Q @ G, BQ @ G
        Tq = Q.T @ BQ
    return Q, Tq


def localisation(sys_: StepSystems, vector: np.ndarray) -> tuple[int, str, int, int]:
    """How many nodes hold 90 % of the eigenvector's state-space direction M⁻¹u (the
    squared norm), which unknown dominates it, and its largest node and the largest at
    least 50 nodes from that one."""
    z = np.abs(sys_.precondition(vector.real) + 1j * sys_.precondition(vector.imag))
    Z = z.reshape(-1, 12)
    weight = (Z ** 2).sum(axis=1)
    per_node = np.sort(weight)[::-1]
    nodes = int(np.searchsorted(per_node.cumsum() / per_node.sum(), 0.9)) + 1
    per_unknown = [(Z[:, 3 * i:3 * i + 3] ** 2).sum() for i in range(4)]
    first = int(np.argmax(weight))
    far = np.abs(np.arange(weight.size) - first) >= 50
    second = int(np.flatnonzero(far)[np.argmax(weight[far])])
    return nodes, COMPONENTS[int(np.argmax(per_unknown))], first, second


#: --coarse: residual rows of a cell (offsets in its 12 rows, E1..E4 at 0, 3, 6, 9) that
#: the coarse space's aggregates cover
COARSE_ROWS = {"E3 lateral": (6, 7), "E3": (6, 7, 8), "E1 and E2": (0, 1, 2, 3, 4, 5)}


def contact_cells(sys_: StepSystems) -> np.ndarray:
    """The cells (m,) int, sorted, next to a node of the operator's contact pairs (the
    exact load product's nodes, 5 per pair)."""
    P = int(sys_.op.pairs[0])
    nodes = np.unique(sys_.op.exact.nodes[:P])
    n_cells = sys_.n // 12 - 1
    return np.unique(np.clip(np.concatenate([nodes - 1, nodes]), 0, n_cells - 1))


def coarse_basis(n: int, cells: np.ndarray, b: int, rows) -> np.ndarray:
    """Orthonormal Q (n, k): per aggregate of b consecutive cells of ``cells`` (the cells
    split where they are not consecutive) and per row offset of ``rows``, the indicator of
    those cells' rows (row 6 + 12c + offset of cell c). cells (m,) int, m ≥ 1; b ≥ 1.
    Raises ValueError for no cells."""
    cols = []
    for run_ in np.split(cells, np.flatnonzero(np.diff(cells) > 1) + 1):
        for a in range(0, run_.size, b):
            for r in rows:
                q = np.zeros(n)
                q[6 + 12 * run_[a:a + b] + r] = 1.0
                cols.append(q)
    return np.linalg.qr(np.column_stack(cols))[0]


def coarse_correction(sys_: StepSystems, Q: np.ndarray):
    """B (a callable (n,) -> (n,)) = I − X(QᵀY)⁻¹Qᵀ with Y = J M⁻¹ Q (k operator
    applications at the current operator) and X = Y − Q (module docstring, item 4).
    Q: (n, k) orthonormal. Raises numpy.linalg.LinAlgError where QᵀY is singular."""
    Y = np.column_stack([sys_.matvec(sys_.precondition(Q[:, j])) for j in range(Q.shape[1])])
    X = Y - Q
    S = np.linalg.inv(Q.T @ Y)
    return lambda y: y - X @ (S @ (Q.T @ y))


def coarse_study(run: RodRun, h: float, sizes=(10, 25, 50)) -> None:
    """Print GMRES's iterations with the coarse corrections of item 4 over one step of h
    (s) and the first iterate of the next (``sizes``: the aggregates' cell counts b).
    Raises RuntimeError as :class:`StepSystems` where Newton fails at h."""
    sys_ = StepSystems(run, h)
    rhs = sys_.at(0)
    cells = contact_cells(sys_)
    print(f"t = {run.state.t:.4f} s, {len(sys_.iterates)} Newton iterates, {cells.size} contact "
          f"cells ({cells.min()}-{cells.max()}); GMRES iterations:", flush=True)
    spaces = {(b, name): coarse_basis(sys_.n, cells, b, rows)
              for name, rows in COARSE_ROWS.items() for b in sizes
              if name == "E3 lateral" or b == 25}
    first = {}
    line = [f"plain {gmres(sys_, rhs)[0]}"]
    for key, Q in spaces.items():
        first[key] = coarse_correction(sys_, Q)
        line.append(f"{key[1]}, b = {key[0]} (k = {Q.shape[1]}): "
                    f"{gmres(sys_, rhs, P=first[key])[0]}")
    print("  iterate 0, B built there: " + "; ".join(line), flush=True)
    for it in range(1, len(sys_.iterates)):
        rhs = sys_.at(it)
        line = [f"plain {gmres(sys_, rhs)[0]}"]
        for key, Q in spaces.items():
            own = gmres(sys_, rhs, P=coarse_correction(sys_, Q))[0]
            stale = gmres(sys_, rhs, P=first[key])[0]
            line.append(f"{key[1]}, b = {key[0]}: {own} / {stale}")
        print(f"  iterate {it}, B built there / at iterate 0: " + "; ".join(line), flush=True)
    att = run.try_step(h)
    nxt = StepSystems(run, h)
    rhs = nxt.at(0)
    line = [f"plain {gmres(nxt, rhs)[0]}"]
    for key, Q in spaces.items():
        Qn = coarse_basis(nxt.n, contact_cells(nxt), key[0], COARSE_ROWS[key[1]])
        line.append(f"{key[1]}, b = {key[0]}: {gmres(nxt, rhs, P=coarse_correction(nxt, Qn))[0]}"
                    f" / {gmres(nxt, rhs, P=first[key])[0]}")
    print(f"  next step ({'accepted' if att.ok else 'refused: ' + str(att.reason)}), iterate "
          "0, B built there / the last step's: " + "; ".join(line), flush=True)


def augmented_matrix(sys_: StepSystems) -> tuple[sparse.csc_matrix, int]:
    """The operator last set (:meth:`StepSystems.at`) as a sparse square matrix of
    n + 6(N+1) unknowns: the scaled unknowns x (n,) and per node k the unscaled pose
    change δφ_k (rad), δr_k (m) at columns n + 6k + (0..2, 3..5). Rows 0..n−1: the band
    cells, the boundary rows and the E3 rows' exact load change (:func:`solver.newton.
    _matvec`) with the pose change as unknowns; rows n + 6k + (0..5): the recurrence of
    :func:`solver.scheme.exact_loads_product` (δφ_0 = A₀ δω_0, δr_0 = ½Δt(δφ_0 × ṙ_0 +
    R_0 δv_0); δφ_k = δφ_{k−1} + C κ̄, δr_k = δr_{k−1} + Δs (δφ_{k−1} + D κ̄) × t_mid with
    κ̄ the mean of δκ over cell k − 1), each minus its left side. Eliminating the pose
    unknowns gives J x back (:func:`augmented_product`); a pair couples only its own five
    nodes. Returns (matrix, n). No seabed terms (raises ValueError where cells touch)."""
    lin, op = sys_.lin, sys_.op
    step = sys_.run.system.kernel_args()[1]
    blocks, bc_scaled, lrw, ex = op.blocks, op.bc_scaled, op.load_row_weight, op.exact
    R, C, D, tmid, rdot, A0, G, L = ex.R, ex.C, ex.D, ex.tmid, ex.rdot, ex.A0, ex.G, ex.L
    nodes, w, Fp, d_dr, d_dv = ex.nodes, ex.weights, ex.force, ex.dF_dr, ex.dF_dv
    dtdr, dwdt, scal = ex.dt_dr, ex.dw_dt, ex.scalars
    if ex.seabed_count[0] > 0:
        raise ValueError("augmented_matrix: seabed cells touch; their terms are not assembled")
    P = int(op.pairs[0]) if op.coupled[0] else 0
    cs = lin.col_scale
    nc = blocks.shape[0]
    n1 = nc + 1
    n = 12 * n1
    h, ds = scal[0], scal[1]
    rows, cols, vals = [], [], []

    def put(r, c, v):
        r, c, v = np.broadcast_arrays(np.asarray(r), np.asarray(c), np.asarray(v, dtype=float))
        rows.append(r.ravel())
        cols.append(c.ravel())
        vals.append(v.ravel())

    def pose(k, a):
        return n + 6 * np.asarray(k)[..., None] + np.asarray(a)

    c_, i_, j_ = np.meshgrid(np.arange(nc), np.arange(12), np.arange(24), indexing="ij")
    put(6 + 12 * c_ + i_, 12 * c_ + j_, blocks)
    bc_rows, bc_cols = step.bc_rows, step.bc_cols
    put(bc_rows, bc_cols, bc_scaled[:bc_rows.shape[0]])
    for e in range(2):
        if step.turning_start if e == 0 else step.turning_end:
            k = 0 if e == 0 else n1 - 1
            ii, jj = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
            put(bc_rows[6 * e + ii], 12 * k + W + jj, bc_scaled[12 + 9 * e + 3 * ii + jj])

    def load_rows(node, col, coef):
        """dB at nodes node (m,) changes by coef (m, 3, q) times the unknowns col (m, q):
        rows E3 of the cells on either side, weighted as the operator weighs them."""
        for c in (node - 1, node):
            ok = (c >= 0) & (c < nc)
            cc = c[ok]
            for i in range(3):
                put((6 + 12 * cc + E3 + i)[:, None], col[ok], lrw[cc, i][:, None] * coef[ok, i])
    k = np.arange(n1)
    # node-local: Rᵀ [G]× δφ − L δ(v, ω)
    load_rows(k, pose(k, np.arange(3)), np.einsum("kmi,kmj->kij", R, skew(G)))
    load_rows(k, 12 * k[:, None] + np.arange(6), -L * cs[:6][None, None, :])
    if P:
        a = nodes[:P]                                             # (P, 5)
        Fm = np.empty((P, 3, 5, 9))
        Fm[..., 0:3] = np.moveaxis(d_dr[:P], 1, 2)
        Fm[..., 3:6] = np.moveaxis(d_dv[:P] @ -skew(rdot[a]), 1, 2)
        Fm[..., 6:9] = np.moveaxis(d_dv[:P] @ R[a], 1, 2) * cs[V:V + 3]
        Tm = np.zeros((P, 5, 9))
        Tm[..., 0:3] = dtdr[:P]
        col = np.concatenate([pose(a, np.arange(3, 6)), pose(a, np.arange(3)),
                              12 * a[..., None] + V + np.arange(3)], axis=-1)   # (P, 5, 9)
        col = col.reshape(P, 45)
        Fm = Fm.reshape(P, 3, 45)
        Tm = Tm.reshape(P, 45)
        for b in range(5):
            # the weights' change as the closest point slides along the partner (∂w/∂t δt)
            slide = (dwdt[:P, b, None] * Fp[:P])[:, :, None] * Tm[:, None, :]
            dG = w[:P, b, None, None] * Fm + slide
            load_rows(a[:, b], col, np.einsum("pmi,pmq->piq", R[a[:, b]], dG))
    # the recurrence rows
    base = n + 6 * k
    put(base[:, None] + np.arange(6), base[:, None] + np.arange(6), 1.0)
    ii, jj = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    put(n + ii, W + jj, -A0[ii, jj] * cs[W + jj])
    put(n + 3 + ii, n + jj, 0.5 * h * skew(rdot[0])[ii, jj])
    put(n + 3 + ii, V + jj, -0.5 * h * R[0][ii, jj] * cs[V + jj])
    kk = np.arange(1, n1)
    c = kk - 1
    St = -skew(tmid[:nc])                                  # s × t = −[t]× s
    SD = St @ D[:nc]
    r3 = 6 * kk[:, None, None] + ii
    put(n + r3, n + 6 * c[:, None, None] + ii, -(ii == jj).astype(float))
    put(n + 3 + r3, n + 6 * c[:, None, None] + 3 + ii, -(ii == jj).astype(float))
    put(n + 3 + r3, n + 6 * c[:, None, None] + jj, -ds * St)
    for node in (kk, c):
        kcol = 12 * node[:, None, None] + K + jj
        put(n + r3, kcol, -0.5 * C[:nc] * cs[K + jj])
        put(n + 3 + r3, kcol, -0.5 * ds * SD * cs[K + jj])
    size = n + 6 * n1
    A = sparse.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(size, size)).tocsc()
    A.sum_duplicates()
    return A, n


def augmented_product(A: sparse.csc_matrix, n: int, x: np.ndarray) -> np.ndarray:
    """J x (n,) for x (n,) from the augmented matrix of :func:`augmented_matrix`: the pose
    unknowns solved from their recurrence rows (SuperLU; RuntimeError where that block is
    singular), then the first n rows."""
    z = splu(A[n:, n:].tocsc()).solve(-(A[n:, :n] @ x))
    return A[:n, :n] @ x + A[:n, n:] @ z


class _AugmentedPreconditioner:
    """GMRES's operator with the augmented matrix's LU as its preconditioner."""

    def __init__(self, sys_: StepSystems, lu, n: int):
        self.sys_, self.lu, self.n = sys_, lu, n

    def matvec(self, x):
        return self.sys_.matvec(x)

    def precondition(self, x):
        b = np.zeros(self.lu.shape[0])
        b[:self.n] = x
        return self.lu.solve(b)[:self.n]


def _other_factorisations(sys_: StepSystems, A: sparse.csc_matrix, n: int, rhs) -> str:
    """The first iterate's extra line of :func:`augmented_study`."""
    parts = []
    lu = splu(A, permc_spec="MMD_ATA")
    t = _median_ms(lambda: splu(A, permc_spec="MMD_ATA"), 3)
    parts.append(f"SuperLU with MMD_ATA {t:.1f} ms (LU {lu.L.nnz + lu.U.nnz})")
    scale = 1.0 / np.maximum(abs(A).max(axis=1).toarray().ravel(), 1e-300)
    As = (sparse.diags(scale) @ A).tocsc()

    class _Scaled(_AugmentedPreconditioner):
        def precondition(self, x):
            return super().precondition(x * scale[:self.n])
    for drop in (1e-3, 1e-4):
        def factor():
            return spilu(As, drop_tol=drop, fill_factor=4, permc_spec="COLAMD")
        ilu = factor()
        t = _median_ms(factor, 3)
        its = gmres(_Scaled(sys_, ilu, n), rhs, m=120)[0]
        parts.append(f"ILU drop {drop:g}: {its} GMRES iterations (of at most 120), "
                     f"{t:.1f} ms (LU {ilu.L.nnz + ilu.U.nnz})")
    return "; ".join(parts)


def _band_factorisation_ms(sys_: StepSystems) -> float:
    """The median time (ms) of :func:`solver.newton._factor` at the step's first iterate,
    which :meth:`StepSystems.at` (0) has just evaluated and factorised: refactoring it
    there leaves the operator and the LU as they were."""
    system, newton = sys_.run.system, sys_.run.newton
    st = newton._state
    rod, step, cand, cdata = system.kernel_args()
    Y = sys_.iterates[0]
    return _median_ms(lambda: newton_mod._factor(Y, system.buf, system.ev, sys_.lin, sys_.op,
                                                 rod, step, newton.CONTACT_BAND_WEIGHT,
                                                 st["ctr"]), 9)


def augmented_study(run: RodRun, h: float, steps: int) -> None:
    """Print item 5 of the module docstring over ``steps`` steps of h (s). Raises
    RuntimeError as :class:`StepSystems` where Newton fails at h."""
    last = None
    for _ in range(steps):
        sys_ = StepSystems(run, h)
        print(f"t = {run.state.t:.4f} s, {int(sys_.op.pairs[0])} pairs, {len(sys_.iterates)} Newton "
              "iterates; GMRES iterations plain / augmented LU fresh / of the step's start "
              "(at iterate 0: of the last step's start)", flush=True)
        start = None
        for it in range(len(sys_.iterates)):
            rhs = sys_.at(it)
            A, n = augmented_matrix(sys_)
            lu = splu(A, permc_spec="COLAMD")
            t_lu = _median_ms(lambda: splu(A, permc_spec="COLAMD"), 3)
            b = np.zeros(A.shape[0])
            b[:n] = rhs
            t_solve = _median_ms(lambda: lu.solve(b), 5)
            t_band = _median_ms(lambda: sys_.precondition(rhs), 5)
            stale = last if it == 0 else start
            counts = [gmres(sys_, rhs)[0], gmres(_AugmentedPreconditioner(sys_, lu, n), rhs)[0],
                      gmres(_AugmentedPreconditioner(sys_, stale, n), rhs)[0]
                      if stale is not None else "–"]
            print(f"  iterate {it}: {' / '.join(str(c) for c in counts)}; {A.shape[0]} "
                  f"unknowns, {A.nnz} nonzeros, LU {lu.L.nnz + lu.U.nnz}; SuperLU "
                  f"{t_lu:.1f} ms, its solve {t_solve:.2f} ms, the band LU's solve "
                  f"{t_band:.2f} ms", flush=True)
            if it == 0:
                start = lu
                print(f"    the band factorisation at this iterate (equilibration, operator "
                      f"and LU, as Newton makes it): {_band_factorisation_ms(sys_):.2f} ms",
                      flush=True)
                if last is None:
                    print("    " + _other_factorisations(sys_, A, n, rhs), flush=True)
        last = start
        att = run.try_step(h)
        if not att.ok:
            print(f"  (the step was refused: {att.reason}; the next one starts from the same "
                  "state)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", type=Path, default=TENSION)
    ap.add_argument("--at", type=float, default=21.0)
    ap.add_argument("--dt", type=float, default=0.003)
    ap.add_argument("--k", type=int, default=12)
    ap.add_argument("--steps", type=int, default=3)
    ap.add_argument("--gap", type=float, default=0.3)
    ap.add_argument("--coarse", action="store_true",
                    help="item 4 of the docstring instead of items 1-3")
    ap.add_argument("--augmented", action="store_true",
                    help="item 5 of the docstring instead of items 1-3")
    args = ap.parse_args()
    case = Case.from_file(args.case)
    with threadpool_limits(limits=1, user_api="blas"):
        run = RodRun(case)
        t0 = time.perf_counter()
        _advance_to(run, args.at, case.numerics.dt, 0)
        print(f"{case.name} to {run.state.t:g} s in {time.perf_counter() - t0:.0f} s; contact "
              f"steps of {args.dt} s from there", flush=True)
        if args.coarse:
            coarse_study(run, args.dt)
            return
        if args.augmented:
            augmented_study(run, args.dt, args.steps)
            return
        previous_start = None
        totals = [0, 0]
        for s in range(args.steps + 1):
            sys_ = StepSystems(run, args.dt)
            runs = sys_.prob.candidates.runs if sys_.prob.candidates is not None else 0
            rhs = sys_.at(0)
            values, vectors, U0, T0, (secs, applied) = eigen_basis(sys_, args.k)
            order = np.argsort(-np.abs(values - 1.0))
            if s == 0:
                print(f"eigenvalues λ of J M⁻¹ farthest from 1 at the start ({runs} "
                      f"candidate runs; {args.k} found in {secs:.3f} s, {applied} operator "
                      "applications):")
                for i in order:
                    nodes, unknown, a, b = localisation(sys_, vectors[:, i])
                    print(f"  |λ − 1| = {abs(values[i] - 1.0):8.3f}   90 % on {nodes:4d} "
                          f"nodes, mostly {unknown}; peaks at nodes {a} and {b}")
            cells = []
            own, before = (U0, T0), None
            Ur = Tr = None
            for k in range(len(sys_.iterates)):
                if k:
                    rhs = sys_.at(k)
                    values_k, _, Uk, Tk, _ = eigen_basis(sys_, args.k)
                    own = (Uk, Tk)
                plain, V, H = gmres(sys_, rhs)
                cell = [plain, gmres(sys_, rhs, *own)[0]]
                cell.append(gmres(sys_, rhs, before[0], _projected(sys_, before[0]))[0]
                            if before is not None else None)
                cell.append(gmres(sys_, rhs, U0, _projected(sys_, U0))[0] if k else None)
                cell.append(gmres(sys_, rhs, previous_start, _projected(sys_, previous_start))[0]
                            if previous_start is not None and k == 0 else None)
                its_r, Vr, Hr = gmres(sys_, rhs, Ur, Tr)
                cell.append(its_r)
                Ur, Tr = recycled_basis(Ur, Tr, Vr, Hr, args.k, args.gap)
                before = own
                cells.append(cell)
            print(f"step at t = {run.state.t:.4f} s, {len(sys_.iterates)} Newton iterates; GMRES "
                  "iterations per iterate: plain / deflated by U of (a) the iterate, (b) the "
                  "iterate before, (c) the step's start, (d) the step before's start / (e) "
                  "recycled Ritz vectors")
            for k, c in enumerate(cells):
                txt = " / ".join("–" if x is None else str(x) for x in c)
                print(f"  iterate {k}: {txt}")
            tot = [sum(c[i] or 0 for c in cells) for i in (0, 5)]
            totals[0] += tot[0]
            totals[1] += tot[1]
            print(f"  step: plain {tot[0]}, recycled {tot[1]}", flush=True)
            previous_start = U0
            att = run.try_step(args.dt)
            if not att.ok:
                print(f"  (the step was refused: {att.reason}; the next one starts from the "
                      "same state)")
        print(f"all {args.steps + 1} steps: GMRES iterations plain {totals[0]}, with recycled "
              f"Ritz vectors {totals[1]} ({100.0 * (totals[1] / totals[0] - 1.0):+.0f} %)")


if __name__ == "__main__":
    main()
