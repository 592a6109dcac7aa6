"""One step's problem: assembled in one place and handed to Newton.

A step of size h from the run's state (:class:`solver.state.RunState`) to t + h is the
system of difference equations of :mod:`solver.scheme` (the box scheme in s, the
generalized-α scheme in t, or backward Euler for a restart or across a switch of the
boundary conditions), with the boundary rows in force at t + h (:mod:`solver.boundary`,
plus the end correction of :meth:`ProblemAssembly.end_correction`), the loads
(:mod:`solver.loads`) and, with self-contact, the contact terms of the candidate pairs
(:mod:`solver.contact.search`). :class:`StepProblem` holds these; Newton
(:mod:`solver.newton`) solves it from the predicted start, and the contact coverage check
after Newton adds the pairs the search missed and solves again
(:meth:`ProblemAssembly.solve_problem`). What is done with the solution (the checks that
refuse it, the accepted state) is :meth:`solver.run.RodRun.try_step`. The run holds
the assembly as an object of its own (``run.assembly``) and hands it its state.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple, Optional

import numpy as np

from .boundary import BoundaryRows
from .contact.geometry import max_distance
from .kinematics import quat_to_matrix, relative_rotation, space_route
from .scheme import BACKWARD_EULER, alpha_parameters, pose_into
from .stepping import extrapolate, kappa_distance

__all__ = ["StepProblem", "Solution", "ProblemAssembly"]


@dataclass
class StepProblem:
    """The problem of one step.

    h : step, s; t_new : the time it ends at, s; left_limit : the loads take their left
    limit at t_new (a step landing on a breakpoint); restart : a backward-Euler restart
    step; bc : the boundary rows at t_new (with the end correction ``offset`` (12,) or
    None added); switched : the boundary conditions differ from the old level's; params :
    the time scheme's parameters (:func:`solver.scheme.alpha_parameters` or
    BACKWARD_EULER); predictions : dict of (N+1, 12) Newton starts by name or None;
    guess : the Newton start (N+1, 12); candidates : the contact candidate pairs or None.
    """

    h: float
    t_new: float
    left_limit: bool
    restart: bool
    bc: BoundaryRows
    switched: bool
    offset: Optional[np.ndarray]
    params: Any
    predictions: Optional[dict]
    guess: np.ndarray
    candidates: Any


class Solution(NamedTuple):
    """Newton's answer to a :class:`StepProblem`: the new level Y (N+1, 12), its node
    terms Fn, the iterations, the scaled residual, the pose (q, R, r) or None, the
    candidates the contact terms were evaluated for, and the reason it failed ("newton",
    "contact") or None."""

    Y: Any
    Fn: Any
    iterations: int
    residual: float
    pose: Any
    candidates: Any
    reason: Optional[str] = None
    nonfinite: bool = False


def end_drift_length(bc: BoundaryRows, n_last: int, q_end, r_end, r_time_end) -> float:
    """How far the carried s = L end ``r_end`` (3,) m, frame quaternion ``q_end`` (4,), lies
    from the end's prescribed motion ``r_time_end`` (3,) m: the length of the components
    a_i·(r_time − r) along the translations i that ``bc`` prescribes at node ``n_last``
    (a_i the end's body axes; 0 where none is prescribed). The output ``end_drift`` and
    the bound of :meth:`ProblemAssembly.drifts_off`. Raises nothing."""
    axes = [idx for _, idx in bc.end_kinematic_dofs(n_last) if idx < 3]
    if not axes:
        return 0.0
    q = np.asarray(q_end, dtype=float)
    R = quat_to_matrix((q / np.linalg.norm(q))[None, :])[0]
    e = R.T @ (np.asarray(r_time_end, dtype=float) - np.asarray(r_end, dtype=float))
    return float(np.sqrt(sum(e[i] ** 2 for i in axes)))


class ProblemAssembly:
    """The assembly of one step's problem and its solution by Newton: an object the run
    holds (``run.assembly``, :class:`solver.run.RodRun`). It holds the parts that do not
    change from step to step (the case, the rod's properties, the system of equations,
    Newton, the boundary schedule, the time scheme's parameters, the contact law and its
    candidate search) and is handed the state a step starts from
    (:class:`solver.state.RunState`, ``st``) by every method that reads it; the few that
    write it (:meth:`update_space_route`, :meth:`_hold_from_here`) rebind its arrays.

    Parameters
    ----------
    case : solver.case.Case
    props : solver.properties.RodProperties
    system : solver.scheme.RodSystem
    newton : solver.newton.NewtonSolver
    bc_schedule : solver.boundary.BoundarySchedule
    params : the generalized-α parameters of ``numerics.rho_inf``
    contact : solver.contact.SelfContact or None
    search : solver.contact.search.CandidateSearch or None
    """

    def __init__(self, case, props, system, newton, bc_schedule, params, contact=None,
                 search=None):
        self.case = case
        self.props = props
        self.system = system
        self.newton = newton
        self.bc_schedule = bc_schedule
        self.params = params
        self.contact = contact
        self.search = search

    #: the share of the s = L end's drift that each step's boundary values correct
    #: (:meth:`end_correction`; None: no correction). The correction enters the step's
    #: end motion through the trapezoid ½h(v^n + v^{n+1}), so the drift obeys
    #: e_{n+1} = e_n − ½g(e_{n−1} + e_n) + (the step's new route difference), whose
    #: roots have modulus √(g/2): g = 0.5 halves it per step (a damped oscillation).
    #: Measured with 0.25, 0.5 and 1 alike (docs/contact.md § 4)
    DRIFT_GAIN = 0.5
    #: the correction's rate is DRIFT_GAIN / max(h, DRIFT_STEP_FLOOR · numerics.dt, T_w): a
    #: step of at least a quarter of the case's Δt moves the end by g·e (halving the
    #: drift per step), every shorter step prescribes the end velocity of the floor's
    #: step, so a cut step's prescribed end velocity is at most 1/DRIFT_STEP_FLOOR times
    #: the uncut one's and its correction within the step vanishes with h. Why a floor:
    #: at the rate g/h a cut step prescribed a new end velocity g·e/h, a velocity jump
    #: whose impulse on the held end (its reaction growing as 1/h, 37 N to 3.7 kN with
    #: the floor at Δt/100) the energy check read as injected energy at every cut
    #: (cases/seabed-hockle.yaml failed at 5.1 s), and at a fixed drift e the end moved
    #: by g·e in every step however small, which the route rule read as the step's
    #: position error (PyElastica's plectoneme, N = 25, Δt = 0.1 s, ρ∞ = 0.8: without a
    #: floor it ended at 7.5 s, with the floor at Δt/100 at 11.4 s). Why not the floor
    #: at Δt: the correction is then slow on the many cut steps of a collapse, and the
    #: plectoneme's held end (Δt = 0.1 s, ρ∞ = 0.5) strays 31 mm from its axis against
    #: 14 mm at Δt/4 and Δt/100. Measured (``research/drift_rate.py``, docs/contact.md
    #: § 1): at Δt/4 all three complete and the seed example's events and |Wr| are those
    #: of Δt/100. Nor is the time constant ever shorter than one period of the fastest
    #: wave the grid carries (:attr:`solver.properties.RodProperties.fastest_wave_period`),
    #: which binds only where Δt/4 is shorter than that: at rates above it the correction
    #: and the end's answer to it fed each other (cases/seabed-hockle.yaml untwisted at
    #: Δt = 0.2 ms: the end's drift oscillated with a period of about ten steps, grew from
    #: 8 µm to 0.5 mm in 0.3 s and the run failed in Newton; with the period, 0.87 ms
    #: there, as the floor it completes; docs/contact.md, "Where the correction fed the
    #: drift")
    DRIFT_STEP_FLOOR = 0.25

    #: with ``numerics.backward_euler_retry`` (true by default; fixed steps only: the
    #: error estimate of ``numerics.tolerance`` is generalized-α's), the refusal reasons
    #: after which the retry (and any further one) is a backward-Euler step. The first
    #: step after a cut reads the rates Ẏⁿ carried from the longer step, an error that
    #: fades by |αm|/(1 − αm) per step (0.64 at ρ∞ = 0.8). On PyElastica's plectoneme (ρ∞ = 0.8,
    #: N = 25, Δt = 0.1 s) the first steps after a refusal put in 2.7 J over 10.4-11.2 s
    #: with Newton's tolerance ×1.1 while the others took out 0.5 J, the run's energy
    #: grew from 16 to 40 J and it failed at 11.46 s; with these retries every tolerance
    #: ×0.8-1.25 completes, in 14.1-17.3 Newton iterations per nominal step against
    #: 32.1-35.1 for the four of six that complete without, its writhe as far from the
    #: N = 100 run (docs/contact.md § 3). Not after a route refusal: that step is cut for
    #: its accuracy, which a first-order step lowers (the seed example: 70 route
    #: refusals against 40). After energy refusals only, PyElastica's spread completes too
    #: but in 24-38 Newton iterations per nominal step; the retries after Newton refusals
    #: stop more frictionless-bottom runs at the consistent restart at a knot of the held
    #: end's motion (docs/hockle.md, "Friction under imposed slack")
    BACKWARD_EULER_AFTER = ("newton", "energy")

    def step_problem(self, st, h: float, t_new=None, left_limit=False, restart=False,
                     predictor: str = "linear", after=None) -> StepProblem:
        """Assemble the problem of a step of h (s) from the current state, ending at
        t_new (default t + h): boundary rows, end correction, time scheme (backward Euler
        for a restart, after a switch of the conditions and, with
        ``numerics.backward_euler_retry``, after a refusal of
        :data:`BACKWARD_EULER_AFTER`; else generalized-α), predicted start and
        contact candidates. ``st``: the state the step starts from
        (:class:`solver.state.RunState`); ``predictor``: the Newton start's extrapolation,
        "linear" or "quadratic" (:meth:`_better_predictor`); ``after``: why the last
        attempt from this level was refused (None: it was accepted)."""
        sysm = self.system
        t_new = st.t + h if t_new is None else t_new
        bc = self.bc_schedule.at(t_new)
        switched = bc.key != st.bc.key
        offset = self.end_correction(st, h, bc, restart)
        if offset is not None:
            bc.values = bc.values + offset
        predictions = None if restart else self._predictions(st, h)
        if predictions is None:
            guess = st.Y
        else:
            guess = predictions.get(predictor, predictions["linear"])
        cand = None
        if self.contact is not None:
            cand = self._candidates(st, h, guess)
        if restart or switched:
            params = BACKWARD_EULER
        elif (self.case.numerics.backward_euler_retry
              and after in self.BACKWARD_EULER_AFTER):
            # the step after a Newton or energy refusal is cut, and generalized-α's
            # carried rates Ẏⁿ belong to the longer step: backward Euler, which does not
            # read them (docs/contact.md § 3, "The step after a refusal")
            params = BACKWARD_EULER
        elif cand is not None and self.case.numerics.contact_rho_inf is not None:
            # numerics.contact_rho_inf: where strands may meet, the scheme damps the modes
            # above 1/Δt by that ρ∞ per step (the tension variant at 0: 6,200 against
            # 12,188 Newton iterations over 45 s, its onset and final writhe unchanged;
            # docs/contact.md)
            params = alpha_parameters(self.case.numerics.contact_rho_inf)
        else:
            params = self.params
        return StepProblem(h, t_new, left_limit, restart, bc, switched, offset, params,
                           predictions, guess, cand)

    def begin_solve(self, st, prob: StepProblem, guess=None, candidates=None,
                    first: bool = True) -> np.ndarray:
        """Set the system up for the step of ``prob`` (:meth:`RodSystem.begin_step` on the
        old pose the step takes: the carried centreline, or with a seabed and no
        self-contact each node's time route) and return Newton's start (N+1, 12): ``guess``
        (default ``prob.guess``), made feasible on a ``first`` attempt with contact
        candidates (:meth:`_feasible_guess`), with the step's boundary values where the end
        correction moves them. ``candidates``: default ``prob.candidates`` (a repeated
        attempt passes the merged set). The one set-up of a step's Newton solve, which
        :meth:`solve_problem` and the diagnostics that repeat a solve share. Raises
        nothing."""
        cand = prob.candidates if candidates is None else candidates
        guess = prob.guess if guess is None else guess
        q_old, r_old, v_old = st.q, st.r, st.v_global
        if self.system.seabed is not None and self.contact is None:
            # the sea floor's spring acts on positions (a micrometre is a newton per metre
            # at its default stiffness): the step takes each node's own time route, which
            # it carries from step to step, not the shape integrated from κ, whose
            # difference from the last step's positions would jump the penetration
            q_old, r_old, v_old = st.q_time, st.r_time, st.v_global_time
        self.system.begin_step(prob.h, prob.params, prob.t_new, st.Y, st.Ydot, st.F_old,
                               prob.bc, q_old=q_old, r_old=r_old, v_old_global=v_old,
                               candidates=cand, left_limit=prob.left_limit)
        if first and cand is not None:
            guess = self._feasible_guess(st, guess)
        if prob.offset is not None:
            # the end correction moves the s = L values in every step, which no
            # extrapolation of earlier levels knows (nor the feasible start's blend):
            # the Newton start takes the step's boundary values (PyElastica's
            # plectoneme, N = 25, Δt = 0.1 s: 1066 against 1245 Newton iterations;
            # docs/contact.md § 4)
            guess = prob.bc.project(guess)
        return guess

    def solve_problem(self, st, prob: StepProblem) -> Solution:
        """Hand the step's problem to Newton (:meth:`solver.newton.NewtonSolver.solve`), set up
        by :meth:`begin_solve`. With self-contact every pair within reach of the new
        positions must have been among the candidates (the kept search holds them while
        the nodes stay within half its skin); pairs found beyond them are added and the
        step solved again, at most three times."""
        sysm, cand, guess = self.system, prob.candidates, prob.guess
        its_total = 0
        for attempt in range(3):
            guess = self.begin_solve(st, prob, guess, cand, first=attempt == 0)
            Y, Fn, its, res, ok, pose = self.newton.solve(guess)
            its_total += its
            if not ok:
                return Solution(Y, Fn, its_total, res, pose, cand, "newton",
                                not np.isfinite(res))
            if self.contact is None:
                break
            if pose is None:
                pose = sysm.pose_new(Y)
            if self.search.covers(pose[2]):
                break
            found = self.search.search(pose[2], pose[1], 0.0)
            if found is None or self.contact.covers(cand, found):
                break
            cand, guess = self.contact.merge(cand, found), Y
        else:
            return Solution(Y, Fn, its_total, res, pose, cand, "contact")
        return Solution(Y, Fn, its_total, res, pose, cand)

    @staticmethod
    def _body_force(glob, pose):
        """The global-frame distributed load glob (N+1, 3) in the body frames of pose
        ((R (N+1, 3, 3), ...)), or None without either."""
        if glob is None or pose is None:
            return None
        return np.einsum("nji,nj->ni", pose[0], glob)

    def _time_step(self, st, h, Y, q, r, v_global, offsets=None):
        """Nodes advanced one step h (s) in time, each on its own (the time route):
        q' = q ⊗ exp(½h(ω^n + ω)), r' = r + ½h(ṙ^n + R' v), with ω, v from Y (N+1, 12),
        q (N+1, 4), r and ṙ^n = v_global (N+1, 3) m, m/s. Returns (q' unnormalised,
        R' (N+1, 3, 3), ṙ' = R' v (N+1, 3), r' (N+1, 3)). ``offsets``: ((old-level
        offsets (12,) or None, their columns (12,)), (the same at the new level)): the
        boundary offsets of :meth:`end_correction`, taken out of both levels' unknowns
        first, so that the end node's time route is its prescribed motion."""
        Y_old = st.Y
        if offsets is not None and (offsets[0][0] is not None or offsets[1][0] is not None):
            (old, old_cols), (new, new_cols) = offsets
            Y_old, Y = Y_old.copy(), Y.copy()
            if old is not None:
                Y_old.reshape(-1)[old_cols] -= old
            if new is not None:
                Y.reshape(-1)[new_cols] -= new
        n1 = Y.shape[0]
        q_new, R_new, r_new, vg = (np.empty((n1, 4)), np.empty((n1, 3, 3)), np.empty((n1, 3)),
                                   np.empty((n1, 3)))
        c = np.ascontiguousarray
        pose_into(c(Y, dtype=float), c(Y_old, dtype=float), float(h), False, c(q, dtype=float),
                  c(r, dtype=float), c(v_global, dtype=float), True, 0.0, q_new, R_new, r_new,
                  np.empty((n1, 3)), vg)
        return q_new, R_new, vg, r_new

    def end_correction(self, st, h, bc, restart):
        """Offsets (12,) of the boundary values of a step of h (s) that keep the carried
        centreline's s = L end on its prescribed motion, or None (no self-contact: the
        centreline is not carried; a restart step; DRIFT_GAIN None).

        Why: with self-contact the centreline carried from step to step is the space
        route, integrated along s from κ and anchored at node 0 (docs/contact.md, "One
        geometry"). Node 0 is exact by construction, but the s = L end is wherever the
        integral of κ puts it: each step adds the difference between the two routes, and
        on PyElastica's plectoneme case (N = 25, Δt = 0.05 s) a laterally held end had
        drifted 25 mm off its axis and tilted 2.6° by the end of the collapse, and at
        Δt = 0.1 s the collapse pressed it onto the clamped end (docs/contact.md § 4).
        The end's own time route (its prescribed velocities integrated in time; the
        carried ``r_time``, ``q_time`` of node N, which the offsets do not enter) is
        where it should be. Each step prescribes, on top of the case's values, the
        velocity g·e/h and angular velocity g·θ/h toward it (g = DRIFT_GAIN; e and θ the
        position and tilt of the time route relative to the carried end, in the end's
        body frame; :meth:`solver.boundary.BoundaryRows.end_drift_offsets`):
        a Baumgarte stabilisation of the end's constraint at velocity level. The offset
        is O(route difference / h) = O(h²) on a smooth motion, so second order is kept,
        and it vanishes as Δt → 0 (measured: docs/contact.md § 4); on
        steps shorter than DRIFT_STEP_FLOOR · numerics.dt the rate is that of the floor,
        so that the end's prescribed velocity jumps by at most 1/DRIFT_STEP_FLOOR when a
        step is cut and the correction within a step vanishes with h even where the
        drift does not; nor is the rate's time constant ever shorter than one period of
        the fastest wave the grid carries (see DRIFT_STEP_FLOOR).
        """
        if self.contact is None or self.DRIFT_GAIN is None or restart:
            return None
        R, e = self.end_position_error(st)
        theta = relative_rotation(st.q[-1], st.q_time[-1])
        h_rate = max(h, self.DRIFT_STEP_FLOOR * self.case.numerics.dt,
                     self.props.fastest_wave_period)
        off = bc.end_drift_offsets(self.props.s.size - 1, e, theta, self.DRIFT_GAIN / h_rate)
        if bc.turning[1]:
            # a towed end free to turn holds global values (V, imposed through the new
            # frame): its body-frame offsets turned to global with the old-level frame
            off[6:9] = R @ off[6:9]
        return off

    def end_position_error(self, st):
        """(R, e): the carried s = L end's frame R (3, 3) and where the end's prescribed
        motion (its time route ``r_time``) puts it relative to the carried end,
        e = Rᵀ(r_time − r) at node N (3,) m, body frame: what :meth:`end_correction`
        steers back and the output ``end_drift`` reports. Raises nothing."""
        R = quat_to_matrix(st.q[-1:])[0]
        return R, R.T @ (st.r_time[-1] - st.r[-1])

    def end_drift(self, st) -> float:
        """How far the centreline's s = L end (integrated along s from κ, anchored at node
        0) is from the end's prescribed motion (its time route, the prescribed velocities
        integrated in time) (m): :func:`end_drift_length` of the carried end, the
        body-frame components a_i·(r_time − r) at node N along the end's prescribed
        translations i (:meth:`end_position_error`'s e). The output ``end_drift``. With
        self-contact this is what :meth:`end_correction` steers back and
        :meth:`drifts_off` bounds; without it the dynamics never see the integrated
        shape, which only the outputs show (docs/contact.md, "The far end is steered onto
        its prescribed motion"). 0 while no translation is prescribed at s = L (which
        translations are prescribed may change at a breakpoint). Raises nothing."""
        return end_drift_length(st.bc, self.props.s.size - 1, st.q[-1], st.r[-1],
                                st.r_time[-1])

    def end_drift_tolerance(self) -> float:
        """The largest end drift a step may leave (m): ``contact.end_drift_tolerance``, by
        default the rod's largest diameter (used with self-contact only)."""
        tol = self.case.contact.end_drift_tolerance
        return float(np.max(self.props.diameter)) if tol is None else float(tol)

    def drifts_off(self, prob: StepProblem, sol: Solution, r_time_end) -> bool:
        """Whether the converged step of ``prob`` leaves the carried s = L end farther than
        :meth:`end_drift_tolerance` from its prescribed motion (``r_time_end`` (3,) m, the
        end's time route at the new level): :func:`end_drift_length` at the new level.
        Not on a step that switches the end's conditions, where a newly held degree of
        freedom takes the carried end as its reference (:meth:`_hold_from_here`).

        Why a bound and not a cut of Δt: the two ends part at a rate, the difference
        between the end's prescribed velocity and the rate of the end integrated from κ,
        that shorter steps do not lower: the box rule's route rate, an error in s. On a
        member of docs/hockle.md's slack map in free space (160 segments, 8 turns,
        δ = 0.8 m) the route difference of one step from t = 3.6 s falls as h, 0.82, 0.19
        and 0.048 mm at h = 1.25, 0.31 and 0.078 ms, all at node N (0.62 m/s as Δt → 0,
        the box rule's route rate 0.674 m/s of it; 0.092 and 0.020 m/s on 320 and 640
        segments), and with ``contact.position_tolerance`` 1e-3 or 2.5e-4 m instead of
        5 mm the run still drifted 34-36 mm and then failed. In its wrapped loop the rate
        reaches 84 % of the fastest node's speed on 320 segments, which stop at the bound;
        640 complete with 8.6 mm (docs/contact.md § 1). Raises nothing."""
        if self.contact is None or prob.switched:
            return False
        q_end = sol.pose[0][-1]
        drift = end_drift_length(prob.bc, self.props.s.size - 1, q_end, sol.pose[2][-1],
                                 r_time_end)
        return drift > self.end_drift_tolerance()

    def _hold_from_here(self, st, prev_bc, bc) -> None:
        """A degree of freedom of the s = L end that has just become kinematic (a sliding
        end held, as the seed's at 30 s) is held where the carried end is, not where the
        end's time route had got to while it was free (the two differ by the route
        differences of the free motion, which :meth:`end_correction` does not touch): the
        end's time route is moved onto the carried end along each such translation axis
        a_i, and its frame set to the carried frame when ω1 or ω2 becomes prescribed."""
        R = quat_to_matrix(st.q[-1:])[0]
        for j, idx in bc.end_kinematic_dofs(self.props.s.size - 1):
            if prev_bc.kinematic[j] and prev_bc.cols[j] == bc.cols[j]:
                continue                          # held before: its reference stays
            if idx < 3:
                a = R[:, idx]
                st.r_time = st.r_time.copy()
                st.r_time[-1] += a * float(a @ (st.r[-1] - st.r_time[-1]))
            elif idx < 5:
                st.q_time = st.q_time.copy()
                st.q_time[-1] = st.q[-1]

    def _local_error(self, st, h, Y, r_new) -> float:
        """Local error indicator of a step (m): the largest distance between the new
        centreline (integrated along s from κ) and the same nodes advanced one
        trapezoidal step in time from the old centreline, r^n + ½h(ṙ^n + R^{n+1} v^{n+1})
        (R^{n+1} = R^n exp(½h(ω^n + ω^{n+1})) per node). Both are second-order routes to
        the same positions, so their difference is O(h³) per step and measures the step's
        position error (docs/contact.md, "Step control"); after a cut of h it also holds
        h·c(Ẏⁿ − Ẏ_E), the generalized-α rates carried from the longer step (docs/contact.md
        § 1)."""
        r_t = self._time_step(st, h, Y, st.q, st.r, st.v_global)[3]
        return max_distance(r_t, np.ascontiguousarray(r_new, dtype=float))

    def _candidates(self, st, h, guess):
        """Contact candidates for a step of h (s) from the Newton start ``guess``
        (N+1, 12): :meth:`solver.contact.search.CandidateSearch.candidates` between the
        old positions and those the start predicts (each node advanced in time)."""
        _, R_new, _, r_new = self._time_step(st, h, guess, st.q, st.r, st.v_global)
        return self.search.candidates(st.r, lambda: quat_to_matrix(st.q), r_new, R_new)

    def _feasible_guess(self, st, guess):
        """A Newton start whose contact gaps are open (:meth:`NewtonSolver.feasible_start`: the
        replay of the seed example's first contact, where an extrapolated start penetrated
        and Newton died at the barrier), unless ``guess`` is the old level itself. The
        step (with its candidates) must have been set up by ``system.begin_step``."""
        if guess is st.Y:
            return guess
        return self.newton.feasible_start(guess)

    def update_space_route(self, st) -> None:
        """Recompute the pose of ``st`` along the rod from κ, anchored at node 0's time-route
        pose (rebinds st.q, st.r, st.v_global)."""
        st.q, st.r = space_route(st.q_time[0], st.r_time[0], st.Y[:, 9:12],
                                     self.props.ds)
        st.v_global = np.einsum("nij,nj->ni", quat_to_matrix(st.q), st.Y[:, 0:3])

    def _predictions(self, st, h: float):
        """Newton starts for a step of h (s) extrapolated from the accepted levels: the
        line through the last two ("linear") and, with three since the last restart, the
        parabola through the last three ("quadratic", with the actual steps;
        :func:`solver.stepping.extrapolate`).
        None without a level before the current one. Returns a dict of (N+1, 12) arrays."""
        if st.Y_prev is None or not st.h_prev:
            return None
        # times relative to the current level (t = 0)
        h1 = st.h_prev
        out = {"linear": extrapolate((-h1, 0.0), (st.Y_prev, st.Y), h)}
        if st.Y_prev2 is not None and st.h_prev2:
            out["quadratic"] = extrapolate((-h1 - st.h_prev2, -h1, 0.0),
                                           (st.Y_prev2, st.Y_prev, st.Y), h)
        return out

    @staticmethod
    def _better_predictor(Y: np.ndarray, predictions: dict) -> str:
        """The predictor whose curvature κ was nearer the accepted level Y (N+1, 12)'s
        (sum of squares over the nodes; ``predictions`` as :meth:`_predictions` returns).
        κ is what the centreline, and so every contact gap, is
        integrated from: at the seed's 40 s the parabola's κ was 2-10× nearer and its
        centreline within 0.04-0.3 mm against 0.2-0.9 mm, while the RMS over all twelve
        unknowns ranked the two alike. The parabola halves the Newton iterations of the
        intertwined phase (156 → 89 over 40-43 s) but extrapolates an oscillation that
        alternates from step to step (a transient the step does not resolve, damped by
        ρ∞: the held end after 30 s) seven times instead of three (152 → 231 over
        30-33 s), so the last step's record decides."""
        best, least = None, None
        for k, g in predictions.items():
            err = kappa_distance(Y, g)
            if least is None or err < least:
                best, least = k, err
        return best
