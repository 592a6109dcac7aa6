"""File I/O for result datasets (the solver package itself does none)."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import xarray as xr

from solver.results import START_VARIABLES, start_state_from

__all__ = ["write_netcdf", "open_result", "read_start_state", "start_state_from",
           "START_VARIABLES"]


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
    """Write a result dataset as NetCDF4, atomically.

    The dataset is written to a temporary file in the destination directory, flushed to
    disk (``fsync``), then moved over ``path`` with :func:`os.replace`, so a reader sees
    either the old file or the complete new one, never a partial write. The per-variable
    ``encoding`` (float64, zlib level 4 for (time, s, ...) variables) is honoured. The
    parent directory is created when missing. On failure the temporary file is removed
    and ``path`` is left untouched.

    Parameters
    ----------
    ds : xarray.Dataset
        The dataset.
    path : str or os.PathLike
        The destination.

    Returns
    -------
    pathlib.Path
        The destination.
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
    """Open a result file fully into memory and close it (safe to replace afterwards).

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    xarray.Dataset
    """
    with xr.open_dataset(path, engine="netcdf4") as ds:
        return ds.load()


def read_start_state(case):
    """The start state a case's ``initial.from_result`` names.

    The earlier result file's v, ω, f, κ, position and orientation at its output time
    ``time``, with the end rotations (from its linking number) and ``work_in`` where it
    has them (:func:`start_state_from`).

    Parameters
    ----------
    case : solver.Case
        A case with ``initial.from_result``.

    Returns
    -------
    solver.initial.StartState

    Raises
    ------
    solver.CaseError
        Before any work, naming ``initial.from_result.file`` (a file that cannot be read,
        is not a hockle result, lacks a variable, or is of another rod: its case's ``rod``
        or ``numerics.n_segments`` differ), ``initial.from_result.time`` (not one of its
        output times) or ``initial.from_result.job`` (a job id, which only the service
        resolves).
    """
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
