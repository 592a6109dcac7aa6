"""Newton's method for one time step: iteration, safeguards and the linear solver.

The difference equations of a step (:class:`solver.scheme.RodSystem`) are solved for all
12(N+1) unknowns at once. The whole iteration of a step is one compiled kernel
(:func:`_newton_kernel`): residual and Jacobian (:func:`solver.scheme.residual_into`,
contact included), equilibration, the Jacobian's LU, GMRES with the exact operator, the
feasibility filter and the line search, with no Python between them (measured: a
Newton iteration of PyElastica's plectoneme at N = 20 made ~840 Python-level calls,
docs/contact.md § 4). The strategy, in one place:

* **Jacobian and factorisation.** The analytic Jacobian, almost block diagonal (a band,
  kl = ku = 17), LU-factorised by node windows (:mod:`solver.banded`), equilibrated by a
  column scale (characteristic
  size of each unknown) and a row scale (size of the terms of each row). Without contact
  the LU is reused across iterations and steps (chord) while the step size, the scheme's
  weights and the boundary rows are unchanged, and refactored when the residual falls
  by less than 4× in an iteration.
* **Self-contact.** The pose is the space route (:meth:`RodSystem.pose_new`), so the
  contact forces depend on κ upstream of each node: the exact Jacobian is not banded.
  GMRES (right-preconditioned, Saad & Schultz 1986) solves with the exact operator
  applied matrix-free (:func:`solver.scheme.exact_loads_product`), preconditioned by the
  band LU of the node-local (time-route) approximation without its contact blocks
  (``CONTACT_BAND_WEIGHT`` = 0: the rod's own band Jacobian). That LU is kept across
  iterates while GMRES converges in at most ``GMRES_REFACTOR`` iterations and refactored
  when it needs more: about one factorisation per contact step (docs/contact.md).
* **Feasible iterates.** A correction may close no candidate gap to less than
  ``GAP_KEEP`` of itself (halving; an IPC-like filter), then an Armijo backtracking on
  the scaled residual, whose evaluation with its Jacobian is reused as the next iterate.
  Where the last correction passed the filter whole, the next one is first evaluated
  whole and its gaps read off that evaluation, which is then the line search's first
  trial (no separate gap evaluation for the filter).
* **Converged contact steps.** The scaled residual below the tolerance, or (contact
  steps) the iterate's position error estimated from the contraction of its last two
  corrections (Hairer & Wanner) below ``CONTACT_POSITION_FRACTION`` of the step's
  position bound (``contact.position_tolerance``) with the residual below √10·√tolerance:
  the route rule allows each step a position error up to that bound, so iterating
  further only polishes digits the step does not have (one iteration fewer in most
  contact steps of the seed example; its positions within ~3e-7 m of the fully
  converged iterate's).
* **Sea floor.** With a seabed (:mod:`solver.seabed`) and no strands near (no contact
  candidates), every
  correction is backtracked (Armijo on the scaled residual) and the Jacobian refactored
  after a cut one: the contact law's kink at zero penetration made full steps cycle.
  With self-contact configured the pose is the space route, so a touching cell's seabed
  load depends on κ upstream too: the operator is then the band plus the exact product
  (its seabed part, :func:`solver.scheme.exact_loads_product`) whenever a cell touches,
  and GMRES solves with it as in a contact step. The
  damper's clamp is held on one branch per cell through the iterations and re-decided
  near their solution, until the law's own residual passes (an active-set strategy,
  :class:`solver.seabed.SeabedContact`): its bounds swapping between iterates made Newton cycle
  while the cable settles onto the bottom.
* **Fail fast.** A contact step that halves its residual less than once in four
  iterations, whose corrections are cut to 1/64 three times, or whose GMRES does not
  converge even with a fresh factorisation, fails at once: the step control
  (:mod:`solver.stepping.control`) cuts Δt.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from .banded import (NV, block_factor, block_solve, block_storage, copy_into, fill,
                     true_at_run_time)
from .contact.model import candidate_gaps_into
from .kernel_data import (EXACT_PAIR_FIELDS, BandFactor, ExactProduct, GmresWork, LinearSolve,
                          NewtonCounters, NewtonParams, NewtonWork, Operator)
from .scheme import E3, E4, W, exact_loads_product, pose_into, residual_into

__all__ = ["NewtonSolver", "equilibrate", "scale_blocks", "FAILURES"]

#: why a solve failed, by the kernel's code: None (converged, or iterations exhausted),
#: a singular Jacobian, a stall, GMRES failing with a fresh factorisation, a non-finite
#: residual
FAILURES = (None, "singular", "stalled", "gmres", None)
_SINGULAR, _STALLED, _GMRES, _NONFINITE = 1, 2, 3, 4


def equilibrate(system, Y, blocks):
    """Row and column scales of the step's Jacobian at the iterate Y (N+1, 12).

    Columns: the characteristic size of each kind of unknown (``RodSystem.column_scale``,
    (12,) per node); rows: 1 / Σ_j |J_ij| s_j over the row's entries (cell blocks
    (N, 12, 24) and the boundary rows), 1 where a row is empty. Returns
    (row_scale (n,), s12 (12,)). docs/numerics.md § 3 ("Scaling"). The same scales as
    the compiled :func:`_equilibrate`, which Newton uses.
    """
    rs = np.empty(system.n)
    s12 = np.empty(NV)
    bc = system.step.bc
    _equilibrate(np.ascontiguousarray(Y, dtype=float), np.ascontiguousarray(blocks), bc.rows,
                 bc.cols, bc.coef.astype(float), system.floor, rs, s12)
    return rs, s12


@numba.njit(cache=True)
def _equilibrate(Y, blocks, bc_rows, bc_cols, bc_coef, floor, rs, s12):
    """The scales of :func:`equilibrate` into rs (n,) and s12 (12,)."""
    for kind in range(4):
        m = 0.0
        for k in range(Y.shape[0]):
            for c in range(3):
                a = abs(Y[k, 3 * kind + c])
                if a > m:
                    m = a
        for c in range(3):
            s12[3 * kind + c] = max(m, floor[3 * kind + c])
    for c in range(blocks.shape[0]):
        for i in range(NV):
            acc = 0.0
            for j in range(2 * NV):
                acc += abs(blocks[c, i, j]) * s12[j % NV]
            rs[6 + NV * c + i] = 1.0 / acc if acc > 0.0 else 1.0
    for m in range(bc_rows.shape[0]):
        v = abs(bc_coef[m]) * s12[bc_cols[m] % NV]
        rs[bc_rows[m]] = 1.0 / v if v > 0.0 else 1.0


@numba.njit(cache=True)
def _scale_blocks_kernel(blocks, row_scale, s12, out):
    """out[c, i, j] = blocks[c, i, j] · (r_{6 + 12c + i} s_{j mod 12}) for cell blocks
    (N, 12, 24): the product of :func:`scale_blocks` in one pass."""
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
    bc_rows, bc_cols, bc_vals = system.step.bc.jacobian_entries()
    scaled = np.empty_like(blocks)
    _scale_blocks_kernel(np.ascontiguousarray(blocks), row_scale, np.ascontiguousarray(s12),
                         scaled)
    return scaled, bc_vals * row_scale[bc_rows] * s12[bc_cols % NV]


@numba.njit(cache=True)
def _matvec_kernel(blocks, x, load_weight, dB, out):
    """The cell rows of a scaled Jacobian-vector product into out (n,): cell c's rows
    6 + 12c + i are blocks[c] (12, 24) times x on nodes (c, c + 1); with loads (dB
    (N+1, 3) non-empty) its E3 rows also get load_weight[c] (N, 3) times dB_c + dB_{c+1}
    (the cell average of a node load). One pass, no (N, 12) temporaries. The boundary
    rows are left to the caller."""
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


# ----------------------------------------------------------------------------- kernels
# The persistent state of a Newton object, as the kernels take it (allocated by
# NewtonSolver._allocate), is named tuples of solver.kernel_data: lin (LinearSolve),
# op (Operator, its exact product an ExactProduct), gm (GmresWork), ws (NewtonWork),
# ctr (NewtonCounters); prm (NewtonParams) the controls of a solve.


def _product_tail(n1, nc, ds):
    """The :class:`ExactProduct` fields from ``scalars`` on, zero: the scalars (Δt, Δs,
    αf), scratch dφ, dr, dG (N+1, 3) and the seabed's linearisation (cells (N,) int,
    count (1,) int, partials (N, 6, 12), loads (N, 6), R ω (N+1, 3), ½Δt R J_r(θ)
    (N+1, 3, 3)), as a dict by field."""
    return dict(scalars=np.array([0.0, float(ds), 0.0]), dphi=np.zeros((n1, 3)),
                dr=np.zeros((n1, 3)), dG=np.zeros((n1, 3)),
                seabed_cells=np.zeros(nc, np.int64), seabed_count=np.zeros(1, np.int64),
                seabed_partials=np.zeros((nc, 6, 12)), seabed_loads=np.zeros((nc, 6)),
                Romega=np.zeros((n1, 3)), Aphi=np.zeros((n1, 3, 3)))


@numba.njit(cache=True)
def _set_operator(buf, ev, lin, op, step, weight, af):
    """The (scaled) Jacobian at the last residual evaluation with its Jacobian as GMRES's
    operator: its band part in the scales of the last factorisation, with only
    ``weight`` of the node-local contact blocks (the rest moves to the exact load
    product's node-local term L, so band + exact product is still the Jacobian; the
    row scale stays that of the full blocks), and the exact product's data."""
    rs, s12 = lin.row_scale, lin.s12
    blocks, bc_scaled, lrw, ex = op.blocks, op.bc_scaled, op.load_row_weight, op.exact
    _scale_blocks_kernel(buf.blocks, rs, s12, blocks)
    bc_rows, bc_cols, bc_coef = step.bc_rows, step.bc_cols, step.bc_coef
    for m in range(bc_rows.shape[0]):
        bc_scaled[m] = bc_coef[m] * rs[bc_rows[m]] * s12[bc_cols[m] % NV]
    for e in range(2):
        # a towed end free to turn: its translation rows' block on ω (buf.bc_jac); 0 else
        turning = step.turning_start if e == 0 else step.turning_end
        for i in range(3):
            for j in range(3):
                bc_scaled[12 + 9 * e + 3 * i + j] = (
                    buf.bc_jac[e, i, j] * rs[bc_rows[6 * e + i]] * s12[W + j] if turning
                    else 0.0)
    nc = blocks.shape[0]
    for c in range(nc):
        for i in range(3):
            lrw[c, i] = 0.5 * (1.0 - af) * rs[6 + NV * c + E3 + i]
    bflags = buf.flags
    if bflags[3] == 0:
        op.coupled[0] = 0
        op.pairs[0] = 0
        return
    P = bflags[1]
    nodes, w, Fp, d_dr, d_dv = ex.nodes, ex.weights, ex.force, ex.dF_dr, ex.dF_dv
    dtdr, dwdt, L = ex.dt_dr, ex.dw_dt, ex.L
    sbc, sbj, sbl = ex.seabed_cells, ex.seabed_partials, ex.seabed_loads
    copy_into(ex.R, buf.Rm)
    copy_into(ex.C, buf.C)
    copy_into(ex.D, buf.D)
    copy_into(ex.tmid, buf.tmid)
    copy_into(ex.rdot, buf.rdot)
    copy_into(ex.A0, buf.A0)
    copy_into(ex.G, buf.G)
    copy_into(L, buf.L)
    ex.scalars[0] = step.dt
    ex.scalars[2] = af
    # the seabed's linearisation (solver.seabed.seabed_into's ``lin``), its cells only
    nsb = buf.seabed_count[0]
    ex.seabed_count[0] = nsb
    for j in range(nsb):
        c = buf.seabed_cells[j]
        sbc[j] = c
        for i in range(6):
            sbl[c, i] = buf.seabed_loads[c, i]
            for m in range(12):
                sbj[c, i, m] = buf.seabed_partials[c, i, m]
    if nsb > 0:
        copy_into(ex.Romega, buf.Romega)
        copy_into(ex.Aphi, buf.Aphi)
    for p in range(P):
        for b in range(5):
            nodes[p, b] = ev.nodes[p, b]
            w[p, b] = ev.weights[p, b]
            dwdt[p, b] = ev.dw_dt[p, b]
            for i in range(3):
                dtdr[p, b, i] = ev.dt_dr[p, b, i]
                for j in range(3):
                    d_dr[p, b, i, j] = ev.dF_dr[p, b, i, j]
                    d_dv[p, b, i, j] = ev.dF_dv[p, b, i, j]
        for i in range(3):
            Fp[p, i] = ev.force[p, i]
    if P > 0 and weight != 1.0:
        diag = buf.diag
        cut = 1.0 - weight
        for c in range(nc):
            for i in range(3):
                row = cut * lrw[c, i]
                for j in range(6):
                    blocks[c, E3 + i, j] -= row * diag[c, i, j] * s12[j]
                    blocks[c, E3 + i, NV + j] -= row * diag[c + 1, i, j] * s12[j]
        for k in range(L.shape[0]):
            for i in range(3):
                for j in range(6):
                    L[k, i, j] -= cut * diag[k, i, j]
    op.coupled[0] = 1
    op.pairs[0] = P


@numba.njit(cache=True)
def _factor(Y, buf, ev, lin, op, rod, step, weight, ctr):
    """Scale, assemble and LU-factorise the Jacobian whose cell blocks the last residual
    evaluation left in buf at the iterate Y (:func:`equilibrate`), and make it (with the
    exact load data) GMRES's operator. Returns False for a singular Jacobian."""
    lu, rs, s12, cs = lin.lu, lin.row_scale, lin.s12, lin.col_scale
    _equilibrate(Y, buf.blocks, step.bc_rows, step.bc_cols, step.bc_coef, rod.floor, rs, s12)
    n1 = Y.shape[0]
    for k in range(n1):
        for j in range(NV):
            cs[NV * k + j] = s12[j]
    _set_operator(buf, ev, lin, op, step, weight, step.af)
    if step.turning_start or step.turning_end:
        rows, cols = _turning_entries(step, n1)
        if block_factor(op.blocks, rows, cols, op.bc_scaled, lu) != 0:
            return False
    elif block_factor(op.blocks, step.bc_rows, step.bc_cols, op.bc_scaled, lu) != 0:
        return False
    ctr.factorizations[0] += 1
    ctr.factor_valid[0] = 1
    return True


@numba.njit(cache=True)
def _matvec(x, out, lin, op, step, gm):
    """The scaled Jacobian times x (n,) into out (n,): band cells and boundary rows of
    the operator, plus (self-contact configured) the exact load terms of the space-route
    pose in place of their node-local part (:func:`solver.scheme.exact_loads_product`)."""
    blocks, bc_scaled, lrw, ex = op.blocks, op.bc_scaled, op.load_row_weight, op.exact
    cs = lin.col_scale
    if op.coupled[0]:
        dY, dB, dS = gm.dY, gm.dB, gm.dS
        n1 = dY.shape[0]
        for k in range(n1):
            for j in range(NV):
                dY[k, j] = x[NV * k + j] * cs[NV * k + j]
        exact_loads_product(dY, ex, op.pairs[0], dB, dS)
        _matvec_kernel(blocks, x, lrw, dB, out)
        rs = lin.row_scale
        sbc = ex.seabed_cells
        for j in range(ex.seabed_count[0]):
            c = sbc[j]
            base = 6 + NV * c
            for i in range(3):
                out[base + E3 + i] += rs[base + E3 + i] * dS[c, i]
                out[base + E4 + i] += rs[base + E4 + i] * dS[c, 3 + i]
    else:
        _matvec_kernel(blocks, x, lrw[:0], gm.dB[:0], out)
    bc_rows, bc_cols = step.bc_rows, step.bc_cols
    for m in range(bc_rows.shape[0]):
        out[bc_rows[m]] = bc_scaled[m] * x[bc_cols[m]]
    for e in range(2):
        if step.turning_start if e == 0 else step.turning_end:
            k = 0 if e == 0 else x.shape[0] // NV - 1
            for i in range(3):
                for j in range(3):
                    out[bc_rows[6 * e + i]] += bc_scaled[12 + 9 * e + 3 * i + j] * x[NV * k + W + j]


@numba.njit(cache=True)
def _turning_entries(step, n1):
    """The boundary entries' rows and columns (30,) with a towed end free to turn: the 12
    of the step's rows, then per end e (s = 0, s = L) the 9 of its translation rows on
    its ω columns (the operator's bc_scaled[12 + 9e + 3i + j], 0 for an end that is not
    turning: :func:`_set_operator`)."""
    rows = np.empty(30, np.intp)
    cols = np.empty(30, np.intp)
    for m in range(12):
        rows[m] = step.bc_rows[m]
        cols[m] = step.bc_cols[m]
    for e in range(2):
        k = 0 if e == 0 else n1 - 1
        for i in range(3):
            for j in range(3):
                m = 12 + 9 * e + 3 * i + j
                rows[m] = step.bc_rows[6 * e + i]
                cols[m] = NV * k + W + j
    return rows, cols


@numba.njit(cache=True, fastmath={"reassoc", "contract"})
def _dot(a, b):
    """a · b for (n,) arrays. Reassociation allowed (only here) so that the sum is
    vectorised: a single accumulator waits on each addition's latency (9.9 against 2.0 µs
    at n = 12,012; GMRES's Gram-Schmidt takes ~100 of these per solve at the seed
    example's 1000 segments). No NaN or infinity assumptions: a non-finite
    product still propagates."""
    acc = 0.0
    for i in range(a.shape[0]):
        acc += a[i] * b[i]
    return acc


@numba.njit(cache=True)
def _gmres(rhs, out, rtol, m, lin, op, step, gm, ctr):
    """Solve the contact-coupled (scaled) system by right-preconditioned GMRES into out.

    The operator is :func:`_matvec` (the exact Jacobian); the preconditioner the band LU
    of the node-local approximation, possibly from an earlier iterate. Arnoldi with
    classical Gram-Schmidt and one reorthogonalisation (two products with the basis per
    iteration); the Hessenberg matrix is reduced by Givens rotations as it grows, so the
    least-squares residual is known at every iteration without solving for it (Saad &
    Schultz 1986, § 3). Stops at a relative residual rtol (an inexact Newton step;
    Newton's own test is on the nonlinear residual; 1e-3 against 1e-4, replayed from the
    seed's states at 18 and 32 s over 3 s each: Newton iterations 547 / 568 and
    144 / 143, GMRES iterations −21 % and −18 %; 1e-2 took 15-20 % more Newton
    iterations). Counts its iterations and failures (m iterations without reaching
    rtol) in ctr. Source: Saad & Schultz, SIAM J. Sci. Stat. Comput. 7 (1986) 856-869.
    Returns the number of iterations."""
    lu = lin.lu
    V, Z, H, cs, sn, g = gm.V, gm.Z, gm.H, gm.cs, gm.sn, gm.g
    w, x0, r = gm.w, gm.x0, gm.r
    n = rhs.shape[0]
    for i in range(n):
        x0[i] = rhs[i]
    block_solve(lu, x0)
    _matvec(x0, r, lin, op, step, gm)
    for i in range(n):
        r[i] = rhs[i] - r[i]
    bnorm = math.sqrt(_dot(rhs, rhs))
    beta = math.sqrt(_dot(r, r))
    if beta <= rtol * bnorm or beta == 0.0:
        copy_into(out, x0)
        return 0
    fill(H, 0.0)
    fill(g, 0.0)
    g[0] = beta
    hb = np.empty(m + 1)
    for i in range(n):
        V[0, i] = r[i] / beta
    k = 0
    converged = False
    for k in range(m):
        Zk = Z[k]
        copy_into(Zk, V[k])
        block_solve(lu, Zk)
        _matvec(Zk, w, lin, op, step, gm)
        # classical Gram-Schmidt and one reorthogonalisation
        for _ in range(2):
            for i in range(k + 1):
                hb[i] = _dot(V[i], w)
            for i in range(k + 1):
                hi = hb[i]
                Vi = V[i]
                for j in range(n):
                    w[j] -= hi * Vi[j]
                H[i, k] += hi
        hnext = math.sqrt(_dot(w, w))
        # apply the earlier rotations to the new column, then annihilate H[k+1, k]
        for i in range(k):
            a = H[i, k]
            b = H[i + 1, k]
            H[i, k] = cs[i] * a + sn[i] * b
            H[i + 1, k] = -sn[i] * a + cs[i] * b
        a = H[k, k]
        rho = math.hypot(a, hnext)
        if rho == 0.0:
            cs[k] = 1.0
            sn[k] = 0.0
        else:
            cs[k] = a / rho
            sn[k] = hnext / rho
        H[k, k] = rho
        g[k + 1] = -sn[k] * g[k]
        g[k] = cs[k] * g[k]
        if abs(g[k + 1]) <= rtol * bnorm or hnext <= 1e-14 * beta:
            converged = True
            break
        for i in range(n):
            V[k + 1, i] = w[i] / hnext
    if not converged:
        ctr.gmres_failures[0] += 1
    kk = k + 1
    ctr.gmres_iterations[0] += kk
    y = _back_substitute(H, g, kk)
    for i in range(n):
        acc = x0[i]
        for j in range(kk):
            acc += y[j] * Z[j, i]
        out[i] = acc
    return kk


@numba.njit(cache=True)
def _back_substitute(H, g, k):
    """y (k,) with T y = g[:k] for the upper triangle T of H[:k, :k] (GMRES's rotated
    Hessenberg matrix). A zero pivot (a breakdown: the Krylov space holds the solution
    already) leaves its component at zero."""
    y = np.empty(k)
    for i in range(k - 1, -1, -1):
        acc = g[i]
        for j in range(i + 1, k):
            acc -= H[i, j] * y[j]
        y[i] = acc / H[i, i] if H[i, i] != 0.0 else 0.0
    return y


@numba.njit(cache=True)
def _norm_scaled(R, rs):
    """‖R ∘ rs‖₂ (inf or NaN where the product has one)."""
    acc = 0.0
    for i in range(R.shape[0]):
        x = R[i] * rs[i]
        acc += x * x
    return math.sqrt(acc)


@numba.njit(cache=True)
def _max_scaled(R, rs):
    """max_i |R_i| rs_i."""
    m = 0.0
    for i in range(R.shape[0]):
        x = abs(R[i]) * rs[i]
        if x > m or x != x:
            m = x
    return m


@numba.njit(cache=True)
def _trial_gaps(Yt, step, rod, cand, cdata, ws, out):
    """The candidate gaps (R,) at the trial iterate Yt (:meth:`RodSystem.candidate_gaps`):
    its space-route positions, −inf everywhere when they are not finite."""
    q, Rm, r, th = ws.q, ws.Rm, ws.r, ws.theta
    yes = true_at_run_time(Yt)
    pose_into(Yt, step.Y_old, step.dt, yes, step.q_old, step.r_old, step.vg_old, yes, rod.ds,
              q, Rm, r, th, ws.vg)
    for k in range(r.shape[0]):
        for c in range(3):
            if not np.isfinite(r[k, c]):
                fill(out, -np.inf)
                return
    candidate_gaps_into(r, cand, cdata, out)


@numba.njit(cache=True)
def _current_gaps(buf, ev, fresh, cand, cdata, g0):
    """The candidate gaps (R,) at the current iterate, into g0, for the feasibility
    filter: the last residual evaluation's positions (buf.r); ``fresh``: that evaluation
    selected afresh, so its per-run gaps (ev.run_gap) are these gaps and are not computed
    again (0.6 of a contact Newton iteration's ~8 ms at the seed example's 1000
    segments). Returns False where the filter does not apply (positions not finite, a
    gap NaN or −inf): every correction is then feasible."""
    nr = g0.shape[0]
    r = buf.r
    for k in range(r.shape[0]):
        for c in range(3):
            if not np.isfinite(r[k, c]):
                return False
    if fresh:
        run_gap = ev.run_gap
        for q in range(nr):
            g0[q] = run_gap[q]
    else:
        candidate_gaps_into(r, cand, cdata, g0)
    for q in range(nr):
        if np.isnan(g0[q]) or g0[q] == -np.inf:
            return False
    return True


@numba.njit(cache=True)
def _gaps_kept(g0, g1, gap_keep):
    """Whether no candidate gap g1 (R,) of a trial closes to less than gap_keep of its
    current value g0 (R,) (an open gap), or below twice a current penetration."""
    for q in range(g0.shape[0]):
        if np.isnan(g1[q]):
            return False
        if np.isfinite(g0[q]):
            floor = gap_keep * g0[q] if g0[q] > 0.0 else 2.0 * g0[q]
            if not g1[q] >= floor:
                return False
    return True


@numba.njit(cache=True)
def _feasible_fraction(Y, delta, g0, gap_keep, alpha, step, rod, cand, cdata, ws):
    """Largest fraction alpha·2^−k (k ≤ 10) of a Newton correction delta (N+1, 12) that
    keeps every candidate gap at least gap_keep of its current value g0 (R,)
    (:func:`_gaps_kept`; a filter in the manner of IPC's CCD-bounded line search: Li et
    al., ACM TOG 39(4), 2020, §4); delta is scaled by it in place. Gaps are the
    closest-point gaps of the step's candidates re-selected at each trial, so a
    correction cannot carry a strand through one it was not pressed against. alpha: the
    first fraction tried (1, or ½ where the whole correction is known to fail)."""
    Yt, g1 = ws.Y_trial, ws.gaps1[:g0.shape[0]]
    for _ in range(10):
        for k in range(Y.shape[0]):
            for j in range(NV):
                Yt[k, j] = Y[k, j] + alpha * delta[k, j]
        _trial_gaps(Yt, step, rod, cand, cdata, ws, g1)
        if _gaps_kept(g0, g1, gap_keep):
            break
        alpha *= 0.5
    if alpha != 1.0:
        for k in range(Y.shape[0]):
            for j in range(NV):
                delta[k, j] *= alpha
    return alpha


@numba.njit(cache=True)
def _feasible_start(Y_old, guess, step, rod, cand, cdata, ws, out, keep):
    """A Newton start whose contact gaps are open, into out (N+1, 12): the
    zero-displacement state (v, ω) = −(v^n, ω^n) keeps every node where it is (the
    trapezoidal position update), and the start is blended from it toward ``guess`` by
    the largest 2^−k (k ≤ 7) that keeps every candidate gap at least ``keep``
    (NewtonSolver.START_GAP_KEEP) of its old value (else the zero-displacement state). Why:
    the replay of the seed example's first contact, where an extrapolated start
    penetrated and Newton died at the barrier (docs/contact.md § 2). Returns the blend
    factor."""
    nr = cand.run_start.shape[0]
    g_old, g = ws.gaps0[:nr], ws.gaps1[:nr]
    n1 = Y_old.shape[0]
    still = ws.Y_trial
    copy_into(still, Y_old)
    for k in range(n1):
        for j in range(6):
            still[k, j] = -Y_old[k, j]
    _trial_gaps(still, step, rod, cand, cdata, ws, g_old)
    beta = 1.0
    for _ in range(8):
        for k in range(n1):
            for j in range(NV):
                out[k, j] = still[k, j] + beta * (guess[k, j] - still[k, j])
        _trial_gaps(out, step, rod, cand, cdata, ws, g)
        ok = True
        for q in range(nr):
            if np.isfinite(g_old[q]) and not g[q] >= keep * max(g_old[q], 0.0):
                ok = False
                break
        if ok:
            return beta
        beta *= 0.5
    copy_into(out, still)
    return 0.0


@numba.njit(cache=True)
def _position_converged(r, r_prev, moved, it, res, res_limit, bound, trace):
    """The position test of a contact step's Newton iterate ``it`` (module docstring).
    r (N+1, 3): its space-route positions (m); r_prev (N+1, 3): the last iterate's,
    overwritten by r; moved (1,): how far the last-but-one correction moved the positions
    (m; < 0: unknown), overwritten by how far the last one did, d = max_k |r_k − r_prev,k|.
    With the contraction ρ = d / moved[0] of two successive corrections the iterate's own
    position error is about ρ/(1 − ρ)·d (Hairer & Wanner, Solving Ordinary Differential
    Equations II, § IV.8, eq. (8.10), in the maximum norm of the positions). Converged
    when that is at most ``bound`` (m), ρ < ½, the last correction was taken whole (cut
    by the feasibility filter or the line search, d does not measure convergence), and
    the scaled residual ``res`` is at most ``res_limit`` (NewtonSolver.CONTACT_RESIDUAL_FACTOR
    × √tol: one or two more quadratic iterations would reach tol). trace: the kernel's
    per-iteration record (feasible and line-search fractions in columns 1, 2). Returns
    the verdict."""
    d = 0.0
    for k in range(r.shape[0]):
        for c in range(3):
            x = abs(r[k, c] - r_prev[k, c])
            if x > d or x != x:
                d = x
            r_prev[k, c] = r[k, c]
    last = moved[0]
    moved[0] = d if it >= 1 else -1.0
    if it < 2 or last <= 0.0 or not d == d:
        return False
    if trace[it - 1, 1] != 1.0 or trace[it - 1, 2] != 1.0:
        return False
    rho = d / last
    if rho >= 0.5 or res > res_limit:
        return False
    return rho / (1.0 - rho) * d <= bound


@numba.njit(cache=True)
def _newton_kernel(Y0, prm, rod, step, cand, cdata, buf, ev, lin, op, gm, ws, ctr):
    """Newton's iterations for one step (the module docstring's strategy), compiled
    whole. Y0 (N+1, 12): the start; prm: the controls
    (:class:`~solver.kernel_data.NewtonParams`); rod, step, cand, cdata:
    :meth:`solver.scheme.RodSystem.kernel_args`; buf, ev: the residual's buffers; lin,
    op, gm, ws, ctr: the Newton object's state (:mod:`solver.kernel_data`). The solution
    is left in ws.Y, its residual evaluation in buf. Returns (iterations, scaled residual
    max_i |R_i| r_i, converged, failure code (:data:`FAILURES`))."""
    tol = prm.tolerance
    max_it = prm.max_iterations
    min_it = prm.min_iterations
    freeze_after = prm.freeze_after
    gap_keep = prm.gap_keep
    gm_refactor = prm.gmres_refactor
    gm_rtol = prm.gmres_rtol
    gm_max = prm.gmres_max
    weight = prm.contact_band_weight
    pos_bound = prm.position_bound
    res_limit = prm.position_residual
    R = buf.R
    Y, Yt, delta_flat, rhs = ws.Y, ws.Y_trial, ws.delta, ws.rhs
    stall_scale, history, frozen = ws.stall_scale, ws.history, ws.frozen
    rs, cs = lin.row_scale, lin.col_scale
    lu = lin.lu
    n1 = Y.shape[0]
    delta = delta_flat.reshape(n1, NV)
    nr = cand.run_start.shape[0]
    contact = nr > 0
    seabed = rod.seabed.scalars[0] != 0.0
    # the seabed damper's branches held within the solve (solver.seabed.SeabedContact.freeze_control)
    hold = rod.seabed.hold
    held = seabed and not contact and hold[1] != 0.0
    hold_at = int(hold[2])
    hold[0] = 0.0
    if held:
        # taken at the start, or (hold_at < 0) the last solve's
        hold[0] = 1.0 if hold_at == 0 else (2.0 if hold_at < 0 else 0.0)
    hold[4] = 0.0
    copy_into(Y, Y0)
    yes = true_at_run_time(Y0)      # want_jac's values, never literals (see its docstring)
    no = not yes
    refactor = ctr.factor_valid[0] == 0 or contact
    res_prev = np.inf
    res = np.inf
    tiny = 0
    nh = 0
    gmres_last = 0
    cached = False
    frozen_on = False
    fresh_sel = True
    # contact steps: the positions of the last iterate and how far the last correction
    # moved them (m), for the position test of NewtonSolver.CONTACT_POSITION_FRACTION
    r_prev, moved = ws.r_prev, ws.moved
    moved[0] = -1.0
    position_test = contact and pos_bound > 0.0
    flags = buf.flags
    whole = True            # the last correction passed the feasibility filter whole
    for it in range(max_it + 1):
        if not cached:
            residual_into(Y, refactor or contact, rod, step, cand,
                          frozen[:nr] if frozen_on else frozen[:0], cdata, buf, ev)
            fresh_sel = not frozen_on
            if hold[0] == 1.0:
                hold[0] = 2.0
        cached = False
        for i in range(R.shape[0]):
            if not np.isfinite(R[i]):
                return it, np.inf, False, _NONFINITE
        fresh = refactor
        if refactor:
            if not _factor(Y, buf, ev, lin, op, rod, step, weight, ctr):
                return it, np.inf, False, _SINGULAR
            refactor = False
        elif contact:
            # the operator becomes the Jacobian at this iterate; the older band LU stays
            # the preconditioner
            _set_operator(buf, ev, lin, op, step, weight, step.af)
        res = _max_scaled(R, rs)
        trace = ws.trace
        trace[it, 0] = res
        trace[it, 1] = 1.0
        trace[it, 2] = 1.0
        trace[it, 3] = 0.0
        done = res <= tol and it >= min_it
        if position_test and not done:
            done = _position_converged(buf.r, r_prev, moved, it, res, res_limit,
                                       pos_bound, trace) and it >= min_it
        if held and hold[0] == 2.0 and hold[7] > 0.0 and (done or res <= hold[6]):
            # converged, or near the held branches' solution, with touching cells off
            # the law's branch (hold[7], counted at this iterate's evaluation): re-decide
            # the branches here (after REDECISIONS, let the law's clamp act) and go on
            hold[0] = 0.0
            if hold[4] < hold[3]:
                hold[4] += 1.0
                hold[5] += 1.0
                hold[0] = 3.0
            residual_into(Y, yes, rod, step, cand, frozen[:0], cdata, buf, ev)
            if hold[0] == 3.0:
                hold[0] = 2.0
            cached = True
            refactor = True
            res_prev = np.inf
            continue
        if done:
            # held branches all the law's at this iterate: its residual is the law's
            return it, res, True, 0
        if it == max_it:
            break
        if contact:
            # stalls are judged in one scale (the row scale changes with the contact
            # stiffness from one factorisation to the next)
            if nh == 0:
                copy_into(stall_scale, rs)
            history[nh] = _max_scaled(R, stall_scale)
            nh += 1
            if it >= 6 and history[nh - 1] > 0.5 * history[nh - 5]:
                # less than a halving in four iterations: Δt is too large
                return it, res, False, _STALLED
        elif not fresh and res > 0.25 * res_prev:
            # the reused factor converges slowly: refactor at this iterate
            residual_into(Y, yes, rod, step, cand, frozen[:0], cdata, buf, ev)
            if not _factor(Y, buf, ev, lin, op, rod, step, weight, ctr):
                return it, np.inf, False, _SINGULAR
            res = _max_scaled(R, rs)
        res_prev = res
        for i in range(rhs.shape[0]):
            rhs[i] = -R[i] * rs[i]
        if op.coupled[0]:
            failures = ctr.gmres_failures[0]
            gmres_last = _gmres(rhs, delta_flat, gm_rtol, gm_max, lin, op, step, gm, ctr)
            if ctr.gmres_failures[0] > failures:
                if not fresh:
                    # a stale preconditioner: refactor here and solve again
                    if not contact:
                        residual_into(Y, yes, rod, step, cand, frozen[:0], cdata, buf, ev)
                    if not _factor(Y, buf, ev, lin, op, rod, step, weight, ctr):
                        return it, np.inf, False, _SINGULAR
                    for i in range(rhs.shape[0]):
                        rhs[i] = -R[i] * rs[i]
                    failures = ctr.gmres_failures[0]
                    if op.coupled[0]:
                        gmres_last = _gmres(rhs, delta_flat, gm_rtol, gm_max, lin, op, step,
                                            gm, ctr)
                    else:
                        copy_into(delta_flat, rhs)
                        block_solve(lu, delta_flat)
                if ctr.gmres_failures[0] > failures:
                    # the contact coupling is too strong for the band preconditioner at
                    # this Δt: the correction is unreliable. Fail now; the caller cuts Δt.
                    return it + 1, res, False, _GMRES
        else:
            copy_into(delta_flat, rhs)
            block_solve(lu, delta_flat)
        for i in range(delta_flat.shape[0]):
            delta_flat[i] *= cs[i]
        if contact:
            if it + 1 == freeze_after:
                # from here on each contact keeps its partner segment (see
                # SelfContact.closest): no switching between iterates
                for q in range(nr):
                    frozen[q] = ev.selection[q]
                frozen_on = True
            # the feasibility filter, then the line search. Where the last correction
            # was taken whole and the selection is not frozen, the whole correction's
            # residual evaluation (which selects afresh, as the filter's trials do)
            # gives its gaps: when they pass, it is the line search's first trial and
            # the filter costs no evaluation of its own
            g0 = ws.gaps0[:nr]
            f0 = _norm_scaled(R, rs)
            alpha = 1.0
            evaluated = False
            if _current_gaps(buf, ev, fresh_sel, cand, cdata, g0):
                if whole and not frozen_on:
                    for k in range(n1):
                        for j in range(NV):
                            Yt[k, j] = Y[k, j] + delta[k, j]
                    residual_into(Yt, yes, rod, step, cand, frozen[:0], cdata, buf, ev)
                    fresh_sel = True
                    if flags[0] == 0 and _gaps_kept(g0, ev.run_gap[:nr], gap_keep):
                        evaluated = True
                    else:
                        alpha = _feasible_fraction(Y, delta, g0, gap_keep, 0.5, step, rod,
                                                   cand, cdata, ws)
                else:
                    alpha = _feasible_fraction(Y, delta, g0, gap_keep, 1.0, step, rod,
                                               cand, cdata, ws)
            whole = alpha == 1.0
            trace[it, 1] = alpha
            trace[it, 3] = gmres_last
            # corrections cut to 1/64 or less three times in a row: the iterate sits
            # against the barrier and Newton stalls
            tiny = tiny + 1 if alpha <= 1.0 / 64.0 else 0
            if tiny >= 3:
                return it + 1, res, False, _STALLED
            # backtracking on the row-scaled residual 2-norm: halve the correction, at
            # most 4 times, until the residual decreases (Armijo, c = 1e-4); the last
            # evaluation (with its Jacobian) is the next iterate's
            step_frac = 1.0
            for _ in range(4):
                if not evaluated:
                    for k in range(n1):
                        for j in range(NV):
                            Yt[k, j] = Y[k, j] + step_frac * delta[k, j]
                    residual_into(Yt, yes, rod, step, cand,
                                  frozen[:nr] if frozen_on else frozen[:0], cdata, buf, ev)
                    fresh_sel = not frozen_on
                evaluated = False
                f1 = _norm_scaled(R, rs)
                if np.isfinite(f1) and f1 <= (1.0 - 1e-4 * step_frac) * f0:
                    break
                step_frac *= 0.5
            trace[it, 2] = step_frac
            # the last trial point (Y + step_frac·delta, doubled back when none was
            # accepted) is the next iterate
            copy_into(Y, Yt)
            cached = True
            refactor = gmres_last > gm_refactor
        elif seabed:
            # the sea floor's contact switches on and off between iterates (its law has
            # a kink at zero penetration; a full Newton step cycled between the two
            # sides): backtracking on the row-scaled residual 2-norm as with
            # self-contact, at most 6 halvings, and a fresh Jacobian after a cut step
            # (else the chord rule above decides)
            f0 = _norm_scaled(R, rs)
            step_frac = 1.0
            if held and it + 1 == hold_at and hold[0] == 0.0:
                hold[0] = 1.0       # the branches taken at the next iterate
            for _ in range(6):
                for k in range(n1):
                    for j in range(NV):
                        Yt[k, j] = Y[k, j] + step_frac * delta[k, j]
                residual_into(Yt, no, rod, step, cand, frozen[:0], cdata, buf, ev)
                f1 = _norm_scaled(R, rs)
                if np.isfinite(f1) and f1 <= (1.0 - 1e-4 * step_frac) * f0:
                    break
                step_frac *= 0.5
            if hold[0] == 1.0:
                hold[0] = 2.0
            trace[it, 2] = step_frac
            trace[it, 3] = gmres_last
            copy_into(Y, Yt)
            cached = True
            if step_frac < 1.0:
                residual_into(Y, yes, rod, step, cand, frozen[:0], cdata, buf, ev)
                refactor = True
        else:
            for k in range(n1):
                for j in range(NV):
                    Y[k, j] = Y[k, j] + delta[k, j]
    return max_it, res, False, 0


class NewtonSolver:
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
    #: preconditioning GMRES holds (the operator stays exact). None: the preconditioner
    #: is the rod's band Jacobian without contact. With all of them GMRES needs more
    #: iterations (each touching node is tied to a fixed partner, while the pair moves
    #: together); on the seed example to 45 s with the position test, none against 5 %
    #: took 17,941 against 26,498 GMRES and 4418 against 4711 Newton iterations, with
    #: the same events and Wr at 45 s (docs/contact.md § 4)
    CONTACT_BAND_WEIGHT = 0.0

    #: contact steps: from this iterate on, the closest-point selection is frozen
    FREEZE_AFTER = 6

    #: a Newton correction may close no candidate gap to less than this fraction of itself
    GAP_KEEP = 0.2

    #: contact steps: the Newton start may close no candidate gap to less than this
    #: fraction of its old value (:func:`_feasible_start`). Newton iterations over the
    #: tension variant's 19-19.3 s (where 154 of 177 starts are blended) with 0, 0.2,
    #: 0.5, 0.8, 0.95: 1212, 1055, 910, 961, 1134; over the seed's 25-30 s (10 of 351
    #: blended) 924 at 0.2, 919 at 0.5, 959 at 0.8 (``python -m research.contact_steps
    #: tension --from 19 --t-end 19.3 --starts --newton START_GAP_KEEP=0.2``;
    #: docs/contact.md § 2)
    START_GAP_KEEP = 0.5

    #: GMRES: relative residual at which a solve stops, and its iteration limit
    GMRES_RTOL = 1e-3
    GMRES_MAX = 40

    #: iterations taken even when the start passes the test (a class default, so that
    #: runs pickled before it existed resume; the run sets 1 under error control)
    min_iterations = 0

    #: contact steps: an iterate whose estimated position error is at most this fraction
    #: of ``position_tolerance`` (and whose scaled residual is at most
    #: CONTACT_RESIDUAL_FACTOR·√tolerance) is
    #: converged (:func:`_position_converged`). The step's own position error is allowed
    #: up to position_tolerance and its steps are sized for 0.35 of it
    #: (docs/contact.md § 3), so Newton's share is under 3 % of the step's error. The
    #: seed example to 45 s (the residual at √tolerance): 4052 Newton iterations against
    #: 4414 at 1e-3, its writhe
    #: 0.854 % off the converged reference over 18-45 s against 0.853 % (docs/contact.md
    #: § 2)
    CONTACT_POSITION_FRACTION = 1e-2

    #: the accuracy of a contact step's positions (m): the route rule's bound, set by the
    #: run (:meth:`solver.run.RodRun._route_tolerance`); 0: no position test (a class
    #: default, so that runs pickled before it existed resume without it)
    position_tolerance = 0.0

    #: contact steps: the position test may stop Newton at a scaled residual of up to
    #: this factor times √tolerance (1e-4 at the default tolerance 1e-9; one more
    #: quadratic iteration would take it to ~10 tolerance). The seed example to 45 s: 3894
    #: Newton iterations against 4052 at a factor of 1, 3.5 % less wall (medians of 3 run
    #: alternately, python -m research.step_overhead compare OLD_TREE --cases seed-1000
    #: --rounds 3), its writhe 0.852 % off the converged reference over 18-45 s against
    #: 0.854 %, the centreline of each replayed step within 0.9 µm of the factor-1 one
    #: (docs/contact.md § 2). A factor of 10 saved 7.7 % of the iterations of the
    #: replayed steps against 4.8 % at the chosen one, for a writhe 0.856 % off
    CONTACT_RESIDUAL_FACTOR = 10.0 ** 0.5

    def __init__(self, system, tolerance=1e-9, max_iterations=25):
        self.system = system
        self.tol = float(tolerance)
        self.max_iterations = int(max_iterations)
        self.factor_key = None
        self.last_failure = None
        self._factored_with_contact = False
        self._state = None
        self.last_frozen = False

    # ------------------------------------------------------------------ state
    def _allocate(self, runs):
        """The kernels' persistent state (:mod:`solver.kernel_data`) for up to ``runs``
        candidate runs; a factorisation and its operator survive a reallocation for more
        runs."""
        sysm = self.system
        n, n1, nc = sysm.n, sysm.n_nodes, sysm.n_cells
        old = self._state
        cap = max(int(runs), 1)
        if old is not None and old["cap"] >= cap:
            return
        if old is not None:
            cap = max(cap, 2 * old["cap"])
        m = self.GMRES_MAX
        if old is None:
            lin = LinearSolve(lu=block_storage(nc), row_scale=np.ones(n), s12=np.ones(NV),
                              col_scale=np.ones(n))
            ctr = NewtonCounters.zeros()
            gm = GmresWork(V=np.zeros((m + 1, n)), Z=np.zeros((m, n)), H=np.zeros((m + 1, m)),
                           cs=np.zeros(m), sn=np.zeros(m), g=np.zeros(m + 1), w=np.zeros(n),
                           x0=np.zeros(n), r=np.zeros(n), dY=np.zeros((n1, NV)),
                           dB=np.zeros((n1, 3)), dS=np.zeros((nc, 6)))
        else:
            lin, ctr, gm = old["lin"], old["ctr"], old["gm"]
        pairs = dict(nodes=np.zeros((cap, 5), np.intp), weights=np.zeros((cap, 5)),
                     force=np.zeros((cap, 3)), dF_dr=np.zeros((cap, 5, 3, 3)),
                     dF_dv=np.zeros((cap, 5, 3, 3)), dt_dr=np.zeros((cap, 5, 3)),
                     dw_dt=np.zeros((cap, 5)))
        if old is not None:
            prev_op = old["op"]
            for name in EXACT_PAIR_FIELDS:
                prev = getattr(prev_op.exact, name)
                pairs[name][:prev.shape[0]] = prev
            ex = prev_op.exact._replace(**pairs)
            op = prev_op._replace(exact=ex)
        else:
            ex = ExactProduct(
                R=np.zeros((n1, 3, 3)), C=np.zeros((nc, 3, 3)), D=np.zeros((nc, 3, 3)),
                tmid=np.zeros((nc, 3)), rdot=np.zeros((n1, 3)), A0=np.zeros((3, 3)),
                G=np.zeros((n1, 3)), L=np.zeros((n1, 3, 6)), **pairs,
                **_product_tail(n1, nc, sysm.p.ds))
            op = Operator(blocks=np.zeros((nc, NV, 2 * NV)), bc_scaled=np.zeros(30),
                          load_row_weight=np.zeros((nc, 3)), exact=ex,
                          coupled=np.zeros(1, np.int64), pairs=np.zeros(1, np.int64))
        hist = self.max_iterations + 2
        ws = NewtonWork(Y=np.zeros((n1, NV)), Y_trial=np.zeros((n1, NV)), delta=np.zeros(n),
                        rhs=np.zeros(n), stall_scale=np.zeros(n), history=np.zeros(hist),
                        gaps0=np.zeros(cap), gaps1=np.zeros(cap),
                        frozen=np.zeros(cap, np.intp), q=np.zeros((n1, 4)),
                        Rm=np.zeros((n1, 3, 3)), r=np.zeros((n1, 3)), theta=np.zeros((n1, 3)),
                        trace=np.zeros((hist, 4)), vg=np.zeros((n1, 3)),
                        r_prev=np.zeros((n1, 3)), moved=np.zeros(1))
        self._state = {"cap": cap, "lin": lin, "op": op, "gm": gm, "ws": ws, "ctr": ctr}

    def __getstate__(self):
        # the factorisation, its operator and the counters travel with a checkpoint (a
        # resumed run reuses the factor as the uninterrupted one does); the work arrays
        # are made afresh
        state = self.__dict__.copy()
        st = state.pop("_state", None)
        state["_saved"] = None if st is None else {k: st[k] for k in ("cap", "lin", "op", "ctr")}
        return state

    def __setstate__(self, state):
        saved = state.pop("_saved", None)
        self.__dict__.update(state)
        self._state = None
        if saved is not None:
            self._allocate(saved["cap"])
            if not isinstance(saved["op"], Operator):
                saved = dict(saved, **_named_state(saved, self.system))
            self._state.update(saved)

    @property
    def factorizations(self) -> int:
        return 0 if self._state is None else int(self._state["ctr"].factorizations[0])

    @property
    def gmres_iterations(self) -> int:
        return 0 if self._state is None else int(self._state["ctr"].gmres_iterations[0])

    @property
    def gmres_failures(self) -> int:
        return 0 if self._state is None else int(self._state["ctr"].gmres_failures[0])

    @property
    def factor_valid(self) -> bool:
        return self._state is not None and bool(self._state["ctr"].factor_valid[0])

    @factor_valid.setter
    def factor_valid(self, value: bool) -> None:
        if self._state is not None:
            self._state["ctr"].factor_valid[0] = int(bool(value))

    def _params(self):
        """The controls of a solve as :func:`_newton_kernel` takes them."""
        return NewtonParams(
            tolerance=float(self.tol), max_iterations=int(self.max_iterations),
            min_iterations=int(self.min_iterations), freeze_after=int(self.FREEZE_AFTER),
            gap_keep=float(self.GAP_KEEP), gmres_refactor=int(self.GMRES_REFACTOR),
            gmres_rtol=float(self.GMRES_RTOL), gmres_max=int(self.GMRES_MAX),
            contact_band_weight=float(self.CONTACT_BAND_WEIGHT),
            position_bound=float(self.CONTACT_POSITION_FRACTION * self.position_tolerance),
            position_residual=float(self.CONTACT_RESIDUAL_FACTOR * math.sqrt(self.tol)))

    # ------------------------------------------------------------------ solve
    def solve(self, Y_guess):
        """Newton iterations for the step set up by :meth:`RodSystem.begin_step`.

        Y_guess: (N+1, 12) start. Returns (Y (N+1, 12), F_nodes (N+1, 12), iterations,
        residual_norm, converged, pose or None); the scaled residual norm is
        max_i |R_i| r_i with r_i the row scale of the last factorisation; the pose
        (:meth:`RodSystem.pose_new`) is that of Y where the iterations computed one
        (global-frame loads or contact candidates), else None. A failure is returned,
        not raised (``last_failure`` says why). The module docstring gives the strategy;
        the iterations are one compiled call (:func:`_newton_kernel`).
        """
        system = self.system
        contact = system.step.candidates is not None
        runs = system.step.candidates.runs if contact else 0
        self._allocate(max(runs, system.ev.selection.shape[0]))
        st = self._state
        if (system.step.key != self.factor_key or contact or self._factored_with_contact):
            st["ctr"].factor_valid[0] = 0
        self.factor_key = system.step.key
        rod, step, cand, cdata = system.kernel_args()
        factorizations = int(st["ctr"].factorizations[0])
        its, res, ok, code = _newton_kernel(
            np.ascontiguousarray(Y_guess, dtype=float), self._params(), rod, step, cand, cdata,
            system.buf, system.ev, st["lin"], st["op"], st["gm"], st["ws"], st["ctr"])
        rod.seabed.hold[0] = 0.0    # the seabed's law at evaluations outside Newton
        if st["ctr"].factorizations[0] != factorizations:
            self._factored_with_contact = contact
        self.last_failure = FAILURES[code]
        #: whether the last solve's final residual used a frozen contact selection
        #: (FREEZE_AFTER iterations or more); if not, its contact evaluation
        #: (RodSystem.contact_summary) is that of a fresh selection at the solution
        self.last_frozen = contact and its >= self.FREEZE_AFTER
        buf = system.buf
        pose = None
        if buf.flags[2] and np.isfinite(res):
            has_r = system.contact is not None or system.step.data.has_r_old
            pose = (buf.q.copy(), buf.Rm.copy(), buf.r.copy() if has_r else None,
                    buf.theta.copy())
        return st["ws"].Y.copy(), buf.Fn.copy(), int(its), float(res), bool(ok), pose

    def feasible_start(self, guess):
        """A Newton start for the step set up by :meth:`RodSystem.begin_step` (with
        contact candidates) whose candidate gaps are open: blended from the
        zero-displacement state toward ``guess`` (N+1, 12) (:func:`_feasible_start`).
        Returns (N+1, 12)."""
        system = self.system
        self._allocate(system.step.candidates.runs)
        rod, step, cand, cdata = system.kernel_args()
        out = np.empty((system.n_nodes, NV))
        _feasible_start(step.Y_old, np.ascontiguousarray(guess, dtype=float), step, rod, cand,
                        cdata, self._state["ws"], out, self.START_GAP_KEEP)
        return out

    # ------------------------------------------------------------------ linear algebra
    def linearize(self, Y, refactor=True):
        """Make the Jacobian at the iterate Y (N+1, 12) of the current step GMRES's
        operator as a Newton iteration does: factorised afresh (equilibrated, the
        preconditioner band with its share of the contact blocks), or with
        ``refactor=False`` in the scales and with the band LU of the last factorisation
        (a stale preconditioner, as between refactorisations in contact steps). For tests
        and diagnostics: :meth:`operator` and :meth:`gmres` are then those of that
        iterate. Raises BandFactorError for a singular Jacobian."""
        from .banded import BandFactorError
        system = self.system
        cand = system.step.candidates
        self._allocate(cand.runs if cand is not None else 1)
        st = self._state
        system.evaluate(Y, True)
        rod, step, cand, cdata = system.kernel_args()
        if not refactor:
            _set_operator(system.buf, system.ev, st["lin"], st["op"], step,
                          self.CONTACT_BAND_WEIGHT, float(step.af))
            return
        if not _factor(np.ascontiguousarray(Y, dtype=float), system.buf, system.ev, st["lin"],
                       st["op"], rod, step, self.CONTACT_BAND_WEIGHT, st["ctr"]):
            raise BandFactorError("singular Jacobian")
        self.factor_key = system.step.key
        self._factored_with_contact = system.step.candidates is not None

    @property
    def row_scale(self):
        """The row scale (n,) of the last factorisation."""
        return self._state["lin"].row_scale

    @property
    def col_scale(self):
        """The column scale (n,) of the last factorisation."""
        return self._state["lin"].col_scale

    @property
    def coupled(self) -> bool:
        """Whether the last operator has exact load terms (GMRES solves with it)."""
        return self._state is not None and bool(self._state["op"].coupled[0])

    def operator(self, x):
        """The scaled Jacobian of the last factorisation or iterate times x (n,)."""
        st = self._state
        out = np.empty(self.system.n)
        _matvec(np.ascontiguousarray(x, dtype=float), out, st["lin"], st["op"],
                self.system.step.data, st["gm"])
        return out

    def gmres(self, rhs, rtol=None):
        """GMRES's solution (n,) of the scaled system with the operator of
        :meth:`operator`, preconditioned by the last band LU, to relative residual rtol
        (default GMRES_RTOL). Returns (x, iterations, converged)."""
        st = self._state
        rtol = self.GMRES_RTOL if rtol is None else float(rtol)
        out = np.empty(self.system.n)
        failures = int(st["ctr"].gmres_failures[0])
        its = _gmres(np.ascontiguousarray(rhs, dtype=float), out, rtol, self.GMRES_MAX,
                     st["lin"], st["op"], self.system.step.data, st["gm"], st["ctr"])
        return out, int(its), int(st["ctr"].gmres_failures[0]) == failures

    def band_solve(self, rhs):
        """The last LU's solution (n,) of rhs (n,) (the preconditioner; the node-local
        band of the Jacobian, :mod:`solver.banded`)."""
        x = np.array(rhs, dtype=float)
        block_solve(self._state["lin"].lu, x)
        return x

    def filtered(self, e):
        """The error filter of stiff integrators, J⁻¹(c M_b e) (Shampine's for RADAU5,
        Hairer & Wanner, *Solving ODEs II*, § IV.8; Hosea & Shampine, Appl. Numer. Math.
        20 (1996) 21-37, for the trapezoid): e (N+1, 12) is mapped through the step's last
        band LU, J = c M_b + (1 − αf) A_b. Components that the step resolves (|λΔt| small)
        pass unchanged; stiff ones, which the scheme damps and an error estimate should
        not chase (contact oscillations, checkerboard modes), are divided by about λ/c.
        The result satisfies the linearised constraints (its f and E2 rows are
        consistent). Returns (N+1, 12); needs a factorisation of the current step."""
        rhs = self.system.step.cm * self.system.cell_inertia(e)
        x = self.band_solve(rhs * self.row_scale) * self.col_scale
        return x.reshape(e.shape)


def _named_state(saved, system):
    """A checkpoint's Newton state pickled before :mod:`solver.kernel_data` (plain
    tuples: lin, op with its exact product's data, and an int64 counter array (4,)) as
    the named tuples, by the positions they had then: {"lin", "op", "ctr"}."""
    lin, op, ctr = saved["lin"], saved["op"], saved["ctr"]
    ex = tuple(op[3])
    names = ExactProduct._fields
    if len(ex) < len(names):
        # a checkpoint from before the seabed's exact product: its (Δt, Δs) and scratch,
        # then the seabed's arrays (empty: the next factorisation fills them)
        tail = _product_tail(system.n_nodes, system.n_cells, float(ex[15][1]))
        tail["scalars"][0] = ex[15][0]
        ex = ex[:15] + tuple(tail.values())
    flags = op[4]
    return {"lin": LinearSolve(BandFactor(*lin[0]), *lin[1:]),
            "op": Operator(op[0], op[1], op[2], ExactProduct(*ex),
                           np.array(flags[:1], np.int64), np.array(flags[1:2], np.int64)),
            "ctr": NewtonCounters(*(np.array(ctr[i:i + 1], np.int64) for i in range(4)))}
