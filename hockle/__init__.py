"""hockle's command line and Python API around the rod solver (:mod:`solver`).

``hockle.__version__`` is the installed distribution's version, the one
``solver.__version__``, ``hockle --version``, the service's ``/v1/health`` and every
result file's ``product_version`` attribute show.
"""
from __future__ import annotations


def __getattr__(name: str):
    if name == "__version__":
        from solver import __version__

        return __version__
    raise AttributeError(f"module 'hockle' has no attribute {name!r}")
