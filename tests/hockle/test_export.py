"""hockle export: the VTK time series reads back with meshio and carries the fields."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import xarray as xr

meshio = pytest.importorskip("meshio")

from hockle.cli import main  # noqa: E402
from hockle.export import ExportError, export_vtk, read_pvd  # noqa: E402


def _result(n_nodes: int = 6, n_times: int = 4) -> xr.Dataset:
    """A small result dataset with the layout of solver.results (no solver run needed):
    a rod along z bending in x, κ1 growing with time."""
    t = np.linspace(0.0, 0.3, n_times)
    s = np.linspace(0.0, 1.0, n_nodes)
    position = np.zeros((n_times, n_nodes, 3))
    position[:, :, 2] = s
    position[:, :, 0] = t[:, None] * s[None, :] ** 2
    kappa = np.zeros((n_times, n_nodes, 3))
    kappa[:, :, 0] = 10 * t[:, None] + s[None, :]
    kappa[:, :, 2] = 0.5
    v = np.random.default_rng(0).normal(size=(n_times, n_nodes, 3))
    orientation = np.zeros((n_times, n_nodes, 4))
    orientation[..., 0] = 1.0
    return xr.Dataset(
        {
            "position": (("time", "s", "xyz"), position, {"units": "m"}),
            "kappa": (("time", "s", "component"), kappa, {"units": "rad m-1"}),
            "v": (("time", "s", "component"), v, {"units": "m s-1"}),
            "orientation": (("time", "s", "quaternion"), orientation, {"units": "1"}),
            "writhe": (("time",), 0.1 * t, {"units": "1"}),
            "contact_count": (("time",), np.arange(n_times, dtype=np.int32)),
        },
        coords={"time": t, "s": s, "xyz": [1, 2, 3], "component": [1, 2, 3],
                "quaternion": [0, 1, 2, 3]},
    )


def test_export_reads_back_with_fields(tmp_path: Path):
    ds = _result()
    files = export_vtk(ds, tmp_path / "run.pvd")
    assert files[0] == tmp_path / "run.pvd" and len(files) == 1 + ds.sizes["time"]
    entries = read_pvd(tmp_path / "run.pvd")
    assert [t for t, _ in entries] == pytest.approx(ds["time"].values)
    for i, (t, frame) in enumerate(entries):
        mesh = meshio.read(frame)
        np.testing.assert_allclose(mesh.points, ds["position"].values[i])
        np.testing.assert_allclose(mesh.point_data["kappa"], ds["kappa"].values[i])
        np.testing.assert_allclose(mesh.point_data["s"], ds["s"].values)
        assert mesh.point_data["orientation"].shape == (ds.sizes["s"], 4)
        lines = mesh.cells_dict["line"]
        assert lines.shape == (ds.sizes["s"] - 1, 2) and lines[-1].tolist() == [4, 5]
        assert "writhe" not in mesh.point_data      # the (time,) series stay in the .nc


def test_export_stride_window_and_single_frame(tmp_path: Path):
    ds = _result(n_times=7)
    files = export_vtk(ds, tmp_path / "a.pvd", stride=3)
    times = [t for t, _ in read_pvd(files[0])]
    assert times == pytest.approx(ds["time"].values[[0, 3, 6]])
    files = export_vtk(ds, tmp_path / "b.pvd", window=(0.09, 0.21))
    assert [t for t, _ in read_pvd(files[0])] == pytest.approx([0.1, 0.15, 0.2])
    one = export_vtk(ds, tmp_path / "c.vtu")
    assert one == [tmp_path / "c.vtu"]
    np.testing.assert_allclose(meshio.read(one[0]).points, ds["position"].values[0])


def test_export_refuses_what_it_cannot_draw(tmp_path: Path):
    with pytest.raises(ExportError, match="position"):
        export_vtk(_result().drop_vars("position"), tmp_path / "x.pvd")
    with pytest.raises(ExportError, match=r"\.pvd"):
        export_vtk(_result(), tmp_path / "x.vtk")
    with pytest.raises(ExportError, match="window"):
        export_vtk(_result(), tmp_path / "x.pvd", window=(5.0, 6.0))


def test_cli_export(tmp_path: Path, capsys):
    nc = tmp_path / "run.nc"
    _result().to_netcdf(nc)
    assert main(["export", str(nc), "-o", str(tmp_path / "out.pvd"), "-q"]) == 0
    assert "out.pvd (4 frames)" in capsys.readouterr().out
    mesh = meshio.read(read_pvd(tmp_path / "out.pvd")[-1][1])
    np.testing.assert_allclose(mesh.point_data["kappa"][:, 0], 3.0 + _result()["s"].values)
    assert main(["export", str(tmp_path / "missing.nc")]) == 2
    assert "cannot read" in capsys.readouterr().err
