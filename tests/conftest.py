"""Session set-up shared by every test module."""
import pytest


@pytest.fixture(scope="session", autouse=True)
def compiled_kernels():
    """Load (on a fresh checkout: compile, 1.5 to 6 minutes) the solver's numba kernels once,
    before any test runs, so that no test's time limit includes the compilation."""
    from solver import warm_up

    warm_up()


@pytest.fixture(autouse=True)
def formulation_under_test(monkeypatch):
    """With HOCKLE_TEST_FORMULATION=centreline in the environment, every run the time loop
    builds (:func:`solver.simulation.make_run`) is a centreline run where the case allows
    one (no end the scheme refuses; else the seed scheme's),
    so the whole suite measures the centreline scheme against the same expectations
    (docs/numerics.md § 9). Unset (the default and CI): nothing changes."""
    import os

    if os.environ.get("HOCKLE_TEST_FORMULATION") != "centreline":
        return
    from solver import simulation
    from solver.centreline import CentrelineError
    from solver.centreline_run import CentrelineRun

    from rodcases import CENTRELINE_RUNS

    def make_run(case, extra_force=None, start=None):
        try:
            run = CentrelineRun(case, extra_force, start)
        except CentrelineError:
            return simulation.RodRun(case, extra_force, start)
        CENTRELINE_RUNS[id(case)] = case
        return run

    monkeypatch.setattr(simulation, "make_run", make_run)
