"""``hockle sweep``: a parameter sweep, on a service (``--url``) or on this machine's cores.

    hockle sweep BASE --set PATH=v1,v2,... [--set PATH=...] [--zip] [-o sweep.nc]
                      [--fields position,kappa] [--workers N]                  # here
    hockle sweep BASE --set ... --url URL [--wait] [-o sweep.nc] [--fresh]
                      [--time-limit S] [--api-key KEY]                        # on a service

A value list is comma-separated (each value read as JSON, else kept as text), a range
``start:stop:count`` (``count`` values from ``start`` to ``stop``, both included) or a JSON
list (``[0, {"t": [0, 1], "value": [0, 2]}]``).

A path given one value (``--set numerics.n_segments=100``) is set in every member instead
of becoming an axis of one value.

Exit status: 0 every member succeeded (or, with --url and no --wait, the sweep was
accepted); 1 some members failed or stopped (the combined file is still written, with
its member_status); 2 an invalid sweep or case (each problem printed as "path: reason");
3 the sweep was dismissed; 4 the service cannot be reached.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

__all__ = ["register", "parse_values", "parse_sets", "split_fixed", "cmd_sweep"]


def _err(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _value(text: str) -> Any:
    text = text.strip()
    try:
        return json.loads(text)
    except ValueError:
        return text


def parse_values(text: str) -> list[Any]:
    """``"1,2,3"`` -> [1, 2, 3]; ``"0:1:5"`` -> [0.0, 0.25, 0.5, 0.75, 1.0];
    ``'[0, "x"]'`` -> [0, "x"]. Raises ValueError with what is allowed."""
    text = text.strip()
    if not text:
        raise ValueError("no values after '='")
    if text.startswith("["):
        values = json.loads(text)
        if not isinstance(values, list) or not values:
            raise ValueError("a JSON list of values is needed")
        return values
    parts = text.split(":")
    if len(parts) == 3 and all(p.strip() for p in parts):
        import numpy as np

        start, stop, count = float(parts[0]), float(parts[1]), parts[2]
        if not count.strip().isdigit() or int(count) < 1:
            raise ValueError(f"a range is start:stop:count with a whole count >= 1, got {text!r}")
        return [float(x) for x in np.linspace(start, stop, int(count))]
    return [_value(v) for v in text.split(",")]


def parse_sets(items: list[str]) -> dict[str, list]:
    """``["PATH=v1,v2", ...]`` -> ``{PATH: [v1, v2], ...}`` in order."""
    out: dict[str, list] = {}
    for item in items:
        path, eq, values = item.partition("=")
        if not eq or not path.strip():
            raise ValueError(f"--set {item!r}: give PATH=v1,v2,... (e.g. "
                             "boundary.end.translation.2.force=0,0.5,1)")
        try:
            out[path.strip()] = parse_values(values)
        except ValueError as exc:
            raise ValueError(f"--set {item!r}: {exc}") from None
    return out


def split_fixed(parameters: dict[str, list]) -> tuple[dict[str, list], dict[str, Any]]:
    """``(varied, fixed)``: a path given one value is a fixed override of the base case for
    every member, not an axis of the sweep (an axis of one value would make the threshold
    map a stack of one-row maps). When no path has more than one value, all stay as they
    are: a sweep of one member."""
    varied = {p: v for p, v in parameters.items() if len(v) > 1}
    if not varied:
        return dict(parameters), {}
    return varied, {p: v[0] for p, v in parameters.items() if len(v) == 1}


def _base_with(base: str, fixed: dict[str, Any]) -> Any:
    """The base case file, or its document with the fixed overrides set (raises
    service.sweeps.SweepError for a path that cannot be followed, OSError/ValueError for
    a file that cannot be read)."""
    if not fixed:
        return base
    from service.client import case_document
    from service.sweeps import set_path

    doc = case_document(base)
    for path, value in fixed.items():
        set_path(doc, path, value)
    return doc


def register(subparsers) -> None:
    """Add ``sweep`` to the ``hockle`` command's subparsers."""
    p = subparsers.add_parser(
        "sweep", help="run a parameter sweep (here, or on a service with --url)",
        description="Run a base case with fields varied over values: every combination "
        "(default) or, with --zip, the i-th values together. Without --url the members run "
        "here in as many processes as cores; with --url they are jobs of that service. "
        "The combined NetCDF has a dimension per varied path (or 'member' with --zip), the "
        "members' scalar time series, their event times and member_status.",
        epilog=__doc__.split("Exit status", 1)[1].join(["Exit status", ""]),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("base", metavar="BASE", help="base case spec, .yaml/.yml or .json")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="PATH=VALUES",
                   required=True,
                   help="a dotted path into the case (list indices as numbers) and its values: "
                   "v1,v2,... or start:stop:count or a JSON list; repeat for more paths. A "
                   "path given one value is set in every member, not swept")
    p.add_argument("--zip", action="store_true",
                   help="pair the i-th values of every --set instead of every combination")
    p.add_argument("-o", "--output", metavar="OUT.nc",
                   help="combined dataset (default here: <base stem>_sweep.nc; with --url: "
                   "written only with --wait)")
    p.add_argument("--fields", default="", metavar="F1,F2",
                   help="full (time, s, ...) fields to add (position, kappa, ...); the "
                   "scalar series and event times are always there")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="here: processes (default: as many as cores)")
    p.add_argument("--url", default=None, help="run on this hockle service instead")
    p.add_argument("--api-key", default=None, metavar="KEY",
                   help="with --url: the service's API key (default HOCKLE_API_KEY)")
    p.add_argument("--wait", action="store_true",
                   help="with --url: wait for every member, printing progress")
    p.add_argument("--fresh", action="store_true",
                   help="with --url: run members even if an identical case succeeded before")
    p.add_argument("--time-limit", type=float, default=None, metavar="S",
                   help="with --url: hard time limit of each member job, s")
    p.add_argument("--timeout", type=float, default=None, metavar="S",
                   help="with --wait: give up after S seconds (default: wait as long as it "
                   "takes)")
    p.add_argument("--poll", type=float, default=1.0, metavar="S",
                   help="with --wait: seconds between status polls (default 1)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=cmd_sweep)


def _print_errors(errors: list[dict], head: str) -> None:
    _err(head)
    for err in errors:
        _err(f"{err.get('loc') or '(sweep)'}: {err.get('msg')}")


def cmd_sweep(args: argparse.Namespace) -> int:
    """Run ``hockle sweep``; returns the exit status."""
    try:
        parameters = parse_sets(args.sets)
    except ValueError as exc:
        _err(f"hockle sweep: {exc}")
        return 2
    parameters, fixed = split_fixed(parameters)
    from hockle.io import result_file_given

    problem = result_file_given(args.base)
    if problem:
        _err(f"hockle sweep: {problem}")
        return 2
    try:
        from service.sweeps import SweepError

        base = _base_with(args.base, fixed)
    except SweepError as exc:
        _print_errors(exc.errors, f"hockle sweep: {exc.detail}")
        return 2
    except (OSError, ValueError) as exc:
        _err(f"hockle sweep: cannot read {args.base}: {exc}")
        return 2
    if fixed and not args.quiet:
        _err("hockle sweep: for every member (one value, not an axis): "
             + ", ".join(f"{p} = {json.dumps(v)}" for p, v in fixed.items()))
    combine = "zip" if args.zip else "grid"
    fields = [f.strip() for f in args.fields.split(",") if f.strip()]
    if args.url:
        return _on_service(args, base, parameters, combine, fields)
    return _here(args, base, parameters, combine, fields)


def _exit_for(states: list[str], dismissed: bool = False) -> int:
    if dismissed:
        return 3
    return 0 if all(s == "successful" for s in states) else 1


def _here(args, base, parameters, combine, fields) -> int:
    import os

    from hockle.api import sweep
    from hockle.io import write_netcdf
    from service.sweeps import SweepError
    from solver.case import CaseError

    out = Path(args.output) if args.output else Path(Path(args.base).stem + "_sweep.nc")
    workers = args.workers or os.cpu_count() or 1
    t0 = time.perf_counter()

    def show(done, total, index, state):
        if not args.quiet:
            _err(f"hockle sweep: {done}/{total} members done (member {index}: {state}), "
                 f"{time.perf_counter() - t0:.1f} s")

    try:
        ds = sweep(base, parameters, combine, workers=workers, fields=fields,
                   on_member=show)
    except SweepError as exc:
        _print_errors(exc.errors, f"hockle sweep: {exc.detail}")
        return 2
    except CaseError as exc:
        _print_errors(list(exc.errors), f"hockle sweep: cannot read {args.base}")
        return 2
    except OSError as exc:
        _err(f"hockle sweep: {exc}")
        return 2
    try:
        write_netcdf(ds, out)
    except OSError as exc:
        _err(f"hockle sweep: cannot write {out}: {exc}")
        return 1
    states = [str(s) for s in ds["member_status"].values.ravel()]
    counts = {s: states.count(s) for s in dict.fromkeys(states)}
    print(f"{len(states)} members ({', '.join(f'{n} {s}' for s, n in counts.items())}) in "
          f"{time.perf_counter() - t0:.1f} s on {workers} worker process(es): wrote {out}")
    return _exit_for(states)


def _on_service(args, base, parameters, combine, fields) -> int:
    import httpx

    from service.client import HockleAPIError, HockleClient

    try:
        with HockleClient(args.url, api_key=args.api_key) as client:
            status = client.sweep(base, parameters, combine=combine, fresh=args.fresh,
                                  time_limit=args.time_limit)
            print(f"sweep {status.id} {status.state}: {len(status.members)} members "
                  f"({client.base_url}/v1/sweeps/{status.id})")
            if not args.wait:
                return 0
            last = [None]

            def show(st) -> None:
                line = (f"{st.state:<10} {st.progress:6.1f}%  " + ", ".join(
                    f"{n} {s}" for s, n in st.counts.items()))
                if line != last[0] and not args.quiet:
                    _err(line)
                    last[0] = line

            status = client.wait_sweep(status.id, timeout=args.timeout,
                                       poll_interval=args.poll, on_progress=show)
            print(f"sweep {status.id} {status.state}: " + ", ".join(
                f"{n} {s}" for s, n in status.counts.items()))
            if args.output:
                client.download_sweep(status.id, args.output, fields or None)
                print(f"wrote {args.output}")
            return _exit_for([m.state for m in status.members], status.state == "dismissed")
    except HockleAPIError as exc:
        _print_errors(exc.errors, f"hockle sweep: refused: {exc.status}: "
                      f"{exc.problem.get('detail') or exc.problem.get('title')}")
        return 2
    except TimeoutError as exc:
        _err(f"hockle sweep: {exc}")
        return 1
    except httpx.TransportError as exc:
        _err(f"hockle sweep: cannot reach the service: {exc}")
        return 4
    except (OSError, ValueError) as exc:
        _err(f"hockle sweep: {exc}")
        return 2
