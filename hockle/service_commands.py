"""The service's subcommands of ``hockle``: ``serve``, ``worker``, ``submit`` and ``db``.

``hockle.cli`` calls :func:`register` with its argparse subparsers; each subcommand sets a
``func`` default that takes the parsed arguments and returns the exit code.

    hockle serve [--host H] [--port P] [--workers N] [--no-worker]
    hockle worker [--concurrency N] [--hostname NAME] [--loglevel L]
    hockle submit CASE [--url URL] [--api-key KEY] [--wait] [-o OUT.nc] [--idempotency-key K]
                       [--fresh] [--time-limit S]
                       [--continue --parameter PATH --to VALUE [--time T] [--switch]
                        [--max-points N] [--step F] [--shapes-every K]]
    hockle db {current,upgrade,downgrade,check,history,revision} [--url URL]

``submit`` exit codes: 0 accepted (or, with --wait, successful); 1 failed; 2 invalid case or
other refusal; 3 dismissed; 4 service unreachable.
"""
from __future__ import annotations

import argparse
import sys

__all__ = ["register", "serve", "worker", "submit", "db"]


def register(subparsers) -> None:
    """Add ``serve``, ``worker``, ``submit`` and ``db`` to an argparse subparsers object."""
    from service import serve as serve_module
    from service.migrations import cli as db_cli
    from worker import cli as worker_cli

    p = subparsers.add_parser(
        "serve", help="run the REST API (and a local worker when no broker is configured)",
        description="Run the REST API. With no HOCKLE_BROKER_URL the service is embedded: SQLite "
                    "registry and broker under HOCKLE_DATA_DIR and a local worker process.",
    )
    serve_module.add_arguments(p)
    p.set_defaults(func=serve)

    p = subparsers.add_parser(
        "worker", help="run a worker that takes jobs from the queue",
        description="Run a Celery worker (prefork pool) that runs queued jobs with the solver.",
    )
    worker_cli.add_arguments(p)
    p.set_defaults(func=worker)

    p = subparsers.add_parser(
        "submit", help="submit a case to a running service",
        description="Submit a case file to a hockle service; with --wait, follow its progress.",
    )
    p.add_argument("case", metavar="CASE", help="case spec, .yaml/.yml or .json")
    p.add_argument("--url", default=None,
                   help="service base URL (default HOCKLE_PUBLIC_URL or http://HOST:PORT)")
    p.add_argument("--api-key", default=None, metavar="KEY",
                   help="API key of the service, sent as 'Authorization: Bearer KEY' (default "
                   "HOCKLE_API_KEY, which other users of the machine cannot see in the process "
                   "list as they can an argument)")
    p.add_argument("--wait", action="store_true", help="wait for the job, printing progress")
    p.add_argument("-o", "--output", default=None, metavar="OUT.nc",
                   help="with --wait: save the NetCDF result here (partial results too)")
    p.add_argument("--idempotency-key", default=None, metavar="ID",
                   help="any string naming this submission: a retried submit with the same "
                   "ID returns the same job instead of a second one")
    p.add_argument("--fresh", action="store_true",
                   help="run even if an identical case already succeeded")
    p.add_argument("--time-limit", type=float, default=None, metavar="S",
                   help="hard time limit of the job in seconds, up to the service's "
                   "HOCKLE_TIME_LIMIT_MAX (default: derived from the case's size and contact)")
    p.add_argument("--timeout", type=float, default=None, metavar="S",
                   help="with --wait: give up after S seconds (default: wait as long as it "
                   "takes)")
    p.add_argument("--poll", type=float, default=1.0, metavar="S",
                   help="with --wait: seconds between status polls (default 1)")
    g = p.add_argument_group(
        "continuation", "with --continue: a continuation job (POST /v1/continuations), the "
        "case's static branch as `hockle continue` follows it, computed by the service")
    g.add_argument("--continue", dest="continuation", action="store_true",
                   help="submit a continuation of the case instead of a dynamic run")
    g.add_argument("--parameter", metavar="PATH", help="dotted path of a scalar of the case, "
                   "e.g. boundary.end.translation.2.force")
    g.add_argument("--to", type=float, metavar="VALUE", help="the parameter's target value")
    g.add_argument("--time", type=float, metavar="T", help="time at which the end conditions "
                   "are read, s (default: numerics.t_end)")
    g.add_argument("--switch", action="store_true", help="leave the branch at its first "
                   "branch point (a simple one along the critical mode, a round rod's "
                   "symmetric pair along one mode of the pair)")
    g.add_argument("--max-points", type=int, metavar="N", help="stop after N points "
                   "(default 500)")
    g.add_argument("--step", type=float, metavar="F", help="largest step, a fraction of the "
                   "range's arclength (default 0.05)")
    g.add_argument("--shapes-every", type=int, metavar="K", help="store positions and "
                   "curvatures at every K-th point (default 1)")
    p.set_defaults(func=submit)

    p = subparsers.add_parser(
        "db", help="the job registry's schema migrations (current, upgrade, check, ...)",
        description=db_cli.__doc__.split("\n\n")[0].replace("``", "") + " See "
                    "docs/service.md, Schema migrations.",
        epilog="\n\n".join(db_cli.__doc__.split("\n\n")[1:]).replace("``", ""),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    db_cli.add_arguments(p)
    p.set_defaults(func=db)


def serve(args: argparse.Namespace) -> int:
    from service.serve import run

    return run(args)


def worker(args: argparse.Namespace) -> int:
    from worker.cli import run

    return run(args)


def db(args: argparse.Namespace) -> int:
    from service.migrations.cli import run

    return run(args)


# what `hockle submit` says when the service answered with an earlier job (JobStatus.reused)
_REUSED = {
    "identical_case": "reused the result of job {id}, an identical case that already ran "
                      "successfully (finished {finished}); nothing was run now (--fresh runs "
                      "it again)",
    "idempotency_key": "the Idempotency-Key was used before: this is job {id}, submitted "
                       "then; nothing new was queued",
}


def submit(args: argparse.Namespace) -> int:
    import httpx

    from service.client import HockleAPIError, HockleClient

    out = sys.stdout
    branch = bool(getattr(args, "continuation", False))
    options = {k: getattr(args, k, None) for k in ("parameter", "to", "time", "max_points",
                                                   "step", "shapes_every")}
    if branch and (options["parameter"] is None or options["to"] is None):
        print("hockle submit: --continue needs --parameter PATH and --to VALUE",
              file=sys.stderr)
        return 2
    from hockle.io import result_file_given

    problem = result_file_given(args.case)
    if problem:
        print(f"hockle submit: {problem}", file=sys.stderr)
        return 2
    given = [f"--{k.replace('_', '-')}" for k, v in options.items() if v is not None]
    if not branch and (given or getattr(args, "switch", False)):
        print(f"hockle submit: {', '.join(given) or '--switch'} only with --continue",
              file=sys.stderr)
        return 2
    try:
        with HockleClient(args.url, api_key=getattr(args, "api_key", None)) as client:
            if branch:
                job = client.submit_continuation(
                    args.case, switch=args.switch, idempotency_key=args.idempotency_key,
                    fresh=args.fresh, time_limit=getattr(args, "time_limit", None), **options)
            else:
                job = client.submit(args.case, idempotency_key=args.idempotency_key,
                                    fresh=args.fresh, time_limit=getattr(args, "time_limit", None))
            print(f"job {job.id} {job.state} ({client.base_url}/v1/jobs/{job.id})", file=out)
            reused = _REUSED.get(job.reused or "")
            if reused:
                print(f"hockle submit: {reused.format(id=job.id, finished=job.finished)}",
                      file=out)
            for advice in job.advice:
                print(f"hockle submit: advice: {advice}", file=sys.stderr)
            for warning in job.warnings:
                print(f"hockle submit: warning: {warning['loc']}: {warning['msg']}",
                      file=sys.stderr)
            if not args.wait:
                return 0
            last = [None]

            def show(status) -> None:
                if branch:
                    line = f"{status.state:<10} {status.progress:6.1f}%  point {status.step}"
                else:
                    line = (f"{status.state:<10} {status.progress:6.1f}%  t = "
                            f"{status.sim_time:.4g} / {status.t_end:.4g} s  step {status.step}")
                if status.eta_seconds is not None and status.state == "running":
                    line += f"  eta {status.eta_seconds:.0f} s"
                if line != last[0]:
                    print(line, file=sys.stderr)
                    last[0] = line

            job = client.wait(job.id, timeout=args.timeout, poll_interval=args.poll,
                              on_progress=show)
            if job.error is not None:
                where = ""
                if job.error.time is not None and not branch:
                    where = f" at t = {job.error.time:.6g} s, step {job.error.step}"
                print(f"job {job.id} {job.state} ({job.reason}){where}: {job.message}", file=out)
            else:
                print(f"job {job.id} {job.state}", file=out)
                if job.message and not branch:
                    # a completed run's warning (the result's hockle_warning; a branch's
                    # message says how far it went)
                    print(f"hockle submit: warning: {job.message}", file=sys.stderr)
            if args.output and job.result_available:
                client.download(job.id, args.output)
                print(f"wrote {args.output}" + (" (partial)" if job.result_partial else ""),
                      file=out)
            return {"successful": 0, "failed": 1, "dismissed": 3}[job.state]
    except HockleAPIError as exc:
        print(f"hockle submit: refused: {exc}", file=sys.stderr)
        if exc.status == 401:
            print("hockle submit: give the service's API key with --api-key or HOCKLE_API_KEY",
                  file=sys.stderr)
        return 2
    except TimeoutError as exc:  # (an OSError: first)
        print(f"hockle submit: {exc}", file=sys.stderr)
        return 1
    except httpx.TransportError as exc:
        print(f"hockle submit: cannot reach the service: {exc}", file=sys.stderr)
        return 4
    except (OSError, ValueError) as exc:
        print(f"hockle submit: {exc}", file=sys.stderr)
        return 2
