"""``initial.from_result.job`` over HTTP: a case starts from the result of an earlier
successful job of the same owner, named by its id (never a server path). The API
in-process with two keys (SQLite registry, in-memory broker, the worker's task code run in
this process with the real solver)."""
from __future__ import annotations

import numpy as np
import pytest

from svc_support import tiny_case

KEY_A = "alice-key-0123456789abcdef"
KEY_B = "bob-key-0123456789abcdef-bob"
A = {"Authorization": f"Bearer {KEY_A}"}
B = {"Authorization": f"Bearer {KEY_B}"}
STATE = ("v", "omega", "f", "kappa", "position", "orientation")


#: the in-process service's settings (svc_support's ``settings`` and ``client`` fixtures)
SERVICE_SETTINGS = dict(api_keys=f"{KEY_A}, {KEY_B}", rate_limit=1000.0,
                        rate_limit_burst=1000)


def _run(settings, job_id):
    from worker.tasks import run_job

    return run_job(job_id, "from-job@test", settings)


def _case(name, **initial):
    case = tiny_case(name, t_end=0.08)
    case["output"] = {"fields": list(STATE)}
    if initial:
        case["initial"] = {"from_result": initial}
    return case


@pytest.fixture(scope="module")
def earlier(client, settings):
    """A successful job of key A whose result holds the start state."""
    response = client.post("/v1/jobs", json=_case("earlier"), headers=A)
    assert response.status_code == 201, response.text
    job_id = response.json()["id"]
    assert _run(settings, job_id) == "successful"
    return job_id


def _refused(response, loc, etype):
    assert response.status_code == 422, response.text
    body = response.json()
    assert [(e["loc"], e["type"]) for e in body["errors"]] == [(loc, etype)], body
    return body


def test_a_job_starts_from_an_earlier_job_of_its_owner(client, settings, earlier):
    response = client.post("/v1/jobs", json=_case("later", job=earlier, time=0.03), headers=A)
    assert response.status_code == 201, response.text
    later = response.json()["id"]
    assert _run(settings, later) == "successful"
    import xarray as xr

    a = xr.open_dataset(settings.results_dir / f"{earlier}.nc")
    b = xr.open_dataset(settings.results_dir / f"{later}.nc")
    k = int(np.flatnonzero(np.isclose(a.time.values, 0.03))[0])
    assert b.time.values[0] == pytest.approx(0.03)
    for name in STATE:          # the start state is the earlier job's at 0.03 s
        assert np.array_equal(a[name].values[k], b[name].values[0]), name
    # the continuation follows the earlier run to Newton's tolerance
    assert np.abs(a["position"].values[-1] - b["position"].values[-1]).max() < 1e-8


def test_another_owners_or_an_unknown_job_is_refused_alike(client, earlier):
    bob = _refused(client.post("/v1/jobs", json=_case("bob", job=earlier, time=0.03),
                               headers=B), "initial.from_result.job", "unknown_job")
    assert f"no job with id {earlier}" in bob["errors"][0]["msg"]
    _refused(client.post("/v1/jobs", json=_case("x", job="0" * 8 + "-0000-0000-0000-" + "0" * 12,
                                                time=0.03), headers=A),
             "initial.from_result.job", "unknown_job")


def test_an_unfinished_job_is_refused(client):
    queued = client.post("/v1/jobs", json=_case("queued"), headers=A).json()["id"]
    body = _refused(client.post("/v1/jobs", json=_case("after-queued", job=queued, time=0.0),
                                headers=A), "initial.from_result.job", "job_not_successful")
    assert "accepted" in body["errors"][0]["msg"]


def test_another_rod_or_time_is_refused_naming_the_field(client, earlier):
    other = _case("thicker", job=earlier, time=0.03)
    other["rod"]["diameter"] = 0.03
    _refused(client.post("/v1/jobs", json=other, headers=A), "initial.from_result.job",
             "another_rod")
    late = _case("t", job=earlier, time=0.1)          # after the earlier run's end
    late["numerics"]["t_end"] = 0.2
    body = _refused(client.post("/v1/jobs", json=late, headers=A),
                    "initial.from_result.time", "out_of_range")
    assert "not an output time" in body["errors"][0]["msg"]


def test_a_path_or_both_sources_are_refused(client, earlier):
    _refused(client.post("/v1/jobs", json=_case("path", file="/etc/passwd", time=0.0),
                         headers=A), "initial.from_result.file", "not_accepted_over_http")
    both = client.post("/v1/jobs", json=_case("both", file="x.nc", job=earlier, time=0.0),
                       headers=A)
    assert both.status_code == 422
    assert [e["loc"] for e in both.json()["errors"]] == ["initial.from_result.job"]


def test_a_sweep_member_from_another_owners_job_queues_nothing(client, earlier):
    base = _case("sweep", job=earlier, time=0.03)
    response = client.post("/v1/sweeps", json={"base": base, "parameters": {
        "rod.youngs_modulus": [1.25e7, 1.3e7]}}, headers=B)
    assert response.status_code == 422, response.text
    assert all(e["loc"].endswith("initial.from_result.job") for e in response.json()["errors"])
