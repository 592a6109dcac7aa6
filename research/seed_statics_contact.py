"""The seed rod's static branch through buckling to its first self-contact.

    PYTHONPATH=$PWD python3 -m research.seed_statics_contact [--segments 200]

cases/goyal-writhing.yaml at the phase of the seed's first contact (t < 30 s: the end
slides freely along the axis under zero force, both ends held in rotation), its minute
e1 force raised from 1e-5 to 1e-3 N/m (``--imperfection``) as the imperfection that lets
the branch leave the straight rod at the Greenhill pair of helical modes (with 1e-5 N/m
the continuation steps over the pair and stays on the straight branch), its self-contact (the seed law, without damping in statics) on;
the parameter is the start's total rotation about the axis (rad; Lk = −rotation/2π).
Prints per point the rotation, Lk, end slide, Tw, Wr, the smallest segment-to-segment
gap and the number of nodes carrying a contact load, then the first point with a
contact load (a pair inside the law's cut-off, the dynamic run's "contact count > 0")
and its Lk beside the dynamic run's Lk at its first contact (18.1 s of the seed's twist
schedule, docs/seed-example.md), and the branch in contact at that Lk (Wr, end slide).

    PYTHONPATH=$PWD python3 -m research.seed_statics_contact --to -30 --points 2000 --ds-max 0.01
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from solver import statics as st
from solver.continuation import continuation
from solver.topology import twist, writhe


def schedule_angle(t_end: float, doc) -> float:
    """The seed's start rotation (rad) at t_end from its angular-velocity table."""
    table = doc["boundary"]["start"]["rotation"][2]["angular_velocity"]
    tt = np.linspace(0.0, t_end, 200001)
    w = np.interp(tt, table["t"], table["value"])
    return float(np.sum(0.5 * (w[1:] + w[:-1]) * np.diff(tt)))


def main():
    from solver.case import parse_text
    from hockle.api import continuation_family

    ap = argparse.ArgumentParser()
    ap.add_argument("--segments", type=int, default=200)
    ap.add_argument("--to", type=float, default=-20.0)
    ap.add_argument("--points", type=int, default=600)
    ap.add_argument("--start", type=float, default=-10.0,
                    help="the start rotation, rad (below Greenhill's, straight)")
    ap.add_argument("--ds-max", type=float, default=0.005)
    ap.add_argument("--imperfection", type=float, default=1e-3,
                    help="the e1 force per length, N/m (the case's is 1e-5)")
    a = ap.parse_args()
    root = Path(__file__).resolve().parents[1]
    doc = parse_text((root / "cases" / "goyal-writhing.yaml").read_text(), "yaml")
    angle_dyn = schedule_angle(18.1, doc)
    doc["numerics"]["n_segments"] = a.segments
    doc["distributed_forces"][0]["value"] = [a.imperfection, 0.0, 0.0]
    doc["boundary"]["start"]["rotation"][2] = {"angular_velocity": 0.0}
    # at time 1 s a constant angular velocity (rad/s) is the rotation angle (rad)
    problem_at, lam0, to = continuation_family(doc, "boundary.start.rotation.2.angular_velocity",
                                               a.to, time=1.0)
    t0 = time.perf_counter()
    br = continuation(problem_at, a.start, to, ds=0.01, ds_max=a.ds_max, max_points=a.points,
                      stability=False, locate=False, tol=1e-7)
    wall = time.perf_counter() - t0
    print(f"{len(br.parameter)} points in {wall:.0f} s ({br.stopped}), N = {a.segments}")
    s = br.problems[0].s
    first = None
    print(" rotation    Lk    slide(m)    Tw      Wr    min gap (mm)  loaded nodes")
    rows = []
    for i, (lam, Y, prob) in enumerate(zip(br.parameter, br.Y, br.problems)):
        f = st.fields(Y, prob)
        loaded = int(np.sum(np.any(st.contact_loads(Y, prob) != 0, axis=1)))
        gap = st.contact_gap(Y, prob)
        row = (lam, -lam / (2 * np.pi), 1.0 - Y[-1, 2], twist(f["kappa"][:, 2], s),
               writhe(Y[:, 0:3]), 1e3 * gap, loaded)
        rows.append(row)
        if loaded and first is None:
            first = row
    for r in rows[:: max(1, len(rows) // 50)] + rows[-1:]:
        print(f"{r[0]:8.4f} {r[1]:7.4f} {r[2]:9.4f} {r[3]:7.3f} {r[4]:7.3f} {r[5]:10.3f} {r[6]:6d}")
    before = rows[:rows.index(first)] if first is not None else rows
    k_fold = int(np.argmax([r[1] for r in before]))
    print(f"the branch leaves the straight rod at its largest Lk before contact: "
          f"{rows[k_fold][1]:.4f} turns (point {k_fold}, rotation {rows[k_fold][0]:.4f} rad)")
    print(f"dynamic run: first contact at 18.1 s, Lk = {-angle_dyn / (2 * np.pi):.4f} turns")
    if first is None:
        print("static branch: no contact load on the branch followed")
    else:
        print(f"static branch: first contact load at rotation {first[0]:.4f} rad, "
              f"Lk = {first[1]:.4f} turns (Tw {first[3]:.3f}, Wr {first[4]:.3f}, slide "
              f"{first[2]:.4f} m, gap {first[5]:.2f} mm)")
    print(f"smallest gap along the branch: {min(r[5] for r in rows):.3f} mm")
    if first is not None:
        lk_dyn = -angle_dyn / (2 * np.pi)
        arr = np.array(rows)
        k0 = rows.index(first)
        lk = arr[k0:, 1]
        hit = np.flatnonzero((lk[:-1] - lk_dyn) * (lk[1:] - lk_dyn) <= 0)
        if hit.size:
            i = k0 + hit[0]
            w = (lk_dyn - arr[i, 1]) / (arr[i + 1, 1] - arr[i, 1])
            at = (1 - w) * arr[i] + w * arr[i + 1]
            print(f"in contact at the dynamic run's Lk = {lk_dyn:.4f} (first crossing after "
                  f"first contact, point {i}): Wr = {at[4]:.3f}, Tw = {at[3]:.3f}, slide "
                  f"{at[2]:.4f} m, gap {at[5]:.3f} mm, {int(arr[i, 6])} loaded nodes; "
                  f"{hit.size} crossings of that Lk in contact")


if __name__ == "__main__":
    main()
