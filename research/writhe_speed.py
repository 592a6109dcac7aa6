"""Time per writhe, the compiled pair sum of ``solver.topology`` against the row kernel it
replaced, and the largest difference between the two.

Shapes: a plectoneme (two strands interwound about an axis, an end loop, straight tails;
the helper of ``tests/solver/test_topology.py``) at N = 250, 1000 and 2000 segments, closed at
infinity as :func:`solver.topology.writhe` closes it; with ``--result FILE.nc`` also the
last output of a result file (its ``position``) and the largest difference over all its
outputs (the seed example: ``cases/goyal-writhing.yaml``, 451 outputs of 1001 nodes).

*old* is the kernel before the change, kept below verbatim as the baseline: per pair the
four vertex distances, five dot products and two arctangents from the vectors r13 … r23,
the triple products and denominators in one pass and the arctangents in a second; *new* is
``solver.topology._pair_sum_kernel`` / ``_pair_sum_parallel``. Both are compiled and run
once before timing. Timed: the pair sum of the already extended, centred polyline, on one
thread (the serial kernels) and on all threads (the parallel kernels, numba's thread
count), interleaved old, new, old, new … over ``--rounds`` rounds; medians printed with
the 1-min load average before and after. Difference: |Wr_new − Wr_old| in turns (both are
the exact polyline writhe; the difference is rounding).

Run: ``python -m research.writhe_speed [--rounds 40] [--result /tmp/wr_seed.nc]``.
"""
from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path

import numba
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
from solver import topology
from test_topology import plectoneme

# ------------------------------------------------------------------ the previous kernel

_EPS64 = 64.0 * float(np.finfo(float).eps)


@numba.njit
def _old_atan2_fast(t, den):
    if den > 0.0:
        x = t / den
        if abs(x) <= 0.0625:
            x2 = x * x
            p = -1.0 / 15.0
            p = p * x2 + 1.0 / 13.0
            p = p * x2 - 1.0 / 11.0
            p = p * x2 + 1.0 / 9.0
            p = p * x2 - 1.0 / 7.0
            p = p * x2 + 1.0 / 5.0
            p = p * x2 - 1.0 / 3.0
            p = p * x2 + 1.0
            return x * p
    return math.atan2(t, den)


@numba.njit
def _old_row_terms(qx, qy, qz, sx, sy, sz, ux, uy, uz, i, j0, j1, T, D1, D2):
    pix, piy, piz = qx[i], qy[i], qz[i]
    pjx, pjy, pjz = qx[i + 1], qy[i + 1], qz[i + 1]
    six, siy, siz = sx[i], sy[i], sz[i]
    uix, uiy, uiz = ux[i], uy[i], uz[i]
    for j in range(j0, j1):
        ax = qx[j] - pix
        ay = qy[j] - piy
        az = qz[j] - piz
        bx = qx[j + 1] - pix
        by = qy[j + 1] - piy
        bz = qz[j + 1] - piz
        cx = qx[j + 1] - pjx
        cy = qy[j + 1] - pjy
        cz = qz[j + 1] - pjz
        dx = qx[j] - pjx
        dy = qy[j] - pjy
        dz = qz[j] - pjz
        na = math.sqrt(ax * ax + ay * ay + az * az)
        nb = math.sqrt(bx * bx + by * by + bz * bz)
        nc = math.sqrt(cx * cx + cy * cy + cz * cz)
        nd = math.sqrt(dx * dx + dy * dy + dz * dz)
        ab = ax * bx + ay * by + az * bz
        ac = ax * cx + ay * cy + az * cz
        ad = ax * dx + ay * dy + az * dz
        bc = bx * cx + by * cy + bz * cz
        cd = cx * dx + cy * dy + cz * dz
        T[j] = six * ux[j] + siy * uy[j] + siz * uz[j] + sx[j] * uix + sy[j] * uiy + sz[j] * uiz
        D1[j] = na * nb * nc + ab * nc + ac * nb + bc * na
        D2[j] = na * nc * nd + ac * nd + ad * nc + cd * na


@numba.njit
def _old_setup(q):
    qx = np.ascontiguousarray(q[:, 0])
    qy = np.ascontiguousarray(q[:, 1])
    qz = np.ascontiguousarray(q[:, 2])
    sx = qx[1:] - qx[:-1]
    sy = qy[1:] - qy[:-1]
    sz = qz[1:] - qz[:-1]
    ux = qy[:-1] * sz - qz[:-1] * sy
    uy = qz[:-1] * sx - qx[:-1] * sz
    uz = qx[:-1] * sy - qy[:-1] * sx
    seg_len = np.sqrt(sx * sx + sy * sy + sz * sz)
    radius = np.sqrt(qx * qx + qy * qy + qz * qz)
    rho = np.maximum(radius[:-1], radius[1:])
    return qx, qy, qz, sx, sy, sz, ux, uy, uz, seg_len, rho


@numba.njit
def _old_row_sum(data, i, closed, T, D1, D2):
    qx, qy, qz, sx, sy, sz, ux, uy, uz, seg_len, rho = data
    m = seg_len.shape[0]
    j0 = i + 2
    j1 = m - 1 if (closed and i == 0) else m
    _old_row_terms(qx, qy, qz, sx, sy, sz, ux, uy, uz, i, j0, j1, T, D1, D2)
    thr_a = _EPS64 * seg_len[i] * rho[i]
    thr_b = _EPS64 * seg_len[i]
    row = 0.0
    for j in range(j0, j1):
        t = T[j]
        d1 = D1[j]
        d2 = D2[j]
        if min(d1, d2) <= 0.0 and abs(t) <= (thr_a + thr_b * rho[j]) * seg_len[j]:
            continue
        row += _old_atan2_fast(t, d1) + _old_atan2_fast(t, d2)
    return row


@numba.njit
def old_serial(q, closed):
    data = _old_setup(q)
    m = q.shape[0] - 1
    T = np.empty(m)
    D1 = np.empty(m)
    D2 = np.empty(m)
    total = 0.0
    for i in range(m - 2):
        total += _old_row_sum(data, i, closed, T, D1, D2)
    return 2.0 * total


@numba.njit(parallel=True)
def old_parallel(q, closed):
    data = _old_setup(q)
    m = q.shape[0] - 1
    rows = m - 2
    half = (rows + 1) // 2
    total = 0.0
    for k in numba.prange(half):
        T = np.empty(m)
        D1 = np.empty(m)
        D2 = np.empty(m)
        part = _old_row_sum(data, k, closed, T, D1, D2)
        other = rows - 1 - k
        if other != k:
            part += _old_row_sum(data, other, closed, T, D1, D2)
        total += part
    return 2.0 * total


# ------------------------------------------------------------------ measurement

def closed_at_infinity(points: np.ndarray) -> np.ndarray:
    """The extended, centred polyline that :func:`solver.topology.writhe` sums."""
    return topology._extended(np.ascontiguousarray(points, dtype=float), -1.0,
                              topology.DEFAULT_EXTENSION_FACTOR)


def timed(fn, q, rounds_out: list) -> float:
    t0 = time.perf_counter()
    value = fn(q, False)
    rounds_out.append(time.perf_counter() - t0)
    return value


def compare(label: str, q: np.ndarray, rounds: int) -> float:
    """Print the medians old/new on one and on all threads for the polyline q; return
    |Wr_new − Wr_old| (turns)."""
    pairs = {"1 thread": (old_serial, topology._pair_sum_kernel),
             f"{numba.get_num_threads()} threads": (old_parallel, topology._pair_sum_parallel)}
    worst = 0.0
    for threads, (old, new) in pairs.items():
        w_old = old(q, False)
        w_new = new(q, False)
        worst = max(worst, abs(w_new - w_old) / (2.0 * math.pi))
        t_old: list = []
        t_new: list = []
        for _ in range(rounds):
            timed(old, q, t_old)
            timed(new, q, t_new)
        a, b = np.median(t_old) * 1e3, np.median(t_new) * 1e3
        print(f"{label:>26} {threads:>10}: old {a:8.3f} ms  new {b:8.3f} ms  "
              f"old/new {a / b:5.1f}")
    return worst


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=40)
    parser.add_argument("--sizes", type=int, nargs="+", default=[250, 1000, 2000])
    parser.add_argument("--result", type=Path, default=None,
                        help="a result file (.nc) whose position outputs are compared too")
    args = parser.parse_args(argv)
    # compile both versions (not timed)
    warm = closed_at_infinity(plectoneme(50))
    for fn in (old_serial, old_parallel, topology._pair_sum_kernel, topology._pair_sum_parallel):
        fn(warm, False)
    print(f"1-min load before: {os.getloadavg()[0]:.2f}; {os.cpu_count()} cores, "
          f"numba threads {numba.get_num_threads()}; medians of {args.rounds} interleaved rounds")
    worst = 0.0
    for n in args.sizes:
        worst = max(worst, compare(f"plectoneme N = {n}", closed_at_infinity(plectoneme(n)),
                                   args.rounds))
    if args.result is not None:
        import xarray as xr

        with xr.open_dataset(args.result) as ds:
            positions = ds["position"].values
        n = positions.shape[1] - 1
        worst = max(worst, compare(f"{args.result.name} last, N = {n}",
                                   closed_at_infinity(positions[-1]), args.rounds))
        seed_worst = max(abs(topology._pair_sum_kernel(q, False) - old_serial(q, False))
                         for q in map(closed_at_infinity, positions)) / (2.0 * math.pi)
        print(f"largest |Wr_new - Wr_old| over the {len(positions)} outputs of "
              f"{args.result.name}: {seed_worst:.1e} turns")
        worst = max(worst, seed_worst)
    print(f"largest |Wr_new - Wr_old| over all shapes timed: {worst:.1e} turns")
    print(f"1-min load after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
