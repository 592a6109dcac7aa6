"""Speed of static solves and continuation (solver/statics.py, solver/continuation.py),
printed (issue 42's targets: one continuation point at 1000 segments costs at most a few
dynamic steps, <= 10 Newton iterations; a branch of 200 points at 200 segments in <= 30 s).

    PYTHONPATH=$PWD python3 benchmarks/continuation_speed.py

1. One pseudo-arclength point at 1000 segments on the twisted clamped-clamped rod
   (Greenhill's problem, past the start): Newton iterations and wall time of the step, with
   and without the unstable-mode count, against one fixed time step of a dynamic run of
   the same rod (hockle.api.simulate: the difference of runs of 25 and 5 steps over 20,
   the median of three).
2. A branch of 200 points at 200 segments through Greenhill's branch point, with the
   unstable modes counted at every point: wall time.
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


def one_point(n=1000):
    prob = greenhill(n)
    tc = GREENHILL * B / C
    out = {}
    for stability in (False, True):
        t0 = time.perf_counter()
        br = continuation(prob, 0.0, tc, max_points=2, stability=stability, ds=0.05)
        out[stability] = (time.perf_counter() - t0, br)
    # the start solve (straight guess, a linear problem) is part of the time: time it alone
    t0 = time.perf_counter()
    sol = st.solve(prob(0.0))
    t_start = time.perf_counter() - t0
    return out, t_start, sol.iterations


def dynamic_step(n=1000):
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
    per_step = []
    for _ in range(3):
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
    print(f"load: {os.getloadavg()[0]:.2f} (1-min), cores: {os.cpu_count()}")
    pts, t_start, its_start = one_point()
    for stability, (t, br) in pts.items():
        print(f"1000 segments, start solve + 1 continuation point"
              f"{' + unstable modes at both' if stability else ''}: {t:.2f} s, "
              f"Newton iterations of the point: {br.iterations[-1]}")
    print(f"  of which the start solve: {t_start:.2f} s ({its_start} iterations)")
    t_pt = pts[False][0] - t_start
    t_dyn = dynamic_step()
    print(f"1000 segments, one dynamic step (median of run lengths): {t_dyn * 1e3:.1f} ms; "
          f"one continuation point / dynamic step: {t_pt / t_dyn:.1f}")
    t, br = branch()
    print(f"200 segments, a branch of {len(br.parameter)} points with unstable modes: "
          f"{t:.1f} s (target <= 30 s); bifurcations: "
          + ", ".join(f"{b.kind} at M L/B = {b.parameter * C / B:.4f}" for b in br.bifurcations))


if __name__ == "__main__":
    main()
