"""The case spec, schema_version 1: hockle's input contract (docs/case-spec.md).

A case file (YAML or JSON, SI units throughout) describes one simulation of a twisted
elastic rod: its material and geometry, the surrounding fluid, loads, the initial
configuration, six boundary conditions at each end, self-contact, numerics and output.
This module turns such a file into a validated, immutable-by-convention :class:`Case`
that the solver, the CLI and the REST service all read.

Usage::

    from solver.case import Case, CaseError
    case = Case.from_file("cases/goyal-writhing.yaml")   # raises CaseError
    case = Case.from_text(text, fmt="json")               # raises CaseError
    case = Case.model_validate(mapping)                   # raises pydantic.ValidationError
    case.canonical_json(); case.spec_hash()

Conventions (also in ``docs/case-spec.md``):

* every quantity is SI: m, s, kg, N, Pa, rad (the contact ``aperture`` is in degrees);
* boundary conditions are components in the body frame (a1, a2, a3) of the rod end;
  distributed forces and gravity are components in the global frame;
* a boundary condition with ``until: T`` is in force while ``t <= T``; the next one in the
  list takes over after ``T``;
* a table ``{t, value}`` or profile ``{s, value}`` is piecewise linear and held constant
  outside its range.

Every refusal names the field by its path, formatted like ``rod.diameter.value[2]`` or
``boundary.end.translation[2][0].until`` (see :func:`format_loc`).
"""
from __future__ import annotations

import hashlib
import json
import math
import numbers
import re
import sys
from pathlib import Path
from typing import Annotated, Any, Literal, Optional, Union

import numpy as np
import yaml
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    StrictBool,
    ValidationError,
    WrapValidator,
    field_validator,
    model_serializer,
    model_validator,
)
from pydantic_core import PydanticCustomError

__all__ = [
    "SCHEMA_VERSION",
    "OUTPUT_FIELDS",
    "DEFAULT_OUTPUT_FIELDS",
    "MATERIAL_PROPERTIES",
    "TRANSLATION_KEYS",
    "ROTATION_KEYS",
    "CaseError",
    "format_loc",
    "format_validation_errors",
    "parse_text",
    "Profile",
    "Table",
    "Rod",
    "Fluid",
    "DistributedForce",
    "PointLoad",
    "Centreline",
    "FromResult",
    "Initial",
    "Condition",
    "EndCondition",
    "Boundary",
    "Contact",
    "Electrostatics",
    "Thermal",
    "Bathymetry",
    "Friction",
    "Seabed",
    "Newton",
    "Numerics",
    "Output",
    "Case",
]

SCHEMA_VERSION = 1

#: Names accepted in ``output.fields``, in canonical order.
OUTPUT_FIELDS: tuple[str, ...] = (
    "v",
    "omega",
    "f",
    "kappa",
    "moment",
    "position",
    "orientation",
    "energies",
    "topology",
    "contact",
    "reactions",
    "bend_radius",
)
DEFAULT_OUTPUT_FIELDS: tuple[str, ...] = (
    "v",
    "omega",
    "f",
    "kappa",
    "position",
    "energies",
    "topology",
)
#: Rod properties that may be a number or a :class:`Profile`.
MATERIAL_PROPERTIES: tuple[str, ...] = ("youngs_modulus", "shear_modulus", "density", "diameter")
#: Condition keys allowed in a ``translation`` item and in a ``rotation`` item.
TRANSLATION_KEYS: tuple[str, ...] = ("velocity", "force", "position")
ROTATION_KEYS: tuple[str, ...] = ("angular_velocity", "moment")
_CONDITION_KEYS = TRANSLATION_KEYS + ROTATION_KEYS
_KINEMATIC_KEYS = frozenset({"velocity", "angular_velocity", "position"})
#: relative tolerance (of rod.length) with which a prescribed position at t = 0 must be
#: where the end starts
POSITION_RTOL = 1e-3

#: Relative slack when comparing a time with a condition's ``until``.
UNTIL_RTOL = 1e-12
#: Relative tolerance with which ``numerics.ds`` must divide ``rod.length``.
DS_RTOL = 1e-9
#: the most segments and the most nominal time steps a case may have (bounds against inputs
#: that validate but cannot run: 1e9 segments, dt = 5e-324 s)
MAX_SEGMENTS = 1_000_000
MAX_STEPS = 1e9
#: Largest |cos| allowed between ``initial.tangent`` and ``initial.normal``.
ORTHOGONALITY_TOL = 1e-9

_MODEL_CONFIG = ConfigDict(extra="forbid", allow_inf_nan=False, validate_default=True)


# --------------------------------------------------------------------------- errors


def format_loc(loc: tuple | list) -> str:
    """Format a pydantic error location as a field path.

    ``("boundary", "end", "translation", 2, 0, "until")`` becomes
    ``"boundary.end.translation[2][0].until"``; an empty location (the document itself)
    becomes ``""``.
    """
    out = ""
    for part in loc:
        if isinstance(part, int) and not isinstance(part, bool):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out


_MSG_PREFIXES = ("Value error, ", "Assertion failed, ")


def format_validation_errors(exc: ValidationError) -> list[dict]:
    """Turn a :class:`pydantic.ValidationError` into ``[{"loc", "msg", "type"}, ...]``.

    ``loc`` is a path string (:func:`format_loc`), ``msg`` a human-readable reason and
    ``type`` pydantic's (or this module's) machine-readable error type. The REST service
    reuses this for its 422 problem details; the CLI prints it. Input values are left out
    on purpose (they can be large arrays). Accepts any object with pydantic's
    ``errors()`` method.
    """
    result = []
    for err in exc.errors(include_url=False):
        msg = str(err.get("msg", ""))
        for prefix in _MSG_PREFIXES:
            if msg.startswith(prefix):
                msg = msg[len(prefix):]
        etype = str(err.get("type", "value_error"))
        if etype == "extra_forbidden":
            msg = "unknown field (not part of case spec schema v1)"
            if getattr(exc, "title", None) == "Case":
                allowed = allowed_fields(Case, tuple(err.get("loc", ()))[:-1])
                if allowed:
                    msg += f"; allowed here: {', '.join(allowed)}"
        result.append({"loc": format_loc(err.get("loc", ())), "msg": msg, "type": etype})
    return result


def allowed_fields(model: type, loc: tuple) -> list[str]:
    """Field names of the model(s) found at ``loc`` (a pydantic error location, e.g.
    ``("rod",)``) inside ``model`` (best effort: through unions, lists and Annotated)."""
    candidates: list[type] = [model]
    for part in loc:
        if isinstance(part, int):
            continue
        following: list[type] = []
        for cand in candidates:
            field = cand.model_fields.get(part)
            if field is not None:
                following.extend(_models_in(field.annotation))
        if following:
            candidates = following
        # an unmatched part is a union tag (e.g. 'function-wrap[...]'): stay on the candidates
    names: list[str] = []
    for cand in candidates:
        for name in cand.model_fields:
            if name not in names:
                names.append(name)
    return names


def _models_in(annotation: Any) -> list[type]:
    import types
    import typing

    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    origin = typing.get_origin(annotation)
    if origin is typing.Annotated:
        return _models_in(typing.get_args(annotation)[0])
    if origin in (Union, types.UnionType, list, tuple, typing.Union):
        found: list[type] = []
        for arg in typing.get_args(annotation):
            found.extend(_models_in(arg))
        return found
    return []


class CaseError(ValueError):
    """An invalid case spec, or one that could not be read or parsed.

    Raised by :meth:`Case.from_file` and :meth:`Case.from_text`; ``str(error)`` is a
    readable multi-line message, one ``path: reason`` line per error.

    Attributes
    ----------
    errors : list of dict
        ``{"loc": str, "msg": str, "type": str}`` each; ``loc`` is a field path such as
        ``rod.diameter.value[2]`` (``""`` for the document as a whole).
    """

    def __init__(self, errors: list[dict], source: Optional[str] = None):
        self.errors: list[dict] = [
            {"loc": str(e.get("loc", "")), "msg": str(e.get("msg", "")), "type": str(e.get("type", "value_error"))}
            for e in errors
        ]
        self.source = source
        super().__init__(self._render())

    @classmethod
    def from_validation_error(cls, exc: ValidationError, source: Optional[str] = None) -> "CaseError":
        """Wrap a pydantic validation error, keeping every error's field path."""
        return cls(format_validation_errors(exc), source)

    def _render(self) -> str:
        where = f" ({self.source})" if self.source else ""
        n = len(self.errors)
        head = f"invalid case spec{where}: {n} error{'s' if n != 1 else ''}"
        lines = [f"  {e['loc'] or '(case)'}: {e['msg']}".replace("\n", "\n    ") for e in self.errors]
        return "\n".join([head, *lines])

    def __str__(self) -> str:
        return self._render()


def _doc_error(msg: str, etype: str, source: Optional[str]) -> CaseError:
    """A CaseError about the document as a whole (location ``""``)."""
    return CaseError([{"loc": "", "msg": msg, "type": etype}], source)


def _err(loc: tuple, etype: str, msg: str, value: Any = None) -> dict:
    """One line error for :func:`_raise`. ``msg`` is used literally (no templating)."""
    return {"type": PydanticCustomError(etype, msg.replace("{", "(").replace("}", ")")), "loc": loc, "input": value}


def _raise(title: str, errors: list[dict]) -> None:
    """Raise a ValidationError carrying ``errors`` with their own locations.

    Raised inside a validator, pydantic keeps each error's location and prefixes the
    location of the model being validated, so nested paths come out right.
    """
    if errors:
        raise ValidationError.from_exception_data(title, errors)


# --------------------------------------------------------------------------- scalars


#: units a number may be written with in a string, and their factor to SI: what
#: :func:`_text_not_number` suggests (case-sensitive: mN is milli, MN mega)
_SI_SPELLINGS = {"m", "s", "kg", "N", "Pa", "rad", "kg/m3", "kg/m^3", "kg/m³", "m/s",
                 "rad/s", "rad/m", "N/m", "m/s2", "m/s^2", "m/s²", "N m", "N·m", "Nm",
                 "Pa s", "Pa·s", "W", "J"}
_TO_SI = {"mm": 1e-3, "cm": 1e-2, "km": 1e3, "kPa": 1e3, "MPa": 1e6, "GPa": 1e9,
          "g/cm3": 1e3, "g/cm^3": 1e3, "g/cm³": 1e3, "ms": 1e-3, "kN": 1e3, "mN": 1e-3,
          "MN": 1e6, "deg": math.pi / 180, "°": math.pi / 180, "mm/s2": 1e-3,
          "mm/s^2": 1e-3, "mm/s²": 1e-3, "min": 60.0, "h": 3600.0}
_LEADING_NUMBER = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*$")


def _text_not_number(value: str, what: str = "a number") -> PydanticCustomError:
    """The error for a string where ``what`` is expected: it echoes the text and says
    that values are SI numbers, and how to write this one where it can tell
    (``"1500 kg/m3"`` -> write 1500; ``"12.5 MPa"`` -> 12.5 MPa is 1.25e+07 in SI)."""
    shown = value if len(value) <= 60 else value[:57] + "..."
    hint = ""
    m = _LEADING_NUMBER.match(value)
    if m:
        number, unit = float(m.group(1)), m.group(2)
        if not unit:
            hint = f": write {number:g} without quotes"
        elif unit in _SI_SPELLINGS:
            hint = f": write {number:g}"
        elif unit in _TO_SI:
            si = number * _TO_SI[unit]
            hint = f": {number:g} {unit} is {si:.6g} in SI, so write {si:.6g}"
        else:
            hint = f": write the number in SI units, not in {unit!r}"
    return PydanticCustomError(
        "float_type",
        "Input should be {what}, not the text {text}: case values are plain numbers in SI "
        "units (m, s, kg, N, Pa, rad), written without a unit{hint}",
        {"what": what, "text": repr(shown), "hint": hint})


def _check_number(value: Any) -> Any:
    """Refuse strings and booleans where a number is expected (pydantic would coerce)."""
    if isinstance(value, str):
        raise _text_not_number(value)
    if isinstance(value, (bytes, bool)):
        raise PydanticCustomError("float_type", "Input should be a number, not {kind}", {"kind": type(value).__name__})
    return value


def _check_integer(value: Any) -> Any:
    """Refuse strings and booleans where an integer is expected."""
    if isinstance(value, (str, bytes, bool)):
        raise PydanticCustomError("int_type", "Input should be an integer, not {kind}", {"kind": type(value).__name__})
    return value


Finite = Annotated[float, BeforeValidator(_check_number), Field(allow_inf_nan=False)]
Integer = Annotated[int, BeforeValidator(_check_integer)]
Vector3 = Annotated[list[Finite], Field(min_length=3, max_length=3)]


def _as_float(value: Any) -> float:
    """A finite float from a real number; raises the pydantic error types otherwise."""
    if isinstance(value, str):
        raise _text_not_number(value, "a number or a table/profile mapping")
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise PydanticCustomError("float_type", "Input should be a number or a table/profile mapping")
    try:
        value = float(value)
    except OverflowError:   # an integer literal beyond the largest float, ~1.8e308
        raise PydanticCustomError("finite_number", "Input should be a finite number (this integer "
                                  "is too large for a float)") from None
    if not math.isfinite(value):
        raise PydanticCustomError("finite_number", "Input should be a finite number")
    return value


# --------------------------------------------------------------------------- tables


#: the boundary a closed rod is given (both ends free: the join's rows replace them)
_CLOSED_BOUNDARY = {
    name: {"translation": [{"force": 0.0}] * 3, "rotation": [{"moment": 0.0}] * 3}
    for name in ("start", "end")}


def _closed_rod_ends(data: Any) -> Any:
    """A case mapping of a closed rod with its boundary filled in (both ends free, never
    read: the join's rows replace the ends'). Raises ``ValidationError`` at ``boundary``
    where a closed rod is given one."""
    if not isinstance(data, dict):
        return data
    rod = data.get("rod")
    if not (isinstance(rod, dict) and rod.get("closed") is True):
        return data
    if data.get("boundary") is not None:
        raise ValidationError.from_exception_data("Case", [{
            "type": PydanticCustomError("inconsistent", "a closed rod (rod.closed) has no ends: "
                                        "leave boundary out"),
            "loc": ("boundary",), "input": data["boundary"]}])
    return {**data, "boundary": _CLOSED_BOUNDARY}


def _check_increasing(values: list[float], name: str, noun: str) -> list[dict]:
    errors = []
    for k in range(1, len(values)):
        if not values[k] > values[k - 1]:
            errors.append(
                _err(
                    (name, k),
                    "not_increasing",
                    f"{noun} must be strictly increasing: {name}[{k}] = {values[k]!r} "
                    f"is not > {name}[{k - 1}] = {values[k - 1]!r}",
                    values[k],
                )
            )
    return errors


class Profile(BaseModel):
    """A rod property along the arclength: piecewise linear in ``s``, held constant outside.

    ``s`` (m) must have at least 2 points, be strictly increasing and lie within
    ``[0, rod.length]`` (checked by :class:`Rod`); ``value`` (the property's SI unit) has
    the same number of points. Errors: ``not_increasing`` at ``s[k]``,
    ``length_mismatch`` at ``value``.
    """

    model_config = _MODEL_CONFIG

    s: list[Finite] = Field(..., min_length=2, description="Arclength stations, m; strictly increasing, within [0, rod.length].")
    value: list[Finite] = Field(
        ..., min_length=2, description="Property value at each station, in the property's SI unit (Pa, kg/m^3 or m)."
    )

    @model_validator(mode="after")
    def _check(self) -> "Profile":
        errors = _check_increasing(self.s, "s", "profile arclengths")
        if len(self.value) != len(self.s):
            errors.append(
                _err(("value",), "length_mismatch", f"has {len(self.value)} points but s has {len(self.s)}", self.value)
            )
        _raise("Profile", errors)
        return self

    def evaluate(self, s: Any) -> np.ndarray:
        """The profile at arclengths ``s`` (m): linear interpolation, ends held."""
        return np.asarray(np.interp(np.asarray(s, dtype=float), self.s, self.value), dtype=float)


class Table(BaseModel):
    """A boundary value in time: piecewise linear in ``t``, held constant outside.

    ``t`` (s) has at least 2 points and is strictly increasing; ``value`` (the
    condition's SI unit: m/s, N, rad/s or N m) has the same number of points. Errors:
    ``not_increasing`` at ``t[k]``, ``length_mismatch`` at ``value``.
    """

    model_config = _MODEL_CONFIG

    t: list[Finite] = Field(..., min_length=2, description="Times, s; strictly increasing.")
    value: list[Finite] = Field(
        ..., min_length=2, description="Value at each time, in the condition's SI unit (m/s, N, rad/s or N m)."
    )

    @model_validator(mode="after")
    def _check(self) -> "Table":
        errors = _check_increasing(self.t, "t", "table times")
        if len(self.value) != len(self.t):
            errors.append(
                _err(("value",), "length_mismatch", f"has {len(self.value)} points but t has {len(self.t)}", self.value)
            )
        _raise("Table", errors)
        return self

    def value_at(self, t: float) -> float:
        """The table at time ``t`` (s): linear interpolation, ends held."""
        return float(np.interp(float(t), self.t, self.value))


def _material(value: Any, handler: Any) -> Union[float, Profile]:
    """A positive finite number, or a :class:`Profile` whose values are all > 0."""
    if isinstance(value, (dict, Profile)):
        profile = Profile.model_validate(value)
        _raise(
            "Profile",
            [_err(("value", k), "greater_than", "must be > 0", v) for k, v in enumerate(profile.value) if not v > 0],
        )
        return profile
    number = _as_float(value)
    if not number > 0:
        raise PydanticCustomError("greater_than", "must be > 0")
    return number


def _number_or_table(value: Any, handler: Any) -> Union[float, Table]:
    """A finite number, or a :class:`Table`."""
    if isinstance(value, (dict, Table)):
        return Table.model_validate(value)
    return _as_float(value)


Material = Annotated[Union[Annotated[float, Field(gt=0)], Profile], WrapValidator(_material)]


def _number_or_profile(value: Any, handler: Any) -> Union[float, Profile]:
    """A finite number of either sign, or a :class:`Profile`."""
    if isinstance(value, (dict, Profile)):
        return Profile.model_validate(value)
    return _as_float(value)


#: a signed property along the rod: a finite number or a profile in s
SignedProfile = Annotated[Union[float, Profile], WrapValidator(_number_or_profile)]


# --------------------------------------------------------------------------- representable

#: the normal range of a double: below DOUBLE_MIN a number loses significant bits (subnormal)
#: and underflows to 0 soon after; above DOUBLE_MAX it is inf
DOUBLE_MIN = sys.float_info.min
DOUBLE_MAX = sys.float_info.max
_LN_MIN, _LN_MAX = math.log(DOUBLE_MIN), math.log(DOUBLE_MAX)


def _bounds(prop: Any) -> tuple[float, float]:
    """(natural log of the smallest, of the largest) value of a rod property: a number, or
    the values of a :class:`Profile` (the grid interpolates between them)."""
    values = prop.value if isinstance(prop, Profile) else [prop]
    return math.log(min(values)), math.log(max(values))


def _unrepresentable(name: str, formula: str, ln_lo: float, ln_hi: float) -> Optional[str]:
    """Why the quantity ``name`` (= ``formula``), whose natural log lies in [ln_lo, ln_hi]
    over the rod, is not a normal double; None when it is."""
    if ln_lo < _LN_MIN:
        return (f"{name} {formula} = {_e10(ln_lo)} underflows double precision (below "
                f"{DOUBLE_MIN:.3g}, where a double loses its digits and then becomes 0)")
    if ln_hi > _LN_MAX:
        return f"{name} {formula} = {_e10(ln_hi)} overflows double precision (above {DOUBLE_MAX:.3g})"
    return None


def _e10(ln_value: float) -> str:
    """exp(ln_value) as text, also where it is beyond a double: '4.9e-1295'."""
    exponent = math.floor(ln_value / math.log(10.0))
    mantissa = math.exp(ln_value - exponent * math.log(10.0))
    if mantissa >= 9.995:
        mantissa, exponent = mantissa / 10.0, exponent + 1
    return f"{mantissa:.3g}e{exponent:+d}"


def representability_errors(rod: "Rod") -> list[dict]:
    """The rod's coefficients that the solver cannot hold as normal doubles, as errors
    naming the field to blame (``rod.diameter``, ``rod.youngs_modulus``, ...).

    The solver forms, at every grid node (:class:`solver.properties.RodProperties`), the
    section's area A = πD²/4 and moments J1 = πD⁴/64, J3 = πD⁴/32, the stiffnesses E·J1 and
    G·J3, the mass ρA and the inertias ρJ1, ρJ3; and, to scale its Newton iterations
    (:class:`solver.scheme.RodSystem`, docs/numerics.md § 3), the bending time scale
    T = L²√(ρA/EJ1) and the floors L/T, 1/T, EJ1/L² and 1/L. Each must lie in the normal
    range of a double, [2.2e-308, 1.8e308]: below it a number loses its significant
    digits and becomes 0 (a zero stiffness or mass is a singular system), above it inf.
    Bounds over a profile take the extremes of its values, which the grid interpolates
    between. A diameter of 5e-324 m, a Young's modulus or density of 5e-324 are refused
    here; any physical material is many orders of magnitude inside."""
    length = float(rod.length)
    d_lo, d_hi = _bounds(rod.diameter)
    e_lo, e_hi = _bounds(rod.youngs_modulus)
    g_lo, g_hi = _bounds(rod.shear_modulus)
    r_lo, r_hi = _bounds(rod.density)
    ln_l = math.log(length)
    area = (math.log(math.pi / 4) + 2 * d_lo, math.log(math.pi / 4) + 2 * d_hi)
    j1 = (math.log(math.pi / 64) + 4 * d_lo, math.log(math.pi / 64) + 4 * d_hi)
    j3 = (math.log(math.pi / 32) + 4 * d_lo, math.log(math.pi / 32) + 4 * d_hi)
    checks = [
        ("diameter", "the section's area", "πD²/4", area),
        ("diameter", "the section's moment", "πD⁴/64", j1),
        ("diameter", "the section's polar moment", "πD⁴/32", j3),
    ]
    errors = []
    for field, name, formula, (lo, hi) in checks:
        why = _unrepresentable(name, formula, lo, hi)
        if why:
            errors.append(_err((field,), "not_representable", why + _fix(field), None))
            return errors                   # the rest follows from the section
    b = (e_lo + j1[0], e_hi + j1[1])
    m = (r_lo + area[0], r_hi + area[1])
    checks = [
        ("youngs_modulus", "the bending stiffness", "E·πD⁴/64", b),
        ("shear_modulus", "the torsional stiffness", "G·πD⁴/32", (g_lo + j3[0], g_hi + j3[1])),
        ("density", "the mass per length", "ρ·πD²/4", m),
        ("density", "the rotary inertia per length", "ρ·πD⁴/64", (r_lo + j1[0], r_hi + j1[1])),
    ]
    for field, name, formula, (lo, hi) in checks:
        why = _unrepresentable(name, formula, lo, hi)
        if why:
            errors.append(_err((field,), "not_representable", why + _fix(field), None))
    if errors:
        return errors
    # the scales of the Newton iterations, from the largest stiffness and mass (as the solver)
    ln_tc = 2 * ln_l + 0.5 * (m[1] - b[1])
    # blame the length where it, not the material's ratio, takes T out of range
    by = ("length",) if abs(2 * ln_l) > abs(0.5 * (m[1] - b[1])) else ("density", "youngs_modulus")
    for fields, name, formula, ln_value in (
            (by, "the bending time scale", "L²√(ρA/EJ1)", ln_tc),
            (by, "the velocity scale", "L/T", ln_l - ln_tc),
            (("youngs_modulus",), "the force scale", "EJ1/L²", b[1] - 2 * ln_l),
            (("length",), "the curvature scale", "1/L", -ln_l)):
        why = _unrepresentable(name, formula, ln_value, ln_value)
        if why:
            for field in fields:
                errors.append(_err((field,), "not_representable", why + _fix(field), None))
    return errors


def _fix(field: str) -> str:
    return (f"; rod.{field} is in SI units ({_UNITS[field]}): check its value and unit, "
            "and the other properties it is multiplied with")


_UNITS = {"diameter": "m", "youngs_modulus": "Pa", "shear_modulus": "Pa", "density": "kg/m^3",
          "length": "m"}
NumberOrTable = Annotated[Union[float, Table], WrapValidator(_number_or_table)]


# --------------------------------------------------------------------------- rod, fluid, loads


class Rod(BaseModel):
    """The rod: length and (possibly arclength-dependent) material and section.

    Each of ``youngs_modulus``, ``shear_modulus``, ``density`` and ``diameter`` is a
    positive number or a :class:`Profile` with all values > 0 and all stations within
    ``[0, length]``. Errors name the path, e.g. ``rod.diameter.value[2]: must be > 0``
    or ``rod.density.s[3]: must be within [0, length]``.
    """

    model_config = _MODEL_CONFIG

    length: Finite = Field(..., gt=0, description="Unstretched length L of the rod, m; > 0.")
    youngs_modulus: Material = Field(..., description="Young's modulus E, Pa; > 0; a number or a profile in s (m).")
    shear_modulus: Material = Field(..., description="Shear modulus G, Pa; > 0; a number or a profile in s (m).")
    density: Material = Field(..., description="Mass density of the rod material, kg/m^3; > 0; a number or a profile in s (m).")
    diameter: Material = Field(
        ..., description="Diameter of the circular cross-section, m; > 0; a number or a profile in s (m)."
    )
    minimum_bend_radius: Optional[Finite] = Field(
        None, gt=0, description="The cable's minimum bend radius (MBR, from its datasheet), m; > 0; "
        "null: none. The result's events then say when the smallest bend radius first falls "
        "below it (solver.results.run_events).")
    intrinsic_curvature: Optional[list[SignedProfile]] = Field(
        None, min_length=3, max_length=3,
        description="The unloaded rod's curvatures and twist [kappa0_1, kappa0_2, kappa0_3] in the "
        "body frame, 1/m, each a number or a profile in s (m); the constitutive law is "
        "q = K (kappa - kappa0). null: straight and untwisted. Taken by the statics and "
        "numerics.formulation: centreline.")
    closed: bool = Field(
        False, description="A closed rod (a ring: a plasmid, a loop of cable): s = L joined to s = 0 "
        "with continuity of position, frame, force and moment; no boundary. It starts as a "
        "circle (initial.linking_number). Only numerics.formulation: centreline, dynamics.")

    @model_validator(mode="after")
    def _check_stations(self) -> "Rod":
        errors = representability_errors(self)
        profiles = [((name,), getattr(self, name)) for name in MATERIAL_PROPERTIES]
        profiles += [(("intrinsic_curvature", i), prop)
                     for i, prop in enumerate(self.intrinsic_curvature or ())]
        for loc, prop in profiles:
            if isinstance(prop, Profile):
                for k, s in enumerate(prop.s):
                    if not (0.0 <= s <= self.length):
                        errors.append(
                            _err(loc + ("s", k), "out_of_range", f"must be within [0, length] = [0, {self.length!r}] m", s)
                        )
        _raise("Rod", errors)
        return self

    @model_serializer(mode="wrap")
    def _drop_unused(self, handler: Any):  # no return type: keeps the JSON schema
        # added after schema 1's first release: written only when given, so that a case
        # without it keeps its canonical JSON and spec_hash
        out = handler(self)
        for name in ("minimum_bend_radius", "intrinsic_curvature"):
            if getattr(self, name) is None:
                out.pop(name, None)
        if not self.closed:
            out.pop("closed", None)
        return out

    def evaluate_intrinsic_curvature(self, s: Any) -> np.ndarray:
        """κ⁰ (..., 3) (1/m) at arclengths ``s`` (m, any shape): each component's number
        broadcast or profile interpolated linearly (held outside its stations); zeros
        without ``intrinsic_curvature``. Raises nothing."""
        s_arr = np.asarray(s, dtype=float)
        out = np.zeros(s_arr.shape + (3,))
        for i, prop in enumerate(self.intrinsic_curvature or ()):
            out[..., i] = prop.evaluate(s_arr) if isinstance(prop, Profile) else float(prop)
        return out

    def evaluate(self, name: str, s: Any) -> np.ndarray:
        """Property ``name`` (one of :data:`MATERIAL_PROPERTIES`) at arclengths ``s`` (m).

        Returns a float array shaped like ``s``, in the property's SI unit. A number is
        broadcast; a profile is interpolated linearly and held constant outside its
        stations. Raises ``ValueError`` for an unknown name.
        """
        if name not in MATERIAL_PROPERTIES:
            raise ValueError(f"unknown rod property {name!r}; expected one of {', '.join(MATERIAL_PROPERTIES)}")
        prop = getattr(self, name)
        s_arr = np.asarray(s, dtype=float)
        if isinstance(prop, Profile):
            return prop.evaluate(s_arr)
        return np.full(s_arr.shape, float(prop))


class Fluid(BaseModel):
    """The surrounding fluid: buoyancy, Morison-type added mass and quadratic drag, and
    with ``viscosity`` the linear Stokes drag of resistive-force theory. Omit for vacuum.

    ``density`` (kg/m³) gives the buoyancy and the added mass; the Morison drag per length
    is ½ρ_f D C_dn |v_n| v_n across the axis and ½ρ_f πD C_dt |v_t| v_t along it.
    ``viscosity`` μ (Pa s; null: none) adds the drag of a slender body at low Reynolds
    number, −R(ζ_n v_n + ζ_t v_t e3) per length and −ζ_r W3 a3 about the axis, with
    ζ_n = 4πμ/(ln(ℓ/d) + 0.84), ζ_t = 2πμ/(ln(ℓ/d) − 0.20) (Tirado & García de la Torre,
    J. Chem. Phys. 71, 2581, 1979, Table I, p⁻¹ = 0) and ζ_r = πμd² = 4πμa² (the exact
    Stokes flow around a cylinder turning about its axis); ℓ is ``slenderness_length``,
    the rod's length when null, d the local diameter (:mod:`solver.resistive_force`).
    Both drags act where both are given, summed; at a Reynolds number Re = ρ_f |v| d/μ the
    Morison share is of order Re, so a case at Re ≪ 1 (water at 25 °C: density 1000,
    viscosity 8.9e-4) may keep the Morison defaults or set ``drag_coefficient_normal: 0``.
    Only ``numerics.formulation: centreline`` takes ``viscosity`` (checked by
    :class:`Case`), and ℓ/d must be at least 2 over the rod (checked by :class:`Case`).
    """

    model_config = _MODEL_CONFIG

    density: Finite = Field(..., gt=0, description="Fluid density, kg/m^3; > 0.")
    added_mass_coefficient: Finite = Field(
        1.0, ge=0, description="Added-mass coefficient C_a (dimensionless, normal motion); >= 0."
    )
    drag_coefficient_normal: Finite = Field(1.0, ge=0, description="Normal drag coefficient C_dn (dimensionless); >= 0.")
    drag_coefficient_tangential: Finite = Field(
        0.0, ge=0, description="Tangential drag coefficient C_dt (dimensionless); >= 0."
    )
    viscosity: Optional[Finite] = Field(
        None, gt=0, description="Dynamic viscosity mu, Pa s; > 0; null: no viscous drag. Adds the "
        "linear Stokes drag of resistive-force theory (low Reynolds number; water at 25 C: 8.9e-4); "
        "numerics.formulation centreline only.")
    slenderness_length: Optional[Finite] = Field(
        None, gt=0, description="The length l of the slenderness factor ln(l/d) in the viscous drag "
        "coefficients, m; > 0, l/d >= 2; null: rod.length. Only with viscosity.")

    @model_validator(mode="after")
    def _check(self) -> "Fluid":
        if self.slenderness_length is not None and self.viscosity is None:
            _raise("Fluid", [_err(("slenderness_length",), "unsupported",
                                  "only read with fluid.viscosity (the viscous drag's "
                                  "slenderness factor); give viscosity or leave it out",
                                  self.slenderness_length)])
        return self

    @model_serializer(mode="wrap")
    def _drop_unused(self, handler: Any):  # no return type: keeps the JSON schema
        # added after schema 1's first release: written only when given, so that a case
        # without them keeps its canonical JSON and spec_hash
        out = handler(self)
        for name in ("viscosity", "slenderness_length"):
            if getattr(self, name) is None:
                out.pop(name, None)
        return out


class DistributedForce(BaseModel):
    """A uniform force per unit length, global frame, applied for ``start <= t < end``.

    ``value`` is N/m in the global frame; ``start``/``end`` are times in s (``end`` None:
    until the end of the run; ``end`` must be > ``start``); ``s_range`` optionally limits
    it to arclengths ``[s0, s1]`` in m (``s0 < s1``, both within ``[0, rod.length]``,
    checked by :class:`Case`); ``factor`` optionally scales it in time by a dimensionless
    :class:`Table` (piecewise linear, held constant outside its knots), so that a load can
    be ramped on and off smoothly instead of switched (a switch costs the scheme an order
    at the switch unless the step lands on it and restarts, docs/numerics.md § 7).
    """

    model_config = _MODEL_CONFIG

    value: Vector3 = Field(..., description="Force per unit length, N/m, global-frame components [x, y, z].")
    start: Finite = Field(0.0, ge=0, description="Time the force is switched on, s; >= 0.")
    end: Optional[Finite] = Field(
        None, description="Time the force is switched off (exclusive), s; > start; null: never switched off."
    )
    s_range: Optional[Annotated[list[Finite], Field(min_length=2, max_length=2)]] = Field(
        None, description="Arclength interval [s0, s1] the force acts on, m; s0 < s1 within [0, rod.length]; null: whole rod."
    )
    factor: Optional[Table] = Field(
        None,
        description="Dimensionless multiplier of value in time: a table {t: [s], value: [-]}, piecewise "
        "linear, held constant outside its knots (e.g. a ramp {t: [0, 1], value: [0, 1]}); null: 1.",
    )

    @model_validator(mode="after")
    def _check(self) -> "DistributedForce":
        errors = []
        if self.end is not None and not self.end > self.start:
            errors.append(_err(("end",), "greater_than", f"must be > start = {self.start!r} s", self.end))
        if self.s_range is not None and not self.s_range[1] > self.s_range[0]:
            s0, s1 = self.s_range
            errors.append(_err(("s_range", 1), "greater_than", f"must be > s_range[0] = {s0!r} m", s1))
        _raise("DistributedForce", errors)
        return self

    def is_active(self, t: float) -> bool:
        """Whether the force acts at time ``t`` (s): ``start <= t < end``."""
        return self.start <= t and (self.end is None or t < self.end)

    def scale_at(self, t: float) -> float:
        """The ``factor`` table at time ``t`` (s), 1 without one (dimensionless)."""
        return 1.0 if self.factor is None else self.factor.value_at(t)


class PointLoad(BaseModel):
    """A concentrated force (N) at one arclength ``s`` (m), applied for ``start <= t < end``.

    ``value`` is N in the global frame (a dead load: its direction is fixed in space),
    or with ``body: true`` components along the directors (a1, a2, a3) at ``s`` (a
    follower load, turning with the rod). ``s`` must lie within ``[0, rod.length]``
    (checked by :class:`Case`). ``factor`` scales it in time like a distributed force's
    (:class:`DistributedForce`). The solver places the load as a jump of the internal
    force at a node (exact), or, between nodes, splits it over the two nodes of its cell
    by the lever rule (:mod:`solver.loads`).
    """

    model_config = _MODEL_CONFIG

    s: Finite = Field(..., description="Arclength at which the load acts, m; within [0, rod.length].")
    value: Vector3 = Field(
        ..., description="Force, N: global-frame components [x, y, z], or with body: true "
        "components along the directors a1, a2, a3 at s.")
    body: StrictBool = Field(False, description="true: a follower load (value in the body frame); "
                       "false: a dead load (value in the global frame).")
    start: Finite = Field(0.0, ge=0, description="Time the load is switched on, s; >= 0.")
    end: Optional[Finite] = Field(
        None, description="Time the load is switched off (exclusive), s; > start; null: never switched off."
    )
    factor: Optional[Table] = Field(
        None,
        description="Dimensionless multiplier of value in time: a table {t: [s], value: [-]}, piecewise "
        "linear, held constant outside its knots; null: 1.",
    )

    @model_validator(mode="after")
    def _check(self) -> "PointLoad":
        if self.end is not None and not self.end > self.start:
            _raise("PointLoad", [_err(("end",), "greater_than", f"must be > start = {self.start!r} s",
                                      self.end)])
        return self

    def is_active(self, t: float) -> bool:
        """Whether the load acts at time ``t`` (s): ``start <= t < end``."""
        return self.start <= t and (self.end is None or t < self.end)

    def scale_at(self, t: float) -> float:
        """The ``factor`` table at time ``t`` (s), 1 without one (dimensionless)."""
        return 1.0 if self.factor is None else self.factor.value_at(t)


def _unit(v: list[float]) -> list[float]:
    """``v`` scaled to unit length; idempotent (a unit vector is returned unchanged)."""
    norm = math.hypot(*v)
    if abs(norm - 1.0) <= 1e-15:
        return [float(x) for x in v]
    return [x / norm for x in v]


def _straight(centreline: Optional["Centreline"]) -> bool:
    """Whether an initial centreline (None: the default straight rod) is a straight
    line: every point within 1e-9 of its span from the line through its ends."""
    if centreline is None:
        return True
    P = np.asarray(centreline.points, float)
    d = P[-1] - P[0]
    span = float(np.linalg.norm(d))
    if span == 0.0:
        return False
    off = np.cross(P - P[0], d / span)
    return bool(np.linalg.norm(off, axis=1).max() <= 1e-9 * span)


class Centreline(BaseModel):
    """An initial centreline: ``points`` (m, global), at least 2, no two consecutive
    ones equal (``zero_segment``). The run resamples it by arclength
    (:mod:`solver.initial`); its length must match ``rod.length`` (checked by
    :class:`Case`)."""

    model_config = _MODEL_CONFIG

    points: list[Vector3] = Field(..., min_length=2, description="Points along the centreline, m, "
                                  "global frame, from s = 0 to s = L.")

    @model_validator(mode="after")
    def _check(self) -> "Centreline":
        errors = []
        for k in range(1, len(self.points)):
            if self.points[k] == self.points[k - 1]:
                errors.append(_err(("points", k), "zero_segment",
                                   f"equals points[{k - 1}]: a zero-length segment", self.points[k]))
        _raise("Centreline", errors)
        return self


class FromResult(BaseModel):
    """Start from the state of an earlier result at one of its output times ``time`` (s):
    ``file``, a result NetCDF written by hockle (read by the CLI and the Python API; a path
    is never read over HTTP), or ``job``, the id of an earlier successful job of the same
    owner (resolved by the service only). Exactly one of the two. The solver itself reads
    nothing: the caller reads the state (:func:`hockle.io.read_start_state`, the service's
    :func:`service.validation.start_from_job`) and hands it to :func:`solver.integrate`."""

    model_config = _MODEL_CONFIG

    file: Optional[str] = Field(None, min_length=1, max_length=4096,
                                description="Path of the earlier result (NetCDF); CLI and Python API.")
    job: Optional[str] = Field(None, min_length=1, max_length=64,
                               description="Id of an earlier successful job of the same owner; over HTTP.")
    time: Finite = Field(..., ge=0, description="Output time of the earlier result to start from, s.")

    @model_validator(mode="after")
    def _one_source(self) -> "FromResult":
        if (self.file is None) == (self.job is None):
            _raise("FromResult", [_err(("file",) if self.file is None else ("job",),
                                       "missing" if self.file is None else "inconsistent",
                                       "give exactly one of file (a result file: CLI, Python "
                                       "API) and job (an earlier job's id: over HTTP)", None)])
        return self

    @model_serializer(mode="wrap")
    def _drop_unset(self, handler: Any):  # no return type: keeps the JSON schema
        out = handler(self)
        for name in ("file", "job"):
            if out.get(name) is None:
                out.pop(name, None)
        return out


class Initial(BaseModel):
    """The initial configuration: by default a straight, stress-free rod with its start
    at the origin; or a given ``centreline``, and an initial ``twist_rate``.

    ``tangent`` is the global direction of a3 along the rod, ``normal`` that of a1.
    Both must be non-zero and, once normalised, orthogonal within |cos| <= 1e-9. After
    validation both are unit vectors (plain lists of floats) and ``normal`` is exactly
    orthogonal to ``tangent`` (projected, to round-off). ``binormal`` gives a2.

    With a ``centreline``, ``tangent`` is its tangent at the first point (left out, it
    is set to it; given, it must agree within 1e-6 rad) and ``normal`` (a1 at s = 0) is
    projected onto the plane normal to it (refused when within 1e-3 rad of parallel;
    left out, the default [1, 0, 0], or where that is within 25° of the tangent the
    global axis least aligned with it). ``twist_rate`` (rad/m)
    is κ3 along the whole rod at t = 0. Both new fields are written to the canonical
    JSON only when used.
    """

    model_config = _MODEL_CONFIG

    centreline: Optional[Centreline] = Field(
        None, description="Initial centreline points, m, resampled by arclength; null: straight.")
    twist_rate: Finite = Field(0.0, description="Initial twist rate kappa_3, rad/m, along the whole rod.")
    from_result: Optional[FromResult] = Field(
        None, description="Start from an earlier result's state at one of its output times; null: no.")
    linking_number: Optional[int] = Field(
        None, description="A closed rod's start: the circle's frame turns this many times about its "
        "tangent (its Lk, turns; the excess over the relaxed ring's is Lk minus the integral of "
        "kappa0_3 over 2 pi); only with rod.closed; null: 0.")

    tangent: Vector3 = Field(
        default_factory=lambda: [0.0, 0.0, 1.0],
        description="Global direction of the body axis a3 (dimensionless, normalised by the model).",
    )
    normal: Vector3 = Field(
        default_factory=lambda: [1.0, 0.0, 0.0],
        description="Global direction of the body axis a1 (dimensionless, normalised by the model); orthogonal to tangent.",
    )

    @model_validator(mode="after")
    def _normalise(self) -> "Initial":
        if self.from_result is not None and (self.centreline is not None or self.twist_rate != 0.0):
            _raise("Initial", [_err(("from_result",), "inconsistent",
                                    "from_result gives the whole start state: leave out centreline "
                                    "and twist_rate", None)])
        if self.centreline is not None:
            return self._along_centreline()
        errors = []
        for name in ("tangent", "normal"):
            if math.hypot(*getattr(self, name)) == 0.0:
                errors.append(_err((name,), "zero_vector", "must be a non-zero vector", getattr(self, name)))
        _raise("Initial", errors)
        t = _unit(self.tangent)
        n = _unit(self.normal)
        cos = sum(a * b for a, b in zip(t, n))
        if abs(cos) > ORTHOGONALITY_TOL:
            _raise(
                "Initial",
                [
                    _err(
                        ("normal",),
                        "not_orthogonal",
                        f"must be orthogonal to initial.tangent (|cos| = {abs(cos):.3g} > 1e-9)",
                        self.normal,
                    )
                ],
            )
        if abs(cos) > 1e-14:
            n = _unit([b - cos * a for a, b in zip(t, n)])
        self.tangent = t
        self.normal = n
        return self

    def _along_centreline(self) -> "Initial":
        from .initial import Curve

        t0 = Curve(self.centreline.points).start_tangent()
        given = self.model_fields_set
        if "tangent" in given:
            norm = math.hypot(*self.tangent)
            cos = float(np.dot(t0, self.tangent) / norm) if norm > 0 else -1.0
            if not cos >= math.cos(1e-6):
                _raise("Initial", [_err(("tangent",), "inconsistent",
                                        f"must be the centreline's tangent at its first point "
                                        f"({', '.join(f'{x:.6g}' for x in t0)}), or be left out",
                                        self.tangent)])
        if "normal" in given:
            n = np.asarray(self.normal, float)
            norm = float(np.linalg.norm(n))
            if norm == 0.0 or abs(float(np.dot(n, t0))) / norm > math.cos(1e-3):
                _raise("Initial", [_err(("normal",), "not_orthogonal",
                                        "must not be parallel to the centreline's tangent at "
                                        "its first point", self.normal)])
        else:
            n = np.asarray(self.normal, float)     # the default, unless nearly parallel
            if abs(float(np.dot(n, t0))) > 0.9:
                n = np.eye(3)[int(np.argmin(np.abs(t0)))]
        n = n - float(np.dot(n, t0)) * t0
        self.tangent = [float(x) for x in t0]
        self.normal = [float(x) for x in n / np.linalg.norm(n)]
        return self

    @model_serializer(mode="wrap")
    def _drop_unused(self, handler: Any):  # no return type: keeps the JSON schema
        out = handler(self)
        if self.centreline is None:
            out.pop("centreline", None)
        if self.twist_rate == 0.0:
            out.pop("twist_rate", None)
        if self.from_result is None:
            out.pop("from_result", None)
        if self.linking_number is None:
            out.pop("linking_number", None)
        return out

    @property
    def binormal(self) -> list[float]:
        """a2 = a3 x a1 (global components, unit vector)."""
        t, n = self.tangent, self.normal
        return [t[1] * n[2] - t[2] * n[1], t[2] * n[0] - t[0] * n[2], t[0] * n[1] - t[1] * n[0]]


# --------------------------------------------------------------------------- boundary conditions


class Condition(BaseModel):
    """One boundary condition on one degree of freedom of one rod end.

    Exactly one of ``velocity`` (m/s) / ``force`` (N) for a translation item, or
    ``angular_velocity`` (rad/s) / ``moment`` (N m) for a rotation item; components are
    in the body frame of that end. The value is a number or a :class:`Table` in time.
    ``until`` (s, > 0) makes the condition hold while ``t <= until``; it is required on
    every item of a list but the last, and forbidden on the last (see
    :class:`EndCondition`). Errors: ``two_conditions`` ("two conditions for one DOF"),
    ``missing_condition``; the group check happens in :class:`EndCondition`.
    """

    model_config = _MODEL_CONFIG

    velocity: Optional[NumberOrTable] = Field(None, description="Prescribed velocity component, m/s, body frame (translation only).")
    force: Optional[NumberOrTable] = Field(None, description="Applied force component, N, body frame (translation only).")
    angular_velocity: Optional[NumberOrTable] = Field(
        None, description="Prescribed angular velocity component, rad/s, body frame (rotation only)."
    )
    moment: Optional[NumberOrTable] = Field(None, description="Applied moment component, N m, body frame (rotation only).")
    position: Optional[NumberOrTable] = Field(
        None, description="Prescribed position component, m, global frame (translation of an end with frame: global only).")
    until: Optional[Finite] = Field(None, gt=0, description="Last time this condition is in force (t <= until), s; > 0.")

    @model_validator(mode="after")
    def _exactly_one(self) -> "Condition":
        given = [k for k in _CONDITION_KEYS if getattr(self, k) is not None]
        if len(given) > 1:
            raise PydanticCustomError(
                "two_conditions",
                "two conditions for one DOF ({given}); give exactly one of velocity/force (translation) "
                "or angular_velocity/moment (rotation) per item, and use a list with until to switch",
                {"given": ", ".join(given)},
            )
        if not given:
            raise PydanticCustomError(
                "missing_condition",
                "no condition given; give one of velocity/force (translation) or angular_velocity/moment (rotation)",
            )
        return self

    @model_serializer(mode="wrap")
    def _drop_absent(self, handler: Any) -> dict:
        return {k: v for k, v in handler(self).items() if v is not None}

    @property
    def kind(self) -> str:
        """The key given: ``velocity``, ``force``, ``angular_velocity`` or ``moment``."""
        for key in _CONDITION_KEYS:
            if getattr(self, key) is not None:
                return key
        raise AssertionError("a validated Condition has exactly one key")

    @property
    def value(self) -> Union[float, Table]:
        """The number or :class:`Table` given for :attr:`kind`."""
        return getattr(self, self.kind)

    @property
    def kinematic(self) -> bool:
        """True for ``velocity``/``angular_velocity``, False for ``force``/``moment``."""
        return self.kind in _KINEMATIC_KEYS

    def value_at(self, t: float) -> float:
        """The value at time ``t`` (s), SI unit of :attr:`kind`; a table is held at its ends."""
        value = self.value
        if isinstance(value, Table):
            return value.value_at(t)
        return float(value)


def _as_condition_list(value: Any) -> Any:
    """A single condition mapping becomes a one-item list (the canonical form)."""
    if isinstance(value, (dict, Condition)):
        return [value]
    return value


DOFConditions = Annotated[list[Condition], BeforeValidator(_as_condition_list), Field(min_length=1)]


class EndCondition(BaseModel):
    """The six conditions at one rod end: ``translation`` and ``rotation``, 3 items each.

    Item ``i`` is the body-frame component ``i + 1`` (a1, a2, a3). An item is a single
    condition mapping or a list of them switching in time with ``until``; it is stored
    as a list (a single mapping becomes a one-item list). Rules, each refused with the
    item's path: translation items take ``velocity``/``force`` and rotation items
    ``angular_velocity``/``moment`` (``wrong_group``); every list item but the last has
    ``until`` (``until_required``), strictly increasing (``not_increasing``); the last has
    none (``no_condition_after``: "boundary DOF has no condition after t=...").
    """

    model_config = _MODEL_CONFIG

    translation: Annotated[list[DOFConditions], Field(min_length=3, max_length=3)] = Field(
        ..., description="Conditions on the 3 body-frame translation DOFs: velocity (m/s) or force (N)."
    )
    rotation: Annotated[list[DOFConditions], Field(min_length=3, max_length=3)] = Field(
        ..., description="Conditions on the 3 body-frame rotation DOFs: angular_velocity (rad/s) or moment (N m)."
    )
    frame: Literal["body", "global"] = Field(
        "body", description="body: items are components along a1, a2, a3 of the end; global: translation "
        "items are global x, y, z components (velocity m/s, position m, force N) and the rotation is "
        "held fixed in space (angular_velocity 0) or free (moment 0).")

    @model_serializer(mode="wrap")
    def _drop_body_frame(self, handler: Any):  # no return type: keeps the JSON schema
        out = handler(self)
        if self.frame == "body":
            out.pop("frame", None)
        return out

    @property
    def rotation_mode(self) -> Optional[str]:
        """With ``frame: global``: ``"fixed"`` (every rotation item angular_velocity 0) or
        ``"free"`` (every one moment 0); None otherwise (the rotation does not switch)."""
        if self.frame != "global":
            return None
        kinds = {c[0].kind for c in self.rotation}
        return "fixed" if kinds == {"angular_velocity"} else "free"

    def _check_global(self) -> list[dict]:
        """The rules of ``frame: global`` (docs/case-spec.md, "Global-frame ends")."""
        errors = []
        for i, conditions in enumerate(self.rotation):
            if len(conditions) > 1:
                errors.append(_err(("rotation", i), "unsupported",
                                   "the rotation of an end with frame: global does not switch in "
                                   "time: give one condition per rotation item", None))
        untils = [[c.until for c in conditions] for conditions in self.translation]
        if any(u != untils[0] for u in untils[1:]):
            errors.append(_err(("translation",), "unsupported",
                               "the three translation items of an end with frame: global switch "
                               "together: give them the same until times", None))
        if errors:
            return errors
        rot = [c[0] for c in self.rotation]
        fixed = all(c.kind == "angular_velocity" and not isinstance(c.value, Table)
                    and c.value == 0.0 for c in rot)
        free = all(c.kind == "moment" and not isinstance(c.value, Table) and c.value == 0.0
                   for c in rot)
        if not (fixed or free):
            errors.append(_err(("rotation",), "unsupported",
                               "with frame: global the rotation is held fixed in space (every item "
                               "angular_velocity: 0) or free (every item moment: 0)", None))
            return errors
        for j in range(len(untils[0])):
            phase = [conditions[j] for conditions in self.translation]
            kinds = [c.kind for c in phase]
            # kinematic (held or moved, the rotation fixed or free) or force
            if not set(kinds) <= {"velocity", "position"} and set(kinds) != {"force"}:
                errors.append(_err(("translation",), "mixed_frame_conditions",
                                   f"with frame: global the three translation items must all be "
                                   f"kinematic (velocity/position) or all force at any time, got "
                                   f"{', '.join(kinds)}: a mixed set would tie the end's body "
                                   "components together", None))
        return errors

    @model_validator(mode="after")
    def _check(self) -> "EndCondition":
        errors = []
        if self.frame != "global":
            for i, conditions in enumerate(self.translation):
                for j, cond in enumerate(conditions):
                    if cond.kind == "position":
                        errors.append(_err(("translation", i, j, "position"), "wrong_frame",
                                           "position is a global-frame condition: give the end "
                                           "frame: global", None))
        for group, allowed in (("translation", TRANSLATION_KEYS), ("rotation", ROTATION_KEYS)):
            for i, conditions in enumerate(getattr(self, group)):
                for j, cond in enumerate(conditions):
                    if cond.kind not in allowed:
                        errors.append(
                            _err(
                                (group, i, j, cond.kind),
                                "wrong_group",
                                f"{cond.kind} is not allowed in a {group} item; allowed keys: {', '.join(allowed)}",
                                cond.value if not isinstance(cond.value, Table) else None,
                            )
                        )
                last = len(conditions) - 1
                previous = None
                for j, cond in enumerate(conditions):
                    if j < last and cond.until is None:
                        errors.append(
                            _err((group, i, j, "until"), "until_required",
                                 "until (s) is required on every condition of a list but the last", None)
                        )
                    if j == last and cond.until is not None:
                        errors.append(
                            _err((group, i, j, "until"), "no_condition_after",
                                 f"boundary DOF has no condition after t={cond.until!r} s: "
                                 "the last condition of a DOF must not have until", cond.until)
                        )
                    if cond.until is not None:
                        if previous is not None and not cond.until > previous:
                            errors.append(
                                _err((group, i, j, "until"), "not_increasing",
                                     f"until must increase along the list: {cond.until!r} is not > {previous!r} s", cond.until)
                            )
                        previous = cond.until
        _raise("EndCondition", errors)
        if self.frame == "global":
            _raise("EndCondition", self._check_global())
        return self

    def active(self, group: str, i: int, t: float) -> Condition:
        """The condition in force on DOF ``i`` (0, 1, 2) of ``group`` at time ``t`` (s).

        ``group`` is ``"translation"`` or ``"rotation"``. Returns the first condition of
        the list whose ``until`` is None or satisfies ``t <= until * (1 + 1e-12)``.
        Raises ``ValueError`` for an unknown group and ``IndexError`` for ``i`` outside 0..2.
        """
        if group not in ("translation", "rotation"):
            raise ValueError(f"unknown group {group!r}; expected 'translation' or 'rotation'")
        if not 0 <= i <= 2:
            raise IndexError(f"DOF index {i} outside 0..2")
        conditions = getattr(self, group)[i]
        for cond in conditions:
            if cond.until is None or t <= cond.until * (1.0 + UNTIL_RTOL):
                return cond
        return conditions[-1]  # unreachable for a validated spec: the last has no until


class Boundary(BaseModel):
    """Boundary conditions at both ends: ``start`` (s = 0) and ``end`` (s = L)."""

    model_config = _MODEL_CONFIG

    start: EndCondition = Field(..., description="Conditions at s = 0 (body-frame components).")
    end: EndCondition = Field(..., description="Conditions at s = L (body-frame components).")


# --------------------------------------------------------------------------- contact, numerics, output


class Contact(BaseModel):
    """Self-contact: pair search parameters and the penalty/damping law. Omit for none.

    The repulsive force per unit length is ``rho*A*k1/gap**k2`` (``law: seed``, the
    default) or IPC's compact-support barrier (``law: barrier``), plus damping set by
    ``k3`` and ``k4`` (docs/contact.md gives the exact laws).
    """

    model_config = _MODEL_CONFIG

    aperture: Finite = Field(
        ..., gt=0, le=180, description="Search cone aperture, degrees (the only non-SI field); in (0, 180]."
    )
    tolerance: Finite = Field(..., gt=0, description="Centreline distance below which pairs are tested, m; > 0.")
    k1: Finite = Field(..., ge=0, description="Repulsion stiffness, m^(1+k2)/s^2 (rho*A*k1/gap^k2 is N/m); >= 0.")
    k2: Finite = Field(..., gt=0, description="Repulsion exponent on the surface gap (dimensionless); > 0.")
    k3: Finite = Field(..., ge=0, description="Contact damping coefficient (SI, per the solver's contact law); >= 0.")
    k4: Finite = Field(..., ge=0, description="Contact damping exponent (dimensionless); >= 0.")
    exclusion: Optional[Finite] = Field(
        None, ge=0, description="Minimum arclength separation of a contact pair, m (on a closed rod "
        "the shorter way round the ring); >= 0; null: 2 x the largest diameter."
    )
    law: Literal["seed", "barrier"] = Field(
        "seed",
        description="Repulsion law: 'seed' (rho*A*k1/gap^k2, seed eq. 6, cut off C2-smoothly at the tolerance) "
        "or 'barrier' (IPC's compact-support log barrier with barrier_gap and barrier_stiffness, stiff enough "
        "that impacts stop at a fair fraction of barrier_gap: docs/contact.md); the k3/k4 damping applies to both.",
    )
    barrier_gap: Optional[Finite] = Field(
        None, gt=0, description="Barrier law: surface gap at which the repulsion starts (d_hat), m; > 0."
    )
    barrier_stiffness: Optional[Finite] = Field(
        None, gt=0, description="Barrier law: stiffness kappa, 1/s^2 (rho*A*kappa*[2(g-d)ln(g/d)+(g-d)^2/g] is N/m); > 0."
    )
    position_tolerance: Optional[Finite] = Field(
        None, gt=0,
        description="Largest position error per step where strands may meet, m; > 0 (the step is refused and "
        "cut above it, and the next step's size is chosen from its ratio to this bound; estimated as the "
        "distance between each node advanced in time and the centreline integrated from the curvature). "
        "Null: a quarter of (tolerance - largest diameter), and with "
        "numerics.tolerance at most its relative value x the rod length (docs/contact.md).",
    )
    end_drift_tolerance: Optional[Finite] = Field(
        None, gt=0,
        description="Largest distance, m, between the s = L end of the centreline integrated from the curvature "
        "(the positions the output reports) and the end's prescribed motion, along its prescribed translations; "
        "> 0. A step that would exceed it ends the run (solver_diverged): the two part at the box rule's "
        "route rate, an error in s that shorter steps do not lower (refine numerics.n_segments). "
        "Null: the rod's largest diameter (docs/contact.md).",
    )

    @model_validator(mode="after")
    def _barrier_parameters(self) -> "Contact":
        if self.law == "barrier":
            for name in ("barrier_gap", "barrier_stiffness"):
                if getattr(self, name) is None:
                    raise PydanticCustomError(
                        "missing_barrier_parameter",
                        "law 'barrier' needs {name} (> 0)", {"name": name})
        return self

    @model_serializer(mode="wrap")
    def _drop_unused(self, handler: Any) -> dict:
        out = handler(self)
        if self.law == "seed":
            for name in ("barrier_gap", "barrier_stiffness"):
                if out.get(name) is None:
                    out.pop(name, None)
        if self.end_drift_tolerance is None:
            # added after schema 1's first release: written only when given, so that a
            # case without it keeps its canonical JSON and spec_hash
            out.pop("end_drift_tolerance", None)
        return out


class Electrostatics(BaseModel):
    """Screened electrostatics: the Debye–Hückel repulsion of a charged rod (DNA) between
    its non-adjacent segments (:mod:`solver.electrostatics`, docs/contact.md § 7). Omit
    for none.

    The energy of two line elements ds, ds' at distance ρ is
    ν²/(4π ε₀ ε_r) e^{−ρ/λ}/ρ ds ds' (two parallel lines at distance d repel with
    ν²/(2π ε₀ ε_r λ) K₁(d/λ) per length), switched off C²-smoothly over the last Debye
    length before ``cutoff`` · λ, between segments at least ``exclusion`` apart in
    arclength, by Gauss–Legendre quadrature with ``quadrature_points`` per segment. λ is
    ``debye_length``, or that of a 1:1 salt of ``salt_concentration`` at
    ``temperature`` (λ = √(ε₀ ε_r k_B T / (2 N_A e² 1000 c))); give one or the other.
    Only ``numerics.formulation: centreline`` takes it (checked by :class:`Case`).
    """

    model_config = _MODEL_CONFIG

    charge_per_length: Finite = Field(
        ..., gt=0, description="Magnitude of the (effective) line charge nu, C/m; > 0 (for DNA, "
        "Stigter's effective charge, docs/contact.md section 7; the bare charge of B-DNA is "
        "2e per 0.34 nm = 9.4e-10 C/m).")
    debye_length: Optional[Finite] = Field(
        None, gt=0, description="Debye screening length lambda, m; > 0; null: from salt_concentration "
        "and temperature.")
    salt_concentration: Optional[Finite] = Field(
        None, gt=0, description="Molar concentration of a 1:1 salt (NaCl), mol/L; > 0; with "
        "temperature, instead of debye_length.")
    temperature: Optional[Finite] = Field(
        None, gt=0, description="Temperature, K; > 0; with salt_concentration, instead of debye_length.")
    relative_permittivity: Finite = Field(
        78.4, ge=1, description="Relative permittivity of the solvent (dimensionless); >= 1; "
        "default water at 25 C (IAPWS, Fernandez et al. 1997).")
    cutoff: Finite = Field(
        6.0, ge=2, description="Cut-off distance in Debye lengths; >= 2 (the interaction is switched "
        "off over the last Debye length before it).")
    exclusion: Optional[Finite] = Field(
        None, gt=0, description="Least arclength between two segments that interact, m (on a closed "
        "rod the shorter way round the ring); > 0; "
        "null: the cut-off distance (a straight rod then stores no electrostatic energy).")
    quadrature_points: Integer = Field(
        6, ge=1, le=16, description="Gauss-Legendre points per segment of a pair; 1 to 16.")

    @model_validator(mode="after")
    def _check(self) -> "Electrostatics":
        errors = []
        salt = self.salt_concentration is not None or self.temperature is not None
        if self.debye_length is not None and salt:
            loc = "salt_concentration" if self.salt_concentration is not None else "temperature"
            errors.append(_err((loc,), "unsupported", "give debye_length or "
                               "salt_concentration with temperature, not both",
                               getattr(self, loc)))
        elif self.debye_length is None and not salt:
            errors.append(_err(("debye_length",), "missing", "give debye_length, or "
                               "salt_concentration and temperature", None))
        elif self.debye_length is None:
            for name in ("salt_concentration", "temperature"):
                if getattr(self, name) is None:
                    errors.append(_err((name,), "missing", "the Debye length from the salt "
                                       "needs both salt_concentration and temperature", None))
        _raise("Electrostatics", errors)
        return self

    def screening_length(self) -> float:
        """λ (m): ``debye_length``, or that of the salt at the temperature
        (:func:`solver.electrostatics.debye_length`)."""
        if self.debye_length is not None:
            return float(self.debye_length)
        from .electrostatics import debye_length

        return debye_length(self.salt_concentration, self.temperature,
                            self.relative_permittivity)


class Thermal(BaseModel):
    """Thermal fluctuations: Langevin forces and moments at ``temperature`` whose
    covariance matches the viscous drag (fluctuation–dissipation; :mod:`solver.thermal`,
    docs/thermal.md). Omit for none. Needs ``fluid.viscosity`` and
    ``numerics.formulation: centreline`` (checked by :class:`Case`).
    """

    model_config = _MODEL_CONFIG

    temperature: Finite = Field(
        ..., gt=0, description="Temperature T, K; > 0 (kT = 1.380649e-23 J/K x T; 298.15 K: "
        "4.116e-21 J).")
    seed: Integer = Field(
        ..., ge=0, description="Seed of the random forces (numpy PCG64), an integer >= 0: the same "
        "seed gives the same run, bit for bit.")


#: the most points a bathymetry grid may hold (a case stays a case)
MAX_BATHYMETRY_POINTS = 1_000_000
#: how far (a share of the largest diameter) the cable's surface may start below the bottom
START_PENETRATION_TOL = 0.05


class Bathymetry(BaseModel):
    """A sea floor on a regular grid: ``z[i][j]`` (m, global z of the bottom) at
    ``x[i]``, ``y[j]`` (m), both axes strictly increasing; bilinear between the grid
    points with its gradient, held constant outside the grid (docs/seabed.md). At most
    MAX_BATHYMETRY_POINTS points. Errors: ``not_increasing``, ``wrong_shape``,
    ``too_many_points``."""

    model_config = _MODEL_CONFIG

    x: list[Finite] = Field(..., min_length=2, description="Grid x coordinates, m, global; strictly increasing.")
    y: list[Finite] = Field(..., min_length=2, description="Grid y coordinates, m, global; strictly increasing.")
    z: list[list[Finite]] = Field(..., description="Bottom elevation z[i][j] at (x[i], y[j]), m, global.")

    @model_validator(mode="after")
    def _check(self) -> "Bathymetry":
        nx, ny = len(self.x), len(self.y)
        if nx * ny > MAX_BATHYMETRY_POINTS:
            _raise("Bathymetry", [_err(("z",), "too_many_points",
                                       f"{nx} x {ny} = {nx * ny} grid points: more than "
                                       f"{MAX_BATHYMETRY_POINTS:.0e}", None)])
        errors = (_check_increasing(self.x, "x", "bathymetry x")
                  + _check_increasing(self.y, "y", "bathymetry y"))
        if len(self.z) != nx:
            errors.append(_err(("z",), "wrong_shape", f"must have len(x) = {nx} rows "
                               f"(z[i][j] at x[i], y[j]), got {len(self.z)}", None))
        for i, row in enumerate(self.z):
            if len(row) != ny:
                errors.append(_err(("z", i), "wrong_shape", f"must have len(y) = {ny} values, "
                                   f"got {len(row)}", None))
                break
        _raise("Bathymetry", errors)
        return self


class Friction(BaseModel):
    """Coulomb friction of the sea floor, axial and lateral separately, regularised below
    ``slip_velocity`` (docs/seabed.md gives the law)."""

    model_config = _MODEL_CONFIG

    axial: Finite = Field(..., ge=0, description="Kinetic friction coefficient along the cable (dimensionless); >= 0.")
    lateral: Finite = Field(..., ge=0, description="Kinetic friction coefficient across the cable (dimensionless); >= 0.")
    static_to_kinetic: Finite = Field(
        1.0, ge=1, description="Static over kinetic coefficient (dimensionless); >= 1; the static "
        "coefficient applies below slip_velocity.")
    slip_velocity: Finite = Field(
        0.01, gt=0, description="Sliding speed of the contact point below which friction is "
        "regularised (linear in the speed), m/s; > 0.")


class Seabed(BaseModel):
    """A sea floor the rod rests on: a flat bottom at ``elevation`` (m, global z; normal
    +z) or a ``bathymetry`` grid; a linear spring-damper on the penetration of the
    cable's surface (MoorDyn v2's kBot, cBot) and optional Coulomb ``friction``.
    Omit for none (docs/seabed.md)."""

    model_config = _MODEL_CONFIG

    elevation: Optional[Finite] = Field(None, description="Global z of a flat bottom, m (normal +z); or give bathymetry.")
    bathymetry: Optional[Bathymetry] = Field(None, description="Bottom elevation on a regular grid; or give elevation.")
    normal_stiffness: Finite = Field(
        3e6, ge=0, description="Normal stiffness, Pa (N/m per m of cable per m of penetration; MoorDyn's kBot times the diameter); >= 0.")
    normal_damping: Finite = Field(
        3e5, ge=0, description="Normal damping, Pa s (N/m per m of cable per m/s; MoorDyn's cBot times the diameter); >= 0.")
    friction: Optional[Friction] = Field(None, description="Coulomb friction; null: frictionless.")

    @model_validator(mode="after")
    def _one_bottom(self) -> "Seabed":
        if (self.elevation is None) == (self.bathymetry is None):
            raise PydanticCustomError("one_bottom", "give exactly one of elevation (a flat bottom) "
                                      "or bathymetry (a grid)")
        return self

    @model_serializer(mode="wrap")
    def _drop_unused(self, handler: Any):  # no return type: keeps the JSON schema
        out = handler(self)
        for name in ("elevation", "bathymetry", "friction"):
            if out.get(name) is None:
                out.pop(name, None)
        return out

    def bottom(self, x, y):
        """The bottom's elevation (m) at global (x, y) (arrays, m): the flat elevation or
        the grid's bilinear interpolation, held constant outside the grid."""
        x, y = np.asarray(x, float), np.asarray(y, float)
        if self.bathymetry is None:
            return np.full(np.broadcast(x, y).shape, float(self.elevation))
        from scipy.interpolate import RegularGridInterpolator

        b = self.bathymetry
        gx, gy = np.asarray(b.x, float), np.asarray(b.y, float)
        f = RegularGridInterpolator((gx, gy), np.asarray(b.z, float))
        pts = np.stack(np.broadcast_arrays(np.clip(x, gx[0], gx[-1]), np.clip(y, gy[0], gy[-1])),
                       axis=-1)
        return f(pts)


class Newton(BaseModel):
    """Newton iteration controls for each implicit time step."""

    model_config = _MODEL_CONFIG

    tolerance: Finite = Field(
        1e-9, gt=0, description="Convergence tolerance on the scaled residual norm (dimensionless); > 0. Steps where "
        "strands may meet also stop once their positions are converged to 1e-2 of contact.position_tolerance with the "
        "scaled residual below √10 times its square root (docs/contact.md § 2).")
    max_iterations: Integer = Field(25, ge=1, description="Iterations before a step counts as not converged; >= 1.")


class Tolerance(BaseModel):
    """Local error tolerances of the error-controlled time stepping (docs/numerics.md § 7).

    A step is accepted when, for each of the fields v, ω, κ, its local error estimate is
    at most ``absolute`` × the field's characteristic size + ``relative`` × the field's
    largest value on the rod (at the old or new level).
    """

    model_config = _MODEL_CONFIG

    relative: Finite = Field(1e-3, gt=0, lt=1, description="Relative tolerance on the local error (dimensionless); in (0, 1).")
    absolute: Finite = Field(
        1e-6, gt=0, description="Absolute tolerance, in units of each field's characteristic size (dimensionless); > 0."
    )


class Numerics(BaseModel):
    """Discretisation, time integration and step control.

    Give ``ds`` or ``n_segments`` (or both, agreeing). :class:`Case` checks them against
    the rod length and fills in both (``ds = length / n_segments`` exactly), so after a
    case validates ``ds`` and ``n_segments`` are never None.
    """

    model_config = _MODEL_CONFIG

    ds: Optional[Finite] = Field(None, gt=0, description="Segment length, m; > 0; must divide rod.length (1e-9 relative).")
    n_segments: Optional[Integer] = Field(
        None, ge=1, le=MAX_SEGMENTS, description="Number of segments (grid points - 1); 1 to 1e6."
    )
    dt: Finite = Field(..., gt=0, description="Time step, s; > 0 (with tolerance: the first step).")
    t_end: Finite = Field(..., gt=0, description="End time of the run, s; > 0.")
    rho_inf: Finite = Field(
        0.5, ge=0, le=1, description="Spectral radius at infinite frequency of the generalized-alpha scheme, in [0, 1]."
    )
    contact_rho_inf: Optional[Finite] = Field(
        None, ge=0, le=1,
        description="The scheme's rho_inf in steps where strands may meet (steps with self-contact "
        "candidates), in [0, 1]; null: rho_inf there too. Ignored without contact.",
    )
    backward_euler_retry: StrictBool = Field(
        True,
        description="Fixed steps: after a step refused by Newton or the energy check, take the cut retry by "
        "backward Euler, which does not read the generalized-alpha rates carried from the longer step "
        "(docs/contact.md section 3); false: generalized-alpha. With numerics.tolerance not applied (its "
        "error estimate is generalized-alpha's): true given with it is refused.",
    )
    newton: Newton = Field(default_factory=Newton, description="Newton iteration controls.")
    max_dt_cuts: Integer = Field(
        6, ge=0, le=50, description="Times a non-converging step may be retried with a smaller dt; 0 to 50."
    )
    dt_cut_factor: Finite = Field(
        4.0, gt=1, le=1000, description="Divisor applied to dt at each cut (dimensionless); > 1, <= 1000."
    )
    wall_clock_budget: Optional[Finite] = Field(
        None, gt=0, description="Wall-clock limit for the run, s; > 0; null: none."
    )
    tolerance: Optional[Tolerance] = Field(
        None,
        description="Error-controlled time stepping: the solver chooses each dt from a local error "
        "estimate (dt is the first step); null: fixed steps of dt.",
    )
    dt_max: Optional[Finite] = Field(None, gt=0, description="Largest step with tolerance, s; > 0; null: none.")
    growth_guard: Optional[Finite] = Field(
        1.0,
        gt=0,
        description="Largest sigma*dt allowed, sigma the fastest growth rate (1/s) of the linearised "
        "dynamics: a step that would exceed it is cut, so a large dt cannot suppress a buckling "
        "(dimensionless); > 0; null: no check.",
    )
    energy_tolerance: Optional[Finite] = Field(
        0.5,
        gt=0,
        description="Energy check of every step: a step whose rod energy grows by more than the work "
        "of its loads plus this share of the energy scale (the kinetic energy, floored at 1e-5 of "
        "the stored energy) is refused and dt cut (a large step of a nonlinear motion can inject "
        "energy); > 0; null: no check.",
    )

    formulation: Literal["goyal", "centreline"] = Field(
        "goyal",
        description="The dynamic scheme: goyal, the seed paper's body-frame unknowns (v, omega, f, "
        "kappa) with positions integrated; centreline, each node's position, frame, force and "
        "moment as unknowns, the statics' rows with inertia (experimental: fixed steps; "
        "docs/numerics.md).",
    )

    @model_validator(mode="after")
    def _one_of(self) -> "Numerics":
        if self.ds is None and self.n_segments is None:
            _raise("Numerics", [_err(("ds",), "missing", "give numerics.ds (m) or numerics.n_segments", None)])
        if self.tolerance is not None and self.backward_euler_retry:
            if "backward_euler_retry" in self.model_fields_set:
                _raise("Numerics", [_err(("backward_euler_retry",), "unsupported",
                                         "fixed steps only (the error estimate of numerics.tolerance "
                                         "is generalized-alpha's): leave out numerics.tolerance or "
                                         "set false", True)])
            # the default does not apply to error-controlled steps: the field says what runs
            self.backward_euler_retry = False
        return self

    @model_serializer(mode="wrap")
    def _drop_unused(self, handler: Any):  # no return type: keeps the JSON schema
        # added after schema 1's first release: written only when given, so that a case
        # without it keeps its canonical JSON and spec_hash
        out = handler(self)
        if self.contact_rho_inf is None:
            out.pop("contact_rho_inf", None)
        if self.formulation == "goyal":
            out.pop("formulation", None)
        if self.backward_euler_retry or self.tolerance is not None:
            # written only where it differs from the default for fixed steps (false): a
            # case without it keeps its spec_hash, which now means the backward-Euler retry
            out.pop("backward_euler_retry", None)
        return out


def _check_output_field(value: Any, handler: Any) -> str:
    if not isinstance(value, str) or value not in OUTPUT_FIELDS:
        raise PydanticCustomError(
            "unknown_output_field",
            "unknown output field {name}; allowed: {allowed}",
            {"name": repr(value), "allowed": ", ".join(OUTPUT_FIELDS)},
        )
    return value


OutputField = Annotated[
    Literal["v", "omega", "f", "kappa", "moment", "position", "orientation", "energies", "topology", "contact",
            "reactions", "bend_radius"],
    WrapValidator(_check_output_field),
]


class Output(BaseModel):
    """What the result dataset keeps.

    ``fields`` are unique names from :data:`OUTPUT_FIELDS`; they are stored in canonical
    order (so the same set gives the same spec hash). An unknown name is refused with the
    list of allowed ones; a repeated one with ``duplicate``.
    """

    model_config = _MODEL_CONFIG

    every: Integer = Field(1, ge=1, description="Keep every n-th accepted time step (the first and last are always kept); >= 1.")
    interval: Optional[Finite] = Field(
        None,
        gt=0,
        description="With numerics.tolerance: keep the state every interval s instead of every n-th "
        "step; > 0; null: use every.",
    )
    interpolate: bool = Field(
        True,
        description="With interval: the states between steps are the steps' dense output (cubic "
        "Hermite), so the outputs do not bound the steps; false: the steps land on the output times.",
    )
    fields: list[OutputField] = Field(
        default_factory=lambda: list(DEFAULT_OUTPUT_FIELDS),
        description="Variables to store: any of v, omega, f, kappa, moment, position, orientation, energies, topology, contact, "
        "reactions, bend_radius.",
    )

    @field_validator("fields", mode="after")
    @classmethod
    def _unique(cls, fields: list[str]) -> list[str]:
        seen: set[str] = set()
        errors = []
        for k, name in enumerate(fields):
            if name in seen:
                errors.append(_err((k,), "duplicate", f"output field {name!r} is listed twice", name))
            seen.add(name)
        _raise("Output", errors)
        return [name for name in OUTPUT_FIELDS if name in seen]


# --------------------------------------------------------------------------- parsing


_YAML_FLOAT = re.compile(
    r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
    |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
    |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
    |[-+]?\.(?:inf|Inf|INF)
    |\.(?:nan|NaN|NAN))$""",
    re.X,
)


class _YamlLoader(yaml.SafeLoader):
    """SafeLoader that reads ``1e-3`` as a float (YAML 1.2) and refuses duplicate keys."""

    def construct_mapping(self, node: Any, deep: bool = False) -> dict:
        if isinstance(node, yaml.MappingNode):
            self.flatten_mapping(node)
            seen = set()
            for key_node, _ in node.value:
                key = self.construct_object(key_node, deep=deep)
                try:
                    duplicate = key in seen
                    seen.add(key)
                except TypeError:
                    continue
                if duplicate:
                    raise yaml.constructor.ConstructorError(
                        "while constructing a mapping", node.start_mark, f"found duplicate key {key!r}", key_node.start_mark
                    )
        return super().construct_mapping(node, deep=deep)


_YamlLoader.yaml_implicit_resolvers = {
    first: [(tag, rx) for tag, rx in resolvers if tag != "tag:yaml.org,2002:float"]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_YamlLoader.add_implicit_resolver("tag:yaml.org,2002:float", _YAML_FLOAT, list("-+0123456789."))


def _json_object(pairs: list[tuple[str, Any]]) -> dict:
    out: dict = {}
    for key, value in pairs:
        if key in out:
            raise ValueError(f"duplicate key {key!r}")
        out[key] = value
    return out


def _yaml_where(exc: "yaml.YAMLError") -> str:
    """`` at line L, column C: <problem> (<context> at line L, column C)`` of a PyYAML
    error (1-based), or ``: <its text>`` where it has no marks."""
    mark = getattr(exc, "problem_mark", None)
    if mark is None:
        return f": {exc}"
    out = f" at line {mark.line + 1}, column {mark.column + 1}: {exc.problem}"
    context, cmark = getattr(exc, "context", None), getattr(exc, "context_mark", None)
    if context and cmark is not None:
        out += f" ({context} at line {cmark.line + 1}, column {cmark.column + 1})"
    return out


def parse_text(text: Union[str, bytes], fmt: str = "yaml", source: Optional[str] = None) -> Any:
    """Parse case-spec text (not yet validated) into Python objects.

    ``fmt`` is ``"yaml"``/``"yml"`` or ``"json"`` (a leading dot is ignored). YAML follows
    YAML 1.2 for numbers (``1e-3`` and ``1.25e7`` are floats, which PyYAML's default
    YAML 1.1 rules read as strings); duplicate keys are refused in both formats. Bytes
    must be UTF-8. Raises :class:`CaseError` (``yaml_syntax``, ``json_syntax``,
    ``too_deep``, ``encoding_error``, ``unknown_format``); ``source`` only labels the
    message.
    """
    fmt = fmt.lower().lstrip(".")
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise _doc_error(f"not UTF-8 text: {exc}", "encoding_error", source) from exc
    too_deep = ("the document nests lists or mappings too deeply to parse (a case spec "
                "nests at most a few levels)")
    if fmt in ("yaml", "yml"):
        try:
            return yaml.load(text, Loader=_YamlLoader)  # noqa: S506 - a SafeLoader subclass
        except yaml.YAMLError as exc:
            raise _doc_error(f"YAML syntax error{_yaml_where(exc)}", "yaml_syntax", source) from exc
        except RecursionError:
            raise _doc_error(too_deep, "too_deep", source) from None
    if fmt == "json":
        try:
            return json.loads(text, object_pairs_hook=_json_object)
        except ValueError as exc:
            raise _doc_error(f"JSON syntax error: {exc}", "json_syntax", source) from exc
        except RecursionError:
            raise _doc_error(too_deep, "too_deep", source) from None
    raise _doc_error(f"unknown format {fmt!r}; expected yaml, yml or json", "unknown_format", source)


# --------------------------------------------------------------------------- the case


class Case(BaseModel):
    """A complete, validated simulation case (schema_version 1).

    Construct with :meth:`from_file`, :meth:`from_text` (both raise :class:`CaseError`)
    or ``Case.model_validate(mapping)`` (raises ``pydantic.ValidationError``; format it
    with :func:`format_validation_errors`). Beyond the per-model rules this checks that
    ``numerics.ds`` divides ``rod.length`` (1e-9 relative) or agrees with
    ``numerics.n_segments``, fills in both, and that every ``distributed_forces[i].s_range``
    lies within ``[0, rod.length]``. Every field, its unit and its rule: docs/case-spec.md.

    Identity: :meth:`canonical_json` (sorted keys, no whitespace, defaults filled) and
    :meth:`spec_hash` (its sha256); re-validating the canonical JSON gives an equal case
    with the same hash.
    """

    model_config = _MODEL_CONFIG

    schema_version: Literal[1] = Field(..., description="Case spec schema version; this module reads 1.")
    name: str = Field(
        ..., min_length=1, max_length=200,
        description="Free-text name of the case; 1 to 200 characters, no control characters.",
    )
    rod: Rod = Field(..., description="Rod length (m), material (Pa, kg/m^3) and diameter (m).")
    fluid: Optional[Fluid] = Field(None, description="Surrounding fluid; null: vacuum, no fluid terms.")
    gravity: Optional[Vector3] = Field(None, description="Gravitational acceleration, m/s^2, global frame; null: none.")
    distributed_forces: list[DistributedForce] = Field(
        default_factory=list, description="Uniform forces per unit length, N/m, global frame, each on [start, end) s."
    )
    point_loads: list[PointLoad] = Field(
        default_factory=list, description="Concentrated forces, N, each at one arclength s (m) on [start, end) s; "
        "global frame (dead) or body frame (follower, body: true)."
    )
    initial: Initial = Field(default_factory=Initial, description="Initial configuration: straight "
                             "(global directions) or a given centreline, and a twist rate.")
    boundary: Boundary = Field(..., description="Boundary conditions at s = 0 and s = L, body-frame "
                               "components. Left out for a closed rod (rod.closed), which has no ends.")
    contact: Optional[Contact] = Field(None, description="Self-contact parameters; null: no self-contact search.")
    seabed: Optional[Seabed] = Field(None, description="Sea floor: flat or a bathymetry grid, normal "
                                     "stiffness and damping, friction; null: none (docs/seabed.md).")
    electrostatics: Optional[Electrostatics] = Field(
        None, description="Screened (Debye-Hueckel) repulsion between non-adjacent segments of a charged "
        "rod; null: none (docs/contact.md section 7). numerics.formulation centreline only.")
    thermal: Optional[Thermal] = Field(
        None, description="Thermal fluctuations (Langevin forces and moments matching the viscous "
        "drag) at a temperature, K, from a seed; null: none (docs/thermal.md). Needs "
        "fluid.viscosity; numerics.formulation centreline only.")
    numerics: Numerics = Field(..., description="Grid (m), time step (s) and solver controls.")
    output: Output = Field(default_factory=Output, description="Stored variables and output stride.")

    @field_validator("schema_version", mode="wrap")
    @classmethod
    def _version(cls, value: Any, handler: Any) -> int:
        if isinstance(value, bool) or value != SCHEMA_VERSION:
            raise PydanticCustomError(
                "unsupported_schema_version",
                "unsupported schema_version {v}; this hockle reads schema_version 1",
                {"v": repr(value)},
            )
        return SCHEMA_VERSION

    @field_validator("name", mode="after")
    @classmethod
    def _printable_name(cls, name: str) -> str:
        for k, ch in enumerate(name):
            if ord(ch) < 0x20 or ord(ch) == 0x7F:
                raise PydanticCustomError(
                    "control_character",
                    "must not contain control characters (U+{code:04X} at position {pos})",
                    {"code": ord(ch), "pos": k},
                )
        return name

    @model_validator(mode="wrap")
    @classmethod
    def _every_error(cls, data: Any, handler: Any) -> "Case":
        """Report the checks across sections even where some section has errors of its
        own: pydantic runs :meth:`_cross_checks` only on a case whose every field is valid,
        so an error inside ``initial`` hid, say, a point load off the rod. On a failed
        validation each section without errors is validated on its own, and every check
        across sections whose sections are all valid adds its errors to the raised
        ``ValidationError`` (those needing a broken section are left out)."""
        data = _closed_rod_ends(data)
        try:
            return handler(data)
        except ValidationError as exc:
            if not isinstance(data, dict):
                raise
            found = exc.errors()
            extra = cls._cross_errors_of_valid_sections(data, {e["loc"][0] for e in found
                                                                if e["loc"]})
            if not extra:
                raise
            lines = [{"type": PydanticCustomError(e["type"], e["msg"].replace("{", "(")
                                                  .replace("}", ")")),
                      "loc": e["loc"], "input": e.get("input")} for e in found]
            raise ValidationError.from_exception_data(exc.title, lines + extra) from None

    @classmethod
    def _cross_errors_of_valid_sections(cls, data: dict, bad: set) -> list[dict]:
        """The errors of :meth:`_cross_checks`' checks on the sections of ``data`` that
        validate on their own (``bad``: the top-level fields that did not); a check that
        needs a missing section is skipped."""
        from pydantic import TypeAdapter

        valid = {}
        for name, info in cls.model_fields.items():
            if name in bad:
                continue
            if name in data:
                try:
                    kind = (Annotated[(info.annotation, *info.metadata)] if info.metadata
                            else info.annotation)
                    valid[name] = TypeAdapter(kind).validate_python(data[name])
                except Exception:                     # noqa: BLE001 - reported by pydantic
                    continue
            elif not info.is_required():
                valid[name] = info.get_default(call_default_factory=True)
        partial = cls.model_construct(**valid)
        for name in bad:                              # not the default in its place
            partial.__dict__.pop(name, None)
        errors = []
        for check in (partial._check_initial, partial._check_loads_on_rod,
                      partial._check_contact, partial._check_ill_posed_ends,
                      partial._check_fluid, lambda: partial._check_numerics(errors)):
            try:
                got = check()
            except ValidationError as exc:            # _check_numerics' early raise
                got = [{"type": PydanticCustomError(e["type"], e["msg"].replace("{", "(")
                                                    .replace("}", ")")),
                        "loc": e["loc"], "input": e.get("input")} for e in exc.errors()]
            except (AttributeError, TypeError, KeyError, ValueError):
                continue                              # needs a section that is broken
            if isinstance(got, list) and got is not errors:
                errors.extend(got)
        unique = []
        for e in errors:
            if all(e["loc"] != u["loc"] for u in unique):
                unique.append(e)
        return unique

    @model_validator(mode="after")
    def _cross_checks(self) -> "Case":
        """Checks across sections (raising :class:`CaseError` with every error found);
        sets ``numerics.n_segments`` and ``numerics.ds`` from whichever was given."""
        errors = (self._check_initial() + self._check_loads_on_rod() + self._check_contact()
                  + self._check_ill_posed_ends() + self._check_seabed()
                  + self._check_formulation() + self._check_fluid() + self._check_closed())
        n_segments = self._check_numerics(errors)
        if n_segments:
            errors.extend(self._check_twist_resolved(n_segments))
        _raise("Case", errors)
        numerics, length = self.numerics, self.rod.length
        self.numerics = numerics.model_copy(update={"n_segments": n_segments, "ds": length / n_segments})
        return self

    def _check_formulation(self) -> list[dict]:
        """What the centreline scheme does not take, refused at the field (error-controlled
        steps with thermal fluctuations, at ``numerics.tolerance``; the end conditions the
        statics' end rows cannot say are refused when the run is built,
        :class:`solver.centreline.CentrelineError`); and what the seed scheme
        (goyal) does not take, refused at the field: ``fluid.viscosity``,
        ``rod.intrinsic_curvature``, ``electrostatics``, ``thermal``."""
        if self.numerics.formulation != "centreline":
            errors = []
            if self.rod.intrinsic_curvature is not None:
                errors.append(_err(("rod", "intrinsic_curvature"), "unsupported",
                                   "the goyal scheme (numerics.formulation's default) does not "
                                   "take an intrinsic curvature: set numerics.formulation: "
                                   "centreline (the statics and the centreline scheme take it)",
                                   self.rod.intrinsic_curvature))
            if self.fluid is not None and self.fluid.viscosity is not None:
                errors.append(_err(("fluid", "viscosity"), "unsupported",
                                   "the goyal scheme (numerics.formulation's default) does not "
                                   "take the viscous drag yet: set numerics.formulation: "
                                   "centreline", self.fluid.viscosity))
            if self.electrostatics is not None:
                errors.append(_err(("electrostatics",), "unsupported",
                                   "the goyal scheme (numerics.formulation's default) does not "
                                   "take screened electrostatics yet: set "
                                   "numerics.formulation: centreline", None))
            if self.thermal is not None:
                errors.append(_err(("thermal",), "unsupported",
                                   "the goyal scheme (numerics.formulation's default) does not "
                                   "take thermal fluctuations: set numerics.formulation: "
                                   "centreline", None))
            return errors
        if self.thermal is not None and self.numerics.tolerance is not None:
            return [_err(("numerics", "tolerance"), "unsupported",
                         "error-controlled steps do not take thermal fluctuations: the "
                         "local error estimate would follow the noise (each step's random "
                         "impulses are fresh); give a fixed numerics.dt", None)]
        return []

    def _check_closed(self) -> list[dict]:
        """A closed rod (``rod.closed``): the centreline scheme only (self-contact and
        electrostatics periodic: :func:`solver.statics._pair_models`), a circle for a start (no ``initial.centreline`` or ``twist_rate``; its twist is
        ``initial.linking_number``); ``linking_number`` only for a closed rod."""
        ini = self.initial
        if not self.rod.closed:
            if ini.linking_number is not None:
                return [_err(("initial", "linking_number"), "inconsistent",
                             "only a closed rod (rod.closed: true) starts from a linked "
                             "circle; an open rod's twist is initial.twist_rate",
                             ini.linking_number)]
            return []
        errors = []
        if self.numerics.formulation != "centreline":
            errors.append(_err(("rod", "closed"), "unsupported",
                               "a closed rod runs on numerics.formulation: centreline only", True))
        for name in ("centreline", "twist_rate"):
            if getattr(ini, name) not in (None, 0.0):
                errors.append(_err(("initial", name), "inconsistent",
                                   "a closed rod starts from a circle: leave out "
                                   f"initial.{name} (the circle's twist is "
                                   "initial.linking_number)", None))
        return errors

    def _check_fluid(self) -> list[dict]:
        """The viscous drag's slenderness factor ln(ℓ/d): ℓ/d at least
        :data:`solver.resistive_force.SMALLEST_SLENDERNESS` at the largest diameter (ℓ:
        ``fluid.slenderness_length`` or ``rod.length``), refused at the field that sets ℓ;
        ``thermal`` needs ``fluid.viscosity`` (the drag its forces balance), refused at
        ``thermal``."""
        fluid = self.fluid
        if fluid is None or fluid.viscosity is None:
            if getattr(self, "thermal", None) is not None:
                return [_err(("thermal",), "missing_viscosity",
                             "thermal fluctuations need fluid.viscosity: the random forces' "
                             "covariance is that of the viscous drag (fluctuation-"
                             "dissipation); give fluid.viscosity or leave thermal out", None)]
            return []
        from .resistive_force import SMALLEST_SLENDERNESS

        rod = self.rod
        diameter = rod.diameter
        d = float(max(diameter.value) if isinstance(diameter, Profile) else diameter)
        given = fluid.slenderness_length is not None
        ell = float(fluid.slenderness_length if given else rod.length)
        if ell >= SMALLEST_SLENDERNESS * d:
            return []
        loc = ("fluid", "slenderness_length") if given else ("fluid", "viscosity")
        what = "fluid.slenderness_length" if given else "rod.length"
        return [_err(loc, "not_slender",
                     f"the viscous drag (resistive-force theory) needs a slender rod: "
                     f"ℓ/d = {ell / d:.3g} with ℓ = {what} = {ell!r} m and the largest "
                     f"rod.diameter {d!r} m, below {SMALLEST_SLENDERNESS:g}",
                     fluid.slenderness_length if given else fluid.viscosity)]

    def _check_initial(self) -> list[dict]:
        """The initial state: a centreline as long as the rod, positions where the ends
        are, a start from a result at an output time of fixed steps."""
        errors = []
        length = self.rod.length
        if self.initial.centreline is not None:
            from .initial import LENGTH_RTOL, Curve

            got = Curve(self.initial.centreline.points).length
            if abs(got - length) > LENGTH_RTOL * length:
                errors.append(_err(("initial", "centreline", "points"), "length_mismatch",
                                   f"the centreline is {got:.6g} m long but rod.length is "
                                   f"{length!r} m (they must agree within "
                                   f"{LENGTH_RTOL:g} relative)", None))
        errors.extend(self._check_positions())
        start = self.initial.from_result
        if start is not None:
            num = self.numerics
            k = start.time / num.dt
            if num.tolerance is not None:
                errors.append(_err(("initial", "from_result"), "unsupported",
                                   "a start from an earlier result runs fixed steps only: "
                                   "leave out numerics.tolerance", None))
            # t_end first: a time of 1e308 made k infinite and round(k) an OverflowError
            elif not start.time < num.t_end or abs(k - round(k)) > 1e-9 * max(1.0, k):
                errors.append(_err(("initial", "from_result", "time"), "out_of_range",
                                   f"must be a multiple of numerics.dt = {num.dt!r} s before "
                                   f"numerics.t_end = {num.t_end!r} s", start.time))
        return errors

    def _check_twist_resolved(self, n_segments: int) -> list[dict]:
        """The initial twist rate against the grid: the solver represents the rotation of
        the section from one node to the next as a rotation of at most π (half a turn;
        :func:`solver.kinematics.relative_rotation` takes it the short way), so
        |twist_rate|·Δs must not exceed π, or the twist aliases to another one (1e308 rad/m
        gave non-finite quaternions and an internal_error at run time)."""
        ds = self.rod.length / n_segments
        rate = abs(float(self.initial.twist_rate))
        link = self.initial.linking_number
        if self.rod.closed and link is not None and abs(link) * 2 > n_segments:
            return [_err(("initial", "linking_number"), "not_resolved",
                         f"{link} turns over {n_segments} cells turn the section by more "
                         "than π rad (half a turn) per cell, more than the grid holds: "
                         f"raise numerics.n_segments to at least {2 * abs(link)}", link)]
        if not rate * ds > math.pi:
            return []
        return [_err(("initial", "twist_rate"), "not_resolved",
                     f"a twist rate of {self.initial.twist_rate!r} rad/m turns the section by "
                     f"{rate * ds:.3g} rad over one grid cell (Δs = {ds:.6g} m); the grid holds "
                     f"at most π rad (half a turn) per cell, {math.pi / ds:.6g} rad/m on this "
                     "grid: raise numerics.n_segments or lower the twist rate (rad/m, SI)",
                     self.initial.twist_rate)]

    def _check_loads_on_rod(self) -> list[dict]:
        """Point loads and distributed forces placed within [0, rod.length]."""
        errors = []
        length = self.rod.length
        for k, load in enumerate(self.point_loads):
            if not 0.0 <= load.s <= length:
                errors.append(_err(("point_loads", k, "s"), "out_of_range",
                                   f"must be within [0, rod.length] = [0, {length!r}] m", load.s))
        for k, force in enumerate(self.distributed_forces):
            if force.s_range is not None:
                for j, s in enumerate(force.s_range):
                    if not 0.0 <= s <= length:
                        errors.append(
                            _err(("distributed_forces", k, "s_range", j), "out_of_range",
                                 f"must be within [0, rod.length] = [0, {length!r}] m", s)
                        )
        return errors

    def _check_contact(self) -> list[dict]:
        """The contact search's tolerance against the largest diameter (and the barrier's gap)."""
        errors = []
        if self.contact is not None:
            d = self.rod.diameter
            d_max = max(d.value) if isinstance(d, Profile) else float(d)
            if self.contact.tolerance <= d_max:
                errors.append(
                    _err(("contact", "tolerance"), "out_of_range",
                         f"must exceed the largest rod diameter ({d_max!r} m): pairs are "
                         "tested only below this centreline distance, so touching pairs "
                         "(distance = diameter) would be missed", self.contact.tolerance)
                )
            elif (self.contact.law == "barrier"
                  and d_max + self.contact.barrier_gap > self.contact.tolerance):
                errors.append(
                    _err(("contact", "barrier_gap"), "out_of_range",
                         f"the largest diameter ({d_max!r} m) plus barrier_gap must not exceed "
                         f"the tolerance ({self.contact.tolerance!r} m): the search would miss "
                         "pairs the barrier acts on", self.contact.barrier_gap)
                )
        return errors

    def _check_seabed(self) -> list[dict]:
        """Gravity into the bottom (its normal is +z: g_z < 0 where gravity is given) and
        a cable that starts above it: its surface below the bottom by at most
        START_PENETRATION_TOL of the largest diameter (the initial centreline's points, or
        200 points of the straight start)."""
        sb = self.seabed
        if sb is None:
            return []
        errors = []
        g = self.gravity
        if g is not None and any(c != 0.0 for c in g) and not g[2] < 0.0:
            errors.append(_err(("gravity",), "away_from_seabed",
                               "with a seabed (normal +z) gravity must point into it "
                               f"(gravity[2] < 0), got {g!r}", g))
        ini = self.initial
        if ini.from_result is not None:
            return errors
        d = self.rod.diameter
        d_max = max(d.value) if isinstance(d, Profile) else float(d)
        if ini.centreline is not None:
            pts = np.asarray(ini.centreline.points, float)
        else:
            pts = np.linspace(0.0, self.rod.length, 200)[:, None] * np.asarray(ini.tangent)[None, :]
        gap = pts[:, 2] - sb.bottom(pts[:, 0], pts[:, 1]) - 0.5 * d_max
        k = int(np.argmin(gap))
        if gap[k] < -START_PENETRATION_TOL * d_max:
            where = "elevation" if sb.bathymetry is None else "bathymetry"
            errors.append(_err(("seabed", where), "starts_below_seabed",
                               f"the cable starts {-gap[k]:.6g} m into the bottom at "
                               f"({', '.join(f'{c:.6g}' for c in pts[k])}) m (its surface may be at "
                               f"most {START_PENETRATION_TOL:g} x its diameter below it)", None))
        return errors

    def _check_ill_posed_ends(self) -> list[dict]:
        """End conditions that leave the straight inextensible rod's tension undetermined."""
        errors = []
        # a straight inextensible rod whose two ends both prescribe the axial velocity has
        # an undetermined tension (the step's Jacobian is exactly singular); the rod is
        # straight at t = 0 unless a curved initial.centreline is given, so the
        # conditions in force then decide (issue 11, item 5)
        if (self.boundary.start.active("translation", 2, 0.0).kinematic
                and self.boundary.end.active("translation", 2, 0.0).kinematic
                and _straight(self.initial.centreline)):
            errors.append(_err(
                ("boundary", "end", "translation", 2), "ill_posed",
                "both ends prescribe the axial velocity (translation[2]) of the straight "
                "inextensible rod at t = 0, which leaves its tension undetermined; give one "
                "end an axial force instead (force: 0 lets it slide freely)", None))
        return errors

    def _check_numerics(self, errors: list[dict]) -> int | None:
        """Step and grid sizes against the run and the rod, appending to ``errors``;
        returns the number of segments (raises at once, with ``errors``, where the grid
        would be too large to check further)."""
        length = self.rod.length
        numerics = self.numerics
        # fixed steps only: with numerics.tolerance, dt is the first trial step, which the
        # step control cuts to land on t_end
        if numerics.tolerance is None and numerics.dt > numerics.t_end:
            errors.append(_err(("numerics", "dt"), "out_of_range",
                               f"the time step must not exceed the run, t_end = {numerics.t_end!r} s",
                               numerics.dt))
        d = self.rod.diameter
        d_max = max(d.value) if isinstance(d, Profile) else float(d)
        if d_max > length:
            errors.append(_err(("rod", "diameter"), "out_of_range",
                               f"a diameter of {d_max!r} m exceeds the rod's length ({length!r} m): "
                               "not a slender rod", d_max))
        steps = numerics.t_end / numerics.dt
        if numerics.tolerance is None and 1 <= steps <= MAX_STEPS and self.output.every > math.ceil(steps - 1e-9):
            errors.append(_err(("output", "every"), "out_of_range",
                               f"keeping every {self.output.every}-th step of a run of "
                               f"{math.ceil(steps - 1e-9)} steps keeps only the first and last "
                               "states; at most the number of steps", self.output.every))
        if not steps <= MAX_STEPS:
            errors.append(_err(("numerics", "dt"), "too_many_steps",
                               f"t_end / dt = {steps:.3g} steps (t_end = {numerics.t_end!r} s): "
                               f"more than {MAX_STEPS:.0e}; raise dt or lower t_end", numerics.dt))
        if numerics.ds is not None and not length / numerics.ds <= MAX_SEGMENTS * (1 + DS_RTOL):
            errors.append(_err(("numerics", "ds"), "too_many_segments",
                               f"rod.length / ds = {length / numerics.ds:.3g} segments: more than "
                               f"{MAX_SEGMENTS:.0e}", numerics.ds))
            _raise("Case", errors)
        if numerics.tolerance is None:
            if numerics.dt_max is not None:
                errors.append(_err(("numerics", "dt_max"), "needs_tolerance",
                                   "dt_max applies only to error-controlled steps: give "
                                   "numerics.tolerance, or remove dt_max", numerics.dt_max))
            if self.output.interval is not None:
                errors.append(_err(("output", "interval"), "needs_tolerance",
                                   "output.interval applies only to error-controlled steps "
                                   "(numerics.tolerance); with fixed steps use output.every",
                                   self.output.interval))
        elif numerics.dt_max is not None and numerics.dt > numerics.dt_max:
            errors.append(_err(("numerics", "dt"), "out_of_range",
                               f"the first step dt must not exceed dt_max = {numerics.dt_max!r} s",
                               numerics.dt))
        n_segments = numerics.n_segments
        if numerics.ds is not None:
            ratio = length / numerics.ds
            nearest = round(ratio)
            if n_segments is not None:
                if abs(ratio - n_segments) > DS_RTOL * n_segments:
                    errors.append(
                        _err(("numerics", "n_segments"), "inconsistent",
                             f"n_segments = {n_segments} disagrees with ds = {numerics.ds!r} m "
                             f"(rod.length / ds = {ratio:.10g}); give only one of them", n_segments)
                    )
            elif nearest < 1 or abs(ratio - nearest) > DS_RTOL * ratio:
                errors.append(
                    _err(("numerics", "ds"), "ds_not_dividing",
                         f"ds = {numerics.ds!r} m does not divide rod.length = {length!r} m "
                         f"(length / ds = {ratio:.10g}, not a whole number); give numerics.n_segments instead "
                         f"(e.g. n_segments: {max(nearest, 1)}) or a ds that divides the length", numerics.ds)
                )
            else:
                n_segments = nearest
        return n_segments

    def _check_positions(self) -> list[dict]:
        """Global ``position`` conditions: at t = 0 where the end starts (within
        POSITION_RTOL × rod.length), and with both ends' positions prescribed, never
        farther apart than the inextensible rod is long. Both tables are piecewise linear,
        so their difference is linear between the union of their knots and its length
        convex there: checking the knots suffices."""
        length = self.rod.length
        ini = self.initial
        if ini.centreline is not None:
            where = {"start": np.asarray(ini.centreline.points[0], float),
                     "end": np.asarray(ini.centreline.points[-1], float)}
        else:
            where = {"start": np.zeros(3), "end": length * np.asarray(ini.tangent, float)}
        errors = []
        tables = {}
        for name in ("start", "end"):
            ec = getattr(self.boundary, name)
            items = [c[0] for c in ec.translation]
            if ec.frame != "global" or any(c.kind != "position" for c in items):
                continue
            tables[name] = items
            p0 = np.array([c.value_at(0.0) for c in items])
            if np.linalg.norm(p0 - where[name]) > POSITION_RTOL * length:
                errors.append(_err(("boundary", name, "translation"), "inconsistent",
                                   f"the position at t = 0 ({', '.join(f'{x:.6g}' for x in p0)}) m "
                                   f"is not where the rod's {name} is "
                                   f"({', '.join(f'{x:.6g}' for x in where[name])}) m", None))
        if len(tables) == 2:
            times = sorted({0.0, *(t for items in tables.values() for c in items
                                   if isinstance(c.value, Table) for t in c.value.t)})
            for t in times:
                gap = np.linalg.norm([a.value_at(t) - b.value_at(t)
                                      for a, b in zip(tables["start"], tables["end"])])
                if gap > length * (1.0 + 1e-9):
                    errors.append(_err(("boundary", "end", "translation"), "stretches_rod",
                                       f"the prescribed positions put the ends {gap:.6g} m apart "
                                       f"at t = {t:.6g} s, farther than rod.length = {length!r} m: "
                                       "the rod is inextensible", None))
                    break
        return errors

    @model_serializer(mode="wrap")
    def _drop_empty(self, handler: Any):  # no return type: keeps the JSON schema
        # fields added after schema 1's first release are written only when used, so that
        # a case without them keeps its canonical JSON and spec_hash
        out = handler(self)
        if not self.point_loads:
            out.pop("point_loads", None)
        if self.seabed is None:
            out.pop("seabed", None)
        if self.electrostatics is None:
            out.pop("electrostatics", None)
        if self.thermal is None:
            out.pop("thermal", None)
        if self.rod.closed:
            # a closed rod has no ends: its boundary (both ends free, filled in by
            # _closed_rod_ends) is not written, so that the written case validates again
            out.pop("boundary", None)
        return out

    # ----------------------------------------------------------------- loading

    @classmethod
    def from_text(cls, text: Union[str, bytes], fmt: str = "yaml", source: Optional[str] = None) -> "Case":
        """Parse and validate a case spec given as text.

        ``fmt`` is ``"yaml"`` (or ``"yml"``) or ``"json"``; ``source`` only labels error
        messages. Raises :class:`CaseError` for a syntax error, a document that is not a
        mapping, an unknown format or any validation error (with field paths).
        """
        data = parse_text(text, fmt, source)
        if not isinstance(data, dict):
            raise _doc_error(f"a case spec must be a mapping of fields, got {type(data).__name__}", "dict_type", source)
        try:
            return cls.model_validate(data)
        except ValidationError as exc:
            raise CaseError.from_validation_error(exc, source) from None

    @classmethod
    def from_file(cls, path: Union[str, Path]) -> "Case":
        """Read and validate a case file; the format follows the suffix.

        ``.yaml``/``.yml`` are YAML, ``.json`` JSON. Raises :class:`CaseError` for an
        unknown suffix, a missing or unreadable file, a syntax error or any validation
        error (with field paths).
        """
        path = Path(path)
        suffix = path.suffix.lower()
        if suffix not in (".yaml", ".yml", ".json"):
            raise _doc_error(
                f"unknown case file suffix {path.suffix!r}; expected .yaml, .yml or .json", "unknown_format", str(path)
            )
        try:
            raw = path.read_bytes()
        except FileNotFoundError:
            raise _doc_error(f"no such file: {path}", "file_not_found", str(path)) from None
        except OSError as exc:
            raise _doc_error(f"cannot read {path}: {exc.strerror or exc}", "file_unreadable", str(path)) from None
        return cls.from_text(raw, suffix, source=str(path))

    # ----------------------------------------------------------------- identity and size

    def canonical_json(self) -> str:
        """The case as canonical JSON: defaults filled in, sorted keys, no whitespace.

        Boundary items are written as lists, output fields in canonical order, numerics
        with both ``ds`` and ``n_segments``; initial directions normalised.
        """
        return json.dumps(self.model_dump(mode="json"), sort_keys=True, separators=(",", ":"), allow_nan=False)

    def spec_hash(self) -> str:
        """sha256 hex digest of :meth:`canonical_json` (UTF-8): the case's identity."""
        return hashlib.sha256(self.canonical_json().encode("utf-8")).hexdigest()

    @property
    def grid_points(self) -> int:
        """Number of grid points along the rod, ``numerics.n_segments + 1``."""
        return int(self.numerics.n_segments) + 1

    @property
    def n_steps(self) -> int:
        """Number of time steps at the nominal dt, ``ceil(t_end / dt - 1e-9)`` (with
        ``numerics.tolerance``: the steps the run would take at its first step dt)."""
        return int(math.ceil(self.numerics.t_end / self.numerics.dt - 1e-9))
