"""hockle's Python API for in-process runs: callbacks, custom loads, case builders, sweeps.

For users who know PyElastica's ``CallBackBaseClass`` and external forcing: build a case
with the case spec's own pydantic models (and :func:`clamped`, :func:`twisted`,
:func:`sliding`, ... for the usual ends), watch or steer a run with callbacks at a cadence,
add distributed loads written as Python functions, and run sweeps on the local cores::

    from hockle.api import (Callback, Recorder, simulate, sweep, make_case, clamped,
                            twisted, sliding)
    case = make_case("twist", start=twisted(2.0), end=sliding(tension=0.5),
                     n_segments=50, dt=0.05, t_end=20.0)
    rec = Recorder(["position", "writhe"], interval=1.0)        # every simulated second
    stop = Callback.when(lambda st: st.writhe > 1.0, reason="writhe above one turn")
    ds = simulate(case, callbacks=[rec, stop])                  # the result dataset
    grid = sweep(case, {"boundary.end.translation.2.force": [0.1, 0.5, 1.0]})

:func:`simulate` is :func:`solver.simulate` with its ``observer`` hook (the callbacks) and
its ``extra_force`` hook (the loads): the same time loop, steps, outputs, checkpoints and
result dataset.
"""
from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "State",
    "Callback",
    "Recorder",
    "DistributedLoad",
    "simulate",
    "sweep",
    "equilibrium",
    "equilibrium_start",
    "continue_branch",
    "branch_key",
    "make_case",
    "clamped",
    "free",
    "pinned",
    "twisted",
    "sliding",
    "end",
    "ramp",
    "switch",
    "circular_arc",
    "helix",
    "catenary",
    "catenary_parameter",
]


# --------------------------------------------------------------------------- the state


class State:
    """The rod at one accepted step, as a callback (or a state-aware load) sees it.

    ``t`` (s), ``step`` (accepted steps so far; 0 at the start), ``dt`` (s, the last step),
    ``s`` (m, the grid). The fields are computed when first read and are copies (changing
    them changes nothing in the run): ``position`` (N+1, 3) m, global; ``v``, ``omega``,
    ``f``, ``kappa``, ``moment`` (N+1, 3) body frame; ``orientation`` (N+1, 4) unit
    quaternions; ``twist``, ``writhe``, ``linking_number`` (turns; the writhe costs
    O(N²)); ``energies`` (a dict of J); ``contact_count``, ``min_surface_gap`` (m);
    ``bend_radius_min``, ``bend_radius_min_s`` (m). ``get(*groups)`` returns the output field groups of the result dataset as a dict.
    ``run`` is the :class:`solver.simulation.RodRun` itself, for experts: read it, do not
    change it.
    """

    _GROUPS = {"v": "v", "omega": "omega", "f": "f", "kappa": "kappa", "moment": "moment",
               "position": "position", "orientation": "orientation", "twist": "topology",
               "writhe": "topology", "linking_number": "topology", "contact_count": "contact",
               "min_surface_gap": "contact", "bend_radius_min": "bend_radius",
               "bend_radius_min_s": "bend_radius"}

    def __init__(self, run, step: int):
        self.run = run
        self.t = float(run.t)
        self.step = int(step)
        self.dt = float(run.last_dt)
        self.s = run.props.s
        self._cache: dict[str, Any] = {}

    def get(self, *groups: str) -> dict[str, Any]:
        """The result dataset's quantities of these output field groups (``position``,
        ``energies``, ``topology``, ``contact``, ...) at this state."""
        missing = [g for g in groups if g not in self._cache]
        if missing:
            snap = self.run.snapshot(set(missing))
            for g in missing:
                self._cache[g] = snap
        out: dict[str, Any] = {}
        for g in groups:
            out.update(self._cache[g])
        return out

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        if name == "energies":
            snap = self.get("energies")
            return {k: v for k, v in snap.items()
                    if k.startswith("energy_") or k in ("work_in", "power_in")}
        group = State._GROUPS.get(name)
        if group is None:
            raise AttributeError(f"State has no {name!r}; fields: "
                                 f"{', '.join(sorted(State._GROUPS))}, energies")
        return self.get(group)[name]

    def __repr__(self) -> str:
        return f"State(t={self.t:.6g} s, step={self.step})"


# --------------------------------------------------------------------------- callbacks


class Callback:
    """An observer called with the :class:`State` at a cadence; it may stop the run.

    Subclass and override :meth:`__call__`, or wrap a function: ``Callback(func,
    every=10)``. ``every``: every that many accepted steps; ``interval``: at the first
    accepted step at or after each multiple of that many simulated seconds; neither: every
    accepted step. Every callback is also called once at t = 0 (step 0). Returning ``True``
    or a non-empty string stops the run at once (any other value is ignored): ``simulate``
    returns the dataset up to there with ``hockle_status = "stopped"`` and
    ``hockle_stop_reason`` the string (or ``"callback"``). As in PyElastica, ``every`` is its ``step_skip``.
    """

    def __init__(self, func: Callable[[State], Any] | None = None, *, every: int | None = None,
                 interval: float | None = None, name: str | None = None):
        if every is not None and interval is not None:
            raise ValueError("Callback: give every (steps) or interval (simulated seconds), "
                             "not both")
        if every is not None and (int(every) != every or every < 1):
            raise ValueError(f"Callback.every must be a whole number of steps >= 1, got {every!r}")
        if interval is not None and not (interval > 0 and math.isfinite(interval)):
            raise ValueError(f"Callback.interval must be a positive number of seconds, got "
                             f"{interval!r}")
        self.func = func
        self.every = int(every) if every is not None else (None if interval else 1)
        self.interval = float(interval) if interval is not None else None
        self.name = name or getattr(func, "__name__", None) or type(self).__name__
        self._next_t = 0.0

    def __call__(self, state: State) -> Any:
        """Observe ``state``; return ``True`` or a reason string to stop the run."""
        if self.func is None:
            raise NotImplementedError("override Callback.__call__ or pass a function")
        return self.func(state)

    @classmethod
    def when(cls, predicate: Callable[[State], Any], *, reason: str = "stop condition met",
             every: int | None = None, interval: float | None = None) -> "Callback":
        """A callback that stops the run when ``predicate(state)`` is true, with ``reason``."""
        def check(state: State):
            return reason if predicate(state) else None
        return cls(check, every=every, interval=interval, name=f"when({reason})")

    # the cadence --------------------------------------------------------------------
    def _start(self) -> None:
        self._next_t = self.interval if self.interval else 0.0

    def _due(self, state: State) -> bool:
        if state.step == 0:
            return True
        if self.interval is not None:
            tol = 1e-9 * max(self.interval, abs(state.t))
            if state.t >= self._next_t - tol:
                self._next_t = (math.floor((state.t + tol) / self.interval) + 1) * self.interval
                return True
            return False
        return state.step % self.every == 0


class Recorder(Callback):
    """A callback that keeps quantities of the state: ``times`` (s), ``steps`` and
    ``data[name]`` (a list per name, e.g. ``position``, ``writhe``, ``energy_total``);
    :meth:`arrays` stacks them. ``names``: any attribute of :class:`State` or key of its
    ``energies``."""

    def __init__(self, names: Iterable[str] = ("position",), *, every: int | None = None,
                 interval: float | None = None):
        super().__init__(None, every=every, interval=interval, name="Recorder")
        self.names = list(names)
        self.times: list[float] = []
        self.steps: list[int] = []
        self.data: dict[str, list] = {n: [] for n in self.names}

    def __call__(self, state: State) -> None:
        self.times.append(state.t)
        self.steps.append(state.step)
        energies = None
        for n in self.names:
            if n.startswith("energy_") or n in ("work_in", "power_in"):
                energies = energies if energies is not None else state.energies
                self.data[n].append(energies[n])
            else:
                self.data[n].append(getattr(state, n))
        return None

    def arrays(self) -> dict[str, np.ndarray]:
        """``{"time": (K,), name: (K, ...)}``."""
        out = {"time": np.asarray(self.times)}
        out.update({n: np.asarray(v) for n, v in self.data.items()})
        return out


def _as_callback(cb: Any) -> Callback:
    if isinstance(cb, Callback):
        return cb
    if callable(cb):
        return Callback(cb)
    raise TypeError(f"a callback is a hockle.api.Callback or a function of the state, got "
                    f"{type(cb).__name__}")


# --------------------------------------------------------------------------- custom loads


class DistributedLoad:
    """A distributed force per unit length written as a Python function (in-process runs
    only; the service takes data, never code).

    ``func(t, s)`` returns the force in N/m, **global frame**, at time ``t`` (s) on the grid
    ``s`` (m, (N+1,)): an (N+1, 3) array or one 3-vector for the whole rod. With
    ``uses_state=True`` it is ``func(t, s, state)`` with the :class:`State` of the last
    accepted step: the load is then explicit in the state (lagged by one step; Newton sees
    it as constant within a step), fine for slowly varying loads, not for stiff ones.

    The solver assembles global-frame distributed forces as it does the case's
    ``distributed_forces`` (work and power included), and asks for them at every Newton
    iteration at the new time level. It does not know where the load changes suddenly:
    steps do not land on a jump of ``func`` (write the case's own ``distributed_forces``
    for windows in time).
    """

    def __init__(self, func: Callable[..., Any], *, uses_state: bool = False,
                 name: str | None = None):
        if not callable(func):
            raise TypeError(f"DistributedLoad needs a function, got {type(func).__name__}")
        self.func = func
        self.uses_state = bool(uses_state)
        self.name = name or getattr(func, "__name__", "load")

    def evaluate(self, t: float, s: np.ndarray, state: State | None) -> np.ndarray:
        """The load on the grid, (N+1, 3) N/m; raises ValueError naming the load for a
        wrong shape or a non-finite value."""
        value = self.func(t, s, state) if self.uses_state else self.func(t, s)
        arr = np.asarray(value, dtype=float)
        if arr.shape == (3,):
            arr = np.broadcast_to(arr, (s.size, 3))
        if arr.shape != (s.size, 3):
            raise ValueError(f"distributed load {self.name!r} returned shape {arr.shape} at "
                             f"t = {t:g} s; expected (3,) or ({s.size}, 3) N/m, global frame")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"distributed load {self.name!r} returned a non-finite value at "
                             f"t = {t:g} s")
        return arr


# a force on the rod that the case never had, so that the run assembles global-frame
# distributed loads (needs_pose, the work of distributed forces); removed at once
class _LoadSum:
    """The ``extra_force`` hook of :func:`solver.simulate`: the sum of the user's loads at
    time t, with the :class:`State` of the run's last accepted step for state-aware ones."""

    def __init__(self, loads: Sequence["DistributedLoad"]):
        self.loads = list(loads)
        self.uses_state = any(load.uses_state for load in self.loads)

    def __call__(self, t: float, run) -> np.ndarray | None:
        state = State(run, -1) if self.uses_state else None
        out = None
        for load in self.loads:
            extra = load.evaluate(float(t), run.props.s, state)
            out = extra.copy() if out is None else out + extra
        return out


class _CallbackSet:
    """The ``observer`` hook of :func:`solver.simulate`: the callbacks that are due, in
    order; the first that asks to stop stops the run (with its reason)."""

    def __init__(self, callbacks: Sequence["Callback"]):
        self.callbacks = list(callbacks)
        for cb in self.callbacks:
            cb._start()

    def __call__(self, run, step: int):
        state = None
        for cb in self.callbacks:
            state = state or State(run, step)
            if cb._due(state):
                flag = cb(state)
                if flag is True or (isinstance(flag, str) and flag):
                    return flag if isinstance(flag, str) else "callback"
        return None


def _as_load(load: Any) -> DistributedLoad:
    if isinstance(load, DistributedLoad):
        return load
    if callable(load):
        return DistributedLoad(load)
    raise TypeError(f"a load is a hockle.api.DistributedLoad or a function (t, s) -> N/m, "
                    f"got {type(load).__name__}")


# --------------------------------------------------------------------------- simulate


def _as_case(case: Any):
    from solver.case import Case

    if isinstance(case, Case):
        return case
    if isinstance(case, Mapping):
        return Case.model_validate(dict(case))
    if isinstance(case, (str, os.PathLike)):
        return Case.from_file(case)
    raise TypeError(f"a case is a solver.case.Case, a mapping or a case file, got "
                    f"{type(case).__name__}")


def simulate(case, callbacks: Iterable[Any] = (), loads: Iterable[Any] = (),
             progress: Callable | None = None, should_stop: Callable | None = None,
             **solver_options: Any):
    """Run ``case`` (a ``Case``, a mapping or a case file) in this process and return the
    result dataset (docs/interfaces.md).

    ``callbacks``: :class:`Callback` objects or functions of the :class:`State` (every
    step), called at their cadence after accepted steps and once at t = 0; returning ``True``
    or a reason string stops the run (``hockle_status = "stopped"``, ``hockle_stop_reason``
    its string). ``loads``: :class:`DistributedLoad` objects or functions ``(t, s) -> N/m``
    (global frame) added to the case's distributed forces; the dataset then has
    ``hockle_custom_loads`` naming them (its ``case`` alone no longer reproduces the run).
    ``progress``, ``should_stop`` and the other options (``checkpoint``,
    ``checkpoint_interval``, ``resume``) are :func:`solver.simulate`'s; with loads a
    checkpoint needs picklable (module-level) load functions. Raises ``SolverDivergence``
    (with ``.partial``) as :func:`solver.simulate` does.
    """
    from solver.simulation import simulate as solver_simulate

    case = _as_case(case)
    callbacks = [_as_callback(c) for c in callbacks]
    loads = [_as_load(load) for load in loads]
    for key in ("observer", "extra_force"):
        if key in solver_options:
            raise ValueError(f"{key}: given by hockle.api.simulate itself (use callbacks= "
                             "and loads=)")
    if (case.initial.from_result is not None and "start" not in solver_options
            and solver_options.get("resume") is None):
        from .io import read_start_state
        solver_options["start"] = read_start_state(case)    # CaseError naming the field
    ds = solver_simulate(case, progress=progress, should_stop=should_stop,
                         observer=_CallbackSet(callbacks) if callbacks else None,
                         extra_force=_LoadSum(loads) if loads else None, **solver_options)
    if loads:
        ds.attrs["hockle_custom_loads"] = ", ".join(load.name for load in loads)
    return ds


# --------------------------------------------------------------------------- case builders


def _dof(key: str, value: Any) -> dict:
    return {key: value}


def clamped() -> dict:
    """An end held in place and in orientation: every velocity and angular velocity 0."""
    return {"translation": [_dof("velocity", 0.0) for _ in range(3)],
            "rotation": [_dof("angular_velocity", 0.0) for _ in range(3)]}


def free() -> dict:
    """A free end: no force, no moment."""
    return {"translation": [_dof("force", 0.0) for _ in range(3)],
            "rotation": [_dof("moment", 0.0) for _ in range(3)]}


def pinned() -> dict:
    """An end held in place but free to turn (a ball joint): velocities 0, moments 0."""
    return {"translation": [_dof("velocity", 0.0) for _ in range(3)],
            "rotation": [_dof("moment", 0.0) for _ in range(3)]}


def twisted(rate: Any, *, ramp_time: float | None = None) -> dict:
    """A clamped end turned about the rod's axis at ``rate`` rad/s (a number or a
    :func:`ramp` table); ``ramp_time`` (s): from 0 to ``rate`` linearly over that time."""
    if ramp_time is not None:
        rate = ramp([0.0, float(ramp_time)], [0.0, float(rate)])
    out = clamped()
    out["rotation"][2] = _dof("angular_velocity", rate)
    return out


def sliding(tension: Any = 0.0, *, held_after: float | None = None) -> dict:
    """An end held sideways and in orientation that slides along the rod's axis under an
    axial force ``tension`` (N, > 0 pulls; a number or a :func:`ramp` table);
    ``held_after`` (s): held in place from then on (the seed example's end at 30 s)."""
    out = clamped()
    axial: Any = _dof("force", tension)
    if held_after is not None:
        axial = switch((_dof("force", tension), held_after), _dof("velocity", 0.0))
    out["translation"][2] = axial
    return out


def end(translation: Sequence[Any], rotation: Sequence[Any]) -> dict:
    """Any end: three translation items (``{"velocity": v}`` or ``{"force": f}``) and three
    rotation items (``{"angular_velocity": w}`` or ``{"moment": m}``), body frame; an item
    may be a :func:`switch`."""
    if len(translation) != 3 or len(rotation) != 3:
        raise ValueError("end() needs 3 translation and 3 rotation items (body-frame "
                         "components a1, a2, a3)")
    return {"translation": list(translation), "rotation": list(rotation)}


def ramp(t: Sequence[float], value: Sequence[float]) -> dict:
    """A table in time, piecewise linear, held outside: ``{"t": [...], "value": [...]}``."""
    return {"t": [float(x) for x in t], "value": [float(x) for x in value]}


def switch(*items: Any) -> list[dict]:
    """One DOF switching in time: ``switch(({"force": 0}, 30.0), {"velocity": 0})`` is the
    force until t = 30 s, then the velocity (every item but the last is ``(condition,
    until)``)."""
    out = []
    for k, item in enumerate(items):
        if k < len(items) - 1:
            cond, until = item
            out.append({**cond, "until": float(until)})
        else:
            out.append(dict(item))
    return out


def make_case(name: str, *, start: Any, end: Any, n_segments: int, dt: float, t_end: float,
              length: float = 1.0, youngs_modulus: Any = 1.25e7, shear_modulus: Any = 5.0e6,
              density: Any = 1500.0, diameter: Any = 0.02, **sections: Any):
    """A validated ``Case`` from the usual few numbers (defaults: the seed paper's cable,
    1 m, E 12.5 MPa, G 5 MPa, 1500 kg/m³, 2 cm) and two ends (:func:`clamped`,
    :func:`twisted`, ``EndCondition`` models or mappings). ``sections`` are the case's
    other top-level fields, mappings or their models: ``fluid``, ``gravity``,
    ``distributed_forces``, ``contact``, ``initial``, ``output``, and ``numerics`` (merged
    over n_segments, dt, t_end). Raises ``pydantic.ValidationError`` naming the field."""
    from solver.case import Case

    def plain(x: Any) -> Any:
        return x.model_dump(mode="json") if hasattr(x, "model_dump") else x

    numerics = {"n_segments": n_segments, "dt": dt, "t_end": t_end,
                **(plain(sections.pop("numerics", None)) or {})}
    doc = {"schema_version": 1, "name": name,
           "rod": {"length": length, "youngs_modulus": plain(youngs_modulus),
                   "shear_modulus": plain(shear_modulus), "density": plain(density),
                   "diameter": plain(diameter)},
           "boundary": {"start": plain(start), "end": plain(end)},
           "numerics": numerics}
    doc.update({k: plain(v) for k, v in sections.items()})
    return Case.model_validate(doc)


# --------------------------------------------------------------------------- initial shapes


def _centreline(points: np.ndarray) -> dict:
    return {"points": [[float(x) for x in p] for p in points]}


def circular_arc(length: float, radius: float, *, n_points: int = 401) -> dict:
    """An ``initial.centreline`` along a circular arc of ``length`` m and ``radius`` m
    from the origin, starting along +z and bending towards +x (in the x-z plane):
    r(s) = (R(1 − cos(s/R)), 0, R sin(s/R)), sampled at ``n_points`` equal arclengths.
    Use it as ``initial={"centreline": circular_arc(1.0, 0.5)}``; κ2 = 1/R with the
    start's a1 along +x. Raises ValueError for a non-positive length or radius."""
    if not (length > 0 and radius > 0):
        raise ValueError("circular_arc: length and radius must be > 0 (m)")
    phi = np.linspace(0.0, length / radius, int(n_points))
    return _centreline(np.stack([radius * (1.0 - np.cos(phi)), np.zeros_like(phi),
                                 radius * np.sin(phi)], axis=1))


def helix(length: float, radius: float, pitch: float, *, n_points: int = 1001) -> dict:
    """An ``initial.centreline`` along a circular helix about the axis x = −radius, y = 0
    (parallel to z) from the origin: r(θ) = (R cos θ − R, R sin θ, pθ/(2π)), θ from 0 to
    length/√(R² + (p/2π)²), sampled at ``n_points`` equal arclengths; right-handed for
    ``pitch`` > 0 (m per turn), left-handed for < 0. Its curvature is R/(R² + h²) and its
    torsion h/(R² + h²) with h = p/(2π) (m); with ``twist_rate`` equal to the torsion the
    rod's κ is constant along it (its frame turns with the Frenet frame). Raises
    ValueError for a non-positive length or radius."""
    if not (length > 0 and radius > 0):
        raise ValueError("helix: length and radius must be > 0 (m)")
    h = pitch / (2.0 * math.pi)
    theta = np.linspace(0.0, length / math.hypot(radius, h), int(n_points))
    return _centreline(np.stack([radius * (np.cos(theta) - 1.0), radius * np.sin(theta),
                                 h * theta], axis=1))


def catenary_parameter(length: float, span: float) -> float:
    """The catenary's a = H/w (m) of a cable of ``length`` hanging between two points at
    the same height ``span`` apart (span < length): the root of 2a sinh(span/(2a)) =
    length (scipy's brentq). Raises ValueError unless 0 < span < length."""
    from scipy.optimize import brentq

    if not 0 < span < length:
        raise ValueError("catenary: needs 0 < span < length (m)")
    g = lambda a: 2.0 * a * math.sinh(min(span / (2.0 * a), 700.0)) - length  # noqa: E731
    lo = span / 1400.0
    hi = span
    while g(hi) > 0:
        hi *= 2.0
    return brentq(g, lo, hi, xtol=1e-15 * span, rtol=4 * np.finfo(float).eps)


def catenary(length: float, span: float, *, n_points: int = 401) -> dict:
    """An ``initial.centreline`` along the catenary of a cable of ``length`` m hanging
    under gravity (−z) between the origin and (span, 0, 0): z = a(cosh((x − X/2)/a) −
    cosh(X/(2a))) with a from :func:`catenary_parameter`, sampled at ``n_points`` equal
    arclengths (x = X/2 + a asinh((s − L/2)/a)). Its sag is a(cosh(X/(2a)) − 1).
    Raises ValueError unless 0 < span < length."""
    a = catenary_parameter(length, span)
    s = np.linspace(0.0, length, int(n_points))
    x = 0.5 * span + a * np.arcsinh((s - 0.5 * length) / a)
    z = a * (np.cosh((x - 0.5 * span) / a) - math.cosh(0.5 * span / a))
    x[0], x[-1], z[0], z[-1] = 0.0, span, 0.0, 0.0
    return _centreline(np.stack([x, np.zeros_like(x), z], axis=1))


# --------------------------------------------------------------------------- local sweeps


def _run_member(case_json: str, out_path: str) -> tuple[str, str]:
    """Run one member in this process, write its dataset (partial ones too) to
    ``out_path``; returns (state, message) in the job states' vocabulary."""
    from hockle.io import write_netcdf
    from solver.case import Case
    from solver.simulation import SolverDivergence
    from solver.simulation import simulate as solver_simulate

    case = Case.model_validate_json(case_json)
    try:
        ds = solver_simulate(case)
    except SolverDivergence as exc:
        if exc.partial is not None:
            write_netcdf(exc.partial, out_path)
        return "failed", f"{exc.reason}: {exc}"
    write_netcdf(ds, out_path)
    if ds.attrs.get("hockle_status") == "completed":
        # a completed run's warning (hockle_warning), as a service job's message
        return "successful", str(ds.attrs.get("hockle_warning", ""))
    return "failed", str(ds.attrs.get("hockle_message") or ds.attrs.get("hockle_stop_reason"))


def sweep(base: Any, parameters: Mapping[str, Sequence[Any]], combine: str = "grid", *,
          workers: int | None = None, fields: Sequence[str] = (),
          on_member: Callable[[int, int, int, str], None] | None = None):
    """Run a parameter sweep on this machine and return the combined dataset (the same
    :func:`service.sweeps.combine_results` as ``GET /v1/sweeps/{id}/results``).

    ``base``: a ``Case``, mapping or case file; ``parameters``: ``{PATH: [values]}``
    (docs/service.md, sweeps); ``combine``: ``"grid"`` or ``"zip"``. Every member is
    validated first (``service.sweeps.SweepError`` names each bad one). Members run in
    ``workers`` processes (default: as many as cores; 1: in this process); identical
    member cases run once. A member that fails is marked in ``member_status``, not fatal.
    ``on_member(done, total, index, state)`` is called as members finish.
    """
    from service import sweeps as sw

    if isinstance(base, (str, os.PathLike)):
        from solver.case import parse_text

        path = Path(base)
        doc = parse_text(path.read_bytes(), path.suffix, str(path))
    elif hasattr(base, "model_dump"):
        doc = base.model_dump(mode="json")
    else:
        doc = dict(base)
    params = sw.normalize_parameters(parameters)
    members = sw.expand(doc, params, combine)
    cases = sw.validate_members(members)
    unique: dict[str, str] = {}
    key_of = []
    for case in cases:
        key = case.spec_hash()
        unique.setdefault(key, case.canonical_json())
        key_of.append(key)
    workers = max(1, int(workers or os.cpu_count() or 1))
    outcome: dict[str, tuple[str, str]] = {}
    with tempfile.TemporaryDirectory(prefix="hockle-sweep-") as tmp:
        paths = {key: os.path.join(tmp, f"{n}.nc") for n, key in enumerate(unique)}
        done = 0

        def report(key):
            nonlocal done
            done += 1
            if on_member is not None:
                first = key_of.index(key)
                on_member(done, len(unique), first, outcome[key][0])

        if workers == 1 or len(unique) == 1:
            for key, text in unique.items():
                outcome[key] = _run_member(text, paths[key])
                report(key)
        else:
            from concurrent.futures import ProcessPoolExecutor, as_completed

            with ProcessPoolExecutor(max_workers=min(workers, len(unique))) as pool:
                futures = {pool.submit(_run_member, text, paths[key]): key
                           for key, text in unique.items()}
                for fut in as_completed(futures):
                    key = futures[fut]
                    try:
                        outcome[key] = fut.result()
                    except Exception as exc:  # noqa: BLE001 - a member, not the sweep
                        outcome[key] = ("failed", f"internal_error: {type(exc).__name__}: {exc}")
                    report(key)
        from hockle.io import open_result

        datasets = {key: open_result(p) if os.path.exists(p) else None
                    for key, p in paths.items()}
    results = [sw.MemberResult(index=m.index, values=m.values, state=outcome[k][0],
                               dataset=datasets[k], message=outcome[k][1])
               for m, k in zip(members, key_of)]
    return sw.combine_results(results, params, combine, fields=fields,
                              attrs={"hockle_sweep_name": doc.get("name")})


# --------------------------------------------------------------------------- statics


def _case_scalar(doc: dict, path: str) -> float:
    """The number at ``path`` in the case document; ValueError naming the path when the
    path does not lead to a number (a one-item list of conditions is looked through, as
    :func:`service.sweeps.set_path` does)."""
    from service.sweeps import parse_path

    node: Any = doc
    for part in parse_path(path):
        if isinstance(node, list) and isinstance(part, str) and len(node) == 1:
            node = node[0]
        try:
            node = node[part]
        except (KeyError, IndexError, TypeError):
            raise ValueError(f"--parameter {path}: not a field of the case (no {part!r} "
                             "there)") from None
    if isinstance(node, bool) or not isinstance(node, (int, float)):
        raise ValueError(f"--parameter {path}: not a scalar of the case (the value there is "
                         f"{type(node).__name__} {str(node)[:60]})")
    return float(node)


def _problem_family(case: Any, parameter: str, time: float | None):
    """(λ -> StaticProblem, the case's value at ``parameter``)."""
    from service.client import case_document
    from service.sweeps import SweepError, set_path
    from solver.case import Case, CaseError
    from solver.statics import static_problem

    doc = case_document(case) if not isinstance(case, (str, os.PathLike)) else \
        _as_case(case).model_dump(mode="json")
    lam0 = _case_scalar(doc, parameter)

    def problem_at(lam: float):
        d = _copy_doc(doc)
        try:
            set_path(d, parameter, float(lam))
        except SweepError as exc:
            raise ValueError(f"--parameter {parameter}: {exc.errors[0]['msg']}") from exc
        try:
            c = Case.model_validate(d)
        except (CaseError, ValueError) as exc:
            raise ValueError(f"{parameter} = {lam!r} makes the case invalid: {exc}") from exc
        return static_problem(c, time)

    return problem_at, lam0


def _copy_doc(doc: dict) -> dict:
    import copy

    return copy.deepcopy(doc)


def equilibrium(case: Any, *, time: float | None = None):
    """The static equilibrium of ``case`` (a ``Case``, mapping or case file) at ``time``
    (s; default ``numerics.t_end``; docs/statics.md): a one-point branch dataset
    (:func:`solver.continuation.branch_dataset`) with the shape, end loads, Tw, Wr, Lk,
    energies and the number of unstable modes. Raises ``solver.statics.StaticsError``."""
    from solver.continuation import Branch, branch_dataset
    from solver.statics import solve, static_problem, unstable_modes

    c = _as_case(case)
    prob = static_problem(c, time)
    sol = solve(prob)
    count, mu = unstable_modes(sol.Y, prob)
    br = Branch(parameter=[0.0], Y=[sol.Y], unstable=[count],
                mu=[float(mu[0].real) if mu.size else float("nan")],
                iterations=[sol.iterations], problems=[prob], stopped="equilibrium")
    return branch_dataset(br, "", attrs={"case": c.canonical_json()})


def continue_branch(case: Any, parameter: str, to: float, *, time: float | None = None,
                    switch: bool = False, max_points: int = 500, step: float = 0.05,
                    shapes_every: int = 1, stability: bool = True,
                    on_point: Callable[[int, float], None] | None = None,
                    should_stop: Callable[[], object] | None = None,
                    checkpoint: Callable[[Any], None] | None = None,
                    resume: Any = None):
    """Pseudo-arclength continuation of the equilibria of ``case`` in the scalar at the
    dotted ``parameter`` path (as sweeps spell it, e.g. ``boundary.end.translation.2.force``)
    from the case's value to ``to`` (docs/statics.md). ``time``: the time at which the
    end conditions are read (velocities integrated up to it; default ``numerics.t_end``).
    ``switch``: leave the branch at its first branch point (a simple one along the
    critical mode, a round rod's symmetric pair along one mode of the pair). ``step``:
    the largest step as a fraction of the start tangent's arclength over the range.
    ``should_stop``: asked before every step; a true answer (a reason) ends the branch
    there, its ``stopped`` attribute "stopped: <reason>". ``checkpoint``: called
    with a :class:`solver.checkpoint.BranchCheckpoint` after every point (and at a stop);
    ``resume``: such a checkpoint of the same case and options, continued to the branch an
    uninterrupted call returns (its dataset's ``resumed_at_point`` attribute says after
    how many points). Returns the branch dataset (:func:`solver.continuation.branch_dataset`).

    Raises ValueError (a path that is not a scalar of the case, a value that makes the case
    invalid or changes its grid, a ``resume`` of another case or options) and
    ``solver.continuation.ContinuationError`` (a range that does not move, no equilibrium
    or a singular Jacobian at the start), both before any continuation step. Any exception
    raised later carries the branch so far as a dataset, ``exc.partial`` (its ``stopped``
    attribute "failed: <exception>").
    """
    import time as _time

    from solver.checkpoint import BranchCheckpoint
    from solver.continuation import branch_dataset, continuation

    problem_at, lam0, to = continuation_family(case, parameter, to, time=time)
    c = _as_case(case)
    key = branch_key(c, parameter, to, time=time, switch=switch, step=step,
                     stability=stability)
    if resume is not None and resume.key != key:
        raise ValueError("resume: the checkpoint belongs to another case or continuation")
    began = _time.monotonic()
    spent = 0.0 if resume is None else float(resume.wall_time)

    def keep(state: dict) -> None:
        checkpoint(BranchCheckpoint(key, state, spent + _time.monotonic() - began))

    attrs = {"case": c.canonical_json(), "target": to}
    if resume is not None:
        attrs["resumed_at_point"] = int(resume.points)
    try:
        br = continuation(problem_at, lam0, to, max_points=max_points, ds_max=step,
                          ds=min(step, 0.02), stability=stability, switch=switch,
                          on_point=on_point, should_stop=should_stop,
                          checkpoint=keep if checkpoint is not None else None,
                          resume=None if resume is None else resume.state)
    except Exception as exc:
        partial = getattr(exc, "partial_branch", None)
        if partial is not None and partial.parameter:
            try:
                exc.partial = branch_dataset(partial, parameter, shapes_every=shapes_every,
                                             attrs=attrs)
            except Exception:  # noqa: BLE001 - the exception to report is the first one
                pass
        raise
    return branch_dataset(br, parameter, shapes_every=shapes_every, attrs=attrs)


def branch_key(case: Any, parameter: str, to: float, *, time: float | None = None,
               switch: bool = False, step: float = 0.05, stability: bool = True) -> str:
    """The key a :class:`solver.checkpoint.BranchCheckpoint` of :func:`continue_branch`
    is bound to: the case and the options that shape the branch
    (:func:`solver.checkpoint.branch_resume_key`; ``max_points`` and ``shapes_every`` do
    not, so a branch may be resumed with more points)."""
    from solver.checkpoint import branch_resume_key

    return branch_resume_key(_as_case(case), parameter=parameter, to=float(to), time=time,
                             switch=bool(switch), step=float(step), stability=bool(stability))


def continuation_family(case: Any, parameter: str, to: float, *, time: float | None = None):
    """The checks :func:`continue_branch` makes before any solve, and what it continues:
    ``(λ -> StaticProblem, the case's value λ0 at parameter, to)``. Raises ValueError (a
    path that is not a scalar of the case, a ``to`` that makes the case invalid or changes
    its grid), ``solver.continuation.ContinuationError`` (a range that does not move) and
    ``solver.statics.StaticsError`` (a case the static problem does not support, naming the
    field). The service runs it at submission (service/continuations.py)."""
    from solver.continuation import ContinuationError

    problem_at, lam0 = _problem_family(case, parameter, time)
    to = float(to)
    if not math.isfinite(to) or to == lam0:
        raise ContinuationError(f"--to {to!r}: the range {lam0!r} -> {to!r} does not move "
                                f"{parameter}")
    p0, p1 = problem_at(lam0), problem_at(to)
    if p1.n_segments != p0.n_segments or p1.length != p0.length:
        raise ValueError(f"--parameter {parameter}: changes the grid (rod.length or "
                         "numerics); continue in a parameter that keeps it")
    from solver.continuation import range_unrepresentable

    why = range_unrepresentable(p0, p1)
    if why:
        raise ValueError(f"--to {to!r}: {why}")
    return problem_at, lam0, to


def equilibrium_start(case: Any, *, time: float | None = None, parameter: str | None = None,
                      value: float | None = None, amplitude: float = 0.0):
    """A start state for :func:`simulate` (``simulate(case, start=...)``): the static
    equilibrium of ``case`` at ``time`` (default ``numerics.t_end``), with the scalar at
    ``parameter`` set to ``value`` when given (e.g. a branch point's
    ``bifurcation_parameter`` from :func:`continue_branch`), at rest, plus ``amplitude`` (m)
    times its critical mode (the eigenvector of the stability pencil with the eigenvalue
    nearest zero, largest displacement 1 m) so that post-buckling dynamics start where
    the statics leave off. Raises ``solver.statics.StaticsError`` and ValueError."""
    from solver.statics import critical_mode, solve, start_state, static_problem

    if parameter is not None:
        if value is None:
            raise ValueError("equilibrium_start: a parameter needs its value")
        problem_at, _ = _problem_family(case, parameter, time)
        prob = problem_at(float(value))
    else:
        prob = static_problem(_as_case(case), time)
    sol = solve(prob)
    mode = critical_mode(sol.Y, prob) if amplitude else None
    return start_state(sol.Y, prob, mode, amplitude)
