"""The registry's tables (SQLAlchemy 2 declarative models): ``hockle_jobs``, ``hockle_job_events``,
``hockle_workers``, ``hockle_sweeps``.

Their one home, read by the registry's data access (:mod:`service.registry`) and by the
schema migrations (:mod:`service.migrations`, whose revisions build these tables and whose
autogenerate compares against them), so that neither imports the other for them.
"""
from __future__ import annotations

import datetime as dt
import json

from sqlalchemy import Boolean, DateTime, Float, Integer, String, Text
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

__all__ = ["Base", "Job", "JobEvent", "WorkerBeat", "SweepRecord"]


class Base(DeclarativeBase):
    """The declarative base of the registry's tables (their shared ``MetaData``)."""


class Job(Base):
    __tablename__ = "hockle_jobs"

    id: Mapped[str] = mapped_column(String(36), primary_key=True)
    name: Mapped[str | None] = mapped_column(String(200))
    state: Mapped[str] = mapped_column(String(16), index=True)
    # what the job computes: "dynamic" (a run of its case, spec_json the case) or
    # "continuation" (a static branch, spec_json {"case": ..., "continuation": ...})
    kind: Mapped[str] = mapped_column(String(16), default="dynamic", server_default="dynamic")
    reason: Mapped[str | None] = mapped_column(String(32))
    message: Mapped[str | None] = mapped_column(Text)

    spec_json: Mapped[str] = mapped_column(Text)
    spec_hash: Mapped[str] = mapped_column(String(64), index=True)
    solver_version: Mapped[str] = mapped_column(String(32))
    grid_points: Mapped[int] = mapped_column(Integer)
    n_steps: Mapped[int] = mapped_column(Integer)
    t_end: Mapped[float] = mapped_column(Float)

    # as stored: scoped to the owner (scoped_idempotency_key), unique
    idempotency_key: Mapped[str | None] = mapped_column(String(200), unique=True)
    request_fingerprint: Mapped[str | None] = mapped_column(String(64))
    # service.auth.owner_id of the API key that submitted the job (a hash, never the key);
    # None when the service ran without keys
    owner: Mapped[str | None] = mapped_column(String(64), index=True)

    created_at: Mapped[dt.datetime] = mapped_column(DateTime, index=True)
    updated_at: Mapped[dt.datetime] = mapped_column(DateTime)
    started_at: Mapped[dt.datetime | None] = mapped_column(DateTime)
    finished_at: Mapped[dt.datetime | None] = mapped_column(DateTime)
    deadline_at: Mapped[dt.datetime | None] = mapped_column(DateTime, index=True)

    progress: Mapped[float] = mapped_column(Float, default=0.0)
    sim_time: Mapped[float] = mapped_column(Float, default=0.0)
    step: Mapped[int] = mapped_column(Integer, default=0)
    wall_time: Mapped[float | None] = mapped_column(Float)
    eta_seconds: Mapped[float | None] = mapped_column(Float)
    failed_time: Mapped[float | None] = mapped_column(Float)
    failed_step: Mapped[int | None] = mapped_column(Integer)

    worker: Mapped[str | None] = mapped_column(String(200))
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    # written every heartbeat_interval by the process solving the job (its attempt)
    heartbeat_at: Mapped[dt.datetime | None] = mapped_column(DateTime)
    # when the job's latest message was sent, and how many were sent (re-queues included)
    enqueued_at: Mapped[dt.datetime | None] = mapped_column(DateTime)
    dispatches: Mapped[int | None] = mapped_column(Integer, default=1)
    cancel_requested: Mapped[bool] = mapped_column(Boolean, default=False)

    time_limit: Mapped[float] = mapped_column(Float)
    soft_time_limit: Mapped[float] = mapped_column(Float)
    wall_clock_budget: Mapped[float] = mapped_column(Float)

    result_path: Mapped[str | None] = mapped_column(Text)
    result_partial: Mapped[bool] = mapped_column(Boolean, default=False)


class JobEvent(Base):
    """Append-only history of a job: submitted, started, solve_finished, finished, ..."""

    __tablename__ = "hockle_job_events"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    job_id: Mapped[str] = mapped_column(String(36), index=True)
    at: Mapped[dt.datetime] = mapped_column(DateTime)
    kind: Mapped[str] = mapped_column(String(32))
    attempt: Mapped[int | None] = mapped_column(Integer)
    worker: Mapped[str | None] = mapped_column(String(200))
    detail: Mapped[str | None] = mapped_column(Text)


class WorkerBeat(Base):
    __tablename__ = "hockle_workers"

    name: Mapped[str] = mapped_column(String(200), primary_key=True)
    last_seen: Mapped[dt.datetime] = mapped_column(DateTime)
    current_job: Mapped[str | None] = mapped_column(String(36))


class SweepRecord(Base):
    """A parameter sweep (service/sweeps.py): its members are ordinary jobs, listed here in
    member order; the sweep's state is derived from theirs."""

    __tablename__ = "hockle_sweeps"

    id: Mapped[str] = mapped_column(String(36), primary_key=True)
    name: Mapped[str | None] = mapped_column(String(200))
    combine: Mapped[str] = mapped_column(String(8))
    # JSON: [{"path": ..., "values": [...]}, ...] in the request's order
    parameters_json: Mapped[str] = mapped_column(Text)
    # JSON: the member's job id for each member index (a job may serve several members)
    member_job_ids: Mapped[str] = mapped_column(Text)
    base_json: Mapped[str] = mapped_column(Text)
    owner: Mapped[str | None] = mapped_column(String(64), index=True)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime, index=True)
    dismissed_at: Mapped[dt.datetime | None] = mapped_column(DateTime)

    @property
    def parameters(self) -> dict[str, list]:
        return {p["path"]: p["values"] for p in json.loads(self.parameters_json)}

    @property
    def job_ids(self) -> list[str]:
        return list(json.loads(self.member_job_ids))
