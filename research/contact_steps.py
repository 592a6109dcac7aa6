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
with its iterations (NewtonSolver.last_trace: scaled residual, the feasibility filter's
fraction, the line search's fraction, GMRES iterations) and why it failed.

With ``--starts`` also, per window, how good each contact solve's Newton start was: the
distance of the line and the parabola extrapolated from the last levels (the predictors
of ``ProblemAssembly._predictions``) and of the start Newton was given (the feasible start, blended
toward the old positions where a predicted gap closed below ``NewtonSolver.START_GAP_KEEP`` of
itself) from the step's solution, per unknown (v, ω, f, κ), relative to the step's own
change ‖Y − Yⁿ‖ (medians over the window's solves; 1 is no better than the old level),
the share of solves whose start was blended, the histogram of the accepted steps'
Newton iterations, and how the corrections of every attempt's contact solves were taken:
whole, cut by the feasibility filter, or by the line search alone (NewtonSolver.last_trace).

With ``--watch NODE`` also, per window, how much that node's v and ω flip from one
accepted step to the next (:func:`alternation` of each component: 0 for a motion smooth
on the step's scale, 1 + ρ∞ where a stiff mode that generalized-α damps dominates, 2 for
a pure alternation), the RMS of ω's change per accepted step and the largest |ω|.

With ``--writhe T1,T2,...`` also, from the run's outputs, when |Wr| first reaches 1, the
largest |Wr|, Wr at those times and the tightest bend radius (:func:`writhe_readings`).

With ``--probe T`` instead: the case is advanced by nominal steps to T (s), and from that
one state a single step of each Δt of ``--probe-dt`` is attempted: accepted or refused,
Newton iterations, the route rule's ratio (how the step's position error grows with Δt,
and whether Newton or the route rule limits it there) and, for an accepted step of a
case with self-contact, the route difference over Δt (m/s) and as a share of the fastest
node's speed at T: it falls as Δt² where the step's own error dominates, and stays
where the κ-integrated centreline and the node velocities part at a rate of their own,
or where the rates carried from the (longer) step that reached T set the new κ. The
first of those is printed with T's state: the box rule's route rate
(:func:`semi_discrete_route_rate`, an error in s alone: docs/contact.md § 1), then the
limit of a step's route difference over Δt as Δt → 0 (:func:`step_route_rate`: that rate
and the part of the generalized-α rates carried to T); with ``--probe-steps K`` each
accepted probe step is followed by K − 1 more of its Δt, each beside that limit at its
start (how the carried part fades, by |αm|/(1 − αm) a step). With
``--residuals`` also, per Newton iterate of each attempt, the largest scaled residual of
each row group (E1, E2, E3 lateral, E3 axial, E4 and the end rows) with the cell where
it sits, and the fractions of the correction the filter and the line search kept. With
``--modes K`` also the K smallest singular values of each step's (scaled) Jacobian at
its Newton start, the weight each has in the exact first correction and the largest
components of its vector, and the correction's own largest components
(:func:`jacobian_modes`; dense, up to 6000 unknowns).

The case is a suite case's name or the path of a case file; ``--set FIELD=VALUE``
(repeatable, VALUE read as YAML) changes one of its fields first.

Run: ``PYTHONPATH=$PWD python -m research.contact_steps seed-in-air --from 17.5
--t-end 18.4`` (the seed example without its fluid, from just before its first contact),
``... cases/seabed-hockle.yaml --t-end 10 --edges 0,0.5,1,1.5,2,3,3.5,4,5,6,8,10`` (where
the sea floor's steps go, research/notes/seabed.md; ``--set seabed.friction=null --set
contact=null`` without its friction and self-contact),
``... tension --from 18.4 --t-end 18.7``, ``... tension --from 18 --t-end 45 --edges
18,18.5,19,20,22,25,30,35,40,45`` (the tension variant's whole contact phase, ~3 min),
``... tension --probe 19 --probe-dt 0.0005,0.001,0.0017,0.003,0.005,0.01``,
``... tension --probe 18.6 --probe-dt 0.001 --residuals`` (where a collapse step's
residual sits, iterate by iterate), ``... cases/seabed-hockle.yaml --set contact=null
--set seabed.friction=null --probe 2.2 --probe-dt 0.0125 --residuals --seabed-cells
29:34`` (with it, cells 29-33's seabed penetration, force and E3 residual at each
iterate: a cell whose contact switches on and off between iterates shows there).
``... cases/seabed-hockle.yaml --set initial.twist_rate=0 --probe 1 --probe-dt 0.0125
--modes 3`` (why that step's Newton struggles: the Jacobian's smallest singular values at
the step's start, and how much of the first correction lies along each, docs/seabed.md).
``... cases/seabed-hockle.yaml --set initial.twist_rate=0 --set numerics.rho_inf=0
--t-end 3 --edges 0,1,2,3 --watch 115`` (the untwisted lay's spin: it flips from step to
step at the case's ρ∞ = 0.5, not at 0; docs/seabed.md).
``... seed --t-end 45 --out a.nc`` (the run's outputs, for ``python
benchmarks/compare_results.py a.nc b.nc --largest 25:45``).
``... tension --from 19 --t-end 19.3 --starts`` (how far the starts of the collapse
are from their solutions). ``--newton ATTR=VALUE[,...]`` sets class attributes of
:class:`solver.newton.NewtonSolver` for the run (as contact_suite.py's option), e.g.
``... pyelastica-0.8 --from 7.5 --t-end 7.6 --every 0.01 --newton
CONTACT_RESIDUAL_FACTOR=2 --newton-failures 12``.
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


def trace_newton() -> None:
    """Give :class:`solver.newton.NewtonSolver` the two diagnostics this laboratory reads and
    the solver does not keep: ``last_trace`` after every solve (per iteration the scaled
    residual, the feasibility filter's fraction, the line search's fraction and GMRES's
    iterations: the rows the Newton kernel writes into its workspace) and
    ``last_start_blend`` after every :meth:`~solver.newton.NewtonSolver.feasible_start`
    (its blend factor: 1 the guess to rounding, 2^−k, 0 the zero-displacement state).
    Wraps the two methods for the rest of the process; the results are the unwrapped
    ones. Idempotent; called when this module is imported."""
    from solver import newton as nm

    cls = nm.NewtonSolver
    if getattr(cls, "_laboratory_trace", False):
        return
    solve = cls.solve

    def traced_solve(self, Y_guess):
        out = solve(self, Y_guess)
        self.last_trace = self._state["ws"].trace[:out[2] + 1].copy()
        return out

    def traced_feasible_start(self, guess):        # NewtonSolver.feasible_start, keeping
        system = self.system                         # the blend factor it discards
        self._allocate(system.step.candidates.runs)
        rod, step, cand, cdata = system.kernel_args()
        out = np.empty((system.n_nodes, nm.NV))
        self.last_start_blend = float(nm._feasible_start(
            step.Y_old, np.ascontiguousarray(guess, dtype=float), step, rod, cand, cdata,
            self._state["ws"], out, self.START_GAP_KEEP))
        return out

    traced_solve.__doc__, traced_feasible_start.__doc__ = (
        solve.__doc__, cls.feasible_start.__doc__)
    cls.solve, cls.feasible_start = traced_solve, traced_feasible_start
    cls.last_trace, cls.last_start_blend = None, 1.0
    cls._laboratory_trace = True


trace_newton()


#: the unknowns of a node's row of Y (N+1, 12), as --starts reports them
GROUPS = {"v": slice(0, 3), "ω": slice(3, 6), "f": slice(6, 9), "κ": slice(9, 12)}


def start_distances(Y_old, Y, starts: dict) -> dict:
    """How far each Newton start is from a step's solution, per unknown: for each start
    P (N+1, 12) of ``starts`` (name -> array) and each group g of :data:`GROUPS`,
    ‖Y_g − P_g‖ / ‖Y_g − Yⁿ_g‖ (Frobenius norms over the nodes; Y_old = Yⁿ, Y the
    solution, both (N+1, 12)); NaN where the step left the group unchanged. Returns
    {name: {group: float}}."""
    out = {}
    for name, P in starts.items():
        out[name] = {}
        for g, cols in GROUPS.items():
            change = float(np.linalg.norm(Y[:, cols] - Y_old[:, cols]))
            miss = float(np.linalg.norm(Y[:, cols] - P[:, cols]))
            out[name][g] = miss / change if change > 0.0 else math.nan
    return out


def correction_cuts(trace) -> np.ndarray:
    """How a Newton solve's corrections were taken, from its ``NewtonSolver.last_trace``
    (K+1, 4: per iterate the scaled residual, the feasibility filter's fraction, the line
    search's fraction, GMRES iterations; the last row is the final iterate, which made no
    correction): the counts (3,) int of corrections taken whole, cut by the filter, and
    cut by the line search alone."""
    rows = np.asarray(trace, float)[:-1]
    filtered = rows[:, 1] < 1.0
    backtracked = ~filtered & (rows[:, 2] < 1.0)
    return np.array([rows.shape[0] - filtered.sum() - backtracked.sum(), filtered.sum(),
                     backtracked.sum()], int)


def start_summary(solves: list, accepted_its: list, cuts=None) -> list:
    """Lines of the --starts report over one window: ``solves`` the dicts of
    :func:`start_distances` of its contact solves (each with "blend": the feasible start's
    blend factor, NewtonSolver.last_start_blend, 1 where the start is the predictor),
    ``accepted_its`` the Newton iterations of its accepted steps, ``cuts`` the
    :func:`correction_cuts` (3,) of each attempt's contact solves, summed (None: no line)."""
    lines = []
    if solves:
        names = [k for k in solves[0] if k != "blend"]
        for name in names:
            med = {g: np.nanmedian([s[name][g] for s in solves if name in s]) for g in GROUPS}
            lines.append(f"    {name:9s} " + "  ".join(f"{g} {v:5.2f}" for g, v in med.items()))
        blend = np.array([s["blend"] for s in solves], float)
        cut = blend[blend < 1.0]
        lines.append(f"    start blended toward the old positions in {cut.size} of {blend.size} "
                     "contact solves" + (f" (median factor {np.median(cut):.3g})"
                                         if cut.size else ""))
    hist = collections.Counter(accepted_its)
    lines.append("    Newton iterations of the accepted steps: "
                 + ", ".join(f"{k}: {hist[k]}" for k in sorted(hist)))
    if cuts:
        whole, filtered, backtracked = np.sum(cuts, axis=0)
        lines.append(f"    corrections of the contact solves (every attempt): {whole} of "
                     f"{whole + filtered + backtracked} taken whole, {filtered} cut by the "
                     f"feasibility filter, {backtracked} by the line search alone")
    return lines


def _starts_of(rows: list) -> list:
    """:func:`start_summary` of recorded attempts (``record(..., starts=True)``)."""
    return start_summary([r["starts"] for r in rows if r["starts"] is not None],
                         [r["its"] for r in rows if r["ok"]],
                         [r["cuts"] for r in rows if r.get("cuts") is not None])


def case_spec(name: str, sets=()) -> dict:
    """The spec (a dict) of suite case ``name``, or of the case file at the path
    ``name``, with each "dotted.field=VALUE" of ``sets`` applied (VALUE read as YAML:
    ``seabed.friction=null``, ``contact=null``, ``seabed.normal_damping=0``). Raises
    SystemExit naming a field of ``sets`` that the spec does not hold."""
    from benchmarks import contact_suite as cs
    from solver.case import Case

    if name in cs.CASES:
        spec = cs.CASES[name][1]()
    else:
        spec = Case.from_file(name).model_dump(mode="json")
    return cs.with_sets(spec, sets)


def alternation(x) -> float:
    """How much a series x (K,) flips from step to step: RMS(Δ²x_n) / RMS(Δx_n) over
    n = 0..K−3 (Δx_n = x_{n+1} − x_n, Δ²x_n = Δx_{n+1} − Δx_n), from 0 (a straight line;
    2 sin(φ/2) ≈ φ for a sine sampled every φ radians, so small for a series smooth on
    the step's scale) to 2 (x alternating about a constant); NaN with fewer than three
    values or a constant series. A sequence c + a(−ρ)^n gives exactly 1 + ρ: a stiff mode
    that generalized-α damps per step by its spectral radius at infinite frequency ρ∞
    alternates by the factor −ρ∞ (Chung & Hulbert 1993, the amplification matrix's
    limit), so where such a mode dominates a series its alternation is 1 + ρ∞."""
    x = np.asarray(x, float)
    if x.size < 3:
        return math.nan
    d1 = np.diff(x)
    r1 = float(np.sqrt(np.mean(d1[:-1] ** 2)))
    if r1 == 0.0:
        return math.nan
    return float(np.sqrt(np.mean(np.diff(d1) ** 2))) / r1


def record(name: str, t_end: float, starts: bool = False, sets=(), watch=None,
           result=None) -> list:
    """Run ``name`` (:func:`case_spec`, with ``sets``) to t_end (s); the attempts as
    dicts (with ``starts``, each with "starts": :func:`start_distances` of its last
    Newton solve with contact candidates, else None; with ``watch`` a node's index, each
    accepted attempt with "node": that node's (v, ω) (6,) in the body frame after it).
    ``result``: a dict that receives the run's dataset under "ds" (absent where the run
    stopped)."""
    from benchmarks import contact_suite as cs
    from solver.case import Case
    from solver.run import RodRun
    from solver.simulation import SolverDivergence, integrate
    from solver.step_problem import ProblemAssembly

    spec = case_spec(name, sets)
    spec["numerics"]["energy_tolerance"] = cs.ENERGY_TOLERANCE
    spec["numerics"]["t_end"] = t_end
    case = Case.model_validate(spec)
    from solver.newton import NewtonSolver

    attempts, plain, plain_solve = [], RodRun.try_step, NewtonSolver.solve
    current = {}

    def recording(self, h, *args, **kwargs):
        if watch is not None and not 0 <= watch < self.state.Y.shape[0]:
            raise SystemExit(f"--watch {watch}: the case's nodes are 0 to {self.state.Y.shape[0] - 1}")
        t0 = self.state.t
        g0 = self.newton.gmres_iterations
        current.clear()
        current["run"] = self
        w0 = time.perf_counter()
        att = plain(self, h, *args, **kwargs)
        wall = time.perf_counter() - w0
        trace = None
        if att.reason == "newton" and self.newton.last_trace is not None:
            trace = (self.newton.last_failure, self.newton.last_trace.copy())
        attempts.append({"t": t0, "h": h, "ok": bool(att.ok), "why": att.reason,
                         "its": att.iterations, "ratio": att.route_ratio,
                         "gmres": self.newton.gmres_iterations - g0, "wall": wall,
                         "contacts": self.contact_count, "trace": trace,
                         "starts": current.get("starts"), "cuts": current.get("cuts"),
                         "node": (self.state.Y[watch, 0:6].copy()
                                  if watch is not None and att.ok else None)})
        return att

    def solving(self, guess):
        out = plain_solve(self, guess)
        run = current.get("run")
        prob = getattr(run.assembly, "_last_problem", None)
        if prob is not None and prob.candidates is not None \
                and self.last_trace is not None:
            current["cuts"] = current.get("cuts", 0) + correction_cuts(self.last_trace)
        if run is not None and prob is not None and prob.candidates is not None \
                and prob.predictions and out[4]:
            d = start_distances(run.state.Y, out[0], dict(prob.predictions, start=guess))
            d["blend"] = current.pop("blend", 1.0)
            current["starts"] = d
        return out

    plain_feasible = NewtonSolver.feasible_start

    def feasible(self, guess):
        out = plain_feasible(self, guess)
        current["blend"] = self.last_start_blend
        return out

    plain_problem = ProblemAssembly.step_problem

    def problem(self, *args, **kwargs):
        prob = plain_problem(self, *args, **kwargs)
        self._last_problem = prob
        return prob

    RodRun.try_step = recording
    if starts:
        NewtonSolver.solve = solving
        NewtonSolver.feasible_start = feasible
        ProblemAssembly.step_problem = problem
    try:
        ds = integrate(case)
        if result is not None:
            result["ds"] = ds
    except SolverDivergence as exc:
        print(f"stopped: {exc.reason} at t = {exc.t:.4f} s")
    finally:
        RodRun.try_step = plain
        NewtonSolver.solve = plain_solve
        NewtonSolver.feasible_start = plain_feasible
        ProblemAssembly.step_problem = plain_problem
    return attempts


def _watched(rows: list, node: int) -> str:
    """The --watch line of recorded attempts: the :func:`alternation` of the watched
    node's v and ω over the accepted steps, the RMS of |ω|'s change from one accepted
    step to the next and the largest |ω| (rad/s)."""
    vals = np.array([r["node"] for r in rows if r["ok"] and r["node"] is not None])
    if vals.size == 0:
        return f"    node {node}: no accepted step"
    names = ("v1", "v2", "v3", "ω1", "ω2", "ω3")
    alt = "  ".join(f"{n} {alternation(vals[:, j]):.2f}" for j, n in enumerate(names))
    jump = (float(np.sqrt(np.mean(np.sum(np.diff(vals[:, 3:6], axis=0) ** 2, axis=1))))
            if len(vals) > 1 else math.nan)
    return (f"    node {node} over {len(vals)} accepted steps: alternation {alt};  "
            f"ω's change per step RMS {jump:.3g}, |ω| max "
            f"{np.linalg.norm(vals[:, 3:6], axis=1).max():.3g} rad/s")


def writhe_readings(ds, times) -> str:
    """The --writhe line of a run's dataset ``ds`` (its ``writhe`` output, turns, on
    ``time``, s): the first output time where |Wr| reaches 1, the largest |Wr| and when,
    Wr at the output times nearest each of ``times`` (s), and with the ``bend_radius``
    output the smallest ``bend_radius_min`` (m) and when."""
    if "writhe" not in ds:
        return "writhe: the case does not output it (output.fields without topology)"
    t, wr = ds["time"].values, ds["writhe"].values
    hit = np.nonzero(np.abs(wr) >= 1.0)[0]
    first = f"{t[hit[0]]:.2f} s" if hit.size else "never"
    at = "  ".join(f"Wr({t[i]:g} s) {wr[i]:.4f}"
                   for i in (int(np.argmin(np.abs(t - x))) for x in times))
    k = int(np.nanargmax(np.abs(wr)))
    out = (f"writhe: |Wr| through 1 at {first} (output times), largest |Wr| "
           f"{abs(wr[k]):.3f} at {t[k]:g} s;  {at}")
    if "bend_radius_min" in ds:
        r = ds["bend_radius_min"].values
        j = int(np.nanargmin(r))
        out += f";  tightest bend radius {r[j]:.4f} m at {t[j]:g} s"
    return out


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


#: the residual rows of a cell (offsets in its 12 rows) as --residuals groups them
#: (solver/scheme.py: E1 compatibility, E2 inextensibility, E3 linear and E4 angular
#: momentum, each in the body frame, component 3 along the tangent)
ROW_GROUPS = {"E1": (0, 1, 2), "E2": (3, 4, 5), "E3 lateral": (6, 7), "E3 axial": (8,),
              "E4": (9, 10, 11)}


def residual_groups(scaled) -> dict:
    """The largest |scaled residual| of each row group of :data:`ROW_GROUPS` and the cell
    where it is, from a step's scaled residual (n,) = 6 boundary rows at s = 0, 12 rows
    per cell, 6 at s = L; the boundary rows as one group "ends" (cell −1 / −2 for s = 0 /
    s = L). Returns {group: (value, cell)}."""
    r = np.abs(np.asarray(scaled, dtype=float))
    cells = r[6:-6].reshape(-1, 12)
    out = {}
    for g, offs in ROW_GROUPS.items():
        block = cells[:, offs].max(axis=1)
        c = int(np.argmax(block))
        out[g] = (float(block[c]), c)
    ends = (float(r[:6].max()), -1) if r[:6].max() >= r[-6:].max() else (float(r[-6:].max()), -2)
    out["ends"] = ends
    return out


def _iterates_residuals(snapshot: bytes, h: float, its: int, cells=None) -> list:
    """The scaled residual's row groups (:func:`residual_groups`) at each iterate 0 … its
    of the first Newton solve of a step of h (s) from the pickled run ``snapshot``: the
    solve repeated with at most k iterations, set up as the run's first attempt
    (:meth:`solver.step_problem.ProblemAssembly.begin_solve`). With ``cells`` (a range of
    cells, a case with a seabed) each row also holds, under "seabed", per cell its
    midpoint's penetration (m), the seabed's force per unit length normal to the bottom
    (N/m; :meth:`solver.seabed.SeabedContact.cell_loads` at the iterate's new-level pose) and the
    largest |unscaled residual| of its E3 rows (N/m)."""
    import pickle

    rows = []
    for k in range(its + 1):
        run = pickle.loads(snapshot)
        guess = run.assembly.begin_solve(run.state, run.assembly.step_problem(run.state, h, predictor=run.predictor, after=run.last_reject))
        Y = guess
        if k:
            run.newton.max_iterations = k
            Y = run.newton.solve(guess)[0]
        R = run.system.residual(Y, want_jacobian=True)[0]
        run.newton.linearize(Y)
        row = residual_groups(R * run.newton.row_scale)
        if cells is not None and run.system.seabed is not None:
            _, Rm, r, _ = run.system.pose_new(Y)
            vg = np.einsum("kij,kj->ki", Rm, Y[:, 0:3])
            F, _, pen = run.system.seabed.cell_loads(r, vg, Rm, Y[:, 3:6])
            e3 = np.abs(R[6:-6].reshape(-1, 12)[:, 6:9]).max(axis=1)
            row["seabed"] = [(c, float(pen[c]), float(np.linalg.norm(F[c, 0:3])), float(e3[c]))
                             for c in cells]
        rows.append(row)
    return rows


#: the unknowns of a node's row of Y by component: body-frame v, ω, f, κ (1, 2, 3 the
#: directions d1, d2, d3 of the section's frame, d3 the tangent)
COMPONENTS = [f"{g}{i}" for g in ("v", "ω", "f", "κ") for i in (1, 2, 3)]

#: the largest system :func:`jacobian_modes` forms densely (12 (N+1) unknowns)
MODES_MAX_UNKNOWNS = 6000


def _largest(x) -> dict:
    """Per component of :data:`COMPONENTS`, the largest |x| of (N+1, 12) x over the nodes
    and its node: {component: (value, node)}."""
    a = np.abs(x)
    nodes = np.argmax(a, axis=0)
    return {c: (float(a[nodes[j], j]), int(nodes[j])) for j, c in enumerate(COMPONENTS)}


def jacobian_modes(snapshot: bytes, h: float, k: int = 4) -> dict:
    """The smallest singular values of a step's Jacobian at its Newton start, and what
    the first Newton correction carries along them.

    The step of h (s) from the pickled run ``snapshot`` is set up as the run's first
    attempt (:meth:`solver.step_problem.ProblemAssembly.begin_solve`); the operator Newton
    solves with there (row- and column-scaled, :meth:`solver.newton.NewtonSolver.operator`: the
    exact Jacobian, the exact product included where the pose is the space route) is
    formed densely, column by column, and decomposed, J = U diag(σ) Vᵀ (numpy's SVD). The
    exact first correction δ = J⁻¹ b (b = the scaled residual's negative) is
    Σ_i (u_i·b / σ_i) v_i: a right vector whose σ is tiny against the residual's part
    along its left vector dominates it.

    Returns {"n": unknowns, "sigma": the k smallest σ (ascending), "sigma_max",
    "correction": :func:`_largest` of δ unscaled (N+1, 12), "modes": per one of the k
    smallest σ, {"sigma", "coefficient": u·b/σ (its weight in δ, in the scaled
    unknowns), "part": u·b, "vector": :func:`_largest` of its right vector unscaled}}.
    Raises SystemExit where the system has more than :data:`MODES_MAX_UNKNOWNS` unknowns
    (the dense SVD's O(n³))."""
    import pickle

    run = pickle.loads(snapshot)
    Y = run.assembly.begin_solve(run.state, run.assembly.step_problem(run.state, h, predictor=run.predictor, after=run.last_reject))
    newton, system = run.newton, run.system
    R = system.residual(Y, want_jacobian=True)[0]
    n = R.size
    if n > MODES_MAX_UNKNOWNS:
        raise SystemExit(f"--modes: {n} unknowns, more than the {MODES_MAX_UNKNOWNS} a dense "
                         "SVD takes in reasonable time")
    newton.linearize(Y)
    J = np.empty((n, n))
    e = np.zeros(n)
    for j in range(n):
        e[j] = 1.0
        J[:, j] = newton.operator(e)
        e[j] = 0.0
    U, S, Vt = np.linalg.svd(J)
    b = -R * newton.row_scale
    parts = U.T @ b
    cs = newton.col_scale
    shape = Y.shape
    modes = []
    for i in range(1, min(k, n) + 1):
        modes.append({"sigma": float(S[-i]), "coefficient": float(parts[-i] / S[-i]),
                      "part": float(parts[-i]),
                      "vector": _largest((Vt[-i] * cs).reshape(shape))})
    delta = (Vt.T @ (parts / S)) * cs
    return {"n": n, "sigma": [m["sigma"] for m in modes], "sigma_max": float(S[0]),
            "correction": _largest(delta.reshape(shape)), "modes": modes}


def _print_modes(modes: dict, shown: int = 5) -> None:
    """Print :func:`jacobian_modes`: the correction's and each mode's ``shown`` largest
    components."""
    def top(d):
        items = sorted(d.items(), key=lambda kv: -kv[1][0])[:shown]
        return ", ".join(f"{c} {v:.2g} @ {node}" for c, (v, node) in items)

    print(f"    Jacobian at the start ({modes['n']} unknowns, scaled): σ max "
          f"{modes['sigma_max']:.3g}, min {modes['sigma'][0]:.3g} (condition "
          f"{modes['sigma_max'] / modes['sigma'][0]:.2g})")
    print(f"    first Newton correction (unscaled, largest components @ node): "
          f"{top(modes['correction'])}")
    for m in modes["modes"]:
        print(f"    σ {m['sigma']:.3g}: weight {m['coefficient']:+.3g} in the correction "
              f"(the residual's part {m['part']:+.2g}); its vector: {top(m['vector'])}")


def semi_discrete_route_rate(run, kappa_rate=None) -> np.ndarray:
    """How fast the κ-integrated centreline moves away from the nodes' own motion at the
    run's level, from that level alone (no time step): ṙ_space − R v per node (N+1, 3),
    m/s, global. ṙ_space is the space route's derivative (central difference, ε = 1e-6 s,
    of :func:`solver.kinematics.space_route`) along each cell's κ̄ rate that the box
    rule's compatibility row E1 gives at this level, (ω_k − ω_{k−1})/Δs + ⟨κ×ω⟩ (seed
    eq. 2, solver/scheme.py), with node 0's pose moved by its v and ω; R v are the
    nodes' velocities on the space route's frames. The continuous model makes the two
    equal, so this is the box rule's own error in s, free of the time step's. With
    ``kappa_rate`` (N+1, 3; rad/m/s, body frame) the space route moves along those nodal
    rates instead (their cell means are what it reads), e.g. the generalized-α rates κ̇ⁿ
    the run carries (:func:`step_route_rate`). The grid is uniform (the space route's Δs
    is its mean spacing). Raises nothing."""
    from solver.kinematics import quat_exp, quat_multiply, quat_to_matrix, space_route

    Y = run.state.Y
    v, w, k = Y[:, 0:3], Y[:, 3:6], Y[:, 9:12]
    ds = np.diff(run.props.s)[:, None]
    if kappa_rate is None:
        cell = (w[1:] - w[:-1]) / ds + 0.5 * (np.cross(k[:-1], w[:-1])
                                               + np.cross(k[1:], w[1:]))
        # nodal rates whose cell means are ``cell`` (the space route reads κ̄ = ⟨κ⟩ only)
        nodal = np.zeros_like(k)
        for c in range(cell.shape[0]):
            nodal[c + 1] = 2.0 * cell[c] - nodal[c]
    else:
        nodal = np.asarray(kappa_rate, float)
    q0, r0 = run.state.q_time[0], run.state.r_time[0]
    R0 = quat_to_matrix(q0[None])[0]
    eps = 1e-6
    ends = [space_route(quat_multiply(q0, quat_exp(sg * eps * w[0])),
                        r0 + sg * eps * R0 @ v[0], k + sg * eps * nodal, float(ds.mean()))[1]
            for sg in (1.0, -1.0)]
    q, _ = space_route(q0, r0, k, float(ds.mean()))
    return (ends[0] - ends[1]) / (2.0 * eps) - np.einsum("nij,nj->ni", quat_to_matrix(q), v)


def carried_rate_weight(params) -> float:
    """The weight c = 1 − γ/(1 − αm) of the carried rate Ẏⁿ in the first step of a
    generalized-α step (hockle's weights on the old level, :func:`solver.scheme.
    alpha_parameters`) as Δt → 0: the step's equations at level n + 1 − αm,
    (1 − αm) Ẏⁿ⁺¹ + αm Ẏⁿ = Ẏ_E(Yⁿ) (Ẏ_E the rate the equations give at Yⁿ), with
    Yⁿ⁺¹ = Yⁿ + Δt((1 − γ)Ẏⁿ + γẎⁿ⁺¹), move Y at (Yⁿ⁺¹ − Yⁿ)/Δt = Ẏ_E + c(Ẏⁿ − Ẏ_E).
    0 at ρ∞ = 1 (the trapezoidal rule), 1/11 at 0.8, 1/5 at 0.5, 1/3 at 0. Raises
    nothing."""
    return 1.0 - params.gamma / (1.0 - params.alpha_m)


def step_route_rate(run, params=None) -> tuple[np.ndarray, np.ndarray]:
    """What a step from the run's level, as Δt → 0, does to the route rule's distance
    per unit time (the route difference over Δt, m/s): the space route moves along
    κ̇_E + c(κ̇ⁿ − κ̇_E) (:func:`carried_rate_weight`; κ̇_E the box rule's rate of E1,
    κ̇ⁿ the generalized-α rates the run carries, ``run.state.Ydot``), the time route along
    R vⁿ. Returns (that rate, the carried rates' own route rate), each (N+1, 3) m/s:
    the first is :func:`semi_discrete_route_rate` plus c times the difference of the
    two. The carried κ̇ⁿ satisfy the equations at the level n − αm of the step that
    reached n, not at n, so the second part is as large as the rates' change over that
    step. ``params``: the step's :class:`solver.scheme.StepParameters` (default the run's
    ρ∞). Raises nothing."""
    params = run.assembly.params if params is None else params
    box = semi_discrete_route_rate(run)
    carried = semi_discrete_route_rate(run, run.state.Ydot[:, 9:12])
    return box + carried_rate_weight(params) * (carried - box), carried


def _probe_params(run, case):
    """The generalized-α parameters of a contact step from the run's level: the case's
    ``numerics.contact_rho_inf`` where set and the last step had contact candidates (as
    :meth:`solver.step_problem.ProblemAssembly.step_problem` picks), else the run's."""
    from solver.scheme import alpha_parameters

    rho = case.numerics.contact_rho_inf
    last = run.control.last_attempt
    if rho is not None and last is not None and last.had_candidates:
        return alpha_parameters(rho)
    return run.assembly.params


def _steady_steps(run, h: float, count: int, params) -> str:
    """``count`` more steps of h (s) on ``run`` (changed): per step the route difference
    over h and, in brackets, :func:`step_route_rate`'s limit at the level it started from
    (m/s); stops at a refused step."""
    out = []
    for _ in range(count):
        limit = float(np.linalg.norm(step_route_rate(run, params)[0], axis=1).max())
        att = run.try_step(h)
        if not att.ok:
            out.append(f"refused ({att.reason})")
            break
        out.append(f"{run.last_step_error / h:.3g} ({limit:.3g})")
    return ", ".join(out)


def probe(name: str, at: float, sizes: list, residuals: bool = False, sets=(),
          cells=None, modes: int = 0, steps: int = 1) -> None:
    """Advance suite case ``name`` by nominal steps to ``at`` (s), then attempt one step
    of each Δt in ``sizes`` (s) from that state; prints each attempt, and with a self-
    contact the route rates of that state (:func:`step_route_rate`). With ``steps`` > 1
    each accepted first step is followed by ``steps`` − 1 more of the same Δt, each with
    its route difference over Δt beside the limit :func:`step_route_rate` gives at the
    level it starts from (how the carried rates' part fades at a steady Δt). ``residuals``: also,
    per Newton iterate of each attempt, its filter and line-search fractions and where
    its scaled residual is largest (:func:`residual_groups`), and with ``cells`` (a
    range) those cells' seabed penetration, force and E3 residual
    (:func:`_iterates_residuals`). With ``modes`` > 0 also each step's ``modes`` smallest
    singular values of the Jacobian at its start and what the first correction carries
    along them (:func:`jacobian_modes`)."""
    import pickle

    from benchmarks import contact_suite as cs
    from solver.case import Case
    from solver.run import RodRun

    spec = case_spec(name, sets)
    spec["numerics"]["energy_tolerance"] = cs.ENERGY_TOLERANCE
    case = Case.model_validate(spec)
    from research.contact_iteration_cost import _advance_to

    run = RodRun(case)
    _advance_to(run, at, case.numerics.dt, 0)
    snapshot = pickle.dumps(run, protocol=pickle.HIGHEST_PROTOCOL)
    fastest = float(np.linalg.norm(run.state.v_global, axis=1).max())
    rate = float(np.linalg.norm(semi_discrete_route_rate(run), axis=1).max())

    def share(x):
        return f"{x / fastest:.2%} of it" if fastest > 0.0 else "the rod at rest"

    print(f"{name} at t = {run.state.t:g} s, {run.contact_count} contacts, fastest node "
          f"{fastest:.3g} m/s, the box rule's route rate {rate:.3g} m/s "
          f"({share(rate)}):")
    params = _probe_params(run, case)
    if run.contact is not None:
        limit, carried = (np.linalg.norm(x, axis=1).max() for x in step_route_rate(run, params))
        last = run.state.h_prev
        print(f"  the carried generalized-α rates κ̇ⁿ"
              + (f" (from steps of {last:.3g} s)" if last else "")
              + f" move the space route {carried:.3g} m/s off the nodes; with weight "
              f"{carried_rate_weight(params):.3g} and the box rule's rate, a step's route "
              f"difference over Δt → {limit:.3g} m/s ({share(limit)}) as Δt → 0")
    for h in sizes:
        trial = pickle.loads(snapshot)
        att = trial.try_step(h)
        state = "accepted" if att.ok else f"refused ({att.reason})"
        rate = ""
        if att.ok and trial.contact is not None:
            # the route difference per unit time: O(h²) where the step's own error
            # dominates; a constant where the two routes part at a rate of their own
            # (the box rule's, above) or where the rates carried from a longer step
            # than h (generalized-α's Ẏⁿ) set the new level's κ
            per_s = trial.last_step_error / h
            rate = f"  route difference / Δt {per_s:.3g} m/s ({share(per_s)})"
        print(f"  Δt = {h:<8g} s  {state:18s} Newton {att.iterations:3d}  route ratio "
              f"{att.route_ratio:.3g}{rate}")
        if steps > 1 and att.ok and trial.contact is not None:
            print("    the next steps of Δt: route difference / Δt (the limit at the step's "
                  "start), m/s: " + _steady_steps(trial, h, steps - 1, params))
        if modes:
            _print_modes(jacobian_modes(snapshot, h, modes))
        if residuals:
            trace = trial.newton.last_trace
            for k, groups in enumerate(_iterates_residuals(snapshot, h, att.iterations,
                                                           cells)):
                cut = (f"filter {trace[k, 1]:.3g}, line search {trace[k, 2]:.3g}"
                       if k < att.iterations and trace is not None and k < len(trace)
                       else "")
                floor = groups.pop("seabed", None)
                where = ", ".join(f"{g} {v:.3g} @ {c}" for g, (v, c) in groups.items())
                print(f"    iterate {k}: {where}" + (f"  ({cut})" if cut else ""))
                if floor:
                    print("      seabed: " + "; ".join(
                        f"cell {c} p {1e6 * p:+.2f} µm, F {f:.3g} N/m, E3 {e:.2g}"
                        for c, p, f, e in floor))


def main() -> None:
    from benchmarks import contact_suite as cs
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", help="a suite case (" + ", ".join(cs.CASES)
                    + ") or the path of a case file")
    ap.add_argument("--set", dest="sets", action="append", default=[],
                    metavar="FIELD=VALUE", help="change a field of the case, VALUE as YAML "
                    "(repeatable): --set seabed.friction=null --set contact=null")
    ap.add_argument("--from", dest="t_from", type=float, default=0.0)
    ap.add_argument("--t-end", type=float, default=None)
    ap.add_argument("--every", type=float, default=0.1)
    ap.add_argument("--edges", default="",
                    help="comma-separated times (s) bounding the printed windows")
    ap.add_argument("--probe", type=float, default=None,
                    help="attempt single steps from the state at this time (s)")
    ap.add_argument("--out", default="", metavar="FILE.nc",
                    help="without --probe: write the run's outputs there (e.g. for "
                         "compare_results.py --largest)")
    ap.add_argument("--probe-steps", type=int, default=1, metavar="K",
                    help="with --probe: K steps of each Δt in a row")
    ap.add_argument("--probe-dt", default="0.0005,0.001,0.002,0.005,0.01,0.02",
                    help="comma-separated Δt (s) of the probe's attempts")
    ap.add_argument("--residuals", action="store_true",
                    help="with --probe: where each Newton iterate's residual is largest")
    ap.add_argument("--seabed-cells", default="", metavar="A:B",
                    help="with --probe --residuals: cells A to B-1's seabed penetration, "
                    "force and E3 residual at each iterate")
    ap.add_argument("--modes", type=int, default=0, metavar="K",
                    help="with --probe: the K smallest singular values of each step's "
                    "Jacobian at its start and what the first correction carries along them")
    ap.add_argument("--watch", type=int, default=None, metavar="NODE",
                    help="also, per window, how much NODE's v and ω flip from one accepted "
                    "step to the next (alternation: 0 smooth, 2 alternating)")
    ap.add_argument("--writhe", default="", metavar="T1,T2,...",
                    help="also when |Wr| first reaches 1 and Wr at these times (s; the case "
                    "must output topology)")
    ap.add_argument("--newton-failures", type=int, default=0)
    ap.add_argument("--starts", action="store_true",
                    help="also how far each contact solve's Newton start was from its solution")
    ap.add_argument("--newton", default="", help="Newton class attributes (or VERLET_SKIN) "
                    "ATTR=VALUE[,...] for the run (as contact_suite.py --newton)")
    args = ap.parse_args()
    if args.case not in cs.CASES and not os.path.isfile(args.case):
        ap.error(f"{args.case}: neither a suite case nor a case file")
    if (args.modes or args.residuals or args.seabed_cells or args.probe_steps > 1) \
            and args.probe is None:
        ap.error("--modes, --residuals, --seabed-cells and --probe-steps need --probe")
    if args.watch is not None and args.probe is not None:
        ap.error("--watch reports a run's windows, not a probe: leave out --probe")
    if args.newton:
        from benchmarks.tuning import set_newton
        set_newton(args.newton)
    if args.probe is not None:
        cells = None
        if args.seabed_cells:
            a, b = (int(x) for x in args.seabed_cells.split(":"))
            cells = range(a, b)
        probe(args.case, args.probe, [float(x) for x in args.probe_dt.split(",")],
              args.residuals, args.sets, cells, args.modes, args.probe_steps)
        return
    if args.t_end is None:
        ap.error("--t-end is required (without --probe)")
    load = os.getloadavg()[0]
    wall = time.perf_counter()
    result = {}
    rows = [a for a in record(args.case, args.t_end, args.starts, args.sets, args.watch,
                              result)
            if a["t"] >= args.t_from - 1e-12]
    wall = time.perf_counter() - wall
    edges = (np.array([float(x) for x in args.edges.split(",")]) if args.edges
             else np.arange(args.t_from, args.t_end + 1e-9, args.every))
    for a, b in zip(edges[:-1], edges[1:]):
        part = [r for r in rows if a - 1e-12 <= r["t"] < b - 1e-12]
        if part:
            print(f"{a:7.2f}-{b:<7.2f} {summary(part)}")
            if args.starts:
                print("\n".join(_starts_of(part)))
            if args.watch is not None:
                print(_watched(part, args.watch))
    print(f"{args.t_from:.2f}-{args.t_end:.2f}  {summary(rows)}")
    if args.starts:
        print("\n".join(_starts_of(rows)))
    if args.watch is not None:
        print(_watched(rows, args.watch))
    if args.out and "ds" in result:
        result["ds"].to_netcdf(args.out)
        print(f"outputs written to {args.out}")
    if args.writhe and "ds" in result:
        print(writhe_readings(result["ds"], [float(x) for x in args.writhe.split(",")]))
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
