"""Export a result file to ParaView: a VTK time series of the rod's centreline.

    hockle export goyal.nc -o goyal.pvd            # goyal.pvd + goyal/goyal_00000.vtu ...

Each output time becomes one VTK unstructured grid (``.vtu``, written by meshio): the
grid points of the centreline (``position``, m, global frame) joined by line cells, one
per segment, with every per-node field of the result as point data (``v``, ``omega``,
``f``, ``kappa``, ``moment`` with their body-frame components a1, a2, a3, ``orientation``
as a scalar-first quaternion, and the arclength ``s``). The run's scalar series
(energies, twist, writhe, ...) stay in the NetCDF file: meshio's VTU writer does not
write VTK field data. A ParaView data collection (``.pvd``) lists the files with their times, so ParaView
opens the run as one time series (File > Open the ``.pvd``; a Tube filter with the
rod's diameter shows it as a cable). Per-node fields that a result does not carry (a
run without ``kappa`` output, contact forces, which the result dataset does not store)
are not invented: whatever (time, s, ...) variables the file holds are exported.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import xarray as xr

__all__ = ["export_vtk", "read_pvd", "ExportError"]


class ExportError(ValueError):
    """The result cannot be exported (no positions, no outputs in the time window)."""


def _node_fields(ds: xr.Dataset, i: int) -> dict[str, np.ndarray]:
    """Per-node arrays at output i: (N,) or (N, k) float64, one per (time, s, ...) variable."""
    out: dict[str, np.ndarray] = {"s": np.asarray(ds["s"].values, dtype=float)}
    for name, var in ds.data_vars.items():
        if var.dims[:2] != ("time", "s") or name == "position":
            continue
        values = np.asarray(var.isel(time=i).values, dtype=float)
        out[name] = values.reshape(values.shape[0], -1) if values.ndim > 1 else values
    return out


def export_vtk(ds: xr.Dataset, out: str | Path, *, stride: int = 1,
               window: Sequence[float] | None = None,
               progress: Callable[[int, int], None] | None = None) -> list[Path]:
    """Write a result dataset as a ParaView time series; returns the files written.

    Parameters
    ----------
    ds : xarray.Dataset
        A result of :func:`hockle.api.simulate` or ``hockle run`` (``hockle.io.open_result``);
        it must hold ``position`` (time, s, xyz) in m.
    out : path
        The ``.pvd`` collection to write; the frames go to ``<stem>/<stem>_NNNNN.vtu``
        beside it (``.vtu`` alone: the first frame only, one file).
    stride : int
        Keep every ``stride``-th output time (the last one always), ≥ 1.
    window : (t0, t1), optional
        Only the outputs with t0 <= t <= t1 (s).
    progress : callable(done, total), optional
        Called after each frame.

    Returns
    -------
    list of Path
        The ``.pvd`` file first, then the ``.vtu`` frames.

    Raises
    ------
    ExportError
        No ``position`` variable, no output in the window, a stride below 1 or a suffix
        other than ``.pvd`` or ``.vtu``.
    OSError
        A file that cannot be written.
    """
    import meshio

    out = Path(out)
    if out.suffix not in (".pvd", ".vtu"):
        raise ExportError(f"{out}: the output must end in .pvd (a time series) or .vtu "
                          "(one frame)")
    if "position" not in ds:
        raise ExportError("the result has no 'position' variable (output.fields without "
                          "position): nothing to draw")
    if stride < 1:
        raise ExportError(f"stride must be >= 1, got {stride}")
    times = np.asarray(ds["time"].values, dtype=float)
    index = np.arange(times.size)
    if window is not None:
        t0, t1 = window
        index = index[(times >= t0) & (times <= t1)]
    if index.size == 0:
        raise ExportError("no output time in the window" if window is not None
                          else "the result has no output times")
    keep = index[::stride]
    if keep[-1] != index[-1]:
        keep = np.append(keep, index[-1])
    if out.suffix == ".vtu":
        keep = keep[:1]

    n_nodes = ds.sizes["s"]
    cells = [("line", np.column_stack([np.arange(n_nodes - 1), np.arange(1, n_nodes)]))]
    frame_dir = out.with_suffix("") if out.suffix == ".pvd" else out.parent
    frame_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for k, i in enumerate(keep):
        points = np.asarray(ds["position"].isel(time=int(i)).values, dtype=float)
        mesh = meshio.Mesh(points, cells, point_data=_node_fields(ds, int(i)))
        path = out if out.suffix == ".vtu" else frame_dir / f"{out.stem}_{k:05d}.vtu"
        meshio.write(path, mesh, file_format="vtu")
        written.append(path)
        if progress is not None:
            progress(k + 1, keep.size)
    if out.suffix == ".vtu":
        return written

    root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    collection = ET.SubElement(root, "Collection")
    for i, path in zip(keep, written):
        ET.SubElement(collection, "DataSet", timestep=repr(float(times[i])), group="",
                      part="0", file=path.relative_to(out.parent).as_posix())
    ET.indent(root)
    ET.ElementTree(root).write(out, encoding="utf-8", xml_declaration=True)
    return [out, *written]


def read_pvd(path: str | Path) -> list[tuple[float, Path]]:
    """The (time in s, frame file) entries of a ``.pvd`` collection, in order."""
    path = Path(path)
    root = ET.parse(path).getroot()
    return [(float(d.get("timestep")), path.parent / d.get("file"))
            for d in root.iter("DataSet")]
