"""File I/O for result datasets (the solver package itself does none)."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import xarray as xr

__all__ = ["write_netcdf", "open_result", "read_start_state", "start_state_from"]


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
def read_start_state(case):
    """The :class:`solver.initial.StartState` of ``case.initial.from_result``: the
    earlier result file's v, ω, f, κ, position and orientation at its output time
    ``time``, with the end rotations (from its linking number) and ``work_in`` where it
    has them (:func:`start_state_from`).

    Raises :class:`solver.case.CaseError` naming ``initial.from_result.file`` (a file that
    cannot be read, is not a hockle result, lacks a variable, or is of another rod: its
    case's ``rod`` or ``numerics.n_segments`` differ), ``initial.from_result.time`` (not
    one of its output times) or ``initial.from_result.job`` (a job id, which only the
    service resolves), before any work."""
    from solver.case import CaseError

    spec = case.initial.from_result
    if spec.file is None:
        raise CaseError([{"loc": "initial.from_result.job", "type": "not_here",
                          "msg": "a job id is resolved by the service (hockle submit); "
                                 "hockle run and the Python API start from a result file: "
                                 "give initial.from_result.file"}])
    try:
        ds = open_result(spec.file)
    except (OSError, ValueError) as exc:
        raise CaseError([{"loc": "initial.from_result.file", "type": "file_unreadable",
                          "msg": f"cannot read {spec.file}: {exc}"}]) from None
    return start_state_from(ds, case, spec.file, "file")


#: the result variables a start from an earlier result needs
START_VARIABLES = ("v", "omega", "f", "kappa", "position", "orientation")


def start_state_from(ds, case, source: str, field: str = "file") -> StartState:
    """The :class:`StartState` of ``case.initial.from_result`` read from ``ds``, an
    earlier result (``xarray.Dataset`` as :func:`solver.results.build_dataset` writes
    it, opened by the caller: a file here, a job's result in the service): its v, ω, f, κ, position and
    orientation at the output time ``from_result.time``, the end rotations (from its
    linking number) and ``work_in`` where it has them. ``source`` names the result in
    messages (a path, a job id); ``field`` is where it was given (``"file"``, ``"job"``).

    Raises :class:`solver.case.CaseError` naming ``initial.from_result.<field>`` (not a
    hockle result, another rod: its case's ``rod`` or ``numerics.n_segments`` differ, a
    variable missing) or ``initial.from_result.time`` (not one of its output times)."""
    import math

    import numpy as np

    from solver.case import Case, CaseError
    from solver.initial import StartState

    spec = case.initial.from_result

    def fail(where, etype, msg):
        return CaseError([{"loc": f"initial.from_result.{where}", "msg": msg, "type": etype}])

    try:
        earlier = Case.model_validate_json(ds.attrs["case"])
    except Exception:                                   # noqa: BLE001 - any reason: not ours
        raise fail(field, "not_a_result",
                   f"{source} is not a hockle result (no valid case attribute)") from None
    if (earlier.rod != case.rod
            or earlier.numerics.n_segments != case.numerics.n_segments):
        raise fail(field, "another_rod",
                   f"{source} is a result of another rod (its rod or n_segments "
                   "differ from this case's)")
    missing = [name for name in START_VARIABLES if name not in ds.data_vars]
    if missing:
        raise fail(field, "missing_variable",
                   f"{source} lacks {', '.join(missing)}: run it with output.fields "
                   f"including {', '.join(START_VARIABLES)}")
    times = np.asarray(ds["time"].values, float)
    hit = np.flatnonzero(np.abs(times - spec.time) <= 1e-9 * max(1.0, abs(spec.time)))
    if hit.size == 0:
        raise fail("time", "out_of_range",
                   f"{spec.time!r} s is not an output time of {source} (it has "
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
                      kappa=at("kappa", ("s", "component")),
                      q=at("orientation", ("s", "quaternion")),
                      r=at("position", ("s", "xyz")), phi=phi, work_in=work)
