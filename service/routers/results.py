"""/v1/jobs/{id}/results, .../results/variables[/{name}], /v1/jobs/{id}/summary."""
from __future__ import annotations

import hashlib
import os
from contextlib import contextmanager
from typing import Annotated, Any, Iterator

import numpy as np
import orjson
from fastapi import APIRouter, Depends, Query, Request, Response
from fastapi.responses import FileResponse

from ..deps import Services, services
from ..auth import caller
from ..problems import ProblemError, problem_responses
from ..registry import Job
from ..schemas import Series, Summary, VariableInfo, VariableList, VariableSlice
from ..store import open_result
from .jobs import get_job_or_404

router = APIRouter(tags=["results"])

NETCDF_MEDIA_TYPE = "application/x-netcdf"
SUMMARY_NAMES = ("work_in", "power_in", "twist", "writhe", "linking_number", "contact_count",
                 "min_surface_gap")
SLICE_DIMS = ("time", "s", "component", "xyz", "quaternion", "step", "point", "bifurcation")


def _result_path(svc: Services, job: Job) -> str:
    path = job.result_path
    if not path or not os.path.exists(path):
        raise ProblemError(404, "result-not-ready", "Result not ready",
                           f"job {job.id} is {job.state} and has no result file"
                           + (" yet" if job.state in ("accepted", "running") else ""))
    return path


def _etag(path: str) -> str:
    st = os.stat(path)
    raw = f"{os.path.basename(path)}:{st.st_size}:{st.st_mtime_ns}".encode()
    return '"' + hashlib.sha256(raw).hexdigest()[:32] + '"'


def _not_modified(request: Request, etag: str) -> bool:
    header = request.headers.get("if-none-match")
    if not header:
        return False
    tags = [t.strip() for t in header.split(",")]
    return "*" in tags or etag in tags or f"W/{etag}" in tags


@contextmanager
def _open(path: str) -> Iterator[Any]:
    with open_result(path, cache=False) as ds:
        yield ds


@router.get(
    "/jobs/{job_id}/results",
    operation_id="download_results",
    summary="The NetCDF result file",
    response_class=FileResponse,
    responses={200: {"content": {NETCDF_MEDIA_TYPE: {}}, "description": "NetCDF4 dataset"},
               304: {"description": "Not modified (If-None-Match)"},
               **problem_responses(404)},
)
def download_results(job_id: str, request: Request,
                     svc: Annotated[Services, Depends(services)],
                     owner: Annotated[str | None, Depends(caller)]) -> Response:
    """The job's dataset (partial for failed or dismissed jobs), with Content-Length and ETag."""
    job = get_job_or_404(svc, job_id, owner)
    path = _result_path(svc, job)
    etag = _etag(path)
    if _not_modified(request, etag):
        return Response(status_code=304, headers={"ETag": etag})
    return FileResponse(path, media_type=NETCDF_MEDIA_TYPE, filename=f"{job.id}.nc",
                        headers={"ETag": etag, "Cache-Control": "private, max-age=0"})


@router.get("/jobs/{job_id}/results/variables", operation_id="list_result_variables",
            summary="Variables of the result", response_model=VariableList,
            responses=problem_responses(404))
def list_result_variables(job_id: str, svc: Annotated[Services, Depends(services)],
                          owner: Annotated[str | None, Depends(caller)]) -> VariableList:
    """Each variable and coordinate with its dims, shape, units and long name."""
    job = get_job_or_404(svc, job_id, owner)
    path = _result_path(svc, job)
    with _open(path) as ds:
        items = [_info(name, ds[name], coordinate=True) for name in ds.coords]
        items += [_info(name, ds[name], coordinate=False) for name in ds.data_vars]
        dims = {str(k): int(v) for k, v in ds.sizes.items()}
    return VariableList(job_id=job.id, dims=dims, variables=items)


def _info(name, var, coordinate: bool) -> VariableInfo:
    return VariableInfo(
        name=str(name),
        dims=[str(d) for d in var.dims],
        shape=[int(n) for n in var.shape],
        dtype=str(var.dtype),
        units=_attr(var, "units"),
        long_name=_attr(var, "long_name"),
        coordinate=coordinate,
    )


def _attr(var, key) -> str | None:
    value = var.attrs.get(key)
    if value is None and key == "units":
        value = var.encoding.get("units")
    return None if value is None else str(value)


_SELECTOR_HELP = ("a value (nearest for time and s, within the stored span), a range 'a:b' "
                  "(inclusive, low to high, either end may be left out) or a list 'a,b,c'")


@router.get(
    "/jobs/{job_id}/results/variables/{name}",
    operation_id="get_result_variable",
    summary="A server-side slice of one variable",
    response_model=VariableSlice,
    responses=problem_responses(404, 422),
)
def get_result_variable(
    job_id: str,
    name: str,
    svc: Annotated[Services, Depends(services)],
    owner: Annotated[str | None, Depends(caller)],
    time: Annotated[str | None, Query(description=f"Time, s: {_SELECTOR_HELP}.")] = None,
    s: Annotated[str | None, Query(description=f"Arclength, m: {_SELECTOR_HELP}.")] = None,
    component: Annotated[str | None, Query(description="Body-frame component 1, 2, 3 (or '1,3', "
                                                       "'1:2').")] = None,
    xyz: Annotated[str | None, Query(description="Global axis: x, y, z (or its index 1, 2, "
                                                 "3).")] = None,
    quaternion: Annotated[str | None, Query(description="Quaternion part: w, x, y, z (or its "
                                                        "index 0, 1, 2, 3).")] = None,
    step: Annotated[str | None, Query(description="Solver step number (step diagnostics).")] = None,
    point: Annotated[str | None, Query(description=(
        "A continuation job's branch: the point index 0, 1, ... (a value, a range 'a:b' "
        "or a list 'a,b,c')."))] = None,
    bifurcation: Annotated[str | None, Query(description=(
        "A continuation job's branch: the index of a located fold or branch point."))] = None,
) -> VariableSlice:
    """Select by coordinate labels (``time``, ``s`` ... for a dynamic run, ``point`` and
    ``bifurcation`` for a branch); a selector for a dimension the variable lacks, or a
    label it does not store, is refused (422 naming ``query.<selector>``), and so is a
    slice larger than HOCKLE_MAX_SLICE_VALUES."""
    job = get_job_or_404(svc, job_id, owner)
    path = _result_path(svc, job)
    query = {"time": time, "s": s, "component": component, "xyz": xyz,
             "quaternion": quaternion, "step": step, "point": point, "bifurcation": bifurcation}
    query = {k: v for k, v in query.items() if v is not None}
    with _open(path) as ds:
        if name not in ds.variables:
            raise ProblemError(404, "variable-not-found", "Variable not found",
                               f"the result of job {job.id} has no variable {name!r}; see "
                               f"/v1/jobs/{job.id}/results/variables")
        var = ds[name]
        errors = []
        selected: dict[str, Any] = {}
        for dim, raw in query.items():
            if dim not in var.dims:
                errors.append({"loc": f"query.{dim}", "type": "dimension_absent",
                               "msg": f"{name} has no dimension {dim!r}; its dimensions are "
                                      f"({', '.join(map(str, var.dims))})"})
                continue
            try:
                var, where = _select(var, dim, raw)
            except ValueError as exc:
                errors.append({"loc": f"query.{dim}", "type": "value_error",
                               "msg": f"{exc}; give {_SELECTOR_HELP}"})
                continue
            if where is not None:
                selected[dim] = where
        if errors:
            raise ProblemError(422, "invalid-slice", "Invalid slice",
                               "the slice parameters do not fit this variable", errors=errors)
        size = int(var.size)
        cap = svc.settings.max_slice_values
        if size > cap:
            msg = (f"the slice has {size} values ({' x '.join(f'{d}={n}' for d, n in var.sizes.items())}),"
                   f" more than this service serves as JSON ({cap}); narrow it with "
                   f"{', '.join(f'{d}=' for d in var.dims)} or download the NetCDF file")
            raise ProblemError(422, "slice-too-large", "Slice too large", msg, errors=[
                {"loc": f"query.{d}", "msg": msg, "type": "slice_too_large"} for d in var.dims])
        values = var.values
        coords = {str(d): _jsonable(var[d].values) for d in var.dims if d in var.coords}
        meta = VariableSlice(
            job_id=job.id,
            name=name,
            dims=[str(d) for d in var.dims],
            shape=[int(n) for n in var.shape],
            units=_attr(var, "units"),
            long_name=_attr(var, "long_name"),
            coords=coords,
            selected=selected,
            data=None,
        ).model_dump(mode="json")
    # the data go from the numpy array straight to JSON bytes (orjson: NaN and ±inf as null):
    # no list of a million Python floats, and no second copy of it for the encoder (the audit
    # measured ~60 MB per near-limit slice that way)
    if values.ndim and values.dtype.kind in "fiub":
        meta["data"] = np.ascontiguousarray(values)
    else:
        meta["data"] = _jsonable(values)
    return Response(orjson.dumps(meta, option=orjson.OPT_SERIALIZE_NUMPY),
                    media_type="application/json")


def _select(var, dim: str, raw: str):
    """Apply one selector; returns (selected var, scalar label or None). Raises ValueError
    (a 422 naming ``query.<dim>``) for a label outside the stored ones (beyond the first or
    last stored value by more than half a spacing for time and s), a reversed range, and a
    selection that keeps nothing."""
    index = var.indexes.get(dim) if dim in var.coords else None
    kind = "int"
    if index is not None:
        kind = {"f": "float", "i": "int", "u": "int"}.get(index.dtype.kind, "str")
    convert = {"float": float, "int": int, "str": str}[kind]
    named = _flag_labels(var, dim) if index is not None else {}

    def conv(text: str):
        text = text.strip()
        if text in named:           # "x" for xyz = 1, "w" for quaternion = 0 (flag_meanings)
            return named[text]
        try:
            value = convert(text)
        except ValueError:
            hint = f" or one of {', '.join(named)}" if named else ""
            raise ValueError(f"{text!r} is not a {kind} label{hint}") from None
        if kind == "float" and not np.isfinite(value):
            raise ValueError(f"{text!r} is not a finite number")
        return value

    def within(value):
        """A float label must lie within the stored span (nearest is for between values)."""
        if kind != "float" or not len(index):
            return value
        values = np.asarray(index.values, dtype=float)
        lo, hi = float(values.min()), float(values.max())
        slack = 0.5 * float(np.median(np.diff(np.sort(values)))) if values.size > 1 else 0.0
        if not lo - slack <= value <= hi + slack:
            raise ValueError(f"{value!r} is outside the stored {dim} values, {lo:.6g} to "
                             f"{hi:.6g}")
        return value

    raw = raw.strip()
    if index is None:  # a dim without coordinate: positions
        if ":" in raw or "," in raw:
            raise ValueError(f"{dim} has no coordinate; give one position")
        position = conv(raw)
        if not 0 <= position < var.sizes[dim]:
            raise ValueError(f"position {position} is outside 0 to {var.sizes[dim] - 1}")
        return var.isel({dim: position}), int(raw)
    if ":" in raw:
        lo, _, hi = raw.partition(":")
        start = conv(lo) if lo.strip() else None
        stop = conv(hi) if hi.strip() else None
        if start is not None and stop is not None and start > stop:
            raise ValueError(f"the range {raw!r} is reversed: give 'low:high'")
        out = var.sel({dim: slice(start, stop)})
        if out.sizes[dim] == 0:
            raise ValueError(f"the range {raw!r} selects no stored {dim} value; labels: "
                             f"{_label_hint(index)}")
        return out, None
    if "," in raw:
        labels = [within(conv(x)) for x in raw.split(",") if x.strip()]
        if not labels:
            raise ValueError(f"the list {raw!r} names no {dim} value")
        try:
            if kind == "float":
                return var.sel({dim: labels}, method="nearest"), None
            return var.sel({dim: labels}), None
        except KeyError:
            raise ValueError(f"not all of {labels} are {dim} labels; labels: "
                             f"{_label_hint(index)}") from None
    label = within(conv(raw))
    try:
        out = var.sel({dim: label}, method="nearest") if kind == "float" else var.sel({dim: label})
    except KeyError:
        raise ValueError(f"{label!r} is not a {dim} label; labels: {_label_hint(index)}") from None
    return out, _jsonable(out[dim].values)


def _flag_labels(var, dim: str) -> dict[str, Any]:
    """Word -> index of an integer index coordinate that names its values with CF
    ``flag_values``/``flag_meanings`` (``xyz``: x y z, ``quaternion``: w x y z); empty
    for other coordinates (and for files written before these coordinates were integer)."""
    coord = var[dim]
    meanings = str(coord.attrs.get("flag_meanings", "")).split()
    values = np.atleast_1d(np.asarray(coord.attrs.get("flag_values", []))).tolist()
    if not meanings or len(meanings) != len(values):
        return {}
    return dict(zip(meanings, values))


def _label_hint(index) -> str:
    values = list(index.values)
    if len(values) <= 8:
        return ", ".join(map(str, values))
    return f"{values[0]} ... {values[-1]} ({len(values)} values)"


def _jsonable(values) -> Any:
    arr = np.asarray(values)
    if arr.dtype.kind == "f":
        obj = arr.astype(object)
        obj[~np.isfinite(arr)] = None
        return obj.tolist()
    if arr.dtype.kind in "US":
        return arr.astype(str).tolist()
    return arr.tolist()


@router.get("/jobs/{job_id}/summary", operation_id="get_summary",
            summary="Scalar time series for dashboards", response_model=Summary,
            responses={304: {"description": "Not modified (If-None-Match)"},
                       **problem_responses(404, 409)})
def get_summary(job_id: str, request: Request, response: Response,
                svc: Annotated[Services, Depends(services)],
                owner: Annotated[str | None, Depends(caller)]) -> Summary | Response:
    """Energies, twist, writhe, linking number and contact count over time. A continuation
    job's result is a branch, not a time history: 409 ``result-is-a-branch``."""
    job = get_job_or_404(svc, job_id, owner)
    if (job.kind or "dynamic") != "dynamic":
        raise ProblemError(409, "result-is-a-branch", "The result is a branch",
                           f"job {job.id} is a {job.kind} job: its result is a branch of "
                           "equilibria (dimension point), not a time history; read its "
                           f"variables at /v1/jobs/{job.id}/results/variables or download "
                           f"/v1/jobs/{job.id}/results")
    path = _result_path(svc, job)
    etag = _etag(path)
    if _not_modified(request, etag):
        return Response(status_code=304, headers={"ETag": etag})
    with _open(path) as ds:
        series = {}
        for name in ds.data_vars:
            var = ds[name]
            if var.dims != ("time",):
                continue
            if not (str(name).startswith("energy_") or name in SUMMARY_NAMES):
                continue
            series[str(name)] = Series(units=_attr(var, "units"), long_name=_attr(var, "long_name"),
                                       values=_jsonable(var.values))
        time = _jsonable(ds["time"].values) if "time" in ds.coords else []
    response.headers["ETag"] = etag
    return Summary(job_id=job.id, state=job.state, partial=bool(job.result_partial), time=time,
                   series=series)
