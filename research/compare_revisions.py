"""The centreline scheme's wall time on three cases, this tree against another checkout,
run alternately, the one after the other.

Each job runs in a fresh interpreter (``python -c``) with the checkout's root as its
working directory and first on ``PYTHONPATH``, BLAS on one thread; the two checkouts take
turns job by job, ``--repeat`` times, and the medians and their ratio are printed with
each run's Newton iterations and writhe at the end (which must agree to rounding where a
change is meant to keep the answer). Jobs:

* ``seed8``: cases/goyal-writhing.yaml without its contact, 0-8 s (N = 1000);
* ``hockle3``: cases/seabed-hockle.yaml, 0-3 s (the push-in and the lift-off);
* ``hockle10``: the same to 10 s (its self-contact from about 3.9 s);
* ``plect50``: PyElastica's plectoneme (benchmarks/pyelastica_compare.py), N = 50,
  Δt = 0.05 s, 0-9 s.

Run from the repository's root, with the other revision checked out beside it, e.g.
``git worktree add /tmp/base 59e54e7`` then ``python -m research.compare_revisions
--base /tmp/base --repeat 3 seed8 hockle3 plect50`` (about 2 minutes; each checkout
compiles its kernels on its first run, so run each once before).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_CASE = ("from solver.case import Case\n"
         "spec = Case.from_file('cases/{name}.yaml').model_dump(mode='json')\n")
JOBS = {
    "seed8": _CASE.format(name="goyal-writhing")
    + "spec['contact'] = None\nspec['numerics']['t_end'] = 8.0\n",
    "hockle3": _CASE.format(name="seabed-hockle") + "spec['numerics']['t_end'] = 3.0\n",
    "hockle10": _CASE.format(name="seabed-hockle") + "spec['numerics']['t_end'] = 10.0\n",
    "plect50": "from benchmarks.pyelastica_compare import hockle_plectoneme_case\n"
    "spec = hockle_plectoneme_case(50, 0.05, 9.0, out_dt=0.05).model_dump(mode='json')\n",
}
_RUN = """
import json, time
from threadpoolctl import threadpool_limits
from solver.case import Case
from solver.simulation import integrate
threadpool_limits(1)
spec['numerics']['formulation'] = 'centreline'
spec['output'] = {'every': 1, 'fields': ['position', 'topology']}
case = Case.model_validate(spec)
t0 = time.perf_counter()
ds = integrate(case)
wall = time.perf_counter() - t0
print(json.dumps([wall, int(ds.step_newton_iterations.sum()), float(ds.writhe[-1]),
                  ds.attrs.get('hockle_status')]))
"""


def run(job: str, root: Path) -> list:
    """[wall s, Newton iterations, Wr at the end, status] of ``job`` in checkout ``root``."""
    out = subprocess.run([sys.executable, "-c", JOBS[job] + _RUN], cwd=root,
                         capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": str(root)})
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("jobs", nargs="*", choices=sorted(JOBS), default=["seed8", "hockle3"])
    ap.add_argument("--base", type=Path, required=True, help="the other checkout's root")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    trees = {"base": args.base.resolve(), "this": ROOT}
    runs = {(j, t): [] for j in args.jobs for t in trees}
    print(f"load {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores at the start")
    for _ in range(args.repeat):
        for job in args.jobs:
            for name, root in trees.items():
                runs[(job, name)].append(run(job, root))
    print(f"load {os.getloadavg()[0]:.2f} at the end")
    for job in args.jobs:
        med = {t: statistics.median(r[0] for r in runs[(job, t)]) for t in trees}
        for t in trees:
            last = runs[(job, t)][-1]
            print(f"  {job:9s} {t:4s}: wall median {med[t]:6.2f} s "
                  f"({', '.join(f'{r[0]:.2f}' for r in runs[(job, t)])}), Newton "
                  f"iterations {last[1]}, Wr {last[2]:.10f}, {last[3]}")
        print(f"  {job:9s} this / base: {med['this'] / med['base']:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
