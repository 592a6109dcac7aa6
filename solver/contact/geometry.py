"""Distances between the centreline polyline's nodes and segments, and the swept test.

Numpy, with the closest point on the partner curve compiled by numba. Positions are
global (m); a segment k joins nodes k and k+1.
"""
from __future__ import annotations

import math

import numba
import numpy as np
from scipy.spatial import cKDTree

__all__ = ["point_segment", "run_minima", "point_curve", "curve_basis", "segment_segment", "swept_min_distance", "close_node_pairs", "candidate_pairs", "run_closest",
           "min_surface_gap", "max_distance", "ALL_PAIRS_NODES", "BLOCK_MIN_NODES"]


@numba.njit(cache=True, inline="always")
def _project(p0, p1, p2, a0, a1, a2, b0, b1, b2):
    """Closest point of p on the segment [a, b] (one point, compiled): returns
    (t ∈ [0, 1], x = p − (a + t(b − a)) as three floats, |b − a|²); t = 0 for a
    degenerate segment."""
    e0 = b0 - a0
    e1 = b1 - a1
    e2 = b2 - a2
    ee = e0 * e0 + e1 * e1 + e2 * e2
    w0 = p0 - a0
    w1 = p1 - a1
    w2 = p2 - a2
    t = 0.0
    if ee > 0.0:
        t = min(max((w0 * e0 + w1 * e1 + w2 * e2) / ee, 0.0), 1.0)
    return t, w0 - t * e0, w1 - t * e1, w2 - t * e2, ee


@numba.njit(cache=True)
def _point_segment_kernel(p, a, b, t, x, d, tau):
    for m in range(p.shape[0]):
        tm, x0, x1, x2, ee = _project(p[m, 0], p[m, 1], p[m, 2], a[m, 0], a[m, 1], a[m, 2],
                                      b[m, 0], b[m, 1], b[m, 2])
        t[m] = tm
        x[m, 0] = x0
        x[m, 1] = x1
        x[m, 2] = x2
        d[m] = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        sq = math.sqrt(ee) if ee > 0.0 else 1.0
        for c in range(3):
            tau[m, c] = (b[m, c] - a[m, c]) / sq


def point_segment(p, a, b):
    """Closest points of points p on segments [a, b], all (M, 3) m.

    Returns (t (M,) in [0, 1], x = p − (a + t(b − a)) (M, 3) m, d = |x| (M,) m,
    tau (M, 3) the unit segment tangents). Degenerate segments give t = 0.
    Compiled (numba).
    """
    p = np.ascontiguousarray(p, dtype=float)
    a = np.ascontiguousarray(a, dtype=float)
    b = np.ascontiguousarray(b, dtype=float)
    m = p.shape[0]
    t = np.empty(m)
    x = np.empty((m, 3))
    d = np.empty(m)
    tau = np.empty((m, 3))
    _point_segment_kernel(p, a, b, t, x, d, tau)
    return t, x, d, tau


@numba.njit(cache=True, inline="always")
def _run_minimum(r, own, seg, lo, hi):
    """The first combination m in [lo, hi) whose segment is closest to its owner."""
    best = np.inf
    arg = lo
    for m in range(lo, hi):
        i = own[m]
        j = seg[m]
        t, x0, x1, x2, ee = _project(r[i, 0], r[i, 1], r[i, 2], r[j, 0], r[j, 1],
                                     r[j, 2], r[j + 1, 0], r[j + 1, 1], r[j + 1, 2])
        # the distance itself (not its square): ties at rounding level resolve as
        # on point_segment's distances, to the first
        dd = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        if dd < best:
            best = dd
            arg = m
    return arg


@numba.njit(cache=True)
def _run_minima_kernel(r, own, seg, start, out):
    n_runs = start.shape[0]
    total = own.shape[0]
    for q in range(n_runs):
        out[q] = _run_minimum(r, own, seg, start[q],
                              start[q + 1] if q + 1 < n_runs else total)


def run_minima(positions, owner, segment, run_start):
    """For each run of owner/segment combinations (a run: the combinations from
    ``run_start[q]`` up to the next run's start), the index of the first combination
    whose segment [r_j, r_{j+1}] is closest to the owner node r_i (the polyline's closest
    segment). positions (N, 3) m; owner, segment (M,) int; run_start (R,) int, increasing
    from 0. Returns (R,) int. Compiled (numba): no (M, 3) gathers."""
    out = np.empty(len(run_start), dtype=np.intp)
    _run_minima_kernel(np.ascontiguousarray(positions, dtype=float),
                       np.ascontiguousarray(owner, dtype=np.intp),
                       np.ascontiguousarray(segment, dtype=np.intp),
                       np.ascontiguousarray(run_start, dtype=np.intp), out)
    return out


#: the uniform Catmull-Rom cubic in power form: c(t) = [1, t, t², t³] · _CATMULL_ROM ·
#: [r_{j−1}, r_j, r_{j+1}, r_{j+2}] (Catmull & Rom 1974; rows: powers of t, columns:
#: nodes): the cubic through r_j, r_{j+1} with tangents ½(r_{j+1} − r_{j−1}), ½(r_{j+2} − r_j)
_CATMULL_ROM = 0.5 * np.array([[0.0, 2.0, 0.0, 0.0],
                               [-1.0, 0.0, 1.0, 0.0],
                               [2.0, -5.0, 4.0, -1.0],
                               [-1.0, 3.0, -3.0, 1.0]])


def _fold_ends(m, lo, hi):
    """The matrix m (4, 4) with the ghost nodes of a first (lo) or last (hi) segment
    folded into the real ones: r_{−1} = 2r_0 − r_1, r_n = 2r_{n−1} − r_{n−2}."""
    m = m.copy()
    if lo:
        m[:, 1] += 2.0 * m[:, 0]
        m[:, 2] -= m[:, 0]
        m[:, 0] = 0.0
    if hi:
        m[:, 2] += 2.0 * m[:, 3]
        m[:, 1] -= m[:, 3]
        m[:, 3] = 0.0
    return m


#: _CATMULL_ROM for an interior segment, the first, the last, and a rod of one segment
_CATMULL_ROM_ENDS = np.stack([_fold_ends(_CATMULL_ROM, lo, hi)
                              for lo, hi in ((False, False), (True, False), (False, True),
                                             (True, True))])


def _segment_nodes(j, n_nodes, closed=False):
    """The four node indices (M, 4) of the Catmull-Rom cubic on each segment j (M,) int,
    clamped to the rod (the ghost nodes beyond an end are folded into the matrices). Of
    a closed rod (nodes 0 .. N, node N node 0 again, n_nodes = N + 1) the neighbours
    across the join instead: node N − 1 before segment 0, node 1 after segment N − 1
    (whose second node is N)."""
    idx = np.empty((j.shape[0], 4), dtype=np.intp)
    if closed:
        ring = n_nodes - 1
        idx[:, 0] = np.where(j - 1 < 0, j - 1 + ring, j - 1)
        idx[:, 3] = np.where(j + 2 > ring, j + 2 - ring, j + 2)
    else:
        idx[:, 0] = np.maximum(j - 1, 0)
        idx[:, 3] = np.minimum(j + 2, n_nodes - 1)
    idx[:, 1] = j
    idx[:, 2] = j + 1
    return idx


def _segment_matrices(j, n_nodes, closed=False):
    """The Catmull-Rom matrix (M, 4, 4) of each segment j (M,) int, its ends folded (of
    a closed rod every segment is interior: :func:`_segment_nodes`)."""
    if closed:
        return _CATMULL_ROM_ENDS[np.zeros(j.shape[0], np.intp)]
    return _CATMULL_ROM_ENDS[(j - 1 < 0).astype(np.intp) + 2 * (j + 2 > n_nodes - 1)]


def _basis(t, mats):
    """β, β', β'' stacked (M, 3, 4) at t (M,) for the segment matrices ``mats``
    (M, 4, 4): the powers of t and their derivatives times the matrix."""
    T = np.zeros((t.shape[0], 3, 4))
    t2 = t * t
    T[:, 0, 0] = 1.0
    T[:, 0, 1] = t
    T[:, 0, 2] = t2
    T[:, 0, 3] = t2 * t
    T[:, 1, 1] = 1.0
    T[:, 1, 2] = 2.0 * t
    T[:, 1, 3] = 3.0 * t2
    T[:, 2, 2] = 2.0
    T[:, 2, 3] = 6.0 * t
    return np.matmul(T, mats)


def curve_basis(t, j, n_nodes):
    """The partner curve's basis on segment j at parameter t: the uniform Catmull-Rom
    cubic c(t) = Σ_b β_b(t) r_{idx_b} through r_j (t = 0) and r_{j+1} (t = 1) with the
    tangents ½(r_{j+1} − r_{j−1}) and ½(r_{j+2} − r_j) (Catmull & Rom, "A class of local
    interpolating splines", Computer Aided Geometric Design, 1974; the Hermite form of
    Farin, *Curves and Surfaces for CAGD*, § 8.5). Beyond a rod end the missing node is
    the linear extrapolation (r_{−1} = 2r_0 − r_1), folded into the coefficients.

    The curve is C¹ across nodes, so the closest point of a partner strand to a node moves
    continuously as the strands slide, also on the concave side of a bend, where the
    closest point of the polyline jumps between segments (docs/contact.md § 1).

    t, j: (M,) float in [0, 1] and int segment indices (0 ≤ j ≤ n_nodes − 2).
    Returns (idx (M, 4) int node indices, β, β', β'' (M, 4) the basis and its first and
    second derivatives in t); Σ β = 1, Σ β' = Σ β'' = 0.
    """
    t = np.asarray(t, float)
    b = _basis(t, _segment_matrices(j, n_nodes))
    return _segment_nodes(j, n_nodes), b[:, 0], b[:, 1], b[:, 2]


@numba.njit(cache=True, inline="always")
def _curve_point(p0, p1, p2, r, idx, mat, iterations, b0_out, b1_out, m):
    """The closest point of p on the Catmull-Rom cubic of one segment (node indices idx
    (4,), matrix mat (4, 4); :func:`point_curve`'s docstring): writes β, β' into row m of
    b0_out, b1_out and returns (t, x (3 floats), c' (3 floats), g)."""
    # start: the chord's closest point
    t = _project(p0, p1, p2, r[idx[1], 0], r[idx[1], 1], r[idx[1], 2],
                 r[idx[2], 0], r[idx[2], 1], r[idx[2], 2])[0]
    x0 = x1 = x2 = 0.0
    d0 = d1 = d2 = 0.0
    g = 0.0
    for it in range(iterations + 1):
        t2 = t * t
        c0x = c0y = c0z = 0.0
        d0 = d1 = d2 = 0.0
        s0 = s1 = s2 = 0.0
        for b in range(4):
            # β_b, β'_b, β''_b: powers of t (and their derivatives) times column b
            bb = mat[0, b] + t * mat[1, b] + t2 * mat[2, b] + t2 * t * mat[3, b]
            db = mat[1, b] + 2.0 * t * mat[2, b] + 3.0 * t2 * mat[3, b]
            sb = 2.0 * mat[2, b] + 6.0 * t * mat[3, b]
            b0_out[m, b] = bb
            b1_out[m, b] = db
            a = idx[b]
            c0x += bb * r[a, 0]
            c0y += bb * r[a, 1]
            c0z += bb * r[a, 2]
            d0 += db * r[a, 0]
            d1 += db * r[a, 1]
            d2 += db * r[a, 2]
            s0 += sb * r[a, 0]
            s1 += sb * r[a, 1]
            s2 += sb * r[a, 2]
        x0 = p0 - c0x
        x1 = p1 - c0y
        x2 = p2 - c0z
        g = d0 * d0 + d1 * d1 + d2 * d2 - (x0 * s0 + x1 * s1 + x2 * s2)
        if it == iterations:
            break
        if g > 0.0:
            t = min(max(t + (d0 * x0 + d1 * x1 + d2 * x2) / g, 0.0), 1.0)
    return t, x0, x1, x2, d0, d1, d2, g


@numba.njit(cache=True)
def _point_curve_kernel(p, r, iterations, idx, mats, t_out, x_out, d_out, c1_out, g_out,
                        b0_out, b1_out):
    """Compiled body of :func:`point_curve`, one point at a time (its docstring); idx
    (M, 4) and mats (M, 4, 4) from :func:`_segment_nodes` and :func:`_segment_matrices`."""
    for m in range(p.shape[0]):
        t, x0, x1, x2, d0, d1, d2, g = _curve_point(p[m, 0], p[m, 1], p[m, 2], r, idx[m],
                                                    mats[m], iterations, b0_out, b1_out, m)
        t_out[m] = t
        x_out[m, 0] = x0
        x_out[m, 1] = x1
        x_out[m, 2] = x2
        d_out[m] = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        c1_out[m, 0] = d0
        c1_out[m, 1] = d1
        c1_out[m, 2] = d2
        g_out[m] = g


@numba.njit(cache=True)
def _run_point(r, own, seg, lo, hi, frozen_k, iterations, seg_nodes, seg_mats, tb0, tb1):
    """The closest point of one run (combinations lo .. hi inclusive) on its partner
    curve: the combination ``frozen_k`` if it is ≥ 0, else the best of the polyline's
    closest segment and its two neighbours in the run (the first on a tie). Writes β, β'
    of the candidates into rows 0-2 of tb0, tb1 (3, 4) and returns (k, t, x0, x1, x2, d,
    c'0, c'1, c'2, g, row of tb0/tb1 that holds the chosen one's basis)."""
    if frozen_k >= 0:
        trio = (frozen_k, frozen_k, frozen_k)
        count = 1
    else:
        k0 = _run_minimum(r, own, seg, lo, hi + 1)
        trio = (max(k0 - 1, lo), k0, min(k0 + 1, hi))
        count = 3
    best = np.inf
    bk = trio[0]
    bt = bx0 = bx1 = bx2 = bd = bc0 = bc1 = bc2 = bg = 0.0
    brow = 0
    for c in range(count):
        kc = trio[c]
        j = seg[kc]
        i = own[kc]
        t, x0, x1, x2, d0, d1, d2, g = _curve_point(r[i, 0], r[i, 1], r[i, 2], r,
                                                    seg_nodes[j], seg_mats[j],
                                                    iterations, tb0, tb1, c)
        d = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        if c == 0 or d < best:
            best = d
            bk, bt, bx0, bx1, bx2, bd = kc, t, x0, x1, x2, d
            bc0, bc1, bc2, bg, brow = d0, d1, d2, g, c
    return bk, bt, bx0, bx1, bx2, bd, bc0, bc1, bc2, bg, brow


@numba.njit(cache=True)
def _run_closest_kernel(r, own, seg, start, frozen, iterations, seg_nodes, seg_mats, k_out,
                        t_out, x_out, d_out, c1_out, g_out, idx_out, b0_out, b1_out):
    """Compiled body of :func:`run_closest`: per run q, the combination k (frozen[q] if
    ``frozen`` is non-empty, else the best of the polyline's closest segment and its two
    neighbours in the run, the first on a tie) and its closest point on the curve
    (:func:`_run_point`); seg_nodes (N−1, 4) and seg_mats (N−1, 4, 4) every segment's
    nodes and matrix (:func:`_segment_nodes`, :func:`_segment_matrices`)."""
    n_runs = start.shape[0]
    total = own.shape[0]
    tb0 = np.empty((3, 4))
    tb1 = np.empty((3, 4))
    for q in range(n_runs):
        lo = start[q]
        hi = (start[q + 1] if q + 1 < n_runs else total) - 1
        fk = frozen[q] if frozen.shape[0] else -1
        k, t, x0, x1, x2, d, c0, c1, c2, g, row = _run_point(
            r, own, seg, lo, hi, fk, iterations, seg_nodes, seg_mats, tb0, tb1)
        k_out[q] = k
        t_out[q] = t
        x_out[q, 0] = x0
        x_out[q, 1] = x1
        x_out[q, 2] = x2
        d_out[q] = d
        c1_out[q, 0] = c0
        c1_out[q, 1] = c1
        c1_out[q, 2] = c2
        g_out[q] = g
        j = seg[k]
        for b in range(4):
            idx_out[q, b] = seg_nodes[j, b]
            b0_out[q, b] = tb0[row, b]
            b1_out[q, b] = tb1[row, b]


def run_closest(positions, owner, segment, run_start, frozen=None, iterations=3,
                closed=False):
    """For each run of owner/segment combinations (as :func:`run_minima`), the
    combination whose partner curve segment holds the owner's closest point, and that
    point (:func:`point_curve`): the polyline's closest segment of the run
    (:func:`run_minima`) and its two neighbours in the run are tried on the curve, the
    nearest kept (the first on a tie). ``frozen`` (R,) int: the combination of each run
    given instead (Newton's frozen selection). Returns (k (R,), and point_curve's t, x,
    d, c', g, idx, β, β' for those combinations; shapes as there with M = R). positions
    (N, 3) m; owner, segment (M,) int, run_start (R,) int as :func:`run_minima` takes
    them (indices not checked). Compiled (numba): one pass over the runs, no (3R, 3)
    gathers; every segment's nodes and matrix from :func:`_segment_nodes` and
    :func:`_segment_matrices` (``closed``: of a closed rod, across its join)."""
    r = np.ascontiguousarray(positions, dtype=float)
    every = np.arange(r.shape[0] - 1)
    start = np.ascontiguousarray(run_start, dtype=np.intp)
    m = start.shape[0]
    k = np.empty(m, np.intp)
    t = np.empty(m)
    x = np.empty((m, 3))
    d = np.empty(m)
    c1 = np.empty((m, 3))
    g = np.empty(m)
    idx = np.empty((m, 4), np.intp)
    b0 = np.empty((m, 4))
    b1 = np.empty((m, 4))
    fz = (np.zeros(0, np.intp) if frozen is None
          else np.ascontiguousarray(frozen, dtype=np.intp))
    _run_closest_kernel(r, np.ascontiguousarray(owner, dtype=np.intp),
                        np.ascontiguousarray(segment, dtype=np.intp), start, fz,
                        int(iterations), _segment_nodes(every, r.shape[0], closed),
                        _segment_matrices(every, r.shape[0], closed), k, t, x, d, c1, g,
                        idx, b0, b1)
    return k, t, x, d, c1, g, idx, b0, b1


def point_curve(p, positions, j, iterations=3):
    """Closest points of points p (M, 3) m on the partner curves' segments j (M,) int
    (:func:`curve_basis` over the nodes ``positions`` (N, 3) m), t ∈ [0, 1].

    Newton on the stationarity c'(t)·(c(t) − p) = 0 from the polyline's closest point,
    clamped to [0, 1] (a few iterations reach round-off: the curve departs from the
    chord by O(Δs² κ)).
    Returns (t (M,), x = p − c(t) (M, 3) m, d = |x| (M,) m, c' (M, 3) m, g = |c'|² −
    x·c'' (M,) m², the second derivative of ½|p − c|² in t, idx (M, 4), β (M, 4),
    β' (M, 4)). Compiled (numba): one pass over the points, all iterations in registers.
    """
    p = np.ascontiguousarray(p, dtype=float)
    r = np.ascontiguousarray(positions, dtype=float)
    j = np.ascontiguousarray(j, dtype=np.intp)
    m = p.shape[0]
    t = np.empty(m)
    x = np.empty((m, 3))
    d = np.empty(m)
    c1 = np.empty((m, 3))
    g = np.empty(m)
    b0 = np.empty((m, 4))
    b1 = np.empty((m, 4))
    n = r.shape[0]
    idx = _segment_nodes(j, n)
    _point_curve_kernel(p, r, int(iterations), idx, _segment_matrices(j, n), t, x, d,
                        c1, g, b0, b1)
    return t, x, d, c1, g, idx, b0, b1


#: grids of at most this many nodes find their close node pairs by a compiled loop over
#: all pairs instead of a k-d tree: building and querying scipy's tree costs ~50 µs at 21
#: nodes, the loop ~1 µs; at 1001 nodes the tree takes ~0.4 ms and the loop would take ~1 ms
#: (measured 2026-11-23 on the 2-core development machine)
ALL_PAIRS_NODES = 128

#: the k-d tree is built on blocks of consecutive nodes, each about ``radius`` long in
#: arclength, when a block holds at least this many nodes (else on the nodes themselves)
BLOCK_MIN_NODES = 4


def close_node_pairs(positions, radius, s, separation_cut, period=np.inf):
    """Node pairs (a < b) closer than ``radius`` (m) and further apart in arclength than
    ``separation_cut`` (m), as two (P,) int arrays (no order). On grids of at most
    :data:`ALL_PAIRS_NODES` nodes from a compiled loop over all pairs (the whole grid as
    one block of :func:`_block_pairs_kernel`). Else from a k-d tree
    (scipy.spatial.cKDTree) over blocks of m ≈ radius/Δs consecutive nodes, each stood for
    by its middle node and the largest distance h of its nodes from it: two blocks can hold
    a pair within radius only if their middle nodes are within radius + h_A + h_B, blocks
    no farther apart in arclength than ``separation_cut`` are skipped whole, and the node
    pairs of the others are tested in a compiled pass (:func:`_block_pairs_kernel`). The
    same pairs as the tree's ``query_pairs`` on the nodes (distance ≤ radius), whose
    output grows as N·radius/Δs with the pairs along the rod that the arclength rule then
    drops (43,000 pairs for 4,300 kept at the seed example's 1000 segments, 199,000 for
    43,000 at 2000: 0.8 and 7.8 ms against 0.23 and 1.06 ms over blocks, measured 2026-11-23).
    With fewer than :data:`BLOCK_MIN_NODES` nodes per block the tree is built on the
    nodes. positions (N, 3) m, s (N,) m non-decreasing. ``period`` (m): a closed rod's
    length L, its N distinct nodes given (node N, node 0 again, left out), the arclength
    separation then measured around the ring, min(|Δs|, L − |Δs|); inf for an open rod.
    Raises ValueError for non-finite positions beyond :data:`ALL_PAIRS_NODES` nodes (as
    scipy's tree does).
    """
    n = len(positions)
    r = np.ascontiguousarray(positions, dtype=float)
    s = np.ascontiguousarray(s, dtype=float)
    if n < 2:
        z = np.zeros(0, dtype=np.intp)
        return z, z.copy()
    if n <= ALL_PAIRS_NODES:
        # all pairs: the whole grid as one block
        return _block_pairs_kernel(r, s, n, np.zeros((0, 2), np.intp), np.zeros(1),
                                   float(radius), float(separation_cut), float(period))
    ds = (s[-1] - s[0]) / (n - 1) if s[-1] > s[0] else 0.0
    m = int(radius / ds) if ds > 0.0 else 0
    if m < BLOCK_MIN_NODES:
        m = 1                                   # blocks of one node: the tree on the nodes
    centres, h = _block_bounds(r, m)
    if not np.isfinite(h).all():
        raise ValueError("close_node_pairs: positions must be finite")
    bp = cKDTree(centres).query_pairs(r=float(radius) + 2.0 * float(h.max()),
                                      output_type="ndarray")
    return _block_pairs_kernel(r, s, m, np.ascontiguousarray(bp, dtype=np.intp), h,
                               float(radius), float(separation_cut), float(period))


@numba.njit(cache=True)
def _block_bounds(r, m):
    """Blocks of m consecutive nodes of r (N, 3) (the last one shorter): their middle
    nodes' positions (B, 3) and the largest distance h (B,) (m) of a block's nodes from
    its middle node. Non-finite positions give an infinite h (every block is tested)."""
    n = r.shape[0]
    nb = (n + m - 1) // m
    centres = np.empty((nb, 3))
    h = np.zeros(nb)
    for blk in range(nb):
        lo = blk * m
        hi = min(n, lo + m)
        c = (lo + hi - 1) // 2
        for i in range(3):
            centres[blk, i] = r[c, i]
        big = 0.0
        for k in range(lo, hi):
            d0 = r[k, 0] - r[c, 0]
            d1 = r[k, 1] - r[c, 1]
            d2 = r[k, 2] - r[c, 2]
            d = d0 * d0 + d1 * d1 + d2 * d2
            if not d <= big:
                big = d if d == d else np.inf
        h[blk] = math.sqrt(big)
    return centres, h


@numba.njit(cache=True)
def _block_pairs_kernel(r, s, m, block_pairs, h, radius, cut, period):
    """The node pairs (a < b) within ``radius`` and beyond ``cut`` in arclength of the
    blocks of m nodes (:func:`_block_bounds`) in block_pairs (Q, 2) (A < B) and of each
    block with itself: blocks whose largest arclength separation is at most ``cut`` are
    skipped whole, and in the others each node's partners start beyond the cut (s (N,)
    non-decreasing, as arclength is). ``period``: a ring's length (m; inf for an open
    rod), pairs then also beyond the cut the other way round, L − (s_b − s_a) > cut (the
    skip stays right: the periodic separation is at most the linear one). Two passes,
    count and fill."""
    n = r.shape[0]
    nb = h.shape[0]
    r2 = radius * radius
    nq = block_pairs.shape[0]
    count = 0
    a = np.empty(0, np.intp)
    b = np.empty(0, np.intp)
    for pas in range(2):
        if pas == 1:
            a = np.empty(count, np.intp)
            b = np.empty(count, np.intp)
            count = 0
        for q in range(nq + nb):
            if q < nq:
                A = block_pairs[q, 0]
                B = block_pairs[q, 1]
            else:
                A = q - nq
                B = A
            a_lo = A * m
            a_hi = min(n, a_lo + m)
            b_lo = B * m
            b_hi = min(n, b_lo + m)
            if max(abs(s[b_hi - 1] - s[a_lo]), abs(s[a_hi - 1] - s[b_lo])) <= cut:
                continue
            jc = b_lo
            for i in range(a_lo, a_hi):
                # s is non-decreasing: the partners beyond the cut start at jc, which
                # only moves on with i
                while jc < b_hi and not s[jc] - s[i] > cut:
                    jc += 1
                for j in range(max(jc, i + 1), b_hi):
                    if not s[j] - s[i] < period - cut:
                        break           # s non-decreasing: the rest are near round the ring
                    d0 = r[i, 0] - r[j, 0]
                    d1 = r[i, 1] - r[j, 1]
                    d2 = r[i, 2] - r[j, 2]
                    if d0 * d0 + d1 * d1 + d2 * d2 <= r2:
                        if pas == 1:
                            a[count] = i
                            b[count] = j
                        count += 1
    return a, b


@numba.njit(cache=True)
def max_distance(a, b):
    """max_k |a_k − b_k| (m) for point sets a, b (N, 3): how far any node moved."""
    m = 0.0
    for k in range(a.shape[0]):
        d0 = a[k, 0] - b[k, 0]
        d1 = a[k, 1] - b[k, 1]
        d2 = a[k, 2] - b[k, 2]
        d = d0 * d0 + d1 * d1 + d2 * d2
        if d > m or d != d:
            m = d
    return math.sqrt(m)


@numba.njit(cache=True)
def _candidate_pairs_kernel(r, t, a, b, sin_half_aperture):
    """Of the node pairs (a, b) (P,) each, those (if sin_half_aperture < 1) with
    |t_a·n| ≤ and |t_b·n| ≤ it, n the unit vector between them, in both orders, laid out
    by owner (a counting sort) with each owner's partners sorted. Returns (owner (M,),
    partner (M,))."""
    n = r.shape[0]
    keep = np.zeros(a.shape[0], np.bool_)
    start = np.zeros(n + 1, np.intp)
    for k in range(a.shape[0]):
        i = a[k]
        j = b[k]
        if sin_half_aperture < 1.0:
            x = r[i, 0] - r[j, 0]
            y = r[i, 1] - r[j, 1]
            z = r[i, 2] - r[j, 2]
            d = math.sqrt(x * x + y * y + z * z)
            if d > 0.0:
                x /= d
                y /= d
                z /= d
            if (abs(t[i, 0] * x + t[i, 1] * y + t[i, 2] * z) > sin_half_aperture
                    or abs(t[j, 0] * x + t[j, 1] * y + t[j, 2] * z) > sin_half_aperture):
                continue
        keep[k] = True
        start[i + 1] += 1
        start[j + 1] += 1
    for k in range(n):
        start[k + 1] += start[k]
    fill = start[:n].copy()
    m = start[n]
    owner = np.empty(m, np.intp)
    partner = np.empty(m, np.intp)
    for k in range(a.shape[0]):
        if keep[k]:
            i = a[k]
            j = b[k]
            owner[fill[i]] = i
            partner[fill[i]] = j
            fill[i] += 1
            owner[fill[j]] = j
            partner[fill[j]] = i
            fill[j] += 1
    for k in range(n):
        if start[k + 1] - start[k] > 1:
            partner[start[k]:start[k + 1]] = np.sort(partner[start[k]:start[k + 1]])
    return owner, partner


def candidate_pairs(positions, tangents, radius, s, separation_cut, sin_half_aperture,
                    period=np.inf):
    """Node pairs for the contact search, both orders: (owner (M,), partner (M,)) int
    arrays sorted by owner and then partner, each pair with centreline distance ≤
    ``radius`` (m), arclength separation > ``separation_cut`` (m) (:func:`close_node_pairs`)
    and, when ``sin_half_aperture`` < 1, each node inside the other's aperture cone
    (|a3 · n| ≤ sin(θ/2), n the unit vector between them; seed § 3). positions (N, 3) m,
    tangents (N, 3) unit a3 axes, s (N,) m. The cones and the ordering are one compiled
    pass (:func:`_candidate_pairs_kernel`), where numpy's filters and deduplication had
    taken 2 of the search's 3.4 ms at the seed example's 32 s. ``period``: a ring's
    length (:func:`close_node_pairs`). Raises nothing of its own (scipy's k-d tree
    rejects non-finite positions)."""
    r = np.ascontiguousarray(positions, dtype=float)
    a, b = close_node_pairs(r, radius, s, separation_cut, period)
    return _candidate_pairs_kernel(r, np.ascontiguousarray(tangents, dtype=float),
                                   np.ascontiguousarray(a, dtype=np.intp),
                                   np.ascontiguousarray(b, dtype=np.intp),
                                   float(sin_half_aperture))


def swept_min_distance(r0, r1, a, b):
    """Closest approach of node pairs (a, b) whose relative position moves linearly from
    r0[a] − r0[b] to r1[a] − r1[b] over the step. r0, r1: (N, 3) m; returns (P,) m.
    Compiled (:func:`_swept_kernel`)."""
    out = np.empty(len(a))
    _swept_kernel(np.ascontiguousarray(r0, dtype=float), np.ascontiguousarray(r1, dtype=float),
                  np.ascontiguousarray(a, dtype=np.intp), np.ascontiguousarray(b, dtype=np.intp),
                  out)
    return out


@numba.njit(cache=True)
def _swept_kernel(r0, r1, a, b, out):
    """:func:`swept_min_distance` into out (P,): per pair, x0 = r0_a − r0_b, its change
    dx over the step and the distance at the clamped minimiser t = −x0·dx/|dx|²."""
    for p in range(a.shape[0]):
        i = a[p]
        j = b[p]
        x0 = r0[i, 0] - r0[j, 0]
        x1 = r0[i, 1] - r0[j, 1]
        x2 = r0[i, 2] - r0[j, 2]
        d0 = (r1[i, 0] - r1[j, 0]) - x0
        d1 = (r1[i, 1] - r1[j, 1]) - x1
        d2 = (r1[i, 2] - r1[j, 2]) - x2
        dd = d0 * d0 + d1 * d1 + d2 * d2
        t = 0.0
        if dd > 0.0:
            t = min(max(-(x0 * d0 + x1 * d1 + x2 * d2) / dd, 0.0), 1.0)
        y0 = x0 + t * d0
        y1 = x1 + t * d1
        y2 = x2 + t * d2
        out[p] = math.sqrt(y0 * y0 + y1 * y1 + y2 * y2)


def segment_segment(p0, p1, q0, q1):
    """Closest distance (M,) m between segments [p0, p1] and [q0, q1], all (M, 3) m.

    The clamped two-parameter minimisation of Lumelsky, "On fast computation of distance
    between line segments", Inf. Process. Lett. 21 (1985) 55-61: s from the unclamped
    line-line solution clamped to [0, 1], t from s clamped, s recomputed from t.
    """
    d1 = p1 - p0
    d2 = q1 - q0
    r = p0 - q0
    a = np.einsum("ij,ij->i", d1, d1)
    e = np.einsum("ij,ij->i", d2, d2)
    f = np.einsum("ij,ij->i", d2, r)
    c = np.einsum("ij,ij->i", d1, r)
    b = np.einsum("ij,ij->i", d1, d2)
    denom = a * e - b * b
    a_s = np.where(a > 0, a, 1.0)
    e_s = np.where(e > 0, e, 1.0)
    s = np.where(denom > 1e-14 * a * e, np.clip((b * f - c * e) / np.where(denom > 0, denom, 1.0), 0, 1), 0.0)
    t = (b * s + f) / e_s
    s = np.where(t < 0, np.clip(-c / a_s, 0, 1), np.where(t > 1, np.clip((b - c) / a_s, 0, 1), s))
    t = np.clip(t, 0, 1)
    diff = p0 + s[:, None] * d1 - q0 - t[:, None] * d2
    return np.linalg.norm(diff, axis=1)


def min_surface_gap(positions, diameter, s, separation_cut, radius):
    """Smallest surface gap (m) between segments of the centreline polyline whose
    arclength separation exceeds ``separation_cut`` (m), over segment pairs whose
    midpoints are within ``radius`` (m); inf when there is none. The gap of a pair is
    the segment-segment distance minus the mean of the four end diameters' halves.
    positions (N, 3) m, diameter (N,) m, s (N,) m."""
    mid = 0.5 * (positions[1:] + positions[:-1])
    smid = 0.5 * (s[1:] + s[:-1])
    a, b = close_node_pairs(mid, radius, smid, separation_cut)
    if a.size == 0:
        return float("inf")
    d = segment_segment(positions[a], positions[a + 1], positions[b], positions[b + 1])
    dbar = 0.25 * (diameter[a] + diameter[a + 1] + diameter[b] + diameter[b + 1])
    return float(np.min(d - dbar))
