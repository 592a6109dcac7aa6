"""hockle's rod solver: the dynamic Kirchhoff rod of Goyal, Perkins & Lee.

Pure numerics: no I/O, no web or queue imports. Public API (docs/interfaces.md, "Python API")::

    from solver import Case, integrate, SolverDivergence, Progress, warm_up

``integrate`` is the time loop on a validated ``Case``; ``hockle.api.simulate`` is the
public ``simulate`` on top of it (any case form, callbacks, loads in Python).

Names are resolved lazily so that importing :mod:`solver.case` alone (as the service's
API process does) does not import the numerics.
"""
from __future__ import annotations

from importlib.metadata import PackageNotFoundError as _NotInstalled
from importlib.metadata import version as _dist_version

try:
    # written once, in pyproject.toml; the installed distribution's metadata carries it
    __version__ = _dist_version("hockle")
except _NotInstalled:  # pragma: no cover - a source tree that was never installed
    __version__ = "0+unknown"

import os as _os
import sys as _sys

from ._kernel_cache import purge_stale as _purge_stale

_purge_stale()   # compiled kernels cached for other sources are stale (_kernel_cache)

if "NUMBA_THREADING_LAYER" not in _os.environ:
    # numba's own work queue for the parallel kernels (the writhe's pair sum): unlike
    # GNU OpenMP, which numba picks where libgomp is installed, it survives a fork, and
    # the service's Celery pool and the sweeps' process pool fork after the parent has
    # run them (with OpenMP every job of a warmed worker ended in "fork() called from a
    # process already using GNU OpenMP"). Set before numba reads its environment
    # (numba is not imported here: the service's API process never loads the numerics)
    _os.environ["NUMBA_THREADING_LAYER"] = "workqueue"
    if "numba" in _sys.modules:
        _sys.modules["numba"].config.THREADING_LAYER = "workqueue"

_LAZY = {
    "Case": ("solver.case", "Case"),
    "CaseError": ("solver.case", "CaseError"),
    "integrate": ("solver.simulation", "integrate"),
    "SolverDivergence": ("solver.simulation", "SolverDivergence"),
    "Progress": ("solver.simulation", "Progress"),
    "warm_up": ("solver.compiled", "warm_up"),
}

__all__ = sorted(_LAZY) + ["__version__"]


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        module, attr = _LAZY[name]
        value = getattr(importlib.import_module(module), attr)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'solver' has no attribute {name!r}")
