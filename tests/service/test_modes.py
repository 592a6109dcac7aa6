"""The same end-to-end path in the embedded mode (`python -m service` with nothing configured)
and in the distributed mode with the default SQLite registry and a real Redis broker; and the
registry's transitions on both SQLite and PostgreSQL."""
from __future__ import annotations

import datetime as dt
import json

import pytest
import xarray as xr

from service.registry import Registry
from svc_support import Stack, make_stack, tiny_case, wait_until

TERMINAL = ("successful", "failed", "dismissed")


def _end_to_end(stack: Stack, tmp_path, name: str) -> dict:
    response = stack.submit(tiny_case(name))
    assert response.status_code == 201, response.text
    job = stack.wait_state(response.json()["id"], TERMINAL, 90)
    assert job["state"] == "successful", job
    data = stack.http.get(f"/v1/jobs/{job['id']}/results")
    assert data.status_code == 200
    path = tmp_path / f"{name}.nc"
    path.write_bytes(data.content)
    with xr.open_dataset(path, engine="netcdf4") as ds:
        assert ds.attrs["hockle_status"] == "completed" and ds.sizes["time"] == 6
    sl = stack.http.get(f"/v1/jobs/{job['id']}/results/variables/energy_total",
                        params={"time": "0.02:"}).json()
    assert sl["shape"] == [4]
    assert stack.http.post("/v1/jobs", json={**tiny_case(), "extra": 1}).status_code == 422
    return job


@pytest.mark.service
def test_embedded_mode_end_to_end(tmp_path_factory, tmp_path):
    stack = make_stack(tmp_path_factory, "embedded", {})
    try:
        stack.start_api()  # starts its own local worker: no server to install
        health = wait_until(lambda: (lambda h: h if h["workers"] else None)(
            stack.http.get("/v1/health").json()), 60, 0.3, "the embedded worker")
        assert health["mode"] == "embedded" and health["status"] == "ok"
        _end_to_end(stack, tmp_path, "embedded")
        data = stack.root / "data"
        assert (data / "registry.db").exists() and (data / "broker.db").exists()
        assert len(list((data / "results").glob("*.nc"))) == 1
    finally:
        stack.close()
    # no worker survives the API that started it
    assert "Warm shutdown" in stack.log("api.log")


@pytest.mark.service
def test_redis_broker_with_sqlite_registry(tmp_path_factory, tmp_path, redis_server):
    stack = make_stack(tmp_path_factory, "sqlite-redis", {"HOCKLE_BROKER_URL": redis_server.url,
                                                          "HOCKLE_QUEUE": "sqlite-redis"})
    try:
        stack.start_api()
        stack.start_worker("s1")
        job = _end_to_end(stack, tmp_path, "sqlite-redis")
        assert job["worker"] == "s1@test"
        assert stack.http.get("/v1/health").json()["mode"] == "distributed"
    finally:
        stack.close()


@pytest.fixture(params=["sqlite", "postgresql"])
def registry(request, tmp_path):
    if request.param == "sqlite":
        url = f"sqlite:///{tmp_path / 'r.db'}"
    else:
        url = request.getfixturevalue("pg_url").replace("postgresql://", "postgresql+psycopg://")
    reg = Registry(url)
    reg.create_schema()
    yield reg
    reg.dispose()


def _new(reg: Registry, name="r", key=None, fingerprint="f", hard=1000.0):
    job, created = reg.create_job(
        spec_json=json.dumps({"name": name}), spec_hash="h" * 64, solver_version="0.1.0",
        name=name, grid_points=9, n_steps=5, t_end=0.05, limits=(hard, hard * 0.9, hard * 0.8),
        idempotency_key=key, request_fingerprint=fingerprint)
    return job, created


def test_registry_transitions(registry: Registry):
    job, created = _new(registry, key=f"k-{id(registry)}")
    assert created and job.state == "accepted"
    again, created = _new(registry, key=f"k-{id(registry)}")
    assert not created and again.id == job.id
    from service.registry import IdempotencyConflict

    with pytest.raises(IdempotencyConflict):
        _new(registry, key=f"k-{id(registry)}", fingerprint="other")

    first = registry.claim(job.id, "a@x")
    # a second delivery of a running job does nothing: only an accepted job can be claimed
    assert registry.claim(job.id, "b@x") is None
    # worker a is lost (no heartbeat for 2 minutes): the sweeper queues the job again
    later = dt.datetime.now(dt.timezone.utc).replace(tzinfo=None) + dt.timedelta(seconds=120)
    assert [a for j, a in registry.requeue_lost(heartbeat_timeout=60, max_attempts=3, now=later)
            if j.id == job.id] == ["requeued"]  # the PostgreSQL database is shared: ours only
    second = registry.claim(job.id, "b@x")
    assert (first, second) == (1, 2)
    assert not registry.job_heartbeat(job.id, first)  # the old attempt learns it lost the job
    assert not registry.finish(job.id, first, state="successful")  # stale attempt refused
    assert registry.finish(job.id, second, state="successful")
    assert registry.claim(job.id, "c@x") is None  # terminal: never runs again
    assert registry.get(job.id).attempts == 2

    queued, _ = _new(registry, "queued")
    assert registry.dismiss(queued.id).state == "dismissed"
    assert registry.claim(queued.id, "a@x") is None

    running, _ = _new(registry, "running", hard=0.01)
    attempt = registry.claim(running.id, "a@x")
    after = registry.dismiss(running.id)
    assert after.state == "running" and after.cancel_requested
    assert registry.cancel_requested(running.id)
    # the hard limit passed (Celery killed it): the reaper fails it with reason timeout
    later = dt.datetime.now(dt.timezone.utc).replace(tzinfo=None) + dt.timedelta(seconds=60)
    assert registry.reap(now=later, grace=30) == [running.id]
    reaped = registry.get(running.id)
    assert (reaped.state, reaped.reason) == ("failed", "timeout")
    assert not registry.finish(running.id, attempt, state="successful")


@pytest.mark.service
def test_sigterm_to_the_api_alone_stops_its_embedded_worker(tmp_path_factory):
    """`kill <pid of hockle serve>` (SIGTERM to the API process only, as a service manager or
    a user sends it): uvicorn re-raises the signal after its shutdown, which used to kill the
    process before it stopped its embedded worker, leaving an orphan worker behind."""
    import os
    import signal
    import subprocess

    stack = make_stack(tmp_path_factory, "embedded-sigterm", {})
    stack.api_pid = 0
    try:
        stack.start_api()
        stack.api_pid = stack.api.pid
        wait_until(lambda: stack.http.get("/v1/health").json()["workers"], 60, 0.3,
                   "the embedded worker")
        pattern = f"embedded-{stack.api.pid}@"

        def workers() -> str:
            return subprocess.run(["pgrep", "-f", pattern], capture_output=True,
                                  text=True).stdout.strip()

        assert workers()
        os.kill(stack.api.pid, signal.SIGTERM)        # the API process only, not its group
        stack.api.wait(timeout=60)
        wait_until(lambda: not workers(), 60, 0.2, "the embedded worker to stop")
        assert "Warm shutdown" in stack.log("api.log")
    finally:
        stack.close()
        subprocess.run(["pkill", "-9", "-f", f"embedded-{stack.api_pid}@"], check=False)
