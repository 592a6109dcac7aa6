"""Checkpoints of a run: everything :func:`solver.integrate` needs to continue bit for bit.

A :class:`Checkpoint` holds the run (:class:`solver.run.RodRun`: its state, step control,
Newton's factorisation and counters, pickled whole, so that this module needs to know
nothing of the step logic and imports nothing of the solver), the output records and step diagnostics kept so far,
the number of accepted steps, and the case it belongs to. :meth:`Checkpoint.dumps` /
:meth:`Checkpoint.loads` turn it into bytes and back; the solver itself does no I/O: the
caller of ``integrate(..., checkpoint=...)`` decides where the bytes go (``hockle run
--checkpoint``, the service's result store).

The bytes are a header line (format name, version, case hash) and a pickle of the
objects: exact (the resumed run repeats the uninterrupted one to the last bit, tested),
and as trustworthy as the file it comes from. Load checkpoints only from sources you
trust (your own runs, the service's own store), as with any pickle.

A :class:`BranchCheckpoint` is the same for a continuation (:func:`solver.continuation.
continuation`): the state it hands to ``checkpoint=`` (the points so far and the step
state), bound to the case and the continuation's options by :func:`branch_resume_key`; its
header's format is ``hockle-branch-checkpoint``.
"""
from __future__ import annotations

import hashlib
import json
import pickle
from dataclasses import dataclass, field

__all__ = ["Checkpoint", "BranchCheckpoint", "CheckpointError", "FORMAT", "BRANCH_FORMAT",
           "VERSION", "resume_key", "branch_resume_key"]

FORMAT = "hockle-checkpoint"
BRANCH_FORMAT = "hockle-branch-checkpoint"
VERSION = 1


def resume_key(case) -> str:
    """The identity a checkpoint is bound to.

    Parameters
    ----------
    case : solver.Case

    Returns
    -------
    str
        sha256 of the case's canonical JSON without ``numerics.wall_clock_budget``: a run
        may be continued under another budget; any other change, physics, numerics or
        outputs, makes it another run.
    """
    spec = case.model_dump(mode="json")
    spec.get("numerics", {}).pop("wall_clock_budget", None)
    text = json.dumps(spec, sort_keys=True, separators=(",", ":"), ensure_ascii=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def branch_resume_key(case, **options) -> str:
    """The identity a :class:`BranchCheckpoint` is bound to.

    Parameters
    ----------
    case : solver.Case
    **options
        The continuation's options that shape the branch (JSON scalars).

    Returns
    -------
    str
        sha256 of :func:`resume_key` of the case and the ``options`` (parameter, target,
        time, switch, step, stability, ...).
    """
    text = json.dumps({"case": resume_key(case), **options}, sort_keys=True,
                      separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _header(data: bytes, fmt: str) -> dict:
    line = data.split(b"\n", 1)[0]
    try:
        head = json.loads(line.decode())
    except (UnicodeDecodeError, ValueError):
        head = None
    if not isinstance(head, dict) or head.get("format") != fmt:
        raise CheckpointError(f"not a {fmt.replace('-', ' ')} (no {fmt} header)")
    if head.get("version") != VERSION:
        raise CheckpointError(f"checkpoint version {head.get('version')!r} is not "
                              f"{VERSION}: written by another hockle version; rerun from "
                              f"the start")
    return head


class CheckpointError(ValueError):
    """A checkpoint that cannot be used: not a checkpoint, another version, or another
    case. The message names the reason."""


@dataclass
class Checkpoint:
    """The state of a run after an accepted step.

    Attributes
    ----------
    case_hash : str
        :func:`resume_key` of the run's case; a resume with another case is refused.
    step : int
        Accepted (nominal or error-controlled) steps so far.
    run : solver.run.RodRun
    times : list of float
        Output times so far, s.
    records : list of dict
        Output records so far (:func:`solver.recording.snapshot`).
    diag : dict of lists
        Per-step diagnostics so far (``step_time``, ``step_dt``, ...).
    wall_time : float
        Wall-clock seconds spent on the run up to this checkpoint (all attempts).
    """

    case_hash: str
    step: int
    run: object
    times: list = field(default_factory=list)
    records: list = field(default_factory=list)
    diag: dict = field(default_factory=dict)
    wall_time: float = 0.0

    @property
    def t(self) -> float:
        """Simulated time reached, s."""
        return float(self.run.state.t)

    def dumps(self) -> bytes:
        """The checkpoint as bytes: a JSON header line, then the pickle."""
        header = json.dumps({"format": FORMAT, "version": VERSION, "case_hash": self.case_hash,
                             "t": self.t, "step": self.step}).encode()
        return header + b"\n" + pickle.dumps(self, protocol=pickle.HIGHEST_PROTOCOL)

    @staticmethod
    def header(data: bytes) -> dict:
        """The header of checkpoint bytes (format, version, case_hash, t, step) without
        unpickling anything. Raises CheckpointError when ``data`` is not a checkpoint."""
        return _header(data, FORMAT)

    @classmethod
    def loads(cls, data: bytes, case=None) -> "Checkpoint":
        """Checkpoint from :meth:`dumps` bytes. With ``case``, the checkpoint must belong to
        it (same :func:`resume_key`) and hold every attribute a run of this code has (a
        checkpoint of an older solver that lacks one is refused rather than failing deep
        inside a step). Raises CheckpointError with the reason."""
        head = cls.header(data)
        if case is not None and head.get("case_hash") != resume_key(case):
            raise CheckpointError("the checkpoint belongs to another case (resume key "
                                  f"{head.get('case_hash')} != {resume_key(case)})")
        try:
            obj = pickle.loads(data.split(b"\n", 1)[1])
        except Exception as exc:  # noqa: BLE001 - any unpickling failure is a bad file
            raise CheckpointError(f"checkpoint cannot be read: {exc}") from None
        if not isinstance(obj, cls):
            raise CheckpointError("checkpoint does not hold a run")
        if case is not None:
            # a fresh run of the case, of the class the pickle names: what this code's
            # runs hold
            missing = sorted(_layout(type(obj.run)(case)) - _layout(obj.run))
            if missing:
                raise CheckpointError("the checkpoint was written by another version of the "
                                      f"solver (its state lacks {', '.join(missing[:4])}"
                                      f"{' ...' if len(missing) > 4 else ''}); rerun from "
                                      "the start")
        return obj


@dataclass
class BranchCheckpoint:
    """The state of a continuation after an accepted point.

    Attributes
    ----------
    key : str
        :func:`branch_resume_key` of the case and options; a resume with others is refused.
    state : dict
        What :func:`solver.continuation.continuation` hands to ``checkpoint=`` and takes
        as ``resume=``: the points so far (``parameter``, ``Y`` (N+1, 13) each, ...) and
        the step state.
    wall_time : float
        Wall-clock seconds spent on the branch up to this checkpoint (all attempts).
    """

    key: str
    state: dict
    wall_time: float = 0.0

    @property
    def points(self) -> int:
        """The points of the branch so far."""
        return len(self.state["parameter"])

    @property
    def parameter(self) -> float:
        """The parameter at the last point (its unit)."""
        return float(self.state["parameter"][-1])

    @property
    def t(self) -> float:
        """The points so far as a float: the progress coordinate the service's checkpoint
        policy reads (a dynamic run's simulated time)."""
        return float(self.points)

    def dumps(self) -> bytes:
        """The checkpoint as bytes: a JSON header line, then the pickle."""
        header = json.dumps({"format": BRANCH_FORMAT, "version": VERSION, "key": self.key,
                             "points": self.points, "parameter": self.parameter}).encode()
        return header + b"\n" + pickle.dumps(self, protocol=pickle.HIGHEST_PROTOCOL)

    @classmethod
    def loads(cls, data: bytes, key: str | None = None) -> "BranchCheckpoint":
        """BranchCheckpoint from :meth:`dumps` bytes; with ``key``, it must belong to it.
        Raises CheckpointError with the reason."""
        head = _header(data, BRANCH_FORMAT)
        if key is not None and head.get("key") != key:
            raise CheckpointError("the checkpoint belongs to another continuation (key "
                                  f"{head.get('key')} != {key})")
        try:
            obj = pickle.loads(data.split(b"\n", 1)[1])
        except Exception as exc:  # noqa: BLE001 - any unpickling failure is a bad file
            raise CheckpointError(f"checkpoint cannot be read: {exc}") from None
        if not isinstance(obj, cls):
            raise CheckpointError("checkpoint does not hold a branch")
        return obj


def _layout(run) -> set:
    """``Class.attribute`` names of a run and of the solver objects it holds, two levels
    deep (its state, step control, loads, system, Newton, contact, error control ...):
    what a checkpoint must provide to continue."""
    names = set()
    level = [run]
    for _ in range(3):
        deeper = []
        for obj in level:
            if obj is None or not hasattr(obj, "__dict__"):
                continue
            names.update(f"{type(obj).__name__}.{key}" for key in vars(obj))
            deeper += [v for v in vars(obj).values()
                       if type(v).__module__.startswith("solver.") and hasattr(v, "__dict__")
                       and v is not run]
        level = deeper
    return names
