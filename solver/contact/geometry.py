"""Distances between the centreline polyline's nodes and segments, and the swept test.

Pure numpy. Positions are global (m); a segment k joins nodes k and k+1.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["point_segment", "swept_min_distance", "close_node_pairs"]


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
