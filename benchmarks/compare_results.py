"""Compare result files bit for bit: every variable, coordinate and attribute of two hockle
NetCDF results (or of every ``*.nc`` in one folder against the same name in another).

Run: ``python -m benchmarks.compare_results A.nc B.nc`` or ``python
benchmarks/compare_results.py DIR_A DIR_B``. Prints IDENTICAL or DIFFERENT per file with
the differing names; exit status 1 on any difference or missing file. Values are compared
with ``np.array_equal`` (NaN equal to NaN), shapes and dtypes too; only the attributes
that record when and how long a run took (:data:`IGNORED`) are left out. The check that a
change which only moves code leaves the results as they were (docs/developer.md).

With ``--largest T0:T1[,T2:T3...] [--fields position,f,writhe]`` (two files only) it
prints instead, per window of output times and field, how far B lies from A
(:func:`largest_differences`): for changes that are meant to move the results.
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


def largest_differences(path_a, path_b, t0: float, t1: float, fields) -> dict:
    """How far result B lies from result A over the outputs with t0 ≤ time ≤ t1 (s):
    per field of ``fields`` (names of variables on a ``time`` dimension that both files
    hold with one shape), (the largest |B − A|, that over the largest |A|), in the field's
    units; over a ``component`` dimension the Euclidean norm is taken first (a position's
    distance in m, a force's magnitude in N). Raises KeyError for a field one file lacks
    and ValueError for shapes that differ."""
    out = {}
    with xr.open_dataset(path_a, decode_times=False) as a, \
            xr.open_dataset(path_b, decode_times=False) as b:
        for name in fields:
            x = a[name].sel(time=slice(t0, t1))
            y = b[name].sel(time=slice(t0, t1))
            if x.shape != y.shape:
                raise ValueError(f"{name}: shapes {x.shape} and {y.shape} differ")
            d, m = np.abs(y.values - x.values), np.abs(x.values)
            if "component" in x.dims:
                axis = x.dims.index("component")
                d = np.sqrt((d ** 2).sum(axis=axis))
                m = np.sqrt((m ** 2).sum(axis=axis))
            largest = float(d.max()) if d.size else 0.0
            scale = float(m.max()) if m.size else 0.0
            out[name] = (largest, largest / scale if scale > 0.0 else float("nan"))
    return out


def _print_largest(a: Path, b: Path, windows: str, fields: str) -> None:
    names = [f for f in fields.split(",") if f]
    for w in windows.split(","):
        t0, t1 = (float(x) for x in w.split(":"))
        row = largest_differences(a, b, t0, t1, names)
        print(f"{t0:g}-{t1:g} s: " + "; ".join(
            f"{n} {d:.3g} ({r:.2e} of its largest)" for n, (d, r) in row.items()))


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if "--largest" in argv:
        k = argv.index("--largest")
        windows = argv[k + 1]
        rest = argv[:k] + argv[k + 2:]
        fields = "position,f,writhe"
        if "--fields" in rest:
            j = rest.index("--fields")
            fields = rest[j + 1]
            rest = rest[:j] + rest[j + 2:]
        if len(rest) != 2:
            print(__doc__)
            return 2
        _print_largest(Path(rest[0]), Path(rest[1]), windows, fields)
        return 0
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
