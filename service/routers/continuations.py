"""/v1/continuations: submit a continuation job (a case's static branch in one parameter;
service/continuations.py). The job is then an ordinary job: its status, dismissal, spec and
result are under /v1/jobs/{id}."""
from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Header, Query, Request, Response
from fastapi.concurrency import run_in_threadpool

from ..auth import caller
from ..continuations import (KIND, POINT_COST_STEPS, canonical_request, request_body_schema,
                             request_hash, validate_request)
from ..deps import Services, services
from ..problems import problem_responses
from ..registry import Job
from ..schemas import JobStatus
from ..validation import parse_request
from .jobs import (REUSED_HEADER, _check_time_limit, _exists, job_status, record_and_enqueue,
                   submit_slots)

router = APIRouter(tags=["continuations"])


def _submit(svc: Services, data, idempotency_key: str | None, fresh: bool,
            time_limit: float | None, owner: str | None) -> tuple[Job, int, str | None]:
    """Validate (``data``: the parsed body), record and queue a continuation."""
    _check_time_limit(time_limit, svc.settings.time_limit_max)
    case, options = validate_request(data, svc.settings.max_case_size)
    canonical = canonical_request(case, options)
    limits = svc.settings.time_limits(case.grid_points, POINT_COST_STEPS * options.max_points,
                                      requested=time_limit)
    t_read = float(case.numerics.t_end if options.time is None else options.time)
    return record_and_enqueue(
        svc, kind=KIND, canonical=canonical, spec_hash=request_hash(canonical), name=case.name,
        grid_points=case.grid_points, n_steps=options.max_points, t_end=t_read, limits=limits,
        idempotency_key=idempotency_key, fresh=fresh, time_limit=time_limit, owner=owner)


@router.post(
    "/continuations",
    operation_id="submit_continuation",
    summary="Submit a continuation (a static branch of a case)",
    status_code=201,
    response_model=JobStatus,
    responses={
        200: {"model": JobStatus, "description": "No job created: an Idempotency-Key replay, "
              "or an identical request answered from an earlier successful job"},
        **problem_responses(400, 413, 415, 422, 503),
    },
    openapi_extra={"requestBody": {"required": True, "content": {
        "application/json": {"schema": request_body_schema()},
        "application/yaml": {"schema": request_body_schema()}}}},
)
async def submit_continuation(
    request: Request,
    response: Response,
    svc: Annotated[Services, Depends(services)],
    owner: Annotated[str | None, Depends(caller)],
    idempotency_key: Annotated[str | None, Header(
        description="Makes retries safe: the same key and body give the same job.")] = None,
    fresh: Annotated[bool, Query(
        description="Run even if an identical request already succeeded.")] = False,
    time_limit: Annotated[float | None, Query(
        description="Hard time limit of the job in seconds, 1 to HOCKLE_TIME_LIMIT_MAX; "
        "default: that of a dynamic case of 20 steps per point of max_points.")] = None,
) -> JobStatus:
    """Validate the case and the continuation (a parameter that is not a scalar of the case,
    a range that does not move, a case the static problem does not support: 422 naming the
    field) and queue a job of kind ``continuation``; answers at once (201). Its result, at
    /v1/jobs/{id}/results, is the branch dataset (dimension ``point``; docs/statics.md);
    ``step`` in its status counts the points done."""
    data = await parse_request(request, svc.settings.body_parse_timeout)
    async with submit_slots(request):
        job, status, reused = await run_in_threadpool(
            _submit, svc, data, idempotency_key, fresh, time_limit, owner)
    response.status_code = status
    response.headers["Location"] = f"/v1/jobs/{job.id}"
    if reused is not None:
        response.headers[REUSED_HEADER] = reused
    return job_status(job, _exists).model_copy(update={"reused": reused})


__all__ = ["router"]
