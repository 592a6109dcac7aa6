"""Rod-solver benchmarks (issue 2): cost per time step against the number of segments,
and the seed's material in water twisted at one end, 1000 segments, Δt = 0.1 s, run to
28 s without contact.

Run: ``python benchmarks/bench_solver.py [--repeats 3] [--quick]``. Prints the figures,
medians of the repeats, and the ratios; nothing is asserted (targets live here, not in
unit tests).
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from solver import Case, integrate

ROOT = Path(__file__).resolve().parents[1]
SEED = ROOT / "cases" / "goyal-writhing.yaml"


def seed_without_contact(n_segments: int, t_end: float, fields=("energies",)) -> Case:
    spec = Case.from_file(SEED).model_dump(mode="json")
    spec.pop("contact")
    spec["numerics"].pop("ds")
    spec["numerics"]["n_segments"] = n_segments
    spec["numerics"]["t_end"] = t_end
    spec["output"]["fields"] = list(fields)
    spec["output"]["every"] = 10
    return Case.model_validate(spec)


def time_run(case: Case, repeats: int):
    walls, its = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        ds = integrate(case)
        walls.append(time.perf_counter() - t0)
        its.append(int(ds.step_newton_iterations.sum()))
    n_steps = int(ds.sizes["step"])
    return statistics.median(walls), n_steps, statistics.median(its), ds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="smaller sizes, one repeat")
    args = ap.parse_args()
    repeats = 1 if args.quick else args.repeats

    time_run(seed_without_contact(50, 0.5), 1)   # warm-up: imports, caches
    print("== cost per step against the number of segments "
          "(seed material in water, t = 0..3 s of the twist ramp, Δt = 0.1 s)")
    sizes = [100, 250, 500, 1000] if args.quick else [100, 250, 500, 1000, 2000, 4000]
    rows = []
    for n in sizes:
        wall, steps, its, _ = time_run(seed_without_contact(n, 3.0), repeats)
        rows.append((n, wall / steps * 1e3, wall / its * 1e3))
        print(f"  N = {n:5d}: {wall / steps * 1e3:7.2f} ms/step  "
              f"{wall / its * 1e3:7.2f} ms/Newton iteration  ({its / steps:.1f} it/step)")
    ns = np.array([r[0] for r in rows], float)
    per_step = np.array([r[1] for r in rows])
    slope = np.polyfit(np.log(ns[1:]), np.log(per_step[1:]), 1)[0]
    print(f"  growth exponent of time per step in N (N >= {int(ns[1])}): {slope:.2f} "
          f"(1 = linear); ratio (ms/step per segment) largest/smallest N: "
          f"{(per_step[-1] / ns[-1]) / (per_step[1] / ns[1]):.2f}")

    print("== seed material in water, 1000 segments, Δt = 0.1 s, twisted at s = 0, "
          "no contact, to 28 s")
    wall, steps, its, ds = time_run(seed_without_contact(1000, 28.0), repeats)
    print(f"  wall time (median of {repeats}): {wall:.2f} s  ({steps} steps, {its} Newton "
          f"iterations, {ds.attrs['factorizations']} LU factorisations)")
    print(f"  bar 60 s: {'met' if wall <= 60 else 'MISSED'} ({wall / 60:.2f} of it); "
          f"goal 10 s: {'met' if wall <= 10 else 'missed'} ({wall / 10:.2f} of it)")


if __name__ == "__main__":
    main()
