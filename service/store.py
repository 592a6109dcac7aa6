"""The result store: a directory of NetCDF files keyed by job id.

Workers write ``<id>.nc.tmp-<host>-<pid>`` and rename it to ``<id>.nc`` (``os.replace`` is atomic
on one file system), so a reader never sees a half-written file. A job's second and later attempts
(after a lost worker) write ``<id>.attempt-<n>.nc``: an attempt that was given up but still runs
somewhere can never replace the file of the attempt that finished the job (the registry's
``result_path`` names the one that counts). When workers run on several machines the directory is
a shared (ReadWriteMany) volume mounted at the same path everywhere. A running job's latest
solver checkpoint is ``<id>.ckpt`` (written the same atomic way); a re-run continues from it.
"""
from __future__ import annotations

import os
import re
import socket
import tempfile
import threading
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

__all__ = ["NETCDF_LOCK", "ResultStore", "open_result"]

#: netCDF4-C and HDF5 are not thread-safe, and the API's routes run in a thread pool: every
#: NetCDF open, read and write in an API process holds this lock for its whole duration
#: (concurrent result reads without it crashed the API process or answered 500 with
#: "NetCDF: Can't open HDF5 attribute"; tests/service/test_concurrent_reads.py).
NETCDF_LOCK = threading.RLock()


@contextmanager
def open_result(path: str | os.PathLike, **kwargs: Any) -> Iterator[Any]:
    """An ``xarray.Dataset`` of the NetCDF file at ``path`` (netcdf4 engine), open while
    :data:`NETCDF_LOCK` is held; read what is needed inside the ``with`` block.

    Raises whatever ``xarray.open_dataset`` raises (``FileNotFoundError``, ``OSError``)."""
    import xarray as xr

    with NETCDF_LOCK, xr.open_dataset(path, engine="netcdf4", **kwargs) as ds:
        yield ds

_ID = re.compile(r"^[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}$")


class ResultStore:
    def __init__(self, root: str | os.PathLike):
        self.root = Path(root)

    def ensure(self) -> None:
        self.root.mkdir(parents=True, exist_ok=True)

    def path_for(self, job_id: str, attempt: int | None = None) -> Path:
        """``<id>.nc`` for the first attempt (or none given), ``<id>.attempt-<n>.nc`` after."""
        if not _ID.match(job_id):
            raise ValueError(f"not a job id: {job_id!r}")
        if attempt is None or attempt <= 1:
            return self.root / f"{job_id}.nc"
        return self.root / f"{job_id}.attempt-{int(attempt)}.nc"

    def _atomic(self, final: Path, write) -> Path:
        """Write ``final`` atomically: ``write(tmp)`` to a temporary name in the same
        directory, fsync, rename (os.replace), so a reader or a crash never sees half a
        file; the temporary file is removed on failure."""
        self.ensure()
        tmp = final.with_name(f"{final.name}.tmp-{socket.gethostname()}-{os.getpid()}")
        try:
            write(tmp)
            with open(tmp, "rb") as fh:
                os.fsync(fh.fileno())
            os.replace(tmp, final)
        finally:
            if tmp.exists():
                tmp.unlink()
        return final

    def write_dataset(self, job_id: str, ds, attempt: int | None = None) -> Path:
        """Write an xarray.Dataset as NetCDF4 under a temporary name, then rename it to
        :meth:`path_for` ``(job_id, attempt)``."""
        def write(tmp):
            with NETCDF_LOCK:
                ds.to_netcdf(tmp, engine="netcdf4")

        return self._atomic(self.path_for(job_id, attempt), write)

    def checkpoint_path(self, job_id: str) -> Path:
        """``<id>.ckpt``: the job's latest solver checkpoint (solver.checkpoint)."""
        if not _ID.match(job_id):
            raise ValueError(f"not a job id: {job_id!r}")
        return self.root / f"{job_id}.ckpt"

    def write_checkpoint(self, job_id: str, data: bytes) -> Path:
        """Replace the job's checkpoint atomically (as :meth:`write_dataset`): a worker
        killed while writing leaves the previous checkpoint intact."""
        return self._atomic(self.checkpoint_path(job_id), lambda tmp: tmp.write_bytes(data))

    def read_checkpoint(self, job_id: str) -> bytes | None:
        """The job's checkpoint bytes, or None when it has none."""
        try:
            return self.checkpoint_path(job_id).read_bytes()
        except FileNotFoundError:
            return None

    def discard_checkpoint(self, job_id: str) -> None:
        """Remove the job's checkpoint (the job has finished)."""
        try:
            self.checkpoint_path(job_id).unlink()
        except FileNotFoundError:
            pass

    def discard(self, path: str | os.PathLike) -> None:
        """Remove a result file this store wrote (an attempt that did not finish the job)."""
        path = Path(path)
        if path.resolve().parent != self.root.resolve():
            raise ValueError(f"{path} is not in the result store {self.root}")
        try:
            path.unlink()
        except FileNotFoundError:
            pass

    def check_writable(self) -> None:
        """Raise OSError when files cannot be created in the store."""
        self.ensure()
        with tempfile.NamedTemporaryFile(dir=self.root, prefix=".health-"):
            pass
