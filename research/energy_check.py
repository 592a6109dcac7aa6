"""The energy check's evidence on the cases that argue for and against its default
(docs/numerics.md § 8, ``numerics.energy_tolerance``, on by default at 0.5), printed:

* the soft hanging cable of research/loads_verification.py with the check at the
  default tolerance and without, at several Δt: status, refusals, settled sag against
  the catenary, the κ-integrated centreline's held end against its hold;
* the cable resting on a flat bottom (tests/solver/test_seabed.py's 2-cm cable, touching at the
  start) at Δt = 1e-4 s over 0.05 s: refusals and the largest ε/scale;
* the seabed cases cases/catenary-touchdown.yaml (to 20 s) and cases/seabed-hockle.yaml
  (to 1 s) without and with the check, interleaved: refusals, when, and wall time;
* ε summed over 4 steps, the check measuring only, on the cantilever and the cable
  (against STUDY_TOLERANCE);
* Newton's history against the balance on the steel cantilever of
  tests/solver/test_energy_check.py (the check measuring only): whether the steps that inject
  energy (ε > STUDY_TOLERANCE · T) show a Newton that contracts worse than the others;
* self-contact (``contact``): the contact account's −ΔU_c against the contact forces'
  work (trapezoid on the two levels, and along each step's chord) in the crossing loop
  of tests/solver/test_energy_check.py by Δt, both laws; the seed example
  cases/goyal-writhing.yaml to 30 s without and with the check (contact steps measured),
  interleaved: refusals (with and without candidates), the largest ε/scale, events
  (first contact, |Wr| through 1 and 1.5), Wr at 20, 25, 30 s, wall time;
* error control (``--only control``): the cantilever with ``numerics.tolerance`` at
  relative 1e-2 and 1e-3, without the check and at the default;
* the tolerances (``--only tolerances``): the dead-load cantilever (100 segments) and
  the soft hanging cable at several Δt, without the check and at ``energy_tolerance``
  0.05, 0.25, 0.5 and 1: status, the answer (tip x/L against the elastica; sag against
  the catenary and the κ-integrated end from its hold), energy refusals and Newton
  iterations (all attempts);
* the full-length right runs (``--only full``, several minutes): cases/seabed-hockle.yaml
  to 10 s and cases/goyal-writhing.yaml to 45 s without the check and at the default:
  status, where a failed run stops, energy refusals, Newton iterations, |Wr| and the mid
  node at the end, wall time and the check's own share of it (``--only full-seed``: the
  seed example's pair alone);
* what lies behind them (``--only diagnose``, :func:`diagnose`);
* PyElastica's plectoneme (``--only plectoneme``, :func:`plectoneme`, about 75 s): the
  check measuring only, by grid, Δt, ρ∞, ``contact_rho_inf``, the route rule's bound and
  with the s = L end's drift correction on and off, where a run diverges and per window
  the accounts, ε, the end forces' work on the end velocities, ε over the end moments'
  work and the median step.

Run: ``PYTHONPATH=$PWD python -m research.energy_check [--only cable|rest|cases|windows|
newton|contact|control|tolerances|full|full-seed|diagnose|plectoneme]`` (about a minute
each after the kernels are compiled; ``tolerances`` and ``full`` several).
"""
from __future__ import annotations

import argparse
import contextlib
import math
import time
from pathlib import Path

import numpy as np

from research import loads_verification as LV
from research.contact_steps import trace_newton
import test_energy_check as EC
import test_seabed as SB
from hockle.api import catenary_parameter
from solver import balance as B
from solver.case import Case, Numerics
from solver.simulation import RodRun, SolverDivergence, integrate

trace_newton()                  # NewtonSolver.last_trace, which :func:`newton` reads

#: the default tolerance (``numerics.energy_tolerance``)
TOLERANCE = Numerics.model_fields["energy_tolerance"].default
#: the threshold of the windows' and Newton's studies (ε > STUDY_TOLERANCE · T)
STUDY_TOLERANCE = 0.05


def _refused(ds, reason="energy"):
    items = dict(item.rsplit(" ", 1) for item in ds.attrs["hockle_refused_attempts"].split(", ")
                 if item)
    return int(items.get(reason, 0))


def cable():
    L, X = 1.0, 0.8
    a = catenary_parameter(L, X)
    sag = a * (math.cosh(X / (2 * a)) - 1)
    for dt in (0.0125, 0.05, 0.1, 0.2):
        for tol in (None, TOLERANCE):
            spec = LV.catenary_spec(dt, tol)
            spec["output"]["fields"] = ["position", "energies"]
            try:
                ds, status = integrate(Case.model_validate(spec)), "completed"
            except SolverDivergence as exc:
                ds, status = exc.partial, f"failed at t = {exc.partial.time.values[-1]:.4g} s"
            z = ds.position.values[-1, :, 2]
            end = ds.position.values[-1, -1]
            print(f"hanging cable, Δt = {dt:6.4f} s, check {'off' if tol is None else tol}: "
                  f"{status}, {_refused(ds)} energy refusals, sag {(-z.min() / sag - 1) * 100:+.2f} % "
                  f"off the catenary, T at 16 s {float(ds.energy_kinetic.values[-1]):.1e} J, "
                  f"κ-integrated end {np.linalg.norm(end - (X, 0.0, 0.0)) * 1e3:.2f} mm "
                  f"from its hold")


def rest():
    spec = SB._spec({"elevation": -SB.D / 2}, dt=1e-4, t_end=0.05)
    spec["numerics"]["energy_tolerance"] = TOLERANCE
    ds = integrate(Case.model_validate(spec))
    print(f"cable resting on the bottom, Δt = 1e-4 s, 0.05 s: {ds.attrs['hockle_status']}, "
          f"{_refused(ds)} energy refusals, largest ε/scale "
          f"{np.nanmax(ds.step_energy_error.values):.2e}")


def cases():
    root = Path(__file__).resolve().parents[1] / "cases"
    for name, t_end in (("catenary-touchdown.yaml", 20.0), ("seabed-hockle.yaml", 1.0)):
        for tol in (None, TOLERANCE):                     # interleaved, off then on
            spec = Case.from_text((root / name).read_text(), fmt="yaml").model_dump(
                mode="json", exclude_none=True)
            spec["numerics"].update(t_end=t_end, energy_tolerance=tol)
            run = RodRun(Case.model_validate(spec))
            dt, k, t0 = spec["numerics"]["dt"], 0, time.perf_counter()
            refused = []
            while run.state.t < t_end - 1e-9:
                k += 1
                before = run.control.refusals.get("energy", 0)
                t_from = run.state.t
                run.advance(k * dt)
                if run.control.refusals.get("energy", 0) > before:
                    refused.append(t_from)
            wall = time.perf_counter() - t0
            print(f"{name} to {t_end} s, check {'off' if tol is None else tol}: "
                  f"{len(refused) and run.control.refusals['energy']} energy refusals"
                  f"{' (steps from t = ' + ', '.join(f'{t:.4g}' for t in refused) + ' s)' if refused else ''}, "
                  f"{run.control.refusals.get('newton', 0)} Newton refusals, wall {wall:.1f} s")


def windows(m=4):
    """ε summed over m consecutive steps against tol × their largest scale, the check
    measuring only: does a window separate the cantilever's injection from the cable?"""
    def series(case, dt, t_end):
        run = RodRun(case)
        run.advance(dt)
        out = []
        while run.state.t < t_end - 1e-9:
            run.advance(run.state.t + dt)
            out.append((run.last_balance.error, run.last_balance.scale))
        return np.array(out)
    for name, case, dt, t_end in (
            ("cantilever", EC.cantilever(0.1, n=50, energy_tolerance=1e9), 0.1, 8.0),
            ("hanging cable", Case.model_validate(LV.catenary_spec(0.2, 1e9)), 0.2, 16.0)):
        e = series(case, dt, t_end)
        win = np.array([e[i:i + m, 0].sum() / (STUDY_TOLERANCE * e[i:i + m, 1].max())
                        for i in range(len(e) - m + 1)])
        print(f"{name}, Δt = {dt} s: {np.sum(e[:, 0] > STUDY_TOLERANCE * e[:, 1])} of {len(e)} "
              f"steps over the tolerance, {np.sum(win > 1)} of {len(win)} {m}-step windows")


def newton():
    for dt in (0.1, 0.04):
        run = RodRun(EC.cantilever(dt, n=50, energy_tolerance=1e9))   # measures only
        run.advance(dt)
        rows = []
        while run.state.t < 8.0 - 1e-9:
            run.advance(run.state.t + dt)
            res = run.newton.last_trace[:, 0]
            last = res[-1] / res[-2] if res.size > 1 else 0.0
            prev = res[-2] / res[-3] if res.size > 2 else 0.0
            rows.append((run.last_balance.relative, res.size - 1, last, prev))
        r = np.array(rows)
        bad = r[:, 0] > STUDY_TOLERANCE
        print(f"cantilever, Δt = {dt} s, 50 segments, no check: {len(r)} steps, "
              f"{bad.sum()} inject ε > {STUDY_TOLERANCE} T")
        for name, col in (("Newton iterations", 1), ("last contraction", 2),
                          ("contraction before it", 3)):
            print(f"  {name}: injecting steps median {np.median(r[bad, col]):.3g}, "
                  f"max {r[bad, col].max():.3g}; the others median "
                  f"{np.median(r[~bad, col]):.3g}, max {r[~bad, col].max():.3g}")
        slow = r[:, 3] > 0.1
        print(f"  steps whose contraction before the last was > 0.1: {slow.sum()}, "
              f"of them injecting {np.sum(slow & bad)}")


def contact(t_end=30.0):
    print("crossing loop (undamped push-off, to 10 ms): the account's -dU_c against the "
          "contact forces' work")
    for law in ("seed", "barrier"):
        for dt in (2e-4, 1e-4, 5e-5, 2.5e-5):
            booked, trap, chord, n = EC.contact_work_in_run(dt, law, 0.01)
            print(f"  {law:8s} dt {dt:7.1e} s: -dU_c {booked:.5e} J, trapezoid off "
                  f"{(trap - booked) / booked:+.2e}, chord (8-point GL) off "
                  f"{(chord - booked) / booked:+.1e}, {n} steps")
    print(f"seed example to {t_end:g} s (cases/goyal-writhing.yaml), without and with "
          f"energy_tolerance {TOLERANCE} (contact steps measured)")
    from solver import run as runmod
    spec = Case.from_file(Path(__file__).resolve().parents[1] / "cases"
                          / "goyal-writhing.yaml").model_dump(mode="json")
    spec["numerics"]["t_end"] = t_end
    original = runmod.RodRun._refusal
    for rep in range(2):
        for tol in (None, TOLERANCE):
            spec["numerics"]["energy_tolerance"] = tol
            counts = {"free": 0, "contact": 0, "measured": 0}
            worst = {"free": 0.0, "contact": 0.0}
            refused = []

            def refusal(self, prob, sol, estimate):
                reason, summary, ratios = original(self, prob, sol, estimate)
                key = "free" if sol.candidates is None else "contact"
                bal = self.last_balance
                if bal is not None:
                    worst[key] = max(worst[key], bal.relative)
                    counts[key] += reason == "energy"
                    counts["measured"] += key == "contact" and reason is None
                    if reason == "energy" and key == "contact":
                        refused.append((prob.t_new, bal.error, bal.scale,
                                        abs(sum(bal.work.values())),
                                        abs(bal.work["contact"])))
                return reason, summary, ratios

            runmod.RodRun._refusal = refusal
            try:
                start = time.perf_counter()
                ds = integrate(Case.model_validate(spec))
                wall = time.perf_counter() - start
            finally:
                runmod.RodRun._refusal = original
            t, wr, cc = ds.time.values, np.abs(ds.writhe.values), ds.contact_count.values
            first = t[np.argmax(cc > 0)] if (cc > 0).any() else math.nan
            through = [t[np.argmax(wr >= v)] if (wr >= v).any() else math.nan
                       for v in (1.0, 1.5)]
            at = [wr[np.argmin(np.abs(t - v))] for v in (20.0, 25.0, t_end)]
            err = ds.step_energy_error.values if "step_energy_error" in ds else np.zeros(1)
            print(f"  tolerance {tol}: {ds.attrs['hockle_status']}, energy refusals "
                  f"{counts['free']} without candidates, {counts['contact']} with; largest "
                  f"eps/T {worst['free']:.3g} / {worst['contact']:.3g} (accepted "
                  f"{np.nanmax(err):.3g}); first contact "
                  f"{first:.2f} s, |Wr| through 1 at {through[0]:.2f} s, 1.5 at "
                  f"{through[1]:.2f} s; |Wr| at 20/25/{t_end:g} s "
                  + "/".join(f"{v:.4f}" for v in at) + f"; wall {wall:.1f} s")
            if tol is not None:
                e = np.array(refused).reshape(-1, 5)
                print(f"    {counts['measured']} accepted contact steps measured; the refused "
                      f"ones at {e[:, 0].min():.2f}-{e[:, 0].max():.2f} s: eps "
                      f"{e[:, 1].min():.2g}-{e[:, 1].max():.2g} J, T {e[:, 2].min():.2g}-"
                      f"{e[:, 2].max():.2g} J, |sum W| {e[:, 3].min():.2g}-{e[:, 3].max():.2g}"
                      f" J, |contact work| {e[:, 4].min():.2g}-{e[:, 4].max():.2g} J" if len(e)
                      else f"    {counts['measured']} accepted contact steps measured")


TOLERANCES = (None, 0.05, 0.25, 0.5, 1.0)


def _simulate(case):
    """(dataset, status): a failed run's partial result and its last accepted step."""
    try:
        return integrate(case), "completed"
    except SolverDivergence as exc:
        return exc.partial, f"failed after t = {exc.partial.step_time.values[-1]:.4g} s"


def _cost(ds):
    return (f"{_refused(ds)} energy refusals, "
            f"{int(ds.step_newton_iterations.values.sum())} Newton iterations")


def _cantilever_row(dt, tol):
    ds, status = _simulate(EC.cantilever(dt, n=100, energy_tolerance=tol))
    x = ds.position.values[-1, -1, 2] / EC.L
    return (f"cantilever, Δt = {dt:5.3f} s, check {'off' if tol is None else tol}: {status}, "
            f"tip {(x / EC.X_TIP - 1) * 100:+.3f} % off the elastica, {_cost(ds)}")


def _cable_row(dt, tol):
    L, X = 1.0, 0.8
    a = catenary_parameter(L, X)
    sag = a * (math.cosh(X / (2 * a)) - 1)
    spec = LV.catenary_spec(dt, tol)
    spec["output"]["fields"] = ["position", "energies"]
    ds, status = _simulate(Case.model_validate(spec))
    z, end = ds.position.values[-1, :, 2], ds.position.values[-1, -1]
    return (f"hanging cable, Δt = {dt:6.4f} s, check {'off' if tol is None else tol}: {status}, "
            f"sag {(-z.min() / sag - 1) * 100:+.2f} % off the catenary, κ-integrated end "
            f"{np.linalg.norm(end - (X, 0.0, 0.0)) * 1e3:.2f} mm from its hold, {_cost(ds)}")


def control():
    """Error-controlled steps (``numerics.tolerance``, the first step Δt = 0.1 s) on the
    cantilever (100 segments) at relative 1e-2 and 1e-3, without the check and at the
    default: does the error estimate alone catch the injecting steps?"""
    for rel in (1e-2, 1e-3):
        for tol in (None, TOLERANCE):
            ds, status = _simulate(EC.cantilever(0.1, n=100, energy_tolerance=tol,
                                                 tolerance={"relative": rel}))
            x = ds.position.values[-1, -1, 2] / EC.L
            print(f"cantilever, error control relative {rel:g}, check "
                  f"{'off' if tol is None else tol}: {status}, tip "
                  f"{(x / EC.X_TIP - 1) * 100:+.3f} % off the elastica, kinetic energy at "
                  f"8 s {float(ds.energy_kinetic.values[-1]):.2g} J, refused "
                  f"{ds.attrs['hockle_refused_attempts']}, "
                  f"{int(ds.step_newton_iterations.values.sum())} Newton iterations")


def tolerances(tols=TOLERANCES):
    for dt in (0.2, 0.1, 0.05, 0.04, 0.02):
        for tol in tols:
            print(_cantilever_row(dt, tol))
    for dt in (0.2, 0.1, 0.05, 0.0125):
        for tol in tols:
            print(_cable_row(dt, tol))


@contextlib.contextmanager
def energy_share(share):
    """The energy scale's floor at share × (E + U) (``EnergyBalance.ENERGY_SHARE``) for the
    runs inside."""
    floor = B.EnergyBalance.ENERGY_SHARE
    B.EnergyBalance.ENERGY_SHARE = share
    try:
        yield
    finally:
        B.EnergyBalance.ENERGY_SHARE = floor


@contextlib.contextmanager
def timed_check():
    """Time the energy check inside (EnergyBalance.measure, and of it ContactWork.step):
    yields a dict {"check": s, "contact": s, "contact_steps": count}."""
    out = {"check": 0.0, "contact": 0.0, "contact_steps": 0}
    measure, contact = B.EnergyBalance.measure, B.ContactWork.step

    def timed_measure(self, *args):
        t0 = time.perf_counter()
        try:
            return measure(self, *args)
        finally:
            out["check"] += time.perf_counter() - t0

    def timed_contact(self, run, prob, sol, old):
        t0 = time.perf_counter()
        try:
            return contact(self, run, prob, sol, old)
        finally:
            out["contact"] += time.perf_counter() - t0
            out["contact_steps"] += sol.candidates is not None

    B.EnergyBalance.measure, B.ContactWork.step = timed_measure, timed_contact
    try:
        yield out
    finally:
        B.EnergyBalance.measure, B.ContactWork.step = measure, contact


def full(names=("seabed-hockle.yaml", "goyal-writhing.yaml")):
    root = Path(__file__).resolve().parents[1] / "cases"
    for name, tols in ((name, (None, 0.5)) for name in names):
        for tol in tols:
            spec = Case.from_file(root / name).model_dump(mode="json")
            spec["numerics"]["energy_tolerance"] = tol
            start = time.perf_counter()
            with timed_check() as spent:
                ds, status = _simulate(Case.model_validate(spec))
            p = ds.position.values[-1]
            print(f"{name} to {spec['numerics']['t_end']:g} s, check "
                  f"{'off' if tol is None else tol}: {status}, {_cost(ds)}, |Wr| "
                  f"{abs(float(ds.writhe.values[-1])):.4f}, mid node "
                  + "(" + ", ".join(f"{v:.4f}" for v in p[p.shape[0] // 2]) + ") m"
                  + f", wall {time.perf_counter() - start:.0f} s"
                  + (f" (the check {spent['check']:.1f} s, of it the contact account "
                     f"{spent['contact']:.1f} s over {spent['contact_steps']} steps with "
                     f"candidates)" if tol is not None else ""))


def diagnose():
    """The figures behind the default's reading (docs/numerics.md § 8): the cable's
    settling steps at Δt = 0.2 s that the check refuses (ε > 0.5 scale, the check
    measuring only); the floor at 1e-4 and 1e-3 (E + U) at tolerance 0.5; the catenary
    with touchdown without and with the check against a Δt = 3.125-ms reference."""
    def measured(dt, t_end, lo=0.0):
        run = RodRun(Case.model_validate(LV.catenary_spec(dt, 1e9)))    # measures only
        run.advance(dt)
        while run.state.t < t_end - 1e-9:
            run.advance(run.state.t + dt)
            b = run.last_balance
            if run.state.t > lo and b.error > 0.5 * b.scale:
                work = sum(b.work.values())
                print(f"  t = {run.state.t:5.2f} s: ε {b.error:+.2e} J, Σ W {work:+.2e} J, "
                      f"T {b.carry['kinetic']:.1e} J, E {b.energy:.3e} J, "
                      f"ε/scale {b.relative:.2f}")
    print("hanging cable, Δt = 0.2 s, 5-9 s (ε > 0.5 scale):")
    measured(0.2, 9.0, 5.0)
    for share in (1e-4, 1e-3):
        print(f"the floor at {share:g} (E + U), tolerance 0.5:")
        with energy_share(share):
            for dt in (0.1, 0.05, 0.04):
                print("  " + _cantilever_row(dt, 0.5))
            print("  " + _cable_row(0.2, 0.5))
    root = Path(__file__).resolve().parents[1] / "cases"
    spec = Case.from_file(root / "catenary-touchdown.yaml").model_dump(mode="json")
    for dt, tol in ((0.05, None), (0.05, 0.5), (0.003125, None)):
        spec["numerics"].update(dt=dt, energy_tolerance=tol)
        ds = integrate(Case.model_validate(spec))
        p = ds.position.values[-1]
        print(f"catenary-touchdown.yaml, Δt = {dt:g} s, check {'off' if tol is None else tol}: "
              f"{_refused(ds)} energy refusals, mid node x {p[p.shape[0] // 2, 0]:.5f} m")


#: PyElastica's plectoneme (benchmarks/peer_compare.py's case) in :func:`plectoneme`:
#: (segments N, Δt (s), ρ∞, the s = L end's drift correction on, contact_rho_inf,
#: contact.position_tolerance (m; None: the default, a quarter of the search margin,
#: 12.5 mm here))
PLECTONEME_SETTINGS = ((25, 0.1, 0.8, True, None, None), (25, 0.025, 0.8, True, None, None),
                       (25, 0.00625, 0.8, True, None, None),
                       (25, 0.025, 0.8, True, None, 3.75e-5),
                       (25, 0.1, 1.0, True, None, None), (25, 0.025, 0.8, False, None, None),
                       (25, 0.1, 0.5, True, None, None), (25, 0.025, 0.5, True, None, None),
                       (50, 0.05, 0.8, True, None, None), (100, 0.0125, 0.8, True, None, None),
                       (25, 0.1, 0.8, True, 0.0, None), (25, 0.1, 0.8, False, 0.0, None))


def plectoneme_accounts(n, dt, rho_inf, correction=True, contact_rho_inf=None,
                        position_tolerance=None, t_end=12.0):
    """PyElastica's plectoneme (:func:`peer_compare.hockle_case`, N segments, Δt s,
    ``rho_inf``, ``numerics.contact_rho_inf``, ``contact.position_tolerance`` (m), the
    route rule's bound that sizes the contact steps) with the energy check measuring only
    (``energy_tolerance`` 1e9: every converged step's ε measured, none refused) and,
    without ``correction``, the s = L end's drift correction off
    (``ProblemAssembly.DRIFT_GAIN`` None for the run) and its drift unbounded
    (``contact.end_drift_tolerance`` 1 m: the uncorrected end drifts past the 50-mm
    diameter, the default bound, at 7.15 s at N = 25, Δt = 0.1 s).

    Returns (status, rows): status "completed" or "diverged at t = … s"; rows (S, 9)
    over the S accepted steps: t (s), then the step's work (J) of the end moments
    (``ends``), the end forces and the imperfection on the space route (``loads``),
    the contact law (``contact``) and the drag (``drag``), the energy's change ΔE (J),
    ε = ΔE − Σ W (J), the scale T (J), and the end forces' work on the end sections'
    velocities, ½h(f^n·v^n + f^{n+1}·v^{n+1}) summed over both ends (J; the prescribed
    velocities with the drift correction's offsets: what the correction's motion of the
    held end does against its reaction). Read off each accepted step's balance
    (:attr:`solver.run.RodRun.last_balance` when the step is accepted). Raises nothing
    of its own; a run that fails returns its accepted steps."""
    from benchmarks import peer_compare as pcmp
    from solver.energies import end_loads
    from solver.step_problem import ProblemAssembly

    spec = pcmp.hockle_case(n, dt, t_end).model_dump(mode="json")
    spec["numerics"]["rho_inf"] = rho_inf
    spec["numerics"]["contact_rho_inf"] = contact_rho_inf
    spec["contact"]["position_tolerance"] = position_tolerance
    spec["numerics"]["energy_tolerance"] = 1e9
    if not correction:
        spec["contact"]["end_drift_tolerance"] = 1.0
    rows = []
    original, gain = RodRun._accept, ProblemAssembly.DRIFT_GAIN

    def accept(self, prob, sol, summary, timed):
        bal = self.last_balance
        if bal is not None:
            w = bal.work
            old, new = end_loads(self.state.Y, self.props), end_loads(sol.Y, self.props)
            power = [float(np.sum(L[:, :3] * Y[[0, -1], 0:3]))
                     for L, Y in ((old, self.state.Y), (new, sol.Y))]
            total = sum(w.values())
            rows.append((prob.t_new, w.get("ends", 0.0), w.get("loads", 0.0),
                         w.get("contact", 0.0), w.get("drag", 0.0), bal.error + total,
                         bal.error, bal.scale, 0.5 * float(prob.h) * sum(power)))
        return original(self, prob, sol, summary, timed)

    RodRun._accept = accept
    if not correction:
        ProblemAssembly.DRIFT_GAIN = None
    try:
        integrate(Case.model_validate(spec))
        status = "completed"
    except SolverDivergence as exc:
        status = f"diverged at t = {exc.t:.2f} s"
    finally:
        RodRun._accept, ProblemAssembly.DRIFT_GAIN = original, gain
    return status, np.array(rows).reshape(-1, 9)


def plectoneme(settings=PLECTONEME_SETTINGS,
               edges=(0.0, 7.0, 8.0, 9.0, 10.0, 10.75, 11.0, 12.0)):
    """The balance of PyElastica's plectoneme by setting (:func:`plectoneme_accounts`),
    the check measuring only: where a run diverges, and per window of ``edges`` (s) the
    columns of :func:`plectoneme_accounts` summed over its accepted steps (J), the median
    scale T (J), ε over the end moments' work and the median accepted step (ms).
    ``settings``: tuples as :data:`PLECTONEME_SETTINGS`. Prints; returns nothing."""
    print("PyElastica's plectoneme (peer_compare.hockle_case), the check measuring only: "
          "per window the work of each account, dE, eps = dE - sum W (J), median T (J), "
          "the end forces' work on the end velocities (J), eps over the end moments' work "
          "and the median accepted step")
    for n, dt, rho, corr, crho, ptol in settings:
        status, r = plectoneme_accounts(n, dt, rho, corr, crho, ptol)
        steps = np.diff(np.concatenate([[0.0], r[:, 0]]))
        print(f"N = {n}, dt = {dt:g} s, rho_inf = {rho:g}"
              + ("" if crho is None else f", contact_rho_inf = {crho:g}")
              + ("" if ptol is None else f", position_tolerance = {ptol:g} m")
              + ("" if corr else ", no end correction") + f": {status}, {len(r)} steps")
        print("    window        ends    loads  contact     drag       dE      eps  "
              "median T  end f.v  eps/ends  median step (ms)")
        for a, b in zip(edges[:-1], edges[1:]):
            m = (r[:, 0] > a) & (r[:, 0] <= b)
            if not m.any():
                continue
            s = r[m].sum(axis=0)
            print(f"  {a:5.2f}-{b:5.2f} s " + " ".join(f"{x:8.3f}" for x in s[1:7])
                  + f"  {np.median(r[m, 7]):8.2e} {s[8]:8.3f}  {s[6] / s[1]:+8.3f}"
                  + f"  {1e3 * np.median(steps[m]):8.3f}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", choices=("cable", "rest", "cases", "windows", "newton",
                                           "contact", "control", "tolerances", "full",
                                           "full-seed", "diagnose", "plectoneme"))
    only = parser.parse_args().only
    for name, fn in (("cable", cable), ("rest", rest), ("cases", cases),
                     ("windows", windows), ("newton", newton), ("contact", contact),
                     ("control", control), ("tolerances", tolerances), ("full", full),
                     ("full-seed", lambda: full(("goyal-writhing.yaml",))),
                     ("diagnose", diagnose), ("plectoneme", plectoneme)):
        if only == name or (only is None and name != "full-seed"):
            fn()
