"""The seed example at the seed's resolution (issue 3): 1000 segments, Δt = 0.1 s, with
self-contact, to 45 s. Prints the wall time, the time per nominal step with and without
active contact (medians), and the shares of the wall time spent in the contact search and
in the writhe. Bar: 120 s on this 2-core machine; goal: 20 s.

Run: ``python benchmarks/bench_seed.py [--t-end 45] [--out goyal.nc]``. The timers wrap
the contact search (SelfContact.may_touch / find_pairs) and the writhe from here; the
solver itself is not changed.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from seed_events import events  # noqa: E402

import solver.contact as contact_mod  # noqa: E402
import solver.topology as topology_mod  # noqa: E402
from solver import Case, SolverDivergence, simulate  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
TIMERS = {"contact_search": 0.0, "writhe": 0.0}


def timed(owner, name, key):
    fn = getattr(owner, name)

    def wrapper(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            TIMERS[key] += time.perf_counter() - t0

    setattr(owner, name, wrapper)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--t-end", type=float, default=45.0)
    ap.add_argument("--out", default=None, help="also write the dataset (NetCDF)")
    args = ap.parse_args()
    timed(contact_mod.SelfContact, "find_pairs", "contact_search")
    timed(contact_mod.SelfContact, "may_touch", "contact_search")
    timed(topology_mod, "writhe", "writhe")
    spec = Case.from_file(ROOT / "cases" / "goyal-writhing.yaml").model_dump(mode="json")
    spec["numerics"]["t_end"] = args.t_end
    case = Case.model_validate(spec)
    steps = []
    last = [0.0]

    def progress(p):
        steps.append((p.wall_time - last[0], p.contact_count > 0))
        last[0] = p.wall_time

    t0 = time.perf_counter()
    try:
        ds = simulate(case, progress=progress)
    except SolverDivergence as exc:
        print("solver diverged:", exc)
        ds = exc.partial
    wall = time.perf_counter() - t0
    with_c = [w for w, c in steps if c]
    without = [w for w, c in steps if not c]
    print(f"== seed example, {case.numerics.n_segments} segments, Δt = {case.numerics.dt} s, "
          f"to {float(ds.time[-1]):.1f} s")
    print(f"  wall time: {wall:.1f} s  (bar 120 s: {wall / 120:.2f} of it; goal 20 s: "
          f"{wall / 20:.2f} of it)")
    print(f"  nominal steps: {len(steps)}; Newton iterations: "
          f"{int(ds.step_newton_iterations.sum())}; smallest Δt: {float(ds.step_dt.min()):.3g} s")
    if without:
        print(f"  time per step without contact: median {statistics.median(without) * 1e3:.1f} ms "
              f"({len(without)} steps)")
    if with_c:
        print(f"  time per step with active contact: median {statistics.median(with_c) * 1e3:.0f} ms, "
              f"mean {statistics.mean(with_c) * 1e3:.0f} ms ({len(with_c)} steps, "
              f"{sum(with_c):.1f} s in all)")
    for key, val in TIMERS.items():
        print(f"  share in {key.replace('_', ' ')}: {val / wall * 100:.1f} % ({val:.2f} s)")
    ev = events(ds)
    print("  events:", json.dumps({k: float(f"{v:.4g}") for k, v in ev.items()}))
    if args.out:
        from hockle.io import write_netcdf

        write_netcdf(ds, args.out)
        print("  dataset:", args.out)


if __name__ == "__main__":
    main()
