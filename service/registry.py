"""The job registry: the durable source of truth for job records (SQLAlchemy 2).

SQLite by default, PostgreSQL when ``HOCKLE_DATABASE_URL`` says so. The API writes a record and
commits it *before* the job is enqueued; workers move it through the states with conditional
``UPDATE`` statements, so that two deliveries of one job cannot both bring it to a terminal state.

States (OGC API - Processes): ``accepted -> running -> successful | failed | dismissed``, and
``accepted -> dismissed``. Only an ``accepted`` job can be claimed (one conditional ``UPDATE``):
a delivery that finds the job running or terminal does nothing. The process that solves a job
writes its heartbeat (``heartbeat_at``); a running job whose heartbeat is stale has lost its
worker and goes back to ``accepted`` (:meth:`Registry.requeue_lost`), and every write of an
attempt is keyed on its number, so an attempt that was given up cannot finish the job.
"""
from __future__ import annotations

import base64
import datetime as dt
import hashlib
import json
import math
import re
import uuid
from dataclasses import dataclass
from typing import Any, Iterable

from sqlalchemy import (
    and_,
    create_engine,
    event,
    func,
    or_,
    select,
    text,
    update,
)
from sqlalchemy.engine import Engine
from sqlalchemy.exc import (
    DisconnectionError,
    IntegrityError,
    InterfaceError,
    OperationalError,
)
from sqlalchemy.exc import TimeoutError as PoolTimeoutError
from sqlalchemy.orm import sessionmaker

# the tables live in service/models.py (also read by the migrations); imported from here too
from .models import Base, Job, JobEvent, SweepRecord, WorkerBeat  # noqa: F401

__all__ = [
    "ACTIVE_STATES",
    "TERMINAL_STATES",
    "REASONS",
    "Job",
    "JobEvent",
    "WorkerBeat",
    "Registry",
    "IdempotencyConflict",
    "scoped_idempotency_key",
    "REGISTRY_UNAVAILABLE",
    "utcnow",
    "well_formed_id",
]

ACCEPTED, RUNNING, SUCCESSFUL, FAILED, DISMISSED = (
    "accepted",
    "running",
    "successful",
    "failed",
    "dismissed",
)
STATES = (ACCEPTED, RUNNING, SUCCESSFUL, FAILED, DISMISSED)
ACTIVE_STATES = (ACCEPTED, RUNNING)
TERMINAL_STATES = (SUCCESSFUL, FAILED, DISMISSED)
REASONS = ("solver_diverged", "nonfinite_state", "timeout", "cancelled_by_user", "internal_error")


# errors of a registry that is locked (SQLite "database is locked"), restarting or unreachable:
# a worker retries them (worker.tasks.with_registry_retry)
REGISTRY_UNAVAILABLE = (OperationalError, InterfaceError, DisconnectionError, PoolTimeoutError)


#: what a job or sweep id can be: the registry makes them with uuid4 (36 characters). Any
#: other string names nothing and is answered without asking the database (PostgreSQL
#: refuses a NUL character in a text parameter: an error, not "no such job").
_ID = re.compile(r"[0-9A-Za-z_-]{1,36}")


def well_formed_id(value: object) -> bool:
    """True when ``value`` could be a job or sweep id of this registry."""
    return isinstance(value, str) and _ID.fullmatch(value) is not None


def utcnow() -> dt.datetime:
    """Naive UTC (both SQLite and PostgreSQL columns are ``timestamp without time zone``)."""
    return dt.datetime.now(dt.timezone.utc).replace(tzinfo=None)


def scoped_idempotency_key(owner: str | None, key: str) -> str:
    """The value stored for an ``Idempotency-Key``: the key itself for jobs without an owner
    (a service without API keys), else ``o:`` + SHA-256 of (owner, key), so that two owners'
    equal keys never meet in the unique column, which still fits (66 characters)."""
    if owner is None:
        return key
    return "o:" + hashlib.sha256(f"{owner}\n{key}".encode()).hexdigest()


class IdempotencyConflict(Exception):
    """The Idempotency-Key was used before with a different request."""

    def __init__(self, job_id: str):
        super().__init__(job_id)
        self.job_id = job_id


@dataclass
class Page:
    jobs: list[Job]
    next_token: str | None


def _encode_token(job: Job) -> str:
    raw = f"{job.created_at.isoformat()}|{job.id}".encode()
    return base64.urlsafe_b64encode(raw).decode().rstrip("=")


def decode_page_token(token: str) -> tuple[dt.datetime, str]:
    """Raises ValueError for a token this server did not make."""
    try:
        raw = base64.urlsafe_b64decode(token + "=" * (-len(token) % 4)).decode()
        when, job_id = raw.split("|", 1)
        if not well_formed_id(job_id):      # a NUL in it was a 500 on PostgreSQL
            raise ValueError(job_id)
        return dt.datetime.fromisoformat(when), job_id
    except Exception as exc:  # noqa: BLE001 - any malformed token is the same client error
        raise ValueError("page_token is not one this server issued") from exc


class Registry:
    """Data access to the registry; one per process (holds the connection pool)."""

    def __init__(self, url: str, *, echo: bool = False, busy_timeout: float = 30.0,
                 request_timeout: float | None = None):
        """``busy_timeout``: SQLite only, seconds a statement waits for another connection's
        lock before it fails with ``database is locked`` (an ``OperationalError``).

        ``request_timeout`` (the API's ``HOCKLE_REGISTRY_REQUEST_TIMEOUT``; None for workers,
        which wait and retry instead): the most seconds any one wait on the registry may take,
        so that a locked or slow registry answers an error (mapped to 503) instead of holding
        the request: PostgreSQL ``statement_timeout`` and ``lock_timeout``, the wait for a
        pooled connection and the connection attempt; SQLite the busy time-out (the smaller
        of the two). Each raises one of :data:`REGISTRY_UNAVAILABLE`."""
        self.url = url
        self.busy_timeout = self.migration_busy_timeout = float(busy_timeout)
        if request_timeout is not None:
            self.busy_timeout = min(self.busy_timeout, float(request_timeout))
        kwargs: dict[str, Any] = {"echo": echo, "pool_pre_ping": True}
        if url.startswith("sqlite"):
            kwargs["connect_args"] = {"check_same_thread": False, "timeout": self.busy_timeout}
        else:
            # the API serves requests from a thread pool: enough connections for it
            kwargs.update(pool_size=10, max_overflow=20, pool_timeout=30)
            if request_timeout is not None:
                ms = max(1, int(request_timeout * 1000))
                kwargs.update(pool_timeout=request_timeout, connect_args={
                    "connect_timeout": max(1, math.ceil(request_timeout)),
                    "options": f"-c statement_timeout={ms} -c lock_timeout={ms}"})
        self.engine: Engine = create_engine(url, **kwargs)
        if url.startswith("sqlite"):
            busy_ms = int(self.busy_timeout * 1000)
            event.listen(self.engine, "connect",
                         lambda conn, record: _sqlite_pragmas(conn, record, busy_ms))
        self.sessions = sessionmaker(self.engine, expire_on_commit=False)

    # --- schema --------------------------------------------------------------------------------
    def create_schema(self, *, auto_migrate: bool | None = None) -> None:
        """Bring the registry's schema to what this code needs, at start-up.

        With ``auto_migrate`` (None: the setting ``HOCKLE_AUTO_MIGRATE``, default true) the
        Alembic migrations are run to head (:func:`service.migrations.upgrade`: under a lock,
        safe when several processes start at once, a no-op when there already; a registry
        made before migrations is adopted with its rows). Without, only checked:
        :class:`service.migrations.SchemaNotCurrent` says what to run.
        """
        from service import migrations

        if auto_migrate is None:
            from service.settings import get_settings

            auto_migrate = get_settings().auto_migrate
        # a migration at start-up may wait for a lock as long as a worker would
        migrations.ensure_schema(self.url, auto_migrate=auto_migrate,
                                 busy_timeout=self.migration_busy_timeout)

    def ping(self) -> None:
        """Read one row of ``hockle_jobs``: raises one of :data:`REGISTRY_UNAVAILABLE` when the
        server is down, and also when the table is locked (a migration, ``LOCK TABLE``), which
        a bare ``SELECT 1`` would not notice."""
        with self.engine.connect() as conn:
            conn.execute(select(Job.id).limit(1)).first()

    def dispose(self) -> None:
        self.engine.dispose()

    def probe_write(self) -> None:
        """A write that changes nothing but needs what a job's heartbeat needs (the write
        lock of ``hockle_jobs``: SQLite's database lock, PostgreSQL's row-exclusive lock on
        the table): it waits or fails exactly when a heartbeat would. Raises one of
        :data:`REGISTRY_UNAVAILABLE`. :class:`service.queue.RegistryWatch` times it."""
        with self.sessions.begin() as session:
            session.execute(update(Job).where(Job.id == "").values(heartbeat_at=Job.heartbeat_at))

    # --- creation ------------------------------------------------------------------------------
    def create_job(
        self,
        *,
        spec_json: str,
        spec_hash: str,
        solver_version: str,
        name: str | None,
        grid_points: int,
        n_steps: int,
        t_end: float,
        limits: tuple[float, float, float],
        idempotency_key: str | None = None,
        request_fingerprint: str | None = None,
        owner: str | None = None,
        kind: str = "dynamic",
    ) -> tuple[Job, bool]:
        """Insert an accepted job and commit it. Returns (job, created).

        ``kind``: "dynamic" (``spec_json`` a case) or "continuation" (``spec_json`` the
        validated request of service/continuations.py).

        ``owner``: the owner id of the API key that submits it (None without keys).
        With an ``idempotency_key`` this owner already used: the earlier job when the
        fingerprint matches (created False), else :class:`IdempotencyConflict`.
        """
        if idempotency_key is not None:
            earlier = self.by_idempotency_key(idempotency_key, owner=owner)
            if earlier is not None:
                return self._replay(earlier, request_fingerprint), False
        now = utcnow()
        job = Job(
            id=str(uuid.uuid4()),
            name=name,
            state=ACCEPTED,
            kind=kind,
            spec_json=spec_json,
            spec_hash=spec_hash,
            solver_version=solver_version,
            grid_points=grid_points,
            n_steps=n_steps,
            t_end=t_end,
            idempotency_key=(None if idempotency_key is None
                             else scoped_idempotency_key(owner, idempotency_key)),
            request_fingerprint=request_fingerprint,
            owner=owner,
            created_at=now,
            updated_at=now,
            progress=0.0,
            sim_time=0.0,
            step=0,
            attempts=0,
            cancel_requested=False,
            enqueued_at=now,
            dispatches=1,
            time_limit=limits[0],
            soft_time_limit=limits[1],
            wall_clock_budget=limits[2],
            result_partial=False,
        )
        try:
            with self.sessions.begin() as session:
                session.add(job)
                session.add(JobEvent(job_id=job.id, at=now, kind="submitted"))
        except IntegrityError:
            # a concurrent request with the same key won the race
            earlier = (self.by_idempotency_key(idempotency_key, owner=owner)
                       if idempotency_key else None)
            if earlier is None:
                raise
            return self._replay(earlier, request_fingerprint), False
        return job, True

    @staticmethod
    def _replay(earlier: Job, fingerprint: str | None) -> Job:
        if earlier.request_fingerprint != fingerprint:
            raise IdempotencyConflict(earlier.id)
        return earlier

    def by_idempotency_key(self, key: str, *, owner: str | None = None) -> Job | None:
        """The job that ``owner`` (None: the service without keys) submitted with this
        Idempotency-Key, if any."""
        stored = scoped_idempotency_key(owner, key)
        with self.sessions() as session:
            return session.scalars(select(Job).where(Job.idempotency_key == stored)).first()

    def find_successful(self, spec_hash: str, solver_version: str, *,
                        owner: str | None = None, kind: str = "dynamic") -> Job | None:
        """The latest successful job of this ``kind`` with this spec hash and solver version
        and a result file; with ``owner``, among that owner's jobs only."""
        query = select(Job).where(
            Job.kind == kind,
            Job.spec_hash == spec_hash,
            Job.solver_version == solver_version,
            Job.state == SUCCESSFUL,
            Job.result_path.is_not(None),
        )
        if owner is not None:
            query = query.where(Job.owner == owner)
        with self.sessions() as session:
            return session.scalars(query.order_by(Job.finished_at.desc()).limit(1)).first()

    # --- reading -------------------------------------------------------------------------------
    def get(self, job_id: str) -> Job | None:
        """The job, or None (also for a string that cannot be an id: :func:`well_formed_id`)."""
        if not well_formed_id(job_id):
            return None
        with self.sessions() as session:
            return session.get(Job, job_id)

    def events(self, job_id: str | None = None) -> list[JobEvent]:
        with self.sessions() as session:
            query = select(JobEvent).order_by(JobEvent.id)
            if job_id is not None:
                query = query.where(JobEvent.job_id == job_id)
            return list(session.scalars(query))

    def cancel_requested(self, job_id: str) -> bool:
        with self.engine.connect() as conn:
            row = conn.execute(
                select(Job.cancel_requested, Job.state).where(Job.id == job_id)
            ).first()
        return row is None or bool(row[0]) or row[1] == DISMISSED

    def list(
        self,
        *,
        states: Iterable[str] | None = None,
        created_after: dt.datetime | None = None,
        created_before: dt.datetime | None = None,
        page_size: int = 50,
        page_token: str | None = None,
        owner: str | None = None,
    ) -> Page:
        """Newest first; keyset pagination on (created_at, id); with ``owner``, that owner's
        jobs only."""
        query = select(Job).order_by(Job.created_at.desc(), Job.id.desc()).limit(page_size + 1)
        if owner is not None:
            query = query.where(Job.owner == owner)
        states = list(states or [])
        if states:
            query = query.where(Job.state.in_(states))
        if created_after is not None:
            query = query.where(Job.created_at >= created_after)
        if created_before is not None:
            query = query.where(Job.created_at < created_before)
        if page_token:
            when, job_id = decode_page_token(page_token)
            query = query.where(
                or_(Job.created_at < when, and_(Job.created_at == when, Job.id < job_id))
            )
        with self.sessions() as session:
            jobs = list(session.scalars(query))
        token = _encode_token(jobs[page_size - 1]) if len(jobs) > page_size else None
        return Page(jobs[:page_size], token)

    def counts(self) -> dict[str, int]:
        with self.sessions() as session:
            rows = session.execute(select(Job.state, func.count()).group_by(Job.state)).all()
        return {state: n for state, n in rows}

    # --- transitions (API side) ----------------------------------------------------------------
    def dismiss(self, job_id: str) -> Job | None:
        """Dismiss: an accepted job becomes dismissed at once; a running one gets its cancel flag.

        Returns the job after the change (None when unknown).
        """
        now = utcnow()
        with self.sessions.begin() as session:
            done = session.execute(
                update(Job)
                .where(Job.id == job_id, Job.state == ACCEPTED)
                .values(
                    state=DISMISSED,
                    reason="cancelled_by_user",
                    message="dismissed before it started",
                    cancel_requested=True,
                    finished_at=now,
                    updated_at=now,
                )
            ).rowcount
            if done:
                session.add(JobEvent(job_id=job_id, at=now, kind="dismissed"))
            else:
                flagged = session.execute(
                    update(Job)
                    .where(Job.id == job_id, Job.state == RUNNING, Job.cancel_requested.is_(False))
                    .values(cancel_requested=True, updated_at=now)
                ).rowcount
                if flagged:
                    session.add(JobEvent(job_id=job_id, at=now, kind="cancel_requested"))
        return self.get(job_id)

    def mark_enqueue_failed(self, job_id: str, message: str) -> None:
        now = utcnow()
        with self.sessions.begin() as session:
            session.execute(
                update(Job)
                .where(Job.id == job_id, Job.state == ACCEPTED)
                .values(
                    state=FAILED,
                    reason="internal_error",
                    message=message,
                    finished_at=now,
                    updated_at=now,
                )
            )
            session.add(JobEvent(job_id=job_id, at=now, kind="enqueue_failed", detail=message))

    # --- transitions (worker side) -------------------------------------------------------------
    def claim(self, job_id: str, worker: str) -> int | None:
        """accepted -> running for this delivery; returns the attempt number (1, 2, ...).

        One conditional ``UPDATE ... WHERE state = 'accepted'``: of two deliveries of one job
        (a re-queue, a redelivered message) at most one claims it. None when the job is
        unknown, already running (another attempt holds it and heartbeats), terminal, or
        dismissed while queued (then it becomes ``dismissed`` here and never starts).
        """
        now = utcnow()
        with self.sessions.begin() as session:
            claimed = session.execute(
                update(Job)
                .where(Job.id == job_id, Job.state == ACCEPTED, Job.cancel_requested.is_(False))
                .values(
                    state=RUNNING,
                    attempts=Job.attempts + 1,
                    worker=worker,
                    started_at=now,
                    updated_at=now,
                    heartbeat_at=now,
                    progress=0.0,
                    sim_time=0.0,
                    step=0,
                    eta_seconds=None,
                )
            ).rowcount
            if not claimed:
                dismissed = session.execute(
                    update(Job)
                    .where(Job.id == job_id, Job.state == ACCEPTED, Job.cancel_requested.is_(True))
                    .values(
                        state=DISMISSED,
                        reason="cancelled_by_user",
                        message=func.coalesce(Job.message, "dismissed before it started"),
                        finished_at=now,
                        updated_at=now,
                    )
                ).rowcount
                if dismissed:
                    session.add(JobEvent(job_id=job_id, at=now, kind="dismissed", worker=worker))
                return None
            # the row is ours (write-locked) until commit: read back the attempt and limit
            attempt, limit = session.execute(
                select(Job.attempts, Job.time_limit).where(Job.id == job_id)
            ).one()
            session.execute(
                update(Job)
                .where(Job.id == job_id)
                .values(deadline_at=now + dt.timedelta(seconds=float(limit)))
            )
            session.add(
                JobEvent(job_id=job_id, at=now, kind="started", attempt=attempt, worker=worker)
            )
        return int(attempt)

    def job_heartbeat(self, job_id: str, attempt: int) -> bool:
        """Record that ``attempt`` of the job is alive. False when it no longer holds the job
        (finished, reaped, dismissed, or given up as lost and re-queued): it should stop."""
        now = utcnow()
        with self.sessions.begin() as session:
            return bool(session.execute(
                update(Job)
                .where(Job.id == job_id, Job.state == RUNNING, Job.attempts == attempt)
                .values(heartbeat_at=now)
            ).rowcount)

    def record_progress(
        self,
        job_id: str,
        attempt: int,
        *,
        progress: float,
        sim_time: float,
        step: int,
        wall_time: float,
        eta_seconds: float | None,
    ) -> None:
        now = utcnow()
        with self.sessions.begin() as session:
            session.execute(
                update(Job)
                .where(Job.id == job_id, Job.state == RUNNING, Job.attempts == attempt)
                .values(
                    progress=progress,
                    sim_time=sim_time,
                    step=step,
                    wall_time=wall_time,
                    eta_seconds=eta_seconds,
                    updated_at=now,
                )
            )

    def add_event(
        self, job_id: str, kind: str, *, attempt: int | None = None, worker: str | None = None,
        detail: Any = None,
    ) -> None:
        with self.sessions.begin() as session:
            session.add(
                JobEvent(
                    job_id=job_id,
                    at=utcnow(),
                    kind=kind,
                    attempt=attempt,
                    worker=worker,
                    detail=None if detail is None else json.dumps(detail),
                )
            )

    def finish(
        self,
        job_id: str,
        attempt: int,
        *,
        state: str,
        reason: str | None = None,
        message: str | None = None,
        result_path: str | None = None,
        result_partial: bool = False,
        progress: float | None = None,
        sim_time: float | None = None,
        step: int | None = None,
        wall_time: float | None = None,
        failed_time: float | None = None,
        failed_step: int | None = None,
        worker: str | None = None,
    ) -> bool:
        """running -> terminal, only for the attempt that holds the job. True if it did."""
        assert state in TERMINAL_STATES
        now = utcnow()
        values: dict[str, Any] = dict(
            state=state,
            reason=reason,
            message=message,
            result_path=result_path,
            result_partial=result_partial,
            finished_at=now,
            updated_at=now,
            eta_seconds=0.0 if state == SUCCESSFUL else None,
            failed_time=failed_time,
            failed_step=failed_step,
        )
        for key, value in (
            ("progress", progress),
            ("sim_time", sim_time),
            ("step", step),
            ("wall_time", wall_time),
        ):
            if value is not None:
                values[key] = value
        with self.sessions.begin() as session:
            done = session.execute(
                update(Job)
                .where(Job.id == job_id, Job.state == RUNNING, Job.attempts == attempt)
                .values(**values)
            ).rowcount
            session.add(
                JobEvent(
                    job_id=job_id,
                    at=now,
                    kind="finished" if done else "finish_refused",
                    attempt=attempt,
                    worker=worker,
                    detail=json.dumps({"state": state, "reason": reason}),
                )
            )
        return bool(done)

    def reap(self, now: dt.datetime | None = None, grace: float = 30.0,
             heartbeat_timeout: float | None = None) -> list[str]:
        """Fail running jobs whose hard time limit (plus ``grace``) has passed: reason timeout.

        Celery kills a task at its hard limit without running any of its code; this is what
        brings such a job to a terminal state. With ``heartbeat_timeout``, only jobs whose
        last heartbeat came within ``heartbeat_timeout`` of their deadline (they were alive
        until about then); a job whose heartbeat stopped earlier lost its worker and is
        :meth:`requeue_lost`'s. The message says how far the job got. Returns the ids failed.
        """
        now = now or utcnow()
        cutoff = now - dt.timedelta(seconds=grace)
        beat = func.coalesce(Job.heartbeat_at, Job.started_at)
        reaped = []
        with self.sessions.begin() as session:
            rows = session.execute(
                select(Job.id, Job.attempts, beat, Job.deadline_at, Job.time_limit, Job.sim_time,
                       Job.t_end, Job.step, Job.kind)
                .where(Job.state == RUNNING, Job.deadline_at < cutoff)
            ).all()
            for job_id, attempt, last, deadline, limit, sim_time, t_end, step, kind in rows:
                if (heartbeat_timeout is not None and last is not None
                        and last < deadline - dt.timedelta(seconds=heartbeat_timeout)):
                    continue
                done = session.execute(
                    update(Job)
                    .where(Job.id == job_id, Job.state == RUNNING, Job.attempts == attempt)
                    .values(
                        state=FAILED,
                        reason="timeout",
                        message=f"killed at the hard time limit of {limit:.0f} s at "
                                f"{_how_far(kind, sim_time, t_end, step)}; no result was "
                                "written",
                        finished_at=now,
                        updated_at=now,
                        eta_seconds=None,
                    )
                ).rowcount
                if done:
                    reaped.append(job_id)
                    session.add(JobEvent(job_id=job_id, at=now, kind="reaped", attempt=attempt))
        return reaped

    def requeue_lost(self, *, heartbeat_timeout: float, max_attempts: int,
                     now: dt.datetime | None = None,
                     writable_since: dt.datetime | None = None) -> list[tuple[Job, str]]:
        """Running jobs whose heartbeat is older than ``heartbeat_timeout`` lost their worker.

        Each goes back to ``accepted`` (the caller sends its message again; the next claim is
        attempt + 1), or, when it had ``max_attempts`` attempts, becomes ``failed`` (reason
        ``internal_error``), or ``dismissed`` when a cancel was requested. A job whose last
        heartbeat came within ``heartbeat_timeout`` of its deadline is left to :meth:`reap`.
        Conditional on (state, attempt, stale heartbeat): of several sweepers one acts.
        Returns ``(job, action)`` pairs, ``action`` in ``requeued``, ``failed``, ``dismissed``.

        ``writable_since`` (the caller's :class:`service.queue.RegistryWatch`): since when
        the registry has taken writes without a break, as far as the caller saw. A job's
        silence counts only while its heartbeat could have been written, so nothing is
        lost before the registry has been writable for ``heartbeat_timeout``: an outage of
        any length changes nothing for a job whose worker lives.
        """
        now = now or utcnow()
        if writable_since is not None and writable_since > now - dt.timedelta(
                seconds=heartbeat_timeout):
            return []
        stale = now - dt.timedelta(seconds=heartbeat_timeout)
        beat = func.coalesce(Job.heartbeat_at, Job.started_at)
        done: list[tuple[str, str]] = []
        with self.sessions.begin() as session:
            rows = session.execute(
                select(Job.id, Job.attempts, beat, Job.deadline_at, Job.cancel_requested,
                       Job.worker, Job.sim_time, Job.t_end, Job.step, Job.kind)
                .where(Job.state == RUNNING, beat < stale)
            ).all()
            for (job_id, attempt, last, deadline, cancel, worker, sim_time, t_end, step,
                 kind) in rows:
                if deadline is not None and last >= deadline - dt.timedelta(
                        seconds=heartbeat_timeout):
                    continue  # alive until about its hard limit: reap() fails it as timeout
                where = (Job.id == job_id, Job.state == RUNNING, Job.attempts == attempt,
                         beat < stale)
                lost = (f"attempt {attempt} lost its worker {worker} at "
                        + _how_far(kind, sim_time, t_end, step, "no heartbeat since "
                                   f"{last.isoformat(timespec='seconds')}Z"))
                if cancel:
                    action = "dismissed"
                    values = dict(state=DISMISSED, reason="cancelled_by_user",
                                  message=f"dismissed while running; {lost}; no result",
                                  finished_at=now, eta_seconds=None)
                elif attempt - self._handed_back(session, job_id) >= max_attempts:
                    # attempts handed back at a worker's shutdown were not lost: not counted
                    action = "failed"
                    values = dict(state=FAILED, reason="internal_error",
                                  message=f"{lost}; given up after {attempt} attempts "
                                          f"(HOCKLE_MAX_ATTEMPTS = {max_attempts}); no result",
                                  finished_at=now, eta_seconds=None)
                else:
                    action = "requeued"
                    values = _requeued(now, f"{lost}; queued again as attempt {attempt + 1} of "
                                            f"at most {max_attempts}")
                changed = session.execute(
                    update(Job).where(*where).values(updated_at=now, **values)
                ).rowcount
                if changed:
                    done.append((job_id, action))
                    session.add(JobEvent(
                        job_id=job_id, at=now, kind="worker_lost", attempt=attempt,
                        worker=worker, detail=json.dumps({
                            "action": action, "last_heartbeat": last.isoformat() + "Z",
                            "sim_time": sim_time, "step": step})))
        return [(self.get(job_id), action) for job_id, action in done]

    @staticmethod
    def _handed_back(session, job_id: str) -> int:
        """How many attempts of the job were handed back at a worker's shutdown."""
        return int(session.scalar(
            select(func.count()).select_from(JobEvent)
            .where(JobEvent.job_id == job_id, JobEvent.kind == "requeued_at_shutdown")) or 0)

    def requeue_at_shutdown(self, job_id: str, attempt: int, *, worker: str | None = None,
                            reason: str = "worker_shutdown", sim_time: float | None = None,
                            step: int | None = None, at: str | None = None) -> str | None:
        """``attempt`` stopped because its worker shuts down (a redeploy): the job goes back to
        ``accepted`` at once, as :meth:`requeue_lost` does for a lost worker but without waiting
        for its heartbeat to go stale (the caller sends its message again; the next claim is
        attempt + 1 and continues from the job's checkpoint). Such attempts do not count
        towards ``max_attempts``. A job whose dismissal was requested becomes ``dismissed``.

        Conditional on (running, ``attempt``): returns ``"requeued"``, ``"dismissed"``, or None
        when this attempt no longer holds the job (given up as lost, reaped, finished).
        Event ``requeued_at_shutdown`` with the reason and where it stopped (``t``, ``step``).
        ``at`` describes where it stopped in the message (a continuation's point and
        parameter); default ``t = <sim_time> s (step <step>)``.
        """
        now = utcnow()
        where = (Job.id == job_id, Job.state == RUNNING, Job.attempts == attempt)
        at = at or f"t = {sim_time or 0.0:.6g} s (step {step or 0})"
        stopped = f"attempt {attempt} stopped at {at} because its worker {worker} shut down"
        with self.sessions.begin() as session:
            action = "requeued"
            changed = session.execute(
                update(Job).where(*where, Job.cancel_requested.is_(False))
                .values(updated_at=now, **_requeued(
                    now, f"{stopped}; queued again as attempt {attempt + 1}"))
            ).rowcount
            if not changed:
                action = "dismissed"
                changed = session.execute(
                    update(Job).where(*where, Job.cancel_requested.is_(True))
                    .values(state=DISMISSED, reason="cancelled_by_user",
                            message=f"dismissed while running; {stopped}; no result",
                            finished_at=now, updated_at=now, eta_seconds=None)
                ).rowcount
            if not changed:
                return None
            session.add(JobEvent(
                job_id=job_id, at=now, kind="requeued_at_shutdown", attempt=attempt,
                worker=worker, detail=json.dumps({"action": action, "reason": reason,
                                                  "t": sim_time, "step": step})))
        return action

    def requeue_unclaimed(self, *, after: float, now: dt.datetime | None = None,
                          longest_wait: float = 3600.0) -> list[Job]:
        """Accepted jobs that no worker claimed within ``after`` s of their last message (which
        may be lost: a worker that failed before its claim, a broker that lost data, an API
        stopped between commit and send). The wait doubles with each message sent, up to
        ``longest_wait`` (a job behind a long queue gets few duplicates). Marks them sent again
        (conditional on the previous send time: of several sweepers one acts) and returns them;
        the caller sends the messages. A duplicate is harmless: only one delivery can claim.
        """
        now = now or utcnow()
        sent = func.coalesce(Job.enqueued_at, Job.created_at)
        due = []
        with self.sessions.begin() as session:
            rows = session.execute(
                select(Job.id, Job.enqueued_at, sent, Job.dispatches)
                .where(Job.state == ACCEPTED, Job.cancel_requested.is_(False),
                       sent < now - dt.timedelta(seconds=after))
            ).all()
            for job_id, enqueued_at, last, dispatches in rows:
                n = max(1, int(dispatches or 1))
                wait = min(after * 2.0 ** min(n - 1, 30), max(after, longest_wait))
                if last > now - dt.timedelta(seconds=wait):
                    continue
                same = (Job.enqueued_at.is_(None) if enqueued_at is None
                        else Job.enqueued_at == enqueued_at)
                changed = session.execute(
                    update(Job)
                    .where(Job.id == job_id, Job.state == ACCEPTED, same)
                    .values(enqueued_at=now, dispatches=n + 1)
                ).rowcount
                if changed:
                    due.append(job_id)
                    session.add(JobEvent(
                        job_id=job_id, at=now, kind="requeued",
                        detail=json.dumps({"reason": f"not claimed within {wait:.0f} s of its "
                                           "last message", "dispatch": n + 1})))
        jobs = [self.get(job_id) for job_id in due]
        return [job for job in jobs if job is not None]

    def mark_unsent(self, job_id: str) -> None:
        """The message of this accepted job could not be sent: make the next
        :meth:`requeue_unclaimed` send it at once."""
        with self.sessions.begin() as session:
            session.execute(
                update(Job)
                .where(Job.id == job_id, Job.state == ACCEPTED)
                .values(enqueued_at=dt.datetime(1970, 1, 1))
            )

    # --- workers -------------------------------------------------------------------------------
    def heartbeat(self, name: str, current_job: str | None = None, *, clear: bool = False) -> None:
        now = utcnow()
        with self.sessions.begin() as session:
            beat = session.get(WorkerBeat, name)
            if beat is None:
                session.add(WorkerBeat(name=name, last_seen=now, current_job=current_job))
            else:
                beat.last_seen = now
                if current_job is not None or clear:
                    beat.current_job = current_job

    def workers_seen(self, window: float) -> list[WorkerBeat]:
        since = utcnow() - dt.timedelta(seconds=window)
        with self.sessions() as session:
            return list(
                session.scalars(
                    select(WorkerBeat).where(WorkerBeat.last_seen >= since).order_by(WorkerBeat.name)
                )
            )


    # --- sweeps --------------------------------------------------------------------------------
    def create_sweep(self, *, name: str | None, combine: str, parameters: dict[str, list],
                     job_ids: list[str], base_json: str, owner: str | None = None) -> SweepRecord:
        """Record a sweep whose member jobs exist already (one id per member, in order)."""
        sweep = SweepRecord(
            id=str(uuid.uuid4()), name=name, combine=combine,
            parameters_json=json.dumps([{"path": p, "values": v} for p, v in parameters.items()]),
            member_job_ids=json.dumps(list(job_ids)), base_json=base_json, owner=owner,
            created_at=utcnow(), dismissed_at=None)
        with self.sessions.begin() as session:
            session.add(sweep)
        return sweep

    def get_sweep(self, sweep_id: str) -> SweepRecord | None:
        """The sweep, or None (also for a string that cannot be an id)."""
        if not well_formed_id(sweep_id):
            return None
        with self.sessions() as session:
            return session.get(SweepRecord, sweep_id)

    def mark_sweep_dismissed(self, sweep_id: str) -> None:
        """Record that the sweep was dismissed (once: the first time stays)."""
        with self.sessions.begin() as session:
            session.execute(update(SweepRecord)
                            .where(SweepRecord.id == sweep_id, SweepRecord.dismissed_at.is_(None))
                            .values(dismissed_at=utcnow()))

    def sweeps_of(self, jobs: Iterable[Job], owner: str | None = None) -> dict[str, str]:
        """For each of ``jobs`` that is a member of a sweep (of ``owner``'s; None: anyone's),
        the id of the newest such sweep, by job id. A sweep is recorded after its members
        (and may reuse an earlier job), so only sweeps created at or after the oldest of the
        jobs are read, and only those whose member list names one of them (the jobs list's
        "kind" column; a page of 50 jobs is one query)."""
        jobs = [j for j in jobs if well_formed_id(j.id)]
        if not jobs:
            return {}
        since = min(j.created_at for j in jobs)
        ids = {j.id for j in jobs}
        query = select(SweepRecord.id, SweepRecord.member_job_ids).where(
            SweepRecord.created_at >= since,
            or_(*[SweepRecord.member_job_ids.contains(f'"{i}"') for i in ids]))
        if owner is not None:
            query = query.where(SweepRecord.owner == owner)
        found: dict[str, str] = {}
        with self.sessions() as session:
            for sweep_id, members in session.execute(query.order_by(SweepRecord.created_at)):
                for job_id in json.loads(members):
                    if job_id in ids:
                        found[job_id] = sweep_id        # the newest sweep last, kept
        return found

    def get_many(self, job_ids: Iterable[str]) -> dict[str, Job]:
        """The jobs with these ids (unknown ids are left out), by id."""
        ids = [i for i in dict.fromkeys(job_ids) if well_formed_id(i)]
        found: dict[str, Job] = {}
        with self.sessions() as session:
            for start in range(0, len(ids), 500):
                for job in session.scalars(select(Job).where(Job.id.in_(ids[start:start + 500]))):
                    found[job.id] = job
        return found

def _requeued(now: dt.datetime, message: str) -> dict[str, Any]:
    """The values that put a running job back to ``accepted`` for its next attempt (a lost
    worker, a worker's shutdown); its message is marked sent now."""
    return dict(state=ACCEPTED, message=message, worker=None, heartbeat_at=None,
                deadline_at=None, progress=0.0, sim_time=0.0, step=0, eta_seconds=None,
                enqueued_at=now, dispatches=func.coalesce(Job.dispatches, 1) + 1)


def _how_far(kind: str | None, sim_time, t_end, step, note: str = "") -> str:
    """Where a running job got, from its registry row: 't = 1.2 s of 45 s (step 120)';
    for a continuation (whose ``step`` counts points and which has no simulated time)
    'point 12'. ``note`` goes into the parentheses."""
    if kind == "continuation":
        return f"point {step or 0}" + (f" ({note})" if note else "")
    return (f"t = {sim_time or 0.0:.6g} s of {t_end:.6g} s (step {step or 0}"
            + (f"; {note})" if note else ")"))


def _sqlite_pragmas(dbapi_connection, _record, busy_ms: int = 30000) -> None:
    cursor = dbapi_connection.cursor()
    cursor.execute("PRAGMA journal_mode=WAL")
    cursor.execute("PRAGMA synchronous=NORMAL")
    cursor.execute(f"PRAGMA busy_timeout={int(busy_ms)}")
    cursor.close()
