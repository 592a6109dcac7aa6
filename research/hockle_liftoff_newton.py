"""Where the centreline scheme's Newton spends its work on the hockle case.

Runs ``cases/seabed-hockle.yaml`` (with its self-contact and friction) on
``numerics.formulation: centreline`` to ``--end`` (default 10 s) with BLAS on one thread
and prints, per second of simulated time, the step attempts, Newton iterations, refused
attempts, wall time and factorisations; then, for the steps between ``--trace T0 T1``
(default 1.2 1.45 s, the lift-off near the pushed end), each step's rounds of the sea
floor's contact-set re-decisions (``CentrelineRod._held_solve``): the nodes held at the
round's start and end and its Newton iterations, and the nodes touching at the solution.

Run from the repository's root: ``python -m research.hockle_liftoff_newton`` (about a
minute on 2 cores).
"""
from __future__ import annotations

import argparse
import collections
import os
import time
from pathlib import Path

from threadpoolctl import threadpool_limits

from solver import centreline as C
from solver.case import Case
from solver.centreline_run import CentrelineRun

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--end", type=float, default=10.0, help="s (default 10)")
    ap.add_argument("--trace", type=float, nargs=2, default=(1.2, 1.45), help="s s")
    args = ap.parse_args(argv)
    threadpool_limits(1)
    spec = Case.from_file(ROOT / "cases" / "seabed-hockle.yaml").model_dump(mode="json")
    spec["numerics"]["formulation"] = "centreline"
    case = Case.model_validate(spec)
    log, rounds = [], []
    step, newton = C.CentrelineRod.step, C.CentrelineRod.newton

    def traced_newton(rod, old, co, prob, Y, tolerance=None):
        held = None if rod.seabed_hold is None else int(rod.seabed_hold.sum())
        try:
            out = newton(rod, old, co, prob, Y, tolerance)
        except C.StepFailure:
            rounds.append(f"[held {held}: failed]")
            raise
        after = None if rod.seabed_hold is None else int(rod.seabed_hold.sum())
        to = "" if tolerance is None else f" to {tolerance:g}"
        rounds.append(f"[held {held}->{after}, {out[1]} its{to}]")
        return out

    def traced_step(rod, old, h, t=None):
        rounds.clear()
        w0, f0, ok, its = time.perf_counter(), rod.factorizations, False, 0
        try:
            out = step(rod, old, h, t)
            ok, its = True, out[1]
            return out
        finally:
            log.append((old.t, its, ok, time.perf_counter() - w0, rod.factorizations - f0))
            if args.trace[0] <= old.t <= args.trace[1]:
                print(f"  t = {old.t:.3f} s, h = {h:.4g} s, {'accepted' if ok else 'refused'}:"
                      f" {' '.join(rounds)}")

    C.CentrelineRod.step, C.CentrelineRod.newton = traced_step, traced_newton
    print(f"cases/seabed-hockle.yaml on the centreline scheme to {args.end:g} s "
          f"(load {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores); the steps from "
          f"{args.trace[0]:g} to {args.trace[1]:g} s, each round of the contact set:")
    run = CentrelineRun(case)
    t0, k = time.perf_counter(), 0
    try:
        while run.state.t < args.end - 1e-9:
            k += 1
            run.advance(k * case.numerics.dt)
    finally:
        C.CentrelineRod.step, C.CentrelineRod.newton = step, newton
    print(f"wall {time.perf_counter() - t0:.1f} s, factorisations {run.rod.factorizations}, "
          f"refused {run.control.refusals}")
    bins = collections.defaultdict(lambda: [0, 0, 0, 0.0, 0])
    for t, its, ok, wall, nf in log:
        b = bins[int(t)]
        b[0] += 1
        b[1] += its
        b[2] += not ok
        b[3] += wall
        b[4] += nf
    for second in sorted(bins):
        n, its, bad, wall, nf = bins[second]
        print(f"  {second}-{second + 1} s: attempts {n}, Newton iterations {its}, refused "
              f"{bad}, wall {wall:.1f} s, factorisations {nf}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
