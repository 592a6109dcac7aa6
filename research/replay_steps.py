"""Per-step replays of the seed example's contact phase: solver variants compared step by
step from the same states (issue 9).

A replay of a window of the seed example from one saved state diverges from the
original after a few steps (any change of rounding moves later Newton stalls), and on a
shared machine the wall time of the same computation moves by tens of percent, so
neither a window replay nor one run per version can judge a change of 10 %. Here the
baseline solver advances the seed example (`cases/goyal-writhing.yaml`, 1000 segments,
Δt = 0.1 s) through the chosen windows; before every nominal step inside a window its
state is copied, and each variant advances that copy by one nominal step. Every variant
thus starts every step from the same state, and its Newton iterations, GMRES iterations
and band factorisations per step are deterministic; the sums per window are printed with
the wall time (the variants run alternately, step by step, so their wall times share the
machine's moods; the counts are what to compare first).

A variant is a set of class attributes of :class:`solver.newton.NewtonSolver` (the solver's
tuning constants), e.g. ``CONTACT_BAND_WEIGHT=1.0`` (all node-local contact blocks in the
preconditioner, the earlier setting) or ``GAP_KEEP=0.1``, or of the contact candidate
search :class:`solver.contact.search.CandidateSearch` (``VERLET_SKIN``; :data:`OWNERS`).
Where a variant may change the solution (a looser stopping test), the largest distance of
its centreline at the end of each replayed step from the baseline's (m) is printed with
its window.

Run: ``python -m research.replay_steps [--case CASE.yaml] [--windows 18:21 26:29 34:36
41:44] [--variant NAME:ATTR=VALUE[,ATTR=VALUE...]] ...``; without ``--variant`` the
baseline and ``CONTACT_BAND_WEIGHT=1.0`` are compared; ``--case`` another case file than
the seed example's (e.g. cases/goyal-writhing-tension.yaml). Results:
research/results/replay_steps.json (another case: replay_steps_<case name>.json).
About 3 min per variant for the default windows, plus 1 min to reach 18 s.
"""
from __future__ import annotations

import argparse
import json
import pickle
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from solver import Case
from benchmarks.tuning import owner, parse_variant
from solver.simulation import RodRun

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "research" / "results" / "replay_steps.json"
SEED = ROOT / "cases" / "goyal-writhing.yaml"


def replay_step(snapshot: bytes, t_target: float, settings: dict) -> dict:
    """One nominal step to t_target (s) from a pickled RodRun with the class attributes
    ``settings`` (:func:`owner`) set for its duration; returns its counts, wall time and
    centreline at t_target (N+1, 3), m."""
    saved = {k: getattr(owner(k), k) for k in settings}
    try:
        for k, v in settings.items():
            setattr(owner(k), k, v)
        run = pickle.loads(snapshot)
        if "VERLET_SKIN" in settings and getattr(run, "search", None) is not None:
            # the snapshot's kept candidates and skin are those of the baseline's skin
            run.search.reset()
        g0, f0 = run.newton.gmres_iterations, run.newton.factorizations
        t0 = time.perf_counter()
        its, _ = run.advance(t_target)
        wall = time.perf_counter() - t0
        return {"newton": its, "gmres": run.newton.gmres_iterations - g0,
                "factorizations": run.newton.factorizations - f0, "wall": wall,
                "r": run.state.r.copy()}
    finally:
        for k, v in saved.items():
            setattr(owner(k), k, v)


def replay(windows: list[tuple[float, float]], variants: dict[str, dict],
           case_path: Path = SEED) -> dict:
    """Advance the case (default the seed example) with the baseline through the windows
    (s), replaying every nominal step inside them with each variant; returns the sums per
    window and variant, the per-step Newton iterations and the largest centreline
    distance from the baseline's replay at the end of a step (m)."""
    case = Case.from_file(case_path)
    dt = case.numerics.dt
    run = RodRun(case)
    out = {"windows": [list(w) for w in windows], "variants": variants, "results": {}}
    end = max(w[1] for w in windows)
    k = 0
    with threadpool_limits(limits=1, user_api="blas"):
        while run.state.t < end - 1e-9:
            t_target = round((k + 1) * dt, 10)
            window = next((w for w in windows if w[0] - 1e-9 <= run.state.t < w[1] - 1e-9), None)
            if window is not None:
                snapshot = pickle.dumps(run, protocol=pickle.HIGHEST_PROTOCOL)
                r_base = None
                for name, settings in variants.items():
                    res = replay_step(snapshot, t_target, settings)
                    if r_base is None:
                        r_base = res["r"]
                    key = f"{window[0]:g}-{window[1]:g}"
                    acc = out["results"].setdefault(name, {}).setdefault(
                        key, {"steps": 0, "newton": 0, "gmres": 0, "factorizations": 0,
                              "wall": 0.0, "per_step_newton": [], "max_dr": 0.0})
                    acc["steps"] += 1
                    for f in ("newton", "gmres", "factorizations", "wall"):
                        acc[f] += res[f]
                    acc["per_step_newton"].append(res["newton"])
                    acc["max_dr"] = max(acc["max_dr"],
                                        float(np.abs(res["r"] - r_base).max()))
            run.advance(t_target)
            k += 1
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", type=Path, default=SEED,
                    help="case file (default: the seed example's)")
    ap.add_argument("--windows", nargs="+", default=["18:21", "26:29", "34:36", "41:44"],
                    help="windows START:END in s of simulated time")
    ap.add_argument("--variant", action="append", default=[],
                    help="NAME:ATTR=VALUE[,ATTR=VALUE...] (class attributes of NewtonSolver "
                    "or, VERLET_SKIN, of CandidateSearch)")
    args = ap.parse_args()
    windows = []
    for w in args.windows:
        a, _, b = w.partition(":")
        windows.append((float(a), float(b)))
    variants = {"baseline": {}}
    for text in args.variant or ["weight-1:CONTACT_BAND_WEIGHT=1.0"]:
        name, settings = parse_variant(text)
        variants[name] = settings
    t0 = time.perf_counter()
    res = replay(sorted(windows), variants, args.case)
    res["wall_s"] = time.perf_counter() - t0
    res["case"] = str(args.case)
    name = Case.from_file(args.case).name
    path = (RESULTS if args.case.resolve() == SEED.resolve()
            else RESULTS.with_name(f"replay_steps_{name}.json"))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(res, indent=1))
    print(f"per-step replays of {name} ({res['wall_s']:.0f} s); Newton / GMRES iterations "
          "/ factorisations / wall s; largest centreline distance from the baseline (m)")
    for name, per in res["results"].items():
        total = {f: sum(v[f] for v in per.values())
                 for f in ("steps", "newton", "gmres", "factorizations", "wall")}
        cells = "  ".join(f"{key}: {v['newton']} / {v['gmres']} / {v['factorizations']} / "
                          f"{v['wall']:.1f}, {v['max_dr']:.1e} m" for key, v in per.items())
        print(f"{name:>12}  all {total['steps']} steps: {total['newton']} / {total['gmres']} / "
              f"{total['factorizations']} / {total['wall']:.1f}   {cells}")


if __name__ == "__main__":
    main()
