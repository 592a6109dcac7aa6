"""The time loop: ``simulate(case) -> xarray.Dataset`` (docs/interfaces.md, "Python API").

Each time step solves the box/generalized-α difference equations of
:mod:`solver.scheme` for all grid points at once by Newton. A step that does not converge
is retried from the restored state with Δt cut by ``numerics.dt_cut_factor``, up to
``numerics.max_dt_cuts`` times (WHOI Cable's adaptive pattern, numerics-notes §1.2); the
cut steps complete the nominal step, so outputs stay on the nominal time grid. When all
cuts fail, :class:`SolverDivergence` is raised carrying the partial dataset.

Steps land on the case's breakpoints (force windows, ``until`` switches, corners of
boundary tables); at t = 0 and after each breakpoint two short backward-Euler steps
restart the scheme consistently (:mod:`solver.stepping`, docs/numerics.md § 7).
"""
from __future__ import annotations

import copy
import functools
import math
import pickle
import time as _time
from dataclasses import dataclass

import numpy as np

from .banded import BlockLU
from .boundary import BoundaryRows, boundary_plan
from .contact import SelfContact
from .contact.geometry import max_distance
from .energies import (distributed_power, distributed_work_into, end_loads, end_power,
                       end_work_into, energies)
from .initial import apply_start, initial_state, start_step
from .kinematics import (normalize_quaternions, quat_slerp,
                         quat_to_matrix, relative_rotation, rotate_rows, space_route)
from .loads import LoadModel, end_reactions
from .properties import RodProperties
from .newton import Newton
from .scheme import BACKWARD_EULER, RodSystem, alpha_parameters, pose_into
from .stepping import (RESTART_FRACTION, RESTART_STEPS, ErrorControl, PIController,
                       breakpoints, extrapolate,
                       growth_rate, hermite)

__all__ = ["simulate", "SolverDivergence", "Progress", "RodRun", "RateEstimate"]


@dataclass(frozen=True)
class Progress:
    """What the progress callback receives after every accepted nominal step.

    t, t_end, dt: s; step: number of nominal steps done; newton_iterations: of the last
    step; residual_norm: scaled (dimensionless); wall_time: s since the start;
    fraction: t / t_end in [0, 1]; eta_seconds: wall seconds left at the recent pace
    (:class:`RateEstimate`), None until known.
    """

    t: float
    t_end: float
    step: int
    dt: float
    newton_iterations: int
    residual_norm: float
    wall_time: float
    fraction: float
    contact_count: int = 0
    eta_seconds: float | None = None


class RateEstimate:
    """Wall-clock seconds left, from the recent rate of simulated time per wall second.

    The rate is taken over the last ``max(window_s, share × elapsed)`` wall seconds, so a
    run that slows down (the seed example: 60 ms per 0.1 s before contact, seconds after)
    is extrapolated at its current pace, not at its average since the start (which
    promised a minute against ~21 min). Returns None until two samples exist.
    """

    def __init__(self, window_s: float = 30.0, share: float = 0.2):
        self.window_s = window_s
        self.share = share
        self.samples: list = []          # (wall s, simulated s)

    def update(self, wall: float, t: float, t_end: float):
        """Record a sample (wall: s since the start; t, t_end: simulated s) and return the
        wall seconds left at the recent pace, or None while the pace is unknown."""
        self.samples.append((wall, t))
        span = max(self.window_s, self.share * wall)
        while len(self.samples) > 2 and self.samples[1][0] < wall - span:
            self.samples.pop(0)
        (w0, t0), (w1, t1) = self.samples[0], self.samples[-1]
        if t1 <= t0 or w1 <= w0:
            return None
        return max(0.0, (t_end - t1) * (w1 - w0) / (t1 - t0))


class SolverDivergence(RuntimeError):
    """A time step could not be completed even after all Δt cuts.

    Attributes: t (s, the time reached), step (nominal steps completed), residual (the
    scaled residual of the last attempt), reason ("solver_diverged" or
    "nonfinite_state"), partial (the xarray.Dataset up to the last accepted step).
    """

    def __init__(self, message, t, step, residual, reason, partial=None):
        super().__init__(message)
        self.t = t
        self.step = step
        self.residual = residual
        self.reason = reason
        self.partial = partial


class RodRun:
    """The state of one run and the step logic; :func:`simulate` drives it.

    Exposed for tests and benchmarks that need the state between steps.

    Parameters
    ----------
    case : solver.case.Case (validated)
    extra_force : callable(t, run) -> (N+1, 3) or None, optional
        A further global-frame distributed force, N/m (:class:`solver.loads.LoadModel`).
    start : solver.initial.StartState or None, optional
        The state to start from (:func:`simulate`); None: the case's initial one.
    """

    GROW_AFTER = 3   # accepted substeps at one Δt level before Δt is allowed to grow
    GUARD_EVERY = 10  # accepted steps between growth-guard checks at an unchanged Δt
    GROW_AFTER_MAX = 48  # the same after repeated failed growths (doubling back-off)

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

    #: the level before Y_prev and its step (s), for the quadratic predictor (class
    #: defaults: runs pickled before it existed read them too)
    Y_prev2 = None
    h_prev2 = None
    #: the Newton start of the next step, "linear" or "quadratic" extrapolation:
    #: whichever predicted the last accepted step better (:meth:`_better_predictor`)
    predictor = "linear"

    def __init__(self, case, extra_force=None, start=None):
        self.case = case
        num = case.numerics
        self.props = props = RodProperties.from_case(case)
        self.loads = LoadModel(case, props, extra=extra_force, owner=self)
        self.contact = None
        self.route_tolerance = math.inf
        self.last_step_error = 0.0
        if case.contact is not None:
            self.contact = SelfContact(case.contact, props.s, props.diameter, props.rho_a)
            # accuracy of a step where strands may meet (m): contact.position_tolerance,
            # by default a quarter of the search margin, and with numerics.tolerance at
            # most relative × L (ROUTE_RELATIVE)
            self.route_tolerance = case.contact.position_tolerance
            if self.route_tolerance is None:
                self.route_tolerance = 0.25 * (self.contact.tolerance
                                               - float(np.max(props.diameter)))
                if num.tolerance is not None and self.ROUTE_RELATIVE is not None:
                    length = float(props.s[-1] - props.s[0])
                    self.route_tolerance = min(self.route_tolerance, self.ROUTE_RELATIVE
                                               * num.tolerance.relative * length)
        self.system = RodSystem(props, self.loads, contact=self.contact)
        self.newton = Newton(self.system, num.newton.tolerance, num.newton.max_iterations)
        self.params = alpha_parameters(num.rho_inf)
        self.rho_inf = num.rho_inf
        n1 = props.s.size
        self.t = 0.0
        self.Y = np.zeros((n1, 12))
        self.Ydot = np.zeros((n1, 12))
        self.Y_prev = None
        self.h_prev = None
        # space-route pose and unknowns at the start (solver.initial: the case's initial
        # configuration, or a StartState from an earlier result)
        self.q, self.r, self.Y, self.t = initial_state(case, props.s, start)
        self.q_time = self.q.copy()                       # time-route pose (diagnostic)
        self.r_time = self.r.copy()
        self.bc_offset = None                             # end_correction of the last step
        self.v_global = np.zeros((n1, 3))
        self.v_global_time = np.zeros((n1, 3))
        self.phi = np.zeros(2)                            # end rotations about a3, rad
        self.work_in = 0.0
        if start is not None:
            apply_start(self, start)
        # end displacement rates (2, 6) of the α-relation, m/s and rad/s; [:, 5] is φ̇
        self.xdot_end = np.zeros((2, 6))
        self.xdot_nodes = np.zeros((n1, 3))               # node displacement rates, m/s
        # (advanced only where distributed loads do work: loads.has_global)
        self.quat_norm_error = 0.0
        self.bc_plan = boundary_plan(case, props, self.system.n)
        self.bc = BoundaryRows(case, props, self.t, self.system.n, self.bc_plan)
        self.breakpoints = breakpoints(case)
        # error-controlled steps (numerics.tolerance): the estimator and controller, the
        # error ratio of the last estimated step, the next step size; why the last
        # attempt was refused ("newton", "contact", "error", "growth")
        tol = num.tolerance
        self.errctl = (ErrorControl(tol.relative, tol.absolute, self.system.floor, num.rho_inf,
                                    props.s)
                       if tol is not None else None)
        if self.errctl is not None:
            # the estimate is the corrector minus the predictor: a start that already
            # passes Newton's test would measure an error of exactly 0, blind below
            # Newton's tolerance (docs/numerics.md § 7, "Newton's noise")
            self.newton.min_iterations = 1
        self.last_error_ratio = math.nan
        self.h_next = num.dt
        self.last_reject = None
        # refused step attempts so far, by reason (the dataset's step_rejected_attempts
        # and hockle_refused_attempts)
        self.refusals = {"error": 0, "newton": 0, "contact": 0, "growth": 0}
        self.last_had_candidates = False
        # growth guard (solver.stepping.growth_rate): the last estimate of the fastest
        # growth rate σ (1/s; NaN: not yet checked), the Δt it was checked at, the largest
        # Δt checked, accepted steps since, the Arnoldi start vector
        self.growth_guard = num.growth_guard
        self.guard_sigma = math.nan
        self.guard_h = 0.0
        self.guard_h_max = 0.0
        self.guard_since = 0
        self.guard_v0 = None
        self._guard_layout = None
        self.restart_pending = True       # a consistent restart before the next step
        self.level_hint = 0
        self.accepted_at_level = 0
        self.grow_after = self.GROW_AFTER
        # fixed steps where strands may meet: Δt from the route rule's error ratio by the
        # PI controller (:meth:`_route_step`); h_route is the next such step (None: the
        # levels of :meth:`_advance_to` decide)
        self.route_pi = (PIController() if self.contact is not None and self.errctl is None
                         and math.isfinite(self.route_tolerance) else None)
        self.h_route = None
        self.last_route_ratio = math.nan
        self.last_iterations = 0
        self.last_residual = 0.0
        self.last_dt = num.dt
        self.contact_count = 0
        self.min_gap = math.inf
        # the loads at t = 0, last: an extra_force sees a complete run
        glob = self.loads.global_force(self.t) if self.loads.has_global else None
        pose = ((quat_to_matrix(self.q), np.zeros((n1, 3)), 0.0)
                if self.system.needs_pose else None)
        self.F_old, _ = self.system.node_terms(self.Y, False, pose, glob)
        self.body_force = self.loads.with_points(self._body_force(glob, pose), self.t,
                                                 None if pose is None else pose[0])
        self.power = end_power(self.Y, props) + distributed_power(self.Y, self.body_force, props)
        self.end_load = end_loads(self.Y, props)

    @staticmethod
    def _body_force(glob, pose):
        if glob is None or pose is None:
            return None
        return np.einsum("nji,nj->ni", pose[0], glob)

    # -------------------------------------------------------------------------------
    def try_step(self, h: float, t_new=None, left_limit=False, restart=False,
                 estimate=True):
        """Attempt one step of size h (s), ending at t_new (default t + h; given exactly
        when the step lands on a breakpoint, with ``left_limit`` so that the loads are
        their left limit there). ``restart``: a backward-Euler restart step
        (:mod:`solver.stepping`); ``estimate=False``: no error estimate (the steps of a
        step-doubling estimate, :meth:`_doubled_step`). On success the state advances and
        (True, iterations, residual, nonfinite=False) is returned; on failure the state is
        untouched."""
        sysm = self.system
        self.last_route_ratio = math.nan
        t_new = self.t + h if t_new is None else t_new
        bc = BoundaryRows(self.case, self.props, t_new, sysm.n, self.bc_plan)
        switched = bc.key != self.bc.key
        offset = self.end_correction(h, bc, restart)
        if offset is not None:
            bc.values = bc.values + offset
        params = BACKWARD_EULER if (restart or switched) else self.params
        predictions = None if restart else self._predictions(h)
        if predictions is None:
            guess = self.Y
        else:
            guess = predictions.get(self.predictor, predictions["linear"])
        cand = None
        if self.contact is not None:
            cand = self._candidates(h, guess)
        self.last_had_candidates = cand is not None
        its_total = 0
        for attempt in range(3):
            sysm.begin_step(h, params, t_new, self.Y, self.Ydot, self.F_old, bc,
                            q_old=self.q, r_old=self.r, v_old_global=self.v_global,
                            candidates=cand, left_limit=left_limit)
            if attempt == 0 and cand is not None:
                guess = self._feasible_guess(guess)
            if offset is not None:
                # the end correction moves the s = L values in every step, which no
                # extrapolation of earlier levels knows (nor the feasible start's blend):
                # the Newton start takes the step's boundary values (PyElastica's
                # plectoneme, N = 25, Δt = 0.1 s: 1066 against 1245 Newton iterations;
                # docs/contact.md § 4, session 18)
                guess = bc.project(guess)
            Y, Fn, its, res, ok, pose = self.newton.solve(guess)
            its_total += its
            if not ok:
                self.last_reject = "newton"
                return False, its_total, res, not np.isfinite(res)
            if self.contact is None:
                break
            if pose is None:
                pose = sysm.pose_new(Y)
            # every combination within reach of the new positions must have been searched
            # (the kept search holds them while the nodes stay within half its skin)
            if self._verlet_covers(pose[2]):
                break
            found = self._search(pose[2], pose[1], 0.0)
            if found is None or self.contact.covers(cand, found):
                break
            cand, guess = self.contact.merge(cand, found), Y
        else:
            self.last_reject = "contact"
            return False, its_total, res, False
        its = its_total
        if self.contact is not None:
            contact_count, min_gap = 0, math.inf
            if cand is not None and cand.runs:
                # unless Newton froze the selection, its last residual evaluated these
                # contacts at this very state
                frozen = self.newton.last_frozen
                vg = np.einsum("nij,nj->ni", pose[1], Y[:, 0:3]) if frozen else None
                contact_count, min_gap = sysm.contact_summary(pose[2], vg, not frozen)
            if min_gap < 0.0:
                # the surfaces interpenetrate: reject, the caller cuts Δt
                self.last_reject = "contact"
                return False, its, res, False
        # local error: the route rule where strands may meet (a node's trapezoidal step
        # in time against the κ-integrated centreline) and, with numerics.tolerance, the
        # estimate of solver.stepping.ErrorControl; their ratios to their tolerances. In
        # steps with contact candidates only the route rule: there the estimate follows
        # the stiff law's impact transients (the seed case at tolerance 1e-2 ran its first
        # loop at 5e-4 s steps, 20x the route rule's, which keeps its events within
        # 0.001 s of a 6.25-ms reference; docs/numerics.md § 7). With a tolerance the
        # route rule's own tolerance follows it (ROUTE_RELATIVE)
        ratio = 0.0
        if self.contact is not None:
            self.last_step_error = self._local_error(h, Y, pose[2])
            ratio = self.last_route_ratio = self.last_step_error / self.route_tolerance
            if self.errctl is None and ratio > 1.0:
                self.last_reject = "contact"
                return False, its, res, False
        if self.errctl is not None and not restart and estimate:
            if cand is None:
                ratio = max(ratio, self.errctl.ratio(t_new, Y, self.Y, self.newton.filtered))
            self.last_error_ratio = ratio      # NaN: not estimated (after a restart)
            if ratio > 1.0:
                self.last_reject = "error"
                return False, its, res, False
        if self.contact is not None and self.contact.passes_through(self.r, pose[2]):
            # a strand passed through another within the step
            self.last_reject = "contact"
            return False, its, res, False
        if self.growth_guard is not None and not restart and cand is None:
            if not self._growth_ok(h, Y):
                self.last_reject = "growth"
                return False, its, res, False
        # accept ------------------------------------------------------------------
        g = params.gamma
        Ydot = (Y - self.Y) / (g * h) - ((1.0 - g) / g) * self.Ydot
        props = self.props
        # time route of every node (a diagnostic: its distance to the space route is a
        # discretisation-error indicator) and the end rotations (linking number)
        q_t, _, vg_t, r_t = self._time_step(h, Y, self.q_time, self.r_time,
                                              self.v_global_time,
                                              offsets=((self.bc_offset, self.bc.cols),
                                                       (offset, bc.cols)))
        drift = normalize_quaternions(q_t)
        if self.contact is not None:
            self.contact_count, self.min_gap = contact_count, min_gap
        if self.errctl is not None:
            if restart:
                self.errctl.reset(t_new, Y)
            else:
                self.errctl.push(t_new, Y)
        self.quat_norm_error = max(self.quat_norm_error, drift)
        self.r_time, self.q_time, self.v_global_time = r_t, q_t, vg_t
        # displacement increments of the end sections (v, ω components, body frame) with
        # the scheme's own generalized-α relation (the one κ obeys through E1). Their
        # a3 rotations are the end rotations φ of the linking number, so Lk and the
        # discrete twist advance consistently; with the end loads they give the work.
        am, af = params.alpha_m, params.alpha_f
        glob = sysm._glob_force
        body = self._body_force(glob, None if pose is None else (pose[1],))
        body = self.loads.with_points(body, t_new, None if pose is None else pose[1],
                                      left_limit)
        loads, xdot = np.empty((2, 6)), np.empty((2, 6))
        work, power, dphi0, dphi1 = end_work_into(Y, self.Y, float(h), float(g), float(am),
                                                  float(af), self.xdot_end, self.end_load,
                                                  props.stiffness, xdot, loads)
        self.phi = self.phi + np.array([dphi0, dphi1])
        self.work_in += work
        self.xdot_end, self.end_load = xdot, loads
        if self.loads.has_global or self.loads.points is not None:
            # distributed global-frame loads (and point loads, as loads per node length):
            # the same per node, with the quadrature weights
            vdot = np.empty_like(self.xdot_nodes)
            none = np.zeros((0, 3))
            work, dpower = distributed_work_into(
                Y, self.Y, float(h), float(g), float(am), float(af), self.xdot_nodes,
                none if self.body_force is None else self.body_force, self.body_force is not None,
                none if body is None else body, body is not None, props.quad_weights, vdot)
            self.work_in += work
            power += dpower
            self.xdot_nodes = vdot
        self.power, self.body_force = power, body
        if not restart:
            self.guard_since += 1
        if predictions is not None and "quadratic" in predictions:
            self.predictor = self._better_predictor(Y, predictions)
        # after a restart the old level is inconsistent (f jumped): no extrapolation
        if restart:
            self.Y_prev2 = self.h_prev2 = self.Y_prev = self.h_prev = None
        else:
            self.Y_prev2, self.h_prev2 = self.Y_prev, self.h_prev
            self.Y_prev, self.h_prev = self.Y, h
        self.Y, self.Ydot, self.F_old = Y, Ydot, Fn
        self.t = t_new
        prev_bc, self.bc = self.bc, bc
        self.bc_offset = offset
        if self.contact is not None:
            self.q = pose[0].copy()
            normalize_quaternions(self.q)
            self.r = pose[2]
            self.v_global = np.empty_like(self.r)
            rotate_rows(self.q, self.Y[:, 0:3], self.v_global)
            if switched:
                self._hold_from_here(prev_bc, bc)
        elif sysm.needs_pose:
            self.update_space_route()
        self.last_iterations, self.last_residual = its, res
        return True, its, res, False

    def _growth_ok(self, h, Y) -> bool:
        """The growth guard for a converged step of h (s) to Y (N+1, 12): False when the
        fastest growth rate σ of the linearised dynamics has σh > ``numerics.growth_guard``
        (such a step would damp the growing mode instead of following it). σ is estimated
        (:func:`solver.stepping.growth_rate`, shift 2g/h, which finds every σ up to 4g/h;
        and 16g/h as well when h is more than twice the largest step checked so far)
        every GUARD_EVERY accepted steps (every 4 GUARD_EVERY while the last check found
        σh < g/4), at every step longer than a tenth of the bending time scale
        L²√(ρA/EJ) (a run of a few long steps would otherwise see one check: the
        stability map's twisted rod at Δt = 0.3 s buckles after its fifth step), and
        whenever h exceeds twice the step of the last
        check (below that the last check's disc covers σ = g/h); in between the last
        estimate is used. Not run for steps with contact candidates (their Jacobian is not
        banded)."""
        g = self.growth_guard
        # far from the limit (σh < g/4 at the last check) a check every 4·GUARD_EVERY
        every = self.GUARD_EVERY * (4 if self.guard_sigma * self.guard_h < 0.25 * g else 1)
        if (math.isnan(self.guard_sigma) or self.guard_since >= every
                or h > 2.0 * self.guard_h or h > 0.1 * self.system.tc):
            if self._guard_layout is None:
                self._guard_layout = BlockLU(self.system.n_cells)
            sigma, vec = growth_rate(self.system, Y, 2.0 * g / h, self._guard_layout,
                                     self.guard_v0)
            # further out (16g/h) at new largest steps, and when a growth known from the
            # last check is not in the near disc any more: under a rising load σ grows
            # past 4g/h rather than vanishing (the stability map's twisted rod at Δt =
            # 0.3 s: σ = 2.2 s⁻¹, then none in (0, 14), then 21 s⁻¹ one step later)
            if h > 2.0 * self.guard_h_max or (not sigma > 0.0 and self.guard_sigma > 0.0):
                far, _ = growth_rate(self.system, Y, 16.0 * g / h, self._guard_layout)
                sigma = max(sigma, far)
                self.guard_h_max = max(self.guard_h_max, h)
            self.guard_sigma = max(sigma, 0.0)
            self.guard_v0 = vec
            self.guard_h = h
            self.guard_since = 0
        return self.guard_sigma * h <= g * (1.0 + 1e-9)

    def _h_cap(self) -> float:
        """Largest Δt (s) the growth guard allows now (inf when no growth is known)."""
        if self.growth_guard is None or not self.guard_sigma > 0.0:
            return math.inf
        return self.growth_guard / self.guard_sigma

    def _time_step(self, h, Y, q, r, v_global, offsets=None):
        """Nodes advanced one step h (s) in time, each on its own (the time route):
        q' = q ⊗ exp(½h(ω^n + ω)), r' = r + ½h(ṙ^n + R' v), with ω, v from Y (N+1, 12),
        q (N+1, 4), r and ṙ^n = v_global (N+1, 3) m, m/s. Returns (q' unnormalised,
        R' (N+1, 3, 3), ṙ' = R' v (N+1, 3), r' (N+1, 3)). ``offsets``: ((old-level
        offsets (12,) or None, their columns (12,)), (the same at the new level)): the
        boundary offsets of :meth:`end_correction`, taken out of both levels' unknowns
        first, so that the end node's time route is its prescribed motion."""
        Y_old = self.Y
        if offsets is not None and any(o is not None for o, _ in offsets):
            (old, old_cols), (new, new_cols) = offsets
            Y_old, Y = Y_old.copy(), Y.copy()
            if old is not None:
                Y_old.reshape(-1)[old_cols] -= old
            if new is not None:
                Y.reshape(-1)[new_cols] -= new
        n1 = Y.shape[0]
        q_new, R_new, r_new, vg = (np.empty((n1, 4)), np.empty((n1, 3, 3)), np.empty((n1, 3)),
                                   np.empty((n1, 3)))
        pose_into(np.ascontiguousarray(Y, dtype=float), np.ascontiguousarray(Y_old, dtype=float),
                  float(h), False, np.ascontiguousarray(q, dtype=float),
                  np.ascontiguousarray(r, dtype=float),
                  np.ascontiguousarray(v_global, dtype=float), True, 0.0, q_new, R_new, r_new,
                  np.empty((n1, 3)), vg)
        return q_new, R_new, vg, r_new

    #: the share of the s = L end's drift that each step's boundary values correct
    #: (:meth:`end_correction`; None: no correction). The correction enters the step's
    #: end motion through the trapezoid ½h(v^n + v^{n+1}), so the drift obeys
    #: e_{n+1} = e_n − ½g(e_{n−1} + e_n) + (the step's new route difference), whose
    #: roots have modulus √(g/2): g = 0.5 halves it per step (a damped oscillation).
    #: Measured with 0.25, 0.5 and 1 alike (docs/contact.md § 4, session 15)
    DRIFT_GAIN = 0.5
    #: the correction's rate is DRIFT_GAIN / max(h, DRIFT_STEP_FLOOR · numerics.dt): on
    #: substeps shorter than a hundredth of the case's Δt it moves the end by a share
    #: ∝ h of its drift, not by DRIFT_GAIN of it. Why: at a fixed drift e the end moved
    #: by ~g·e in every step however small, and the route rule read a part of that as
    #: the step's position error, so no Δt could pass once g·e outgrew the tolerance
    #: (PyElastica's plectoneme, N = 25, Δt = 0.1 s, ρ∞ = 0.8: a 44-mm drift in the
    #: collapse, the route error 14.5-15.8 mm at h = 5e-5 s against 12.5 mm, the run
    #: stopped at 7.50 s; docs/contact.md § 4, session 17). Steps at or above the floor
    #: are unchanged (the seed example's smallest is 1.1 ms = dt/90)
    DRIFT_STEP_FLOOR = 0.01
    #: the boundary offsets of the last accepted step (12,), or None (a class default,
    #: so that runs pickled before it existed resume)
    bc_offset = None

    def end_correction(self, h, bc, restart):
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
        and it vanishes as Δt → 0 (measured: docs/contact.md § 4, session 15); on
        substeps below DRIFT_STEP_FLOOR · numerics.dt the rate is that of the floor, so
        that the end's correction within a step vanishes with h even where the drift
        does not.
        """
        if self.contact is None or self.DRIFT_GAIN is None or restart:
            return None
        R = quat_to_matrix(self.q[-1:])[0]
        e = R.T @ (self.r_time[-1] - self.r[-1])
        theta = relative_rotation(self.q[-1], self.q_time[-1])
        h_rate = max(h, self.DRIFT_STEP_FLOOR * self.case.numerics.dt)
        return bc.end_drift_offsets(self.props.s.size - 1, e, theta, self.DRIFT_GAIN / h_rate)

    def _hold_from_here(self, prev_bc, bc) -> None:
        """A degree of freedom of the s = L end that has just become kinematic (a sliding
        end held, as the seed's at 30 s) is held where the carried end is, not where the
        end's time route had got to while it was free (the two differ by the route
        differences of the free motion, which :meth:`end_correction` does not touch): the
        end's time route is moved onto the carried end along each such translation axis
        a_i, and its frame set to the carried frame when ω1 or ω2 becomes prescribed."""
        R = quat_to_matrix(self.q[-1:])[0]
        for j, idx in bc.end_kinematic_dofs(self.props.s.size - 1):
            if prev_bc.kinematic[j] and prev_bc.cols[j] == bc.cols[j]:
                continue                          # held before: its reference stays
            if idx < 3:
                a = R[:, idx]
                self.r_time = self.r_time.copy()
                self.r_time[-1] += a * float(a @ (self.r[-1] - self.r_time[-1]))
            elif idx < 5:
                self.q_time = self.q_time.copy()
                self.q_time[-1] = self.q[-1]

    def _local_error(self, h, Y, r_new) -> float:
        """Local error indicator of a step (m): the largest distance between the new
        centreline (integrated along s from κ) and the same nodes advanced one
        trapezoidal step in time from the old centreline, r^n + ½h(ṙ^n + R^{n+1} v^{n+1})
        (R^{n+1} = R^n exp(½h(ω^n + ω^{n+1})) per node). Both are second-order routes to
        the same positions, so their difference is O(h³) per step and measures the step's
        position error (docs/contact.md, "Step control")."""
        r_t = self._time_step(h, Y, self.q, self.r, self.v_global)[3]
        return max_distance(r_t, np.ascontiguousarray(r_new, dtype=float))

    def _search(self, positions, R, reach):
        """Contact candidates near the given positions (N+1, 3) and rotations (N+1, 3, 3)
        within tolerance + reach (m), or None when none is possible (the O(N) pre-test
        skips the k-d tree) or none is found (:meth:`SelfContact.search`)."""
        return self.contact.search(positions, R[:, :, 2], reach)

    #: the contact search's skin (a share of ``tolerance − D_max``, m): candidates are
    #: searched within tolerance + skin of the old positions and kept over the following
    #: steps while no node has moved more than half the skin from where they were
    #: searched (a Verlet list: Verlet, Phys. Rev. 159 (1967) 98-103); every pair within
    #: the tolerance is then among them, so neither a new search nor the coverage check
    #: after Newton is needed (docs/contact.md § 2)
    VERLET_SKIN = 0.25
    #: (candidates or None, the positions (N+1, 3) they were searched at) or None (a class
    #: default: runs pickled before it existed search afresh)
    verlet = None

    def _skin(self) -> float:
        """The search skin (m): VERLET_SKIN × (tolerance − D_max)."""
        skin = getattr(self, "_skin_m", None)
        if skin is None:
            skin = self._skin_m = self.VERLET_SKIN * (
                self.contact.tolerance - float(np.max(self.props.diameter)))
        return skin

    def _verlet_covers(self, positions) -> bool:
        """Whether the kept candidates (:attr:`verlet`) hold every pair within the
        tolerance at these positions (N+1, 3): no node more than half the skin from where
        they were searched."""
        if self.verlet is None:
            return False
        return max_distance(positions, self.verlet[1]) <= 0.5 * self._skin()

    def _candidates(self, h, guess):
        """Candidates for a step of h (s) from the Newton start ``guess`` (N+1, 12): the
        kept ones (:attr:`verlet`) while they cover the old positions and those the start
        predicts, else node pairs within tolerance + skin of the old positions (and of the
        predicted ones, when those lie more than half the skin away). Pairs that come
        within the tolerance beyond that are added by the coverage check after Newton,
        and the step is solved again."""
        _, R_new, _, r_new = self._time_step(h, guess, self.q, self.r, self.v_global)
        finite = bool(np.all(np.isfinite(r_new)))
        if self._verlet_covers(self.r) and (not finite or self._verlet_covers(r_new)):
            return self.verlet[0]
        skin = self._skin()
        cand = self._search(self.r, quat_to_matrix(self.q), skin)
        self.verlet = (cand, self.r)
        if finite and not self._verlet_covers(r_new):
            new = self._search(r_new, R_new, skin)
            if new is not None:
                cand = new if cand is None else self.contact.merge(cand, new)
        return cand

    def _feasible_guess(self, guess):
        """A Newton start whose contact gaps are open (:meth:`Newton.feasible_start`: the
        replay of the seed example's first contact, where an extrapolated start penetrated
        and Newton died at the barrier), unless ``guess`` is the old level itself. The
        step (with its candidates) must have been set up by ``system.begin_step``."""
        if guess is self.Y:
            return guess
        return self.newton.feasible_start(guess)

    def update_space_route(self):
        """Recompute pose along the rod from κ, anchored at node 0's time-route pose."""
        self.q, self.r = space_route(self.q_time[0], self.r_time[0], self.Y[:, 9:12],
                                     self.props.ds)
        self.v_global = np.einsum("nij,nj->ni", quat_to_matrix(self.q), self.Y[:, 0:3])

    def advance(self, t_target: float):
        """Advance to t_target (s): the nominal step, split at the case's breakpoints,
        each substep run by :meth:`_advance_to`, with a consistent restart (a backward-
        Euler step of RESTART_FRACTION·Δt) at t = 0 and after each breakpoint. Returns
        (iterations, residual) of the nominal step; raises SolverDivergence (without
        partial) when all cuts fail."""
        h_full = t_target - self.t
        snap = 1e-9 * h_full
        total_its = 0
        while self.t < t_target - snap:
            its, stop, at_break = self._next_stop(t_target, snap)
            total_its += its + self._advance_to(stop, h_full, at_break)
            if at_break:
                self.restart_pending = True
        return total_its, self.last_residual

    def step_adaptive(self, t_stop: float):
        """One accepted error-controlled step (``numerics.tolerance``) toward t_stop (s):
        never past t_stop or the next breakpoint, landing on them exactly (a step that
        would leave less than itself before the stop is halved instead). A step refused
        for its error is retried at the controller's smaller size, one refused by the
        growth guard at g/σ, one whose Newton or contact checks fail at Δt/dt_cut_factor;
        below 1e-9 t_end SolverDivergence is raised. Returns
        (iterations of all attempts, residual)."""
        num = self.case.numerics
        ctl = self.errctl
        total_its, stop, at_break = self._next_stop(t_stop, 1e-9 * max(self.h_next, 1e-300))
        # the step-size floor: 1e-9 of the run (the error control may need far smaller
        # steps than dt/dt_cut_factor^max_dt_cuts after a switch)
        h_min = 1e-9 * max(num.t_end, num.dt)
        h_max = num.dt_max if num.dt_max is not None else math.inf
        h = self.h_next
        refused = None           # (h, ratio) of the last attempt refused for its error
        while True:
            h = min(h, h_max, self._h_cap())
            h_try, last = self._landing(h, stop - self.t)
            doubled = not ctl.can_estimate and not self.last_had_candidates
            if doubled:
                ok, its, res, nonfinite = self._doubled_step(h_try, stop if last else None,
                                                             last and at_break)
                if ok is None:                   # strands may meet: no doubling there
                    total_its += its
                    doubled = False
            if not doubled:
                ok, its, res, nonfinite = self.try_step(
                    h_try, t_new=stop if last else None, left_limit=last and at_break)
            total_its += its
            if ok:
                self.last_dt = h_try
                # a doubled step is kept as its two half steps, whose error was measured
                h_new = ctl.accepted(0.5 * h_try if doubled else h_try, self.last_error_ratio)
                # a step shortened to land on a stop does not shrink the next one
                self.h_next = max(h_new, h) if h_try < h else h_new
                if last and at_break:
                    self.restart_pending = True
                self.last_iterations = total_its
                return total_its, res
            self._count_refusal()
            h, refused = self._retry_size(h_try, ctl, self.last_error_ratio,
                                          self.last_reject == "error", refused)
            if h < h_min * (1.0 - 1e-9):
                raise self._divergence(
                    f"time step from t = {self.t:.6g} s could not be completed above the "
                    f"smallest step 1e-9 t_end = {h_min:.3g} s "
                    f"(last refusal: {self.last_reject})", h_try, res, nonfinite)

    @staticmethod
    def _landing(h: float, remaining: float) -> tuple[float, bool]:
        """The step to try (s) of a controller's size h (s) with ``remaining`` (s) to the
        next stop, and whether it lands there: the remainder when h reaches it, half of
        it when h would leave less than itself, else h."""
        last = h >= remaining * (1.0 - 1e-9)
        return (remaining if last else (0.5 * remaining if 2.0 * h > remaining else h)), last

    def _retry_size(self, h_try: float, ctl, ratio: float, by_error: bool, refused):
        """Size (s) to retry a controlled step of h_try (s) with, after a refusal, and the
        (h, ratio) to pass as ``previous`` next time: the controller's smaller size
        (:meth:`solver.stepping.PIController.rejected`) when the error estimate refused
        it (``by_error``, ratio its error ratio), half of it within the growth guard's
        cap after a growth refusal, else h_try / dt_cut_factor (Newton or a contact
        check failed)."""
        if by_error:
            return ctl.rejected(h_try, ratio, refused), (h_try, ratio)
        if self.last_reject == "growth":
            return min(0.5 * h_try, self._h_cap()), refused
        return h_try / self.case.numerics.dt_cut_factor, refused

    def _count_refusal(self) -> None:
        """Count the attempt just refused under its reason (:attr:`last_reject`)."""
        self.refusals[self.last_reject] = self.refusals.get(self.last_reject, 0) + 1

    def _state(self):
        """The run's state between steps, for :meth:`_restore` (the accepted-step path
        rebinds every array it changes, so a shallow copy suffices)."""
        return dict(self.__dict__), self.errctl.state() if self.errctl is not None else None

    #: what the growth guard has learnt about the dynamics (its last σ, the Δt and the
    #: Arnoldi vector of that check): kept through :meth:`_restore`, so that a check made
    #: in a probe step of step doubling serves the steps that replace it. Rolled back
    #: with the state, it was lost at every doubled step and every refused one (Greenhill
    #: at tolerance 1e-2: 16 of 21 checks, each a band LU and an Arnoldi run)
    GUARD_KNOWLEDGE = ("guard_sigma", "guard_h", "guard_h_max", "guard_since", "guard_v0")

    def _restore(self, state) -> None:
        """Return to a :meth:`_state`, keeping :attr:`GUARD_KNOWLEDGE`."""
        known = {k: self.__dict__[k] for k in self.GUARD_KNOWLEDGE}
        self.__dict__.update(state[0])
        self.__dict__.update(known)
        if self.errctl is not None:
            self.errctl.restore(state[1])

    def _doubled_step(self, h: float, t_new, left_limit: bool):
        """The first error-controlled step after a restart, which has no predictor: one
        step h (s) and two steps h/2 over the same interval, the difference giving a half
        step's local error (step doubling, :meth:`ErrorControl.doubling_error`). The two
        half steps are kept when the error ratio of each is ≤ 1, nothing when not (ratio
        in ``last_error_ratio``); the run is then at t + h with three levels since the
        restart, so the next step has the quadratic predictor (Hairer, Nørsett & Wanner
        I, § II.4: step doubling continues from the two half steps). Until session 19
        only the first half was kept: the next step then had two levels, a linear
        predictor whose O(h²) estimate read as O(h³) refused it (Greenhill at tolerance
        1e-2: ratios 2.1 and 1.7 after the doubled step's 0.35, the step cut 7× and regrown
        over ~10 steps). Before session 5 the first step after a restart went unmeasured:
        the numerics.dt it ran at set the Greenhill growth rate 2 % off at every
        tolerance (docs/numerics.md § 7). Returns try_step's tuple (the residual of the
        second half), with ok = None (state unchanged) when strands may meet in one of the
        steps: there the route rule decides (docs/contact.md)."""
        start, Y_old = self._state(), self.Y
        t_end = self.t + h if t_new is None else t_new
        its, Y_full = 0, None
        for leg in ("whole", "first half", "second half"):
            if leg == "first half":              # the whole step is kept aside
                Y_full = self.Y
                self._restore(start)
            size = {"whole": h, "first half": 0.5 * h, "second half": t_end - self.t}[leg]
            ends = None if leg == "first half" else t_new
            ok, k, res, nonfinite = self.try_step(size, t_new=ends, estimate=False,
                                                  left_limit=left_limit and ends is not None)
            its += k
            if not ok or self.last_had_candidates:
                self._restore(start)
                return (None if ok else False), its, res, nonfinite
        ctl = self.errctl
        ratio = ctl.measure(ctl.doubling_error(Y_full, self.Y), self.Y, Y_old,
                            self.newton.filtered)
        accepted = ratio <= 1.0
        if not accepted:
            self._restore(start)
            self.last_reject = "error"
        self.last_error_ratio = ratio
        return accepted, its, res, False

    def _predictions(self, h: float):
        """Newton starts for a step of h (s) extrapolated from the accepted levels: the
        line through the last two ("linear") and, with three since the last restart, the
        parabola through the last three ("quadratic", with the actual steps;
        :func:`solver.stepping.extrapolate`).
        None without a level before the current one. Returns a dict of (N+1, 12) arrays."""
        if self.Y_prev is None or not self.h_prev:
            return None
        # times relative to the current level (t = 0)
        h1 = self.h_prev
        out = {"linear": extrapolate((-h1, 0.0), (self.Y_prev, self.Y), h)}
        if self.Y_prev2 is not None and self.h_prev2:
            out["quadratic"] = extrapolate((-h1 - self.h_prev2, -h1, 0.0),
                                           (self.Y_prev2, self.Y_prev, self.Y), h)
        return out

    def _better_predictor(self, Y: np.ndarray, predictions: dict) -> str:
        """The predictor whose curvature κ was nearer the accepted level Y (N+1, 12)'s
        (sum of squares over the nodes; ``predictions`` as :meth:`_predictions` returns). κ is what the centreline, and so every contact gap, is
        integrated from: at the seed's 40 s the parabola's κ was 2-10× nearer and its
        centreline within 0.04-0.3 mm against 0.2-0.9 mm, while the RMS over all twelve
        unknowns ranked the two alike. The parabola halves the Newton iterations of the
        intertwined phase (156 → 89 over 40-43 s) but extrapolates an oscillation that
        alternates from step to step (a transient the step does not resolve, damped by
        ρ∞: the held end after 30 s) seven times instead of three (152 → 231 over
        30-33 s), so the last step's record decides."""
        err = {k: float(np.sum((Y[:, 9:12] - g[:, 9:12]) ** 2))
               for k, g in predictions.items()}
        return min(err, key=err.get)

    def _next_stop(self, t_stop: float, snap: float):
        """Take the pending consistent restart, if any, and return (its Newton iterations,
        the time (s) the next steps must land on, whether it is a breakpoint): the first
        breakpoint after t if it comes before t_stop (within ``snap`` s), else t_stop."""
        its = 0
        if self.restart_pending:
            its = self._restart()
            self.restart_pending = False
        later = self.breakpoints[self.breakpoints > self.t + snap]
        if later.size and later[0] <= t_stop + snap:
            return its, float(later[0]), True
        return its, t_stop, False

    def _restart(self) -> int:
        """RESTART_STEPS backward-Euler steps of ε = RESTART_FRACTION·Δt (ε cut by 10 up
        to three times if one fails): f and Ẏ become consistent with the loads and
        conditions now in force, also after a jump of the velocities
        (:mod:`solver.stepping`). Returns their Newton iterations."""
        eps = RESTART_FRACTION * self.case.numerics.dt
        its_total = 0
        taken = 0
        for _ in range(RESTART_STEPS + 3):
            ok, its, res, nonfinite = self.try_step(eps, restart=True)
            its_total += its
            if ok:
                taken += 1
                if taken == RESTART_STEPS:
                    return its_total
            else:
                eps *= 0.1
        raise self._divergence(f"the consistent restart (a backward-Euler step) at "
                               f"t = {self.t:.6g} s did not converge", 10.0 * eps, res,
                               nonfinite)

    def _divergence(self, what, h, res, nonfinite) -> "SolverDivergence":
        """The SolverDivergence of a step that cannot be completed, with the reason."""
        singular = self.newton.last_failure == "singular"
        reason = "nonfinite_state" if (nonfinite and not singular) else "solver_diverged"
        why = ("singular Jacobian: the boundary conditions leave a force or moment "
               "undetermined (e.g. a straight inextensible rod held axially at both "
               "ends)" if singular else
               "non-finite state" if nonfinite else "Newton did not converge")
        return SolverDivergence(f"{what} (Δt = {h:.3g} s, scaled residual {res:.3g}, {why})",
                                t=self.t, step=None, residual=res, reason=reason)

    def _advance_to(self, stop: float, h_full: float, at_break: bool) -> int:
        """Advance to ``stop`` (s) with the nominal step h_full (s), cutting Δt on failure;
        the step that reaches ``stop`` ends exactly there (with the loads' left limit when
        ``at_break``). Returns the Newton iterations.

        Δt levels: h = h_full/factor^level. A nominal step starts at the level the
        previous one ended on and substeps at the current level until t_target is
        reached; a failure raises the level by one, and after ``grow_after`` consecutive
        accepted substeps (counted across nominal steps; GROW_AFTER, and for the growth to
        the nominal Δt doubled after each such growth that fails at once, up to
        GROW_AFTER_MAX, and reset by one that holds) the
        level drops by one (Δt grows by the factor) as soon as the larger step fits in
        what remains of the nominal step, so a growth is always tried and a Δt that
        keeps failing is not retried at every nominal step. Once a step with contact
        candidates is accepted, the steps go on by :meth:`_route_step` (Δt from the
        route rule's error ratio) until one has none.
        """
        num = self.case.numerics
        level = self.level_hint
        total_its = 0
        while self.t < stop - 1e-9 * h_full:
            if self.h_route is not None:
                total_its += self._route_step(stop, h_full, at_break)
                level = self.level_hint
                continue
            remaining = stop - self.t
            grew = False
            cap = self._h_cap() * (1.0 + 1e-9)
            while h_full / num.dt_cut_factor**level > cap:
                # a known growth rate: the levels it forbids are not tried
                if level >= num.max_dt_cuts:
                    raise SolverDivergence(
                        f"at t = {self.t:.6g} s the dynamics grow at σ = "
                        f"{self.guard_sigma:.3g} 1/s: the growth guard needs Δt ≤ "
                        f"{self._h_cap():.3g} s, more than numerics.max_dt_cuts = "
                        f"{num.max_dt_cuts} cuts of dt (raise max_dt_cuts, lower dt, or set "
                        f"numerics.growth_guard to null to run without the check)",
                        t=self.t, step=None, residual=math.nan, reason="solver_diverged")
                level += 1
                self.accepted_at_level = 0
            needed = self.grow_after if level == 1 else self.GROW_AFTER
            grown = h_full / num.dt_cut_factor ** (level - 1)   # the step one level up
            if (self.accepted_at_level >= needed and level > 0
                    and grown <= remaining * (1.0 + 1e-9) and grown <= cap):
                # grow only when the larger step fits and will be tried
                level -= 1
                self.accepted_at_level = 0
                grew = True
            h = h_full / num.dt_cut_factor**level
            h_try = min(h, remaining)
            last = remaining - h_try < 1e-9 * h
            if last:
                h_try = remaining
            ok, its, res, nonfinite = self.try_step(
                h_try, t_new=stop if last else None, left_limit=last and at_break)
            total_its += its
            if ok:
                self.last_dt = h_try
                self.accepted_at_level += 1
                if grew:
                    self.grow_after = self.GROW_AFTER
                if self.route_pi is not None and self.last_had_candidates:
                    # strands may meet: from here Δt follows the route rule's ratio
                    self.route_pi.forget()
                    self.h_route = self.route_pi.accepted(h_try, self.last_route_ratio)
                continue
            self.accepted_at_level = 0
            self._count_refusal()
            if grew and level == 0:
                # a growth to the nominal Δt that failed at once: wait twice as long
                # before the next one (below the nominal Δt a growth is cheap to retry)
                self.grow_after = min(2 * self.grow_after, self.GROW_AFTER_MAX)
            if level >= num.max_dt_cuts:
                raise self._divergence(f"time step from t = {self.t:.6g} s did not "
                                       f"converge after {level} Δt cuts", h_try, res,
                                       nonfinite)
            level += 1
        self.level_hint = level
        return total_its

    def _route_step(self, stop: float, h_full: float, at_break: bool) -> int:
        """One accepted fixed-mode step where strands may meet, toward ``stop`` (s), of
        at most the nominal h_full (s): Δt from the route rule's error ratio (the step's
        position error over ``contact.position_tolerance``, :meth:`_local_error`) by the
        PI controller of error-controlled steps (:class:`solver.stepping.PIController`:
        target ratio 0.35, retries after a route refusal at its smaller size), cut by
        ``dt_cut_factor`` when Newton or a contact check fails; it lands on ``stop`` as
        :meth:`step_adaptive` does (a step that would leave less than itself is halved).
        The levels h_full/factor^k chose these steps before session 13: with Δt chosen
        continuously the seed example's contact phase is more accurate for its cost
        (docs/contact.md § 4). When the accepted step has no candidates the levels take
        over again, at the level of that step. Raises SolverDivergence below
        h_full/dt_cut_factor^max_dt_cuts. Returns the Newton iterations."""
        num = self.case.numerics
        ctl = self.route_pi
        h_min = h_full / num.dt_cut_factor ** num.max_dt_cuts
        h = min(self.h_route, h_full, self._h_cap())
        refused = None           # (h, ratio) of the last attempt refused by the route rule
        total_its = 0
        while True:
            h_try, last = self._landing(h, stop - self.t)
            ok, its, res, nonfinite = self.try_step(
                h_try, t_new=stop if last else None, left_limit=last and at_break)
            total_its += its
            if ok:
                self.last_dt = h_try
                if self.last_had_candidates:
                    h_new = ctl.accepted(h_try, self.last_route_ratio)
                    # a step shortened to land on a stop does not shrink the next one
                    self.h_route = max(h_new, h) if h_try < h else h_new
                else:
                    # strands apart: the levels again, from the largest not above this Δt
                    self.h_route = None
                    self.level_hint = max(0, math.ceil(
                        math.log(h_full / h_try) / math.log(num.dt_cut_factor) - 1e-9))
                    self.accepted_at_level = 0
                return total_its
            self._count_refusal()
            h, refused = self._retry_size(
                h_try, ctl, self.last_route_ratio,
                self.last_reject == "contact" and self.last_route_ratio > 1.0, refused)
            if h < h_min * (1.0 - 1e-9):
                raise self._divergence(
                    f"time step from t = {self.t:.6g} s did not converge above the smallest "
                    f"step dt/dt_cut_factor^max_dt_cuts = {h_min:.3g} s (last refusal: "
                    f"{self.last_reject})", h_try, res, nonfinite)

    # -------------------------------------------------------------------------------
    def dense_state(self):
        """What :meth:`interpolated_snapshot` needs of the level a step starts from (the
        accepted-step path rebinds every array it changes, so references suffice)."""
        return (self.t, self.Y, self.Ydot, self.q_time, self.r_time, self.v_global_time,
                self.phi, self.xdot_end[:, 5], self.work_in, self.power)

    def interpolated_snapshot(self, fields: set, t: float, start) -> dict:
        """:meth:`snapshot` at a time t (s) inside the last accepted step, which began at
        the :meth:`dense_state` ``start``: the dense output of error-controlled steps.

        Y (v, ω, f, κ), the time-route positions, the end rotations φ (linking number)
        and the work put in by cubic Hermite interpolation between the step's levels with
        their rates (Ẏ of the scheme, the global node velocities, φ̇, the power:
        :func:`solver.stepping.hermite`); the anchor's orientation by slerp; the centreline
        and frames then by the space route from the interpolated κ, as at a step. The
        contact count and smallest gap, Newton's figures and Δt are the step's (the
        interpolated state is not itself checked for contact). Where no field needs the
        centreline (:data:`POSE_FIELDS`) and the steps keep it (``system.needs_pose``)
        the space route is not integrated and ``position_route_difference`` is the
        step's too (measured: 5 % of an adaptive run of the seed problem that keeps only
        energies). Returns the snapshot dict.
        """
        t0, Y0, D0, q0, r0, v0, phi0, dphi0, w0, p0 = start
        h = self.t - t0
        s = (t - t0) / h
        view = copy.copy(self)
        view.t = t
        view.Y = hermite(s, h, Y0, D0, self.Y, self.Ydot)
        view.r_time = hermite(s, h, r0, v0, self.r_time, self.v_global_time)
        view.q_time = self.q_time.copy()
        view.q_time[0] = quat_slerp(q0[0], self.q_time[0], s)
        view.phi = hermite(s, h, phi0, dphi0, self.phi, self.xdot_end[:, 5])
        view.work_in = float(hermite(s, h, w0, p0, self.work_in, self.power))
        view.power = (1.0 - s) * p0 + s * self.power
        if fields & self.POSE_FIELDS or not self.system.needs_pose:
            view.update_space_route()
            return view.snapshot(fields, route_current=True)
        out = view.snapshot(fields, route_current=True)
        out["position_route_difference"] = float(
            max_distance(self.r_time, self.r))
        return out

    def snapshot(self, fields: set, route_current: bool = False) -> dict:
        """Output quantities of the current state for the requested field groups
        (``route_current``: the space route is already that of the current κ; otherwise it
        is recomputed where the steps do not keep it, ``system.needs_pose`` False)."""
        out = {}
        Y = self.Y
        if not self.system.needs_pose and not route_current:
            self.update_space_route()
        if "v" in fields:
            out["v"] = Y[:, 0:3].copy()
        if "omega" in fields:
            out["omega"] = Y[:, 3:6].copy()
        if "f" in fields:
            out["f"] = Y[:, 6:9].copy()
        if "kappa" in fields:
            out["kappa"] = Y[:, 9:12].copy()
        if "moment" in fields:
            out["moment"] = self.props.stiffness * Y[:, 9:12]
        if "position" in fields:
            out["position"] = self.r.copy()
        if "orientation" in fields:
            out["orientation"] = self.q.copy()
        if "energies" in fields:
            out.update(energies(Y, self.props))
            out["work_in"] = self.work_in
            out["power_in"] = self.power
        if "topology" in fields:
            from .topology import linking_number, twist, writhe

            tw = twist(Y[:, 11], self.props.s)
            wr = writhe(self.r)
            lk = linking_number(self.phi[0], self.phi[1])
            # the open rod's writhe is that of the curve closed by its end tangents'
            # extensions; a passage of the rod through them changes it by ±2 with no
            # self-crossing. With self-contact, true crossings are refused by the step
            # control (swept test of every accepted step), so a jump of 2 against
            # Lk − Tw is a closure passage: count it and keep Wr continuous. Without
            # contact strands may pass through each other, and a jump stays visible in
            # topology_error (docs/topology.md).
            k = round((lk - tw - wr) / 2.0) if self.contact is not None else 0
            out.update(twist=tw, writhe=wr + 2.0 * k, linking_number=lk,
                       topology_error=abs(tw + wr + 2.0 * k - lk),
                       writhe_closure_passages=float(k))
        if "reactions" in fields:
            out.update(end_reactions(Y, self.q, self.props.stiffness))
        if "contact" in fields:
            out["contact_count"] = self.contact_count
            out["min_surface_gap"] = self.min_gap
        out["newton_iterations"] = self.last_iterations
        out["residual_norm"] = self.last_residual
        out["dt"] = self.last_dt
        out["position_route_difference"] = max_distance(self.r_time, self.r)
        out["quaternion_norm_error"] = self.quat_norm_error
        return out


def simulate(case, progress=None, should_stop=None, checkpoint=None,
             checkpoint_interval=300.0, resume=None, observer=None, extra_force=None,
             start=None):
    """Run a case and return its result dataset (docs/interfaces.md, "Result dataset").

    Parameters
    ----------
    case : solver.case.Case
    progress : callable(Progress) or None, called after every accepted nominal step
    should_stop : callable() -> bool | str, or None; checked before every step. A truthy
        value stops the run: the partial dataset is *returned* with
        ``attrs["hockle_status"] = "stopped"`` and ``attrs["hockle_stop_reason"]``.
    checkpoint : callable(solver.checkpoint.Checkpoint) or None
        Called after the accepted step at which ``checkpoint_interval`` wall-clock seconds
        (default 300) have passed since the start or the last checkpoint, and with the last
        accepted state when the run stops or fails; the caller
        serialises it there (``Checkpoint.dumps()``: it refers to the live run) and stores
        it. The solver does no I/O.
    resume : solver.checkpoint.Checkpoint or None
        Continue from this checkpoint instead of t = 0 (the records and diagnostics before
        it are kept, nothing is recomputed, and the result is the uninterrupted run's to
        the last bit). It must belong to ``case``.
    observer : callable(run, step) -> None | bool | str, or None
        Called with the :class:`RodRun` once at t = 0 (step 0) and after every accepted
        step, after that step's output record; it may read the state (do not change it).
        A truthy value stops the run there: the state is recorded if it was not, and the
        partial dataset is returned with ``hockle_status = "stopped"`` and
        ``hockle_stop_reason`` the string returned (or ``"observer"``). The hook of the
        Python API's callbacks (:mod:`hockle.api`).
    extra_force : callable(t, run) -> (N+1, 3) array or None, or None
        A global-frame distributed force, N/m per grid point, written as code, added to
        the case's distributed forces at every time level Newton evaluates (it sees the
        run's last accepted state, so a state-dependent force is explicit: lagged by one
        step). In-process runs only (the service takes data, never code); with
        ``checkpoint`` it must be picklable (a module-level function).
    start : solver.initial.StartState or None
        Start from this state at its time instead of the case's initial configuration
        (``initial.from_result``; :func:`hockle.io.read_start_state` reads it from an
        earlier result): the first output is that state, the fixed steps continue from
        the one after it.

    Returns
    -------
    xarray.Dataset with ``attrs["hockle_status"]`` in {"completed", "stopped"}.

    Raises
    ------
    SolverDivergence
        when a step cannot be completed after all Δt cuts; ``.partial`` holds the dataset
        up to the last accepted step (``hockle_status = "failed"``).
    solver.checkpoint.CheckpointError
        when ``resume`` belongs to another case.
    """
    # the linear algebra is band LU and small dense blocks: BLAS threads only add
    # overhead and oversubscribe shared cores (measured 3.8x slower in contact phases)
    with _blas_controller().limit(limits=1, user_api="blas"):
        return _simulate(case, progress, should_stop, checkpoint, checkpoint_interval,
                         resume, observer, extra_force, start)


@functools.cache
def _blas_controller():
    """threadpoolctl's view of the BLAS libraries this process has loaded, made once:
    finding them scans every loaded library (~3 ms, 1 % of a 0.3-s run of PyElastica's
    plectoneme at N = 20), setting their limits then costs ~0.1 ms."""
    import scipy.linalg  # noqa: F401  (loads scipy's own BLAS before the scan)
    import scipy.sparse.linalg  # noqa: F401
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


def _simulate(case, progress, should_stop, checkpoint=None, checkpoint_interval=300.0,
              resume=None, observer=None, extra_force=None, start=None):
    from .checkpoint import Checkpoint, CheckpointError, resume_key
    from .results import build_dataset

    wall0 = _time.perf_counter()
    num = case.numerics
    fields = set(case.output.fields)
    every = case.output.every
    n_steps = max(1, int(math.ceil(num.t_end / num.dt - 1e-9)))
    if resume is None:
        run = RodRun(case, extra_force, start)
        times, records = [], []
        diag = {"step_time": [], "step_dt": [], "step_newton_iterations": [],
                "step_residual_norm": [], "step_growth_rate": [],
                "step_rejected_attempts": []}
        first_step, wall_before = start_step(case, start), 0.0
    else:
        if resume.case_hash != resume_key(case):
            raise CheckpointError("the checkpoint belongs to another case (resume key "
                                  f"{resume.case_hash} != {resume_key(case)})")
        # a copy: the checkpoint stays valid for another resume
        state = pickle.loads(pickle.dumps(resume))
        run, times, records, diag = state.run, state.times, state.records, state.diag
        first_step, wall_before = state.step + 1, state.wall_time
        if extra_force is not None:
            run.loads.extra = extra_force
    last_checkpoint = [_time.perf_counter()]
    refused_before = [sum(run.refusals.values())]
    done = [first_step - 1]                   # accepted steps so far

    def save():
        if checkpoint is not None:
            checkpoint(Checkpoint(resume_key(case), done[0], run, times, records, diag,
                                  wall_before + _time.perf_counter() - wall0))
            last_checkpoint[0] = _time.perf_counter()

    def record(t=None, start=None):
        """Keep the state now, or (error-controlled steps) at t inside the last step,
        which began at the dense state ``start``."""
        if t is None:
            times.append(run.t)
            records.append(run.snapshot(fields))
        else:
            times.append(t)
            records.append(run.interpolated_snapshot(fields, t, start))

    def finish(status, message="", reason=None):
        if status != "completed":
            save()                            # the last accepted state, to resume from
        stacked = {}
        if records:
            for key in records[0]:
                stacked[key] = np.asarray([rec[key] for rec in records])
        ds = build_dataset(case, run.props.s, np.asarray(times), stacked,
                           {k: np.asarray(v) for k, v in diag.items()}, status, message)
        if reason is not None:
            ds.attrs["hockle_stop_reason"] = reason
        ds.attrs["wall_time_s"] = wall_before + _time.perf_counter() - wall0
        ds.attrs["factorizations"] = run.newton.factorizations
        ds.attrs["hockle_refused_attempts"] = ", ".join(
            f"{k} {v}" for k, v in sorted(run.refusals.items()))
        if resume is not None:
            ds.attrs["hockle_resumed_at"] = resume.t
        return ds

    if resume is None:
        record()
    budget = num.wall_clock_budget
    rate = RateEstimate()

    def stopped():
        """The partial dataset when the caller or the wall-clock budget stops the run."""
        if should_stop is not None:
            flag = should_stop()
            if flag:
                reason = flag if isinstance(flag, str) else "stopped"
                return finish("stopped", f"stopped at t = {run.t:.6g} s: {reason}", reason)
        if budget is not None and _time.perf_counter() - wall0 > budget:
            return finish("stopped", f"wall-clock budget of {budget} s exceeded at "
                          f"t = {run.t:.6g} s", "timeout")
        return None

    def accepted(step, its, res):
        """Diagnostics, progress, checkpoint and observer after an accepted (nominal or
        error-controlled) step; the partial dataset when the observer stops the run."""
        diag["step_time"].append(run.t)
        diag["step_dt"].append(run.last_dt)
        diag["step_newton_iterations"].append(its)
        diag["step_residual_norm"].append(res)
        diag["step_growth_rate"].append(run.guard_sigma)
        refused = sum(run.refusals.values())
        diag["step_rejected_attempts"].append(refused - refused_before[0])
        refused_before[0] = refused
        done[0] = step
        if progress is not None:
            wall = _time.perf_counter() - wall0
            progress(Progress(t=run.t, t_end=num.t_end, step=step, dt=run.last_dt,
                              newton_iterations=its, residual_norm=res,
                              wall_time=wall, fraction=min(1.0, run.t / num.t_end),
                              contact_count=run.contact_count,
                              eta_seconds=rate.update(wall, run.t, num.t_end)))
        if _time.perf_counter() - last_checkpoint[0] >= checkpoint_interval:
            save()
        return observed(step)

    def observed(step):
        """The partial dataset when the observer stops the run after ``step``."""
        if observer is None:
            return None
        flag = observer(run, step)
        if not flag:
            return None
        reason = flag if isinstance(flag, str) else "observer"
        if not times or times[-1] != run.t:
            record()                          # the state the observer stopped at
        return finish("stopped", f"stopped at t = {run.t:.6g} s: {reason}", reason)

    if resume is None:
        out = observed(0)
        if out is not None:
            return out
    if num.tolerance is not None:
        return _simulate_adaptive(case, run, record, finish, stopped, accepted,
                                  first_step - 1)
    for step in range(first_step, n_steps + 1):
        out = stopped()
        if out is not None:
            return out
        t_target = min(step * num.dt, num.t_end)
        try:
            its, res = run.advance(t_target)
        except SolverDivergence as exc:
            exc.step = step - 1
            exc.partial = finish("failed", str(exc), exc.reason)
            raise
        if step % every == 0 or step == n_steps:
            record()
        out = accepted(step, its, res)
        if out is not None:
            return out
    return finish("completed", f"completed {n_steps} steps to t = {run.t:.6g} s")


def _simulate_adaptive(case, run, record, finish, stopped, accepted, step=0):
    """The time loop of error-controlled steps (``numerics.tolerance``): one accepted
    step per pass, the state kept at every ``output.interval`` s or, without an interval,
    every ``output.every``-th step; the diagnostics hold every accepted step. With an
    interval the outputs inside a step are its dense output
    (:meth:`RodRun.interpolated_snapshot`; ``output.interpolate``, the default) or the
    steps land on them (``interpolate: false``). ``stopped`` and ``accepted`` are
    :func:`_simulate`'s helpers; ``step``: the accepted steps so far (a resumed run)."""
    t_end = case.numerics.t_end
    interval = case.output.interval
    dense = interval is not None and case.output.interpolate
    every = case.output.every
    next_out = t_end
    if interval is not None:
        next_out = min((math.floor(run.t / interval + 1e-9) + 1) * interval, t_end)
    while run.t < t_end * (1.0 - 1e-12):
        out = stopped()
        if out is not None:
            return out
        start = run.dense_state() if dense else None
        try:
            its, res = run.step_adaptive(t_end if dense else next_out)
        except SolverDivergence as exc:
            exc.step = step
            exc.partial = finish("failed", str(exc), exc.reason)
            raise
        step += 1
        done = run.t >= t_end * (1.0 - 1e-12)
        if interval is not None:
            # every output time the step reached: inside it interpolated, at its end the
            # state itself
            while next_out <= run.t * (1.0 + 1e-12) or done:
                if next_out < run.t * (1.0 - 1e-12) and start is not None:
                    record(next_out, start)
                else:
                    record()
                if next_out >= t_end * (1.0 - 1e-12):
                    break
                k = math.floor(next_out / interval + 1e-9) + 1
                next_out = min(k * interval, t_end)
        elif step % every == 0 or done:
            record()
        out = accepted(step, its, res)
        if out is not None:
            return out
    return finish("completed", f"completed {step} error-controlled steps to "
                  f"t = {run.t:.6g} s")
