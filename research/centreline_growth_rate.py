"""Is the centreline scheme's frozen growth rate a growth? (issue 79: the growth guard)

The growth guard on the centreline scheme (:meth:`solver.centreline.CentrelineRod.
growth_rate`) estimates σ from the quadratic pencil of the dynamics linearised about a
level, frozen at its velocities and accelerations. This script measures, on the DNA-like
rod of tests/solver/test_stability.py (D = 2 nm, L = 20 µm, 100 segments, twisted through
a sin² ramp to 1.2 × Greenhill's critical twist, held, pushed sideways at 5.5 T_c; Morison
drag in water; no contact), at levels of a run without the guard:

* the level's dynamic share (:meth:`solver.centreline.CentrelineRod.dynamic_share`);
* σ of the pencil near 2/Δt and 16/Δt (ARPACK to 1e-10, 40 vectors);
* the growth of a run perturbed along that mode: the level ± 1e-9 of the mode's largest
  position, stepped at Δt_s = 0.05/σ for 200 steps (10/σ), the rate fitted as the log of
  the difference's growth over the last 100 steps;

and the seed scheme's guard's σ on the same case before the push (its `step_growth_rate`).

Run: ``python -m research.centreline_growth_rate`` (about two minutes on one core).
"""
from __future__ import annotations

import copy
import math

import numpy as np
import scipy.sparse.linalg as sla

import test_stability
from solver.case import Case
from solver.centreline_run import CentrelineRun
from solver.simulation import integrate


class _Captured(Exception):
    pass


def dna_case(factor: float = 1.2, slenderness: float = 1e4) -> Case:
    """The case of test_stability.test_slender_dna_like_rod, the run not made."""
    def capture(case, **_):
        raise _Captured(case)

    real = test_stability.run_checked
    test_stability.run_checked = capture
    try:
        test_stability.test_slender_dna_like_rod(slenderness, factor)
    except _Captured as exc:
        return exc.args[0]
    finally:
        test_stability.run_checked = real
    raise RuntimeError("the test made no run")


def levels(case: Case, steps: list[int]):
    """The centreline run's levels after the given numbers of steps, growth guard off."""
    spec = case.model_dump()
    spec["numerics"].update(formulation="centreline", growth_guard=None)
    run = CentrelineRun(Case.model_validate(spec))
    dt = case.numerics.dt
    out = {}
    for k in range(1, max(steps) + 1):
        run.advance(k * dt)
        if k in steps:
            out[k] = copy.deepcopy(run.level)
    return run.rod, out


def tight_eigs(op, k=3, which="LM", ncv=12, tol=1e-2, maxiter=5, v0=None):
    """scipy's eigs converged to 1e-10 on 6 values and 40 vectors (the guard's settings
    stop at 1e-2, 5 restarts)."""
    return _EIGS(op, k=6, which="LM", ncv=40, tol=1e-10, maxiter=1000, v0=v0)


_EIGS = sla.eigs


def perturbed_growth(rod, level, sigma, vec) -> float:
    """The fitted growth rate (1/s) of the difference of two runs from the level ± ε y,
    y the mode's (r, p, n, m) part, at steps of 0.05/σ."""
    n = rod.n * 13
    y = (vec[:n] * np.tile(rod.problem(level.t).scales(), rod.n)).reshape(rod.n, 13)
    eps = 1e-9 * rod.props.s[-1] / np.abs(y[:, 0:3]).max()
    runs = []
    for sign in (1.0, -1.0):
        state = copy.deepcopy(level)
        state.Y = state.Y + sign * eps * y
        state.Y[:, 3:7] /= np.linalg.norm(state.Y[:, 3:7], axis=1)[:, None]
        runs.append(state)
    h = 0.05 / sigma
    diffs = []
    for _ in range(200):
        runs = [rod.step(s, h)[0] for s in runs]
        diffs.append(float(np.abs(runs[0].Y[:, 0:7] - runs[1].Y[:, 0:7]).max()))
    return math.log(diffs[-1] / diffs[99]) / (100 * h)


def main() -> None:
    case = dna_case()
    dt = case.numerics.dt
    tc = 50 * dt
    rod, lv = levels(case, [250, 400])
    sla.eigs = tight_eigs
    try:
        print("| level | dynamic share | shift (1/s) | frozen σ (1/s) | perturbed run's rate (1/s) |")
        print("| --- | --- | --- | --- | --- |")
        for k, level in lv.items():
            share = rod.dynamic_share(level, rod.problem(level.t))
            for shift in (2.0 / dt, 16.0 / dt):
                rod.QUASI_STATIC = math.inf          # estimate whatever the share
                sigma, vec = rod.growth_rate(level, shift)
                rate = perturbed_growth(rod, level, sigma, vec) if sigma > 0 else math.nan
                print(f"| {level.t / tc:.1f} T_c | {share:.2g} | {shift:.3g} | {sigma:.4g} | "
                      f"{rate:.4g} |")
    finally:
        sla.eigs = _EIGS
    ds = integrate(case)
    before = np.cumsum(ds.step_dt.values) < 5.5 * tc
    print(f"seed scheme's guard before the push: largest σ "
          f"{np.nanmax(ds.step_growth_rate.values[before]):.3g} 1/s")


if __name__ == "__main__":
    main()
