"""Twist, writhe and linking number of the rod centreline (numpy, the writhe pair sum compiled by numba; no I/O).

Conventions (see ``docs/topology.md``):

* Twist, seed eq. 7: ``Tw = (1/2π) ∫₀ᴸ κ3 ds`` with κ3 = a1'·a2 the material twist rate.
* Writhe: the Gauss double integral of the centreline, evaluated *exactly* for a polyline
  by the segment-pair solid-angle formula of Klenin & Langowski (2000).  An open rod is
  closed by long straight extensions of its end tangents (the "closure at infinity" used
  for a rod whose end tangents stay on a fixed axis).
* Linking number: ``Lk = (φ_end − φ_start)/2π`` from the end rotations about the axis, so
  that ``Lk = Tw + Wr`` (Călugăreanu–White–Fuller) holds for the closed ribbon.

Sources:

* K. Klenin & J. Langowski, "Computation of writhe in modeling of supercoiled DNA",
  Biopolymers 54 (2000) 307–317 (solid angle of a segment pair, normalisation
  Wr = Σ_{i≠j} Ω_ij / 4π).
* F. B. Fuller, "The writhing number of a space curve", PNAS 68 (1971) 815–819.
* G. Călugăreanu (1959/61); J. H. White, Am. J. Math. 91 (1969) 693–728: Lk = Tw + Wr.
* S. Goyal, N. C. Perkins, C. L. Lee, "Writhing dynamics of cables with self-contact"
  (the seed), eq. 7.

Implementation note on the pair formula.  For segments i = (p1, p2) and j = (p3, p4) the
directions (r_j(t) − r_i(u))/|·| sweep a spherical quadrilateral whose corners are the
directions of r13, r14, r24, r23; its signed area Ω_ij is the pair's Gauss integral.
Klenin & Langowski write |Ω_ij| as a sum of four arcsines of dot products of the
normalised face normals and take the sign of (r34 × r12)·r13.  Here the same solid angle
is evaluated as the sum of the two triangles (r13, r14, r24) and (r13, r24, r23) with the
Van Oosterom–Strackee formula, tan(Ω/2) = a·(b×c) / (|a||b||c| + (a·b)|c| + (a·c)|b| +
(b·c)|a|).  Both triangles have the same triple product, a·(b×c) = −(r34 × r12)·r13, so
with T = (r34 × r12)·r13 in the numerator the result carries the K&L sign directly:
Ω_ij = 2 atan2(T, den1) + 2 atan2(T, den2).  The result is the same number (the tests
compare with an arcsine implementation), but atan2 is well conditioned for nearly coplanar
pairs, where the arcsines sit at ±1, and it needs fewer transcendental calls.

Well-separated pairs (most of them).  Row i of the upper triangle needs the distances from
the vertices i and i+1 to every vertex; each row computes those of vertex i+1 once and
hands them to the next row.  The five dot products then follow from the squared vertex
distances and the segments by the law of cosines (a·b = (|a|² + |b|² − |s_j|²)/2 and
alike, a·c with s_i·s_j), and the two arctangents combine into one,
atan2(T, D1) + atan2(T, D2) = atan(x), x = T (D1 + D2)/(D1 D2 − T²), valid for D1, D2 > 0
and D1 D2 > T², evaluated by its Taylor series to x¹⁵ for |x| ≤ 1/16 (the next term is
below 5e-21·|x|).  This is the same closed form, not an approximation.  It is used where
every vertex distance of the pair is at least the longer segment's length (and the
conditions on x hold): then each angle of the triangles (a, b, s_j), (a, d, s_i), … facing
a segment is at most 60°, D1 ≥ |a||b||c| and D2 ≥ |a||c||d|, and the rounding of the dot
products (a few ε times the squared distances, at most 4.5 times |a||b| there) moves the
denominators by a few ε relative: the value agrees with the direct evaluation to rounding
(measured: 6.2e-15 turns over the 451 outputs of the seed example, 2e-14 on random walks;
``python -m research.writhe_speed --result FILE.nc``).
Pairs that fail the test (neighbours along the curve, pairs with the long end
extensions, strands crossing closer than a segment length, degenerate pairs) take the
direct evaluation from the vectors r13 … r23.  Source of the closed form: Klenin &
Langowski (2000), Van Oosterom & Strackee, IEEE Trans. Biomed. Eng. 30 (1983) 125–126.

Degenerate pairs.  Where T vanishes to working precision (|T| ≤ 64 ε |r12| |r34|
(|r_i| + |r_j|), r measured from the centroid) and the solid angle would jump (a
denominator ≤ 0: coplanar segments that intersect or share a vertex) the pair contributes
exactly 0; other coplanar, parallel, collinear or zero-length pairs give atan2(±0, >0) = 0
anyway.  No NaN can arise.  At an exact self-intersection the writhe is undefined (it jumps
by ±2 when one strand passes through another); this convention gives the coplanar value 0.
"""
from __future__ import annotations

import math
import threading

import numba
import numpy as np

__all__ = [
    "twist",
    "writhe",
    "writhe_closed",
    "writhe_polyline",
    "linking_number",
    "DEFAULT_EXTENSION_FACTOR",
]

#: Default length of each straight end extension, as a multiple of the polyline length.
#: The truncation error of the closure decays like (L/ℓ)² when both end tangents are on
#: one axis and like L/ℓ otherwise (docs/topology.md): measured ~1e-14 and ~5e-8 at 1e6
#: respectively, while the long segments are still well conditioned in double precision
#: (results agree to ~2e-8 from 1e6 up to 1e9).
DEFAULT_EXTENSION_FACTOR = 1.0e6

_TWO_PI = 2.0 * np.pi


# --------------------------------------------------------------------------- twist

def twist(kappa3, s) -> float:
    """Twist of the rod, seed eq. 7: ``Tw = (1/2π) ∫ κ3 ds`` (trapezoid rule over nodes).

    Parameters
    ----------
    kappa3 : (N,) array_like, rad/m
        Twist rate κ3 = a1'·a2 at the nodes (body component 3 of the curvature vector).
    s : (N,) array_like, m
        Arclength of the nodes, strictly increasing.

    Returns
    -------
    float
        Tw in turns.  N = 1 gives 0.

    Raises
    ------
    ValueError
        Shapes differ or are not 1-D, N = 0, non-finite values, or s not strictly
        increasing.

    Convention: a straight rod whose start end is rotated by +φ about a3 while the other end
    is held has κ3 = −φ/L and Tw = −φ/2π (``linking_number(φ, 0)`` gives the same).
    """
    k = np.asarray(kappa3, dtype=float)
    x = np.asarray(s, dtype=float)
    if k.ndim != 1 or x.ndim != 1:
        raise ValueError(f"twist: kappa3 and s must be 1-D, got shapes {k.shape} and {x.shape}")
    if k.shape != x.shape:
        raise ValueError(f"twist: kappa3 {k.shape} and s {x.shape} must have the same shape")
    if k.size == 0:
        raise ValueError("twist: need at least one node")
    total, problem = _twist_kernel(k, x)
    if problem == 1:
        raise ValueError("twist: kappa3 and s must be finite")
    if problem == 2:
        raise ValueError("twist: s must be strictly increasing")
    return total / _TWO_PI


@numba.njit(cache=True)
def _twist_kernel(k, s):
    """(∫ κ3 ds by the trapezoid rule, 0) for kappa3 k and arclength s (N,), or (NaN, 1)
    for a non-finite value and (NaN, 2) for s not strictly increasing."""
    total = 0.0
    for i in range(k.shape[0]):
        if not (np.isfinite(k[i]) and np.isfinite(s[i])):
            return np.nan, 1
    for i in range(k.shape[0] - 1):
        ds = s[i + 1] - s[i]
        if not ds > 0.0:
            return np.nan, 2
        total += 0.5 * (k[i + 1] + k[i]) * ds
    return total, 0


# --------------------------------------------------------------------------- writhe

def _as_points(points, name: str, min_points: int) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"{name}: points must have shape (N, 3), got {p.shape}")
    if p.shape[0] < min_points:
        raise ValueError(f"{name}: need at least {min_points} points, got {p.shape[0]}")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"{name}: points must be finite")
    return p


_EPS64 = 64.0 * float(np.finfo(float).eps)


@numba.njit(cache=True)
def _pair_setup(q):
    """Per-segment data of the centred polyline q (M+1, 3), m: the coordinate columns
    (M+1,), the segments s_k = q_{k+1} − q_k, U_k = q_k × s_k, the squared segment lengths,
    the segment lengths and the larger end radius |q| (all (M,))."""
    qx = np.ascontiguousarray(q[:, 0])
    qy = np.ascontiguousarray(q[:, 1])
    qz = np.ascontiguousarray(q[:, 2])
    sx = qx[1:] - qx[:-1]
    sy = qy[1:] - qy[:-1]
    sz = qz[1:] - qz[:-1]
    # U_k = q_k × seg_k
    ux = qy[:-1] * sz - qz[:-1] * sy
    uy = qz[:-1] * sx - qx[:-1] * sz
    uz = qx[:-1] * sy - qy[:-1] * sx
    len2 = sx * sx + sy * sy + sz * sz
    seg_len = np.sqrt(len2)
    radius = np.sqrt(qx * qx + qy * qy + qz * qz)
    rho = np.maximum(radius[:-1], radius[1:])
    return qx, qy, qz, sx, sy, sz, ux, uy, uz, len2, seg_len, rho


@numba.njit(cache=True)
def _distance_row(qx, qy, qz, v, k0, k1, e, n):
    """e[k] = |q_k − q_v|² and n[k] = |q_k − q_v| for k0 ≤ k < k1 (vertex distances of
    one row). The loop runs over slices from index 0, which numba compiles to contiguous
    vector loads (indices it cannot prove non-negative give gathers)."""
    px, py, pz = qx[v], qy[v], qz[v]
    xs = qx[k0:k1]
    ys = qy[k0:k1]
    zs = qz[k0:k1]
    es = e[k0:k1]
    ns = n[k0:k1]
    for k in range(k1 - k0):
        dx = xs[k] - px
        dy = ys[k] - py
        dz = zs[k] - pz
        d2 = dx * dx + dy * dy + dz * dz
        es[k] = d2
        ns[k] = math.sqrt(d2)


@numba.njit(cache=True, error_model="numpy", fastmath={"reassoc"})
def _row_far(data, e0, n0, e1, n1, i, j0, j1, near):
    """Σ Ω_ij/2 over the well-separated pairs (segment i, segment j), j0 ≤ j < j1, of one
    row (module docstring, "Well-separated pairs"); near[j] = True marks the others,
    which the caller sums by :func:`_pair_direct`. e0/n0 and e1/n1 hold the squared and
    plain distances from vertices i and i+1 to the vertices j0 … j1. Branch-free, over
    slices from index 0: compiled to a vector loop (the sum reassociated)."""
    qx, qy, qz, sx, sy, sz, ux, uy, uz, len2, seg_len, rho = data
    six, siy, siz = sx[i], sy[i], sz[i]
    uix, uiy, uiz = ux[i], uy[i], uz[i]
    li2 = len2[i]
    ea_ = e0[j0:j1]
    eb_ = e0[j0 + 1:j1 + 1]
    ec_ = e1[j0 + 1:j1 + 1]
    ed_ = e1[j0:j1]
    na_ = n0[j0:j1]
    nb_ = n0[j0 + 1:j1 + 1]
    nc_ = n1[j0 + 1:j1 + 1]
    nd_ = n1[j0:j1]
    lj2_ = len2[j0:j1]
    sjx = sx[j0:j1]
    sjy = sy[j0:j1]
    sjz = sz[j0:j1]
    ujx = ux[j0:j1]
    ujy = uy[j0:j1]
    ujz = uz[j0:j1]
    flag = near[j0:j1]
    acc = 0.0
    for k in range(j1 - j0):
        ea = ea_[k]
        eb = eb_[k]
        ec = ec_[k]
        ed = ed_[k]
        na = na_[k]
        nb = nb_[k]
        nc = nc_[k]
        nd = nd_[k]
        lj2 = lj2_[k]
        # a = r13, b = r14, c = r24, d = r23; dot products by the law of cosines
        # (a − b = −s_j, b − c = s_i, a − d = s_i, c − d = s_j, a − c = s_i − s_j)
        ab = 0.5 * (ea + eb - lj2)
        bc = 0.5 * (eb + ec - li2)
        ad = 0.5 * (ea + ed - li2)
        cd = 0.5 * (ec + ed - lj2)
        ac = 0.5 * (ea + ec - li2 - lj2) + (six * sjx[k] + siy * sjy[k] + siz * sjz[k])
        # (r34 × r12)·r13 = seg_i·U_j + seg_j·U_i
        t = (six * ujx[k] + siy * ujy[k] + siz * ujz[k]
             + sjx[k] * uix + sjy[k] * uiy + sjz[k] * uiz)
        d1 = na * nb * nc + ab * nc + ac * nb + bc * na
        d2 = na * nc * nd + ac * nd + ad * nc + cd * na
        # atan2(t, d1) + atan2(t, d2) = atan(x) for d1, d2 > 0 and d1 d2 > t²
        den = d1 * d2 - t * t
        x = t * (d1 + d2) / den
        far = (min(min(ea, eb), min(ec, ed)) >= max(li2, lj2)) and den > 0.0 and abs(x) <= 0.0625
        # atan(x) to x¹⁵: for |x| ≤ 1/16 the next term is below 5e-21·|x|
        x2 = x * x
        p = -1.0 / 15.0
        p = p * x2 + 1.0 / 13.0
        p = p * x2 - 1.0 / 11.0
        p = p * x2 + 1.0 / 9.0
        p = p * x2 - 1.0 / 7.0
        p = p * x2 + 1.0 / 5.0
        p = p * x2 - 1.0 / 3.0
        p = p * x2 + 1.0
        acc += x * p if far else 0.0
        flag[k] = not far
    return acc


@numba.njit(cache=True)
def _pair_direct(data, i, j):
    """Ω_ij/2 of the pair (segment i, segment j) from the vectors r13, r14, r24, r23
    themselves (module docstring), 0 for a degenerate pair."""
    qx, qy, qz, sx, sy, sz, ux, uy, uz, len2, seg_len, rho = data
    pix, piy, piz = qx[i], qy[i], qz[i]
    pjx, pjy, pjz = qx[i + 1], qy[i + 1], qz[i + 1]
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
    t = sx[i] * ux[j] + sy[i] * uy[j] + sz[i] * uz[j] + sx[j] * ux[i] + sy[j] * uy[i] + sz[j] * uz[i]
    d1 = na * nb * nc + ab * nc + ac * nb + bc * na
    d2 = na * nc * nd + ac * nd + ad * nc + cd * na
    # degenerate pairs (coplanar to working precision, module docstring)
    if min(d1, d2) <= 0.0 and abs(t) <= _EPS64 * seg_len[i] * (rho[i] + rho[j]) * seg_len[j]:
        return 0.0
    return math.atan2(t, d1) + math.atan2(t, d2)


@numba.njit(cache=True)
def _rows(data, r0, r1, closed):
    """Σ_{r0 ≤ i < r1} Σ_{j ≥ i+2} Ω_ij/2: the rows r0 … r1−1 of the upper triangle, the
    vertex distances of each row computed once and shared with the next."""
    qx, qy, qz = data[0], data[1], data[2]
    m = qx.shape[0] - 1
    e0 = np.empty(m + 1)
    n0 = np.empty(m + 1)
    e1 = np.empty(m + 1)
    n1 = np.empty(m + 1)
    near = np.empty(m, dtype=np.bool_)
    _distance_row(qx, qy, qz, r0, r0 + 2, m + 1, e0, n0)
    total = 0.0
    for i in range(r0, r1):
        j0 = i + 2
        j1 = m - 1 if (closed and i == 0) else m   # closed: (0, M−1) are adjacent
        _distance_row(qx, qy, qz, i + 1, j0, m + 1, e1, n1)
        row = _row_far(data, e0, n0, e1, n1, i, j0, j1, near)
        for j in range(j0, j1):
            if near[j]:
                row += _pair_direct(data, i, j)
        total += row
        e0, e1 = e1, e0
        n0, n1 = n1, n0
    return total


#: the rows of the pair sum are cut into this many runs of consecutive rows holding
#: about equal numbers of pairs, summed in this order on one core or on all: the result
#: is the same number whatever the number of threads
_CHUNKS = 16


@numba.njit(cache=True)
def _chunk_bounds(m):
    """Row bounds (_CHUNKS + 1,) of the runs of rows of the M − 2 rows (row i has
    M − 2 − i pairs) that hold about equal numbers of pairs."""
    rows = max(m - 2, 0)
    bounds = np.empty(_CHUNKS + 1, dtype=np.int64)
    bounds[0] = 0
    total = 0.5 * rows * (rows + 1)
    r = 0
    for c in range(1, _CHUNKS):
        target = total * c / _CHUNKS
        # pairs in rows 0 … r−1: r·rows − r(r−1)/2
        while r < rows and r * rows - 0.5 * r * (r - 1) < target:
            r += 1
        bounds[c] = r
    bounds[_CHUNKS] = rows
    return bounds


@numba.njit(cache=True)
def _pair_sum_kernel(q, closed):
    """Σ_{i<j, j ≥ i+2} Ω_ij of the (already centred) polyline q (M+1, 3), the runs of
    rows one after the other."""
    data = _pair_setup(q)
    bounds = _chunk_bounds(q.shape[0] - 1)
    total = 0.0
    for c in range(_CHUNKS):
        if bounds[c + 1] > bounds[c]:
            total += _rows(data, bounds[c], bounds[c + 1], closed)
    return 2.0 * total


@numba.njit(cache=True, parallel=True)
def _pair_sum_parallel(q, closed):
    """:func:`_pair_sum_kernel` on all cores: the runs of rows in parallel, their sums
    added in the same order, so the result is the same number."""
    data = _pair_setup(q)
    bounds = _chunk_bounds(q.shape[0] - 1)
    parts = np.zeros(_CHUNKS)
    for c in numba.prange(_CHUNKS):
        if bounds[c + 1] > bounds[c]:
            parts[c] = _rows(data, bounds[c], bounds[c + 1], closed)
    total = 0.0
    for c in range(_CHUNKS):
        total += parts[c]
    return 2.0 * total


#: polylines of at least this many segments sum their pairs on all cores
#: (:func:`_pair_sum_parallel`); waking the threads costs more than the sum below a few
#: hundred segments
PARALLEL_SEGMENTS = 400
_PARALLEL_LOCK = threading.Lock()


def _pair_sum(q: np.ndarray, closed: bool, center: np.ndarray | None = None) -> float:
    """Σ over non-adjacent segment pairs i < j of Ω_ij, for the polyline through q.

    q : (M+1, 3) vertices of M segments (segment k = q[k] → q[k+1]).  With ``closed`` the
    last vertex must equal the first one, and the pair (0, M−1), adjacent through the
    closure, is left out.  ``center`` (default: the mean vertex) is subtracted first; pass
    the mean of the rod's own nodes when q holds far-away extension vertices.  Returns
    Σ_{i<j} Ω_ij (radians of solid angle).

    Compiled (numba): one row of pairs at a time, a vector loop over the well-separated
    pairs (module docstring) and the direct formula for the others; from
    :data:`PARALLEL_SEGMENTS` segments on all cores, 16 runs of rows summed in a fixed
    order (the same number on any number of threads).  Cost per writhe at 1000 segments:
    ``python -m research.writhe_speed`` (docs/topology.md).
    """
    if center is None:
        center = q.mean(axis=0)
    # translation invariance; keeps the products well scaled
    return _centred_pair_sum(np.ascontiguousarray(q - center), closed)


def _centred_pair_sum(q: np.ndarray, closed: bool) -> float:
    """:func:`_pair_sum` of an already centred polyline q (M+1, 3), C-contiguous: on one
    core, or from :data:`PARALLEL_SEGMENTS` segments on all."""
    m = q.shape[0] - 1  # number of segments
    if m < 3:
        return 0.0
    if m >= PARALLEL_SEGMENTS:
        # numba's default threading layer (workqueue) takes one parallel launch at a
        # time: calls from several Python threads wait for each other here
        with _PARALLEL_LOCK:
            return float(_pair_sum_parallel(q, bool(closed)))
    return float(_pair_sum_kernel(q, bool(closed)))


def writhe_polyline(points) -> float:
    """Writhe of the open polyline through ``points`` *without* any closure.

    Σ over non-adjacent segment pairs i ≠ j of Ω_ij/4π (Klenin & Langowski 2000).  This
    is the building block of :func:`writhe`; on its own it is not a topological quantity.

    Parameters
    ----------
    points : (N, 3) array_like, m.  N ≥ 2.

    Returns
    -------
    float, dimensionless.

    Raises
    ------
    ValueError on a bad shape, fewer than 2 points or non-finite values.
    """
    p = _as_points(points, "writhe_polyline", 2)
    return _pair_sum(p, closed=False) / _TWO_PI


def _end_direction(seg: np.ndarray, from_start: bool) -> np.ndarray | None:
    lengths = np.linalg.norm(seg, axis=1)
    scale = float(np.max(lengths)) if lengths.size else 0.0
    if scale == 0.0:
        return None
    nonzero = np.flatnonzero(lengths > 1e-12 * scale)
    k = nonzero[0] if from_start else nonzero[-1]
    return seg[k] / lengths[k]


def writhe(points, extension=None) -> float:
    """Writhe of an open rod centreline closed by straight extensions of its end tangents.

    The polyline r_0 … r_{N−1} is extended by one straight segment of length ℓ before
    r_0, along −t_first, and one after r_{N−1}, along +t_last, where t_first / t_last are
    the directions of the first / last segment of non-zero length.  The writhe of the
    extended polyline is the exact segment-pair sum of Klenin & Langowski (2000):
    ``Wr = Σ_{i≠j} Ω_ij/4π = 2 Σ_{i<j} Ω_ij/4π`` over non-adjacent pairs (adjacent pairs
    contribute 0).  As ℓ → ∞ this is the writhe of the curve closed at infinity, the one
    for which ``Lk = Tw + Wr`` with ``Lk`` from :func:`linking_number` when both end
    tangents lie on the fixed axis.  The closure error decays like (L/ℓ)² for end tangents
    on one common line and like L/ℓ for general end tangents (docs/topology.md).

    Parameters
    ----------
    points : (N, 3) array_like, m
        Node positions along the centreline (global frame).  N ≥ 2.
    extension : float, optional, m
        Length ℓ of each end extension.  Default ``DEFAULT_EXTENSION_FACTOR`` (1e6) times
        the polyline length.  0 disables the extensions (then this is
        :func:`writhe_polyline`).

    Returns
    -------
    float
        Wr, dimensionless (≈ number of signed crossings averaged over all views).
        0 when all points coincide.

    Raises
    ------
    ValueError
        Points not of shape (N, 3) with N ≥ 2, non-finite points, or a negative or
        non-finite extension.

    Cost: O(N²) pairs, one row of the upper triangle at a time (O(N) memory); about
    1 ms for 1000 segments on one core of the 2-core development machine (compiled;
    ``python -m research.writhe_speed``).
    """
    p = _as_points(points, "writhe", 2)
    if extension is None:
        ell = -1.0
    else:
        ell = float(extension)
        if not np.isfinite(ell) or ell < 0.0:
            raise ValueError(f"writhe: extension must be a finite length >= 0, got {extension!r}")
    q = _extended(np.ascontiguousarray(p), ell, DEFAULT_EXTENSION_FACTOR)
    if q.shape[0] == 0:
        return 0.0
    return _centred_pair_sum(q, closed=False) / _TWO_PI


@numba.njit(cache=True)
def _extended(p, ell, factor):
    """The polyline p (N, 3) with :func:`writhe`'s end extensions of length ell (m; −1:
    ``factor`` × the polyline's length, 0: none), centred on p's mean; empty (0, 3) when
    all points coincide. The end directions are those of the first and last segment
    longer than 1e-12 of the longest."""
    n = p.shape[0]
    longest = 0.0
    length = 0.0
    for k in range(n - 1):
        d = math.sqrt((p[k + 1, 0] - p[k, 0]) ** 2 + (p[k + 1, 1] - p[k, 1]) ** 2
                      + (p[k + 1, 2] - p[k, 2]) ** 2)
        length += d
        longest = max(longest, d)
    if longest == 0.0:
        return np.zeros((0, 3))
    if ell < 0.0:
        ell = factor * length
    first = last = -1
    for k in range(n - 1):
        d = math.sqrt((p[k + 1, 0] - p[k, 0]) ** 2 + (p[k + 1, 1] - p[k, 1]) ** 2
                      + (p[k + 1, 2] - p[k, 2]) ** 2)
        if d > 1e-12 * longest:
            if first < 0:
                first = k
            last = k
    center = np.zeros(3)
    for k in range(n):
        for c in range(3):
            center[c] += p[k, c]
    for c in range(3):
        center[c] /= n
    extra = 1 if ell > 0.0 else 0
    q = np.empty((n + 2 * extra, 3))
    for k in range(n):
        for c in range(3):
            q[k + extra, c] = p[k, c] - center[c]
    if extra:
        d0 = math.sqrt((p[first + 1, 0] - p[first, 0]) ** 2 + (p[first + 1, 1] - p[first, 1]) ** 2
                       + (p[first + 1, 2] - p[first, 2]) ** 2)
        d1 = math.sqrt((p[last + 1, 0] - p[last, 0]) ** 2 + (p[last + 1, 1] - p[last, 1]) ** 2
                       + (p[last + 1, 2] - p[last, 2]) ** 2)
        for c in range(3):
            t0 = (p[first + 1, c] - p[first, c]) / d0
            t1 = (p[last + 1, c] - p[last, c]) / d1
            q[0, c] = (p[0, c] - ell * t0) - center[c]
            q[n + 1, c] = (p[n - 1, c] + ell * t1) - center[c]
    return q


def writhe_closed(points) -> float:
    """Writhe of the closed polygon r_0 → r_1 → … → r_{N−1} → r_0.

    Same exact segment-pair sum as :func:`writhe`, over the N segments of the closed
    polygon; the two segments meeting at r_0 are adjacent and contribute 0.  Do not repeat
    the first point at the end (a repeated point only adds a zero-length segment, which
    contributes 0, so the result is the same).

    Parameters
    ----------
    points : (N, 3) array_like, m.  N ≥ 3 (fewer cannot enclose anything and raise).

    Returns
    -------
    float, dimensionless.  Invariant under rigid motions and scaling, odd under mirror
    reflection.

    Raises
    ------
    ValueError on a bad shape, N < 3 or non-finite values.
    """
    p = _as_points(points, "writhe_closed", 3)
    q = np.vstack([p, p[:1]])
    return _pair_sum(q, closed=True) / _TWO_PI


# --------------------------------------------------------------------------- link

def linking_number(phi_start, phi_end):
    """Linking number of a rod whose end tangents stay on one fixed axis.

    ``Lk = (φ_end − φ_start)/2π`` where φ_start and φ_end are the rotation angles (rad) of
    the start (s = 0) and end (s = L) cross-sections about the axis, measured in the same
    right-handed sense about the common tangent direction, from the reference state.  The
    rod is closed at infinity by extending both ends along the axis, so Lk is the linking
    number of that closed ribbon and ``Lk = Tw + Wr`` (Călugăreanu–White) with Tw from
    :func:`twist` and Wr from :func:`writhe`, as long as no part of the rod passes around
    the closure (an integer jump of Lk − Tw − Wr signals a crossing).

    Example: a straight rod whose start is rotated by +φ while the end is held has
    κ3 = −φ/L, Tw = −φ/2π, Wr = 0 and Lk = (0 − φ)/2π = −φ/2π.

    Parameters
    ----------
    phi_start, phi_end : float or array_like (broadcastable), rad

    Returns
    -------
    float for scalar inputs, otherwise an ndarray of the broadcast shape (turns).

    Raises
    ------
    ValueError on non-finite input or shapes that do not broadcast.
    """
    a = np.asarray(phi_start, dtype=float)
    b = np.asarray(phi_end, dtype=float)
    try:
        lk = (b - a) / _TWO_PI
    except ValueError as exc:  # pragma: no cover - numpy raises on incompatible shapes
        raise ValueError(f"linking_number: shapes {a.shape} and {b.shape} do not broadcast") from exc
    if not np.all(np.isfinite(lk)):
        raise ValueError("linking_number: angles must be finite")
    if lk.ndim == 0:
        return float(lk)
    return lk
