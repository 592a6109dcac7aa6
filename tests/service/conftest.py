"""Fixtures of the service tests (defined in svc_support.py, which the tests import too)."""
from svc_support import pg_url, redis_server  # noqa: F401
