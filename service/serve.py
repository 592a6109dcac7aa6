"""``hockle serve`` / ``python -m service``: the API, plus a local worker in embedded mode.

With no ``HOCKLE_BROKER_URL`` the service is *embedded*: the registry is SQLite and the Celery
broker is kombu's SQLAlchemy transport on a SQLite file, both under ``HOCKLE_DATA_DIR``, and a
worker process (``python -m worker``, the same task code as the distributed mode) is started
next to the API and stopped with it. With a broker URL the API only enqueues.
"""
from __future__ import annotations

import argparse
import logging
import os
import signal
import subprocess
import sys

log = logging.getLogger("hockle.serve")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--host", default=None, help="bind address (default HOCKLE_HOST, 127.0.0.1)")
    parser.add_argument("--port", type=int, default=None, help="port (default HOCKLE_PORT, 8000)")
    parser.add_argument(
        "--workers", type=int, default=None,
        help="embedded mode: solver processes of the local worker (default "
             "HOCKLE_WORKER_CONCURRENCY, 1); 0 starts none",
    )
    parser.add_argument("--no-worker", action="store_true",
                        help="do not start the local worker even in embedded mode")


def run(args: argparse.Namespace) -> int:
    import uvicorn

    from .settings import SECRET_FIELDS, get_settings

    overrides = {"host": args.host, "port": args.port}
    for key, value in overrides.items():
        if value is not None:
            os.environ[f"HOCKLE_{key.upper()}"] = str(value)
    get_settings.cache_clear()
    settings = get_settings()
    logging.basicConfig(level=settings.log_level.upper(),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        api_keys = settings.load_api_keys()
    except ValueError as exc:
        log.error("cannot start: %s", exc)
        return 2
    if not api_keys:
        warn_if_open(settings.host)
    settings.data_dir.mkdir(parents=True, exist_ok=True)

    worker = None
    concurrency = settings.worker_concurrency if args.workers is None else args.workers
    if settings.embedded and settings.embedded_worker and not args.no_worker and concurrency > 0:
        # the worker never authenticates: it gets no API key
        secrets = {f"HOCKLE_{name.upper()}" for name in SECRET_FIELDS}
        env = {k: v for k, v in os.environ.items() if k not in secrets}
        env.update(settings.child_env())
        if "HOCKLE_WORKER_NICE" not in os.environ:
            env["HOCKLE_WORKER_NICE"] = "10"  # the API on this machine stays responsive
        cmd = [sys.executable, "-m", "worker", "--concurrency", str(concurrency),
               "--hostname", f"embedded-{os.getpid()}@%h"]
        log.info("embedded mode: starting a local worker: %s", " ".join(cmd))
        worker = subprocess.Popen(cmd, env=env)
    elif settings.embedded:
        log.info("embedded mode without a local worker: jobs wait for `hockle worker`")
    # uvicorn re-raises the SIGTERM it caught once it has shut down; with the default action
    # that kills this process before the `finally` below, and the embedded worker was left
    # running (seen: an orphan worker after `kill <hockle serve>`). A handler of our own, which
    # uvicorn restores before re-raising, turns it into SystemExit so the worker is stopped.
    signal.signal(signal.SIGTERM, _exit_on_signal)
    try:
        from .app import create_app

        app = create_app(settings)
        uvicorn.run(app, host=settings.host, port=settings.port,
                    log_level=settings.log_level.lower(), access_log=False,
                    timeout_keep_alive=30)
    finally:
        if worker is not None and worker.poll() is None:
            worker.send_signal(signal.SIGTERM)  # warm shutdown: a running job is requeued
            try:
                worker.wait(timeout=30)
            except subprocess.TimeoutExpired:
                worker.kill()
                worker.wait()
    return 0


def _exit_on_signal(signum, _frame) -> None:
    """SIGTERM after uvicorn's shutdown: leave through the ``finally`` of :func:`run`."""
    raise SystemExit(128 + signum)


def warn_if_open(host: str) -> bool:
    """Log a loud warning when the API binds an address other machines can reach without API
    keys (anyone who reaches it may read, submit and dismiss every job). True if it warned."""
    from .auth import is_loopback

    if is_loopback(host):
        return False
    rule = "!" * 78
    log.warning(
        "\n%s\n!! NO AUTHENTICATION: the API binds %s without API keys.\n"
        "!! Anyone who can reach this address can submit, read and dismiss every job.\n"
        "!! Set HOCKLE_API_KEYS (or HOCKLE_API_KEYS_FILE), or bind 127.0.0.1.\n"
        "!! Without keys it answers only requests naming an allowed host (Host header):\n"
        "!! %s (HOCKLE_ALLOWED_HOSTS; add the names clients use).\n%s",
        rule, host, _allowed(), rule)
    return True


def _allowed() -> str:
    from .settings import get_settings

    names = get_settings().allowed_host_names()
    return "any host (*)" if names is None else ", ".join(sorted(names))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m service", description=__doc__.split("\n\n")[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))
