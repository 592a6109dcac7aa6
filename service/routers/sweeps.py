"""/v1/sweeps: submit a parameter sweep, its status, dismiss it, its combined results.

A sweep is a base case and some of its fields varied (:mod:`service.sweeps`). Every member
case is validated before anything is queued; then each member becomes an ordinary job through
the same code path as ``POST /v1/jobs`` (same task, registry, dedupe of identical cases), and
the sweep (its parameters and its members' job ids) is recorded in the registry
(``hockle_sweeps``). Its state is derived from its members' job states.
"""
from __future__ import annotations

import datetime as dt
import hashlib
import json
import logging
import os
import threading
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, Depends, Query, Request, Response
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse

from .. import sweeps as sw
from ..auth import caller
from ..deps import Services, services
from ..problems import ProblemError, problem_responses
from ..registry import ACTIVE_STATES, RUNNING, Job, SweepRecord
from ..store import NETCDF_LOCK, open_result
from ..validation import parse_request, start_from_job, validate_case
from . import jobs as jobs_router
from .results import NETCDF_MEDIA_TYPE, _etag, _not_modified

router = APIRouter(tags=["sweeps"])
log = logging.getLogger(__name__)

#: combined datasets kept per sweep (one per field set asked for); beyond it the oldest
#: built go, and are built again if asked for (each spelling of ?fields= built and kept
#: another file before)
MAX_COMBINED_PER_SWEEP = 8


def _invalid(exc: sw.SweepError) -> ProblemError:
    return ProblemError(422, "invalid-sweep", "Invalid sweep", exc.detail, errors=exc.errors)


def _member(svc: Services, doc, owner: str | None):
    """One member's validated case, its start from an earlier job checked too."""
    case = validate_case(doc, svc.settings.max_case_size)
    start_from_job(case, svc.registry, owner)
    return case


def _create(svc: Services, data, fresh: bool, time_limit: float | None,
            owner: str | None) -> tuple[SweepRecord, dict[str, Job]]:
    try:
        base, parameters, combine, name = sw.parse_request(data)
        members = sw.expand(base, parameters, combine)
    except sw.SweepError as exc:
        raise _invalid(exc) from None
    jobs_router._check_time_limit(time_limit, svc.settings.time_limit_max)
    try:
        # every member first: a bad value anywhere queues nothing
        cases = sw.validate_members(members, lambda doc: _member(svc, doc, owner))
    except sw.SweepError as exc:
        raise _invalid(exc) from None
    job_ids: list[str] = []
    jobs: dict[str, Job] = {}
    by_hash: dict[str, str] = {}
    created: list[str] = []
    try:
        for member, case in zip(members, cases):
            known = by_hash.get(case.spec_hash())
            if known is not None:          # the same case twice in one sweep: one job
                job_ids.append(known)
                continue
            extra = {"owner": owner} if owner is not None else {}
            job, status, _, _ = jobs_router._submit(svc, body=case.canonical_json().encode(),
                                                 content_type="application/json",
                                                 idempotency_key=None, fresh=fresh,
                                                 time_limit=time_limit, **extra)
            if status == 201:
                created.append(job.id)
            by_hash[case.spec_hash()] = job.id
            job_ids.append(job.id)
            jobs[job.id] = job
        sweep = svc.registry.create_sweep(
            name=name or str(base.get("name") or "")[:200] or None, combine=combine,
            parameters=sw.normalize_parameters(parameters), job_ids=job_ids,
            base_json=json.dumps(base, sort_keys=True), owner=owner)
    except Exception:
        # the broker or the registry went away midway: the members this request queued
        # must not run alone, outside any sweep (earlier jobs it reused are left alone)
        _dismiss_created(svc, created)
        raise
    return sweep, jobs


def _dismiss_created(svc: Services, job_ids: list[str]) -> None:
    """Dismiss the jobs a failed sweep submission created, each on its own (best effort:
    one the registry cannot dismiss now stays queued and is logged); the submission's own
    error is the answer."""
    for job_id in job_ids:
        try:
            svc.registry.dismiss(job_id)
        except Exception:  # noqa: BLE001 - best effort; the original error is raised
            log.warning("could not dismiss job %s of a failed sweep submission", job_id,
                        exc_info=True)


def sweep_status(sweep: SweepRecord, jobs: dict[str, Job]) -> sw.SweepStatus:
    """The status body of a sweep from its record and its member jobs."""
    parameters = sweep.parameters
    values = sw.member_values(parameters, sweep.combine)
    rows, states, progress = [], [], []
    for index, (member, job_id) in enumerate(zip(values, sweep.job_ids)):
        job = jobs.get(job_id)
        state = job.state if job is not None else "failed"
        done = 100.0 if state in ("successful", "failed", "dismissed") else float(
            min(max((job.progress if job is not None else 0.0) or 0.0, 0.0), 100.0))
        rows.append(sw.SweepMember(index=index, values=member, job_id=job_id,
                                   state=state, reason=job.reason if job is not None
                                   else "internal_error", progress=round(done, 3),
                                   message=job.message if job is not None else None))
        states.append(state)
        progress.append(done)
    counts = {s: states.count(s) for s in sw.STATES if states.count(s)}
    state = sw.sweep_state(states, dismissed=sweep.dismissed_at is not None)
    shape = ([len(v) for v in parameters.values()] if sweep.combine == "grid"
             else [len(values)])
    base = f"/v1/sweeps/{sweep.id}"
    return sw.SweepStatus(
        id=sweep.id, name=sweep.name, state=state,
        progress=round(sum(progress) / max(len(progress), 1), 3), combine=sweep.combine,
        shape=shape, parameters=[sw.SweepParameter(path=p, values=v)
                                 for p, v in parameters.items()],
        counts=counts, members=rows, created=sweep.created_at.replace(tzinfo=dt.timezone.utc),
        dismissed=sweep.dismissed_at is not None,
        result_available=all(s not in ACTIVE_STATES for s in states),
        links=sw.SweepLinks(self=base, results=f"{base}/results"))


def _sweep_or_404(svc: Services, sweep_id: str, owner: str | None) -> SweepRecord:
    sweep = svc.registry.get_sweep(sweep_id)
    if sweep is None or (owner is not None and sweep.owner != owner):
        raise ProblemError(404, "sweep-not-found", "Sweep not found",
                           f"no sweep with id {sweep_id}")
    return sweep


@router.post(
    "/sweeps",
    operation_id="submit_sweep",
    summary="Submit a parameter sweep",
    status_code=201,
    response_model=sw.SweepStatus,
    responses=problem_responses(400, 413, 415, 422, 503),
)
async def submit_sweep(
    request: Request,
    response: Response,
    svc: Annotated[Services, Depends(services)],
    owner: Annotated[str | None, Depends(caller)],
    fresh: Annotated[bool, Query(
        description="Run every member even if an identical case already succeeded.")] = False,
    time_limit: Annotated[float | None, Query(
        description="Hard time limit of each member job in seconds (as POST /v1/jobs).")] = None,
) -> sw.SweepStatus:
    """``{"base": CASE, "parameters": {PATH: [values...]}, "combine": "grid" | "zip"}``.
    Every member is validated first (a 422 names the member, its values and the field, and
    nothing is queued); then one job per member is queued as ``POST /v1/jobs`` does."""
    # parsed on a thread of its own within its budget (it was parsed on the event loop: a
    # 383-byte alias bomb held every request, liveness too, for 23-29 s)
    data = await parse_request(request, svc.settings.body_parse_timeout)
    async with jobs_router.submit_slots(request):
        sweep, jobs = await run_in_threadpool(_create, svc, data, fresh, time_limit, owner)
    response.headers["Location"] = f"/v1/sweeps/{sweep.id}"
    missing = [j for j in sweep.job_ids if j not in jobs]
    if missing:
        jobs.update(svc.registry.get_many(missing))
    return sweep_status(sweep, jobs)


@router.get("/sweeps/{sweep_id}", operation_id="get_sweep", summary="Sweep status",
            response_model=sw.SweepStatus, responses=problem_responses(404))
def get_sweep(sweep_id: str, svc: Annotated[Services, Depends(services)],
              owner: Annotated[str | None, Depends(caller)]) -> sw.SweepStatus:
    """State (the job states' vocabulary), progress, counts per state, each member's state."""
    sweep = _sweep_or_404(svc, sweep_id, owner)
    return sweep_status(sweep, svc.registry.get_many(sweep.job_ids))


@router.delete(
    "/sweeps/{sweep_id}",
    operation_id="dismiss_sweep",
    summary="Dismiss a sweep",
    response_model=sw.SweepStatus,
    responses={202: {"model": sw.SweepStatus,
                     "description": "Some members were running: they stop within a step"},
               **problem_responses(404, 409)},
)
def dismiss_sweep(sweep_id: str, response: Response,
                  svc: Annotated[Services, Depends(services)],
                  owner: Annotated[str | None, Depends(caller)]) -> sw.SweepStatus:
    """Queued members never start, running ones stop within one time step (202); finished
    members keep their results. 409 when every member had already finished."""
    sweep = _sweep_or_404(svc, sweep_id, owner)
    jobs = svc.registry.get_many(sweep.job_ids)
    if sweep.dismissed_at is None and not any(j.state in ACTIVE_STATES for j in jobs.values()):
        raise ProblemError(409, "sweep-finished", "Sweep already finished",
                           f"every member of sweep {sweep_id} has finished; nothing to dismiss")
    svc.registry.mark_sweep_dismissed(sweep_id)
    for job_id, job in jobs.items():
        if job.state in ACTIVE_STATES:
            svc.registry.dismiss(job_id)
    sweep = svc.registry.get_sweep(sweep_id) or sweep
    jobs = svc.registry.get_many(sweep.job_ids)
    if any(j.state == RUNNING for j in jobs.values()):
        response.status_code = 202
    return sweep_status(sweep, jobs)


def canonical_fields(fields: str | None) -> list[str]:
    """The field set of ``?fields=``: its names, stripped, once each, sorted; ``kappa``,
    ``kappa,kappa`` and ``kappa, kappa`` are one set, one combined file."""
    return sorted({f.strip() for f in (fields or "").split(",") if f.strip()})


def _combined_path(svc: Services, sweep: SweepRecord, fields: list[str]) -> Path:
    key = hashlib.sha256(",".join(fields).encode()).hexdigest()[:12]
    return Path(svc.settings.results_dir) / "sweeps" / f"{sweep.id}.{key}.nc"


def _evict_combined(path: Path, keep: int | None = None) -> None:
    """Remove the sweep's combined files beyond the ``keep`` most recently built (by
    mtime; not touched when served, which would change their ETag); never ``path``, the
    one being answered. ``keep``: default :data:`MAX_COMBINED_PER_SWEEP`."""
    keep = MAX_COMBINED_PER_SWEEP if keep is None else keep
    mine = []
    for other in path.parent.glob(f"{path.name.split('.', 1)[0]}.*.nc"):
        try:
            mine.append((other.stat().st_mtime, other))
        except FileNotFoundError:        # removed by another request meanwhile
            continue
    mine.sort(reverse=True)
    for _, other in mine[keep:]:
        if other != path:
            other.unlink(missing_ok=True)


def _load_member(job: Job | None):
    if job is None or not job.result_path or not os.path.exists(job.result_path):
        return None
    with open_result(job.result_path) as ds:
        return ds.load()


@router.get(
    "/sweeps/{sweep_id}/results",
    operation_id="download_sweep_results",
    summary="The combined NetCDF dataset of a finished sweep",
    response_class=FileResponse,
    responses={200: {"content": {NETCDF_MEDIA_TYPE: {}}, "description": "NetCDF4 dataset"},
               304: {"description": "Not modified (If-None-Match)"},
               **problem_responses(404, 422)},
)
def download_sweep_results(
    sweep_id: str,
    request: Request,
    svc: Annotated[Services, Depends(services)],
    owner: Annotated[str | None, Depends(caller)],
    fields: Annotated[str | None, Query(
        description="Full (time, s, ...) fields to add, comma-separated (position, kappa, "
        "...); the scalar series and event times are always there.")] = None,
) -> Response:
    """One dataset: a dimension per varied parameter (grid) or ``member`` (zip), the members'
    scalar series over time, event times, ``member_status`` (a failed member is marked, its
    values NaN). Built once every member has finished (404 ``result-not-ready`` before) and
    kept beside the members' results."""
    sweep = _sweep_or_404(svc, sweep_id, owner)
    jobs = svc.registry.get_many(sweep.job_ids)
    active = [j for j in sweep.job_ids if j not in jobs or jobs[j].state in ACTIVE_STATES]
    if any(j in jobs for j in active):
        raise ProblemError(404, "result-not-ready", "Result not ready",
                           f"sweep {sweep_id} has {len(set(active))} member job(s) still queued "
                           "or running; the combined dataset is built when all have finished")
    wanted = canonical_fields(fields)
    path = _combined_path(svc, sweep, wanted)
    if not path.exists():
        _build(svc, sweep, jobs, wanted, path)
        _evict_combined(path)
    etag = _etag(str(path))
    if _not_modified(request, etag):
        return Response(status_code=304, headers={"ETag": etag})
    return FileResponse(path, media_type=NETCDF_MEDIA_TYPE, filename=f"sweep-{sweep.id}.nc",
                        headers={"ETag": etag, "Cache-Control": "private, max-age=0"})


def _build(svc: Services, sweep: SweepRecord, jobs: dict[str, Job], fields: list[str],
           path: Path) -> None:
    values = sw.member_values(sweep.parameters, sweep.combine)
    loaded: dict[str, object] = {}
    results = []
    for index, (member, job_id) in enumerate(zip(values, sweep.job_ids)):
        job = jobs.get(job_id)
        if job_id not in loaded:
            loaded[job_id] = _load_member(job)
        results.append(sw.MemberResult(
            index=index, values=member,
            state=job.state if job is not None else "failed", dataset=loaded[job_id],
            job_id=job_id, message=(job.message or "") if job is not None else ""))
    try:
        ds = sw.combine_results(results, sweep.parameters, sweep.combine, fields=fields,
                                attrs={"id": sweep.id, "hockle_sweep_id": sweep.id,
                                       "hockle_sweep_name": sweep.name})
    except sw.SweepError as exc:
        raise _invalid(exc) from None
    # beside the members' results, written under a temporary name and renamed (as they are)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.name}.tmp-{os.getpid()}-{threading.get_ident()}")
    try:
        with NETCDF_LOCK:
            ds.to_netcdf(tmp, engine="netcdf4")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


__all__ = ["router", "sweep_status"]
