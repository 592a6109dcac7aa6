"""Where a contact Newton iteration's time goes: the parts of one iteration of the seed
example (`cases/goyal-writhing.yaml`, 1000 segments) timed alone at a contact step.

The case is run to ``--at`` s (default 30 s, the plies wrapped, ~430 candidate runs), a
contact step of ``--dt`` s is set up from that state as the run would set it up, and Newton
is taken to its solution. At that iterate each compiled part is timed alone (median
of ``--repeats`` calls, one BLAS thread): the residual with its Jacobian and without it
(:func:`solver.scheme.residual_into`), the candidate gaps of a trial iterate
(:func:`solver.newton._trial_gaps`: the space-route pose and the closest points), the
band factorisation with its equilibration (:func:`solver.newton._factor`), one exact
operator product (:func:`solver.newton._matvec`) and one band solve
(:func:`solver.banded.block_solve`), the last two being one GMRES iteration's work. Then
the next ``--steps`` nominal steps are advanced and their Newton and GMRES iterations,
band factorisations and attempts counted, from which a contact Newton iteration's cost is
put together from its parts.

Run: ``PYTHONPATH=$PWD python benchmarks/contact_iteration_cost.py [--at 30] [--dt 0.015]
[--steps 3] [--repeats 200]`` (about 30 s of running to reach 30 s, plus the kernels'
compilation the first time).
"""
from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np
from threadpoolctl import threadpool_limits

from solver import Case
from solver import newton as newton_mod
from solver.banded import block_solve
from solver.run import RodRun
from solver.scheme import residual_into


def _median_ms(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e3


def measure(at: float, dt: float, steps: int, repeats: int) -> dict:
    """Run the seed example to ``at`` (s), time the parts of a contact Newton iteration at
    a step of ``dt`` (s) from there, and count the next ``steps`` nominal steps' work.
    Returns a dict of the figures (ms and counts)."""
    case = Case.from_file(os.path.join(os.path.dirname(__file__), "..", "cases",
                                       "goyal-writhing.yaml"))
    run = RodRun(case)
    h_nominal = case.numerics.dt
    k = 0
    with threadpool_limits(limits=1, user_api="blas"):
        while run.t < at - 1e-9:
            k += 1
            run.advance(round(k * h_nominal, 10))
        prob = run.step_problem(dt)
        system, newton = run.system, run.newton
        system.begin_step(prob.h, prob.params, prob.t_new, run.Y, run.Ydot, run.F_old,
                          prob.bc, q_old=run.q, r_old=run.r, v_old_global=run.v_global,
                          candidates=prob.candidates, left_limit=prob.left_limit)
        Y, _, its, res, ok, _ = newton.solve(run._feasible_guess(prob.guess))
        st = newton._state
        rod, step, cand, cdata = system.kernel_args()
        frozen = st["ws"][8][:0]
        runs = cand[2].shape[0]
        gaps = np.empty(runs)
        x = np.random.default_rng(0).standard_normal(Y.size)
        out = np.empty_like(x)
        parts = {
            "residual and Jacobian": lambda: residual_into(Y, True, rod, step, cand, frozen,
                                                           cdata, system.buf, system.ev),
            "residual alone": lambda: residual_into(Y, False, rod, step, cand, frozen, cdata,
                                                    system.buf, system.ev),
            "trial gaps": lambda: newton_mod._trial_gaps(Y, step, rod, cand, cdata,
                                                         st["ws"], gaps),
        }
        timed = {name: _median_ms(fn, repeats) for name, fn in parts.items()}
        residual_into(Y, True, rod, step, cand, frozen, cdata, system.buf, system.ev)
        timed["factorisation"] = _median_ms(
            lambda: newton_mod._factor(Y, system.buf, system.ev, st["lin"], st["op"], rod,
                                       step, newton.CONTACT_BAND_WEIGHT, st["ctr"]),
            max(repeats // 4, 5))
        timed["exact product"] = _median_ms(
            lambda: newton_mod._matvec(x, out, st["lin"], st["op"], step, st["gm"]), repeats)
        timed["band solve"] = _median_ms(lambda: block_solve(st["lin"][0], out), repeats)
        g0, f0 = newton.gmres_iterations, newton.factorizations
        attempts = [0, 0]
        solve = newton.solve

        def counted(Y_guess):
            out_ = solve(Y_guess)
            attempts[0] += 1
            attempts[1] += out_[2]
            return out_

        newton.solve = counted
        t0 = time.perf_counter()
        for _ in range(steps):
            k += 1
            run.advance(round(k * h_nominal, 10))
        wall = time.perf_counter() - t0
        del newton.solve
    return {"at": at, "dt": dt, "runs": runs, "start_iterations": its, "parts_ms": timed,
            "steps": steps, "solves": attempts[0], "newton": attempts[1],
            "gmres": newton.gmres_iterations - g0,
            "factorizations": newton.factorizations - f0, "wall_s": wall}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--at", type=float, default=30.0)
    ap.add_argument("--dt", type=float, default=0.015)
    ap.add_argument("--steps", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=200)
    args = ap.parse_args()
    load = os.getloadavg()[0]
    res = measure(args.at, args.dt, args.steps, args.repeats)
    p = res["parts_ms"]
    print(f"seed example at {res['at']:g} s, a {res['dt']:g}-s contact step, "
          f"{res['runs']} candidate runs (1-min load {load:.1f})")
    for name, ms in p.items():
        print(f"  {name:<22} {ms:6.3f} ms")
    n = max(res["newton"], 1)
    gm = res["gmres"] / n
    fa = res["factorizations"] / n
    per_it = (p["residual and Jacobian"] + gm * (p["exact product"] + p["band solve"])
              + fa * p["factorisation"])
    print(f"next {res['steps']} nominal steps: {res['solves']} Newton solves, "
          f"{res['newton']} iterations ({res['newton'] / max(res['solves'], 1):.2f} per solve), "
          f"{gm:.2f} GMRES iterations and {fa:.2f} factorisations per iteration, "
          f"{res['wall_s']:.2f} s")
    print(f"  per Newton iteration from the parts: {per_it:.2f} ms (residual and Jacobian "
          f"{p['residual and Jacobian']:.2f}, "
          f"GMRES {gm * (p['exact product'] + p['band solve']):.2f}, "
          f"factorisation {fa * p['factorisation']:.2f}); measured "
          f"{res['wall_s'] * 1e3 / n:.2f} ms with the step's other work")


if __name__ == "__main__":
    main()
