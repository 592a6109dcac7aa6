"""What a run keeps: the output records, the per-step diagnostics, progress and checkpoints.

:class:`OutputRecorder` is the output side of :func:`solver.simulation.integrate`: it takes the
run's state at the output times (:func:`snapshot`, or inside an error-controlled step its
dense output, :func:`interpolated_snapshot`), the diagnostics of every accepted step, calls
the caller's progress, checkpoint and observer hooks, and builds the result dataset
(:func:`solver.results.build_dataset`) when the run completes, stops or fails. No I/O: the
hooks decide where anything goes.
"""
from __future__ import annotations

import copy
import time as _time
from dataclasses import dataclass

import numpy as np

from .checkpoint import Checkpoint, resume_key
from .contact.geometry import max_distance
from .energies import energies
from .initial import start_offset
from .loads import end_reactions
from .plausibility import plausibility_warnings, suspects
from .results import build_dataset, events_summary
from .stepping import hermite
from .kinematics import min_bend_radius, quat_slerp

__all__ = ["Progress", "RateEstimate", "EtaModel", "OutputRecorder", "snapshot",
           "interpolated_snapshot",
           "dense_state", "end_drift"]


@dataclass(frozen=True)
class Progress:
    """What the progress callback receives after every accepted nominal step.

    Attributes
    ----------
    t, t_end, dt : float
        The time reached, the run's end and the last step, s.
    step : int
        Nominal steps done.
    newton_iterations : int
        Of the last step.
    residual_norm : float
        Its scaled residual (dimensionless).
    wall_time : float
        Seconds since the start.
    fraction : float
        t / t_end, in [0, 1].
    contact_count : int
        Self-contact pairs at t.
    eta_seconds : float or None
        Wall seconds left, estimated at the pace of the contact steps once contact began;
        None until known.
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
    run that slows down is extrapolated at its current pace, not at its average since
    the start. Returns None until two samples exist. The pace of a run without contact;
    :class:`EtaModel` adds the contact phase.
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


class EtaModel:
    """Wall-clock seconds left, knowing that contact steps cost far more than free ones.

    A step with self-contact costs 10-50 times a free step of the same simulated time
    (the seed example: 0.13 wall s per simulated s before contact, 1-6 s/s after: smaller
    steps from the route rule, more Newton iterations, the contact terms). The estimate
    therefore keeps two paces, wall s per simulated s: that of the steps with contact
    pairs (``contact_count`` > 0 at the step's end) and the recent pace of the others
    (:class:`RateEstimate`). Before any contact the remaining simulated time is priced at
    the recent free pace (a coming contact cannot be foreseen); from the first contact on
    at the contact pace, the wall time of all contact steps over their simulated time
    (their cumulative mean: the collapse into contact is its most expensive part, so the
    estimate starts high and falls towards the truth, never promising an early end; the
    recent pace alone swings with each new contact event); once the contact pairs are
    gone for ``release`` of the simulated time the run has taken, back at the free pace.
    Measured on the seed example by ``benchmarks/eta_accuracy.py`` (docs/benchmarks.md).
    Pure: no clock of its own, fed the samples.
    """

    def __init__(self, window_s: float = 30.0, share: float = 0.2, release: float = 0.05):
        self.free = RateEstimate(window_s, share)
        self.release = release
        self.last = None                 # (wall s, simulated s) of the previous sample
        self.contact_wall = 0.0          # wall s spent in contact steps
        self.contact_time = 0.0          # simulated s they covered
        self.last_contact_t = None       # simulated s of the last step with contact

    def update(self, wall: float, t: float, t_end: float, contacts: int = 0):
        """Record a sample (wall: s since the start; t, t_end: simulated s; contacts: the
        contact pairs at t) and return the wall seconds left, or None while no pace is
        known."""
        free = self.free.update(wall, t, t_end)
        last, self.last = self.last, (wall, t)
        if contacts > 0:
            self.last_contact_t = t
            if last is not None and t > last[1]:
                self.contact_wall += wall - last[0]
                self.contact_time += t - last[1]
        if (self.last_contact_t is None or self.contact_time <= 0.0
                or t - self.last_contact_t > self.release * max(t, 1e-300)):
            return free
        return max(0.0, (t_end - t) * self.contact_wall / self.contact_time)


# ------------------------------------------------------------------------- output records
def snapshot(run, fields: set, route_current: bool = False, pose=None) -> dict:
    """Output quantities of the current state of ``run`` (:class:`solver.run.RodRun`) for
    the requested field groups (``route_current``: the space route is already that of the
    current κ; otherwise it is recomputed where the steps do not keep it,
    ``system.needs_pose`` False; ``pose``: the (q, r, ṙ) the seabed outputs take, None:
    the run's own, :meth:`solver.run.RodRun.seabed_loads`). Shapes and units:
    :func:`solver.results.build_dataset`."""
    out = {}
    Y = run.state.Y
    if not run.system.needs_pose and not route_current:
        run.update_space_route()
    if "v" in fields:
        out["v"] = Y[:, 0:3].copy()
    if "omega" in fields:
        out["omega"] = Y[:, 3:6].copy()
    if "f" in fields:
        out["f"] = Y[:, 6:9].copy()
    if "kappa" in fields:
        out["kappa"] = Y[:, 9:12].copy()
    if "moment" in fields:
        kappa0 = run.props.intrinsic_curvature
        out["moment"] = run.props.stiffness * (Y[:, 9:12] if kappa0 is None
                                               else Y[:, 9:12] - kappa0)
    if "position" in fields:
        out["position"] = run.state.r.copy()
    if "orientation" in fields:
        out["orientation"] = run.state.q.copy()
    if "energies" in fields:
        out.update(energies(Y, run.props))
        out["work_in"] = run.state.work_in
        out["power_in"] = run.state.power
    if "topology" in fields:
        out.update(_topology(run))
    if "reactions" in fields:
        out.update(end_reactions(Y, run.state.q, run.props.stiffness,
                                 run.props.intrinsic_curvature))
    if "contact" in fields:
        out["contact_count"] = run.contact_count
        out["min_surface_gap"] = run.min_gap
    if "bend_radius" in fields:
        radius, s_min = min_bend_radius(Y[:, 9:12], run.props.s)
        out["bend_radius_min"] = float(radius)
        out["bend_radius_min_s"] = float(s_min)
    if run.system.seabed is not None:
        out.update(_seabed(run, pose))
    out["newton_iterations"] = run.last_iterations
    out["residual_norm"] = run.last_residual
    out["dt"] = run.control.last_dt
    out["position_route_difference"] = max_distance(run.state.r_time, run.state.r)
    out["end_drift"] = run.end_drift()
    out["quaternion_norm_error"] = run.state.quat_norm_error
    return out


def _seabed(run, pose) -> dict:
    """The seabed's outputs (with a seabed only): its normal reaction and friction per
    unit length (N+1, 3) N/m, global; the length on the bottom (m), the touchdown
    arclength (m, NaN where none: :func:`solver.seabed.touchdown`) and its work (J)."""
    from .seabed import contact_length, hover_gap, touchdown

    Fn, Ff, _, pen = run.seabed_loads(pose)
    s = run.props.s
    return {"seabed_force": Fn, "seabed_friction": Ff,
            "seabed_contact_length": contact_length(pen, s,
                                                    hover_gap(2.0 * run.system.seabed.radius)),
            "seabed_touchdown": touchdown(pen, s), "seabed_work": run.state.seabed_work}


def _topology(run) -> dict:
    """Twist, writhe and linking number of the run's state (turns; docs/topology.md). A
    closed rod's Wr is that of its closed polygon (no closure at infinity) and its Lk
    the start circle's ``initial.linking_number``, a topological invariant: Tw + Wr
    stays on it while no strand passes through another (``topology_error``)."""
    from .topology import linking_number, twist, writhe, writhe_closed

    tw = twist(run.state.Y[:, 11], run.props.s)
    if getattr(run.case.rod, "closed", False):
        wr = writhe_closed(run.state.r[:-1])
        lk = float(run.case.initial.linking_number or 0)
        return dict(twist=tw, writhe=wr, linking_number=lk,
                    topology_error=abs(tw + wr - lk), writhe_closure_passages=0.0)
    wr = writhe(run.state.r)
    lk = linking_number(run.state.phi[0], run.state.phi[1])
    # the open rod's writhe is that of the curve closed by its end tangents'
    # extensions; a passage of the rod through them changes it by ±2 with no
    # self-crossing. With self-contact, true crossings are refused by the step
    # control (swept test of every accepted step), so a jump of 2 against
    # Lk − Tw is a closure passage: count it and keep Wr continuous. Without
    # contact strands may pass through each other, and a jump stays visible in
    # topology_error (docs/topology.md).
    k = round((lk - tw - wr) / 2.0) if run.contact is not None else 0
    return dict(twist=tw, writhe=wr + 2.0 * k, linking_number=lk,
                topology_error=abs(tw + wr + 2.0 * k - lk),
                writhe_closure_passages=float(k))


def closure_warning(case, times, passages) -> str | None:
    """The warning a run with fixed steps carries where its writhe crossed the closure of
    its end tangents (``writhe_closure_passages`` changed), else None: such a run may have
    taken a path the converged motion does not (docs/numerics.md § 6: the thin-rod
    plectoneme at Δt = 0.2 s, 10× its own, sweeps a loop across the closure ray and ends
    with Wr 2.01 against 2.83, each step passing every check). case: the run's
    :class:`solver.case.Case`; times (T,) s, the output times; passages (T,) the output
    series ``writhe_closure_passages`` (signed count, 1), or None where the run has no
    topology outputs or no self-contact. Each change of the count by one is a passage.
    Not with ``numerics.tolerance``, whose steps are error-controlled. Returns the text
    or None. Raises nothing."""
    if passages is None or case.numerics.tolerance is not None:
        return None
    k = np.nan_to_num(np.asarray(passages, float))
    jumps = np.abs(np.diff(np.concatenate([[0.0], k])))
    count = int(round(float(jumps.sum())))
    if count == 0:
        return None
    first = float(times[int(np.argmax(jumps > 0.5))])
    return (f"the writhe crossed the closure of the end tangents {count} time"
            f"{'s' if count > 1 else ''}, first by t = {first:g} s "
            "(writhe_closure_passages): a loop swept across the line beyond an end. With "
            "fixed steps a numerics.dt that does not resolve a loop's formation can do "
            "that where the converged motion does not: compare with a smaller "
            "numerics.dt, or run with numerics.tolerance (docs/numerics.md § 6)")


def dense_state(run):
    """What :func:`interpolated_snapshot` needs of the level a step starts from (the
    accepted-step path rebinds every array it changes, so references suffice)."""
    st = run.state
    return (st.t, st.Y, st.Ydot, st.q_time, st.r_time, st.v_global_time, st.phi,
            st.xdot_end[:, 5], st.work_in, st.power, st.seabed_work, st.seabed_power)


def interpolated_snapshot(run, fields: set, t: float, start) -> dict:
    """:func:`snapshot` at a time t (s) inside the last accepted step, which began at
    the :func:`dense_state` ``start``: the dense output of error-controlled steps.

    Y (v, ω, f, κ), the time-route positions, the end rotations φ (linking number)
    and the work put in by cubic Hermite interpolation between the step's levels with
    their rates (Ẏ of the scheme, the global node velocities, φ̇, the power:
    :func:`solver.stepping.hermite`); the anchor's orientation by slerp; the centreline
    and frames then by the space route from the interpolated κ, as at a step. The
    contact count and smallest gap, Newton's figures and Δt are the step's (the
    interpolated state is not itself checked for contact). Where no field needs the
    centreline (``run.POSE_FIELDS``) and the steps keep it (``system.needs_pose``)
    the space route is not integrated and ``position_route_difference`` is the
    step's too (measured: 5 % of an adaptive run of the seed problem that keeps only
    energies). Returns the snapshot dict.
    """
    t0, Y0, D0, q0, r0, v0, phi0, dphi0, w0, p0 = start[:10]
    h = run.state.t - t0
    s = (t - t0) / h
    st = run.state
    # the run with the interpolated state (its methods read the view's state)
    view = copy.copy(run)
    view.state = vs = copy.copy(st)
    vs.t = t
    vs.Y = hermite(s, h, Y0, D0, st.Y, st.Ydot)
    vs.r_time = hermite(s, h, r0, v0, st.r_time, st.v_global_time)
    vs.q_time = st.q_time.copy()
    vs.q_time[0] = quat_slerp(q0[0], st.q_time[0], s)
    vs.phi = hermite(s, h, phi0, dphi0, st.phi, st.xdot_end[:, 5])
    vs.work_in = float(hermite(s, h, w0, p0, st.work_in, st.power))
    vs.power = (1.0 - s) * p0 + s * st.power
    pose = None
    if run.system.seabed is not None:
        # the seabed on the interpolated time route (each node's own positions), with
        # its velocities linear across the step and the frames of the step's end
        vs.seabed_work = float(hermite(s, h, start[10], start[11], st.seabed_work,
                                       st.seabed_power))
        pose = (st.q_time if run.contact is None else vs.q, vs.r_time,
                (1.0 - s) * v0 + s * st.v_global_time)
    if fields & run.POSE_FIELDS or not run.system.needs_pose:
        view.update_space_route()
        if pose is not None and run.contact is not None:
            pose = (vs.q, vs.r, vs.v_global)
        return snapshot(view, fields, route_current=True, pose=pose)
    out = snapshot(view, fields, route_current=True, pose=pose)
    out["position_route_difference"] = float(
        max_distance(run.state.r_time, run.state.r))
    out["end_drift"] = run.end_drift()
    return out


# ------------------------------------------------------------------------------ recorder
class OutputRecorder:
    """The records, diagnostics and hooks of one :func:`solver.simulation.integrate` call.

    Parameters
    ----------
    case : solver.case.Case
    run : solver.run.RodRun
    hooks : dict
        ``progress``, ``should_stop``, ``checkpoint``, ``checkpoint_interval`` (s),
        ``observer`` as :func:`solver.simulation.integrate` takes them.
    resume : solver.checkpoint.Checkpoint or None
        The checkpoint the run continues from, as the caller gave it.
    state : solver.checkpoint.Checkpoint or None
        A copy of it whose records and diagnostics are continued.
    wall0 : float or None
        ``time.perf_counter()`` at the start of the call (default: now).
    """

    def __init__(self, case, run, hooks: dict, resume=None, state=None, wall0=None):
        self.case = case
        self.run = run
        self.hooks = hooks
        self.resume = resume
        self.fields = set(case.output.fields)
        self.wall0 = _time.perf_counter() if wall0 is None else wall0
        if state is None:
            self.times, self.records = [], []
            self.diag = {"step_time": [], "step_dt": [], "step_newton_iterations": [],
                         "step_residual_norm": [], "step_growth_rate": [],
                         "step_rejected_attempts": []}
            self.done, self.wall_before = 0, 0.0
        else:
            self.times, self.records, self.diag = state.times, state.records, state.diag
            self.done, self.wall_before = state.step, state.wall_time
        if run.energy_check is not None and "step_energy_error" not in self.diag:
            # the energy check's series (a checkpoint written without it: NaN before)
            self.diag["step_energy_error"] = [float("nan")] * len(self.diag["step_time"])
        self.last_checkpoint = _time.perf_counter()
        self.refused_before = sum(run.control.refusals.values())
        self.budget = case.numerics.wall_clock_budget
        self.rate = EtaModel()
        # how far the start pose lies from the case's centreline (None: no centreline); a
        # fresh run is at its start pose
        self.start_offset = start_offset(case, run.props.s, run.props.diameter,
                                         r=run.state.r if resume is None else None)

    def save(self) -> None:
        """Hand a checkpoint of the last accepted state to the checkpoint hook."""
        checkpoint = self.hooks["checkpoint"]
        if checkpoint is not None:
            checkpoint(Checkpoint(resume_key(self.case), self.done, self.run, self.times,
                                  self.records, self.diag,
                                  self.wall_before + _time.perf_counter() - self.wall0))
            self.last_checkpoint = _time.perf_counter()

    def record(self, t=None, start=None) -> None:
        """Keep the state now, or (error-controlled steps) at t inside the last step,
        which began at the dense state ``start``."""
        if t is None:
            self.times.append(self.run.state.t)
            self.records.append(snapshot(self.run, self.fields))
        else:
            self.times.append(t)
            self.records.append(self.run.interpolated_snapshot(self.fields, t, start))

    def finish(self, status, message="", reason=None):
        """The result dataset with ``hockle_status`` = status; a run that did not
        complete first leaves a checkpoint of its last accepted state."""
        run = self.run
        if status != "completed":
            self.save()                       # the last accepted state, to resume from
        stacked = {}
        if self.records:
            for key in self.records[0]:
                stacked[key] = np.asarray([rec[key] for rec in self.records])
        ds = build_dataset(self.case, run.props.s, np.asarray(self.times), stacked,
                           {k: np.asarray(v) for k, v in self.diag.items()}, status, message)
        if reason is not None:
            ds.attrs["hockle_stop_reason"] = reason
        warning = closure_warning(self.case, np.asarray(self.times),
                                  stacked.get("writhe_closure_passages"))
        if warning is not None:
            ds.attrs["hockle_warning"] = warning
        events = events_summary(ds)
        if events:
            ds.attrs["hockle_events"] = events         # in the order they happened
        implausible = plausibility_warnings(self.case)
        if implausible:
            ds.attrs["hockle_input_warnings"] = "; ".join(
                f"{w['loc']}: {w['msg']}" for w in implausible)
        ds.attrs["wall_time_s"] = self.wall_before + _time.perf_counter() - self.wall0
        ds.attrs["factorizations"] = run.newton.factorizations
        ds.attrs["gmres_iterations"] = run.newton.gmres_iterations
        ds.attrs["hockle_refused_attempts"] = ", ".join(
            f"{k} {v}" for k, v in sorted(run.control.refusals.items()))
        if self.resume is not None:
            ds.attrs["hockle_resumed_at"] = self.resume.t
        off = self.start_offset
        if off is not None:
            ds.attrs["hockle_start_offset"] = off.distance
            ds.attrs["hockle_start_offset_s"] = off.s
            advice = off.advice()
            if advice is not None:
                ds.attrs["hockle_advice"] = advice
        return ds

    def stopped(self):
        """The partial dataset when the caller or the wall-clock budget stops the run."""
        should_stop, run = self.hooks["should_stop"], self.run
        if should_stop is not None:
            flag = should_stop()
            if flag:
                reason = flag if isinstance(flag, str) else "stopped"
                return self.finish("stopped", f"stopped at t = {run.state.t:.6g} s: {reason}",
                                   reason)
        if self.budget is not None and _time.perf_counter() - self.wall0 > self.budget:
            return self.finish("stopped", f"wall-clock budget of {self.budget} s exceeded "
                               f"at t = {run.state.t:.6g} s", "timeout")
        return None

    def accepted(self, step, its, res):
        """Diagnostics, progress, checkpoint and observer after an accepted (nominal or
        error-controlled) step; the partial dataset when the observer stops the run."""
        run, diag = self.run, self.diag
        diag["step_time"].append(run.state.t)
        diag["step_dt"].append(run.control.last_dt)
        diag["step_newton_iterations"].append(its)
        diag["step_residual_norm"].append(res)
        diag["step_growth_rate"].append(run.control.guard.sigma)
        refused = sum(run.control.refusals.values())
        diag["step_rejected_attempts"].append(refused - self.refused_before)
        if "step_energy_error" in diag:
            diag["step_energy_error"].append(run.energy_error)
            run.energy_error = float("nan")
        self.refused_before = refused
        self.done = step
        progress = self.hooks["progress"]
        if progress is not None:
            wall = _time.perf_counter() - self.wall0
            t_end = self.case.numerics.t_end
            progress(Progress(t=run.state.t, t_end=t_end, step=step, dt=run.control.last_dt,
                              newton_iterations=its, residual_norm=res,
                              wall_time=wall, fraction=min(1.0, run.state.t / t_end),
                              contact_count=run.contact_count,
                              eta_seconds=self.rate.update(wall, run.state.t, t_end,
                                                            run.contact_count)))
        if _time.perf_counter() - self.last_checkpoint >= self.hooks["checkpoint_interval"]:
            self.save()
        return self.observed(step)

    def observed(self, step):
        """The partial dataset when the observer stops the run after ``step``."""
        observer, run = self.hooks["observer"], self.run
        if observer is None:
            return None
        flag = observer(run, step)
        if not flag:
            return None
        reason = flag if isinstance(flag, str) else "observer"
        if not self.times or self.times[-1] != run.state.t:
            self.record()                     # the state the observer stopped at
        return self.finish("stopped", f"stopped at t = {run.state.t:.6g} s: {reason}", reason)

    def failed(self, exc, step):
        """Put the steps done and the partial dataset on a SolverDivergence ``exc``; its
        message then ends with the inputs that look wrong and may be why
        (:func:`solver.plausibility.suspects`), where there are any: a bare "Newton did not
        converge" of a rod 1000 m long with its diameter profile over its first metre then
        names rod.length's unit."""
        exc.step = step
        hint = suspects(self.case)
        if hint and hint not in str(exc):
            exc.args = (f"{exc}; {hint}",) + tuple(exc.args[1:])
        exc.partial = self.finish("failed", str(exc), exc.reason)
        return exc

