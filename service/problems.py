"""RFC 9457 problem details: every error the API answers is ``application/problem+json``.

A body has ``type`` (a URN naming the class of problem), ``title``, ``status``, ``detail``,
``instance`` and, for invalid input, ``errors``: one ``{"loc", "msg", "type"}`` per bad field,
``loc`` being the field's path (``rod.diameter.value[2]``, ``query.time``). Tracebacks never
reach a client: an unexpected exception is logged once and answered with one generic 500
problem by :class:`CatchAllMiddleware`, and the client's keep-alive connection stays usable. A
registry that is locked, slow or down (its errors and time-outs, :data:`REGISTRY_UNAVAILABLE`)
is a 503 ``registry-unavailable`` problem with ``Retry-After``.
"""
from __future__ import annotations

import logging
import math
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from .registry import REGISTRY_UNAVAILABLE

__all__ = ["PROBLEM_MEDIA_TYPE", "Problem", "ProblemError", "FieldError", "install_handlers",
           "problem_responses", "CatchAllMiddleware"]

PROBLEM_MEDIA_TYPE = "application/problem+json"
log = logging.getLogger("hockle.api")


class FieldError(BaseModel):
    loc: str = Field(..., description="Path of the bad field, e.g. rod.diameter or query.time.")
    msg: str = Field(..., description="What is wrong and what is allowed.")
    type: str = Field(..., description="Machine-readable error type.")


class Problem(BaseModel):
    type: str = Field("about:blank", description="URI naming the class of problem.")
    title: str
    status: int
    detail: str | None = None
    instance: str | None = None
    errors: list[FieldError] | None = None


class ProblemError(Exception):
    """Raise in a route to answer with a problem body."""

    def __init__(
        self,
        status: int,
        slug: str,
        title: str,
        detail: str | None = None,
        *,
        errors: list[dict[str, Any]] | None = None,
        headers: dict[str, str] | None = None,
    ):
        super().__init__(detail or title)
        self.status = status
        self.slug = slug
        self.title = title
        self.detail = detail
        self.errors = errors
        self.headers = headers or {}


def problem_body(type_: str, title: str, status: int, detail: str | None, instance: str,
                 errors: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    body: dict[str, Any] = {"type": type_, "title": title, "status": status, "detail": detail,
                            "instance": instance}
    if errors is not None:
        body["errors"] = errors
    return body


def problem_response(
    request: Request,
    status: int,
    type_: str,
    title: str,
    detail: str | None = None,
    errors: list[dict[str, Any]] | None = None,
    headers: dict[str, str] | None = None,
) -> JSONResponse:
    body = problem_body(type_, title, status, detail, request.url.path, errors)
    return JSONResponse(body, status_code=status, media_type=PROBLEM_MEDIA_TYPE, headers=headers)


def _loc(parts) -> str:
    out = ""
    for part in parts:
        if isinstance(part, int) and not isinstance(part, bool):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out


def install_handlers(app: FastAPI) -> None:
    @app.exception_handler(ProblemError)
    async def _problem(request: Request, exc: ProblemError):
        return problem_response(
            request, exc.status, f"urn:hockle:problem:{exc.slug}", exc.title, exc.detail,
            exc.errors, exc.headers,
        )

    @app.exception_handler(RequestValidationError)
    async def _request_validation(request: Request, exc: RequestValidationError):
        errors = [
            {"loc": _loc(err.get("loc", ())), "msg": str(err.get("msg", "")),
             "type": str(err.get("type", "value_error"))}
            for err in exc.errors()
        ]
        return problem_response(
            request, 422, "urn:hockle:problem:invalid-request", "Invalid request",
            "a query parameter, header or path parameter is not valid", errors,
        )

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException):
        detail = exc.detail if isinstance(exc.detail, str) else None
        title = {404: "Not Found", 405: "Method Not Allowed"}.get(exc.status_code, "HTTP error")
        return problem_response(request, exc.status_code, "about:blank", title, detail,
                                headers=getattr(exc, "headers", None))

    async def _registry_unavailable(request: Request, exc: Exception):
        settings = request.app.state.services.settings
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]
        log.warning("registry unavailable on %s %s: %s", request.method, request.url.path, first)
        retry = max(1, math.ceil(settings.registry_request_timeout))
        return problem_response(
            request, 503, "urn:hockle:problem:registry-unavailable", "Job registry unavailable",
            "the job registry did not answer within this service's time-out "
            f"(HOCKLE_REGISTRY_REQUEST_TIMEOUT = {settings.registry_request_timeout:g} s): it "
            "is locked, overloaded or down; nothing was changed by this request, try again "
            "after Retry-After seconds", headers={"Retry-After": str(retry)})

    for exc_class in REGISTRY_UNAVAILABLE:
        app.add_exception_handler(exc_class, _registry_unavailable)


class CatchAllMiddleware:
    """The last word on an unexpected exception: one 500 problem, one log record with the
    traceback, and no exception left for the server, so the client's keep-alive connection
    stays open (Starlette's server-error middleware re-raises after its handler answered;
    uvicorn then logs the traceback a second time and closes the connection).

    A pure ASGI middleware, added outermost (``app.add_middleware``, after the others). If the
    response had already started, nothing valid can follow: the exception goes on to the
    server, which closes the connection.
    """

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = False

        async def tracked(message: Message) -> None:
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        try:
            await self.app(scope, receive, tracked)
        except Exception:
            if started:
                raise
            log.exception("unhandled error on %s %s", scope.get("method"), scope.get("path"))
            response = JSONResponse(
                problem_body("urn:hockle:problem:internal-error", "Internal Server Error", 500,
                             "the server met an unexpected error; it has been logged",
                             scope.get("path", "")),
                status_code=500, media_type=PROBLEM_MEDIA_TYPE)
            await response(scope, receive, send)


def problem_responses(*codes: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` entries for problem bodies."""
    return {
        code: {"model": Problem, "content": {PROBLEM_MEDIA_TYPE: {}}, "description": "Problem details"}
        for code in codes
    }
