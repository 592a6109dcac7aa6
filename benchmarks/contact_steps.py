"""Every step attempt of a contact-suite case (benchmarks/contact_suite.py) over a window:
how Δt is chosen and why attempts are refused.

The case runs from t = 0 to ``--t-end`` (with ``numerics.energy_tolerance`` = the suite's
``ENERGY_TOLERANCE``); each attempt (RodRun.try_step) is recorded: its start time, Δt, accepted or
the refusal's reason ("contact" covers the route rule, a negative gap and tunnelling;
"newton" a Newton failure), Newton and GMRES iterations, its wall time, the route rule's
error ratio and the contacts. Printed per ``--every`` seconds from ``--from`` on (or
between the times of ``--edges``): attempts, accepted, refused by reason, Newton and GMRES
iterations, wall time, median and smallest accepted Δt, median route ratio and Newton
iterations of the accepted steps, median contacts; then the totals over the window. With
``--newton-failures K`` also the first K attempts of the window refused by Newton, each
with its iterations (Newton.last_trace: scaled residual, the feasibility filter's
fraction, the line search's fraction, GMRES iterations) and why it failed.

With ``--probe T`` instead: the case is advanced by nominal steps to T (s), and from that
one state a single step of each Δt of ``--probe-dt`` is attempted: accepted or refused,
Newton iterations, the route rule's ratio (how the step's position error grows with Δt,
and whether Newton or the route rule limits it there).

Run: ``PYTHONPATH=$PWD python benchmarks/contact_steps.py seed-in-air --from 17.5
--t-end 18.4`` (the seed example without its fluid, from just before its first contact),
``... tension --from 18.4 --t-end 18.7``, ``... tension --from 18 --t-end 45 --edges
18,18.5,19,20,22,25,30,35,40,45`` (the tension variant's whole contact phase, ~3 min),
``... tension --probe 19 --probe-dt 0.0005,0.001,0.0017,0.003,0.005,0.01``.
``--newton ATTR=VALUE[,...]`` sets class attributes of :class:`solver.newton.Newton` for
the run (as contact_suite.py's option), e.g. ``... pyelastica-0.8 --from 7.5 --t-end 7.6
--every 0.01 --newton CONTACT_RESIDUAL_FACTOR=2 --newton-failures 12``.
"""
from __future__ import annotations

import argparse
import collections
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))


def record(name: str, t_end: float) -> list:
    """Run suite case ``name`` to t_end (s); the attempts as dicts."""
    import contact_suite as cs
    from solver.case import Case
    from solver.run import RodRun
    from solver.simulation import SolverDivergence, simulate

    spec = cs.CASES[name][1]()
    spec["numerics"]["energy_tolerance"] = cs.ENERGY_TOLERANCE
    spec["numerics"]["t_end"] = t_end
    case = Case.model_validate(spec)
    attempts, plain = [], RodRun.try_step

    def recording(self, h, *args, **kwargs):
        t0 = self.t
        g0 = self.newton.gmres_iterations
        w0 = time.perf_counter()
        att = plain(self, h, *args, **kwargs)
        wall = time.perf_counter() - w0
        trace = None
        if att.reason == "newton" and self.newton.last_trace is not None:
            trace = (self.newton.last_failure, self.newton.last_trace.copy())
        attempts.append({"t": t0, "h": h, "ok": bool(att.ok), "why": att.reason,
                         "its": att.iterations, "ratio": self.last_route_ratio,
                         "gmres": self.newton.gmres_iterations - g0, "wall": wall,
                         "contacts": self.contact_count, "trace": trace})
        return att

    RodRun.try_step = recording
    try:
        simulate(case)
    except SolverDivergence as exc:
        print(f"stopped: {exc.reason} at t = {exc.t:.4f} s")
    finally:
        RodRun.try_step = plain
    return attempts


def summary(rows: list) -> str:
    acc = [a for a in rows if a["ok"]]
    why = collections.Counter(a["why"] for a in rows if not a["ok"])
    h = np.array([a["h"] for a in acc])
    ratio = np.array([a["ratio"] for a in acc], float)
    med = (lambda x: float(np.nanmedian(x)) if x.size and np.isfinite(x).any()
           else math.nan)
    return (f"attempts {len(rows):5d}  accepted {len(acc):5d}  refused "
            f"{dict(why) or '-'}  Newton {sum(a['its'] for a in rows):6d}  GMRES "
            f"{sum(a['gmres'] for a in rows):6d}  wall {sum(a['wall'] for a in rows):6.1f} s  "
            f"Δt median {med(h):.3g} min {(h.min() if h.size else math.nan):.3g} s  "
            f"route ratio median {med(ratio):.2f}  Newton per accepted "
            f"{med(np.array([a['its'] for a in acc], float)):.0f}  contacts median "
            f"{med(np.array([a['contacts'] for a in acc], float)):.0f}")


def probe(name: str, at: float, sizes: list) -> None:
    """Advance suite case ``name`` by nominal steps to ``at`` (s), then attempt one step
    of each Δt in ``sizes`` (s) from that state; prints each attempt."""
    import pickle

    import contact_suite as cs
    from solver.case import Case
    from solver.run import RodRun

    spec = cs.CASES[name][1]()
    spec["numerics"]["energy_tolerance"] = cs.ENERGY_TOLERANCE
    case = Case.model_validate(spec)
    from contact_iteration_cost import _advance_to

    run = RodRun(case)
    _advance_to(run, at, case.numerics.dt, 0)
    snapshot = pickle.dumps(run, protocol=pickle.HIGHEST_PROTOCOL)
    print(f"{name} at t = {run.t:g} s, {run.contact_count} contacts:")
    for h in sizes:
        trial = pickle.loads(snapshot)
        att = trial.try_step(h)
        state = "accepted" if att.ok else f"refused ({att.reason})"
        print(f"  Δt = {h:<8g} s  {state:18s} Newton {att.iterations:3d}  route ratio "
              f"{trial.last_route_ratio:.3g}")


def main() -> None:
    import contact_suite as cs
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", choices=list(cs.CASES))
    ap.add_argument("--from", dest="t_from", type=float, default=0.0)
    ap.add_argument("--t-end", type=float, default=None)
    ap.add_argument("--every", type=float, default=0.1)
    ap.add_argument("--edges", default="",
                    help="comma-separated times (s) bounding the printed windows")
    ap.add_argument("--probe", type=float, default=None,
                    help="attempt single steps from the state at this time (s)")
    ap.add_argument("--probe-dt", default="0.0005,0.001,0.002,0.005,0.01,0.02",
                    help="comma-separated Δt (s) of the probe's attempts")
    ap.add_argument("--newton-failures", type=int, default=0)
    ap.add_argument("--newton", default="", help="Newton class attributes (or VERLET_SKIN) "
                    "ATTR=VALUE[,...] for the run (as contact_suite.py --newton)")
    args = ap.parse_args()
    if args.newton:
        from replay_steps import set_newton
        set_newton(args.newton)
    if args.probe is not None:
        probe(args.case, args.probe, [float(x) for x in args.probe_dt.split(",")])
        return
    if args.t_end is None:
        ap.error("--t-end is required (without --probe)")
    load = os.getloadavg()[0]
    wall = time.perf_counter()
    rows = [a for a in record(args.case, args.t_end) if a["t"] >= args.t_from - 1e-12]
    wall = time.perf_counter() - wall
    edges = (np.array([float(x) for x in args.edges.split(",")]) if args.edges
             else np.arange(args.t_from, args.t_end + 1e-9, args.every))
    for a, b in zip(edges[:-1], edges[1:]):
        part = [r for r in rows if a - 1e-12 <= r["t"] < b - 1e-12]
        if part:
            print(f"{a:7.2f}-{b:<7.2f} {summary(part)}")
    print(f"{args.t_from:.2f}-{args.t_end:.2f}  {summary(rows)}")
    failed = [r for r in rows if r["trace"] is not None][:args.newton_failures]
    for r in failed:
        print(f"Newton failed ({r['trace'][0]}) at t = {r['t']:.5f} s, Δt = {r['h']:.3g} s, "
              f"{r['contacts']} contacts before the step:")
        for k, (res, feas, frac, gm) in enumerate(r["trace"][1]):
            print(f"   iteration {k}: residual {res:.3g}, feasible fraction {feas:.3g}, "
                  f"line search {frac:.3g}, GMRES {gm:.0f}")
    print(f"wall {wall:.1f} s for the whole run (compilation included); 1-min load "
          f"{load:.1f} at the start, {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
