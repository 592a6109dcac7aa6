"""A locked PostgreSQL registry, as a migration or an administrator's transaction holds it: the
API process (real `python -m service`, Redis broker) keeps answering liveness at once, its
readiness reports the registry, and every request that needs the registry answers 503 with
Retry-After within HOCKLE_REGISTRY_REQUEST_TIMEOUT instead of waiting for the lock (or a 500
from the connection pool). Skipped where no PostgreSQL server answers on 127.0.0.1:5432.
"""
from __future__ import annotations

import json
import statistics
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import httpx
import pytest

from svc_support import empty_database_url, make_stack, tiny_case

pytestmark = pytest.mark.service

TIMEOUT = 2.0        # HOCKLE_REGISTRY_REQUEST_TIMEOUT of the API under test
CONCURRENT = 60      # GET /v1/jobs/{id} sent at once, in waves while the lock is held

PROBER = """
import json, os, sys, time
import httpx
url, stop = sys.argv[1], sys.argv[2]
out = []
with httpx.Client(base_url=url, timeout=30) as http:
    while not os.path.exists(stop):
        start = time.monotonic()
        code = http.get("/v1/health", params={"live": "true"}).status_code
        out.append((time.monotonic() - start, code))
        time.sleep(0.05)
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def stack(tmp_path_factory, redis_server):
    root = tmp_path_factory.mktemp("outage-db")
    with empty_database_url("postgresql", root, "hockle_outage") as url:
        stack = make_stack(tmp_path_factory, "outage", {
            "HOCKLE_DATABASE_URL": url, "HOCKLE_BROKER_URL": redis_server.url,
            "HOCKLE_REGISTRY_REQUEST_TIMEOUT": str(TIMEOUT)})
        stack.database_url = url
        stack.start_api()
        try:
            yield stack
        finally:
            stack.close()


def test_metrics_report_the_redis_queue_depth(stack, redis_server):
    """hockle_queue_depth is the Redis list KEDA scales the workers on (no worker runs here,
    so each job's message waits in it)."""
    import redis

    for k in range(2):
        assert stack.submit(tiny_case(f"queued-{k}")).status_code == 201
    waiting = redis.Redis(port=redis_server.port).llen("hockle")
    assert waiting >= 2
    text = stack.http.get("/metrics").text
    assert f'hockle_queue_depth{{queue="hockle"}} {float(waiting)}' in text, text
    assert 'hockle_jobs{state="accepted"}' in text


@pytest.mark.parametrize("lock_held", [12.0, pytest.param(45.0, marks=pytest.mark.slow)],
                         ids=["12s", "45s"])
def test_a_locked_registry_leaves_liveness_alone_and_answers_503(stack, lock_held):
    import psycopg

    response = stack.submit(tiny_case("outage"))
    assert response.status_code == 201, response.text
    job_id = response.json()["id"]

    locker = psycopg.connect(stack.database_url.replace("postgresql+psycopg", "postgresql"))
    locker.execute("LOCK TABLE hockle_jobs IN ACCESS EXCLUSIVE MODE")   # in a transaction
    locked_at = time.monotonic()
    release = threading.Timer(lock_held, locker.rollback)   # whatever the API does
    release.start()
    # the liveness prober is a process of its own, as a kubelet is: its timings are the API's,
    # not this process's threads competing for its interpreter
    stop_file = stack.root / "stop-probing"
    prober = subprocess.Popen([sys.executable, "-c", PROBER, stack.url, str(stop_file)],
                              stdout=subprocess.PIPE, text=True)
    # one client, its connections opened by the waves: no client set up while they run
    http_pool = httpx.Client(base_url=stack.url, timeout=60, limits=httpx.Limits(
        max_connections=CONCURRENT, max_keepalive_connections=CONCURRENT))

    def get_job(_):
        start = time.monotonic()
        answer = http_pool.get(f"/v1/jobs/{job_id}")
        return answer.status_code, time.monotonic() - start, answer

    try:
        answers, waves = [], 0
        with ThreadPoolExecutor(CONCURRENT) as pool:
            # waves of concurrent requests for as long as the lock is held (less a margin)
            while waves == 0 or time.monotonic() - locked_at < lock_held - 4 * TIMEOUT - 2:
                answers += list(pool.map(get_job, range(CONCURRENT)))
                waves += 1
        with httpx.Client(base_url=stack.url, timeout=30) as http:
            ready = http.get("/v1/health")
        held = time.monotonic() - locked_at
    finally:
        stop_file.touch()
        live = [tuple(x) for x in json.loads(prober.communicate(timeout=60)[0] or "[]")]
        http_pool.close()
        release.cancel()
        locker.rollback()
        locker.close()
    codes = [code for code, _, _ in answers]
    slowest = max(took for _, took, _ in answers)
    latencies = sorted(took for took, _ in live)
    print(f"\n{waves} x {CONCURRENT} GETs under the lock: "
          f"{dict((c, codes.count(c)) for c in set(codes))},"
          f" slowest {slowest:.2f} s; liveness {len(latencies)} probes, median "
          f"{1000 * statistics.median(latencies):.1f} ms, max {1000 * latencies[-1]:.1f} ms; "
          f"readiness {ready.status_code}")
    assert held < lock_held, f"the answers took {held:.1f} s: they waited for the lock"
    assert set(codes) == {503}, codes
    for _, _, answer in answers[:3]:
        assert answer.headers["content-type"].startswith("application/problem+json")
        assert answer.json()["type"] == "urn:hockle:problem:registry-unavailable"
        assert int(answer.headers["retry-after"]) >= 1
    # each waits at most for a thread of the API's pool (40: the 20 others queue), a pooled
    # connection and the lock, each bounded by the time-out
    assert slowest < 3 * TIMEOUT + 3.0, slowest
    assert ready.status_code == 503 and not ready.json()["registry"]["ok"], ready.text
    assert ready.json()["broker"]["ok"]
    assert latencies and {code for _, code in live} == {200}
    assert latencies[-1] < 0.5, latencies[-5:]

    # the lock gone, everything answers again
    assert stack.http.get(f"/v1/jobs/{job_id}").status_code == 200
    assert stack.http.get("/v1/health").status_code == 200
    assert "Traceback" not in stack.log("api.log")
