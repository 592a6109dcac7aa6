"""Where the centreline scheme's time goes in the seed example's contact phase.

Runs ``cases/goyal-writhing.yaml`` on ``numerics.formulation: centreline`` to ``--start``
(default 17.5 s, before the first contact at 18.3 s), then from that state to ``--end``
(default 20 s) under cProfile with BLAS on one thread (as ``solver.simulation`` pins it):
the wall time, the steps, refusals and factorisations, and the functions that take the
most time. Then, on the last contact step's Jacobian (the band plus the pairs' blocks that
``solver.centreline._SparseLU`` factors), SuperLU's factorisation and solve under the
column orderings scipy offers, against LAPACK's band LU of the same matrix without the
pairs (``solver.static_band.BorderedBandLU``): what a factor outside SuperLU could save;
and two ways around SuperLU on that matrix, both with the pairs' entries inside the band
added to it and factored by the band LU: the Woodbury (capacitance) solve with the pairs'
columns outside the band as the low-rank part, and GMRES preconditioned by the band LU
(scipy's ``gmres``, relative residual 1e-12).

Run from the repository's root: ``python -m research.centreline_contact_cost``
(about 1.5 minutes on 2 cores). Cited in docs/numerics.md § 9 ("Limits").
"""
from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import time
from pathlib import Path

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from threadpoolctl import threadpool_limits

from solver import centreline as C
from solver.case import Case
from solver.centreline_run import CentrelineRun
from solver.static_band import KL, KU, BorderedBandLU

ROOT = Path(__file__).resolve().parents[1]


def _load() -> str:
    return f"load {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--start", type=float, default=17.5, help="s (default 17.5)")
    ap.add_argument("--end", type=float, default=20.0, help="s (default 20)")
    args = ap.parse_args(argv)
    threadpool_limits(1)
    spec = Case.from_file(ROOT / "cases" / "goyal-writhing.yaml").model_dump(mode="json")
    spec["numerics"]["formulation"] = "centreline"
    case = Case.model_validate(spec)
    dt = case.numerics.dt
    run = CentrelineRun(case)
    k = 0
    while run.state.t < args.start - 1e-9:
        k += 1
        run.advance(k * dt)
    captured = []
    factor = C._SparseLU.__init__

    def keep(self, ab, extra):
        factor(self, ab, extra)
        captured.append((ab, extra))

    C._SparseLU.__init__ = keep
    before = run.rod.factorizations
    print(f"the seed example on the centreline scheme, {args.start:g} -> {args.end:g} s "
          f"({_load()})")
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    steps = 0
    while run.state.t < args.end - 1e-9:
        k += 1
        run.advance(k * dt)
        steps += 1
    prof.disable()
    C._SparseLU.__init__ = factor
    print(f"  wall {time.perf_counter() - t0:.1f} s, {steps} nominal steps, "
          f"factorisations {run.rod.factorizations - before}, refused {run.control.refusals}")
    pstats.Stats(prof).sort_stats("tottime").print_stats(8)
    if not captured:
        print("  no step with pairs: nothing to factor")
        return 0
    ab, extra = captured[-1]
    A = C._SparseLU(ab, extra).A
    b = np.random.default_rng(0).standard_normal(A.shape[0])
    print(f"the last contact Jacobian: n = {A.shape[0]}, nnz = {A.nnz} ({_load()})")
    for perm in ("COLAMD", "MMD_ATA", "NATURAL"):
        times = []
        for _ in range(3):
            t0 = time.perf_counter()
            lu = spla.splu(A, permc_spec=perm)
            times.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        x = lu.solve(b)
        solve = time.perf_counter() - t0
        print(f"  SuperLU {perm:8s} factor {1e3 * min(times):7.1f} ms, solve {1e3 * solve:6.2f} "
              f"ms, nnz(L + U) {lu.L.nnz + lu.U.nnz}, residual "
              f"{np.abs(A @ x - b).max() / np.abs(b).max():.1e}")
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        band = BorderedBandLU(ab)
        times.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    band.solve(b)
    print(f"  band LU without the pairs: factor {1e3 * min(times):.1f} ms, solve "
          f"{1e3 * (time.perf_counter() - t0):.2f} ms")
    _around_superlu(ab, extra, A, b)
    return 0


def _around_superlu(ab, extra, A, b) -> None:
    """The Woodbury solve and band-preconditioned GMRES on A = band(ab) + extra."""
    e = extra.tocoo()
    inside = (e.row - e.col >= -KU) & (e.row - e.col <= KL)
    ab2 = ab.copy()
    ab2[KL + KU + e.row[inside] - e.col[inside], e.col[inside]] += e.data[inside]
    off = sp.csc_matrix((e.data[~inside], (e.row[~inside], e.col[~inside])), shape=A.shape)
    off.eliminate_zeros()
    cols = np.flatnonzero(np.diff(off.indptr))
    t0 = time.perf_counter()
    band = BorderedBandLU(ab2)
    Z = band._band_solve(off[:, cols].toarray())
    cap = sla.lu_factor(np.eye(cols.size) + Z[cols, :])
    factor = time.perf_counter() - t0
    y = band._band_solve(b)
    x = y - Z @ sla.lu_solve(cap, y[cols])
    print(f"  Woodbury on the {cols.size} columns outside the band: factor "
          f"{1e3 * factor:.1f} ms, residual {np.abs(A @ x - b).max() / np.abs(b).max():.1e}")
    its = [0]
    t0 = time.perf_counter()
    x, _ = spla.gmres(A, b, M=spla.LinearOperator(A.shape, matvec=band._band_solve),
                      rtol=1e-12, restart=100, maxiter=300, callback_type="pr_norm",
                      callback=lambda _: its.__setitem__(0, its[0] + 1))
    print(f"  GMRES with the band LU: {its[0]} iterations, {1e3 * (time.perf_counter() - t0):.1f}"
          f" ms a solve, residual {np.abs(A @ x - b).max() / np.abs(b).max():.1e}")


if __name__ == "__main__":
    raise SystemExit(main())
