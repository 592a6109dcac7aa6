"""The result dataset: solver arrays -> a self-describing :class:`xarray.Dataset`.

Pure: builds the dataset in memory and does no file I/O (writing is
:func:`hockle.io.write_netcdf`). The layout is the outside contract of DESIGN.md
("Result dataset") and the seam of docs/interfaces.md (``solver.results``).

Dimensions
----------
``time``        output instants, s (every ``case.output.every``-th accepted step, and t0)
``s``           arclength of the grid points along the centreline, m
``component``   body-frame component 1, 2, 3 (directors a1, a2, a3; a3 the tangent)
``xyz``         global-frame axis "x", "y", "z" (e1, e2, e3)
``quaternion``  quaternion component "w", "x", "y", "z" (scalar first)
``step``        every accepted solver step 1..K (diagnostics), with ``step_time``

Every variable carries ``units`` (UDUNITS-2 strings) and ``long_name``. No quantity here
has a CF standard name (the CF table has none for rod strain resultants, body-frame
velocities, strain energies, twist or writhe, and ``time`` is elapsed simulation time in
"s", not a "units since epoch" time coordinate), so no ``standard_name`` is set.

Global attributes follow CF-1.12 and ACDD-1.3 and hold the canonical case spec, so a
file alone reproduces its run.
"""
from __future__ import annotations

import datetime as _dt
from collections.abc import Mapping
from typing import Any

import numpy as np
import xarray as xr

__all__ = [
    "build_dataset",
    "FIELD_VARIABLES",
    "DIAGNOSTIC_VARIABLES",
    "STATUSES",
    "REFERENCES",
]

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
        "kinetic energy of the rod including the entrained (added) fluid mass",
        None,
    ),
    "energy_kinetic_fluid": (
        ("time",),
        "J",
        "added-mass share of the kinetic energy",
        "part of energy_kinetic carried by the entrained fluid; zero in vacuum",
    ),
    "energy_total": (
        ("time",),
        "J",
        "total mechanical energy of the rod (strain plus kinetic)",
        None,
    ),
    "work_in": (
        ("time",),
        "J",
        "cumulative work put in at the rod ends",
        "time integral of power_in from the start of the run",
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
    "contact_count": (("time",), "1", "number of self-contact pairs", None),
    "min_surface_gap": (("time",), "m", "smallest surface gap among self-contact pairs", None),
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
}

_INTEGER_VARIABLES = {"contact_count", "newton_iterations", "step_newton_iterations"}

_COMPRESSED = {"dtype": "float64", "zlib": True, "complevel": 4, "shuffle": True}


def _utc_now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()


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
    parts = [
        "Nonlinear dynamics of a twisted elastic rod (dynamic Kirchhoff rod of Goyal, "
        "Perkins & Lee, generalized-alpha scheme in space and time"
    ]
    if getattr(case, "contact", None) is not None:
        parts.append(", with self-contact")
    if getattr(case, "fluid", None) is not None:
        parts.append(", in a fluid (added mass and Morison drag)")
    parts.append(f"): {n_points} grid points")
    if times.size:
        parts.append(f", simulation time {times[0]:g} s to {times[-1]:g} s")
    t_end = getattr(getattr(case, "numerics", None), "t_end", None)
    if t_end is not None:
        parts.append(f" of {float(t_end):g} s")
    parts.append(f"; run {status}.")
    return "".join(parts)


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
        ``contact_count``: (T,); ``min_surface_gap``: (T,) m; ``newton_iterations
        residual_norm quaternion_norm_error``: (T,); ``dt``: (T,) s;
        ``position_route_difference``: (T,) m.
    diagnostics:
        Per accepted step, all of length K: ``step_time`` (s), ``step_dt`` (s),
        ``step_newton_iterations``, ``step_residual_norm``. An empty mapping adds no
        ``step`` dimension.
    status:
        ``"completed"``, ``"stopped"`` or ``"failed"`` (global attribute
        ``hockle_status``).
    message:
        Free text for the global attribute ``hockle_message`` (e.g. why a run stopped).
    attrs:
        Extra global attributes (e.g. ``hockle_stop_reason``); strings or numbers.

    Returns
    -------
    xarray.Dataset
        float64 data; (time, s, ...) variables carry zlib level-4 compression in their
        ``encoding`` so that ``to_netcdf`` applies it.
    """
    from solver import __version__

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

    n_t, n_s = times.size, s.size
    sizes = {"time": n_t, "s": n_s, "component": 3, "xyz": 3, "quaternion": 4}

    coords: dict[str, xr.Variable] = {
        "time": xr.Variable(
            "time",
            times,
            {"units": "s", "long_name": "simulation time (elapsed from the start of the run)"},
        ),
        "s": xr.Variable(
            "s",
            s,
            {
                "units": "m",
                "long_name": "arclength along the rod centreline from the start end",
                "comment": "s = 0 is the start end, s = L the far end",
            },
        ),
        "component": xr.Variable(
            "component",
            np.array([1, 2, 3], dtype=np.int32),
            {
                "units": "1",
                "long_name": "body-frame component (directors a1, a2, a3; a3 the tangent)",
            },
        ),
        "xyz": xr.Variable(
            "xyz", np.array(["x", "y", "z"]), {"long_name": "global-frame axis (e1, e2, e3)"}
        ),
        "quaternion": xr.Variable(
            "quaternion",
            np.array(["w", "x", "y", "z"]),
            {"long_name": "unit quaternion component, scalar first"},
        ),
    }
    for name in ("time", "s", "component"):
        coords[name].encoding = {"_FillValue": None}

    data_vars: dict[str, xr.Variable] = {}
    for name, values in fields.items():
        dims, units, long_name, comment = FIELD_VARIABLES[name]
        arr = _as_values(name, values, tuple(sizes[d] for d in dims))
        var_attrs = {"units": units, "long_name": long_name}
        if comment:
            var_attrs["comment"] = comment
        var = xr.Variable(dims, arr, var_attrs)
        var.encoding = _encoding(arr, dims)
        data_vars[name] = var

    if diagnostics:
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
            {"units": "1", "long_name": "accepted solver step number"},
        )
        coords["step"].encoding = {"_FillValue": None}
        for name, values in diagnostics.items():
            units, long_name = DIAGNOSTIC_VARIABLES[name]
            arr = _as_values(name, values, (n_steps,))
            var = xr.Variable(("step",), arr, {"units": units, "long_name": long_name})
            var.encoding = _encoding(arr, ("step",))
            if name == "step_time":
                coords[name] = var  # coordinate-like: the time axis of the step dimension
            else:
                data_vars[name] = var

    now = _utc_now()
    global_attrs: dict[str, Any] = {
        "Conventions": "CF-1.12 ACDD-1.3",
        "title": str(case.name),
        "summary": _summary(case, n_s, times, status),
        "source": f"hockle {__version__}",
        "history": f"{now} created by hockle {__version__}",
        "references": REFERENCES,
        "case": case.canonical_json(),
        "case_hash": case.spec_hash(),
        "date_created": now,
        "hockle_status": status,
        "hockle_message": str(message),
    }
    for key, value in (attrs or {}).items():
        if isinstance(value, bool) or not isinstance(value, (str, int, float)):
            raise ValueError(f"attribute {key!r}: expected a string or number, got {value!r}")
        global_attrs[key] = value

    return xr.Dataset(data_vars=data_vars, coords=coords, attrs=global_attrs)
