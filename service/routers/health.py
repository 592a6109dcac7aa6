"""/v1/health: liveness (the process) and readiness (registry, broker, result store).

``?live=true`` is the liveness probe: a coroutine that answers from the event loop without
touching anything, so it answers while the registry is locked or every thread of the pool is
busy (a Kubernetes liveness probe that waited on the registry would restart healthy pods
during a migration). Without it, the readiness probe: the registry (one row of
``hockle_jobs``, so a locked table counts as unavailable), the broker and the result store,
checked on threads of their own and each bounded by ``HOCKLE_REGISTRY_REQUEST_TIMEOUT``; 503
when one fails, so a load balancer stops sending requests that would only get 503s.
"""
from __future__ import annotations

import asyncio
from concurrent.futures import ThreadPoolExecutor
from typing import Annotated

from fastapi import APIRouter, Depends, Query, Request
from fastapi.responses import JSONResponse

from ..auth import authenticated
from ..deps import Services, services
from ..schemas import Check, Health

router = APIRouter(tags=["health"])

# readiness checks never queue behind the request threads (a stalled registry can hold all)
_CHECKS = ThreadPoolExecutor(max_workers=4, thread_name_prefix="hockle-health")


def _check(fn) -> Check:
    try:
        fn()
        return Check(ok=True)
    except Exception as exc:  # noqa: BLE001 - a failed dependency is reported, not raised
        first = (str(exc).strip().splitlines() or [""])[0]
        return Check(ok=False, detail=f"{type(exc).__name__}: {first[:200]}")


async def _bounded(fn, timeout: float) -> Check:
    loop = asyncio.get_running_loop()
    try:
        return await asyncio.wait_for(loop.run_in_executor(_CHECKS, _check, fn), timeout)
    except asyncio.TimeoutError:
        return Check(ok=False, detail=f"no answer within {timeout:g} s")


@router.get("/health", operation_id="get_health", summary="Health of the service",
            response_model=Health, responses={503: {"model": Health,
                                                    "description": "A dependency is down"}})
async def get_health(
    request: Request,
    svc: Annotated[Services, Depends(services)],
    live: Annotated[bool, Query(description="Liveness only: answer 200 while the process "
                                            "serves requests, without checking dependencies.")]
    = False,
):
    """Readiness: 200 when the registry, the broker and the result store answer, 503
    otherwise. ``?live=true``: liveness, 200 without checking anything. With API keys the
    workers' names (``workers``) go to a request with a valid key only; ``workers_seen``
    counts them for everyone."""
    import solver

    mode = "embedded" if svc.settings.embedded else "distributed"
    if live:
        ok = Check(ok=True, detail="not checked (live=true)")
        return Health(status="ok", mode=mode, solver_version=solver.__version__, registry=ok,
                      broker=ok, result_store=ok)
    # a registry that cannot answer a one-row read within its request time-out is not ready
    # (deploy/k8s/api.yaml's probe waits 8 s for the default 5 s)
    timeout = svc.settings.registry_request_timeout
    registry, broker, store = await asyncio.gather(
        _bounded(svc.registry.ping, timeout), _bounded(svc.enqueuer.ping, timeout),
        _bounded(svc.store.check_writable, timeout))
    workers, counts = [], {}
    # the names of the machines a service runs on are for its users: with keys, a key's
    names = authenticated(request) or not getattr(request.app.state, "auth_enabled", False)
    if registry.ok:
        def details():
            seen = [{"name": w.name, "last_seen": w.last_seen.isoformat() + "Z",
                     "current_job": w.current_job}
                    for w in svc.registry.workers_seen(svc.settings.worker_seen_window)]
            return seen, svc.registry.counts()

        try:
            workers, counts = await asyncio.wait_for(
                asyncio.get_running_loop().run_in_executor(_CHECKS, details), timeout)
        except Exception:  # noqa: BLE001 - the details are optional; the checks said ok
            pass
    healthy = registry.ok and broker.ok and store.ok
    body = Health(status="ok" if healthy else "unavailable", mode=mode,
                  solver_version=solver.__version__, registry=registry, broker=broker,
                  result_store=store, workers=workers if names else [],
                  workers_seen=len(workers), jobs=counts)
    if healthy:
        return body
    return JSONResponse(body.model_dump(mode="json"), status_code=503)
