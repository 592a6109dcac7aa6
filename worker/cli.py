"""Command line of a worker process, shared by ``hockle worker`` and ``python -m worker``."""
from __future__ import annotations

import argparse
import os
import socket
import sys


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--concurrency", "-c", type=int, default=None,
        help="solver processes in this worker (default HOCKLE_WORKER_CONCURRENCY, 1)",
    )
    parser.add_argument(
        "--hostname", "-n", default=None,
        help="node name, unique per worker (default hockle-<pid>@<host>)",
    )
    parser.add_argument("--loglevel", "-l", default=None, help="log level (default HOCKLE_LOG_LEVEL)")


def celery_argv(args: argparse.Namespace) -> list[str]:
    from service.settings import get_settings

    settings = get_settings()
    concurrency = args.concurrency or settings.worker_concurrency
    hostname = args.hostname or f"hockle-{os.getpid()}@{socket.gethostname()}"
    return [
        "worker",
        "--pool=prefork",
        f"--concurrency={concurrency}",
        f"--queues={settings.queue}",
        f"--hostname={hostname}",
        f"--loglevel={args.loglevel or settings.log_level}",
        "--without-gossip",
        "--without-mingle",
        "--prefetch-multiplier=1",
    ]


def schema_ready() -> str | None:
    """Bring the registry's schema to head (``HOCKLE_AUTO_MIGRATE``) or check it, before Celery
    starts: None when ready, else why the worker must not start (a schema this code cannot
    use). A registry that does not answer is not refused here: the worker starts and retries
    it, as before."""
    import logging

    from service.migrations import SchemaNotCurrent
    from service.registry import Registry
    from service.settings import get_settings

    settings = get_settings()
    registry = Registry(settings.registry_url, busy_timeout=settings.registry_busy_timeout)
    try:
        registry.create_schema(auto_migrate=settings.auto_migrate)
    except SchemaNotCurrent as exc:
        return str(exc)
    except Exception as exc:  # noqa: BLE001 - unreachable now: the worker retries later
        logging.getLogger("hockle.worker").warning(
            "registry schema not checked before start (%s: %s)", type(exc).__name__, exc)
    finally:
        registry.dispose()
    return None


def run(args: argparse.Namespace) -> int:
    if args.concurrency:
        os.environ["HOCKLE_WORKER_CONCURRENCY"] = str(args.concurrency)
    argv = celery_argv(args)
    problem = schema_ready()
    if problem is not None:
        print(f"hockle worker: not started: {problem}", file=sys.stderr)
        return 1
    from worker.app import app  # pins BLAS threads before numpy is imported

    load_kernels()
    app.worker_main(argv=argv)
    return 0


def load_kernels() -> None:
    """Load the solver's compiled kernels before the pool forks, so that no job pays for
    them. The first start after an installation (or a change of the solver) compiles
    them into numba's cache, 1.5 to 6 minutes on 2 cores (``python
    benchmarks/compile_time.py``), and says so on stderr, with how long it took; later
    starts load them in about 2 s and say nothing."""
    import time

    from solver import warm_up
    from solver._kernel_cache import kernels_cached

    cached = kernels_cached()
    if not cached:
        print("hockle worker: compiling the solver's kernels before the pool starts (once "
              "after installing or changing the solver; 1.5 to 6 minutes on 2 cores) ...",
              file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    warm_up()
    if not cached:
        print(f"hockle worker: kernels compiled in {time.perf_counter() - t0:.0f} s",
              file=sys.stderr, flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m worker", description=__doc__)
    add_arguments(parser)
    return run(parser.parse_args(argv))
