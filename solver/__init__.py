"""hockle's rod solver: the dynamic Kirchhoff rod of Goyal, Perkins & Lee.

Pure numerics: no I/O, no web or queue imports. Public API (docs/interfaces.md, "Python API")::

    from solver import Case, simulate, SolverDivergence, Progress, warm_up

Names are resolved lazily so that importing :mod:`solver.case` alone (as the service's
API process does) does not import the numerics.
"""
from __future__ import annotations

__version__ = "0.1.0"

from ._kernel_cache import purge_stale as _purge_stale

_purge_stale()   # compiled kernels cached for other sources are stale (_kernel_cache)

_LAZY = {
    "Case": ("solver.case", "Case"),
    "CaseError": ("solver.case", "CaseError"),
    "simulate": ("solver.simulation", "simulate"),
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
