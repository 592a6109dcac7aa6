"""Load benchmark of the hockle service (distributed mode on this machine).

Starts a redis-server on a free port, a fresh PostgreSQL database on 127.0.0.1:5432 (or SQLite
with --registry sqlite), the API and N Celery worker processes; submits JOBS tiny cases
concurrently while a "dashboard" polls GET /v1/jobs/{id} at RATE requests/s; and prints:

* jobs completed per minute (first submit to last finish),
* p50 / p99 latency of GET /v1/jobs/{id} while the workers are busy, and of POST /v1/jobs,
* jobs lost (not successful) and jobs run twice to completion (from the registry's events).

    python -m benchmarks.load_service [--jobs 200] [--rate 50] [--workers 2] [--registry postgresql]
"""
from __future__ import annotations

import argparse
import asyncio
import collections
import contextlib
import json
import os
import random
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import httpx

REPO = Path(__file__).resolve().parents[1]
TINY = {
    "schema_version": 1,
    "name": "bench",
    "rod": {"length": 1.0, "youngs_modulus": 1.25e7, "shear_modulus": 5.0e6, "density": 1500.0,
            "diameter": 0.02},
    "boundary": {
        "start": {"translation": [{"velocity": 0}, {"velocity": 0}, {"velocity": 0}],
                  "rotation": [{"angular_velocity": 0}, {"angular_velocity": 0},
                               {"angular_velocity": 1.0}]},
        "end": {"translation": [{"velocity": 0}, {"velocity": 0}, {"force": 0}],
                "rotation": [{"angular_velocity": 0}, {"angular_velocity": 0},
                             {"angular_velocity": 0}]},
    },
    "numerics": {"n_segments": 8, "dt": 0.01, "t_end": 0.05},
}
TERMINAL = ("successful", "failed", "dismissed")


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    if not ordered:
        return float("nan")
    k = min(len(ordered) - 1, max(0, int(round(q / 100 * (len(ordered) - 1)))))
    return ordered[k]


class Processes:
    def __init__(self, root: Path):
        self.root = root
        self.procs: list[subprocess.Popen] = []

    def spawn(self, args: list[str], log: str, env: dict | None = None) -> subprocess.Popen:
        proc = subprocess.Popen(args, stdout=open(self.root / log, "w"), stderr=subprocess.STDOUT,
                                env=env, cwd=self.root, start_new_session=True)
        self.procs.append(proc)
        return proc

    def stop_all(self) -> None:
        for proc in reversed(self.procs):
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
        for proc in reversed(self.procs):
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()


def wait_for(predicate, timeout: float, what: str):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if predicate():
                return
        except Exception:  # noqa: BLE001 - not up yet
            pass
        time.sleep(0.2)
    raise SystemExit(f"timed out waiting for {what}")


def dashboard(base: str, rate: float, ids, stop, out) -> None:
    """A separate process, like a real dashboard: GET /v1/jobs/{id} at `rate` requests/s on
    random known jobs (8 threads, each on its own keep-alive connection) until `stop`."""
    import queue
    import threading

    known: list[str] = []
    latencies: list[float] = []
    errors = [0]
    lock = threading.Lock()
    todo: queue.Queue = queue.Queue()

    def client_thread() -> None:
        with httpx.Client(base_url=base, timeout=60) as client:
            while True:
                job_id = todo.get()
                if job_id is None:
                    return
                t0 = time.perf_counter()
                try:
                    ok = client.get(f"/v1/jobs/{job_id}").status_code == 200
                except httpx.HTTPError:
                    ok = False
                elapsed = time.perf_counter() - t0
                with lock:
                    if ok:
                        latencies.append(elapsed)
                    else:
                        errors[0] += 1

    threads = [threading.Thread(target=client_thread, daemon=True) for _ in range(8)]
    for t in threads:
        t.start()
    next_at = time.perf_counter()
    while not stop.is_set():
        while True:
            try:
                known.append(ids.get_nowait())
            except queue.Empty:
                break
        if known:
            todo.put(random.choice(known))
        next_at += 1.0 / rate
        time.sleep(max(0.0, next_at - time.perf_counter()))
    for _ in threads:
        todo.put(None)
    for t in threads:
        t.join()
    out.put({"latencies": latencies, "errors": errors[0]})


async def submit_all(base: str, n_jobs: int, concurrency: int, ids) -> tuple[list[str], list[float]]:
    job_ids: list[str] = []
    latencies: list[float] = []
    limits = httpx.Limits(max_connections=concurrency, max_keepalive_connections=concurrency)
    async with httpx.AsyncClient(base_url=base, timeout=120, limits=limits) as client:
        sem = asyncio.Semaphore(concurrency)

        async def submit(i: int) -> None:
            case = json.loads(json.dumps(TINY))
            case["name"] = f"bench-{i}-{uuid.uuid4().hex[:6]}"
            async with sem:
                t0 = time.perf_counter()
                response = await client.post("/v1/jobs", json=case,
                                             headers={"Idempotency-Key": f"bench-{case['name']}"})
                latencies.append(time.perf_counter() - t0)
            response.raise_for_status()
            job_ids.append(response.json()["id"])
            ids.put(response.json()["id"])

        await asyncio.gather(*(submit(i) for i in range(n_jobs)))
    return job_ids, latencies


def run_load(base: str, n_jobs: int, rate: float, submit_concurrency: int) -> dict:
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    ids, out, stop = ctx.Queue(), ctx.Queue(), ctx.Event()
    poller = ctx.Process(target=dashboard, args=(base, rate, ids, stop, out))
    poller.start()
    t0 = time.monotonic()
    job_ids, post_latencies = asyncio.run(submit_all(base, n_jobs, submit_concurrency, ids))
    submit_wall = time.monotonic() - t0
    # wait until every job is terminal (the workers are busy until then)
    states: dict[str, dict] = {}
    with httpx.Client(base_url=base, timeout=60) as client:
        while True:
            time.sleep(0.5)
            seen, token = {}, None
            while True:
                params = {"page_size": 500, **({"page_token": token} if token else {})}
                page = client.get("/v1/jobs", params=params).json()
                seen.update({j["id"]: j for j in page["jobs"]})
                token = page["next_page_token"]
                if not token:
                    break
            mine = {i: seen[i] for i in job_ids if i in seen}
            if len(mine) == n_jobs and all(j["state"] in TERMINAL for j in mine.values()):
                states = mine
                break
    stop.set()
    polled = out.get(timeout=120)
    poller.join(timeout=30)
    return {"get": polled["latencies"], "get_errors": polled["errors"], "post": post_latencies,
            "states": states, "submit_wall": submit_wall, "ids": job_ids}


@contextlib.contextmanager
def service_stack(root: Path, registry: str, workers: int, name: str,
                  worker_env: dict[str, str] | None = None,
                  worker_procs: list | None = None):
    """The distributed service on this machine for a benchmark: a redis-server on a free
    port, the registry (a fresh PostgreSQL database on 127.0.0.1:5432, dropped afterwards,
    or SQLite under ``root``), the API and ``workers`` Celery worker processes (concurrency
    1, hostnames ``<name><i>@host``, ``worker_env`` added to their environment). Yields (the
    API's base URL, the services' environment); stops every process on exit. The workers'
    processes are appended to ``worker_procs`` when given (a benchmark that kills one). Raises RuntimeError when a process does not
    come up in time."""
    procs = Processes(root)
    admin = db_name = None
    env = {k: v for k, v in os.environ.items() if not k.startswith("HOCKLE_")}
    try:
        redis_port = free_port()
        procs.spawn(["redis-server", "--port", str(redis_port), "--bind", "127.0.0.1", "--dir",
                     str(root), "--appendonly", "yes", "--save", "",
                     "--maxmemory-policy", "noeviction"], "redis.log")
        import redis

        wait_for(lambda: redis.Redis(port=redis_port).ping(), 15, "redis-server")
        if registry == "postgresql":
            import psycopg

            admin = psycopg.connect("postgresql://postgres@127.0.0.1:5432/postgres",
                                    autocommit=True)
            db_name = f"hockle_bench_{uuid.uuid4().hex[:8]}"
            admin.execute(f'CREATE DATABASE "{db_name}"')
            env["HOCKLE_DATABASE_URL"] = f"postgresql://postgres@127.0.0.1:5432/{db_name}"
        api_port = free_port()
        env.update({
            "HOCKLE_DATA_DIR": str(root / "data"),
            "HOCKLE_BROKER_URL": f"redis://127.0.0.1:{redis_port}/0",
            "HOCKLE_HOST": "127.0.0.1",
            "HOCKLE_PORT": str(api_port),
            "HOCKLE_LOG_LEVEL": "WARNING",
            "PYTHONUNBUFFERED": "1",
        })
        base = f"http://127.0.0.1:{api_port}"
        procs.spawn([sys.executable, "-m", "service"], "api.log", env)
        wait_for(lambda: httpx.get(f"{base}/v1/health").status_code == 200, 60, "the API")
        for i in range(workers):
            proc = procs.spawn([sys.executable, "-m", "worker", "--concurrency", "1",
                                "--hostname", f"{name}{i}@%h", "--loglevel", "WARNING"],
                               f"worker{i}.log", {**env, **(worker_env or {})})
            if worker_procs is not None:
                worker_procs.append(proc)
        wait_for(lambda: len(httpx.get(f"{base}/v1/health").json()["workers"]) >= workers,
                 90, "the workers")
        yield base, env
    finally:
        procs.stop_all()
        if admin is not None and db_name is not None:
            admin.execute("SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
                          "WHERE datname = %s", (db_name,))
            admin.execute(f'DROP DATABASE IF EXISTS "{db_name}"')
            admin.close()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--jobs", type=int, default=200)
    parser.add_argument("--rate", type=float, default=50.0, help="dashboard GETs per second")
    parser.add_argument("--workers", type=int, default=2, help="worker processes (concurrency 1)")
    parser.add_argument("--registry", choices=("postgresql", "sqlite"), default="postgresql")
    parser.add_argument("--submit-concurrency", type=int, default=50)
    parser.add_argument("--worker-nice", type=int, default=10,
                        help="HOCKLE_WORKER_NICE of the workers (0: same priority as the API)")
    parser.add_argument("--json", default=None, help="also write the figures to this file")
    args = parser.parse_args()

    root = Path(tempfile.mkdtemp(prefix="hockle-bench-"))
    try:
        # API and workers share this machine: the workers run niced (HOCKLE_WORKER_NICE)
        with service_stack(root, args.registry, args.workers, "bench",
                           {"HOCKLE_WORKER_NICE": str(args.worker_nice)}) as (base, env):
            t0 = time.monotonic()
            result = run_load(base, args.jobs, args.rate, args.submit_concurrency)
            wall = time.monotonic() - t0

            states = result["states"]
            counts = collections.Counter(j["state"] for j in states.values())
            starts = [j["created"] for j in states.values()]
            finishes = [j["finished"] for j in states.values() if j["finished"]]
            from datetime import datetime

            span = (max(datetime.fromisoformat(f) for f in finishes)
                    - min(datetime.fromisoformat(s) for s in starts)).total_seconds()

            from service.registry import Registry
            from service.settings import Settings

            registry = Registry(Settings(data_dir=root / "data",
                                         database_url=env.get("HOCKLE_DATABASE_URL")).registry_url)
            solves = collections.Counter()
            finished = collections.Counter()
            for event in registry.events():
                if event.kind == "solve_finished":
                    solves[event.job_id] += 1
                if event.kind == "finished":
                    finished[event.job_id] += 1
            registry.dispose()
            twice = sorted(j for j in result["ids"] if solves[j] > 1 or finished[j] > 1)
            lost = sorted(j for j in result["ids"] if states.get(j, {}).get("state") != "successful")
            attempts = collections.Counter(j["attempts"] for j in states.values())

            figures = {
                "jobs": args.jobs,
                "workers": args.workers,
                "registry": args.registry,
                "dashboard_rate_per_s": args.rate,
                "worker_nice": args.worker_nice,
                "wall_s": round(wall, 2),
                "submit_wall_s": round(result["submit_wall"], 2),
                "jobs_per_minute": round(len(finishes) / span * 60.0, 1) if span > 0 else None,
                "get_requests": len(result["get"]),
                "get_errors": result["get_errors"],
                "get_p50_ms": round(statistics.median(result["get"]) * 1e3, 2),
                "get_p90_ms": round(percentile(result["get"], 90) * 1e3, 2),
                "get_p99_ms": round(percentile(result["get"], 99) * 1e3, 2),
                "get_max_ms": round(max(result["get"]) * 1e3, 2),
                "post_p50_ms": round(statistics.median(result["post"]) * 1e3, 2),
                "post_p99_ms": round(percentile(result["post"], 99) * 1e3, 2),
                "states": dict(counts),
                "lost": len(lost),
                "run_twice_to_completion": len(twice),
                "attempts": dict(attempts),
            }
            print(f"hockle load benchmark: {args.jobs} tiny jobs, {args.workers} workers, "
                  f"{args.registry} registry, dashboard {args.rate:g} GET/s, workers niced "
                  f"{args.worker_nice}")
            print(f"  jobs completed per minute     {figures['jobs_per_minute']}")
            print(f"  GET /v1/jobs/{{id}} p50 / p99   {figures['get_p50_ms']} / {figures['get_p99_ms']} ms"
                  f"  ({figures['get_requests']} requests while busy; p90 {figures['get_p90_ms']} ms,"
                  f" max {figures['get_max_ms']} ms)")
            print(f"  POST /v1/jobs p50 / p99       {figures['post_p50_ms']} / {figures['post_p99_ms']} ms"
                  f"  (all {args.jobs} submitted in {figures['submit_wall_s']} s)")
            print(f"  states                        {dict(counts)}")
            print(f"  lost                          {len(lost)}")
            print(f"  run twice to completion       {len(twice)}")
            if args.json:
                Path(args.json).write_text(json.dumps(figures, indent=2))
            print(f"  dashboard GET errors          {result['get_errors']}")
            return 0 if not lost and not twice and not result["get_errors"] else 1
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
