"""The centreline scheme beside the seed paper's, on the cases both take
(``numerics.formulation``; docs/numerics.md § 9 quotes what this prints).

Sections (``--only`` picks some):

* ``time``: the order study's tip case (a cantilever in water whose base swings through
  about a radian about a normal and twists, tests/solver/test_convergence_order.py), the
  final positions at Δt = 1/40 ... 1/320 s against 1/1280 s on 40 segments, per scheme;
* ``space``: the same on 10 ... 80 segments against 320 at Δt = 1/200 s;
* ``galilean``: the pendulum pinned at s = 0 and the same pendulum towed at constant
  velocity from a start moving with it, the largest distance between the towed one and
  the pinned one moved along (exactly zero in the continuum);
* ``seed``: the seed example without self-contact over its first ``--seed-end`` seconds
  (the twisting before the first contact): wall time and Newton iterations of each
  scheme, run alternately ``--repeat`` times (medians), and where the two centrelines end.
* ``hockle``: ``cases/seabed-hockle.yaml`` without its ``contact`` block on the centreline
  scheme (the seed's scheme needs the contact the case has): how far towards 4.5 s it runs
  on 160/320/640 segments at Δt 0.05/0.025/0.0125 s, on 160 at 0.025 and 320 at 0.05 (Δs
  and Δt apart), and on 160 at 0.025 s with the friction coefficients 1 % higher; when
  the MBR is crossed; how far the held end strays from its path, the bottom's reaction
  at its node and the largest over the last ``NEAR_END`` of the cable (N) beside the
  cable's submerged weight there; the largest distance between these centrelines and the finest
  grid's (and between the two frictions) at 1.1 ... 3 s; and the largest speed of the
  cable resting on the bottom in its first 0.15 s at Δt 0.0125 s, ρ∞ 0.5 and 0,
  frictionless (the sea floor's chatter).

* ``seedfull``: the seed example as it is, with its contact, 0-45 s, each scheme once
  (the seed's first): wall time, Newton iterations, refused attempts, the first contact,
  Wr at 20, 30 and 45 s and the largest |Lk − Tw − Wr|.

* ``touchdown``: ``cases/catenary-touchdown.yaml`` as it is (0-20 s), the schemes
  alternately, twice (the first to compile): wall time, refused attempts, the suspended
  length L − s_touchdown against the catenary's √(h² + 2ah), a = H/w, at its first
  defined output, its largest relative distance while H ramps and at the end, and how far
  the touchdown walks along the cable.

* ``plectoneme``: PyElastica's plectoneme (benchmarks/pyelastica_compare.py, its contact),
  0-9 s, on 25 segments at Δt 0.1 and 0.05 s and 50 at 0.05 s, each scheme in turn (a
  first run to compile, then the timed one): wall time, refused attempts, the first
  contact, Wr at 9 s, the largest |Tw + Wr − Lk| and the smallest surface gap.

* ``control``: error-controlled steps (``numerics.tolerance``, relative = absolute) on
  the tip case at 1e-2, 1e-3 and 1e-4, the schemes alternately: accepted steps, refused
  attempts, wall time and the final positions' largest error (against each scheme's
  fixed-step 1/1280 s run) over the tip's 0.4 m travel; then ``cases/seabed-hockle.yaml``
  to 10 s on the centreline scheme at relative 1e-3, absolute 1e-4 (the state every
  0.05 s) beside its fixed 0.05-s steps: wall time, accepted steps, median step, refused
  attempts, Wr at 10 s.

Each line says the machine's load (1-min load average) at the start. Run from the
repository's root: ``python -m benchmarks.centreline_compare [--only time space ...]``.
"""
from __future__ import annotations

import argparse
import math
import os
import statistics
import time
from pathlib import Path

import numpy as np

from solver.case import Case
from solver.simulation import integrate

ROOT = Path(__file__).resolve().parents[1]
SCHEMES = ("goyal", "centreline")
FLUID = {"density": 1000.0, "added_mass_coefficient": 1.0,
         "drag_coefficient_normal": 1.0, "drag_coefficient_tangential": 0.05}
ROD = {"length": 1.0, "youngs_modulus": 1.25e7, "shear_modulus": 5.0e6,
       "density": 1500.0, "diameter": 0.02}
FREE = {"translation": [{"force": 0.0}] * 3, "rotation": [{"moment": 0.0}] * 3}


def _pulse(amplitude, duration=1.0, n=401):
    t = np.linspace(0.0, duration, n)
    return {"t": t.tolist(), "value": (amplitude * np.sin(np.pi * t / duration) ** 2).tolist()}


def tip_case(n_segments: int, dt: float, formulation: str, rho_inf: float = 0.5) -> Case:
    """The order study's case on ``formulation``."""
    start = {"translation": [{"velocity": 0.0}] * 3,
             "rotation": [{"angular_velocity": _pulse(2.0)}, {"angular_velocity": 0.0},
                          {"angular_velocity": _pulse(1.0)}]}
    spec = {"schema_version": 1, "name": "tip", "rod": ROD, "fluid": FLUID,
            "boundary": {"start": start, "end": FREE},
            "numerics": {"n_segments": n_segments, "dt": dt, "t_end": 1.0,
                         "rho_inf": rho_inf, "formulation": formulation,
                         "newton": {"tolerance": 1e-12, "max_iterations": 30}},
            "output": {"every": max(1, round(1.0 / dt)), "fields": ["position"]}}
    return Case.model_validate(spec)


def _final(case) -> np.ndarray:
    ds = integrate(case)
    if ds.attrs["hockle_status"] != "completed":
        raise RuntimeError(ds.attrs.get("hockle_message", "run failed"))
    return ds.position.isel(time=-1).values


def _order(steps, errors) -> float:
    return float(np.polyfit(np.log(steps), np.log(errors), 1)[0])


def _load() -> str:
    return f"load {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores"


def section_time():
    print(f"time order, tip case, 40 segments, rho_inf 0.5 ({_load()})")
    dts = [1 / 40, 1 / 80, 1 / 160, 1 / 320]
    refs = {f: _final(tip_case(40, 1 / 1280, f)) for f in SCHEMES}
    errors = {f: [] for f in SCHEMES}
    for dt in dts:                                     # the schemes alternately
        for f in SCHEMES:
            errors[f].append(float(np.abs(_final(tip_case(40, dt, f)) - refs[f]).max()))
    for f in SCHEMES:
        print(f"  {f:10s} errors (m) " + " ".join(f"{e:.3g}" for e in errors[f])
              + f"   order {_order(dts, errors[f]):.2f}")


def section_space():
    print(f"space order, tip case, dt 1/200 s, rho_inf 0.5 ({_load()})")
    ns = [10, 20, 40, 80]
    refs = {f: _final(tip_case(320, 1 / 200, f)) for f in SCHEMES}
    errors = {f: [] for f in SCHEMES}
    for n in ns:
        for f in SCHEMES:
            got = _final(tip_case(n, 1 / 200, f))
            errors[f].append(float(np.abs(got - refs[f][:: 320 // n]).max()))
    for f in SCHEMES:
        print(f"  {f:10s} errors (m) " + " ".join(f"{e:.3g}" for e in errors[f])
              + f"   order {_order([1 / n for n in ns], errors[f]):.2f}")


def _pendulum(V, dt, formulation, n=10):
    """A 1-m rod pinned at s = 0 (frame global, free to turn) under gravity 0.5 rad off
    its axis, the pin moving at V from a start moving with it."""
    from solver.initial import StartState, initial_pose
    from solver.kinematics import quat_to_matrix

    spec = {"schema_version": 1, "name": "pendulum", "rod": ROD,
            "gravity": [9.81 * math.sin(0.5), 0.0, 9.81 * math.cos(0.5)],
            "boundary": {"start": {"frame": "global",
                                   "translation": [{"velocity": float(x)} for x in V],
                                   "rotation": [{"moment": 0.0}] * 3}, "end": FREE},
            "numerics": {"n_segments": n, "dt": dt, "t_end": 1.0, "formulation": formulation,
                         "newton": {"tolerance": 1e-10}},
            "output": {"fields": ["position"]}}
    case = Case.model_validate(spec)
    q, r, _ = initial_pose(case, np.linspace(0.0, 1.0, n + 1))
    v = np.einsum("nji,j->ni", quat_to_matrix(q), np.asarray(V, float))
    zero = np.zeros((n + 1, 3))
    ds = integrate(case, start=StartState(t=0.0, v=v, omega=zero, f=zero.copy(),
                                          kappa=zero.copy(), q=q, r=r))
    return ds.time.values, ds.position.values


def section_galilean():
    print(f"galilean: towed minus pinned pendulum moved along, 10 segments ({_load()})")
    V = np.array([0.7, -0.3, 0.2])
    for dt in (0.02, 0.01):
        line = []
        for f in SCHEMES:
            t, pinned = _pendulum(np.zeros(3), dt, f)
            _, towed = _pendulum(V, dt, f)
            gap = float(np.abs(towed - t[:, None, None] * V - pinned).max())
            line.append(f"{f} {gap:.3g} m")
        print(f"  dt {dt:g} s: " + ", ".join(line))


def section_seed(seed_end: float, repeat: int):
    print(f"seed example without contact, 0-{seed_end:g} s, 1000 segments, dt 0.1 s "
          f"({_load()})")
    spec = Case.from_file(ROOT / "cases" / "goyal-writhing.yaml").model_dump(mode="json")
    spec["contact"] = None
    spec["numerics"]["t_end"] = seed_end
    spec["output"] = {"every": 1, "fields": ["position", "kappa", "topology"]}
    walls = {f: [] for f in SCHEMES}
    results = {}
    for _ in range(repeat):
        for f in SCHEMES:
            spec["numerics"]["formulation"] = f
            case = Case.model_validate(spec)
            t0 = time.perf_counter()
            ds = integrate(case)
            walls[f].append(time.perf_counter() - t0)
            results[f] = ds
    for f in SCHEMES:
        ds = results[f]
        its = int(ds["step_newton_iterations"].sum())
        print(f"  {f:10s} wall {statistics.median(walls[f]):6.2f} s (median of {repeat}), "
              f"Newton iterations {its}, Tw {float(ds.twist[-1]):.6f}, "
              f"Wr {float(ds.writhe[-1]):.3g}, Lk - Tw - Wr "
              f"{float(ds.topology_error[-1]):.2g}")
    a, b = (results[f].position.values[-1] for f in SCHEMES)
    print(f"  the two centrelines at {seed_end:g} s apart by {np.abs(a - b).max():.3g} m")


SNAP_TIMES = (1.1, 1.25, 1.5, 2.0, 3.0)
#: the length at the held end (m) over which the hockle rows sum the bottom's reaction
NEAR_END = 0.1


def _hockle_run(n, dt, t_end, rho_inf=None, friction=True, friction_scale=1.0):
    """The hockle case without contact on the centreline scheme on n segments, stepped
    by dt to t_end (s), the friction coefficients times ``friction_scale``: (the time
    reached, the largest node speed on the way (m/s), the first time the smallest bend
    radius is below the case's MBR (s, None: never), the reason it stopped or None, the
    run's Newton refusals, {t: the centreline (161, 3) m at the 160-segment grid's nodes}
    at SNAP_TIMES, (the largest distance of the held end from its prescribed position (m),
    the largest bottom reaction at the held end's node (N/m), the largest reaction over
    the last NEAR_END of the cable (N), the time of that, the cable's submerged weight
    (N/m)), over the steps)."""
    from solver.centreline_run import CentrelineRun
    from solver.kinematics import min_bend_radius
    from solver.stepping.control import SolverDivergence

    spec = Case.from_file(ROOT / "cases" / "seabed-hockle.yaml").model_dump(mode="json")
    spec["contact"] = None
    spec["numerics"].update(formulation="centreline", n_segments=n, dt=dt, t_end=t_end)
    spec["numerics"].pop("ds", None)
    if rho_inf is not None:
        spec["numerics"]["rho_inf"] = rho_inf
    if not friction:
        spec["seabed"]["friction"] = None
    else:
        for key in ("axial", "lateral"):
            spec["seabed"]["friction"][key] *= friction_scale
    case = Case.model_validate(spec)
    run = CentrelineRun(case)
    fastest, reason, crossed, snaps = 0.0, None, None, {}
    near = run.props.s >= case.rod.length - NEAR_END - 1e-12
    # the trapezoid's weights of the last NEAR_END (its first node a half cell)
    w = np.where(near, run.props.quad_weights, 0.0)
    w[np.argmax(near)] = 0.5 * case.rod.length / n
    weight = ((case.rod.density - case.fluid.density) * np.pi * case.rod.diameter ** 2 / 4
              * float(np.linalg.norm(case.gravity)))          # submerged, N/m
    ends = [0.0, 0.0, 0.0, math.nan, weight]
    for k in range(1, int(round(t_end / dt)) + 1):
        try:
            run.advance(k * dt)
        except SolverDivergence as exc:
            reason = str(exc)
            break
        fastest = max(fastest, float(np.abs(run.level.X[:, 0:3]).max()))
        normal = run.seabed_loads()[0][:, 2]
        held = run.rod.problem(run.state.t).end.position
        ends[0] = max(ends[0], float(np.abs(run.level.Y[-1, 0:3] - held).max()))
        ends[1] = max(ends[1], abs(float(normal[-1])))
        if float(w @ normal) > ends[2]:
            ends[2], ends[3] = float(w @ normal), run.state.t
        radius, _ = min_bend_radius(run.state.Y[:, 9:12], run.props.s)
        if crossed is None and radius < case.rod.minimum_bend_radius:
            crossed = run.state.t
        for ts in SNAP_TIMES:
            if abs(run.state.t - ts) < 1e-9:
                snaps[ts] = run.level.Y[:: n // 160, 0:3].copy()
    return (run.state.t, fastest, crossed, reason, sum(run.control.refusals.values()),
            snaps, ends)


def section_hockle():
    print(f"hockle case without contact on the centreline scheme ({_load()})")
    grids = ((160, 0.05, 1.0), (320, 0.025, 1.0), (640, 0.0125, 1.0), (160, 0.025, 1.0),
             (320, 0.05, 1.0), (160, 0.025, 1.01))
    snaps = {}
    for n, dt, mu in grids:
        t0 = time.perf_counter()
        t, _, crossed, reason, refused, snaps[n, dt, mu], ends = _hockle_run(
            n, dt, 4.5, friction_scale=mu)
        when = "never" if crossed is None else f"at {crossed:.4g} s"
        print(f"  {n} segments, dt {dt:g} s, friction x {mu:g}, to 4.5 s: reached "
              f"t = {t:.4g} s, MBR crossed {when}, {refused} Newton refusals, "
              f"wall {time.perf_counter() - t0:.1f} s; {reason or 'completed'}; held end "
              f"off its path by at most {ends[0]:.2g} m, its node's bottom reaction at "
              f"most {ends[1]:.3g} N/m, the last {NEAR_END:g} m's at most {ends[2]:.3g} N "
              f"(at {ends[3]:.3g} s; the cable's submerged weight there "
              f"{NEAR_END * ends[4]:.3g} N)")
    print("  largest distance between centrelines (mm) at t = "
          + ", ".join(f"{t:g}" for t in SNAP_TIMES) + " s:")
    pairs = [((n, dt, mu), (640, 0.0125, 1.0)) for n, dt, mu in grids[:2] + grids[3:5]]
    pairs.append(((160, 0.025, 1.01), (160, 0.025, 1.0)))
    for a, b in pairs:
        got = [float(np.abs(snaps[a][t] - snaps[b][t]).max()) * 1e3
               if t in snaps[a] and t in snaps[b] else math.nan for t in SNAP_TIMES]
        print(f"    {a[0]}/{a[1]:g}/x{a[2]:g} - {b[0]}/{b[1]:g}/x{b[2]:g}: "
              + " ".join(f"{x:.3g}" for x in got))
    for rho in (0.5, 0.0):
        t, fastest, _, reason, _, _, _ = _hockle_run(160, 0.0125, 0.15, rho,
                                                     friction=False)
        print(f"  160 segments, dt 0.0125 s, rho_inf {rho:g}, no friction, resting "
              f"0-0.15 s: largest speed {fastest:.3g} m/s, reached t = {t:.4g} s"
              + (f" ({reason})" if reason else ""))


def _plectoneme(n, dt, formulation):
    """PyElastica's plectoneme (benchmarks/pyelastica_compare.py) on ``formulation``: (wall s, the run's
    status, refused attempts, first contact s, Wr at 9 s, largest |Tw + Wr − Lk|, the
    smallest surface gap m)."""
    from benchmarks.pyelastica_compare import hockle_plectoneme_case

    spec = hockle_plectoneme_case(n, dt, 9.0, out_dt=dt).model_dump(mode="json")
    spec["numerics"]["formulation"] = formulation
    case = Case.model_validate(spec)
    t0 = time.perf_counter()
    ds = integrate(case)
    wall = time.perf_counter() - t0
    touching = ds.contact_count.values > 0
    first = float(ds.time.values[np.argmax(touching)]) if touching.any() else math.nan
    return (wall, ds.attrs["hockle_status"], ds.attrs.get("hockle_refused_attempts", ""),
            first, float(ds.writhe.values[-1]), float(ds.topology_error.max()),
            float(ds.min_surface_gap.min()))


def section_plectoneme():
    print(f"PyElastica's plectoneme with self-contact, 0-9 s, the schemes alternately "
          f"({_load()})")
    for n, dt in ((25, 0.1), (25, 0.05), (50, 0.05)):
        for f in SCHEMES:
            _plectoneme(n, dt, f)                      # compiled and cached first
            wall, status, refused, first, wr, topo, gap = _plectoneme(n, dt, f)
            print(f"  {n} segments, dt {dt:g} s, {f:10s}: {status}, wall {wall:.2f} s, "
                  f"first contact {first:.2f} s, Wr(9 s) {wr:.3f}, |Tw+Wr-Lk| <= {topo:.3g}, "
                  f"smallest gap {gap * 1e3:.3g} mm; refused: {refused}")


def section_seedfull():
    print(f"the seed example as it is (cases/goyal-writhing.yaml, contact, 0-45 s), the "
          f"schemes alternately ({_load()})")
    spec = Case.from_file(ROOT / "cases" / "goyal-writhing.yaml").model_dump(mode="json")
    for f in SCHEMES:
        spec["numerics"]["formulation"] = f
        case = Case.model_validate(spec)
        t0 = time.perf_counter()
        ds = integrate(case)
        wall = time.perf_counter() - t0
        t = ds.time.values
        touching = ds.contact_count.values > 0
        first = float(t[np.argmax(touching)]) if touching.any() else math.nan
        wr = [float(ds.writhe.sel(time=x, method="nearest")) for x in (20.0, 30.0, 45.0)]
        print(f"  {f:10s} {ds.attrs['hockle_status']}, wall {wall:.1f} s, Newton iterations "
              f"{int(ds['step_newton_iterations'].sum())}, refused: "
              f"{ds.attrs.get('hockle_refused_attempts')}, first contact {first:.2f} s, "
              f"Wr at 20/30/45 s {wr[0]:.4f} / {wr[1]:.4f} / {wr[2]:.4f}, largest "
              f"|Lk - Tw - Wr| {float(np.nanmax(ds.topology_error.values)):.2g} ({_load()})")


def section_touchdown():
    print(f"cases/catenary-touchdown.yaml (0-20 s), the schemes alternately ({_load()})")
    spec = Case.from_file(ROOT / "cases" / "catenary-touchdown.yaml").model_dump(mode="json")
    w = 500.0 * np.pi * 0.01 ** 2 * 9.81          # submerged weight, N/m
    for repeat in range(2):
        for f in SCHEMES:
            spec["numerics"]["formulation"] = f
            t0 = time.perf_counter()
            ds = integrate(Case.model_validate(spec))
            wall = time.perf_counter() - t0
            if repeat == 0:
                continue                                # compiled and cached first
            t = ds.time.values
            H = 1.0 + 2.0 * np.clip(t - 2.0, 0.0, 10.0) / 10.0
            suspended = 4.0 - ds["seabed_touchdown"].values
            catenary = np.sqrt(1.0 + 2.0 * H / w)
            off = suspended / catenary - 1.0
            i = int(np.flatnonzero(np.isfinite(suspended))[0])
            print(f"  {f:10s} {ds.attrs['hockle_status']}, wall {wall:.1f} s, refused: "
                  f"{ds.attrs.get('hockle_refused_attempts') or 'none'}; suspended {suspended[i]:.3f} m "
                  f"at {t[i]:g} s against {catenary[i]:.3f} m, largest off "
                  f"{100 * np.nanmax(np.abs(off)):.1f} %, at 20 s {suspended[-1]:.3f} against "
                  f"{catenary[-1]:.3f} m ({100 * off[-1]:.2f} %), the touchdown walks "
                  f"{suspended[-1] - suspended[i]:.2f} m ({_load()})")


def section_control():
    print(f"error-controlled steps, tip case, 40 segments, rho_inf 0.5 ({_load()})")
    refs = {f: _final(tip_case(40, 1 / 1280, f)) for f in SCHEMES}
    for tol in (1e-2, 1e-3, 1e-4):
        for f in SCHEMES:                               # the schemes alternately
            spec = tip_case(40, 0.01, f).model_dump(mode="json")
            spec["numerics"]["tolerance"] = {"relative": tol, "absolute": tol}
            t0 = time.perf_counter()
            ds = integrate(Case.model_validate(spec))
            wall = time.perf_counter() - t0
            err = float(np.abs(ds.position.isel(time=-1).values - refs[f]).max()) / 0.4
            print(f"  tolerance {tol:g}, {f:10s}: {ds.sizes['step']} steps, refused: "
                  f"{ds.attrs.get('hockle_refused_attempts') or 'none'}, wall {wall:.2f} s, "
                  f"error {err:.3g} of the travel")
    print(f"cases/seabed-hockle.yaml to 10 s, centreline, fixed 0.05-s steps and "
          f"tolerance 1e-3/1e-4 ({_load()})")
    base = Case.from_file(ROOT / "cases" / "seabed-hockle.yaml").model_dump(mode="json")
    base["numerics"]["formulation"] = "centreline"
    for controlled in (False, True):
        spec = {**base, "numerics": dict(base["numerics"]), "output": dict(base["output"])}
        if controlled:
            spec["numerics"]["tolerance"] = {"relative": 1e-3, "absolute": 1e-4}
            spec["output"].pop("every", None)
            spec["output"]["interval"] = 0.05
        t0 = time.perf_counter()
        ds = integrate(Case.model_validate(spec))
        wall = time.perf_counter() - t0
        dt = ds.step_dt.values
        print(f"  {'tolerance' if controlled else 'fixed':9s}: {ds.attrs['hockle_status']}, "
              f"wall {wall:.1f} s, {dt.size} steps, median {1e3 * np.median(dt):.3g} ms, "
              f"refused: {ds.attrs.get('hockle_refused_attempts') or 'none'}, Wr at 10 s "
              f"{float(ds.writhe[-1]):.4f} ({_load()})")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", nargs="+",
                    choices=["time", "space", "galilean", "seed", "seedfull", "hockle",
                             "touchdown", "plectoneme", "control"],
                    default=["time", "space", "galilean", "seed", "seedfull", "hockle",
                             "touchdown", "plectoneme", "control"])
    ap.add_argument("--seed-end", type=float, default=8.0, help="s (default 8)")
    ap.add_argument("--repeat", type=int, default=3, help="seed runs per scheme (default 3)")
    args = ap.parse_args(argv)
    for name in args.only:
        if name == "seed":
            section_seed(args.seed_end, args.repeat)
        else:
            globals()[f"section_{name}"]()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
