"""RFC 9457 problem details: every error the API answers is ``application/problem+json``.

A body has ``type`` (a URN naming the class of problem), ``title``, ``status``, ``detail``,
``instance`` and, for invalid input, ``errors``: one ``{"loc", "msg", "type"}`` per bad field,
``loc`` being the field's path (``rod.diameter.value[2]``, ``query.time``). Tracebacks never
reach a client: unexpected exceptions are logged and answered with a generic 500 problem.
"""
from __future__ import annotations

import logging
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field
from starlette.exceptions import HTTPException as StarletteHTTPException

__all__ = ["PROBLEM_MEDIA_TYPE", "Problem", "ProblemError", "FieldError", "install_handlers",
           "problem_responses"]

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


def problem_response(
    request: Request,
    status: int,
    type_: str,
    title: str,
    detail: str | None = None,
    errors: list[dict[str, Any]] | None = None,
    headers: dict[str, str] | None = None,
) -> JSONResponse:
    body: dict[str, Any] = {
        "type": type_,
        "title": title,
        "status": status,
        "detail": detail,
        "instance": request.url.path,
    }
    if errors is not None:
        body["errors"] = errors
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

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception):
        log.exception("unhandled error on %s %s", request.method, request.url.path)
        return problem_response(
            request, 500, "urn:hockle:problem:internal-error", "Internal Server Error",
            "the server met an unexpected error; it has been logged",
        )


def problem_responses(*codes: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` entries for problem bodies."""
    return {
        code: {"model": Problem, "content": {PROBLEM_MEDIA_TYPE: {}}, "description": "Problem details"}
        for code in codes
    }
