"""A bounded schemathesis run over every operation of the REST API (issue 11): no input may
give a server error.

Starts the API alone (`python -m service`, embedded mode without a local worker, a fresh data
directory: jobs are accepted and wait in the queue), runs ``schemathesis run`` against its
OpenAPI document with the ``not_a_server_error`` check (plus the response-schema checks when
``--all-checks``), at most ``--max-examples`` inputs per operation and a fixed seed, and prints
schemathesis's summary and its exit status (0: no failure). schemathesis is a benchmark-only
dependency: ``python -m pip install -r benchmarks/requirements-fuzz.txt``.

    python benchmarks/fuzz_api.py [--max-examples 50] [--seed 1] [--all-checks]
"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

from load_service import free_port, wait_for  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-examples", type=int, default=50)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--all-checks", action="store_true",
                    help="also the response-schema and status-code conformance checks")
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
                   HOCKLE_EMBEDDED_WORKER="false", HOCKLE_RATE_LIMIT="100000",
                   HOCKLE_RATE_LIMIT_BURST="100000")
        log = open(Path(tmp) / "api.log", "w")
        api = subprocess.Popen([sys.executable, "-m", "service"], env=env, cwd=REPO,
                               stdout=log, stderr=subprocess.STDOUT)
        base = f"http://127.0.0.1:{port}"
        try:
            wait_for(lambda: httpx.get(f"{base}/v1/health", params={"live": "true"},
                                       timeout=2).status_code == 200, 60, "the API")
            checks = "all" if args.all_checks else "not_a_server_error"
            cmd = [exe, "run", f"{base}/openapi.json", "--checks", checks,
                   "--max-examples", str(args.max_examples), "--seed", str(args.seed),
                   "--request-timeout", "60", "--workers", "1"]
            print("$", " ".join(cmd), flush=True)
            t0 = time.perf_counter()
            rc = subprocess.run(cmd, cwd=tmp).returncode
            print(f"schemathesis exit status {rc} after {time.perf_counter() - t0:.0f} s")
            text = (Path(tmp) / "api.log").read_text(errors="replace")
            tracebacks = text.count("Traceback (most recent call last)")
            print(f"API log: {tracebacks} tracebacks; API alive afterwards: "
                  f"{httpx.get(f'{base}/v1/health', timeout=10).status_code == 200}")
        finally:
            api.terminate()
            api.wait(timeout=30)
    return rc


if __name__ == "__main__":
    raise SystemExit(main())
