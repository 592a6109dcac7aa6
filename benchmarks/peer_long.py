"""hockle and PyElastica on the shared physics of ``benchmarks/peer_compare.py`` over the
example's whole horizon (issue 43): untimed, the writhe histories to 100 s.

Run: ``nice -n 10 python -m benchmarks.peer_long`` (PyElastica from
``benchmarks/requirements-pyelastica.txt``). It prints a Markdown section, writes
``benchmarks/results/peer_long.json`` and ``docs/figures/benchmarks/peer_long_writhe.png``.
``--t-end``: another horizon; ``--render``: rebuild from the saved JSON.

The problem, damping (the same Morison drag in both codes, PyElastica's
LaplaceDissipationFilter of order 5) and contact laws (each code's own) are those of
``peer_compare.py``; only the end's schedule follows PyElastica's ``PlectonemesCase``
to its end: the rate ramps to Ω = 2π·10/50 rad/s over 0.5 s, holds, ramps down over
[50, 50.5] s (10 turns in all) and the end is held to 100 s. Lk is that prescribed turn
in both codes, so the comparison is Wr(t) (Tw = Lk − Wr). Reported: max |ΔWr| over the
run and over the held phase, the buckling and first-contact times (``pc.events``), and
the final Wr, for each code at two resolutions; a run that stops (divergence, non-finite
state) is compared up to where it stopped.
"""
from __future__ import annotations

import os

if __name__ == "__main__":
    for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                 "MKL_NUM_THREADS"):
        os.environ[_var] = "1"

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
from benchmarks import peer_compare as peer
from benchmarks import pyelastica_compare as pc
from benchmarks.peer_compare import LONG_T_TWIST as T_TWIST
from benchmarks.peer_compare import long_pairs as _pairs
from benchmarks.peer_compare import render_long as render
from benchmarks.peer_compare import trimmed

NAME = "peer_long"
T_END = 100.0                    # s: the example's final time
#: (code, N or n, Δt s or Δt/Δs s/m): each code at the coarser and the finer of two
#: settings of peer_compare's grid (PyElastica n = 40 and 80 at 0.011 s/m; hockle (50,
#: 0.0125 s) and (100, 0.00625 s)); the references (hockle N = 400, PyElastica n = 160)
#: would take about 2 and 10 min of a loaded core per 12 s, so not to 100 s
RUNS = [("hockle", 50, 0.0125), ("PyElastica", 40, 0.011),
        ("hockle", 100, 0.00625), ("PyElastica", 80, 0.011)]
RATE_T = [0.0, pc.T_RAMP, T_TWIST, T_TWIST + pc.T_RAMP]
RATE_V = [0.0, pc.OMEGA, pc.OMEGA, 0.0]


def end_rate(t: float) -> float:
    """The example's end rate ω3 (rad/s): ramp to Ω over T_RAMP, Ω, ramp down over
    [T_TWIST, T_TWIST + T_RAMP], then 0 (piecewise linear, as hockle's table)."""
    return float(np.interp(t, RATE_T, RATE_V))


def end_angle(t: float) -> float:
    """The integral of :func:`end_rate` (rad): Ω·T_TWIST = 10 turns once held."""
    om, r = pc.OMEGA, pc.T_RAMP
    if t < r:
        return 0.5 * om * t * t / r
    if t < T_TWIST:
        return om * (t - 0.5 * r)
    if t < T_TWIST + r:
        u = t - T_TWIST
        return om * (T_TWIST - 0.5 * r) + om * (u - 0.5 * u * u / r)
    return om * T_TWIST


def run_hockle(n: int, dt: float, t_end: float) -> dict:
    from solver import Case, SolverDivergence, integrate
    every = max(1, int(round(peer.OUT_DT / dt)))
    spec = pc._hockle_spec(n, dt, t_end, every,
                           end_rate_table={"t": RATE_T, "value": RATE_V},
                           fluid=True, forces=[{"value": [pc.IMPERFECTION, 0.0, 0.0]}],
                           contact=True, fields=["position"])
    status = "completed"
    t0 = time.perf_counter()
    try:
        ds = integrate(Case.model_validate(spec))
    except SolverDivergence as exc:
        ds, status = exc.partial, f"diverged at t = {exc.t:.3f} s ({exc.reason})"
    wall = time.perf_counter() - t0
    return {"t": ds.time.values, "pos": ds.position.values, "wall": wall, "status": status}


def run_pyelastica(n: int, ratio: float, t_end: float) -> dict:
    """peer_compare's lean harness with this module's end schedule; stops at the first
    non-finite output."""
    peer.end_rate, peer.end_angle = end_rate, end_angle     # read by its TwistedEnds
    dt = peer.pyelastica_step(n, ratio)
    sim, rod, stepper = peer.pyelastica_sim(n, dt, filter_order=peer.FILTER_ORDER)
    every = max(1, int(round(peer.OUT_DT / dt)))
    steps = int(round(t_end / dt))
    ts, pos = [0.0], [rod.position_collection.copy()]
    t, status = 0.0, "completed"
    t0 = time.perf_counter()
    for k in range(1, steps + 1):
        t = stepper.step(sim, t, dt)
        if k % every == 0:
            p = rod.position_collection.copy()
            if not np.isfinite(p).all():
                status = f"non-finite state at t = {t:.2f} s"
                break
            ts.append(t)
            pos.append(p)
    wall = time.perf_counter() - t0
    return {"t": np.array(ts), "pos": np.array(pos).transpose(0, 2, 1), "wall": wall,
            "status": status}


def analyse(run: dict) -> dict:
    run = dict(run, finite=True)
    out = peer.post(run)
    return {"t": run["t"], "Wr": out["Wr"], "t_buckle": out["t_buckle"],
            "t_contact": out["t_contact"], "wall": run["wall"], "status": run["status"]}


def collect(t_end: float, log=print, save=None, runs=None, previous=None) -> dict:
    """Run ``runs`` (default RUNS) one after the other; after each, ``save(res)`` (if
    given) with the pairs so far, so that a run stopped part-way leaves the finished runs'
    results. ``previous``: results of an earlier call (JSON) whose runs are kept."""
    from threadpoolctl import threadpool_limits
    import numba
    threadpool_limits(limits=1)
    numba.set_num_threads(1)
    res = {"t_end": t_end, "load_start": peer.loadavg(), "runs": {},
           "pyelastica_version": pc._pyelastica_version()}
    if previous:
        res["load_start"] = previous["load_start"]
        for k, d in previous["runs"].items():
            res["runs"][k] = dict(d, t=np.asarray(d["t"], float),
                                  Wr=np.asarray(d["Wr"], float))
    t_all = time.perf_counter() - (previous or {}).get("total_s", 0.0)
    for code, a, b in runs or RUNS:
        load = peer.loadavg()
        run = (run_hockle if code == "hockle" else run_pyelastica)(a, b, t_end)
        d = analyse(run)
        d.update(load_before=load, load_after=peer.loadavg())
        key = f"{code}:{a:g}:{b:g}"
        res["runs"][key] = d
        log(f"  {key}: {d['wall']:.1f} s wall, load {load[0]:.2f}, {d['status']}, "
            f"contact {d['t_contact']:.3f} s, final Wr {d['Wr'][-1]:.3f}")
        res.update(pairs=_pairs(res), load_end=peer.loadavg(),
                   total_s=time.perf_counter() - t_all,
                   utc=time.strftime("%Y-%m-%d %H:%M", time.gmtime()))
        if save:
            save(res)
    return res


def figure(res: dict, figdir: Path) -> str:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    name = "peer_long_writhe.png"
    fig, ax = plt.subplots(figsize=(9, 4.2))
    styles = {"hockle": ("C0", ["--", "-", ":"]), "PyElastica": ("C3", ["--", "-", ":"])}
    seen = {"hockle": 0, "PyElastica": 0}
    for key, d in res["runs"].items():
        d = trimmed(d)
        code = key.split(":")[0]
        c, ls = styles[code]
        ax.plot(d["t"], d["Wr"], color=c, ls=ls[min(seen[code], 2)], lw=1.1,
                label=key.replace(":", " ", 1).replace(":", ", ") + ("" if code == "hockle"
                                                                    else " s/m"))
        seen[code] += 1
    t_last = max(float(trimmed(d)["t"][-1]) for d in res["runs"].values())
    t = np.linspace(0.0, min(res["t_end"], t_last + 5.0), 2001)
    ax.plot(t, [end_angle(x) / (2 * math.pi) for x in t], color="0.5", lw=0.8,
            label="Lk (prescribed end turn)")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("turns")
    ax.set_title("Wr(t) toward the end of PyElastica's plectoneme example (same drag): "
                 "each run to where it stopped", fontsize=10)
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    Path(figdir).mkdir(parents=True, exist_ok=True)
    fig.savefig(Path(figdir) / name, dpi=110)
    plt.close(fig)
    return name


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--t-end", type=float, default=T_END)
    ap.add_argument("--render", action="store_true")
    ap.add_argument("--add", default=None, help="code:N:dt[,...]: run these and add them to "
                    "the saved results")
    ap.add_argument("--figdir", default=str(ROOT / "docs" / "figures" / "benchmarks"))
    args = ap.parse_args()
    path = HERE / "results" / f"{NAME}.json"
    if args.render:
        res = json.loads(path.read_text())
        figure(res, Path(args.figdir))
        print(render(res))
        return
    def save(raw):
        figure(raw, Path(args.figdir))
        path.write_text(json.dumps(peer.to_json(raw)))
    runs, previous = None, None
    if args.add:
        runs = [(c, int(a), float(b)) for c, a, b in
                (item.split(":") for item in args.add.split(","))]
        previous = json.loads(path.read_text())
    raw = collect(args.t_end, log=lambda m: print(m, file=sys.stderr, flush=True),
                  save=save, runs=runs, previous=previous)
    print(render(peer.to_json(raw)))


if __name__ == "__main__":
    main()
