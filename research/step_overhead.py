"""The Python around each time step's compiled Newton solve (issue 41, "Less Python per
step on small grids"): where a small grid's wall time goes, and the wall time of one tree
of the code against another's, run interleaved.

Cases: PyElastica's plectoneme (``benchmarks/peer_compare.py``: the rod twisted at one end
into a plectoneme with self-contact, Morison drag, positions every 0.02 s) from t = 0 to
T_END = 8 s, through buckling (~6.5 s) and into contact (from ~7.2 s), at N = 20,
Δt = 0.05 s and at hockle's 1-% setting N = 100, Δt = 12.5 ms; for reference the seed
example (``cases/goyal-writhing.yaml``, N = 1000, Δt = 0.1 s) before its first contact,
to 10 s. Whole runs for ``compare --cases``: the seed example to 45 s (``seed-1000``),
the plectoneme at N = 100 to 12 s and ``cases/seabed-hockle.yaml`` to 10 s
(``seabed-hockle``), each with its case file's outputs.

Run:

* ``python -m research.step_overhead profile [--case plectoneme-20] [--root TREE]``:
  after a warm-up run, the fastest of 5 runs, the time inside numba-compiled calls made
  from Python (each compiled function the ``solver`` modules hold, timed by a wrapper;
  the fastest of 5 such runs) and what is left per step attempt, the inclusive time of
  the parts of an attempt (:data:`PARTS`, each wrapped in a timer), and a cProfile of one
  more run: Python-level calls per step attempt, the functions of largest own time.
* ``python -m research.step_overhead compare OLD_ROOT [--rounds 3]``: this tree
  against another checkout of hockle (``OLD_ROOT``, e.g. the main branch's), each in a
  worker process of its own, one thread each, kernels warmed first, run interleaved
  (old, new, old, new, ... per case, ``--rounds`` rounds): the wall per run, per accepted
  step and per Newton iteration (medians; also the smallest wall and the median CPU time
  of the worker process, which a shared machine's load inflates less), the ratios
  old/new, and the load average before and after each case. Results in
  ``research/results/step_overhead.json`` (other ``--cases``:
  ``step_overhead_<case>_<case>.json``).
* ``python -m research.step_overhead save DIR [--root OTHER_ROOT]``: each case's result
  with every output field, from this tree or another, as DIR/NAME.nc; two such folders
  are compared by ``python -m benchmarks.compare_results DIR_A DIR_B``.
"""
from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
             "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / "results"

T_END = 8.0
#: name -> (kind, N, Δt s, t_end s)
CASES = {
    "plectoneme-20": ("plectoneme", 20, 0.05, T_END),
    "plectoneme-100": ("plectoneme", 100, 0.0125, T_END),
    "seed-1000-precontact": ("seed", 1000, 0.1, 10.0),
    # whole runs, for ``compare --cases``: the seed example as its case file has it
    # (to 45 s, every output field) and the plectoneme at hockle's 1-% setting to the
    # 12 s of the PyElastica comparison (benchmarks/peer_compare.py)
    "seed-1000": ("seed", 1000, 0.1, 45.0),
    "plectoneme-100-12s": ("plectoneme", 100, 0.0125, 12.0),
    # the twisted cable that loops on the sea floor (docs/hockle.md), as its case file has it
    "seabed-hockle": ("seabed-hockle", 160, 0.05, 10.0),
}
#: the case files of the kinds built from one (their grid, Δt and end set from CASES)
CASE_FILES = {"seed": "goyal-writhing.yaml", "seabed-hockle": "seabed-hockle.yaml"}
#: the cases run when ``--cases`` is not given
DEFAULT_CASES = ["plectoneme-20", "plectoneme-100", "seed-1000-precontact"]


# --------------------------------------------------------------------------- the cases
def build_case(name: str, full: bool = False):
    """The Case of CASES[name], built with the ``solver`` already imported (a worker
    imports it from its own tree first); ``full``: every output field (the results
    compared by ``save``), else the plectoneme's positions alone."""
    from solver import Case
    kind, n, dt, t_end = CASES[name]
    if kind in CASE_FILES:
        spec = Case.from_file(ROOT / "cases" / CASE_FILES[kind]).model_dump(mode="json")
        spec["numerics"]["t_end"] = t_end
        spec["numerics"]["dt"] = dt
        spec["numerics"].pop("ds", None)
        spec["numerics"]["n_segments"] = n
        return Case.model_validate(spec)
    sys.path.insert(1, str(ROOT))          # benchmarks/, after the worker's own root
    from benchmarks import pyelastica_compare as pc
    every = max(1, int(round(0.02 / dt)))
    spec = pc._hockle_spec(n, dt, t_end, every,
                           end_rate_table={"t": [0.0, pc.T_RAMP], "value": [0.0, pc.OMEGA]},
                           fluid=True, forces=[{"value": [pc.IMPERFECTION, 0.0, 0.0]}],
                           contact=True,
                           fields=(["v", "omega", "f", "kappa", "position", "energies",
                                    "topology", "contact"] if full else ["position"]))
    return Case.model_validate(spec)


def run_once(case) -> dict:
    """One timed ``simulate`` of a case: wall and CPU time (s), accepted steps, refused
    attempts, Newton
    iterations, and the run's result dataset."""
    from solver import SolverDivergence, integrate
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        ds = integrate(case)
        status = "completed"
    except SolverDivergence as exc:
        ds, status = exc.partial, f"diverged at t = {exc.t:.4g} s"
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"wall": wall, "cpu": cpu, "status": status, "ds": ds,
            "steps": int(ds.sizes["step"]),
            "newton": int(ds.step_newton_iterations.sum()),
            "refused": int(ds.attrs.get("hockle_refused_attempts_total",
                                        sum(int(v) for v in ds.step_rejected_attempts.values)
                                        if "step_rejected_attempts" in ds else 0))}


# --------------------------------------------------------------------------- profile
def compiled_functions():
    """(module, attribute name, dispatcher) of every numba-compiled function the
    ``solver`` modules hold."""
    from numba.core.registry import CPUDispatcher
    import solver
    import pkgutil
    import importlib
    for info in pkgutil.walk_packages(solver.__path__, "solver."):
        importlib.import_module(info.name)
    out = []
    for mod_name, mod in list(sys.modules.items()):
        if not mod_name.startswith("solver") or mod is None:
            continue
        for attr, val in list(vars(mod).items()):
            if isinstance(val, CPUDispatcher):
                out.append((mod, attr, val))
    return out


def time_compiled(case) -> dict:
    """A run with every compiled function called from Python wrapped in a timer: the
    time inside them (s), their calls, the wall (s)."""
    acc = {"time": 0.0, "calls": 0}
    by_name: dict = {}
    patched = []
    wrappers = {}
    for mod, attr, fn in compiled_functions():
        if id(fn) not in wrappers:
            def wrapper(*a, _fn=fn, _name=fn.py_func.__qualname__, **k):
                t0 = time.perf_counter()
                try:
                    return _fn(*a, **k)
                finally:
                    dt = time.perf_counter() - t0
                    acc["time"] += dt
                    acc["calls"] += 1
                    e = by_name.setdefault(_name, [0, 0.0])
                    e[0] += 1
                    e[1] += dt
            wrappers[id(fn)] = wrapper
        setattr(mod, attr, wrappers[id(fn)])
        patched.append((mod, attr, fn))
    try:
        r = run_once(case)
    finally:
        for mod, attr, fn in patched:
            setattr(mod, attr, fn)
    r.pop("ds")
    return {**r, "compiled_s": acc["time"], "compiled_calls": acc["calls"],
            "by_kernel": sorted(((k, v[0], v[1]) for k, v in by_name.items()),
                                key=lambda x: -x[2])}


#: the parts of a step attempt timed by :func:`time_parts`: (module, class or None, name)
PARTS = [("solver.run", "RodRun", "try_step"),
         ("solver.step_problem", "ProblemAssembly", "step_problem"),
         ("solver.step_problem", "ProblemAssembly", "solve_problem"),
         ("solver.newton", "Newton", "solve"), ("solver.newton", None, "_newton_kernel"),
         ("solver.run", "RodRun", "_refusal"), ("solver.run", "RodRun", "_accept"),
         ("solver.stepping.guard", "GrowthGuard", "ok"),
         ("solver.balance", "EnergyBalance", "measure"),
         # balance's own name for the function, the one its calls go through (``_energy``
         # in trees before it moved to solver.energies)
         ("solver.balance", None, "total_and_kinetic"), ("solver.balance", None, "_energy"),
         ("solver.balance", "GlobalLoadWork", "step"),
         ("solver.balance", "EndWork", "step"), ("solver.balance", "DragWork", "step"),
         ("solver.balance", "ContactWork", "step"),
         ("solver.scheme", "RodSystem", "contact_summary"),
         ("solver.step_problem", "ProblemAssembly", "_candidates"),
         ("solver.step_problem", "ProblemAssembly", "end_correction"),
         ("solver.step_problem", "ProblemAssembly", "_predictions"),
         ("solver.scheme", "RodSystem", "begin_step"),
         ("solver.run", "RodRun", "_advance_accounts"),
         ("solver.step_problem", "ProblemAssembly", "_better_predictor"),
         ("solver.step_problem", "ProblemAssembly", "_local_error"),
         ("solver.contact.model", "SelfContact", "passes_through"),
         ("solver.recording", "OutputRecorder", "accepted"), ("solver.recording", "OutputRecorder", "record")]


def time_parts(case, repeats: int) -> list:
    """Inclusive wall time (s) and calls of each of PARTS present in this tree, summed
    over ``repeats`` runs with each part wrapped in a timer, and the attempts:
    (rows (name, calls, seconds), attempts)."""
    import importlib
    acc, patched = {}, []
    for mod_name, cls_name, attr in PARTS:
        mod = importlib.import_module(mod_name)
        owner = getattr(mod, cls_name) if cls_name else mod
        if attr not in vars(owner):
            continue
        fn = vars(owner)[attr]
        label = f"{cls_name or mod_name}.{attr}"
        acc[label] = [0, 0.0]

        def wrapper(*a, _fn=fn, _e=acc[label], **k):
            t0 = time.perf_counter()
            try:
                return _fn(*a, **k)
            finally:
                _e[0] += 1
                _e[1] += time.perf_counter() - t0
        setattr(owner, attr, wrapper)
        patched.append((owner, attr, fn))
    try:
        for _ in range(repeats):
            run_once(case)
    finally:
        for owner, attr, fn in patched:
            setattr(owner, attr, fn)
    attempts = acc["RodRun.try_step"][0] // repeats
    return [(k, c // repeats, t / repeats) for k, (c, t) in acc.items()], attempts


def profile(name: str, top: int = 30, repeats: int = 5) -> None:
    import cProfile
    import io
    import pstats
    case = build_case(name)
    run_once(case)                                   # warm: kernels, caches
    # the fastest of `repeats` runs, plain and with the compiled calls timed
    base = min((run_once(case) for _ in range(repeats)), key=lambda r: r["wall"])
    comp = min((time_compiled(case) for _ in range(repeats)), key=lambda r: r["wall"])
    prof = cProfile.Profile()
    prof.enable()
    r = run_once(case)
    prof.disable()
    st = pstats.Stats(prof)
    attempts = sum(v[1] for k, v in st.stats.items() if k[2] == "try_step")
    py_calls = sum(v[1] for v in st.stats.values())
    import solver
    print(f"solver from {Path(solver.__file__).parent}; load {_load()}")
    print(f"{name}: wall {base['wall']:.3f} s, {base['steps']} nominal steps, "
          f"{attempts} step attempts, {base['newton']} Newton iterations "
          f"({base['status']})")
    print(f"  per attempt: {1e6 * base['wall'] / attempts:.0f} µs wall, "
          f"{py_calls / attempts:.0f} Python-level calls (cProfile), "
          f"{comp['compiled_calls'] / attempts:.1f} compiled calls from Python")
    print(f"  compiled: {comp['compiled_s']:.3f} s of {comp['wall']:.3f} s "
          f"({100 * comp['compiled_s'] / comp['wall']:.0f} %); outside: "
          f"{1e6 * (comp['wall'] - comp['compiled_s']) / attempts:.0f} µs per attempt; "
          f"Newton iteration {1e6 * base['wall'] / max(base['newton'], 1):.0f} µs wall")
    for k, c, t in comp["by_kernel"][:8]:
        print(f"    {k:40s} {c:7d} calls {1e3 * t:9.1f} ms")
    rows, att = time_parts(case, repeats)
    print(f"  parts of a step attempt (inclusive, each wrapped in a timer; mean of "
          f"{repeats} runs):")
    for label, calls, t in rows:
        print(f"    {label:38s} {calls / att:5.2f} calls {1e6 * t / att:7.1f} µs an attempt")
    for key in ("tottime", "cumulative"):
        buf = io.StringIO()
        pstats.Stats(prof, stream=buf).strip_dirs().sort_stats(key).print_stats(top)
        text = buf.getvalue()
        print(text[text.index("   ncalls"):].rstrip())
    print(f"cProfile wall {r['wall']:.3f} s")


# --------------------------------------------------------------------------- compare
def worker(root: str) -> None:
    """A worker process: ``solver`` from ``root``; reads case names on stdin, answers one
    JSON line each (``warm NAME``: an untimed run)."""
    sys.path.insert(0, root)
    import solver
    assert Path(solver.__file__).resolve().parents[1] == Path(root).resolve(), solver.__file__
    from solver.compiled import warm_up
    warm_up()
    print(json.dumps({"ready": str(Path(solver.__file__).parent)}), flush=True)
    for line in sys.stdin:
        cmd = line.split()
        if not cmd:
            continue
        name = cmd[-1]
        r = run_once(build_case(name, full=cmd[0] == "save"))
        ds = r.pop("ds")
        if cmd[0] == "save":
            ds.to_netcdf(Path(cmd[1]) / f"{name}.nc")
        print(json.dumps(r), flush=True)


def _load() -> list[float]:
    return [round(x, 2) for x in os.getloadavg()]


def compare(old_root: str, rounds: int, names: list[str]) -> dict:
    trees = {"old": str(Path(old_root).resolve()), "new": str(ROOT)}
    procs = {}
    for key, root in trees.items():
        procs[key] = subprocess.Popen(
            [sys.executable, __file__, "worker", root], stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, text=True, cwd=root,
            env=dict(os.environ, PYTHONPATH=root))
        print(key, json.loads(procs[key].stdout.readline()), flush=True)

    def ask(key, cmd):
        procs[key].stdin.write(cmd + "\n")
        procs[key].stdin.flush()
        return json.loads(procs[key].stdout.readline())

    res = {"trees": trees, "rounds": rounds, "cases": {},
           "utc_start": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    for name in names:
        for key in trees:                            # warm: this case's kernels
            ask(key, f"warm {name}")
        load0, walls, cpus = _load(), {k: [] for k in trees}, {k: [] for k in trees}
        info = {}
        for _ in range(rounds):
            for key in trees:
                r = ask(key, f"run {name}")
                walls[key].append(r["wall"])
                cpus[key].append(r["cpu"])
                info[key] = r
        load1 = _load()
        row = {"load_before": load0, "load_after": load1}
        for key in trees:
            med = statistics.median(walls[key])
            row[key] = {"walls": walls[key], "median": med, "min": min(walls[key]),
                        "cpus": cpus[key], "cpu_median": statistics.median(cpus[key]),
                        "steps": info[key]["steps"], "newton": info[key]["newton"],
                        "status": info[key]["status"],
                        "per_step_ms": 1e3 * med / info[key]["steps"],
                        "per_newton_us": 1e6 * med / max(info[key]["newton"], 1)}
        for stat in ("median", "min", "cpu_median"):
            row[f"ratio_old_new_{stat}"] = row["old"][stat] / row["new"][stat]
        res["cases"][name] = row
        o, n = row["old"], row["new"]
        print(f"{name}: {CASES[name]}, load {load0} -> {load1}", flush=True)
        for key, d in (("old", o), ("new", n)):
            print(f"  {key}: walls {' '.join(f'{w:.3f}' for w in d['walls'])} s; median "
                  f"{d['median']:.3f} s, min {d['min']:.3f} s, CPU median "
                  f"{d['cpu_median']:.3f} s; {d['steps']} steps, {d['newton']} Newton "
                  f"iterations: {d['per_step_ms']:.3f} ms per step, "
                  f"{d['per_newton_us']:.0f} µs per iteration ({d['status']})", flush=True)
        print(f"  old/new: wall median {row['ratio_old_new_median']:.3f}, wall min "
              f"{row['ratio_old_new_min']:.3f}, CPU median "
              f"{row['ratio_old_new_cpu_median']:.3f}", flush=True)
    for p in procs.values():
        p.stdin.close()
        p.wait()
    RESULTS.mkdir(exist_ok=True)
    name = ("step_overhead.json" if sorted(names) == sorted(DEFAULT_CASES)
            else f"step_overhead_{'_'.join(names)}.json")
    (RESULTS / name).write_text(json.dumps(res, indent=1))
    return res


def save(root: str, folder: str, names: list[str]) -> None:
    """Each case's result (every field) from the tree at ``root``, written to
    ``folder``/NAME.nc, for ``benchmarks/compare_results.py``."""
    Path(folder).mkdir(parents=True, exist_ok=True)
    proc = subprocess.Popen([sys.executable, __file__, "worker", root], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, cwd=root,
                            env=dict(os.environ, PYTHONPATH=root))
    print(json.loads(proc.stdout.readline()), flush=True)
    for name in names:
        proc.stdin.write(f"save {Path(folder).resolve()} {name}\n")
        proc.stdin.flush()
        print(name, json.loads(proc.stdout.readline()), flush=True)
    proc.stdin.close()
    proc.wait()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("profile")
    p.add_argument("--case", default="plectoneme-20", choices=list(CASES))
    p.add_argument("--root", default=str(ROOT), help="the hockle tree to profile")
    c = sub.add_parser("compare")
    c.add_argument("old_root")
    c.add_argument("--rounds", type=int, default=3)
    c.add_argument("--cases", nargs="+", default=DEFAULT_CASES, choices=list(CASES))
    sv = sub.add_parser("save")
    sv.add_argument("folder")
    sv.add_argument("--root", default=str(ROOT))
    sv.add_argument("--cases", nargs="+", default=DEFAULT_CASES, choices=list(CASES))
    w = sub.add_parser("worker")
    w.add_argument("root")
    args = ap.parse_args()
    if args.cmd == "profile":
        sys.path.insert(0, str(Path(args.root).resolve()))
        profile(args.case)
    elif args.cmd == "save":
        save(args.root, args.folder, args.cases)
    elif args.cmd == "compare":
        compare(args.old_root, args.rounds, args.cases)
    else:
        worker(args.root)


if __name__ == "__main__":
    main()
