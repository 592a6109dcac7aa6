"""How responsive the dashboard (/ui/) stays with 1,000 jobs and a 1000-segment result.

Starts the API in this process (uvicorn in a thread, SQLite registry, in-memory broker, one
API key), records ``--jobs`` jobs in its registry (mixed states) and one successful job whose
result is a 1000-segment run of ``cases/goyal-writhing.yaml`` (``--result``; by default
benchmarks/results/dashboard_seed.nc, made by running the case once when missing: ~2 min),
then drives headless Chromium (Selenium) through the pages and prints, as medians over
``--rounds`` rounds taken in turn (A B A B ...):

* jobs page: first render of a page of 50 after a fresh page load (ms from navigation
  start), each further page of 50 (click to render) through all the jobs, and the server's
  answer to the poll of a page (200 with the page, 304 when unchanged);
* job page of the 1000-segment result: plots drawn, first 3-D frame drawn (ms from
  navigation start), a new output time from the slider (input to frame drawn, including the
  60-ms debounce), the canvas's draw time;
* the 3-D view's slice: position at one time at the 200 points the page asks for against all
  1001 points (the whole file is the alternative a page without the slice API would have).

    python3 -m benchmarks.dashboard_load [--jobs 1000] [--rounds 5] [--screenshots docs/figures]

Needs selenium, chromium and chromedriver (apt-get install chromium chromium-driver).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import socket
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx

REPO = Path(__file__).resolve().parents[1]
KEY = "bench-key-0123456789abcdef"
DEFAULT_RESULT = REPO / "benchmarks" / "results" / "dashboard_seed.nc"
SEED_CASE = REPO / "cases" / "goyal-writhing.yaml"


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def make_result(path: Path) -> None:
    """Run the seed example (1000 segments, 45 s) and write its dataset to ``path``."""
    from hockle.io import write_netcdf
    from solver.case import Case
    from solver.simulation import integrate

    print(f"running {SEED_CASE.name} once for its 1000-segment result (a few minutes) ...",
          flush=True)
    t0 = time.perf_counter()
    ds = integrate(Case.from_file(SEED_CASE))
    path.parent.mkdir(parents=True, exist_ok=True)
    write_netcdf(ds, path)
    print(f"  {time.perf_counter() - t0:.0f} s -> {path}", flush=True)


def populate(registry, n_jobs: int, result: Path, owner: str) -> str:
    """``n_jobs`` tiny jobs in mixed states, then the job holding ``result``; its id."""
    import hashlib

    import xarray as xr

    from benchmarks.load_service import TINY

    limits = (3600.0, 3500.0, 3400.0)
    for i in range(n_jobs):
        spec = json.dumps({**TINY, "name": f"job {i:04d}"})
        job, _ = registry.create_job(
            spec_json=spec, spec_hash=hashlib.sha256(spec.encode()).hexdigest(),
            solver_version="bench", name=f"job {i:04d}", grid_points=9, n_steps=5, t_end=0.05,
            limits=limits, owner=owner)
        kind = i % 10
        if kind < 8:                                   # 70 % successful, 10 % failed, 10 % running
            attempt = registry.claim(job.id, "bench@host")
            if kind < 7:
                registry.finish(job.id, attempt, state="successful", progress=100.0,
                                sim_time=0.05, step=5, wall_time=0.2)
            elif kind == 7:
                registry.finish(job.id, attempt, state="failed", reason="solver_diverged",
                                message="Newton did not converge", progress=40.0)
        elif kind == 8:
            attempt = registry.claim(job.id, "bench@host")
        # kind 9: accepted
    with xr.open_dataset(result, engine="netcdf4") as ds:
        case = json.loads(ds.attrs["case"])
        grid = int(ds.sizes["s"])
        t_end = float(ds["time"].values[-1])
        steps = int(ds.sizes.get("step", 0))
    spec = json.dumps(case)
    job, _ = registry.create_job(
        spec_json=spec, spec_hash=hashlib.sha256(spec.encode()).hexdigest(),
        solver_version="bench", name=case.get("name", "seed"), grid_points=grid,
        n_steps=steps, t_end=t_end, limits=limits,
        owner=owner)
    attempt = registry.claim(job.id, "bench@host")
    registry.finish(job.id, attempt, state="successful", result_path=str(result),
                    progress=100.0, sim_time=t_end, step=steps, wall_time=None)
    return job.id


def start_api(data_dir: Path):
    import uvicorn

    from service.app import create_app
    from service.settings import Settings

    settings = Settings(data_dir=data_dir, broker_url="memory://", api_keys=KEY,
                        rate_limit=0, heartbeat_interval=1800, job_heartbeat_timeout=7200)
    app = create_app(settings)
    port = _free_port()
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    url = f"http://127.0.0.1:{port}"
    for _ in range(600):
        try:
            if httpx.get(f"{url}/v1/health?live=true", timeout=2).status_code == 200:
                break
        except httpx.TransportError:
            time.sleep(0.1)
    return server, thread, url, app.state.services.registry


def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    binary = next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome")
                   if shutil.which(n)), None)
    driver_path = shutil.which("chromedriver")
    if binary is None or driver_path is None:
        sys.exit("needs chromium and chromedriver on PATH (apt-get install chromium chromium-driver)")
    options = Options()
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu",
                "--window-size=1400,1500", "--force-device-scale-factor=1"):
        options.add_argument(arg)
    options.binary_location = binary
    driver = webdriver.Chrome(options=options, service=Service(driver_path))
    driver.set_script_timeout(120)
    return driver


def wait(driver, script: str, timeout: float = 120.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = driver.execute_script(script)
        if value:
            return value
        time.sleep(0.02)
    raise TimeoutError(script)


def mark(driver, name: str) -> float:
    """ms from navigation start to the first performance mark ``name``."""
    return float(wait(driver, f"var m = performance.getEntriesByName('{name}');"
                              "return m.length ? m[0].startTime : null;"))


def load(driver, url: str, fragment: str) -> None:
    """A fresh page load of /ui/#fragment (the key stays in sessionStorage)."""
    driver.get(f"{url}/ui/#{fragment}")
    driver.refresh()


def jobs_round(driver, url: str, pages: int) -> tuple[float, list[float]]:
    load(driver, url, "/jobs")
    first = mark(driver, "hockle:jobs-rendered")
    per_page = []
    for _ in range(pages - 1):
        ms = driver.execute_async_script("""
            var done = arguments[arguments.length - 1], t0 = performance.now();
            var n = performance.getEntriesByName('hockle:jobs-rendered').length;
            var next = Array.from(document.querySelectorAll('button')).find(b => b.textContent.indexOf('Older') === 0);
            if (!next || next.disabled) { done(null); return; }
            next.click();
            (function check() {
              if (performance.getEntriesByName('hockle:jobs-rendered').length > n) done(performance.now() - t0);
              else setTimeout(check, 2);
            })();""")
        if ms is None:
            break
        per_page.append(ms)
    return first, per_page


def job_round(driver, url: str, job_id: str, n_times: int, rng) -> dict:
    load(driver, url, f"/job/{job_id}")
    out = {"plots": mark(driver, "hockle:plots-drawn"),
           "view3d": mark(driver, "hockle:view3d-drawn")}
    out["slice_ms"] = float(driver.execute_script(
        "return document.getElementById('rod3d').dataset.loadMs"))
    slider = []
    for _ in range(5):
        index = int(rng.integers(0, n_times - 1))
        ms = driver.execute_async_script("""
            var i = arguments[0], done = arguments[arguments.length - 1], t0 = performance.now();
            var s = document.getElementById('time-slider'), c = document.getElementById('rod3d');
            s.value = i; s.dispatchEvent(new Event('input'));
            (function check() {
              if (c.dataset.frame === String(i)) done(performance.now() - t0); else setTimeout(check, 2);
            })();""", index)
        slider.append(ms)
    out["slider"] = statistics.median(slider)
    # one frame drawn from the 200 points shown and from all the grid points, in turn
    out["draw_200"], out["draw_all"] = driver.execute_async_script("""
        var done = arguments[arguments.length - 1], id = arguments[0];
        var headers = {Authorization: 'Bearer ' + sessionStorage.getItem('hockle.apiKey')};
        fetch('../v1/jobs/' + id + '/results/variables/position?time=45', {headers: headers})
          .then(function (r) { return r.json(); }).then(function (d) {
            var all = d.data, n = all.length, few = [];
            for (var i = 0; i < 200; i++) few.push(all[Math.round(i * (n - 1) / 199)]);
            var c = document.createElement('canvas');
            c.style.width = '1100px'; c.style.height = '460px';
            document.body.appendChild(c);
            var view = new window.HockleView3D.RodView(c), times = {few: [], all: []};
            for (var k = 0; k < 5; k++) {
              [['few', few], ['all', all]].forEach(function (p) {
                view.setShape(p[1], p[1].map(function () { return 0.01; }), [], true);
                times[p[0]].push(view.lastDrawMs);
              });
            }
            c.remove();
            function med(a) { a.sort(function (x, y) { return x - y; }); return a[2]; }
            done([med(times.few), med(times.all)]);
          });""", job_id)
    out["draw"] = float(driver.execute_script("return document.getElementById('rod3d').dataset.drawMs"))
    return out


def timed_get(client, path: str, headers=None) -> tuple[float, int, int]:
    t0 = time.perf_counter()
    response = client.get(path, headers=headers)
    return (time.perf_counter() - t0) * 1000, response.status_code, len(response.content)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=1000)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--result", type=Path, default=DEFAULT_RESULT,
                        help="a 1000-segment result (made from cases/goyal-writhing.yaml if missing)")
    parser.add_argument("--screenshots", type=Path, default=None,
                        help="save dashboard-jobs-1000.png and dashboard-job-seed.png here")
    args = parser.parse_args(argv)
    import numpy as np
    import xarray as xr

    from service.auth import owner_id

    if not args.result.exists():
        make_result(args.result)
    with xr.open_dataset(args.result, engine="netcdf4") as ds:
        n_times, n_s = int(ds.sizes["time"]), int(ds.sizes["s"])
        s_values = ds["s"].values
    data_dir = Path(tempfile.mkdtemp(prefix="hockle-dash-"))
    server, thread, url, registry = start_api(data_dir)
    driver = None
    try:
        t0 = time.perf_counter()
        seed_id = populate(registry, args.jobs, args.result.resolve(), owner_id(KEY))
        print(f"recorded {args.jobs} jobs and the {n_s - 1}-segment result ({n_times} outputs) "
              f"in {time.perf_counter() - t0:.1f} s")
        driver = browser()
        driver.get(f"{url}/ui/")
        driver.execute_script(f"sessionStorage.setItem('hockle.apiKey', '{KEY}')")
        client = httpx.Client(base_url=url, headers={"Authorization": f"Bearer {KEY}"},
                              timeout=120)
        rng = np.random.default_rng(1)
        pages = -(-(args.jobs + 1) // 50)
        first, per_page, job = [], [], []
        page200, page304, dec, full, dec_bytes, full_bytes = [], [], [], [], 0, 0
        idx = sorted(set(np.round(np.linspace(0, n_s - 1, min(n_s, 200))).astype(int)))
        s_list = ",".join(repr(float(s_values[i])) for i in idx)
        etag = client.get("/v1/ui/jobs?page_size=50").headers["etag"]
        for r in range(args.rounds):
            f, p = jobs_round(driver, url, pages)
            first.append(f)
            per_page.extend(p)
            job.append(job_round(driver, url, seed_id, n_times, rng))
            for _ in range(5):   # server: page of 50 (200) and unchanged (304), in turn
                ms, code, _ = timed_get(client, "/v1/ui/jobs?page_size=50")
                page200.append(ms)
                ms, code, _ = timed_get(client, "/v1/ui/jobs?page_size=50",
                                        {"If-None-Match": etag})
                assert code == 304, code
                page304.append(ms)
            for _ in range(3):   # the 3-D slice: 200 points against all of them, in turn
                t = float(rng.uniform(0, 45))
                ms, code, size = timed_get(
                    client, f"/v1/jobs/{seed_id}/results/variables/position?time={t}&s={s_list}")
                assert code == 200
                dec.append(ms)
                dec_bytes = size
                ms, code, size = timed_get(
                    client, f"/v1/jobs/{seed_id}/results/variables/position?time={t}")
                assert code == 200
                full.append(ms)
                full_bytes = size
            print(f"  round {r + 1}/{args.rounds} done", flush=True)
        med = statistics.median
        load_avg = os.getloadavg()
        print(f"\nload average {load_avg[0]:.2f} {load_avg[1]:.2f} {load_avg[2]:.2f} "
              f"(uptime); {os.cpu_count()} CPUs; medians of {args.rounds} rounds")
        print(f"jobs page ({args.jobs + 1} jobs, 50 per page, {pages} pages):")
        print(f"  first page rendered after a fresh load     {med(first):8.0f} ms from navigation start")
        print(f"  next page (click to rendered)             {med(per_page):8.0f} ms "
              f"(max {max(per_page):.0f} ms over {len(per_page)} page turns)")
        print(f"  poll of a page: 200 with the page          {med(page200):8.1f} ms")
        print(f"  poll of a page: 304 not modified           {med(page304):8.1f} ms "
              f"(ratio 200/304 {med(page200) / med(page304):.2f})")
        print(f"job page ({n_s - 1}-segment result, {n_times} output times, "
              f"{args.result.stat().st_size / 1e6:.1f} MB file):")
        print(f"  plots drawn                                {med([j['plots'] for j in job]):8.0f} ms from navigation start")
        print(f"  first 3-D frame drawn                      {med([j['view3d'] for j in job]):8.0f} ms from navigation start")
        print(f"  3-D slice fetch, in the page               {med([j['slice_ms'] for j in job]):8.0f} ms")
        print(f"  3-D frame draw (canvas)                    {med([j['draw'] for j in job]):8.1f} ms")
        print(f"  3-D frame draw, 200 / all {n_s} points      {med([j['draw_200'] for j in job]):8.1f} / "
              f"{med([j['draw_all'] for j in job]):.1f} ms (ratio "
              f"{med([j['draw_all'] / j['draw_200'] for j in job]):.2f}; each drag of the view redraws)")
        print(f"  new output time from the slider            {med([j['slider'] for j in job]):8.0f} ms "
              f"(input to frame drawn, 60-ms debounce included)")
        print(f"3-D slice from the API: {len(idx)} of {n_s} points {med(dec):.0f} ms "
              f"({dec_bytes / 1e3:.0f} kB), all {n_s} points {med(full):.0f} ms "
              f"({full_bytes / 1e3:.0f} kB); ratio all/decimated {med(full) / med(dec):.2f} "
              f"in time, {full_bytes / dec_bytes:.1f} in bytes; the whole file "
              f"{args.result.stat().st_size / 1e6:.1f} MB")
        if args.screenshots:
            args.screenshots.mkdir(parents=True, exist_ok=True)
            load(driver, url, "/jobs")
            mark(driver, "hockle:jobs-rendered")
            driver.set_window_size(1400, 1000)
            driver.save_screenshot(str(args.screenshots / "dashboard-jobs-1000.png"))
            driver.set_window_size(1400, 2600)
            load(driver, url, f"/job/{seed_id}")
            mark(driver, "hockle:plots-drawn")
            mark(driver, "hockle:view3d-drawn")
            time.sleep(0.5)
            driver.save_screenshot(str(args.screenshots / "dashboard-job-seed.png"))
            print(f"screenshots in {args.screenshots}")
        return 0
    finally:
        if driver is not None:
            driver.quit()
        server.should_exit = True
        thread.join(timeout=10)
        registry.dispose()
        shutil.rmtree(data_dir, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
