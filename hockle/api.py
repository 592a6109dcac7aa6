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

:func:`simulate`, hockle's one ``simulate``, is :func:`solver.integrate` with its
``observer`` hook (the callbacks) and its ``extra_force`` hook (the loads): the same time
loop, steps, outputs, checkpoints and result dataset.
"""
from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

# the statics live in the service layer, which continuation jobs share; these are their
# documented names here
from service.branches import as_case as _as_case
from service.branches import (branch_key, continuation_family, continue_branch, equilibrium,
                              equilibrium_start)

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
    "continuation_family",
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

    The fields below are computed when first read and are copies: changing them changes
    nothing in the run. ``get(*groups)`` returns whole output field groups of the result
    dataset as a dict.

    Parameters
    ----------
    run : solver.simulation.RodRun
        The run, for experts: read it, do not change it.
    step : int
        Accepted steps so far (0 at the start).

    Attributes
    ----------
    t : float
        Simulated time, s.
    step : int
        Accepted steps so far; 0 at the start.
    dt : float
        The last step, s.
    s : numpy.ndarray
        The grid, (N+1,) m.
    position : numpy.ndarray
        (N+1, 3) m, global frame.
    v, omega, f, kappa, moment : numpy.ndarray
        (N+1, 3), body frame, SI units.
    orientation : numpy.ndarray
        (N+1, 4) unit quaternions, scalar first.
    twist, writhe, linking_number : float
        Turns (the writhe costs O(N²)).
    energies : dict
        The energies, the work put in and its power, J and W.
    contact_count : int
        Self-contact pairs.
    min_surface_gap : float
        Smallest surface gap among them, m.
    bend_radius_min, bend_radius_min_s : float
        The smallest bend radius and where it is, m.
    run : solver.simulation.RodRun
        The run itself.
    """

    _GROUPS = {"v": "v", "omega": "omega", "f": "f", "kappa": "kappa", "moment": "moment",
               "position": "position", "orientation": "orientation", "twist": "topology",
               "writhe": "topology", "linking_number": "topology", "contact_count": "contact",
               "min_surface_gap": "contact", "bend_radius_min": "bend_radius",
               "bend_radius_min_s": "bend_radius"}

    def __init__(self, run, step: int):
        self.run = run
        self.t = float(run.state.t)
        self.step = int(step)
        self.dt = float(run.control.last_dt)
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

    Subclass and override :meth:`__call__`, or wrap a function. Every callback is also
    called once at t = 0 (step 0). Returning ``True`` or a non-empty string stops the run at
    once (any other value is ignored): :func:`simulate` returns the dataset up to there with
    ``hockle_status = "stopped"`` and ``hockle_stop_reason`` the string (or ``"callback"``).

    Parameters
    ----------
    func : callable, optional
        ``func(state) -> bool | str | None``; without it, override :meth:`__call__`.
    every : int, optional
        Called every that many accepted steps (PyElastica's ``step_skip``).
    interval : float, optional
        Called at the first accepted step at or after each multiple of that many simulated
        seconds. Neither ``every`` nor ``interval``: every accepted step.
    name : str, optional
        A name for messages; default the function's.

    Raises
    ------
    ValueError
        Both ``every`` and ``interval``, or either not positive.

    Examples
    --------
    >>> stop = Callback.when(lambda st: st.writhe > 1.0, reason="writhe above one turn")
    >>> every_tenth = Callback(lambda st: print(st.t), every=10)
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
        """Observe ``state``.

        Parameters
        ----------
        state : State
            The rod at this step.

        Returns
        -------
        bool or str or None
            ``True`` or a reason string to stop the run.
        """
        if self.func is None:
            raise NotImplementedError("override Callback.__call__ or pass a function")
        return self.func(state)

    @classmethod
    def when(cls, predicate: Callable[[State], Any], *, reason: str = "stop condition met",
             every: int | None = None, interval: float | None = None) -> "Callback":
        """A callback that stops the run when ``predicate(state)`` is true.

        Parameters
        ----------
        predicate : callable
            ``predicate(state) -> bool``.
        reason : str
            The stop reason the result carries (``hockle_stop_reason``).
        every, interval : optional
            The cadence, as for :class:`Callback`.

        Returns
        -------
        Callback
        """
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
    """A callback that keeps quantities of the state at its cadence.

    Parameters
    ----------
    names : iterable of str
        Any attribute of :class:`State` (``position``, ``writhe``, ...) or key of its
        ``energies`` (``energy_total``, ...).
    every, interval : optional
        The cadence, as for :class:`Callback`.

    Attributes
    ----------
    times : list of float
        The recorded times, s.
    steps : list of int
        The recorded steps.
    data : dict of list
        One list per name; :meth:`arrays` stacks them.
    """

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
        """The records as arrays.

        Returns
        -------
        dict of numpy.ndarray
            ``{"time": (K,), name: (K, ...)}``.
        """
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
    """A distributed force per unit length written as a Python function.

    In-process runs only: the service takes data, never code. The solver assembles the
    load as it does the case's ``distributed_forces`` (work and power included) and asks
    for it at every Newton iteration at the new time level. It does not know where the load
    changes suddenly: steps do not land on a jump of ``func`` (write the case's own
    ``distributed_forces`` for windows in time).

    Parameters
    ----------
    func : callable
        ``func(t, s)`` returns the force in N/m, **global frame**, at time ``t`` (s) on the
        grid ``s`` ((N+1,) m): an (N+1, 3) array or one 3-vector for the whole rod.
    uses_state : bool
        If true, ``func(t, s, state)`` with the :class:`State` of the last accepted step:
        the load is then explicit in the state (lagged by one step, constant within a
        step's Newton solve), fine for slowly varying loads, not for stiff ones.
    name : str, optional
        The name the result's ``hockle_custom_loads`` lists; default the function's.

    Raises
    ------
    TypeError
        ``func`` is not callable.
    """

    def __init__(self, func: Callable[..., Any], *, uses_state: bool = False,
                 name: str | None = None):
        if not callable(func):
            raise TypeError(f"DistributedLoad needs a function, got {type(func).__name__}")
        self.func = func
        self.uses_state = bool(uses_state)
        self.name = name or getattr(func, "__name__", "load")

    def evaluate(self, t: float, s: np.ndarray, state: State | None) -> np.ndarray:
        """The load on the grid.

        Parameters
        ----------
        t : float
            Time, s.
        s : numpy.ndarray
            The grid, (N+1,) m.
        state : State or None
            The last accepted step's state, for a load with ``uses_state``.

        Returns
        -------
        numpy.ndarray
            (N+1, 3) N/m, global frame.

        Raises
        ------
        ValueError
            A wrong shape or a non-finite value, naming the load.
        """
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
    """The ``extra_force`` hook of :func:`solver.integrate`: the sum of the user's loads at
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
    """The ``observer`` hook of :func:`solver.integrate`: the callbacks that are due, in
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


def simulate(case, callbacks: Iterable[Any] = (), loads: Iterable[Any] = (),
             progress: Callable | None = None, should_stop: Callable | None = None,
             **solver_options: Any):
    """Run a case in this process and return its result dataset.

    hockle's one ``simulate``: :func:`solver.integrate` with the callbacks as its
    ``observer`` and the loads as its ``extra_force`` (docs/interfaces.md).

    Parameters
    ----------
    case : solver.Case or mapping or str or os.PathLike
        A validated case, a mapping of the case spec or a case file (YAML or JSON); a case
        with ``initial.from_result`` starts from that result's state.
    callbacks : iterable
        :class:`Callback` objects or functions of the :class:`State` (called every step),
        called at their cadence after accepted steps and once at t = 0; returning ``True``
        or a reason string stops the run (``hockle_status = "stopped"``,
        ``hockle_stop_reason`` its string).
    loads : iterable
        :class:`DistributedLoad` objects or functions ``(t, s) -> N/m`` (global frame)
        added to the case's distributed forces; the dataset then has
        ``hockle_custom_loads`` naming them (its ``case`` alone no longer reproduces the
        run).
    progress : callable, optional
        ``progress(info)`` with a :class:`solver.Progress` after every accepted step.
    should_stop : callable, optional
        Asked before every step; a truthy answer stops the run (its string the reason).
    **solver_options
        :func:`solver.integrate`'s other options: ``checkpoint``, ``checkpoint_interval``,
        ``resume``, ``start``. With loads a checkpoint needs picklable (module-level) load
        functions.

    Returns
    -------
    xarray.Dataset
        The result dataset (docs/interfaces.md, "The result dataset").

    Raises
    ------
    solver.SolverDivergence
        A step that could not be completed after all Δt cuts; ``.partial`` holds the
        dataset up to there.
    solver.CaseError
        An invalid case file.
    ValueError
        ``observer`` or ``extra_force`` among the options (give ``callbacks`` and
        ``loads``).

    Examples
    --------
    >>> ds = simulate("cases/goyal-writhing.yaml",
    ...               progress=lambda p: print(p.t, p.step))     # doctest: +SKIP
    """
    from solver.simulation import integrate

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
    ds = integrate(case, progress=progress, should_stop=should_stop,
                         observer=_CallbackSet(callbacks) if callbacks else None,
                         extra_force=_LoadSum(loads) if loads else None, **solver_options)
    if loads:
        ds.attrs["hockle_custom_loads"] = ", ".join(load.name for load in loads)
    return ds


# --------------------------------------------------------------------------- case builders


def _dof(key: str, value: Any) -> dict:
    return {key: value}


def clamped() -> dict:
    """An end held in place and in orientation: every velocity and angular velocity 0.

    Returns
    -------
    dict
        An ``EndCondition`` mapping for ``boundary.start`` or ``boundary.end``.
    """
    return {"translation": [_dof("velocity", 0.0) for _ in range(3)],
            "rotation": [_dof("angular_velocity", 0.0) for _ in range(3)]}


def free() -> dict:
    """A free end: no force, no moment.

    Returns
    -------
    dict
        An ``EndCondition`` mapping.
    """
    return {"translation": [_dof("force", 0.0) for _ in range(3)],
            "rotation": [_dof("moment", 0.0) for _ in range(3)]}


def pinned() -> dict:
    """An end held in place but free to turn (a ball joint): velocities 0, moments 0.

    Returns
    -------
    dict
        An ``EndCondition`` mapping.
    """
    return {"translation": [_dof("velocity", 0.0) for _ in range(3)],
            "rotation": [_dof("moment", 0.0) for _ in range(3)]}


def twisted(rate: Any, *, ramp_time: float | None = None) -> dict:
    """A clamped end turned about the rod's axis.

    Parameters
    ----------
    rate : float or dict
        The angular velocity about the axis, rad/s: a number or a :func:`ramp` table.
    ramp_time : float, optional
        From 0 to ``rate`` linearly over that time, s.

    Returns
    -------
    dict
        An ``EndCondition`` mapping.
    """
    if ramp_time is not None:
        rate = ramp([0.0, float(ramp_time)], [0.0, float(rate)])
    out = clamped()
    out["rotation"][2] = _dof("angular_velocity", rate)
    return out


def sliding(tension: Any = 0.0, *, held_after: float | None = None) -> dict:
    """An end held sideways and in orientation that slides along the rod's axis.

    Parameters
    ----------
    tension : float or dict
        The axial force, N (> 0 pulls): a number or a :func:`ramp` table.
    held_after : float, optional
        Held in place from then on, s (the seed example's end at 30 s).

    Returns
    -------
    dict
        An ``EndCondition`` mapping.
    """
    out = clamped()
    axial: Any = _dof("force", tension)
    if held_after is not None:
        axial = switch((_dof("force", tension), held_after), _dof("velocity", 0.0))
    out["translation"][2] = axial
    return out


def end(translation: Sequence[Any], rotation: Sequence[Any]) -> dict:
    """Any end, item by item (body frame).

    Parameters
    ----------
    translation : sequence
        Three items, ``{"velocity": v}`` or ``{"force": f}``, or a :func:`switch`.
    rotation : sequence
        Three items, ``{"angular_velocity": w}`` or ``{"moment": m}``, or a :func:`switch`.

    Returns
    -------
    dict
        An ``EndCondition`` mapping.

    Raises
    ------
    ValueError
        Not three items of each.
    """
    if len(translation) != 3 or len(rotation) != 3:
        raise ValueError("end() needs 3 translation and 3 rotation items (body-frame "
                         "components a1, a2, a3)")
    return {"translation": list(translation), "rotation": list(rotation)}


def ramp(t: Sequence[float], value: Sequence[float]) -> dict:
    """A table in time, piecewise linear, held constant outside.

    Parameters
    ----------
    t : sequence of float
        The times, s, increasing.
    value : sequence of float
        The values there.

    Returns
    -------
    dict
        ``{"t": [...], "value": [...]}``.
    """
    return {"t": [float(x) for x in t], "value": [float(x) for x in value]}


def switch(*items: Any) -> list[dict]:
    """One degree of freedom switching in time.

    Parameters
    ----------
    *items
        Every item but the last is ``(condition, until)``: the condition in force until
        that time (s); the last is the condition from then on.

    Returns
    -------
    list of dict
        The item of an ``EndCondition``.

    Examples
    --------
    >>> switch(({"force": 0.0}, 30.0), {"velocity": 0.0})   # the force until 30 s
    [{'force': 0.0, 'until': 30.0}, {'velocity': 0.0}]
    """
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
    """A validated case from the usual few numbers.

    Parameters
    ----------
    name : str
        The case's name.
    start, end : dict or solver.case.EndCondition
        The two ends: :func:`clamped`, :func:`twisted`, ... or their models.
    n_segments : int
        Grid cells.
    dt : float
        The nominal step, s.
    t_end : float
        The run's end, s.
    length, youngs_modulus, shear_modulus, density, diameter : float or dict
        The rod, SI units (a profile mapping allowed where the case spec allows one);
        default the seed paper's cable: 1 m, 12.5 MPa, 5 MPa, 1500 kg/m³, 2 cm.
    **sections
        The case's other top-level fields, mappings or their models: ``fluid``,
        ``gravity``, ``distributed_forces``, ``point_loads``, ``contact``, ``seabed``,
        ``initial``, ``output``, and ``numerics`` (merged over n_segments, dt, t_end).

    Returns
    -------
    solver.Case

    Raises
    ------
    pydantic.ValidationError
        Naming the field.
    """
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
    """An ``initial.centreline`` along a circular arc.

    From the origin, starting along +z and bending towards +x (in the x-z plane):
    r(s) = (R(1 − cos(s/R)), 0, R sin(s/R)); κ2 = 1/R with the start's a1 along +x.

    Parameters
    ----------
    length : float
        Arc length, m.
    radius : float
        Radius, m.
    n_points : int
        Points at equal arclengths.

    Returns
    -------
    dict
        ``{"points": [[x, y, z], ...]}``, for ``initial={"centreline": ...}``.

    Raises
    ------
    ValueError
        A non-positive length or radius.
    """
    if not (length > 0 and radius > 0):
        raise ValueError("circular_arc: length and radius must be > 0 (m)")
    phi = np.linspace(0.0, length / radius, int(n_points))
    return _centreline(np.stack([radius * (1.0 - np.cos(phi)), np.zeros_like(phi),
                                 radius * np.sin(phi)], axis=1))


def helix(length: float, radius: float, pitch: float, *, n_points: int = 1001) -> dict:
    """An ``initial.centreline`` along a circular helix.

    About the axis x = −radius, y = 0 (parallel to z) from the origin:
    r(θ) = (R cos θ − R, R sin θ, pθ/(2π)), θ from 0 to length/√(R² + (p/2π)²). Its
    curvature is R/(R² + h²) and its torsion h/(R² + h²) with h = p/(2π); with
    ``initial.twist_rate`` equal to the torsion the rod's κ is constant along it (its frame
    turns with the Frenet frame).

    Parameters
    ----------
    length : float
        Arc length, m.
    radius : float
        Radius, m.
    pitch : float
        m per turn: right-handed for > 0, left-handed for < 0.
    n_points : int
        Points at equal arclengths.

    Returns
    -------
    dict
        ``{"points": [[x, y, z], ...]}``.

    Raises
    ------
    ValueError
        A non-positive length or radius.
    """
    if not (length > 0 and radius > 0):
        raise ValueError("helix: length and radius must be > 0 (m)")
    h = pitch / (2.0 * math.pi)
    theta = np.linspace(0.0, length / math.hypot(radius, h), int(n_points))
    return _centreline(np.stack([radius * (np.cos(theta) - 1.0), radius * np.sin(theta),
                                 h * theta], axis=1))


def catenary_parameter(length: float, span: float) -> float:
    """The catenary's parameter a = H/w of a hanging cable.

    The root of 2a sinh(span/(2a)) = length (scipy's brentq).

    Parameters
    ----------
    length : float
        The cable's length, m.
    span : float
        The distance between its two ends, at the same height, m.

    Returns
    -------
    float
        a, m.

    Raises
    ------
    ValueError
        Unless 0 < span < length.
    """
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
    """An ``initial.centreline`` along a hanging catenary.

    Under gravity (−z) between the origin and (span, 0, 0):
    z = a(cosh((x − X/2)/a) − cosh(X/(2a))) with a from :func:`catenary_parameter`, at
    x = X/2 + a asinh((s − L/2)/a). Its sag is a(cosh(X/(2a)) − 1).

    Parameters
    ----------
    length : float
        The cable's length, m.
    span : float
        The distance between its ends, m.
    n_points : int
        Points at equal arclengths.

    Returns
    -------
    dict
        ``{"points": [[x, y, z], ...]}``.

    Raises
    ------
    ValueError
        Unless 0 < span < length.
    """
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
    from solver.simulation import integrate

    case = Case.model_validate_json(case_json)
    try:
        ds = integrate(case)
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
    """Run a parameter sweep on this machine and return the combined dataset.

    The same combination (:func:`service.sweeps.combine_results`) as the service's
    ``GET /v1/sweeps/{id}/results``. Every member is validated first; identical member
    cases run once; a member that fails is marked in ``member_status``, not fatal.

    Parameters
    ----------
    base : solver.Case or mapping or str or os.PathLike
        The case every member starts from, or its case file.
    parameters : mapping
        ``{PATH: [values]}``, PATH a dotted path into the case (docs/service.md, sweeps).
    combine : {"grid", "zip"}
        Every combination of the values, or the values side by side.
    workers : int, optional
        Processes (default: as many as cores; 1: in this process).
    fields : sequence of str
        The output fields to combine (default all).
    on_member : callable, optional
        ``on_member(done, total, index, state)``, called as members finish.

    Returns
    -------
    xarray.Dataset
        The members' results along a ``member`` dimension, with their parameter values,
        ``member_status`` and ``member_message``.

    Raises
    ------
    service.sweeps.SweepError
        Naming each member that does not validate.
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
