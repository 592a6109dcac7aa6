"""API keys, job ownership and rate limits (issue 11): the API in-process with two keys (SQLite
registry, in-memory broker, the worker's task code run in this process with the real solver),
the settings and start-up checks, the client and CLI, and one run through real processes
(`python -m service` embedded: its own worker process, keys from the environment)."""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

import httpx
import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.auth import RateLimiter, owner_id
from service.registry import Registry
from service.settings import Settings
from svc_support import empty_database_url, free_port, make_stack, tiny_case

PROBLEM = "application/problem+json"
KEY_A = "alice-key-0123456789abcdef"
KEY_B = "bob-key-0123456789abcdef-bob"
A = {"Authorization": f"Bearer {KEY_A}"}
B = {"Authorization": f"Bearer {KEY_B}"}


#: the in-process service's settings (svc_support's ``settings`` and ``client`` fixtures)
SERVICE_SETTINGS = dict(api_keys=f"{KEY_A}, {KEY_B}", rate_limit=1000.0,
                        rate_limit_burst=1000)


def _run(settings, job_id):
    """Run the queued job with the worker's task code in this process (real solver)."""
    from worker.tasks import run_job

    return run_job(job_id, "auth@test", settings)


@pytest.fixture(scope="module")
def alices_job(client, settings):
    """A successful job of key A, with its result."""
    response = client.post("/v1/jobs", json=tiny_case("alice"), headers=A)
    assert response.status_code == 201, response.text
    job_id = response.json()["id"]
    assert _run(settings, job_id) == "successful"
    return job_id


# --- who may call what -----------------------------------------------------------------------
@pytest.mark.parametrize("method,path", [
    ("GET", "/v1/jobs"), ("POST", "/v1/jobs"), ("GET", "/v1/jobs/some-id"),
    ("DELETE", "/v1/jobs/some-id"), ("GET", "/v1/jobs/some-id/results"),
    ("GET", "/v1/jobs/some-id/results/variables/kappa"), ("GET", "/v1/no-such-route"),
])
def test_no_key_is_401_with_www_authenticate(client, method, path):
    response = client.request(method, path)
    assert response.status_code == 401
    assert response.headers["content-type"].startswith(PROBLEM)
    assert response.headers["www-authenticate"].startswith("Bearer")
    body = response.json()
    assert body["status"] == 401 and "Authorization: Bearer" in body["detail"]


@pytest.mark.parametrize("header", [f"Bearer {KEY_A}x", "Bearer ", f"Basic {KEY_A}", KEY_A,
                                    f"Bearer {KEY_A[:-1]}"])
def test_wrong_or_malformed_key_is_401(client, header):
    response = client.get("/v1/jobs", headers={"Authorization": header})
    assert response.status_code == 401
    assert response.headers["content-type"].startswith(PROBLEM)
    assert response.headers["www-authenticate"].startswith("Bearer")


def test_health_and_docs_need_no_key(client):
    assert client.get("/v1/health").status_code == 200
    assert client.get("/v1/health", params={"live": "true"}).status_code == 200
    for path in ("/docs", "/redoc", "/openapi.json", "/metrics"):
        assert client.get(path).status_code == 200, path


def test_scheme_is_case_insensitive(client):
    assert client.get("/v1/jobs", headers={"Authorization": f"bearer {KEY_A}"}).status_code == 200


# --- ownership -------------------------------------------------------------------------------
def test_own_job_is_200_on_every_route(client, alices_job):
    base = f"/v1/jobs/{alices_job}"
    status = client.get(base, headers=A)
    assert status.status_code == 200 and status.json()["state"] == "successful"
    for path in ("/spec", "/results", "/results/variables", "/results/variables/energy_total",
                 "/summary"):
        assert client.get(base + path, headers=A).status_code == 200, path
    listed = client.get("/v1/jobs", headers=A).json()["jobs"]
    assert alices_job in {j["id"] for j in listed}


def test_another_owners_job_is_404_on_every_route(client, alices_job):
    base = f"/v1/jobs/{alices_job}"
    unknown = client.get("/v1/jobs/00000000-0000-0000-0000-000000000000", headers=B).json()
    for method, path in [("GET", ""), ("GET", "/spec"), ("GET", "/results"),
                         ("GET", "/results/variables"),
                         ("GET", "/results/variables/energy_total"), ("GET", "/summary"),
                         ("DELETE", "")]:
        response = client.request(method, base + path, headers=B)
        assert response.status_code == 404, (method, path, response.text)
        body = response.json()
        # answered exactly as an id that does not exist: nothing tells that the job is there
        assert (body["type"], body["title"]) == (unknown["type"], unknown["title"])
        assert body["detail"] == f"no job with id {alices_job}"
    listed = client.get("/v1/jobs", headers=B).json()["jobs"]
    assert alices_job not in {j["id"] for j in listed}
    assert client.get(base, headers=A).json()["state"] == "successful"  # untouched


def test_another_owner_cannot_dismiss_a_queued_job(client):
    job_id = client.post("/v1/jobs", json=tiny_case("queued", t_end=0.03), headers=A).json()["id"]
    assert client.delete(f"/v1/jobs/{job_id}", headers=B).status_code == 404
    assert client.get(f"/v1/jobs/{job_id}", headers=A).json()["state"] == "accepted"
    dismissed = client.delete(f"/v1/jobs/{job_id}", headers=A)
    assert dismissed.status_code == 200 and dismissed.json()["state"] == "dismissed"


def test_list_filters_keep_to_the_owner(client):
    mine = client.post("/v1/jobs", json=tiny_case("bobs", t_end=0.02), headers=B).json()["id"]
    ids = {j["id"] for j in client.get("/v1/jobs", params={"status": "accepted"},
                                       headers=B).json()["jobs"]}
    assert mine in ids
    alices = {j["id"] for j in client.get("/v1/jobs", params={"page_size": 500},
                                          headers=A).json()["jobs"]}
    assert mine not in alices


def test_identical_case_is_answered_from_the_owners_own_jobs_only(client, alices_job):
    again = client.post("/v1/jobs", json=tiny_case("alice"), headers=A)
    assert again.status_code == 200 and again.json()["id"] == alices_job
    other = client.post("/v1/jobs", json=tiny_case("alice"), headers=B)
    assert other.status_code == 201 and other.json()["id"] != alices_job


def test_idempotency_keys_are_per_owner(client):
    case_a, case_b = tiny_case("idem-a", t_end=0.04), tiny_case("idem-b", t_end=0.03)
    same = {"Idempotency-Key": "nightly-run-1"}
    first_a = client.post("/v1/jobs", json=case_a, headers={**A, **same})
    assert first_a.status_code == 201
    # the same key from another owner, with another case, is another owner's first use
    first_b = client.post("/v1/jobs", json=case_b, headers={**B, **same})
    assert first_b.status_code == 201, first_b.text
    assert first_b.json()["id"] != first_a.json()["id"]
    # each owner's replay finds its own job
    replay_a = client.post("/v1/jobs", json=case_a, headers={**A, **same})
    replay_b = client.post("/v1/jobs", json=case_b, headers={**B, **same})
    assert (replay_a.status_code, replay_a.json()["id"]) == (200, first_a.json()["id"])
    assert (replay_b.status_code, replay_b.json()["id"]) == (200, first_b.json()["id"])
    # reuse with a different case stays a conflict within one owner
    reused = client.post("/v1/jobs", json=case_b, headers={**A, **same})
    assert reused.status_code == 422
    assert reused.json()["errors"][0]["loc"] == "header.Idempotency-Key"


def test_registry_holds_owner_hashes_never_the_keys(client, settings, alices_job):
    registry = Registry(settings.registry_url)
    try:
        assert registry.get(alices_job).owner == owner_id(KEY_A)
        assert len(owner_id(KEY_A)) == 64 and owner_id(KEY_A) != owner_id(KEY_B)
    finally:
        registry.dispose()
    db = settings.data_dir / "registry.db"
    raw = b"".join(p.read_bytes() for p in db.parent.glob("registry.db*"))
    assert owner_id(KEY_A).encode() in raw
    for key in (KEY_A, KEY_B):
        assert key.encode() not in raw


def test_openapi_documents_bearer_auth(client):
    schema = client.get("/openapi.json").json()
    assert schema["components"]["securitySchemes"]["apiKey"]["scheme"] == "bearer"
    ops = {op["operationId"]: op for item in schema["paths"].values() for op in item.values()}
    assert "security" not in ops["get_health"] and "security" not in ops["get_metrics"]
    for name in ("submit_job", "get_job", "download_results", "dismiss_job"):
        assert ops[name]["security"] == [{"apiKey": []}]
        assert {"401", "429"} <= set(ops[name]["responses"])


# --- rate limits -----------------------------------------------------------------------------
def test_rate_limit_is_429_with_retry_after_per_key(tmp_path):
    settings = Settings(data_dir=tmp_path, broker_url="memory://", api_keys=f"{KEY_A},{KEY_B}",
                        rate_limit=0.2, rate_limit_burst=3)
    with TestClient(create_app(settings)) as c:
        codes = [c.get("/v1/jobs", headers=A).status_code for _ in range(3)]
        assert codes == [200, 200, 200]
        limited = c.get("/v1/jobs", headers=A)
        assert limited.status_code == 429
        assert limited.headers["content-type"].startswith(PROBLEM)
        assert 1 <= int(limited.headers["retry-after"]) <= 5  # one token per 5 s
        assert "HOCKLE_RATE_LIMIT" in limited.json()["detail"]
        # another key has its own bucket; health is never limited
        assert c.get("/v1/jobs", headers=B).status_code == 200
        assert c.get("/v1/health", params={"live": "true"}).status_code == 200
        # a wrong key is 401, not a turn of the bucket
        assert c.get("/v1/jobs", headers={"Authorization": "Bearer " + "x" * 20}).status_code == 401


def test_token_bucket_refills_at_the_rate():
    bucket = RateLimiter(rate=2.0, burst=2)
    assert [bucket.take("o", now=0.0) for _ in range(3)] == [0.0, 0.0, 0.5]
    assert bucket.take("o", now=0.25) == pytest.approx(0.25)  # half a token so far
    assert bucket.take("o", now=0.5) == 0.0
    assert bucket.take("other", now=0.5) == 0.0
    assert RateLimiter(rate=0, burst=1).take("o", now=0.0) == 0.0  # 0: no limit


# --- settings and start-up -------------------------------------------------------------------
def test_key_settings_errors_name_the_variable(tmp_path):
    with pytest.raises(ValueError, match=r"HOCKLE_API_KEYS: key 2 is 5 characters long"):
        Settings(api_keys=f"{KEY_A},short").load_api_keys()
    with pytest.raises(ValueError, match="HOCKLE_API_KEYS: no key"):
        Settings(api_keys=" , ").load_api_keys()
    with pytest.raises(ValueError, match="HOCKLE_API_KEYS_FILE: cannot read"):
        Settings(api_keys_file=tmp_path / "missing").load_api_keys()
    path = tmp_path / "keys"
    path.write_text(f"# lab keys\n\n{KEY_B}\n  {KEY_A}  \n")
    assert Settings(api_keys=KEY_A, api_keys_file=path).load_api_keys() == [KEY_A, KEY_B]
    path.write_text(f"{KEY_A}\nhas a space in it, sadly\n")
    with pytest.raises(ValueError, match=r"HOCKLE_API_KEYS_FILE: the key on line 2 .* whitespace"):
        Settings(api_keys_file=path).load_api_keys()
    path.write_text("# nothing\n")
    with pytest.raises(ValueError, match="holds no key"):
        Settings(api_keys_file=path).load_api_keys()
    with pytest.raises(ValueError, match="HOCKLE_API_KEYS"):
        create_app(Settings(data_dir=tmp_path / "d", broker_url="memory://", api_keys="short"))


def test_keys_file_is_read_by_the_app(tmp_path):
    path = tmp_path / "keys"
    path.write_text(f"{KEY_B}\n")
    settings = Settings(data_dir=tmp_path, broker_url="memory://", api_keys_file=path)
    with TestClient(create_app(settings)) as c:
        assert c.get("/v1/jobs", headers=B).status_code == 200
        assert c.get("/v1/jobs", headers=A).status_code == 401


def test_keys_never_reach_a_worker_environment():
    env = Settings(api_keys=KEY_A, api_key=KEY_B, api_keys_file="/k").child_env()
    assert not {"HOCKLE_API_KEYS", "HOCKLE_API_KEY", "HOCKLE_API_KEYS_FILE"} & set(env)
    assert KEY_A not in repr(Settings(api_keys=KEY_A))  # a secret in logs and tracebacks


def test_binding_beyond_loopback_without_keys_warns(caplog, monkeypatch):
    from service import serve

    with caplog.at_level(logging.WARNING, logger="hockle.serve"):
        assert not serve.warn_if_open("127.0.0.1") and not serve.warn_if_open("localhost")
        assert not serve.warn_if_open("::1")
        assert not caplog.records
        assert serve.warn_if_open("0.0.0.0")
    assert "NO AUTHENTICATION" in caplog.text and "HOCKLE_API_KEYS" in caplog.text


def test_serve_refuses_bad_keys_before_starting_anything(monkeypatch, tmp_path, caplog):
    from service import serve
    from service.settings import get_settings

    monkeypatch.setenv("HOCKLE_API_KEYS", "short")
    monkeypatch.setenv("HOCKLE_DATA_DIR", str(tmp_path / "never"))
    get_settings.cache_clear()
    try:
        with caplog.at_level(logging.ERROR, logger="hockle.serve"):
            code = serve.run(argparse.Namespace(host=None, port=None, workers=None,
                                                no_worker=True))
    finally:
        get_settings.cache_clear()
    assert code == 2 and "HOCKLE_API_KEYS: key 1" in caplog.text
    assert not (tmp_path / "never").exists()


@pytest.fixture(params=["sqlite", "postgresql"])
def empty_registry_url(request, tmp_path):
    """The URL of an empty database: a SQLite file, or a new PostgreSQL database of its own
    (dropped afterwards; skipped when no server answers on 127.0.0.1:5432)."""
    with empty_database_url(request.param, tmp_path, "hockle_old") as db_url:
        yield db_url


def test_an_older_registry_gets_the_owner_column_and_index(empty_registry_url):
    from sqlalchemy import inspect, text

    from service.registry import Base

    reg = Registry(empty_registry_url)
    jobs = Base.metadata.tables["hockle_jobs"]
    with reg.engine.begin() as conn:
        cols = ", ".join(f"{c.name} {c.type.compile(dialect=reg.engine.dialect)}"
                         for c in jobs.columns if c.name != "owner")
        conn.exec_driver_sql(f"CREATE TABLE hockle_jobs ({cols})")
        conn.exec_driver_sql("INSERT INTO hockle_jobs (id, state, created_at) "
                             "VALUES ('old', 'successful', '2026-01-01 00:00:00')")
    reg.create_schema()
    reg.create_schema()  # the next start finds column and index made
    inspector = inspect(reg.engine)
    assert "owner" in {c["name"] for c in inspector.get_columns("hockle_jobs")}
    assert any(ix["column_names"] == ["owner"] for ix in inspector.get_indexes("hockle_jobs"))
    assert reg.list(owner=owner_id(KEY_A)).jobs == []  # a job made before keys is no one's
    assert [j.id for j in reg.list().jobs] == ["old"]  # and everyone's without keys
    with reg.engine.connect() as conn:
        assert conn.execute(text("SELECT owner FROM hockle_jobs")).all() == [(None,)]
    reg.dispose()


# --- client and command line -----------------------------------------------------------------
def test_client_sends_the_key(monkeypatch):
    from service.client import HockleClient

    seen = []

    def handler(request: httpx.Request) -> httpx.Response:
        seen.append(request.headers.get("authorization"))
        return httpx.Response(200, json={"jobs": [], "next_page_token": None, "next": None})

    transport = httpx.MockTransport(handler)
    monkeypatch.delenv("HOCKLE_API_KEY", raising=False)
    with HockleClient("http://hockle.test", api_key=KEY_A, transport=transport) as c:
        c.list()
    with HockleClient("http://hockle.test", transport=transport) as c:
        c.list()
    monkeypatch.setenv("HOCKLE_API_KEY", KEY_B)
    with HockleClient("http://hockle.test", transport=transport) as c:
        c.list()
    with HockleClient("http://hockle.test", api_key="", transport=transport) as c:
        c.list()
    assert seen == [f"Bearer {KEY_A}", None, f"Bearer {KEY_B}", None]


def test_cli_submit_passes_api_key(monkeypatch, tmp_path, capsys):
    import json

    from hockle.cli import main
    from service import client as client_module

    given = []
    real = client_module.HockleClient.__init__

    def spy(self, *args, **kwargs):
        given.append(kwargs.get("api_key"))
        real(self, *args, **kwargs)

    monkeypatch.setattr(client_module.HockleClient, "__init__", spy)
    case = tmp_path / "tiny.json"
    case.write_text(json.dumps(tiny_case()))
    url = f"http://127.0.0.1:{free_port()}"  # nothing listens: exit 4 after the client is made
    code = main(["submit", str(case), "--url", url, "--api-key", KEY_A])
    assert code == 4 and given == [KEY_A]


# --- through real processes ------------------------------------------------------------------
@pytest.mark.service
def test_embedded_service_with_keys_end_to_end(tmp_path_factory, tmp_path):
    """`python -m service` with HOCKLE_API_KEYS and its own worker process: key A's job runs and
    is A's; key B and no key see nothing of it; no start-up warning on 127.0.0.1."""
    from service.client import HockleAPIError, HockleClient

    stack = make_stack(tmp_path_factory, "auth-embedded", {"HOCKLE_API_KEYS": f"{KEY_A},{KEY_B}"})
    try:
        stack.start_api()
        with HockleClient(stack.url, api_key=KEY_A) as alice, \
                HockleClient(stack.url, api_key=KEY_B) as bob:
            assert alice.health().status == "ok"
            job = alice.submit(tiny_case("embedded-auth"))
            done = alice.wait(job.id, timeout=120, poll_interval=0.2)
            assert done.state == "successful", done
            assert alice.dataset(job.id).attrs["hockle_status"] == "completed"
            for call in (lambda: bob.get(job.id), lambda: bob.dismiss(job.id),
                         lambda: bob.summary(job.id)):
                with pytest.raises(HockleAPIError) as err:
                    call()
                assert err.value.status == 404
            assert job.id not in {j.id for j in bob.iter_jobs()}
        assert stack.http.get(f"/v1/jobs/{job.id}").status_code == 401
        # the embedded worker process got no key in its environment
        workers = [pid for pid in _children(stack.api.pid)
                   if b"worker" in Path(f"/proc/{pid}/cmdline").read_bytes()]
        assert workers
        for pid in workers:
            assert b"HOCKLE_API_KEYS" not in Path(f"/proc/{pid}/environ").read_bytes()
        assert stack.http.get("/docs").status_code == 200
        assert "NO AUTHENTICATION" not in stack.log("api.log")
        assert KEY_A not in stack.log("api.log")
    finally:
        stack.close()


def _children(pid: int) -> list[int]:
    """The ids of the direct children of a process (Linux /proc)."""
    out = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        children = (task / "children").read_text().split()
        out += [int(c) for c in children]
    return out
