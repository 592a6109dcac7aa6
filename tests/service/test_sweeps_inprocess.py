"""/v1/sweeps in-process (SQLite registry, in-memory broker, the worker's task code run here
with the real solver): results only once every member finished, a member that fails is
marked, sweeps belong to the API key that made them, the OpenAPI document."""
from __future__ import annotations

import pytest
import xarray as xr

from svc_support import tiny_case

TENSION = "boundary.end.translation.2.force"
KEY_A = "alice-key-0123456789abcdef"
KEY_B = "bob-key-0123456789abcdef-bob"
A = {"Authorization": f"Bearer {KEY_A}"}
B = {"Authorization": f"Bearer {KEY_B}"}


def _run(settings, job_id):
    from worker.tasks import run_job

    return run_job(job_id, "sweep@test", settings)


#: the in-process service's settings (svc_support's ``settings`` and ``client`` fixtures)
SERVICE_SETTINGS = dict(api_keys=f"{KEY_A},{KEY_B}", rate_limit=1000.0, rate_limit_burst=1000)


def test_results_wait_for_every_member_and_a_failed_one_is_marked(client, settings, tmp_path):
    # member 1 diverges: a huge spin with one Newton iteration and no Δt cuts
    base = tiny_case("partly-failing", max_dt_cuts=0, dt=0.01, t_end=0.05)
    base["numerics"]["newton"] = {"max_iterations": 1, "tolerance": 1e-14}
    spin = "boundary.start.rotation.2.angular_velocity"
    body = {"base": base, "combine": "zip", "parameters": {spin: [0.0, 1.0e4]}}
    sweep = client.post("/v1/sweeps", json=body, headers=A).json()
    first, second = (m["job_id"] for m in sweep["members"])
    assert client.get(f"/v1/sweeps/{sweep['id']}/results", headers=A).status_code == 404
    assert _run(settings, first) == "successful"
    status = client.get(f"/v1/sweeps/{sweep['id']}", headers=A).json()
    assert status["state"] == "running" and status["progress"] == 50.0
    not_ready = client.get(f"/v1/sweeps/{sweep['id']}/results", headers=A)
    assert not_ready.status_code == 404 and "still queued or running" in not_ready.json()["detail"]
    assert _run(settings, second).startswith("failed")
    status = client.get(f"/v1/sweeps/{sweep['id']}", headers=A).json()
    assert status["state"] == "failed" and status["counts"] == {"successful": 1, "failed": 1}
    response = client.get(f"/v1/sweeps/{sweep['id']}/results", headers=A)
    assert response.status_code == 200
    etag = response.headers["etag"]
    assert client.get(f"/v1/sweeps/{sweep['id']}/results",
                      headers={**A, "If-None-Match": etag}).status_code == 304
    path = tmp_path / "s.nc"
    path.write_bytes(response.content)
    with xr.open_dataset(path, engine="netcdf4") as ds:
        assert list(ds["member_status"].values) == ["successful", "failed"]
        assert str(ds["member_message"].values[1])          # why it failed
        assert ds["energy_total"].isel(member=0).notnull().all()
    bad_field = client.get(f"/v1/sweeps/{sweep['id']}/results", params={"fields": "colour"},
                           headers=A)
    assert bad_field.status_code == 422 and bad_field.json()["errors"][0]["loc"] == "query.fields"


def test_a_successful_members_warning_reaches_the_status_and_the_combined_result(
        client, settings, tmp_path):
    """A member whose run completes with hockle_warning (the thin-rod plectoneme at 10x
    its step: its loop sweeps across an end's closure, docs/numerics.md § 6) is successful;
    its warning is the member's ``message`` in the sweep's status and its
    ``member_message`` in the combined dataset (it was dropped there for successful
    members); the member at the case's own step has neither."""
    from rodcases import thin_plectoneme_case

    base = thin_plectoneme_case(0.02, 10.0).model_dump(mode="json")
    body = {"base": base, "combine": "zip", "parameters": {"numerics.dt": [0.02, 0.2]}}
    sweep = client.post("/v1/sweeps", json=body, headers=A).json()
    for member in sweep["members"]:
        assert _run(settings, member["job_id"]) == "successful"
    status = client.get(f"/v1/sweeps/{sweep['id']}", headers=A).json()
    assert status["state"] == "successful"
    plain, warned = status["members"]
    assert plain["message"] is None
    assert "crossed the closure of the end tangents" in warned["message"]
    response = client.get(f"/v1/sweeps/{sweep['id']}/results", headers=A)
    assert response.status_code == 200
    path = tmp_path / "warned.nc"
    path.write_bytes(response.content)
    with xr.open_dataset(path, engine="netcdf4") as ds:
        assert list(ds["member_status"].values) == ["successful", "successful"]
        assert str(ds["member_message"].values[0]) == ""
        assert str(ds["member_message"].values[1]) == warned["message"]


def test_a_sweep_belongs_to_its_key(client, settings):
    assert client.post("/v1/sweeps", json={}).status_code == 401
    body = {"base": tiny_case("alice-sweep"), "parameters": {TENSION: [0.0, 0.5]}}
    sweep = client.post("/v1/sweeps", json=body, headers=A).json()
    for method, url in (("GET", f"/v1/sweeps/{sweep['id']}"),
                        ("GET", f"/v1/sweeps/{sweep['id']}/results"),
                        ("DELETE", f"/v1/sweeps/{sweep['id']}")):
        response = client.request(method, url, headers=B)
        assert response.status_code == 404, (method, url, response.text)
        assert response.json()["type"] == "urn:hockle:problem:sweep-not-found"
    # its members are Alice's jobs
    job_id = sweep["members"][0]["job_id"]
    assert client.get(f"/v1/jobs/{job_id}", headers=A).status_code == 200
    assert client.get(f"/v1/jobs/{job_id}", headers=B).status_code == 404
    dismissed = client.delete(f"/v1/sweeps/{sweep['id']}", headers=A)
    assert dismissed.status_code == 200 and dismissed.json()["state"] == "dismissed"


def test_openapi_documents_the_sweep_routes(client):
    paths = client.get("/openapi.json").json()["paths"]
    ops = {op["operationId"] for item in paths.values() for op in item.values()
           if isinstance(op, dict) and "operationId" in op}
    assert {"submit_sweep", "get_sweep", "dismiss_sweep", "download_sweep_results"} <= ops


def test_a_submission_that_fails_midway_leaves_no_member_queued(client, monkeypatch):
    """The registry fails when the sweep itself is recorded, after its members were
    queued: the members this request created are dismissed, not left to run alone."""
    from sqlalchemy.exc import OperationalError

    from service.registry import Registry

    made = []
    create_job = Registry.create_job

    def spy(self, **kwargs):
        job, created = create_job(self, **kwargs)
        made.append(job.id)
        return job, created

    def locked(self, **kwargs):
        raise OperationalError("INSERT INTO hockle_sweeps", {}, Exception("database is locked"))

    monkeypatch.setattr(Registry, "create_job", spy)
    monkeypatch.setattr(Registry, "create_sweep", locked)
    response = client.post("/v1/sweeps", json={"base": tiny_case("half-queued"),
                                               "parameters": {TENSION: [0.5, 0.75]}},
                           headers=A)
    assert response.status_code == 503, response.text
    assert len(made) == 2
    for job_id in made:
        assert client.get(f"/v1/jobs/{job_id}", headers=A).json()["state"] == "dismissed"
