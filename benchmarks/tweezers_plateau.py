"""The DNA tweezers case's plectonemic phase against the two-phase theory (issue 81).

Runs ``cases/dna-tweezers.yaml`` (200 nm of DNA under 1 pN, turned at 1 turn per ms to
3.5 turns on the centreline scheme; docs/tweezers.md) and prints, past ``--from`` turns:
the torque plateau (mean, range) and the extension's slope per turn (least squares),
beside :func:`solver.results.plectoneme_two_phase` with the superhelix radius R taken
from the simulated ply: half the median distance between its two axes at the last
output (:func:`solver.results.ply_axis_distance` of the nodes whose nearest strand more
than 20 diameters away along the rod is within 1.5 diameters). The theory has no
thermal fluctuations and no electrostatics, as the case has none; it is the long-ply
limit (no end loop, no tails). Each run prints the machine's load (1-min load average)
and its wall time.

Run from the repository's root: ``python -m benchmarks.tweezers_plateau``.
"""
from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
CASE = ROOT / "cases" / "dna-tweezers.yaml"


def compare(ds, case, start_turns: float = 2.6) -> dict:
    """The measured plateau beside the two-phase theory's, from a tweezers result ``ds``
    of ``case``: torque (N m: mean, min, max past ``start_turns``), extension per turn
    (m, from the fit), the ply's median axis distance (m) and node count, and the
    theory's θ (rad), M_p (N m) and extension per turn (m) for R from the ply. Raises
    ValueError where the result has no ply or no point past ``start_turns``."""
    from solver.results import (plectoneme_two_phase, ply_axis_distance, tweezers_protocol,
                                tweezers_series)

    series = tweezers_series(ds)
    past = series["turns"] >= start_turns
    if past.sum() < 2:
        raise ValueError(f"no two stored times past {start_turns} turns")
    torque = series["torque"][past]
    slope = float(np.polyfit(series["turns"][past], series["extension"][past], 1)[0])
    rod = case.rod
    diameter = float(rod.diameter)
    axis = ply_axis_distance(ds.position.values[-1], ds.s.values, 20.0 * diameter)
    ply = axis < 1.5 * diameter
    if not ply.any():
        raise ValueError("no ply at the last output")
    two_r = float(np.median(axis[ply]))
    bend = float(rod.youngs_modulus) * math.pi * diameter**4 / 64.0
    force = float(tweezers_protocol(case.model_dump(mode="json"))["force"])
    theory = plectoneme_two_phase(bend, force, 0.5 * two_r)
    return {"torque_mean": float(torque.mean()), "torque_min": float(torque.min()),
            "torque_max": float(torque.max()), "extension_per_turn": -slope,
            "axis_distance": two_r, "ply_nodes": int(ply.sum()), **{
                f"theory_{k}": v for k, v in theory.items()}}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--from", dest="start", type=float, default=2.6,
                        help="the plateau's first turn (default 2.6)")
    args = parser.parse_args(argv)
    from solver.case import Case
    from solver.simulation import integrate

    case = Case.from_file(CASE)
    load = os.getloadavg()[0]
    began = time.perf_counter()
    ds = integrate(case)
    wall = time.perf_counter() - began
    c = compare(ds, case, args.start)
    print(f"cases/dna-tweezers.yaml: {ds.attrs['hockle_status']}, {wall:.1f} s wall "
          f"(first run includes compiling), load {load:.2f} on {os.cpu_count()} cores")
    print(f"ply: {c['ply_nodes']} nodes, axis distance 2R = {c['axis_distance'] * 1e9:.3f} nm")
    print(f"theory (R = {c['axis_distance'] * 0.5e9:.3f} nm): theta = "
          f"{c['theory_theta']:.4f} rad, M_p = {c['theory_torque'] * 1e21:.3f} pN nm, "
          f"{c['theory_extension_per_turn'] * 1e9:.2f} nm per turn")
    print(f"run past {args.start} turns: torque {c['torque_mean'] * 1e21:.3f} pN nm "
          f"(range {c['torque_min'] * 1e21:.3f}-{c['torque_max'] * 1e21:.3f}), "
          f"{c['extension_per_turn'] * 1e9:.2f} nm per turn")
    print(f"ratios run/theory: torque {c['torque_mean'] / c['theory_torque']:.4f}, "
          f"extension per turn "
          f"{c['extension_per_turn'] / c['theory_extension_per_turn']:.4f}")


if __name__ == "__main__":
    main()
