"""Block-banded Jacobian of the box scheme, in LAPACK band storage.

Unknown ordering: node-major, 12 unknowns per node (v, ω, f, κ), n = 12(N+1).
Row ordering: the 6 boundary rows of s = 0, then 12 rows per cell (E1..E4 of seed eqs.
2-5), then the 6 boundary rows of s = L. A cell couples two neighbouring nodes (24
columns), so the half-bandwidths are kl = ku = 17 (numerics-notes §9).

LAPACK general band storage (``dgbtrf``): ``ab[kl + ku + i - j, j] = A[i, j]`` with
``2 kl + ku + 1`` rows, the top kl rows being workspace for the fill-in of pivoting.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

__all__ = ["BandLayout", "BandFactorError"]

KL = 17
KU = 17
NV = 12  # unknowns per node


class BandFactorError(ArithmeticError):
    """The band LU factorisation met an exactly singular pivot (``info > 0``)."""


class BandLayout:
    """Index maps from (cell, row, column) blocks to band storage, computed once.

    Parameters
    ----------
    n_cells : int
        Number of cells N (the grid has N+1 nodes).
    """

    def __init__(self, n_cells: int):
        self.n_cells = n_cells
        self.n = NV * (n_cells + 1)
        self.ldab = 2 * KL + KU + 1
        c = np.arange(n_cells)[:, None, None]
        i = np.arange(NV)[None, :, None]
        j = np.arange(2 * NV)[None, None, :]
        rows = 6 + NV * c + i
        cols = NV * c + j
        self.cell_flat = self.flat_index(rows, cols).ravel()
        # Fortran-ordered band array (what dgbtrf wants, so no copy is made); its
        # transpose is C-contiguous, and flat_index addresses that flat view.
        self._ab = np.zeros((self.ldab, self.n), order="F")
        self.lu = None
        self.piv = None

    def flat_index(self, row, col) -> np.ndarray:
        """Flat indices (into the Fortran-ordered band array) of matrix entries (row, col)."""
        row = np.asarray(row)
        col = np.asarray(col)
        return (KL + KU + row - col) + col * self.ldab

    def factor(self, cell_blocks: np.ndarray, bc_rows: np.ndarray, bc_cols: np.ndarray,
               bc_vals: np.ndarray) -> None:
        """Assemble and LU-factorise the (already scaled) Jacobian.

        cell_blocks: (N, 12, 24) blocks of the cell rows on [node k-1 | node k] columns;
        bc_rows, bc_cols, bc_vals: (12,) the boundary-condition entries.
        Raises BandFactorError on an exactly singular matrix.
        """
        if not self._ab.flags.f_contiguous:  # e.g. after unpickling
            self._ab = np.asfortranarray(self._ab)
        self._ab.fill(0.0)
        flat = self._ab.T.reshape(-1)    # a view (taken here, so copies of self stay valid)
        flat[self.cell_flat] = cell_blocks.ravel()
        flat[self.flat_index(bc_rows, bc_cols)] = bc_vals
        lu, piv, info = lapack.dgbtrf(self._ab, KL, KU, overwrite_ab=1)
        if info > 0:
            raise BandFactorError(f"singular Jacobian (zero pivot at unknown {info - 1})")
        if info < 0:  # pragma: no cover - an argument error is a programming error
            raise ValueError(f"dgbtrf argument {-info} invalid")
        self.lu, self.piv = lu, piv

    def dense(self) -> np.ndarray:
        """The assembled (pre-factorisation) matrix as a dense array, for tests (small n)."""
        a = np.zeros((self.n, self.n))
        for jcol in range(self.n):
            for irow in range(max(0, jcol - KU), min(self.n, jcol + KL + 1)):
                a[irow, jcol] = self._ab[KL + KU + irow - jcol, jcol]
        return a

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve with the current factor (``dgbtrs``); rhs (n,) -> (n,)."""
        x, info = lapack.dgbtrs(self.lu, KL, KU, rhs, self.piv)
        if info != 0:  # pragma: no cover
            raise ValueError(f"dgbtrs argument {-info} invalid")
        return x
