"""The s = L end's drift correction at three rates (docs/contact.md § 1,
``ProblemAssembly.DRIFT_STEP_FLOOR``): g / max(h, f·Δt) with the floor f = 1/100, 1/4
(the code's) and 1. Below the floor a cut step prescribes the floor's end velocity; above
it the rate g/h prescribes a new one, up to 1/f times the uncut step's. Printed per
floor, the energy check at its default unless said:

* the plectoneme of tests/solver/test_contact_run.py (N = 25, Δt = 0.1 s, ρ∞ = 0.5): status,
  the held end's largest distance from its axis, and after the collapse (t > 7.5 s);
* PyElastica's plectoneme (benchmarks/peer_compare.py's case, N = 25, Δt = 0.1 s, to
  12 s) at the default ρ∞ and at ρ∞ = 0.8: status, Newton iterations, and the relative
  L1 error of its writhe history against hockle's N = 100, Δt = 0.0125-s run
  (:func:`peer_compare.wr_error`);
* the seed example (cases/goyal-writhing.yaml): status, Newton iterations, refused
  attempts, |Wr| at 20, 25, 30 and 45 s, events;
* cases/seabed-hockle.yaml to 10 s with and without the check, and without the seabed's
  friction: status (where a failed run stops), Newton iterations, refused attempts, |Wr|
  at the end, the carried end's largest distance from its prescribed motion
  (``end_drift``) and the largest seabed reaction per unit length;
* (``profile``, at the code's rate only) where along cases/seabed-hockle.yaml the route
  differences that make its end drift arise: each accepted step's difference between the
  time route and the centreline integrated from κ, summed from 3.8 to 4.0 s, at a few
  arclengths;
* (``soft``, at the code's rate only) the case and its frictionless variant on a bottom
  50 times softer (6e4 Pa: MoorDyn's default kBot times the cable's diameter).

Run: ``PYTHONPATH=$PWD python -m research.drift_rate [--only held,pyelastica,seed,hockle,profile,soft]``
``[--set FIELD=VALUE]`` (a field of PyElastica's plectoneme, repeatable)
(about 8 minutes alone on 2 cores; counts and answers, the wall times only indicative).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
from benchmarks import peer_compare as pc
from benchmarks.contact_suite import with_sets
from hockle.plots import run_events
from solver.case import Case
from solver.simulation import SolverDivergence, integrate
from solver.step_problem import ProblemAssembly

#: DRIFT_STEP_FLOOR values compared: the floor at Δt/100, Δt/4 (the code's) and Δt
FLOORS = (0.01, 0.25, 1.0)


def _run(spec):
    """(dataset, status, wall s) of a case spec (dict); a failed run's partial result."""
    t0 = time.perf_counter()
    try:
        ds, status = integrate(Case.model_validate(spec)), "completed"
    except SolverDivergence as exc:
        ds, status = exc.partial, f"failed at t = {exc.t:.4g} s"
    return ds, status, time.perf_counter() - t0


def _newton(ds) -> int:
    return int(ds.step_newton_iterations.values.sum())


def held(floor: float) -> str:
    from test_contact_run import _end_offset, plectoneme_case
    ds, status, wall = _run(plectoneme_case(25, 0.1).model_dump(mode="json"))
    t, off = ds.time.values, _end_offset(ds)
    return (f"plectoneme, N = 25, Δt = 0.1 s, ρ∞ = 0.5: {status}, held end at most "
            f"{off.max() * 1e3:.1f} mm from its axis, {off[t > 7.5].max() * 1e3:.1f} mm "
            f"after 7.5 s; {_newton(ds)} Newton iterations")


def seed(floor: float) -> str:
    spec = Case.from_file(ROOT / "cases" / "goyal-writhing.yaml").model_dump(mode="json")
    ds, status, wall = _run(spec)
    t, wr = ds.time.values, np.abs(ds.writhe.values)
    at = " / ".join(f"{np.interp(x, t, wr):.4f}" for x in (20.0, 25.0, 30.0, 45.0))
    ev = {k: (round(float(t[v]), 1) if v is not None else None)
          for k, v in run_events(ds).items()}
    return (f"seed example: {status}, {_newton(ds)} Newton iterations, refused "
            f"{ds.attrs['hockle_refused_attempts']}; |Wr| at 20/25/30/45 s {at}; "
            f"events {ev}; wall {wall:.1f} s")


def _end_figures(ds) -> str:
    """The carried end's largest distance from its prescribed motion (``end_drift``) and
    the largest seabed normal reaction per unit length, with where and when; the s = L
    end's largest and median reaction force; the run's
    events (:func:`hockle.plots.run_events`), largest writhe and smallest bend radius."""
    t, drift = ds.time.values, ds.end_drift.values
    i = int(np.nanargmax(drift))
    force = np.linalg.norm(ds.seabed_force.values, axis=2)
    k, j = np.unravel_index(int(np.argmax(force)), force.shape)
    radius = ds.bend_radius_min.values
    reaction = np.linalg.norm(ds.reaction_force_end.values, axis=1)
    m = int(np.nanargmax(reaction))
    ev = {name: round(float(t[at]), 2) for name, at in run_events(ds).items()
          if at is not None}
    return (f"end drift at most {drift[i] * 1e3:.1f} mm (t = {t[i]:.1f} s), seabed reaction "
            f"at most {force[k, j]:.0f} N/m (s = {ds.s.values[j]:.2f} m, t = {t[k]:.1f} s), "
            f"s = L reaction at most {reaction[m]:.0f} N (t = {t[m]:.1f} s, median "
            f"{np.nanmedian(reaction):.1f} N); events {ev}, Wr at most {np.nanmax(ds.writhe.values):.2f}, bend radius at "
            f"least {np.nanmin(radius):.4f} m (t = {t[np.nanargmin(radius)]:.1f} s)")


def hockle(floor: float) -> list[str]:
    out = []
    for variant in ("default", "check off", "frictionless"):
        spec = Case.from_file(ROOT / "cases" / "seabed-hockle.yaml").model_dump(mode="json")
        if variant == "check off":
            spec["numerics"]["energy_tolerance"] = None
        if variant == "frictionless":
            spec["seabed"]["friction"] = None
        ds, status, wall = _run(spec)
        out.append(f"seabed-hockle.yaml to 10 s, {variant}: "
                   f"{status}, {_newton(ds)} Newton iterations, refused "
                   f"{ds.attrs['hockle_refused_attempts']}, |Wr| at the end "
                   f"{abs(float(ds.writhe.values[-1])):.4f}; {_end_figures(ds)}; "
                   f"wall {wall:.1f} s")
    return out


def profile(t0: float = 3.8, t1: float = 4.0) -> list[str]:
    """Where along the rod ``seabed-hockle.yaml``'s route differences arise: each accepted
    step's difference between the time route (every node advanced in time from the
    carried pose) and the new centreline integrated from κ, summed over the steps from t0
    to t1 (s), at a few arclengths (the drift the end correction must take back)."""
    from solver.run import RodRun

    steps = []
    accept = RodRun._accept

    def recording(run, prob, sol, summary, timed):
        if t0 <= run.state.t <= t1 and not prob.restart:
            r_time = run.assembly._time_step(run.state, prob.h, sol.Y, run.state.q, run.state.r, run.state.v_global)[3]
            steps.append(r_time - sol.pose[2])
        return accept(run, prob, sol, summary, timed)

    case = Case.from_file(ROOT / "cases" / "seabed-hockle.yaml")
    RodRun._accept = recording
    try:
        integrate(case, observer=lambda run, step: run.state.t > t1)
    finally:
        RodRun._accept = accept
    total = np.linalg.norm(np.sum(steps, axis=0), axis=1)
    s = np.linspace(0.0, case.rod.length, total.size)
    at = ", ".join(f"{x:g} m {np.interp(x, s, total) * 1e3:.2f} mm"
                   for x in (1.0, 2.0, 3.0, 3.25, 3.5, 3.75, 4.0))
    return [f"seabed-hockle.yaml, {len(steps)} steps from {t0:g} to {t1:g} s: summed route "
            f"difference (time route − integrated centreline) at s = {at}"]


def soft() -> list[str]:
    """``seabed-hockle.yaml`` and its frictionless variant on a bottom 50 times softer,
    k = 6e4 Pa: MoorDyn's default kBot = 3e6 Pa/m times the cable's 2-cm diameter (the
    case's 3e6 Pa is that default times 1 m): status, Newton iterations, the largest end
    drift and seabed reaction, wall."""
    out = []
    for variant in ("soft bottom", "soft bottom, frictionless"):
        spec = Case.from_file(ROOT / "cases" / "seabed-hockle.yaml").model_dump(mode="json")
        spec["seabed"]["normal_stiffness"] = 6.0e4
        if variant.endswith("frictionless"):
            spec["seabed"]["friction"] = None
        ds, status, wall = _run(spec)
        out.append(f"seabed-hockle.yaml to 10 s, {variant} (6e4 Pa): {status}, "
                   f"{_newton(ds)} Newton iterations, refused "
                   f"{ds.attrs['hockle_refused_attempts']}; {_end_figures(ds)}; "
                   f"wall {wall:.1f} s")
    return out


_REFERENCE = {}


#: ``--set FIELD=VALUE`` items applied to PyElastica's plectoneme (as contact_suite.py's)
SETS: list = []


def pyelastica(floor: float) -> list[str]:
    if not _REFERENCE:
        ref = pc.run_hockle(100, 0.0125, 12.0)
        _REFERENCE.update(t=ref["t"], wr=pc.post(ref)["Wr"])
    out = []
    for rho in (None, 0.8):
        spec = with_sets(pc.hockle_case(25, 0.1, 12.0).model_dump(mode="json"), SETS)
        if rho is not None:
            spec["numerics"]["rho_inf"] = rho
        ds, status, wall = _run(spec)
        run = {"t": ds.time.values, "pos": ds.position.values,
               "finite": bool(np.isfinite(ds.position.values).all())
               and status == "completed"}
        err = pc.wr_error(run["t"], pc.post(run)["Wr"], _REFERENCE["t"], _REFERENCE["wr"])
        out.append(f"PyElastica's plectoneme, N = 25, Δt = 0.1 s, ρ∞ "
                   f"{spec['numerics']['rho_inf']}: {status}, {_newton(ds)} Newton "
                   f"iterations, Wr history {err * 100:.1f} % (L1) off the N = 100 run")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="held,pyelastica,seed,hockle,profile,soft")
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="a field of PyElastica's plectoneme for its runs (e.g. "
                    "numerics.backward_euler_retry=true); repeatable")
    args = ap.parse_args()
    names = args.only.split(",")
    SETS[:] = args.set
    for name, rows in (("profile", profile), ("soft", soft)):
        if name in names:
            for row in rows():
                print(row, flush=True)
    original = ProblemAssembly.DRIFT_STEP_FLOOR
    try:
        for name in ("held", "pyelastica", "seed", "hockle"):
            if name not in names:
                continue
            for floor in FLOORS:                 # the two rates interleaved per case
                ProblemAssembly.DRIFT_STEP_FLOOR = floor
                rows = {"held": held, "seed": seed, "hockle": hockle,
                        "pyelastica": pyelastica}[name](floor)
                for row in [rows] if isinstance(rows, str) else rows:
                    print(f"floor {floor:g} Δt: {row}", flush=True)
    finally:
        ProblemAssembly.DRIFT_STEP_FLOOR = original


if __name__ == "__main__":
    main()
