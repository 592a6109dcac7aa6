"""Sensitivity of the seed example's event times (issue 3): Δt, Δs, ρ∞ and the
perturbation each halved (the perturbation also divided by 10), against the base case.

Run: ``python -m research.seed_sensitivity [--t-end 26] [--variants base,dt/2,...]``.
Prints one row per variant (event definitions: benchmarks/seed_events.py) and writes
them as JSON to research/results/seed_sensitivity.json.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from benchmarks.seed_events import events

from solver import Case, SolverDivergence, integrate

ROOT = Path(__file__).resolve().parents[1]
BASE = ROOT / "cases" / "goyal-writhing.yaml"


def variant(name: str, t_end: float) -> Case:
    spec = Case.from_file(BASE).model_dump(mode="json")
    num = spec["numerics"]
    num["t_end"] = t_end
    spec["output"]["fields"] = ["energies", "topology", "contact"]
    if name == "dt/2":
        num["dt"] /= 2
    elif name == "ds/2":
        num["n_segments"] *= 2
        num.pop("ds")
    elif name == "rho_inf/2":
        num["rho_inf"] /= 2
    elif name.startswith("perturbation/"):
        k = float(name.split("/")[1])
        for f in spec["distributed_forces"]:
            f["value"] = [x / k for x in f["value"]]
    elif name != "base":
        raise SystemExit(f"unknown variant {name!r}")
    return Case.model_validate(spec)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--t-end", type=float, default=26.0)
    ap.add_argument("--variants", default="base,dt/2,ds/2,rho_inf/2,perturbation/2,perturbation/10")
    args = ap.parse_args()
    out_dir = ROOT / "research" / "results"
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "seed_sensitivity.json"
    rows = json.loads(path.read_text()) if path.exists() else {}
    keys = ["buckling_onset", "torsion_peak", "first_contact", "writhe_after_contact",
            "max_topology_error", "min_surface_gap"]
    print(f"{'variant':16s} " + " ".join(f"{k:>20s}" for k in keys) + "   wall")
    for name in args.variants.split(","):
        t0 = time.perf_counter()
        try:
            ds = integrate(variant(name, args.t_end))
        except SolverDivergence as exc:
            ds = exc.partial
        ev = events(ds)
        ev["wall_time_s"] = time.perf_counter() - t0
        rows[name] = ev
        path.write_text(json.dumps(rows, indent=1))
        print(f"{name:16s} " + " ".join(f"{ev[k]:20.4g}" for k in keys)
              + f"   {ev['wall_time_s']:.0f} s", flush=True)


if __name__ == "__main__":
    main()
