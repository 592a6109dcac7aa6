"""The coarse space of research/gmres_spectrum.py --coarse: its aggregates and the
Woodbury correction, on small operators with known answers. The solver's contact steps
are not run here."""
from __future__ import annotations

import numpy as np

from research import gmres_spectrum as gs


def test_coarse_basis_aggregates_consecutive_cells_on_the_chosen_rows():
    n_cells = 20
    n = 12 * (n_cells + 1)
    cells = np.array([2, 3, 4, 5, 6, 10, 11, 12])      # two runs: 2-6 and 10-12
    Q = gs.coarse_basis(n, cells, 3, (6, 7))
    # aggregates 2-4, 5-6, 10-12, two rows each
    assert Q.shape == (n, 6)
    assert np.allclose(Q.T @ Q, np.eye(6))
    support = np.flatnonzero(np.abs(Q).sum(axis=1) > 1e-12)
    expected = sorted(6 + 12 * c + r for c in cells for r in (6, 7))
    assert support.tolist() == expected
    # each column is constant on its aggregate's rows: cells 5 and 6 share one column
    col = np.flatnonzero(np.abs(Q[6 + 12 * 5 + 6]) > 1e-12)
    assert col.size == 1
    assert np.isclose(Q[6 + 12 * 5 + 6, col[0]], Q[6 + 12 * 6 + 6, col[0]])
    assert abs(Q[6 + 12 * 4 + 6, col[0]]) < 1e-12


class _Operator:
    """J M⁻¹ = I + X Qᵀ with M the identity: the case where the correction is exact."""

    def __init__(self, A):
        self.A = A

    def matvec(self, x):
        return self.A @ x

    def precondition(self, x):
        return np.array(x, dtype=float)


def test_coarse_correction_inverts_a_perturbation_that_lives_on_the_coarse_space():
    rng = np.random.default_rng(1)
    n, k = 60, 5
    Q = np.linalg.qr(rng.standard_normal((n, k)))[0]
    X = 3.0 * rng.standard_normal((n, k))
    A = np.eye(n) + X @ Q.T
    B = gs.coarse_correction(_Operator(A), Q)
    y = rng.standard_normal(n)
    assert np.allclose(A @ B(y), y, atol=1e-10)
    # GMRES on A B converges in one iteration; on A alone it needs up to k + 1
    op = _Operator(A)
    assert gs.gmres(op, y, P=B)[0] == 1
    assert gs.gmres(op, y)[0] > 1


def test_augmented_matrix_is_the_exact_contact_operator_on_a_real_contact_step():
    """--augmented's sparse form of the Jacobian (the space route's pose change as
    auxiliary unknowns) on a contact step of PyElastica's plectoneme (N = 25, 10-ms step
    at 8.5 s, in contact since 7.2 s): eliminating the pose unknowns gives the solver's
    exact operator to rounding at every Newton iterate, and its LU as the preconditioner
    takes GMRES to one iteration where the band LU needs more."""
    from scipy.sparse.linalg import splu

    from benchmarks import peer_compare as pcmp
    from research.contact_iteration_cost import _advance_to
    from solver.run import RodRun

    case = pcmp.hockle_case(25, 0.05, 12.0)
    run = RodRun(case)
    _advance_to(run, 8.5, 0.05, 0)
    sys_ = gs.StepSystems(run, 0.01)
    assert int(sys_.op.pairs[0]) > 0                      # contact pairs in the operator
    rng = np.random.default_rng(3)
    for it in range(len(sys_.iterates)):
        rhs = sys_.at(it)
        A, n = gs.augmented_matrix(sys_)
        assert A.shape == (n + 6 * (n // 12), n + 6 * (n // 12))
        x = rng.standard_normal(n)
        ref = sys_.matvec(x)
        assert np.abs(gs.augmented_product(A, n, x) - ref).max() <= 1e-10 * np.abs(ref).max()
        pre = gs._AugmentedPreconditioner(sys_, splu(A), n)
        assert gs.gmres(pre, rhs)[0] == 1
    assert gs.gmres(sys_, rhs)[0] > 1
