"""The laboratory: one-question studies behind the docs' prose (how a choice was made,
what a part costs, how a figure moves with the grid) and the printing scripts of the
verification studies. Not part of hockle: not installed, not in the default test run.
research/README.md lists what is here and how to run it (``python -m research.NAME``
from the repository's root).

The instruments reuse the tests' case builders (``import test_energy_check``, ``from
rodcases import ...``): importing this package puts tests/ on ``sys.path`` once, here,
for them.
"""
import sys as _sys
from pathlib import Path as _Path

_TESTS = str(_Path(__file__).resolve().parents[1] / "tests")
if _TESTS not in _sys.path:
    _sys.path.append(_TESTS)
