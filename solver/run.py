"""One run of a case: its state, its step control and the step itself.

:class:`RodRun` owns the parts a step needs and tries one step:

* the state (``run.state``, :class:`solver.state.RunState`: Y, Ẏ, the previous levels,
  the poses, the end rotations, the energy accounts: ``run.state.Y``, ``run.state.t``);
* the step control (``run.control``, :class:`solver.stepping.control.StepControl`), which
  chooses the steps and calls :meth:`RodRun.try_step` (``run.control.h_next``,
  ``run.control.refusals``, the growth guard's ``run.control.guard.sigma``);
* the step's problem (``run.assembly``, :class:`solver.step_problem.ProblemAssembly`:
  boundary rows, loads, contact candidates from
  :class:`solver.contact.search.CandidateSearch`), handed to Newton
  (:class:`solver.newton.NewtonSolver`).

The run's attributes are its own (no property forwards to the state or the step control);
the sea floor is the system's (``run.system.seabed``). :func:`solver.simulation.integrate`
drives it; tests and benchmarks use it to reach the state between steps.
"""
from __future__ import annotations

import copy
import math

import numpy as np

from .balance import EnergyBalance
from .boundary import BoundarySchedule
from .contact import SelfContact
from .contact.search import CandidateSearch
from .energies import (distributed_power, distributed_work_into, end_loads, end_power,
                       end_work_into)
from .kinematics import normalize_quaternions, quat_to_matrix, rotate_rows
from .loads import LoadModel
from .newton import NewtonSolver
from .properties import RodProperties
from .recording import dense_state, interpolated_snapshot, snapshot
from .scheme import RodSystem, alpha_parameters
from .seabed import SeabedContact
from .state import RunState
from .step_problem import ProblemAssembly
from .stepping import ErrorControl, PIController
from .stepping.control import Attempt, StepControl

__all__ = ["RodRun"]


class RodRun:
    """The state of one run, its step control, and one step; :func:`solver.integrate` drives it.

    Exposed for tests and benchmarks that need the state between steps.

    Parameters
    ----------
    case : solver.case.Case (validated)
    extra_force : callable(t, run) -> (N+1, 3) or None, optional
        A further global-frame distributed force, N/m (:class:`solver.loads.LoadModel`).
    start : solver.initial.StartState or None, optional
        The state to start from (:func:`solver.simulation.integrate`); None: the case's
        initial configuration.
    """

    #: with numerics.tolerance and no contact.position_tolerance, the route rule's
    #: tolerance in steps where strands may meet (a node's position error per step, m)
    #: is at most ROUTE_RELATIVE × relative tolerance × rod length, so that the contact
    #: phase's accuracy follows the tolerance too (None: the search margin's quarter
    #: alone, as with fixed steps).
    #: Measured on the seed's first loop (docs/numerics.md § 7): with the margin's
    #: 5 mm alone the writhe stayed 1.1-2.7 % off a 6.25-ms reference at every
    #: tolerance from 1e-2 to 1e-4; tied, 1e-3 gives 0.65-1.2 % and 1e-4 0.37 %
    ROUTE_RELATIVE = 1.0

    #: output fields that need the centreline and frames (the space route)
    POSE_FIELDS = frozenset({"position", "orientation", "topology"})

    #: the Newton start of the next step, "linear" or "quadratic" extrapolation:
    #: whichever predicted the last accepted step better (:meth:`_better_predictor`)
    predictor = "linear"

    #: the energy check (:class:`solver.balance.EnergyBalance`, None: off), the last
    #: measured step's balance and the largest relative error of the accepted steps
    #: since the recorder last read it (NaN: none); class defaults, so that a run
    #: pickled before the check existed resumes without it
    energy_check = None
    last_balance = None
    energy_error = math.nan

    def __init__(self, case, extra_force=None, start=None):
        self.case = case
        num = case.numerics
        self.props = props = RodProperties.from_case(case)
        self.loads = LoadModel(case, props, extra=extra_force, owner=self)
        self.contact = self.search = None
        self.route_tolerance = math.inf
        self.last_step_error = 0.0
        if case.contact is not None:
            self.contact = SelfContact(case.contact, props.s, props.diameter, props.rho_a)
            self.search = CandidateSearch(self.contact, props.diameter)
            self.route_tolerance = self._route_tolerance()
        seabed = SeabedContact(case.seabed, props.diameter) if case.seabed is not None else None
        self.system = RodSystem(props, self.loads, contact=self.contact, seabed=seabed)
        self.newton = NewtonSolver(self.system, num.newton.tolerance, num.newton.max_iterations)
        if self.contact is not None:
            self.newton.position_tolerance = self.route_tolerance
        self.state = RunState.at_rest(case, props.s, start)
        # the boundary rows at any time, from the case's plan of conditions
        schedule = BoundarySchedule(case, props, self.system.n)
        if any(len(choice) > 5 and choice[5] for _, choices in schedule.plan
               for choice in choices):
            # an end towed with its rotation free: its boundary rows need the new frames
            self.system.needs_pose = True
        self.state.bc = schedule.at(self.state.t)
        # the step's problem and its Newton solve (the boundary schedule and the time
        # scheme's parameters live there)
        self.assembly = ProblemAssembly(case, props, self.system, self.newton, schedule,
                                        alpha_parameters(num.rho_inf), self.contact,
                                        self.search)
        self.control = StepControl(case, *self._controllers())
        # why the last attempt was refused ("newton", "contact", "error", "growth",
        # "energy", "drift"; None: accepted), which the next step's time scheme reads
        # (its Attempt carries it and the rest of its figures); the last accepted step's
        # Newton figures and contacts
        self.last_reject = None
        self.last_iterations = 0
        self.last_residual = 0.0
        self.contact_count = 0
        self.min_gap = math.inf
        self._initial_loads()
        self.energy_check = EnergyBalance.for_run(self)
        self.last_balance = None
        self.energy_error = math.nan

    def _route_tolerance(self) -> float:
        """Accuracy of a step where strands may meet (m): contact.position_tolerance, by
        default a quarter of the search margin, and with numerics.tolerance at most
        ROUTE_RELATIVE × relative tolerance × L."""
        case, props, num = self.case, self.props, self.case.numerics
        tol = case.contact.position_tolerance
        if tol is None:
            tol = 0.25 * (self.contact.tolerance - float(np.max(props.diameter)))
            if num.tolerance is not None and self.ROUTE_RELATIVE is not None:
                length = float(props.s[-1] - props.s[0])
                tol = min(tol, self.ROUTE_RELATIVE * num.tolerance.relative * length)
        return tol

    def _controllers(self):
        """(the error control of ``numerics.tolerance`` or None, the PI controller of
        fixed steps where strands may meet or None)."""
        num, props = self.case.numerics, self.props
        tol = num.tolerance
        errctl = (ErrorControl(tol.relative, tol.absolute, self.system.floor, num.rho_inf,
                               props.s)
                  if tol is not None else None)
        if errctl is not None:
            # the estimate is the corrector minus the predictor: a start that already
            # passes Newton's test would measure an error of exactly 0, blind below
            # Newton's tolerance (docs/numerics.md § 7, "Newton's noise")
            self.newton.min_iterations = 1
        route_pi = (PIController() if self.contact is not None and errctl is None
                    and math.isfinite(self.route_tolerance) else None)
        return errctl, route_pi

    def _initial_loads(self) -> None:
        """The loads at the start (t = 0, or a start state's time), last: an extra_force
        sees a complete run."""
        props, st = self.props, self.state
        glob = self.loads.global_force(st.t) if self.loads.has_global else None
        pose = ((quat_to_matrix(st.q), np.zeros((props.s.size, 3)), 0.0)
                if self.system.needs_pose else None)
        st.F_old, _ = self.system.node_terms(st.Y, False, pose, glob)
        if self.system.seabed is not None:
            # the sea floor's loads are cell terms, not node terms: each step's residual
            # takes their old level from the old pose (solver.seabed.seabed_into)
            Fn, Ff, M, _ = self.seabed_loads()
            st.seabed_power = self._seabed_power(Fn + Ff, M)
        st.body_force = self.loads.with_points(ProblemAssembly._body_force(glob, pose), st.t,
                                               None if pose is None else pose[0])
        st.power = end_power(st.Y, props) + distributed_power(st.Y, st.body_force, props)
        st.end_load = end_loads(st.Y, props)

    # ------------------------------------------------------------------- the step
    def try_step(self, h: float, t_new=None, left_limit=False, restart=False,
                 estimate=True) -> Attempt:
        """Attempt one step of size h (s), ending at t_new (default t + h; given exactly
        when the step lands on a breakpoint, with ``left_limit`` so that the loads are
        their left limit there). ``restart``: a backward-Euler restart step
        (:mod:`solver.stepping`); ``estimate=False``: no error estimate (the steps of a
        step-doubling estimate). On success the state advances and an accepted
        :class:`Attempt` is returned; on failure the state is untouched and the Attempt
        has ok False and the reason: Newton's or :meth:`_refusal`'s, or "drift" where the
        step passes them but leaves the s = L end beyond ``contact.end_drift_tolerance``
        from its prescribed motion (:meth:`drifts_off`; the step control then ends the
        run). Either way the Attempt carries what the step control decides by: its error
        and route ratios where they were measured and whether it had contact candidates.
        The run keeps the reason in ``last_reject`` (None after an accepted attempt) for
        the next step's time scheme (``ProblemAssembly.BACKWARD_EULER_AFTER``)."""
        asm, st = self.assembly, self.state
        prob = asm.step_problem(st, h, t_new, left_limit, restart, self.predictor,
                                self.last_reject)
        had = prob.candidates is not None
        sol = asm.solve_problem(st, prob)
        reason, summary, ratios = sol.reason, None, {}
        if reason is None:
            reason, summary, ratios = self._refusal(prob, sol, estimate)
        timed = None
        if reason is None:
            timed = self._time_route(prob, sol)
            if asm.drifts_off(prob, sol, timed[3][-1]):
                reason = "drift"             # the end strays off its prescribed motion
        if reason is not None:
            self.last_reject = reason
            return Attempt(False, sol.iterations, sol.residual, sol.nonfinite, reason,
                           had_candidates=had, **ratios)
        self._accept(prob, sol, summary, timed)
        self.last_reject = None
        return Attempt(True, sol.iterations, sol.residual, had_candidates=had, **ratios)

    def _refusal(self, prob, sol, estimate):
        """Why a converged step must be refused (None: it passes), its contact summary
        (count, smallest gap m) and the ratios it measured (a dict of the :class:`Attempt`'s
        ``route_ratio`` and ``error_ratio``, those measured). The checks, in order:
        interpenetration; the local error: the route rule where strands may meet (a node's
        trapezoidal step in time against the κ-integrated centreline) and, with
        numerics.tolerance, the estimate of :class:`solver.stepping.ErrorControl`, their
        ratios to their tolerances (in steps with contact candidates only the route rule:
        there the estimate follows the stiff law's impact transients; the seed case at
        tolerance 1e-2 ran its first loop at 5e-4 s steps, 20x the route rule's, which keeps
        its events within 0.001 s of a 6.25-ms reference; docs/numerics.md § 7); a strand
        through another within the step; the energy balance (:mod:`solver.balance`,
        ``numerics.energy_tolerance``; not in restarts; in steps with contact candidates
        with the contact law's account); the growth guard."""
        Y, pose, cand, h = sol.Y, sol.pose, sol.candidates, prob.h
        summary, ratios = None, {}
        if self.contact is not None:
            contact_count, min_gap = 0, math.inf
            if cand is not None and cand.runs:
                # unless Newton froze the selection, its last residual evaluated these
                # contacts at this very state
                frozen = self.newton.last_frozen
                vg = np.einsum("nij,nj->ni", pose[1], Y[:, 0:3]) if frozen else None
                contact_count, min_gap = self.system.contact_summary(pose[2], vg,
                                                                     not frozen)
            summary = (contact_count, min_gap)
            if min_gap < 0.0:
                return "contact", summary, ratios    # the surfaces interpenetrate
        ratio = 0.0
        if self.contact is not None:
            self.last_step_error = self.assembly._local_error(self.state, h, Y, pose[2])
            ratio = ratios["route_ratio"] = self.last_step_error / self.route_tolerance
            if self.control.errctl is None and ratio > 1.0:
                return "contact", summary, ratios
        if self.control.errctl is not None and not prob.restart and estimate:
            if cand is None:
                ratio = max(ratio, self.control.errctl.ratio(prob.t_new, Y, self.state.Y,
                                                     self.newton.filtered))
            ratios["error_ratio"] = ratio      # not estimated in restarts
            if ratio > 1.0:
                return "error", summary, ratios
        if self.contact is not None and self.contact.passes_through(self.state.r, pose[2]):
            return "contact", summary, ratios    # a strand passed through another
        self.last_balance = None
        if (self.energy_check is not None and not prob.restart
                and (cand is None or self.energy_check.contact_steps)):
            if self.state.balance is None:         # after a restart
                self.state.balance = self.energy_check.start(self)
            self.last_balance = self.energy_check.measure(self, prob, sol)
            if self.energy_check.refuses(self.last_balance):
                return "energy", summary, ratios     # the step put in energy no load gave
        if self.control.guard.limit is not None and not prob.restart and cand is None:
            if not self.control.guard.ok(self.system, h, Y):
                return "growth", summary, ratios
        return None, summary, ratios

    def _time_route(self, prob, sol):
        """Every node advanced in time by the step of ``prob`` to its solution ``sol`` on
        its own, the end correction's offsets taken out (:meth:`_time_step`): (q', R', ṙ',
        r') at the new level. A diagnostic (its distance to the space route is a
        discretisation-error indicator), the end rotations of the linking number, and node
        N's prescribed motion (:meth:`drifts_off`)."""
        st = self.state
        return self.assembly._time_step(st, prob.h, sol.Y, st.q_time, st.r_time, st.v_global_time,
                               offsets=((st.bc_offset, st.bc.cols),
                                        (prob.offset, prob.bc.cols)))

    def _accept(self, prob, sol, summary, timed) -> None:
        """Advance the state to the accepted solution of the step's problem, ``timed`` its
        time route (:meth:`_time_route`) (the state's fields read and written on
        ``self.state``)."""
        st = self.state
        Y, pose, h, bc, restart = sol.Y, sol.pose, prob.h, prob.bc, prob.restart
        g = prob.params.gamma
        Ydot = (Y - st.Y) / (g * h) - ((1.0 - g) / g) * st.Ydot
        q_t, _, vg_t, r_t = timed
        drift = normalize_quaternions(q_t)
        if self.contact is not None:
            self.contact_count, self.min_gap = summary
        errctl = self.control.errctl
        if errctl is not None:
            if restart:
                errctl.reset(prob.t_new, Y)
            else:
                errctl.push(prob.t_new, Y)
        st.quat_norm_error = max(st.quat_norm_error, drift)
        st.r_time, st.q_time, st.v_global_time = r_t, q_t, vg_t
        self._advance_accounts(prob, Y, pose)
        if self.energy_check is not None:
            # restarts are not measured: the next step starts afresh
            bal = self.last_balance
            st.balance = None if bal is None else bal.carry
            if bal is not None and (math.isnan(self.energy_error)
                                    or bal.relative > self.energy_error):
                self.energy_error = bal.relative
        if not restart:
            self.control.guard.since += 1
        if prob.predictions is not None and "quadratic" in prob.predictions:
            self.predictor = self.assembly._better_predictor(Y, prob.predictions)
        # after a restart the old level is inconsistent (f jumped): no extrapolation
        if restart:
            st.Y_prev2 = st.h_prev2 = st.Y_prev = st.h_prev = None
        else:
            st.Y_prev2, st.h_prev2 = st.Y_prev, st.h_prev
            st.Y_prev, st.h_prev = st.Y, h
        st.Y, st.Ydot, st.F_old = Y, Ydot, sol.Fn
        st.t = prob.t_new
        prev_bc, st.bc = st.bc, bc
        st.bc_offset = prob.offset
        if self.contact is not None:
            st.q = q = pose[0].copy()
            normalize_quaternions(q)
            st.r = pose[2]
            st.v_global = np.empty_like(st.r)
            rotate_rows(q, Y[:, 0:3], st.v_global)
            if prob.switched:
                self.assembly._hold_from_here(st, prev_bc, bc)
        elif self.system.needs_pose:
            self.assembly.update_space_route(st)
        if self.system.seabed is not None:
            self._advance_seabed_work(h)
        self.last_iterations, self.last_residual = sol.iterations, sol.residual

    def _seabed_pose(self):
        """(q, r, ṙ) the seabed acts on: the pose the steps carry with self-contact (the
        space route), else each node's time route (:meth:`solve_problem`)."""
        if self.contact is not None:
            return self.state.q, self.state.r, self.state.v_global
        return self.state.q_time, self.state.r_time, self.state.v_global_time

    def seabed_loads(self, pose=None):
        """The seabed's (normal reaction, friction, moment) per unit length (N+1, 3),
        global frame, and the surface penetration (N+1,) m, at the current level's
        pose (:meth:`_seabed_pose`; or pose = (q, r, ṙ) given), by
        :meth:`solver.seabed.SeabedContact.loads`."""
        q, r, v = self._seabed_pose() if pose is None else pose
        return self.system.seabed.loads(r, v, quat_to_matrix(q), self.state.Y[:, 3:6])

    def _seabed_power(self, F, M):
        """Power of the seabed's loads F, M (N+1, 3) on the current level, W: ∫ (F·ṙ +
        M·Ω) ds with the quadrature weights (Ω = R ω the global angular velocity)."""
        q, _, v = self._seabed_pose()
        omega = np.einsum("nij,nj->ni", quat_to_matrix(q), self.state.Y[:, 3:6])
        per = np.einsum("ni,ni->n", F, v) + np.einsum("ni,ni->n", M, omega)
        return float(per @ self.props.quad_weights)

    def _advance_seabed_work(self, h) -> None:
        """The seabed's work over an accepted step of h (s), by the trapezoid rule on its
        power at the two levels (its own account, ``seabed_work``, J: the dissipation of
        friction and damping, and the spring's energy)."""
        Fn, Ff, M, _ = self.seabed_loads()
        power = self._seabed_power(Fn + Ff, M)
        self.state.seabed_work = self.state.seabed_work + 0.5 * h * (self.state.seabed_power + power)
        self.state.seabed_power = power

    def _advance_accounts(self, prob, Y, pose) -> None:
        """The end rotations φ and the work and power of the loads over an accepted step
        to Y (N+1, 12): the displacement increments of the end sections (v, ω components,
        body frame) with the scheme's own generalized-α relation (the one κ obeys through
        E1). Their a3 rotations are the end rotations φ of the linking number, so Lk and
        the discrete twist advance consistently; with the end loads they give the work
        (:func:`solver.energies.end_work_into`), and per node the work of distributed
        global-frame loads (:func:`solver.energies.distributed_work_into`)."""
        props, params, h = self.props, prob.params, prob.h
        g, am, af = params.gamma, params.alpha_m, params.alpha_f
        glob = self.system.step.glob_force
        body = ProblemAssembly._body_force(glob, None if pose is None else (pose[1],))
        body = self.loads.with_points(body, prob.t_new, None if pose is None else pose[1],
                                      prob.left_limit)
        st = self.state                 # read and written directly (every step)
        loads, xdot = np.empty((2, 6)), np.empty((2, 6))
        work, power, dphi0, dphi1 = end_work_into(Y, st.Y, float(h), float(g), float(am),
                                                  float(af), st.xdot_end, st.end_load,
                                                  props.stiffness, xdot, loads)
        st.phi = st.phi + np.array([dphi0, dphi1])
        st.work_in += work
        st.xdot_end, st.end_load = xdot, loads
        if self.loads.has_global or self.loads.points is not None:
            # distributed global-frame loads (and point loads, as loads per node length):
            # the same per node, with the quadrature weights
            vdot = np.empty_like(st.xdot_nodes)
            none = np.zeros((0, 3))
            old = st.body_force
            work, dpower = distributed_work_into(
                Y, st.Y, float(h), float(g), float(am), float(af), st.xdot_nodes,
                none if old is None else old, old is not None,
                none if body is None else body, body is not None, props.quad_weights, vdot)
            st.work_in += work
            power += dpower
            st.xdot_nodes = vdot
        st.power, st.body_force = power, body

    # ------------------------------------------------- step control (StepControl)
    def advance(self, t_target: float):
        """Advance to t_target (s) by fixed steps (:meth:`StepControl.advance`);
        returns (iterations, residual)."""
        return self.control.advance(self, t_target)

    def step_adaptive(self, t_stop: float):
        """One accepted error-controlled step toward t_stop (s)
        (:meth:`StepControl.step_adaptive`); returns (iterations, residual)."""
        return self.control.step_adaptive(self, t_stop)

    def _h_cap(self) -> float:
        """Largest Δt (s) the growth guard allows now (inf when no growth is known)."""
        return self.control.guard.cap()

    def _state(self):
        """The run's state between steps, for :meth:`_restore`: the state (a shallow
        copy: the accepted-step path rebinds every array it changes), the step control's
        and the run's own attributes, the kept contact candidates and the error
        control's history. The growth guard's knowledge is not part of it: a check made
        in a probe step serves the steps that replace it."""
        own = dict(self.__dict__)
        own["state"] = copy.copy(self.state)
        return (own, dict(self.control.__dict__),
                self.search.verlet if self.search is not None else None,
                self.control.errctl.state() if self.control.errctl is not None else None)

    def _restore(self, saved, refused=None) -> None:
        """Return to a :meth:`_state` (which stays valid for another restore). ``refused``:
        the reason of a refused attempt that the restore takes back, kept for the next
        step's time scheme (``last_reject``; None: the saved one)."""
        own, control, verlet, errctl = saved
        self.__dict__.update(own)
        if refused is not None:
            self.last_reject = refused
        self.state = copy.copy(own["state"])
        self.control.__dict__.update(control)
        if self.search is not None:
            self.search.verlet = verlet
        if self.control.errctl is not None:
            self.control.errctl.restore(errctl)

    # ------------------------------------------------------------- outputs
    def end_drift(self) -> float:
        """How far the carried s = L end is from its prescribed motion now, m
        (:meth:`solver.step_problem.ProblemAssembly.end_drift`; the output ``end_drift``)."""
        return self.assembly.end_drift(self.state)

    def update_space_route(self) -> None:
        """The state's centreline and frames integrated from its κ
        (:meth:`solver.step_problem.ProblemAssembly.update_space_route`), for the outputs
        where the steps do not keep them."""
        self.assembly.update_space_route(self.state)

    def snapshot(self, fields: set, route_current: bool = False) -> dict:
        """Output quantities of the current state (:func:`solver.recording.snapshot`)."""
        return snapshot(self, fields, route_current)

    def dense_state(self):
        """The start of a step's dense output (:func:`solver.recording.dense_state`)."""
        return dense_state(self)

    def interpolated_snapshot(self, fields: set, t: float, start) -> dict:
        """The outputs at t (s) inside the last step
        (:func:`solver.recording.interpolated_snapshot`)."""
        return interpolated_snapshot(self, fields, t, start)
