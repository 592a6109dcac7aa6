"""What a continuation's branch shows (the branch dataset of
:func:`solver.continuation.branch_dataset`, written by ``hockle continue`` and by continuation
jobs): the parameter's unit, the measures a bifurcation diagram draws against the parameter
(round-off drawn as zero), the branch's events and its mode counts. ``hockle plot`` on a
branch file (hockle/branch_plots.py) and the dashboard's branch page
(``GET /v1/ui/jobs/{id}/branch``) both draw from here, so they agree.

Round-off: a quantity that is exactly zero in exact arithmetic (the end moment along the
axis of a planar elastica, its writhe) comes out of the solve as 1e-17 N m or 1e-12 turns;
drawn on an axis of its own it becomes a zig-zag. Every value whose size is below
:data:`ROUND_OFF` times the quantity's scale (the rod's length for lengths, the largest end
force for forces, ...) is set to zero here.
"""
from __future__ import annotations

import json
import math
import re
from typing import Any

import numpy as np

__all__ = ["ROUND_OFF", "parameter_unit", "parameter_label", "is_branch", "excursion",
           "measures", "overview", "MEASURES"]

#: values below this fraction of their quantity's scale are round-off, drawn as zero
ROUND_OFF = 1e-12

#: (name, label, units) of the measures a bifurcation diagram may draw, in the order
#: ``hockle plot`` picks its panels from
MEASURES = (
    ("excursion", "largest lateral excursion", "m"),
    ("end_to_end", "end-to-end distance", "m"),
    ("end_force_axial", "end force along the start tangent", "N"),
    ("end_moment_axial", "end moment along the start tangent", "N m"),
    ("writhe", "writhe Wr", "turns"),
    ("twist", "twist Tw", "turns"),
    ("total_energy", "total energy", "J"),
)

# the unit of a condition's value, by its key (boundary items, distributed loads' factors)
_KEY_UNITS = {"force": "N", "velocity": "m/s", "position": "m", "moment": "N m",
              "angular_velocity": "rad/s"}
_UNIT_SHAPE = re.compile(r"^(1/)?[A-Za-z]{1,3}(\^[-0-9()+a-z]+)?([ /*][A-Za-z]{1,3}(\^[-0-9()+a-z]+)?)*$")


def is_branch(ds) -> bool:
    """Whether ``ds`` is a branch dataset (``hockle_kind = "branch"``, dimension ``point``)."""
    return str(ds.attrs.get("hockle_kind", "")) == "branch" or (
        "point" in ds.dims and "time" not in ds.dims)


def parameter_unit(path: str) -> str:
    """The SI unit of the case scalar at the dotted ``path``
    (``boundary.end.translation.2.force`` -> ``"N"``), from the key of a boundary condition
    or the case spec's own field description (``rod.youngs_modulus`` -> ``"Pa"``); ``"1"``
    for a dimensionless field, ``""`` when the path does not name a field of the case."""
    from solver.case import Case

    parts = [p for p in re.split(r"[.\[\]]", str(path)) if p]
    names = [p for p in parts if not p.isdigit()]
    if not names:
        return ""
    if names[-1] in _KEY_UNITS and len(names) >= 2 and names[-2] in ("translation", "rotation"):
        return _KEY_UNITS[names[-1]]
    model: Any = Case
    field = None
    for name in names:
        fields = getattr(model, "model_fields", None)
        if not fields or name not in fields:
            field = None
            break
        field = fields[name]
        model = _model_of(field.annotation)
    if field is None:
        return _KEY_UNITS.get(names[-1], "")
    text = field.description or ""
    if "dimensionless" in text:
        return "1"
    first = re.match(r"^[^,]*,\s*([^;,:]+)", text)
    candidates = [first.group(1).split(" (")[0].strip()] if first else []
    candidates += [m.strip() for m in re.findall(r",\s*([^;,:]+?)\s*;", text)]
    for unit in candidates:
        if unit == "degrees":
            return "°"
        if _UNIT_SHAPE.match(unit):
            return unit
    return ""


def _model_of(annotation: Any) -> Any:
    """The pydantic model inside an annotation (``Optional[Rod]``, ``list[Item]``), if any."""
    import typing

    stack = [annotation]
    while stack:
        a = stack.pop()
        if hasattr(a, "model_fields"):
            return a
        stack.extend(typing.get_args(a))
    return None


def parameter_label(ds) -> str:
    """The parameter's axis label: its path and unit (``"boundary.end.translation.2.force
    (N)"``)."""
    path = str(ds.attrs.get("parameter_path") or ds["parameter"].attrs.get("path") or "")
    if re.search(r"\(.+\)$", path):          # a name that carries its unit: "P (N)"
        return path
    unit = parameter_unit(path) if path else ""
    return f"{path or 'parameter'} ({unit or 'unit of the case field'})"


def excursion(ds) -> np.ndarray:
    """(point,) the largest distance (m) of a node from the straight line through the rod's
    ends (NaN where the shape is not stored)."""
    r = np.asarray(ds["position"].values, float)
    a, b = r[:, :1, :], r[:, -1:, :]
    axis = b - a
    norm = np.linalg.norm(axis, axis=-1, keepdims=True)
    u = np.where(norm > 0, axis / np.where(norm > 0, norm, 1.0), 0.0)
    d = r - a
    perp = d - np.sum(d * u, axis=-1, keepdims=True) * u
    return np.max(np.linalg.norm(perp, axis=-1), axis=-1)


def _case(ds) -> dict:
    try:
        return json.loads(str(ds.attrs.get("case") or "{}"))
    except ValueError:
        return {}


def _length(ds) -> float:
    rod = _case(ds).get("rod") or {}
    try:
        return float(rod["length"])
    except (KeyError, TypeError, ValueError):
        r = np.asarray(ds["position"].values, float)
        seg = np.linalg.norm(np.diff(r, axis=1), axis=-1)
        total = np.nansum(seg, axis=1)
        return float(np.nanmax(total)) if np.isfinite(total).any() else 1.0


def _start_tangent(ds) -> np.ndarray:
    """(point, 3) the unit tangent at s = 0, from the stored shapes (the last stored one
    before a point without a shape; the case's initial tangent before the first)."""
    r = np.asarray(ds["position"].values, float)
    t = r[:, 1, :] - r[:, 0, :]
    norm = np.linalg.norm(t, axis=-1, keepdims=True)
    t = np.where(norm > 0, t / np.where(norm > 0, norm, 1.0), np.nan)
    fallback = np.asarray((_case(ds).get("initial") or {}).get("tangent") or [0, 0, 1], float)
    fallback = fallback / max(float(np.linalg.norm(fallback)), 1e-300)
    last = fallback
    for i in range(t.shape[0]):
        if np.all(np.isfinite(t[i])):
            last = t[i]
        else:
            t[i] = last
    return t


def _clean(values: np.ndarray, scale: float) -> np.ndarray:
    """``values`` with every entry below ROUND_OFF x ``scale`` in size set to zero."""
    v = np.asarray(values, float).copy()
    if math.isfinite(scale) and scale > 0:
        v[np.abs(v) < ROUND_OFF * scale] = 0.0
    return v


def measures(ds) -> dict[str, dict[str, Any]]:
    """The measures of :data:`MEASURES` per point, round-off set to zero: ``{name: {"label",
    "units", "values" (point,) float array (NaN where it needs a shape that is not stored),
    "constant" (the same value at every point where it is defined, to round-off)}}``.

    Scales of the round-off (:data:`ROUND_OFF` times): lengths, the rod's length; forces, the
    largest end force; moments, the largest end moment or end force times the length;
    energies, the largest elastic energy or load potential; turns, 1e6 turns (Wr closes the
    open rod by extensions 1e6 times its length, :data:`solver.topology.DEFAULT_EXTENSION_FACTOR`,
    and rounds as they do: 1e-11 turns on a planar elastica, exactly zero in exact arithmetic)."""
    length = _length(ds)
    t0 = _start_tangent(ds)
    fe = np.asarray(ds["end_force"].values, float)
    me = np.asarray(ds["end_moment"].values, float)
    force_scale = float(np.nanmax(np.linalg.norm(fe, axis=-1), initial=0.0))
    moment_scale = max(float(np.nanmax(np.linalg.norm(me, axis=-1), initial=0.0)),
                       force_scale * length)
    energy_scale = max(float(np.nanmax(np.abs(ds[k].values), initial=0.0))
                       for k in ("elastic_energy", "load_potential"))
    from solver.topology import DEFAULT_EXTENSION_FACTOR

    # Wr closes the open rod with straight extensions DEFAULT_EXTENSION_FACTOR (1e6) times
    # its length: its terms, and their rounding, are that much larger than the rod's own
    turn_scale = float(DEFAULT_EXTENSION_FACTOR)
    raw = {
        "excursion": (excursion(ds), length),
        "end_to_end": (ds["end_to_end"].values, length),
        "end_force_axial": (np.sum(fe * t0, axis=-1), force_scale),
        "end_moment_axial": (np.sum(me * t0, axis=-1), moment_scale),
        "writhe": (ds["writhe"].values, turn_scale),
        "twist": (ds["twist"].values, turn_scale),
        "total_energy": (ds["total_energy"].values, energy_scale),
    }
    out = {}
    for name, label, units in MEASURES:
        values, scale = raw[name]
        v = _clean(values, scale)
        ok = v[np.isfinite(v)]
        constant = bool(ok.size == 0 or np.ptp(ok) <= ROUND_OFF * max(scale, 1e-300))
        out[name] = {"label": label, "units": units, "values": v, "constant": constant}
    return out


def _num(value) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


def overview(ds) -> dict[str, Any]:
    """The branch as the dashboard draws it (JSON-able): the parameter (path, unit, values,
    its start and target), per point its unstable-mode count, part of the branch (0; 1 after
    a switch) and whether its shape is stored, the measures (:func:`measures`), and the
    events: each located fold and branch point with the mode counts on either side."""
    lam = np.asarray(ds["parameter"].values, float)
    path = str(ds.attrs.get("parameter_path") or ds["parameter"].attrs.get("path") or "")
    modes = np.asarray(ds["unstable_modes"].values, int)
    part = np.asarray(ds["branch"].values, int) if "branch" in ds else np.zeros(lam.size, int)
    r = np.asarray(ds["position"].values, float) if "position" in ds else None
    stored = ([] if r is None else
              np.flatnonzero(np.all(np.isfinite(r.reshape(r.shape[0], -1)), axis=1)).tolist())
    switched = int(ds.attrs.get("switched_at", -1))
    events = []
    kinds = [str(k) for k in ds["bifurcation_kind"].values] if "bifurcation_kind" in ds else []
    for i, kind in enumerate(kinds):
        after = int(ds["bifurcation_after"].values[i])
        simple = bool(int(ds["bifurcation_simple"].values[i]))
        before_n = int(modes[after]) if 0 <= after < modes.size else None
        after_n = int(modes[after + 1]) if 0 <= after + 1 < modes.size else None
        events.append({
            "kind": kind, "parameter": _num(ds["bifurcation_parameter"].values[i]),
            "after": after, "simple": simple,
            "label": ("fold" if kind == "fold" else
                      "branch point" if simple else "branch point (a pair of modes)"),
            "modes_before": before_n, "modes_after": after_n,
            "switched_here": switched >= 0 and after < switched and not any(
                int(ds["bifurcation_after"].values[j]) < switched
                for j in range(i + 1, len(kinds))),
        })
    ms = measures(ds)
    return {
        "parameter": {"path": path, "unit": parameter_unit(path) if path else "",
                      "label": parameter_label(ds), "values": [_num(v) for v in lam],
                      "start": _num(lam[0]) if lam.size else None,
                      "target": _num(ds.attrs["target"]) if "target" in ds.attrs else None},
        "n_points": int(lam.size),
        "n_segments": int(ds.attrs.get("n_segments", max(int(ds.sizes.get("node", 1)) - 1, 0))),
        "stopped": str(ds.attrs.get("stopped", "")),
        "switched_at": switched if switched >= 0 else None,
        "unstable_modes": modes.tolist(),
        "branch": part.tolist(),
        "stored": stored,
        "measures": [{"name": name, "label": m["label"], "units": m["units"],
                      "constant": m["constant"], "values": [_num(v) for v in m["values"]]}
                     for name, m in ms.items()],
        "events": events,
    }
