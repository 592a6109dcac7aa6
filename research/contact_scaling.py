"""How the contact phase's cost scales with the grid and with the number of contacts.

The seed example (`cases/goyal-writhing.yaml`) at N = 100-2000 segments: each run goes at
the case's Δt to its first contact, then on for ``--window`` seconds of contact. Printed
(and written to research/results/contact_scaling.json):

* per N: the time of first contact, the wall time per simulated second of the contact
  window, per nominal step and per Newton iteration, the mean number of active contacts,
  factorisations and Newton iterations per nominal step, GMRES iterations per Newton
  iteration; the exponent of the wall time per Newton iteration against N (1 = linear);
* per contact-count bin (all N together): the wall time per Newton iteration divided by
  N, which should not grow with the number of contacts faster than the O(N + P) work of
  the matrix-free product.

Run: ``python -m research.contact_scaling [--sizes 100 250 500 1000 2000] [--window 2]``.
"""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from solver import Case
from solver.simulation import RodRun

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "research" / "results"


def measure(n: int, window: float) -> dict:
    spec = Case.from_file(ROOT / "cases" / "goyal-writhing.yaml").model_dump(mode="json")
    spec["numerics"]["n_segments"] = n
    spec["numerics"].pop("ds", None)
    case = Case.model_validate(spec)
    dt = case.numerics.dt
    run = RodRun(case)
    k = 0
    t_pre = time.perf_counter()
    while run.contact_count == 0 and run.state.t < case.numerics.t_end - 1e-9:
        k += 1
        run.advance(k * dt)
    pre = time.perf_counter() - t_pre
    t_first = run.state.t
    steps = []
    f0, it0 = run.newton.factorizations, 0
    g0 = run.newton.gmres_iterations
    t0 = time.perf_counter()
    end = min(case.numerics.t_end, t_first + window)
    while run.state.t < end - 1e-9:
        k += 1
        w = time.perf_counter()
        its, _ = run.advance(k * dt)
        steps.append((time.perf_counter() - w, its, run.contact_count))
        it0 += its
    wall = time.perf_counter() - t0
    n_steps = max(len(steps), 1)
    sim = max(run.state.t - t_first, 1e-12)
    return {"n_segments": n, "first_contact_s": t_first, "pre_contact_wall_s": pre,
            "window_s": sim, "wall_per_simulated_s": wall / sim,
            "wall_per_step_s": wall / n_steps, "wall_per_iteration_s": wall / max(it0, 1),
            "iterations_per_step": it0 / n_steps,
            "factorizations_per_step": (run.newton.factorizations - f0) / n_steps,
            "gmres_per_iteration": (run.newton.gmres_iterations - g0) / max(it0, 1),
            "mean_contacts": float(np.mean([c for _, _, c in steps])) if steps else 0.0,
            "steps": steps}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 250, 500, 1000, 2000])
    ap.add_argument("--window", type=float, default=2.0)
    args = ap.parse_args()
    from threadpoolctl import threadpool_limits

    rows = []
    with threadpool_limits(limits=1, user_api="blas"):
        for n in args.sizes:
            r = measure(n, args.window)
            rows.append(r)
            print(f"N = {n:5d}: first contact {r['first_contact_s']:.1f} s, contact phase "
                  f"{r['wall_per_simulated_s']:.2f} s wall per simulated s, "
                  f"{r['wall_per_step_s'] * 1e3:.0f} ms/step, "
                  f"{r['wall_per_iteration_s'] * 1e3:.1f} ms/iteration, "
                  f"{r['iterations_per_step']:.1f} its and "
                  f"{r['factorizations_per_step']:.1f} factorisations per step, "
                  f"{r['gmres_per_iteration']:.1f} GMRES iterations per Newton iteration, "
                  f"{r['mean_contacts']:.0f} contacts", flush=True)
    ns = np.array([r["n_segments"] for r in rows], float)
    per_it = np.array([r["wall_per_iteration_s"] for r in rows])
    slope = float(np.polyfit(np.log(ns), np.log(per_it), 1)[0]) if len(rows) > 1 else math.nan
    print(f"wall time per Newton iteration ~ N^{slope:.2f}")
    # cost per iteration and node against the number of contacts (all runs pooled)
    pooled = [(w / max(i, 1) / r["n_segments"], c) for r in rows for (w, i, c) in r["steps"] if i]
    bins = [(0, 50), (50, 150), (150, 300), (300, 600), (600, 10**9)]
    by_pairs = []
    for lo, hi in bins:
        sel = [x for x, c in pooled if lo <= c < hi]
        if sel:
            by_pairs.append({"contacts": f"{lo}-{hi if hi < 10**9 else ''}",
                             "steps": len(sel), "us_per_iteration_per_node":
                             float(np.median(sel) * 1e6)})
            print(f"contacts {lo}-{hi if hi < 10**9 else '...'}: median "
                  f"{np.median(sel) * 1e6:.1f} µs per Newton iteration per node "
                  f"({len(sel)} steps)")
    RESULTS.mkdir(parents=True, exist_ok=True)
    out = {"rows": [{k: v for k, v in r.items() if k != "steps"} for r in rows],
           "exponent_per_iteration": slope, "by_contacts": by_pairs}
    (RESULTS / "contact_scaling.json").write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
