"""Self-contact of one rod: candidate search, closest points and forces (seed §3, eq. 6).

Formulation (docs/contact.md):

* **Node to curve.** Every node i looks at the other strands as a C¹ curve: the uniform
  Catmull-Rom cubic through the nodes (:func:`~.geometry.curve_basis`). For each *run* of
  nearby partner nodes (contiguous along the partner strand, found once per time step by
  a k-d tree), the partner point is the closest point of that run's curve to r_i:
  segment (j, j+1) at parameter t ∈ [0, 1], c(t) = Σ β_b(t) r_b over nodes j − 1 .. j + 2.
  The selection is redone at every Newton iterate, and it is continuous as the strands
  slide, on the concave side of a bend too (where the closest point of the polyline
  jumps between segments, and the residual with it), so a node never holds two partners
  on one strand and no re-solve with a union of pairs is needed. A minimum at the outer
  vertex of a run (not a rod end) is the edge of a cut (exclusion or search radius), not
  a closest approach, and gives no force.
* **Force.** f(d, ḋ) n per unit length (:mod:`solver.contact.laws`), n = x/d,
  x = r_i − c(t), ḋ = n·(v_i − Σ β_b v_b). Node i receives ½ f n; the curve's node b
  receives −½ f n β_b Δs_i/Δs_b (Δs the nodal quadrature weights), so Σ Δs·force = 0
  (Σ β_b = 1) and, as both strands' nodes own pairs, each strand receives f per unit
  length in total.
* **Search.** Candidates are node pairs with |s_i − s_j| > exclusion, centreline
  distance < tolerance + reach (reach: the motion the step may make) and each node
  inside the other's aperture cone (|a3 · n| ≤ sin(θ/2)), tested once per step.

Contact acts through the centreline without friction: no contact moment.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from .geometry import candidate_pairs, run_closest
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
    nodes : (P, 5) int        (i, j − 1, j, j + 1, j + 2): the owner and the nodes of the
                              partner curve on segment j (a node index repeats next to a
                              rod end, with coefficient 0 in its ghost slot)
    weights : (P, 5) float    load weights w_a: node a receives w_a · force (N/m)
    coef : (P, 5) float       kinematic coefficients c_a: x = Σ c_a r_a, u = Σ c_a v_a
    force : (P, 3) float      force per unit length F = f n on the owner, N/m, global
    d_force_d_r : (P, 5, 3, 3)  ∂F/∂r_a for a = nodes[:, a] (N/m²), the closest point
                              sliding along the segment
    d_force_d_v : (P, 5, 3, 3)  ∂F/∂v_a (N·s/m²)
    d_t_d_r : (P, 5, 3)       ∂t/∂r_a (1/m): the load weights move with t
    d_weights_d_t : (P, 5)    ∂w_a/∂t, so node a's load w_a F changes by
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
    for a in range(ev.nodes.shape[1]):
        np.add.at(out, ev.nodes[:, a], ev.weights[:, a, None] * ev.force)
    return out


#: largest key range (n_nodes²) deduplicated through a boolean table (bytes) rather than
#: np.unique: 1001² = 1e6 for the seed example, 16e6 at 4000 nodes
_TABLE_KEYS = 16_000_000


def _unique_keys(keys: np.ndarray, size: int) -> np.ndarray:
    """Sorted unique values of integer ``keys`` (M,) in [0, size): the same result as
    np.unique, through a boolean table when size ≤ _TABLE_KEYS (O(M + size); np.unique
    hashed and sorted the node-pair keys of a contact search in 2-3 ms a call, about 7 %
    of the intertwined seed example's time at 34-35 s)."""
    if size > _TABLE_KEYS:
        return np.unique(keys)
    seen = np.zeros(size, dtype=bool)
    seen[keys] = True
    return np.flatnonzero(seen)


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
        own, par = candidate_pairs(r, t, self.tolerance + reach, self.s,
                                   self.separation_cut, self.sin_half_aperture)
        return self._runs(own, par, sorted_unique=True)

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
        have = _unique_keys(cand.owner * n + cand.segment, n * n)
        need = _unique_keys(other.owner * n + other.segment, n * n)
        return bool(np.all(np.isin(need, have, assume_unique=True)))

    def _runs(self, own, par, sorted_unique=False) -> ContactCandidates:
        """Runs of the node pairs (own (M,), par (M,)): per owner, partners closer than 3
        nodes apart form one run, extended by one node each side. ``sorted_unique``: the
        pairs are already unique and sorted by owner, then partner."""
        n = self.n_nodes
        if own.size == 0:
            z = np.zeros(0, dtype=np.intp)
            zb = np.zeros(0, dtype=bool)
            return ContactCandidates(z, z.copy(), z.copy(), zb, zb.copy())
        if not sorted_unique:
            key = _unique_keys(own.astype(np.int64) * n + par, n * n)
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
        """Closest point of each run on the partner curve (:func:`~.geometry.curve_basis`):
        (k (R,) index into the combinations, t (R,), x (R, 3), d (R,), c' (R, 3), g (R,),
        idx (R, 4), β (R, 4), β' (R, 4), valid (R,) bool: not an interior run edge); the
        fields after d are those of :func:`~.geometry.point_curve`.

        frozen: (R,) combination indices from an earlier call, or None. Given, each run
        keeps that segment (the closest point still slides along it): Newton freezes the
        selection after a few iterates so that a minimum near a node cannot move back and
        forth between the two segments that meet there."""
        memo = getattr(self, "_closest_memo", None)
        if (memo is not None and memo[0] is cand and memo[1] is frozen
                and np.array_equal(memo[2], positions)):
            return memo[3]                # the same positions again (one Newton trial point)
        out = self._closest(cand, positions, frozen)
        self._closest_memo = (cand, frozen, np.array(positions, copy=True), out)
        return out

    def _closest(self, cand, positions, frozen):
        # the polyline's closest segment of each run, then the curve on it and its two
        # neighbours in the run (the curve departs from the chords by O(Δs² κ), so its
        # closest point lies on one of them); or the frozen combination of each run
        k, *geo = run_closest(positions, cand.owner, cand.segment, cand.run_start, frozen)
        start = cand.run_start
        last = np.append(start[1:], cand.owner.size) - 1
        tk = geo[0]
        edge_lo = (k == start) & (tk == 0.0) & ~cand.first_vertex_is_end
        edge_hi = (k == last) & (tk == 1.0) & ~cand.last_vertex_is_end
        return (k, *geo, ~(edge_lo | edge_hi))

    def gaps(self, cand: ContactCandidates, positions) -> np.ndarray:
        """Surface gaps (R,) m of the runs' closest points (inf for run edges)."""
        if cand is None or not cand.runs:
            return np.zeros(0)
        k, t, x, d, *_, valid = self.closest(cand, positions)
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
        closest point sliding along the partner curve. With G = ∂F/∂x|_u = n (f_d nᵀ +
        f_ḋ (u − ḋ n)ᵀ/d) + (f/d)(I − n nᵀ), G_u = ∂F/∂u = f_ḋ n nᵀ, x = Σ c_a r_a,
        u = Σ c_a v_a (c_a = 1 for the owner, −β_a(t) for the curve's nodes) and, for
        0 < t < 1, the stationarity c'·x = 0 differentiated: g dt = Σ_a (c_a c' − ∂c_a/∂t
        x)·dr_a with g = |c'|² − x·c'', dx = Σ c_a dr_a − c' dt, du = Σ c_a dv_a +
        (Σ ∂c_a/∂t v_a) dt. The mean diameter and ρA at the contact are interpolated
        linearly on segment (j, j + 1); how they move with t is left out of the
        derivatives.

        Raises ValueError on bad shapes or values, or coincident centreline points.
        """
        r = self._check_field("positions", positions)
        v = self._check_field("velocities", velocities)
        if cand is None or not cand.runs:
            return _empty_evaluation()
        k, t, x, d, c1, g, idx, beta, dbeta, valid = self.closest(cand, r, frozen)
        i, j = cand.owner[k], cand.segment[k]
        dbar = self._at_contact(self.diameter, i, j, t)
        d_off = self.law.cutoff(dbar)[1]
        keep = valid & (d < d_off)
        if not np.any(keep):
            return _empty_evaluation(k)
        i, j, t, x, d, dbar = i[keep], j[keep], t[keep], x[keep], d[keep], dbar[keep]
        c1, g, idx, beta, dbeta = c1[keep], g[keep], idx[keep], beta[keep], dbeta[keep]
        if np.any(d == 0.0):
            raise ValueError("SelfContact.evaluate: coincident centreline points in a pair")
        p = i.size
        # the contact's nodes: the owner and the partner curve's four; x = Σ c_a r_a
        nodes = np.concatenate([i[:, None], idx], axis=1)                 # (P, 5)
        coef = np.concatenate([np.ones((p, 1)), -beta], axis=1)
        dcoef = np.concatenate([np.zeros((p, 1)), -dbeta], axis=1)       # ∂c_a/∂t
        x, c1 = np.ascontiguousarray(x), np.ascontiguousarray(c1)
        n, u, ddot, u_t = _relative_motion(x, d, coef, dcoef, nodes, np.ascontiguousarray(v))
        rho = self._at_contact(self.rho_a, i, j, t)
        f, f_d, f_dd, gap = self.law(d, ddot, dbar, rho)
        force, d_dr, d_dv, dt_dr, weights, dw_dt = _force_derivatives(
            n, u, ddot, u_t, d, f, f_d, f_dd, coef, dcoef, c1, x, g, t, self.weights,
            nodes)
        return ContactEvaluation(i, j, t, nodes, weights, coef, force, d_dr, d_dv, dt_dr,
                                 dw_dt, gap, d, float(gap.min()), int(p), k)


@numba.njit(cache=True)
def _relative_motion(x, d, coef, dcoef, nodes, v):
    """Per contact (P,): the normal n = x/d (P, 3), the relative velocity u = Σ c_a v_a
    (P, 3), the approach rate ḋ = n·u (P,) and u_t = Σ ∂c_a/∂t v_a (P, 3) (how u moves
    with the closest point's parameter); v (N, 3) global node velocities, m/s."""
    p = x.shape[0]
    n = np.empty((p, 3))
    u = np.zeros((p, 3))
    u_t = np.zeros((p, 3))
    ddot = np.empty(p)
    for q in range(p):
        for a in range(nodes.shape[1]):
            b = nodes[q, a]
            for c in range(3):
                u[q, c] += coef[q, a] * v[b, c]
                u_t[q, c] += dcoef[q, a] * v[b, c]
        acc = 0.0
        for c in range(3):
            n[q, c] = x[q, c] / d[q]
            acc += n[q, c] * u[q, c]
        ddot[q] = acc
    return n, u, ddot, u_t


@numba.njit(cache=True)
def _force_derivatives(n, u, ddot, u_t, d, f, f_d, f_dd, coef, dcoef, c1, x, g, t, w,
                       nodes):
    """Force F = f n (P, 3) and its derivatives per contact (formulas in
    :meth:`SelfContact.evaluate`): G = n (f_d nᵀ + f_ḋ (u − ḋ n)ᵀ/d) + (f/d)(I − n nᵀ),
    G_u = f_ḋ n nᵀ, ∂t/∂r_a = (c_a c' − ∂c_a/∂t x)/g for 0 < t < 1 (else 0; g ≤ 0 as
    g = ∞), H = G_u u_t − G c', ∂F/∂r_a = c_a G + H (∂t/∂r_a)ᵀ, ∂F/∂v_a = c_a G_u; the
    load weights w_a = ½ c_a Δs_i/Δs_a and ∂w_a/∂t = ½ ∂c_a/∂t Δs_i/Δs_a (w: (N,)
    nodal quadrature weights). Returns (force, d_dr (P, 5, 3, 3), d_dv (P, 5, 3, 3),
    dt_dr (P, 5, 3), weights (P, 5), dw_dt (P, 5))."""
    p = n.shape[0]
    m = nodes.shape[1]
    force = np.empty((p, 3))
    d_dr = np.empty((p, m, 3, 3))
    d_dv = np.empty((p, m, 3, 3))
    dt_dr = np.zeros((p, m, 3))
    weights = np.empty((p, m))
    dw_dt = np.empty((p, m))
    G = np.empty((3, 3))
    Gu = np.empty((3, 3))
    tang = np.empty(3)
    H = np.empty(3)
    for q in range(p):
        fq = f[q]
        fd = f_d[q]
        fdd = f_dd[q]
        dq = d[q]
        for c in range(3):
            force[q, c] = fq * n[q, c]
            tang[c] = (u[q, c] - ddot[q] * n[q, c]) / dq
        for a in range(3):
            for b in range(3):
                nn = n[q, a] * n[q, b]
                eye = 1.0 if a == b else 0.0
                G[a, b] = n[q, a] * (fd * n[q, b] + fdd * tang[b]) + (fq / dq) * (eye - nn)
                Gu[a, b] = fdd * nn
        interior = 0.0 < t[q] < 1.0
        gs = g[q] if g[q] > 0.0 else np.inf
        for a in range(3):
            H[a] = (Gu[a, 0] * u_t[q, 0] + Gu[a, 1] * u_t[q, 1] + Gu[a, 2] * u_t[q, 2]) - (
                G[a, 0] * c1[q, 0] + G[a, 1] * c1[q, 1] + G[a, 2] * c1[q, 2])
        wi = w[nodes[q, 0]]
        for k in range(m):
            ck = coef[q, k]
            if interior:
                for c in range(3):
                    dt_dr[q, k, c] = (ck * c1[q, c] - dcoef[q, k] * x[q, c]) / gs
            for a in range(3):
                for b in range(3):
                    d_dr[q, k, a, b] = ck * G[a, b] + H[a] * dt_dr[q, k, b]
                    d_dv[q, k, a, b] = ck * Gu[a, b]
            ratio = wi / w[nodes[q, k]]
            weights[q, k] = 0.5 * ck * ratio
            dw_dt[q, k] = 0.5 * dcoef[q, k] * ratio
    return force, d_dr, d_dv, dt_dr, weights, dw_dt


def _empty_evaluation(selection=None) -> ContactEvaluation:
    z = np.zeros(0)
    zi = np.zeros(0, dtype=np.intp)
    return ContactEvaluation(zi, zi.copy(), z, np.zeros((0, 5), np.intp), np.zeros((0, 5)),
                             np.zeros((0, 5)), np.zeros((0, 3)), np.zeros((0, 5, 3, 3)),
                             np.zeros((0, 5, 3, 3)), np.zeros((0, 5, 3)), np.zeros((0, 5)),
                             z.copy(), z.copy(), float("inf"), 0, selection)
