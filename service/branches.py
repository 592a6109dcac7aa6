"""Static equilibria of a case and their branches in one of its scalars, named by the
dotted path sweeps use (``boundary.end.translation.2.force``; docs/statics.md): what
``hockle continue``, the Python API (:mod:`hockle.api` re-exports these names) and the
service's continuation jobs (service/continuations.py, worker/tasks.py) share.

:func:`continuation_family` makes the checks before any solve, :func:`continue_branch`
follows the branch, :func:`branch_key` is the identity its checkpoints are bound to;
:func:`equilibrium` solves one point and :func:`equilibrium_start` turns one into the start
state of a dynamic run.
"""
from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["as_case", "continuation_family", "continue_branch", "branch_key", "equilibrium",
           "equilibrium_start"]


def as_case(case: Any):
    """A :class:`solver.case.Case` of ``case``: a ``Case`` as it is, a mapping validated, a
    case file read (``Case.from_file``). Raises ``solver.case.CaseError`` and TypeError."""
    from solver.case import Case

    if isinstance(case, Case):
        return case
    if isinstance(case, Mapping):
        return Case.model_validate(dict(case))
    if isinstance(case, (str, os.PathLike)):
        return Case.from_file(case)
    raise TypeError(f"a case is a solver.case.Case, a mapping or a case file, got "
                    f"{type(case).__name__}")


def _case_scalar(doc: dict, path: str) -> float:
    """The number at ``path`` in the case document; ValueError naming the path when the
    path does not lead to a number (a one-item list of conditions is looked through, as
    :func:`service.sweeps.set_path` does)."""
    from .sweeps import parse_path

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
    from .client import case_document
    from .sweeps import SweepError, set_path
    from solver.case import Case, CaseError
    from solver.statics import static_problem

    doc = case_document(case) if not isinstance(case, (str, os.PathLike)) else \
        as_case(case).model_dump(mode="json")
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
    """The static equilibrium of a case (docs/statics.md).

    Parameters
    ----------
    case : solver.Case or mapping or str or os.PathLike
        The case, a mapping of it or its case file.
    time : float, optional
        The time at which the end conditions are read, s; default ``numerics.t_end``.

    Returns
    -------
    xarray.Dataset
        A one-point branch dataset (:func:`solver.continuation.branch_dataset`): the
        shape, end loads, Tw, Wr, Lk, energies and the number of unstable modes.

    Raises
    ------
    solver.statics.StaticsError
        A case the static problem does not support, or no equilibrium found.
    """
    from solver.continuation import Branch, branch_dataset
    from solver.statics import solve, static_problem, unstable_modes

    c = as_case(case)
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
    """Pseudo-arclength continuation of a case's equilibria in one of its scalars.

    From the case's value of the scalar at ``parameter`` to ``to`` (docs/statics.md), with
    folds and branch points located and the unstable modes counted at every point.

    Parameters
    ----------
    case : solver.Case or mapping or str or os.PathLike
        The case, a mapping of it or its case file.
    parameter : str
        The dotted path of the scalar, as sweeps spell it
        (``boundary.end.translation.2.force``).
    to : float
        The value to continue to.
    time : float, optional
        The time at which the end conditions are read (velocities integrated up to it), s;
        default ``numerics.t_end``.
    switch : bool
        Leave the branch at its first branch point (a simple one along the critical mode,
        a round rod's symmetric pair along one mode of the pair).
    max_points : int
        The most points.
    step : float
        The largest step, as a fraction of the start tangent's arclength over the range.
    shapes_every : int
        Keep the shape of every that many points.
    stability : bool
        Count the unstable modes at every point.
    on_point : callable, optional
        ``on_point(points, value)`` after every point.
    should_stop : callable, optional
        Asked before every step; a true answer (a reason) ends the branch there, its
        ``stopped`` attribute "stopped: <reason>".
    checkpoint : callable, optional
        Called with a :class:`solver.checkpoint.BranchCheckpoint` after every point (and
        at a stop).
    resume : solver.checkpoint.BranchCheckpoint, optional
        A checkpoint of the same case and options: continued to the branch an
        uninterrupted call returns (the dataset's ``resumed_at_point`` says after how many
        points).

    Returns
    -------
    xarray.Dataset
        The branch dataset (:func:`solver.continuation.branch_dataset`).

    Raises
    ------
    ValueError
        Before any step: a path that is not a scalar of the case, a value that makes the
        case invalid or changes its grid, a ``resume`` of another case or options.
    solver.continuation.ContinuationError
        Before any step: a range that does not move, no equilibrium or a singular
        Jacobian at the start. Any exception raised later carries the branch so far as a
        dataset, ``exc.partial`` (its ``stopped`` attribute "failed: <exception>").
    """
    import time as _time

    from solver.checkpoint import BranchCheckpoint
    from solver.continuation import branch_dataset, continuation

    problem_at, lam0, to = continuation_family(case, parameter, to, time=time)
    c = as_case(case)
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
    """The key a branch checkpoint of :func:`continue_branch` is bound to.

    The case and the options that shape the branch
    (:func:`solver.checkpoint.branch_resume_key`); ``max_points`` and ``shapes_every`` do
    not, so a branch may be resumed with more points.

    Parameters
    ----------
    case, parameter, to, time, switch, step, stability
        As for :func:`continue_branch`.

    Returns
    -------
    str
    """
    from solver.checkpoint import branch_resume_key

    return branch_resume_key(as_case(case), parameter=parameter, to=float(to), time=time,
                             switch=bool(switch), step=float(step), stability=bool(stability))


def continuation_family(case: Any, parameter: str, to: float, *, time: float | None = None):
    """The checks :func:`continue_branch` makes before any solve, and what it continues.

    The service runs it at submission (service/continuations.py).

    Parameters
    ----------
    case, parameter, to, time
        As for :func:`continue_branch`.

    Returns
    -------
    tuple
        ``(problem_at, lam0, to)``: λ -> the static problem, the case's value at
        ``parameter``, and ``to`` as a float.

    Raises
    ------
    ValueError
        A path that is not a scalar of the case, a ``to`` that makes the case invalid or
        changes its grid.
    solver.continuation.ContinuationError
        A range that does not move.
    solver.statics.StaticsError
        A case the static problem does not support, naming the field.
    """
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
    """A start state at an equilibrium, for ``hockle.api.simulate(case, start=...)``.

    The static equilibrium at rest plus ``amplitude`` times its critical mode, so that
    post-buckling dynamics start where the statics leave off.

    Parameters
    ----------
    case : solver.Case or mapping or str or os.PathLike
        The case, a mapping of it or its case file.
    time : float, optional
        The time at which the end conditions are read, s; default ``numerics.t_end``.
    parameter : str, optional
        A dotted path whose scalar is set to ``value`` (e.g. a branch point's
        ``bifurcation_parameter`` from :func:`continue_branch`).
    value : float, optional
        Its value; required with ``parameter``.
    amplitude : float
        m: the critical mode (the eigenvector of the stability pencil with the eigenvalue
        nearest zero, largest displacement 1 m) times this is added.

    Returns
    -------
    solver.initial.StartState
        The start state.

    Raises
    ------
    solver.statics.StaticsError
        No equilibrium, or a case the statics do not support.
    ValueError
        A parameter without its value.
    """
    from solver.statics import critical_mode, solve, start_state, static_problem

    if parameter is not None:
        if value is None:
            raise ValueError("equilibrium_start: a parameter needs its value")
        problem_at, _ = _problem_family(case, parameter, time)
        prob = problem_at(float(value))
    else:
        prob = static_problem(as_case(case), time)
    sol = solve(prob)
    mode = critical_mode(sol.Y, prob) if amplitude else None
    return start_state(sol.Y, prob, mode, amplitude)
