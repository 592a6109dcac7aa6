"""Reading and validating a submitted case: the same pydantic ``Case`` the CLI uses.

Every refusal is a :class:`~service.problems.ProblemError` whose ``errors`` name each bad field by
its path (``rod.youngs_modulus``) and say what is allowed; unknown fields list the allowed ones.
"""
from __future__ import annotations

import json
from typing import Any

from pydantic import ValidationError

from solver.case import allowed_fields  # noqa: F401  (its home is solver.case)

from .problems import ProblemError

MAX_BODY_BYTES = 4 * 1024 * 1024
#: the deepest nesting of lists and mappings a body may have (the deepest a case spec needs
#: is 9 levels: a sweep's base, boundary, end, translation, an item, a list of conditions, a
#: condition, a table, its times)
MAX_NESTING = 32
YAML_TYPES = ("application/yaml", "application/x-yaml", "text/yaml", "text/x-yaml")


def too_large() -> ProblemError:
    """The 413 problem of a body over MAX_BODY_BYTES."""
    return ProblemError(413, "body-too-large", "Request body too large",
                        f"a case spec may be at most {MAX_BODY_BYTES} bytes")


async def read_body(request) -> bytes:
    """The request body, read in chunks and refused (413) as soon as it exceeds
    MAX_BODY_BYTES, or at once when Content-Length says so: a large body is never held
    whole (eight concurrent 50 MB POSTs took the API from 183 to 767 MB when bodies were
    read before the check)."""
    declared = request.headers.get("content-length")
    if declared is not None:
        try:
            if int(declared) > MAX_BODY_BYTES:
                raise too_large()
        except ValueError:
            raise ProblemError(400, "malformed-body", "Malformed request body",
                               "the Content-Length header is not a number") from None
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > MAX_BODY_BYTES:
            raise too_large()
        chunks.append(chunk)
    return b"".join(chunks)


def parse_body(body: bytes, content_type: str | None) -> Any:
    """JSON (default) or YAML (by Content-Type) to Python data; 400/413/415 problems."""
    if len(body) > MAX_BODY_BYTES:
        raise too_large()
    media = (content_type or "application/json").split(";")[0].strip().lower()
    if not body.strip():
        raise ProblemError(422, "invalid-case", "Invalid case spec", "the request body is empty",
                           errors=[{"loc": "", "msg": "a case spec (JSON object) is required",
                                    "type": "missing"}])
    if media in YAML_TYPES:
        from solver.case import CaseError, parse_text

        try:
            return check_nesting(parse_text(body, "yaml", "request body"))
        except CaseError as exc:
            if any(e.get("type") == "too_deep" for e in exc.errors):
                raise too_deep("") from None
            raise ProblemError(400, "malformed-body", "Malformed request body",
                               "the body is not valid YAML", errors=list(exc.errors)) from None
    if media not in ("application/json", "text/json") and not media.endswith("+json"):
        raise ProblemError(415, "unsupported-media-type", "Unsupported media type",
                           f"send the case as application/json or application/yaml, not {media}")
    try:
        data = json.loads(body)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ProblemError(400, "malformed-body", "Malformed request body",
                           f"the body is not valid JSON: {exc}") from None
    except RecursionError:
        raise too_deep("") from None
    return check_nesting(data)


def too_deep(loc: str) -> ProblemError:
    """The 422 problem of a body nested deeper than MAX_NESTING (at ``loc``)."""
    msg = (f"lists and mappings nested more than {MAX_NESTING} deep here; a case spec or "
           "a sweep nests at most about 10 levels")
    return ProblemError(422, "nesting-too-deep", "Body nested too deeply",
                        f"the body nests lists or mappings more than {MAX_NESTING} deep",
                        errors=[{"loc": loc, "msg": msg, "type": "nesting_too_deep"}])


def check_nesting(data: Any, limit: int = MAX_NESTING) -> Any:
    """``data`` unchanged, or a 422 ``nesting_too_deep`` problem naming the first place where
    lists and mappings nest deeper than ``limit``. Iterative: no recursion limit to meet, and
    nothing deeper reaches the validation (a sweep value 500 deep ended in a RecursionError
    in ``copy.deepcopy``)."""
    stack: list[tuple[Any, int, tuple]] = [(data, 1, ())]
    while stack:
        node, depth, path = stack.pop()
        if isinstance(node, dict):
            items = node.items()
        elif isinstance(node, list):
            items = enumerate(node)
        else:
            continue
        if depth > limit:
            from .problems import _loc

            raise too_deep(_loc(path))
        stack.extend((value, depth + 1, path + (key,)) for key, value in items
                     if isinstance(value, (dict, list)))
    return data


def validate_case(data: Any, max_case_size: int):
    """Return the validated ``Case`` or raise a 422 problem listing every bad field."""
    from solver.case import Case, format_validation_errors

    if not isinstance(data, dict):
        raise ProblemError(422, "invalid-case", "Invalid case spec",
                           "a case spec must be a JSON object",
                           errors=[{"loc": "", "msg": f"must be an object (mapping of fields), "
                                    f"got {type(data).__name__}", "type": "dict_type"}])
    try:
        case = Case.model_validate(data)
    except ValidationError as exc:
        errors = format_validation_errors(exc)   # unknown fields list the allowed ones
        raise ProblemError(422, "invalid-case", "Invalid case spec",
                           f"{len(errors)} field(s) of the case spec are not valid",
                           errors=errors) from None
    if case.initial.from_result is not None and case.initial.from_result.file is not None:
        # a path on this server is never read for a request (the CLI and the Python API
        # read the file themselves: hockle.io.read_start_state); over HTTP an earlier job
        # of the same owner is named by its id (start_from_job)
        msg = ("a result file is not accepted over HTTP: the service reads no paths on its "
               "machine; give initial.from_result.job, the id of an earlier successful job "
               "of yours, or run the case with the CLI or the Python API")
        raise ProblemError(422, "invalid-case", "Invalid case spec", msg, errors=[
            {"loc": "initial.from_result.file", "msg": msg, "type": "not_accepted_over_http"}])
    size = case.grid_points * case.n_steps
    if size > max_case_size:
        msg = (f"case too large: {case.grid_points} grid points x {case.n_steps} time steps = "
               f"{size} exceeds this service's limit of {max_case_size}; lower numerics.n_segments "
               f"(or raise numerics.ds), or the steps t_end / dt (lower numerics.t_end or raise "
               f"numerics.dt)")
        raise ProblemError(422, "case-too-large", "Case too large", msg, errors=[
            {"loc": "numerics.n_segments", "msg": msg, "type": "case_too_large"},
            {"loc": "numerics.t_end", "msg": msg, "type": "case_too_large"},
            {"loc": "numerics.dt", "msg": msg, "type": "case_too_large"},
        ])
    return case



def start_from_job(case, registry, owner: str | None):
    """The :class:`solver.initial.StartState` of a case whose ``initial.from_result``
    names an earlier job (``job``), or None for any other case.

    The job must be the caller's (``owner``, :func:`service.auth.caller`; None, a service
    without API keys: any job), have finished successfully and still hold its result,
    which must be of the same rod with ``time`` among its output times
    (:func:`solver.results.start_state_from`). Another owner's job is answered exactly
    as an unknown id, so that ids cannot be probed. Raises a 422 :class:`ProblemError`
    naming ``initial.from_result.job`` or ``initial.from_result.time``."""
    from solver.case import CaseError
    from solver.results import start_state_from

    from .registry import SUCCESSFUL
    from .store import open_result

    spec = case.initial.from_result
    if spec is None or spec.job is None:
        return None

    def refuse(loc, etype, msg):
        return ProblemError(422, "invalid-case", "Invalid case spec", msg,
                            errors=[{"loc": loc, "msg": msg, "type": etype}])

    loc = "initial.from_result.job"
    job = registry.get(spec.job)
    if job is None or (owner is not None and job.owner != owner):
        raise refuse(loc, "unknown_job", f"no job with id {spec.job} of yours")
    if (job.kind or "dynamic") != "dynamic":
        raise refuse(loc, "job_not_dynamic",
                     f"job {spec.job} is a {job.kind} job: its result is a branch, not a run "
                     "to start from (hockle.api.equilibrium_start starts from a branch point)")
    if job.state != SUCCESSFUL or not job.result_path:
        raise refuse(loc, "job_not_successful",
                     f"job {spec.job} is {job.state}, not successful: a start from an "
                     "earlier job needs its complete result")
    try:
        with open_result(job.result_path) as ds:
            return start_state_from(ds, case, f"the result of job {spec.job}", "job")
    except CaseError as exc:
        raise ProblemError(422, "invalid-case", "Invalid case spec", exc.errors[0]["msg"],
                           errors=[{"loc": e["loc"], "msg": e["msg"], "type": e["type"]}
                                   for e in exc.errors]) from None
    except OSError:
        raise refuse(loc, "result_gone",
                     f"the result of job {spec.job} is no longer stored") from None
