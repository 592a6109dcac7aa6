"""FastAPI application factory: ``create_app(settings)``.

``uvicorn --factory service.app:create_app`` or ``hockle serve``. The API validates cases, keeps
the job registry and serves results; it never runs a solve: jobs go to the Celery queue.
"""
from __future__ import annotations

import logging
import threading
from contextlib import asynccontextmanager

from fastapi import Depends, FastAPI
from fastapi.openapi.utils import get_openapi

from .auth import AuthMiddleware, HostAllowList
from .dashboard import UI_URL, install_dashboard
from .deps import Services, known_query_only, services
from .docs import ASSETS_URL, DOCS_URL, OAUTH2_REDIRECT_URL, REDOC_URL, install_docs
from .problems import CatchAllMiddleware, install_handlers
from .queue import Enqueuer
from .registry import REGISTRY_UNAVAILABLE, Registry
from .routers import continuations, health, jobs, metrics, results, sweeps
from .settings import Settings, get_settings
from .store import ResultStore

log = logging.getLogger("hockle.api")

API_DESCRIPTION = """\
Simulation service for the dynamics of twisted elastic rods (hockle).

Submit a case (`POST /v1/jobs`, the case spec schema v1 as JSON or YAML), poll its status,
dismiss it, and query its time histories. Errors are RFC 9457 problem details
(`application/problem+json`) whose `errors` list names each bad field by its path.
"""


__all__ = ["create_app", "Services", "services"]


def create_app(settings: Settings | None = None, *, enqueuer: Enqueuer | None = None) -> FastAPI:
    """The API. With API keys (``HOCKLE_API_KEYS`` / ``HOCKLE_API_KEYS_FILE``) every route but
    ``/v1/health`` and the docs needs one (:mod:`service.auth`); a bad key setting raises
    ``ValueError`` naming the variable before anything starts."""
    settings = settings or get_settings()
    api_keys = settings.load_api_keys()
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    # a request waits on the registry at most registry_request_timeout (then 503)
    registry = Registry(settings.registry_url, busy_timeout=settings.registry_busy_timeout,
                        request_timeout=settings.registry_request_timeout)
    registry.create_schema(auto_migrate=settings.auto_migrate)
    store = ResultStore(settings.results_dir)
    store.ensure()
    svc = Services(settings, registry, store, enqueuer or Enqueuer(settings))
    stop = threading.Event()

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        _warm_up(svc)
        thread = threading.Thread(target=_reaper, args=(svc, stop), name="hockle-reaper",
                                  daemon=True)
        thread.start()
        try:
            yield
        finally:
            stop.set()
            thread.join(timeout=5)
            svc.enqueuer.close()
            registry.dispose()

    app = FastAPI(
        title="hockle",
        version=_version(),
        description=API_DESCRIPTION,
        lifespan=lifespan,
        docs_url=None,  # served from the package's own assets: service/docs.py
        redoc_url=None,
        openapi_url="/openapi.json",
    )
    app.state.services = svc
    app.state.auth_enabled = bool(api_keys)
    install_handlers(app)
    install_docs(app)
    app.add_middleware(
        AuthMiddleware, keys=api_keys, rate=settings.rate_limit, burst=settings.rate_limit_burst,
        public_paths=("/v1/health", metrics.PATH, app.openapi_url, DOCS_URL, REDOC_URL,
                      OAUTH2_REDIRECT_URL, UI_URL),
        public_prefixes=(ASSETS_URL + "/", UI_URL + "/"))
    allowed = settings.allowed_host_names()
    if not api_keys and allowed is not None:   # keys are the protection when set
        # probes and scrapers name the pod's address; these answer counts, no job's data
        app.add_middleware(HostAllowList, allowed=allowed,
                           exempt_paths=("/v1/health", metrics.PATH))
    app.add_middleware(CatchAllMiddleware)  # outermost: the last word on an unexpected error

    checked = [Depends(known_query_only)]  # a misspelt query parameter is a 422, not ignored
    app.include_router(jobs.router, prefix="/v1", dependencies=checked)
    app.include_router(results.router, prefix="/v1", dependencies=checked)
    app.include_router(sweeps.router, prefix="/v1", dependencies=checked)
    app.include_router(continuations.router, prefix="/v1", dependencies=checked)
    app.include_router(health.router, prefix="/v1", dependencies=checked)
    app.include_router(metrics.router)
    install_dashboard(app)  # /ui/ (static, public) and its /v1/ui routes
    app.openapi = lambda: _openapi(app)  # type: ignore[method-assign]
    return app


def _warm_up(svc: Services) -> None:
    """Import the case model and connect to the broker before the first request needs them,
    so that a burst of first submissions does not stall every request on the import lock."""
    from solver.case import Case

    Case.model_json_schema()
    try:
        svc.enqueuer.ping()
    except Exception:  # noqa: BLE001 - reported by /v1/health; submissions answer 503
        log.warning("broker not reachable at start-up", exc_info=True)


def _reaper(svc: Services, stop: threading.Event) -> None:
    """Every heartbeat_interval: fail jobs killed at their hard time limit, queue again the jobs
    of lost workers and the accepted jobs whose message is lost (:func:`service.queue.sweep`;
    every worker's heartbeat thread runs the same sweep)."""
    from .queue import RegistryWatch, sweep

    watch = RegistryWatch()       # a job's silence counts only while the registry took writes
    while not stop.wait(svc.settings.heartbeat_interval):
        try:
            sweep(svc.registry, svc.enqueuer, svc.settings, log, watch)
        except REGISTRY_UNAVAILABLE as exc:  # registry briefly down: next sweep
            log.warning("sweep failed, registry unavailable: %s", str(exc).splitlines()[0][:200])
        except Exception:  # noqa: BLE001
            log.warning("sweep failed", exc_info=True)


def _version() -> str:
    import solver

    return solver.__version__


def _openapi(app: FastAPI) -> dict:
    """The generated schema plus the case spec as the request body of POST /v1/jobs."""
    if app.openapi_schema:
        return app.openapi_schema
    schema = get_openapi(title=app.title, version=app.version, description=app.description,
                         routes=app.routes)
    from solver.case import Case

    case_schema = Case.model_json_schema(ref_template="#/components/schemas/{model}")
    components = schema.setdefault("components", {}).setdefault("schemas", {})
    for name, sub in case_schema.pop("$defs", {}).items():
        components.setdefault(name, sub)
    components["Case"] = case_schema
    post = schema["paths"]["/v1/jobs"]["post"]
    post["requestBody"] = {
        "required": True,
        "description": "The case spec, schema_version 1 (JSON, or YAML with Content-Type "
        "application/yaml).",
        "content": {
            "application/json": {"schema": {"$ref": "#/components/schemas/Case"}},
            "application/yaml": {"schema": {"$ref": "#/components/schemas/Case"}},
        },
    }
    if getattr(app.state, "auth_enabled", False):
        _document_auth(schema)
    app.openapi_schema = schema
    return schema


def _document_auth(schema: dict) -> None:
    """Bearer authentication in the OpenAPI document (Swagger UI's Authorize button), with the
    401 and 429 answers, on every operation but the health check and the metrics."""
    schema["components"].setdefault("securitySchemes", {})["apiKey"] = {
        "type": "http", "scheme": "bearer",
        "description": "An API key of this service (HOCKLE_API_KEYS): "
                       "`Authorization: Bearer <key>`."}
    answers = {401: "No API key, or one this service does not know",
               429: "The key's rate limit is reached: retry after Retry-After seconds"}
    for item in schema["paths"].values():
        for operation in item.values():
            if not isinstance(operation, dict) or operation.get("operationId") in (
                    "get_health", "get_metrics"):   # public, as the probes and scrapers are
                continue
            operation["security"] = [{"apiKey": []}]
            responses = operation.setdefault("responses", {})
            for code, description in answers.items():
                responses.setdefault(str(code), {
                    "description": description,
                    "content": {"application/problem+json": {
                        "schema": {"$ref": "#/components/schemas/Problem"}}}})
