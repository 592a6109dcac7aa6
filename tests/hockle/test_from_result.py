"""A run started from an earlier result (``initial.from_result``; hockle.io
``read_start_state``, solver.initial ``StartState``): what it continues exactly, the
refusals naming the field, and the service's 422."""
from __future__ import annotations

import json

import numpy as np
import pytest

from hockle.api import simulate
from hockle.io import read_start_state, write_netcdf
from solver.case import Case, CaseError

STATE = ("v", "omega", "f", "kappa", "moment", "position", "orientation")


def _spec(**numerics):
    from rodcases import free_end, make_case

    spec = make_case(n_segments=20, dt=0.01, t_end=0.6, end=free_end(), gravity=(0, -9.81, 0),
                     forces=[{"value": [0.05, 0, 0], "start": 0.3}],
                     fields=["v", "omega", "f", "kappa", "moment", "position", "orientation",
                             "energies", "topology"]).model_dump(mode="json")
    spec["numerics"].update(numerics)
    return spec


@pytest.fixture(scope="module")
def earlier(tmp_path_factory):
    path = tmp_path_factory.mktemp("from_result") / "earlier.nc"
    ds = simulate(Case.model_validate(_spec()))
    write_netcdf(ds, path)
    return ds, path


def test_continues_the_run_it_came_from(earlier):
    """Started at t = 0.3 s (a breakpoint of the earlier run: a force switched on there,
    so both runs make the same consistent restart), the continuation is the earlier run's
    bit for bit at its first outputs; from the third step on the Newton start differs
    (the earlier run's choice of predictor, solver state that a result does not store)
    and the runs agree to within Newton's tolerance: measured 1.1e-8 N in f, 2.4e-9 of
    its size."""
    a, path = earlier
    spec = _spec()
    spec["initial"] = {"from_result": {"file": str(path), "time": 0.3}}
    b = simulate(Case.model_validate(spec))
    k = int(np.flatnonzero(np.isclose(a.time.values, 0.3))[0])
    assert np.array_equal(a.time.values[k:], b.time.values)
    for name in STATE:
        x, y = a[name].values[k:], b[name].values
        assert np.array_equal(x[:3], y[:3]), name
        assert np.abs(x - y).max() <= 1e-7 * np.abs(x).max(), name
    assert b.attrs["hockle_status"] == "completed"


@pytest.mark.parametrize("change, field, etype", [
    ({"time": 0.305}, "time", "out_of_range"),
    ({"file": "/nonexistent/earlier.nc"}, "file", "file_unreadable"),
])
def test_bad_start_names_the_field(earlier, change, field, etype):
    _, path = earlier
    spec = _spec()
    spec["initial"] = {"from_result": {"file": str(path), "time": 0.3, **change}}
    spec["numerics"]["dt"] = 0.005
    with pytest.raises(CaseError) as info:
        read_start_state(Case.model_validate(spec))
    assert info.value.errors[0]["loc"] == f"initial.from_result.{field}"
    assert info.value.errors[0]["type"] == etype


def test_a_result_of_another_rod_or_without_the_state_is_refused(earlier, tmp_path):
    _, path = earlier
    spec = _spec()
    spec["rod"]["diameter"] = 0.03
    spec["initial"] = {"from_result": {"file": str(path), "time": 0.3}}
    with pytest.raises(CaseError) as info:
        read_start_state(Case.model_validate(spec))
    assert info.value.errors[0]["type"] == "another_rod"
    bare = _spec()
    bare["output"]["fields"] = ["v", "f"]
    bare["numerics"]["t_end"] = 0.05
    short = tmp_path / "bare.nc"
    write_netcdf(simulate(Case.model_validate(bare)), short)
    spec = _spec()
    spec["initial"] = {"from_result": {"file": str(short), "time": 0.0}}
    with pytest.raises(CaseError) as info:
        read_start_state(Case.model_validate(spec))
    err = info.value.errors[0]
    assert err["type"] == "missing_variable" and "omega, kappa, position, orientation" in err["msg"]


def test_case_level_refusals():
    spec = _spec()
    spec["initial"] = {"from_result": {"file": "x.nc", "time": 0.305}}
    with pytest.raises(CaseError) as info:
        Case.from_text(json.dumps(spec), fmt="json")
    assert info.value.errors[0]["loc"] == "initial.from_result.time"
    spec["initial"] = {"from_result": {"file": "x.nc", "time": 0.3}, "twist_rate": 1.0}
    with pytest.raises(CaseError) as info:
        Case.from_text(json.dumps(spec), fmt="json")
    assert info.value.errors[0]["loc"] == "initial.from_result"
    plain = Case.model_validate(_spec())
    assert "from_result" not in plain.canonical_json()


def test_service_refuses_a_server_path():
    pytest.importorskip("fastapi")
    from service.problems import ProblemError
    from service.validation import validate_case

    spec = _spec()
    spec["initial"] = {"from_result": {"file": "/etc/passwd", "time": 0.0}}
    with pytest.raises(ProblemError) as info:
        validate_case(spec, 10**9)
    assert info.value.status == 422
    assert info.value.errors[0]["loc"] == "initial.from_result.file"


def test_a_job_id_is_for_the_service_only(earlier):
    """The CLI and the Python API read a file; a job id is resolved by the service."""
    spec = _spec()
    spec["initial"] = {"from_result": {"job": "0123", "time": 0.3}}
    with pytest.raises(CaseError) as info:
        read_start_state(Case.model_validate(spec))
    assert info.value.errors[0]["loc"] == "initial.from_result.job"
    spec["initial"] = {"from_result": {"time": 0.3}}
    with pytest.raises(CaseError) as info:
        Case.from_text(json.dumps(spec), fmt="json")
    assert info.value.errors[0]["loc"] == "initial.from_result.file"
