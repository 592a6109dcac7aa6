"""Export a result file to ParaView: a VTK series of the rod's centreline.

    hockle export goyal.nc -o goyal.pvd            # goyal.pvd + goyal/goyal_00000.vtu ...
    hockle export branch.nc -o branch.pvd          # a continuation's shapes over its parameter

**A run** (dimension ``time``): each output time becomes one VTK unstructured grid
(``.vtu``, written by meshio): the grid points of the centreline (``position``, m, global
frame) joined by line cells, one per segment, with the per-node fields as point data, each
name saying its frame:

* ``v_body``, ``omega_body``, ``f_body``, ``kappa_body``, ``moment_body``: the stored
  components along the directors a1, a2, a3 (a3 the tangent: ``kappa_body`` 3 is the twist
  rate, ``f_body`` 3 the tension);
* ``v_global``, ``omega_global``, ``f_global``, ``kappa_global``, ``moment_global``: the same
  vectors turned into the global frame x, y, z by each node's frame (x_global = R(q) x_body,
  ``orientation``), the ones ParaView's glyphs and stream tools expect; written when the
  result stores ``orientation`` (``output.fields``; the default fields do not);
* ``orientation`` (scalar-first unit quaternion), ``s`` (m) and ``radius`` (m, the case's
  ``rod.diameter`` / 2 at each node: a Tube filter with *Vary Radius* by this scalar, in
  absolute mode, draws the cable at its real thickness).

The run's scalar series (energies, twist, writhe, ...) stay in the NetCDF file: meshio's VTU
writer does not write VTK field data. A ParaView data collection (``.pvd``) lists the files
with their times, so ParaView opens the run as one time series.

**A branch** (``hockle continue``, a continuation job; dimension ``point``): each stored
shape becomes one ``.vtu`` (``position``, with ``kappa_body``, ``s``, ``radius`` and, the
same at every node, ``parameter``, ``unstable_modes`` and ``stable``), and the ``.pvd``
lists them with the point's index as its time step (the parameter can go back and forth
along a branch, through folds and after a switch, and ParaView orders time steps by value);
an XML comment before each entry names its parameter value. A branch without stored shapes,
or asked for a time window, is refused with the reason (:class:`ExportError`).

Per-node fields that a result does not carry (a run without ``kappa`` output, contact
forces, which the result dataset does not store) are not invented.
"""
from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import xarray as xr

__all__ = ["export_vtk", "read_pvd", "ExportError", "BODY_VECTORS", "global_frame"]

#: the (time, s, component) vectors of a run, stored along the directors a1, a2, a3
BODY_VECTORS = ("v", "omega", "f", "kappa", "moment")


class ExportError(ValueError):
    """The result cannot be exported (no positions, no outputs in the time window, a
    branch without stored shapes, not a hockle result): the message says why, in one line."""


def _rotation(q: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions, scalar first -> (N, 3, 3) rotation matrices, body -> global
    (the columns are a1, a2, a3: solver.kinematics.quat_to_matrix)."""
    q = np.asarray(q, float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], axis=-2)


def global_frame(orientation: np.ndarray, body: np.ndarray) -> np.ndarray:
    """Body-frame components (N, 3) turned into the global frame by the node frames
    ``orientation`` (N, 4, scalar first): R(q_n) @ body_n."""
    return np.einsum("nij,nj->ni", _rotation(orientation), np.asarray(body, float))


def _radius(ds: xr.Dataset, s: np.ndarray) -> np.ndarray | None:
    """The rod's radius (m) at arclengths ``s`` from the case's ``rod.diameter`` (a number,
    or a profile interpolated and held outside), or None without a readable case."""
    try:
        d = json.loads(str(ds.attrs["case"]))["rod"]["diameter"]
        if isinstance(d, dict):
            return 0.5 * np.interp(s, np.asarray(d["s"], float), np.asarray(d["value"], float))
        return np.full(s.shape, 0.5 * float(d))
    except (KeyError, TypeError, ValueError):
        return None


def _node_fields(ds: xr.Dataset, i: int, s: np.ndarray,
                 radius: np.ndarray | None) -> dict[str, np.ndarray]:
    """Per-node arrays at output i: (N,) or (N, k) float64, named with their frame."""
    out: dict[str, np.ndarray] = {"s": s}
    if radius is not None:
        out["radius"] = radius
    q = (np.asarray(ds["orientation"].isel(time=i).transpose("s", "quaternion").values, float)
         if "orientation" in ds else None)
    for name, var in ds.data_vars.items():
        if var.dims[:2] != ("time", "s") or name == "position":
            continue
        values = np.asarray(var.isel(time=i).values, dtype=float)
        values = values.reshape(values.shape[0], -1) if values.ndim > 1 else values
        if name in BODY_VECTORS and values.ndim == 2 and values.shape[1] == 3:
            out[f"{name}_body"] = values
            if q is not None:
                out[f"{name}_global"] = global_frame(q, values)
        else:
            out[str(name)] = values
    return out


def _keep(index: np.ndarray, stride: int) -> np.ndarray:
    keep = index[::stride]
    if keep[-1] != index[-1]:
        keep = np.append(keep, index[-1])
    return keep


def export_vtk(ds: xr.Dataset, out: str | Path, *, stride: int = 1,
               window: Sequence[float] | None = None,
               progress: Callable[[int, int], None] | None = None) -> list[Path]:
    """Write a result dataset (a run, or a continuation's branch) as a ParaView series;
    returns the files written.

    Parameters
    ----------
    ds : xarray.Dataset
        A result of :func:`hockle.api.simulate` or ``hockle run`` (``hockle.io.open_result``)
        holding ``position`` (time, s, xyz) in m, or a branch of ``hockle continue``
        (:func:`hockle.api.continue_branch`) holding shapes, ``position`` (point, node, xyz).
    out : path
        The ``.pvd`` collection to write; the frames go to ``<stem>/<stem>_NNNNN.vtu``
        beside it (``.vtu`` alone: the first frame only, one file).
    stride : int
        Keep every ``stride``-th output time (of a branch: stored shape), the last one
        always, ≥ 1.
    window : (t0, t1), optional
        Only the outputs with t0 <= t <= t1 (s); a run only.
    progress : callable(done, total), optional
        Called after each frame.

    Returns
    -------
    list of Path
        The ``.pvd`` file first, then the ``.vtu`` frames.

    Raises
    ------
    ExportError
        No ``position`` variable, no output in the window, a stride below 1, a suffix other
        than ``.pvd`` or ``.vtu``, a branch without stored shapes or with a window, a
        dataset that is neither a run nor a branch (a sweep's combined file).
    OSError
        A file that cannot be written.
    """
    out = Path(out)
    if out.suffix not in (".pvd", ".vtu"):
        raise ExportError(f"{out}: the output must end in .pvd (a series) or .vtu "
                          "(one frame)")
    if stride < 1:
        raise ExportError(f"stride must be >= 1, got {stride}")
    from .branch_view import is_branch

    if is_branch(ds):
        return _export_branch(ds, out, stride=stride, window=window, progress=progress)
    if "member" in ds.dims or "hockle_sweep_combine" in ds.attrs:
        raise ExportError("this is a sweep's combined file (one run per member): export a "
                          "member's own result, e.g. ds.isel(member=0) of it or the member "
                          "job's file")
    if "time" not in ds.dims:
        raise ExportError("not a hockle result: neither a run (dimension time) nor a "
                          "branch (dimension point)")
    if "position" not in ds:
        raise ExportError("the result has no 'position' variable (output.fields without "
                          "position): nothing to draw")
    times = np.asarray(ds["time"].values, dtype=float)
    index = np.arange(times.size)
    if window is not None:
        t0, t1 = window
        index = index[(times >= t0) & (times <= t1)]
    if index.size == 0:
        raise ExportError("no output time in the window" if window is not None
                          else "the result has no output times")
    keep = _keep(index, stride)
    if out.suffix == ".vtu":
        keep = keep[:1]
    s = np.asarray(ds["s"].values, dtype=float)
    radius = _radius(ds, s)

    def frame(i: int):
        points = np.asarray(ds["position"].isel(time=int(i)).transpose("s", "xyz").values,
                            dtype=float)
        return points, _node_fields(ds, int(i), s, radius)

    return _write_series(out, keep, frame, [(repr(float(times[i])), None) for i in keep],
                         progress)


def _export_branch(ds: xr.Dataset, out: Path, *, stride: int, window, progress) -> list[Path]:
    """A branch's stored shapes as a series over its points (module docstring)."""
    if window is not None:
        raise ExportError("a time window selects output times of a run; a branch is a "
                          "series of equilibria over its parameter (choose with the stride)")
    if "position" not in ds:
        raise ExportError("the branch stores no shapes (no 'position' variable): nothing "
                          "to draw")
    r = np.asarray(ds["position"].transpose("point", "node", "xyz").values, float)
    stored = np.flatnonzero(np.all(np.isfinite(r.reshape(r.shape[0], -1)), axis=1))
    if stored.size == 0:
        raise ExportError("the branch stores no shape at any point (position is NaN "
                          "everywhere): nothing to draw")
    keep = _keep(stored, stride)
    if out.suffix == ".vtu":
        keep = keep[:1]
    s = np.asarray(ds["s"].values, float)
    radius = _radius(ds, s)
    lam = np.asarray(ds["parameter"].values, float)
    path = str(ds.attrs.get("parameter_path") or ds["parameter"].attrs.get("path") or
               "parameter")
    from .branch_view import parameter_unit

    unit = parameter_unit(path)
    modes = (np.asarray(ds["unstable_modes"].values, float) if "unstable_modes" in ds
             else np.full(lam.size, np.nan))
    kappa = (np.asarray(ds["kappa"].transpose("point", "node", "xyz").values, float)
             if "kappa" in ds else None)
    ones = np.ones(s.size)

    def frame(i: int):
        fields = {"s": s}
        if radius is not None:
            fields["radius"] = radius
        if kappa is not None:
            fields["kappa_body"] = kappa[i]
        fields["parameter"] = lam[i] * ones
        fields["unstable_modes"] = modes[i] * ones
        fields["stable"] = (modes[i] == 0) * ones
        return r[i], fields

    def comment(i: int) -> str:
        text = f" point {i}: {path} = {float(lam[i])!r} {unit}".rstrip()
        return text + (f", {int(modes[i])} unstable mode(s) " if np.isfinite(modes[i]) else " ")

    labels = [(str(int(i)), comment(int(i))) for i in keep]
    return _write_series(out, keep, frame, labels, progress)


def _write_series(out: Path, keep, frame, labels, progress) -> list[Path]:
    """Write one .vtu per index of ``keep`` (``frame(i)`` -> points, point data) and, for a
    ``.pvd``, the collection with ``labels`` (time step, comment or None) per frame."""
    import meshio

    frame_dir = out.with_suffix("") if out.suffix == ".pvd" else out.parent
    frame_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for k, i in enumerate(keep):
        points, data = frame(int(i))
        n = points.shape[0]
        cells = [("line", np.column_stack([np.arange(n - 1), np.arange(1, n)]))]
        mesh = meshio.Mesh(points, cells, point_data=data)
        path = out if out.suffix == ".vtu" else frame_dir / f"{out.stem}_{k:05d}.vtu"
        meshio.write(path, mesh, file_format="vtu")
        written.append(path)
        if progress is not None:
            progress(k + 1, len(keep))
    if out.suffix == ".vtu":
        return written

    root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    collection = ET.SubElement(root, "Collection")
    for (step, comment), path in zip(labels, written):
        if comment:
            collection.append(ET.Comment(comment.replace("--", "-")))
        ET.SubElement(collection, "DataSet", timestep=step, group="", part="0",
                      file=path.relative_to(out.parent).as_posix())
    ET.indent(root)
    ET.ElementTree(root).write(out, encoding="utf-8", xml_declaration=True)
    return [out, *written]


def read_pvd(path: str | Path) -> list[tuple[float, Path]]:
    """The (time step, frame file) entries of a ``.pvd`` collection, in order (a run's
    times in s; a branch's point indices)."""
    path = Path(path)
    root = ET.parse(path).getroot()
    return [(float(d.get("timestep")), path.parent / d.get("file"))
            for d in root.iter("DataSet")]
