"""Session set-up shared by every test module."""
import pytest


@pytest.fixture(scope="session", autouse=True)
def compiled_kernels():
    """Load (on a fresh checkout: compile, 1.5 to 6 minutes) the solver's numba kernels once,
    before any test runs, so that no test's time limit includes the compilation."""
    from solver import warm_up

    warm_up()
