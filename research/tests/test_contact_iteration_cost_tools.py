"""The contact-iteration cost benchmark's accounting (research/contact_iteration_cost.py):
a Newton iteration's cost put together from its timed parts, on counts with a known
answer. The benchmark's own solver runs are not repeated here."""
from __future__ import annotations

import pytest

from research.contact_iteration_cost import _per_iteration

PARTS = {"residual and Jacobian": 0.9, "factorisation": 1.6, "operator set-up": 0.2,
         "exact product": 0.1, "band solve": 0.3}


def test_a_contact_iteration_counts_the_start_gmres_factorisations_and_the_operator():
    """10 solves, 20 iterations, 80 GMRES iterations, 5 factorisations: per iteration
    0.9·(1 + 10/20) for the evaluations, 4·(0.1 + 0.3) for GMRES, 0.75·0.2 for the
    operator set up where the factorisation is kept, 0.25·1.6 for the factorisations."""
    counts = {"solves": 10, "newton": 20, "gmres": 80, "factorizations": 5}
    gm, fa, ms = _per_iteration(PARTS, counts)
    assert (gm, fa) == (4.0, 0.25)
    assert ms == pytest.approx(1.35 + 1.6 + 0.15 + 0.4)


def test_a_contact_free_iteration_is_one_band_solve_and_no_operator():
    """Without contact parts (no exact product): one band solve per iteration, no operator
    set-up, the start's evaluation shared over the solve's iterations (each evaluation
    counted with its Jacobian: an upper bound there)."""
    parts = {"residual and Jacobian": 0.2, "factorisation": 1.5, "band solve": 0.25}
    counts = {"solves": 20, "newton": 20, "gmres": 0, "factorizations": 9}
    gm, fa, ms = _per_iteration(parts, counts)
    assert (gm, fa) == (0.0, 0.45)
    assert ms == pytest.approx(0.2 * 2 + 0.25 + 0.45 * 1.5)
