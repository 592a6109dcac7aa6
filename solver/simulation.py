"""The time loop: ``integrate(case) -> xarray.Dataset`` (docs/interfaces.md, "Python API").

:func:`integrate` integrates a validated case in time with the solver's own hooks;
:func:`hockle.api.simulate`, the public ``simulate``, takes a case in any form, reads an
``initial.from_result`` file and adds callbacks and loads written in Python on top of it.

The loop builds the run (:class:`solver.run.RodRun`: the state, the step control, the
step's problem), steps it to each output time, records, and finishes (:mod:`solver.
recording`, :mod:`solver.results`). docs/developer.md draws one step through these parts.

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

import functools
import math
import pickle
import time as _time

from .checkpoint import CheckpointError, resume_key
from .recording import EtaModel, Progress, RateEstimate, OutputRecorder
from .initial import start_step
from .run import RodRun
from .stepping.control import SolverDivergence

__all__ = ["integrate", "make_run", "SolverDivergence", "Progress", "RodRun",
           "RateEstimate", "EtaModel"]


def integrate(case, progress=None, should_stop=None, checkpoint=None,
              checkpoint_interval=300.0, resume=None, observer=None, extra_force=None,
              start=None):
    """Integrate a case in time and return its result dataset (docs/interfaces.md, "Result dataset").

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


def make_run(case, extra_force=None, start=None):
    """The run of ``case``'s ``numerics.formulation``: :class:`solver.run.RodRun` (goyal)
    or :class:`solver.centreline_run.CentrelineRun` (centreline). Raises
    :class:`solver.centreline.CentrelineError` (a ValueError) naming a field the
    centreline scheme does not take."""
    if case.numerics.formulation == "centreline":
        from .centreline_run import CentrelineRun

        return CentrelineRun(case, extra_force, start)
    return RodRun(case, extra_force, start)


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
    """:func:`integrate` under the BLAS thread limit: build (or resume) the run, then step
    it with fixed or error-controlled steps."""
    wall0 = _time.perf_counter()
    hooks = dict(progress=progress, should_stop=should_stop, checkpoint=checkpoint,
                 checkpoint_interval=checkpoint_interval, observer=observer)
    if resume is None:
        run = make_run(case, extra_force, start)
        rec = OutputRecorder(case, run, hooks, wall0=wall0)
        rec.done = start_step(case, start) - 1      # 0, or the steps before the start
        rec.record()
        out = rec.observed(0)
        if out is not None:
            return out
    else:
        if resume.case_hash != resume_key(case):
            raise CheckpointError("the checkpoint belongs to another case (resume key "
                                  f"{resume.case_hash} != {resume_key(case)})")
        # a copy: the checkpoint stays valid for another resume
        state = pickle.loads(pickle.dumps(resume))
        run = state.run
        if extra_force is not None:
            run.loads.extra = extra_force
        rec = OutputRecorder(case, run, hooks, resume=resume, state=state, wall0=wall0)
    if case.numerics.tolerance is not None:
        return _simulate_adaptive(case, run, rec, rec.done)
    return _simulate_fixed(case, run, rec, rec.done + 1)


def _simulate_fixed(case, run, rec, first_step):
    """The time loop of fixed steps: one nominal step of ``numerics.dt`` per pass (cut
    and substepped inside by the step control), the state kept every ``output.every``-th
    step and at the last."""
    num = case.numerics
    every = case.output.every
    n_steps = max(1, int(math.ceil(num.t_end / num.dt - 1e-9)))
    for step in range(first_step, n_steps + 1):
        out = rec.stopped()
        if out is not None:
            return out
        t_target = min(step * num.dt, num.t_end)
        try:
            its, res = run.advance(t_target)
        except SolverDivergence as exc:
            raise rec.failed(exc, step - 1)
        if step % every == 0 or step == n_steps:
            rec.record()
        out = rec.accepted(step, its, res)
        if out is not None:
            return out
    return rec.finish("completed", f"completed {n_steps} steps to t = {run.state.t:.6g} s")


def _simulate_adaptive(case, run, rec, step=0):
    """The time loop of error-controlled steps (``numerics.tolerance``): one accepted
    step per pass, the state kept at every ``output.interval`` s or, without an interval,
    every ``output.every``-th step; the diagnostics hold every accepted step. With an
    interval the outputs inside a step are its dense output
    (:meth:`RodRun.interpolated_snapshot`; ``output.interpolate``, the default) or the
    steps land on them (``interpolate: false``). ``rec``: the run's
    :class:`solver.recording.OutputRecorder`; ``step``: the accepted steps so far (a resumed
    run)."""
    t_end = case.numerics.t_end
    interval = case.output.interval
    dense = interval is not None and case.output.interpolate
    every = case.output.every
    next_out = t_end
    if interval is not None:
        next_out = min((math.floor(run.state.t / interval + 1e-9) + 1) * interval, t_end)
    while run.state.t < t_end * (1.0 - 1e-12):
        out = rec.stopped()
        if out is not None:
            return out
        start = run.dense_state() if dense else None
        try:
            its, res = run.step_adaptive(t_end if dense else next_out)
        except SolverDivergence as exc:
            raise rec.failed(exc, step)
        step += 1
        done = run.state.t >= t_end * (1.0 - 1e-12)
        if interval is not None:
            # every output time the step reached: inside it interpolated, at its end the
            # state itself
            while next_out <= run.state.t * (1.0 + 1e-12) or done:
                if next_out < run.state.t * (1.0 - 1e-12) and start is not None:
                    rec.record(next_out, start)
                else:
                    rec.record()
                if next_out >= t_end * (1.0 - 1e-12):
                    break
                k = math.floor(next_out / interval + 1e-9) + 1
                next_out = min(k * interval, t_end)
        elif step % every == 0 or done:
            rec.record()
        out = rec.accepted(step, its, res)
        if out is not None:
            return out
    return rec.finish("completed", f"completed {step} error-controlled steps to "
                      f"t = {run.state.t:.6g} s")
