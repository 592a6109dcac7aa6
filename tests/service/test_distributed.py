"""End to end, distributed mode: real redis-server, PostgreSQL registry, API and Celery worker
processes. Submit, poll, download, slice; dismiss; kill or pause a worker mid-job; lose a job's
message; restart Redis and API.
"""
from __future__ import annotations

import argparse
import io
import json
import os
import signal
import time
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from svc_support import Stack, long_case, make_stack, record_job, registry_for, tiny_case, \
    wait_until

pytestmark = pytest.mark.service

TERMINAL = ("successful", "failed", "dismissed")


@pytest.fixture(scope="module")
def stack(tmp_path_factory, redis_server, pg_url):
    stack = make_stack(tmp_path_factory, "pg-stack", {
        "HOCKLE_DATABASE_URL": pg_url,
        "HOCKLE_BROKER_URL": redis_server.url,
        # a job whose worker died is re-queued after 10 s without a heartbeat (beats every 1 s)
        "HOCKLE_JOB_HEARTBEAT_TIMEOUT": "10",
        # an accepted job whose message is lost is sent again after 5 s
        "HOCKLE_REQUEUE_AFTER": "5",
        "HOCKLE_UNACKED_RESTORE_INTERVAL": "1",
        # a running job's solver checkpoint every second (a re-run continues from it)
        "HOCKLE_CHECKPOINT_INTERVAL": "1",
    })
    stack.redis = redis_server
    try:
        stack.start_api()
        stack.start_worker("w1", wait=False)
        stack.start_worker("w2", wait=False)
        for name in ("w1", "w2"):
            wait_until(lambda: stack._ready(name), 60, 0.2, f"worker {name}")
        yield stack
    finally:
        stack.close()


def test_submit_poll_download_slice(stack: Stack, tmp_path):
    response = stack.submit(tiny_case("e2e-pg"))
    assert response.status_code == 201, response.text
    job = response.json()
    assert response.headers["location"] == f"/v1/jobs/{job['id']}"
    assert job["state"] in ("accepted", "running")
    assert job["grid_points"] == 9 and job["n_steps"] == 5

    done = stack.wait_state(job["id"], TERMINAL, 60)
    assert done["state"] == "successful", done
    assert done["progress"] == 100.0 and done["step"] == 5
    assert abs(done["sim_time"] - 0.05) < 1e-9
    assert done["started"] and done["finished"] and done["worker"].endswith("@test")
    assert done["result_available"] and not done["result_partial"]

    # the NetCDF file, with Content-Length and ETag, opens with xarray
    response = stack.http.get(f"/v1/jobs/{job['id']}/results")
    assert response.status_code == 200
    assert response.headers["content-type"] == "application/x-netcdf"
    assert int(response.headers["content-length"]) == len(response.content)
    etag = response.headers["etag"]
    path = tmp_path / "out.nc"
    path.write_bytes(response.content)
    with xr.open_dataset(path, engine="netcdf4") as ds:
        assert ds.attrs["hockle_status"] == "completed"
        assert ds.attrs["hockle_job_id"] == job["id"]
        assert ds.sizes["time"] == 6 and ds.sizes["s"] == 9
        kappa = ds["kappa"].load()
    again = stack.http.get(f"/v1/jobs/{job['id']}/results", headers={"If-None-Match": etag})
    assert again.status_code == 304

    variables = stack.http.get(f"/v1/jobs/{job['id']}/results/variables").json()
    by_name = {v["name"]: v for v in variables["variables"]}
    assert by_name["kappa"]["dims"] == ["time", "s", "component"]
    assert by_name["kappa"]["units"] and by_name["kappa"]["long_name"]

    # a slice: kappa_3 along the rod at t = 0.02 s, equal to the file's values
    sl = stack.http.get(f"/v1/jobs/{job['id']}/results/variables/kappa",
                        params={"time": "0.02", "component": "3"})
    assert sl.status_code == 200, sl.text
    body = sl.json()
    assert body["dims"] == ["s"] and body["shape"] == [9]
    assert body["selected"] == {"time": 0.02, "component": 3}
    expected = kappa.sel(time=0.02, method="nearest").sel(component=3).values.tolist()
    assert body["data"] == pytest.approx(expected)
    ranged = stack.http.get(f"/v1/jobs/{job['id']}/results/variables/position",
                            params={"time": "0.01:0.03", "s": "0.5", "xyz": "x,z"}).json()
    assert ranged["dims"] == ["time", "xyz"] and ranged["shape"] == [3, 2]

    summary = stack.http.get(f"/v1/jobs/{job['id']}/summary").json()
    assert summary["time"] == pytest.approx([0.0, 0.01, 0.02, 0.03, 0.04, 0.05])
    for name in ("energy_total", "energy_kinetic", "twist", "writhe", "linking_number"):
        assert len(summary["series"][name]["values"]) == 6
    assert summary["series"]["energy_total"]["units"] == "J"

    spec = stack.http.get(f"/v1/jobs/{job['id']}/spec").json()
    assert spec["name"] == "e2e-pg" and spec["numerics"]["n_segments"] == 8

    listing = stack.http.get("/v1/jobs", params={"status": "successful", "page_size": 1}).json()
    assert len(listing["jobs"]) == 1 and listing["jobs"][0]["state"] == "successful"


def test_unknown_job_is_404_whatever_celery_thinks(stack: Stack):
    missing = "00000000-0000-4000-8000-000000000000"
    for url in (f"/v1/jobs/{missing}", f"/v1/jobs/{missing}/results", f"/v1/jobs/{missing}/summary"):
        response = stack.http.get(url)
        assert response.status_code == 404
        assert response.headers["content-type"] == "application/problem+json"
        assert response.json()["type"] == "urn:hockle:problem:job-not-found"
    assert stack.http.delete(f"/v1/jobs/{missing}").status_code == 404


def test_idempotency_and_identical_spec(stack: Stack):
    case = tiny_case("idem")
    first = stack.submit(case, headers={"Idempotency-Key": "key-idem-1"})
    assert first.status_code == 201
    retry = stack.submit(case, headers={"Idempotency-Key": "key-idem-1"})
    assert retry.status_code == 200 and retry.json()["id"] == first.json()["id"]
    other = tiny_case("idem-other")
    conflict = stack.submit(other, headers={"Idempotency-Key": "key-idem-1"})
    assert conflict.status_code == 422
    assert conflict.json()["errors"][0]["loc"] == "header.Idempotency-Key"

    done = stack.wait_state(first.json()["id"], TERMINAL, 60)
    assert done["state"] == "successful"
    # an identical spec (same canonical hash and solver version) is answered from that job
    cached = stack.submit(case)
    assert cached.status_code == 200 and cached.json()["id"] == first.json()["id"]
    # unless the client asks for a fresh run
    # a finished job cannot be dismissed
    finished = stack.http.delete(f"/v1/jobs/{first.json()['id']}")
    assert finished.status_code == 409
    assert finished.json()["type"] == "urn:hockle:problem:job-finished"
    fresh = stack.submit(case, params={"fresh": "true"})
    assert fresh.status_code == 201 and fresh.json()["id"] != first.json()["id"]
    assert stack.wait_state(fresh.json()["id"], TERMINAL, 60)["state"] == "successful"


def _wait_running(stack: Stack, job_id: str, timeout: float = 60, min_step: int = 1) -> dict:
    def running():
        job = stack.job(job_id)
        assert job["state"] in ("accepted", "running"), job
        return job if job["state"] == "running" and job["step"] >= min_step else None

    return wait_until(running, timeout, 0.1, f"job {job_id} to run")


def test_dismiss_queued_and_running(stack: Stack):
    # occupy both workers, then queue a third job behind them
    long_ids = [stack.submit(long_case(f"long-{i}")).json()["id"] for i in range(2)]
    for job_id in long_ids:
        _wait_running(stack, job_id, min_step=50)  # past a few output steps (every 10)
    queued = stack.submit(tiny_case("queued-then-dismissed")).json()
    assert queued["state"] == "accepted"

    response = stack.http.delete(f"/v1/jobs/{queued['id']}")
    assert response.status_code == 200
    assert response.json()["state"] == "dismissed"
    assert response.json()["reason"] == "cancelled_by_user"

    for job_id in long_ids:
        response = stack.http.delete(f"/v1/jobs/{job_id}")
        assert response.status_code == 202, response.text
        assert response.json()["cancel_requested"] is True
    for job_id in long_ids:
        job = stack.wait_state(job_id, TERMINAL, 30)
        assert job["state"] == "dismissed" and job["reason"] == "cancelled_by_user", job
        assert 0 < job["progress"] < 100
        # the partial dataset is kept and served
        assert job["result_available"] and job["result_partial"]
        response = stack.http.get(f"/v1/jobs/{job_id}/results")
        assert response.status_code == 200
        summary = stack.http.get(f"/v1/jobs/{job_id}/summary").json()
        assert summary["partial"] is True and 0 < summary["time"][-1] < 20.0

    # the stop came within one time step of the request: the solver read the flag every step
    registry = registry_for(stack)
    try:
        for job_id in long_ids:
            events = {e.kind: e for e in registry.events(job_id)}
            assert events["cancel_requested"].at < events["finished"].at
            # request -> stopped, partial dataset written and recorded: well under a second
            # of wall time here (a step of this case takes a few ms)
            assert (events["finished"].at - events["cancel_requested"].at).total_seconds() < 3
        # the dismissed queued job was delivered to a worker and never started
        wait_until(lambda: "skipped" in [e.kind for e in registry.events(queued["id"])], 30, 0.2,
                   "the dismissed job's delivery")
        kinds = [e.kind for e in registry.events(queued["id"])]
        assert "started" not in kinds
        job = stack.job(queued["id"])
        assert job["attempts"] == 0 and job["started"] is None and job["state"] == "dismissed"
    finally:
        registry.dispose()
    # dismissing a dismissed job again is harmless
    assert stack.http.delete(f"/v1/jobs/{long_ids[0]}").status_code == 200


def _victim_and_survivor(job: dict) -> tuple[str, str]:
    victim = job["worker"].split("@")[0]
    return victim, "w2" if victim == "w1" else "w1"


def _events(stack: Stack, job_id: str):
    registry = registry_for(stack)
    try:
        return registry.events(job_id)
    finally:
        registry.dispose()


def _attempt_of(path: str) -> int:
    with xr.open_dataset(path, engine="netcdf4") as ds:
        return int(ds.attrs["hockle_attempt"])


def test_worker_killed_mid_job_is_requeued_and_finishes_once(stack: Stack):
    job_id = stack.submit(long_case("killed-worker", t_end=16.0)).json()["id"]
    job = _wait_running(stack, job_id, timeout=120)
    # a checkpoint in the store before the kill (written every second here)
    checkpoint = stack.root / "data" / "results" / f"{job_id}.ckpt"
    wait_until(checkpoint.exists, 120, 0.1, "the job's first checkpoint")
    job = stack.job(job_id)
    victim, survivor = _victim_and_survivor(job)
    # SIGKILL the whole worker node (main process and its pool process): nothing of it runs
    stack.stop_worker(victim, sig=signal.SIGKILL)
    # its heartbeat goes stale (10 s here), a sweeper queues the job again, the other worker
    # claims it as attempt 2; generous wait: the machine may be loaded
    done = stack.wait_state(job_id, TERMINAL, 300)
    assert done["state"] == "successful", done
    assert done["attempts"] == 2 and done["worker"] == f"{survivor}@test"
    assert done["progress"] == 100.0 and not done["result_partial"]
    events = _events(stack, job_id)
    kinds = [e.kind for e in events]
    assert kinds.count("finished") == 1 and "finish_refused" not in kinds
    assert [e.worker for e in events if e.kind == "started"] == [f"{victim}@test",
                                                                 f"{survivor}@test"]
    [lost] = [e for e in events if e.kind == "worker_lost"]
    assert lost.attempt == 1 and json.loads(lost.detail)["action"] == "requeued"
    registry = registry_for(stack)
    try:
        path = registry.get(job_id).result_path
    finally:
        registry.dispose()
    assert path.endswith(f"{job_id}.attempt-2.nc") and _attempt_of(path) == 2
    # attempt 2 continued from the last checkpoint of attempt 1: nothing before it recomputed
    [resumed] = [e for e in events if e.kind == "resumed"]
    at = json.loads(resumed.detail)
    assert resumed.attempt == 2 and at["t"] > 0.0 and at["step"] > 0
    with xr.open_dataset(path, engine="netcdf4") as ds:
        assert float(ds.attrs["hockle_resumed_at"]) == at["t"]
        assert ds.attrs["hockle_status"] == "completed" and float(ds.time[-1]) == 16.0
    assert not checkpoint.exists()                 # removed with the job's terminal state
    stack.start_worker(victim)  # back to two workers for the next tests


_REFERENCE: dict = {}


def _uninterrupted(case: dict) -> dict:
    """The data variables of ``case`` solved in this process without a stop (cached)."""
    key = json.dumps(case["numerics"], sort_keys=True)
    if key not in _REFERENCE:
        from solver.case import Case
        from solver.simulation import integrate

        ds = integrate(Case.model_validate(case))
        _REFERENCE[key] = {name: ds[name].values.copy() for name in ds.data_vars}
    return _REFERENCE[key]


@pytest.mark.parametrize("target", ["process_group", "main_process"])
def test_worker_shut_down_mid_job_hands_it_back(stack: Stack, target: str):
    """SIGTERM to a worker mid-job (warm shutdown: to its whole process group as systemd and
    `kill -TERM -pgid` send it, or to its main process alone as docker stop and Kubernetes
    do): the solve stops at its next step, its final checkpoint is stored, the job goes back
    to the queue at once (no heartbeat timeout), the worker exits by itself, and the other
    worker continues from that checkpoint to a result equal bit for bit to an uninterrupted
    run, finished exactly once."""
    case = long_case(f"shutdown-{target}", t_end=16.0)
    job_id = stack.submit(case).json()["id"]
    _wait_running(stack, job_id, timeout=120, min_step=20)
    job = stack.job(job_id)
    victim, survivor = _victim_and_survivor(job)
    proc = stack.workers.pop(victim)
    before = job["sim_time"]
    signalled = time.monotonic()
    if target == "process_group":
        os.killpg(proc.pid, signal.SIGTERM)
    else:
        os.kill(proc.pid, signal.SIGTERM)
    try:
        # handed back promptly: well before the 10-s heartbeat timeout of a lost worker
        wait_until(lambda: any(e.kind == "requeued_at_shutdown" for e in _events(stack, job_id)),
                   60, 0.2, "the job to be handed back")
        handed_back_after = time.monotonic() - signalled
        # the warm shutdown ends by itself once the job is handed back
        assert proc.wait(timeout=60) == 0
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
    assert handed_back_after < 10.0, handed_back_after
    log = stack.log(f"worker-{victim}.log")
    assert "WorkerLostError" not in log and "Traceback" not in log.split("Warm shutdown")[-1]

    done = stack.wait_state(job_id, TERMINAL, 300)
    assert done["state"] == "successful", done
    assert done["attempts"] == 2 and done["worker"] == f"{survivor}@test"
    assert done["progress"] == 100.0 and not done["result_partial"]
    events = _events(stack, job_id)
    kinds = [e.kind for e in events]
    assert kinds.count("finished") == 1 and "finish_refused" not in kinds
    assert "worker_lost" not in kinds                 # not the lost-worker path
    assert [e.worker for e in events if e.kind == "started"] == [f"{victim}@test",
                                                                 f"{survivor}@test"]
    [back] = [e for e in events if e.kind == "requeued_at_shutdown"]
    stop = json.loads(back.detail)
    assert back.attempt == 1 and stop["action"] == "requeued"
    assert stop["reason"] == "worker_shutdown" and stop["t"] >= before
    # attempt 2 continued from the checkpoint handed out at the stop (nothing recomputed)
    [resumed] = [e for e in events if e.kind == "resumed"]
    at = json.loads(resumed.detail)
    assert resumed.attempt == 2 and at["t"] >= before and at["t"] == stop["t"]
    registry = registry_for(stack)
    try:
        path = registry.get(job_id).result_path
    finally:
        registry.dispose()
    assert path.endswith(f"{job_id}.attempt-2.nc") and _attempt_of(path) == 2
    # the stopped attempt wrote no dataset: its result is not the job's
    assert not Path(path).with_name(f"{job_id}.nc").exists()
    assert not (stack.root / "data" / "results" / f"{job_id}.ckpt").exists()
    reference = _uninterrupted(case)
    with xr.open_dataset(path, engine="netcdf4") as ds:
        assert float(ds.attrs["hockle_resumed_at"]) == at["t"]
        assert ds.attrs["hockle_status"] == "completed" and float(ds.time[-1]) == 16.0
        for name, values in reference.items():
            assert np.array_equal(ds[name].values, values, equal_nan=True), name
    stack.start_worker(victim)  # back to two workers for the next tests


def test_paused_worker_comes_back_and_cannot_overwrite(stack: Stack):
    """A worker stalls (SIGSTOP) past the heartbeat timeout: the job is re-queued and finished by
    the other worker; when the stalled one resumes (SIGCONT) its attempt is refused everywhere
    and it writes nothing over the result."""
    job_id = stack.submit(long_case("paused-worker", t_end=16.0)).json()["id"]
    job = _wait_running(stack, job_id, timeout=120)
    victim, survivor = _victim_and_survivor(job)
    proc = stack.workers[victim]
    os.killpg(proc.pid, signal.SIGSTOP)
    try:
        done = stack.wait_state(job_id, TERMINAL, 300)
    finally:
        os.killpg(proc.pid, signal.SIGCONT)
    assert done["state"] == "successful", done
    assert done["attempts"] == 2 and done["worker"] == f"{survivor}@test"
    # the old attempt learns at its next heartbeat (or at its refused finish) that it lost
    wait_until(lambda: any(e.kind in ("attempt_abandoned", "finish_refused") and e.attempt == 1
                           for e in _events(stack, job_id)), 120, 0.5,
               "the paused attempt to give up")
    after = stack.job(job_id)
    for key in ("state", "attempts", "worker", "progress", "finished", "sim_time"):
        assert after[key] == done[key], key
    events = _events(stack, job_id)
    assert [e.kind for e in events].count("finished") == 1
    registry = registry_for(stack)
    try:
        path = registry.get(job_id).result_path
    finally:
        registry.dispose()
    assert _attempt_of(path) == 2
    # attempt 1's own file (<id>.nc) is not left behind: nothing written, or deleted
    first = Path(path).with_name(f"{job_id}.nc")
    wait_until(lambda: not first.exists(), 30, 0.2, "attempt 1's file to be gone")
    assert stack.http.get(f"/v1/jobs/{job_id}/results").status_code == 200


def test_accepted_job_whose_message_is_lost_is_sent_again(stack: Stack):
    job = record_job(stack, tiny_case("lost-message"))  # recorded, never sent
    done = stack.wait_state(job.id, TERMINAL, 120)
    assert done["state"] == "successful", done
    assert done["attempts"] == 1
    kinds = [e.kind for e in _events(stack, job.id)]
    assert kinds.index("requeued") < kinds.index("started")
    assert kinds.count("started") == 1 and kinds.count("finished") == 1


def test_restart_redis_and_api_keeps_jobs_and_results(stack: Stack):
    first = stack.submit(tiny_case("before-restart")).json()
    done = stack.wait_state(first["id"], TERMINAL, 60)
    assert done["state"] == "successful"
    before = stack.http.get(f"/v1/jobs/{first['id']}/results")
    listing_before = stack.http.get("/v1/jobs", params={"page_size": 500}).json()["jobs"]

    stack.stop_api()
    stack.redis.restart()
    stack.start_api()

    after = stack.job(first["id"])
    for key in ("state", "created", "finished", "spec_hash", "worker", "progress"):
        assert after[key] == done[key]
    results = stack.http.get(f"/v1/jobs/{first['id']}/results")
    assert results.status_code == 200
    assert results.content == before.content and results.headers["etag"] == before.headers["etag"]
    listing_after = stack.http.get("/v1/jobs", params={"page_size": 500}).json()["jobs"]
    assert [j["id"] for j in listing_after] == [j["id"] for j in listing_before]

    # the workers reconnected to the restarted Redis: a new job runs
    second = stack.submit(tiny_case("after-restart")).json()
    assert stack.wait_state(second["id"], TERMINAL, 90)["state"] == "successful"
    health = stack.http.get("/v1/health").json()
    assert health["broker"]["ok"] and health["registry"]["ok"] and health["mode"] == "distributed"
    assert {w["name"] for w in health["workers"]} >= {"w1@test", "w2@test"}


def test_hockle_submit_wait(stack: Stack, tmp_path):
    import json

    from hockle.service_commands import register

    case_path = tmp_path / "case.json"
    case_path.write_text(json.dumps(tiny_case("from-cli")))
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    out = tmp_path / "cli.nc"
    args = parser.parse_args(["submit", str(case_path), "--url", stack.url, "--wait",
                              "--poll", "0.2", "-o", str(out)])
    buffer = io.StringIO()
    with redirect_stdout(buffer):
        code = args.func(args)
    assert code == 0, buffer.getvalue()
    assert "successful" in buffer.getvalue()
    with xr.open_dataset(out, engine="netcdf4") as ds:
        assert ds.attrs["title"] == "from-cli"

    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({**tiny_case("bad"), "colour": "red"}))
    args = parser.parse_args(["submit", str(bad), "--url", stack.url])
    assert args.func(args) == 2


def test_python_client(stack: Stack):
    from service.client import HockleAPIError, HockleClient

    seen = []
    with HockleClient(stack.url) as client:
        job = client.submit(tiny_case("client"), fresh=True)
        job = client.wait(job.id, poll_interval=0.1, on_progress=lambda j: seen.append(j.state))
        assert job.state == "successful" and seen[-1] == "successful"
        ds = client.dataset(job.id)
        assert isinstance(ds, xr.Dataset) and ds.attrs["hockle_job_id"] == job.id
        sl = client.variable(job.id, "omega", time=0.05, component=3)
        assert sl.dims == ["s"]
        assert client.summary(job.id).series["energy_total"].units == "J"
        with pytest.raises(HockleAPIError) as err:
            client.submit({**tiny_case("bad"), "rod": {"length": -1}})
        assert err.value.status == 422
        assert any(e["loc"] == "rod.length" for e in err.value.errors)
