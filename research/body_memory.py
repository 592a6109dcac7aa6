"""The API's memory under oversized request bodies (issue 11, item 4).

Starts the API alone (`python -m service`, embedded mode without a local worker, a fresh data
directory), then sends CONCURRENT POST /v1/jobs requests with bodies of SIZE MB each, twice:
with a Content-Length header (refused from the header) and streamed in chunks without one
(refused once 4 MiB have been read). Prints the answers and the API process's resident memory
before and its peak after (VmRSS and VmHWM from /proc, Linux only), and the growth of the peak
against the bodies' total size. Before the bounded reader the audit saw 183 -> 767 MB for
eight concurrent 50 MB bodies.

    python -m research.body_memory [--concurrent 8] [--size 50]
"""
from __future__ import annotations

import argparse
import asyncio
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

REPO = Path(__file__).resolve().parents[1]
from benchmarks.load_service import free_port, wait_for


def memory_mb(pid: int) -> dict[str, float]:
    """VmRSS and VmHWM (peak resident set) of a process, MB."""
    out = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        key, _, value = line.partition(":")
        if key in ("VmRSS", "VmHWM"):
            out[key] = int(value.split()[0]) / 1024.0
    return out


async def flood(base: str, n: int, size: int, streamed: bool) -> list[int]:
    """n concurrent POSTs of ``size`` bytes each; the status codes (or -1 for a connection
    the server closed while the body was still being sent)."""
    chunk = b"x" * (1 << 20)

    async def body():
        for _ in range(size // len(chunk)):
            yield chunk
            await asyncio.sleep(0)

    async def one(client: httpx.AsyncClient) -> int:
        try:
            if streamed:
                response = await client.post("/v1/jobs", content=body(),
                                             headers={"content-type": "application/json"})
            else:
                response = await client.post("/v1/jobs", content=b"x" * size,
                                             headers={"content-type": "application/json"})
            return response.status_code
        except httpx.HTTPError:
            return -1

    async with httpx.AsyncClient(base_url=base, timeout=120) as client:
        return await asyncio.gather(*(one(client) for _ in range(n)))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--concurrent", type=int, default=8)
    ap.add_argument("--size", type=int, default=50, help="MB per body")
    args = ap.parse_args()
    port = free_port()
    with tempfile.TemporaryDirectory() as tmp:
        env = {k: v for k, v in os.environ.items() if not k.startswith("HOCKLE_")}
        env.update(HOCKLE_DATA_DIR=tmp, HOCKLE_PORT=str(port), HOCKLE_HOST="127.0.0.1",
                   HOCKLE_EMBEDDED_WORKER="false")
        api = subprocess.Popen([sys.executable, "-m", "service"], env=env, cwd=REPO,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        base = f"http://127.0.0.1:{port}"
        try:
            wait_for(lambda: httpx.get(f"{base}/v1/health", params={"live": "true"},
                                       timeout=2).status_code == 200, 60, "the API")
            httpx.get(f"{base}/v1/jobs", timeout=10)          # warm the routes
            before = memory_mb(api.pid)
            print(f"API alone: RSS {before['VmRSS']:.0f} MB, peak {before['VmHWM']:.0f} MB")
            size = args.size << 20
            for streamed in (False, True):
                t0 = time.perf_counter()
                codes = asyncio.run(flood(base, args.concurrent, size, streamed))
                mem = memory_mb(api.pid)
                how = "streamed, no Content-Length" if streamed else "with Content-Length"
                print(f"{args.concurrent} x {args.size} MB {how}: answers {sorted(codes)} in "
                      f"{time.perf_counter() - t0:.1f} s; RSS {mem['VmRSS']:.0f} MB, peak "
                      f"{mem['VmHWM']:.0f} MB (+{mem['VmHWM'] - before['VmHWM']:.0f} MB for "
                      f"{args.concurrent * args.size} MB sent)")
            alive = httpx.get(f"{base}/v1/health", timeout=10).status_code
            print(f"health afterwards: {alive}")
        finally:
            api.terminate()
            api.wait(timeout=30)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
