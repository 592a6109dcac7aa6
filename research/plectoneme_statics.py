"""A clamped rod under tension T twisted through plectoneme formation, with self-contact:
the static branch in the end rotation against the elastic-rod plectoneme theory.

    PYTHONPATH=$PWD python3 -m research.plectoneme_statics [--segments 120] [--length 24] [--points 3000]

The rod (B = EJ1 = EJ2 = 1 N m², C = GJ3 = 1 N m², diameter D = 0.4 m, T = 1 N: lengths
in units of √(B/T) = 1 m) is clamped at s = 0; at s = L its frame is turned about the axis
by the parameter λ (rad), it is held on the axis laterally and pulled along it by the dead
tension T. A lateral load growing linearly from 0 to 2e-4 T/L per length along the rod
breaks the symmetries of the round, end-to-end symmetric rod (the circle of helical modes
at Greenhill's load, the loop leaving the middle), so that the branch passes them without
a branch switch.
Self-contact: the barrier law (ĝ = D/20, κ = 100 1/s², ρA = 1 kg/m), no damping in
statics. Prints the branch (end rotation in turns, end torque M, end shortening, Tw, Wr,
smallest gap) and the comparison with the theory (docs/statics.md, "The plectoneme"):

* buckling: Greenhill's torque with tension, M_b → 2√(BT) as TL²/B grows;
* plateau: in the two-phase model of Clauvelin, Audoly & Neukirch (Biophys. J. 96,
  3716, 2009) and Neukirch & Marko (PRL 106, 2011) without thermal fluctuations and with the
  hard-core superhelix radius R = (D + g)/2, the plectonemic phase (pitch angle θ from
  the superhelix axis, curvature sin²θ/R, writhe sin 2θ/(4πR) per unit length of rod;
  tests/solver/test_topology.py) coexists with the straight phase when its energy per
  length B sin⁴θ/(2R²) − M sin 2θ/(2R), minimised in θ, equals the straight phase's −T:
      sin⁴θ (2 cos²θ / cos 2θ − ½) = T R²/B,   M_p = 2 B sin³θ cos θ / (R cos 2θ),
  and every further turn goes into writhe: the extension falls by 4πR / sin 2θ per turn.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from solver import statics as st
from solver.contact import SelfContact
from solver.continuation import continuation
from solver.results import plectoneme_two_phase
from solver.topology import twist, writhe


def theory(T, B, R):
    """(θ, plateau torque M_p, extension slope per turn, m) of the plectonemic phase
    (:func:`solver.results.plectoneme_two_phase`)."""
    p = plectoneme_two_phase(B, T, R)
    return p["theta"], p["torque"], p["extension_per_turn"]


def problem_family(L, N, *, B=1.0, C=1.0, T=1.0, D=0.4, g_hat=None, kappa=100.0,
                   rho_a=1.0, imperfection=1e-4):
    g_hat = D / 20 if g_hat is None else g_hat
    s = np.linspace(0.0, L, N + 1)
    contact = SelfContact(dict(aperture=90.0, tolerance=D + 2 * g_hat, k1=0, k2=0, k3=0,
                               k4=0, law="barrier", barrier_gap=g_hat,
                               barrier_stiffness=kappa),
                          s, np.full(N + 1, D), np.full(N + 1, rho_a))

    load = np.zeros((N + 1, 3))
    load[:, 0] = 2 * imperfection * T / L * s / L

    def at(lam):
        return st.StaticProblem(L, N, np.tile([B, B, C], (N + 1, 1)), load,
                                st.clamp([0, 0, 0], [1, 0, 0, 0]),
                                st.clamp([0, 0, L], st.quat_axis_angle([0, 0, 1], lam), lam,
                                         held=(True, True, False), force=(0, 0, T)),
                                contact=contact, mass=np.full(N + 1, rho_a))
    return at


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--segments", type=int, default=120)
    ap.add_argument("--length", type=float, default=24.0)
    ap.add_argument("--turns", type=float, default=14.0)
    ap.add_argument("--points", type=int, default=3000)
    ap.add_argument("--ds-max", type=float, default=0.05)
    ap.add_argument("--save", default="")
    a = ap.parse_args()
    B = C = T = 1.0
    D = 0.4
    L, N = a.length, a.segments
    at = problem_family(L, N, B=B, C=C, T=T, D=D)
    t0 = time.perf_counter()
    br = continuation(at, 0.0, 2 * np.pi * a.turns, ds=0.01, ds_max=a.ds_max,
                      max_points=a.points, stability=False, locate=False, max_turn=0.3)
    wall = time.perf_counter() - t0
    print(f"{len(br.parameter)} points in {wall:.0f} s ({br.stopped}); N = {N}, L = {L}")
    s = np.linspace(0, L, N + 1)
    rows = []
    for lam, Y, prob in zip(br.parameter, br.Y, br.problems):
        f = st.fields(Y, prob)
        M = Y[-1, 12]
        short = L - Y[-1, 2]
        tw = twist(f["kappa"][:, 2], s)
        wr = writhe(Y[:, 0:3])
        gap = st.contact_gap(Y, prob)
        rows.append((lam / (2 * np.pi), M, short, tw, wr, gap))
    rows = np.array(rows)
    print(" turns   M (N m)  shortening (m)   Tw     Wr    min gap (m)")
    for r in rows[:: max(1, len(rows) // 40)]:
        print(f"{r[0]:6.3f} {r[1]:8.4f} {r[2]:12.4f} {r[3]:7.3f} {r[4]:7.3f} {r[5]:10.3g}")
    if a.save:
        np.save(a.save, rows)
    compare(rows, B=B, T=T, D=D, L=L, g_hat=D / 20)


def compare(rows, *, B, T, D, L, g_hat):
    """Print the branch's figures beside the theory (module doc). rows: (turns, M,
    shortening, Tw, Wr, gap) per point."""
    turns, M, short, gap = rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 5]
    k = int(np.argmax(turns[1:] < turns[:-1]))          # the first fold in the rotation
    print(f"buckling (first fold in the rotation): {turns[k]:.3f} turns, M = {M[k]:.4f} N m "
          f"= {M[k] / (2 * np.sqrt(B * T)):.4f} x 2√(BT) (T L²/B = {T * L**2 / B:.0f})")
    touch = np.flatnonzero(gap < g_hat)
    if touch.size == 0:
        print("no self-contact on the branch followed")
        return
    c = touch[0]
    print(f"first contact (gap < ĝ): {turns[c]:.3f} turns, M = {M[c]:.4f} N m, shortening "
          f"{short[c]:.3f} m, Wr = {rows[c, 4]:.3f}")
    print(f"smallest segment-to-segment gap along the branch: {np.min(gap):.3g} m "
          f"({np.min(gap) / D:.2%} of D)")
    after = slice(c, None)
    mean_gap = float(np.median(np.clip(gap[after], 0, None)))
    th, Mp, slope = theory(T, B, 0.5 * (D + mean_gap))
    print(f"theory (R = (D + g)/2, g = {mean_gap:.3g} m the median gap after contact): "
          f"θ = {th:.4f} rad, plateau M_p = {Mp:.4f} N m, extension falls "
          f"{slope:.3f} m per turn")
    tt, mm, ss = turns[after], M[after], short[after]
    grow = np.flatnonzero((np.diff(tt) > 0) & (np.diff(ss) > 0))
    if grow.size < 3 or np.ptp(ss[grow]) < 0.5 * slope:
        print(f"after contact ({tt.size} points): {tt.min():.3f}-{tt.max():.3f} turns, M "
              f"{mm.min():.4f}-{mm.max():.4f} N m, shortening {ss.min():.3f}-{ss.max():.3f} m, "
              "Wr {:.3f}-{:.3f}: the shortening does not grow by half a theoretical turn's "
              "(no plectoneme growth on the branch followed)".format(rows[c:, 4].min(),
                                                                    rows[c:, 4].max()))
        return
    fit = np.polyfit(tt[grow], ss[grow], 1)
    print(f"plectoneme growth on {grow.size} steps: M = {np.median(mm[grow]):.4f} N m "
          f"(median; {mm[grow].min():.4f}-{mm[grow].max():.4f}), shortening "
          f"{fit[0]:.3f} m per turn")


if __name__ == "__main__":
    main()
