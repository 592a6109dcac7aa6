"""The solver's tuning constants for the runs of a benchmark: ``--newton ATTR=VALUE[,...]``
of ``benchmarks.seed_accuracy`` and ``benchmarks.contact_suite`` (and the variants of
research/replay_steps.py) set class attributes of :class:`solver.newton.NewtonSolver` (or
of the candidate search, :data:`OWNERS`) for the rest of the process."""
from __future__ import annotations

from solver.contact.search import CandidateSearch
from solver.newton import NewtonSolver

__all__ = ["OWNERS", "owner", "parse_variant", "set_newton"]

#: the classes other than NewtonSolver whose class attributes a variant may set, by attribute
OWNERS = {"VERLET_SKIN": CandidateSearch}


def owner(attr: str):
    """The class whose attribute ``attr`` a variant sets (:data:`OWNERS`, else NewtonSolver)."""
    return OWNERS.get(attr, NewtonSolver)


def parse_variant(text: str) -> tuple[str, dict]:
    """``NAME:ATTR=VALUE,...`` -> (NAME, {ATTR: float or int}); raises ValueError naming
    an attribute that its class (:func:`owner`) does not have."""
    name, _, body = text.partition(":")
    settings = {}
    for item in filter(None, body.split(",")):
        attr, _, value = item.partition("=")
        cls = owner(attr)
        if not hasattr(cls, attr):
            raise ValueError(f"--variant {text!r}: {cls.__name__} has no attribute {attr!r}")
        current = getattr(cls, attr)
        settings[attr] = int(value) if isinstance(current, int) else float(value)
    return name, settings


def set_newton(text: str) -> dict:
    """Set the class attributes ``ATTR=VALUE[,ATTR=VALUE...]`` of NewtonSolver or the
    candidate search (:func:`owner`) for the rest of the process; returns them. Raises
    ValueError as :func:`parse_variant`."""
    settings = parse_variant(f"newton:{text}")[1]
    for attr, value in settings.items():
        setattr(owner(attr), attr, value)
    return settings
