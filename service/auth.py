"""API keys, job ownership and rate limits.

With ``HOCKLE_API_KEYS`` (or ``HOCKLE_API_KEYS_FILE``) set, every request but ``/v1/health``
and the documentation pages must carry ``Authorization: Bearer <key>``; :class:`AuthMiddleware`
answers 401 (``WWW-Authenticate: Bearer``) otherwise, and 429 (``Retry-After``) when the key
has spent its token bucket. A valid request's *owner* is :func:`owner_id` of its key (a hash:
the registry never holds a key) and the routes read it with the :func:`caller` dependency:
jobs are recorded with it, and another owner's job is answered as if it did not exist (404).

Without keys, ``caller`` is ``None``: no authentication, no ownership, no rate limit (the
embedded service on 127.0.0.1).

The check is a middleware, not a route dependency, so that no route can be added without it.
"""
from __future__ import annotations

import hashlib
import math
import threading
import time
from typing import Iterable

from starlette.requests import Request
from starlette.types import ASGIApp, Receive, Scope, Send

from .problems import problem_response
from .settings import host_name

__all__ = ["owner_id", "RateLimiter", "AuthMiddleware", "HostAllowList", "caller",
           "is_loopback", "host_name", "authenticated"]

REALM = "hockle"


def owner_id(key: str) -> str:
    """The owner id of an API key as the registry stores it: SHA-256 hex of the key (with a
    fixed prefix). An operator who holds a key can compute it to find that key's jobs."""
    return hashlib.sha256(f"hockle-api-key:{key}".encode()).hexdigest()


class RateLimiter:
    """A token bucket per owner: ``burst`` tokens at most, refilled at ``rate`` per second;
    each request takes one. Thread-safe; holds one small entry per key that was used."""

    def __init__(self, rate: float, burst: int):
        self.rate = float(rate)
        self.burst = float(burst)
        self._buckets: dict[str, tuple[float, float]] = {}
        self._lock = threading.Lock()

    def take(self, owner: str, now: float | None = None) -> float:
        """Take a token for ``owner``: 0.0 when granted, else the seconds until one is free."""
        if self.rate <= 0:
            return 0.0
        now = time.monotonic() if now is None else now
        with self._lock:
            tokens, last = self._buckets.get(owner, (self.burst, now))
            tokens = min(self.burst, tokens + (now - last) * self.rate)
            if tokens >= 1.0:
                self._buckets[owner] = (tokens - 1.0, now)
                return 0.0
            self._buckets[owner] = (tokens, now)
            return (1.0 - tokens) / self.rate


class AuthMiddleware:
    """ASGI middleware: authenticate the key, rate-limit it, and put its owner id in the
    request's state (``request.state.owner``, ``None`` without keys).

    ``public_paths`` (exact) and ``public_prefixes`` need no key (health, docs, docs assets);
    they are not rate-limited either.
    """

    def __init__(self, app: ASGIApp, *, keys: Iterable[str], rate: float, burst: int,
                 public_paths: Iterable[str] = (), public_prefixes: Iterable[str] = ()):
        self.app = app
        self.owners = {owner_id(key) for key in keys}
        self.limiter = RateLimiter(rate, burst)
        self.public_paths = frozenset(public_paths)
        self.public_prefixes = tuple(public_prefixes)

    @property
    def enabled(self) -> bool:
        """True when keys are configured."""
        return bool(self.owners)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        scope.setdefault("state", {})["owner"] = None
        path = scope.get("path", "")
        if not self.owners:
            await self.app(scope, receive, send)
            return
        if path in self.public_paths or path.startswith(self.public_prefixes):
            # no key needed; a valid one still identifies the caller (the health check
            # names the workers only to a caller with a key)
            key = _bearer(Request(scope).headers.get("authorization"))
            if key is not None and owner_id(key) in self.owners:
                scope["state"]["owner"] = owner_id(key)
            await self.app(scope, receive, send)
            return
        request = Request(scope)
        key = _bearer(request.headers.get("authorization"))
        if key is None:
            response = problem_response(
                request, 401, "urn:hockle:problem:unauthorized", "Unauthorized",
                "this service needs an API key: send the header 'Authorization: Bearer <key>'",
                headers={"WWW-Authenticate": f'Bearer realm="{REALM}"'})
            await response(scope, receive, send)
            return
        owner = owner_id(key)
        if owner not in self.owners:
            response = problem_response(
                request, 401, "urn:hockle:problem:invalid-api-key", "Unauthorized",
                "the API key in the Authorization header is not one this service knows",
                headers={"WWW-Authenticate":
                         f'Bearer realm="{REALM}", error="invalid_token", '
                         f'error_description="unknown API key"'})
            await response(scope, receive, send)
            return
        wait = self.limiter.take(owner)
        if wait > 0:
            retry = max(1, math.ceil(wait))
            response = problem_response(
                request, 429, "urn:hockle:problem:rate-limited", "Too Many Requests",
                f"this API key made more than {self.limiter.burst:.0f} requests at once or "
                f"{self.limiter.rate:g} per second on average (HOCKLE_RATE_LIMIT_BURST, "
                f"HOCKLE_RATE_LIMIT); retry after {retry} s",
                headers={"Retry-After": str(retry)})
            await response(scope, receive, send)
            return
        scope["state"]["owner"] = owner
        await self.app(scope, receive, send)


class HostAllowList:
    """ASGI middleware for a service without API keys: a request whose ``Host`` header names
    no host of ``allowed`` (:meth:`service.settings.Settings.allowed_host_names`) is answered
    400 ``host-not-allowed``. A web page the user opens can otherwise reach an API on
    127.0.0.1 through a name of its own that its DNS answers with 127.0.0.1 (DNS rebinding)
    and read, submit and dismiss jobs: the browser then sends that name as Host.
    ``exempt_paths`` (the health checks and the metrics: a probe or a scraper names the
    pod's address) are not checked;
    a request without Host (HTTP/1.0) is not either (no browser sends one)."""

    def __init__(self, app: ASGIApp, *, allowed: Iterable[str],
                 exempt_paths: Iterable[str] = ()):
        self.app = app
        self.allowed = frozenset(allowed)
        self.exempt = frozenset(exempt_paths)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket") or scope.get("path") in self.exempt:
            await self.app(scope, receive, send)
            return
        header = next((v for k, v in scope.get("headers", ()) if k == b"host"), None)
        if header is None:
            await self.app(scope, receive, send)
            return
        name = host_name(header.decode("latin-1"))
        if name in self.allowed:
            await self.app(scope, receive, send)
            return
        shown = "".join(c if c.isprintable() else "?" for c in name)[:100]
        allowed = ", ".join(sorted(self.allowed))
        response = problem_response(
            Request(scope), 400, "urn:hockle:problem:host-not-allowed", "Host not allowed",
            f"this service has no API keys and answers only the hosts {allowed} "
            f"(HOCKLE_ALLOWED_HOSTS), not {shown!r}: add the name clients use to "
            "HOCKLE_ALLOWED_HOSTS, or set API keys",
            errors=[{"loc": "header.Host", "type": "host_not_allowed",
                     "msg": f"{shown!r} is not one of: {allowed}"}])
        await response(scope, receive, send)


def authenticated(request: Request) -> bool:
    """True when the request carries a valid API key (on any route, public ones too)."""
    return getattr(request.state, "owner", None) is not None


def _bearer(header: str | None) -> str | None:
    """The token of an ``Authorization: Bearer <token>`` header (scheme case-insensitive)."""
    if not header:
        return None
    scheme, _, token = header.strip().partition(" ")
    token = token.strip()
    if scheme.lower() != "bearer" or not token:
        return None
    return token


async def caller(request: Request) -> str | None:
    """FastAPI dependency: the owner id of the request's API key, or ``None`` when the service
    runs without keys (then every job is everyone's). A coroutine: resolving it takes no
    thread from the pool that blocking routes use."""
    return getattr(request.state, "owner", None)


def is_loopback(host: str) -> bool:
    """True for addresses only this machine can reach (127.0.0.0/8, ::1, localhost)."""
    import ipaddress

    if host.strip().lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False
