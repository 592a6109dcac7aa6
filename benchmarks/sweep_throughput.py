"""Sweep throughput of the hockle service (distributed mode on this machine).

Starts a redis-server on a free port, a registry (a fresh PostgreSQL database on
127.0.0.1:5432, or SQLite with --registry sqlite), the API and N Celery worker processes;
then

1. warms each worker with tiny jobs (a pool process's first job imports the solver), then
   runs one member of the sweep alone as a job (POST /v1/jobs, wait): the single-job rate,
   60 / (its time from creation to finish in the registry) jobs per minute;
2. submits the sweep (POST /v1/sweeps: MEMBERS twist rates of a 100-segment twisted rod in
   water, all distinct so that none is answered from an earlier job) and waits for it:
   members per minute from its first member's creation to its last member's finish;

and prints both, their ratio (ideal: the number of workers, each worker running members back
to back) and the workers' busy share (the members' solver wall
times over workers x span),
then fetches the combined dataset once (GET /v1/sweeps/{id}/results) and times that.

    python -m benchmarks.sweep_throughput [--members 16] [--workers 2] [--registry postgresql]
    python -m benchmarks.sweep_throughput --quick      # 4 members of a 10-segment case
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

import httpx

REPO = Path(__file__).resolve().parents[1]
from benchmarks.load_service import service_stack

TWIST = "boundary.start.rotation.2.angular_velocity"
TERMINAL = ("successful", "failed", "dismissed")


def base_case(segments: int, t_end: float) -> dict:
    """A rod in water turned at one end, the other sliding under 0.1 N; no contact."""
    end_free = [{"velocity": 0}, {"velocity": 0}, {"force": 0.1}]
    return {
        "schema_version": 1, "name": f"sweep throughput {segments} segments",
        "rod": {"length": 1.0, "youngs_modulus": 1.25e7, "shear_modulus": 5.0e6,
                "density": 1500.0, "diameter": 0.02},
        "fluid": {"density": 1000.0},
        "distributed_forces": [{"value": [1e-5, 0.0, 0.0], "start": 0.0, "end": 2.0}],
        "boundary": {
            "start": {"translation": [{"velocity": 0}] * 3,
                      "rotation": [{"angular_velocity": 0}, {"angular_velocity": 0},
                                   {"angular_velocity": -2.0}]},
            "end": {"translation": end_free, "rotation": [{"angular_velocity": 0}] * 3}},
        "numerics": {"n_segments": segments, "dt": 0.1, "t_end": t_end},
        "output": {"fields": ["position", "energies", "topology"]},
    }


def _iso(text: str) -> datetime:
    return datetime.fromisoformat(text.replace("Z", "+00:00"))


def _wait(client: httpx.Client, url: str, timeout: float) -> dict:
    deadline = time.monotonic() + timeout
    while True:
        body = client.get(url).json()
        if body["state"] in TERMINAL:
            return body
        if time.monotonic() > deadline:
            raise SystemExit(f"timed out waiting for {url}: {body['state']}")
        time.sleep(0.25)


def measure(base: str, members: int, segments: int, t_end: float, workers: int) -> dict:
    rates = [round(-1.5 - 0.05 * k, 3) for k in range(members)]
    case = base_case(segments, t_end)
    with httpx.Client(base_url=base, timeout=120) as client:
        # 0. warm every worker's pool process (its first job imports the solver's modules)
        warm = []
        for k in range(2 * workers):
            tiny = base_case(4, 0.2)
            tiny["name"] = f"warm-up {k}"
            warm.append(client.post("/v1/jobs", json=tiny, params={"fresh": "true"}).json())
        for job in warm:
            _wait(client, f"/v1/jobs/{job['id']}", 600)
        # 1. one member alone
        alone = json.loads(json.dumps(case))
        alone["boundary"]["start"]["rotation"][2] = {"angular_velocity": rates[members // 2]}
        alone["name"] += " alone"          # not the sweep's member: that one runs in the sweep
        t0 = time.monotonic()
        job = client.post("/v1/jobs", json=alone, params={"fresh": "true"}).json()
        job = _wait(client, f"/v1/jobs/{job['id']}", 3600)
        single_wall = time.monotonic() - t0
        if job["state"] != "successful":
            raise SystemExit(f"the single job ended {job['state']}: {job.get('message')}")
        single_solver = job["wall_time"]
        single_span = (_iso(job["finished"]) - _iso(job["created"])).total_seconds()

        # 2. the sweep
        body = {"base": case, "parameters": {TWIST: rates}, "combine": "grid"}
        t0 = time.monotonic()
        response = client.post("/v1/sweeps", json=body, params={"fresh": "true"})
        if response.status_code != 201:
            raise SystemExit(f"sweep refused: {response.status_code} {response.text}")
        submit_s = time.monotonic() - t0
        sweep = _wait(client, f"/v1/sweeps/{response.json()['id']}", 4 * 3600)
        sweep_wall = time.monotonic() - t0
        jobs = [client.get(f"/v1/jobs/{m['job_id']}").json() for m in sweep["members"]]
        span = (max(_iso(j["finished"]) for j in jobs)
                - min(_iso(j["created"]) for j in jobs)).total_seconds()
        solver = [j["wall_time"] or 0.0 for j in jobs]
        by_worker: dict[str, int] = {}
        for j in jobs:
            by_worker[j["worker"] or "?"] = by_worker.get(j["worker"] or "?", 0) + 1

        t0 = time.monotonic()
        combined = client.get(f"/v1/sweeps/{sweep['id']}/results")
        combine_s = time.monotonic() - t0
    # rates from the registry's timestamps (created -> finished), not this script's polls
    single_rate = 60.0 / single_span
    sweep_rate = 60.0 * members / span
    return {
        "members": members, "segments": segments, "t_end_s": t_end, "workers": workers,
        "sweep_state": sweep["state"], "member_states": sweep["counts"],
        "single_job_span_s": round(single_span, 3),
        "single_job_wall_s": round(single_wall, 2),
        "single_job_solver_s": round(single_solver, 2),
        "single_job_rate_per_min": round(single_rate, 2),
        "sweep_submit_s": round(submit_s, 3),
        "sweep_wall_s": round(sweep_wall, 2),
        "sweep_span_s": round(span, 2),
        "members_per_min": round(sweep_rate, 2),
        "ratio_to_single_job": round(sweep_rate / single_rate, 3),
        "ideal_ratio": workers,
        "member_solver_s_mean": round(sum(solver) / len(solver), 2),
        "workers_busy_share": round(sum(solver) / (workers * span), 3),
        "members_by_worker": by_worker,
        "combined_results_status": combined.status_code,
        "combined_results_bytes": len(combined.content),
        "combined_results_s": round(combine_s, 3),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--members", type=int, default=16)
    parser.add_argument("--segments", type=int, default=100)
    parser.add_argument("--t-end", type=float, default=20.0, help="simulated seconds")
    parser.add_argument("--workers", type=int, default=2, help="worker processes (concurrency 1)")
    parser.add_argument("--registry", choices=("postgresql", "sqlite"), default="postgresql")
    parser.add_argument("--quick", action="store_true",
                        help="a smoke run: 4 members of a 10-segment case to 2 s")
    parser.add_argument("--json", default=None, help="also write the figures to this file")
    args = parser.parse_args()
    if args.quick:
        args.members, args.segments, args.t_end = 4, 10, 2.0

    root = Path(tempfile.mkdtemp(prefix="hockle-sweep-bench-"))
    with service_stack(root, args.registry, args.workers, "sweep") as (base, _env):
        figures = measure(base, args.members, args.segments, args.t_end, args.workers)
        print(f"hockle sweep throughput: {args.members} members of a {args.segments}-segment "
              f"case to {args.t_end:g} s, {args.workers} workers, {args.registry} registry")
        print(f"  single job                {figures['single_job_span_s']} s created-to-finished "
              f"({figures['single_job_solver_s']} s solver): "
              f"{figures['single_job_rate_per_min']} jobs/min")
        print(f"  sweep                     {figures['sweep_span_s']} s first created to last "
              f"finished: {figures['members_per_min']} members/min ({figures['member_states']})")
        print(f"  ratio to the single job   {figures['ratio_to_single_job']} "
              f"(ideal {args.workers}: every worker busy)")
        print(f"  workers busy              {100 * figures['workers_busy_share']:.0f} % of "
              f"{args.workers} x the sweep's span (solver time); members by worker "
              f"{figures['members_by_worker']}")
        print(f"  combined results          HTTP {figures['combined_results_status']}, "
              f"{figures['combined_results_bytes']} bytes in {figures['combined_results_s']} s")
        if args.json:
            Path(args.json).write_text(json.dumps(figures, indent=2) + "\n")
        return 0 if figures["sweep_state"] == "successful" else 1


if __name__ == "__main__":
    sys.exit(main())
