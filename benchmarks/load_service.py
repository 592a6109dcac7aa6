"""Load benchmark of the hockle service (distributed mode on this machine).

Starts a redis-server on a free port, a fresh PostgreSQL database on 127.0.0.1:5432 (or SQLite
with --registry sqlite), the API and N Celery worker processes; submits JOBS tiny cases
concurrently while a "dashboard" polls GET /v1/jobs/{id} at RATE requests/s; and prints:

* jobs completed per minute (first submit to last finish),
* p50 / p99 latency of GET /v1/jobs/{id} while the workers are busy, and of POST /v1/jobs,
* jobs lost (not successful) and jobs run twice to completion (from the registry's events).

    python benchmarks/load_service.py [--jobs 200] [--rate 50] [--workers 2] [--registry postgresql]
"""
from __future__ import annotations

import argparse
import asyncio
import collections
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
sys.path.insert(0, str(REPO))

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


async def run_load(base: str, n_jobs: int, rate: float, submit_concurrency: int) -> dict:
    latencies_get: list[float] = []
    latencies_post: list[float] = []
    job_ids: list[str] = []
    states: dict[str, dict] = {}
    submitted_at = time.monotonic()
    busy = asyncio.Event()
    limits = httpx.Limits(max_connections=64, max_keepalive_connections=64)
    async with httpx.AsyncClient(base_url=base, timeout=60, limits=limits) as client:
        sem = asyncio.Semaphore(submit_concurrency)

        async def submit(i: int) -> None:
            case = json.loads(json.dumps(TINY))
            case["name"] = f"bench-{i}-{uuid.uuid4().hex[:6]}"
            async with sem:
                t0 = time.perf_counter()
                response = await client.post("/v1/jobs", json=case,
                                             headers={"Idempotency-Key": f"bench-{case['name']}"})
                latencies_post.append(time.perf_counter() - t0)
            response.raise_for_status()
            job_ids.append(response.json()["id"])

        async def dashboard() -> None:
            """GET /v1/jobs/{id} at `rate` requests/s on random jobs until all are terminal."""
            interval = 1.0 / rate
            next_at = time.perf_counter()
            pending: set[asyncio.Task] = set()

            async def one(job_id: str) -> None:
                t0 = time.perf_counter()
                response = await client.get(f"/v1/jobs/{job_id}")
                elapsed = time.perf_counter() - t0
                if response.status_code == 200 and busy.is_set():
                    latencies_get.append(elapsed)

            while not (len(job_ids) == n_jobs and all_done.is_set()):
                if job_ids:
                    task = asyncio.create_task(one(random.choice(job_ids)))
                    pending.add(task)
                    task.add_done_callback(pending.discard)
                next_at += interval
                await asyncio.sleep(max(0.0, next_at - time.perf_counter()))
            await asyncio.gather(*pending)

        async def collector() -> None:
            """Find out when every job is terminal (paged listing, 2 requests/s)."""
            while True:
                await asyncio.sleep(0.5)
                if len(job_ids) < n_jobs:
                    continue
                token = None
                seen = {}
                while True:
                    params = {"page_size": 500}
                    if token:
                        params["page_token"] = token
                    page = (await client.get("/v1/jobs", params=params)).json()
                    for job in page["jobs"]:
                        seen[job["id"]] = job
                    token = page["next_page_token"]
                    if not token:
                        break
                mine = {i: seen[i] for i in job_ids if i in seen}
                running = sum(1 for j in mine.values() if j["state"] in ("running", "accepted"))
                if running:
                    busy.set()
                if len(mine) == n_jobs and all(j["state"] in TERMINAL for j in mine.values()):
                    states.update(mine)
                    all_done.set()
                    return

        all_done = asyncio.Event()
        busy.set()  # workers are busy from the first submit until the last job finishes
        poll = asyncio.create_task(dashboard())
        watch = asyncio.create_task(collector())
        await asyncio.gather(*(submit(i) for i in range(n_jobs)))
        submit_wall = time.monotonic() - submitted_at
        await watch
        busy.clear()
        await poll
    return {"get": latencies_get, "post": latencies_post, "states": states,
            "submit_wall": submit_wall, "ids": job_ids}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--jobs", type=int, default=200)
    parser.add_argument("--rate", type=float, default=50.0, help="dashboard GETs per second")
    parser.add_argument("--workers", type=int, default=2, help="worker processes (concurrency 1)")
    parser.add_argument("--registry", choices=("postgresql", "sqlite"), default="postgresql")
    parser.add_argument("--submit-concurrency", type=int, default=50)
    parser.add_argument("--json", default=None, help="also write the figures to this file")
    args = parser.parse_args()

    root = Path(tempfile.mkdtemp(prefix="hockle-bench-"))
    procs = Processes(root)
    admin = None
    db_name = None
    env = {k: v for k, v in os.environ.items() if not k.startswith("HOCKLE_")}
    try:
        redis_port = free_port()
        procs.spawn(["redis-server", "--port", str(redis_port), "--bind", "127.0.0.1", "--dir",
                     str(root), "--appendonly", "yes", "--save", "",
                     "--maxmemory-policy", "noeviction"], "redis.log")
        import redis

        wait_for(lambda: redis.Redis(port=redis_port).ping(), 15, "redis-server")
        if args.registry == "postgresql":
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
        for i in range(args.workers):
            procs.spawn([sys.executable, "-m", "worker", "--concurrency", "1", "--hostname",
                         f"bench{i}@%h", "--loglevel", "WARNING"], f"worker{i}.log", env)
        wait_for(lambda: len(httpx.get(f"{base}/v1/health").json()["workers"]) >= args.workers,
                 90, "the workers")

        t0 = time.monotonic()
        result = asyncio.run(run_load(base, args.jobs, args.rate, args.submit_concurrency))
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
            "wall_s": round(wall, 2),
            "submit_wall_s": round(result["submit_wall"], 2),
            "jobs_per_minute": round(len(finishes) / span * 60.0, 1) if span > 0 else None,
            "get_requests": len(result["get"]),
            "get_p50_ms": round(statistics.median(result["get"]) * 1e3, 2),
            "get_p99_ms": round(percentile(result["get"], 99) * 1e3, 2),
            "post_p50_ms": round(statistics.median(result["post"]) * 1e3, 2),
            "post_p99_ms": round(percentile(result["post"], 99) * 1e3, 2),
            "states": dict(counts),
            "lost": len(lost),
            "run_twice_to_completion": len(twice),
            "attempts": dict(attempts),
        }
        print(f"hockle load benchmark: {args.jobs} tiny jobs, {args.workers} workers, "
              f"{args.registry} registry, dashboard {args.rate:g} GET/s")
        print(f"  jobs completed per minute     {figures['jobs_per_minute']}")
        print(f"  GET /v1/jobs/{{id}} p50 / p99   {figures['get_p50_ms']} / {figures['get_p99_ms']} ms"
              f"  ({figures['get_requests']} requests while busy)")
        print(f"  POST /v1/jobs p50 / p99       {figures['post_p50_ms']} / {figures['post_p99_ms']} ms"
              f"  (all {args.jobs} submitted in {figures['submit_wall_s']} s)")
        print(f"  states                        {dict(counts)}")
        print(f"  lost                          {len(lost)}")
        print(f"  run twice to completion       {len(twice)}")
        if args.json:
            Path(args.json).write_text(json.dumps(figures, indent=2))
        return 0 if not lost and not twice else 1
    finally:
        procs.stop_all()
        if admin is not None and db_name:
            admin.execute("SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
                          "WHERE datname = %s", (db_name,))
            admin.execute(f'DROP DATABASE IF EXISTS "{db_name}"')
            admin.close()
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
