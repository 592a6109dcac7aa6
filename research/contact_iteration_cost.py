"""Where a contact Newton iteration's time goes, against a contact-free one at the same
N: the parts of one iteration of the seed example (`cases/goyal-writhing.yaml`, 1000
segments) timed alone at a contact step and at a step before contact.

The case is run to ``--at`` s (default 30 s, the plies wrapped, ~430 candidate runs), a
contact step of ``--dt`` s is set up from that state as the run would set it up, and Newton
is taken to its solution. At that iterate each compiled part is timed alone (median
of ``--repeats`` calls, one BLAS thread): the residual with its Jacobian and without it
(:func:`solver.scheme.residual_into`), the candidate gaps of a trial iterate
(:func:`solver.newton._trial_gaps`: the space-route pose and the closest points), the
factorisation (:func:`solver.newton._factor`: the equilibration, the operator's set-up
and the band LU) and the band LU alone (:func:`solver.banded.block_factor`; beside it
LAPACK's band LU ``dgbtrf`` of the same matrix, its copy into the band storage not
counted), one exact
operator product (:func:`solver.newton._matvec`) and one band solve
(:func:`solver.banded.block_solve`), the last two being one GMRES iteration's work, and
the operator's set-up at an iterate that keeps the older factorisation
(:func:`solver.newton._set_operator`). Then the next ``--steps`` nominal steps are
advanced and their Newton and GMRES iterations, band factorisations and attempts counted,
from which a contact Newton iteration's cost is put together from its parts (each solve's
start evaluated with its Jacobian too, the operator set up at every iteration without a
factorisation), and set beside the measured wall per iteration.

The same is done for a contact-free iteration of the same rod: the run is taken back to
its start and advanced to ``--free-at`` s (default 10 s, straight and twisting, before
buckling), a nominal step set up, and its residual with and without the Jacobian, the
factorisation and the band solve timed; then ``--free-steps`` nominal steps are counted.
A contact-free iteration is the residual with its Jacobian, a band solve and (some
iterations) a factorisation; the ratio of the two iterations' measured walls is printed
last (the figure docs/contact.md § 4 quotes for the cost of contact per Newton
iteration).

Then ``--steps`` more nominal steps from the contact state with each contact Newton solve
done twice from the same start, with and without the position test of
``NewtonSolver.CONTACT_POSITION_FRACTION`` (docs/contact.md § 2): the iterations of each and how
far the test's positions are from the fully converged ones.

Run: ``PYTHONPATH=$PWD python -m research.contact_iteration_cost [--at 30] [--dt 0.015]
[--steps 3] [--free-at 10] [--free-steps 20] [--repeats 200]`` (about 35 s of running,
plus the kernels' compilation the first time).
"""
from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np
from scipy.linalg import lapack
from threadpoolctl import threadpool_limits

from solver import Case
from solver import newton as newton_mod
from solver.banded import block_factor, block_solve
from solver.run import RodRun
from solver.scheme import residual_into

KL = KU = 17  # the Jacobian's band (solver.banded)


def _median_ms(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e3


def _advance_to(run: RodRun, at: float, h_nominal: float, k: int) -> int:
    """Advance ``run`` by nominal steps to ``at`` (s); returns the step count k."""
    while run.state.t < at - 1e-9:
        k += 1
        run.advance(round(k * h_nominal, 10))
    return k


def _lapack_band(blocks, bc_rows, bc_cols, bc_vals):
    """The same Jacobian (cell blocks (N, 12, 24), boundary entries (12,)) in LAPACK's band
    storage for ``dgbtrf`` (kl = ku = 17, (2kl + ku + 1, n), Fortran order)."""
    n_cells = blocks.shape[0]
    n = 12 * (n_cells + 1)
    ab = np.zeros((2 * KL + KU + 1, n), order="F")
    c, i, j = np.meshgrid(np.arange(n_cells), np.arange(12), np.arange(24), indexing="ij")
    rows = 6 + 12 * c + i
    cols = 12 * c + j
    ab[KL + KU + rows - cols, cols] = blocks
    ab[KL + KU + bc_rows - bc_cols, bc_cols] = bc_vals[:bc_rows.shape[0]]
    return ab


def _parts(run: RodRun, dt: float, repeats: int) -> tuple[dict, int, int]:
    """Set up a step of ``dt`` (s) from the run's state as the run would, solve it, and
    time the compiled parts of an iteration at the solution (ms, medians). Returns
    (parts, candidate runs, the solve's iterations)."""
    prob = run.assembly.step_problem(run.state, dt, predictor=run.predictor, after=run.last_reject)
    system, newton = run.system, run.newton
    guess = run.assembly.begin_solve(run.state, prob)
    Y, _, its, res, ok, _ = newton.solve(guess)
    st = newton._state
    rod, step, cand, cdata = system.kernel_args()
    frozen = st["ws"].frozen[:0]
    runs = cand.run_start.shape[0]
    x = np.random.default_rng(0).standard_normal(Y.size)
    out = np.empty_like(x)
    parts = {
        "residual and Jacobian": lambda: residual_into(Y, True, rod, step, cand, frozen,
                                                       cdata, system.buf, system.ev),
        "residual alone": lambda: residual_into(Y, False, rod, step, cand, frozen, cdata,
                                                system.buf, system.ev),
    }
    if runs:
        gaps = np.empty(runs)
        parts["trial gaps"] = lambda: newton_mod._trial_gaps(Y, step, rod, cand, cdata,
                                                             st["ws"], gaps)
    timed = {name: _median_ms(fn, repeats) for name, fn in parts.items()}
    residual_into(Y, True, rod, step, cand, frozen, cdata, system.buf, system.ev)
    timed["factorisation"] = _median_ms(
        lambda: newton_mod._factor(Y, system.buf, system.ev, st["lin"], st["op"], rod,
                                   step, newton.CONTACT_BAND_WEIGHT, st["ctr"]),
        max(repeats // 4, 5))
    lu, op = st["lin"].lu, st["op"]
    timed["band LU alone"] = _median_ms(
        lambda: block_factor(op.blocks, step.bc_rows, step.bc_cols, op.bc_scaled, lu), max(repeats // 4, 5))
    ab = _lapack_band(op.blocks, step.bc_rows, step.bc_cols, op.bc_scaled)
    work = np.empty_like(ab, order="F")
    copy_ms = _median_ms(lambda: np.copyto(work, ab), max(repeats // 4, 5))

    def lapack_factor():
        np.copyto(work, ab)
        if lapack.dgbtrf(work, KL, KU, overwrite_ab=True)[2] != 0:
            raise RuntimeError("dgbtrf: singular")

    timed["LAPACK dgbtrf"] = _median_ms(lapack_factor, max(repeats // 4, 5)) - copy_ms
    if runs:
        # the buffers still hold the evaluation at Y made before the factorisation
        timed["operator set-up"] = _median_ms(
            lambda: newton_mod._set_operator(system.buf, system.ev, st["lin"], op, step,
                                             newton.CONTACT_BAND_WEIGHT, step.af),
            repeats)
        timed["exact product"] = _median_ms(
            lambda: newton_mod._matvec(x, out, st["lin"], op, step, st["gm"]), repeats)
    timed["band solve"] = _median_ms(lambda: block_solve(lu, out), repeats)
    return timed, runs, its


def _count(run: RodRun, steps: int, h_nominal: float, k: int) -> tuple[dict, int]:
    """Advance ``steps`` nominal steps, counting Newton solves and iterations, GMRES
    iterations and factorisations; returns (counts with the wall in s, k)."""
    newton = run.newton
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
    return {"steps": steps, "solves": attempts[0], "newton": attempts[1],
            "gmres": newton.gmres_iterations - g0,
            "factorizations": newton.factorizations - f0, "wall_s": wall}, k


def _position_test(run: RodRun, steps: int, h_nominal: float, k: int) -> tuple[dict, int]:
    """Advance ``steps`` nominal steps with each contact Newton solve done twice from the
    same start, with the position test (``NewtonSolver.CONTACT_POSITION_FRACTION`` of the
    step's position bound) and without it (to the residual tolerance): the iterations of
    each and the largest distance (m) between their positions. Returns (figures, k)."""
    newton, system = run.newton, run.system
    bound = newton.position_tolerance
    solve = newton.solve
    rows = []

    def twice(Y_guess):
        if system.step.candidates is None or not system.step.candidates.runs:
            return solve(Y_guess)
        newton.position_tolerance = 0.0
        full = solve(Y_guess)
        newton.position_tolerance = bound
        out = solve(Y_guess)
        if out[4] and full[4]:
            r_full = system.pose_new(full[0])[2]
            rows.append((out[2], full[2],
                         float(np.abs(system.pose_new(out[0])[2] - r_full).max())))
        return out

    newton.solve = twice
    try:
        for _ in range(steps):
            k += 1
            run.advance(round(k * h_nominal, 10))
    finally:
        del newton.solve
    its, its_full, moved = (np.array(rows).T if rows else (np.zeros(0),) * 3)
    return {"solves": len(rows), "iterations": int(its.sum()),
            "iterations_full": int(its_full.sum()),
            "largest_difference_m": float(moved.max()) if rows else float("nan"),
            "bound_m": bound, "fraction": newton.CONTACT_POSITION_FRACTION}, k


def measure(at: float, dt: float, steps: int, repeats: int, free_at: float = 10.0,
            free_steps: int = 20) -> dict:
    """Run the seed example to ``at`` (s), time the parts of a contact Newton iteration at
    a step of ``dt`` (s) from there, and count the next ``steps`` nominal steps' work;
    then the same for a contact-free iteration at ``free_at`` (s), a nominal step, and
    ``free_steps`` steps. Returns a dict of the figures (ms and counts)."""
    case = Case.from_file(os.path.join(os.path.dirname(__file__), "..", "cases",
                                       "goyal-writhing.yaml"))
    h_nominal = case.numerics.dt
    with threadpool_limits(limits=1, user_api="blas"):
        run = RodRun(case)
        k = _advance_to(run, at, h_nominal, 0)
        timed, runs, its = _parts(run, dt, repeats)
        counts, k = _count(run, steps, h_nominal, k)
        position, k = _position_test(run, steps, h_nominal, k)
        free_run = RodRun(case)
        kf = _advance_to(free_run, free_at, h_nominal, 0)
        free_timed, free_runs, _ = _parts(free_run, h_nominal, repeats)
        free_counts, kf = _count(free_run, free_steps, h_nominal, kf)
    if free_runs:
        raise RuntimeError(f"the rod has contact candidates at {free_at} s")
    return {"at": at, "dt": dt, "runs": runs, "start_iterations": its, "parts_ms": timed,
            **counts, "position_test": position, "free": {"at": free_at, "parts_ms": free_timed, **free_counts}}


def _per_iteration(p: dict, c: dict) -> tuple[float, float, float]:
    """(GMRES iterations, factorisations, ms of the timed parts) per Newton iteration:
    the residual with its Jacobian at the iterate and, shared over the solve's
    iterations, at its start; the linear solve (GMRES's products and band solves with
    contact, one band solve without); the factorisations; with contact the operator's
    set-up at each iteration that keeps the older factorisation. Without contact the
    kernel builds the Jacobian only where it factorises, so there every evaluation
    counted with its Jacobian makes the figure an upper bound."""
    n = max(c["newton"], 1)
    gm = c["gmres"] / n
    fa = c["factorizations"] / n
    starts = c["solves"] / n
    if "exact product" in p:
        solve = gm * (p["exact product"] + p["band solve"])
        solve += max(1.0 - fa, 0.0) * p["operator set-up"]
    else:
        solve = p["band solve"]
    return gm, fa, (1.0 + starts) * p["residual and Jacobian"] + solve + fa * p["factorisation"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--at", type=float, default=30.0)
    ap.add_argument("--dt", type=float, default=0.015)
    ap.add_argument("--steps", type=int, default=3)
    ap.add_argument("--free-at", type=float, default=10.0)
    ap.add_argument("--free-steps", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=200)
    args = ap.parse_args()
    load = os.getloadavg()[0]
    res = measure(args.at, args.dt, args.steps, args.repeats, args.free_at, args.free_steps)
    per_wall = {}
    for label, p, c in (
            (f"contact: the seed example at {res['at']:g} s, a {res['dt']:g}-s step, "
             f"{res['runs']} candidate runs", res["parts_ms"], res),
            (f"contact-free: the seed example at {res['free']['at']:g} s, a nominal step",
             res["free"]["parts_ms"], res["free"])):
        print(f"{label} (1-min load {load:.1f})")
        for name, ms in p.items():
            print(f"  {name:<22} {ms:6.3f} ms")
        n = max(c["newton"], 1)
        gm, fa, per_it = _per_iteration(p, c)
        per_wall[label] = c["wall_s"] * 1e3 / n
        print(f"  next {c['steps']} nominal steps: {c['solves']} Newton solves, "
              f"{c['newton']} iterations ({c['newton'] / max(c['solves'], 1):.2f} per "
              f"solve), {gm:.2f} GMRES iterations and {fa:.2f} factorisations per "
              f"iteration, {c['wall_s']:.2f} s")
        print(f"  per Newton iteration from the parts: {per_it:.2f} ms; measured "
              f"{per_wall[label]:.2f} ms with the step's other work")
    pt = res["position_test"]
    print(f"position test (the next {args.steps} nominal steps, each contact solve twice): "
          f"{pt['solves']} solves, {pt['iterations']} iterations against "
          f"{pt['iterations_full']} to the residual tolerance; positions within "
          f"{pt['largest_difference_m']:.2e} m of the fully converged ones (fraction "
          f"{pt['fraction']:g} of the {pt['bound_m']:.2g}-m bound: "
          f"{pt['fraction'] * pt['bound_m']:.1e} m)")
    contact_ms, free_ms = per_wall.values()
    print(f"a contact Newton iteration costs {contact_ms / free_ms:.2f}× a contact-free one "
          f"(measured walls per iteration, {contact_ms:.2f} against {free_ms:.2f} ms)")


if __name__ == "__main__":
    main()
