"""The static solver and continuation against analytic results, printed, with the
bifurcation diagrams of docs/statics.md written to docs/figures/:

    PYTHONPATH=$PWD python3 -m research.statics_verification [--figures]

* Mattiasson's cantilever under a dead tip load (P L²/EI = 1, 2, 10) at 50 and 100
  segments: tip errors;
* Euler's clamped-clamped column (EJ2 = 2 EJ1, so the first mode is simple): the branch
  point against 4π²EJ1/L² at 25, 50, 100 segments (the order in Δs), the unstable-mode
  counts, and the elastica's end shortening against the elliptic-integral solution;
* Greenhill's twisted clamped-clamped rod at zero axial force: the branch point against
  M L/B = 8.9868 at 25, 50, 100 segments;
* Greenhill with tension T: the branch point's M / 2√(BT) for TL²/B = 4, 25, 100 (40
  segments per unit length), which tends to 1 as L grows;
* the seed's rod (cases/goyal-writhing.yaml at 200 segments, its perturbing force left
  out, the start's twist as the parameter): the branch point's Lk, and the time at which
  the seed's twist schedule reaches it.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.optimize import brentq
from scipy.special import ellipe, ellipk

from solver import statics as st
from solver.continuation import branch_dataset, continuation

MATTIASSON = {1: (0.30172, 0.94357), 2: (0.49346, 0.83936), 10: (0.81061, 0.44501)}
GREENHILL = 8.9868


def euler(n):
    return lambda P: st.uniform(1.0, n, (1.0, 2.0, 1.0), st.clamp([0, 0, 0], [1, 0, 0, 0]),
                                st.clamp([0, 0, 1.0], [1, 0, 0, 0], held=(True, True, False),
                                         force=(0, 0, -P)))


def greenhill(n, C=1.0 / 1.3):
    return lambda th: st.uniform(1.0, n, (1.0, 1.0, C), st.clamp([0, 0, 0], [1, 0, 0, 0]),
                                 st.clamp([0, 0, 1.0], st.quat_axis_angle([0, 0, 1], th), th,
                                          held=(True, True, False)))


def shortening(p):
    m = brentq(lambda m: ellipk(m) - 0.25 * np.sqrt(p), 0.0, 1 - 1e-15)
    return 2 * (1 - ellipe(m) / ellipk(m))


def main(figures: bool) -> None:
    print("Mattiasson cantilever, tip (w/L, x/L) relative errors")
    for n in (50, 100):
        for load, (w_ref, x_ref) in MATTIASSON.items():
            prob = st.uniform(1.0, n, (1.0, 1.0, 0.8), st.clamp([0, 0, 0], [1, 0, 0, 0]),
                              st.free_end([-load, 0, 0]))
            Y = st.solve(prob).Y
            print(f"  N = {n:3d}  PL²/EI = {load:2d}: {-Y[-1, 0] / w_ref - 1:+.2e}, "
                  f"{Y[-1, 2] / x_ref - 1:+.2e}")
    pc = 4 * np.pi**2
    print("Euler column, first branch point / (4π² EJ1/L²) - 1")
    for n in (25, 50, 100):
        br = continuation(euler(n), 0.0, 1.5 * pc, switch=(n == 100), max_points=80)
        bp = [b for b in br.bifurcations if b.kind == "branch_point"][0]
        print(f"  N = {n:3d}: {bp.parameter / pc - 1:+.2e}   unstable modes along the branch: "
              f"{''.join(map(str, br.unstable))}")
    k = br.switched_at
    errs = [(p / pc, (1 - (Y[-1, 2] - Y[0, 2])) / shortening(p) - 1)
            for p, Y in zip(br.parameter[k + 1:], br.Y[k + 1:])]
    print("Elastica end shortening (N = 100), relative error at P/P_c:")
    print("  " + ", ".join(f"{a:.3f}: {e:+.1e}" for a, e in errs))
    if figures:
        from hockle.branch_plots import plot_branch

        out = Path(__file__).resolve().parents[1] / "docs" / "figures"
        for path in plot_branch(branch_dataset(br, "P (N)"), out,
                                stem="statics_euler"):
            print(f"  wrote {path}")
    print("Greenhill, branch point M L/B / 8.9868 - 1 (M = GJ Θ / L)")
    C = 1.0 / 1.3
    for n in (25, 50, 100):
        br = continuation(greenhill(n), 0.0, 1.3 * GREENHILL / C, max_points=80)
        bp = [b for b in br.bifurcations if b.kind == "branch_point"][0]
        print(f"  N = {n:3d}: {bp.parameter * C / GREENHILL - 1:+.2e}  (simple: {bp.simple}; "
              f"unstable modes {br.unstable[0]} -> {br.unstable[-1]})")


def greenhill_tension() -> None:
    B, C, T = 1.0, 1.0 / 1.3, 1.0
    mg = 2 * np.sqrt(B * T)
    print("Greenhill with tension, branch point M / 2√(BT) (-> 1 as L grows)")
    for L in (2.0, 5.0, 10.0):
        n = int(40 * L)

        def prob(th, L=L, n=n):
            return st.uniform(L, n, (B, B, C), st.clamp([0, 0, 0], [1, 0, 0, 0]),
                              st.clamp([0, 0, L], st.quat_axis_angle([0, 0, 1], th), th,
                                       held=(True, True, False), force=(0, 0, T)))

        br = continuation(prob, 0.0, (1.2 * mg + 10 * B / L) * L / C, max_points=80)
        bp = [b for b in br.bifurcations if b.kind == "branch_point"][0]
        print(f"  T L²/B = {T * L**2 / B:5.0f}, N = {n}: {bp.parameter * C / L / mg:.4f}")


def seed_rod() -> None:
    from solver.case import parse_text

    from hockle.api import continue_branch

    root = Path(__file__).resolve().parents[1]
    doc = parse_text((root / "cases" / "goyal-writhing.yaml").read_text(), "yaml")
    table = doc["boundary"]["start"]["rotation"][2]["angular_velocity"]
    doc["numerics"]["n_segments"] = 200
    doc["distributed_forces"] = []
    doc["boundary"]["start"]["rotation"][2] = {"angular_velocity": 0.0}
    # with time 1 s the constant angular velocity (rad/s) is the twist angle (rad)
    ds = continue_branch(doc, "boundary.start.rotation.2.angular_velocity", -16.0, time=1.0,
                         max_points=60)
    phi = float(ds["bifurcation_parameter"][0])
    tt = np.linspace(0.0, 45.0, 450001)
    w = np.interp(tt, table["t"], table["value"])
    angle = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(tt))])
    t_hit = float(np.interp(-phi, -angle, tt))
    print(f"Seed rod (N = 200): branch point at a start twist of {phi:.4f} rad, "
          f"|Lk| = {abs(phi) / (2 * np.pi):.4f} turns (pair: "
          f"{not bool(ds['bifurcation_simple'][0])}), reached by the seed's schedule at "
          f"t = {t_hit:.2f} s")


if __name__ == "__main__":
    main("--figures" in sys.argv[1:])
    greenhill_tension()
    seed_rod()
