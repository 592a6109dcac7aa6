"""Fixtures of the service tests (defined in svc_support.py, which the tests import too):
``settings`` and ``client``, the in-process service of a test module (its
``SERVICE_SETTINGS`` over the defaults), and the real servers ``redis_server`` and
``pg_url``."""
import os

from svc_support import client, pg_url, redis_server, settings  # noqa: F401

# In-process tests talk to the app through Starlette's TestClient, whose requests name the
# host "testserver": without API keys the app answers only the hosts it is allowed
# (HOCKLE_ALLOWED_HOSTS; tests of the default list pass allowed_hosts themselves). The API
# and worker processes of svc_support.Stack get none of the HOCKLE_ variables of this one.
os.environ.setdefault("HOCKLE_ALLOWED_HOSTS", "localhost,127.0.0.1,::1,testserver")
