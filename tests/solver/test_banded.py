"""The LU of the step's Jacobian (solver.banded): node windows of the almost-block-
diagonal matrix, against dense and LAPACK band solves of the same matrices."""
import numpy as np
import pytest
from scipy.linalg import lapack

from solver.banded import NV, BandFactorError, BlockLU

KL = KU = 17


def _matrix(rng, n_cells, zero_diagonal=False):
    """Random cell blocks (N, 12, 24) and boundary entries of a step's Jacobian, and the
    same as a dense (n, n) matrix. ``zero_diagonal``: the cell blocks' first 12 columns
    zero on their diagonal, so that every column needs a row interchange."""
    n = NV * (n_cells + 1)
    blocks = rng.normal(size=(n_cells, NV, 2 * NV))
    if zero_diagonal:
        for c in range(n_cells):
            blocks[c, np.arange(NV), np.arange(NV)] = 0.0
    rows = np.r_[0:6, n - 6:n].astype(np.intp)
    cols = np.r_[rng.permutation(NV)[:6], n - NV + rng.permutation(NV)[:6]].astype(np.intp)
    vals = rng.normal(size=12) + 2.0
    dense = np.zeros((n, n))
    for c in range(n_cells):
        dense[6 + NV * c:6 + NV * (c + 1), NV * c:NV * (c + 2)] = blocks[c]
    dense[rows, cols] = vals
    return blocks, rows, cols, vals, dense


@pytest.mark.parametrize("n_cells", [1, 2, 5, 40])
@pytest.mark.parametrize("zero_diagonal", [False, True])
def test_block_lu_solves_the_dense_system(n_cells, zero_diagonal):
    rng = np.random.default_rng(n_cells + 7 * zero_diagonal)
    blocks, rows, cols, vals, dense = _matrix(rng, n_cells, zero_diagonal)
    lu = BlockLU(n_cells)
    lu.factor(blocks, rows, cols, vals)
    for _ in range(3):
        b = rng.normal(size=dense.shape[0])
        x = lu.solve(b)
        exact = np.linalg.solve(dense, b)
        assert np.linalg.norm(x - exact) <= 1e-10 * np.linalg.norm(exact) * np.linalg.cond(dense) ** 0.5
        assert np.linalg.norm(dense @ x - b) <= 1e-12 * np.linalg.norm(dense, np.inf) * np.linalg.norm(x)


def test_block_lu_takes_lapacks_band_pivots():
    """Partial pivoting over the rows with an entry in the column, as LAPACK's dgbtrf:
    on a matrix where every column pivots, the two factors give the same solution to
    rounding (different pivots would differ at the level of the growth they cause)."""
    rng = np.random.default_rng(11)
    blocks, rows, cols, vals, dense = _matrix(rng, 30, zero_diagonal=True)
    n = dense.shape[0]
    ab = np.zeros((2 * KL + KU + 1, n), order="F")
    for j in range(n):
        for i in range(max(0, j - KU), min(n, j + KL + 1)):
            ab[KL + KU + i - j, j] = dense[i, j]
    band, piv, info = lapack.dgbtrf(ab, KL, KU)
    assert info == 0
    b = rng.normal(size=n)
    want, _ = lapack.dgbtrs(band, KL, KU, b, piv)
    lu = BlockLU(30)
    lu.factor(blocks, rows, cols, vals)
    assert np.allclose(lu.solve(b), want, rtol=0, atol=1e-11 * np.abs(want).max())


def test_block_lu_reports_the_singular_unknown():
    rng = np.random.default_rng(5)
    blocks, rows, cols, vals, _ = _matrix(rng, 6)
    blocks[:, :, NV + 4] = 0.0            # no cell row holds unknown 4 of nodes 1..6
    blocks[:, :, 4] = 0.0                 # nor of node 0 (the boundary rows do not either,
    cols[:6] = np.r_[0:4, 5:7]            # they are on unknowns 0-3, 5, 6)
    lu = BlockLU(6)
    with pytest.raises(BandFactorError, match="unknown 4"):
        lu.factor(blocks, rows, cols, vals)
