"""Compare result files bit for bit: every variable, coordinate and attribute of two hockle
NetCDF results (or of every ``*.nc`` in one folder against the same name in another).

Run: ``python benchmarks/compare_results.py A.nc B.nc`` or ``python
benchmarks/compare_results.py DIR_A DIR_B``. Prints IDENTICAL or DIFFERENT per file with
the differing names; exit status 1 on any difference or missing file. Values are compared
with ``np.array_equal`` (NaN equal to NaN), shapes and dtypes too; only the attributes
that record when and how long a run took (:data:`IGNORED`) are left out. The check that a
change which only moves code leaves the results as they were (docs/developer.md).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import xarray as xr

#: global attributes that differ between two runs of the same case
IGNORED = frozenset({"wall_time_s", "date_created", "date_modified", "date_metadata_modified",
                     "history"})


def _same(x, y) -> bool:
    x, y = np.asarray(x), np.asarray(y)
    return (x.shape == y.shape and x.dtype == y.dtype
            and np.array_equal(x, y, equal_nan=x.dtype.kind in "fc"))


def _same_attrs(a: dict, b: dict) -> bool:
    return set(a) == set(b) and all(_same(a[k], b[k]) for k in a)


def differences(path_a, path_b) -> list[str]:
    """The names in which two result files differ (empty: identical)."""
    with xr.open_dataset(path_a, decode_times=False) as a, \
            xr.open_dataset(path_b, decode_times=False) as b:
        bad = []
        for name in sorted(set(a.variables) | set(b.variables)):
            if name not in a.variables or name not in b.variables:
                bad.append(f"{name}: in one file only")
                continue
            if not _same(a[name].values, b[name].values):
                bad.append(f"{name}: values differ")
            if not _same_attrs(a[name].attrs, b[name].attrs):
                bad.append(f"{name}: attributes differ")
        for key in sorted((set(a.attrs) | set(b.attrs)) - IGNORED):
            if key not in a.attrs or key not in b.attrs or not _same(a.attrs[key], b.attrs[key]):
                bad.append(f"attribute {key}: {a.attrs.get(key)!r} != {b.attrs.get(key)!r}")
        return bad


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2:
        print(__doc__)
        return 2
    a, b = Path(argv[0]), Path(argv[1])
    pairs = [(a, b)] if a.is_file() else [(f, b / f.name) for f in sorted(a.glob("*.nc"))]
    failed = False
    for x, y in pairs:
        if not y.exists():
            print(f"{x.name}: MISSING in {b}")
            failed = True
            continue
        bad = differences(x, y)
        print(f"{x.name}: {'DIFFERENT' if bad else 'IDENTICAL'}")
        for line in bad:
            print("   ", line)
        failed |= bool(bad)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
