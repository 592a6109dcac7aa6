"""Continuation jobs (issue 42): ``POST /v1/continuations`` queues a job of kind
``continuation`` whose worker follows a case's static branch (hockle.api.continue_branch) and
stores the branch dataset as the job's result. The API in-process (SQLite registry, in-memory
broker, the worker's task code run in this process with the real solver) on a 20-segment
Euler column (cases/euler-column.yaml): its first branch point at P = 4π²B/L²."""
from __future__ import annotations

import math
from pathlib import Path

import pytest
import xarray as xr

from svc_support import REPO, tiny_case

FORCE = "boundary.end.translation.2.force"


def _column(n_segments: int = 20) -> dict:
    from solver.case import parse_text

    path = REPO / "cases" / "euler-column.yaml"
    case = parse_text(path.read_bytes(), path.suffix, str(path))
    case["numerics"]["n_segments"] = n_segments
    return case


def _euler_load(case: dict) -> float:
    """4π² B / L², B = E π D⁴ / 64 (N)."""
    rod = case["rod"]
    bending = float(rod["youngs_modulus"]) * math.pi * float(rod["diameter"]) ** 4 / 64
    return 4 * math.pi ** 2 * bending / float(rod["length"]) ** 2


def _run(settings, job_id):
    from worker.tasks import run_job

    return run_job(job_id, "continuation@test", settings)


def _body(case=None, **options):
    return {"case": _column() if case is None else case,
            "continuation": {"parameter": FORCE, "to": -0.4, "max_points": 60, **options}}


@pytest.fixture(scope="module")
def branch_job(client, settings):
    response = client.post("/v1/continuations", json=_body())
    assert response.status_code == 201, response.text
    job = response.json()
    assert job["kind"] == "continuation" and job["state"] == "accepted"
    assert response.headers["Location"] == f"/v1/jobs/{job['id']}"
    assert _run(settings, job["id"]) == "successful"
    return job["id"]


def test_a_continuation_job_finds_the_euler_branch_point(client, branch_job, tmp_path):
    status = client.get(f"/v1/jobs/{branch_job}").json()
    assert status["state"] == "successful" and status["kind"] == "continuation"
    assert status["progress"] == 100.0 and status["result_available"]
    response = client.get(f"/v1/jobs/{branch_job}/results")
    assert response.status_code == 200
    path = tmp_path / "branch.nc"
    path.write_bytes(response.content)
    with xr.open_dataset(path) as ds:
        assert ds.attrs["hockle_job_id"] == branch_job
        assert status["step"] == ds.sizes["point"] >= 2      # step: the points done
        assert ds.attrs["stopped"] == "reached the target value"
        assert ds["parameter"].values[-1] == pytest.approx(-0.4)
        kinds = [str(k) for k in ds["bifurcation_kind"].values]
        assert "branch_point" in kinds
        first = float(ds["bifurcation_parameter"].values[kinds.index("branch_point")])
    # second order in Δs: 1.7 % high at 20 segments (0.1 % at 100: tests/test_statics*)
    assert -first == pytest.approx(_euler_load(_column()), rel=0.025)
    assert status["message"].startswith(f"{status['step']} points")


def test_the_results_queries_of_a_branch(client, branch_job):
    listed = client.get(f"/v1/jobs/{branch_job}/results/variables").json()
    assert "point" in listed["dims"] and "bifurcation" in listed["dims"]
    one = client.get(f"/v1/jobs/{branch_job}/results/variables/parameter").json()
    assert one["dims"] == ["point"] and len(one["data"]) == listed["dims"]["point"]
    summary = client.get(f"/v1/jobs/{branch_job}/summary")
    assert summary.status_code == 409, summary.text
    assert summary.json()["type"].endswith("result-is-a-branch")
    spec = client.get(f"/v1/jobs/{branch_job}/spec").json()
    assert spec["continuation"]["parameter"] == FORCE and spec["continuation"]["to"] == -0.4
    assert spec["case"]["numerics"]["n_segments"] == 20
    # the same request again is answered from the finished job; ?fresh=true queues a new one
    again = client.post("/v1/continuations", json=_body())
    assert again.status_code == 200 and again.json()["id"] == branch_job
    assert again.headers["Hockle-Reused"] == "identical_case"


def _refused(response, loc):
    assert response.status_code == 422, response.text
    locs = [e["loc"] for e in response.json()["errors"]]
    assert loc in locs, response.json()
    return response.json()


@pytest.mark.parametrize("options, loc", [
    ({"parameter": "rod.nothing"}, "continuation.parameter"),
    ({"parameter": "numerics"}, "continuation.parameter"),            # a mapping, not a scalar
    ({"to": -0.1}, "continuation.to"),                                # the case's own value
    ({"parameter": "rod.diameter", "to": -1.0}, "continuation.to"),   # makes the case invalid
    ({"max_points": 1}, "continuation.max_points"),
    ({"step": 0}, "continuation.step"),
    ({"unknown": 1}, "continuation.unknown"),
])
def test_bad_continuations_are_refused_before_any_work(client, options, loc):
    body = _body()
    body["continuation"].update(options)
    _refused(client.post("/v1/continuations", json=body), loc)


def test_a_bad_case_or_body_is_refused_naming_the_field(client):
    case = _column()
    case["rod"]["youngs_modulus"] = -1.0
    _refused(client.post("/v1/continuations", json=_body(case)), "case.rod.youngs_modulus")
    _refused(client.post("/v1/continuations", json={"case": _column()}), "continuation")
    case = _column()        # a turning end the static problem does not take
    case["boundary"]["end"]["rotation"][0] = {"angular_velocity": 0.1}
    _refused(client.post("/v1/continuations", json=_body(case)), "case.boundary.end.rotation")
    # the service's size limit counts the points, not the case's own time steps
    case = _column()
    case["numerics"]["dt"] = 1e-7
    _refused(client.post("/v1/jobs", json=case), "numerics.dt")
    assert client.post("/v1/continuations", json=_body(case, max_points=5)).status_code == 201
    body = client.post("/v1/continuations", json=_body(_column(200), max_points=5000)).json()
    assert "continuation.max_points" in [e["loc"] for e in body["errors"]]
    _refused(client.post("/v1/continuations", json=_column()), "case")


def test_a_dismissed_continuation_keeps_the_branch_so_far(client, settings, monkeypatch):
    from service.registry import Registry

    response = client.post("/v1/continuations", json=_body(), params={"fresh": "true"})
    assert response.status_code == 201, response.text
    job_id = response.json()["id"]
    asked = []

    def cancel_after_three(self, jid):          # the user dismisses it after three points
        asked.append(jid)
        return len(asked) > 3

    monkeypatch.setattr(Registry, "cancel_requested", cancel_after_three)
    assert _run(settings, job_id) == "dismissed"
    status = client.get(f"/v1/jobs/{job_id}").json()
    assert status["state"] == "dismissed" and status["result_partial"]
    assert status["step"] == 4 and "branch so far is kept" in status["message"]
    path = Path(settings.results_dir) / f"{job_id}.nc"
    with xr.open_dataset(path) as ds:
        assert ds.sizes["point"] == 4 and ds.attrs["stopped"] == "stopped: cancelled_by_user"


def test_a_dynamic_job_is_unaffected(client, settings, branch_job):
    response = client.post("/v1/jobs", json=tiny_case("dynamic beside a branch"))
    assert response.status_code == 201, response.text
    job = response.json()
    assert job["kind"] == "dynamic" and set(job["links"]) == {
        "self", "spec", "results", "variables", "summary"}
    assert _run(settings, job["id"]) == "successful"
    summary = client.get(f"/v1/jobs/{job['id']}/summary")
    assert summary.status_code == 200 and summary.json()["time"]
    spec = client.get(f"/v1/jobs/{job['id']}/spec").json()
    assert spec["name"] == "dynamic beside a branch"
    # a continuation's result is no start state for a dynamic run
    case = tiny_case("from a branch")
    case["initial"] = {"from_result": {"job": branch_job, "time": 0.0}}
    _refused(client.post("/v1/jobs", json=case), "initial.from_result.job")


def test_the_python_client_submits_a_continuation(client, monkeypatch):
    from service.client import HockleAPIError, HockleClient

    monkeypatch.delenv("HOCKLE_API_KEY", raising=False)
    with HockleClient("http://testserver", transport=client._transport) as hc:
        status = hc.submit_continuation(_column(), FORCE, -0.3, max_points=40, step=0.1)
        assert status.kind == "continuation" and status.state == "accepted"
        assert hc.spec(status.id)["continuation"] == {
            "parameter": FORCE, "to": -0.3, "time": None, "switch": False, "max_points": 40,
            "step": 0.1, "shapes_every": 1, "stability": True}
        with pytest.raises(HockleAPIError) as info:
            hc.submit_continuation(_column(), "rod.nothing", 1.0)
    assert info.value.status == 422
    assert [e["loc"] for e in info.value.errors] == ["continuation.parameter"]


def test_openapi_documents_the_continuation(client):
    schema = client.get("/openapi.json").json()
    post = schema["paths"]["/v1/continuations"]["post"]
    assert post["operationId"] == "submit_continuation"
    body = post["requestBody"]["content"]["application/json"]["schema"]
    assert body["properties"]["case"] == {"$ref": "#/components/schemas/Case"}
    assert {"parameter", "to", "max_points"} <= set(body["properties"]["continuation"]
                                                     ["properties"])
    assert "kind" in schema["components"]["schemas"]["JobStatus"]["properties"]


def test_a_continuation_out_of_time_keeps_its_branch(client, settings):
    from sqlalchemy import update

    from service.models import Job
    from service.registry import Registry

    response = client.post("/v1/continuations", json=_body(), params={"fresh": "true"})
    job_id = response.json()["id"]
    reg = Registry(settings.registry_url)
    try:            # a budget spent before the first step: the start point is all there is
        with reg.sessions.begin() as session:
            session.execute(update(Job).where(Job.id == job_id).values(wall_clock_budget=0.0))
    finally:
        reg.dispose()
    assert _run(settings, job_id) == "failed:timeout"
    status = client.get(f"/v1/jobs/{job_id}").json()
    assert (status["state"], status["reason"], status["step"]) == ("failed", "timeout", 1)
    assert status["result_partial"] and "the branch so far is kept" in status["message"]
    assert f"after 1 point ({FORCE} = -0.1)" in status["message"]
    response = client.get(f"/v1/jobs/{job_id}/results/variables/parameter")
    assert response.json()["data"] == [pytest.approx(-0.1)]


def _submit_fresh(client, **options) -> str:
    response = client.post("/v1/continuations", json=_body(**options), params={"fresh": "true"})
    assert response.status_code == 201, response.text
    return response.json()["id"]


def _variable(client, job_id, name, **query):
    response = client.get(f"/v1/jobs/{job_id}/results/variables/{name}", params=query)
    assert response.status_code == 200, response.text
    return response.json()


def test_an_exception_mid_branch_fails_the_job_and_keeps_its_points(client, settings,
                                                                     monkeypatch):
    """An unexpected exception at the fifth point (the unstable-mode count raising): the job
    fails (internal_error, naming the exception) and the four points before it are its
    partial result, as a failed dynamic run keeps what it computed."""
    import solver.continuation as continuation

    real, calls = continuation.unstable_modes, []

    def breaks_at_the_fifth(*args, **kwargs):
        calls.append(1)
        if len(calls) == 5:
            raise RuntimeError("ARPACK lost its way")
        return real(*args, **kwargs)

    monkeypatch.setattr(continuation, "unstable_modes", breaks_at_the_fifth)
    job_id = _submit_fresh(client)
    assert _run(settings, job_id) == "failed:internal_error"
    status = client.get(f"/v1/jobs/{job_id}").json()
    assert (status["state"], status["reason"]) == ("failed", "internal_error")
    assert status["result_partial"] and status["result_available"]
    assert "RuntimeError: ARPACK lost its way" in status["message"]
    assert "the branch so far is kept (after 4 points" in status["message"]
    data = _variable(client, job_id, "parameter")["data"]
    assert len(data) == 4 and data[0] == pytest.approx(-0.1)
    whole = _variable(client, _branch_of(client), "parameter")["data"]
    assert data == whole[:4]


def _branch_of(client) -> str:
    """The uninterrupted branch of _body() (the module's first job, answered from it)."""
    response = client.post("/v1/continuations", json=_body())
    assert response.status_code == 200, response.text
    return response.json()["id"]


def _same_branch_files(settings, job_id, other_id):
    results = Path(settings.results_dir)
    with xr.open_dataset(results / f"{job_id}.attempt-2.nc") as a, \
            xr.open_dataset(results / f"{other_id}.nc") as b:
        assert a.sizes == b.sizes
        for name in ("parameter", "position", "end_force", "unstable_modes",
                     "bifurcation_parameter"):
            assert a[name].equals(b[name]), name
        return dict(a.attrs)


def test_a_continuation_handed_back_at_shutdown_resumes_where_it_stopped(
        client, settings, branch_job, monkeypatch):
    """A worker shutting down after the 7th point: its final checkpoint is stored, the job
    goes back to the queue saying the point and the parameter; attempt 2 continues from
    point 7 to the branch of an uninterrupted job, to the last bit."""
    from service.registry import Registry
    from worker import tasks

    job_id = _submit_fresh(client)
    real = tasks.JobRun.should_stop

    def shutdown_after_seven(self):
        if self.attempt == 1 and self.last_info is not None and self.last_info.step >= 7:
            self.stopping = True
            return tasks.SHUTDOWN_REASON
        return real(self)

    monkeypatch.setattr(tasks.JobRun, "should_stop", shutdown_after_seven)
    assert _run(settings, job_id) == "requeued_at_shutdown:requeued"
    assert (Path(settings.results_dir) / f"{job_id}.ckpt").exists()
    status = client.get(f"/v1/jobs/{job_id}").json()
    assert status["state"] == "accepted"
    assert f"attempt 1 stopped at point 7 ({FORCE} = " in status["message"]
    assert " s (step" not in status["message"]
    assert _run(settings, job_id) == "successful"
    reg = Registry(settings.registry_url)
    try:
        events = reg.events(job_id)
    finally:
        reg.dispose()
    [resumed] = [e for e in events if e.kind == "resumed"]
    assert resumed.attempt == 2 and '"point": 7' in resumed.detail
    attrs = _same_branch_files(settings, job_id, branch_job)
    assert attrs["resumed_at_point"] == 7 and attrs["hockle_attempt"] == 2
    assert not (Path(settings.results_dir) / f"{job_id}.ckpt").exists()


def test_a_killed_continuation_resumes_from_its_last_checkpoint(client, settings, branch_job,
                                                               monkeypatch):
    """A worker killed after the 15th point (nothing of the attempt runs after it): the job is
    given up as lost and queued again; attempt 2 continues from the last checkpoint the
    policy stored (every tenth of max_points = 60: after point 12) to the uninterrupted
    branch."""
    import datetime as dt

    from service.registry import Registry
    from worker import tasks

    class Killed(BaseException):
        """What SIGKILL does to the attempt: nothing after it runs."""

    job_id = _submit_fresh(client)
    real = tasks.JobRun.should_stop

    def killed_after_fifteen(self):
        if self.attempt == 1 and self.last_info is not None and self.last_info.step >= 15:
            raise Killed
        return real(self)

    monkeypatch.setattr(tasks.JobRun, "should_stop", killed_after_fifteen)
    with pytest.raises(Killed):
        _run(settings, job_id)
    reg = Registry(settings.registry_url)
    try:
        later = dt.datetime.now(dt.timezone.utc).replace(tzinfo=None) + dt.timedelta(hours=1)
        [(job, action)] = [(j, a) for j, a in reg.requeue_lost(
            heartbeat_timeout=1.0, max_attempts=3, now=later) if j.id == job_id]
        assert action == "requeued"
        assert "lost its worker continuation@test at point 15 (no heartbeat" in job.message
        assert _run(settings, job_id) == "successful"
        [resumed] = [e for e in reg.events(job_id) if e.kind == "resumed"]
    finally:
        reg.dispose()
    assert resumed.attempt == 2 and '"point": 12' in resumed.detail
    assert _same_branch_files(settings, job_id, branch_job)["resumed_at_point"] == 12


def test_the_point_selector_of_a_branch(client, branch_job):
    n = client.get(f"/v1/jobs/{branch_job}/results/variables").json()["dims"]["point"]
    whole = _variable(client, branch_job, "parameter")["data"]
    one = _variable(client, branch_job, "parameter", point="3")
    assert one["dims"] == [] and one["data"] == whole[3] and one["selected"] == {"point": 3}
    some = _variable(client, branch_job, "end_force", point="2:4", xyz="z")
    assert some["dims"] == ["point"] and some["coords"]["point"] == [2, 3, 4]
    listed = _variable(client, branch_job, "position", point="0,5", xyz="z")
    assert listed["shape"][0] == 2
    first = _variable(client, branch_job, "bifurcation_parameter", bifurcation="0")
    assert first["dims"] == []
    for query, loc in [({"point": str(n)}, "query.point"), ({"point": "4:2"}, "query.point"),
                       ({"point": "x"}, "query.point"),
                       ({"time": "0"}, "query.time")]:        # a branch has no time
        response = client.get(f"/v1/jobs/{branch_job}/results/variables/parameter",
                              params=query)
        assert response.status_code == 422, (query, response.text)
        assert [e["loc"] for e in response.json()["errors"]] == [loc]


def test_hockle_submit_continue(client, monkeypatch, tmp_path, capsys):
    """`hockle submit CASE --continue --parameter P --to V` submits what `hockle continue`
    computes locally; its options without --continue, or --continue without both, are
    refused (exit 2)."""
    import json

    from hockle.cli import main
    from service import client as client_module

    monkeypatch.delenv("HOCKLE_API_KEY", raising=False)
    real = client_module.HockleClient.__init__

    def through_the_test_client(self, url=None, **kwargs):
        real(self, "http://testserver", transport=client._transport, **kwargs)

    monkeypatch.setattr(client_module.HockleClient, "__init__", through_the_test_client)
    case = tmp_path / "column.json"
    case.write_text(json.dumps(_column()))
    code = main(["submit", str(case), "--continue", "--parameter", FORCE, "--to", "-0.25",
                 "--max-points", "30", "--switch", "--fresh"])
    out = capsys.readouterr().out
    assert code == 0, out
    job_id = out.split()[1]
    status = client.get(f"/v1/jobs/{job_id}").json()
    assert status["kind"] == "continuation"
    assert client.get(f"/v1/jobs/{job_id}/spec").json()["continuation"] == {
        "parameter": FORCE, "to": -0.25, "time": None, "switch": True, "max_points": 30,
        "step": 0.05, "shapes_every": 1, "stability": True}
    assert main(["submit", str(case), "--continue", "--to", "1"]) == 2
    assert "--continue needs --parameter PATH and --to VALUE" in capsys.readouterr().err
    assert main(["submit", str(case), "--parameter", FORCE]) == 2
    assert "--parameter only with --continue" in capsys.readouterr().err
