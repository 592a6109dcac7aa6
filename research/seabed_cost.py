"""What the sea floor costs per time step (issue 38): a 1000-segment cable lying on the
bottom, without a seabed, on a flat seabed (with friction) and on a bathymetry grid of the
same flat bottom (201 x 201 points, so only the grid's lookup differs).

The cable (10 m, D = 0.02 m, in water under gravity) is clamped at s = 0 and held at
s = L except along its axis; Δt = 0.01 s. Without a seabed it sags between its ends;
with one it settles onto the bottom (it starts touching it, and sinks by w/k in the first
steps) and then rests. Timed apart: the first 0.2 s (the touchdown) and the 50 steps
after it (steady). Each variant is run ``--repeats`` times, interleaved (none, flat,
grid, none, ...), after a warm-up; the medians of the wall time per step and their
ratios to the run without a seabed are printed with ``uptime``. Targets (steady):
flat ≤ 1.5×, grid ≤ 2×.

Run: ``PYTHONPATH=$PWD python -m research.seabed_cost [--repeats 5]``.

``--cases`` times instead the two documented runs side by side, alternately (seed,
hockle, seed, ...; ``--repeats`` of each, after a warm-up): ``cases/seabed-hockle.yaml``
(the twisted cable that loops on the sea floor, docs/hockle.md) and the seed example
``cases/goyal-writhing.yaml``, their wall times, Newton iterations, simulated seconds and
wall time per simulated second.
"""
from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from solver import Case, integrate

D = 0.02
CLAMPED = {"translation": [{"velocity": 0}] * 3, "rotation": [{"angular_velocity": 0}] * 3}
SLIDING = {"translation": [{"velocity": 0}, {"velocity": 0}, {"force": 0}],
           "rotation": [{"angular_velocity": 0}] * 3}


def spec(seabed, n_segments=1000, t_end=1.0):
    out = {"schema_version": 1, "name": "seabed cost",
           "rod": {"length": 10.0, "youngs_modulus": 1.25e7, "shear_modulus": 5e6,
                   "density": 1500.0, "diameter": D},
           "fluid": {"density": 1000.0}, "gravity": [0.0, 0.0, -9.81],
           "initial": {"tangent": [1, 0, 0], "normal": [0, 0, 1]},
           "boundary": {"start": CLAMPED, "end": SLIDING},
           "numerics": {"n_segments": n_segments, "dt": 0.01, "t_end": t_end},
           "output": {"fields": ["kappa"], "every": 10}}
    if seabed is not None:
        out["seabed"] = seabed
    return out


def variants():
    friction = {"axial": 0.3, "lateral": 0.6}
    xs = np.linspace(-1.0, 11.0, 201).tolist()
    ys = np.linspace(-1.0, 1.0, 201).tolist()
    grid = {"x": xs, "y": ys, "z": [[-D / 2] * len(ys) for _ in xs]}
    return [("no seabed", spec(None)),
            ("flat seabed with friction", spec({"elevation": -D / 2, "friction": friction})),
            ("bathymetry grid 201 x 201 with friction",
             spec({"bathymetry": grid, "friction": friction}))]


def per_step(case, settle=0.2, steps=50):
    """(wall s per step over the first ``settle`` s, which holds the cable's touchdown on
    the bottom, and per step over the next ``steps`` steps), by fixed steps of the
    case's Δt (:class:`solver.run.RodRun`)."""
    from solver.run import RodRun

    dt = case.numerics.dt
    n0 = int(round(settle / dt))
    run = RodRun(case)
    t0 = time.perf_counter()
    for k in range(1, n0 + 1):
        run.advance(k * dt)
    t1 = time.perf_counter()
    for k in range(n0 + 1, n0 + steps + 1):
        run.advance(k * dt)
    t2 = time.perf_counter()
    return (t1 - t0) / n0, (t2 - t1) / steps


CASES = (("seed example", "cases/goyal-writhing.yaml"),
         ("seabed hockle", "cases/seabed-hockle.yaml"))


def cases_side_by_side(repeats: int):
    """Wall time of the two documented runs, alternately; prints medians and spreads."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    loaded = [(label, Case.from_file(root / path)) for label, path in CASES]
    for _, case in loaded:               # warm-up: kernels loaded, a few steps
        short = case.model_copy(deep=True)
        short.numerics.t_end = 5 * short.numerics.dt
        integrate(short)
    walls = {label: [] for label, _ in loaded}
    info = {}
    for _ in range(repeats):
        for label, case in loaded:
            t0 = time.perf_counter()
            ds = integrate(case)
            walls[label].append(time.perf_counter() - t0)
            info[label] = (ds.attrs.get("hockle_status", "?"), float(ds["time"].values[-1]),
                           int(ds["step_newton_iterations"].sum())
                           if "step_newton_iterations" in ds else -1)
    print(f"uptime: {os.popen('uptime').read().strip()}")
    print(f"{'case':16s} {'status':10s} {'to t (s)':>9s} {'Newton its':>10s} "
          f"{'wall median (s)':>16s} {'wall/sim s':>10s}  runs (s)")
    for label, _ in loaded:
        med = statistics.median(walls[label])
        status, t_end, its = info[label]
        runs = " ".join(f"{t:.1f}" for t in walls[label])
        print(f"{label:16s} {status:10s} {t_end:9.2f} {its:10d} {med:16.1f} "
              f"{med / t_end:10.2f}  {runs}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--cases", action="store_true",
                    help="the seabed-hockle case beside the seed example (wall times)")
    args = ap.parse_args()
    if args.cases:
        cases_side_by_side(args.repeats)
        return
    rows = [(label, Case.model_validate(s)) for label, s in variants()]
    for _, case in rows:                 # warm-up: the kernels compiled and cached
        per_step(case, settle=0.02, steps=1)
    times = {label: ([], []) for label, _ in rows}
    for _ in range(args.repeats):
        for label, case in rows:
            first, steady = per_step(case)
            times[label][0].append(first)
            times[label][1].append(steady)
    print(f"uptime: {os.popen('uptime').read().strip()}")
    for part, name in ((1, "steady: 50 steps after the first 0.2 s"),
                       (0, "touchdown: the first 0.2 s (20 steps)")):
        base = statistics.median(times[rows[0][0]][part])
        print(f"\n{name}")
        print(f"{'variant':42s} {'ms/step (median)':>17s} {'ratio':>7s}  runs (ms/step)")
        for label, _ in rows:
            med = statistics.median(times[label][part])
            runs = " ".join(f"{1e3 * t:.1f}" for t in times[label][part])
            print(f"{label:42s} {1e3 * med:17.2f} {med / base:7.2f}  {runs}")


if __name__ == "__main__":
    main()
