"""One run of a case on the centreline scheme (``numerics.formulation: centreline``).

:class:`CentrelineRun` steps a :class:`solver.centreline.CentrelineRod` with the case's
fixed Δt (:meth:`CentrelineRun.advance`) or, with ``numerics.tolerance``, with steps
chosen from their local error (:meth:`CentrelineRun.step_adaptive`,
:class:`solver.stepping.DisplacementErrorControl`; dense output by
:func:`interpolated_level`) and hands the time loop of
:func:`solver.simulation.integrate` (its recorder, progress, observer and checkpoints)
the state in the names the seed scheme's run uses
(``run.state``, as :class:`solver.state.RunState`; ``run.control.refusals``,
``run.control.last_dt``, ``run.control.guard.sigma``, as
:class:`solver.stepping.control.StepControl`; ``run.system.seabed`` None): ``Y``
(N+1, 12) = (v, ω, f, κ) in the body frame, read off the centreline's own r, q, n,
m and velocities (:meth:`solver.centreline.CentrelineRod.body_fields`), ``r`` and ``q``
as they are (one centreline: the space route, the time route and the outputs are the
same positions, so ``position_route_difference`` and ``end_drift`` are 0 by
construction).

A step Newton does not converge (or in which strands pass through each other, with
self-contact: :meth:`solver.contact.SelfContact.passes_through`) is retried from the same
state with Δt cut by ``numerics.dt_cut_factor``, up to ``numerics.max_dt_cuts`` times,
the cut steps completing the nominal step (with ``thermal``, the nominal step's random
impulses are drawn once at its start and the cut steps take their parts of them by the
Brownian bridge, :class:`solver.thermal.ThermalForcing`); the cut Δt is kept into the
following nominal steps and grows back by the factor after ``GROW_AFTER`` accepted
sub-steps (the seed scheme's rule, :mod:`solver.stepping`). The growth guard
(``numerics.growth_guard``, :meth:`CentrelineRun._growth_ok`) refuses a converged step
whose Δt exceeds g/σ, σ the fastest growth rate of the dynamics linearised about the new
level, and cuts Δt below that cap, where it stays until σ falls. The energy check
(``numerics.energy_tolerance``, :class:`solver.balance.CentrelineBalance`,
:meth:`CentrelineRun._check_energy`) refuses a converged step that put in more energy
than its loads' work allows, and Δt is cut as after a Newton failure. When all cuts fail,
:class:`solver.stepping.control.SolverDivergence` (reason ``solver_diverged``) carries the partial result.

The work put in (``work_in``, J) is the scheme's discrete work (:meth:`CentrelineRun.
_work`): the ends' n·Δr + m·(R Δθ) at s = L minus the same at s = 0 and the dead loads'
∫ f·Δr ds (trapezoid in s), the loads the mean of the step's two levels. The end
rotations of the linking number (``phi``, rad) integrate the end nodes' W3 by the
trapezoid in time.
"""
from __future__ import annotations

import copy
import math
from types import SimpleNamespace

import numpy as np

from . import statics as st
from .balance import CentrelineBalance
from .centreline import (CentrelineError, CentrelineRod, CentrelineState, StepFailure,
                         box_centreline)
from .stepping import (DisplacementErrorControl, breakpoints, floored_step, hermite,
                       landing_step)
from .stepping.control import SolverDivergence
from .stepping.guard import GrowthGuard

__all__ = ["CentrelineRun"]


class CentrelineRun:
    """The state of one centreline run and its fixed-step control.

    Parameters
    ----------
    case : solver.case.Case (validated, ``numerics.formulation`` "centreline")
    extra_force : must be None (a force written as code is not taken yet)
    start : solver.initial.StartState or None: start from this state (its r, q, and the
        body-frame v, ω, f, κ turned into ṙ, W, n, m) instead of the case's initial pose

    Raises :class:`solver.centreline.CentrelineError` naming the field the scheme does
    not take, or when the consistent start does not converge.
    """

    #: the recorder's output groups that need the pose (all do here)
    POSE_FIELDS = frozenset({"position", "orientation", "topology"})

    #: the recorder's defaults: the energy check (:class:`solver.balance.
    #: CentrelineBalance`, None: off) and its largest ε/scale over the nominal step
    seabed = energy_check = None
    contact_count = 0
    min_gap = math.inf
    energy_error = math.nan

    def __init__(self, case, extra_force=None, start=None):
        if extra_force is not None:
            raise CentrelineError("extra_force: numerics.formulation 'centreline' does "
                                  "not take a force written as code yet; use 'goyal'")
        self.case = case
        self.rod = rod = CentrelineRod.from_case(case)
        #: self-contact's model (:class:`solver.contact.SelfContact`) or None
        self.contact = rod.contact
        self.props = rod.props
        self.system = SimpleNamespace(needs_pose=True, seabed=rod.seabed)
        self.newton = SimpleNamespace(factorizations=0, gmres_iterations=0)
        # the step control's figures in the seed scheme's names
        self.control = SimpleNamespace(refusals={}, last_dt=case.numerics.dt,
                                       guard=GrowthGuard(case.numerics.growth_guard))
        p = rod.props
        #: the bending time scale L²√(ρA/EJ) (s) of the growth guard's rule
        self.tc = float(p.s[-1] ** 2 * math.sqrt(np.max(p.rho_a)
                                                 / np.max(p.stiffness[:, :2])))
        self.last_iterations = 0
        self.last_residual = 0.0
        self.energy_check = CentrelineBalance.for_run(self)
        Y, X, t = None, None, 0.0
        # the seed scheme's names of the current state (:meth:`_publish`)
        self.state = SimpleNamespace(t=0.0, phi=np.zeros(2), work_in=0.0, seabed_work=0.0)
        if start is not None:
            Y, X = _from_start(start, rod.props.stiffness, rod.h, rod.problem(start.t).kappa0)
            t = float(start.t)
            if start.phi is not None:
                self.state.phi = np.asarray(start.phi, float).copy()
            if start.work_in is not None:
                self.state.work_in = float(start.work_in)
        #: where the case's loads or conditions jump (s, sorted; :func:`solver.stepping.
        #: breakpoints`; with fixed steps without the tables' kinks, whose corners cost
        #: O(Δslope Δt²) once, with error control with them: the estimate has no X⃛
        #: across a corner, and a step of the quasi-static twisting spans seconds): the
        #: steps land on them and restart there; and the ends held after a load phase,
        #: [(end, item, t_a)]
        self.breaks = breakpoints(case, kinks=case.numerics.tolerance is not None)
        self.switches = st.load_to_held_switches(case)
        for name, where, t_a in self.switches:
            if t_a < t:
                # a start after the switch: the held end is where the start has it
                self._anchor_at(name, where, t_a, t, Y)
        try:
            # the centreline's own level (r, q, n, m and their rates)
            self.level = rod.start(Y, t, X)
        except StepFailure as exc:
            raise CentrelineError(f"initial: the consistent start did not converge "
                                  f"({exc.reason})") from exc
        self.phi_start = self.state.phi.copy()
        self.state.seabed_power = self._seabed_power(self.level)
        #: the error control of ``numerics.tolerance`` (None: fixed steps); it keeps the
        #: next step's size (``h_next``, s) and the start's positions and frames its
        #: sizes count from (``origin``)
        self.errctl = None
        tol = case.numerics.tolerance
        if tol is not None:
            ctl = self.errctl = DisplacementErrorControl(
                tol.relative, tol.absolute, float(rod.props.s[-1]), case.numerics.rho_inf,
                rod.props.s)
            ctl.h_next = case.numerics.dt
            ctl.origin = (self.level.Y[:, 0:3].copy(), self.level.Y[:, 3:7].copy())
            ctl.push(ctl.sizes(*self._moved(self.level)))
        if start is None and (case.initial.twist_rate != 0.0
                              or case.initial.centreline is not None):
            # a twisted or curved start: Lk counts from the untwisted straight rod
            from .state import initial_end_rotations

            kappa3 = rod.body_fields(self.level)["kappa"][:, 2]
            self.phi_start = initial_end_rotations(self.level.Y[:, 0:3], kappa3,
                                                   rod.props.s)
            self.state.phi = self.phi_start.copy()
        self._publish()

    # ------------------------------------------------------------------ the state
    def _publish(self) -> None:
        """The seed scheme's names of the current level in ``state`` (t, Y, r, q, power)."""
        st = self.state
        fl = self.rod.body_fields(self.level)
        st.t = self.level.t
        st.Y = np.concatenate([fl["v"], fl["omega"], fl["f"], fl["kappa"]], axis=1)
        st.r = st.r_time = fl["r"]
        st.v_global = st.v_global_time = self.level.X[:, 0:3].copy()
        st.q = st.q_time = fl["q"]
        st.quat_norm_error = float(np.abs(np.linalg.norm(st.q, axis=1) - 1.0).max())
        st.power = self._power(self.level)

    def end_drift(self) -> float:
        """0: the ends are rows of the one centreline (kept for the recorder)."""
        return 0.0

    def update_space_route(self) -> None:
        """Nothing to do: the centreline is the state."""

    def _power(self, state) -> float:
        """The power put in (W) by the ends and the dead loads at ``state``."""
        Y, X = state.Y, state.X
        R = st._rot(Y[[0, -1], 3:7])
        omega = np.einsum("kij,kj->ki", R, X[[0, -1], 3:6])
        ends = (Y[-1, 7:10] @ X[-1, 0:3] + Y[-1, 10:13] @ omega[1]
                - Y[0, 7:10] @ X[0, 0:3] - Y[0, 10:13] @ omega[0])
        load = self.rod.problem(state.t).load
        dist = float(np.sum(self.props.quad_weights * np.sum(load * X[:, 0:3], axis=1)))
        return float(ends) + dist

    def _work(self, old, new, landed) -> float:
        """The work put in over a step from the level ``old`` to ``new`` (J): the dead
        loads' Σ w_k ½(f^n + f^n+1)·Δr_k (trapezoid weights w_k), and at the ends
        n·Δr and m·(R^n Δθ) with n, m the mean of the two levels' (Δθ the rotation
        vector of the step's turn, :func:`_rotation_vector`; s = L minus s = 0), plus
        the thermal loads' f·Δr + m·(R^n Δθ) at the nodes: exact for a load linear in
        the displacement along a fixed axis (a quasi-static twist), where a trapezoid of
        the power at the levels missed where the loads turn within a step, and the
        Cayley vector 2 tan(θ/2) of a large turn overstates θ (the twisted rod of
        tests/solver/test_solver_misc.py at Δt = 1 s, 1.7 rad in a step: by 34 %)."""
        rod = self.rod
        w = self.props.quad_weights
        # the loads in force within the step: the right limit at the old level's time
        # and the left limit at the new one's (at a breakpoint the level's own value is
        # one side's; read at a window's end the old level's load counted the window
        # over the step after it: a sin² pulse of windows by 26 %)
        f0 = rod.problem(float(np.nextafter(old.t, np.inf))).load
        f1 = rod.problem(float(np.nextafter(new.t, -np.inf))).load
        dr = new.Y[:, 0:3] - old.Y[:, 0:3]
        dth = np.einsum("kij,kj->ki", st._rot(old.Y[:, 3:7]),
                        _rotation_vector(old.Y[:, 3:7], new.Y[:, 3:7]))
        nm = 0.5 * (old.Y[:, 7:13] + new.Y[:, 7:13])
        work = float(np.sum(w * np.sum(0.5 * (f0 + f1) * dr, axis=1)))
        work += float(nm[-1, 0:3] @ dr[-1] - nm[0, 0:3] @ dr[0]
                      + nm[-1, 3:6] @ dth[-1] - nm[0, 3:6] @ dth[0])
        th = rod.thermal
        if th is not None and th.load is not None:
            work += float(np.sum(w * (np.sum(th.load[:, 0:3] * dr, axis=1)
                                      + np.sum(th.load[:, 3:6] * dth, axis=1))))
        return work

    def _anchor_at(self, name: str, where: str, t_a: float, t: float, Y) -> None:
        """Record where the end ``name`` held from t_a on (after a load phase) was at t_a,
        from the nodes' unknowns Y (N+1, 13) at t ≥ t_a (the velocities held since moved
        it by their integral, which the anchor takes back)."""
        k = 0 if name == "start" else -1
        r = np.array(Y[k, 0:3], float)
        if t > t_a:
            self.rod.anchor(where, t_a, np.zeros(3))
            spec = getattr(self.rod.problem(t), name)
            i = int(where.rsplit(".", 1)[1])
            since = spec.position @ spec.axes[:, i]      # the integral over [t_a, t]
            r = r - since * spec.axes[:, i]
        self.rod.anchor(where, t_a, r)

    def _take_restart(self) -> None:
        """The restart the last accepted step left pending at the breakpoint it landed on
        (:meth:`_restart`), now that the run goes on from there. Raises
        :class:`SolverDivergence` where an impact does not converge."""
        t_b, impact = self._pending_restart
        self._pending_restart = None
        if self.level.t != t_b:
            return
        self._before = None                   # the restart's n, m are not the left's
        try:
            self.level = self._restart(self.level, impact)
        except StepFailure as exc:
            if impact:
                raise SolverDivergence(
                    f"the impact at the breakpoint t = {t_b:.6g} s did not converge: "
                    f"{exc.reason}", self.state.t, 0, math.inf, "solver_diverged") from exc
            self._refused("restart")
        self._publish()

    def _restart(self, level, impact: bool):
        """The level at a breakpoint it landed on made consistent with what is in force
        after it: Ẋ and (n, m) from the start's Taylor steps (:meth:`solver.centreline.
        CentrelineRod.start`) at the level's positions and velocities, which a load's
        jump or a velocity table's corner leaves continuous while the accelerations jump
        (generalized-α's carried accelerations cost the order: measured 1.03 on the
        2-segment cantilever of tests/solver/test_step_control.py, 1.99 with the restart;
        Arnold & Brüls 2007). With ``impact`` (an end held after a load phase: its
        velocity jumps) the velocities are first those after the impact
        (:meth:`solver.centreline.CentrelineRod.impact`): carried into the held steps,
        the jump rang undamped at ρ∞ = 1. Not in a viscous fluid (the caller's rule: the
        inertial start at steps beyond the drag's inertial time, docs/numerics.md § 9).
        Raises :class:`StepFailure` where the impact or a Taylor step does not
        converge (the caller then goes on from the level as it is, counting a refused
        "restart", or, after an impact, stops the run)."""
        X = self.rod.impact(level) if impact else level.X
        return self.rod.start(level.Y, level.t, X)

    def _landing(self, t: float, h: float) -> tuple[float, float | None]:
        """The step from t (s) of at most h (s), shortened to land on the first breakpoint
        inside it (a step ending within 1e-9 h of one ends on it): (h, the breakpoint
        landed on or None)."""
        tol = 1e-9 * h
        i = int(np.searchsorted(self.breaks, t + tol, side="right"))
        if i < self.breaks.size and self.breaks[i] <= t + h + tol:
            tb = float(self.breaks[i])
            return tb - t, tb
        return h, None

    def _end_angles(self, old, new, h) -> np.ndarray:
        """The ends' rotations about a3 (rad) at the new level: a held end's prescribed
        angle (the statics' ``twist``, exact), else the trapezoid of its node's W3."""
        phi = self.state.phi + 0.5 * h * (old.X[[0, -1], 5] + new.X[[0, -1], 5])
        prob = self.rod.problem(new.t)
        for k, name in ((0, "start"), (1, "end")):
            spec = getattr(prob, name)
            if spec.rotation_held and name not in self.rod.paths:
                phi[k] = self.phi_start[k] + spec.twist
        return phi

    # ------------------------------------------------------------------ the steps
    def advance(self, t_target: float):
        """Step to ``t_target`` (s): one step of t_target − t, cut on a Newton failure
        and completed by the cut steps. Returns (Newton iterations of the last step, its
        scaled update). Raises :class:`SolverDivergence` when every cut fails."""
        num = self.case.numerics
        total_its = 0
        st = self.state
        h_full = t_target - st.t
        cuts = min(self._cut_level, num.max_dt_cuts)
        h = h_full / num.dt_cut_factor ** cuts
        thermal = self.rod.thermal
        if thermal is not None:
            thermal.begin(st.t, t_target)        # the nominal step's random impulses
        while st.t < t_target - 1e-12 * max(1.0, t_target):
            if self._pending_restart is not None:
                self._take_restart()
            if (cuts and self._accepted_at_level >= self.GROW_AFTER
                    and h * num.dt_cut_factor <= self.control.guard.cap() * (1.0 + 1e-9)):
                cuts -= 1                  # grow back by the factor
                h *= num.dt_cut_factor
                self._accepted_at_level = 0
            h = min(h, t_target - st.t)
            step, landed = self._landing(st.t, h)
            try:
                attempt = self._attempt(step, landed)
                if attempt is None:              # the growth guard's refusal
                    h, cuts = self._growth_cut(h, cuts, h_full)
                    continue
            except StepFailure as exc:
                self._count_refusal(exc)
                cuts += 1
                if cuts > num.max_dt_cuts:
                    raise SolverDivergence(
                        f"step to t = {t_target:.6g} s failed after {num.max_dt_cuts} Δt "
                        f"cuts at t = {st.t:.6g} s: {exc.reason}", st.t, 0, math.inf,
                        "solver_diverged") from exc
                h /= num.dt_cut_factor
                self._accepted_at_level = 0
                continue
            self._accepted_at_level += 1
            if thermal is not None:
                thermal.accept()                 # cut steps: the rest of the impulse
            total_its = self._accept(*attempt, step, landed)
        self._cut_level = cuts
        self.last_iterations = total_its
        return total_its, self.last_residual

    def _attempt(self, h: float, landed):
        """One step of h (s) from the current level, ending on the breakpoint ``landed``
        (s) or None, checked: (the new level, Newton iterations, scaled update, the work
        put in, J), or None where the growth guard refuses it. Raises
        :class:`StepFailure` where Newton does not converge, strands pass through each
        other, a node turns too far or the energy check refuses it."""
        new, its, err = self.rod.step(self.level, h, landed)
        if self.contact is not None and self.contact.passes_through(
                self.level.Y[:, 0:3], new.Y[:, 0:3]):
            raise StepFailure("strands passed through each other in the step")
        if not self._growth_ok(new, h):
            return None
        work = self._work(self.level, new, landed)
        self._check_energy(self.level, new, work)
        return new, its, err, work

    def _count_refusal(self, exc: StepFailure) -> None:
        """Count a refused attempt under its reason's key (crossing, turn, energy,
        newton) in ``control.refusals``."""
        self._refused("crossing" if exc.reason.startswith("strands") else
                      "turn" if exc.reason.startswith("a node turned") else
                      "energy" if exc.reason.startswith(self.ENERGY_REFUSAL) else "newton")

    def _refused(self, key: str) -> None:
        """Count one refused attempt under ``key`` in ``control.refusals``."""
        refusals = self.control.refusals
        refusals[key] = refusals.get(key, 0) + 1

    def _accept(self, new, its: int, err: float, work: float, h: float, landed) -> int:
        """Make the checked level ``new`` of a step of h (s) the run's (ending on the
        breakpoint ``landed`` or None; Newton's ``its`` and ``err``, the work ``work``, J):
        the ends held from a switch anchored, a restart left pending at a breakpoint, the
        end angles, the work and the sea floor's work, the contact summary. Returns
        ``its``. Raises :class:`SolverDivergence` on a non-finite level."""
        st = self.state
        self.control.guard.since += 1
        if not all(np.all(np.isfinite(x)) for x in (new.Y, new.X, new.Xd, new.a)):
            raise SolverDivergence(f"non-finite state at t = {new.t:.6g} s", st.t, 0,
                                   math.inf, "nonfinite_state")
        old = self.level
        self.level = new
        self._before = old
        held = [t_a for _, _, t_a in self.switches if landed == t_a]
        for name, where, t_a in self.switches:
            if landed == t_a:
                self._anchor_at(name, where, t_a, t_a, new.Y)
        if landed is not None and self.rod.stokes is None:
            # the level recorded at the breakpoint is its left limit; the next step
            # starts from the restart
            self._pending_restart = (landed, bool(held))
        st.phi = self._end_angles(old, new, h)
        self._publish()
        st.work_in += work
        if self.rod.seabed is not None:
            power = self._seabed_power(new)
            st.seabed_work += 0.5 * h * (st.seabed_power + power)
            st.seabed_power = power
        if self.contact is not None:
            self._contact_summary(new)
        self.last_residual, self.control.last_dt = err, h
        self.newton.factorizations = self.rod.factorizations
        return its

    #: how a step refused by the energy check starts its reason
    ENERGY_REFUSAL = "the step put in more energy than its loads' work"

    def _check_energy(self, old, new, work: float) -> None:
        """The energy check (``numerics.energy_tolerance``, :class:`solver.balance.
        CentrelineBalance`) of a converged step from the level ``old`` to ``new`` with the
        scheme's work ``work`` (J): raises :class:`StepFailure` (refusal key "energy")
        where it put in more than the tolerance allows, else keeps the largest ε/scale of
        the nominal step in ``energy_error``. Nothing without the check."""
        check = self.energy_check
        if check is None:
            return
        bal = check.measure(self, old, new, work)
        if check.refuses(bal):
            raise StepFailure(f"{self.ENERGY_REFUSAL} (ε = {bal.error:.3g} J against a "
                              f"scale of {bal.scale:.3g} J; numerics.energy_tolerance = "
                              f"{check.tolerance:g})")
        if math.isnan(self.energy_error) or bal.relative > self.energy_error:
            self.energy_error = bal.relative

    def _growth_cut(self, h: float, cuts: int, h_full: float) -> tuple[float, int]:
        """After a growth refusal: (Δt, cuts) cut by ``numerics.dt_cut_factor`` until
        within the guard's cap (the levels it forbids skipped). Raises
        :class:`SolverDivergence` where that takes more than ``numerics.max_dt_cuts``
        cuts of the nominal step h_full (s)."""
        num, guard = self.case.numerics, self.control.guard
        self._refused("growth")
        cap = guard.cap() * (1.0 + 1e-9)
        while h > cap and cuts <= num.max_dt_cuts:
            h /= num.dt_cut_factor
            cuts += 1
        if cuts > num.max_dt_cuts:
            t = self.state.t
            raise SolverDivergence(
                f"at t = {t:.6g} s the fastest growth rate is {guard.sigma:.3g} 1/s: the "
                f"growth guard needs Δt ≤ {guard.cap():.3g} s, more than "
                f"numerics.max_dt_cuts = {num.max_dt_cuts} cuts of {h_full:.3g} s (set "
                f"numerics.growth_guard to null to run without the check)", t, 0, math.inf,
                "solver_diverged")
        self._accepted_at_level = 0
        return h, cuts

    def _growth_ok(self, new, h: float) -> bool:
        """The growth guard (``numerics.growth_guard``, :meth:`solver.stepping.guard.
        GrowthGuard.check`) on a converged step of h (s) to the level ``new``: σ of the
        dynamics linearised about it (:meth:`solver.centreline.CentrelineRod.
        growth_rate`); True without a guard, and the last σ stands where the rod declines
        to estimate (pairs, a closed rod, a viscous fluid, a level far from a static
        balance)."""
        guard = self.control.guard
        if guard.limit is None:
            return True
        return guard.check(h, self.tc, lambda shift, v0: self.rod.growth_rate(new, shift, v0),
                           look_far=True)

    #: accepted sub-steps at a cut Δt before it grows back by ``numerics.dt_cut_factor``
    GROW_AFTER = 4
    _cut_level = 0                         # the Δt level the next nominal step starts at
    _accepted_at_level = 0
    _pending_restart = None                # (the breakpoint landed on, impact or not)
    _before = None                         # the level before the current one, or None

    def _contact_summary(self, state) -> None:
        """``contact_count`` (pairs within the law's reach) and ``min_gap`` (m, the
        smallest surface gap of the pairs evaluated, inf with none) at a level."""
        co = SimpleNamespace(cX=0.0, dX=state.X)
        _, ev, _ = self.rod.contact_terms(state.Y, state, co, want=False)
        self.contact_count = 0 if ev is None else int(ev.count)
        self.min_gap = math.inf if ev is None or not ev.count else float(ev.min_gap)

    # ------------------------------------------------------------- error control
    def _moved(self, level) -> tuple[np.ndarray, np.ndarray]:
        """What :class:`solver.stepping.DisplacementErrorControl` measures errors against
        at ``level``: each node's displacement from the start (m, global) and turn from
        the start's frame (rotation vector, rad, body), (N+1, 6); and the bending and
        twist the rod holds, ∫|κ₁,₂| ds and ∫|κ₃| ds (rad, trapezoid), (2,)."""
        r0, p0 = self.errctl.origin
        moved = np.concatenate([level.Y[:, 0:3] - r0,
                                _rotation_vector(p0, level.Y[:, 3:7])], axis=1)
        kappa = self.rod.body_fields(level)["kappa"]
        w = self.props.quad_weights
        held = np.array([w @ np.hypot(kappa[:, 0], kappa[:, 1]), w @ np.abs(kappa[:, 2])])
        return moved, held

    def step_adaptive(self, t_stop: float):
        """One accepted error-controlled step (``numerics.tolerance``) toward t_stop (s):
        never past t_stop or the next breakpoint, landing on them exactly (a step that
        would leave less than itself before the stop is halved instead,
        :func:`solver.stepping.landing_step`). The step's local error is
        :class:`solver.stepping.DisplacementErrorControl`'s; a step refused for it is
        retried at the PI controller's smaller size, one refused by the growth guard at
        half its size within g/σ, one whose Newton, crossing, turn or energy check fails
        at Δt/dt_cut_factor; the floor is 1e-9 t_end (:func:`solver.stepping.
        floored_step`). Returns (Newton iterations of all attempts, the accepted step's
        scaled update). Raises :class:`SolverDivergence` when a step at the floor is
        refused."""
        num, ctl, guard = self.case.numerics, self.errctl, self.control.guard
        if self._pending_restart is not None:
            self._take_restart()
            ctl.forget()
        t = self.level.t
        snap = 1e-9 * ctl.h_next
        later = self.breaks[self.breaks > t + snap]
        at_break = bool(later.size and later[0] <= t_stop + snap)
        stop = float(later[0]) if at_break else float(t_stop)
        h_min = 1e-9 * max(num.t_end, num.dt)
        h_max = num.dt_max if num.dt_max is not None else math.inf
        h, refused, total = ctl.h_next, None, 0
        while True:
            h = min(h, h_max, guard.cap())
            h_try, last = landing_step(h, stop - t)
            landed = stop if last and at_break else None
            try:
                attempt = self._attempt(h_try, stop if last else None)
            except StepFailure as exc:
                self._count_refusal(exc)
                h_next, why = h_try / num.dt_cut_factor, exc.reason
            else:
                if attempt is None:
                    self._refused("growth")
                    h_next, why = min(0.5 * h_try, guard.cap()), "growth"
                else:
                    new = attempt[0]
                    total += attempt[1]
                    sizes = ctl.sizes(*self._moved(new))
                    ratio = ctl.ratio(ctl.estimate(h_try, self.level.a, new.a), sizes)
                    if ratio <= 1.0:
                        ctl.push(sizes)
                        h_new = ctl.accepted(h_try, ratio)
                        # a step shortened to land on a stop does not shrink the next one
                        ctl.h_next = max(h_new, h) if h_try < h else h_new
                        self._accept(*attempt, h_try, landed)
                        self.last_iterations = total
                        return total, self.last_residual
                    self._refused("error")
                    h_next, refused = ctl.rejected(h_try, ratio, refused), (h_try, ratio)
                    why = f"local error {ratio:.3g} × numerics.tolerance"
            h = floored_step(h_next, h_try, h_min)
            if h is None:
                raise SolverDivergence(
                    f"time step from t = {t:.6g} s could not be completed down to the "
                    f"smallest step 1e-9 t_end = {h_min:.3g} s (last refusal: {why})",
                    t, 0, math.inf, "solver_diverged")

    def dense_state(self):
        """What :meth:`interpolated_snapshot` needs of the level a step starts from: the
        level (never changed in place), the one before it where no restart came between
        (else None), and the run's end angles, work and sea floor's work and power
        there."""
        st = self.state
        return (self.level, st.phi.copy(), st.work_in, st.power, st.seabed_work,
                st.seabed_power, self._before)

    def interpolated_snapshot(self, fields: set, t: float, start) -> dict:
        """The outputs (:func:`solver.recording.snapshot`) at t (s) inside the last
        accepted step, which began at the :meth:`dense_state` ``start``: the dense
        output of error-controlled steps (:func:`interpolated_level` for the level; the
        end angles, the work in and the sea floor's work by cubic Hermite interpolation
        with their rates W3 at the end nodes and the powers). The contact count and
        smallest gap are the step's."""
        from .recording import snapshot

        level0, phi0, w0, p0, sw0, sp0, before = start
        if self._before is not level0:
            before = None              # the step began at a restart: n, m jumped there
        st = self.state
        h = st.t - level0.t
        s = (t - level0.t) / h
        view = copy.copy(self)
        view.state = vs = copy.copy(st)
        view.level = interpolated_level(level0, self.level, t, before)
        view._publish()
        vs.phi = hermite(s, h, phi0, level0.X[[0, -1], 5], st.phi, self.level.X[[0, -1], 5])
        vs.work_in = float(hermite(s, h, w0, p0, st.work_in, st.power))
        if self.rod.seabed is not None:
            vs.seabed_work = float(hermite(s, h, sw0, sp0, st.seabed_work,
                                           st.seabed_power))
        return snapshot(view, fields, route_current=True)

    def _seabed_split(self, state):
        """The sea floor's (normal, friction, moment (N+1, 3), penetration (N+1,)) at a
        level, the loads its step solved with (:meth:`solver.centreline.CentrelineRod.
        seabed_terms` at the level's own velocities)."""
        rod = self.rod
        co = SimpleNamespace(cX=0.0, dX=state.X)         # X = 0·Δ + X: the level's own
        return rod.seabed_terms(state.Y, state, co, want=False)[1]

    def seabed_loads(self, pose=None):
        """The sea floor's (normal reaction, friction, moment) per unit length (N+1, 3),
        global, and the surface penetration (N+1,) m, at the current level (``pose`` is
        the seed scheme's and must be None: there is one centreline)."""
        if pose is not None:
            raise CentrelineError("seabed: the centreline scheme has one pose, its own")
        return self._seabed_split(self.level)

    def _seabed_power(self, state) -> float:
        """Power of the sea floor's loads on a level, W: ∫ (F·ṙ + M·Ω) ds (trapezoid),
        0 without a seabed."""
        if self.rod.seabed is None:
            return 0.0
        Fn, Ff, M, _ = self._seabed_split(state)
        R = st._rot(state.Y[:, 3:7])
        omega = np.einsum("kij,kj->ki", R, state.X[:, 3:6])
        per = np.sum((Fn + Ff) * state.X[:, 0:3], axis=1) + np.sum(M * omega, axis=1)
        return float(per @ self.props.quad_weights)


def interpolated_level(old, new, t: float, before=None):
    """The level at t (s) between two levels ``old`` and ``new``
    (:class:`solver.centreline.CentrelineState`) of one step: the dense output of
    error-controlled steps (Hairer, Nørsett & Wanner I, § II.6). Positions r by cubic
    Hermite interpolation with their rates ṙ; each frame p_old ⊗ exp(ψ(t)), ψ the cubic
    Hermite interpolant of the rotation vector from p_old with ψ(old.t) = 0, ψ'(old.t) = W_old, ψ(new.t) = ψ_1 (the step's turn) and
    ψ'(new.t) = J_r⁻¹(ψ_1) W_new (the right Jacobian of SO(3)'s exponential:
    p' = ½ p ⊗ W with p = p_old ⊗ exp(ψ) gives W = J_r(ψ) ψ'); the velocities X by cubic
    Hermite with their rates Ẋ; n and m by the parabola through ``before`` (the level
    before ``old``, where no restart came between; linear without it), so that the
    twist they carry (κ = K⁻¹ Rᵀ m) is interpolated to the same order as the ends'
    angles (a rod twisted at a rising rate: |Lk − Tw| at the outputs 3.5e-3 turns with
    m linear, docs/numerics.md § 9); Ẋ, a and the load rate linear. The interpolant's
    error is O(h³) against the scheme's O(h²) global error."""
    h = new.t - old.t
    s = (t - old.t) / h
    Y = (1.0 - s) * old.Y + s * new.Y
    if before is not None and before.t < old.t:
        # Lagrange through (before, old, new) for n and m
        t0, t1, t2 = before.t, old.t, new.t
        l0 = (t - t1) * (t - t2) / ((t0 - t1) * (t0 - t2))
        l1 = (t - t0) * (t - t2) / ((t1 - t0) * (t1 - t2))
        l2 = (t - t0) * (t - t1) / ((t2 - t0) * (t2 - t1))
        Y[:, 7:13] = l0 * before.Y[:, 7:13] + l1 * old.Y[:, 7:13] + l2 * new.Y[:, 7:13]
    Y[:, 0:3] = hermite(s, h, old.Y[:, 0:3], old.X[:, 0:3], new.Y[:, 0:3], new.X[:, 0:3])
    psi1 = _rotation_vector(old.Y[:, 3:7], new.Y[:, 3:7])
    psi = hermite(s, h, 0.0 * psi1, old.X[:, 3:6], psi1, _inverse_right_jacobian(
        psi1, new.X[:, 3:6]))
    Y[:, 3:7] = st._qmul(old.Y[:, 3:7], _quaternion_exp(psi))
    lin = lambda a, b: (1.0 - s) * a + s * b                              # noqa: E731
    X = hermite(s, h, old.X, old.Xd, new.X, new.Xd)
    return CentrelineState(float(t), Y, X, lin(old.Xd, new.Xd), lin(old.a, new.a),
                           lin(old.load_rate, new.load_rate))


def _inverse_right_jacobian(psi, w):
    """J_r⁻¹(ψ) w (..., 3): w + ½ ψ × w + (1/θ² − (1 + cos θ)/(2θ sin θ)) ψ × (ψ × w),
    θ = |ψ|, the inverse of SO(3)'s right Jacobian (Solà, Deray & Atchuthan, *A micro
    Lie theory for state estimation in robotics*, arXiv:1812.01537, 2018; the
    coefficient → 1/12 as θ → 0)."""
    th = np.linalg.norm(psi, axis=-1, keepdims=True)
    small = th < 1e-2                  # the series to θ²: 7e-13 off at 1e-2
    ths = np.where(small, 1.0, th)
    c = np.where(small, 1.0 / 12.0 + th ** 2 / 720.0,
                 1.0 / ths ** 2 - (1.0 + np.cos(ths)) / (2.0 * ths * np.sin(ths)))
    pw = np.cross(psi, w)
    return w + 0.5 * pw + c * np.cross(psi, pw)


def _quaternion_exp(psi):
    """The unit quaternion (..., 4) (w, x, y, z) of the rotation vector ψ (..., 3) rad:
    (cos(θ/2), sin(θ/2) ψ/θ), θ = |ψ|."""
    th = np.linalg.norm(psi, axis=-1, keepdims=True)
    half = 0.5 * th
    sinc = np.where(th > 1e-12, np.sin(half) / np.where(th > 1e-12, th, 1.0), 0.5)
    return np.concatenate([np.cos(half), sinc * psi], axis=-1)


def _rotation_vector(p_old, p_new):
    """The rotation vector θ a (..., 3) rad, body frame of p_old, of the turn from the
    unit quaternions p_old to p_new (..., 4): d = p̄_old ⊗ p_new taken with w ≥ 0,
    θ = 2 atan2(|vec d|, w), a = vec d / |vec d| (0 where there is no turn)."""
    d = st._qmul(st._qconj(p_old), p_new)
    d = np.where(d[..., 0:1] < 0.0, -d, d)
    v = d[..., 1:]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    theta = 2.0 * np.arctan2(s, d[..., 0:1])
    return np.where(s > 0.0, theta * v / np.where(s > 0.0, s, 1.0), 0.0)


def _from_start(start, stiffness, h, kappa0):
    """(Y (N+1, 13), X (N+1, 6)) of a :class:`solver.initial.StartState`: n = R f,
    m = R K (κ − κ⁰) (κ⁰ (N+1, 3) the intrinsic curvature, 1/m), ṙ = R v, W = ω, and the centreline the box rule builds from its frames
    from its first point (:func:`solver.centreline.box_centreline`: another scheme's
    positions satisfy the position rows only to its discretisation error)."""
    q = np.asarray(start.q, float)
    q = q / np.linalg.norm(q, axis=1)[:, None]
    R = st._rot(q)
    glob = lambda x: np.einsum("kij,kj->ki", R, np.asarray(x, float))   # noqa: E731
    r = box_centreline(q, np.asarray(start.r, float)[0], h)
    Y = np.concatenate([r, q, glob(start.f),
                        glob(stiffness * (np.asarray(start.kappa, float) - kappa0))], axis=1)
    X = np.concatenate([glob(start.v), np.asarray(start.omega, float)], axis=1)
    return Y, X
