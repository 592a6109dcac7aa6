"""The task that runs one job, and the worker's heartbeat and reaper.

``hockle.run_job(job_id)`` is thin: it claims the job in the registry, runs the case with
:func:`solver.simulation`, writes progress at most every ``HOCKLE_PROGRESS_INTERVAL`` seconds, writes
the dataset (partial ones too) to the result store under a temporary name and renames it, and
brings the job to its terminal state. Deterministic failures (a case that does not validate, a
diverged solve) are final: the task never retries.

Faults: the message is acknowledged only after the task returns (``acks_late``); a registry that
is locked or unreachable at the claim (or at the finish) is retried with backoff for
``HOCKLE_REGISTRY_RETRY_TIMEOUT`` s, then the message goes back to the broker. While it solves,
a thread of the solving process writes the job's heartbeat every ``HOCKLE_HEARTBEAT_INTERVAL``
s; when the registry says the attempt no longer holds the job (given up as lost and queued
again), the solve stops and writes nothing. Each attempt writes its own result file, so an old
attempt can never replace the result of the attempt that finished the job. The solver's
checkpoint goes to the result store (``<id>.ckpt``) by :class:`CheckpointPolicy`: every
``HOCKLE_CHECKPOINT_INTERVAL`` s of wall time, every ``HOCKLE_CHECKPOINT_PROGRESS`` of the
simulated run, after the first accepted step in contact, and when the worker stops the solve;
the next attempt continues from it bit for bit instead of from t = 0, and the job's terminal
state removes it.

Shutdown: when the worker shuts down warm (SIGTERM to its main process: ``docker stop``,
Kubernetes, ``hockle serve`` stopping its worker; or SIGTERM to the whole process group), the
running job's ``should_stop`` answers ``worker_shutdown``; the solver stops at its next step and
hands out a final checkpoint, which is stored; the job goes back to ``accepted`` at once
(``Registry.requeue_at_shutdown``, event ``requeued_at_shutdown``) and its message is sent
again, so another worker continues it from that checkpoint (attempt + 1). The stopped attempt's
dataset is not the job's result and is not written.
"""
from __future__ import annotations

import json
import logging
import math
import os
import signal
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

from celery import current_app, shared_task
from celery.exceptions import Reject, SoftTimeLimitExceeded
from celery.signals import worker_process_init, worker_ready, worker_shutdown, \
    worker_shutting_down

from service.queue import TASK_NAME, Enqueuer, RegistryWatch, send_job, sweep
from service.registry import DISMISSED, FAILED, REGISTRY_UNAVAILABLE, SUCCESSFUL, Registry
from service.settings import Settings, get_settings
from service.problems import ProblemError
from service.store import ResultStore
from service.validation import start_from_job

log = logging.getLogger("hockle.worker")

_DIVERGENCE_REASONS = ("solver_diverged", "nonfinite_state")

#: ``should_stop``'s answer while the worker shuts down: the job is handed back, not finished
SHUTDOWN_REASON = "worker_shutdown"
#: how long a hand-back at shutdown retries an unavailable registry (the grace period is
#: short; if it never succeeds the job's heartbeat goes stale and a sweeper re-queues it)
HAND_BACK_RETRY_TIMEOUT = 20.0


def _log_registry_error(what: str, exc: BaseException) -> None:
    """One line for an outage of the registry (retried anyway), a traceback for anything else."""
    if isinstance(exc, REGISTRY_UNAVAILABLE):
        log.warning("%s failed, registry unavailable: %s", what, str(exc).splitlines()[0][:200])
    else:
        log.warning("%s failed", what, exc_info=exc)


class RegistryUnavailable(RuntimeError):
    """The registry stayed unavailable for HOCKLE_REGISTRY_RETRY_TIMEOUT seconds."""


def with_registry_retry(what: str, fn, settings: Settings, *, job_id: str,
                        sleep=time.sleep, timeout: float | None = None):
    """Call ``fn()``; while the registry is locked or unreachable, call it again with
    exponential backoff (0.5 s doubling to 30 s) for up to ``timeout`` seconds (default
    ``settings.registry_retry_timeout``), then raise :class:`RegistryUnavailable`. Other errors
    propagate at once."""
    timeout = settings.registry_retry_timeout if timeout is None else timeout
    deadline = time.monotonic() + timeout
    delay = 0.5
    tries = 0
    while True:
        tries += 1
        try:
            return fn()
        except REGISTRY_UNAVAILABLE as exc:
            left = deadline - time.monotonic()
            if left <= 0:
                raise RegistryUnavailable(
                    f"job {job_id}: the registry was unavailable for {what} for "
                    f"{timeout:.0f} s ({tries} tries): "
                    f"{type(exc).__name__}: {str(exc).splitlines()[0][:200]}") from exc
            wait = min(delay, left)
            log.warning("job %s: registry unavailable for %s (%s); try %d again in %.1f s",
                        job_id, what, str(exc).splitlines()[0][:200], tries + 1, wait)
            sleep(wait)
            delay = min(2.0 * delay, 30.0)


class _ProcessState:
    """Registry and store of this process, made after fork (never shared with the parent)."""

    def __init__(self) -> None:
        self.pid: int | None = None
        self.key: tuple | None = None
        self.registry: Registry | None = None
        self.store: ResultStore | None = None

    def get(self, settings: Settings) -> tuple[Registry, ResultStore]:
        key = (settings.registry_url, settings.registry_busy_timeout, str(settings.results_dir))
        if self.pid != os.getpid() or self.registry is None or self.key != key:
            if self.registry is not None and self.pid == os.getpid():
                self.registry.dispose()
            self.registry = Registry(settings.registry_url,
                                     busy_timeout=settings.registry_busy_timeout)
            self.store = ResultStore(settings.results_dir)
            self.pid = os.getpid()
            self.key = key
        return self.registry, self.store  # type: ignore[return-value]


_process = _ProcessState()


#: how often (wall seconds) the solver hands the worker a checkpoint to consider: the
#: granularity of CheckpointPolicy (building one costs a hash of the case, no copy)
CHECKPOINT_OFFER_INTERVAL = 1.0


@dataclass
class CheckpointPolicy:
    """When a running job's checkpoint is stored: the first of ``interval`` wall seconds and
    ``progress`` (a fraction of ``t_end``) of simulated time since the last one stored, and the
    first accepted step in contact (where a run's pace drops most; docs/contact.md). With the
    defaults (30 s, 10 %) a worker killed at any moment loses at most about 30 s of solving
    (plus one time step and the checkpoint offer interval), and a short job is saved several
    times before its first 30 s are up. The solver offers a checkpoint every
    :data:`CHECKPOINT_OFFER_INTERVAL` s; this policy picks the ones worth writing."""

    interval: float
    progress: float
    t_end: float
    last_wall: float = field(default_factory=time.monotonic)
    last_t: float = 0.0
    in_contact: bool = False

    def due(self, t: float, contact_count: int, now: float | None = None) -> str | None:
        """Why a checkpoint at simulated time ``t`` (s) should be stored now, or None."""
        now = time.monotonic() if now is None else now
        if now - self.last_wall >= self.interval:
            return "wall_time"
        # (relative slack: ten steps of 0.01 s make 0.1 s only to rounding)
        if self.progress > 0 and t - self.last_t >= self.progress * self.t_end * (1 - 1e-9):
            return "progress"
        if contact_count and not self.in_contact:
            return "first_contact"
        return None

    def stored(self, t: float, contact_count: int, now: float | None = None) -> None:
        self.last_wall = time.monotonic() if now is None else now
        self.last_t = t
        self.in_contact = self.in_contact or bool(contact_count)


@dataclass
class JobRun:
    """One attempt at one job inside a worker process."""

    job_id: str
    attempt: int
    worker: str
    registry: Registry
    store: ResultStore
    settings: Settings
    budget: float
    t_end: float
    soft_limit: float = 0.0
    time_limit: float = 0.0
    started: float = field(default_factory=time.monotonic)
    last_write: float = -math.inf
    last_check: float = -math.inf
    last_info: object | None = None
    superseded: bool = False
    stopping: bool = False
    checkpoints: CheckpointPolicy | None = None
    _beat_stop: threading.Event = field(default_factory=threading.Event)
    _beat_thread: threading.Thread | None = None

    # --- the job's heartbeat -------------------------------------------------------------------
    def start_heartbeat(self) -> None:
        """Write the job's heartbeat from a thread of this (the solving) process, so that it
        stops when this process dies, whatever one time step costs."""
        self._beat_thread = threading.Thread(target=self._beat, name=f"hockle-job-{self.job_id}",
                                             daemon=True)
        self._beat_thread.start()

    def stop_heartbeat(self) -> None:
        self._beat_stop.set()
        if self._beat_thread is not None:
            self._beat_thread.join(timeout=5)

    def _beat(self) -> None:
        interval = self.settings.heartbeat_interval
        wait = interval
        while not self._beat_stop.wait(wait):
            try:
                alive = self.registry.job_heartbeat(self.job_id, self.attempt)
            except Exception as exc:  # noqa: BLE001 - registry briefly down: next beat
                _log_registry_error(f"job {self.job_id}: heartbeat", exc)
                # soon again: the beat should land as soon as the registry takes writes
                wait = min(interval, max(1.0, interval / 5))
                continue
            wait = interval
            if not alive and not self._beat_stop.is_set():
                # finished by this attempt is excluded (stop_heartbeat comes first); so the
                # job was reaped, or given up as lost and queued again: stop solving
                log.warning("job %s attempt %s no longer holds the job: stopping", self.job_id,
                            self.attempt)
                self.superseded = True
                return

    # --- callbacks handed to the solver --------------------------------------------------------
    def progress(self, info) -> None:
        self.last_info = info
        now = time.monotonic()
        if now - self.last_write < self.settings.progress_interval:
            return
        self.last_write = now
        self._write_progress(info)

    def _write_progress(self, info) -> None:
        fraction = float(min(max(info.fraction, 0.0), 1.0))
        wall = float(info.wall_time)
        eta = getattr(info, "eta_seconds", None)   # the solver's estimate (EtaModel), as the CLI shows
        try:
            self.registry.record_progress(
                self.job_id,
                self.attempt,
                progress=100.0 * fraction,
                sim_time=float(info.t),
                step=int(info.step),
                wall_time=wall,
                eta_seconds=eta,
            )
        except Exception:  # noqa: BLE001 - a lost progress write must not kill the solve
            log.warning("progress write for %s failed", self.job_id, exc_info=True)

    def should_stop(self):
        """The solver asks before every step: a reason to stop (the last checkpoint of the
        stopped solve is then stored whatever the policy says), or False."""
        reason = self._stop_reason()
        if reason:
            self.stopping = True
        return reason

    def _stop_reason(self):
        if self.superseded:
            return "superseded"
        now = time.monotonic()
        if now - self.started > self.budget:
            return "timeout"
        if now - self.last_check >= self.settings.cancel_check_interval:
            self.last_check = now
            try:
                if self.registry.cancel_requested(self.job_id):
                    return "cancelled_by_user"
            except Exception:  # noqa: BLE001 - registry briefly unreachable: keep solving
                log.warning("cancel check for %s failed", self.job_id, exc_info=True)
        if _shutdown.reason is not None:
            return _shutdown.reason     # the worker shuts down: stop here, hand the job back
        return False

    # --- outcome -------------------------------------------------------------------------------
    def _position(self) -> dict:
        info = self.last_info
        if info is None:
            return {"wall_time": time.monotonic() - self.started}
        return {
            "progress": 100.0 * float(min(max(info.fraction, 0.0), 1.0)),
            "sim_time": float(info.t),
            "step": int(info.step),
            "wall_time": time.monotonic() - self.started,
        }

    def event(self, kind: str, detail=None) -> None:
        """Append an event of this attempt; a registry outage loses the event, not the job."""
        try:
            self.registry.add_event(self.job_id, kind, attempt=self.attempt, worker=self.worker,
                                    detail=detail)
        except Exception as exc:  # noqa: BLE001
            _log_registry_error(f"job {self.job_id}: event {kind}", exc)

    def how_far(self) -> str:
        """Where the run got: 't = 19.3 s of 45 s (step 193)', for a continuation 'point 12
        (P = 0.25)', or that no step finished."""
        info = self.last_info
        if info is None:
            return f"before the first time step ({time.monotonic() - self.started:.0f} s)"
        if isinstance(info, _PointInfo):
            return info.where()
        return f"t = {float(info.t):.6g} s of {self.t_end:.6g} s (step {int(info.step)})"

    # --- checkpoints (solver.checkpoint) in the result store ----------------------------------
    def load_checkpoint(self, case):
        """The job's last checkpoint for ``case`` (a re-run after a lost worker or a
        redeploy continues from it), or None: none, off, or unusable (logged, then t = 0)."""
        from solver.checkpoint import Checkpoint

        ck = self._read_checkpoint(lambda data: Checkpoint.loads(data, case), "t = 0")
        if ck is not None:
            self.event("resumed", {"t": ck.t, "step": ck.step})
            log.info("job %s attempt %s resumes at t = %g s (step %d)", self.job_id,
                     self.attempt, ck.t, ck.step)
        return ck

    def load_branch_checkpoint(self, key: str):
        """The continuation job's last :class:`solver.checkpoint.BranchCheckpoint` bound to
        ``key`` (:func:`service.branches.branch_key`), or None (then from the first point)."""
        from solver.checkpoint import BranchCheckpoint

        ck = self._read_checkpoint(lambda data: BranchCheckpoint.loads(data, key),
                                   "from the first point")
        if ck is not None:
            self.event("resumed", {"point": ck.points, "parameter": ck.parameter})
            log.info("job %s attempt %s resumes after point %d (parameter %g)", self.job_id,
                     self.attempt, ck.points, ck.parameter)
        return ck

    def _read_checkpoint(self, loads, otherwise: str):
        if not self.settings.checkpoint_interval:
            return None
        from solver.checkpoint import CheckpointError

        try:
            data = self.store.read_checkpoint(self.job_id)
            return None if data is None else loads(data)
        except (OSError, CheckpointError) as exc:
            log.warning("job %s: checkpoint not used (%s): %s", self.job_id, exc, otherwise)
            self.event("checkpoint_ignored", {"error": str(exc)})
            return None

    def write_checkpoint(self, ck) -> None:
        """Store a checkpoint handed out by the solver when :attr:`checkpoints` says it is due,
        and always the last one of a solve the worker stopped (a shutdown hands the job back
        from it). An attempt that was given up writes none; a store that cannot be written
        costs the checkpoint, never the solve."""
        if self.superseded:
            return
        contact = int(getattr(self.last_info, "contact_count", 0) or 0)
        policy = self.checkpoints
        if policy is not None and not self.stopping and policy.due(ck.t, contact) is None:
            return
        try:
            self.store.write_checkpoint(self.job_id, ck.dumps())
        except OSError:
            log.warning("job %s: checkpoint not written", self.job_id, exc_info=True)
            return
        if policy is not None:
            policy.stored(ck.t, contact)

    def drop_checkpoint(self) -> None:
        """Remove the job's checkpoint (its terminal state is recorded)."""
        try:
            self.store.discard_checkpoint(self.job_id)
        except OSError:
            log.warning("job %s: checkpoint not removed", self.job_id, exc_info=True)

    def save(self, ds) -> str | None:
        if ds is None:
            return None
        from solver.results import apply_metadata

        # ACDD: the job id is the dataset's id; creator, licence ... from the settings
        apply_metadata(ds, self.settings.dataset_metadata(), dataset_id=self.job_id)
        ds.attrs["hockle_job_id"] = self.job_id
        ds.attrs["hockle_attempt"] = int(self.attempt)
        ds.attrs["hockle_worker"] = self.worker
        return str(self.store.write_dataset(self.job_id, ds, attempt=self.attempt))

    def finish(self, **kwargs) -> bool:
        """Terminal state for this attempt (retried while the registry is unavailable); a
        refused finish (the attempt was given up) removes the file this attempt wrote; a recorded
        one removes the job's checkpoint."""
        done = with_registry_retry(
            "the finish", lambda: self.registry.finish(self.job_id, self.attempt,
                                                     worker=self.worker, **kwargs),
            self.settings, job_id=self.job_id)
        if not done:
            log.warning("job %s attempt %s: finish refused (taken over or reaped)", self.job_id,
                        self.attempt)
            path = kwargs.get("result_path")
            if path:
                self.store.discard(path)
        else:
            self.drop_checkpoint()            # the job is over: nothing to resume
        return done


def run_job(job_id: str, worker: str, settings: Settings | None = None) -> str:
    """Run one job to a terminal state; returns what happened (for logs and tests)."""
    settings = settings or get_settings()
    registry, store = _process.get(settings)
    # nothing is acknowledged before the claim is recorded: a locked or unreachable registry
    # is retried here, then RegistryUnavailable hands the message back to the broker
    attempt = with_registry_retry("the claim", lambda: registry.claim(job_id, worker), settings,
                                  job_id=job_id)
    if attempt is None:
        job = registry.get(job_id)
        state = job.state if job else "unknown"
        log.info("job %s not run: %s", job_id, state)
        if job is not None:
            registry.add_event(job_id, "skipped", worker=worker,
                               detail={"state": state, "attempts": job.attempts})
        return f"skipped:{state}"
    job = with_registry_retry("reading the job", lambda: registry.get(job_id), settings,
                              job_id=job_id)
    assert job is not None
    try:
        registry.heartbeat(worker, job_id)
    except Exception:  # noqa: BLE001 - the worker's row is for /v1/health only
        log.warning("worker heartbeat for %s failed", job_id, exc_info=True)
    run = JobRun(
        job_id=job_id,
        attempt=attempt,
        worker=worker,
        registry=registry,
        store=store,
        settings=settings,
        budget=job.wall_clock_budget,
        t_end=job.t_end,
        soft_limit=job.soft_time_limit,
        time_limit=float(job.time_limit or 0.0),
    )
    run.start_heartbeat()
    try:
        return _prepare_and_solve(run, job)
    finally:
        run.stop_heartbeat()
        try:
            registry.heartbeat(worker, None, clear=True)
        except Exception:  # noqa: BLE001
            log.warning("heartbeat after %s failed", job_id, exc_info=True)


def _prepare_and_solve(run: JobRun, job) -> str:
    job_id = run.job_id
    if (job.kind or "dynamic") == "continuation":
        return _prepare_and_continue(run, job)
    try:
        from solver.case import Case

        case = Case.model_validate(json.loads(job.spec_json))
        case = _with_budget(case, job.wall_clock_budget)
    except Exception as exc:  # noqa: BLE001 - a stored case that no longer validates is final
        log.exception("job %s: stored case does not validate", job_id)
        run.finish(state=FAILED, reason="internal_error",
                   message=f"the stored case does not validate with this solver: {exc}")
        return "failed:internal_error"
    try:
        # a start from an earlier job (initial.from_result.job), checked at submission;
        # its result may have gone since
        start = start_from_job(case, run.registry, job.owner)
    except ProblemError as exc:
        run.finish(state=FAILED, reason="internal_error",
                   message=f"the start state could not be read: {exc.detail}")
        return "failed:internal_error"
    return _solve(run, case, start)


def _prepare_and_continue(run: JobRun, job) -> str:
    """A continuation job (service/continuations.py): its stored request, then the branch."""
    from service.continuations import read_request

    try:
        case, options = read_request(job.spec_json)
    except Exception as exc:  # noqa: BLE001 - a stored request that no longer validates is final
        log.exception("job %s: stored continuation does not validate", run.job_id)
        run.finish(state=FAILED, reason="internal_error",
                   message=f"the stored continuation does not validate with this solver: {exc}")
        return "failed:internal_error"
    return _continue(run, case, options)


@dataclass
class _PointInfo:
    """A continuation's progress in the shape JobRun.progress reads: ``step`` the points
    done, ``fraction`` the larger of points over max_points and the parameter's way from its
    start to its target, ``t`` 0 (no simulated time); ``name`` the parameter's path."""

    fraction: float
    step: int
    wall_time: float
    parameter: float
    name: str = "parameter"
    t: float = 0.0
    eta_seconds: float | None = None
    contact_count: int = 0

    def where(self) -> str:
        """'point 12 (boundary.end.translation.2.force = -0.25)'."""
        return f"point {self.step} ({self.name} = {self.parameter:.6g})"


def _continue(run: JobRun, case, options) -> str:
    """Follow the branch with :func:`service.branches.continue_branch`; progress after every point
    (``step`` = points done), the job's should_stop before every step (dismissal, the
    wall-clock budget, a shutdown: the branch so far is kept as a partial result), the
    branch dataset as the result. The branch is checkpointed in the result store as a
    dynamic run is (:class:`CheckpointPolicy`, progress counted in points of
    ``max_points``); a shutdown hands the job back and the next attempt continues from the
    last checkpoint. An exception after the first point fails the job with the branch so
    far as its (partial) result."""
    from service.branches import branch_key, continue_branch
    from solver.statics import StaticsError

    start: list[float] = []
    interval = run.settings.checkpoint_interval
    resume = None
    if interval:
        try:
            key = branch_key(case, options.parameter, options.to, time=options.time,
                             switch=options.switch, step=options.step,
                             stability=options.stability)
            resume = run.load_branch_checkpoint(key)
        except Exception:  # noqa: BLE001 - a case continue_branch refuses: reported below
            log.warning("job %s: no branch key", run.job_id, exc_info=True)
    run.checkpoints = CheckpointPolicy(interval, run.settings.checkpoint_progress,
                                       float(options.max_points),
                                       last_t=resume.t if resume is not None else 0.0)

    def info(index: int, lam: float) -> _PointInfo:
        span = abs(options.to - start[0]) or 1.0
        way = min(abs(lam - start[0]) / span, 1.0)
        return _PointInfo(fraction=max((index + 1) / options.max_points, way),
                          step=index + 1, wall_time=time.monotonic() - run.started,
                          parameter=float(lam), name=options.parameter)

    if resume is not None:
        start.append(float(resume.state["parameter"][0]))
        run.last_info = info(resume.points - 1, resume.parameter)

    def on_point(index: int, lam: float) -> None:
        if not start:
            start.append(lam)
        run.progress(info(index, lam))

    def where() -> str:
        info = run.last_info
        if info is None:
            return "before the first point"
        plural = "" if info.step == 1 else "s"
        return f"after {info.step} point{plural} ({options.parameter} = {info.parameter:.6g})"

    def failed(reason: str, message: str, exc) -> str:
        """Fail the job; the branch computed before ``exc`` (if any) is its result."""
        path = _save_quietly(run, getattr(exc, "partial", None))
        if path is not None:
            message += f"; the branch so far is kept ({where()})"
        elif reason == "timeout":
            message += "; no result was written"
        run.finish(state=FAILED, reason=reason, message=message, result_path=path,
                   result_partial=path is not None, **run._position())
        return f"failed:{reason}"

    try:
        ds = continue_branch(case, options.parameter, options.to, time=options.time,
                             switch=options.switch, max_points=options.max_points,
                             step=options.step, shapes_every=options.shapes_every,
                             stability=options.stability, on_point=on_point,
                             should_stop=run.should_stop,
                             checkpoint=run.write_checkpoint if interval else None,
                             resume=resume)
    except (StaticsError, ValueError) as exc:   # no equilibrium or a singular start
        if run.superseded:
            return _superseded(run)
        return failed("solver_diverged", str(exc), exc)
    except SoftTimeLimitExceeded as exc:
        return failed("timeout", f"soft time limit of {run.soft_limit:.0f} s reached {where()}",
                      exc)
    except Exception as exc:  # noqa: BLE001 - unexpected: recorded, logged, never retried
        log.exception("job %s: the continuation raised", run.job_id)
        if run.superseded:
            return _superseded(run)
        return failed("internal_error", f"the continuation raised {type(exc).__name__}: "
                      f"{exc}", exc)
    if run.superseded:
        return _superseded(run)
    stopped = str(ds.attrs.get("stopped", ""))
    stop = stopped[len("stopped: "):] if stopped.startswith("stopped: ") else None
    if stop == SHUTDOWN_REASON:
        return _hand_back(run)
    run.event("solve_finished", {"status": "stopped" if stop else "completed",
                                 "points": int(ds.sizes["point"]), "stopped": stopped})
    path = _save_result(run, ds, "branch")
    if path is None:
        return "failed:internal_error"
    points = f"{int(ds.sizes['point'])} points"
    if stop == "cancelled_by_user":
        run.finish(state=DISMISSED, reason="cancelled_by_user",
                   message=f"dismissed while running, {where()}; the branch so far is kept",
                   result_path=path, result_partial=True, **run._position())
        return "dismissed"
    if stop is not None:
        message = (f"wall-clock budget of {run.budget:.0f} s reached {where()}; the branch so "
                   "far is kept (a job may ask for a longer limit: POST "
                   "/v1/continuations?time_limit=)" if stop == "timeout"
                   else f"the continuation stopped: {stop}")
        run.finish(state=FAILED, reason="timeout" if stop == "timeout" else "internal_error",
                   message=message, result_path=path, result_partial=True, **run._position())
        return f"failed:{stop}"
    position = run._position()
    position["progress"] = 100.0
    run.finish(state=SUCCESSFUL, message=f"{points}; {stopped}", result_path=path, **position)
    return "successful"


def _with_budget(case, budget: float):
    """Hand the wall-clock budget to the solver, which checks it itself (reason ``timeout``)."""
    numerics = case.numerics
    current = getattr(numerics, "wall_clock_budget", None)
    if current is not None and current <= budget:
        return case
    if "wall_clock_budget" not in type(numerics).model_fields:
        return case
    return case.model_copy(update={"numerics": numerics.model_copy(update={"wall_clock_budget": budget})})


def _solve(run: JobRun, case, start=None) -> str:
    # the submodule, not the package: `solver.simulation` is also the name of the module
    from solver.simulation import SolverDivergence, integrate

    interval = run.settings.checkpoint_interval
    try:
        resume = run.load_checkpoint(case)
        run.checkpoints = CheckpointPolicy(interval, run.settings.checkpoint_progress,
                                           float(case.numerics.t_end),
                                           last_t=resume.t if resume is not None else 0.0)
        ds = integrate(case, progress=run.progress, should_stop=run.should_stop,
                      checkpoint=run.write_checkpoint if interval else None,
                      checkpoint_interval=(min(interval, CHECKPOINT_OFFER_INTERVAL) if interval
                                           else math.inf), resume=resume,
                      start=start if resume is None else None)
        if run.superseded:
            return _superseded(run)
        if (ds.attrs.get("hockle_status") == "stopped"
                and ds.attrs.get("hockle_stop_reason") == SHUTDOWN_REASON):
            return _hand_back(run)
    except SolverDivergence as exc:
        if run.superseded:
            return _superseded(run)
        run.event("solve_finished", {"status": "failed"})
        path = _save_quietly(run, getattr(exc, "partial", None))
        reason = getattr(exc, "reason", None)
        run.finish(
            state=FAILED,
            reason=reason if reason in _DIVERGENCE_REASONS else "solver_diverged",
            message=str(exc),
            failed_time=_float_or_none(getattr(exc, "t", None)),
            failed_step=_int_or_none(getattr(exc, "step", None)),
            result_path=path,
            result_partial=path is not None,
            **run._position(),
        )
        return f"failed:{reason}"
    except SoftTimeLimitExceeded:
        run.finish(state=FAILED, reason="timeout",
                   message=f"soft time limit of {run.soft_limit:.0f} s reached at "
                           f"{run.how_far()}; no result was written",
                   **run._position())
        return "failed:timeout"
    except Exception as exc:  # noqa: BLE001 - unexpected: recorded, logged, never retried
        log.exception("job %s: solver raised", run.job_id)
        run.finish(state=FAILED, reason="internal_error",
                   message=f"the solver raised {type(exc).__name__}: {exc}", **run._position())
        return "failed:internal_error"

    status = ds.attrs.get("hockle_status", "completed")
    run.event("solve_finished", {"status": status})
    path = _save_result(run, ds, "dataset")
    if path is None:
        return "failed:internal_error"
    if status == "stopped":
        stop = str(ds.attrs.get("hockle_stop_reason", "stopped"))
        if stop == "cancelled_by_user":
            run.finish(state=DISMISSED, reason="cancelled_by_user",
                       message="dismissed while running; the partial result is kept",
                       result_path=path, result_partial=True, **run._position())
            return "dismissed"
        message = (f"wall-clock budget of {run.budget:.0f} s reached at {run.how_far()}; the "
                   "partial result is kept (a job may ask for a longer limit, up to "
                   f"{run.settings.time_limit_max:.0f} s here: POST /v1/jobs?time_limit=)"
                   if stop == "timeout" else f"the solver stopped: {stop}")
        run.finish(state=FAILED, reason="timeout" if stop == "timeout" else "internal_error",
                   message=message, result_path=path, result_partial=True, **run._position())
        return f"failed:{stop}"
    if status != "completed":
        run.finish(state=FAILED, reason="internal_error",
                   message=f"the solver returned a dataset with status {status!r}",
                   result_path=path, result_partial=True, **run._position())
        return "failed:internal_error"
    position = run._position()
    position["progress"] = 100.0
    # a completed run's warning (hockle_warning: its writhe crossed an end's closure with
    # fixed steps, docs/numerics.md § 6) is the job's message
    run.finish(state=SUCCESSFUL, result_path=path, message=ds.attrs.get("hockle_warning"),
               **position)
    return "successful"


def _hand_back(run: JobRun) -> str:
    """The solve stopped because the worker shuts down; the solver handed out its final
    checkpoint, stored by now. Put the job back in the queue at once (attempt + 1 continues from
    that checkpoint) and send its message again; the stopped attempt's dataset is dropped."""
    if run.time_limit and time.monotonic() - run.started >= run.time_limit - 1.0:
        # billiard's SIGTERM at the hard time limit (SIGKILL follows): the reaper fails the job
        log.warning("job %s attempt %s: stopped at its hard time limit; not handed back",
                    run.job_id, run.attempt)
        return "killed_at_hard_limit"
    info = run.last_info
    sim_time = None if info is None else float(info.t)
    step = None if info is None else int(info.step)
    at = info.where() if isinstance(info, _PointInfo) else None
    try:
        action = with_registry_retry(
            "the hand-back at shutdown",
            lambda: run.registry.requeue_at_shutdown(run.job_id, run.attempt, worker=run.worker,
                                                     reason=SHUTDOWN_REASON, sim_time=sim_time,
                                                     step=step, at=at),
            run.settings, job_id=run.job_id, timeout=HAND_BACK_RETRY_TIMEOUT)
    except RegistryUnavailable as exc:
        log.error("%s; its heartbeat stops now and a sweeper queues it again", exc)
        return "shutdown:registry_unavailable"
    if action is None:
        log.warning("job %s attempt %s: stopped at shutdown but no longer holds the job",
                    run.job_id, run.attempt)
        return "superseded"
    log.warning("job %s attempt %s: worker shutting down at %s: %s", run.job_id, run.attempt,
                run.how_far(), "queued again" if action == "requeued" else action)
    if action == "requeued":
        job = run.registry.get(run.job_id)
        if job is not None:
            enqueuer = Enqueuer(run.settings, current_app._get_current_object())
            try:
                send_job(run.registry, enqueuer, job, log)
            finally:
                enqueuer.close()
    return f"requeued_at_shutdown:{action}"


def _superseded(run: JobRun) -> str:
    """This attempt was given up (its heartbeat went stale) and the job queued again: the
    attempt that holds the job now reports it; this one writes nothing."""
    log.warning("job %s attempt %s: superseded, nothing written", run.job_id, run.attempt)
    run.event("attempt_abandoned", {"at": run._position()})
    return "superseded"


def _save_result(run: JobRun, ds, what: str) -> str | None:
    """Write the last progress and the result ``ds`` of ``run``; returns its path, or None
    after recording the job failed (``internal_error``) when writing raised. ``what``
    names the result in the log ("dataset", "branch")."""
    if run.last_info is not None:
        run._write_progress(run.last_info)
    try:
        return run.save(ds)
    except Exception as exc:  # noqa: BLE001 - recorded on the job, logged
        log.exception("job %s: writing the %s failed", run.job_id, what)
        run.finish(state=FAILED, reason="internal_error",
                   message=f"writing the result failed: {type(exc).__name__}: {exc}",
                   **run._position())
        return None


def _save_quietly(run: JobRun, ds) -> str | None:
    try:
        return run.save(ds)
    except Exception:  # noqa: BLE001 - the failure we report is the solver's
        log.exception("job %s: writing the partial dataset failed", run.job_id)
        return None


def _float_or_none(value):
    try:
        return None if value is None else float(value)
    except (TypeError, ValueError):
        return None


def _int_or_none(value):
    try:
        return None if value is None else int(value)
    except (TypeError, ValueError):
        return None


@shared_task(
    name=TASK_NAME,
    bind=True,
    acks_late=True,
    reject_on_worker_lost=True,
    max_retries=0,
    ignore_result=True,
)
def run_job_task(self, job_id: str) -> str:
    try:
        with _stop_on_sigterm():
            return run_job(job_id, self.request.hostname or f"pid-{os.getpid()}")
    except RegistryUnavailable as exc:
        # never acknowledge a job whose claim or outcome is not recorded: back to the broker
        log.error("%s; the message goes back to the queue", exc)
        raise Reject(str(exc), requeue=True) from exc


# --- warm shutdown: hand the running job back --------------------------------------------------
class _ShutdownRequest:
    """Set in the process that solves a job when its worker shuts down (read by should_stop)."""

    def __init__(self) -> None:
        self.reason: str | None = None
        self.at: float = -math.inf
        self.previous = None        # the SIGTERM handler outside a job (billiard's)


_shutdown = _ShutdownRequest()

#: a second SIGTERM this long after the first ends the pool process as before (an operator who
#: will not wait for the step); sooner, it is the same shutdown (process group + forwarded)
_SECOND_SIGTERM_AFTER = 2.0


def _on_sigterm(signum, frame) -> None:
    """SIGTERM while a job solves in a pool process: ask the solve to stop and hand back."""
    now = time.monotonic()
    if _shutdown.reason is None:
        _shutdown.reason, _shutdown.at = SHUTDOWN_REASON, now
        return
    if now - _shutdown.at < _SECOND_SIGTERM_AFTER:
        return
    previous = _shutdown.previous
    if callable(previous):
        previous(signum, frame)       # billiard's: SystemExit, the process goes
    else:
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)


@contextmanager
def _stop_on_sigterm():
    """While the task runs in a pool process, SIGTERM stops the solve at its next step (the
    job is handed back) instead of killing the process mid-step. Billiard installs its own
    handler after ``worker_process_init`` (SystemExit), so ours is set per task and the previous
    one restored afterwards; an idle pool process keeps billiard's behaviour. In the worker's
    main process (a solo pool, tests calling the task in-process) signals are left alone."""
    from billiard.process import current_process

    _shutdown.reason = None
    if (threading.current_thread() is not threading.main_thread()
            or current_process()._name == "MainProcess"):
        yield
        return
    _shutdown.previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, _shutdown.previous)
        _shutdown.previous = None


@worker_shutting_down.connect
def _forward_warm_shutdown(sig=None, how=None, **_kwargs) -> None:
    """In the worker's main process, at a warm shutdown (SIGTERM or SIGINT to it alone, as
    ``docker stop`` and Kubernetes send): pass SIGTERM on to each pool process that runs a job,
    whose solve then stops at its next step and hands the job back (Celery itself would wait for
    the job to finish, hours maybe, and the grace period would kill it)."""
    if how != "Warm":
        return          # cold shutdown: Celery terminates the pool processes itself (SIGTERM)
    from celery.worker import state as worker_state

    for request in list(worker_state.active_requests):
        pid = getattr(request, "worker_pid", None)
        if getattr(request, "name", None) != TASK_NAME or not pid:
            continue
        if pid == os.getpid():
            _shutdown.reason, _shutdown.at = SHUTDOWN_REASON, time.monotonic()
            continue
        try:
            os.kill(pid, signal.SIGTERM)
        except (ProcessLookupError, PermissionError):
            pass


# --- worker process life -----------------------------------------------------------------------
_heartbeat_stop = threading.Event()
_main_registry: list[Registry] = []


@worker_process_init.connect
def _pool_process_init(**_kwargs) -> None:
    """In each forked pool process: drop connections inherited from the parent, pin BLAS."""
    for registry in _main_registry:
        registry.engine.dispose(close=False)
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(get_settings().blas_threads)


@worker_ready.connect
def _start_heartbeat(sender=None, **_kwargs) -> None:
    settings = get_settings()
    registry = Registry(settings.registry_url, busy_timeout=settings.registry_busy_timeout)
    registry.create_schema()
    _main_registry.append(registry)
    name = getattr(sender, "hostname", None) or f"pid-{os.getpid()}"
    enqueuer = Enqueuer(settings, current_app._get_current_object())
    watch = RegistryWatch()       # a job's silence counts only while the registry took writes

    def beat() -> None:
        while not _heartbeat_stop.is_set():
            try:
                registry.heartbeat(name)
            except Exception as exc:  # noqa: BLE001 - registry down: try again next beat
                _log_registry_error("worker heartbeat", exc)
            try:
                sweep(registry, enqueuer, settings, log, watch)
            except Exception as exc:  # noqa: BLE001 - registry down: try again next beat
                _log_registry_error("sweep", exc)
            _heartbeat_stop.wait(settings.heartbeat_interval)

    threading.Thread(target=beat, name="hockle-heartbeat", daemon=True).start()


@worker_shutdown.connect
def _stop_heartbeat(**_kwargs) -> None:
    _heartbeat_stop.set()
