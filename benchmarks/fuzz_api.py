"""A bounded schemathesis run over every operation of the REST API (issue 11), reaching the
routes behind an existing job and sweep (issue 40): no input may give a server error.

Starts the API (`python -m service`, embedded mode with its local worker, a fresh data
directory), runs a tiny job and a two-member sweep of tiny jobs to completion, then runs
``schemathesis run`` against the OpenAPI document with the ``not_a_server_error`` check (plus
the response-schema checks when ``--all-checks``), at most ``--max-examples`` inputs per
operation and a fixed seed. The path parameters are pinned (a schemathesis.toml
``[parameters]`` table) to that job's id, that sweep's id and the result variable ``kappa``, so
the generated query strings and bodies meet a real job, sweep and result file instead of
404s (``--unpinned``: generated ids, as before). Prints schemathesis's summary and exit
status (0: no failure), then the answers per operation from its HAR report, the tracebacks
in the API's log and whether the API is healthy afterwards. schemathesis is a benchmark-only
dependency: ``python -m pip install -r benchmarks/requirements-fuzz.txt``.

    python -m benchmarks.fuzz_api [--max-examples 50] [--seed 1] [--all-checks] [--unpinned]
"""
from __future__ import annotations

import argparse
import collections
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

REPO = Path(__file__).resolve().parents[1]
from benchmarks.load_service import TINY as _LOAD_TINY
from benchmarks.load_service import free_port, wait_for

#: the tiny case of benchmarks.load_service, named for this run
TINY = {**_LOAD_TINY, "name": "fuzz"}


def _seed(base: str) -> tuple[str, str]:
    """A successful job and a successful sweep (waits for the embedded worker)."""
    with httpx.Client(base_url=base, timeout=60) as http:
        job = http.post("/v1/jobs", json=TINY).json()["id"]
        sweep = http.post("/v1/sweeps", json={
            "base": TINY, "combine": "grid",
            "parameters": {"boundary.start.rotation.2.angular_velocity": [2.0, 3.0]}}).json()["id"]
        wait_for(lambda: http.get(f"/v1/jobs/{job}").json()["state"] == "successful", 600,
                 "the seed job")
        wait_for(lambda: http.get(f"/v1/sweeps/{sweep}").json()["state"] == "successful", 600,
                 "the seed sweep")
    return job, sweep


_IDS = re.compile(r"[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}")


def _tally(har: Path, job: str | None, sweep: str | None) -> None:
    """Answers per operation (method and path with the ids as {job_id}/{sweep_id})."""
    if not har.exists():
        print(f"no HAR report at {har}")
        return
    entries = json.loads(har.read_text())["log"]["entries"]
    table: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    for entry in entries:
        url = httpx.URL(entry["request"]["url"])
        path = url.path
        if job:
            path = path.replace(job, "{job_id}")
        if sweep:
            path = path.replace(sweep, "{sweep_id}")
        path = _IDS.sub("{other id}", path)
        path = re.sub(r"/results/variables/(?!$)[^/]+$", "/results/variables/{name}", path)
        table[f"{entry['request']['method']} {path}"][entry["response"]["status"]] += 1
    print(f"\nanswers per operation ({len(entries)} requests in the HAR report):")
    unsupported = 0
    for operation in sorted(table, key=lambda op: (op.split()[1], op.split()[0])):
        counts = table[operation]
        if set(counts) == {405}:        # a method the route does not have
            unsupported += counts[405]
            continue
        shown = ", ".join(f"{code}: {n}" for code, n in sorted(counts.items()))
        print(f"  {operation:<55} {sum(counts.values()):5d}  {shown}")
    print(f"  (methods a route does not have: {unsupported} requests, all 405)")
    errors = sum(n for counts in table.values() for code, n in counts.items() if code >= 500)
    print(f"server errors (5xx): {errors}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-examples", type=int, default=50)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--all-checks", action="store_true",
                    help="also the response-schema and status-code conformance checks")
    ap.add_argument("--unpinned", action="store_true",
                    help="let schemathesis generate the job and sweep ids (mostly 404s)")
    args = ap.parse_args()
    exe = shutil.which("schemathesis") or shutil.which("st")
    if exe is None:
        print("schemathesis is not installed: python -m pip install -r "
              "benchmarks/requirements-fuzz.txt", file=sys.stderr)
        return 2
    port = free_port()
    with tempfile.TemporaryDirectory() as tmp:
        env = {k: v for k, v in os.environ.items() if not k.startswith("HOCKLE_")}
        env.update(HOCKLE_DATA_DIR=tmp, HOCKLE_PORT=str(port), HOCKLE_HOST="127.0.0.1",
                   HOCKLE_RATE_LIMIT="100000", HOCKLE_RATE_LIMIT_BURST="100000",
                   HOCKLE_EMBEDDED_WORKER="false" if args.unpinned else "true")
        log = open(Path(tmp) / "api.log", "w")
        api = subprocess.Popen([sys.executable, "-m", "service"], env=env, cwd=REPO,
                               stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        base = f"http://127.0.0.1:{port}"
        try:
            wait_for(lambda: httpx.get(f"{base}/v1/health", params={"live": "true"},
                                       timeout=2).status_code == 200, 60, "the API")
            job = sweep = None
            config = Path(tmp) / "schemathesis.toml"
            if not args.unpinned:
                t0 = time.perf_counter()
                job, sweep = _seed(base)
                print(f"seeded job {job} and sweep {sweep} ({time.perf_counter() - t0:.0f} s)")
                config.write_text("[parameters]\n" + "".join(
                    f'"path.{key}" = "{value}"\n' for key, value in
                    (("job_id", job), ("sweep_id", sweep), ("name", "kappa"))))
            else:
                config.write_text("")
            checks = "all" if args.all_checks else "not_a_server_error"
            har = Path(tmp) / "report.har"
            cmd = [exe, "--config-file", str(config), "run", f"{base}/openapi.json",
                   "--checks", checks, "--max-examples", str(args.max_examples),
                   "--seed", str(args.seed), "--request-timeout", "60", "--workers", "1",
                   "--report", "har", "--report-har-path", str(har)]
            print("$", " ".join(cmd), flush=True)
            t0 = time.perf_counter()
            rc = subprocess.run(cmd, cwd=tmp).returncode
            print(f"schemathesis exit status {rc} after {time.perf_counter() - t0:.0f} s")
            _tally(har, job, sweep)
            text = (Path(tmp) / "api.log").read_text(errors="replace")
            tracebacks = text.count("Traceback (most recent call last)")
            print(f"API log: {tracebacks} tracebacks; API healthy afterwards: "
                  f"{httpx.get(f'{base}/v1/health', timeout=10).status_code == 200}")
        finally:
            api.terminate()
            api.wait(timeout=60)
    return rc


if __name__ == "__main__":
    raise SystemExit(main())
