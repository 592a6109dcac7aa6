"""Speed of static solves and continuation (solver/statics.py, solver/continuation.py),
printed (issue 42's targets: one continuation point at 1000 segments costs at most a few
dynamic steps, <= 10 Newton iterations with the factorisation reused; a branch of 200
points at 200 segments in <= 30 s).

    PYTHONPATH=$PWD python3 -m research.continuation_speed [--repeats 3]

1. The cost of one pseudo-arclength point at 1000 segments on the twisted clamped-clamped
   rod (Greenhill's problem, past the start): the difference of continuations of 12 and
   2 points over 10 (so the start solve and the tracer's set-up cancel), the median of
   ``--repeats``, with the corrector's iterations per point and the factorisations per
   point (counted on solver.continuation._Scaled.bordered); against one fixed time
   step of a dynamic run of the same rod (hockle.api.simulate: the difference of runs of
   25 and 5 steps over 20, the median of ``--repeats``).
2. A branch of 200 points at 200 segments through Greenhill's branch point, with the
   unstable modes counted at every point: wall time.

The script uses the public functions only, so the same file measures another checkout
(``PYTHONPATH=/path/to/other``) for an interleaved comparison.
"""
from __future__ import annotations

import os
import time

import numpy as np

from solver import statics as st
from solver.continuation import continuation

L, B, C = 1.0, 1.0, 1.0 / 1.3
GREENHILL = 8.9868


def greenhill(n):
    def prob(theta):
        return st.uniform(L, n, (B, B, C), st.clamp([0, 0, 0], [1, 0, 0, 0]),
                          st.clamp([0, 0, L], st.quat_axis_angle([0, 0, 1], theta), theta,
                                   held=(True, True, False)))
    return prob


def one_point(n=1000, repeats=3):
    """Median seconds per continuation point at ``n`` segments, corrector iterations and
    factorisations per point (points 2-11 of a 12-point continuation)."""
    import solver.continuation as co

    prob = greenhill(n)
    tc = GREENHILL * B / C
    factorisations = []
    bordered = co._Scaled.bordered

    def counted(self, *args, **kw):
        factorisations.append(1)
        return bordered(self, *args, **kw)

    continuation(prob, 0.0, tc, max_points=2, stability=False, ds=0.05)     # warm
    per_point = []
    co._Scaled.bordered = counted
    try:
        for _ in range(repeats):
            times = []
            for points in (2, 12):
                factorisations.clear()
                t0 = time.perf_counter()
                br = continuation(prob, 0.0, tc, max_points=points, stability=False, ds=0.05)
                times.append(time.perf_counter() - t0)
                counts = len(factorisations)
                if points == 2:
                    base = counts
            per_point.append((times[1] - times[0]) / 10)
    finally:
        co._Scaled.bordered = bordered
    its = float(np.mean(br.iterations[2:]))
    return float(np.median(per_point)), its, (counts - base) / 10


def dynamic_step(n=1000, repeats=3):
    from hockle.api import simulate

    doc = {
        "schema_version": 1, "name": "twisted",
        "rod": {"length": 1.0, "youngs_modulus": 2.0e8, "shear_modulus": 8.0e7,
                "density": 1500.0, "diameter": 0.01},
        "initial": {"tangent": [0, 0, 1], "normal": [1, 0, 0]},
        "boundary": {
            "start": {"translation": [{"velocity": 0}] * 3,
                      "rotation": [{"angular_velocity": 0}, {"angular_velocity": 0},
                                   {"angular_velocity": 1.0}]},
            "end": {"translation": [{"velocity": 0}, {"velocity": 0}, {"force": 0}],
                    "rotation": [{"angular_velocity": 0}] * 3}},
        "numerics": {"n_segments": n, "dt": 0.01, "t_end": 0.05},
        "output": {"fields": ["position"]},
    }
    simulate(doc)                                    # warm: the kernels loaded
    per_step = []
    for _ in range(repeats):
        times = []
        for steps in (5, 25):
            doc["numerics"]["t_end"] = 0.01 * steps
            t0 = time.perf_counter()
            simulate(doc)
            times.append(time.perf_counter() - t0)
        per_step.append((times[1] - times[0]) / 20)
    return float(np.median(per_step))


def branch(n=200, points=200):
    prob = greenhill(n)
    tc = GREENHILL * B / C
    t0 = time.perf_counter()
    br = continuation(prob, 0.0, 1.5 * tc, max_points=points, ds=0.004, ds_max=0.004)
    return time.perf_counter() - t0, br


def main():
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--skip-branch", action="store_true", help="only the 1000-segment point")
    args = ap.parse_args()
    print(f"load: {os.getloadavg()[0]:.2f} (1-min), cores: {os.cpu_count()}")
    t_pt, its, fac = one_point(repeats=args.repeats)
    t_dyn = dynamic_step(repeats=args.repeats)
    print(f"1000 segments, one continuation point (points 2-11, median of {args.repeats}): "
          f"{t_pt * 1e3:.1f} ms, {its:.1f} corrector iterations and {fac:.1f} "
          f"factorisations per point")
    print(f"1000 segments, one dynamic step (median of run lengths): {t_dyn * 1e3:.2f} ms; "
          f"one continuation point / dynamic step: {t_pt / t_dyn:.1f}")
    if args.skip_branch:
        return
    t, br = branch()
    print(f"200 segments, a branch of {len(br.parameter)} points with unstable modes: "
          f"{t:.1f} s (target <= 30 s); bifurcations: "
          + ", ".join(f"{b.kind} at M L/B = {b.parameter * C / B:.4f}" for b in br.bifurcations))


if __name__ == "__main__":
    main()
