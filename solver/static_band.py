"""The static Jacobian as a band, and the band LU of it and of its bordered systems.

The static rows of :mod:`solver.statics` (7 at s = 0, 13 per cell, 6 at s = L) on the
node-major unknowns (13 per node) give a band matrix: cell i's rows 7 + 13i + (0..12)
touch the columns of nodes i and i + 1, 13i + (0..25), so row − column lies in
[−18, 19], and the end rows stay inside it (node 0's 7 rows: [−12, 6]; node N's 6 rows:
[−5, 12]). Lower and upper bandwidths are :data:`KL` = 19 and :data:`KU` = 18.

:func:`cell_band` writes the cells' 13 × 26 blocks straight into LAPACK's band storage,
exact to rounding by the complex step per cell (Squire & Trapp, SIAM Rev. 40, 1998;
Martins et al., ACM TOMS 29, 2003), a compiled kernel with no sparse assembly.
:class:`BorderedBandLU` factors the band with LAPACK's ``dgbtrf`` (partial pivoting,
Golub & Van Loan, *Matrix Computations*, 4th ed., § 4.3) and solves the bordered system
of pseudo-arclength continuation, [[J, W], [Cᵀ, D]] with k = 1 or 2 borders, by block
elimination (Keller, in *Applications of Bifurcation Theory*, 1977): X = J⁻¹W, the Schur
complement S = D − CᵀX (k × k), and det [[J, W], [Cᵀ, D]] = det J · det S, whose sign the
continuation watches for branch points. Block elimination loses accuracy where J is
nearly singular (at a fold, where the bordered matrix is not); one step of iterative
refinement on the whole bordered system restores it (Govaerts & Pryce, *Mixed block
elimination for linear systems with wider borders*, IMA J. Numer. Anal. 13, 1993;
Govaerts, *Numerical Methods for Bifurcations of Dynamical Equilibria*, SIAM 2000,
§ 3.3), and a solve whose refined residual is still large is redone by a sparse LU of the
whole bordered matrix (scipy's SuperLU), as is a band whose LU meets an exactly zero
pivot.
"""
from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.linalg.lapack import dgbtrf, dgbtrs

__all__ = ["KL", "KU", "BorderedBandLU", "BandSingular", "band_storage", "cell_band",
           "cell_residual", "band_matvec", "band_to_sparse"]

NV = 13          # unknowns per node (solver.statics.NV)
N_START = 7      # boundary rows at s = 0
KL = 19          # sub-diagonals of the static Jacobian
KU = 18          # super-diagonals
_EPS = 1e-30     # complex step
#: a refined bordered solve whose residual exceeds this times |A| |x| + |b| is redone
#: by the sparse LU of the whole bordered matrix
REFINED_RESIDUAL = 1e-11
#: block elimination goes unrefined (``solve(refine=False)``) only while |J⁻¹W| |J| / |W|
#: stays below this: near a fold J is singular to rounding and the unrefined solution
#: is wrong in every digit (tests/solver/test_statics.py: a residual of 26 against 1e-14 refined)
UNREFINED_GROWTH = 1e8


class BandSingular(ArithmeticError):
    """The band LU met an exactly zero pivot, or the Schur complement is singular."""


def band_storage(n: int) -> np.ndarray:
    """(2 KL + KU + 1, n) zeros, Fortran-ordered: LAPACK ``dgbtrf``'s band storage of an
    n × n matrix with :data:`KL`, :data:`KU` (A[i, j] at ab[KL + KU + i − j, j])."""
    return np.zeros((2 * KL + KU + 1, n), order="F")


@numba.njit(cache=True)
def _rotation(p, R):
    """R (3, 3) of the quaternion p (4,) (solver.statics._rot), complex-safe."""
    w, x, y, z = p[0], p[1], p[2], p[3]
    R[0, 0] = w * w + x * x - y * y - z * z
    R[0, 1] = 2 * (x * y - w * z)
    R[0, 2] = 2 * (x * z + w * y)
    R[1, 0] = 2 * (x * y + w * z)
    R[1, 1] = w * w - x * x + y * y - z * z
    R[1, 2] = 2 * (y * z - w * x)
    R[2, 0] = 2 * (x * z - w * y)
    R[2, 1] = 2 * (y * z + w * x)
    R[2, 2] = w * w - x * x - y * y + z * z


@numba.njit(cache=True)
def _cell(y, Ka, Kb, k0a, k0b, fa, fb, h, Ra, Rb, kb, out):
    """The 13 box-rule rows of one cell (solver.statics._cell_rows) from y (26,): node a's
    13 unknowns (r, p, n, m) then node b's; Ka, Kb (3,) stiffness, k0a, k0b (3,) the
    intrinsic curvature κ⁰ (1/m), fa, fb (3,) loads; Ra, Rb (3, 3) and kb (3,) work
    arrays. The curvature is κ = K⁻¹Rᵀm + κ⁰ (the law m = R K (κ − κ⁰))."""
    _rotation(y[3:7], Ra)
    _rotation(y[16:20], Rb)
    for c in range(3):
        ka = (Ra[0, c] * y[10] + Ra[1, c] * y[11] + Ra[2, c] * y[12]) / Ka[c] + k0a[c]
        kk = (Rb[0, c] * y[23] + Rb[1, c] * y[24] + Rb[2, c] * y[25]) / Kb[c] + k0b[c]
        kb[c] = 0.5 * (ka + kk)
        out[c] = y[13 + c] - y[c] - 0.5 * h * (Ra[c, 2] + Rb[c, 2])
        out[7 + c] = y[20 + c] - y[7 + c] + 0.5 * h * (fa[c] + fb[c])
    pw, px, py, pz = y[3] + y[16], y[4] + y[17], y[5] + y[18], y[6] + y[19]
    q = 0.25 * h
    out[3] = y[16] - y[3] - q * (-px * kb[0] - py * kb[1] - pz * kb[2])
    out[4] = y[17] - y[4] - q * (pw * kb[0] + py * kb[2] - pz * kb[1])
    out[5] = y[18] - y[5] - q * (pw * kb[1] - px * kb[2] + pz * kb[0])
    out[6] = y[19] - y[6] - q * (pw * kb[2] + px * kb[1] - py * kb[0])
    for c in range(3):                    # m_b − m_a + h/2 (a3_a × n_a + a3_b × n_b)
        c1, c2 = (c + 1) % 3, (c + 2) % 3
        an = Ra[c1, 2] * y[7 + c2] - Ra[c2, 2] * y[7 + c1]
        bn = Rb[c1, 2] * y[20 + c2] - Rb[c2, 2] * y[20 + c1]
        out[10 + c] = y[23 + c] - y[10 + c] + 0.5 * h * (an + bn)


@numba.njit(cache=True)
def cell_band(Y, K, K0, F, h, ab):
    """Write ∂(cell rows)/∂Y of every cell into the band storage ``ab`` (its other
    entries untouched).

    Y (N+1, 13) the node unknowns, K (N+1, 3) EJ1, EJ2, GJ3 (N m²), K0 (N+1, 3) the
    intrinsic curvature κ⁰ (1/m), F (N+1, 3) the dead load per length (N/m), h the cell
    length (m); ab (2 KL + KU + 1, 13(N+1)).
    The rows are linear in r, n and m (solver.statics, the box rule): their columns
    are written in closed form, ±I, h/2 [a3]× of the moment rows on n, and on m the
    quaternion rows' −h/8 L(p_a + p_b) K⁻¹ Rᵀ (L(P) v = P ⊗ (0, v)); the 8 quaternion
    columns of a cell by one complex step each (exact to rounding; the same rows as
    :func:`solver.statics.residual`)."""
    N = Y.shape[0] - 1
    y = np.empty(26, dtype=np.complex128)
    out = np.empty(13, dtype=np.complex128)
    Ra = np.empty((3, 3), dtype=np.complex128)
    Rb = np.empty((3, 3), dtype=np.complex128)
    kb = np.empty(3, dtype=np.complex128)
    L = np.empty((4, 3))
    d = KL + KU
    q = 0.25 * h
    for i in range(N):
        for j in range(NV):
            y[j] = Y[i, j]
            y[NV + j] = Y[i + 1, j]
        row0 = N_START + NV * i
        ca = NV * i                      # node a's first column; node b's is ca + 13
        for e in range(3):               # ±I of the position, force and moment rows
            ab[d + row0 + e - (ca + e), ca + e] = -1.0
            ab[d + row0 + e - (ca + 13 + e), ca + 13 + e] = 1.0
            for base in (7, 10):
                ab[d + row0 + base + e - (ca + base + e), ca + base + e] = -1.0
                ab[d + row0 + base + e - (ca + 13 + base + e), ca + 13 + base + e] = 1.0
        # the moment rows on n: h/2 [a3]× at either node
        for node in range(2):
            P = Y[i + node]
            a3 = (2 * (P[4] * P[6] + P[3] * P[5]), 2 * (P[5] * P[6] - P[3] * P[4]),
                  P[3] * P[3] - P[4] * P[4] - P[5] * P[5] + P[6] * P[6])
            c0 = ca + 13 * node + 7
            for e in range(3):
                e1, e2 = (e + 1) % 3, (e + 2) % 3
                ab[d + row0 + 10 + e - (c0 + e2), c0 + e2] = 0.5 * h * a3[e1]
                ab[d + row0 + 10 + e - (c0 + e1), c0 + e1] = -0.5 * h * a3[e2]
        # the quaternion rows on m: −h/4 L(P) ½ K⁻¹ Rᵀ at either node
        Pw, Px = Y[i, 3] + Y[i + 1, 3], Y[i, 4] + Y[i + 1, 4]
        Py, Pz = Y[i, 5] + Y[i + 1, 5], Y[i, 6] + Y[i + 1, 6]
        L[0, 0], L[0, 1], L[0, 2] = -Px, -Py, -Pz
        L[1, 0], L[1, 1], L[1, 2] = Pw, -Pz, Py
        L[2, 0], L[2, 1], L[2, 2] = Pz, Pw, -Px
        L[3, 0], L[3, 1], L[3, 2] = -Py, Px, Pw
        for node in range(2):
            _rotation(y[3 + 13 * node:7 + 13 * node], Ra)
            Kn = K[i + node]
            c0 = ca + 13 * node + 10
            for dd in range(3):
                for e in range(4):
                    acc = 0.0
                    for c in range(3):
                        acc += L[e, c] * Ra[dd, c].real / Kn[c]
                    ab[d + row0 + 3 + e - (c0 + dd), c0 + dd] = -0.5 * q * acc
        # the quaternion columns by the complex step
        for j in (3, 4, 5, 6, 16, 17, 18, 19):
            y[j] += 1j * _EPS
            _cell(y, K[i], K[i + 1], K0[i], K0[i + 1], F[i], F[i + 1], h, Ra, Rb, kb, out)
            y[j] = y[j].real
            col = ca + j
            for r in range(NV):
                ab[d + row0 + r - col, col] = out[r].imag / _EPS


@numba.njit(cache=True)
def cell_residual(Y, K, K0, F, h, out):
    """The cells' 13 rows of :func:`solver.statics.residual` for a real Y (N+1, 13) into
    out (N, 13) (K, K0, F, h as :func:`cell_band`)."""
    N = Y.shape[0] - 1
    y = np.empty(26)
    Ra = np.empty((3, 3))
    Rb = np.empty((3, 3))
    kb = np.empty(3)
    for i in range(N):
        for j in range(NV):
            y[j] = Y[i, j]
            y[NV + j] = Y[i + 1, j]
        _cell(y, K[i], K[i + 1], K0[i], K0[i + 1], F[i], F[i + 1], h, Ra, Rb, kb, out[i])


@numba.njit(cache=True)
def band_matvec(band, x, y):
    """y = A x for A in BLAS band storage ``band`` (KL + KU + 1, n) (A[i, j] at
    band[KU + i − j, j]), x, y (n,). Compiled and single-threaded: BLAS's ``dgbmv`` on
    2 shared cores ran 0.1-7 ms for the same product at N = 1000."""
    n = x.size
    for i in range(n):
        y[i] = 0.0
    for j in range(n):
        xj = x[j]
        if xj == 0.0:
            continue
        lo = max(0, j - KU)
        hi = min(n, j + KL + 1)
        for i in range(lo, hi):
            y[i] += band[KU + i - j, j] * xj


def band_to_sparse(band: np.ndarray) -> sp.csc_matrix:
    """The matrix of BLAS band storage ``band`` (KL + KU + 1, n) as a sparse CSC."""
    n = band.shape[1]
    return sp.dia_matrix((band, np.arange(KU, -KL - 1, -1)), shape=(n, n)).tocsc()


class BorderedBandLU:
    """LU of the bordered matrix A = [[J, W], [Cᵀ, D]] with J banded (:data:`KL`,
    :data:`KU`): block elimination on the band LU of J, with one step of iterative
    refinement where asked (module docstring).

    ab : (2 KL + KU + 1, n) J in LAPACK band storage (not changed; without borders it is
         kept by reference for :attr:`band`, so the caller must not change it either)
    W, C : (n, k) the border columns and rows (k = 0, 1 or 2)
    D : (k, k) the corner (default zeros)

    ``det_sign`` is the sign of det A (±1). :meth:`solve` takes (n + k,) and returns
    (n + k,). Raises :class:`BandSingular` where J's LU meets an exactly zero pivot
    without borders (with borders it is perturbed to ε max|J| and the refinement works on
    the true matrix) or the Schur complement is singular to rounding.
    """

    def __init__(self, ab: np.ndarray, W=None, C=None, D=None):
        n = ab.shape[1]
        self.n = n
        self._ab = ab
        self._band = self._norm = None
        self.W = np.zeros((n, 0)) if W is None else np.asarray(W, float).reshape(n, -1)
        self.lu, self.piv, info = dgbtrf(ab, KL, KU)
        d = self.lu[KL + KU]
        if info < 0 or not np.all(np.isfinite(d)):
            raise BandSingular(f"band LU failed (dgbtrf info {info})")
        if info > 0:
            # an exactly zero pivot (J singular to rounding, as at a fold: where it falls
            # depends on the LAPACK build): without borders the system is singular; with
            # them it is perturbed to ε|J| (static pivoting, Li & Demmel 1998), which the
            # refinement step of :meth:`solve` corrects on the true matrix, or the
            # sparse LU takes over where it cannot
            if self.W.shape[1] == 0:
                raise BandSingular(f"band LU: zero pivot in column {info}")
            zero = d == 0.0
            d[zero] = np.finfo(float).eps * max(self.norm, 1e-300)
        sign = int(np.prod(np.sign(d))) * (-1) ** int(np.count_nonzero(
            self.piv != np.arange(n)))
        self.X = self._band_solve(self.W) if self.W.shape[1] else np.zeros((n, 0))
        # |J⁻¹W| |J| / |W|: a lower bound of J's condition number along the borders
        self.growth = (float(np.max(np.abs(self.X))) * self.norm
                       / max(float(np.max(np.abs(self.W))), 1e-300)) if self.W.size else 1.0
        k = self.W.shape[1]
        self.C = np.zeros((n, 0)) if C is None else np.asarray(C, float).reshape(n, -1)
        self.D = np.zeros((k, k)) if D is None else np.asarray(D, float).reshape(k, k)
        self.S = self.D - self.C.T @ self.X
        if k:
            s = np.linalg.svd(self.S, compute_uv=False)
            if not (np.all(np.isfinite(s)) and s[-1] > 1e-14 * max(s[0], 1e-300)):
                raise BandSingular("singular Schur complement of the bordered matrix")
            sign *= int(np.sign(np.linalg.det(self.S)))
        self.det_sign = sign
        self._sparse = None

    @property
    def band(self) -> np.ndarray:
        """J in BLAS band storage (KL + KU + 1, n), Fortran-ordered (copied when first
        asked: a factor without borders never needs it)."""
        if self._band is None:
            self._band = np.asfortranarray(self._ab[KL:])
        return self._band

    @property
    def norm(self) -> float:
        """max |J_ij|."""
        if self._norm is None:
            self._norm = float(np.max(np.abs(self.band)))
        return self._norm

    def _band_solve(self, b):
        x, info = dgbtrs(self.lu, KL, KU, b, self.piv)
        return x

    def _eliminate(self, b):
        n = self.n
        w = self._band_solve(b[:n])
        if not self.W.shape[1]:
            return w
        xi = np.linalg.solve(self.S, b[n:] - self.C.T @ w)
        return np.concatenate([w - self.X @ xi, xi])

    def matvec(self, x):
        """A x for x (n + k,)."""
        n = self.n
        top = np.empty(n)
        band_matvec(self.band, np.ascontiguousarray(x[:n]), top)
        top += self.W @ x[n:]
        return np.concatenate([top, self.C.T @ x[:n] + self.D @ x[n:]])

    def solve(self, b, refine: bool = True):
        """x with A x = b, b (n + k,). With borders (k > 0): one step of iterative
        refinement, and the sparse LU of A where the refined residual is still above
        :data:`REFINED_RESIDUAL` (|A| |x| + |b|); ``refine=False`` leaves the refinement
        out while J is well conditioned along the borders (``growth`` below
        :data:`UNREFINED_GROWTH`; a quasi-Newton iteration then refines by itself).
        Without borders, the band LU's solve (backward stable as it is)."""
        b = np.asarray(b, float)
        if self._sparse is not None:
            return self._sparse.solve(b)
        x = self._eliminate(b)
        if not self.W.shape[1]:                  # no border: the band LU's own solve
            return x
        if not refine and self.growth < UNREFINED_GROWTH:
            return x
        x = x + self._eliminate(b - self.matvec(x))
        r = b - self.matvec(x)
        scale = self.norm * np.max(np.abs(x)) + np.max(np.abs(b))
        if not (np.all(np.isfinite(x)) and np.max(np.abs(r)) <= REFINED_RESIDUAL * scale):
            self._sparse = spla.splu(self.sparse())
            return self._sparse.solve(b)
        return x

    def sparse(self) -> sp.csc_matrix:
        """A as a sparse CSC matrix."""
        J = band_to_sparse(self.band)
        return sp.bmat([[J, sp.csc_matrix(self.W)], [sp.csc_matrix(self.C.T),
                                                    sp.csc_matrix(self.D)]], format="csc")
