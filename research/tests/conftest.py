"""The research instruments' tests: ``python -m pytest research/tests`` from the repository's
root (not in the default run, whose testpaths are tests/). Importing ``research`` puts
tests/ on sys.path for the tests' case builders (``rodcases``)."""
import pytest

import research  # noqa: F401


@pytest.fixture(scope="session", autouse=True)
def compiled_kernels():
    """Load (on a fresh checkout: compile) the solver's numba kernels once, as tests/ does."""
    from solver import warm_up

    warm_up()
