"""Block-banded Jacobian of the box scheme, in LAPACK band storage.

Unknown ordering: node-major, 12 unknowns per node (v, ω, f, κ), n = 12(N+1).
Row ordering: the 6 boundary rows of s = 0, then 12 rows per cell (E1..E4 of seed eqs.
2-5), then the 6 boundary rows of s = L. A cell couples two neighbouring nodes (24
columns), so the half-bandwidths are kl = ku = 17 (numerics-notes §9).

LAPACK general band storage (``dgbtrf``): ``ab[kl + ku + i - j, j] = A[i, j]`` with
``2 kl + ku + 1`` rows, the top kl rows being workspace for the fill-in of pivoting.
"""
from __future__ import annotations

import llvmlite.binding as _llvm
import numba
import numpy as np
from numba import types as _types
from numba.extending import get_cython_function_address

__all__ = ["BandLayout", "BandFactorError", "band_factor", "band_solve", "assemble_band",
           "copy_into", "fill"]

KL = 17
KU = 17
NV = 12  # unknowns per node
LDAB = 2 * KL + KU + 1

# LAPACK's band LU (dgbtrf) and solve (dgbtrs) as scipy ships them
# (scipy.linalg.cython_lapack), bound by symbol name so that the compiled kernels that call
# them can be cached on disk (a ctypes pointer held as a global cannot be).
for _name in ("dgbtrf", "dgbtrs"):
    _llvm.add_symbol("hockle_" + _name,
                     get_cython_function_address("scipy.linalg.cython_lapack", _name))
_vp = _types.voidptr
_dgbtrf = _types.ExternalFunction("hockle_dgbtrf", _types.void(*([_vp] * 8)))
_dgbtrs = _types.ExternalFunction("hockle_dgbtrs", _types.void(*([_vp] * 11)))


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


class BandFactorError(ArithmeticError):
    """The band LU factorisation met an exactly singular pivot (``info > 0``)."""


@numba.njit(cache=True)
def band_factor(abT, piv, iw):
    """LU-factorise in place (LAPACK ``dgbtrf``, partial pivoting) the band matrix whose
    LAPACK storage (LDAB, n), Fortran order, is abT (n, LDAB) in C order; piv (n,) int32
    receives the pivots, iw (8,) int32 is scratch. Returns LAPACK's info (> 0: an exactly
    singular pivot)."""
    n = abT.shape[0]
    iw[0] = n
    iw[1] = n
    iw[2] = KL
    iw[3] = KU
    iw[4] = abT.shape[1]
    iw[5] = 0
    _dgbtrf(iw[0:].ctypes, iw[1:].ctypes, iw[2:].ctypes, iw[3:].ctypes, abT.ctypes,
            iw[4:].ctypes, piv.ctypes, iw[5:].ctypes)
    return iw[5]


@numba.njit(cache=True)
def band_solve(abT, piv, b, iw):
    """Solve in place with the factor of :func:`band_factor` (LAPACK ``dgbtrs``): b (n,)
    becomes the solution. iw (8,) int32 scratch. Returns LAPACK's info."""
    n = abT.shape[0]
    iw[0] = n
    iw[1] = KL
    iw[2] = KU
    iw[3] = 1
    iw[4] = abT.shape[1]
    iw[5] = n
    iw[6] = 0
    iw[7] = 78                      # 'N': no transpose
    _dgbtrs(iw[7:].ctypes, iw[0:].ctypes, iw[1:].ctypes, iw[2:].ctypes, iw[3:].ctypes,
            abT.ctypes, iw[4:].ctypes, piv.ctypes, b.ctypes, iw[5:].ctypes, iw[6:].ctypes)
    return iw[6]


@numba.njit(cache=True)
def assemble_band(abT, cell_blocks, bc_rows, bc_cols, bc_vals):
    """Write the Jacobian into band storage abT (n, LDAB) (zeroed first): cell c's blocks
    (12, 24) at rows 6 + 12c + i, columns 12c + j, and the boundary entries (12,) at
    (bc_rows, bc_cols); A[i, j] is abT[j, KL + KU + i − j] (the module docstring)."""
    fill(abT, 0.0)
    off = KL + KU
    for c in range(cell_blocks.shape[0]):
        for i in range(NV):
            row = 6 + NV * c + i
            for j in range(2 * NV):
                col = NV * c + j
                abT[col, off + row - col] = cell_blocks[c, i, j]
    for m in range(bc_rows.shape[0]):
        abT[bc_cols[m], off + bc_rows[m] - bc_cols[m]] = bc_vals[m]


class BandLayout:
    """The band storage of the step's Jacobian and its LU factor.

    Parameters
    ----------
    n_cells : int
        Number of cells N (the grid has N+1 nodes).
    """

    def __init__(self, n_cells: int):
        self.n_cells = n_cells
        self.n = NV * (n_cells + 1)
        self.ldab = LDAB
        # C-ordered (n, LDAB): the same memory as LAPACK's Fortran-ordered (LDAB, n)
        self.abT = np.zeros((self.n, self.ldab))
        self.piv = np.zeros(self.n, np.int32)
        self.iw = np.zeros(8, np.int32)

    def factor(self, cell_blocks: np.ndarray, bc_rows: np.ndarray, bc_cols: np.ndarray,
               bc_vals: np.ndarray) -> None:
        """Assemble and LU-factorise the (already scaled) Jacobian.

        cell_blocks: (N, 12, 24) blocks of the cell rows on [node k-1 | node k] columns;
        bc_rows, bc_cols, bc_vals: (12,) the boundary-condition entries.
        Raises BandFactorError on an exactly singular matrix.
        """
        assemble_band(self.abT, np.ascontiguousarray(cell_blocks, dtype=float),
                      np.asarray(bc_rows, np.intp), np.asarray(bc_cols, np.intp),
                      np.asarray(bc_vals, dtype=float))
        info = band_factor(self.abT, self.piv, self.iw)
        if info > 0:
            raise BandFactorError(f"singular Jacobian (zero pivot at unknown {info - 1})")
        if info < 0:  # pragma: no cover - an argument error is a programming error
            raise ValueError(f"dgbtrf argument {-info} invalid")

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve with the current factor (``dgbtrs``); rhs (n,) -> (n,)."""
        x = np.array(rhs, dtype=float)
        info = band_solve(self.abT, self.piv, x, self.iw)
        if info != 0:  # pragma: no cover
            raise ValueError(f"dgbtrs argument {-info} invalid")
        return x
