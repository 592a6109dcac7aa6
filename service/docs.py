"""Interactive API docs (Swagger UI at ``/docs``, ReDoc at ``/redoc``) served without internet.

FastAPI's default pages load Swagger UI and ReDoc from a CDN and stay blank on a cluster that
cannot reach it. Here the pages are FastAPI's own (``get_swagger_ui_html``,
``get_redoc_html``, the documented way to self-host the docs assets) pointed at files this
service serves itself under :data:`ASSETS_URL`: the Swagger UI 5 and ReDoc 2 bundles that
the ``fastapi-offline`` package ships (Swagger UI under Apache-2.0, ReDoc under MIT, the
package itself MIT). Google fonts and Swagger UI's online validator badge are turned off, so
no page asks any other host for anything.

Each page is served with a Content-Security-Policy (:func:`docs_csp`): scripts from this
origin and the page's own inline script by its hash, no other origin for anything, no
framing. ReDoc's bundle compiles JSON schemas with ``new Function`` (ajv), so ``/redoc``
also allows ``'unsafe-eval'``; Swagger UI's does not need it.
"""
from __future__ import annotations

import base64
import hashlib
import re
from importlib import resources
from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.openapi.docs import (
    get_redoc_html,
    get_swagger_ui_html,
    get_swagger_ui_oauth2_redirect_html,
)
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles

__all__ = ["DOCS_URL", "REDOC_URL", "OAUTH2_REDIRECT_URL", "ASSETS_URL", "ASSET_FILES",
           "assets_dir", "install_docs", "docs_csp"]

DOCS_URL = "/docs"
REDOC_URL = "/redoc"
OAUTH2_REDIRECT_URL = "/docs/oauth2-redirect"
ASSETS_URL = "/docs-assets"
ASSET_FILES = ("swagger-ui-bundle.js", "swagger-ui.css", "redoc.standalone.js", "favicon.png")


def assets_dir() -> Path:
    """The directory of the packaged Swagger UI and ReDoc files (``fastapi_offline/static``).

    Raises ``RuntimeError`` naming the missing file when the installed package lacks one.
    """
    path = Path(str(resources.files("fastapi_offline") / "static"))
    missing = [name for name in ASSET_FILES if not (path / name).is_file()]
    if missing:
        raise RuntimeError(f"the docs assets {', '.join(missing)} are missing from {path}: "
                           "reinstall the fastapi-offline package")
    return path


_INLINE_SCRIPT = re.compile(r"<script>(.*?)</script>", re.S)


def docs_csp(html: str, *, allow_eval: bool = False) -> str:
    """The Content-Security-Policy of a docs page whose HTML is ``html``: everything from
    this origin only (scripts, styles, images, the OpenAPI document, the search worker),
    data: images and fonts, blob: workers, each inline ``<script>`` of the page by its
    SHA-256, inline styles (both UIs set style attributes), no plugins, no framing, no
    <base>; ``allow_eval`` adds ``'unsafe-eval'`` (ReDoc)."""
    hashes = " ".join(
        "'sha256-" + base64.b64encode(hashlib.sha256(body.encode()).digest()).decode() + "'"
        for body in _INLINE_SCRIPT.findall(html))
    script = " ".join(filter(None, ["'self'", hashes, "'unsafe-eval'" if allow_eval else ""]))
    return (f"default-src 'none'; script-src {script}; style-src 'self' 'unsafe-inline'; "
            "img-src 'self' data:; font-src 'self' data:; connect-src 'self'; "
            "worker-src 'self' blob:; base-uri 'none'; form-action 'self'; "
            "frame-ancestors 'none'; object-src 'none'")


def _secured(page: HTMLResponse, *, allow_eval: bool = False) -> HTMLResponse:
    page.headers["Content-Security-Policy"] = docs_csp(page.body.decode(), allow_eval=allow_eval)
    page.headers["X-Content-Type-Options"] = "nosniff"
    page.headers["Referrer-Policy"] = "no-referrer"
    return page


def install_docs(app: FastAPI) -> None:
    """Add ``/docs``, its OAuth2 redirect page, ``/redoc`` and the assets under
    :data:`ASSETS_URL` to ``app`` (created with ``docs_url=None, redoc_url=None``)."""
    app.mount(ASSETS_URL, StaticFiles(directory=assets_dir()), name="docs-assets")

    @app.get(DOCS_URL, include_in_schema=False)
    async def swagger_ui(request: Request) -> HTMLResponse:
        root = request.scope.get("root_path", "")
        return _secured(get_swagger_ui_html(
            openapi_url=f"{root}{app.openapi_url}",
            title=f"{app.title} - Swagger UI",
            oauth2_redirect_url=f"{root}{OAUTH2_REDIRECT_URL}",
            swagger_js_url=f"{root}{ASSETS_URL}/swagger-ui-bundle.js",
            swagger_css_url=f"{root}{ASSETS_URL}/swagger-ui.css",
            swagger_favicon_url=f"{root}{ASSETS_URL}/favicon.png",
            # validatorUrl None: no badge fetched from validator.swagger.io
            swagger_ui_parameters={"validatorUrl": None, "persistAuthorization": True},
        ))

    @app.get(OAUTH2_REDIRECT_URL, include_in_schema=False)
    async def swagger_ui_redirect() -> HTMLResponse:
        return _secured(get_swagger_ui_oauth2_redirect_html())

    @app.get(REDOC_URL, include_in_schema=False)
    async def redoc(request: Request) -> HTMLResponse:
        root = request.scope.get("root_path", "")
        return _secured(get_redoc_html(
            openapi_url=f"{root}{app.openapi_url}",
            title=f"{app.title} - ReDoc",
            redoc_js_url=f"{root}{ASSETS_URL}/redoc.standalone.js",
            redoc_favicon_url=f"{root}{ASSETS_URL}/favicon.png",
            with_google_fonts=False,
        ), allow_eval=True)
