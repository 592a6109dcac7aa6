"""Step control of a run: which step to try next, and what to do when one is refused.

:class:`StepControl` drives a run (:class:`solver.run.RodRun`) through the small interface
of a step: ``run.try_step(h, t_new=..., left_limit=..., restart=..., estimate=...)`` tries a
step of size h from the run's state and returns an :class:`Attempt` (accepted or refused,
with the reason, the Newton iterations and the residual, the error and route ratios and
whether it had contact candidates); an accepted step has advanced the state, a refused
one has left it untouched. The step control decides by the attempts: of the run it reads
only the state's time, the case and Newton's last failure. The rules it applies are those of
:mod:`solver.stepping` (breakpoints, consistent restarts, the error estimate and the PI
controller) and :class:`solver.stepping.guard.GrowthGuard`.

Fixed steps (:meth:`StepControl.advance`): the nominal step, split at the case's
breakpoints, substepped on the levels Δt/dt_cut_factor^k (cut on failure, grown back
after a run of accepted substeps), and where strands may meet (and after, while the route
rule limits Δt) with Δt from the route rule's error ratio
(:meth:`StepControl._route_step`). Error-controlled steps (``numerics.tolerance``,
:meth:`StepControl.step_adaptive`): one accepted step of the PI controller's size, the
first after a restart measured by step doubling.
"""
from __future__ import annotations

import math
from typing import NamedTuple, Optional

from . import RESTART_FRACTION, RESTART_STEPS, breakpoints, floored_step, landing_step
from .guard import GrowthGuard

__all__ = ["Attempt", "SolverDivergence", "StepControl"]


class Attempt(NamedTuple):
    """The outcome of one step attempt (:meth:`solver.run.RodRun.try_step`), with all the
    step control decides by.

    ok: accepted (the state advanced) or refused (the state untouched); iterations: Newton
    iterations of the attempt; residual: the scaled residual of its last iterate;
    nonfinite: the iterate was not finite; reason: why it was refused ("newton",
    "contact", "error", "growth", "energy", "drift"), None when accepted; error_ratio:
    the error estimate's ratio to its tolerance (``numerics.tolerance``; in steps with
    contact candidates the route rule's), NaN where not estimated (a restart, a step of
    a step-doubling estimate, a refusal before the estimate); route_ratio: the route
    rule's ratio (the step's position error over its tolerance, with self-contact), NaN
    where not measured; had_candidates: the step had contact candidates (strands may
    meet).
    """

    ok: Optional[bool]
    iterations: int
    residual: float
    nonfinite: bool = False
    reason: Optional[str] = None
    error_ratio: float = math.nan
    route_ratio: float = math.nan
    had_candidates: bool = False


class SolverDivergence(RuntimeError):
    """A time step could not be completed even after all Δt cuts.

    Attributes
    ----------
    t : float
        The time reached, s.
    step : int
        Nominal steps completed.
    residual : float
        The scaled residual of the last attempt.
    reason : str
        ``"solver_diverged"`` or ``"nonfinite_state"``.
    partial : xarray.Dataset or None
        The result dataset up to the last accepted step (``hockle_status = "failed"``).
    """

    def __init__(self, message, t, step, residual, reason, partial=None):
        super().__init__(message)
        self.t = t
        self.step = step
        self.residual = residual
        self.reason = reason
        self.partial = partial


class StepControl:
    """The step-size state of a run and the rules that choose its steps.

    Parameters
    ----------
    case : solver.case.Case
    errctl : solver.stepping.ErrorControl or None
        The error estimate and PI controller of ``numerics.tolerance`` (None: fixed steps).
    route_pi : solver.stepping.PIController or None
        The controller of fixed steps where strands may meet (None: without contact, or
        with ``numerics.tolerance``).

    Attributes
    ----------
    h_next : float
        The next error-controlled step, s.
    h_route : float or None
        The next fixed step where strands may meet, s (None: the levels decide).
    level_hint, accepted_at_level, grow_after : int
        The Δt level the last nominal step ended on, the accepted substeps at it, and
        the accepted substeps needed before Δt grows to the nominal step.
    restart_pending : bool
        A consistent restart before the next step.
    breakpoints : (K,) array, s
    refusals : dict
        Refused attempts so far by reason (the dataset's ``step_rejected_attempts`` and
        ``hockle_refused_attempts``).
    last_dt : float
        The last accepted step, s.
    last_attempt : Attempt or None
        The last attempt made (None before the first): an error-controlled step is
        measured by step doubling only where it had no contact candidates.
    guard : GrowthGuard

    The numerics are read from the run's case at every step (a benchmark may swap it).
    """

    GROW_AFTER = 3   # accepted substeps at one Δt level before Δt is allowed to grow
    GROW_AFTER_MAX = 48  # the same after repeated failed growths (doubling back-off)

    def __init__(self, case, errctl=None, route_pi=None):
        num = case.numerics
        self.errctl = errctl
        self.route_pi = route_pi
        self.guard = GrowthGuard(num.growth_guard)
        self.breakpoints = breakpoints(case)
        self.h_next = num.dt
        self.h_route = None
        self.restart_pending = True
        self.level_hint = 0
        self.accepted_at_level = 0
        self.grow_after = self.GROW_AFTER
        self.refusals = {"error": 0, "newton": 0, "contact": 0, "growth": 0}
        self.last_dt = num.dt
        self.last_attempt = None

    def _try(self, run, h: float, **options) -> Attempt:
        """``run.try_step(h, **options)``, its :class:`Attempt` kept as ``last_attempt``."""
        att = self.last_attempt = run.try_step(h, **options)
        return att

    # ------------------------------------------------------------------ fixed steps
    def advance(self, run, t_target: float):
        """Advance ``run`` to t_target (s): the nominal step, split at the case's
        breakpoints, each substep run by :meth:`_advance_to`, with a consistent restart (a
        backward-Euler step of RESTART_FRACTION·Δt) at t = 0 and after each breakpoint.
        Returns (iterations, residual) of the nominal step; raises SolverDivergence
        (without partial) when all cuts fail."""
        h_full = t_target - run.state.t
        snap = 1e-9 * h_full
        total_its = 0
        while run.state.t < t_target - snap:
            its, stop, at_break = self._next_stop(run, t_target, snap)
            total_its += its + self._advance_to(run, stop, h_full, at_break)
            if at_break:
                self.restart_pending = True
        # every path ends on an accepted attempt (the restart's too)
        return total_its, (self.last_attempt.residual if self.last_attempt is not None
                           else 0.0)

    def _advance_to(self, run, stop: float, h_full: float, at_break: bool) -> int:
        """Advance to ``stop`` (s) with the nominal step h_full (s), cutting Δt on failure;
        the step that reaches ``stop`` ends exactly there (with the loads' left limit when
        ``at_break``). Returns the Newton iterations.

        Δt levels: h = h_full/factor^level. A nominal step starts at the level the
        previous one ended on and substeps at the current level until t_target is
        reached; a failure raises the level by one, and after ``grow_after`` consecutive
        accepted substeps the level drops by one (:meth:`_choose_level`). Once a step with
        contact candidates is accepted, the steps go on by :meth:`_route_step` (Δt from
        the route rule's error ratio) until one without candidates is accepted at a ratio
        that allows the nominal step.
        """
        num = run.case.numerics
        level = self.level_hint
        total_its = 0
        while run.state.t < stop - 1e-9 * h_full:
            if self.h_route is not None:
                total_its += self._route_step(run, stop, h_full, at_break)
                level = self.level_hint
                continue
            remaining = stop - run.state.t
            level, grew = self._choose_level(run, level, h_full, remaining)
            h = h_full / num.dt_cut_factor**level
            h_try = min(h, remaining)
            last = remaining - h_try < 1e-9 * h
            if last:
                h_try = remaining
            att = self._try(run, h_try, t_new=stop if last else None,
                            left_limit=last and at_break)
            total_its += att.iterations
            if att.ok:
                self.last_dt = h_try
                self.accepted_at_level += 1
                if grew:
                    self.grow_after = self.GROW_AFTER
                if self.route_pi is not None and att.had_candidates:
                    # strands may meet: from here Δt follows the route rule's ratio
                    self.route_pi.forget()
                    self.h_route = self.route_pi.accepted(h_try, att.route_ratio)
                continue
            self.accepted_at_level = 0
            self._count_refusal(run, h_try, att)
            if grew and level == 0:
                # a growth to the nominal Δt that failed at once: wait twice as long
                # before the next one (below the nominal Δt a growth is cheap to retry)
                self.grow_after = min(2 * self.grow_after, self.GROW_AFTER_MAX)
            if level >= num.max_dt_cuts:
                raise self._divergence(run, f"time step from t = {run.state.t:.6g} s did not "
                                       f"converge after {level} Δt cuts", h_try, att)
            level += 1
        self.level_hint = level
        return total_its

    def _choose_level(self, run, level: int, h_full: float, remaining: float):
        """The Δt level of the next fixed substep and whether it grew: levels whose step
        the growth guard forbids are skipped, and after ``grow_after`` consecutive accepted
        substeps (counted across nominal steps; GROW_AFTER, and for the growth to the
        nominal Δt doubled after each such growth that fails at once, up to
        GROW_AFTER_MAX, and reset by one that holds) the level drops by one (Δt grows by
        the factor) as soon as the larger step fits in what remains (``remaining``, s) of
        the nominal step h_full (s), so a growth is always tried and a Δt that keeps
        failing is not retried at every nominal step. Raises SolverDivergence when the
        guard needs more than ``numerics.max_dt_cuts`` cuts."""
        num = run.case.numerics
        grew = False
        cap = self.guard.cap() * (1.0 + 1e-9)
        while h_full / num.dt_cut_factor**level > cap:
            # a known growth rate: the levels it forbids are not tried
            if level >= num.max_dt_cuts:
                raise SolverDivergence(
                    f"at t = {run.state.t:.6g} s the dynamics grow at σ = "
                    f"{self.guard.sigma:.3g} 1/s: the growth guard needs Δt ≤ "
                    f"{self.guard.cap():.3g} s, more than numerics.max_dt_cuts = "
                    f"{num.max_dt_cuts} cuts of dt (raise max_dt_cuts, lower dt, or set "
                    f"numerics.growth_guard to null to run without the check)",
                    t=run.state.t, step=None, residual=math.nan, reason="solver_diverged")
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
        return level, grew

    def _route_step(self, run, stop: float, h_full: float, at_break: bool) -> int:
        """One accepted fixed-mode step where strands may meet, toward ``stop`` (s), of
        at most the nominal h_full (s): Δt from the route rule's error ratio (the step's
        position error over ``contact.position_tolerance``,
        :meth:`solver.step_problem.ProblemAssembly._local_error`) by the PI controller of error-controlled
        steps (:class:`solver.stepping.PIController`: target ratio 0.35, retries after a
        route refusal at its smaller size), cut by ``dt_cut_factor`` when Newton or a
        contact check fails; it lands on ``stop`` as :meth:`step_adaptive` does (a step
        that would leave less than itself is halved). With Δt chosen continuously rather
        than on the levels h_full/factor^k the seed example's contact phase is more
        accurate for its cost (docs/contact.md § 4). When the accepted step has no
        candidates and the controller's next size reaches h_full the levels take over
        again, at the level of that step. A refused step whose cut falls below the floor
        h_full/dt_cut_factor^max_dt_cuts is retried at the floor (:meth:`_floored`).
        Raises SolverDivergence when a step at the floor is refused. Returns the Newton
        iterations."""
        num = run.case.numerics
        ctl = self.route_pi
        h_min = h_full / num.dt_cut_factor ** num.max_dt_cuts
        h = min(self.h_route, h_full, self.guard.cap())
        refused = None           # (h, ratio) of the last attempt refused by the route rule
        total_its = 0
        while True:
            h_try, last = self._landing(h, stop - run.state.t)
            att = self._try(run, h_try, t_new=stop if last else None,
                            left_limit=last and at_break)
            total_its += att.iterations
            if att.ok:
                self.last_dt = h_try
                h_new = ctl.accepted(h_try, att.route_ratio)
                # a step shortened to land on a stop does not shrink the next one
                h_new = max(h_new, h) if h_try < h else h_new
                if att.had_candidates or h_new < h_full * (1.0 - 1e-9):
                    # strands may meet, or the route rule still limits Δt: its ratio
                    # sizes the next step. Why the second: between contacts the route
                    # rule alone can limit Δt, and the levels, 4x apart, then alternate
                    # between a step it refuses and one 4x too small (the seed example
                    # without its fluid, 17.5-18.4 s: 855 of 4307 attempts refused, most
                    # steps at 0.1/4^5 s with route ratios of 0.02-0.07; kept on the
                    # controller, 53 of 3436, the ratios at its target;
                    # research/contact_steps.py, docs/contact.md § 3)
                    self.h_route = h_new
                else:
                    # strands apart and the route rule allows the nominal step: the
                    # levels again, from the largest not above this Δt
                    self.h_route = None
                    self.level_hint = max(0, math.ceil(
                        math.log(h_full / h_try) / math.log(num.dt_cut_factor) - 1e-9))
                    self.accepted_at_level = 0
                return total_its
            self._count_refusal(run, h_try, att)
            h, refused = self._retry_size(
                run, h_try, ctl, att, att.reason == "contact" and att.route_ratio > 1.0,
                att.route_ratio, refused)
            h = self._floored(h, h_try, h_min)
            if h is None:
                raise self._divergence(
                    run, f"time step from t = {run.state.t:.6g} s could not be completed down "
                    f"to the smallest step dt/dt_cut_factor^max_dt_cuts = {h_min:.3g} s (last "
                    f"refusal: {att.reason})", h_try, att)

    # ------------------------------------------------------- error-controlled steps
    def step_adaptive(self, run, t_stop: float):
        """One accepted error-controlled step (``numerics.tolerance``) toward t_stop (s):
        never past t_stop or the next breakpoint, landing on them exactly (a step that
        would leave less than itself before the stop is halved instead). A step refused
        for its error is retried at the controller's smaller size, one refused by the
        growth guard at g/σ, one whose Newton or contact checks fail at Δt/dt_cut_factor,
        at 1e-9 t_end where that is smaller (:meth:`_floored`); SolverDivergence is raised
        when a step at that floor is refused. Returns
        (iterations of all attempts, residual)."""
        num = run.case.numerics
        ctl = self.errctl
        total_its, stop, at_break = self._next_stop(run, t_stop,
                                                    1e-9 * max(self.h_next, 1e-300))
        # the step-size floor: 1e-9 of the run (the error control may need far smaller
        # steps than dt/dt_cut_factor^max_dt_cuts after a switch)
        h_min = 1e-9 * max(num.t_end, num.dt)
        h_max = num.dt_max if num.dt_max is not None else math.inf
        h = self.h_next
        refused = None           # (h, ratio) of the last attempt refused for its error
        while True:
            h = min(h, h_max, self.guard.cap())
            h_try, last = self._landing(h, stop - run.state.t)
            previous = self.last_attempt
            doubled = not ctl.can_estimate and not (previous is not None
                                                    and previous.had_candidates)
            if doubled:
                # kept as the last attempt: the doubled step had no candidates
                att = self.last_attempt = self._doubled_step(
                    run, h_try, stop if last else None, last and at_break)
                if att.ok is None:               # strands may meet: no doubling there
                    total_its += att.iterations
                    doubled = False
            if not doubled:
                att = self._try(run, h_try, t_new=stop if last else None,
                                left_limit=last and at_break)
            total_its += att.iterations
            if att.ok:
                self.last_dt = h_try
                # a doubled step is kept as its two half steps, whose error was measured
                h_new = ctl.accepted(0.5 * h_try if doubled else h_try, att.error_ratio)
                # a step shortened to land on a stop does not shrink the next one
                self.h_next = max(h_new, h) if h_try < h else h_new
                if last and at_break:
                    self.restart_pending = True
                run.last_iterations = total_its
                return total_its, att.residual
            # ok None: a doubled step whose strands may meet goes to the route rule
            self._count_refusal(run, h_try, att, "route" if att.ok is None else None)
            h, refused = self._retry_size(run, h_try, ctl, att, att.reason == "error",
                                          att.error_ratio, refused)
            h = self._floored(h, h_try, h_min)
            if h is None:
                raise self._divergence(
                    run, f"time step from t = {run.state.t:.6g} s could not be completed down "
                    f"to the smallest step 1e-9 t_end = {h_min:.3g} s "
                    f"(last refusal: {att.reason})", h_try, att)

    def _doubled_step(self, run, h: float, t_new, left_limit: bool) -> Attempt:
        """The first error-controlled step after a restart, which has no predictor: one step
        h (s) and two steps h/2 over the same interval, the difference giving a half step's
        local error (step doubling, :meth:`ErrorControl.doubling_error`). The two half steps
        are kept when the error ratio of each is ≤ 1, nothing when not (the ratio in the
        Attempt's ``error_ratio``); the run is then at t + h with three levels since the
        restart, so the next step has the quadratic predictor (Hairer, Nørsett & Wanner I, §
        II.4: step doubling continues from the two half steps). Keeping only the first half
        left the next step two levels, a linear predictor whose O(h²) estimate read as O(h³)
        refused it (Greenhill at tolerance 1e-2: ratios 2.1 and 1.7 after the doubled step's
        0.35, the step cut 7× and regrown over ~10 steps); leaving the first step after a
        restart unmeasured set the Greenhill growth rate 2 % off at every tolerance
        (docs/numerics.md § 7). Returns the :class:`Attempt` (the residual of the second
        half), with ok = None (state unchanged) when strands may meet in one of the steps:
        there the route rule decides (docs/contact.md)."""
        start, Y_old = run._state(), run.state.Y
        t_end = run.state.t + h if t_new is None else t_new
        its, Y_full = 0, None
        for leg in ("whole", "first half", "second half"):
            if leg == "first half":              # the whole step is kept aside
                Y_full = run.state.Y
                run._restore(start)
            size = {"whole": h, "first half": 0.5 * h, "second half": t_end - run.state.t}[leg]
            ends = None if leg == "first half" else t_new
            att = self._try(run, size, t_new=ends, estimate=False,
                            left_limit=left_limit and ends is not None)
            its += att.iterations
            if not att.ok or att.had_candidates:
                # the restore takes back the run's attributes and this control's, the
                # failed leg's reason too: the run keeps it for its next step
                run._restore(start, None if att.ok else att.reason)
                return Attempt((None if att.ok else False), its, att.residual,
                               att.nonfinite, None if att.ok else att.reason)
        ctl = self.errctl
        ratio = ctl.measure(ctl.doubling_error(Y_full, run.state.Y), run.state.Y, Y_old,
                            run.newton.filtered)
        accepted = ratio <= 1.0
        if not accepted:
            run._restore(start, "error")
        return Attempt(accepted, its, att.residual, False, None if accepted else "error",
                       error_ratio=ratio)

    # ------------------------------------------------------------------ shared rules
    _landing = staticmethod(landing_step)

    def _retry_size(self, run, h_try: float, ctl, att: Attempt, by_error: bool,
                    ratio: float, refused):
        """Size (s) to retry a controlled step of h_try (s) with, after its refused
        attempt ``att``, and the (h, ratio) to pass as ``previous`` next time: the
        controller's smaller size (:meth:`solver.stepping.PIController.rejected`) when
        the error estimate refused it (``by_error``, ``ratio`` its error ratio), half of it
        within the growth guard's cap after a growth refusal, else h_try / dt_cut_factor
        (Newton or a contact check failed)."""
        if by_error:
            return ctl.rejected(h_try, ratio, refused), (h_try, ratio)
        if att.reason == "growth":
            return min(0.5 * h_try, self.guard.cap()), refused
        return h_try / run.case.numerics.dt_cut_factor, refused

    _floored = staticmethod(floored_step)

    def _count_refusal(self, run, h, att: Attempt, reason=None) -> None:
        """Count the attempt ``att`` of h (s) just refused under ``reason`` (default its
        own). A step refused for the end's drift
        ("drift") ends the run here, raising SolverDivergence: no shorter step lowers the
        rate at which the end integrated from κ leaves its prescribed motion
        (:meth:`solver.step_problem.ProblemAssembly.drifts_off`)."""
        reason = att.reason if reason is None else reason
        self.refusals[reason] = self.refusals.get(reason, 0) + 1
        if reason == "drift":
            drift = run.end_drift()
            tolerance = run.assembly.end_drift_tolerance()
            raise self._divergence(
                run, f"the step from t = {run.state.t:.6g} s would leave the s = L end "
                f"beyond contact.end_drift_tolerance = {tolerance * 1e3:.3g} mm from its "
                f"prescribed motion ({drift * 1e3:.3g} mm at the step's start)", h, att,
                reason)

    def _next_stop(self, run, t_stop: float, snap: float):
        """Take the pending consistent restart, if any, and return (its Newton iterations,
        the time (s) the next steps must land on, whether it is a breakpoint): the first
        breakpoint after t if it comes before t_stop (within ``snap`` s), else t_stop."""
        its = 0
        if self.restart_pending:
            its = self._restart(run)
            self.restart_pending = False
        later = self.breakpoints[self.breakpoints > run.state.t + snap]
        if later.size and later[0] <= t_stop + snap:
            return its, float(later[0]), True
        return its, t_stop, False

    def _restart(self, run) -> int:
        """RESTART_STEPS backward-Euler steps of ε = RESTART_FRACTION·Δt (ε cut by 10 up
        to three times if one fails): f and Ẏ become consistent with the loads and
        conditions now in force, also after a jump of the velocities
        (:mod:`solver.stepping`). Returns their Newton iterations."""
        eps = RESTART_FRACTION * run.case.numerics.dt
        its_total = 0
        taken = 0
        failed = None
        for _ in range(RESTART_STEPS + 3):
            att = self._try(run, eps, restart=True)
            its_total += att.iterations
            if att.ok:
                taken += 1
                if taken == RESTART_STEPS:
                    return its_total
            else:
                # the last refused attempt is the one the error reports (a later
                # accepted one does not finish the restart alone)
                failed = (eps, att, run.newton.last_failure)
                eps *= 0.1
        eps, att, failure = failed
        raise self._divergence(run, f"the consistent restart (backward-Euler steps) at "
                               f"t = {run.state.t:.6g} s did not converge ({taken} of its "
                               f"{RESTART_STEPS} steps taken)", eps, att, failure=failure)

    @staticmethod
    def _divergence(run, what, h, att: Attempt, reject=None,
                    failure=None) -> SolverDivergence:
        """The SolverDivergence of a step that cannot be completed, with the reason: that
        of the refused attempt ``att`` of Δt = h (s), refused for ``reject`` (a refusal
        reason; default the attempt's) after Newton's ``failure`` (default
        ``run.newton.last_failure``)."""
        res, nonfinite = att.residual, att.nonfinite
        reject = att.reason if reject is None else reject
        failure = run.newton.last_failure if failure is None else failure
        singular = failure == "singular"
        reason = "nonfinite_state" if (nonfinite and not singular) else "solver_diverged"
        why = ("singular Jacobian: the boundary conditions leave a force or moment "
               "undetermined (e.g. a straight inextensible rod held axially at both "
               "ends)" if singular else
               "non-finite state" if nonfinite else
               "the last attempt converged but put in more energy than its loads' work "
               "(numerics.energy_tolerance): no step down to the smallest is trusted"
               if reject == "energy" else
               "the centreline integrated from κ and the end's prescribed motion part "
               "faster than the end correction steers them together, at the box rule's "
               "route rate, an error in s that shorter steps do not lower: refine "
               "numerics.n_segments (docs/contact.md § 1, \"A bound on the drift\")"
               if reject == "drift" else
               "Newton did not converge" if reject in (None, "newton") else
               f"the last attempt converged but was refused ({reject})")
        return SolverDivergence(f"{what} (Δt = {h:.3g} s, scaled residual {res:.3g}, {why})",
                                t=run.state.t, step=None, residual=res, reason=reason)
