"""/v1/health: broker, registry, result store and the workers seen lately."""
from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Query
from fastapi.responses import JSONResponse

from ..app import Services, services
from ..schemas import Check, Health

router = APIRouter(tags=["health"])


def _check(fn) -> Check:
    try:
        fn()
        return Check(ok=True)
    except Exception as exc:  # noqa: BLE001 - a failed dependency is reported, not raised
        return Check(ok=False, detail=f"{type(exc).__name__}: {str(exc)[:200]}")


@router.get("/health", operation_id="get_health", summary="Health of the service",
            response_model=Health, responses={503: {"model": Health,
                                                    "description": "A dependency is down"}})
def get_health(
    svc: Annotated[Services, Depends(services)],
    live: Annotated[bool, Query(description="Liveness only: answer 200 while the process "
                                            "serves requests, without checking dependencies.")]
    = False,
):
    """200 when the registry, the broker and the result store answer; 503 otherwise."""
    import solver

    mode = "embedded" if svc.settings.embedded else "distributed"
    if live:
        ok = Check(ok=True, detail="not checked (live=true)")
        return Health(status="ok", mode=mode, solver_version=solver.__version__, registry=ok,
                      broker=ok, result_store=ok)
    registry = _check(svc.registry.ping)
    broker = _check(svc.enqueuer.ping)
    store = _check(svc.store.check_writable)
    workers, counts = [], {}
    if registry.ok:
        try:
            workers = [{"name": w.name, "last_seen": w.last_seen.isoformat() + "Z",
                        "current_job": w.current_job}
                       for w in svc.registry.workers_seen(svc.settings.worker_seen_window)]
            counts = svc.registry.counts()
        except Exception:  # noqa: BLE001
            pass
    healthy = registry.ok and broker.ok and store.ok
    body = Health(status="ok" if healthy else "unavailable", mode=mode,
                  solver_version=solver.__version__, registry=registry, broker=broker,
                  result_store=store, workers=workers, jobs=counts)
    if healthy:
        return body
    return JSONResponse(body.model_dump(mode="json"), status_code=503)
