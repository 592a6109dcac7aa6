"""Distances between the centreline polyline's nodes and segments, and the swept test.

Pure numpy. Positions are global (m); a segment k joins nodes k and k+1.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["point_segment", "segment_segment", "swept_min_distance", "close_node_pairs",
           "min_surface_gap"]


def point_segment(p, a, b):
    """Closest points of points p on segments [a, b], all (M, 3) m.

    Returns (t (M,) in [0, 1], x = p − (a + t(b − a)) (M, 3) m, d = |x| (M,) m,
    tau (M, 3) the unit segment tangents). Degenerate segments give t = 0.
    """
    e = b - a
    ee = np.einsum("ij,ij->i", e, e)
    safe = np.where(ee > 0.0, ee, 1.0)
    t = np.clip(np.einsum("ij,ij->i", p - a, e) / safe, 0.0, 1.0)
    x = p - a - t[:, None] * e
    d = np.sqrt(np.einsum("ij,ij->i", x, x))
    tau = e / np.sqrt(safe)[:, None]
    return t, x, d, tau


def close_node_pairs(positions, radius, s, separation_cut):
    """Node pairs (a < b) closer than ``radius`` (m) and further apart in arclength than
    ``separation_cut`` (m), from a k-d tree (scipy.spatial.cKDTree), as two (P,) arrays."""
    cand = cKDTree(positions).query_pairs(r=radius, output_type="ndarray")
    if cand.size == 0:
        z = np.zeros(0, dtype=np.intp)
        return z, z.copy()
    a, b = cand[:, 0].astype(np.intp), cand[:, 1].astype(np.intp)
    keep = np.abs(s[a] - s[b]) > separation_cut
    return a[keep], b[keep]


def swept_min_distance(r0, r1, a, b):
    """Closest approach of node pairs (a, b) whose relative position moves linearly from
    r0[a] − r0[b] to r1[a] − r1[b] over the step. r0, r1: (N, 3) m; returns (P,) m."""
    x0 = r0[a] - r0[b]
    dx = (r1[a] - r1[b]) - x0
    dd = np.einsum("ij,ij->i", dx, dx)
    tmin = np.clip(-np.einsum("ij,ij->i", x0, dx) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    return np.linalg.norm(x0 + tmin[:, None] * dx, axis=1)


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
