"""Tests for solver.results.build_dataset and hockle.io.write_netcdf (the result dataset
of docs/interfaces.md, "The result dataset" and "solver.results")."""
from __future__ import annotations

import datetime as dt
import json
import os
import stat

import numpy as np
import pytest

from rodcases import tiny_spec
import solver
from hockle.io import open_result, write_netcdf
from solver.case import Case
from solver.results import build_dataset

T, N, K = 6, 9, 11

TINY = tiny_spec("results-test", n_segments=N - 1)

# The contract, written out independently of the module's own table:
# name -> (dims, units)
EXPECTED = {
    "v": (("time", "s", "component"), "m s-1"),
    "omega": (("time", "s", "component"), "rad s-1"),
    "f": (("time", "s", "component"), "N"),
    "kappa": (("time", "s", "component"), "rad m-1"),
    "moment": (("time", "s", "component"), "N m"),
    "position": (("time", "s", "xyz"), "m"),
    "orientation": (("time", "s", "quaternion"), "1"),
    "energy_bending": (("time",), "J"),
    "energy_torsion": (("time",), "J"),
    "energy_kinetic": (("time",), "J"),
    "energy_kinetic_fluid": (("time",), "J"),
    "energy_total": (("time",), "J"),
    "work_in": (("time",), "J"),
    "power_in": (("time",), "W"),
    "twist": (("time",), "1"),
    "writhe": (("time",), "1"),
    "linking_number": (("time",), "1"),
    "topology_error": (("time",), "1"),
    "writhe_closure_passages": (("time",), "1"),
    "contact_count": (("time",), "1"),
    "min_surface_gap": (("time",), "m"),
    "newton_iterations": (("time",), "1"),
    "residual_norm": (("time",), "1"),
    "dt": (("time",), "s"),
    "position_route_difference": (("time",), "m"),
    "end_drift": (("time",), "m"),
    "quaternion_norm_error": (("time",), "1"),
}
EXPECTED_DIAG = {
    "step_time": "s",
    "step_dt": "s",
    "step_newton_iterations": "1",
    "step_residual_norm": "1",
    "step_growth_rate": "s-1",
}
SIZES = {"time": T, "s": N, "component": 3, "xyz": 3, "quaternion": 4}


@pytest.fixture(scope="module")
def case():
    return Case.model_validate(TINY)


def synthetic(seed: int = 0):
    rng = np.random.default_rng(seed)
    fields = {}
    for name, (dims, _) in EXPECTED.items():
        fields[name] = rng.standard_normal(tuple(SIZES[d] for d in dims))
    fields["contact_count"] = rng.integers(0, 5, T)
    fields["newton_iterations"] = rng.integers(1, 6, T)
    diagnostics = {
        "step_time": np.linspace(0.01, 0.05, K),
        "step_dt": np.full(K, 0.01),
        "step_newton_iterations": rng.integers(1, 6, K),
        "step_residual_norm": rng.random(K) * 1e-10,
        "step_growth_rate": rng.random(K),
    }
    s = np.linspace(0.0, 1.0, N)
    times = np.linspace(0.0, 0.05, T)
    return s, times, fields, diagnostics


@pytest.fixture()
def full(case):
    s, times, fields, diagnostics = synthetic()
    ds = build_dataset(case, s, times, fields, diagnostics, "completed", "all done")
    return ds, s, times, fields, diagnostics


def test_dimensions_coordinates_and_variable_shapes(full):
    ds, s, times, fields, diagnostics = full
    assert dict(ds.sizes) == {**SIZES, "step": K}
    np.testing.assert_array_equal(ds["time"].values, times)
    np.testing.assert_array_equal(ds["s"].values, s)
    assert list(ds["component"].values) == [1, 2, 3]
    # integer index coordinates, named by CF flag_values / flag_meanings (no strings)
    assert list(ds["xyz"].values) == [1, 2, 3]
    assert ds["xyz"].attrs["flag_meanings"] == "x y z"
    assert list(ds["xyz"].attrs["flag_values"]) == [1, 2, 3]
    assert list(ds["quaternion"].values) == [0, 1, 2, 3]
    assert ds["quaternion"].attrs["flag_meanings"] == "w x y z"
    assert list(ds["quaternion"].attrs["flag_values"]) == [0, 1, 2, 3]
    assert ds["component"].attrs["flag_meanings"] == "a1 a2 a3"
    for name in ("component", "xyz", "quaternion"):
        assert ds[name].dtype == np.int32, name
    assert list(ds["step"].values) == list(range(1, K + 1))
    assert ds["time"].attrs["units"] == "s" and ds["s"].attrs["units"] == "m"
    for name, (dims, _) in EXPECTED.items():
        assert ds[name].dims == dims, name
        np.testing.assert_array_equal(ds[name].values, fields[name])
    for name in EXPECTED_DIAG:
        assert ds[name].dims == ("step",), name
        np.testing.assert_array_equal(ds[name].values, diagnostics[name])
    # step_time is the coordinate-like time axis of the step dimension
    assert "step_time" in ds.coords


def test_every_variable_has_units_and_long_name(full):
    ds = full[0]
    names = set(ds.data_vars) | set(ds.coords)
    assert set(EXPECTED) | set(EXPECTED_DIAG) <= names
    for name in ds.data_vars:
        attrs = ds[name].attrs
        assert attrs.get("long_name"), name
        expected = EXPECTED[name][1] if name in EXPECTED else EXPECTED_DIAG[name]
        assert attrs.get("units") == expected, name
    for name in ds.coords:
        assert ds[name].attrs.get("long_name"), name
        if ds[name].dtype.kind in "iuf":
            assert "units" in ds[name].attrs, name
    assert ds["step_time"].attrs["units"] == "s"


def test_standard_names_only_where_cf_has_one(full):
    ds = full[0]
    # time is CF's "time" (axis T, elapsed seconds); none of the rod quantities has a CF
    # standard name, so none is invented.
    assert ds["time"].attrs["standard_name"] == "time"
    assert ds["time"].attrs["axis"] == "T" and ds["time"].attrs["units"] == "s"
    for name in list(ds.data_vars) + list(ds.coords):
        if name != "time":
            assert "standard_name" not in ds[name].attrs, name


def test_every_variable_has_a_coverage_content_type(full):
    ds = full[0]
    quality = {"topology_error", "newton_iterations", "residual_norm",
               "position_route_difference", "end_drift", "quaternion_norm_error",
               "step_newton_iterations", "step_residual_norm"}
    auxiliary = {"dt", "step_dt", "step_growth_rate"}
    for name in ds.data_vars:
        expected = ("qualityInformation" if name in quality else
                    "auxiliaryInformation" if name in auxiliary else "modelResult")
        assert ds[name].attrs["coverage_content_type"] == expected, name
    for name in ds.coords:
        assert ds[name].attrs["coverage_content_type"] == "coordinate", name
    # CF ancillary links from a variable to the indicators of its quality
    assert (ds["position"].attrs["ancillary_variables"]
            == "position_route_difference end_drift")
    assert ds["orientation"].attrs["ancillary_variables"] == "quaternion_norm_error"
    assert ds["writhe"].attrs["ancillary_variables"] == "topology_error writhe_closure_passages"


def test_global_attributes(full, case):
    ds = full[0]
    a = ds.attrs
    assert a["Conventions"] == "CF-1.12, ACDD-1.3"
    assert a["title"] == "results-test"
    assert a["summary"]
    assert a["id"] == case.spec_hash() and " " not in a["id"]
    assert "writhe" in a["keywords"] and "self-contact" in a["keywords"]
    assert a["product_version"] == solver.__version__
    assert a["time_coverage_duration"] == "PT0.05S"
    assert a["time_coverage_resolution"] == "PT0.01S"
    # simulated time has no calendar epoch: no time_coverage_start/end instants
    assert "time_coverage_start" not in a and "time_coverage_end" not in a
    for key in ("date_created", "date_modified", "date_metadata_modified"):
        assert dt.datetime.fromisoformat(a[key]).tzinfo is not None, key
    # the operator's attributes: defaults that say so until the operator sets them
    assert "HOCKLE_LICENSE" in a["license"] and "HOCKLE_CREATOR_NAME" in a["creator_name"]
    assert a["naming_authority"] == "hockle"
    assert a["source"] == f"hockle {solver.__version__}"
    assert "created by hockle" in a["history"]
    stamp = a["history"].split()[0]
    assert dt.datetime.fromisoformat(stamp).tzinfo is not None
    assert dt.datetime.fromisoformat(a["date_created"]).tzinfo is not None
    assert "Goyal" in a["references"] and "Perkins" in a["references"]
    assert "Writhing dynamics of cables with self-contact" in a["references"]
    assert a["case"] == case.canonical_json()
    assert a["case_hash"] == case.spec_hash()
    # the file alone reproduces its run: the spec round-trips to the same hash
    assert Case.model_validate(json.loads(a["case"])).spec_hash() == case.spec_hash()
    assert a["hockle_status"] == "completed"
    assert a["hockle_message"] == "all done"


def test_extra_attributes_and_status_values(case):
    s, times, fields, _ = synthetic()
    ds = build_dataset(
        case, s, times, fields, {}, "stopped", "budget", attrs={"hockle_stop_reason": "timeout"}
    )
    assert ds.attrs["hockle_status"] == "stopped"
    assert ds.attrs["hockle_stop_reason"] == "timeout"
    with pytest.raises(ValueError, match="status"):
        build_dataset(case, s, times, fields, {}, "done")
    with pytest.raises(ValueError, match="attribute"):
        build_dataset(case, s, times, fields, {}, "failed", attrs={"flag": True})


def test_variables_only_for_fields_present(case):
    s, times, fields, _ = synthetic()
    chosen = {k: fields[k] for k in ("kappa", "energy_total", "writhe")}
    ds = build_dataset(case, s, times, chosen, {}, "completed")
    assert set(ds.data_vars) == {"kappa", "energy_total", "writhe"}
    assert "step" not in ds.dims and "step_time" not in ds.variables
    # no dimension that no variable uses
    assert set(ds.dims) == {"time", "s", "component"}
    scalars = build_dataset(case, s, times, {"energy_total": fields["energy_total"]}, {},
                            "completed")
    assert set(scalars.dims) == {"time"} and set(scalars.coords) == {"time"}
    position = build_dataset(case, s, times, {"position": fields["position"]}, {},
                             "completed")
    assert set(position.dims) == {"time", "s", "xyz"}


def test_encoding_float64_and_compression_for_time_s_variables(full):
    ds = full[0]
    for name, var in ds.data_vars.items():
        enc = var.encoding
        if var.dims[:2] == ("time", "s"):
            assert enc["dtype"] == "float64" and enc["zlib"] is True, name
            assert enc["complevel"] == 4, name
        else:
            assert not enc.get("zlib"), name
        if name in ("contact_count", "newton_iterations", "step_newton_iterations"):
            assert var.dtype == np.int32, name
        else:
            assert var.dtype == np.float64, name


def test_integer_counts_with_missing_values_stay_float(case):
    s, times, fields, _ = synthetic()
    its = np.arange(T, dtype=float)
    its[0] = np.nan
    ds = build_dataset(case, s, times, {"newton_iterations": its}, {}, "completed")
    assert ds["newton_iterations"].dtype == np.float64
    assert np.isnan(ds["newton_iterations"].values[0])


@pytest.mark.parametrize(
    "mutate, match",
    [
        (lambda f, d: f.update(v=np.zeros((T, N, 4))), "v: expected shape"),
        (lambda f, d: f.update(energy_total=np.zeros(T + 1)), "energy_total"),
        (lambda f, d: f.update(energy_gravity=np.zeros(T)), "unknown field"),
        (lambda f, d: d.update(step_dt=np.zeros(K + 1)), "diagnostics"),
        (lambda f, d: d.update(step_bogus=np.zeros(K)), "unknown diagnostic"),
        (lambda f, d: f.update(twist=np.array(["a"] * T)), "real numbers"),
    ],
)
def test_inconsistent_input_is_refused(case, mutate, match):
    s, times, fields, diagnostics = synthetic()
    mutate(fields, diagnostics)
    with pytest.raises(ValueError, match=match):
        build_dataset(case, s, times, fields, diagnostics, "completed")


def test_empty_run_builds(case):
    # a run that failed before its first output still yields a valid dataset
    s = np.linspace(0, 1, N)
    ds = build_dataset(
        case,
        s,
        np.zeros(0),
        {"energy_total": np.zeros(0), "position": np.zeros((0, N, 3))},
        {k: np.zeros(0) for k in EXPECTED_DIAG},
        "failed",
        "diverged at once",
    )
    assert ds.sizes["time"] == 0 and ds.sizes["step"] == 0


def test_netcdf_round_trip(full, tmp_path):
    ds = full[0]
    path = tmp_path / "sub" / "result.nc"
    assert write_netcdf(ds, path) == path
    # atomic: only the destination is left behind, no temporary file
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["result.nc", "sub"]
    back = open_result(path)
    for name in list(ds.data_vars) + list(ds.coords):
        assert back[name].dims == ds[name].dims, name
        assert back[name].dtype == ds[name].dtype, name  # time stays float seconds
        np.testing.assert_array_equal(back[name].values, ds[name].values)
        for key, value in ds[name].attrs.items():
            np.testing.assert_array_equal(back[name].attrs[key], value, err_msg=f"{name}.{key}")
    assert back.attrs == ds.attrs
    enc = back["v"].encoding
    assert enc["zlib"] is True and enc["complevel"] == 4
    assert not back["energy_total"].encoding.get("zlib")
    # readable with the plain netCDF4 library as well, with CF attributes
    import netCDF4

    with netCDF4.Dataset(path) as nc:
        assert nc.Conventions == "CF-1.12, ACDD-1.3"
        # CF 2.5.1: coordinate variables carry no _FillValue
        for name in ("time", "s", "component", "xyz", "quaternion", "step"):
            assert "_FillValue" not in nc[name].ncattrs(), name
        assert nc["v"].units == "m s-1"
        assert nc["v"].filters()["zlib"] is True


def test_write_replaces_existing_file_and_sets_plain_permissions(full, case, tmp_path):
    path = tmp_path / "result.nc"
    write_netcdf(full[0], path)
    s, times, fields, _ = synthetic(seed=1)
    second = build_dataset(case, s, times, {"twist": fields["twist"]}, {}, "stopped")
    old_umask = os.umask(0o022)
    try:
        write_netcdf(second, path)
    finally:
        os.umask(old_umask)
    back = open_result(path)
    assert set(back.data_vars) == {"twist"} and back.attrs["hockle_status"] == "stopped"
    mode = stat.S_IMODE(path.stat().st_mode)
    assert mode == 0o644  # not mkstemp's 0600: other services read the result store
    assert [p.name for p in tmp_path.iterdir()] == ["result.nc"]


def test_failed_write_keeps_old_file_and_leaves_no_temp(full, tmp_path):
    path = tmp_path / "result.nc"
    write_netcdf(full[0], path)
    before = path.read_bytes()
    bad = full[0].copy()
    bad.attrs["not_serialisable"] = {"a": 1}  # netCDF attributes cannot be dicts
    with pytest.raises((TypeError, ValueError)):
        write_netcdf(bad, path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["result.nc"]


def test_round_trip_of_a_real_run(case, tmp_path):
    """The dataset integrate() builds through build_dataset writes and reads back."""
    from solver.simulation import integrate

    spec = json.loads(case.canonical_json())
    spec["output"]["fields"] = ["v", "position", "orientation", "energies", "topology"]
    ds = integrate(Case.model_validate(spec))
    path = write_netcdf(ds, tmp_path / "run.nc")
    back = open_result(path)
    assert back.attrs["hockle_status"] == "completed"
    assert {"v", "position", "orientation", "energy_total", "twist", "writhe"} <= set(
        back.data_vars
    )
    assert back.sizes["time"] == 6 and back.sizes["s"] == N
    for name in back.data_vars:
        assert back[name].attrs.get("units") is not None, name
        assert back[name].attrs.get("long_name"), name


def test_the_two_phase_plectoneme_coexists_with_the_straight_rod():
    """solver.results.plectoneme_two_phase: at its θ and M_p the ply's energy per length
    B sin⁴θ/(2R²) − M sin 2θ/(2R), minimised in θ (zero derivative), equals the straight
    phase's −T; a turn puts 2πR·2/sin 2θ of rod into the ply (its writhe per length is
    sin 2θ/(4πR)); bad arguments are refused."""
    import math

    from solver.results import plectoneme_two_phase

    B, T, R = 2.05e-28, 1e-12, 1.2e-9
    p = plectoneme_two_phase(B, T, R)
    th, M = p["theta"], p["torque"]

    def energy(t):
        return B * math.sin(t) ** 4 / (2 * R * R) - M * math.sin(2 * t) / (2 * R)

    assert energy(th) == pytest.approx(-T, rel=1e-9)
    h = 1e-6
    assert abs(energy(th + h) - energy(th - h)) / (2 * h) < 1e-9 * T
    assert p["extension_per_turn"] == pytest.approx(1.0 / (math.sin(2 * th) / (4 * math.pi * R)),
                                                   rel=1e-12)
    with pytest.raises(ValueError):
        plectoneme_two_phase(B, -T, R)
    with pytest.raises(ValueError):
        plectoneme_two_phase(1.0, 1e12, 1.0)          # θ within 1e-9 of π/4
