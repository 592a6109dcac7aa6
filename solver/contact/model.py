"""Self-contact of one rod: candidate search, closest points and forces (seed §3, eq. 6).

Formulation (docs/contact.md):

* **Node to segment.** Every node i looks at the other strands of the centreline polyline.
  For each *run* of nearby partner nodes (contiguous along the partner strand, found once
  per time step by a k-d tree), the partner point is the closest point of that run's
  polyline to r_i: segment (j, j+1) at parameter t ∈ [0, 1]. The selection is redone at
  every Newton iterate, and it is continuous as the strands slide (the closest point of a
  polyline moves continuously), so a node never holds two partners on one strand and no
  re-solve with a union of pairs is needed. A minimum at the outer vertex of a run (not a
  rod end) is the edge of a cut (exclusion or search radius), not a closest approach, and
  gives no force.
* **Force.** f(d, ḋ) n per unit length (:mod:`solver.contact.laws`), n = x/d,
  x = r_i − c, c = (1 − t) r_j + t r_{j+1}, ḋ = n·(v_i − (1 − t) v_j − t v_{j+1}).
  Node i receives ½ f n; nodes j, j+1 receive −½ f n (1 − t) Δs_i/Δs_j and
  −½ f n t Δs_i/Δs_{j+1} (Δs the nodal quadrature weights), so Σ Δs·force = 0 and, as
  both strands' nodes own pairs, each strand receives f per unit length in total.
* **Search.** Candidates are node pairs with |s_i − s_j| > exclusion, centreline
  distance < tolerance + reach (reach: the motion the step may make) and each node
  inside the other's aperture cone (|a3 · n| ≤ sin(θ/2)), tested once per step.

Contact acts through the centreline without friction: no contact moment.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import close_node_pairs, point_segment
from .laws import BarrierLaw, SeedLaw

__all__ = ["SelfContact", "ContactCandidates", "ContactEvaluation", "assemble_nodal",
           "nodal_weights", "GAP_FLOOR_FRACTION", "EXCLUSION_DIAMETERS"]

#: gap_floor = GAP_FLOOR_FRACTION × mean diameter: below it the repulsion is linear.
GAP_FLOOR_FRACTION = 1.0e-3

#: default exclusion = EXCLUSION_DIAMETERS × max diameter.
EXCLUSION_DIAMETERS = 2.0


@dataclass(frozen=True)
class ContactCandidates:
    """Owner-node / partner-segment combinations to test during one step.

    Attributes
    ----------
    owner : (M,) int
        Owner node of each combination.
    segment : (M,) int
        Partner segment k (nodes k, k+1).
    run_start : (R,) int
        Index into owner/segment where each run begins (runs are contiguous blocks with
        one owner and consecutive segments).
    first_vertex_is_end, last_vertex_is_end : (R,) bool
        Whether the run's outer vertices are rod ends (a minimum there is a real contact).
    """

    owner: np.ndarray
    segment: np.ndarray
    run_start: np.ndarray
    first_vertex_is_end: np.ndarray
    last_vertex_is_end: np.ndarray

    @property
    def runs(self) -> int:
        return int(self.run_start.size)

    def __len__(self) -> int:
        return self.runs


@dataclass(frozen=True)
class ContactEvaluation:
    """Active contacts at one state and their derivatives.

    Attributes
    ----------
    i : (P,) int              owner nodes
    j : (P,) int              first node of the partner segment (the other is j + 1)
    t : (P,) float            closest-point parameter on the segment, [0, 1]
    nodes : (P, 3) int        (i, j, j + 1)
    weights : (P, 3) float    load weights w_a: node a receives w_a · force (N/m)
    coef : (P, 3) float       kinematic coefficients c_a: x = Σ c_a r_a, u = Σ c_a v_a
    force : (P, 3) float      force per unit length F = f n on the owner, N/m, global
    d_force_d_r : (P, 3, 3, 3)  ∂F/∂r_a for a = nodes[:, a] (N/m²), the closest point
                              sliding along the segment
    d_force_d_v : (P, 3, 3, 3)  ∂F/∂v_a (N·s/m²)
    d_t_d_r : (P, 3, 3)       ∂t/∂r_a (1/m): the load weights move with t
    d_weights_d_t : (P, 3)    ∂w_a/∂t, so node a's load w_a F changes by
                              w_a δF + F (∂w_a/∂t) Σ_b ∂t/∂r_b δr_b
    gap, distance : (P,) m    surface gap d − D̄ and centreline distance d
    min_gap : float, m        smallest gap (inf if none)
    count : int               P
    selection : (R,) int or None  the combination chosen in every candidate run (active or
                              not), to pass back as ``frozen`` (:meth:`SelfContact.closest`)
    """

    i: np.ndarray
    j: np.ndarray
    t: np.ndarray
    nodes: np.ndarray
    weights: np.ndarray
    coef: np.ndarray
    force: np.ndarray
    d_force_d_r: np.ndarray
    d_force_d_v: np.ndarray
    d_t_d_r: np.ndarray
    d_weights_d_t: np.ndarray
    gap: np.ndarray
    distance: np.ndarray
    min_gap: float
    count: int
    selection: np.ndarray | None = None


def nodal_weights(s) -> np.ndarray:
    """Nodal quadrature weights Δs (m) of a grid s (N,): half cells at the ends, so
    Σ Δs = s_{N−1} − s_0 (the trapezoid rule)."""
    s = np.asarray(s, dtype=float)
    w = np.zeros_like(s)
    if s.size >= 2:
        h = np.diff(s)
        w[:-1] += 0.5 * h
        w[1:] += 0.5 * h
    return w


def assemble_nodal(ev: ContactEvaluation, n_nodes: int) -> np.ndarray:
    """Nodal contact force density (n_nodes, 3) N/m, global: Σ_pairs w_a F at each node a.
    Σ_k Δs_k out_k = 0 to round-off (momentum balance). Raises ValueError for a node index
    outside [0, n_nodes)."""
    out = np.zeros((int(n_nodes), 3))
    if ev.count == 0:
        return out
    if ev.nodes.min() < 0 or ev.nodes.max() >= n_nodes:
        raise ValueError(f"assemble_nodal: node index outside [0, {n_nodes})")
    for a in range(3):
        np.add.at(out, ev.nodes[:, a], ev.weights[:, a, None] * ev.force)
    return out


def _spec_value(spec, name, default=None):
    if isinstance(spec, dict):
        return spec.get(name, default)
    return getattr(spec, name, default)


class SelfContact:
    """Self-contact of one rod (module doc): search, closest points and the force law.

    Parameters
    ----------
    spec
        Object or dict with ``aperture`` (deg, (0, 180]), ``tolerance`` (m, > max
        diameter: the search distance and the seed law's outer cut-off), ``k1``, ``k2``,
        ``k3``, ``k4`` (seed eq. 6), ``exclusion`` (m or None: 2 × max diameter) and
        optionally ``law`` ("seed" or "barrier"), ``barrier_gap`` ĝ (m) and
        ``barrier_stiffness`` κ (1/s²) for the barrier law.
    s : (N,) m, strictly increasing;  diameter : (N,) m > 0;  rho_a : (N,) kg/m > 0.

    Raises
    ------
    ValueError
        Bad shapes, non-finite or out-of-range values, tolerance ≤ max diameter, or a
        barrier law without a positive ``barrier_gap``/``barrier_stiffness``.
    """

    def __init__(self, spec, s, diameter, rho_a):
        s = np.asarray(s, dtype=float)
        diameter = np.asarray(diameter, dtype=float)
        rho_a = np.asarray(rho_a, dtype=float)
        if s.ndim != 1 or s.size < 2:
            raise ValueError(f"SelfContact: s must be 1-D with at least 2 nodes, got {s.shape}")
        for name, arr in (("diameter", diameter), ("rho_a", rho_a)):
            if arr.shape != s.shape:
                raise ValueError(f"SelfContact: {name} has shape {arr.shape}, s has {s.shape}")
        for name, arr in (("s", s), ("diameter", diameter), ("rho_a", rho_a)):
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"SelfContact: {name} must be finite")
        if np.any(np.diff(s) <= 0.0):
            raise ValueError("SelfContact: s must be strictly increasing")
        if np.any(diameter <= 0.0) or np.any(rho_a <= 0.0):
            raise ValueError("SelfContact: diameter and rho_a must be > 0")

        def num(name, lo=None, lo_open=False, hi=None, optional=False):
            v = _spec_value(spec, name)
            if v is None:
                if optional:
                    return None
                raise ValueError(f"SelfContact: spec.{name} is required")
            v = float(v)
            if not np.isfinite(v):
                raise ValueError(f"SelfContact: spec.{name} must be finite")
            if lo is not None and (v < lo or (lo_open and v == lo)):
                raise ValueError(f"SelfContact: spec.{name} = {v} must be "
                                 f"{'>' if lo_open else '>='} {lo}")
            if hi is not None and v > hi:
                raise ValueError(f"SelfContact: spec.{name} = {v} must be <= {hi}")
            return v

        self.aperture = num("aperture", lo=0.0, lo_open=True, hi=180.0)
        self.tolerance = num("tolerance", lo=0.0, lo_open=True)
        k1, k2 = num("k1", lo=0.0), num("k2", lo=0.0)
        k3, k4 = num("k3", lo=0.0), num("k4", lo=0.0)
        excl = num("exclusion", lo=0.0, optional=True)
        self.exclusion = EXCLUSION_DIAMETERS * float(diameter.max()) if excl is None else excl
        if self.tolerance <= float(diameter.max()):
            raise ValueError(
                f"SelfContact: tolerance ({self.tolerance} m) must exceed the largest diameter "
                f"({float(diameter.max())} m): pairs are tested only for centreline distance "
                "d < tolerance, so touching pairs (d = D) would be missed")
        self.gap_floor = GAP_FLOOR_FRACTION * float(diameter.mean())
        law = _spec_value(spec, "law", "seed") or "seed"
        if law == "seed":
            self.law = SeedLaw(k1, k2, k3, k4, self.tolerance, self.gap_floor)
        elif law == "barrier":
            d_hat = num("barrier_gap", lo=0.0, lo_open=True)
            kappa = num("barrier_stiffness", lo=0.0, lo_open=True)
            if float(diameter.max()) + d_hat > self.tolerance:
                raise ValueError(f"SelfContact: barrier_gap ({d_hat} m) plus the largest "
                                 f"diameter must not exceed the tolerance ({self.tolerance} m)")
            self.law = BarrierLaw(d_hat, kappa, k3, k4, self.gap_floor)
        else:
            raise ValueError(f"SelfContact: spec.law must be 'seed' or 'barrier', got {law!r}")
        self.s = s
        self.diameter = diameter
        self.rho_a = rho_a
        self.n_nodes = s.size
        self.weights = nodal_weights(s)
        # pairs must be further apart than the exclusion by more than rounding
        self.separation_cut = self.exclusion + 1e-9 * (s[-1] - s[0]) / (s.size - 1)
        partner = np.searchsorted(s, s + self.separation_cut, side="right")
        node = np.arange(s.size)
        cand = np.concatenate([partner - 1, partner])
        own = np.concatenate([node, node])
        valid = (cand > own) & (cand < s.size)
        sep = s[cand[valid]] - s[own[valid]]
        sep = sep[sep > self.separation_cut]
        self.min_separation = float(sep.min()) if sep.size else float("inf")
        self.sin_half_aperture = 1.0 if self.aperture >= 180.0 else float(
            np.sin(np.radians(self.aperture) / 2.0))

    # ------------------------------------------------------------------ checks
    def _check_field(self, name, arr) -> np.ndarray:
        a = np.asarray(arr, dtype=float)
        if a.shape != (self.n_nodes, 3):
            raise ValueError(f"SelfContact: {name} must have shape ({self.n_nodes}, 3), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"SelfContact: {name} must be finite")
        return a

    # ------------------------------------------------------------------ may_touch
    def may_touch(self, positions, tangents, reach: float = 0.0) -> bool:
        """O(N) rigorous pre-test: False only if no node pair can come closer than
        tolerance + reach (m).

        With e the normalised mean tangent and c = min_k (r_{k+1} − r_k)·e/(s_{k+1} − s_k),
        |r_j − r_i| ≥ c |s_j − s_i| ≥ c·s_sep for every pair beyond the exclusion (s_sep the
        smallest such grid separation), so c·s_sep ≥ tolerance + reach rules every pair out.
        positions (N, 3) m; tangents (N, 3) a3 (for e only). Raises ValueError on bad input.
        """
        r = self._check_field("positions", positions)
        t = self._check_field("tangents", tangents)
        e = t.mean(axis=0)
        norm = float(np.linalg.norm(e))
        if norm == 0.0:
            return True
        e = e / norm
        c = float(np.min((np.diff(r, axis=0) @ e) / np.diff(self.s)))
        return not (c > 0.0 and c * self.min_separation >= self.tolerance + reach)

    # ------------------------------------------------------------------ candidates
    def candidates(self, positions, tangents, reach: float = 0.0) -> ContactCandidates:
        """Owner/segment combinations for a step whose nodes may move by up to ``reach``
        (m) relative to ``positions`` (N, 3) m; ``tangents`` (N, 3) the a3 axes (global).

        Node pairs from a k-d tree within tolerance + reach, beyond the exclusion and
        inside both aperture cones; for each owner, partners closer than 3 nodes along the
        partner index form one run, extended by one node at each end (within the
        exclusion rule and the rod). Raises ValueError on bad shapes or values.
        """
        r = self._check_field("positions", positions)
        t = self._check_field("tangents", tangents)
        tn = np.linalg.norm(t, axis=1)
        if np.any(tn == 0.0):
            raise ValueError("SelfContact: tangents must be non-zero")
        t = t / tn[:, None]
        a, b = close_node_pairs(r, self.tolerance + reach, self.s, self.separation_cut)
        if a.size and self.sin_half_aperture < 1.0:
            n = r[a] - r[b]
            d = np.linalg.norm(n, axis=1)
            n = n / np.where(d > 0, d, 1.0)[:, None]
            lim = self.sin_half_aperture
            keep = ((np.abs(np.einsum("ij,ij->i", t[a], n)) <= lim)
                    & (np.abs(np.einsum("ij,ij->i", t[b], n)) <= lim))
            a, b = a[keep], b[keep]
        return self._runs(np.concatenate([a, b]), np.concatenate([b, a]))

    def merge(self, c1: ContactCandidates, c2: ContactCandidates) -> ContactCandidates:
        """Candidates covering both sets (runs rebuilt from the union of their nodes)."""
        own, par = [], []
        for c in (c1, c2):
            if c is None or not c.runs:
                continue
            own.append(c.owner)
            par.append(c.segment)
            own.append(c.owner)
            par.append(c.segment + 1)
        if not own:
            return self._runs(np.zeros(0, np.intp), np.zeros(0, np.intp))
        own, par = np.concatenate(own), np.concatenate(par)
        ok = np.abs(self.s[own] - self.s[par]) > self.separation_cut
        return self._runs(own[ok], par[ok])

    def covers(self, cand: ContactCandidates, other: ContactCandidates) -> bool:
        """Whether every owner/segment combination of ``other`` is in ``cand``."""
        if other is None or not other.runs:
            return True
        if cand is None or not cand.runs:
            return False
        n = self.n_nodes
        have = np.unique(cand.owner * n + cand.segment)
        need = np.unique(other.owner * n + other.segment)
        return bool(np.all(np.isin(need, have, assume_unique=True)))

    def _runs(self, own, par) -> ContactCandidates:
        n = self.n_nodes
        if own.size == 0:
            z = np.zeros(0, dtype=np.intp)
            zb = np.zeros(0, dtype=bool)
            return ContactCandidates(z, z.copy(), z.copy(), zb, zb.copy())
        key = np.unique(own.astype(np.int64) * n + par)
        own, par = key // n, key % n
        new = np.ones(own.size, dtype=bool)
        new[1:] = (own[1:] != own[:-1]) | (par[1:] > par[:-1] + 3)
        start = np.flatnonzero(new)
        stop = np.append(start[1:], own.size) - 1
        ro = own[start]
        lo, hi = par[start], par[stop]
        # extend by one node each side where that node is in the rod and beyond the
        # exclusion from the owner
        lo_ext = lo - 1
        ok = (lo_ext >= 0)
        ok[ok] &= np.abs(self.s[ro[ok]] - self.s[lo_ext[ok]]) > self.separation_cut
        lo = np.where(ok, lo_ext, lo)
        hi_ext = hi + 1
        ok = hi_ext < n
        ok[ok] &= np.abs(self.s[ro[ok]] - self.s[hi_ext[ok]]) > self.separation_cut
        hi = np.where(ok, hi_ext, hi)
        nseg = hi - lo                               # segments lo .. hi-1
        keep = nseg > 0
        ro, lo, hi, nseg = ro[keep], lo[keep], hi[keep], nseg[keep]
        run_start = np.concatenate([[0], np.cumsum(nseg)[:-1]]).astype(np.intp)
        owner = np.repeat(ro, nseg).astype(np.intp)
        offs = np.arange(int(nseg.sum())) - np.repeat(run_start, nseg)
        segment = (np.repeat(lo, nseg) + offs).astype(np.intp)
        return ContactCandidates(owner, segment, run_start, lo == 0, hi == n - 1)

    # ------------------------------------------------------------------ closest points
    def closest(self, cand: ContactCandidates, positions, frozen=None):
        """Closest point of each run: (k (R,) index into the combinations, t (R,),
        x (R, 3), d (R,), tau (R, 3), valid (R,) bool: not an interior run edge).

        frozen: (R,) combination indices from an earlier call, or None. Given, each run
        keeps that segment (the closest point still slides along it): Newton freezes the
        selection after a few iterates, because where two segments of a partner strand
        are about equally close (a concave corner) the choice can switch back and forth
        between iterates and the residual has a kink there."""
        r = positions
        own, seg = cand.owner, cand.segment
        start = cand.run_start
        last = np.append(start[1:], own.size) - 1
        if frozen is not None:
            k = frozen
            tk, x, d, tau = point_segment(r[own[k]], r[seg[k]], r[seg[k] + 1])
        else:
            t, x, d, tau = point_segment(r[own], r[seg], r[seg + 1])
            dmin = np.minimum.reduceat(d, start)
            sizes = last - start + 1
            hit = np.flatnonzero(d == np.repeat(dmin, sizes))
            k = hit[np.searchsorted(hit, start)]          # first minimum of each run
            tk, x, d, tau = t[k], x[k], d[k], tau[k]
        edge_lo = (k == start) & (tk == 0.0) & ~cand.first_vertex_is_end
        edge_hi = (k == last) & (tk == 1.0) & ~cand.last_vertex_is_end
        return k, tk, x, d, tau, ~(edge_lo | edge_hi)

    def gaps(self, cand: ContactCandidates, positions) -> np.ndarray:
        """Surface gaps (R,) m of the runs' closest points (inf for run edges)."""
        if cand is None or not cand.runs:
            return np.zeros(0)
        k, t, x, d, tau, valid = self.closest(cand, positions)
        i, j = cand.owner[k], cand.segment[k]
        return np.where(valid, d - self._at_contact(self.diameter, i, j, t), np.inf)

    @staticmethod
    def _at_contact(prop, i, j, t):
        """Mean of a nodal property (N,) between owner i and the partner point at t on
        segment (j, j+1): ½(p_i + (1 − t) p_j + t p_{j+1}), shape (P,)."""
        return 0.5 * (prop[i] + (1.0 - t) * prop[j] + t * prop[j + 1])

    def evaluate(self, cand: ContactCandidates, positions, velocities,
                 frozen=None) -> ContactEvaluation:
        """Active contacts of the candidates at a state (module doc), with derivatives.

        positions (N, 3) m and velocities (N, 3) m/s, global; frozen: see
        :meth:`closest` (``selection`` of the result is the one used). Derivatives with the
        closest point sliding on the segment. With G = ∂F/∂x|_u = n (f_d nᵀ + f_ḋ (u −
        ḋ n)ᵀ/d) + (f/d)(I − n nᵀ) and G_u = ∂F/∂u = f_ḋ n nᵀ, and for 0 < t < 1
        dx = (I − ττᵀ) dy − τ (x·de)/L, dt = τ·dy/L + x·de/L² (y = Σ c_a r_a at fixed t,
        e = r_{j+1} − r_j, L = |e|), u shifting by −(v_{j+1} − v_j) dt.

        Raises ValueError on bad shapes or values, or coincident centreline points.
        """
        r = self._check_field("positions", positions)
        v = self._check_field("velocities", velocities)
        if cand is None or not cand.runs:
            return _empty_evaluation()
        k, t, x, d, tau, valid = self.closest(cand, r, frozen)
        i, j = cand.owner[k], cand.segment[k]
        dbar = self._at_contact(self.diameter, i, j, t)
        d_off = self.law.cutoff(dbar)[1]
        keep = valid & (d < d_off)
        if not np.any(keep):
            return _empty_evaluation(k)
        i, j, t, x, d, tau, dbar = i[keep], j[keep], t[keep], x[keep], d[keep], tau[keep], dbar[keep]
        if np.any(d == 0.0):
            raise ValueError("SelfContact.evaluate: coincident centreline points in a pair")
        p = i.size
        nodes = np.stack([i, j, j + 1], axis=1)
        coef = np.stack([np.ones(p), t - 1.0, -t], axis=1)
        u = np.einsum("pa,pai->pi", coef, v[nodes])
        n = x / d[:, None]
        ddot = np.einsum("ij,ij->i", n, u)
        rho = self._at_contact(self.rho_a, i, j, t)
        f, f_d, f_dd, gap = self.law(d, ddot, dbar, rho)
        force = f[:, None] * n
        nn = n[:, :, None] * n[:, None, :]
        tang = (u - ddot[:, None] * n) / d[:, None]
        G = (n[:, :, None] * (f_d[:, None, None] * n[:, None, :]
                              + f_dd[:, None, None] * tang[:, None, :])
             + (f / d)[:, None, None] * (np.eye(3)[None] - nn))
        Gu = f_dd[:, None, None] * nn
        # the closest point slides: with y = Σ c_a r_a (t fixed), e = r_{j+1} − r_j,
        # L = |e|: dx = (I − ττᵀ) dy − τ (x·de)/L, dt = τ·dy/L + x·de/L², and u moves
        # by −(v_{j+1} − v_j) dt
        interior = ((t > 0.0) & (t < 1.0))[:, None, None]
        seg = r[j + 1] - r[j]
        L = np.linalg.norm(seg, axis=1)[:, None, None]
        gdv = np.einsum("pij,pj->pi", Gu, v[j + 1] - v[j])          # Gu Δv
        Gt = np.einsum("pij,pj->pi", G, tau)                          # G τ
        tt = tau[:, :, None] * tau[:, None, :]
        A = np.where(interior, G - Gt[:, :, None] * tau[:, None, :]
                     - gdv[:, :, None] * tau[:, None, :] / L, G)
        B = np.where(interior, -(Gt[:, :, None] * x[:, None, :]) / L
                     - gdv[:, :, None] * x[:, None, :] / L**2, 0.0)
        del tt
        sgn = np.array([0.0, -1.0, 1.0])
        d_dr = coef[:, :, None, None] * A[:, None] + sgn[None, :, None, None] * B[:, None]
        d_dv = coef[:, :, None, None] * Gu[:, None]
        w = self.weights
        weights = 0.5 * np.stack([np.ones(p), (t - 1.0) * w[i] / w[j], -t * w[i] / w[j + 1]], axis=1)
        dw_dt = 0.5 * np.stack([np.zeros(p), w[i] / w[j], -w[i] / w[j + 1]], axis=1)
        tl = tau / L[:, :, 0]
        xl = x / L[:, :, 0] ** 2
        dt_dr = np.stack([tl, (t - 1.0)[:, None] * tl - xl, -t[:, None] * tl + xl], axis=1)
        dt_dr = np.where(interior, dt_dr, 0.0)
        return ContactEvaluation(i, j, t, nodes, weights, coef, force, d_dr, d_dv, dt_dr,
                                 dw_dt, gap, d, float(gap.min()), int(p), k)


def _empty_evaluation(selection=None) -> ContactEvaluation:
    z = np.zeros(0)
    zi = np.zeros(0, dtype=np.intp)
    return ContactEvaluation(zi, zi.copy(), z, np.zeros((0, 3), np.intp), np.zeros((0, 3)),
                             np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3, 3, 3)),
                             np.zeros((0, 3, 3, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3)),
                             z.copy(), z.copy(), float("inf"), 0, selection)
