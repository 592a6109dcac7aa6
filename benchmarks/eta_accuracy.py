"""How honest the progress ETA is on the seed example (cases/goyal-writhing.yaml).

Runs the case (kernels loaded first by :func:`solver.compiled.warm_up`, so compiling is
not timed) with a progress callback that keeps, at every progress update, the simulated
time t, the wall seconds since the start, the ETA shown (``Progress.eta_seconds``), the
step size and the contact pair count. After the run the true remaining time at each
update is the total wall time minus the wall time then. Prints the ratio shown/true at
10 %, 40 % and 70 % of the simulated time, the worst ratio from the first contact on
(goal: within 2x, i.e. in [0.5, 2]), the time from which it stays within 2x, and
the longest gap between two progress updates
(wall s; the bar must not freeze for more than a few seconds).

Run: ``python -m benchmarks.eta_accuracy [--t-end 45] [--trace eta_trace.json]``
(``--trace`` keeps the updates as JSON). ``--replay eta_trace.json`` recomputes the
figures from a kept trace with the ETA model of this tree
(:class:`solver.recording.EtaModel`) fed the recorded updates, without running the
solver: a model change can be judged on the same run. The last full run's figures are
in docs/benchmarks.md.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from solver import Case, integrate
from solver.compiled import warm_up

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "cases" / "goyal-writhing.yaml"


def run_trace(t_end=None) -> dict:
    """Run the seed example and return the trace: a dict with ``updates`` (list of dicts
    t, wall, eta, dt, contacts, step, newton, substep) and ``wall_total`` (s)."""
    from solver.case import parse_text

    spec = parse_text(CASE.read_text(), source=str(CASE))
    if t_end is not None:
        spec["numerics"]["t_end"] = t_end
    case = Case.model_validate(spec)
    updates = []

    def progress(info):
        updates.append(dict(t=info.t, wall=info.wall_time, eta=info.eta_seconds,
                            dt=info.dt, contacts=info.contact_count, step=info.step,
                            newton=info.newton_iterations,
                            substep=bool(getattr(info, "substep", False))))

    t0 = time.perf_counter()
    ds = integrate(case, progress=progress)
    wall = time.perf_counter() - t0
    return dict(updates=updates, wall_total=wall, t_end=case.numerics.t_end,
                status=ds.attrs.get("hockle_status"), load=os.getloadavg()[0])


def replay(trace: dict) -> dict:
    """The trace with each update's ETA recomputed by this tree's
    :class:`solver.recording.EtaModel` from the recorded updates."""
    from solver.recording import EtaModel

    model = EtaModel()
    out = []
    for u in trace["updates"]:
        eta = model.update(u["wall"], u["t"], trace["t_end"], u["contacts"])
        out.append(dict(u, eta=eta))
    return dict(trace, updates=out)


def figures(trace: dict) -> dict:
    """Ratios shown/true at 10/40/70 % of t_end, the worst from the first contact on
    (the update with the ratio farthest from 1 in log scale) and the longest gap (s)."""
    import math

    ups, total, t_end = trace["updates"], trace["wall_total"], trace["t_end"]

    def ratio(u):
        true = total - u["wall"]
        if u["eta"] is None or true <= 0:
            return None
        return u["eta"] / true

    out = {}
    for share in (0.1, 0.4, 0.7):
        u = next((u for u in ups if u["t"] >= share * t_end - 1e-9), None)
        out[f"at_{int(share * 100)}pct"] = None if u is None else dict(
            t=u["t"], wall=u["wall"], eta=u["eta"], true=total - u["wall"], ratio=ratio(u))
    first = next((i for i, u in enumerate(ups) if u["contacts"] > 0), None)
    worst = None
    if first is not None:
        # the last few seconds of a run divide by a vanishing true remaining time: the
        # worst is taken while at least 5 % of the run's wall time is left
        cands = [(u, ratio(u)) for u in ups[first:]
                 if ratio(u) is not None and total - u["wall"] >= 0.05 * total]
        if cands:
            u, r = max(cands, key=lambda c: abs(math.log(c[1])) if c[1] > 0 else math.inf)
            worst = dict(t=u["t"], wall=u["wall"], eta=u["eta"], true=total - u["wall"],
                         ratio=r, first_contact_t=ups[first]["t"])
    out["worst_from_first_contact"] = worst
    # from which update on every ratio stays within [0.5, 2] (while 5 % of the run is left)
    live = [(u, ratio(u)) for u in ups if total - u["wall"] >= 0.05 * total]
    off = [i for i, (u, r) in enumerate(live) if r is None or not 0.5 <= r <= 2.0]
    within = live[off[-1] + 1][0] if off and off[-1] + 1 < len(live) else (
        live[0][0] if not off else None)
    out["within_2x_from"] = None if within is None else dict(t=within["t"],
                                                             wall=within["wall"])
    walls = [0.0] + [u["wall"] for u in ups] + [total]
    gaps = [(b - a, a) for a, b in zip(walls, walls[1:])]
    g, at = max(gaps)
    out["longest_gap"] = dict(seconds=g, at_wall=at)
    out["wall_total"] = total
    out["updates"] = len(ups)
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--t-end", type=float, default=None)
    ap.add_argument("--trace", type=Path, default=None, help="write the updates (JSON)")
    ap.add_argument("--replay", type=Path, default=None,
                    help="recompute the figures from a kept trace with this tree's model")
    args = ap.parse_args(argv)
    if args.replay is not None:
        kept = json.loads(args.replay.read_text())
        print("as recorded:")
        print(json.dumps(figures(kept), indent=1))
        trace = replay(kept)
        print("this tree's EtaModel on the same updates:")
    else:
        warm_up()
        trace = run_trace(args.t_end)
        if args.trace is not None:
            args.trace.write_text(json.dumps(trace))
        print(f"wall {trace['wall_total']:.1f} s, load {trace['load']:.2f}, "
              f"status {trace['status']}")
    print(json.dumps(figures(trace), indent=1))


if __name__ == "__main__":
    sys.exit(main())
