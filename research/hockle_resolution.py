"""How ``cases/seabed-hockle.yaml``'s figures move with its grid (docs/hockle.md, "How
these figures move with the grid"; docs/contact.md, "On the sea floor the drift is
pressed into the bottom"; docs/case-spec.md, "How a centreline is resampled").

First, for 40 to 320 segments, how far the pose a run starts from (the space route of the
resampled κ, solver/initial.py) lies from the case's given centreline: its s = L end from
the centreline's last point, and its largest height above the plane z = 0 the centreline
lies in, against Δs·τ0 (τ0 the twist rate), and the same without the twist.

Then where the runs on 320 segments with Δt = 0.05, 0.025 and 0.0125 s part (to 3 s:
each run's largest distance from the 0.0125-s run at 1, 1.25, 2 and 3 s, and its smallest
step and refused attempts over 0.95-1.3 s, where the end starts moving).

Then the case (160 segments, Δt = 0.05 s) and the same case on coarser and finer grids,
with its friction to 4.5 s (through the loop's formation) and without friction to 5 s
(the frictionless variant stops at 4.0 s on the case's grid); and, on the case's own grid
and on 320 segments with Δt = 0.025 s, the case with small changes of its data (the twist
rate by 0.1 %, ρ∞ 0.45 for 0.5), to tell a dependence on the grid from a dependence on
any small change. Per run: status, Newton iterations, wall; when the bend radius first
falls below the MBR (0.15 m; linear between outputs every 0.05 s) and when the loop forms
(``loop_formed``, at an output time); where the cable has lifted at 3.0 s (the arclength
of its highest point, and the height; a run that stopped earlier: at its last output);
the carried s = L end's largest distance from its prescribed motion (``end_drift``); the
largest difference between the time route and the centreline integrated from κ
(``position_route_difference``); the largest seabed reaction per unit length on the rod's
last node.

With ``--untwisted`` instead: the untwisted lay (``initial.twist_rate`` 0) on the case's
grid to 3 s at Δt = 0.05 s down to 0.2 ms, each run's nodes against the 0.2-ms run's, and
at Δt = 3 ms the same lay with its imperfection scaled by 1 + 10⁻⁶ and 1 + 10⁻³ against
the unscaled one (docs/contact.md, "Where the correction fed the drift"); ``--rho-inf R``
runs them at ρ∞ = R, ``--without-self-contact`` with ``contact`` null,
``--correction-time T`` with the end correction's rate floored at T in every run,
``--segments N`` on N segments.

With ``--route-difference`` instead: the untwisted lay without self-contact on 160, 320
and 640 segments at Δt = 1 and 0.5 ms to 3 s, and how far its two routes part: the time
route carried and the centreline integrated from κ (``position_route_difference``, and
at the s = L end ``end_drift``).

Run: ``PYTHONPATH=$PWD python -m research.hockle_resolution [--quick | --untwisted
[--rho-inf R] [--without-self-contact] [--correction-time T] [--segments N] |
--route-difference]`` (about 7 minutes alone on 2 cores, 1 of them
the frictionless 640-segment run; ``--quick`` leaves out the 640-segment runs;
``--untwisted`` about 4 minutes, ``--route-difference`` about 2). Counts and answers are
deterministic; the wall times are indicative.
"""
from __future__ import annotations

import argparse
import itertools
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
from hockle.plots import run_events
from solver.case import Case
from solver.simulation import SolverDivergence, integrate
from solver.step_problem import ProblemAssembly

CASE = ROOT / "cases" / "seabed-hockle.yaml"
#: (segments, Δt s) with friction; the case's own grid first
GRIDS = ((160, 0.05), (40, 0.05), (80, 0.05), (160, 0.025), (320, 0.05), (320, 0.025),
         (320, 0.0125), (640, 0.05), (640, 0.025))
#: the same without friction
GRIDS_FRICTIONLESS = ((160, 0.05), (160, 0.025), (320, 0.025), (640, 0.05))
#: small changes of the case's data, run on the grids of :data:`CHANGED_ON`: label ->
#: (what, factor or value)
CHANGES = {"twist rate × 1.001": ("twist", 1.001), "ρ∞ 0.45": ("rho_inf", 0.45)}
CHANGED_ON = ((160, 0.05), (320, 0.025))
OUTPUT_INTERVAL = 0.05          # s


def spec_for(segments: int, dt: float, t_end: float, friction: bool = True,
             change: tuple | None = None) -> dict:
    """The case's spec (dict) on a grid of ``segments`` cells and step ``dt`` (s) to
    ``t_end`` (s), outputs every 0.05 s; without the seabed's friction if not
    ``friction``; ``change``: one entry of :data:`CHANGES`."""
    spec = Case.from_file(CASE).model_dump(mode="json")
    num = spec["numerics"]
    num.pop("ds", None)
    num.update(n_segments=segments, dt=dt, t_end=t_end)
    spec["output"]["every"] = max(1, round(OUTPUT_INTERVAL / dt))
    if not friction:
        spec["seabed"]["friction"] = None
    if change is not None:
        what, value = change
        if what == "twist":
            spec["initial"]["twist_rate"] *= value
        else:
            num[what] = value
    return spec


def figures(spec: dict) -> dict:
    """Run ``spec``; the figures of the module's docstring (a failed run's from its
    partial result)."""
    case = Case.model_validate(spec)
    t0 = time.perf_counter()
    try:
        ds, status = integrate(case), "completed"
    except SolverDivergence as exc:
        ds, status = exc.partial, f"failed at {exc.t:.3g} s"
    wall = time.perf_counter() - t0
    t = ds.time.values
    radius = ds.bend_radius_min.values
    mbr = case.rod.minimum_bend_radius
    below = np.flatnonzero(radius < mbr)
    crossing = None
    if below.size and below[0] > 0:
        i = below[0]
        crossing = t[i - 1] + (mbr - radius[i - 1]) * (t[i] - t[i - 1]) / (radius[i] - radius[i - 1])
    loop = run_events(ds).get("loop_formed")
    k = int(np.argmin(np.abs(t - 3.0)))
    z = ds.position.values[k, :, 2]
    top = int(np.argmax(z))
    seabed = np.linalg.norm(ds.seabed_force.values[:, -1], axis=1)
    return {
        "status": status, "newton": int(ds.step_newton_iterations.values.sum()), "wall": wall,
        "mbr": crossing, "loop": None if loop is None else float(t[loop]),
        "lift_s": float(ds.s.values[top]), "lift_z": float(z[top] - z[0]),
        "drift": float(np.nanmax(ds.end_drift.values)),
        "route": float(np.nanmax(ds.position_route_difference.values)),
        "end_reaction": float(np.nanmax(seabed)),
    }


def start_pose_offsets(segments: int, twist: bool = True) -> tuple[float, float, float]:
    """The start pose on ``segments`` cells against the case's centreline (with its twist
    rate, or none): (Δs·τ0 rad, the s = L end's distance from the centreline's last point
    m, the largest height above z = 0 m)."""
    from solver.initial import initial_pose

    spec = spec_for(segments, 0.05, 1.0)
    if not twist:
        spec["initial"]["twist_rate"] = 0.0
    case = Case.model_validate(spec)
    s = np.linspace(0.0, case.rod.length, segments + 1)
    _, r, kappa = initial_pose(case, s)
    last = np.asarray(case.initial.centreline.points[-1], dtype=float)
    return float(s[1] * kappa[0, 2]), float(np.linalg.norm(r[-1] - last)), float(np.max(r[:, 2]))


def start_pose(segments: int) -> str:
    """The start pose's row of the first table: with the case's twist and without it."""
    phi, end, height = start_pose_offsets(segments)
    _, flat_end, flat_height = start_pose_offsets(segments, twist=False)
    return (f"| {segments} | {phi:.3f} | {end * 1e3:.3g} | {height * 1e3:.3g} | "
            f"{flat_end * 1e3:.3g} | {flat_height * 1e3:.3g} |")


def parting(segments: int = 320, steps=(0.05, 0.025, 0.0125), t_end: float = 3.0) -> list[str]:
    """Where the runs on ``segments`` cells with the Δt of ``steps`` part: each run's
    largest distance from the last one's (the smallest Δt) at a few times (outputs every
    0.05 s), and over 0.95-1.3 s (the end starts moving at 1 s) its smallest step and its
    refused attempts."""
    runs = {}
    for dt in steps:
        spec = spec_for(segments, dt, t_end)
        spec["output"]["fields"] = ["position"]
        runs[dt] = integrate(Case.model_validate(spec))
    ref = runs[steps[-1]]
    out = []
    for dt, ds in runs.items():
        at = []
        for t in (1.0, 1.25, 2.0, t_end):
            k = int(np.argmin(np.abs(ds.time.values - t)))
            d = np.abs(ds.position.values[k] - ref.position.values[k]).max()
            at.append(f"{t:g} s {d * 1e3:.3g} mm")
        ts = ds.step_time.values
        window = (ts > 0.95) & (ts < 1.3)
        out.append(f"{segments} segments, Δt = {dt:g} s: from Δt = {steps[-1]:g} s "
                   f"{', '.join(at)}; over 0.95-1.3 s smallest step "
                   f"{ds.step_dt.values[window].min() * 1e3:.2g} ms, "
                   f"{int(ds.step_rejected_attempts.values[window].sum())} refused attempts")
    return out


def lay_spec(segments: int, dt: float, t_end: float, rho_inf: float | None = None,
             self_contact: bool = True, scale: float = 1.0) -> dict:
    """The untwisted lay's spec (dict): the case with ``initial.twist_rate`` 0 on
    ``segments`` cells at step ``dt`` (s) to ``t_end`` (s), ρ∞ ``rho_inf`` (None: the
    case's), ``contact`` null unless ``self_contact``, the lay imperfection (the
    centreline's y) scaled by ``scale``, the positions output at every step."""
    spec = spec_for(segments, dt, t_end)
    spec["initial"]["twist_rate"] = 0.0
    if rho_inf is not None:
        spec["numerics"]["rho_inf"] = rho_inf
    if not self_contact:
        spec["contact"] = None
    if scale != 1.0:
        pts = np.array(spec["initial"]["centreline"]["points"], dtype=float)
        pts[:, 1] *= scale
        spec["initial"]["centreline"]["points"] = pts.tolist()
        spec["initial"].pop("tangent", None)
    spec["output"].update(fields=["position"], every=1)   # 3 ms does not divide 0.05 s
    return spec


def _run(spec: dict):
    """(result, status) of ``spec``: a failed run's partial result and where it failed."""
    try:
        return integrate(Case.model_validate(spec)), "completed"
    except SolverDivergence as exc:
        return exc.partial, f"failed at {exc.t:.4g} s"


def route_difference(grids=((160, 0.001), (160, 0.0005), (320, 0.001), (320, 0.0005),
                            (640, 0.001)), t_end: float = 3.0,
                     rho_inf: float = 0.0) -> list[str]:
    """The untwisted lay without self-contact (each node's time route carried, the
    centreline integrated from κ only for the output) on each (segments, Δt (s)) of
    ``grids`` to ``t_end`` at ρ∞ ``rho_inf``: per run its status, Newton iterations, and
    the two routes' largest distance (``position_route_difference``) and the s = L end's
    (``end_drift``), largest over the run and at its end, mm: by how much a self-contact
    run's carried centreline would part from the time route if no end correction steered
    it (docs/contact.md, "Where the correction fed the drift"). Raises nothing: a run
    that fails is reported by its status, on its partial result."""
    out = []
    for segments, dt in grids:
        ds, status = _run(lay_spec(segments, dt, t_end, rho_inf, self_contact=False))
        route = ds.position_route_difference.values * 1e3
        drift = ds.end_drift.values * 1e3
        out.append(f"N = {segments}, Δt = {dt:g} s: {status}, "
                   f"{int(ds.step_newton_iterations.values.sum())} Newton; routes apart "
                   f"≤ {np.nanmax(route):.3g} mm, {route[-1]:.3g} mm at "
                   f"{ds.time.values[-1]:g} s; end ≤ {np.nanmax(drift):.3g} mm, "
                   f"{drift[-1]:.3g} mm")
    return out


def untwisted_lay(steps=(0.05, 0.0125, 0.003, 0.001, 0.0005, 0.0002), t_end: float = 3.0,
                  rho_inf: float | None = None, sensitivity_dt: float = 0.003,
                  self_contact: bool = True,
                  correction_time: float | None = None,
                  segments: int | None = None) -> list[str]:
    """The untwisted lay (``initial.twist_rate`` 0) on the case's grid (or ``segments``) to
    ``t_end`` at each Δt of ``steps`` (s), then at ``sensitivity_dt`` with the lay
    imperfection (the centreline's y) scaled by 1 + 10⁻⁶ and 1 + 10⁻³: per run its
    status, Newton iterations, largest ``end_drift``, and the largest distance of a node
    from the same node of the last run of ``steps`` (of the unscaled run, for the scaled
    ones) at 1.5, 2, 2.5 s and ``t_end``. ``rho_inf``: the ρ∞ (None: the case's); not
    ``self_contact``: ``contact`` null (the lay does not touch itself before 3.5 s, but
    without self-contact the centreline is the time route, not carried along s, and the
    s = L end is not corrected: docs/contact.md, "One geometry"). ``correction_time``
    T (s): the end correction's rate g/max(h, T, T_w) in every run, the same on steps
    shorter than T whatever Δt (``ProblemAssembly.DRIFT_STEP_FLOOR`` set to T/Δt for each
    run and restored after); None: the code's g/max(h, Δt/4, T_w). ``segments``: the
    grid (None: the case's)."""
    def run(dt, scale=1.0):
        spec = lay_spec(segments or GRIDS[0][0], dt, t_end, rho_inf, self_contact, scale)
        floor = ProblemAssembly.DRIFT_STEP_FLOOR
        if correction_time is not None:
            ProblemAssembly.DRIFT_STEP_FLOOR = correction_time / dt
        try:
            return _run(spec)
        finally:
            ProblemAssembly.DRIFT_STEP_FLOOR = floor

    def line(label, ds, status, ref):
        at = []
        for t in (1.5, 2.0, 2.5, t_end):
            if ds.time.values[-1] < t - 1e-9:
                break
            k = int(np.argmin(np.abs(ds.time.values - t)))
            j = int(np.argmin(np.abs(ref.time.values - t)))
            d = np.linalg.norm(ds.position.values[k] - ref.position.values[j], axis=-1).max()
            at.append(f"{t:g} s {d * 1e3:.3g} mm")
        drift = ds.end_drift.values if "end_drift" in ds else np.array([np.nan])
        return (f"{label}: {status}, {int(ds.step_newton_iterations.values.sum())} Newton, "
                f"end drift ≤ {np.nanmax(drift) * 1e3:.2g} mm; from the "
                f"reference {', '.join(at) or '–'}")

    runs = {dt: run(dt) for dt in steps}
    ref = runs[steps[-1]][0]
    out = [line(f"untwisted lay, Δt = {dt:g} s", *runs[dt], ref) for dt in steps]
    base = runs[sensitivity_dt][0] if sensitivity_dt in runs else run(sensitivity_dt)[0]
    for eps in (1e-6, 1e-3):
        out.append(line(f"untwisted lay, Δt = {sensitivity_dt:g} s, imperfection × (1 + {eps:g})",
                        *run(sensitivity_dt, 1 + eps), base))
    return out


def row(label: str, f: dict) -> str:
    def at(x):
        return "–" if x is None else f"{x:.2f}"
    return (f"| {label} | {f['status']} | {f['newton']} | {f['wall']:.0f} | {at(f['mbr'])} | "
            f"{at(f['loop'])} | {f['lift_s']:.2f} m ({f['lift_z'] * 100:.0f} cm) | "
            f"{f['drift'] * 1e3:.1f} | {f['route'] * 1e3:.1f} | {f['end_reaction']:.0f} |")


HEADER = ("| run | status | Newton | wall (s) | below the MBR (s) | loop (s) | "
          "lifted at 3.0 s: s (height) | end drift (mm) | route difference (mm) | "
          "last node's seabed reaction (N/m) |\n|---|---|---:|---:|---:|---:|---|---:|---:|---:|")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="leave out the 640-segment runs")
    ap.add_argument("--untwisted", action="store_true",
                    help="only the untwisted lay's Δt refinement and its sensitivity to "
                         "the lay imperfection (about 4 minutes alone)")
    ap.add_argument("--rho-inf", type=float, default=None,
                    help="with --untwisted: the ρ∞ (default: the case's)")
    ap.add_argument("--without-self-contact", action="store_true",
                    help="with --untwisted: contact null (no carried centreline, no end "
                         "correction)")
    ap.add_argument("--correction-time", type=float, default=None, metavar="T",
                    help="with --untwisted: the floor T (s) of the end correction's time "
                         "constant in every run, whatever Δt (default: the code's, Δt/4)")
    ap.add_argument("--segments", type=int, default=None, metavar="N",
                    help="with --untwisted: N segments (default: the case's 160)")
    ap.add_argument("--route-difference", action="store_true",
                    help="only the untwisted lay without self-contact on 160-640 segments "
                         "at Δt = 1 and 0.5 ms: how far the two routes part (about 2 "
                         "minutes alone)")
    args = ap.parse_args()
    if args.route_difference:
        for line in route_difference():
            print(line, flush=True)
        return
    if args.untwisted:
        for line in untwisted_lay(rho_inf=args.rho_inf,
                                  self_contact=not args.without_self_contact,
                                  correction_time=args.correction_time,
                                  segments=args.segments):
            print(line, flush=True)
        return
    quick = args.quick
    print("| segments | Δs·τ0 (rad) | start pose's s = L end from the centreline's last point "
          "(mm) | its largest height above z = 0 (mm) | the same without twist: end (mm) | "
          "height (mm) |\n|---:|---:|---:|---:|---:|---:|")
    for segments in (40, 80, 160, 320):
        print(start_pose(segments), flush=True)
    print()
    for line in parting():
        print(line, flush=True)
    print()
    print(HEADER, flush=True)
    for friction, grids, t_end in ((True, GRIDS, 4.5), (False, GRIDS_FRICTIONLESS, 5.0)):
        for n, dt in grids:
            if quick and n > 320:
                continue
            label = (f"{'with friction' if friction else 'frictionless'}, N = {n}, "
                     f"Δt = {dt:g} s" + (" (the case)" if (n, dt) == GRIDS[0] else ""))
            print(row(label, figures(spec_for(n, dt, t_end, friction))), flush=True)
        if friction:
            for (n, dt), (name, change) in itertools.product(CHANGED_ON, CHANGES.items()):
                print(row(f"with friction, N = {n}, Δt = {dt:g} s, {name}",
                          figures(spec_for(n, dt, t_end, change=change))), flush=True)


if __name__ == "__main__":
    main()
