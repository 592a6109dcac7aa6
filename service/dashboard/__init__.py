"""The browser dashboard at ``/ui/``: jobs, a job's results, sweeps and submission.

The pages are static files shipped in this package (``static/``: HTML, CSS and plain
JavaScript, no build step) and one vendored library, uPlot (MIT, ``static/vendor/``); they
talk to the REST API with the API key the user types once per browser session (kept in
``sessionStorage``, sent as ``Authorization: Bearer``). The files are public, as the API docs
are; every piece of data they show comes from authenticated routes.

Served with a Content-Security-Policy (:data:`CSP`) that allows scripts, styles, images and
connections from this origin only and no inline script, so a job name holding markup can
neither run nor load anything even if a page bug rendered it as HTML (the pages render every
user string with ``textContent``).

The few routes the pages need beyond ``/v1`` live here, under ``/v1/ui/`` (authenticated
and owner-filtered like every ``/v1`` route, left out of the OpenAPI document):

* ``GET /v1/ui/jobs``: ``GET /v1/jobs`` with an ``ETag`` of the page, answering 304 to
  ``If-None-Match`` (the jobs page polls it every few seconds);
* ``GET /v1/ui/jobs/{id}/events``: the run's events (:func:`solver.results.run_events`)
  with their times and Tw, Wr, Lk there;
* ``GET /v1/ui/jobs/{id}/seabed``: the sea floor under the rod, sampled on a grid for the
  3-D view (``null`` when the case has none);
* ``GET /v1/ui/jobs/{id}/branch``: a continuation job's branch (service/branch_view.py):
  the parameter and its unit, the measures for the bifurcation diagram, the mode counts,
  the folds and branch points;
* ``GET /v1/ui/jobs/{id}/paraview``: the result as a zipped ParaView series (a run's
  output times, a branch's shapes);
* ``POST /v1/ui/validate``: the case validated as ``POST /v1/jobs`` validates it (the same
  422 problem), nothing recorded or queued;
* ``GET /v1/ui/sweeps/{id}/map``: each member's parameter values, state and event times, the
  threshold map of a sweep while members still run.

``GET /ui/config`` (public) says whether the service has API keys.
"""
from __future__ import annotations

import hashlib
import json
import os
import threading
from collections import OrderedDict
from pathlib import Path
from typing import Annotated, Any

import orjson
from fastapi import APIRouter, Depends, FastAPI, Query, Request, Response
from fastapi.responses import JSONResponse, RedirectResponse
from fastapi.staticfiles import StaticFiles
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from ..deps import Services, known_query_only, services
from ..auth import caller
from ..problems import ProblemError
from ..store import open_result
from ..routers.results import _not_modified
from ..validation import parse_request, validate_case

__all__ = ["UI_URL", "UI_API_PREFIX", "CSP", "STATIC_DIR", "install_dashboard"]

UI_URL = "/ui"
UI_API_PREFIX = "/v1/ui"
STATIC_DIR = Path(__file__).resolve().parent / "static"

#: Content-Security-Policy of every /ui/ response: this origin only, no inline script or
#: style element, no plugins, no framing, no <base> rewriting.
CSP = ("default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data: blob:; "
       "connect-src 'self'; font-src 'self'; manifest-src 'self'; base-uri 'none'; "
       "form-action 'self'; frame-ancestors 'none'; object-src 'none'")
SECURITY_HEADERS = (
    (b"content-security-policy", CSP.encode()),
    (b"x-content-type-options", b"nosniff"),
    (b"referrer-policy", b"no-referrer"),
    (b"x-frame-options", b"DENY"),
    (b"cache-control", b"no-cache"),
)

# a misspelt query parameter is a 422 naming it, as on the /v1 API
router = APIRouter(include_in_schema=False, dependencies=[Depends(known_query_only)])


class _SecurityHeaders:
    """ASGI wrapper: add :data:`SECURITY_HEADERS` to every response of the wrapped app."""

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                names = {name for name, _ in SECURITY_HEADERS}
                headers = [(k, v) for k, v in message.get("headers", []) if k.lower() not in names]
                message = {**message, "headers": headers + list(SECURITY_HEADERS)}
            await send(message)

        await self.app(scope, receive, send_with_headers)


def install_dashboard(app: FastAPI) -> None:
    """Add the dashboard to ``app``: the ``/v1/ui`` routes, ``GET /ui/config`` and the static
    pages under ``/ui/`` (public: add ``UI_URL + "/"`` to the auth middleware's public
    prefixes). Raises ``RuntimeError`` when the package lacks its static files."""
    index = STATIC_DIR / "index.html"
    if not index.is_file():
        raise RuntimeError(f"the dashboard's files are missing from {STATIC_DIR}: reinstall hockle")
    app.include_router(router)

    @app.get(UI_URL, include_in_schema=False)
    def _ui_root(request: Request) -> RedirectResponse:
        root = request.scope.get("root_path", "")
        return RedirectResponse(f"{root}{UI_URL}/", status_code=307)

    @app.get(f"{UI_URL}/config", include_in_schema=False)
    def _ui_config(request: Request) -> Response:
        body = {"auth": bool(getattr(request.app.state, "auth_enabled", False)),
                "api": "/v1", "version": request.app.version}
        return Response(orjson.dumps(body), media_type="application/json",
                        headers={k.decode(): v.decode() for k, v in SECURITY_HEADERS})

    app.mount(UI_URL, _SecurityHeaders(StaticFiles(directory=STATIC_DIR, html=True)),
              name="dashboard")


# --------------------------------------------------------------------------- jobs, polled


def _etag_of(body: bytes) -> str:
    return '"' + hashlib.sha256(body).hexdigest()[:32] + '"'


@router.get(f"{UI_API_PREFIX}/jobs")
def ui_list_jobs(
    request: Request,
    svc: Annotated[Services, Depends(services)],
    owner: Annotated[str | None, Depends(caller)],
    status: Annotated[str | None, Query()] = None,
    page_size: Annotated[int, Query(ge=1, le=500)] = 50,
    page_token: Annotated[str | None, Query()] = None,
) -> Response:
    """``GET /v1/jobs`` (newest first, keyset pages) with an ETag of the page's body: an
    unchanged page answers 304 with no body. Each job also has ``sweep_id``: the newest sweep
    it is a member of, or null (:meth:`service.registry.Registry.sweeps_of`). ``status``: states, comma-separated; 422 naming
    ``query.status`` or ``query.page_token`` as ``GET /v1/jobs`` does."""
    from ..registry import STATES
    from ..routers.jobs import _exists, job_status

    states = [s.strip() for s in (status or "").split(",") if s.strip()]
    bad = [s for s in states if s not in STATES]
    if bad:
        raise ProblemError(422, "invalid-request", "Invalid request", errors=[
            {"loc": "query.status", "msg": f"unknown state {s!r}; allowed: {', '.join(STATES)}",
             "type": "enum"} for s in bad])
    try:
        page = svc.registry.list(states=states, page_size=page_size, page_token=page_token,
                                 owner=owner)
    except ValueError as exc:
        raise ProblemError(422, "invalid-request", "Invalid request", errors=[
            {"loc": "query.page_token", "msg": str(exc), "type": "value_error"}]) from None
    jobs = [job_status(j, _exists).model_dump(mode="json") for j in page.jobs]
    member_of = svc.registry.sweeps_of(page.jobs, owner)
    for item in jobs:  # the ETA counts down between polls; whole seconds keep 304s possible
        if item.get("eta_seconds") is not None:
            item["eta_seconds"] = round(item["eta_seconds"])
        item["sweep_id"] = member_of.get(item["id"])     # the kind column: a sweep's member
    body = orjson.dumps({"jobs": jobs, "next_page_token": page.next_token})
    etag = _etag_of(body)
    headers = {"ETag": etag, "Cache-Control": "private, no-cache"}
    if _not_modified(request, etag):
        return Response(status_code=304, headers=headers)
    return Response(body, media_type="application/json", headers=headers)


# --------------------------------------------------------------------------- events

_EVENT_CACHE: OrderedDict[tuple[str, int, int], dict] = OrderedDict()
_EVENT_CACHE_SIZE = 2048
_EVENT_LOCK = threading.Lock()
_AT_EVENT = ("twist", "writhe", "linking_number", "energy_total")


def result_events(path: str) -> dict[str, Any]:
    """The events of the result file at ``path``: ``{"time": [...], "events": [{"name",
    "label", "index", "time" (s), "twist", "writhe", "linking_number", "energy_total"},
    ...]}`` (an event that did not happen has ``index`` and ``time`` None), by
    :func:`solver.results.run_events` (the rules of ``hockle plot`` and of a sweep's
    ``event_time``), in the order they happened, each ``label`` the words ``hockle run``
    prints for it (:func:`solver.results.event_label`). Cached per file (path, size,
    mtime)."""
    st = os.stat(path)
    key = (path, st.st_size, st.st_mtime_ns)
    with _EVENT_LOCK:
        if key in _EVENT_CACHE:
            _EVENT_CACHE.move_to_end(key)
            return _EVENT_CACHE[key]
    import numpy as np
    from solver.results import event_label, run_events

    with open_result(path, cache=False) as ds:
        found = run_events(ds)
        time = np.asarray(ds["time"].values, dtype=float) if "time" in ds.coords else np.array([])
        at = {name: np.asarray(ds[name].values, dtype=float) for name in _AT_EVENT if name in ds}
    events = []
    for name, index in found.items():
        item: dict[str, Any] = {"name": name, "label": event_label(name), "index": index,
                                "time": None if index is None else _num(time[index])}
        for var, values in at.items():
            item[var] = None if index is None else _num(values[index])
        events.append(item)
    out = {"events": events, "n_times": int(time.size)}
    with _EVENT_LOCK:
        _EVENT_CACHE[key] = out
        while len(_EVENT_CACHE) > _EVENT_CACHE_SIZE:
            _EVENT_CACHE.popitem(last=False)
    return out


def _num(value) -> float | None:
    import math

    value = float(value)
    return value if math.isfinite(value) else None


def _result_file(svc: Services, job_id: str, owner: str | None):
    """The job (the caller's) and its result file; 404 ``result-not-ready`` before there is
    one."""
    from ..routers.jobs import get_job_or_404

    job = get_job_or_404(svc, job_id, owner)
    if not job.result_path or not os.path.exists(job.result_path):
        raise ProblemError(404, "result-not-ready", "Result not ready",
                           f"job {job.id} is {job.state} and has no result file")
    return job


def _branch_problem(job) -> ProblemError:
    return ProblemError(409, "result-is-a-branch", "The result is a branch",
                        f"job {job.id} is a {job.kind} job: its result is a branch of "
                        "equilibria over a parameter, not a time history; its events and "
                        f"mode counts are at /v1/ui/jobs/{job.id}/branch")


@router.get(f"{UI_API_PREFIX}/jobs/{{job_id}}/events")
def ui_job_events(job_id: str, svc: Annotated[Services, Depends(services)],
                  owner: Annotated[str | None, Depends(caller)]) -> JSONResponse:
    """The events of the job's result (404 ``result-not-ready`` before there is one; 409
    ``result-is-a-branch`` for a continuation job, whose events are those of
    ``/v1/ui/jobs/{id}/branch``)."""
    job = _result_file(svc, job_id, owner)
    if (job.kind or "dynamic") != "dynamic":
        raise _branch_problem(job)
    return JSONResponse({"job_id": job.id, **result_events(job.result_path)})


_BRANCH_CACHE: OrderedDict[tuple[str, int, int], dict] = OrderedDict()
_BRANCH_CACHE_SIZE = 256


def result_branch(path: str) -> dict[str, Any]:
    """The branch of the result file at ``path`` as the dashboard draws it
    (:func:`service.branch_view.overview`: the parameter with its unit, per point the
    unstable modes, the part of the branch and whether its shape is stored, the measures
    with round-off as zero, the folds and branch points with the mode counts on either
    side). Cached per file (path, size, mtime). Raises ValueError for a result that is not
    a branch."""
    st = os.stat(path)
    key = (path, st.st_size, st.st_mtime_ns)
    with _EVENT_LOCK:
        if key in _BRANCH_CACHE:
            _BRANCH_CACHE.move_to_end(key)
            return _BRANCH_CACHE[key]
    from ..branch_view import is_branch, overview

    with open_result(path, cache=False) as ds:
        if not is_branch(ds):
            raise ValueError("the result is a run over time, not a branch")
        out = overview(ds.load())
    with _EVENT_LOCK:
        _BRANCH_CACHE[key] = out
        while len(_BRANCH_CACHE) > _BRANCH_CACHE_SIZE:
            _BRANCH_CACHE.popitem(last=False)
    return out


@router.get(f"{UI_API_PREFIX}/jobs/{{job_id}}/branch")
def ui_job_branch(job_id: str, svc: Annotated[Services, Depends(services)],
                  owner: Annotated[str | None, Depends(caller)]) -> Response:
    """A continuation job's branch for its page (:func:`result_branch`): ``{"job_id",
    "parameter": {"path", "unit", "label", "values", "start", "target"}, "n_points",
    "n_segments", "stopped", "switched_at", "unstable_modes", "branch", "stored",
    "measures": [{"name", "label", "units", "constant", "values"}], "events": [{"kind",
    "label", "parameter", "after", "simple", "modes_before", "modes_after",
    "switched_here"}]}``. 404 ``result-not-ready`` before there is a result (a running
    job's points so far are in its checkpoint, not yet in a file); 409 ``result-is-a-run``
    for a job whose result is a time history."""
    job = _result_file(svc, job_id, owner)
    try:
        body = result_branch(job.result_path)
    except ValueError as exc:
        raise ProblemError(409, "result-is-a-run", "The result is a run",
                           f"job {job.id}'s result is a run over time: {exc}") from None
    return Response(orjson.dumps({"job_id": job.id, **body}), media_type="application/json")


#: the bottom is sampled on this many points a side for the 3-D view (at most)
SEABED_GRID_MAX = 65
#: at most this many output times are read to find the rod's x-y extent
SEABED_EXTENT_TIMES = 200


def result_seabed(path: str, n: int = 25) -> dict[str, Any] | None:
    """The sea floor of the result file at ``path`` for the 3-D view, or None when its case
    has no seabed: ``{"kind": "elevation" | "bathymetry", "x": (n,), "y": (n,), "z": (n, n)}``
    (m, global; ``z[i][j]`` the bottom's elevation at ``x[i]``, ``y[j]``, from
    :meth:`solver.case.Seabed.bottom`: the flat plane, or the bilinear bathymetry held
    outside its grid) over the x-y box of the rod at every stored time (at most
    :data:`SEABED_EXTENT_TIMES` of them, evenly spread), widened on each side by a tenth of
    its larger side and at least 5 diameters. Raises ValueError when the result stores no
    position."""
    import numpy as np

    from solver.case import Seabed

    with open_result(path, cache=False) as ds:
        case = json.loads(str(ds.attrs.get("case") or "{}"))
        if not case.get("seabed"):
            return None
        seabed = Seabed.model_validate(case["seabed"])
        if "position" not in ds or not ds.sizes.get("time", 0):
            raise ValueError("the result stores no position (output.fields), so the rod's "
                             "extent over the bottom is unknown")
        stride = max(1, -(-ds.sizes["time"] // SEABED_EXTENT_TIMES))
        pos = ds["position"].isel(time=slice(None, None, stride)).transpose(..., "xyz")
        xy = np.asarray(pos.values, dtype=float).reshape(-1, 3)[:, :2]
    xy = xy[np.isfinite(xy).all(axis=1)]
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    d = case["rod"]["diameter"]
    dmax = float(np.max(d["value"])) if isinstance(d, dict) else float(d)
    pad = max(0.1 * float(np.max(hi - lo)), 5.0 * dmax)
    x = np.linspace(lo[0] - pad, hi[0] + pad, n)
    y = np.linspace(lo[1] - pad, hi[1] + pad, n)
    z = seabed.bottom(*np.meshgrid(x, y, indexing="ij"))
    return {"kind": "elevation" if seabed.bathymetry is None else "bathymetry",
            "x": x.tolist(), "y": y.tolist(), "z": np.asarray(z, dtype=float).tolist()}


@router.get(f"{UI_API_PREFIX}/jobs/{{job_id}}/seabed")
def ui_job_seabed(job_id: str, svc: Annotated[Services, Depends(services)],
                  owner: Annotated[str | None, Depends(caller)],
                  n: Annotated[int, Query(ge=2, le=SEABED_GRID_MAX)] = 25) -> JSONResponse:
    """The sea floor under the job's rod for the 3-D view (:func:`result_seabed`, an ``n`` x
    ``n`` grid): ``{"job_id", "seabed": {...}}``, ``"seabed": null`` when the case has none.
    404 ``result-not-ready`` before there is a result; 422 naming ``query.n`` outside 2..65;
    422 ``not-drawable`` for a result without positions."""
    from ..routers.jobs import get_job_or_404

    job = get_job_or_404(svc, job_id, owner)
    if not job.result_path or not os.path.exists(job.result_path):
        raise ProblemError(404, "result-not-ready", "Result not ready",
                           f"job {job.id} is {job.state} and has no result file")
    try:
        seabed = result_seabed(job.result_path, n)
    except ValueError as exc:
        raise ProblemError(422, "not-drawable", "Seabed not drawable", str(exc)) from None
    return JSONResponse({"job_id": job.id, "seabed": seabed})


#: at most this many frames in a ParaView download (every k-th output time, the last kept)
PARAVIEW_MAX_FRAMES = 100


@router.get(f"{UI_API_PREFIX}/jobs/{{job_id}}/paraview")
def ui_job_paraview(job_id: str, svc: Annotated[Services, Depends(services)],
                    owner: Annotated[str | None, Depends(caller)]) -> Response:
    """The job's result as a ParaView series, zipped: ``<id>.pvd`` and its ``.vtu`` frames
    (:func:`service.export.export_vtk`, the function behind ``hockle export``), at most
    :data:`PARAVIEW_MAX_FRAMES` frames (every k-th output time, the last one kept; of a
    continuation job's branch, every k-th stored shape over its points). 404
    ``result-not-ready`` before there is a result; 422 ``not-exportable`` with the reason
    for a result without positions (a branch without stored shapes)."""
    import io
    import tempfile
    import zipfile

    from ..branch_view import is_branch
    from ..export import ExportError, export_vtk
    from ..routers.jobs import get_job_or_404

    job = get_job_or_404(svc, job_id, owner)
    if not job.result_path or not os.path.exists(job.result_path):
        raise ProblemError(404, "result-not-ready", "Result not ready",
                           f"job {job.id} is {job.state} and has no result file")
    with open_result(job.result_path) as ds:
        branch = is_branch(ds)
        dim = "point" if branch else "time"
        names = (("position", "kappa", "parameter", "unstable_modes") if branch else
                 ("position", "kappa", "f", "v", "omega", "moment", "orientation"))
        keep = [v for v in names if v in ds]
        loaded = ds[keep].load()
        loaded.attrs.update(ds.attrs)
        if branch and "position" in loaded:
            import numpy as np

            r = np.asarray(loaded["position"].values, float)
            n_frames = int(np.isfinite(r.reshape(r.shape[0], -1)).all(axis=1).sum())
        else:
            n_frames = ds.sizes.get(dim, 0)
    # every k-th frame and the last: floor((n-1)/k) + 1, plus one where k does not divide
    # n-1, is at most PARAVIEW_MAX_FRAMES for k = ceil((n-1)/(max-1))
    stride = max(1, -(-(n_frames - 1) // max(PARAVIEW_MAX_FRAMES - 1, 1)))
    buffer = io.BytesIO()
    with tempfile.TemporaryDirectory() as tmp:
        try:
            files = export_vtk(loaded, os.path.join(tmp, f"{job.id}.pvd"), stride=stride)
        except ExportError as exc:
            raise ProblemError(422, "not-exportable", "Result not exportable", str(exc)) from None
        with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as zf:
            for f in files:
                zf.write(f, os.path.relpath(f, tmp))
    return Response(buffer.getvalue(), media_type="application/zip",
                    headers={"Content-Disposition": f'attachment; filename="{job.id}-paraview.zip"'})


# --------------------------------------------------------------------------- validation


@router.post(f"{UI_API_PREFIX}/validate")
async def ui_validate(request: Request, svc: Annotated[Services, Depends(services)]) -> Response:
    """Validate a case as ``POST /v1/jobs`` does (JSON, or YAML by Content-Type) without
    recording or queueing anything: 200 with its name, size and plausibility warnings
    (``warnings``: ``{loc, msg, type}`` each, the submission's), or the same
    400/413/415/422 problem the submission would get."""
    from fastapi.concurrency import run_in_threadpool

    data = await parse_request(request, svc.settings.body_parse_timeout)

    def check():
        from solver.plausibility import plausibility_warnings

        case = validate_case(data, svc.settings.max_case_size)
        return {"valid": True, "name": case.name, "grid_points": case.grid_points,
                "n_steps": case.n_steps, "t_end": float(case.numerics.t_end),
                "warnings": plausibility_warnings(case)}

    return Response(orjson.dumps(await run_in_threadpool(check)), media_type="application/json")


# --------------------------------------------------------------------------- sweeps


@router.get(f"{UI_API_PREFIX}/sweeps/{{sweep_id}}/map")
def ui_sweep_map(sweep_id: str, svc: Annotated[Services, Depends(services)],
                 owner: Annotated[str | None, Depends(caller)]) -> JSONResponse:
    """The sweep's parameters and, per member, its values, job, state and event times (None
    where the member has no result yet or the event did not happen): the threshold map
    (``event_time`` of the combined dataset) available while members still run; each
    event's name with the label ``hockle run`` prints for it (``event_labels``)."""
    from .. import sweeps as sw

    sweep = svc.registry.get_sweep(sweep_id)
    if sweep is None or (owner is not None and sweep.owner != owner):
        raise ProblemError(404, "sweep-not-found", "Sweep not found", f"no sweep with id {sweep_id}")
    jobs = svc.registry.get_many(sweep.job_ids)
    values = sw.member_values(sweep.parameters, sweep.combine)
    members, names, labels = [], [], {}
    for index, (member, job_id) in enumerate(zip(values, sweep.job_ids)):
        job = jobs.get(job_id)
        times: dict[str, float | None] = {}
        if job is not None and job.result_path and os.path.exists(job.result_path):
            for event in result_events(job.result_path)["events"]:
                times[event["name"]] = event["time"]
                if event["name"] not in names:
                    names.append(event["name"])
                    labels[event["name"]] = event["label"]
        members.append({"index": index, "values": member, "job_id": job_id,
                        "state": job.state if job is not None else "failed",
                        "event_time": times})
    shape = ([len(v) for v in sweep.parameters.values()] if sweep.combine == "grid"
             else [len(values)])
    return JSONResponse({
        "sweep_id": sweep.id, "name": sweep.name, "combine": sweep.combine, "shape": shape,
        "parameters": [{"path": p, "values": v} for p, v in sweep.parameters.items()],
        "events": names, "event_labels": labels, "members": members})
