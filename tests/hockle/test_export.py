"""hockle export: the VTK series reads back with meshio and carries the fields, each named
with its frame: a run's vectors along the directors (``_body``) and turned into the global
frame by the node frames (``_global``), the radius per node; a branch's shapes as a series
over its points; what cannot be exported is refused in one line."""
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
        np.testing.assert_allclose(mesh.point_data["kappa_body"], ds["kappa"].values[i])
        # the identity frames of this dataset: global and body components agree
        np.testing.assert_allclose(mesh.point_data["kappa_global"], ds["kappa"].values[i])
        np.testing.assert_allclose(mesh.point_data["v_global"], ds["v"].values[i])
        assert "kappa" not in mesh.point_data and "v" not in mesh.point_data
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
    np.testing.assert_allclose(mesh.point_data["kappa_body"][:, 0], 3.0 + _result()["s"].values)
    assert main(["export", str(tmp_path / "missing.nc")]) == 2
    assert "cannot read" in capsys.readouterr().err


def _turned(ds: xr.Dataset) -> xr.Dataset:
    """``ds`` with each node's frame turned about z by an angle growing along s and in
    time, and about x by a fixed angle: a1, a2, a3 no longer the global axes."""
    from scipy.spatial.transform import Rotation

    out = ds.copy(deep=True)
    t, s = ds["time"].values, ds["s"].values
    angle = 0.7 * s[None, :] + 2.0 * t[:, None]
    rot = Rotation.from_euler("x", 0.4) * Rotation.from_euler("z", angle.ravel()[:, None])
    xyzw = rot.as_quat()                                  # scalar last
    q = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1).reshape(*angle.shape, 4)
    out["orientation"].values[...] = q
    return out, rot.as_matrix().reshape(*angle.shape, 3, 3)


def test_vectors_are_turned_into_the_global_frame_by_the_node_frames(tmp_path: Path):
    """v and κ read back: ``*_body`` the stored components, ``*_global`` R(q) times them,
    R the node's frame from ``orientation`` (scipy's rotation of the same quaternion)."""
    ds, matrices = _turned(_result())
    export_vtk(ds, tmp_path / "turned.pvd")
    for i, (_, frame) in enumerate(read_pvd(tmp_path / "turned.pvd")):
        mesh = meshio.read(frame)
        for name in ("v", "kappa"):
            body = ds[name].values[i]
            np.testing.assert_allclose(mesh.point_data[f"{name}_body"], body)
            expected = np.einsum("nij,nj->ni", matrices[i], body)
            np.testing.assert_allclose(mesh.point_data[f"{name}_global"], expected, atol=1e-12)
            assert not np.allclose(expected, body)          # the frame matters here
    # without orientation only the body components are written, under their frame's name
    export_vtk(ds.drop_vars("orientation"), tmp_path / "plain.pvd")
    mesh = meshio.read(read_pvd(tmp_path / "plain.pvd")[0][1])
    assert {"v_body", "kappa_body"} <= set(mesh.point_data)
    assert not any(name.endswith("_global") for name in mesh.point_data)


def test_a_real_runs_global_velocity_is_the_rate_of_its_positions(tmp_path: Path):
    """A twisted, pushed rod run by the solver with orientation stored: the exported
    ``v_global`` is d(position)/dt (central differences between outputs), which the
    body-frame components are not; ``radius`` is the case's diameter / 2 at every node."""
    from rodcases import tiny_spec
    from hockle.api import simulate

    spec = tiny_spec("turning", n_segments=8, dt=0.002, t_end=0.05, diameter=0.03)
    spec["boundary"]["start"]["rotation"][2] = {"angular_velocity": 3.0}
    spec["boundary"]["end"]["translation"][0] = {"force": 0.05}
    spec["output"] = {"fields": ["v", "omega", "f", "kappa", "position", "orientation"]}
    ds = simulate(spec)
    files = export_vtk(ds, tmp_path / "run.pvd")
    meshes = [meshio.read(f) for f in files[1:]]
    times = ds["time"].values
    dt = np.diff(times)
    k = int(np.argmax(np.abs(ds["v"].values).max(axis=(1, 2))[1:-1])) + 1
    assert dt[k - 1] == pytest.approx(dt[k])
    rate = (meshes[k + 1].points - meshes[k - 1].points) / (times[k + 1] - times[k - 1])
    v_global = meshes[k].point_data["v_global"]
    scale = np.abs(rate).max()
    assert scale > 1e-3
    np.testing.assert_allclose(v_global, rate, atol=0.02 * scale)
    assert not np.allclose(meshes[k].point_data["v_body"], rate, atol=0.02 * scale)
    np.testing.assert_allclose(meshes[k].point_data["radius"], 0.015)
    assert {"omega_global", "f_global", "kappa_global", "orientation", "s"} \
        <= set(meshes[k].point_data)


def _branch(tmp_path: Path) -> xr.Dataset:
    """A small branch dataset of the layout of solver.continuation.branch_dataset: five
    points, shapes stored at 0, 2 and 4 (NaN elsewhere)."""
    import json

    n_pts, s = 5, np.linspace(0.0, 1.0, 6)
    pos = np.full((n_pts, s.size, 3), np.nan)
    kap = np.full_like(pos, np.nan)
    for i in (0, 2, 4):
        pos[i] = 0.0
        pos[i, :, 2] = s
        pos[i, :, 0] = 0.1 * i * np.sin(np.pi * s)
        kap[i] = 0.0
        kap[i, :, 0] = i
    case = {"rod": {"length": 1.0, "diameter": {"s": [0.0, 1.0], "value": [0.02, 0.04]}}}
    return xr.Dataset(
        {"parameter": ("point", [-0.1, -0.2, -0.3, -0.25, -0.35],
                       {"path": "boundary.end.translation.2.force"}),
         "unstable_modes": ("point", np.array([0, 0, 2, 0, 1])),
         "position": (("point", "node", "xyz"), pos),
         "kappa": (("point", "node", "xyz"), kap)},
        coords={"point": np.arange(n_pts), "s": ("node", s), "xyz": ["x", "y", "z"]},
        attrs={"hockle_kind": "branch", "parameter_path": "boundary.end.translation.2.force",
               "case": json.dumps(case)})


def test_a_branch_exports_its_shapes_as_a_series_over_its_points(tmp_path: Path, capsys):
    ds = _branch(tmp_path)
    files = export_vtk(ds, tmp_path / "branch.pvd")
    entries = read_pvd(files[0])
    assert [t for t, _ in entries] == [0.0, 2.0, 4.0]        # the stored points, by index
    text = files[0].read_text()
    assert "point 2: boundary.end.translation.2.force = -0.3 N, 2 unstable mode(s)" in text
    for (t, frame), i in zip(entries, (0, 2, 4)):
        mesh = meshio.read(frame)
        np.testing.assert_allclose(mesh.points, ds["position"].values[i])
        np.testing.assert_allclose(mesh.point_data["parameter"], ds["parameter"].values[i])
        np.testing.assert_allclose(mesh.point_data["unstable_modes"], ds["unstable_modes"][i])
        np.testing.assert_allclose(mesh.point_data["kappa_body"][:, 0], i)
        np.testing.assert_allclose(mesh.point_data["radius"], 0.01 + 0.01 * ds["s"].values)
    assert [t for t, _ in read_pvd(export_vtk(ds, tmp_path / "b2.pvd", stride=2)[0])] == [0.0, 4.0]
    with pytest.raises(ExportError, match="a branch is a series"):
        export_vtk(ds, tmp_path / "x.pvd", window=(0.0, 1.0))
    empty = ds.copy(deep=True)
    empty["position"].values[...] = np.nan
    with pytest.raises(ExportError, match="no shape"):
        export_vtk(empty, tmp_path / "x.pvd")
    # the command line: the same series, and the refusals in one line
    nc = tmp_path / "branch.nc"
    ds.to_netcdf(nc)
    assert main(["export", str(nc), "-o", str(tmp_path / "cli.pvd"), "-q"]) == 0
    assert "cli.pvd (3 frames)" in capsys.readouterr().out
    assert main(["export", str(nc), "--times", "0", "1", "-o", str(tmp_path / "y.pvd")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a branch is a series" in err
