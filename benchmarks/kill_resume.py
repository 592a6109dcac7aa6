"""kill -9 of the worker running a job half way, with the default settings (issue 40): how much
work is lost and how long the job takes to finish after the kill.

Starts its own Redis, registry (PostgreSQL on 127.0.0.1:5432, or SQLite), API and two workers
with the service's defaults (checkpoints every HOCKLE_CHECKPOINT_INTERVAL = 30 s of wall time
or HOCKLE_CHECKPOINT_PROGRESS = 10 % of the run, HOCKLE_JOB_HEARTBEAT_TIMEOUT = 60 s), submits
one job that solves for about ``--job-seconds`` (a 400-segment rod, smooth, its ``t_end``
scaled from a short calibration job), kills the worker process group holding it with
SIGKILL once its progress passes ``--kill-at`` percent, and prints: the age of the newest
checkpoint at the kill (wall seconds and simulated seconds behind the run), the time from the
kill to the job's re-queue and to its completion, and the attempts.

    python -m benchmarks.kill_resume [--job-seconds 180] [--kill-at 50] [--registry sqlite]
"""
from __future__ import annotations

import argparse
import copy
import os
import signal
import tempfile
import time
from pathlib import Path

import httpx

REPO = Path(__file__).resolve().parents[1]
from benchmarks.fuzz_api import TINY
from benchmarks.load_service import service_stack, wait_for


def _case(t_end: float) -> dict:
    case = copy.deepcopy(TINY)
    case["name"] = "kill-resume"
    case["numerics"].update(n_segments=400, dt=0.01, t_end=round(t_end, 2))
    case["output"] = {"every": 100, "fields": ["position", "energies"]}
    return case


def _wait_state(http: httpx.Client, job_id: str, states: tuple[str, ...], timeout: float) -> dict:
    last = {}

    def done():
        last["job"] = http.get(f"/v1/jobs/{job_id}").json()
        return last["job"]["state"] in states

    wait_for(done, timeout, f"job {job_id} to be {states}")
    return last["job"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--job-seconds", type=float, default=180.0,
                    help="about how long the job solves without a kill, s")
    ap.add_argument("--kill-at", type=float, default=50.0, help="progress (percent) to kill at")
    ap.add_argument("--registry", choices=("postgresql", "sqlite"), default="postgresql")
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f}")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        workers: list = []
        with service_stack(root, args.registry, 2, "kill", worker_procs=workers) as (base, env):
            results = Path(env["HOCKLE_DATA_DIR"]) / "results"
            with httpx.Client(base_url=base, timeout=60) as http:
                # calibration: 20 s of simulated time (numba compiled by now in both workers?
                # the first job pays for it: run it twice, time the second)
                for _ in range(2):
                    cal = http.post("/v1/jobs", json=_case(20.0), params={"fresh": "true"}).json()
                    cal = _wait_state(http, cal["id"], ("successful",), 900)
                pace = cal["wall_time"] / 20.0
                t_end = args.job_seconds / pace
                print(f"calibration: {pace:.3f} s of wall time per simulated s; "
                      f"t_end = {t_end:.0f} s for about {args.job_seconds:.0f} s")
                job = http.post("/v1/jobs", json=_case(t_end)).json()
                job_id = job["id"]
                submitted = time.monotonic()
                wait_for(lambda: http.get(f"/v1/jobs/{job_id}").json()["progress"]
                         >= args.kill_at, 3 * args.job_seconds + 300, "the kill point")
                status = http.get(f"/v1/jobs/{job_id}").json()
                name = status["worker"]
                index = int(name.split("@")[0][len("kill"):])
                ckpt = results / f"{job_id}.ckpt"
                killed = time.monotonic()
                os.killpg(workers[index].pid, signal.SIGKILL)
                age = time.time() - ckpt.stat().st_mtime if ckpt.exists() else float("nan")
                from solver.checkpoint import Checkpoint

                head = Checkpoint.header(ckpt.read_bytes()) if ckpt.exists() else {"t": 0.0}
                print(f"killed worker {name} at {status['progress']:.1f} % (t = "
                      f"{status['sim_time']:.1f} s of {t_end:.0f} s, "
                      f"{killed - submitted:.0f} s after submission)")
                print(f"newest checkpoint at the kill: {age:.1f} s old, t = {head['t']:.1f} s "
                      f"({status['sim_time'] - head['t']:.1f} simulated s behind)")
                _wait_state(http, job_id, ("accepted", "running"), 300)
                wait_for(lambda: http.get(f"/v1/jobs/{job_id}").json()["attempts"] >= 2, 300,
                         "the second attempt")
                requeued = time.monotonic() - killed
                final = _wait_state(http, job_id, ("successful", "failed"), 3 * args.job_seconds
                                    + 600)
                total = time.monotonic() - killed
                print(f"re-queued and claimed {requeued:.0f} s after the kill "
                      f"(HOCKLE_JOB_HEARTBEAT_TIMEOUT 60 s + a sweep)")
                print(f"job {final['state']} {total:.0f} s after the kill, attempts "
                      f"{final['attempts']}; submission to completion "
                      f"{time.monotonic() - submitted:.0f} s")
    print(f"load average {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
