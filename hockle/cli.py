"""The ``hockle`` command: validate, run, plot, animate, export, sweep and continue cases;
serve, worker, submit and db.

Exit status::

    0    success
    1    an internal error, a file that could not be written, or nothing to plot
    2    bad usage or an invalid case (each error printed as "path: reason"), a result
         file that cannot be read, or an animation format this machine cannot write
         (.mp4 without ffmpeg)
    3    the solver diverged (SolverDivergence); the partial results are written
    4    the run stopped before t_end for another reason (e.g. its wall-clock budget);
         the partial results are written
    130  interrupted by Ctrl-C; the run stops at the next step and the partial results
         are written (a second Ctrl-C aborts without writing)
"""
from __future__ import annotations

import argparse
import importlib
import math
import signal
import sys
import textwrap
import threading
import time
from pathlib import Path
from typing import Any, Callable

EXIT_OK = 0
EXIT_ERROR = 1
EXIT_INVALID = 2
EXIT_DIVERGED = 3
EXIT_STOPPED = 4
EXIT_INTERRUPTED = 130

SERVICE_COMMANDS = ("serve", "worker", "submit", "db")
USER_STOP_REASON = "cancelled_by_user"


def _err(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _place(source: str, loc: str) -> str | None:
    """``  at FILE:LINE:COLUMN: <the line>`` for the field path ``loc`` of the case file
    ``source`` (:func:`solver.case_source.where`, the dashboard's way to find a field in
    its editor), or None (no such file, the document as a whole, a path it does not
    write)."""
    from solver.case_source import where

    try:
        text = Path(source).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    place = where(source, text, loc)
    return f"  at {place}" if place else None


def _syntax_place(source: str, msg: str) -> str | None:
    """``  at FILE:LINE:COLUMN: <the line>`` for a syntax error whose message gives its
    place (``at line 4, column 1``: YAML; ``line 3 column 2``: JSON), or None."""
    import re

    m = re.search(r"line (\d+),? column (\d+)", msg)
    if m is None:
        return None
    line, column = int(m.group(1)), int(m.group(2))
    try:
        lines = Path(source).read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError):
        return None
    shown = lines[line - 1].strip()[:100] if 0 < line <= len(lines) else ""
    return f"  at {source}:{line}:{column}: {shown}"


def _print_case_errors(exc: Any, source: str) -> None:
    errors = list(getattr(exc, "errors", None) or [])
    n = len(errors)
    if n == 1 and not errors[0].get("loc"):     # the file as a whole: one line
        msg = " ".join(str(errors[0].get("msg", "")).split())
        _err(f"hockle: invalid case {source}: {msg}")
        place = _syntax_place(source, msg)      # a YAML syntax error: where it is
        if place:
            _err(place)
        return
    _err(f"hockle: invalid case {source} ({n} error{'s' if n != 1 else ''}):")
    for error in errors:
        loc = error.get("loc") or "(case)"
        msg = str(error.get("msg", "")).replace("\n", " ")
        _err(f"{loc}: {msg}")
        place = (_place(source, error["loc"]) if error.get("loc")
                 else _syntax_place(source, msg))
        if place:
            _err(place)
    if not errors:
        _err(str(exc))


def _not_a_case(path: str, command: str) -> bool:
    """Whether ``path`` is a result file given where a case is expected (said in one line)."""
    from hockle.io import result_file_given

    problem = result_file_given(path)
    if problem:
        _err(f"hockle {command}: {problem}")
    return problem is not None


def _print_warnings(case: Any, source: str) -> int:
    """Print the case's plausibility warnings (:func:`solver.plausibility.
    plausibility_warnings`) on stderr, each ``hockle: warning: PATH: reason`` with the
    place in the file below it; returns how many. Warnings do not stop anything."""
    from solver.plausibility import plausibility_warnings

    found = plausibility_warnings(case)
    for warning in found:
        _err(f"hockle: warning: {warning['loc']}: {warning['msg']}")
        place = _place(source, warning["loc"])
        if place:
            _err(place)
    return len(found)


def _load_case(path: str, command: str = "validate") -> Any:
    """The validated Case, or None after printing its errors."""
    from solver.case import Case, CaseError

    if _not_a_case(path, command):
        return None
    try:
        return Case.from_file(path)
    except CaseError as exc:
        _print_case_errors(exc, path)
        return None


def _n_steps(case: Any) -> int:
    num = case.numerics
    return max(1, int(math.ceil(num.t_end / num.dt - 1e-9)))


# --------------------------------------------------------------------------- validate


def cmd_validate(args: argparse.Namespace) -> int:
    case = _load_case(args.case)
    if case is None:
        return EXIT_INVALID
    num = case.numerics
    print(
        f"ok: {case.name}: {num.n_segments + 1} grid points (ds {num.ds:g} m), "
        f"{_n_steps(case)} steps (dt {num.dt:g} s, t_end {num.t_end:g} s), "
        f"spec hash {case.spec_hash()[:12]}"
    )
    from solver.initial import start_offset

    off = start_offset(case)
    if off is not None:
        print(f"start pose: within {off.distance * 1e3:.3g} mm ({off.share:.2g} diameters) "
              f"of initial.centreline (farthest at s = {off.s:.4g} m)")
        _print_advice(off.advice())
    _print_warnings(case, args.case)
    return EXIT_OK


def _print_advice(advice) -> None:
    """Print a case's advice (solver.initial.StartOffset.advice) to stderr, if any."""
    if advice:
        _err(f"hockle: advice: {advice}")


# --------------------------------------------------------------------------- run


class _StopOnInterrupt:
    """SIGINT handler: the first Ctrl-C asks the solver to stop before its next step
    (through ``should_stop``); a second one raises KeyboardInterrupt at once."""

    def __init__(self) -> None:
        self.requested = False
        self._previous: Any = None
        self._installed = False

    def __enter__(self) -> "_StopOnInterrupt":
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)
            self._installed = True
        return self

    def __exit__(self, *exc_info: Any) -> None:
        if self._installed:
            signal.signal(signal.SIGINT, self._previous)

    def _handle(self, signum: int, frame: Any) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        _err("hockle: interrupt: stopping after the current step (Ctrl-C again to abort)")

    def should_stop(self) -> str | bool:
        return USER_STOP_REASON if self.requested else False


class _ProgressBar:
    """Progress on stderr driven by ``solver.Progress`` reports: a rich bar on a
    terminal; otherwise (a log file, a pipe) a plain line every 10 % or 30 s.

    What each number is (:func:`_step_words`): with fixed steps, the nominal steps of
    ``numerics.dt`` done out of the case's count, the last accepted sub-step's Δt where
    that step was cut or split (at a breakpoint, a Newton refusal, a contact), and the
    Newton iterations of all of that nominal step's sub-steps; with ``numerics.tolerance``
    the error-controlled steps taken and the last one's Δt."""

    LINE_EVERY_S = 30.0

    def __init__(self, name: str, t_end: float, enabled: bool, case: Any = None) -> None:
        self.enabled = enabled
        self.case = case
        self._bar = None
        self._task = None
        self._plain = False
        self._last_line = (-1.0, 0.0)  # (fraction decile, wall time) of the last line
        if not enabled:
            return
        from rich.console import Console
        from rich.progress import (
            BarColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
        )

        console = Console(stderr=True)
        if not console.is_terminal:
            self._plain = True
            return
        self._bar = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            TextColumn("t {task.completed:.4g}/{task.total:.4g} s"),
            TextColumn("{task.fields[steps]}"),
            TimeElapsedColumn(),
            TextColumn("ETA {task.fields[eta]}"),
            console=console,
        )
        self._task = self._bar.add_task(name, total=t_end, steps="step 0", eta="-")

    def __enter__(self) -> "_ProgressBar":
        if self._bar is not None:
            self._bar.start()
        return self

    def __exit__(self, *exc_info: Any) -> None:
        if self._bar is not None:
            self._bar.stop()

    def update(self, info: Any) -> None:
        if self._bar is not None:
            self._bar.update(
                self._task,
                completed=info.t,
                steps=_step_words(info, self.case),
                eta=("-" if getattr(info, "eta_seconds", None) is None
                     else f"{info.eta_seconds:.0f} s"),
            )
        elif self._plain:
            decile = math.floor(10 * info.fraction + 1e-9)
            last_decile, last_wall = self._last_line
            if decile > last_decile or info.wall_time - last_wall >= self.LINE_EVERY_S:
                self._last_line = (decile, info.wall_time)
                _err(_progress_line(info, self.case))


def _step_words(info: Any, case: Any = None) -> str:
    """The step part of a progress report, each number saying what it counts: with fixed
    steps ``nominal step 80/200 of Δt 0.05 s (last sub-step 0.00202 s), 136 Newton
    iterations`` (of all the nominal step's sub-steps; the sub-step only where it differs
    from the nominal Δt in the digits shown); with ``numerics.tolerance`` ``step 80 (error-controlled, last
    Δt 0.00202 s), 9 Newton iterations``;
    without the case ``step 80, Δt 0.00202 s, Newton 136``."""
    num = getattr(case, "numerics", None)
    its = info.newton_iterations
    if num is None:
        return f"step {info.step}, Δt {info.dt:.3g} s, Newton {its}"
    if num.tolerance is not None:
        return (f"step {info.step} (error-controlled, last Δt {info.dt:.3g} s), "
                f"{its} Newton iterations")
    words = f"nominal step {info.step}/{_n_steps(case)} of Δt {num.dt:g} s"
    if f"{info.dt:.3g}" != f"{num.dt:.3g}":       # cut or split, as far as it shows
        words += f" (last sub-step {info.dt:.3g} s)"
    return words + f", {its} Newton iterations"


def _progress_line(info: Any, case: Any = None) -> str:
    if info.fraction >= 1:
        eta = "0 s"
    elif getattr(info, "eta_seconds", None) is not None:
        eta = f"{info.eta_seconds:.0f} s"      # solver.recording.EtaModel
    else:
        eta = "-"
    return (
        f"t {info.t:.4g}/{info.t_end:.4g} s ({100 * info.fraction:.0f} %), "
        f"{_step_words(info, case)}, wall {info.wall_time:.0f} s, ETA {eta}"
    )


def _write(ds: Any, out: Path) -> bool:
    from hockle.io import write_netcdf
    from solver.results import apply_metadata

    # ACDD creator, licence ... from the HOCKLE_* environment, as the service's workers do;
    # a problem there costs the attributes, never the result of the run
    try:
        from service.settings import DatasetMetadata

        apply_metadata(ds, DatasetMetadata().dataset_metadata())
    except Exception as exc:  # noqa: BLE001
        _err(f"hockle: operator metadata (HOCKLE_CREATOR_NAME, ...) not applied: {exc}")
    try:
        write_netcdf(ds, out)
    except OSError as exc:
        _err(f"hockle: cannot write {out}: {exc}")
        return False
    return True


def _kernels_cached() -> bool:
    """Whether numba's on-disk cache holds compiled solver kernels. Importing
    :mod:`solver` first purges a cache written for other sources
    (``solver/_kernel_cache.py``), so after an installation or a change of the solver's
    sources this is False until the kernels have been compiled once. With
    ``NUMBA_CACHE_DIR`` set only the solver's folders there count
    (:func:`solver._kernel_cache.kernels_cached`)."""
    from solver._kernel_cache import kernels_cached

    return kernels_cached()


class _CompileProgress:
    """What numba has compiled so far while :func:`solver.compiled.warm_up` runs, on
    stderr: the count of compiled function signatures (numba's ``numba:compile`` events
    that end) and the time since the start, as a rich status line on a terminal;
    otherwise (a log file, a pipe) a plain line every LINE_EVERY_S. Used as a context
    manager around the compilation; ``count`` holds the total after it."""

    LINE_EVERY_S = 30.0

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.count = 0
        self._t0 = time.perf_counter()
        self._last_line = self._t0
        self._status = None
        self._installed = None

    def __enter__(self) -> "_CompileProgress":
        from numba.core import event

        progress = self

        class _Listener(event.Listener):
            def on_start(self, ev: Any) -> None:
                pass

            def on_end(self, ev: Any) -> None:
                progress.compiled()

        self._installed = event.install_listener("numba:compile", _Listener())
        self._installed.__enter__()
        if self.enabled:
            from rich.console import Console

            console = Console(stderr=True)
            if console.is_terminal:
                self._status = console.status(self._text())
                self._status.start()
        return self

    def __exit__(self, *exc_info: Any) -> None:
        if self._status is not None:
            self._status.stop()
        self._installed.__exit__(*exc_info)

    def _text(self) -> str:
        return (f"compiling the solver's kernels: {self.count} function signatures, "
                f"{time.perf_counter() - self._t0:.0f} s")

    def compiled(self) -> None:
        """One compilation ended (a function signature, its callees counted apart)."""
        self.count += 1
        if not self.enabled:
            return
        if self._status is not None:
            self._status.update(self._text())
        elif time.perf_counter() - self._last_line >= self.LINE_EVERY_S:
            self._last_line = time.perf_counter()
            _err(f"hockle: {self._text()} ...")


def _compile_kernels_first(quiet: bool) -> None:
    """Compile the solver's kernels up front, saying so and showing how far it got
    (:class:`_CompileProgress`), when none are cached: otherwise the first run's
    progress bar would stand still at step 0 for a minute or more while numba compiles
    them at their first call."""
    if _kernels_cached():
        return
    from solver.compiled import warm_up

    if not quiet:
        _err("hockle: compiling the solver's kernels (once after installing or changing "
             "the solver; 1.5 to 6 minutes on 2 cores, depending on the machine) ...")
    t0 = time.perf_counter()
    with _CompileProgress(not quiet) as progress:
        warm_up()
    if not quiet:
        _err(f"hockle: kernels compiled in {time.perf_counter() - t0:.0f} s "
             f"({progress.count} function signatures); later runs load them from the cache")


def cmd_run(args: argparse.Namespace) -> int:
    case = _load_case(args.case, "run")
    if case is None:
        return EXIT_INVALID
    out = Path(args.output) if args.output else Path(Path(args.case).stem + ".nc")

    from solver.centreline import CentrelineError
    from solver.checkpoint import Checkpoint, CheckpointError
    from solver.simulation import SolverDivergence, integrate

    resume = None
    if args.resume:
        try:
            resume = Checkpoint.loads(Path(args.resume).read_bytes(), case)
        except (OSError, CheckpointError) as exc:
            _err(f"hockle: cannot resume from {args.resume}: {exc}")
            return EXIT_INVALID
    if args.checkpoint_every <= 0:
        _err("hockle: --checkpoint-every must be positive")
        return EXIT_INVALID
    start = None
    if case.initial.from_result is not None and resume is None:
        from solver.case import CaseError

        from .io import read_start_state
        try:
            start = read_start_state(case)
        except CaseError as exc:
            for error in exc.errors:
                _err(f"hockle run: {args.case}: {error['loc']}: {error['msg']}")
            return EXIT_INVALID
    if resume is None:
        from solver.initial import start_offset

        off = start_offset(case)
        _print_advice(off.advice() if off is not None else None)
        _print_warnings(case, args.case)
    ck_path = Path(args.checkpoint) if args.checkpoint else None
    latest = {}

    def keep(ck: Checkpoint) -> None:
        data = ck.dumps()
        latest["t"] = ck.t
        tmp = ck_path.with_name(ck_path.name + ".tmp")
        try:
            tmp.write_bytes(data)
            tmp.replace(ck_path)               # atomic: a crash keeps the older one
        except OSError as exc:
            _err(f"hockle: cannot write checkpoint {ck_path}: {exc}")

    _compile_kernels_first(args.quiet)
    wall0 = time.perf_counter()
    # The handler stays in place while the result is written, so a Ctrl-C then does not
    # tear the write apart (write_netcdf is atomic in any case).
    with _StopOnInterrupt() as interrupt:
        if not args.quiet:
            _err(
                f"hockle: running {case.name}: {case.numerics.n_segments + 1} grid points, "
                f"{_n_steps(case)} steps to t_end {case.numerics.t_end:g} s -> {out}"
                + (f" (resumed at t = {resume.t:g} s)" if resume is not None else "")
            )
        try:
            with _ProgressBar(case.name, case.numerics.t_end, enabled=not args.quiet,
                              case=case) as bar:
                ds = integrate(case, progress=bar.update, should_stop=interrupt.should_stop,
                              checkpoint=keep if ck_path else None,
                              checkpoint_interval=args.checkpoint_every, resume=resume,
                              start=start)
        except SolverDivergence as exc:
            wall = time.perf_counter() - wall0
            reason = str(exc).replace("\n", " ")
            partial = exc.partial
            written = partial is not None and _write(partial, out)
            where = f"partial results in {out}" if written else "no results written"
            _err(
                f"hockle: solver failed ({exc.reason}) at t = {exc.t:.6g} s after "
                f"{exc.step} steps: {reason}; {where}"
            )
            print(f"failed after {wall:.1f} s wall time" + (f": wrote {out}" if written else ""))
            return EXIT_DIVERGED
        except KeyboardInterrupt:
            _err("hockle: aborted; no results written")
            return EXIT_INTERRUPTED
        except CentrelineError as exc:
            # a field the centreline scheme refuses when the run is built (before any step)
            _err(f"hockle run: {args.case}: {exc}; no results written")
            return EXIT_INVALID
        wall = time.perf_counter() - wall0
        if not _write(ds, out):
            return EXIT_ERROR

    status = ds.attrs.get("hockle_status", "completed")
    t_last = float(ds["time"].values[-1]) if ds.sizes.get("time", 0) else float("nan")
    print(
        f"{status}: t = {t_last:g} of {case.numerics.t_end:g} s in {wall:.1f} s wall time: "
        f"wrote {out}"
    )
    if ds.attrs.get("hockle_events"):
        print(f"events: {ds.attrs['hockle_events']}")      # in the order they happened
    if ds.attrs.get("hockle_warning"):
        _err(f"hockle: warning: {ds.attrs['hockle_warning']}")
    if status == "completed":
        return EXIT_OK
    reason = ds.attrs.get("hockle_stop_reason", "stopped")
    message = ds.attrs.get("hockle_message") or reason
    _err(f"hockle: run stopped before t_end ({message}); partial results in {out}")
    return EXIT_INTERRUPTED if reason == USER_STOP_REASON else EXIT_STOPPED


# --------------------------------------------------------------------------- plot


_CASE_SUFFIXES = (".yaml", ".yml", ".json")


def _read_result(path: Path, command: str, accept: tuple[str, ...], lazy: bool = False):
    """The result file at ``path`` (read into memory, or opened lazily) if it holds one of
    the kinds ``accept`` (:func:`hockle.io.result_kind`); else None after saying, in one
    line, what it is and what to do with it."""
    import xarray as xr

    from hockle.io import describe_result, one_line, open_result, result_kind

    if path.suffix.lower() in _CASE_SUFFIXES and path.is_file():
        _err(f"hockle {command}: {path} is a case file, not a result: run it first "
             f"(hockle run {path}, or hockle continue for a branch)")
        return None
    try:
        ds = xr.open_dataset(path, engine="netcdf4") if lazy else open_result(path)
    except Exception as exc:  # noqa: BLE001 - any reader's failure: one line, not a traceback
        _err(f"hockle {command}: cannot read {path}: {one_line(exc)}")
        return None
    kind = result_kind(ds)
    if kind in accept:
        return ds
    what = describe_result(ds, path)
    if kind == "branch":
        _err(f"hockle {command}: {what}: hockle plot draws its bifurcation diagram and "
             "shapes, hockle export writes its shapes for ParaView")
    elif kind == "sweep":
        _err(f"hockle {command}: {what}: hockle plot draws its threshold map; {command} a "
             "member's own result")
    else:
        _err(f"hockle {command}: {what}")
    ds.close()
    return None


def cmd_plot(args: argparse.Namespace) -> int:
    path = Path(args.result)
    ds = _read_result(path, "plot", ("run", "branch", "sweep"))
    if ds is None:
        return EXIT_INVALID
    out_dir = Path(args.output_dir) if args.output_dir else path.with_name(f"{path.stem}_plots")

    if ds.attrs.get("hockle_kind") == "branch":   # a continuation's branch
        from hockle.branch_plots import plot_branch

        paths = plot_branch(ds, out_dir, stem=path.stem)
    elif "hockle_sweep_combine" in ds.attrs:       # a sweep's combined dataset
        from hockle.sweep_plots import plot_sweep

        paths = plot_sweep(ds, out_dir, stem=path.stem, on_skip=_err)
    else:
        from hockle.plots import plot_all

        paths = plot_all(ds, out_dir, times=args.times, stem=path.stem, on_skip=_err)
    for p in paths:
        print(p)
    if not paths:
        _err(f"hockle: nothing to plot in {path}")
        return EXIT_ERROR
    return EXIT_OK


# --------------------------------------------------------------------------- continue


def cmd_continue(args: argparse.Namespace) -> int:
    from hockle.api import continue_branch
    from solver.case import CaseError
    from solver.statics import StaticsError

    if args.max_points < 2 or args.shapes_every < 1 or not 0 < args.step <= 1:
        _err("hockle continue: --max-points >= 2, --shapes-every >= 1, 0 < --step <= 1")
        return EXIT_INVALID
    if _not_a_case(args.case, "continue"):
        return EXIT_INVALID

    def progress(i: int, lam: float) -> None:
        if not args.quiet:
            print(f"point {i}: {args.parameter} = {lam:.6g}", file=sys.stderr)

    try:
        ds = continue_branch(args.case, args.parameter, args.to, time=args.time,
                             switch=args.switch, max_points=args.max_points, step=args.step,
                             shapes_every=args.shapes_every, on_point=progress)
    except CaseError as exc:
        _print_case_errors(exc, args.case)
        return EXIT_INVALID
    except (StaticsError, ValueError, OSError) as exc:
        _err(f"hockle continue: {exc}")
        return EXIT_INVALID
    out = Path(args.output) if args.output else Path(f"{Path(args.case).stem}_branch.nc")
    from hockle.io import write_netcdf

    try:
        write_netcdf(ds, out)
    except OSError as exc:
        _err(f"hockle: cannot write {out}: {exc}")
        return EXIT_ERROR
    kinds = ds["bifurcation_kind"].values.tolist()
    where = ", ".join(f"{k} at {v:.6g}" for k, v in zip(kinds, ds["bifurcation_parameter"].values))
    print(f"{out}: {ds.sizes['point']} points ({ds.attrs['stopped']}); {where or 'no bifurcation'}")
    return EXIT_OK


# --------------------------------------------------------------------------- animate


def _frame_progress(verb: str):
    """A ``progress(done, total)`` callback that prints ``hockle: VERB: frame done/total``
    on stderr once per tenth of the frames."""
    reported = [-1]

    def progress(done: int, total: int) -> None:
        decile = (10 * done) // total
        if decile > reported[0]:
            reported[0] = decile
            _err(f"hockle: {verb}: frame {done}/{total}")

    return progress


def cmd_animate(args: argparse.Namespace) -> int:
    from hockle.animate import AnimationError, NothingToAnimate, animate

    path = Path(args.result)
    out = Path(args.output) if args.output else path.with_suffix(".gif")
    ds = _read_result(path, "animate", ("run",), lazy=True)   # lazily: read frame by frame
    if ds is None:
        return EXIT_INVALID
    progress = _frame_progress("animate")
    try:
        with ds:
            if not args.quiet:
                _err(f"hockle: animating {path} -> {out}")
            animate(ds, out, frames=args.frames, fps=args.fps, dpi=args.dpi,
                    window=args.times, progress=None if args.quiet else progress)
    except NothingToAnimate as exc:
        _err(f"hockle: nothing to animate in {path}: {exc}")
        return EXIT_ERROR
    except AnimationError as exc:
        _err(f"hockle: {exc}")
        return EXIT_INVALID
    except OSError as exc:
        _err(f"hockle: cannot write {out}: {exc}")
        return EXIT_ERROR
    print(out)
    return EXIT_OK


# --------------------------------------------------------------------------- export


def cmd_export(args: argparse.Namespace) -> int:
    from service.export import ExportError, export_vtk

    path = Path(args.result)
    out = Path(args.output) if args.output else path.with_suffix(".pvd")
    ds = _read_result(path, "export", ("run", "branch"))
    if ds is None:
        return EXIT_INVALID
    progress = _frame_progress("export")
    from service.export import BODY_VECTORS
    from service.branch_view import is_branch

    if (not args.quiet and not is_branch(ds) and "orientation" not in ds
            and any(name in ds for name in BODY_VECTORS)):
        _err(f"hockle: {path} stores no orientation (output.fields): its vectors are written "
             "along the directors only (v_body, ...); with orientation stored they are also "
             "turned into the global frame (v_global, ...)")
    try:
        files = export_vtk(ds, out, stride=args.stride, window=args.times,
                           progress=None if args.quiet else progress)
    except ExportError as exc:
        _err(f"hockle: cannot export {path}: {exc}")
        return EXIT_INVALID
    except OSError as exc:
        _err(f"hockle: cannot write {out}: {exc}")
        return EXIT_ERROR
    print(f"{files[0]} ({len(files) - (out.suffix == '.pvd')} frame"
          f"{'s' if len(files) > 2 else ''})")
    return EXIT_OK


# --------------------------------------------------------------------------- parser


def _version() -> str:
    try:
        from solver import __version__

        return __version__
    except ImportError:  # pragma: no cover - a broken install
        return "unknown"


def _register_service_commands(sub: Any) -> str | None:
    """Add serve/worker/submit from :mod:`hockle.service_commands`.

    Returns None, or why they are unavailable; then placeholders that only explain this
    are added, so run/validate/plot keep working without the service dependencies.
    """
    reason = None
    try:
        module = importlib.import_module("hockle.service_commands")
        module.register(sub)
    except Exception as exc:  # any failure there must not break run/validate/plot
        reason = f"cannot load hockle.service_commands ({type(exc).__name__}: {exc})"
    for name in SERVICE_COMMANDS:
        if name not in sub.choices:
            if reason is None:
                reason = f"hockle.service_commands did not add '{name}'"
            sub.add_parser(name, help="(unavailable here: run it to see why)", add_help=False)
    return reason


def build_parser() -> tuple[argparse.ArgumentParser, str | None]:
    """The argument parser, and why the service commands are unavailable (or None)."""
    parser = argparse.ArgumentParser(
        prog="hockle",
        description="Dynamics of twisted elastic rods with self-contact "
        "(Goyal, Perkins & Lee).",
        epilog="Exit status:\n" + textwrap.dedent(__doc__.split("Exit status::", 1)[1]).strip(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"hockle {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    p = sub.add_parser(
        "validate", help="check a case file and summarise it",
        description="Check a case file against the case spec (schema_version 1) without "
        "running it: every bad field is printed as 'path: reason' (an unknown field with "
        "the fields allowed there) and the exit status is 2; a valid case prints its grid, "
        "steps and spec hash.",
    )
    p.add_argument("case", metavar="CASE", help="case spec, .yaml/.yml or .json")
    p.set_defaults(func=cmd_validate)

    p = sub.add_parser(
        "run",
        help="run a case in-process and write its NetCDF result",
        description="Run a case in this process with a progress bar and write the result "
        "dataset atomically. On solver failure, stop (Ctrl-C) or an exceeded wall-clock "
        "budget the partial results are written and the exit status is non-zero.",
    )
    p.add_argument("case", metavar="CASE", help="case spec, .yaml/.yml or .json")
    p.add_argument(
        "-o", "--output", metavar="OUT.nc", help="result file (default: <case stem>.nc here)"
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.add_argument(
        "--checkpoint", metavar="FILE", help="keep a checkpoint of the run in FILE (written "
        "atomically every --checkpoint-every seconds of wall time and when the run stops "
        "or fails), to continue it later with --resume FILE"
    )
    p.add_argument(
        "--checkpoint-every", metavar="S", type=float, default=300.0,
        help="wall-clock seconds between checkpoints (default 300)"
    )
    p.add_argument(
        "--resume", metavar="FILE", help="continue the run from this checkpoint (written by "
        "--checkpoint for the same case; only load checkpoints you trust: they are pickles)"
    )
    p.set_defaults(func=cmd_run)

    p = sub.add_parser(
        "plot",
        help="draw shape snapshots, energies and Tw/Wr/Lk (or a sweep's threshold map) as "
        "PNG files",
        description="Draw the seed paper's figures from a result file: the rod (a tube of "
        "its diameter, contact sites and ends marked) at the run's events with orthogonal "
        "views (Fig. 6), energies (Fig. 7) and twist, writhe and linking number (Fig. 8); for a "
        "magnetic-tweezers run, extension and torque against the turns. "
        "From a sweep's combined file (hockle sweep): the threshold map, each event's time "
        "and the linking number at buckling against the varied parameter(s), and the "
        "members' writhe over time.",
    )
    p.add_argument("result", metavar="OUT.nc",
                   help="result file written by hockle run (or a sweep's, by hockle sweep)")
    p.add_argument(
        "-o", "--output-dir", metavar="DIR", help="where to write (default: <stem>_plots/ "
        "next to the file)"
    )
    p.add_argument(
        "--times", nargs="+", type=float, metavar="T",
        help="snapshot times in s (default: the run's events: onset of buckling, first "
        "contact, each unit step of the writhe, the end; 5 spread over the run when none)",
    )
    p.set_defaults(func=cmd_plot)

    # hockle.animate.DEFAULT_* (tests/hockle/test_animate.py checks they agree); not imported
    # from there, which would load matplotlib and xarray for every command
    DEFAULT_FRAMES, DEFAULT_FPS, DEFAULT_DPI = 150, 15, 80
    p = sub.add_parser(
        "animate",
        help="an animation (.gif, or .mp4 with ffmpeg) of the rod beside its energies and "
        "Tw/Wr/Lk",
        description="Animate a result file: the rod in 3-D as hockle plot draws it (a tube "
        "of its diameter, contact sites and ends marked; zoomed, as hockle plot's views are, to "
        "where the rod moves when that is a small part of it) beside the energies and twist, "
        "writhe and linking number drawn up to each frame's time, with t in the title. "
        ".gif is written with Pillow; .mp4 needs ffmpeg (exit 2 without it: write a .gif). "
        "The file is read frame by frame, so memory stays bounded.",
    )
    p.add_argument("result", metavar="OUT.nc", help="result file written by hockle run")
    p.add_argument(
        "-o", "--output", metavar="FILE.gif|FILE.mp4",
        help="animation to write; the suffix picks the format (default: <stem>.gif next "
        "to the result)"
    )
    p.add_argument("--fps", type=float, default=DEFAULT_FPS,
                   help=f"frames per second (default {DEFAULT_FPS})")
    p.add_argument(
        "--frames", type=int, default=DEFAULT_FRAMES, metavar="N",
        help=f"at most N frames, the stored outputs subsampled evenly, first and last "
        f"included (default {DEFAULT_FRAMES})"
    )
    p.add_argument("--dpi", type=float, default=DEFAULT_DPI,
                   help=f"resolution; the figure is 11 x 5.6 inches (default {DEFAULT_DPI})")
    p.add_argument("--times", nargs=2, type=float, metavar=("T0", "T1"),
                   help="only the outputs with T0 <= t <= T1 (s); the curves span this "
                   "window")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=cmd_animate)

    p = sub.add_parser(
        "export",
        help="a VTK series (.pvd + .vtu frames) of the rod for ParaView: a run over time, "
        "a branch's shapes over its points",
        description="Write a result file as a ParaView data collection: one VTK file per "
        "output time with the centreline as line cells and the per-node fields as point "
        "data, each named with its frame: v, omega, f, kappa, moment along the directors "
        "(v_body, ...) and, when the result stores orientation, turned into the global "
        "frame (v_global, ...); orientation, s and the radius. A continuation's branch "
        "(hockle continue) exports its stored shapes, one file per point, with the "
        "parameter and the unstable modes. Open the .pvd in ParaView (a Tube filter with "
        "its radius varied by the radius array draws the cable).",
    )
    p.add_argument("result", metavar="OUT.nc",
                   help="result file written by hockle run (or a branch, by hockle continue)")
    p.add_argument("-o", "--output", metavar="FILE.pvd",
                   help="collection to write; the frames go to <stem>/ beside it (default: "
                   "<result stem>.pvd next to the result; FILE.vtu writes the first frame "
                   "only)")
    p.add_argument("--stride", type=int, default=1, metavar="K",
                   help="every K-th output time (of a branch: stored shape), the last one "
                   "included (default 1: all)")
    p.add_argument("--times", nargs=2, type=float, metavar=("T0", "T1"),
                   help="only the outputs with T0 <= t <= T1 (s); a run only")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser(
        "continue",
        help="follow a case's static equilibria in one parameter (folds, branch points, "
        "stability) into a NetCDF branch file",
        description="Solve the static equilibrium of a case (end conditions read at --time, "
        "velocities integrated up to it; docs/statics.md) and follow it by pseudo-arclength "
        "continuation while the scalar at the dotted --parameter path (as sweeps spell it) "
        "goes from the case's value to --to. Folds and branch points are located and the "
        "unstable modes counted at every point; the branch (parameter, end loads, Tw, Wr, "
        "Lk, energies, shapes) is written for hockle plot.",
    )
    p.add_argument("case", metavar="CASE", help="case spec, .yaml/.yml or .json")
    p.add_argument("--parameter", required=True, metavar="PATH",
                   help="dotted path of a scalar of the case, e.g. "
                   "boundary.end.translation.2.force")
    p.add_argument("--to", required=True, type=float, metavar="VALUE",
                   help="the parameter's target value")
    p.add_argument("-o", "--output", metavar="BRANCH.nc",
                   help="branch file (default: <case stem>_branch.nc here)")
    p.add_argument("--time", type=float, metavar="T", help="time at which the end "
                   "conditions are read, s (default: numerics.t_end)")
    p.add_argument("--switch", action="store_true", help="leave the branch at its first "
                   "branch point (a simple one along the critical mode, a round rod's "
                   "symmetric pair along one mode of the pair)")
    p.add_argument("--max-points", type=int, default=500, metavar="N",
                   help="stop after N points (default 500)")
    p.add_argument("--step", type=float, default=0.05, metavar="F",
                   help="largest step, a fraction of the range's arclength (default 0.05)")
    p.add_argument("--shapes-every", type=int, default=1, metavar="K",
                   help="store positions and curvatures at every K-th point (default 1)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=cmd_continue)

    from hockle import sweep_command

    sweep_command.register(sub)

    reason = _register_service_commands(sub)
    return parser, reason


def _first_command(argv: list[str]) -> str | None:
    for token in argv:
        if not token.startswith("-"):
            return token
    return None


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser, service_problem = build_parser()
    command = _first_command(argv)
    if service_problem and command in SERVICE_COMMANDS:
        _err(f"hockle {command} is unavailable: {service_problem}")
        return EXIT_ERROR
    args = parser.parse_args(argv)
    func: Callable[[argparse.Namespace], Any] | None = getattr(args, "func", None) or getattr(
        args, "handler", None
    )
    if func is None:
        parser.print_help(sys.stderr)
        return EXIT_INVALID
    result = func(args)
    return EXIT_OK if result is None else int(result)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
