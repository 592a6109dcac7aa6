"""Continuation jobs (issue 42): a case's static branch in one parameter, computed by a worker
with :func:`service.branches.continue_branch` and stored as the job's result (the branch dataset,
dimension ``point``; docs/statics.md).

The request (``POST /v1/continuations``) is ``{"case": {...}, "continuation": {...}}``;
:class:`ContinuationOptions` is the second part. :func:`validate_request` checks both before any
work, with the checks :func:`service.branches.continuation_family` makes for ``hockle continue`` (a
path that is not a scalar of the case, a range that does not move, a ``to`` that makes the case
invalid or changes its grid, a case the static problem does not support), and answers a 422
naming ``case.<field>`` or ``continuation.<field>``. The job's ``spec_json`` is
:func:`canonical_request`; the worker reads it back with :func:`read_request`.
"""
from __future__ import annotations

import hashlib
import json
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from .problems import ProblemError

__all__ = ["KIND", "ContinuationOptions", "ContinuationRequest", "validate_request",
           "canonical_request", "read_request", "request_hash", "request_body_schema",
           "POINT_COST_STEPS"]

#: the job kind of a continuation (``hockle_jobs.kind``)
KIND = "continuation"
#: the largest number of points one job may ask for
MAX_POINTS = 5000
#: a continuation point costs about as much as this many dynamic steps of the same grid
#: (up to 10 bordered Newton iterations and a shift-invert Arnoldi for the unstable modes):
#: the time limit of a job of ``max_points`` points is that of a dynamic case of
#: ``POINT_COST_STEPS x max_points`` steps (Settings.time_limits)
POINT_COST_STEPS = 20


class ContinuationOptions(BaseModel):
    """How the branch is followed: the arguments of :func:`service.branches.continue_branch`
    (the options of ``hockle continue``)."""

    model_config = ConfigDict(extra="forbid")

    parameter: str = Field(..., min_length=1, max_length=300, description=(
        "Dotted path of a scalar of the case, as sweeps spell it, e.g. "
        "boundary.end.translation.2.force (its unit)."))
    to: float = Field(..., description="The parameter's target value (its unit).")
    time: float | None = Field(None, ge=0, description=(
        "Time at which the end conditions are read, s (velocities integrated up to it); "
        "default numerics.t_end."))
    switch: bool = Field(False, description=(
        "Leave the branch at its first branch point: a simple one along the critical mode, "
        "a round rod's symmetric pair along one mode of the pair."))
    max_points: int = Field(500, ge=2, le=MAX_POINTS, description="Stop after this many points.")
    step: float = Field(0.05, gt=0, le=1, description=(
        "Largest step, a fraction of the range's arclength."))
    shapes_every: int = Field(1, ge=1, description=(
        "Store positions and curvatures at every K-th point."))
    stability: bool = Field(True, description="Count the unstable modes at every point.")


class ContinuationRequest(BaseModel):
    """The body of ``POST /v1/continuations`` (documented in OpenAPI; validated by
    :func:`validate_request`)."""

    case: dict[str, Any] = Field(..., description="The case spec (the body of POST /v1/jobs).")
    continuation: ContinuationOptions


def request_body_schema() -> dict:
    """The JSON schema of the request body (OpenAPI): the case is the body of POST /v1/jobs
    (the Case schema there)."""
    return {"type": "object", "required": ["case", "continuation"],
            "additionalProperties": False, "properties": {
                "case": {"$ref": "#/components/schemas/Case"},
                "continuation": ContinuationOptions.model_json_schema()}}


def _refuse(errors: list[dict], detail: str, type_: str = "invalid-continuation"):
    return ProblemError(422, type_, "Invalid continuation", detail, errors=errors)


def _http_message(msg: str) -> str:
    """The CLI's wording (--parameter, --to) as the request's fields."""
    return msg.replace("--parameter ", "parameter ").replace("--to ", "to ")


def validate_request(data: Any, max_case_size: int):
    """``(case, options)`` of a continuation request, checked before any work; else a 422
    :class:`ProblemError` whose errors name ``case.<field>`` or ``continuation.<field>``.
    ``max_case_size`` (HOCKLE_MAX_CASE_SIZE) bounds grid points x POINT_COST_STEPS x
    max_points, as it bounds grid points x time steps of a dynamic case."""
    from solver.case import format_validation_errors

    from .validation import validate_case

    if not isinstance(data, dict):
        raise _refuse([{"loc": "", "msg": "a continuation request is an object "
                        "{case: {...}, continuation: {parameter, to, ...}}",
                        "type": "dict_type"}], "the body must be an object")
    errors = [{"loc": key, "msg": f"unknown field; allowed: case, continuation",
               "type": "extra_forbidden"} for key in data if key not in ("case", "continuation")]
    for key in ("case", "continuation"):
        if key not in data:
            errors.append({"loc": key, "msg": "field required", "type": "missing"})
    if errors:
        raise _refuse(errors, f"{len(errors)} field(s) of the request are not valid")
    try:
        options = ContinuationOptions.model_validate(data["continuation"])
    except ValidationError as exc:
        errs = [{**e, "loc": "continuation" + (f".{e['loc']}" if e["loc"] else "")}
                for e in format_validation_errors(exc)]
        raise _refuse(errs, f"{len(errs)} field(s) of the continuation are not valid") from None
    try:
        # the case's own time steps do not matter here: the size is the points' (below)
        case = validate_case(data["case"], 2 ** 62)
    except ProblemError as exc:
        exc.errors = [{**e, "loc": "case" + (f".{e['loc']}" if e.get("loc") else "")}
                      for e in (exc.errors or [])]
        raise
    size = case.grid_points * POINT_COST_STEPS * options.max_points
    if size > max_case_size:
        msg = (f"continuation too large: {case.grid_points} grid points x {options.max_points} "
               f"points x {POINT_COST_STEPS} (a point's cost in time steps) = {size} exceeds "
               f"this service's limit of {max_case_size}; lower max_points or "
               "numerics.n_segments")
        raise ProblemError(422, "case-too-large", "Case too large", msg, errors=[
            {"loc": "continuation.max_points", "msg": msg, "type": "case_too_large"},
            {"loc": "case.numerics.n_segments", "msg": msg, "type": "case_too_large"}])
    if case.initial.from_result is not None:
        msg = ("a continuation starts from the case's own equilibrium; initial.from_result "
               "is not used by it: leave it out")
        raise _refuse([{"loc": "case.initial.from_result", "msg": msg,
                        "type": "not_accepted_for_continuation"}], msg)
    _check_family(case, options)
    return case, options


def _check_family(case, options: ContinuationOptions) -> None:
    """The checks of ``hockle continue`` (:func:`service.branches.continuation_family`), as 422s."""
    from solver.continuation import ContinuationError
    from solver.statics import StaticsError

    from .branches import continuation_family

    try:
        continuation_family(case, options.parameter, options.to, time=options.time)
    except ContinuationError as exc:         # the range does not move
        msg = _http_message(str(exc))
        raise _refuse([{"loc": "continuation.to", "msg": msg, "type": "range_does_not_move"}],
                      msg) from None
    except StaticsError as exc:              # the case has no static problem here
        msg = str(exc)
        loc = "case." + msg.split(":", 1)[0] if ":" in msg and " " not in msg.split(":", 1)[0] \
            else "case"
        loc = "continuation.time" if loc == "case.time" else loc
        raise _refuse([{"loc": loc, "msg": msg, "type": "not_static"}], msg) from None
    except ValueError as exc:                # the path, or a `to` the case refuses
        msg = _http_message(str(exc))
        where = ("continuation.parameter" if msg.startswith("parameter ")
                 and "makes the case invalid" not in msg else "continuation.to")
        if "changes the grid" in msg:
            where = "continuation.parameter"
        raise _refuse([{"loc": where, "msg": msg, "type": "value_error"}], msg) from None


def canonical_request(case, options: ContinuationOptions) -> str:
    """The job's ``spec_json``: the validated case (defaults filled in) and the options."""
    return json.dumps({"case": json.loads(case.canonical_json()),
                       "continuation": options.model_dump(mode="json")},
                      sort_keys=True, separators=(",", ":"))


def request_hash(canonical: str) -> str:
    """The job's ``spec_hash`` (never equal to a dynamic case's: the kind is hashed too)."""
    return hashlib.sha256(f"{KIND}|{canonical}".encode()).hexdigest()


def read_request(spec_json: str):
    """``(case, options)`` of a stored continuation job (the worker's side)."""
    from solver.case import Case

    data = json.loads(spec_json)
    return Case.model_validate(data["case"]), ContinuationOptions.model_validate(
        data["continuation"])
