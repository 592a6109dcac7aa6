"""File I/O for result datasets (the solver package itself does none)."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import xarray as xr

__all__ = ["write_netcdf", "open_result"]


def _fsync_path(path: Path, directory: bool = False) -> None:
    flags = os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if directory else 0)
    try:
        fd = os.open(path, flags)
    except OSError:
        if directory:  # not every platform can open a directory; best effort
            return
        raise
    try:
        os.fsync(fd)
    except OSError:
        if not directory:
            raise
    finally:
        os.close(fd)


def _without_coordinate_fill(ds: xr.Dataset) -> xr.Dataset:
    """A shallow copy whose dimension coordinates are written without ``_FillValue``.

    CF-1.12 § 2.5.1 forbids a fill value on a coordinate variable; xarray adds one to
    float coordinates unless told not to, e.g. when a file read back is written again.
    """
    out = ds.copy(deep=False)
    for name in out.dims:
        if name in out.coords:
            out[name].encoding = {**out[name].encoding, "_FillValue": None}
    return out


def write_netcdf(ds: xr.Dataset, path: str | os.PathLike[str]) -> Path:
    """Write ``ds`` to ``path`` as NetCDF4, atomically.

    The dataset is written to a temporary file in the destination directory, flushed to
    disk (``fsync``), then moved over ``path`` with :func:`os.replace`, so a reader sees
    either the old file or the complete new one, never a partial write. The per-variable
    ``encoding`` (float64, zlib level 4 for (time, s, ...) variables) is honoured. The
    parent directory is created when missing. On failure the temporary file is removed
    and ``path`` is left untouched.

    Returns the destination as a :class:`~pathlib.Path`.
    """
    dest = Path(path)
    ds = _without_coordinate_fill(ds)
    parent = dest.parent if str(dest.parent) else Path(".")
    parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{dest.name}.", suffix=".tmp", dir=parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        ds.to_netcdf(tmp, mode="w", format="NETCDF4", engine="netcdf4")
        # mkstemp creates 0600; give the result the permissions a plain create would.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        _fsync_path(tmp)
        os.replace(tmp, dest)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_path(parent, directory=True)
    return dest


def open_result(path: str | os.PathLike[str]) -> xr.Dataset:
    """Open a result file fully into memory and close it (safe to replace afterwards)."""
    with xr.open_dataset(path, engine="netcdf4") as ds:
        return ds.load()


#: the result variables a start from an earlier result needs (output.fields v, omega,
#: f, kappa, position, orientation of that run)
START_VARIABLES = ("v", "omega", "f", "kappa", "position", "orientation")


def read_start_state(case):
    """The :class:`solver.initial.StartState` of ``case.initial.from_result``: the
    earlier result's v, ω, f, κ, position and orientation at its output time ``time``,
    with the end rotations (from its linking number) and ``work_in`` where it has them.

    Raises :class:`solver.case.CaseError` naming ``initial.from_result.file`` (a file that
    cannot be read, is not a hockle result, lacks a variable, or is of another rod: its
    case's ``rod`` or ``numerics.n_segments`` differ) or ``initial.from_result.time`` (not
    one of its output times), before any work."""
    import math

    import numpy as np

    from solver.case import Case, CaseError
    from solver.initial import StartState

    spec = case.initial.from_result

    def fail(field, etype, msg):
        return CaseError([{"loc": f"initial.from_result.{field}", "msg": msg, "type": etype}])

    try:
        ds = open_result(spec.file)
    except (OSError, ValueError) as exc:
        raise fail("file", "file_unreadable", f"cannot read {spec.file}: {exc}") from None
    try:
        earlier = Case.model_validate_json(ds.attrs["case"])
    except Exception:                                   # noqa: BLE001 - any reason: not ours
        raise fail("file", "not_a_result",
                   f"{spec.file} is not a hockle result (no valid case attribute)") from None
    if (earlier.rod != case.rod
            or earlier.numerics.n_segments != case.numerics.n_segments):
        raise fail("file", "another_rod",
                   f"{spec.file} is a result of another rod (its rod or n_segments "
                   "differ from this case's)")
    missing = [name for name in START_VARIABLES if name not in ds.data_vars]
    if missing:
        raise fail("file", "missing_variable",
                   f"{spec.file} lacks {', '.join(missing)}: run it with output.fields "
                   f"including {', '.join(START_VARIABLES)}")
    times = np.asarray(ds["time"].values, float)
    hit = np.flatnonzero(np.abs(times - spec.time) <= 1e-9 * max(1.0, abs(spec.time)))
    if hit.size == 0:
        raise fail("time", "out_of_range",
                   f"{spec.time!r} s is not an output time of {spec.file} (it has "
                   f"{times.size} from {times.min():.6g} to {times.max():.6g} s)")
    k = int(hit[-1])

    def at(name, dims):
        return np.ascontiguousarray(ds[name].transpose("time", *dims).values[k], dtype=float)

    phi = None
    if "linking_number" in ds.data_vars:
        phi = np.array([0.0, 2.0 * math.pi * float(ds["linking_number"].values[k])])
    work = float(ds["work_in"].values[k]) if "work_in" in ds.data_vars else None
    return StartState(t=float(times[k]), v=at("v", ("s", "component")),
                      omega=at("omega", ("s", "component")), f=at("f", ("s", "component")),
                      kappa=at("kappa", ("s", "component")), q=at("orientation", ("s", "quaternion")),
                      r=at("position", ("s", "xyz")), phi=phi, work_in=work)
