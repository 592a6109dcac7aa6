"""Hostile and absurd input, in-process (SQLite registry, in-memory broker, the worker's task
code and the real solver in this process): every refusal is a 422 (or 400/503) problem naming
the field or parameter, never a 500; a locked registry answers 503 with Retry-After; a reused
result says so. The table of these inputs and their answers is in docs/service.md
("Hostile input").
"""
from __future__ import annotations

import json
import sqlite3
import threading
import time

import pytest
from fastapi import Request
from fastapi.testclient import TestClient

from service.app import create_app
from service.settings import Settings
from svc_support import tiny_case

PROBLEM = "application/problem+json"

#: the in-process service's settings (svc_support's ``settings`` and ``client`` fixtures);
#: server errors are answered, as a client sees them
SERVICE_SETTINGS = dict(max_case_size=2_000_000, registry_busy_timeout=1.0)
RAISE_SERVER_EXCEPTIONS = False


@pytest.fixture(scope="module")
def finished_job(client, settings):
    """A successful tiny job (run with the worker's task code in this process)."""
    from worker.tasks import run_job

    response = client.post("/v1/jobs", json=tiny_case("hostile-finished"))
    assert response.status_code == 201, response.text
    job_id = response.json()["id"]
    run_job(job_id, "hostile@test", settings)
    assert client.get(f"/v1/jobs/{job_id}").json()["state"] == "successful"
    return job_id


def _locs(response) -> list[str]:
    return [e["loc"] for e in response.json().get("errors") or []]


def _case_with(path: str, value) -> dict:
    case = tiny_case("absurd")
    node = case
    *parents, last = path.split(".")
    for key in parents:
        node = node.setdefault(key, {})
    node[last] = value
    return case


# --- sizes beyond sense ---------------------------------------------------------------------
ABSURD = {
    "dt larger than the run": ("numerics.dt", 1e308, "numerics.dt"),
    "dt a little larger than t_end": ("numerics.dt", 0.06, "numerics.dt"),
    "diameter larger than the rod": ("rod.diameter", 1e300, "rod.diameter"),
    "output cadence beyond the run": ("output.every", 1e12, "output.every"),
    "steps over the case-size limit": ("numerics.dt", 1e-9, "numerics.dt"),
}


@pytest.mark.parametrize("path,value,loc", ABSURD.values(), ids=list(ABSURD))
def test_absurd_sizes_are_refused_naming_the_field(client, path, value, loc):
    response = client.post("/v1/jobs", json=_case_with(path, value))
    assert response.status_code == 422, response.text
    assert response.headers["content-type"].startswith(PROBLEM)
    assert loc in _locs(response), response.text


def test_a_dt_equal_to_the_run_is_still_accepted(client):
    response = client.post("/v1/jobs", json=_case_with("numerics.dt", 0.05))
    assert response.status_code == 201, response.text
    assert response.json()["n_steps"] == 1


# --- integers too large for a float -----------------------------------------------------------
@pytest.mark.parametrize("field", ["youngs_modulus", "length"])
@pytest.mark.parametrize("media", ["application/json", "application/yaml"])
def test_an_integer_too_large_for_a_float_is_a_422(client, field, media):
    case = tiny_case("overflow")
    case["rod"][field] = 12345
    huge = "1" + "0" * 400
    text = json.dumps(case).replace("12345", huge)      # JSON is YAML too
    response = client.post("/v1/jobs", content=text, headers={"content-type": media})
    assert response.status_code == 422, response.text
    assert f"rod.{field}" in _locs(response)


# --- nesting ------------------------------------------------------------------------------------
def _deep(depth: int):
    value = 1.0
    for _ in range(depth):
        value = [value]
    return value


def _yaml_deep(depth: int) -> str:
    return "[" * depth + "1" + "]" * depth


NESTED = {
    "job JSON": ("/v1/jobs", "application/json",
                 lambda d: json.dumps({**tiny_case("deep"), "name": _deep(d)})),
    "job YAML": ("/v1/jobs", "application/yaml",
                 lambda d: json.dumps(tiny_case("deep"))[:-1] + f', "deep": {_yaml_deep(d)}}}'),
    "sweep JSON": ("/v1/sweeps", "application/json",
                   lambda d: json.dumps({"base": tiny_case("deep"),
                                         "parameters": {"rod.length": [_deep(d)]}})),
    "sweep YAML": ("/v1/sweeps", "application/yaml",
                   lambda d: json.dumps({"base": tiny_case("deep")})[:-1]
                   + f', "parameters": {{"rod.length": [{_yaml_deep(d)}]}}}}'),
}


@pytest.mark.parametrize("depth", [40, 500])
@pytest.mark.parametrize("route,media,make", NESTED.values(), ids=list(NESTED))
def test_nesting_beyond_the_fixed_depth_is_a_422_in_every_body(client, route, media, make,
                                                               depth):
    response = client.post(route, content=make(depth), headers={"content-type": media})
    assert response.status_code == 422, response.text[:500]
    assert response.headers["content-type"].startswith(PROBLEM)
    errors = response.json()["errors"]
    assert any(e["type"] == "nesting_too_deep" for e in errors), errors


# --- a registry that does not answer ------------------------------------------------------------
def test_a_locked_sqlite_registry_answers_503_with_retry_after(client, settings):
    """SQLite ``BEGIN EXCLUSIVE`` held by another connection: POST /v1/jobs gives up after the
    busy timeout (1 s here) with a 503 problem naming the registry and Retry-After, not a 500."""
    path = settings.registry_url.split("///", 1)[1]
    holder = sqlite3.connect(path, timeout=1, isolation_level=None)
    holder.execute("BEGIN EXCLUSIVE")
    try:
        start = time.monotonic()
        response = client.post("/v1/jobs", json=tiny_case("while-locked"))
        took = time.monotonic() - start
    finally:
        holder.execute("ROLLBACK")
        holder.close()
    assert response.status_code == 503, response.text
    assert response.headers["content-type"].startswith(PROBLEM)
    assert response.json()["type"] == "urn:hockle:problem:registry-unavailable"
    assert int(response.headers["retry-after"]) >= 1
    assert took < 10, took
    # and it answers again once the lock is gone
    assert client.post("/v1/jobs", json=tiny_case("after-lock")).status_code == 201


# --- query parameters ---------------------------------------------------------------------------
@pytest.mark.parametrize("method,route,param", [
    ("GET", "/v1/jobs", "colour"),
    ("GET", "/v1/jobs", "page-size"),
    ("GET", "/v1/health", "liv"),
    ("POST", "/v1/jobs", "fersh"),
])
def test_an_unknown_query_parameter_is_a_422_naming_it(client, method, route, param):
    kwargs = {"json": tiny_case("query")} if method == "POST" else {}
    response = client.request(method, route, params={param: "1"}, **kwargs)
    assert response.status_code == 422, response.text
    assert f"query.{param}" in _locs(response)


def test_unknown_query_parameters_on_job_routes(client, finished_job):
    for route in ("", "/spec", "/results", "/results/variables", "/results/variables/kappa",
                  "/summary"):
        response = client.get(f"/v1/jobs/{finished_job}{route}", params={"tiem": "0.01"})
        assert response.status_code == 422, (route, response.text)
        assert "query.tiem" in _locs(response)


@pytest.mark.parametrize("query,loc", [
    ({"time": "5"}, "query.time"),            # t_end is 0.05 s
    ({"time": "-1"}, "query.time"),
    ({"time": "0.04:0.01"}, "query.time"),    # reversed
    ({"time": "0.01,7"}, "query.time"),
    ({"time": "1:2"}, "query.time"),          # a range that selects nothing
    ({"s": "2"}, "query.s"),                  # the rod is 1 m
    ({"s": "0.9:0.1"}, "query.s"),
    ({"component": "3:1"}, "query.component"),
    ({"component": "7"}, "query.component"),
    ({"time": "nan"}, "query.time"),
])
def test_slice_selectors_out_of_range_or_reversed_are_a_422(client, finished_job, query, loc):
    response = client.get(f"/v1/jobs/{finished_job}/results/variables/kappa", params=query)
    assert response.status_code == 422, response.text
    assert loc in _locs(response)


def test_slice_selectors_in_range_still_answer(client, finished_job):
    response = client.get(f"/v1/jobs/{finished_job}/results/variables/kappa",
                          params={"time": "0.02", "s": "0:0.5", "component": "1,3"})
    assert response.status_code == 200, response.text
    body = response.json()
    assert body["selected"]["time"] == pytest.approx(0.02)
    assert body["shape"] == [5, 2]


# --- a reused result says so --------------------------------------------------------------------
def test_a_reused_result_is_reported_as_reused(client, finished_job):
    case = tiny_case("hostile-finished")
    response = client.post("/v1/jobs", json=case)
    assert response.status_code == 200, response.text
    body = response.json()
    assert body["id"] == finished_job
    assert body["reused"] == "identical_case"
    assert response.headers["hockle-reused"] == "identical_case"
    fresh = client.post("/v1/jobs", json=case, params={"fresh": "true"})
    assert fresh.status_code == 201
    assert fresh.json()["reused"] is None and "hockle-reused" not in fresh.headers
    replay = client.post("/v1/jobs", json=case, params={"fresh": "true"},
                         headers={"Idempotency-Key": "hostile-key-1"})
    again = client.post("/v1/jobs", json=case, params={"fresh": "true"},
                        headers={"Idempotency-Key": "hostile-key-1"})
    assert replay.status_code == 201 and again.status_code == 200
    assert again.json()["reused"] == "idempotency_key"
    assert client.get(f"/v1/jobs/{finished_job}").json()["reused"] is None


# --- the catch-all error path -------------------------------------------------------------------
def test_an_unexpected_error_is_one_500_logged_once_and_the_connection_is_kept(settings,
                                                                             caplog):
    """A real server (uvicorn, as `hockle serve` runs it) and a keep-alive client: after a
    route raises, the 500 problem comes once, one log record carries the traceback, and the
    client's next request goes over the same connection."""
    import logging

    import httpx
    import uvicorn

    from svc_support import free_port

    app = create_app(settings)

    @app.get("/v1/test-boom")
    def boom():
        raise RuntimeError("boom for the test")

    @app.get("/v1/test-peer")
    def peer(request: Request):
        return {"port": request.client.port}

    port = free_port()
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="info",
                                           timeout_keep_alive=30))
    thread = threading.Thread(target=server.run, daemon=True)
    caplog.set_level(logging.INFO)
    thread.start()
    try:
        deadline = time.monotonic() + 30
        while not server.started:
            assert time.monotonic() < deadline, "the server did not start"
            time.sleep(0.05)
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=10) as http:
            first = http.get("/v1/test-peer").json()["port"]
            response = http.get("/v1/test-boom")
            assert response.status_code == 500
            assert response.headers["content-type"].startswith(PROBLEM)
            assert response.json()["type"] == "urn:hockle:problem:internal-error"
            assert "boom for the test" not in response.text
            assert http.get("/v1/test-peer").json()["port"] == first
    finally:
        server.should_exit = True
        thread.join(timeout=10)
    tracebacks = [r for r in caplog.records if r.exc_info and "boom" in str(r.exc_info[1])]
    assert len(tracebacks) == 1, [(r.name, r.getMessage()) for r in tracebacks]


# --- metrics --------------------------------------------------------------------------------------
def test_metrics_export_job_counts_and_queue_depth(client):
    from prometheus_client.parser import text_string_to_metric_families

    counts = client.get("/v1/health").json()["jobs"]
    response = client.get("/metrics")
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/plain")
    samples = {(s.name, tuple(sorted(s.labels.items()))): s.value
               for family in text_string_to_metric_families(response.text)
               for s in family.samples}
    for state in ("accepted", "running", "successful", "failed", "dismissed"):
        assert samples[("hockle_jobs", (("state", state),))] == counts.get(state, 0)
    assert samples[("hockle_registry_up", ())] == 1
    assert samples[("hockle_broker_up", ())] == 1
    assert ("hockle_queue_depth", (("queue", "hockle"),)) in samples
    assert client.get("/metrics", params={"x": "1"}).status_code == 200   # not a /v1 route


def test_hockle_submit_says_when_it_reused_a_result(client, finished_job, tmp_path,
                                                    monkeypatch, capsys):
    import argparse

    import service.client
    from hockle.service_commands import submit

    transport = client._transport       # the in-process app behind the test client

    class InProcess(service.client.HockleClient):
        def __init__(self, base_url=None, **kwargs):
            super().__init__("http://testserver", transport=transport, api_key="")

    monkeypatch.setattr(service.client, "HockleClient", InProcess)
    path = tmp_path / "case.json"
    path.write_text(json.dumps(tiny_case("hostile-finished")))
    args = argparse.Namespace(url=None, case=str(path), idempotency_key=None, fresh=False,
                              time_limit=None, wait=False, api_key=None, output=None)
    assert submit(args) == 0
    out = capsys.readouterr().out
    assert f"job {finished_job} successful" in out
    assert f"reused the result of job {finished_job}" in out and "--fresh" in out


# --- the seabed section (docs/seabed.md): refused before any work, naming the field --------
_GRID = {"x": [0.0, 1.0], "y": [0.0, 1.0], "z": [[-1.0, -1.0], [-1.0, -1.0]]}
SEABED = {
    "unsorted bathymetry axis": ({"bathymetry": {**_GRID, "x": [1.0, 0.0]}},
                                 None, "seabed.bathymetry.x[1]"),
    "bathymetry of the wrong shape": ({"bathymetry": {**_GRID, "z": [[-1.0, -1.0]]}},
                                      None, "seabed.bathymetry.z"),
    "negative stiffness": ({"elevation": -1.0, "normal_stiffness": -1.0}, None,
                           "seabed.normal_stiffness"),
    "negative friction": ({"elevation": -1.0, "friction": {"axial": -0.1, "lateral": 0.1}},
                          None, "seabed.friction.axial"),
    "gravity away from the bottom": ({"elevation": -1.0}, [0.0, 0.0, 9.81], "gravity"),
    "a cable starting below the bottom": ({"elevation": 0.5}, None, "seabed.elevation"),
}


@pytest.mark.parametrize("seabed,gravity,loc", SEABED.values(), ids=list(SEABED))
def test_bad_seabed_input_is_a_422_naming_the_field(client, seabed, gravity, loc):
    case = tiny_case("seabed")
    case["seabed"] = seabed
    if gravity is not None:
        case["gravity"] = gravity
    response = client.post("/v1/jobs", json=case)
    assert response.status_code == 422, response.text
    assert response.headers["content-type"].startswith(PROBLEM)
    assert loc in _locs(response), response.text


def test_a_seabed_case_is_accepted(client):
    case = tiny_case("seabed-ok")
    case["seabed"] = {"bathymetry": _GRID, "friction": {"axial": 0.2, "lateral": 0.4}}
    response = client.post("/v1/jobs", json=case)
    assert response.status_code == 201, response.text


# --- bodies that cost more to parse than they weigh (issue 80's audit) -------------------------
# Every POST route that takes a case parses its body on a thread of its own within a budget
# (service.validation.parse_body): YAML aliases counted as the nodes they stand for, nesting
# checked through aliases, integer literals of at most 309 digits, a time limit.
def _yaml_body(doc: dict, extra: str) -> str:
    """``doc`` as block YAML with the lines ``extra`` appended at its top level."""
    import yaml

    return yaml.safe_dump(doc, sort_keys=False) + extra


def alias_bomb(levels: int = 9, width: int = 9) -> str:
    """Top-level YAML lines whose last key expands to width**levels scalars (the audit's
    383-byte body: 9 levels of 9)."""
    lines = ["l0: &l0 [" + ",".join(["x"] * width) + "]"]
    for k in range(1, levels):
        lines.append(f"l{k}: &l{k} [" + ",".join([f"*l{k - 1}"] * width) + "]")
    return "\n".join(lines) + "\n"


def _continuation_body(case: dict) -> dict:
    return {"case": case, "continuation": {"parameter": "boundary.end.translation.2.force",
                                           "to": -0.4}}


#: route -> (the valid body around a case, where the case's own fields are in it)
POST_CASE_ROUTES = {
    "jobs": ("/v1/jobs", lambda case: case, ""),
    "sweeps": ("/v1/sweeps", lambda case: {"base": case, "parameters": {"rod.length": [1.0]}},
               "base."),
    "continuations": ("/v1/continuations", _continuation_body, "case."),
    "ui-validate": ("/v1/ui/validate", lambda case: case, ""),
}
YAML = {"content-type": "application/yaml"}


@pytest.mark.parametrize("route,wrap,prefix", POST_CASE_ROUTES.values(),
                         ids=list(POST_CASE_ROUTES))
def test_an_alias_bomb_is_refused_before_it_expands(client, route, wrap, prefix):
    """9 levels of 9 aliases (387 million scalars once expanded, 400 bytes): 413 naming where
    the expansion passed the budget, in milliseconds (the nesting check walked every path:
    23-29 s with the event loop held on /v1/sweeps, 24.6 s of a thread on the others)."""
    text = _yaml_body(wrap(tiny_case("bomb")), alias_bomb())
    assert len(alias_bomb()) < 400
    start = time.monotonic()
    response = client.post(route, content=text, headers=YAML)
    took = time.monotonic() - start
    assert response.status_code == 413, response.text[:500]
    assert response.headers["content-type"].startswith(PROBLEM)
    errors = response.json()["errors"]
    assert errors[0]["type"] == "too_many_nodes" and errors[0]["loc"].startswith("l")
    assert took < 5.0, took       # milliseconds alone; generous for a loaded machine


@pytest.mark.parametrize("extra,etype,loc", [
    ("a: &a [1, *a]\n", "recursive_alias", "a[1]"),
    ("a: &a {b: *a}\n", "recursive_alias", "a.b"),
    # 10 lists behind an alias put 25 deep: 34 levels through the alias, 26 as written
    ("a: &a [[[[[[[[[[1]]]]]]]]]]\nb: [[[[[[[[[[[[[[[[[[[[[[[[*a]]]]]]]]]]]]]]]]]]]]]]]\n",
     "nesting_too_deep", "b" + "[0]" * 24),
    # many aliases of a wide list: 3,000 x 1,000 values in 6 kB
    ("w: &w [" + ", ".join(["1"] * 1000) + "]\nv: [" + ", ".join(["*w"] * 3000) + "]\n",
     "too_many_nodes", None),
], ids=["recursive-list", "recursive-mapping", "deep-through-alias", "wide"])
@pytest.mark.parametrize("route,wrap,prefix", POST_CASE_ROUTES.values(),
                         ids=list(POST_CASE_ROUTES))
def test_aliases_that_recurse_nest_or_multiply_are_refused(client, route, wrap, prefix, extra,
                                                           etype, loc):
    response = client.post(route, content=_yaml_body(wrap(tiny_case("alias")), extra),
                           headers=YAML)
    assert response.status_code in (413, 422), response.text[:500]
    errors = response.json()["errors"]
    assert errors[0]["type"] == etype, errors
    if loc is not None:
        assert errors[0]["loc"] == loc


def test_aliases_and_merge_keys_of_a_real_case_still_work(client):
    """A case that shares its boundary conditions through anchors and a merge key: valid."""
    case = tiny_case("anchors")
    doc = _yaml_body({k: v for k, v in case.items() if k != "boundary"}, (
        "boundary:\n"
        "  start:\n"
        "    translation: [&fixed {velocity: 0}, *fixed, *fixed]\n"
        "    rotation: [&spin {angular_velocity: 0}, {<<: *spin}, {angular_velocity: 1.0}]\n"
        "  end:\n"
        "    translation: [*fixed, *fixed, {force: 0}]\n"
        "    rotation: [*spin, *spin, *spin]\n"))
    response = client.post("/v1/ui/validate", content=doc, headers=YAML)
    assert response.status_code == 200, response.text
    assert response.json()["name"] == "anchors"


@pytest.mark.parametrize("digits", [310, 4301, 20000])
@pytest.mark.parametrize("media", ["application/json", "application/yaml"])
@pytest.mark.parametrize("route,wrap,prefix", POST_CASE_ROUTES.values(),
                         ids=list(POST_CASE_ROUTES))
def test_an_integer_literal_beyond_any_double_is_a_422_naming_it(client, route, wrap, prefix,
                                                                 media, digits):
    """More than 4,300 digits raised ValueError in Python's int() (JSON and YAML: a 500 on
    every POST route); 310 digits to 4,300 reached the case as an int beyond any float."""
    case = tiny_case("digits")
    case["rod"]["youngs_modulus"] = 12345
    text = json.dumps(wrap(case)).replace("12345", "9" * digits)      # JSON is YAML too
    response = client.post(route, content=text, headers={"content-type": media})
    assert response.status_code == 422, response.text[:500]
    errors = response.json()["errors"]
    assert errors[0]["type"] == "integer_too_long"
    assert errors[0]["loc"] == f"{prefix}rod.youngs_modulus"
    assert f"{digits} digits" in errors[0]["msg"]


def test_a_yaml_hex_literal_of_thousands_of_digits_is_a_422(client):
    """int('0x...', 16) has no digit limit, but the number's decimal text (its repr in any
    message or JSON) would: refused by its length as written."""
    text = json.dumps(tiny_case("hex")).replace('"numerics": {', '"numerics": {"n_segments": 0x'
                                                 + "f" * 5000 + ", ", 1)
    text = text.replace('"n_segments": 8, ', "")
    response = client.post("/v1/jobs", content=text, headers=YAML)
    assert response.status_code == 422, response.text[:500]
    assert response.json()["errors"][0]["loc"] == "numerics.n_segments"


def test_a_large_yaml_body_is_parsed_within_its_time_budget(client, settings):
    """3.4 MB of YAML (500,000 numbers, under the 4-MiB limit; the audit's 3.8-MB body held
    the event loop for 48 s): parsed on a parse thread and refused once it has taken
    HOCKLE_BODY_PARSE_TIMEOUT (2 s by default), or refused by the case; never a 500 and never
    much longer than the budget."""
    case = tiny_case("large")
    text = _yaml_body(case, "extra: [" + ", ".join(str(k) for k in range(500_000)) + "]\n")
    assert 3_000_000 < len(text) < 4 * 1024 * 1024
    start = time.monotonic()
    response = client.post("/v1/jobs", content=text, headers=YAML)
    took = time.monotonic() - start
    assert response.status_code in (413, 422), response.text[:300]
    if response.status_code == 413:
        assert response.json()["errors"][0]["type"] == "parse_time_exceeded"
    assert took < settings.body_parse_timeout + 10.0, took


# --- ids, tokens and dates that cannot name anything (PostgreSQL refuses a NUL) ------------------
@pytest.fixture(scope="module")
def pg_client(tmp_path_factory, pg_url):
    """The API in-process on a PostgreSQL registry of its own (skipped without a server)."""
    root = tmp_path_factory.mktemp("hostile-pg")
    settings = Settings(data_dir=root, broker_url="memory://", database_url=pg_url,
                        progress_interval=0.0)
    with TestClient(create_app(settings), raise_server_exceptions=False) as c:
        yield c


def _token(created: str, job_id: str) -> str:
    import base64

    return base64.urlsafe_b64encode(f"{created}|{job_id}".encode()).decode().rstrip("=")


NUL_ID = "3a3f3b17-f338-4b0c-\x00d9e-283bb17603ab"


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_a_nul_character_in_an_id_is_unknown_not_an_error(request, backend):
    """Job and sweep ids in paths, page_token and initial.from_result.job holding a NUL
    character (PostgreSQL: 500 "PostgreSQL text fields cannot contain NUL" on each): ids
    are checked before they reach the registry, so each is what any unknown id is."""
    client = request.getfixturevalue("client" if backend == "sqlite" else "pg_client")
    quoted = NUL_ID.replace("\x00", "%00")
    for route in ("", "/spec", "/results", "/results/variables", "/results/variables/kappa",
                  "/summary"):
        response = client.get(f"/v1/jobs/{quoted}{route}")
        assert response.status_code == 404, (route, response.text)
        assert response.json()["type"] == "urn:hockle:problem:job-not-found"
    assert client.delete(f"/v1/jobs/{quoted}").status_code == 404
    for route in ("events", "seabed", "paraview", "branch"):
        assert client.get(f"/v1/ui/jobs/{quoted}/{route}").status_code == 404, route
    for route in ("", "/results"):
        response = client.get(f"/v1/sweeps/{quoted}{route}")
        assert response.status_code == 404, (route, response.text)
    assert client.delete(f"/v1/sweeps/{quoted}").status_code == 404
    assert client.get(f"/v1/ui/sweeps/{quoted}/map").status_code == 404
    # a page token of this server's form whose id holds a NUL
    token = _token("2026-11-27T10:00:00", NUL_ID)
    for route in ("/v1/jobs", "/v1/ui/jobs"):
        response = client.get(route, params={"page_token": token})
        assert response.status_code == 422, response.text
        assert "query.page_token" in _locs(response)
    case = tiny_case("nul-start")
    case["initial"] = {"from_result": {"job": NUL_ID, "time": 0.0}}
    response = client.post("/v1/jobs", json=case)
    assert response.status_code == 422, response.text
    assert "initial.from_result.job" in _locs(response)
    sweep = {"base": tiny_case("nul-sweep"), "parameters": {"rod.length": [1.0]},
             "name": "a\x00b"}
    response = client.post("/v1/sweeps", json=sweep)
    assert response.status_code == 422, response.text
    assert "name" in _locs(response)
    response = client.post("/v1/jobs", json=tiny_case("nul-key"),
                           headers={"Idempotency-Key": "key\x01one"})
    assert response.status_code == 422 and "header.Idempotency-Key" in _locs(response)


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
@pytest.mark.parametrize("param,value", [
    ("created_before", "9999-12-31T23:59:59-05:00"),   # past the year 9999 in UTC
    ("created_after", "0001-01-01T00:00:00+05:00"),    # before the year 1 in UTC
    ("created_before", "0001-01-01T00:00:00+05:00"),
    ("created_after", "9999-12-31T23:59:59-05:00"),
])
def test_dates_beyond_the_representable_range_are_clamped(request, backend, param, value):
    """Aware times whose UTC lies outside the years 1-9999 (a 500, OverflowError in
    astimezone): clamped to the nearest representable instant, so the filter still means
    what it says: created before the year 10000 is every job, after it none."""
    client = request.getfixturevalue("client" if backend == "sqlite" else "pg_client")
    assert client.post("/v1/jobs", json=tiny_case(f"dated-{backend}")).status_code in (200, 201)
    response = client.get("/v1/jobs", params={param: value})
    assert response.status_code == 200, response.text
    everything = (param == "created_before") == value.startswith("9999")
    assert bool(response.json()["jobs"]) == everything, response.text[:300]


# --- finite but absurd physics: refused at validation with the reason -------------------------
ABSURD_PHYSICS = {
    "Young's modulus 5e-324": ("rod.youngs_modulus", 5e-324, "rod.youngs_modulus"),
    "shear modulus 5e-324": ("rod.shear_modulus", 5e-324, "rod.shear_modulus"),
    "density 5e-324": ("rod.density", 5e-324, "rod.density"),
    "diameter 5e-324": ("rod.diameter", 5e-324, "rod.diameter"),
    "diameter profile to 1e-100": ("rod.diameter", {"s": [0.0, 1.0], "value": [0.02, 1e-100]},
                                   "rod.diameter"),
    "twist rate 1e308": ("initial.twist_rate", 1e308, "initial.twist_rate"),
    "twist rate past pi per cell": ("initial.twist_rate", 26.0, "initial.twist_rate"),
}


@pytest.mark.parametrize("path,value,loc", ABSURD_PHYSICS.values(), ids=list(ABSURD_PHYSICS))
def test_absurd_physics_is_refused_at_validation_naming_the_field(client, path, value, loc):
    """Each ran to internal_error before (a zero stiffness or mass underflowed from 5e-324, a
    twist of 1e308 rad/m made the quaternions non-finite): now a 422 naming the field and the
    quantity the solver could not hold (solver.case.representability_errors) or the grid's
    limit of π rad of twist per cell (Case._check_twist_resolved)."""
    response = client.post("/v1/jobs", json=_case_with(path, value))
    assert response.status_code == 422, response.text
    errors = [e for e in response.json()["errors"] if e["loc"] == loc]
    assert errors, response.text
    assert errors[0]["type"] in ("not_representable", "not_resolved")
    assert any(word in errors[0]["msg"] for word in ("double precision", "π rad"))


def test_the_bounds_are_double_precision_not_a_taste(client):
    """The bending stiffness E·πD⁴/64 at the smallest normal double is accepted, a quarter of
    it refused: the bound is the solver's arithmetic, not a plausible range (plausibility
    is a warning's business)."""
    import math
    import sys

    j1 = math.pi * 0.02 ** 4 / 64
    low = sys.float_info.min / j1
    assert client.post("/v1/ui/validate", json=_case_with("rod.youngs_modulus", low * 1.01)
                       ).status_code == 200
    response = client.post("/v1/ui/validate", json=_case_with("rod.youngs_modulus", low / 4))
    assert response.status_code == 422 and "rod.youngs_modulus" in _locs(response)
    # a twist of just under half a turn per cell is held; the tiny case's cell is 0.125 m
    assert client.post("/v1/ui/validate", json=_case_with("initial.twist_rate", 25.0)
                       ).status_code == 200


def test_a_start_time_of_1e308_is_a_422_in_the_api_and_one_message_in_the_cli(
        client, finished_job, tmp_path, capsys):
    """initial.from_result.time = 1e308: an OverflowError in the case's own check (500 in
    the API, a traceback in the CLI); now refused naming the field."""
    from hockle.cli import main

    case = tiny_case("late-start")
    case["initial"] = {"from_result": {"job": finished_job, "time": 1e308}}
    response = client.post("/v1/jobs", json=case)
    assert response.status_code == 422, response.text
    assert "initial.from_result.time" in _locs(response)
    case["initial"] = {"from_result": {"file": str(tmp_path / "earlier.nc"), "time": 1e308}}
    path = tmp_path / "late.json"
    path.write_text(json.dumps(case))
    for command in (["validate", str(path)], ["run", str(path), "-o", str(tmp_path / "x.nc")]):
        assert main(command) == 2
        err = capsys.readouterr().err
        assert "Traceback" not in err and "initial.from_result.time" in err, err


@pytest.mark.parametrize("to", [1e308, -1e308, 1e15])
def test_a_continuation_range_beyond_double_precision_is_a_422(client, to):
    """A `to` of ±1e308 N (LinAlgError, internal_error at run time): the change of the end
    force over the range, in the rod's force unit EJ/L², is more than the 1e14 the bordered
    system's pivots can hold (solver.continuation.range_unrepresentable)."""
    response = client.post("/v1/continuations", json=_continuation_body(tiny_case("far"))
                           | {"continuation": {"parameter": "boundary.end.translation.2.force",
                                               "to": to}})
    assert response.status_code == 422, response.text
    errors = response.json()["errors"]
    assert errors[0]["loc"] == "continuation.to", errors
    assert "double precision" in errors[0]["msg"]


def test_a_continuation_in_the_modulus_to_1e300_is_a_422(client):
    body = {"case": tiny_case("stiffer"),
            "continuation": {"parameter": "rod.youngs_modulus", "to": 1e300}}
    response = client.post("/v1/continuations", json=body)
    assert response.status_code == 422, response.text
    assert response.json()["errors"][0]["loc"] == "continuation.to"
    body["continuation"]["to"] = 5e-324            # the case at `to` is refused itself
    response = client.post("/v1/continuations", json=body)
    assert response.status_code == 422, response.text
    assert response.json()["errors"][0]["loc"] == "continuation.to"


def test_a_sweep_member_with_absurd_physics_is_a_422_naming_it(client):
    body = {"base": tiny_case("sweep-absurd"), "parameters": {"rod.density": [1500.0, 5e-324]}}
    response = client.post("/v1/sweeps", json=body)
    assert response.status_code == 422, response.text
    assert "members[1].rod.density" in _locs(response)


def _numeric_paths(doc, prefix=""):
    if isinstance(doc, dict):
        for key, value in doc.items():
            yield from _numeric_paths(value, f"{prefix}{key}.")
    elif isinstance(doc, list):
        for k, value in enumerate(doc):
            yield from _numeric_paths(value, f"{prefix}{k}.")
    elif isinstance(doc, (int, float)) and not isinstance(doc, bool):
        yield prefix[:-1]


@pytest.mark.parametrize("value", [5e-324, -5e-324, 1e308, -1e308, 10 ** 309])
def test_no_numeric_field_takes_the_api_to_a_500(client, value):
    """Every number of a case (with a fluid, gravity and contact) set to the extremes of a
    double: each answer is 200 or a 422, never a 500."""
    case = tiny_case("extremes")
    case["fluid"] = {"density": 1000.0}
    case["gravity"] = [0.0, 0.0, -9.81]
    case["contact"] = {}
    case["initial"] = {"twist_rate": 1.0}
    answers = {}
    for path in _numeric_paths(case):
        doc = json.loads(json.dumps(case))
        node = doc
        for key in path.split(".")[:-1]:
            node = node[int(key)] if isinstance(node, list) else node[key]
        last = path.split(".")[-1]
        node[int(last) if isinstance(node, list) else last] = value
        response = client.post("/v1/ui/validate", json=doc)
        answers[path] = response.status_code
    assert set(answers.values()) <= {200, 422}, answers


# --- a continuation job's branch on the routes made for time series ----------------------------
@pytest.fixture(scope="module")
def branch_job(client, settings):
    """A successful continuation job: the Euler column on 10 segments, 8 points."""
    from solver.case import Case
    from worker.tasks import run_job

    from svc_support import REPO

    case = Case.from_file(REPO / "cases" / "euler-column.yaml").model_dump(mode="json")
    case["numerics"].pop("ds", None)
    case["numerics"]["n_segments"] = 10
    response = client.post("/v1/continuations", json={"case": case, "continuation": {
        "parameter": "boundary.end.translation.2.force", "to": -0.4, "max_points": 8}})
    assert response.status_code == 201, response.text
    job_id = response.json()["id"]
    assert run_job(job_id, "hostile-branch@test", settings) == "successful"
    return job_id


def test_the_paraview_download_of_a_branch_is_its_shapes(client, branch_job):
    """It was a 500 (KeyError: 'time' in hockle/export.py), then a 409; now the branch's
    stored shapes, zipped (tests/service/test_dashboard.py reads them back). The run's
    events route answers a branch with a one-line 409 naming the branch route."""
    response = client.get(f"/v1/ui/jobs/{branch_job}/paraview")
    assert response.status_code == 200, response.text[:300]
    assert response.headers["content-type"] == "application/zip"
    events = client.get(f"/v1/ui/jobs/{branch_job}/events")
    assert events.status_code == 409
    body = events.json()
    assert body["type"] == "urn:hockle:problem:result-is-a-branch"
    assert "\n" not in body["detail"] and "/branch" in body["detail"]
    for route in ("seabed", "branch"):               # not 500s either
        assert client.get(f"/v1/ui/jobs/{branch_job}/{route}").status_code == 200


# --- combined sweep results: one file per field set, a cap per sweep ---------------------------
@pytest.fixture(scope="module")
def finished_sweep(client, settings):
    from worker.tasks import run_job

    body = {"base": tiny_case("hostile-sweep"), "combine": "zip",
            "parameters": {"boundary.start.rotation.2.angular_velocity": [1.0, 2.0]}}
    response = client.post("/v1/sweeps", json=body)
    assert response.status_code == 201, response.text
    sweep = response.json()
    for member in sweep["members"]:
        run_job(member["job_id"], "hostile-sweep@test", settings)
    return sweep["id"]


def _combined_files(settings, sweep_id):
    return sorted((settings.results_dir / "sweeps").glob(f"{sweep_id}.*.nc"))


def test_every_spelling_of_one_field_set_is_one_combined_file(client, settings, finished_sweep):
    """``kappa``, ``kappa,kappa``, ``kappa, kappa``, ... built and kept a file each."""
    url = f"/v1/sweeps/{finished_sweep}/results"
    etags = set()
    for fields in ("kappa", "kappa,kappa", "kappa, kappa", " kappa ,kappa,", ",kappa"):
        response = client.get(url, params={"fields": fields})
        assert response.status_code == 200, response.text[:300]
        etags.add(response.headers["etag"])
    assert len(etags) == 1
    two = {client.get(url, params={"fields": f}).headers["etag"]
           for f in ("kappa,position", "position,kappa", "position, kappa,kappa")}
    assert len(two) == 1 and not two & etags
    assert len(_combined_files(settings, finished_sweep)) == 2


def test_combined_files_are_capped_per_sweep(client, settings, finished_sweep, monkeypatch):
    from service.routers import sweeps as router

    monkeypatch.setattr(router, "MAX_COMBINED_PER_SWEEP", 2)
    url = f"/v1/sweeps/{finished_sweep}/results"
    for fields in ("", "kappa", "position", "kappa,position"):
        assert client.get(url, params={"fields": fields}).status_code == 200
        time.sleep(0.02)                 # distinct build times on coarse file clocks
    assert len(_combined_files(settings, finished_sweep)) == 2
    # an evicted set is built again when asked for
    assert client.get(url).status_code == 200


# --- without API keys: the Host allow-list; worker names; the docs' CSP ------------------------
@pytest.fixture(scope="module")
def default_hosts_client(tmp_path_factory):
    """The app with the default allow-list (this module's conftest widens it for the
    TestClient's host name "testserver")."""
    settings = Settings(data_dir=tmp_path_factory.mktemp("hosts"), broker_url="memory://",
                        allowed_hosts=None)
    with TestClient(create_app(settings), base_url="http://127.0.0.1:8000",
                    raise_server_exceptions=False) as c:
        yield c


@pytest.mark.parametrize("host", ["attacker.example", "attacker.example:8000",
                                  "127.0.0.1.attacker.example", "testserver", "0.0.0.0:8000"])
def test_without_keys_a_foreign_host_header_is_refused(default_hosts_client, host):
    """A page of attacker.example whose DNS answers 127.0.0.1 (DNS rebinding) sends its own
    name as Host: 400 host-not-allowed on every route but the health checks and metrics."""
    for route in ("/v1/jobs", "/ui/", "/docs", "/openapi.json"):
        response = default_hosts_client.get(route, headers={"host": host})
        assert response.status_code == 400, (route, response.text[:200])
        assert response.json()["type"] == "urn:hockle:problem:host-not-allowed"
        assert "HOCKLE_ALLOWED_HOSTS" in response.json()["detail"]
    assert default_hosts_client.get("/v1/health", params={"live": "true"},
                                    headers={"host": host}).status_code == 200
    assert default_hosts_client.get("/metrics", headers={"host": host}).status_code == 200


@pytest.mark.parametrize("host", ["127.0.0.1:8000", "localhost:8000", "LOCALHOST", "[::1]:8000",
                                  "localhost.", "127.0.0.1"])
def test_without_keys_the_loopback_names_are_answered(default_hosts_client, host):
    assert default_hosts_client.get("/v1/jobs", headers={"host": host}).status_code == 200


def test_the_allow_list_follows_the_settings(tmp_path):
    base = dict(data_dir=tmp_path, broker_url="memory://")
    assert Settings(**base, allowed_hosts=None).allowed_host_names() == {
        "localhost", "127.0.0.1", "::1"}
    wide = Settings(**base, allowed_hosts=None, host="0.0.0.0",
                    public_url="http://rods.lab.example:8000/")
    assert wide.allowed_host_names() == {"localhost", "127.0.0.1", "::1", "rods.lab.example"}
    assert "10.0.0.5" in Settings(**base, allowed_hosts=None, host="10.0.0.5").allowed_host_names()
    assert Settings(**base, allowed_hosts="a.example, [fe80::1]").allowed_host_names() == {
        "a.example", "fe80::1"}
    assert Settings(**base, allowed_hosts="*").allowed_host_names() is None
    # with API keys the keys protect the API: no Host check
    keyed = Settings(**base, allowed_hosts=None, api_keys="k" * 20)
    with TestClient(create_app(keyed)) as c:
        assert c.get("/v1/jobs", headers={"Authorization": "Bearer " + "k" * 20,
                                          "host": "anything.example"}).status_code == 200


def test_a_wide_bind_without_keys_warns_and_names_the_allow_list(caplog):
    import logging

    from service import serve

    with caplog.at_level(logging.WARNING, logger="hockle.serve"):
        assert serve.warn_if_open("0.0.0.0")
    assert "NO AUTHENTICATION" in caplog.text and "HOCKLE_ALLOWED_HOSTS" in caplog.text


def test_worker_names_need_a_key_when_there_are_keys(tmp_path):
    key = "health-key-0123456789abcdef"
    settings = Settings(data_dir=tmp_path, broker_url="memory://", api_keys=key)
    with TestClient(create_app(settings)) as c:
        from service.registry import Registry

        registry = Registry(settings.registry_url)
        registry.heartbeat("secret-host-17@rack-4")
        registry.dispose()
        public = c.get("/v1/health").json()
        assert public["workers"] == [] and public["workers_seen"] == 1
        assert "secret-host" not in json.dumps(public)
        wrong = c.get("/v1/health", headers={"Authorization": "Bearer " + "x" * 20})
        assert wrong.status_code == 200 and wrong.json()["workers"] == []
        mine = c.get("/v1/health", headers={"Authorization": f"Bearer {key}"}).json()
        assert [w["name"] for w in mine["workers"]] == ["secret-host-17@rack-4"]
        assert mine["workers_seen"] == 1


@pytest.mark.parametrize("page,evaluates", [("/docs", False), ("/redoc", True),
                                            ("/docs/oauth2-redirect", False)])
def test_the_docs_pages_have_a_csp_that_lets_their_own_scripts_run(client, page, evaluates):
    """default-src 'none'; scripts from this origin and the page's own inline script (by its
    SHA-256) only. Every <script src> of the page is same-origin (allowed by 'self'), every
    inline script's hash is in the policy, stylesheets are same-origin: what the page needs
    to render is allowed, nothing of another origin is. (Chromium is not installed here to
    render them; the browser tests of the dashboard do where it is.)"""
    import base64
    import hashlib
    import re

    response = client.get(page)
    assert response.status_code == 200
    csp = response.headers["content-security-policy"]
    directives = {d.split()[0]: d.split()[1:] for d in csp.split(";") if d.strip()}
    assert directives["default-src"] == ["'none'"]
    assert directives["frame-ancestors"] == ["'none'"]
    assert directives["connect-src"] == ["'self'"]     # openapi.json and "Try it out"
    html = response.text
    for src in re.findall(r"<script[^>]*\ssrc=\"([^\"]+)\"", html):
        assert src.startswith("/") and not src.startswith("//"), src      # same origin
        assert client.get(src).status_code == 200
    for href in re.findall(r"<link[^>]*\shref=\"([^\"]+)\"", html):
        assert href.startswith("/") and not href.startswith("//"), href
    inline = re.findall(r"<script>(.*?)</script>", html, re.S)
    for body in inline:
        digest = base64.b64encode(hashlib.sha256(body.encode()).digest()).decode()
        assert f"'sha256-{digest}'" in directives["script-src"]
    assert ("'unsafe-eval'" in directives["script-src"]) == evaluates
    assert "'unsafe-inline'" not in directives["script-src"]
    assert all(s == "'self'" or s.startswith("'sha256-") or s == "'unsafe-eval'"
               for s in directives["script-src"]), directives["script-src"]
    if page == "/docs":
        assert inline and "SwaggerUIBundle" in inline[0]


# --- liveness while each hostile request is being processed (a real API process) ---------------
LIVENESS_PROBER = """
import os, sys, time
import httpx
url, stop, record = sys.argv[1], sys.argv[2], sys.argv[3]
with httpx.Client(base_url=url, timeout=30) as http, open(record, "a") as out:
    while not os.path.exists(stop):
        sent = time.time()
        start = time.monotonic()
        code = http.get("/v1/health", params={"live": "true"}).status_code
        out.write(f"{sent} {time.monotonic() - start} {code}\\n")
        out.flush()
        time.sleep(0.02)
"""
#: the liveness answer's bound while hostile requests are processed: the issue's 100 ms for
#: 95 % of the probes of each window, and a generous 500 ms for every probe: this 2-core
#: machine is shared with other engineers' runs (load 3-4 when measured), and the test's own
#: four sending threads and the prober run on it too; the benign window below shows that
#: noise without any hostile body
LIVENESS_LIMIT = 0.100
LIVENESS_LIMIT_ANY = 0.500


def _postgres_answers() -> bool:
    try:
        import psycopg

        psycopg.connect("postgresql://postgres@127.0.0.1:5432/postgres", connect_timeout=3).close()
        return True
    except Exception:  # noqa: BLE001
        return False


@pytest.fixture(scope="module")
def live_api(tmp_path_factory):
    """`python -m service` (PostgreSQL registry where a server answers, else SQLite; an
    in-memory broker, no worker) and a liveness prober in a process of its own, polling
    every 20 ms, as a kubelet would."""
    import subprocess
    import sys

    from svc_support import empty_database_url, make_stack

    backend = "postgresql" if _postgres_answers() else "sqlite"
    root = tmp_path_factory.mktemp("live-db")
    with empty_database_url(backend, root, "hockle_hostile_live") as url:
        stack = make_stack(tmp_path_factory, "hostile-live", {
            "HOCKLE_DATABASE_URL": url, "HOCKLE_BROKER_URL": "memory://"})
        stack.backend = backend
        stack.start_api()
        stop = stack.root / "stop-probing"
        stack.record = stack.root / "liveness.txt"
        prober = subprocess.Popen([sys.executable, "-c", LIVENESS_PROBER, stack.url, str(stop),
                                   str(stack.record)])
        stack.windows = []
        try:
            yield stack
        finally:
            stop.touch()
            prober.wait(timeout=60)
            stack.close()


def _case_text(case: dict) -> str:
    return json.dumps(case)


def _hostile_requests() -> dict:
    """label -> (method, route, kwargs, the answers allowed): the audit's requests."""
    big = "9" * 4301
    digits = _case_text(tiny_case("d")).replace('"youngs_modulus": 12500000.0',
                                                f'"youngs_modulus": {big}')
    sweep = json.dumps({"base": tiny_case("s"), "parameters": {"rod.length": [12345]}}
                       ).replace("12345", big)
    absurd = tiny_case("absurd")
    absurd["rod"]["youngs_modulus"] = 5e-324
    late = tiny_case("late")
    late["initial"] = {"from_result": {"job": "3a3f3b17-f338-4b0c-ad9e-283bb17603ab",
                                       "time": 1e308}}
    far = {"case": tiny_case("far"), "continuation": {
        "parameter": "boundary.end.translation.2.force", "to": 1e308}}
    large = _yaml_body(tiny_case("large"),
                       "extra: [" + ", ".join(str(k) for k in range(500_000)) + "]\n")
    y = {"content-type": "application/yaml"}
    out = {}
    for route, wrap, _ in POST_CASE_ROUTES.values():
        out[f"alias bomb {route}"] = ("POST", route, {
            "content": _yaml_body(wrap(tiny_case("bomb")), alias_bomb()), "headers": y},
            {413})
    out.update({
        "4,301 digits JSON /v1/jobs": ("POST", "/v1/jobs", {
            "content": digits, "headers": {"content-type": "application/json"}}, {422}),
        "4,301 digits YAML /v1/ui/validate": ("POST", "/v1/ui/validate", {
            "content": digits, "headers": y}, {422}),
        "4,301 digits YAML /v1/sweeps": ("POST", "/v1/sweeps", {
            "content": sweep, "headers": y}, {422}),
        "3.4-MB YAML body /v1/jobs": ("POST", "/v1/jobs", {"content": large, "headers": y},
                                      {413, 422}),
        "NUL in a job id": ("GET", "/v1/jobs/" + NUL_ID.replace("\x00", "%00"), {}, {404}),
        "NUL in a sweep id": ("GET", "/v1/sweeps/" + NUL_ID.replace("\x00", "%00") +
                              "/results", {}, {404}),
        "NUL in page_token": ("GET", "/v1/jobs", {"params": {
            "page_token": _token("2026-11-27T10:00:00", NUL_ID)}}, {422}),
        "NUL in from_result.job": ("POST", "/v1/jobs", {"json": {**tiny_case("nul"), "initial": {
            "from_result": {"job": NUL_ID, "time": 0.0}}}}, {422}),
        "created_before=9999-12-31T23:59:59-05:00": ("GET", "/v1/jobs", {"params": {
            "created_before": "9999-12-31T23:59:59-05:00"}}, {200}),
        "created_after=0001-01-01T00:00:00+05:00": ("GET", "/v1/jobs", {"params": {
            "created_after": "0001-01-01T00:00:00+05:00"}}, {200}),
        "youngs_modulus = 5e-324": ("POST", "/v1/jobs", {"json": absurd}, {422}),
        "from_result.time = 1e308": ("POST", "/v1/jobs", {"json": late}, {422}),
        "continuation to = 1e308": ("POST", "/v1/continuations", {"json": far}, {422}),
    })
    return out


HOSTILE_REQUESTS = _hostile_requests()
#: the same load of benign requests, for the machine's own noise
BENIGN = ("GET", "/v1/jobs/3a3f3b17-f338-4b0c-ad9e-283bb17603ab", {}, {404})


@pytest.mark.service
@pytest.mark.parametrize("label", ["(benign: unknown job ids)"] + list(HOSTILE_REQUESTS))
def test_liveness_answers_while_each_hostile_request_is_processed(live_api, label):
    """Each of the audit's requests sent by 4 clients at once, again and again for 2 s (at
    least once each): no answer is a 500 (each is the 4xx the in-process tests name), and the
    liveness probes sent meanwhile (every 20 ms from another process) each answer within
    LIVENESS_LIMIT (checked with the others at the module's end, where the figures are
    printed)."""
    import httpx
    from concurrent.futures import ThreadPoolExecutor

    method, route, kwargs, allowed = HOSTILE_REQUESTS.get(label, BENIGN)
    codes: list[int] = []

    def send(_):
        with httpx.Client(base_url=live_api.url, timeout=120) as http:
            end = time.monotonic() + 2.0
            while True:
                codes.append(http.request(method, route, **kwargs).status_code)
                if time.monotonic() > end:
                    return

    start = time.time()
    with ThreadPoolExecutor(4) as pool:
        list(pool.map(send, range(4)))
    live_api.windows.append((label, start, time.time()))
    assert 500 not in codes
    assert set(codes) <= allowed, (label, sorted(set(codes)))
    assert "Traceback" not in live_api.log("api.log")


@pytest.mark.service
def test_liveness_figures_during_the_hostile_requests(live_api):
    """The liveness probes of each window above (runs after them): every probe 200, 95 % of
    each window's within LIVENESS_LIMIT (100 ms), all within LIVENESS_LIMIT_ANY (500 ms).
    The figures are printed (pytest -s)."""
    import statistics

    time.sleep(0.2)
    probes = [tuple(float(x) for x in line.split())
              for line in live_api.record.read_text().splitlines() if line.strip()]
    assert probes and {int(code) for _, _, code in probes} == {200}
    rows, over = [], []
    for label, start, end in live_api.windows:
        inside = sorted(took for sent, took, _ in probes if start <= sent <= end)
        assert inside, f"no liveness probe during {label}"
        p95 = inside[min(len(inside) - 1, int(0.95 * len(inside)))]
        rows.append(f"  {label:45s} {len(inside):4d} probes, median "
                    f"{1000 * statistics.median(inside):6.1f} ms, 95 % {1000 * p95:6.1f} ms, "
                    f"max {1000 * inside[-1]:6.1f} ms")
        if p95 > LIVENESS_LIMIT or inside[-1] > LIVENESS_LIMIT_ANY:
            over.append((label, round(1000 * p95, 1), round(1000 * inside[-1], 1)))
    print(f"\nliveness during hostile requests ({live_api.backend} registry):\n"
          + "\n".join(rows))
    assert not over, f"liveness slower than allowed (label, 95 % ms, max ms): {over}"
