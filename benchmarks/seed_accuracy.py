"""Accuracy of the seed example's contact phase at its time step (issue 9).

The seed example (`cases/goyal-writhing.yaml`, 1000 segments) is run to 18.0 s at its
Δt = 0.1 s (the rod has buckled; no contact yet). From that one state the first loop
(18-21 s: first contact, the loop tightening, writhe rising through 1) is run at the
production step (nominal Δt = 0.1 s, cut only where Newton or the collision check fails)
and at nominal steps of 12.5 ms and 6.25 ms (the reference; the difference between the two
references estimates the reference's own error). Outputs every 0.1 s.

Printed and written to benchmarks/results/seed_accuracy.json:
* the largest writhe difference to the reference, absolute and relative to the largest
  |Wr| of the window (target: within 1 %);
* event times (first contact, Wr through 0.5 and 1.0, by linear interpolation between
  outputs) and their differences (target: within 0.1 s);
* the largest |Tw + Wr − Lk| at the outputs (target < 0.05) and the smallest surface gap
  of the polyline (segment to segment, every segment pair beyond the exclusion) at the
  outputs: > 0 means the centreline never interpenetrates;
* wall time of each run.

With ``--tolerances`` (default 1e-2, 3e-3, 1e-3, 1e-4) the same window is also run from
the same state with error-controlled steps (``numerics.tolerance`` = {relative: tol,
absolute: 1e-6·tol}, first step and dt_max 0.1 s, steps landing on the 0.1-s outputs; the
estimator's field peaks start from the 18-s state), each once with the route rule's
tolerance tied to the tolerance (``RodRun.ROUTE_RELATIVE``, the default) and once with the
search margin's quarter alone ("untied", the rule before it followed the tolerance): rows ``tolerance <tol>``
and ``tolerance <tol> untied``.

With ``--position-tolerances`` (m, default none) the window is also run with
``contact.position_tolerance`` set (the largest position error per step where strands
may meet): at the production step (rows ``position <x>``; with ``--dt-cut-factor f``
also with the fixed steps cut by f instead of 4, rows ``position <x> cut <f>``) and with
each tolerance of ``--tolerances`` (rows ``tolerance <tol> position <x>``).

With ``--against STORED.json`` only the production run is made, from the case's own
state at t0 to t1, and compared with the reference records a full run of this script
stored there (e.g. ``benchmarks/results/seed_accuracy_18-45.json``; ``--windows`` as
below): a change to the contact steps measured without recomputing the 6.25-ms reference,
valid while the state at t0 is the same (the two states' writhe must agree within 0.1 %;
the difference is printed). ``--newton ATTR=VALUE[,ATTR=VALUE...]`` sets class
attributes of :class:`solver.newton.NewtonSolver` (its tuning constants,
:mod:`benchmarks.tuning`, as ``research/replay_steps.py --variant`` does) for every run
the script makes, e.g. ``--newton CONTACT_RESIDUAL_FACTOR=1``.

With ``--spread`` (Newton tolerances, default none) the measurement is repeated from
the case's own state for each: the case (with ``--spread-position`` as its
``contact.position_tolerance``, default the case's) is run from t = 0 with that Newton
tolerance to t0, and the window at the production step is compared with a 6.25-ms
reference from the same state (the Newton tolerance moves the trajectory through
Newton's convergence noise, so the rows show how firm the error is); printed and written
to benchmarks/results/seed_accuracy_spread.json (``seed_accuracy_spread_<x>.json`` with
``--spread-position x``).

Other windows (``--t0``, ``--t1``; the state at t0 from the case run from t = 0) are
written to ``seed_accuracy_<t0>-<t1>.json``; ``--fixed-steps`` adds rows at other
nominal steps with the case's step control (rows ``nominal <h>``: how the window's error
converges with the step), ``--windows`` the writhe error of every row over sub-windows
(``by_window``), and the events include the writhe's first crossings of 1.5 and 2.0 (the
second collapse, the plies wrapped). The whole contact phase, as in docs/contact.md § 4:
``--t0 18 --t1 45 --tolerances '' --fixed-steps 0.025
--windows 18-21,21-25,25-26,26-30,30-35,35-45``.

Run: ``python -m benchmarks.seed_accuracy [--t0 18.0] [--t1 21.0] [--quick]
[--tolerances 1e-3,1e-4] [--position-tolerances 3e-4 [--dt-cut-factor 2]]
[--fixed-steps 0.025,0.0125] [--windows 18-21,26-30] [--spread 1e-10,1e-9,1e-8
[--spread-position 5e-4]] [--against STORED.json] [--newton ATTR=VALUE]`` (quick:
references at 25 ms and 50 ms, to 19.5 s; ``--tolerances ''``: none).
"""
from __future__ import annotations

import argparse
import copy
import json
import time
from pathlib import Path

import numpy as np

from solver import Case
from solver.contact import min_surface_gap
from solver.simulation import RodRun
from solver.topology import linking_number, twist, writhe

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"


def state_at(t0: float, newton_tolerance=None, position_tolerance=None) -> RodRun:
    """The seed example advanced to t0 (s) at its own Δt; with ``newton_tolerance`` and
    ``position_tolerance`` (m) set in the case, None keeping the case's."""
    case = Case.from_file(ROOT / "cases" / "goyal-writhing.yaml")
    if newton_tolerance is not None or position_tolerance is not None:
        from benchmarks.bench_seed import set_variant

        spec = set_variant(case.model_dump(mode="json"), position_tolerance)
        if newton_tolerance is not None:
            spec["numerics"]["newton"]["tolerance"] = newton_tolerance
        case = Case.model_validate(spec)
    run = RodRun(case)
    n = int(round(t0 / case.numerics.dt))
    for k in range(1, n + 1):
        run.advance(k * case.numerics.dt)
    return run


def record(run: RodRun) -> dict:
    props = run.props
    tw = twist(run.state.Y[:, 11], props.s)
    wr = writhe(run.state.r)
    lk = linking_number(run.state.phi[0], run.state.phi[1])
    wr += 2.0 * round((lk - tw - wr) / 2.0)
    c = run.contact
    gap = min_surface_gap(run.state.r, props.diameter, props.s, c.separation_cut, c.tolerance)
    return {"t": run.state.t, "writhe": wr, "topology_error": abs(tw + wr - lk),
            "contacts": run.contact_count, "min_surface_gap": gap}


def advance(run: RodRun, t1: float, h: float, out_every: float = 0.1) -> tuple[list, float]:
    """Advance with nominal steps h (s) to t1, recording every out_every (s)."""
    recs = [record(run)]
    t0 = time.perf_counter()
    n = int(round((t1 - run.state.t) / h))
    start = run.state.t
    per_out = int(round(out_every / h))
    for k in range(1, n + 1):
        run.advance(start + k * h)
        if k % per_out == 0:
            recs.append(record(run))
    return recs, time.perf_counter() - t0


def with_tolerance(base: RodRun, relative: float, tied: bool = True) -> RodRun:
    """A copy of ``base`` that goes on with error-controlled steps: the estimator and the
    route rule's tolerance are those ``RodRun`` sets up for the case with
    numerics.tolerance = {relative, absolute: 1e-6·relative} and dt_max = 0.1 s (with
    ``tied`` False, the route rule keeps the search margin's quarter)."""
    spec = base.case.model_dump()
    spec["numerics"].update(tolerance={"relative": relative, "absolute": 1e-6 * relative},
                            dt_max=0.1)
    case = Case.model_validate(spec)
    fresh = RodRun(case)
    run = copy.deepcopy(base)
    run.case = run.assembly.case = case
    run.control.errctl = fresh.control.errctl
    if tied:                 # untied: the fixed-step run's own bound, the margin's quarter
        run.route_tolerance = fresh.route_tolerance
    run.control.errctl.reset(run.state.t, run.state.Y)
    run.control.h_next = case.numerics.dt
    return run


def with_position_tolerance(base: RodRun, position: float, cut_factor=None) -> RodRun:
    """A copy of ``base`` whose steps where strands may meet keep each node's position
    error within ``position`` (m): ``contact.position_tolerance``; with ``cut_factor``
    its fixed steps are cut by that factor instead (``numerics.dt_cut_factor``, as many
    cuts as keep the smallest step)."""
    from benchmarks.bench_seed import set_variant

    spec = set_variant(base.case.model_dump(), position, cut_factor)
    run = copy.deepcopy(base)
    run.case = run.assembly.case = Case.model_validate(spec)
    run.route_tolerance = position
    run.control.level_hint = 0
    return run


def advance_adaptive(run: RodRun, t1: float, out_every: float = 0.1) -> tuple[list, float, int]:
    """Error-controlled steps to t1 (s), landing on and recording every out_every (s);
    returns (records, wall s, accepted steps)."""
    recs = [record(run)]
    t0 = time.perf_counter()
    steps = 0
    n = int(round((t1 - run.state.t) / out_every))
    start = run.state.t
    for k in range(1, n + 1):
        stop = start + k * out_every
        while run.state.t < stop - 1e-9 * out_every:
            run.step_adaptive(stop)
            steps += 1
        recs.append(record(run))
    return recs, time.perf_counter() - t0, steps


def crossing(ts, ys, level):
    for k in range(1, len(ts)):
        if ys[k - 1] < level <= ys[k]:
            return ts[k - 1] + (level - ys[k - 1]) / (ys[k] - ys[k - 1]) * (ts[k] - ts[k - 1])
    return None


#: writhe levels whose first upward crossing is an event (the seed example's: the loop
#: forms (0.5, 1.0), the second collapse (1.5), the plies wrapped (2.0))
WRITHE_LEVELS = (0.5, 1.0, 1.5, 2.0)


def events(recs) -> dict:
    """Event times (s) of a list of :func:`record` dicts: the first output with contact
    and the first upward crossing of each of :data:`WRITHE_LEVELS` by the writhe
    (interpolated linearly between outputs; None where not reached)."""
    ts = [r["t"] for r in recs]
    wr = [r["writhe"] for r in recs]
    first = next((r["t"] for r in recs if r["contacts"] > 0), None)
    out = {"first_contact": first}
    for level in WRITHE_LEVELS:
        out[f"writhe_{level:.1f}".replace(".", "_")] = crossing(ts, wr, level)
    return out


def compare(recs, ref_recs, windows=()) -> dict:
    """Writhe difference (largest, absolute and relative to the reference's largest |Wr|)
    and event-time differences (s; None where either run misses the event) of a window's
    records against a reference's: both lists of :func:`record` dicts at the same output
    times (equal length; numpy raises ValueError otherwise). ``windows``: (t_lo, t_hi)
    pairs (s); for each, ``by_window`` gives the largest |ΔWr| over the outputs with
    t_lo ≤ t ≤ t_hi relative to the reference's largest |Wr| there (None: no output)."""
    ref = np.array([r["writhe"] for r in ref_recs])
    wr = np.array([r["writhe"] for r in recs])
    ts = np.array([r["t"] for r in ref_recs])
    diff = float(np.max(np.abs(wr - ref)))
    ev, ev_ref = events(recs), events(ref_recs)
    by_window = {}
    for lo, hi in windows:
        sel = (ts >= lo - 1e-9) & (ts <= hi + 1e-9)
        by_window[f"{lo:g}-{hi:g}"] = (float(np.max(np.abs(wr[sel] - ref[sel]))
                                        / np.max(np.abs(ref[sel]))) if sel.any() else None)
    out = {"writhe_max_abs_diff": diff, "writhe_rel_diff": diff / float(np.max(np.abs(ref))),
           "event_time_diffs_s": {k: (None if v is None or ev_ref[k] is None
                                      else v - ev_ref[k]) for k, v in ev.items()}}
    if windows:
        out["by_window"] = by_window
    return out


def spread(newton_tolerances, position, t0: float, t1: float, h_ref: float) -> list:
    """The window's accuracy from the case's own state at t0 for each Newton tolerance
    (the case run from t = 0 with it; ``position``: contact.position_tolerance, m, or
    None for the case's), each against its own reference at nominal steps h_ref (s).
    Returns one dict per tolerance: :func:`compare`'s fields, the wall times (s), the
    largest |Tw + Wr − Lk| and the smallest polyline surface gap (m) of the window."""
    rows = []
    for tol in newton_tolerances:
        base = state_at(t0, tol, position)
        recs, wall = advance(copy.deepcopy(base), t1, 0.1)
        ref, wall_ref = advance(copy.deepcopy(base), t1, h_ref)
        row = {"newton_tolerance": tol, "position_tolerance": base.route_tolerance,
               "wall_s": wall, "reference_wall_s": wall_ref, **compare(recs, ref),
               "max_topology_error": max(x["topology_error"] for x in recs),
               "min_surface_gap_m": min(x["min_surface_gap"] for x in recs)}
        rows.append(row)
        print(f"Newton tolerance {tol:g}, position bound {row['position_tolerance']:g} m: "
              f"writhe {100 * row['writhe_rel_diff']:.2f} % off, event time differences "
              f"{row['event_time_diffs_s']}, max |Tw+Wr-Lk| {row['max_topology_error']:.1e}, "
              f"min gap {1e3 * row['min_surface_gap_m']:.3f} mm", flush=True)
    return rows


def against(stored: Path, t0: float, t1: float, windows) -> dict:
    """The production run from the case's own state at t0 to t1 (s) against the reference
    records stored in ``stored`` (a JSON this script wrote over the same window): the
    code's accuracy now without recomputing the 6.25-ms reference (valid while the code
    before t0, and so the state, is unchanged: the first records' writhe must agree within
    0.1 % of the window's largest, and the difference is printed). Prints and
    returns :func:`compare`'s fields with the wall time (s), the largest |Tw + Wr − Lk|
    and the smallest polyline surface gap (m)."""
    from threadpoolctl import threadpool_limits

    data = json.loads(stored.read_text())
    ref = data["records"]["reference"]
    with threadpool_limits(limits=1, user_api="blas"):
        base = state_at(t0)
        recs, wall = advance(copy.deepcopy(base), t1, 0.1)
    start = abs(recs[0]["writhe"] - ref[0]["writhe"]) / data["writhe_scale"]
    if len(recs) != len(ref) or not start <= 1e-3:
        raise SystemExit(f"{stored}: its reference starts from another state at {t0} s "
                         f"(writhe {100 * start:.3g} % of the window's apart) or covers "
                         "another window")
    out = {"wall_s": wall, "start_writhe_diff_rel": start, **compare(recs, ref, windows),
           "max_topology_error": max(x["topology_error"] for x in recs),
           "min_surface_gap_m": min(x["min_surface_gap"] for x in recs)}
    print(f"production {t0:g}-{t1:g} s against the reference stored in {stored.name}: "
          f"writhe {100 * out['writhe_rel_diff']:.3f} % off; by window "
          + ", ".join(f"{k} {100 * v:.2f} %" for k, v in out.get("by_window", {}).items())
          + f"; event time differences {out['event_time_diffs_s']}; max |Tw+Wr-Lk| "
          f"{out['max_topology_error']:.1e}; min gap {1e3 * out['min_surface_gap_m']:.3f} mm;"
          f" wall {wall:.1f} s; the states at {t0:g} s {100 * start:.4f} % apart in writhe")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--t0", type=float, default=18.0)
    ap.add_argument("--t1", type=float, default=21.0)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--tolerances", default="1e-2,3e-3,1e-3,1e-4",
                    help="comma-separated relative tolerances of error-controlled runs")
    ap.add_argument("--position-tolerances", default="",
                    help="comma-separated contact.position_tolerance values, m")
    ap.add_argument("--dt-cut-factor", type=float, default=None,
                    help="the position rows' numerics.dt_cut_factor (also run with it: "
                         "rows 'position <x> cut <f>')")
    ap.add_argument("--spread", default="",
                    help="comma-separated Newton tolerances: the window from the case's own "
                         "state for each, against its own reference (only this is run)")
    ap.add_argument("--spread-position", type=float, default=None,
                    help="contact.position_tolerance (m) of the --spread runs")
    ap.add_argument("--fixed-steps", default="",
                    help="comma-separated nominal steps (s) also run with the case's step "
                         "control (rows 'nominal <h>'); each must divide 0.1 s")
    ap.add_argument("--windows", default="",
                    help="comma-separated sub-windows lo-hi (s), e.g. 18-21,26-30: the "
                         "writhe error of every row in each (by_window)")
    ap.add_argument("--against", default="",
                    help="a stored result JSON of this script (e.g. benchmarks/results/"
                         "seed_accuracy_18-45.json): run only the production from t0 to "
                         "t1 and compare it with that file's stored reference records")
    ap.add_argument("--newton", default="",
                    help="Newton class attributes (or VERLET_SKIN) ATTR=VALUE[,...] for "
                    "every run made")
    args = ap.parse_args()
    if args.newton:
        from benchmarks.tuning import set_newton
        set_newton(args.newton)
    if args.against:
        against(Path(args.against), args.t0, args.t1,
                [tuple(float(x) for x in w.split("-")) for w in args.windows.split(",")
                 if w.strip()])
        return
    if args.spread:
        from threadpoolctl import threadpool_limits

        t1 = 19.5 if args.quick else args.t1
        with threadpool_limits(limits=1, user_api="blas"):
            rows = spread([float(x) for x in args.spread.split(",") if x.strip()],
                          args.spread_position, args.t0, t1, 0.025 if args.quick else 0.00625)
        RESULTS.mkdir(parents=True, exist_ok=True)
        name = ("seed_accuracy_spread.json" if args.spread_position is None
                else f"seed_accuracy_spread_{args.spread_position:g}.json")
        (RESULTS / name).write_text(json.dumps(rows, indent=1))
        return
    tolerances = [float(x) for x in args.tolerances.split(",") if x.strip()]
    positions = [float(x) for x in args.position_tolerances.split(",") if x.strip()]
    from threadpoolctl import threadpool_limits

    t1 = 19.5 if args.quick else args.t1
    steps = {"production": 0.1}
    steps.update({"reference": 0.025, "reference_coarse": 0.05} if args.quick else
                 {"reference": 0.00625, "reference_coarse": 0.0125})
    with threadpool_limits(limits=1, user_api="blas"):
        base = state_at(args.t0)
        runs = {}
        for name, h in steps.items():
            recs, wall = advance(copy.deepcopy(base), t1, h)
            runs[name] = {"h": h, "wall_s": wall, "records": recs, "events": events(recs)}
            print(f"{name}: nominal Δt {h} s, wall {wall:.1f} s, events {runs[name]['events']}")
        cuts = [None] + ([args.dt_cut_factor] if args.dt_cut_factor else [])
        for h in [float(x) for x in args.fixed_steps.split(",") if x.strip()]:
            name = f"nominal {h:g}"
            recs, wall = advance(copy.deepcopy(base), t1, h)
            runs[name] = {"h": h, "wall_s": wall, "records": recs, "events": events(recs)}
            print(f"{name}: wall {wall:.1f} s, events {runs[name]['events']}", flush=True)
        for pos in positions:
            for cut in cuts:
                name = f"position {pos:g}" + ("" if cut is None else f" cut {cut:g}")
                recs, wall = advance(with_position_tolerance(base, pos, cut), t1,
                                     steps["production"])
                runs[name] = {"h": steps["production"], "position_tolerance": pos,
                              "dt_cut_factor": cut, "wall_s": wall, "records": recs,
                              "events": events(recs)}
                print(f"{name}: wall {wall:.1f} s, events {runs[name]['events']}", flush=True)
        for tol in tolerances:
            variants = [("", dict(tied=True)), (" untied", dict(tied=False))]
            variants += [(f" position {pos:g}", dict(tied=True, position=pos)) for pos in positions]
            for suffix, how in variants:
                name = f"tolerance {tol:g}" + suffix
                run = with_tolerance(base, tol, how["tied"])
                if "position" in how:
                    run = with_position_tolerance(run, how["position"])
                recs, wall, n_steps = advance_adaptive(run, t1)
                runs[name] = {"tolerance": tol, "route_tied": how["tied"], "steps": n_steps,
                              "position_tolerance": how.get("position"),
                              "wall_s": wall, "records": recs, "events": events(recs)}
                print(f"{name}: {n_steps} steps, wall {wall:.1f} s, events "
                      f"{runs[name]['events']}", flush=True)
    ref = np.array([r["writhe"] for r in runs["reference"]["records"]])
    scale = float(np.max(np.abs(ref)))
    summary = {"t0": args.t0, "t1": t1, "writhe_scale": scale}
    windows = [tuple(float(v) for v in w.split("-")) for w in args.windows.split(",")
               if w.strip()]
    for name in [k for k in runs if k != "reference"]:
        summary[name] = {**compare(runs[name]["records"], runs["reference"]["records"],
                                   windows),
                         "wall_s": runs[name]["wall_s"], "steps": runs[name].get("steps")}
    for name, r in runs.items():
        summary.setdefault(name, {})
        summary[name]["max_topology_error"] = max(x["topology_error"] for x in r["records"])
        summary[name]["min_surface_gap_m"] = min(x["min_surface_gap"] for x in r["records"])
        summary[name]["events"] = r["events"]
        summary[name]["wall_s"] = r["wall_s"]
    summary["records"] = {k: v["records"] for k, v in runs.items()}
    RESULTS.mkdir(parents=True, exist_ok=True)
    out = ("seed_accuracy.json" if (args.t0, args.t1) == (18.0, 21.0) and not args.quick
           else f"seed_accuracy_{args.t0:g}-{t1:g}.json")
    (RESULTS / out).write_text(json.dumps(summary, indent=1))
    p = summary["production"]
    print(f"writhe vs reference: max |ΔWr| {p['writhe_max_abs_diff']:.4f} "
          f"({p['writhe_rel_diff'] * 100:.2f} % of max |Wr| {scale:.3f}); the coarse "
          f"reference differs by {summary['reference_coarse']['writhe_rel_diff'] * 100:.2f} %")
    print("event time differences (s):", p["event_time_diffs_s"])
    for name in runs:
        if name != "reference":
            print(f"{name}: writhe {summary[name]['writhe_rel_diff'] * 100:.2f} % off"
                  + "".join(f"; {w} s: {100 * e:.2f} %" for w, e in
                            summary[name].get("by_window", {}).items() if e is not None))
        print(f"{name}: max |Tw+Wr-Lk| {summary[name]['max_topology_error']:.2e}, "
              f"min surface gap {summary[name]['min_surface_gap_m'] * 1e3:.3f} mm, "
              f"wall {summary[name]['wall_s']:.1f} s")


if __name__ == "__main__":
    main()
