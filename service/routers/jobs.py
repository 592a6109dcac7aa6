"""/v1/jobs: submit, list, status, dismiss, spec."""
from __future__ import annotations

import asyncio
import datetime as dt
import hashlib
from functools import partial
from typing import Annotated

from fastapi import APIRouter, Depends, Header, Query, Request, Response
from fastapi.concurrency import run_in_threadpool

from ..deps import Services, services
from ..auth import caller
from ..problems import ProblemError, problem_responses
from ..registry import (
    RUNNING,
    STATES,
    TERMINAL_STATES,
    IdempotencyConflict,
    Job,
    utcnow,
)
from ..schemas import JobError, JobLinks, JobList, JobStatus
from ..validation import parse_body, parse_request, start_from_job, validate_case

router = APIRouter(tags=["jobs"])

# submissions validated and recorded at once; more wait (asynchronously) for a slot
SUBMIT_CONCURRENCY = 4


def _iso(value: dt.datetime | None) -> dt.datetime | None:
    return None if value is None else value.replace(tzinfo=dt.timezone.utc)


def job_status(job: Job, store_exists) -> JobStatus:
    base = f"/v1/jobs/{job.id}"
    eta = job.eta_seconds
    if job.state == RUNNING and eta is not None:
        eta = max(0.0, eta - (utcnow() - job.updated_at).total_seconds())
    error = None
    if job.state in ("failed", "dismissed"):
        error = JobError(reason=job.reason, message=job.message, time=job.failed_time,
                         step=job.failed_step)
    return JobStatus(
        id=job.id,
        kind=job.kind or "dynamic",
        name=job.name,
        state=job.state,
        reason=job.reason,
        message=job.message,
        progress=round(min(max(job.progress or 0.0, 0.0), 100.0), 3),
        sim_time=job.sim_time or 0.0,
        t_end=job.t_end,
        step=job.step or 0,
        n_steps=job.n_steps,
        grid_points=job.grid_points,
        eta_seconds=eta,
        wall_time=job.wall_time,
        created=_iso(job.created_at),
        started=_iso(job.started_at),
        finished=_iso(job.finished_at),
        updated=_iso(job.updated_at),
        worker=job.worker,
        attempts=job.attempts or 0,
        cancel_requested=bool(job.cancel_requested),
        spec_hash=job.spec_hash,
        solver_version=job.solver_version,
        time_limit=job.time_limit,
        result_available=bool(job.result_path) and store_exists(job.result_path),
        result_partial=bool(job.result_partial),
        error=error,
        links=JobLinks(self=base, spec=f"{base}/spec", results=f"{base}/results",
                       variables=f"{base}/results/variables", summary=f"{base}/summary"),
    )


def _exists(path: str) -> bool:
    import os

    return os.path.exists(path)


def get_job_or_404(svc: Services, job_id: str, owner: str | None) -> Job:
    """The job, if the caller may see it; else a 404 problem. ``owner`` is the caller's
    (:func:`service.auth.caller`): another owner's job is answered exactly as an unknown id,
    so that ids cannot be probed. ``None`` (a service without API keys) sees every job."""
    job = svc.registry.get(job_id)
    if job is None or (owner is not None and job.owner != owner):
        raise ProblemError(404, "job-not-found", "Job not found", f"no job with id {job_id}")
    return job


def _check_time_limit(time_limit: float | None, maximum: float) -> None:
    """A requested hard time limit must be a number of seconds in [1, HOCKLE_TIME_LIMIT_MAX]."""
    if time_limit is None:
        return
    if not (1.0 <= time_limit <= maximum):  # also refuses NaN
        raise ProblemError(422, "invalid-request", "Invalid request", errors=[
            {"loc": "query.time_limit",
             "msg": f"the hard time limit asked for must be 1 to {maximum:.0f} s (this "
                    f"service's HOCKLE_TIME_LIMIT_MAX), got {time_limit}",
             "type": "time_limit_out_of_range"}])


#: the Hockle-Reused header of an answer that created no job (JobStatus.reused)
REUSED_HEADER = "Hockle-Reused"


def _submit(svc: Services, body: bytes | None, content_type: str | None,
            idempotency_key: str | None, fresh: bool, time_limit: float | None = None,
            owner: str | None = None, *,
            data=None) -> tuple[Job, int, str | None, dict[str, list]]:
    """Validate, record and queue a case: ``(job, status, reused, notes)``; ``reused`` is
    None for a new job (201), else why an earlier job answers (200): ``identical_case`` or
    ``idempotency_key``; ``notes`` the answer's ``advice`` (:func:`case_advice`) and
    ``warnings`` (:func:`case_warnings`) on the case as given. The case is ``body``
    (parsed here), or ``data`` already parsed (:func:`service.validation.parse_request`)
    when ``body`` is None."""
    _check_time_limit(time_limit, svc.settings.time_limit_max)
    if body is not None:
        data = parse_body(body, content_type, svc.settings.body_parse_timeout)
    case = validate_case(data, svc.settings.max_case_size)
    start_from_job(case, svc.registry, owner)       # checked now; the worker reads it again
    hard, soft, budget = svc.settings.time_limits(case.grid_points, case.n_steps,
                                                  contact=case.contact is not None,
                                                  t_end=float(case.numerics.t_end),
                                                  requested=time_limit)
    job, status, reused = record_and_enqueue(
        svc, kind="dynamic", canonical=case.canonical_json(), spec_hash=case.spec_hash(),
        name=case.name, grid_points=case.grid_points, n_steps=case.n_steps,
        t_end=float(case.numerics.t_end), limits=(hard, soft, budget),
        idempotency_key=idempotency_key, fresh=fresh, time_limit=time_limit, owner=owner)
    return job, status, reused, {"advice": case_advice(case), "warnings": case_warnings(case)}


def case_warnings(case) -> list[dict]:
    """The plausibility warnings on a validated case (``{loc, msg, type}`` each, as a 422's
    errors: :func:`solver.plausibility.plausibility_warnings`): inputs that look wrong by a
    unit (a modulus in MPa, lengths in mm, a step far above the rod's slowest bending
    period); empty for a plausible case. The case runs as given."""
    from solver.plausibility import plausibility_warnings

    return plausibility_warnings(case)


def case_advice(case) -> list[str]:
    """The advice on a validated case as given (the run's ``hockle_advice``): a start pose
    more than a tenth of the diameter off its ``initial.centreline``
    (:meth:`solver.initial.StartOffset.advice`); empty where there is none."""
    from solver.initial import start_offset

    off = start_offset(case)
    advice = off.advice() if off is not None else None
    return [advice] if advice else []


def record_and_enqueue(svc: Services, *, kind: str, canonical: str, spec_hash: str,
                       name: str | None, grid_points: int, n_steps: int, t_end: float,
                       limits: tuple[float, float, float], idempotency_key: str | None,
                       fresh: bool, time_limit: float | None,
                       owner: str | None) -> tuple[Job, int, str | None]:
    """Record a validated job of ``kind`` (``canonical``: its spec_json) and queue it:
    ``(job, status, reused)`` as :func:`_submit` answers. An Idempotency-Key replay or
    an identical spec that already succeeded (unless ``fresh``) creates no job."""
    import solver

    version = solver.__version__
    asked = "" if time_limit is None else f"|time_limit={float(time_limit)!r}"
    fingerprint = hashlib.sha256(f"{canonical}|fresh={fresh}{asked}".encode()).hexdigest()
    if idempotency_key is not None:
        if not 1 <= len(idempotency_key) <= 200 or not idempotency_key.isprintable():
            raise ProblemError(422, "invalid-request", "Invalid request",
                               errors=[{"loc": "header.Idempotency-Key",
                                        "msg": "must be 1 to 200 printable characters",
                                        "type": "string"}])
        earlier = svc.registry.by_idempotency_key(idempotency_key, owner=owner)
        if earlier is not None:
            if earlier.request_fingerprint != fingerprint:
                raise _reuse_problem(earlier.id)
            return earlier, 200, "idempotency_key"
    if not fresh:
        cached = svc.registry.find_successful(spec_hash, version, owner=owner, kind=kind)
        if cached is not None and _exists(cached.result_path):
            return cached, 200, "identical_case"
    hard, soft, _ = limits
    try:
        job, created = svc.registry.create_job(
            spec_json=canonical,
            spec_hash=spec_hash,
            solver_version=version,
            name=name,
            grid_points=grid_points,
            n_steps=n_steps,
            t_end=t_end,
            limits=limits,
            idempotency_key=idempotency_key,
            request_fingerprint=fingerprint,
            owner=owner,
            kind=kind,
        )
    except IdempotencyConflict as exc:
        raise _reuse_problem(exc.job_id) from None
    if not created:
        return job, 200, "idempotency_key"
    # the record is committed: only now may a worker see the job
    try:
        svc.enqueuer.enqueue(job.id, time_limit=hard, soft_time_limit=soft)
    except Exception as exc:  # noqa: BLE001 - broker down: the job must not stay "accepted"
        svc.registry.mark_enqueue_failed(job.id, f"could not enqueue: {type(exc).__name__}")
        raise ProblemError(503, "broker-unavailable", "Queue unavailable",
                           "the job was recorded but could not be queued; submit it again later",
                           headers={"Retry-After": "10"}) from None
    return job, 201, None


def _reuse_problem(job_id: str) -> ProblemError:
    return ProblemError(
        422, "idempotency-key-reused", "Idempotency-Key reused",
        f"this Idempotency-Key was used for job {job_id} with a different request",
        errors=[{"loc": "header.Idempotency-Key",
                 "msg": "already used with a different case spec; use a new key",
                 "type": "idempotency_key_reused"}],
    )


def submit_slots(request: Request) -> asyncio.Semaphore:
    state = request.app.state
    if getattr(state, "submit_slots", None) is None:
        state.submit_slots = asyncio.Semaphore(SUBMIT_CONCURRENCY)
    return state.submit_slots


@router.post(
    "/jobs",
    operation_id="submit_job",
    summary="Submit a case",
    status_code=201,
    response_model=JobStatus,
    responses={
        200: {"model": JobStatus, "description": "No job created: a replay of an "
              "Idempotency-Key, or an identical spec answered from an earlier successful job "
              "(the body's `reused` and the Hockle-Reused header say which)",
              "headers": {REUSED_HEADER: {"description": "identical_case or idempotency_key",
                                          "schema": {"type": "string"}}}},
        **problem_responses(400, 413, 415, 422, 503),
    },
)
async def submit_job(
    request: Request,
    response: Response,
    svc: Annotated[Services, Depends(services)],
    owner: Annotated[str | None, Depends(caller)],
    idempotency_key: Annotated[str | None, Header(
        description="Makes retries safe: the same key and body give the same job.")] = None,
    fresh: Annotated[bool, Query(
        description="Run even if an identical spec already succeeded with this solver version.")]
    = False,
    time_limit: Annotated[float | None, Query(
        description="Hard time limit of the job in seconds, 1 to the service's "
        "HOCKLE_TIME_LIMIT_MAX; default: derived from the case's size and contact (the solver "
        "stops itself before it, keeping the partial result).")] = None,
) -> JobStatus:
    """Validate the case and queue it; answers at once (201), never runs a solve itself. An
    identical case that already succeeded (or a retried Idempotency-Key) is answered 200 with
    the earlier job, marked ``reused``."""
    # parsed on a thread of its own within its budget, never on the event loop
    data = await parse_request(request, svc.settings.body_parse_timeout)
    # a burst of submissions waits here, not in the thread pool that status polls need
    async with submit_slots(request):
        job, status, reused, notes = await run_in_threadpool(
            partial(_submit, data=data), svc, None, None, idempotency_key, fresh,
            time_limit, owner
        )
    response.status_code = status
    response.headers["Location"] = f"/v1/jobs/{job.id}"
    if reused is not None:
        response.headers[REUSED_HEADER] = reused
    return job_status(job, _exists).model_copy(update={"reused": reused, **notes})


@router.get("/jobs", operation_id="list_jobs", summary="List jobs", response_model=JobList,
            responses=problem_responses(422))
def list_jobs(
    request: Request,
    svc: Annotated[Services, Depends(services)],
    owner: Annotated[str | None, Depends(caller)],
    status: Annotated[list[str] | None, Query(
        description="Keep these states (repeat, or comma-separated).")] = None,
    created_after: Annotated[dt.datetime | None, Query(description="Created at or after.")] = None,
    created_before: Annotated[dt.datetime | None, Query(description="Created before.")] = None,
    page_size: Annotated[int, Query(ge=1, le=500)] = 50,
    page_token: Annotated[str | None, Query(description="From next_page_token.")] = None,
) -> JobList:
    """Newest first, keyset-paginated."""
    states = [s.strip() for item in (status or []) for s in item.split(",") if s.strip()]
    bad = [s for s in states if s not in STATES]
    if bad:
        raise ProblemError(422, "invalid-request", "Invalid request", errors=[
            {"loc": "query.status", "msg": f"unknown state {s!r}; allowed: {', '.join(STATES)}",
             "type": "enum"} for s in bad])
    try:
        page = svc.registry.list(states=states, created_after=_naive(created_after),
                                 created_before=_naive(created_before), page_size=page_size,
                                 page_token=page_token, owner=owner)
    except ValueError as exc:
        raise ProblemError(422, "invalid-request", "Invalid request", errors=[
            {"loc": "query.page_token", "msg": str(exc), "type": "value_error"}]) from None
    nxt = None
    if page.next_token:
        nxt = str(request.url.include_query_params(page_token=page.next_token))
    return JobList(jobs=[job_status(j, _exists) for j in page.jobs],
                   next_page_token=page.next_token, next=nxt)


def _naive(value: dt.datetime | None) -> dt.datetime | None:
    """``value`` as naive UTC (the registry's columns); an aware time whose UTC lies outside
    the years 1-9999 (``9999-12-31T23:59:59-05:00``, ``0001-01-01T00:00:00+05:00``: a 500
    before) is clamped to the nearest representable instant, which every job time lies
    within, so the filter means what it said."""
    if value is None or value.tzinfo is None:
        return value
    try:
        return value.astimezone(dt.timezone.utc).replace(tzinfo=None)
    except OverflowError:
        return dt.datetime.max if value.year == dt.MAXYEAR else dt.datetime.min


@router.get("/jobs/{job_id}", operation_id="get_job", summary="Job status",
            response_model=JobStatus, responses=problem_responses(404))
def get_job(job_id: str, svc: Annotated[Services, Depends(services)],
            owner: Annotated[str | None, Depends(caller)]) -> JobStatus:
    """State, progress 0-100, simulated time, step, ETA, timestamps, worker, error."""
    return job_status(get_job_or_404(svc, job_id, owner), _exists)


@router.delete(
    "/jobs/{job_id}",
    operation_id="dismiss_job",
    summary="Dismiss a job",
    response_model=JobStatus,
    responses={202: {"model": JobStatus, "description": "Running: it stops within one step"},
               **problem_responses(404, 409)},
)
def dismiss_job(job_id: str, response: Response,
                svc: Annotated[Services, Depends(services)],
                owner: Annotated[str | None, Depends(caller)]) -> JobStatus:
    """A queued job never starts (200, dismissed); a running one stops within one time step
    and keeps its partial result (202 now, dismissed soon)."""
    job = get_job_or_404(svc, job_id, owner)
    if job.state in TERMINAL_STATES and job.state != "dismissed":
        raise ProblemError(409, "job-finished", "Job already finished",
                           f"job {job_id} is {job.state}; only accepted or running jobs can be "
                           "dismissed")
    job = svc.registry.dismiss(job_id) or job
    if job.state == RUNNING:
        response.status_code = 202
    elif job.state in TERMINAL_STATES and job.state != "dismissed":
        raise ProblemError(409, "job-finished", "Job already finished",
                           f"job {job_id} finished ({job.state}) before it could be dismissed")
    return job_status(job, _exists)


@router.get("/jobs/{job_id}/spec", operation_id="get_job_spec", summary="Canonical case spec",
            responses=problem_responses(404))
def get_job_spec(job_id: str, svc: Annotated[Services, Depends(services)],
                 owner: Annotated[str | None, Depends(caller)]) -> Response:
    """The case spec as the service validated it: canonical JSON, defaults filled in."""
    job = get_job_or_404(svc, job_id, owner)
    return Response(job.spec_json, media_type="application/json",
                    headers={"ETag": f'"{job.spec_hash}"'})


__all__ = ["router", "job_status", "get_job_or_404", "record_and_enqueue", "submit_slots",
           "REUSED_HEADER"]
