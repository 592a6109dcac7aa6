"""The result dataset: solver arrays -> a self-describing :class:`xarray.Dataset`.

Pure: builds the dataset in memory and does no file I/O (writing is
:func:`hockle.io.write_netcdf`). The layout is the outside contract documented in
docs/interfaces.md ("The result dataset"); the same page fixes the seam
``solver.results``.

Dimensions (each present only when a variable uses it)
------------------------------------------------------
``time``        output instants, s (every ``case.output.every``-th accepted step, and t0);
                CF ``standard_name = "time"``, ``axis = "T"``, elapsed simulation time
``s``           arclength of the grid points along the centreline, m
``component``   body-frame component 1, 2, 3 (directors a1, a2, a3; a3 the tangent)
``xyz``         global-frame axis index 1, 2, 3 = x, y, z (e1, e2, e3); ``flag_values`` /
                ``flag_meanings`` name them (CF-1.12 § 3.5), no string coordinate
``quaternion``  quaternion component index 0, 1, 2, 3 = w, x, y, z (scalar first)
``step``        every accepted solver step 1..K (diagnostics), with ``step_time``

Every variable carries ``units`` (UDUNITS-2 strings), ``long_name`` and ACDD-1.3's
``coverage_content_type``. Only ``time`` has a CF standard name: the CF table has none
for rod strain resultants, body-frame velocities, strain energies, twist or writhe, and
an invented one would be wrong. ``time`` keeps units of ``s`` (elapsed simulation time,
no calendar epoch), so that readers get plain seconds; CF § 4.4 asks a time coordinate
for a reference date, which a simulation does not have (docs/interfaces.md).

Global attributes follow CF-1.12 and ACDD-1.3 and hold the canonical case spec, so a
file alone reproduces its run. Who made the data and under which licence is not the
solver's to know: :func:`apply_metadata` sets the ACDD ``creator_*``, ``publisher_*``,
``institution``, ``license`` ... attributes from the operator's settings (the CLI and
the worker call it with the ``HOCKLE_*`` settings of :class:`service.settings.Settings`).
"""
from __future__ import annotations

import datetime as _dt
import json
import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import xarray as xr

__all__ = [
    "build_dataset",
    "start_state_from",
    "START_VARIABLES",
    "run_events",
    "shape_departure",
    "node_departure",
    "events_summary",
    "event_label",
    "EVENT_RULES",
    "bend_radius_series",
    "minimum_bend_radius_of",
    "on_bottom",
    "tweezers_protocol",
    "tweezers_series",
    "TWEEZERS_RULE",
    "plectoneme_two_phase",
    "ply_axis_distance",
    "apply_metadata",
    "FIELD_VARIABLES",
    "DIAGNOSTIC_VARIABLES",
    "COVERAGE_CONTENT_TYPES",
    "METADATA_ATTRIBUTES",
    "DEFAULT_METADATA",
    "INDEX_LABELS",
    "CONVENTIONS",
    "KEYWORDS",
    "STATUSES",
    "REFERENCES",
]

CONVENTIONS = "CF-1.12, ACDD-1.3"

STATUSES = ("completed", "stopped", "failed")

REFERENCES = 'S. Goyal, N.C. Perkins, C.L. Lee, "Writhing dynamics of cables with self-contact"'

_BODY = ("time", "s", "component")

# name -> (trailing dims after time, units, long_name, comment or None)
# Shapes: ("time",) is (T,); ("time", "s", X) is (T, N, len(X)).
FIELD_VARIABLES: dict[str, tuple[tuple[str, ...], str, str, str | None]] = {
    "v": (_BODY, "m s-1", "velocity of the centreline, body-frame components", None),
    "omega": (
        _BODY, "rad s-1", "angular velocity of the cross-section, body-frame components", None
    ),
    "f": (_BODY, "N", "internal force resultant, body-frame components", None),
    "kappa": (
        _BODY,
        "rad m-1",
        "curvature and twist vector (Darboux vector), body-frame components",
        "kappa_1, kappa_2 are the bending curvatures, kappa_3 the twist rate (seed eq. 1)",
    ),
    "moment": (
        _BODY,
        "N m",
        "internal moment resultant, body-frame components",
        "q = diag(E J1, E J2, G J3) kappa (seed eq. 1)",
    ),
    "position": (("time", "s", "xyz"), "m", "position of the centreline, global frame", None),
    "orientation": (
        ("time", "s", "quaternion"),
        "1",
        "orientation of the cross-section as a unit quaternion (scalar first)",
        "maps body-frame components to global ones: x_global = R(q) x_body; "
        "the columns of R(q) are the directors a1, a2, a3",
    ),
    "energy_bending": (("time",), "J", "bending strain energy of the rod", None),
    "energy_torsion": (("time",), "J", "torsional strain energy of the rod", None),
    "energy_kinetic": (
        ("time",),
        "J",
        "kinetic energy of the rod's own mass (translation and rotation)",
        "the entrained fluid's share is energy_kinetic_fluid, apart from this",
    ),
    "energy_kinetic_fluid": (
        ("time",),
        "J",
        "kinetic energy of the entrained (added) fluid mass",
        "not part of energy_kinetic; zero in vacuum",
    ),
    "energy_total": (
        ("time",),
        "J",
        "total mechanical energy of the rod (strain plus kinetic)",
        "energy_bending + energy_torsion + energy_kinetic + energy_kinetic_fluid",
    ),
    "work_in": (
        ("time",),
        "J",
        "cumulative work put in at the rod ends and by the loads",
        "time integral of power_in from the start of the run: the ends' loads and motions, "
        "distributed and point loads, gravity (not the seabed's reaction: seabed_work)",
    ),
    "power_in": (("time",), "W", "power put in at the rod ends", None),
    "twist": (
        ("time",),
        "1",
        "twist Tw of the rod in turns",
        "Tw = (1/(2 pi)) integral of kappa_3 ds over the rod (seed eq. 7)",
    ),
    "writhe": (
        ("time",),
        "1",
        "writhe Wr of the centreline",
        "open centreline closed by extending its end tangents",
    ),
    "linking_number": (
        ("time",),
        "1",
        "linking number Lk of the rod in turns",
        "from the rotation of the ends about the rod axis; Lk = Tw + Wr",
    ),
    "topology_error": (("time",), "1", "magnitude of Tw + Wr - Lk", None),
    "writhe_closure_passages": (
        ("time",),
        "1",
        "net passages of the rod through the closure of its open ends",
        "each changes the writhe of the closed curve by 2 with no self-crossing; writhe "
        "is kept continuous by adding 2 per passage (docs/topology.md)",
    ),
    "reaction_force_start": (
        ("time", "xyz"), "N", "load applied to the rod at its end s = 0, global frame",
        "-R f at s = 0: the support's force, or the end's prescribed force (a point load "
        "at s = 0 is not part of it)",
    ),
    "reaction_force_end": (
        ("time", "xyz"), "N", "load applied to the rod at its end s = L, global frame",
        "R f at s = L: the support's force, or the end's prescribed force (a point load "
        "at s = L is not part of it)",
    ),
    "reaction_moment_start": (
        ("time", "xyz"), "N m", "moment applied to the rod at its end s = 0, global frame",
        "-R q at s = 0, q = diag(E J1, E J2, G J3) kappa",
    ),
    "reaction_moment_end": (
        ("time", "xyz"), "N m", "moment applied to the rod at its end s = L, global frame",
        "R q at s = L, q = diag(E J1, E J2, G J3) kappa",
    ),
    "contact_count": (("time",), "1", "number of self-contact pairs", None),
    "min_surface_gap": (("time",), "m", "smallest surface gap among self-contact pairs", None),
    "bend_radius_min": (
        ("time",), "m", "smallest bend radius along the rod",
        "min over the grid points of 1/|(kappa_1, kappa_2)|, the bending curvatures (kappa_3, "
        "the twist rate, does not bend the centreline); inf: the rod is straight",
    ),
    "bend_radius_min_s": (
        ("time",), "m", "arclength at which the bend radius is smallest",
        "the grid point of bend_radius_min; NaN when the rod is straight",
    ),
    "seabed_force": (
        ("time", "s", "xyz"), "N m-1", "seabed normal reaction per unit length, global frame",
        "k p - c n.v along the bottom's normal n while the surface penetration p > 0 "
        "(docs/seabed.md); present with a seabed only",
    ),
    "seabed_friction": (
        ("time", "s", "xyz"), "N m-1", "seabed friction per unit length, global frame",
        "Coulomb, axial and lateral, at the contact point (docs/seabed.md); present with a "
        "seabed only",
    ),
    "seabed_contact_length": (
        ("time",), "m", "length of rod on the seabed",
        "arclength with surface penetration p > 0, nodes between touching ones hovering "
        "less than 2.5 % of the diameter above the bottom counting as touching "
        "(solver.seabed.CONTACT_GAP; docs/seabed.md)",
    ),
    "seabed_touchdown": (
        ("time",), "m", "arclength of the touchdown point",
        "where the contact holding an end of the rod on the seabed ends; NaN where none",
    ),
    "seabed_work": (
        ("time",), "J", "cumulative work done on the rod by the seabed",
        "normal reaction, friction and its moment; trapezoid rule on its power per step",
    ),
    "newton_iterations": (
        ("time",),
        "1",
        "Newton iterations of the step that reached this output time",
        None,
    ),
    "residual_norm": (
        ("time",),
        "1",
        "final scaled Newton residual norm of the step that reached this output time",
        None,
    ),
    "dt": (("time",), "s", "time step that reached this output time", None),
    "position_route_difference": (
        ("time",),
        "m",
        "largest distance between the shape integrated along s from kappa and the "
        "positions integrated in t from v",
        "a discretisation-error indicator; with self-contact the positions integrated "
        "in t are the centreline (docs/numerics.md)",
    ),
    "end_drift": (
        ("time",),
        "m",
        "distance of the centreline's s = L end from the end's prescribed motion, along "
        "its prescribed translations",
        "the centreline is integrated along s from node 0; with self-contact its s = L "
        "end is steered onto the end's prescribed path, not held on it (docs/contact.md, "
        "\"The far end is steered onto its prescribed motion\"); 0 while no "
        "translation is prescribed at s = L",
    ),
    "quaternion_norm_error": (
        ("time",),
        "1",
        "largest deviation of the orientation quaternion norm from 1",
        None,
    ),
}

DIAGNOSTIC_VARIABLES: dict[str, tuple[str, str]] = {
    "step_time": ("s", "simulation time at the end of the accepted step"),
    "step_dt": ("s", "time step of the accepted step"),
    "step_newton_iterations": ("1", "Newton iterations of the accepted step"),
    "step_residual_norm": ("1", "final scaled Newton residual norm of the accepted step"),
    "step_growth_rate": ("s-1", "largest growth rate sigma of the linearised dynamics at the "
                         "last growth-guard check (0: none found; NaN: not checked)"),
    "step_rejected_attempts": ("1", "attempts refused before the accepted step (error "
                               "estimate, Newton, contact or growth guard), each followed "
                               "by a smaller time step"),
    "step_energy_error": ("1", "largest energy balance error of the accepted step's "
                          "substeps, (energy change minus the loads' work) over the energy "
                          "scale; > 0: energy injected (numerics.energy_tolerance; NaN: "
                          "not checked, in contact or restart steps)"),
}

# ACDD-1.3 coverage_content_type (ISO 19115-1 MD_CoverageContentTypeCode) of each variable;
# coordinates are "coordinate", every other variable not listed here is "modelResult".
COVERAGE_CONTENT_TYPES: dict[str, str] = {
    "topology_error": "qualityInformation",
    "newton_iterations": "qualityInformation",
    "residual_norm": "qualityInformation",
    "position_route_difference": "qualityInformation",
    "end_drift": "qualityInformation",
    "quaternion_norm_error": "qualityInformation",
    "step_newton_iterations": "qualityInformation",
    "step_residual_norm": "qualityInformation",
    "dt": "auxiliaryInformation",
    "step_dt": "auxiliaryInformation",
    "step_growth_rate": "auxiliaryInformation",
    "step_rejected_attempts": "qualityInformation",
    "step_energy_error": "qualityInformation",
}

# CF-1.12 section 3.4: quality variables linked to the variable whose values they qualify
# (written only when both are in the dataset).
_ANCILLARY: dict[str, tuple[str, ...]] = {
    "position": ("position_route_difference", "end_drift"),
    "orientation": ("quaternion_norm_error",),
    "twist": ("topology_error",),
    "writhe": ("topology_error", "writhe_closure_passages"),
    "linking_number": ("topology_error",),
}

# Integer index coordinates of the vector dimensions: dimension -> (index values, labels).
# The labels travel in the file as CF flag_values / flag_meanings (no string coordinate,
# which CF checkers and several readers refuse); the REST API accepts either.
INDEX_LABELS: dict[str, tuple[tuple[int, ...], tuple[str, ...]]] = {
    "component": ((1, 2, 3), ("a1", "a2", "a3")),
    "xyz": ((1, 2, 3), ("x", "y", "z")),
    "quaternion": ((0, 1, 2, 3), ("w", "x", "y", "z")),
}
_INDEX_LONG_NAMES = {
    "component": "body-frame component index: 1, 2, 3 along the directors a1, a2, a3 "
                 "(a3 the tangent)",
    "xyz": "global-frame axis index: 1 = x, 2 = y, 3 = z (unit vectors e1, e2, e3)",
    "quaternion": "unit quaternion component index: 0 = w (scalar part), 1 = x, 2 = y, 3 = z",
}

KEYWORDS = (
    "elastic rod, Kirchhoff rod, cable dynamics, hockling, supercoiling, plectoneme, "
    "twist, writhe, linking number, self-contact, numerical simulation"
)

# ACDD attributes about who made the data and on what terms: set by the operator (the
# HOCKLE_* settings, service.settings.Settings), never guessed by the solver.
METADATA_ATTRIBUTES = (
    "naming_authority",
    "creator_name",
    "creator_email",
    "creator_url",
    "creator_type",
    "creator_institution",
    "institution",
    "publisher_name",
    "publisher_email",
    "publisher_url",
    "publisher_type",
    "publisher_institution",
    "license",
    "project",
    "program",
    "acknowledgement",
    "contributor_name",
    "contributor_role",
)

# What a file says when the operator set nothing: true statements, not invented names.
DEFAULT_METADATA: dict[str, str] = {
    "naming_authority": "hockle",
    "creator_name": "not specified (the operator sets HOCKLE_CREATOR_NAME)",
    "license": "not specified (the operator sets HOCKLE_LICENSE)",
}

_INTEGER_VARIABLES = {"contact_count", "newton_iterations", "step_newton_iterations",
                      "step_rejected_attempts"}

_COMPRESSED = {"dtype": "float64", "zlib": True, "complevel": 4, "shuffle": True}


def _utc_now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()


def _iso_duration(seconds: float) -> str:
    """ISO 8601 duration of ``seconds`` (``PT45S``, ``PT0.05S``)."""
    return f"PT{float(seconds):.12g}S"


def _as_values(name: str, values: Any, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.asarray(values)
    if arr.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {arr.shape}")
    if name in _INTEGER_VARIABLES:
        arr = arr.astype(np.float64)
        if np.all(np.isfinite(arr)):
            return arr.astype(np.int32)
        return arr  # a NaN marks "no step" (e.g. the initial row); keep float64
    if not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
        raise ValueError(f"{name}: expected real numbers, got dtype {arr.dtype}")
    return arr.astype(np.float64)


def _encoding(arr: np.ndarray, dims: tuple[str, ...]) -> dict[str, Any]:
    if arr.dtype == np.int32:
        return {"dtype": "int32"}
    if dims[:2] == ("time", "s"):
        return dict(_COMPRESSED)
    return {"dtype": "float64"}


def _summary(case: Any, n_points: int, times: np.ndarray, status: str) -> str:
    numerics = getattr(case, "numerics", None)
    if getattr(numerics, "formulation", "goyal") == "centreline":
        scheme = ("positions and frames as unknowns, the box rule in arclength and Lie-group "
                  "generalized-alpha in time")
    else:
        scheme = "generalized-alpha scheme in space and time"
    parts = [
        "Nonlinear dynamics of a twisted elastic rod (dynamic Kirchhoff rod of Goyal, "
        f"Perkins & Lee, {scheme}"
    ]
    if getattr(case, "contact", None) is not None:
        parts.append(", with self-contact")
    fluid = getattr(case, "fluid", None)
    if fluid is not None:
        if getattr(fluid, "viscosity", None) is not None:
            parts.append(", in a viscous fluid (added mass, Morison drag and the Stokes drag "
                         "of resistive-force theory)")
        else:
            parts.append(", in a fluid (added mass and Morison drag)")
    thermal = getattr(case, "thermal", None)
    if thermal is not None:
        parts.append(f", with thermal fluctuations at {float(thermal.temperature):g} K "
                     f"(seed {int(thermal.seed)})")
    parts.append(f"): {n_points} grid points")
    if times.size:
        parts.append(f", simulation time {times[0]:g} s to {times[-1]:g} s")
    t_end = getattr(getattr(case, "numerics", None), "t_end", None)
    if t_end is not None:
        parts.append(f" of {float(t_end):g} s")
    parts.append(f"; run {status}.")
    return "".join(parts)


def _index_coordinate(dim: str) -> xr.Variable:
    values, labels = INDEX_LABELS[dim]
    var = xr.Variable(
        dim,
        np.array(values, dtype=np.int32),
        {
            "units": "1",
            "long_name": _INDEX_LONG_NAMES[dim],
            "flag_values": np.array(values, dtype=np.int32),
            "flag_meanings": " ".join(labels),
            "coverage_content_type": "coordinate",
        },
    )
    var.encoding = {"_FillValue": None}
    return var


def _time_coverage(times: np.ndarray) -> dict[str, str]:
    """ACDD time_coverage_duration/_resolution as ISO 8601 durations of simulated time.

    No time_coverage_start/_end: those are calendar instants and simulated time has no
    epoch (docs/interfaces.md, "Time").
    """
    out: dict[str, str] = {}
    if times.size == 0 or not np.all(np.isfinite(times)):
        return out
    out["time_coverage_duration"] = _iso_duration(times[-1] - times[0])
    if times.size > 1:
        steps = np.diff(times)
        if np.allclose(steps, steps[0], rtol=1e-9, atol=0.0) and steps[0] > 0:
            out["time_coverage_resolution"] = _iso_duration(steps[0])
    return out


def build_dataset(
    case: Any,
    s: np.ndarray,
    times: np.ndarray,
    fields: Mapping[str, np.ndarray],
    diagnostics: Mapping[str, np.ndarray],
    status: str,
    message: str = "",
    attrs: Mapping[str, str | int | float] | None = None,
) -> xr.Dataset:
    """Assemble the result dataset of one run.

    Parameters
    ----------
    case:
        The validated :class:`solver.case.Case` (needs ``name``, ``canonical_json()``,
        ``spec_hash()``; ``numerics``, ``contact``, ``fluid`` are read when present).
    s:
        (N,) arclength of the grid points, m, increasing.
    times:
        (T,) output times, s, non-decreasing. ``T`` may be 0 or 1 for a run that failed
        early.
    fields:
        Only the keys computed (unknown keys raise ``ValueError``):
        ``v omega f kappa moment``: (T, N, 3) body frame, in m s-1, rad s-1, N, rad m-1,
        N m; ``position``: (T, N, 3) global frame, m; ``orientation``: (T, N, 4) unit
        quaternion (w, x, y, z); ``energy_bending energy_torsion energy_kinetic
        energy_kinetic_fluid energy_total work_in``: (T,) J; ``power_in``: (T,) W;
        ``twist writhe linking_number topology_error writhe_closure_passages``: (T,)
        turns;
        ``contact_count``: (T,); ``min_surface_gap``: (T,) m; ``bend_radius_min
        bend_radius_min_s``: (T,) m; ``newton_iterations
        residual_norm quaternion_norm_error``: (T,); ``dt``: (T,) s;
        ``position_route_difference``: (T,) m.
    diagnostics:
        Per accepted step, all of length K: ``step_time`` (s), ``step_dt`` (s),
        ``step_newton_iterations``, ``step_residual_norm``, ``step_growth_rate`` (1/s),
        ``step_rejected_attempts`` (optional).
        An empty mapping adds no ``step`` dimension.
    status:
        ``"completed"``, ``"stopped"`` or ``"failed"`` (global attribute
        ``hockle_status``).
    message:
        Free text for the global attribute ``hockle_message`` (e.g. why a run stopped).
    attrs:
        Extra global attributes (e.g. ``hockle_stop_reason``); strings or numbers. They
        are applied last and may replace the defaults (``id``, ``license``, ...).

    Returns
    -------
    xarray.Dataset
        float64 data; (time, s, ...) variables carry zlib level-4 compression in their
        ``encoding`` so that ``to_netcdf`` applies it. Only the dimensions some variable
        uses are present (``time`` always). Global attributes: CF-1.12 and ACDD-1.3
        (``Conventions``, ``id`` = the case hash, ``title``, ``summary``, ``keywords``,
        ``time_coverage_duration``, ``date_created``, ...) with
        :data:`DEFAULT_METADATA` for the operator's attributes (see
        :func:`apply_metadata`).

    Raises
    ------
    ValueError
        Unknown status, field or diagnostic; a shape that does not match; non-numeric
        values; an attribute that is neither a string nor a number.
    """
    _check_inputs(status, s, times, fields, diagnostics)
    s = np.asarray(s, dtype=np.float64)
    times = np.asarray(times, dtype=np.float64)
    data_vars = _field_variables(fields, times.size, s.size)
    used = {d for var in data_vars.values() for d in var.dims}
    coords = _coordinates(times, s, used)
    if diagnostics:
        _diagnostic_variables(diagnostics, coords, data_vars)
    global_attrs = _global_attributes(case, s.size, times, status, message, attrs)
    return xr.Dataset(data_vars=data_vars, coords=coords, attrs=global_attrs)


def _check_inputs(status, s, times, fields, diagnostics) -> None:
    """The checks of :func:`build_dataset`'s arguments; raises ValueError with the reason."""
    if status not in STATUSES:
        raise ValueError(f"status must be one of {STATUSES}, got {status!r}")
    s = np.asarray(s, dtype=np.float64)
    times = np.asarray(times, dtype=np.float64)
    if s.ndim != 1 or s.size < 2:
        raise ValueError(f"s: expected shape (N,) with N >= 2, got {s.shape}")
    if times.ndim != 1:
        raise ValueError(f"times: expected shape (T,), got {times.shape}")
    unknown = sorted(set(fields) - set(FIELD_VARIABLES))
    if unknown:
        raise ValueError(f"unknown field(s) {unknown}; known: {sorted(FIELD_VARIABLES)}")
    unknown = sorted(set(diagnostics) - set(DIAGNOSTIC_VARIABLES))
    if unknown:
        raise ValueError(
            f"unknown diagnostic(s) {unknown}; known: {sorted(DIAGNOSTIC_VARIABLES)}"
        )


def _field_variables(fields: Mapping[str, np.ndarray], n_t: int,
                     n_s: int) -> dict[str, xr.Variable]:
    """The (time, ...) field variables of :func:`build_dataset` with their CF attributes
    and compression encoding; raises ValueError for a shape that does not match."""
    sizes = {"time": n_t, "s": n_s, "component": 3, "xyz": 3, "quaternion": 4}
    data_vars: dict[str, xr.Variable] = {}
    for name, values in fields.items():
        dims, units, long_name, comment = FIELD_VARIABLES[name]
        arr = _as_values(name, values, tuple(sizes[d] for d in dims))
        var_attrs = {
            "units": units,
            "long_name": long_name,
            "coverage_content_type": COVERAGE_CONTENT_TYPES.get(name, "modelResult"),
        }
        if comment:
            var_attrs["comment"] = comment
        ancillary = [a for a in _ANCILLARY.get(name, ()) if a in fields]
        if ancillary:
            var_attrs["ancillary_variables"] = " ".join(ancillary)
        var = xr.Variable(dims, arr, var_attrs)
        var.encoding = _encoding(arr, dims)
        data_vars[name] = var
    return data_vars


def _coordinates(times: np.ndarray, s: np.ndarray, used: set) -> dict[str, xr.Variable]:
    """The coordinates of :func:`build_dataset`: time (always), s and the index labels
    of the dimensions in ``used``."""
    coords: dict[str, xr.Variable] = {
        "time": xr.Variable(
            "time",
            times,
            {
                "standard_name": "time",
                "axis": "T",
                "units": "s",
                "long_name": "simulation time (elapsed from the start of the run)",
                "comment": "elapsed simulated time in seconds, without a calendar epoch",
                "coverage_content_type": "coordinate",
            },
        ),
    }
    if "s" in used:
        coords["s"] = xr.Variable(
            "s",
            s,
            {
                "units": "m",
                "long_name": "arclength along the rod centreline from the start end",
                "comment": "s = 0 is the start end, s = L the far end",
                "coverage_content_type": "coordinate",
            },
        )
    for name in ("time", "s"):
        if name in coords:
            coords[name].encoding = {"_FillValue": None}
    for dim in INDEX_LABELS:
        if dim in used:
            coords[dim] = _index_coordinate(dim)
    return coords


def _diagnostic_variables(diagnostics: Mapping[str, np.ndarray], coords: dict,
                          data_vars: dict) -> None:
    """The per-step diagnostics of :func:`build_dataset`: the ``step`` coordinate and
    ``step_time`` into ``coords``, the others into ``data_vars`` (both changed in place).
    Raises ValueError for unequal or non-(K,) shapes."""
    lengths = {np.shape(v) for v in diagnostics.values()}
    if len(lengths) != 1 or len(next(iter(lengths))) != 1:
        raise ValueError(
            f"diagnostics: expected equal shapes (K,), got "
            f"{ {k: np.shape(v) for k, v in diagnostics.items()} }"
        )
    (n_steps,) = next(iter(lengths))
    coords["step"] = xr.Variable(
        "step",
        np.arange(1, n_steps + 1, dtype=np.int32),
        {
            "units": "1",
            "long_name": "accepted solver step number",
            "coverage_content_type": "coordinate",
        },
    )
    coords["step"].encoding = {"_FillValue": None}
    for name, values in diagnostics.items():
        units, long_name = DIAGNOSTIC_VARIABLES[name]
        arr = _as_values(name, values, (n_steps,))
        ctype = "coordinate" if name == "step_time" else COVERAGE_CONTENT_TYPES.get(
            name, "modelResult")
        var = xr.Variable(
            ("step",),
            arr,
            {"units": units, "long_name": long_name, "coverage_content_type": ctype},
        )
        var.encoding = _encoding(arr, ("step",))
        if name == "step_time":
            coords[name] = var  # coordinate-like: the time axis of the step dimension
        else:
            data_vars[name] = var


def _global_attributes(case: Any, n_s: int, times: np.ndarray, status: str, message: str,
                       attrs: Mapping[str, str | int | float] | None) -> dict[str, Any]:
    """The global attributes of :func:`build_dataset` (CF-1.12, ACDD-1.3, the case and
    the run's status), ``attrs`` applied last; raises ValueError for an attribute that is
    neither a string nor a number."""
    from solver import __version__

    now = _utc_now()
    global_attrs: dict[str, Any] = {
        "Conventions": CONVENTIONS,
        "id": case.spec_hash(),
        "title": str(case.name),
        "summary": _summary(case, n_s, times, status),
        "keywords": KEYWORDS,
        "comment": (
            "Body-frame components (dimension component) are along the cross-section's "
            "directors a1, a2, a3 (a3 the tangent); global-frame ones (dimension xyz) along "
            "x, y, z. Layout, units and frames: docs/interfaces.md of hockle."
        ),
        "source": f"hockle {__version__}",
        "product_version": str(__version__),
        "processing_level": "simulation output as computed by the solver (no post-processing)",
        "history": f"{now} created by hockle {__version__}",
        "references": REFERENCES,
        "standard_name_vocabulary": "CF Standard Name Table v93",
        "date_created": now,
        "date_modified": now,
        "date_metadata_modified": now,
        **_time_coverage(times),
        **DEFAULT_METADATA,
        "case": case.canonical_json(),
        "case_hash": case.spec_hash(),
        "hockle_status": status,
        "hockle_message": str(message),
    }
    for key, value in (attrs or {}).items():
        if isinstance(value, bool) or not isinstance(value, (str, int, float)):
            raise ValueError(f"attribute {key!r}: expected a string or number, got {value!r}")
        global_attrs[key] = value

    return global_attrs


def apply_metadata(
    ds: xr.Dataset,
    metadata: Mapping[str, str | None],
    dataset_id: str | None = None,
) -> xr.Dataset:
    """Set the operator's ACDD attributes (creator, publisher, licence ...) on ``ds``.

    Parameters
    ----------
    ds:
        A dataset from :func:`build_dataset` (changed in place and returned).
    metadata:
        Attribute name -> value, names from :data:`METADATA_ATTRIBUTES`; ``None`` or an
        empty string leaves the attribute as it is (the default of
        :data:`DEFAULT_METADATA`, or absent).
    dataset_id:
        The ACDD ``id`` (e.g. the service's job id); ``None`` keeps the case hash.

    Returns
    -------
    xarray.Dataset
        ``ds``, with ``date_metadata_modified`` set to now when anything changed.

    Raises
    ------
    ValueError
        A name outside :data:`METADATA_ATTRIBUTES`, a value that is not a string, or an
        ``id`` with blanks (ACDD asks for none).
    """
    unknown = sorted(set(metadata) - set(METADATA_ATTRIBUTES))
    if unknown:
        raise ValueError(
            f"unknown metadata attribute(s) {unknown}; known: {list(METADATA_ATTRIBUTES)}"
        )
    changed = False
    for key, value in metadata.items():
        if value is None or value == "":
            continue
        if not isinstance(value, str):
            raise ValueError(f"metadata {key!r}: expected a string, got {value!r}")
        ds.attrs[key] = value
        changed = True
    if dataset_id is not None:
        dataset_id = str(dataset_id)
        if not dataset_id or any(c.isspace() for c in dataset_id):
            raise ValueError(f"dataset id {dataset_id!r}: expected a string without blanks")
        ds.attrs["id"] = dataset_id
        changed = True
    if changed:
        ds.attrs["date_metadata_modified"] = _utc_now()
    return ds


# --------------------------------------------------------------------------- events of a run

#: turns of writhe change that count as buckled when the file stores no position
WRITHE_ONSET = 0.05

EVENT_RULES = (
    "buckling_onset: first stored time the centreline has moved more than the rod's largest "
    "diameter away from its first stored shape across its chord (each point's offset from "
    "the line through the ends, compared with that point's offset at the first output: a "
    "straight start reads as the distance from the chord, a curved lay's own shape does not "
    "count, the ends' motion along the chord neither); without position, the first time "
    "the writhe has changed by 0.05 turns. first_contact: first time contact_count > 0. "
    "loop_formed: first time the rod touches itself (contact_count > 0) or |Wr| has risen "
    "through 1 turn (from below 1), with a seabed only while the rod lies on the bottom. "
    "bend_radius_below_mbr (when the case gives rod.minimum_bend_radius): first time the "
    "smallest bend radius is below it. writhe_k: first time |Wr| >= k turns. NaN: did not "
    "happen in the stored outputs (or the member has no result).")


def _chord_offsets(pos: np.ndarray) -> np.ndarray:
    """(T, N, 3) each point's offset (m) of the centreline (T, N, 3) from the line through
    its ends: its position from the start end less the part along the chord."""
    a, b = pos[:, :1, :], pos[:, -1:, :]
    axis = b - a
    length = np.linalg.norm(axis, axis=2, keepdims=True)
    unit = np.divide(axis, length, out=np.zeros_like(axis), where=length > 0)
    rel = pos - a
    along = np.sum(rel * unit, axis=2, keepdims=True)
    return rel - along * unit


def shape_departure(pos: np.ndarray) -> np.ndarray:
    """(T,) the buckling measure of :data:`EVENT_RULES` (m): the largest distance, over
    the grid points, between a point's offset from the chord (the line through the ends)
    and the same point's offset at the first stored time.

    For a rod that starts straight it is the distance from the chord; for a curved lay
    (the 5-cm half-sine of ``cases/seabed-hockle.yaml``) the lay's own curve reads 0, so a
    shape that starts more than a diameter off its chord still has an onset. The motion
    of the ends along the chord (an end pulled in or let out) does not count."""
    return np.max(node_departure(pos), axis=1)


def node_departure(pos: np.ndarray) -> np.ndarray:
    """(T, N) each grid point's part of :func:`shape_departure` (m): the distance between
    its offset from the chord and its offset at the first of the shapes ``pos`` (T, N, 3).
    ``hockle plot`` zooms to where it is largest."""
    offsets = _chord_offsets(pos)
    return np.linalg.norm(offsets - offsets[:1], axis=2)


def _first(mask: np.ndarray) -> int | None:
    hits = np.flatnonzero(mask)
    return int(hits[0]) if hits.size else None


def _largest_diameter(ds) -> float | None:
    """The rod's largest diameter (m) from the case stored in the file, or None."""
    try:
        d = json.loads(str(ds.attrs["case"]))["rod"]["diameter"]
    except (KeyError, TypeError, ValueError):
        return None
    if isinstance(d, (int, float)) and not isinstance(d, bool):
        return float(d)
    if isinstance(d, dict) and d.get("value"):
        return float(max(d["value"]))
    return None


def _case_of(ds) -> dict:
    """The case stored in the file's ``case`` attribute as a dict ({} when absent)."""
    try:
        case = json.loads(str(ds.attrs["case"]))
    except (KeyError, TypeError, ValueError):
        return {}
    return case if isinstance(case, dict) else {}


def minimum_bend_radius_of(ds) -> float | None:
    """The cable's minimum bend radius from the case a result file carries.

    Parameters
    ----------
    ds : xarray.Dataset
        A result dataset.

    Returns
    -------
    float or None
        ``rod.minimum_bend_radius``, m; None when the case gives none.
    """
    mbr = (_case_of(ds).get("rod") or {}).get("minimum_bend_radius")
    return float(mbr) if isinstance(mbr, (int, float)) and not isinstance(mbr, bool) else None


def bend_radius_series(ds) -> np.ndarray | None:
    """The smallest bend radius at each stored time.

    Parameters
    ----------
    ds : xarray.Dataset
        A result dataset.

    Returns
    -------
    numpy.ndarray or None
        (T,) m: ``bend_radius_min`` when stored, else from ``kappa``; None without either.
    """
    if "bend_radius_min" in ds:
        return np.asarray(ds["bend_radius_min"].values, dtype=float)
    if "kappa" in ds and "s" in ds.coords:
        from .kinematics import min_bend_radius

        kappa = np.asarray(ds["kappa"].transpose("time", "s", "component").values, dtype=float)
        return min_bend_radius(kappa, np.asarray(ds["s"].values, dtype=float))[0]
    return None


def on_bottom(ds) -> np.ndarray | None:
    """Where the rod touches the sea floor.

    Parameters
    ----------
    ds : xarray.Dataset
        A result dataset.

    Returns
    -------
    numpy.ndarray or None
        (T,) bool, ``seabed_contact_length`` > 0, for a result whose case has a seabed;
        None otherwise.
    """
    if "seabed" not in _case_of(ds) or "seabed_contact_length" not in ds:
        return None
    return np.nan_to_num(np.asarray(ds["seabed_contact_length"].values, dtype=float)) > 0


#: How a result is recognised as a magnetic-tweezers run (:func:`tweezers_protocol`), in
#: words for the docs and ``hockle plot``'s help.
TWEEZERS_RULE = (
    "a run is a tweezers run when its case starts straight (no initial.centreline), both ends "
    "in the body frame, each with one condition per item: every rotation item an "
    "angular_velocity, items 0 and 1 zero (each end's tangent stays fixed: the surface and a "
    "bead held by its magnet), item 2 a number or table (the turns); one end pulled by a "
    "constant axial force > 0 (translation item 2, a number: the tension) with its items 0 "
    "and 1 a zero force or a zero velocity; the other end held (every translation item "
    "velocity 0).")


def _single_conditions(items) -> list | None:
    """The one condition mapping of each item of an end's ``translation`` or ``rotation``
    (canonical JSON: a list of conditions per item), or None when an item switches in time
    or the group does not have 3 items."""
    if not isinstance(items, list) or len(items) != 3:
        return None
    out = []
    for item in items:
        if isinstance(item, dict):
            item = [item]
        if not isinstance(item, list) or len(item) != 1 or not isinstance(item[0], dict):
            return None
        out.append(item[0])
    return out


def _number(value) -> float | None:
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def tweezers_protocol(case: Mapping) -> dict | None:
    """The magnetic-tweezers protocol a case states, or None when it states none.

    The rule is :data:`TWEEZERS_RULE` (docs/tweezers.md, "The case form"): one end pulled
    along its fixed tangent by a constant axial force, both ends' tangents held, the rod
    turned about its axis by the ends' ``angular_velocity`` item 2 (either end or both).

    Parameters
    ----------
    case : mapping
        A case document as the canonical JSON holds it (a result's ``case`` attribute,
        parsed), or as written (single condition mappings are read as one-item lists).

    Returns
    -------
    dict or None
        ``force_end`` ("start" or "end", the pulled end), ``force`` (N, > 0, the tension),
        ``axis`` ((3,) unit vector, global: ``initial.tangent``, the force's direction at
        s = L and minus it at s = 0, the axis extension and torque are measured along),
        ``spin`` ({"start": value, "end": value}: each end's ``angular_velocity`` item 2,
        rad/s, a number or a ``{t, value}`` table) and ``length`` (m, ``rod.length``).
    """
    boundary = case.get("boundary") if isinstance(case, Mapping) else None
    initial = (case.get("initial") or {}) if isinstance(case, Mapping) else {}
    if not isinstance(boundary, Mapping) or initial.get("centreline") is not None:
        return None
    groups = {}
    for name in ("start", "end"):
        ec = boundary.get(name)
        if not isinstance(ec, Mapping) or ec.get("frame", "body") != "body":
            return None
        rotation = _single_conditions(ec.get("rotation"))
        translation = _single_conditions(ec.get("translation"))
        if rotation is None or translation is None:
            return None
        if any(set(c) != {"angular_velocity"} for c in rotation):
            return None
        if any(_number(rotation[i]["angular_velocity"]) != 0.0 for i in (0, 1)):
            return None
        groups[name] = (translation, rotation[2]["angular_velocity"])
    pulled = [name for name, (tr, _) in groups.items()
              if set(tr[2]) == {"force"} and (_number(tr[2]["force"]) or 0.0) > 0.0]
    if len(pulled) != 1:
        return None
    force_end = pulled[0]
    held = "start" if force_end == "end" else "end"
    if any(c != {"velocity": 0.0} for c in groups[held][0]):      # 0 == 0.0: either spelling
        return None
    if any(c not in ({"force": 0.0}, {"velocity": 0.0}) for c in groups[force_end][0][:2]):
        return None
    tangent = np.asarray(initial.get("tangent", [0.0, 0.0, 1.0]), dtype=float)
    length = _number((case.get("rod") or {}).get("length"))
    if tangent.shape != (3,) or not np.linalg.norm(tangent) > 0 or length is None:
        return None
    axis = tangent / np.linalg.norm(tangent)
    return {"force_end": force_end, "force": float(groups[force_end][0][2]["force"]),
            "axis": axis if force_end == "end" else -axis,
            "spin": {name: groups[name][1] for name in groups}, "length": length}


def _rotation_angle(rate, times: np.ndarray) -> np.ndarray:
    """(T,) rad: ∫_0^t of an angular velocity (rad/s, a number or a ``{t, value}`` table,
    piecewise linear and held outside its knots) at each of ``times`` (T,) s, exact."""
    number = _number(rate)
    if number is not None:
        return number * times
    tk = np.asarray(rate["t"], dtype=float)
    vk = np.asarray(rate["value"], dtype=float)
    top = float(np.max(times)) if times.size else 0.0
    knots = np.unique(np.concatenate([[0.0], tk[(tk > 0.0) & (tk < top)], times]))
    values = np.interp(knots, tk, vk)
    angle = np.concatenate([[0.0], np.cumsum(0.5 * (values[1:] + values[:-1]) * np.diff(knots))])
    return np.interp(times, knots, angle)


def _torsional_stiffness(case: Mapping) -> float | None:
    """G J3 = G π d⁴/32 (N m²) of a uniform rod (numbers, not profiles), else None."""
    rod = case.get("rod") or {}
    g, d = _number(rod.get("shear_modulus")), _number(rod.get("diameter"))
    return None if g is None or d is None else g * np.pi * d ** 4 / 32.0


def tweezers_series(ds) -> dict | None:
    """The magnetic-tweezers curves of a result: turns, extension and torque at each
    stored time.

    Parameters
    ----------
    ds : xarray.Dataset
        A result dataset whose case is a tweezers run (:func:`tweezers_protocol`).

    Returns
    -------
    dict or None
        None when the case is not a tweezers run or the dataset stores no time. Else the
        protocol's entries (:func:`tweezers_protocol`) and, each (T,):

        * ``turns``: the prescribed rotation of the end s = L less that of s = 0 about
          the axis, in turns (1 = 2π rad), integrated exactly from the case's tables from
          t = 0 (the linking number's sign: with one end held, Lk(t) = turns);
        * ``extension`` (m): (r(L) − r(0))·axis, the pulled end's height above the held
          one along the force, as the instrument reads the bead; None without
          ``position``;
        * ``torque`` (N m): the rod's internal twisting moment at the pulled end along the
          axis, m·axis with m = R q (``reaction_moment_end``·axis at s = L,
          −``reaction_moment_start``·axis at s = 0), positive where the rod is overwound
          (turns > 0), the torque the rod puts on a bead turned back; None without the
          ``reactions`` output;
        * ``twist_torque`` (N m): the straight rod's torque at the same turns,
          2π G J3 turns / L (a uniform rod only, else None): the linear rise before it
          buckles.
    """
    protocol = tweezers_protocol(_case_of(ds)) if ds is not None else None
    if protocol is None or "time" not in ds.coords or ds.sizes.get("time", 0) == 0:
        return None
    t = np.asarray(ds["time"].values, dtype=float)
    spin = protocol["spin"]
    turns = (_rotation_angle(spin["end"], t) - _rotation_angle(spin["start"], t)) / (2 * np.pi)
    axis = protocol["axis"]
    extension = None
    if "position" in ds:
        pos = np.asarray(ds["position"].transpose("time", "s", "xyz").values, dtype=float)
        extension = (pos[:, -1, :] - pos[:, 0, :]) @ np.asarray(axis, float) * (
            1.0 if protocol["force_end"] == "end" else -1.0)
    name = f"reaction_moment_{protocol['force_end']}"
    torque = None
    if name in ds:
        moment = np.asarray(ds[name].transpose("time", "xyz").values, dtype=float)
        # R q at s = L is reaction_moment_end; at s = 0 it is -reaction_moment_start, and
        # the axis there is minus the tangent: the two signs cancel
        torque = moment @ np.asarray(axis, float)
    stiffness = _torsional_stiffness(_case_of(ds))
    twist_torque = None if stiffness is None else (
        2 * np.pi * stiffness * turns / protocol["length"])
    return {**protocol, "turns": turns, "extension": extension, "torque": torque,
            "twist_torque": twist_torque}


def plectoneme_two_phase(bending_stiffness: float, tension: float, radius: float) -> dict:
    """The plectonemic phase of an elastic rod with a hard core under tension and torque,
    coexisting with the straight phase (the two-phase model without thermal fluctuations
    or electrostatics: Clauvelin, Audoly & Neukirch, Biophys. J. 96, 3716, 2009; Neukirch &
    Marko, PRL 106, 138104, 2011; docs/statics.md, "The plectoneme").

    The ply of superhelix radius R and pitch angle θ (from its axis; curvature sin²θ/R,
    writhe sin 2θ/(4πR) per unit length of rod) has the energy B sin⁴θ/(2R²) −
    M sin 2θ/(2R) per length; it coexists with the straight phase (−T) where, minimised
    in θ, they are equal: sin⁴θ (2 cos²θ/cos 2θ − ½) = T R²/B, M_p = 2B sin³θ cos θ/(R cos 2θ);
    every further turn then goes into writhe and the extension falls by 4πR/sin 2θ.

    Parameters
    ----------
    bending_stiffness : float
        B, N m² (> 0).
    tension : float
        T, N (> 0).
    radius : float
        R, m (> 0): half the distance between the ply's two axes.

    Returns
    -------
    dict
        ``theta`` (rad), ``torque`` M_p (N m), ``extension_per_turn`` 4πR/sin 2θ (m).

    Raises
    ------
    ValueError
        For a non-positive or non-finite argument, or T R²/B beyond the phase's range
        (θ → π/4).
    """
    from scipy.optimize import brentq

    B, T, R = float(bending_stiffness), float(tension), float(radius)
    if not all(math.isfinite(x) and x > 0.0 for x in (B, T, R)):
        raise ValueError(f"plectoneme_two_phase: B, T, R must be positive, got {B}, {T}, {R}")
    tau = T * R * R / B

    def excess(th):
        return math.sin(th) ** 4 * (2.0 * math.cos(th) ** 2 / math.cos(2.0 * th) - 0.5) - tau

    hi = math.pi / 4 - 1e-9
    if not excess(hi) > 0.0:
        raise ValueError(f"plectoneme_two_phase: T R²/B = {tau:.3g} has no plectonemic phase")
    th = brentq(excess, 1e-12, hi, xtol=1e-15)
    return {"theta": th,
            "torque": 2.0 * B * math.sin(th) ** 3 * math.cos(th) / (R * math.cos(2.0 * th)),
            "extension_per_turn": 4.0 * math.pi * R / math.sin(2.0 * th)}


def ply_axis_distance(positions, s, far: float) -> np.ndarray:
    """Each node's distance (N+1,) m to the nearest segment of the centreline that lies
    more than ``far`` (m) away along the rod: in a plectoneme's ply, the distance between
    its two axes (2R); inf where no segment is that far. positions (N+1, 3) m, s (N+1,) m
    (segment k from node k to k + 1, its arclength its midpoint's). Raises nothing."""
    from .contact.geometry import segment_segment

    r = np.asarray(positions, dtype=float)
    s = np.asarray(s, dtype=float)
    mid = 0.5 * (s[1:] + s[:-1])
    out = np.full(r.shape[0], np.inf)
    for i in range(r.shape[0]):
        seg = np.nonzero(np.abs(mid - s[i]) > far)[0]
        if seg.size:
            p = np.repeat(r[i][None], seg.size, axis=0)
            out[i] = float(segment_segment(p, p, r[seg], r[seg + 1]).min())
    return out


def _loop_formed(ds, wr: np.ndarray | None) -> int | None:
    """The output index of :data:`EVENT_RULES`' ``loop_formed`` (None: not formed)."""
    n = ds.sizes["time"]
    loop = np.zeros(n, dtype=bool)
    if "contact_count" in ds:
        loop |= np.nan_to_num(np.asarray(ds["contact_count"].values, dtype=float)) > 0
    if wr is not None:
        # |Wr| >= 1 having been below 1 at an earlier (or this) stored time
        loop |= (wr >= 1.0 - 1e-12) & (np.minimum.accumulate(wr) < 1.0 - 1e-12)
    bottom = on_bottom(ds)
    if bottom is not None:
        loop &= bottom
    return _first(loop)


def run_events(ds) -> dict[str, int | None]:
    """The output index of each event of a result dataset.

    The one definition behind ``hockle plot``'s snapshot rows, a sweep's event
    variables, the dashboard's events and a result's ``hockle_events``; the rules are
    :data:`EVENT_RULES` (the buckling threshold is the rod's largest diameter, or 1 % of
    its length when the file does not say).

    Parameters
    ----------
    ds : xarray.Dataset
        A result dataset.

    Returns
    -------
    dict
        ``{event: output index or None}`` (None: it did not happen) for
        ``buckling_onset``, ``first_contact``, ``loop_formed``, ``bend_radius_below_mbr``
        (only when the case gives ``rod.minimum_bend_radius``) and ``writhe_1``,
        ``writhe_2``, ... up to the largest |Wr| reached, in the order the events
        happened (the earliest first, those that did not happen last).
    """
    out: dict[str, int | None] = {"buckling_onset": None, "first_contact": None,
                                  "loop_formed": None}
    mbr = minimum_bend_radius_of(ds) if ds is not None else None
    if mbr is not None:
        out["bend_radius_below_mbr"] = None
    if ds is None or "time" not in ds.coords or ds.sizes.get("time", 0) == 0:
        return out
    if "position" in ds and "s" in ds.coords:
        pos = np.asarray(ds["position"].transpose("time", "s", "xyz").values, dtype=float)
        s = np.asarray(ds["s"].values, dtype=float)
        d = _largest_diameter(ds)
        threshold = d if d is not None else 0.01 * float(s[-1] - s[0])
        dev = shape_departure(pos)
        out["buckling_onset"] = _first(np.nan_to_num(dev, nan=0.0) >= threshold)
    elif "writhe" in ds:
        wr = np.asarray(ds["writhe"].values, dtype=float)
        out["buckling_onset"] = _first(np.abs(wr - wr[0]) >= WRITHE_ONSET)
    if "contact_count" in ds:
        count = np.nan_to_num(np.asarray(ds["contact_count"].values, dtype=float))
        out["first_contact"] = _first(count > 0)
    wr = None
    if "writhe" in ds:
        wr = np.abs(np.asarray(ds["writhe"].values, dtype=float))
        wr = np.where(np.isfinite(wr), wr, 0.0)
    out["loop_formed"] = _loop_formed(ds, wr)
    if mbr is not None:
        radius = bend_radius_series(ds)
        if radius is not None:
            out["bend_radius_below_mbr"] = _first(np.nan_to_num(radius, nan=np.inf) < mbr)
    if wr is not None:
        for k in range(1, int(np.floor(np.max(wr) + 1e-12)) + 1):
            out[f"writhe_{k}"] = _first(wr >= k - 1e-12)
    return _in_time_order(out)


def event_label(name: str) -> str:
    """The words for an event of :func:`run_events` (``writhe_2`` -> ``|Wr| reaches 2``)."""
    if name.startswith("writhe_"):
        return f"|Wr| reaches {name[len('writhe_'):]}"
    return {"buckling_onset": "buckling onset", "first_contact": "first contact",
            "loop_formed": "loop formed",
            "bend_radius_below_mbr": "bend radius below the MBR"}.get(name, name.replace("_", " "))


def events_summary(ds) -> str:
    """One line of the run's events in the order they happened, with their output times,
    then those that did not happen: ``"buckling onset at 1.2 s, ..., |Wr| reaches 2 at
    4 s; did not happen: ..."`` (``hockle run``'s summary and a result's
    ``hockle_events``); "" for a dataset without outputs."""
    if ds is None or "time" not in ds.coords or ds.sizes.get("time", 0) == 0:
        return ""
    t = np.asarray(ds["time"].values, dtype=float)
    found = run_events(ds)
    mbr = minimum_bend_radius_of(ds)

    def label(name):
        extra = f" ({mbr:g} m)" if name == "bend_radius_below_mbr" and mbr else ""
        return event_label(name) + extra

    happened = [f"{label(k)} at {t[i]:.4g} s" for k, i in found.items() if i is not None]
    missed = [label(k) for k, i in found.items() if i is None]
    text = ", ".join(happened) if happened else "none happened"
    return text + (f"; did not happen: {', '.join(missed)}" if missed else "")


def _in_time_order(events: dict[str, int | None]) -> dict[str, int | None]:
    """``events`` ordered by output index (the order they happened in), those that did not
    happen last, each group otherwise in its given order."""
    happened = sorted((k for k, i in events.items() if i is not None), key=lambda k: events[k])
    return {**{k: events[k] for k in happened},
            **{k: i for k, i in events.items() if i is None}}


#: the result variables a start from an earlier result needs
START_VARIABLES = ("v", "omega", "f", "kappa", "position", "orientation")


def start_state_from(ds, case, source: str, field: str = "file"):
    """The start state ``case.initial.from_result`` names, read from an earlier result.

    Its v, ω, f, κ, position and orientation at the output time ``from_result.time``, the
    end rotations (from its linking number) and ``work_in`` where it has them.

    Parameters
    ----------
    ds : xarray.Dataset
        The earlier result, as :func:`build_dataset` writes it, opened by the caller (a
        file in :mod:`hockle.io`, a job's result in the service).
    case : solver.Case
        The case to start.
    source : str
        Names the result in messages (a path, a job id).
    field : str
        Where it was given: ``"file"`` or ``"job"``.

    Returns
    -------
    solver.initial.StartState

    Raises
    ------
    solver.CaseError
        Naming ``initial.from_result.<field>`` (not a hockle result, another rod: its
        case's ``rod`` or ``numerics.n_segments`` differ, a variable missing) or
        ``initial.from_result.time`` (not one of its output times).
    """
    import math

    from .case import Case, CaseError
    from .initial import StartState

    spec = case.initial.from_result

    def fail(where, etype, msg):
        return CaseError([{"loc": f"initial.from_result.{where}", "msg": msg, "type": etype}])

    try:
        earlier = Case.model_validate_json(ds.attrs["case"])
    except Exception:                                   # noqa: BLE001 - any reason: not ours
        raise fail(field, "not_a_result",
                   f"{source} is not a hockle result (no valid case attribute)") from None
    if (earlier.rod != case.rod
            or earlier.numerics.n_segments != case.numerics.n_segments):
        raise fail(field, "another_rod",
                   f"{source} is a result of another rod (its rod or n_segments "
                   "differ from this case's)")
    missing = [name for name in START_VARIABLES if name not in ds.data_vars]
    if missing:
        raise fail(field, "missing_variable",
                   f"{source} lacks {', '.join(missing)}: run it with output.fields "
                   f"including {', '.join(START_VARIABLES)}")
    times = np.asarray(ds["time"].values, float)
    hit = np.flatnonzero(np.abs(times - spec.time) <= 1e-9 * max(1.0, abs(spec.time)))
    if hit.size == 0:
        raise fail("time", "out_of_range",
                   f"{spec.time!r} s is not an output time of {source} (it has "
                   f"{times.size} from {times.min():.6g} to {times.max():.6g} s)")
    k = int(hit[-1])

    def at(name, dims):
        return np.ascontiguousarray(ds[name].transpose("time", *dims).values[k], dtype=float)

    phi = None
    if "linking_number" in ds.data_vars:
        phi = np.array([0.0, 2.0 * math.pi * float(ds["linking_number"].values[k])])
    work = float(ds["work_in"].values[k]) if "work_in" in ds.data_vars else None
    return StartState(t=float(times[k]), v=at("v", ("s", "component")),
                      omega=at("omega", ("s", "component")), f=at("f", ("s", "component")),
                      kappa=at("kappa", ("s", "component")),
                      q=at("orientation", ("s", "quaternion")),
                      r=at("position", ("s", "xyz")), phi=phi, work_in=work)
