"""The laboratory: one-question studies behind the docs' prose (how a choice was made,
what a part costs, how a figure moves with the grid) and the printing scripts of the
verification studies. Not part of hockle: not installed, not in the default test run.
research/README.md lists what is here and how to run it (``python -m research.NAME``
from the repository's root).

The instruments reuse the tests' case builders (``import test_energy_check``, ``from
rodcases import ...``): importing this package puts tests/ and tests/solver/ on
``sys.path`` once, here, for them.
"""
import sys as _sys
from pathlib import Path as _Path

for _folder in ("tests", "tests/solver"):
    _path = str(_Path(__file__).resolve().parents[1] / _folder)
    if _path not in _sys.path:
        _sys.path.append(_path)
