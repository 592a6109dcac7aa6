"""The LU factorisation of the step's Jacobian, an almost-block-diagonal matrix.

Unknown ordering: node-major, 12 unknowns per node (v, ω, f, κ), n = 12(N+1).
Row ordering: the 6 boundary rows of s = 0 (on node 0's unknowns), then 12 rows per cell
k = 0 … N−1 (E1..E4 of seed eqs. 2-5, on nodes k and k + 1), then the 6 boundary rows of
s = L (on node N's). Every cell's rows span 24 columns and consecutive cells overlap by
12: the matrix is almost block diagonal (a two-point boundary-value problem's
collocation matrix), a band with kl = ku = 17 (numerics-notes §9) in which most of the
band is structurally zero.

Gaussian elimination with partial (row) pivoting meets the structure exactly: the
unknowns of node k occur only in the 6 rows left over from node k − 1 and the 12 rows of
cell k, so node k's 12 columns are eliminated in a window of 18 rows × 24 columns (node k
and node k + 1); 12 rows become U's, the other 6 carry over to the next window with fill
on node k + 1 only, and the last window is the 6 carried rows with the 6 boundary rows of
s = L (12 × 12). The pivots are those of LAPACK's band LU (``dgbtrf``: partial pivoting
over the rows that have an entry in the column, the first of equal maxima), with a third
of its flops: per node ~5,300 against ~14,000. A window's rows are updated whole, over
all 24 columns with the eliminated entries held at an exact 0 (:func:`_window`), which the
compiler vectorises: at N = 1000 on the seed example's contact Jacobian 1.1 ms per
factor against 1.9 ms for ``dgbtrf`` on the same matrix (``python
research/contact_iteration_cost.py``, "band LU alone"). The elimination order
and pivots being the band LU's, so is its stability (Golub & Van Loan, *Matrix
Computations*, § 4.3 on band LU with partial pivoting).

The factor's storage is a :class:`solver.kernel_data.BandFactor` (:func:`block_storage`):
LW, UR, piv, LF, pivf and the work arrays W, w, each described there.
"""
from __future__ import annotations

import numba
import numpy as np

from .kernel_data import BandFactor

__all__ = ["BlockLU", "BandFactorError", "block_storage", "block_factor", "block_solve",
           "copy_into", "fill", "true_at_run_time", "NV"]

NV = 12  # unknowns per node
_WIN = 18  # rows of a window: 6 carried + 12 of a cell


@numba.njit(cache=True)
def copy_into(dst, src):
    """dst[...] = src for C-contiguous arrays of one size (an explicit loop: numba's
    broadcasting assignment costs seconds of compile time per use)."""
    d = dst.reshape(dst.size)
    s = src.reshape(src.size)
    for i in range(d.size):
        d[i] = s[i]


@numba.njit(cache=True)
def fill(dst, value):
    """dst[...] = value for a C-contiguous array (see :func:`copy_into`)."""
    d = dst.reshape(dst.size)
    for i in range(d.size):
        d[i] = value


@numba.njit(cache=True, inline="always")
def true_at_run_time(a):
    """True, typed ``bool`` rather than ``Literal[bool](True)``, for any array ``a``
    (a comparison the compiler cannot type as a constant). A compiled function that
    passes the literal True or False to another makes numba compile the callee, and
    everything it calls, once per literal: the step's residual was compiled three times
    (want_jac True, False and run-time), which with the sea floor's and the loads' copies
    made a fresh installation's compilation 124 s instead of 91 s (``python
    benchmarks/compile_time.py``). Callers pass ``yes = true_at_run_time(a)``
    and ``not yes`` instead. a: an array of at least one dimension (its length is read);
    returns True; raises nothing."""
    return a.shape[0] >= 0


@numba.njit(cache=True, inline="always")
def int_at_run_time(a, value):
    """``value``, typed ``int64`` rather than ``Literal[int](value)``, for any array ``a``
    (:func:`true_at_run_time`'s counterpart for integers). numba compiles a function once
    per literal integer it is called with from compiled code as well: the contact's
    closest-point search ``_run_point`` was compiled three times (its frozen segment −1
    and its iteration count 3 as literals from two callers, as run-time values from a
    third), 2.5 s and 3.8 s of a fresh installation's compilation on two machines
    (``python -m benchmarks.compile_time``). a: an array of at least one dimension (its length is
    read); value: an integer; returns value; raises nothing."""
    return value + 0 * a.shape[0]


class BandFactorError(ArithmeticError):
    """The LU factorisation met an exactly singular pivot."""


def block_storage(n_cells: int):
    """The factor's storage for N = n_cells cells (module docstring), a
    :class:`solver.kernel_data.BandFactor`."""
    n = int(n_cells)
    return BandFactor(LW=np.zeros((n, _WIN, NV)), UR=np.zeros((n, NV, NV)),
                      piv=np.zeros((n, NV), np.intp), LF=np.zeros((NV, NV)),
                      pivf=np.zeros(NV, np.intp), W=np.zeros((_WIN, 2 * NV)), w=np.zeros(_WIN))


@numba.njit(cache=True, inline="always")
def _pivot(W, rows, j):
    """Partial pivoting's row for column j of W: the first row in j .. rows−1 whose
    |W[i, j]| is largest (LAPACK's ``dgbtrf`` choice); −1 where the column is exactly 0
    there (a singular matrix)."""
    p = j
    big = abs(W[j, j])
    for i in range(j + 1, rows):
        a = abs(W[i, j])
        if a > big:
            big = a
            p = i
    return p if big != 0.0 else -1


@numba.njit(cache=True)
def _eliminate(W, rows, cols, j, piv_row):
    """Partial pivoting on column j of W (rows j .. rows−1) and elimination below it in
    columns j+1 .. cols−1: the multipliers are stored in column j; the interchange is
    applied to columns j .. cols−1 only (earlier multipliers stay with the row they were
    computed for, so the solve interchanges and eliminates column by column, as LINPACK's
    dgesl). Records the pivot row in piv_row[j]; returns False for an exactly zero
    pivot. Used for the last window (12 × 12); the node windows use :func:`_window`."""
    p = _pivot(W, rows, j)
    if p < 0:
        return False
    piv_row[j] = p
    if p != j:
        for c in range(j, cols):
            tmp = W[j, c]
            W[j, c] = W[p, c]
            W[p, c] = tmp
    inv = 1.0 / W[j, j]
    for i in range(j + 1, rows):
        m = W[i, j] * inv
        W[i, j] = m
        if m != 0.0:
            for c in range(j + 1, cols):
                W[i, c] -= m * W[j, c]
    return True


@numba.njit(cache=True)
def _window(W, LWk, pivk):
    """Eliminate node k's 12 columns in its window W (18, 24) (the 6 carried rows and
    cell k's 12, on nodes k and k + 1) with :func:`_eliminate`'s pivots and multipliers,
    writing the multipliers below the diagonal of LWk (18, 12) as they are computed and
    the pivot rows into pivk (12,). Unlike :func:`_eliminate`, W keeps an eliminated entry
    as an exact 0 (the multiplier goes to LWk only), so every row update runs over all
    24 columns, a fixed trip count the compiler unrolls and vectorises: the entries left of
    column j are 0 in the pivot row and left unchanged, the arithmetic on the others is
    the same, and so is the factor, bit for bit (its time: the module docstring). The
    upper triangle (rows 0-11) is left in W for the caller. Returns 0, or 1 + the column
    whose pivot is exactly zero."""
    for j in range(NV):
        p = _pivot(W, _WIN, j)
        if p < 0:
            return j + 1
        pivk[j] = p
        if p != j:
            for c in range(2 * NV):
                tmp = W[j, c]
                W[j, c] = W[p, c]
                W[p, c] = tmp
        inv = 1.0 / W[j, j]
        for i in range(j + 1, _WIN):
            m = W[i, j] * inv
            LWk[i, j] = m
            if m != 0.0:
                for c in range(2 * NV):
                    W[i, c] -= m * W[j, c]
            W[i, j] = 0.0
    return 0


@numba.njit(cache=True)
def block_factor(blocks, bc_rows, bc_cols, bc_vals, lu):
    """LU-factorise the Jacobian with cell blocks (N, 12, 24) on [node k | node k + 1]
    (already scaled) and the boundary entries (bc_rows, bc_cols, bc_vals) (12,) each,
    rows 0-5 at s = 0 and n−6 … n−1 at s = L, into the storage ``lu``
    (:func:`block_storage`). Returns 0, or 1 + the unknown whose pivot is exactly zero
    (a singular Jacobian)."""
    LW, UR, piv, LF, pivf, W, w = lu.LW, lu.UR, lu.piv, lu.LF, lu.pivf, lu.W, lu.w
    n_cells = blocks.shape[0]
    n = NV * (n_cells + 1)
    # the first window's carried rows: the boundary rows of s = 0
    for i in range(6):
        for c in range(2 * NV):
            W[i, c] = 0.0
    for m in range(bc_rows.shape[0]):
        r = bc_rows[m]
        if r < 6:
            W[r, bc_cols[m]] = bc_vals[m]
    for k in range(n_cells):
        for i in range(NV):
            for c in range(2 * NV):
                W[6 + i, c] = blocks[k, i, c]
        info = _window(W, LW[k], piv[k])
        if info != 0:
            return NV * k + info
        for i in range(NV):
            for c in range(i, NV):
                LW[k, i, c] = W[i, c]
            for c in range(NV):
                UR[k, i, c] = W[i, NV + c]
        # the 6 rows left carry over, on node k + 1's columns
        for i in range(6):
            for c in range(NV):
                W[i, c] = W[NV + i, NV + c]
            for c in range(NV, 2 * NV):
                W[i, c] = 0.0
    # the last window: the carried rows and the boundary rows of s = L, on node N
    for i in range(6):
        for c in range(NV):
            LF[i, c] = W[i, c]
            LF[6 + i, c] = 0.0
    for m in range(bc_rows.shape[0]):
        r = bc_rows[m]
        if r >= n - 6:
            LF[r - (n - 6) + 6, bc_cols[m] - NV * n_cells] = bc_vals[m]
    for j in range(NV):
        if not _eliminate(LF, NV, NV, j, pivf):
            return NV * n_cells + j + 1
    return 0


@numba.njit(cache=True)
def block_solve(lu, x):
    """Solve in place with the factor of :func:`block_factor`: x (n,) holds the right-hand
    side in the residual's row order and becomes the solution in the unknowns' order
    (the forward pass writes node k's entries only after it has read cell k's rows, so
    the two orders can share one array)."""
    LW, UR, piv, LF, pivf, W, w = lu.LW, lu.UR, lu.piv, lu.LF, lu.pivf, lu.W, lu.w
    n_cells = LW.shape[0]
    n = NV * (n_cells + 1)
    for i in range(6):
        w[i] = x[i]
    for k in range(n_cells):
        for i in range(NV):
            w[6 + i] = x[6 + NV * k + i]
        for j in range(NV):
            p = piv[k, j]
            if p != j:
                tmp = w[j]
                w[j] = w[p]
                w[p] = tmp
            wj = w[j]
            if wj != 0.0:
                for i in range(j + 1, _WIN):
                    w[i] -= LW[k, i, j] * wj
        for i in range(NV):
            x[NV * k + i] = w[i]
        for i in range(6):
            w[i] = w[NV + i]
    for i in range(6):
        w[6 + i] = x[n - 6 + i]
    for j in range(NV):
        p = pivf[j]
        if p != j:
            tmp = w[j]
            w[j] = w[p]
            w[p] = tmp
        wj = w[j]
        for i in range(j + 1, NV):
            w[i] -= LF[i, j] * wj
    base = NV * n_cells
    for j in range(NV - 1, -1, -1):
        acc = w[j]
        for c in range(j + 1, NV):
            acc -= LF[j, c] * x[base + c]
        x[base + j] = acc / LF[j, j]
    for k in range(n_cells - 1, -1, -1):
        b0 = NV * k
        nb = b0 + NV
        for j in range(NV - 1, -1, -1):
            acc = x[b0 + j]
            for c in range(NV):
                acc -= UR[k, j, c] * x[nb + c]
            for c in range(j + 1, NV):
                acc -= LW[k, j, c] * x[b0 + c]
            x[b0 + j] = acc / LW[k, j, j]


class BlockLU:
    """The LU factor of a step's Jacobian (module docstring), for callers outside
    Newton's compiled iterations (the growth guard, :func:`solver.stepping.growth_rate`).

    Parameters
    ----------
    n_cells : int
        Number of cells N (the grid has N+1 nodes).
    """

    def __init__(self, n_cells: int):
        self.n_cells = n_cells
        self.n = NV * (n_cells + 1)
        self.lu = block_storage(n_cells)

    def factor(self, cell_blocks: np.ndarray, bc_rows: np.ndarray, bc_cols: np.ndarray,
               bc_vals: np.ndarray) -> None:
        """LU-factorise the (already scaled) Jacobian.

        cell_blocks: (N, 12, 24) blocks of the cell rows on [node k-1 | node k] columns;
        bc_rows, bc_cols, bc_vals: (12,) the boundary-condition entries.
        Raises BandFactorError on an exactly singular matrix.
        """
        info = block_factor(np.ascontiguousarray(cell_blocks, dtype=float),
                            np.asarray(bc_rows, np.intp), np.asarray(bc_cols, np.intp),
                            np.asarray(bc_vals, dtype=float), self.lu)
        if info > 0:
            raise BandFactorError(f"singular Jacobian (zero pivot at unknown {info - 1})")

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve with the current factor; rhs (n,) in the residual's row order -> the
        solution (n,) in the unknowns' order (a new array)."""
        x = np.array(rhs, dtype=float)
        block_solve(self.lu, x)
        return x
