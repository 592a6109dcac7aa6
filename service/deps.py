"""What the routers take from the application, by FastAPI dependency injection.

``create_app`` (service/app.py) builds one :class:`Services` and puts it in ``app.state``; a
route asks for it with ``Depends(services)``. The routers import this module, never
``service.app``, so the application imports its routers and nothing imports back.
"""
from __future__ import annotations

from dataclasses import dataclass

from starlette.requests import HTTPConnection

from .queue import Enqueuer
from .registry import Registry
from .settings import Settings
from .store import ResultStore

__all__ = ["Services", "services", "known_query_only"]


@dataclass
class Services:
    """The process's settings, job registry, result store and queue client."""

    settings: Settings
    registry: Registry
    store: ResultStore
    enqueuer: Enqueuer


async def services(request: HTTPConnection) -> Services:
    """The application's :class:`Services` (a coroutine, so that resolving it never waits for
    a thread of the pool that blocking routes use)."""
    return request.app.state.services


def _query_names(dependant) -> set[str]:
    """The query parameters a route declares: its own and its dependencies' (by alias)."""
    names: set[str] = set()
    stack = [dependant]
    while stack:
        current = stack.pop()
        names.update(field.alias for field in current.query_params)
        stack.extend(current.dependencies)
    return names


_DECLARED: dict[int, frozenset[str]] = {}


async def known_query_only(request: HTTPConnection) -> None:
    """Router dependency: a query parameter the route does not declare (a misspelt
    ``?fersh=true`` would otherwise be ignored in silence) is a 422 problem naming it and
    listing the route's parameters."""
    from .problems import ProblemError

    route = request.scope.get("route")
    dependant = getattr(route, "dependant", None)
    if dependant is None:
        return
    allowed = _DECLARED.get(id(route))
    if allowed is None:
        allowed = _DECLARED[id(route)] = frozenset(_query_names(dependant))
    unknown = [name for name in dict.fromkeys(request.query_params.keys())
               if name not in allowed]
    if unknown:
        known = ", ".join(sorted(allowed)) or "none"
        raise ProblemError(422, "invalid-request", "Invalid request",
                           f"unknown query parameter(s): {', '.join(unknown)}", errors=[
                               {"loc": f"query.{name}", "type": "unknown_parameter",
                                "msg": f"this route has no query parameter {name!r}; its "
                                       f"parameters: {known}"} for name in unknown])
