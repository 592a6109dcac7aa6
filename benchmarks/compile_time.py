"""How long a fresh installation takes to compile the solver's kernels, and where it goes.

A fresh installation compiles every numba kernel on its first run (``hockle run`` says
so; docs/getting-started.md). This compiles them all, through
:func:`solver.compiled.warm_up` (the code paths a run takes), into an empty
``NUMBA_CACHE_DIR`` made for the purpose, and prints the total and, per compiled
function and signature, its compile time with and without the callees it compiled
(numba's ``numba:compile`` events, nested). A function listed more than once was
compiled once per signature: a literal True or False passed between compiled functions
makes a signature of its own (:func:`solver.banded.true_at_run_time`), so every
duplicate is worth a look. Last, the functions compiled for more than one signature,
with the arguments whose types differ.

Run: ``PYTHONPATH=$PWD python -m benchmarks.compile_time [--top 20] [--json PATH]`` (as
long as the compilation: 1.5 to 6 minutes on 2 cores, depending on the machine; the last
measured figure is in docs/benchmarks.md, earlier ones in research/notes/benchmarks-history.md). The process compiles
into its own temporary folder and leaves the installation's cache alone. For
``benchmarks/report.py`` (section "compile_time") the measurement runs in a fresh
process, since numba reads NUMBA_CACHE_DIR when it is first imported.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULT = HERE / "results" / "compile_time.json"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--top", type=int, default=20, help="functions listed (by own time)")
    ap.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = ap.parse_args()
    cache = tempfile.mkdtemp(prefix="hockle-compile-")
    os.environ["NUMBA_CACHE_DIR"] = cache          # before numba is imported
    try:
        res = measure(args.top)
    finally:
        shutil.rmtree(cache, ignore_errors=True)
    print(text(res))
    if args.json:
        args.json.write_text(json.dumps(res, indent=1))


def measure(top: int) -> dict:
    """Compile every kernel (this process must not have imported numba's cache yet) and
    return the total (s), the ``top`` functions by own compile time and the functions
    compiled for more than one signature."""
    from numba.core import event

    stack: list = []
    rows: list = []

    class Timer(event.Listener):
        def on_start(self, ev):
            stack.append([ev.data["dispatcher"], ev.data["args"], time.perf_counter(), 0.0])

        def on_end(self, ev):
            disp, sig, t0, children = stack.pop()
            dt = time.perf_counter() - t0
            if stack:
                stack[-1][3] += dt
            name = f"{disp.py_func.__module__}.{disp.py_func.__qualname__}"
            rows.append((name, dt, dt - children, disp, sig))

    load0 = os.getloadavg()[0]
    event.register("numba:compile", Timer())
    t0 = time.perf_counter()
    from solver.compiled import warm_up
    warm_up()
    total = time.perf_counter() - t0
    by_disp: dict = {}
    for name, _, own, disp, sig in rows:
        by_disp.setdefault(id(disp), (name, []))[1].append((own, sig))
    dups = []
    for name, sigs in sorted((v for v in by_disp.values() if len(v[1]) > 1),
                             key=lambda v: -sum(o for o, _ in v[1])):
        base = sigs[0][1]
        diffs = sorted({i for _, s in sigs[1:] for i, (a, b) in enumerate(zip(base, s))
                        if a != b})
        dups.append({"function": name, "signatures": len(sigs),
                     "own_s": sum(o for o, _ in sigs),
                     "differing": {str(i): sorted({str(s[i]) for _, s in sigs})
                                   for i in diffs}})
    import numba
    return {
        "stamp": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "numba": numba.__version__, "cpus": os.cpu_count(), "total_s": total,
        "signatures": len(rows), "load_start": load0, "load_end": os.getloadavg()[0],
        "top": [{"function": n, "with_callees_s": inc, "own_s": own}
                for n, inc, own, _, _ in sorted(rows, key=lambda r: -r[2])[:top]],
        "duplicates": dups,
    }


def text(res: dict) -> str:
    """The figures of :func:`measure` as a Markdown section."""
    lines = ["## First-run compilation of the kernels", "",
             f"Written by `benchmarks/compile_time.py` on {res['stamp']} (numba "
             f"{res['numba']}, {res['cpus']} CPUs; 1-min load {res['load_start']:.1f} at "
             f"the start, {res['load_end']:.1f} at the end): a fresh installation "
             f"compiles {res['signatures']} function signatures in "
             f"**{res['total_s']:.0f} s** (`solver.compiled.warm_up` into an empty "
             "`NUMBA_CACHE_DIR`; once cached, a process loads them in about 2 s). The "
             "largest by their own compile time (with callees: what compiling them "
             "compiled too):", "",
             "| function | with callees (s) | own (s) |", "|---|---:|---:|"]
    lines += [f"| `{r['function']}` | {r['with_callees_s']:.1f} | {r['own_s']:.1f} |"
              for r in res["top"]]
    lines += ["", f"{len(res['duplicates'])} functions compiled for more than one "
              "signature (each signature is compiled, with its callees, in full; a literal "
              "True or False passed between compiled functions is a signature of its own, "
              "`solver.banded.true_at_run_time`):", ""]
    for d in res["duplicates"]:
        kinds = "; ".join(f"argument {i}: {', '.join(v)}" for i, v in d["differing"].items())
        lines.append(f"* `{d['function']}` ×{d['signatures']}, {d['own_s']:.1f} s: {kinds}")
    return "\n".join(lines) + "\n"


def section(figdir=None, quick: bool = False) -> str:
    """The section for benchmarks/report.py: the measurement in a fresh process (numba
    reads NUMBA_CACHE_DIR once, at its import), its figures saved to RESULT."""
    RESULT.parent.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=str(HERE.parent) + os.pathsep
               + os.environ.get("PYTHONPATH", ""))
    subprocess.run([sys.executable, str(Path(__file__).resolve()), "--top", "10", "--json",
                    str(RESULT)], check=True, env=env, stdout=subprocess.DEVNULL)
    return text(json.loads(RESULT.read_text()))


if __name__ == "__main__":
    main()
