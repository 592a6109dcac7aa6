"""The API in-process (SQLite registry, in-memory broker) and the worker task run in-process with
the real solver: a 422 problem for every class of bad input, slices, size caps, stop semantics.
"""
from __future__ import annotations

import json

import pytest

from service.registry import Registry
from svc_support import long_case, tiny_case

PROBLEM = "application/problem+json"


#: the in-process service's settings (svc_support's ``settings`` and ``client`` fixtures)
SERVICE_SETTINGS = dict(max_slice_values=40, max_case_size=2_000_000,
                        creator_name="Rod Dynamics Lab", license="CC-BY-4.0")


def _run(settings, job_id):
    """Run the queued job with the worker's task code in this process (real solver)."""
    from worker.tasks import run_job

    return run_job(job_id, "inproc@test", settings)


def _bad(**edits):
    case = tiny_case("bad")
    for path, value in edits.items():
        node = case
        keys = path.split("__")
        for key in keys[:-1]:
            node = node[int(key)] if key.isdigit() else node[key]
        last = keys[-1]
        if last.isdigit():
            node[int(last)] = value
        else:
            node[last] = value
    return case


BAD_INPUTS = {
    "wrong type": (_bad(rod__length="one metre"), ["rod.length"]),
    "wrong type nested": (_bad(numerics__n_segments=[8]), ["numerics.n_segments"]),
    "unknown field": ({**tiny_case(), "colour": "red"}, ["colour"]),
    "unknown nested field": (_bad(rod__colour="red"), ["rod.colour"]),
    "non-positive length": (_bad(rod__length=0), ["rod.length"]),
    "non-positive moduli": (_bad(rod__youngs_modulus=-1.0, rod__shear_modulus=0),
                            ["rod.youngs_modulus", "rod.shear_modulus"]),
    "non-positive density": (_bad(rod__density=-1500), ["rod.density"]),
    "non-positive diameter": (_bad(rod__diameter=0.0), ["rod.diameter"]),
    "rho_inf above 1": (_bad(numerics__rho_inf=1.5), ["numerics.rho_inf"]),
    "rho_inf below 0": (_bad(numerics__rho_inf=-0.1), ["numerics.rho_inf"]),
    "table times not increasing": (
        _bad(boundary__start__rotation__2={"angular_velocity": {"t": [0, 2, 1], "value": [0, 1, 1]}}),
        ["boundary.start.rotation[2][0].angular_velocity.t[2]"]),
    "DOF given two conditions": (
        _bad(boundary__end__translation__0={"velocity": 0, "force": 0}),
        ["boundary.end.translation[0][0]"]),
    "DOF given no condition": (
        _bad(boundary__start__rotation__1={}), ["boundary.start.rotation[1][0]"]),
    "end missing a DOF": (
        _bad(boundary__start__translation=[{"velocity": 0}, {"velocity": 0}]),
        ["boundary.start.translation"]),
    "case too large": (_bad(numerics__n_segments=1000, numerics__t_end=50.0),
                       ["numerics.n_segments", "numerics.t_end", "numerics.dt"]),
    "not an object": ([1, 2, 3], [""]),
}


@pytest.mark.parametrize("label", list(BAD_INPUTS))
def test_each_class_of_bad_input_is_a_422_problem(client, label):
    case, locs = BAD_INPUTS[label]
    response = client.post("/v1/jobs", json=case)
    assert response.status_code == 422, response.text
    assert response.headers["content-type"] == PROBLEM
    body = response.json()
    assert body["status"] == 422 and body["title"] and body["type"].startswith("urn:hockle:")
    assert body["instance"] == "/v1/jobs"
    assert [e["loc"] for e in body["errors"]] == locs
    for err in body["errors"]:
        assert err["msg"] and err["type"]
    assert "Traceback" not in response.text
    if label.startswith("unknown"):
        assert "allowed here:" in body["errors"][0]["msg"]
    if label == "case too large":
        assert "1001 grid points x 5000 time steps" in body["errors"][0]["msg"]
        assert "limit of 2000000" in body["errors"][0]["msg"]


def test_nothing_was_recorded_for_bad_input(client, settings):
    client.post("/v1/jobs", json=_bad(rod__length=-1))
    registry = Registry(settings.registry_url)
    try:
        assert all(json.loads(j.spec_json)["name"] != "bad" for j in registry.list(page_size=500).jobs)
    finally:
        registry.dispose()


def test_malformed_and_unsupported_bodies(client):
    response = client.post("/v1/jobs", content=b"{not json", headers={"content-type": "application/json"})
    assert response.status_code == 400 and response.headers["content-type"] == PROBLEM
    response = client.post("/v1/jobs", content=b"<case/>", headers={"content-type": "application/xml"})
    assert response.status_code == 415
    response = client.post("/v1/jobs", content=b"", headers={"content-type": "application/json"})
    assert response.status_code == 422
    import yaml

    response = client.post("/v1/jobs", content=yaml.safe_dump(tiny_case("as-yaml")).encode(),
                           headers={"content-type": "application/yaml"})
    assert response.status_code == 201, response.text
    assert response.json()["name"] == "as-yaml"


def test_deeply_nested_bodies_are_422_problems(client):
    # the audit's bodies: JSON nested 2,000 deep and YAML 5,000 deep raised RecursionError
    # (500; one reset the connection). Each is a 422 nesting_too_deep problem now (as any body
    # nested beyond service.validation.MAX_NESTING), and the API still answers
    for body, media in ((b"[" * 2000 + b"]" * 2000, "application/json"),
                        (b"{\"a\": " * 1500 + b"1" + b"}" * 1500, "application/json"),
                        (b"[" * 5000 + b"]" * 5000, "application/yaml")):
        response = client.post("/v1/jobs", content=body, headers={"content-type": media})
        assert response.status_code == 422, (media, response.status_code, response.text[:200])
        assert response.headers["content-type"] == PROBLEM
        assert response.json()["errors"][0]["type"] == "nesting_too_deep"
    assert client.post("/v1/jobs", json=tiny_case("after-deep")).status_code == 201


def test_oversized_bodies_are_refused_before_they_are_read_whole(client):
    from service.validation import MAX_BODY_BYTES

    big = b" " * (MAX_BODY_BYTES + 1)
    response = client.post("/v1/jobs", content=big, headers={"content-type": "application/json"})
    assert response.status_code == 413 and response.headers["content-type"] == PROBLEM
    # without a Content-Length (chunked): refused once the chunks pass the limit
    def chunks():
        for _ in range(64):
            yield b" " * (1 << 20)

    response = client.post("/v1/jobs", content=chunks(), headers={"content-type": "application/json"})
    assert response.status_code == 413
    assert client.post("/v1/jobs", json=tiny_case("after-big")).status_code == 201


def test_query_errors_are_problems(client):
    response = client.get("/v1/jobs", params={"status": "sleeping"})
    assert response.status_code == 422 and response.json()["errors"][0]["loc"] == "query.status"
    response = client.get("/v1/jobs", params={"page_token": "garbage!"})
    assert response.status_code == 422
    response = client.get("/v1/jobs", params={"page_size": 0})
    assert response.status_code == 422 and response.headers["content-type"] == PROBLEM
    assert client.get("/v1/nowhere").headers["content-type"] == PROBLEM


def test_keyset_pagination_and_filters(client):
    ids = [client.post("/v1/jobs", json=tiny_case(f"page-{i}")).json()["id"] for i in range(5)]
    seen, token = [], None
    while True:
        params = {"page_size": 2, "status": "accepted"}
        if token:
            params["page_token"] = token
        page = client.get("/v1/jobs", params=params).json()
        seen += [j["id"] for j in page["jobs"]]
        token = page["next_page_token"]
        if not token:
            break
    assert len(seen) == len(set(seen))
    assert [i for i in seen if i in ids] == list(reversed(ids))  # newest first, none twice


def test_results_slices_and_caps_with_the_real_solver(client, settings):
    job = client.post("/v1/jobs", json=tiny_case("slices")).json()
    assert client.get(f"/v1/jobs/{job['id']}/results").json()["type"] == \
        "urn:hockle:problem:result-not-ready"
    assert _run(settings, job["id"]) == "successful"
    status = client.get(f"/v1/jobs/{job['id']}").json()
    assert status["state"] == "successful" and status["progress"] == 100.0

    base = f"/v1/jobs/{job['id']}/results/variables"
    ok = client.get(f"{base}/kappa", params={"time": "0.05", "component": "1,3"})
    assert ok.status_code == 200 and ok.json()["shape"] == [9, 2]
    # over the cap (40 values here): refused with a problem naming the dims to narrow
    big = client.get(f"{base}/kappa")
    assert big.status_code == 422 and big.json()["type"] == "urn:hockle:problem:slice-too-large"
    assert {e["loc"] for e in big.json()["errors"]} == {"query.time", "query.s", "query.component"}
    absent = client.get(f"{base}/energy_total", params={"s": "0.5"})
    assert absent.status_code == 422 and absent.json()["errors"][0]["loc"] == "query.s"
    bad = client.get(f"{base}/kappa", params={"time": "soon", "component": "3"})
    assert bad.status_code == 422 and bad.json()["errors"][0]["loc"] == "query.time"
    label = client.get(f"{base}/kappa", params={"time": "0", "component": "7"})
    assert label.status_code == 422 and label.json()["errors"][0]["loc"] == "query.component"
    assert client.get(f"{base}/nonexistent").status_code == 404
    series = client.get(f"{base}/energy_total").json()
    assert series["dims"] == ["time"] and len(series["data"]) == 6

    # the global axes are an integer index named x, y, z (CF flag_meanings): either works
    by_name = client.get(f"{base}/position", params={"time": "0.05", "s": "1", "xyz": "x,z"})
    by_index = client.get(f"{base}/position", params={"time": "0.05", "s": "1", "xyz": "1,3"})
    assert by_name.status_code == 200, by_name.text
    assert by_name.json()["data"] == by_index.json()["data"]
    assert by_name.json()["coords"]["xyz"] == [1, 3]
    one = client.get(f"{base}/position", params={"time": "0.05", "s": "1", "xyz": "z"}).json()
    assert one["selected"]["xyz"] == 3 and one["data"] == pytest.approx(1.0)
    wrong = client.get(f"{base}/position", params={"time": "0", "s": "0", "xyz": "q"})
    assert wrong.status_code == 422 and "x, y, z" in wrong.json()["errors"][0]["msg"]

    # the file's ACDD id is the job id; creator and licence come from the settings
    import xarray as xr

    with xr.open_dataset(settings.results_dir / f"{job['id']}.nc") as ds:
        assert ds.attrs["id"] == job["id"]
        assert ds.attrs["creator_name"] == "Rod Dynamics Lab"
        assert ds.attrs["license"] == "CC-BY-4.0"
        assert ds.attrs["Conventions"] == "CF-1.12, ACDD-1.3"


def test_dismissed_while_running_stops_at_the_next_step(client, settings, monkeypatch):
    """The cancel flag is read before every step: dismissed after step 3, the run ends at 3."""
    from worker import tasks

    job = client.post("/v1/jobs", json=tiny_case("stop-at-3", t_end=0.2)).json()
    original = tasks.JobRun.progress

    def progress(self, info):
        original(self, info)
        if info.step == 3:
            assert client.delete(f"/v1/jobs/{self.job_id}").status_code == 202

    monkeypatch.setattr(tasks.JobRun, "progress", progress)
    assert _run(settings, job["id"]) == "dismissed"
    status = client.get(f"/v1/jobs/{job['id']}").json()
    assert status["state"] == "dismissed" and status["reason"] == "cancelled_by_user"
    assert status["step"] == 3 and status["result_partial"]
    summary = client.get(f"/v1/jobs/{job['id']}/summary").json()
    assert summary["time"][-1] == pytest.approx(0.03)


def test_wall_clock_budget_stops_with_timeout_and_keeps_partial(client, settings):
    registry = Registry(settings.registry_url)
    try:
        job = client.post("/v1/jobs", json=long_case("budget", t_end=30.0)).json()
        with registry.sessions.begin() as session:
            from service.registry import Job

            session.get(Job, job["id"]).wall_clock_budget = 0.5
        assert _run(settings, job["id"]).startswith("failed:timeout")
        status = client.get(f"/v1/jobs/{job['id']}").json()
        assert status["state"] == "failed" and status["reason"] == "timeout"
        assert status["result_partial"] and 0 < status["progress"] < 100
    finally:
        registry.dispose()


def test_divergence_is_failed_with_where_it_stopped(client, settings):
    # a huge spin with one Newton iteration and no dt cuts cannot converge
    case = tiny_case("diverges", dt=0.5, t_end=5.0)
    case["boundary"]["start"]["rotation"][2] = {"angular_velocity": 1.0e4}
    case["numerics"]["newton"] = {"max_iterations": 1, "tolerance": 1e-14}
    case["numerics"]["max_dt_cuts"] = 0
    job = client.post("/v1/jobs", json=case).json()
    assert job["state"] == "accepted", job
    outcome = _run(settings, job["id"])
    status = client.get(f"/v1/jobs/{job['id']}").json()
    assert outcome.startswith("failed:"), outcome
    assert status["state"] == "failed"
    assert status["reason"] in ("solver_diverged", "nonfinite_state")
    assert status["error"]["message"] and status["error"]["time"] is not None
    assert status["error"]["step"] is not None


def test_redelivery_of_a_finished_job_does_nothing(client, settings):
    job = client.post("/v1/jobs", json=tiny_case("twice")).json()
    assert _run(settings, job["id"]) == "successful"
    assert _run(settings, job["id"]) == "skipped:successful"
    registry = Registry(settings.registry_url)
    try:
        kinds = [e.kind for e in registry.events(job["id"])]
    finally:
        registry.dispose()
    assert kinds.count("started") == 1 and kinds.count("solve_finished") == 1


def test_openapi_has_readable_operation_ids_and_the_case_schema(client):
    schema = client.get("/openapi.json").json()
    ops = {op["operationId"] for path in schema["paths"].values() for op in path.values()}
    assert {"submit_job", "list_jobs", "get_job", "dismiss_job", "get_job_spec",
            "download_results", "list_result_variables", "get_result_variable", "get_summary",
            "get_health"} <= ops
    body = schema["paths"]["/v1/jobs"]["post"]["requestBody"]["content"]["application/json"]
    assert body["schema"]["$ref"] == "#/components/schemas/Case"
    assert "rod" in schema["components"]["schemas"]["Case"]["properties"]
    assert client.get("/docs").status_code == 200


def test_job_status_eta_is_the_solvers_estimate(client, settings, monkeypatch):
    """The job status's eta_seconds is the solver's EtaModel figure the progress callback
    received (the CLI's ETA), less the seconds since it was written."""
    from worker import tasks

    job = client.post("/v1/jobs", json=tiny_case("eta", t_end=0.2)).json()
    seen = []

    def progress(self, info):
        self._write_progress(info)
        if info.eta_seconds is not None and not seen:
            status = client.get(f"/v1/jobs/{self.job_id}").json()
            seen.append((info.eta_seconds, status["eta_seconds"]))

    monkeypatch.setattr(tasks.JobRun, "progress", progress)
    assert _run(settings, job["id"]) == "successful"
    [(solver_eta, shown)] = seen
    assert solver_eta - 5.0 <= shown <= solver_eta


def test_a_submission_answers_the_advice_on_its_case_and_the_case_runs(client, settings):
    """A twisted curved start 1.9 diameters off its centreline (a 1-m arc of radius 0.5 m,
    τ0 = 20 rad/m, 40 segments) is accepted (201, advice is not a refusal) with the advice
    naming numerics.n_segments in the answer, and its result carries it as hockle_advice;
    a straight case's answer has none."""
    from hockle.api import circular_arc
    from hockle.io import open_result

    plain = client.post("/v1/jobs", json=tiny_case("no advice"))
    assert plain.status_code == 201 and plain.json()["advice"] == []
    case = tiny_case("advised", n_segments=40)
    case["initial"] = {"centreline": circular_arc(case["rod"]["length"], 0.5),
                       "twist_rate": 20.0}
    answer = client.post("/v1/jobs", json=case)
    assert answer.status_code == 201, answer.text
    body = answer.json()
    assert len(body["advice"]) == 1
    assert body["advice"][0].startswith("initial.centreline: on 40 segments")
    assert "numerics.n_segments of about 180" in body["advice"][0]
    assert client.get(f"/v1/jobs/{body['id']}").json()["advice"] == []
    _run(settings, body["id"])
    data = client.get(f"/v1/jobs/{body['id']}/results").content
    path = settings.data_dir / "advised.nc"
    path.write_bytes(data)
    with open_result(path) as ds:
        assert ds.attrs["hockle_advice"] == body["advice"][0]


def test_a_submission_answers_the_plausibility_warnings_on_its_case(client):
    """A Young's modulus of 12.5 Pa (meant as MPa) is accepted (201: a warning is not a
    refusal) with the warning naming rod.youngs_modulus and its number in the answer, as
    the dashboard's check answers it; a plausible case's answer has none."""
    plain = client.post("/v1/jobs", json=tiny_case("plausible"))
    assert plain.status_code == 201 and plain.json()["warnings"] == []
    case = tiny_case("in MPa")
    case["rod"]["youngs_modulus"] = 12.5
    answer = client.post("/v1/jobs", json=case)
    assert answer.status_code == 201, answer.text
    warnings = answer.json()["warnings"]
    assert warnings[0]["loc"] == "rod.youngs_modulus"
    assert warnings[0]["type"] == "implausible_modulus" and "12.5 Pa" in warnings[0]["msg"]
    assert client.get(f"/v1/jobs/{answer.json()['id']}").json()["warnings"] == []
    checked = client.post("/v1/ui/validate", json=case)
    assert checked.status_code == 200 and checked.json()["warnings"] == warnings


def _thin_plectoneme_at_ten_times_its_step():
    """The contact suite's thin-rod plectoneme (tests/solver/test_contact_run.py) at Δt = 0.2 s,
    10x its own, to 10 s: its loop sweeps across the closure of an end's tangent at
    9.4 s (docs/numerics.md § 6), and its result carries hockle_warning."""
    from rodcases import thin_plectoneme_case

    return thin_plectoneme_case(0.2, 10.0).model_dump(mode="json")


def test_a_completed_run_with_a_warning_says_it_in_the_job_message(client, settings):
    """A run whose result carries hockle_warning ends successful with that warning as
    the job's message; a run without one has no message."""
    job = client.post("/v1/jobs", json=_thin_plectoneme_at_ten_times_its_step())
    assert job.status_code == 201, job.text
    assert _run(settings, job.json()["id"]) == "successful"
    status = client.get(f"/v1/jobs/{job.json()['id']}").json()
    assert status["state"] == "successful"
    assert "crossed the closure of the end tangents" in status["message"]
    plain = client.post("/v1/jobs", json=tiny_case("no warning")).json()
    assert _run(settings, plain["id"]) == "successful"
    assert client.get(f"/v1/jobs/{plain['id']}").json()["message"] is None


def test_hockle_submit_wait_prints_a_completed_runs_warning(client, settings, monkeypatch,
                                                            tmp_path, capsys):
    """`hockle submit CASE --wait` prints a successful job's warning to stderr (the job
    run here by the worker's code while the client waits)."""
    from hockle.cli import main
    from service import client as client_module

    monkeypatch.delenv("HOCKLE_API_KEY", raising=False)
    real_init, real_wait = client_module.HockleClient.__init__, client_module.HockleClient.wait

    def through_the_test_client(self, url=None, **kwargs):
        real_init(self, "http://testserver", transport=client._transport, **kwargs)

    def run_then_wait(self, job_id, **kwargs):
        _run(settings, job_id)
        return real_wait(self, job_id, **kwargs)

    monkeypatch.setattr(client_module.HockleClient, "__init__", through_the_test_client)
    monkeypatch.setattr(client_module.HockleClient, "wait", run_then_wait)
    case = tmp_path / "thin.json"
    case.write_text(json.dumps(_thin_plectoneme_at_ten_times_its_step()))
    assert main(["submit", str(case), "--wait", "--fresh"]) == 0
    captured = capsys.readouterr()
    assert "successful" in captured.out
    assert "hockle submit: warning: the writhe crossed the closure" in captured.err
