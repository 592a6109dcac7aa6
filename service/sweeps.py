"""Parameter sweeps: one base case, some of its fields varied, one job per member.

A sweep request is ``{"base": CASE, "parameters": {PATH: [values...], ...}, "combine":
"grid" | "zip"}``. ``PATH`` is a dotted path into the case document, list indices as numbers
(``boundary.end.translation.2.force``; ``translation[2]`` is read as ``translation.2``). A
boundary item given as a one-item list of conditions is looked through, so the same path
works whether the base writes ``{force: 0}`` or ``[{force: 0}]``.

* ``grid``: every combination, members in row-major order of the parameters as given (the
  last parameter varies fastest); the combined dataset has one dimension per parameter.
* ``zip``: the i-th values of every parameter together (all lists the same length); the
  combined dataset has one ``member`` dimension with each parameter as a coordinate on it.

This module holds what the REST API (``service/routers/sweeps.py``), the client, ``hockle
sweep`` and the local runner (``hockle.api.sweep``) share: reading a request
(:func:`parse_request`), expanding and validating its members (:func:`expand`,
:func:`validate_members`), the sweep's state (:func:`sweep_state`), the events of one
member's run (:func:`member_events`) and the one function that builds the combined
dataset from the members' results (:func:`combine_results`). It imports neither FastAPI
nor the solver's numerics.

Time grids. Members may store different output times (a varied ``numerics.dt``, a failed
member that stopped early). The combined ``time`` is the union of the members' output
times (times closer than 1e-9 of the span are one). When every member stored the same
times (the usual case) values are copied exactly and the dataset says
``hockle_sweep_time_grid = "common"``; otherwise each member's series is interpolated
linearly onto the union within its own stored span (counts: the last stored value), NaN
outside it, and the dataset says ``"union_interpolated"``: values at a member's own output
times are its own.
"""
from __future__ import annotations

import copy
import datetime as dt
import itertools
import json
import math
import re
from dataclasses import dataclass, field
from typing import Any, Callable, Literal, Mapping, Sequence

import numpy as np
from pydantic import BaseModel, Field

from solver.results import EVENT_RULES, run_events

__all__ = [
    "COMBINES",
    "MAX_SWEEP_MEMBERS",
    "SweepError",
    "Member",
    "MemberResult",
    "parse_path",
    "normalize_path",
    "normalize_parameters",
    "set_path",
    "parse_request",
    "expand",
    "member_values",
    "validate_members",
    "sweep_state",
    "member_events",
    "combine_results",
    "SweepStatus",
    "SweepMember",
    "SweepParameter",
    "EVENT_RULES",
]

COMBINES = ("grid", "zip")
#: the most members one sweep may have
MAX_SWEEP_MEMBERS = 1000
#: request keys of POST /v1/sweeps
REQUEST_KEYS = ("base", "parameters", "combine", "name")
#: errors listed at most in one refusal (a 1000-member sweep with one bad value everywhere)
MAX_ERRORS = 100

# units of the usual leaf names, for the parameter coordinates (plots label their axes)
_UNITS = {"force": "N", "velocity": "m s-1", "angular_velocity": "rad s-1", "moment": "N m",
          "length": "m", "diameter": "m", "density": "kg m-3", "youngs_modulus": "Pa",
          "shear_modulus": "Pa", "dt": "s", "t_end": "s", "ds": "m", "until": "s",
          "tolerance": "m", "drag_coefficient_normal": "1", "drag_coefficient_tangential": "1",
          "added_mass_coefficient": "1", "n_segments": "1", "rho_inf": "1",
          "contact_rho_inf": "1", "viscosity": "Pa s", "slenderness_length": "m"}

class SweepError(ValueError):
    """A sweep request that cannot be expanded or whose members do not validate.

    ``errors`` is a list of ``{"loc", "msg", "type"}`` as in the case spec's errors;
    ``loc`` is ``parameters.<PATH>``, ``combine``, ``base...`` or ``members[i].<field>``.
    """

    def __init__(self, errors: list[dict], detail: str | None = None):
        self.errors = errors
        self.detail = detail or f"{len(errors)} problem(s) in the sweep"
        super().__init__(self.detail + "".join(f"\n  {e['loc']}: {e['msg']}" for e in errors))


# --------------------------------------------------------------------------- paths

_BRACKET = re.compile(r"\[(\d+)\]")


def parse_path(path: str) -> list[str | int]:
    """``"boundary.end.translation.2.force"`` -> ``["boundary", "end", "translation", 2,
    "force"]``; ``translation[2]`` is read as ``translation.2``. Raises :class:`SweepError`
    for an empty path or an empty part."""
    if not isinstance(path, str) or not path.strip():
        raise SweepError([_e(f"parameters.{path}", "a parameter path is a dotted path into "
                             "the case, e.g. boundary.end.translation.2.force", "path_syntax")])
    text = _BRACKET.sub(r".\1", path.strip())
    parts: list[str | int] = []
    for raw in text.split("."):
        if not raw:
            raise SweepError([_e(f"parameters.{path}", "empty part in the path (two dots, or a "
                                 "dot at an end)", "path_syntax")])
        parts.append(int(raw) if raw.isdigit() else raw)
    if isinstance(parts[0], int):
        raise SweepError([_e(f"parameters.{path}", "a path starts with a field name of the "
                             "case (rod, boundary, numerics, ...)", "path_syntax")])
    return parts


def normalize_path(path: str) -> str:
    """The canonical spelling of a path: dotted, indices as numbers
    (``boundary.end.translation[2].force`` -> ``boundary.end.translation.2.force``)."""
    return ".".join(map(str, parse_path(path)))


def normalize_parameters(parameters: Mapping[str, Sequence[Any]]) -> dict[str, list]:
    """``parameters`` with every path in its canonical spelling; raises :class:`SweepError`
    for a bad path or two spellings of one path."""
    out: dict[str, list] = {}
    errors = []
    for path, values in parameters.items():
        try:
            key = normalize_path(path)
        except SweepError as exc:
            errors.extend(exc.errors)
            continue
        if key in out:
            errors.append(_e(f"parameters.{path}", f"the same path as {key!r}, given twice",
                             "duplicate"))
            continue
        out[key] = list(values) if isinstance(values, (list, tuple)) else values
    if errors:
        raise SweepError(errors)
    return out


def set_path(doc: dict, path: str, value: Any) -> None:
    """Set ``value`` at ``path`` in the case document ``doc`` (in place).

    Missing mappings on the way are created (the case validation then says what they
    lack); a one-item list met with a field name is looked through (a boundary item
    written as ``[{force: 0}]``). Raises :class:`SweepError` at ``parameters.<path>`` when
    the path cannot be followed (an index out of range, a field name on a list, a part
    below a number).
    """
    parts = parse_path(path)
    node: Any = doc
    done: list[str | int] = []

    def fail(msg: str) -> SweepError:
        where = ".".join(map(str, done)) or "the case"
        return SweepError([_e(f"parameters.{path}", f"{msg} (at {where})", "path_not_found")])

    for k, part in enumerate(parts):
        last = k == len(parts) - 1
        if isinstance(node, list) and isinstance(part, str):
            if len(node) == 1 and isinstance(node[0], dict):
                node = node[0]           # a one-item list of conditions
                done.append(0)
            else:
                raise fail(f"{part!r} is a field name but the value here is a list of "
                           f"{len(node)}; give an index (0..{len(node) - 1})")
        if isinstance(node, dict):
            if isinstance(part, int):
                raise fail(f"{part} is an index but the value here is a mapping with "
                           f"fields {', '.join(map(str, node)) or '(none)'}")
            if last:
                node[part] = copy.deepcopy(value)
                return
            if node.get(part) is None:
                node[part] = {}
            node = node[part]
        elif isinstance(node, list):
            if not 0 <= part < len(node):  # type: ignore[operator]
                raise fail(f"index {part} is out of range for a list of {len(node)}")
            if last:
                node[part] = copy.deepcopy(value)  # type: ignore[index]
                return
            node = node[part]  # type: ignore[index]
        else:
            raise fail(f"cannot go into {type(node).__name__} {node!r} for {part!r}")
        done.append(part)


def _e(loc: str, msg: str, etype: str) -> dict:
    return {"loc": loc, "msg": msg, "type": etype}


# --------------------------------------------------------------------------- requests, members


@dataclass
class Member:
    """One member of a sweep: its index (row-major over the grid, or the zip position),
    the value of each varied path, and its case document (not yet validated)."""

    index: int
    values: dict[str, Any]
    case: dict


def parse_request(data: Any) -> tuple[dict, dict[str, list], str, str | None]:
    """Check the shape of a sweep request; returns ``(base, parameters, combine, name)``.

    Raises :class:`SweepError` naming each bad key (``base``, ``parameters.<PATH>``,
    ``combine``; unknown keys list the allowed ones)."""
    errors: list[dict] = []
    if not isinstance(data, dict):
        raise SweepError([_e("", "a sweep request is an object with base, parameters and "
                             "combine", "dict_type")])
    for key in data:
        if key not in REQUEST_KEYS:
            errors.append(_e(str(key), f"unknown key; allowed: {', '.join(REQUEST_KEYS)}",
                             "extra_forbidden"))
    base = data.get("base")
    if not isinstance(base, dict):
        errors.append(_e("base", "the base case spec (an object) is required", "dict_type"))
    params = data.get("parameters")
    if not isinstance(params, dict) or not params:
        errors.append(_e("parameters", "an object {PATH: [values, ...]} with at least one "
                         "path is required", "dict_type"))
        params = {}
    for path, values in params.items():
        if not isinstance(values, list) or not values:
            errors.append(_e(f"parameters.{path}", "a non-empty list of values is required",
                             "list_type"))
    if not errors:
        try:
            params = normalize_parameters(params)
        except SweepError as exc:
            errors.extend(exc.errors)
    combine = data.get("combine", "grid")
    if combine not in COMBINES:
        errors.append(_e("combine", f"must be one of {', '.join(COMBINES)}, got {combine!r}",
                         "enum"))
    name = data.get("name")
    if name is not None and (not isinstance(name, str) or not 1 <= len(name) <= 200
                             or not name.isprintable()):
        errors.append(_e("name", "a name of 1 to 200 printable characters (no control "
                         "characters)", "string_type"))
    if errors:
        raise SweepError(errors, "the sweep request is not valid")
    return base, dict(params), combine, name  # type: ignore[return-value]


def expand(base: dict, parameters: Mapping[str, Sequence[Any]], combine: str = "grid",
           max_members: int = MAX_SWEEP_MEMBERS) -> list[Member]:
    """The members of a sweep, each with its own deep copy of ``base`` with the values set.

    ``grid``: the product of the value lists in the order of ``parameters`` (last varies
    fastest); ``zip``: the lists side by side (they must have one length). Raises
    :class:`SweepError` for a path that cannot be followed, zipped lists of different
    lengths, or more than ``max_members`` members."""
    if combine not in COMBINES:
        raise SweepError([_e("combine", f"must be one of {', '.join(COMBINES)}, got "
                             f"{combine!r}", "enum")])
    parameters = normalize_parameters(parameters)
    paths = list(parameters)
    if not paths:
        raise SweepError([_e("parameters", "at least one path is required", "missing")])
    lists = [list(parameters[p]) for p in paths]
    errors = [_e(f"parameters.{p}", "a non-empty list of values is required", "list_type")
              for p, v in zip(paths, lists) if not v]
    if errors:
        raise SweepError(errors)
    if combine == "zip":
        lengths = {len(v) for v in lists}
        if len(lengths) > 1:
            raise SweepError([_e(f"parameters.{p}", f"{len(v)} values; zip needs the same "
                                 f"number for every path (got {sorted(lengths)})",
                                 "length_mismatch") for p, v in zip(paths, lists)])
        rows = list(zip(*lists))
    else:
        count = math.prod(len(v) for v in lists)
        if count > max_members:
            rows = []
        else:
            rows = list(itertools.product(*lists))
    n = len(rows) if rows else math.prod(len(v) for v in lists)
    if n > max_members:
        raise SweepError([_e("parameters", f"{n} members; a sweep may have at most "
                             f"{max_members}", "too_many_members")])
    # the paths must be followable on the base (checked once, with the first values)
    probe = copy.deepcopy(base)
    errors = []
    for p, v in zip(paths, lists):
        try:
            set_path(probe, p, v[0])
        except SweepError as exc:
            errors.extend(exc.errors)
    if errors:
        raise SweepError(errors, "a parameter path does not lead into the base case")
    members = []
    for index, row in enumerate(rows):
        doc = copy.deepcopy(base)
        for p, value in zip(paths, row):
            set_path(doc, p, value)
        members.append(Member(index, dict(zip(paths, row)), doc))
    return members


def member_values(parameters: Mapping[str, Sequence[Any]], combine: str = "grid") -> list[dict]:
    """Each member's ``{path: value}`` in member order, without building the cases (what
    :func:`expand` gives as ``Member.values``)."""
    paths = list(parameters)
    lists = [list(parameters[p]) for p in paths]
    rows = zip(*lists) if combine == "zip" else itertools.product(*lists)
    return [dict(zip(paths, row)) for row in rows]


def describe(values: Mapping[str, Any]) -> str:
    """``path = value, ...`` for messages."""
    return ", ".join(f"{p} = {json.dumps(v)}" for p, v in values.items())


def _default_validate(data: dict):
    from pydantic import ValidationError

    from solver.case import Case, CaseError, format_validation_errors

    try:
        return Case.model_validate(data)
    except ValidationError as exc:
        raise CaseError(format_validation_errors(exc)) from None


def validate_members(members: Sequence[Member],
                     validate: Callable[[dict], Any] | None = None) -> list[Any]:
    """Validate every member's case; returns the validated cases in member order.

    ``validate(doc)`` returns a ``Case`` or raises an exception with an ``errors`` list
    (``CaseError``, the service's 422 ``ProblemError``); default: ``Case.model_validate``.
    All members are checked before anything is returned, and one :class:`SweepError`
    lists the problems of every bad member (at most :data:`MAX_ERRORS`): ``loc`` is
    ``members[i].<field>`` and ``msg`` names the member and its parameter values.
    """
    validate = validate or _default_validate
    cases, errors, bad = [], [], []
    for m in members:
        try:
            cases.append(validate(m.case))
        except Exception as exc:  # noqa: BLE001 - anything carrying field errors
            found = list(getattr(exc, "errors", None) or [])
            if callable(getattr(exc, "errors", None)) or not found:
                found = [{"loc": "", "msg": getattr(exc, "detail", None) or str(exc),
                          "type": "invalid_case"}]
            bad.append(m.index)
            for err in found:
                loc = str(err.get("loc") or "")
                errors.append({
                    "loc": f"members[{m.index}]" + (f".{loc}" if loc else ""),
                    "msg": f"member {m.index} ({describe(m.values)}): {err.get('msg')}",
                    "type": str(err.get("type", "value_error")),
                })
    if errors:
        shown = ", ".join(map(str, bad[:10])) + (" ..." if len(bad) > 10 else "")
        raise SweepError(errors[:MAX_ERRORS],
                         f"{len(bad)} of {len(members)} member(s) of the sweep are not valid "
                         f"(members {shown}); nothing was queued")
    return cases


# --------------------------------------------------------------------------- state


STATES = ("accepted", "running", "successful", "failed", "dismissed")


def sweep_state(member_states: Sequence[str], dismissed: bool = False) -> str:
    """The sweep's state in the job states' vocabulary, from its members' states.

    ``accepted`` while no member has started, ``running`` while any member is accepted or
    running (and one has started or finished), then: ``dismissed`` when the sweep was
    dismissed, ``successful`` when every member succeeded, else ``failed`` (at least one
    member failed or was dismissed on its own; the others' results are still combined)."""
    states = list(member_states)
    active = [s for s in states if s in ("accepted", "running")]
    if active:
        if all(s == "accepted" for s in states):
            return "accepted"
        return "running"
    if dismissed:
        return "dismissed"
    if states and all(s == "successful" for s in states):
        return "successful"
    return "failed"


# --------------------------------------------------------------------------- REST models


class SweepParameter(BaseModel):
    path: str = Field(..., description="Dotted path into the case, list indices as numbers.")
    values: list[Any]


class SweepMember(BaseModel):
    index: int = Field(..., description="Member number: row-major over the grid, or the zip "
                       "position.")
    values: dict[str, Any] = Field(..., description="The value of each varied path.")
    job_id: str
    state: Literal["accepted", "running", "successful", "failed", "dismissed"]
    reason: str | None = None
    progress: float = Field(..., ge=0, le=100)
    message: str | None = Field(None, description="The member job's message: why it failed or "
                                "stopped, or a successful run's warning (hockle_warning).")


class SweepLinks(BaseModel):
    self: str
    results: str


class SweepStatus(BaseModel):
    id: str
    name: str | None = None
    state: Literal["accepted", "running", "successful", "failed", "dismissed"]
    progress: float = Field(..., ge=0, le=100, description="Mean of the members' progress, "
                            "percent (a finished member counts 100).")
    combine: Literal["grid", "zip"]
    shape: list[int] = Field(..., description="Sizes of the combined dataset's sweep "
                             "dimensions: one per parameter (grid) or [members] (zip).")
    parameters: list[SweepParameter]
    counts: dict[str, int] = Field(..., description="Members per state.")
    members: list[SweepMember]
    created: dt.datetime
    dismissed: bool = False
    result_available: bool = Field(..., description="Every member is finished: the combined "
                                   "dataset can be fetched.")
    links: SweepLinks

    @property
    def terminal(self) -> bool:
        return self.state in ("successful", "failed", "dismissed")


# --------------------------------------------------------------------------- events


def member_events(ds) -> dict[str, int | None]:
    """The output index of each event of one member's result (None: it did not happen):
    :func:`solver.results.run_events`, the rules of ``hockle plot``'s snapshot rows."""
    return run_events(ds)


# --------------------------------------------------------------------------- combination


@dataclass
class MemberResult:
    """What :func:`combine_results` needs of one member: its index and values, its state
    (the job states' vocabulary), its result dataset (None when it has none) and, for the
    service, its job id and message."""

    index: int
    values: dict[str, Any]
    state: str
    dataset: Any = None
    job_id: str | None = None
    message: str | None = None
    extra: dict = field(default_factory=dict)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _coord_values(values: Sequence[Any]) -> np.ndarray:
    """float64 for numbers, else the JSON text of each value."""
    if all(_is_number(v) for v in values):
        return np.asarray(values, dtype=float)
    return np.asarray([v if isinstance(v, str) else json.dumps(v, sort_keys=True)
                       for v in values], dtype=object)


def _union_times(arrays: list[np.ndarray]) -> tuple[np.ndarray, bool]:
    """The union of the members' output times (within 1e-9 of the span) and whether every
    member stored the same times."""
    nonempty = [a for a in arrays if a.size]
    if not nonempty:
        return np.zeros(0), True
    first = nonempty[0]
    common = all(a.shape == first.shape and np.allclose(a, first, rtol=0,
                                                        atol=1e-9 * max(1.0, abs(first[-1])))
                 for a in nonempty)
    if common:
        return first.astype(float), True
    t = np.sort(np.concatenate(nonempty).astype(float))
    span = max(float(t[-1] - t[0]), 1e-300)
    keep = np.r_[True, np.diff(t) > 1e-9 * span]
    return t[keep], False


def _onto(t_new: np.ndarray, t: np.ndarray, values: np.ndarray, step: bool) -> np.ndarray:
    """values (T, ...) at times t onto t_new: linear (or the last value, ``step``) within
    [t0, t_last], NaN outside. At a stored time the stored value itself, infinite ones
    included (``min_surface_gap`` is +inf where no pair is near); between two stored times
    where one is infinite, that infinity."""
    out = np.full((t_new.size,) + values.shape[1:], np.nan)
    if t.size == 0:
        return out
    tol = 1e-9 * max(abs(float(t[-1])), 1e-300)
    inside = (t_new >= t[0] - tol) & (t_new <= t[-1] + tol)
    tq = np.clip(t_new[inside], t[0], t[-1])
    if t.size == 1:
        out[inside] = values[0]
        return out
    j = np.clip(np.searchsorted(t, tq, side="right") - 1, 0, t.size - 2)
    w = (tq - t[j]) / np.where(t[j + 1] > t[j], t[j + 1] - t[j], 1.0)
    if step:
        w = np.where(w >= 1.0 - 1e-9, 1.0, 0.0)
    w = w.reshape((-1,) + (1,) * (values.ndim - 1))
    before, after = values[j], values[j + 1]
    with np.errstate(invalid="ignore"):       # 0·inf where a stored value is infinite
        between = (1.0 - w) * before + w * after
    out[inside] = np.where(w == 0.0, before, np.where(w == 1.0, after, between))
    return out


def combine_results(members: Sequence[MemberResult], parameters: Mapping[str, Sequence[Any]],
                    combine: str = "grid", *, fields: Sequence[str] = (),
                    attrs: Mapping[str, Any] | None = None):
    """One ``xarray.Dataset`` of a sweep from its members' results.

    Dimensions: one per parameter, named by its path, with the values as coordinate
    (``grid``), or ``member`` with each path a coordinate on it (``zip``); then ``time``
    (the union of the members' output times, see the module's note on time grids) and,
    for ``fields``, the members' own field dimensions (``s``, ``component``, ``xyz``,
    ``quaternion``: every member with a result must have the same grid).

    Variables:

    * every (time,) variable of the members (energies, twist, writhe, linking_number,
      contact_count, min_surface_gap, the quality indicators) over (sweep dims..., time);
    * ``fields`` (e.g. ``["position", "kappa"]``) over (sweep dims..., time, s, ...);
    * ``member_index`` (the member number), ``member_status`` (``successful``, ``failed``,
      ``dismissed``, ...; a member without a result keeps NaN everywhere), ``job_id``,
      ``member_message``, ``member_t_reached`` (last stored time, s);
    * the events of each member (:func:`member_events`) over (sweep dims..., ``event``):
      ``event_time`` (s) and the ``linking_number``, ``twist``, ``writhe`` and
      ``energy_total`` stored at that time (``event_<name>``), NaN when it did not happen.

    A failed member is marked, never fatal. Raises :class:`SweepError` for an unknown or
    inconsistent field (``loc`` ``query.fields``) and for members that do not match the
    parameters.

    Built in parts, each by what it makes: the layout (:class:`_Layout`), the scalar series
    and the fields (:func:`_series_vars`, :func:`_field_vars`), the members' bookkeeping
    (:func:`_member_vars`), the events (:func:`_event_vars`), the coordinates
    (:func:`_coords`) and the attributes (:func:`_attrs`).
    """
    import xarray as xr

    layout = _Layout.of(members, parameters, combine)
    series, data_vars = _series_vars(layout)
    field_vars, coords = _field_vars(layout, fields)
    data_vars.update(field_vars)
    data_vars.update(_member_vars(layout))
    events = [member_events(ds) for ds in layout.datasets]
    names = _event_names(events)
    data_vars.update(_event_vars(layout, series, events, names))
    coords.update(_coords(layout, names))
    ds_out = xr.Dataset(
        {k: xr.Variable(d, v, a) for k, (d, v, a) in data_vars.items()},
        coords={k: xr.Variable(d, v, a) for k, (d, v, a) in coords.items()},
    )
    ds_out.attrs.update(_attrs(layout, fields, attrs))
    return ds_out


@dataclass
class _Layout:
    """What every part of :func:`combine_results` shares: the parameters (canonical paths and
    value lists), the combination, the sweep dimensions and their shape, the members in
    order with their datasets (None without a result), their output times and the union."""

    combine: str
    paths: list[str]
    lists: list[list]
    shape: tuple[int, ...]
    sweep_dims: tuple[str, ...]
    ordered: list[MemberResult]
    datasets: list[Any]
    times: list[np.ndarray]
    t_union: np.ndarray
    common: bool

    @property
    def n(self) -> int:
        return len(self.ordered)

    def sweep_array(self, flat: np.ndarray) -> np.ndarray:
        """(members, ...) -> (sweep dims..., ...)."""
        return flat.reshape(self.shape + flat.shape[1:])

    @classmethod
    def of(cls, members: Sequence[MemberResult], parameters: Mapping[str, Sequence[Any]],
           combine: str) -> "_Layout":
        parameters = normalize_parameters(parameters)
        paths = list(parameters)
        lists = [list(parameters[p]) for p in paths]
        if combine == "grid":
            shape = tuple(len(v) for v in lists)
            sweep_dims = tuple(paths)
        elif combine == "zip":
            shape = (len(lists[0]),)
            sweep_dims = ("member",)
        else:
            raise SweepError([_e("combine", f"must be one of {', '.join(COMBINES)}", "enum")])
        n = math.prod(shape)
        by_index = {m.index: m for m in members}
        if sorted(by_index) != list(range(n)):
            raise SweepError([_e("members", f"the members are numbered "
                                 f"{sorted(by_index)[:5]}..., the parameters make {n}",
                                 "member_mismatch")])
        ordered = [by_index[i] for i in range(n)]
        datasets = [m.dataset if m.dataset is not None and m.dataset.sizes.get("time", 0) > 0
                    else None for m in ordered]
        times = [np.asarray(ds["time"].values, dtype=float) if ds is not None else np.zeros(0)
                 for ds in datasets]
        t_union, common = _union_times(times)
        return cls(combine, paths, lists, shape, sweep_dims, ordered, datasets, times,
                   t_union, common)


def _series_vars(layout: _Layout) -> tuple[dict[str, Any], dict[str, Any]]:
    """Every (time,) variable of the members over (sweep dims..., time): returns the
    prototypes by name and the variables."""
    series: dict[str, Any] = {}
    for ds in layout.datasets:
        if ds is None:
            continue
        for name, var in ds.data_vars.items():
            if var.dims == ("time",) and name not in series:
                series[name] = var
    data_vars: dict[str, Any] = {}
    for name, proto in series.items():
        step = proto.dtype.kind in "iu"
        flat = np.full((layout.n, layout.t_union.size), np.nan)
        for k, (ds, t) in enumerate(zip(layout.datasets, layout.times)):
            if ds is None or name not in ds:
                continue
            values = np.asarray(ds[name].values, dtype=float)
            flat[k] = values if layout.common else _onto(layout.t_union, t, values, step)
        data_vars[name] = (layout.sweep_dims + ("time",), layout.sweep_array(flat),
                           _var_attrs(proto))
    return series, data_vars


def _field_vars(layout: _Layout, fields: Sequence[str]) -> tuple[dict[str, Any], dict[str, Any]]:
    """The requested (time, s, ...) fields over (sweep dims..., time, s, ...) and the
    coordinates of their inner dimensions; :class:`SweepError` (``query.fields``) for a field
    no member has, one that is not a field, or members on different grids."""
    datasets, data_vars, coords = layout.datasets, {}, {}
    for name in fields:
        proto = next((ds[name] for ds in datasets if ds is not None and name in ds), None)
        if proto is None:
            available = sorted({str(v) for ds in datasets if ds is not None
                                for v, var in ds.data_vars.items()
                                if var.dims[:1] == ("time",) and len(var.dims) > 1})
            raise SweepError([_e("query.fields", f"no member's result has {name!r}; fields "
                                 f"stored: {', '.join(available) or '(none)'}",
                                 "unknown_field")])
        if proto.dims[0] != "time" or len(proto.dims) < 2:
            raise SweepError([_e("query.fields", f"{name!r} is not a (time, s, ...) field; the "
                                 "scalar series are always included", "not_a_field")])
        inner = proto.dims[1:]
        for dim in inner:
            if dim in proto.coords:
                ref = np.asarray(proto[dim].values)
                _check_same_grid(datasets, name, dim, ref)
                if dim not in coords:
                    coords[dim] = (dim, ref, dict(proto[dim].attrs))
        flat = np.full((layout.n, layout.t_union.size) + proto.shape[1:], np.nan)
        for k, (ds, t) in enumerate(zip(datasets, layout.times)):
            if ds is None or name not in ds:
                continue
            values = np.asarray(ds[name].transpose(*proto.dims).values, dtype=float)
            flat[k] = values if layout.common else _onto(layout.t_union, t, values, False)
        data_vars[name] = (layout.sweep_dims + ("time",) + inner, layout.sweep_array(flat),
                           _var_attrs(proto))
    return data_vars, coords


def _check_same_grid(datasets: Sequence[Any], name: str, dim: str, ref: np.ndarray) -> None:
    for k, ds in enumerate(datasets):
        if ds is None or name not in ds:
            continue
        other = np.asarray(ds[dim].values)
        if other.shape != ref.shape or (ref.dtype.kind == "f" and not np.allclose(
                other, ref, rtol=1e-12, atol=0)) or (
                ref.dtype.kind != "f" and not np.array_equal(other, ref)):
            raise SweepError([_e("query.fields", f"member {k} stores {name} on "
                                 f"another {dim} grid ({other.shape[0]} points "
                                 f"against {ref.shape[0]}); full fields combine "
                                 "only members with the same grid (the scalar "
                                 "series always combine)", "grid_mismatch")])


def _member_vars(layout: _Layout) -> dict[str, Any]:
    """The members' bookkeeping: number, job state, job id, message, last stored time."""
    ordered, dims, arr = layout.ordered, layout.sweep_dims, layout.sweep_array
    status = np.asarray([m.state for m in ordered], dtype=object)
    reached = np.asarray([t[-1] if t.size else np.nan for t in layout.times], dtype=float)
    return {
        "member_index": (dims, arr(np.arange(layout.n, dtype=np.int32)), {
            "long_name": "member number of the sweep (row-major over the grid, or the zip "
                         "position)", "units": "1"}),
        "member_status": (dims, arr(status), {
            "long_name": "state of the member's job (accepted running successful failed "
                         "dismissed); a member without a result has NaN in every variable"}),
        "job_id": (dims, arr(np.asarray([m.job_id or "" for m in ordered], dtype=object)),
                   {"long_name": "job id of the member"}),
        "member_message": (dims, arr(np.asarray([m.message or "" for m in ordered],
                                                dtype=object)),
                           {"long_name": "why the member failed or stopped; for a "
                                         "successful member its result's hockle_warning "
                                         "(empty without one)"}),
        "member_t_reached": (dims, arr(reached), {
            "long_name": "last stored time of the member's result", "units": "s"}),
    }


_EVENT_QUANTITIES = (("linking_number", "1"), ("twist", "1"), ("writhe", "1"),
                     ("energy_total", "J"))


def _event_names(events: Sequence[Mapping[str, Any]]) -> list[str]:
    levels = max((int(k.split("_")[1]) for ev in events for k in ev if k.startswith("writhe_")),
                 default=0)
    optional = [name for name in ("bend_radius_below_mbr",) if any(name in ev for ev in events)]
    return (["buckling_onset", "first_contact", "loop_formed"] + optional
            + [f"writhe_{k}" for k in range(1, levels + 1)])


def _event_vars(layout: _Layout, series: Mapping[str, Any],
                events: Sequence[Mapping[str, Any]], names: Sequence[str]) -> dict[str, Any]:
    """The time of each member's ``events`` (:func:`member_events`, in member order) and the
    stored topology and energy at them, over (sweep dims..., event ``names``); NaN where an
    event did not happen."""
    at = {q: np.full((layout.n, len(names)), np.nan) for q in ("time",) + tuple(
        q for q, _ in _EVENT_QUANTITIES)}
    for k, (ds, ev, t) in enumerate(zip(layout.datasets, events, layout.times)):
        for j, name in enumerate(names):
            i = ev.get(name)
            if i is None:
                continue
            at["time"][k, j] = t[i]
            for quantity, _ in _EVENT_QUANTITIES:
                if quantity in ds:
                    at[quantity][k, j] = float(ds[quantity].values[i])
    dims = layout.sweep_dims + ("event",)
    out = {"event_time": (dims, layout.sweep_array(at["time"]), {
        "long_name": "time of the event in the member's run", "units": "s",
        "comment": EVENT_RULES})}
    for quantity, units in _EVENT_QUANTITIES:
        if quantity in series:
            out[f"event_{quantity}"] = (dims, layout.sweep_array(at[quantity]), {
                "long_name": f"{quantity} at the event (the member's stored value)",
                "units": units})
    return out


def _coords(layout: _Layout, names: Sequence[str]) -> dict[str, Any]:
    """The parameters (a dimension each, or on ``member``), ``time`` and ``event``."""
    coords: dict[str, Any] = {}
    if layout.combine == "grid":
        for p, v in zip(layout.paths, layout.lists):
            coords[p] = (p, _coord_values(v), _param_attrs(p))
    else:
        coords["member"] = ("member", np.arange(layout.n, dtype=np.int32),
                            {"long_name": "member of the zipped sweep", "units": "1"})
        for p, v in zip(layout.paths, layout.lists):
            coords[p] = ("member", _coord_values(v), _param_attrs(p))
    time_attrs = {"standard_name": "time", "long_name": "time", "units": "s", "axis": "T"}
    if not layout.common:
        time_attrs["comment"] = ("the union of the members' output times; a member's series "
                                 "is interpolated onto it within its own stored span and NaN "
                                 "outside")
    coords["time"] = ("time", layout.t_union, time_attrs)
    coords["event"] = ("event", np.asarray(names, dtype=object),
                       {"long_name": "event of the run", "comment": EVENT_RULES})
    return coords


def _attrs(layout: _Layout, fields: Sequence[str],
           attrs: Mapping[str, Any] | None) -> dict[str, Any]:
    """The dataset's global attributes (CF, the sweep's description, ``attrs`` last)."""
    n, paths = layout.n, layout.paths
    n_ok = int(sum(1 for m in layout.ordered if m.state == "successful"))
    out = {
        "Conventions": "CF-1.12",
        "title": f"sweep of {n} member(s) over {', '.join(paths)}",
        "summary": f"hockle parameter sweep ({layout.combine}): {n} member(s), {n_ok} "
                   "successful; the members' scalar time series and event times",
        "hockle_sweep": 1,
        "hockle_sweep_combine": layout.combine,
        "hockle_sweep_parameters": json.dumps([{"path": p, "values": v}
                                               for p, v in zip(paths, layout.lists)]),
        "hockle_sweep_time_grid": "common" if layout.common else "union_interpolated",
        "hockle_sweep_fields": ",".join(fields),
        "history": f"{dt.datetime.now(dt.timezone.utc).isoformat(timespec='seconds')} "
                   f"combined by hockle",
    }
    first_case = next((ds.attrs.get("case") for ds in layout.datasets if ds is not None), None)
    if first_case is not None:
        out["hockle_first_member_case"] = first_case
    if attrs:
        out.update({k: v for k, v in attrs.items() if v is not None})
    return out


def _var_attrs(var) -> dict:
    keep = ("units", "long_name", "comment", "coverage_content_type")
    out = {k: var.attrs[k] for k in keep if k in var.attrs}
    if "units" not in out and "units" in var.encoding:
        out["units"] = var.encoding["units"]
    return out


def _param_attrs(path: str) -> dict:
    leaf = next((p for p in reversed(parse_path(path)) if isinstance(p, str)), path)
    attrs = {"long_name": f"swept parameter {path}", "hockle_path": path}
    if leaf in _UNITS:
        attrs["units"] = _UNITS[leaf]
    return attrs


def is_sweep(ds) -> bool:
    """True for a dataset made by :func:`combine_results`."""
    return "hockle_sweep_combine" in getattr(ds, "attrs", {})
