"""Celery configuration shared by the API (which only enqueues, by task name) and the workers.

The API never imports the worker's task code nor the solver's numerics: it sends
``hockle.run_job(job_id)`` to the queue. The job registry, not Celery, is the truth about a job:
no result backend is configured and Celery task states never reach a client.
"""
from __future__ import annotations

import datetime as dt
import logging
import threading
import time

from celery import Celery

from .registry import REGISTRY_UNAVAILABLE, Registry, utcnow
from .settings import Settings

__all__ = ["TASK_NAME", "make_celery", "Enqueuer", "sweep", "send_job", "RegistryWatch"]

TASK_NAME = "hockle.run_job"


def make_celery(settings: Settings, main: str = "hockle") -> Celery:
    app = Celery(main, broker=settings.celery_broker_url)
    transport_options: dict = {}
    if settings.celery_broker_url.startswith(("redis://", "rediss://", "sentinel://")):
        transport_options = {
            # longer than any hard time limit: a running job is never handed to a second worker
            # while the first still works on it; a job whose worker died comes back after it
            "visibility_timeout": settings.visibility_timeout,
            "unacked_restore_interval": settings.unacked_restore_interval,
            "unacked_restore_throttle": 1,
            "socket_timeout": 30,
            "socket_connect_timeout": 5,
            "health_check_interval": 10,
        }
    elif settings.celery_broker_url.startswith("sqla+"):
        # handed to sqlalchemy.create_engine by kombu: wait for SQLite's lock, never fail at once
        transport_options = {"connect_args": {"timeout": 30}}
    app.conf.update(
        task_default_queue=settings.queue,
        task_routes={TASK_NAME: {"queue": settings.queue}},
        task_serializer="json",
        accept_content=["json"],
        task_ignore_result=True,
        result_backend=None,
        # a job is acknowledged after it ran; if its worker process dies it is redelivered
        task_acks_late=True,
        task_reject_on_worker_lost=True,
        worker_prefetch_multiplier=1,
        worker_cancel_long_running_tasks_on_connection_loss=False,
        broker_transport_options=transport_options,
        broker_connection_retry_on_startup=True,
        broker_connection_max_retries=None,
        worker_hijack_root_logger=False,
        worker_send_task_events=False,
        task_send_sent_event=False,
        enable_utc=True,
    )
    return app


class Enqueuer:
    """Sends jobs to the queue with their own time limits (thread-safe)."""

    def __init__(self, settings: Settings, app: Celery | None = None):
        self.settings = settings
        self.app = app or make_celery(settings)
        self._lock = threading.Lock()

    def enqueue(self, job_id: str, *, time_limit: float, soft_time_limit: float) -> None:
        with self._lock:
            self.app.send_task(
                TASK_NAME,
                args=[job_id],
                task_id=job_id,
                queue=self.settings.queue,
                time_limit=time_limit,
                soft_time_limit=soft_time_limit,
                retry=True,
                retry_policy={"max_retries": 3, "interval_start": 0.2, "interval_step": 0.5},
            )

    def ping(self) -> None:
        """Raise when the broker cannot be reached."""
        with self.app.connection_for_write() as conn:
            conn.ensure_connection(max_retries=1, timeout=3)

    def queue_depth(self) -> int:
        """Messages waiting in the job queue (the Redis list ``HOCKLE_QUEUE``, which KEDA's
        ``redis`` scaler reads too; the SQL broker's table in embedded mode). Raises when the
        broker cannot be reached."""
        from kombu.exceptions import ChannelError

        with self.app.connection_for_write() as conn:
            conn.ensure_connection(max_retries=1, timeout=3)
            channel = conn.default_channel
            try:
                return int(channel.queue_declare(queue=self.settings.queue,
                                                 passive=True).message_count)
            except ChannelError:   # Redis: an empty list does not exist
                return 0

    def close(self) -> None:
        self.app.close()


class RegistryWatch:
    """Since when the registry has taken writes without a break, as one sweeper sees it.

    Each sweep first makes :meth:`Registry.probe_write` (what a job's heartbeat needs). A
    probe that fails, or that had to wait more than ``slow`` seconds (a lock held, a server
    coming back), marks an outage; ``writable_since`` is then the start of the first quick
    probe after it (or the end of a slow one that succeeded): no earlier than the registry
    could take the heartbeats of running jobs again. It starts at the watch's creation:
    a sweeper judges only what it watched. Sweepers probe every ``heartbeat_interval``, so
    any outage longer than that is seen (a job's heartbeat interval is the same)."""

    def __init__(self, slow: float = 1.0):
        self.slow = float(slow)
        self.writable_since: dt.datetime = utcnow()
        self.down = False

    def probe(self, registry: Registry) -> None:
        """Probe the registry; raises its error (one of REGISTRY_UNAVAILABLE) when it did not
        take the write, after noting the outage."""
        started, t0 = utcnow(), time.monotonic()
        try:
            registry.probe_write()
        except REGISTRY_UNAVAILABLE:
            self.down = True
            raise
        if time.monotonic() - t0 > self.slow:
            self.writable_since = utcnow()      # it waited: writable from now on
        elif self.down:
            self.writable_since = started
        self.down = False


def sweep(registry: Registry, enqueuer: Enqueuer, settings: Settings,
          log: logging.Logger, watch: RegistryWatch | None = None) -> dict[str, list[str]]:
    """One pass of the sweeper that the API and every worker run each heartbeat_interval.

    * the reaper: running jobs killed at their hard time limit -> failed/timeout;
    * lost workers: running jobs whose heartbeat is older than job_heartbeat_timeout -> queued
      again (attempt + 1; the message is sent here), or failed after max_attempts;
    * lost messages: accepted jobs not claimed within requeue_after of their last message ->
      the message is sent again.

    Every change is a conditional UPDATE in the registry, so sweepers running at once act on a
    job once, and a duplicate message is harmless (only an accepted job can be claimed).
    Returns the ids acted on, by kind (for logs and tests).

    With ``watch`` (the API's and every worker's sweeper), a job's silence counts only while
    the registry took writes (:class:`RegistryWatch`): after an outage, no job is lost until
    the registry has been writable again for job_heartbeat_timeout, time for a live job's
    heartbeat to be written (an outage longer than the time-out had running jobs redone as
    attempt 2). A sweep whose probe fails does nothing and raises the registry's error.
    """
    done: dict[str, list[str]] = {"reaped": [], "requeued": [], "failed": [], "dismissed": [],
                                  "resent": []}
    writable_since = None
    if watch is not None:
        watch.probe(registry)               # raises while the registry takes no writes
        writable_since = watch.writable_since
    for job_id in registry.reap(grace=settings.reaper_grace,
                                heartbeat_timeout=settings.job_heartbeat_timeout):
        done["reaped"].append(job_id)
        log.warning("reaper: job %s passed its hard time limit: failed/timeout", job_id)
    for job, action in registry.requeue_lost(heartbeat_timeout=settings.job_heartbeat_timeout,
                                             max_attempts=settings.max_attempts,
                                             writable_since=writable_since):
        done[action].append(job.id)
        log.warning("sweeper: job %s: %s (%s)", job.id, action, job.message)
        if action == "requeued":
            send_job(registry, enqueuer, job, log)
    for job in registry.requeue_unclaimed(after=settings.requeue_after):
        done["resent"].append(job.id)
        log.warning("sweeper: job %s accepted but not claimed since %s: message sent again",
                    job.id, job.created_at.isoformat(timespec="seconds"))
        send_job(registry, enqueuer, job, log)
    return done


def send_job(registry: Registry, enqueuer: Enqueuer, job, log: logging.Logger) -> None:
    """Send the message of an ``accepted`` job (queued again); when the broker cannot be
    reached, mark it unsent so that the next sweep (API or any worker) sends it at once."""
    try:
        enqueuer.enqueue(job.id, time_limit=job.time_limit, soft_time_limit=job.soft_time_limit)
    except Exception:  # noqa: BLE001 - broker down: the next sweep sends it
        log.error("sweeper: could not send job %s to the queue; next sweep retries", job.id,
                  exc_info=True)
        registry.mark_unsent(job.id)
