"""Fixtures of the service tests (defined in svc_support.py, which the tests import too):
``settings`` and ``client``, the in-process service of a test module (its
``SERVICE_SETTINGS`` over the defaults), and the real servers ``redis_server`` and
``pg_url``."""
from svc_support import client, pg_url, redis_server, settings  # noqa: F401
