"""The energy check on the centreline scheme (:class:`solver.balance.CentrelineBalance`,
``numerics.energy_tolerance``): the cases that argue for and against it, each run
without the check and at the default, interleaved, printed as status, refused attempts,
the largest ε/scale, the answer, Newton iterations and wall time:

* ``--only cantilever``: issue 41's dead-load cantilever (100 segments, ρ∞ 0) at Δt 0.2,
  0.1, 0.05, 0.04 and 0.02 s: the tip against Mattiasson's elastica;
* ``--only cable``: the soft hanging cable of tests/solver/test_global_ends.py (ρ∞ 0, to
  16 s) at Δt 0.0125, 0.05, 0.1 and 0.2 s: the sag against the catenary; and at the
  default without the chords' account W_c (:meth:`~solver.balance.CentrelineBalance.
  chord_work` set to 0);
* ``--only rest``: the 2-cm cable resting on a flat bottom (tests/solver/test_seabed.py),
  Δt 1e-4 s over 0.05 s;
* ``--only touchdown``: cases/catenary-touchdown.yaml to 20 s: the mid node, and the
  kinetic energy at 0.05 s (the first fall onto the spring);
* ``--only full`` (minutes): cases/seabed-hockle.yaml to 10 s and cases/goyal-writhing.yaml
  to 45 s: the mid node (and |Wr| for the seed);
* ``--only oscillator``: generalized-α (Chung & Hulbert 1993) on x'' + ω²x = 0 from
  random starts: the largest ε/max(T^n, T^{n+1}) of a step, ε the change of ½v² + ½ω²x²,
  by ρ∞ over ωΔt from 0.05 to 1000 (a linear system, where the scheme is stable: what the
  check's rule against T meets in a mode no step resolves).

Run: ``python -m research.centreline_energy_balance [--only NAME]`` (each a minute or
two; ``full`` about four).
"""
from __future__ import annotations

import argparse
import contextlib
import math
import time
from pathlib import Path

import numpy as np

from hockle.api import catenary_parameter
from research import loads_verification as LV
import test_energy_check as EC
import test_seabed as SB
from solver import balance as B
from solver.case import Case
from solver.simulation import SolverDivergence, integrate

ROOT = Path(__file__).resolve().parents[1]
TOLERANCE = EC.DEFAULT


def _centreline(spec, **numerics) -> Case:
    spec = dict(spec)
    spec["numerics"] = dict(spec["numerics"], formulation="centreline", **numerics)
    return Case.model_validate(spec)


def _run(case):
    """(dataset, status, wall s): a failed run's partial result."""
    t0 = time.perf_counter()
    try:
        ds, status = integrate(case), "completed"
    except SolverDivergence as exc:
        ds, status = exc.partial, f"failed after t = {exc.partial.step_time.values[-1]:.4g} s"
    return ds, status, time.perf_counter() - t0


def _line(label, ds, status, wall, answer):
    ee = ds.step_energy_error.values if "step_energy_error" in ds else np.array([np.nan])
    worst = f"{np.nanmax(ee):.3g}" if np.isfinite(ee).any() else "-"
    refused = ds.attrs["hockle_refused_attempts"] or "none"
    print(f"  {label}: {status}; refused {refused}; largest eps/scale {worst}; {answer}; "
          f"Newton {int(ds.step_newton_iterations.values.sum())}; {wall:.2f} s", flush=True)


def _pair(name, spec, answer, **numerics):
    """The case without the check and at the default, one after the other."""
    print(name)
    for tol in (None, TOLERANCE):
        ds, status, wall = _run(_centreline(spec, energy_tolerance=tol, **numerics))
        _line("off" if tol is None else f"check {tol}", ds, status, wall, answer(ds))


@contextlib.contextmanager
def _without_chords():
    kept = B.CentrelineBalance.__dict__["chord_work"]      # the staticmethod itself
    B.CentrelineBalance.chord_work = staticmethod(lambda Y0, Y1: 0.0)
    try:
        yield
    finally:
        B.CentrelineBalance.chord_work = kept


def cantilever():
    def tip(ds):
        return f"tip {(ds.position.values[-1, -1, 2] / EC.L / EC.X_TIP - 1) * 100:+.3f} % off the elastica"
    for dt in (0.2, 0.1, 0.05, 0.04, 0.02):
        _pair(f"dead-load cantilever, 100 segments, dt {dt} s",
              EC.cantilever(dt, n=100).model_dump(mode="json"), tip)


def cable():
    L, X = 1.0, 0.8
    a = catenary_parameter(L, X)
    sag = a * (math.cosh(X / (2 * a)) - 1)

    def answer(ds):
        return f"sag {(-ds.position.values[-1, :, 2].min() / sag - 1) * 100:+.2f} % off the catenary"
    for dt in (0.0125, 0.05, 0.1, 0.2):
        spec = LV.catenary_spec(dt, None)
        spec["output"]["fields"] = ["position", "energies"]
        _pair(f"soft hanging cable, dt {dt} s", spec, answer)
    with _without_chords():
        spec = LV.catenary_spec(0.1, None)
        spec["output"]["fields"] = ["position", "energies"]
        print("soft hanging cable, dt 0.1 s, the check without the chords' account")
        ds, status, wall = _run(_centreline(spec, energy_tolerance=TOLERANCE))
        _line("check", ds, status, wall, answer(ds))


def rest():
    spec = SB._spec({"elevation": -SB.D / 2}, dt=1e-4, t_end=0.05)
    _pair("cable resting on the bottom, dt 1e-4 s", spec,
          lambda ds: f"lowest node z {ds.position.values[-1, :, 2].min():.4e} m")


def touchdown():
    spec = Case.from_file(ROOT / "cases" / "catenary-touchdown.yaml").model_dump(mode="json")
    spec["output"]["every"] = 1

    def answer(ds):
        r = ds.position.values[-1]
        t1 = ds.energy_kinetic.values[1] + ds.energy_kinetic_fluid.values[1]
        return f"mid node x {r[r.shape[0] // 2, 0]:.6f} m; T at 0.05 s {t1:.2e} J"
    _pair("cases/catenary-touchdown.yaml to 20 s", spec, answer)


def full():
    def mid(ds):
        r = ds.position.values[-1]
        out = f"mid node {np.array2string(r[r.shape[0] // 2], precision=5)} m"
        if "writhe" in ds:
            out += f"; |Wr| {abs(float(ds.writhe.values[-1])):.4f}"
        return out
    for name, t_end in (("seabed-hockle.yaml", 10.0), ("goyal-writhing.yaml", 45.0)):
        spec = Case.from_file(ROOT / "cases" / name).model_dump(mode="json")
        _pair(f"cases/{name} to {t_end:g} s", spec, mid, t_end=t_end)


def _oscillator_worst(rho, wh, x, v, steps=40):
    """The largest step's ε/max(T^n, T^{n+1}) of generalized-α (Chung & Hulbert 1993,
    eqs. 25-26 with α_m, α_f of one ρ∞) on x'' + x = 0 at ωΔt = wh from (x, v)."""
    am, af = (2 * rho - 1) / (rho + 1), rho / (rho + 1)
    gamma, beta = 0.5 - am + af, 0.25 * (1 - am + af) ** 2
    h, a, worst = wh, -x, -math.inf
    for _ in range(steps):
        a1 = (-am * a - ((1 - af) * (x + h * v + h * h * (0.5 - beta) * a) + af * x)) / (
            (1 - am) + (1 - af) * h * h * beta)
        x1 = x + h * v + h * h * ((0.5 - beta) * a + beta * a1)
        v1 = v + h * ((1 - gamma) * a + gamma * a1)
        eps = 0.5 * (v1 * v1 + x1 * x1) - 0.5 * (v * v + x * x)
        worst = max(worst, eps / max(0.5 * v * v, 0.5 * v1 * v1, 1e-300))
        x, v, a = x1, v1, a1
    return worst


def oscillator():
    rng = np.random.default_rng(1)
    print("generalized-alpha on a linear oscillator: largest eps/max(T^n, T^n+1) of a step")
    for rho in (0.0, 0.25, 0.5, 0.75, 0.9):
        worst = max(_oscillator_worst(rho, wh, *rng.normal(size=2))
                    for wh in np.geomspace(0.05, 1e3, 60) for _ in range(5))
        by_wh = ", ".join(f"{wh:g}: {_oscillator_worst(rho, wh, 1.0, 0.0, 30):.3g}"
                          for wh in (1, 4, 16, 100))
        print(f"  rho_inf {rho}: {worst:.4f} over omega dt 0.05-1000 and random starts; "
              f"from x = 1 at rest, by omega dt {by_wh}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    choices = {"cantilever": cantilever, "cable": cable, "rest": rest,
               "touchdown": touchdown, "full": full, "oscillator": oscillator}
    ap.add_argument("--only", choices=sorted(choices))
    only = ap.parse_args(argv).only
    for name, fn in choices.items():
        if only == name or (only is None and name != "full"):
            fn()


if __name__ == "__main__":
    main()
