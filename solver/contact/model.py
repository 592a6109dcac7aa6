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

import math

import numba
import numpy as np

from ..banded import int_at_run_time, true_at_run_time
from ..kernel_data import CandidateArrays, ContactData, EvaluationArrays
from .geometry import (ALL_PAIRS_NODES, _block_pairs_kernel, _candidate_pairs_kernel,
                       _run_point, _segment_matrices, _segment_nodes, _swept_kernel,
                       candidate_pairs, close_node_pairs, max_distance, run_closest)
from .laws import BarrierLaw, SeedLaw, law_cutoff, law_force, law_potential

__all__ = ["SelfContact", "ContactCandidates", "ContactEvaluation", "assemble_nodal",
           "nodal_weights", "close_join", "close_join_jacobian", "GAP_FLOOR_FRACTION",
           "EXCLUSION_DIAMETERS"]

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

    @property
    def arrays(self):
        """The candidates as the compiled kernels take them
        (:class:`solver.kernel_data.CandidateArrays`)."""
        return CandidateArrays(self.owner, self.segment, self.run_start,
                               self.first_vertex_is_end, self.last_vertex_is_end)

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
    closed : bool             of a closed rod: the loads of node N (node 0 again) are
                              node 0's (:func:`assemble_nodal`)
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
    closed: bool = False


def nodal_weights(s, closed: bool = False) -> np.ndarray:
    """Nodal quadrature weights Δs (m) of a grid s (N,): half cells at the ends, so
    Σ Δs = s_{N−1} − s_0 (the trapezoid rule). ``closed``: of a ring whose last node is
    its first again, that node's two half cells at both (Σ over the distinct nodes,
    all but the last, is the ring's length)."""
    s = np.asarray(s, dtype=float)
    w = np.zeros_like(s)
    if s.size >= 2:
        h = np.diff(s)
        w[:-1] += 0.5 * h
        w[1:] += 0.5 * h
        if closed:
            w[0] = w[-1] = 0.5 * (h[0] + h[-1])
    return w


def close_join(loads: np.ndarray) -> np.ndarray:
    """A closed rod's nodal load densities (N+1, k) with node N's added to node 0's and
    node 0's total at both (a copy): node N is node 0 again, the same material point
    with the same weight (:func:`nodal_weights` with ``closed``), and the box rule takes
    a density at both ends of the grid, h/2 into the cells either side of the join, as at
    an interior node (:func:`solver.statics._load_rows`, as
    :func:`solver.statics._closed_problem` puts a point load at the join)."""
    out = np.array(loads, dtype=float)
    out[0] += out[-1]
    out[-1] = out[0]
    return out


def close_join_jacobian(jac):
    """∂L/∂r (3(N+1), 3(N+1)) sparse of loads L that :func:`close_join` then closes: its
    rows of node 0 and node N both their sum (CSR). The columns stay: a closed rod's
    loads may depend on r_N as well as r_0 (the segment N − 1 ends at node N)."""
    import scipy.sparse as sp

    n3 = jac.shape[0]
    k = np.arange(n3)
    top = k < 3
    bottom = k >= n3 - 3
    rows = np.concatenate([k, k[top], k[bottom]])
    cols = np.concatenate([k, k[top] + n3 - 3, k[bottom] - (n3 - 3)])
    fold = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n3, n3))
    return (fold @ sp.csr_matrix(jac)).tocsr()


def assemble_nodal(ev: ContactEvaluation, n_nodes: int) -> np.ndarray:
    """Nodal contact force density (n_nodes, 3) N/m, global: Σ_pairs w_a F at each node a.
    Σ_k Δs_k out_k = 0 to round-off (momentum balance; of a closed rod over nodes 0 ..
    N − 1, its loads at node N those at node 0 again: :func:`close_join`). Raises
    ValueError for a node index outside [0, n_nodes)."""
    out = np.zeros((int(n_nodes), 3))
    if ev.count == 0:
        return out
    if ev.nodes.min() < 0 or ev.nodes.max() >= n_nodes:
        raise ValueError(f"assemble_nodal: node index outside [0, {n_nodes})")
    for a in range(ev.nodes.shape[1]):
        np.add.at(out, ev.nodes[:, a], ev.weights[:, a, None] * ev.force)
    return close_join(out) if ev.closed else out


def assemble_nodal_jacobian(ev: ContactEvaluation, n_nodes: int, d_force=None):
    """∂L/∂r (3 n_nodes, 3 n_nodes) sparse (CSR) of :func:`assemble_nodal`'s loads L,
    N/m²: node a's load w_a F changes by w_a (∂F/∂r_b) δr_b + F (∂w_a/∂t) (∂t/∂r_b) δr_b
    (the closest point sliding along the partner curve; ``d_weights_d_t``, ``d_t_d_r``).
    ``d_force`` (P, 5, 3, 3) N/m² replaces ``ev.d_force_d_r`` where the velocities depend
    on the positions too (a time step's ∂F/∂r + c ∂F/∂v, c in 1/s). Entries of a repeated
    ghost node add up; of a closed rod node N's rows are added to node 0's, at both
    (:func:`close_join_jacobian`). The statics' and the centreline scheme's contact
    Jacobian."""
    import scipy.sparse as sp

    n3 = 3 * int(n_nodes)
    if ev.count == 0:
        return sp.csr_matrix((n3, n3))
    dF = ev.d_force_d_r if d_force is None else d_force
    # block[p, a, b] (3, 3): ∂(w_a F_p)/∂r_b
    block = (ev.weights[:, :, None, None, None] * dF[:, None, :, :, :]
             + (ev.force[:, None, None, :, None] * ev.d_weights_d_t[:, :, None, None, None]
                * ev.d_t_d_r[:, None, :, None, :]))
    shape = (ev.count, 5, 5, 3, 3)
    na = ev.nodes[:, :, None, None, None]
    nb = ev.nodes[:, None, :, None, None]
    ca = np.arange(3)[None, None, None, :, None]
    cb = np.arange(3)[None, None, None, None, :]
    rows = np.broadcast_to(3 * na + ca, shape).ravel()
    cols = np.broadcast_to(3 * nb + cb, shape).ravel()
    jac = sp.csr_matrix((block.ravel(), (rows, cols)), shape=(n3, n3))
    return close_join_jacobian(jac) if ev.closed else jac


def _checked_grid(s, diameter, rho_a, closed):
    """(s, diameter, rho_a) as float arrays (N,) for :class:`SelfContact`. Raises
    ValueError for a grid that is not 1-D with at least 2 nodes (4 on a closed rod),
    strictly increasing and finite, or diameters and ρA of another shape, not finite or
    not > 0."""
    s = np.asarray(s, dtype=float)
    diameter = np.asarray(diameter, dtype=float)
    rho_a = np.asarray(rho_a, dtype=float)
    if s.ndim != 1 or s.size < (4 if closed else 2):
        raise ValueError(f"SelfContact: s must be 1-D with at least 2 nodes (4 on a "
                         f"closed rod), got {s.shape}")
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
    return s, diameter, rho_a


def _min_separation(s, cut) -> float:
    """The smallest arclength separation (m) beyond ``cut`` (m) between two nodes of the
    grid s (N,), inf where no pair is that far apart (:meth:`SelfContact.may_touch`)."""
    partner = np.searchsorted(s, s + cut, side="right")
    node = np.arange(s.size)
    cand = np.concatenate([partner - 1, partner])
    own = np.concatenate([node, node])
    valid = (cand > own) & (cand < s.size)
    sep = s[cand[valid]] - s[own[valid]]
    sep = sep[sep > cut]
    return float(sep.min()) if sep.size else float("inf")


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
    closed : bool
        A closed rod (``rod.closed``): its last node is its first again (the same
        position). The search and the owners run on the distinct nodes 0 .. N − 2, the
        arclength separation is measured round the ring, min(|Δs|, L − |Δs|), the
        partner curve runs on across the join (no ghost nodes, no rod ends), the weights
        are the ring's and an evaluation's loads at the last node are the first's
        (:func:`close_join`). The O(N) pre-test has nothing to rule out on a ring (its
        mean tangent's projections change sign), so every search is made.

    Raises
    ------
    ValueError
        Bad shapes, non-finite or out-of-range values, tolerance ≤ max diameter, or a
        barrier law without a positive ``barrier_gap``/``barrier_stiffness``.
    """

    def __init__(self, spec, s, diameter, rho_a, closed: bool = False):
        s, diameter, rho_a = _checked_grid(s, diameter, rho_a, closed)

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
        self.closed = bool(closed)
        #: the nodes that own pairs (all but the last of a closed rod, node 0 again) and
        #: the arclength period (m: a ring's length, inf for an open rod)
        self.ring = s.size - 1 if self.closed else s.size
        self.period = float(s[-1] - s[0]) if self.closed else np.inf
        self.weights = nodal_weights(s, self.closed)
        # pairs must be further apart than the exclusion by more than rounding
        self.separation_cut = self.exclusion + 1e-9 * (s[-1] - s[0]) / (s.size - 1)
        # the pre-test's smallest grid separation beyond the cut (none on a ring)
        self.min_separation = 0.0 if self.closed else _min_separation(s, self.separation_cut)
        self.sin_half_aperture = 1.0 if self.aperture >= 180.0 else float(
            np.sin(np.radians(self.aperture) / 2.0))
        every = np.arange(s.size - 1)
        #: what the compiled kernels take of this contact model, constant over a run
        #: (:class:`solver.kernel_data.ContactData`)
        self.kernel_data = ContactData(
            seg_nodes=_segment_nodes(every, s.size, self.closed),
            seg_mats=_segment_matrices(every, s.size, self.closed),
            diameter=diameter, rho_a=rho_a, weights=self.weights, law=self.law.params)

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
        return bool(_may_touch_kernel(r, t, self.s, self.min_separation, self.tolerance + reach))

    def may_touch_unchecked(self, positions, tangents, reach: float = 0.0) -> bool:
        """:meth:`may_touch` without its input checks, for the solver's own finite
        (N, 3) arrays."""
        return bool(_may_touch_kernel(np.ascontiguousarray(positions, dtype=float),
                                      np.ascontiguousarray(tangents, dtype=float), self.s,
                                      self.min_separation, self.tolerance + reach))

    # ------------------------------------------------------------------ tunnelling
    def passes_through(self, r_old, r_new) -> bool:
        """Collision check of a step from node positions r_old to r_new (N, 3) m
        (docs/contact.md): True when two nodes beyond the exclusion, moving linearly from
        their old to their new positions, come closer than a quarter of the sum of their
        diameters within the step, or two segments at such nodes do at one of the
        step's sub-times (:func:`_swept_segments_within`: two strands crossing between
        their nodes, which the nodes' own distances miss where a segment is longer than
        about a third of the diameter); a strand passed through another between the
        candidate searches. A pair can come that close only if it ends closer than
        ½D_max plus twice the largest node displacement plus the longest segment, so
        the O(N) pre-test of :meth:`may_touch` at that reach (tangents: the chords of
        r_new) rules most steps out at once, and the swept distances are computed for
        the node pairs within it (:func:`~.geometry.close_node_pairs`,
        :func:`~.geometry.swept_min_distance`). Compiled in two passes
        (:func:`_swept_reach`, :func:`_swept_any_within`).
        Raises ValueError (from :func:`~.geometry.close_node_pairs`) for non-finite
        positions on grids of more than ``ALL_PAIRS_NODES`` nodes; the solver passes only
        converged, finite ones."""
        m = self.ring                           # a ring's distinct nodes
        r0 = np.ascontiguousarray(r_old, dtype=float)[:m]
        r1 = np.ascontiguousarray(r_new, dtype=float)[:m]
        s, diameter = self.s[:m], self.diameter[:m]
        if 2 <= r1.shape[0] <= ALL_PAIRS_NODES:
            # a small grid: the same steps in one compiled call
            return bool(_passes_through_all_pairs(r0, r1, s, diameter, self.min_separation,
                                                  float(self.separation_cut), self.period))
        radius = _swept_reach(r0, r1, s, diameter, self.min_separation)
        if radius < 0.0:
            return False
        a, b = close_node_pairs(r1, radius, s, self.separation_cut, self.period)
        return a.size > 0 and bool(_swept_any_within(r0, r1, a, b, diameter, s,
                                                     float(self.separation_cut), self.period))

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
        m = self.ring
        own, par = candidate_pairs(r[:m], t[:m], self.tolerance + reach, self.s[:m],
                                   self.separation_cut, self.sin_half_aperture, self.period)
        return self._runs(own, par, sorted_unique=True)

    def search(self, positions, tangents, reach: float = 0.0):
        """The run's search (:meth:`candidates` behind the :meth:`may_touch` pre-test),
        without the input validation of the public methods: positions and tangents
        (N, 3) from the solver (tangents need not be unit). Returns the candidates, or
        None where no pair can be within tolerance + reach (m) or none is. Non-finite
        positions give None (the step that made them fails in Newton)."""
        m = self.ring                           # a ring's distinct nodes
        r = np.ascontiguousarray(positions, dtype=float)[:m]
        t = np.ascontiguousarray(tangents, dtype=float)[:m]
        s = self.s[:m]
        radius = self.tolerance + reach
        if 2 <= r.shape[0] <= ALL_PAIRS_NODES:
            # a small grid: the same steps in one compiled call
            searched, *arrays = _search_all_pairs(r, t, s, self.min_separation,
                                                  float(radius), float(self.separation_cut),
                                                  self.sin_half_aperture, self.period)
            return ContactCandidates(*arrays) if searched and arrays[2].size else None
        if not self.may_touch_unchecked(r, t, reach):
            return None
        if not np.isfinite(r).all():
            return None
        a, b = close_node_pairs(r, radius, s, self.separation_cut, self.period)
        arrays = _search_kernel(r, t, a, b, s, self.separation_cut,
                                self.sin_half_aperture, self.period)
        return ContactCandidates(*arrays) if arrays[2].size else None

    def merge(self, c1: ContactCandidates, c2: ContactCandidates) -> ContactCandidates:
        """Candidates covering both sets (runs rebuilt from the union of their nodes)."""
        sets = [c for c in (c1, c2) if c is not None and c.runs]
        if not sets:
            return self._runs(np.zeros(0, np.intp), np.zeros(0, np.intp))
        none = np.zeros(0, np.intp)
        other = sets[1] if len(sets) > 1 else None
        own, par = _merge_nodes_kernel(sets[0].owner, sets[0].segment,
                                       none if other is None else other.owner,
                                       none if other is None else other.segment,
                                       self.s, self.separation_cut, self.period, self.ring)
        return self._runs(own, par)

    def covers(self, cand: ContactCandidates, other: ContactCandidates) -> bool:
        """Whether every owner/segment combination of ``other`` is in ``cand``."""
        if other is None or not other.runs:
            return True
        if cand is None or not cand.runs:
            return False
        return bool(_covers_kernel(cand.owner, cand.segment, other.owner, other.segment,
                                   self.n_nodes))

    def _runs(self, own, par, sorted_unique=False) -> ContactCandidates:
        """Runs of the node pairs (own (M,), par (M,)): per owner, partners closer than 3
        nodes apart form one run, extended by one node each side (where that node is in
        the rod and beyond the exclusion from the owner). ``sorted_unique``: the pairs
        are already unique and sorted by owner, then partner. Compiled
        (:func:`_runs_kernel`)."""
        owner, segment, start, first, last = _runs_kernel(
            np.ascontiguousarray(own, dtype=np.intp), np.ascontiguousarray(par, dtype=np.intp),
            self.s, self.separation_cut, self.ring, bool(sorted_unique), self.period)
        return ContactCandidates(owner, segment, start, first, last)

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
        k, *geo = run_closest(positions, cand.owner, cand.segment, cand.run_start, frozen,
                              closed=self.closed)
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
        out = np.empty(cand.runs)
        candidate_gaps_into(np.ascontiguousarray(positions, dtype=float), cand.arrays,
                            self.kernel_data, out)
        return out

    def potential(self, cand: ContactCandidates, positions) -> float:
        """The energy U (J) the contact law stores at positions (N, 3) m over the
        candidates' runs (:func:`candidate_potential`): Σ over the runs' active closest
        points of ½ Δs_i ρĀ Ψ(d_i), Ψ the law's potential (:func:`~.laws.law_potential`).
        Node i's force ½ f n Δs_i and its reaction at the closest point are −∇U (the
        closest point is stationary in t), the damping left out. 0 without candidates."""
        if cand is None or not cand.runs:
            return 0.0
        return float(candidate_potential(np.ascontiguousarray(positions, dtype=float),
                                         cand.arrays, self.kernel_data))

    def evaluate(self, cand: ContactCandidates, positions, velocities,
                 frozen=None) -> ContactEvaluation:
        """Active contacts of the candidates at a state (module doc), with derivatives.

        positions (N, 3) m and velocities (N, 3) m/s, global; frozen: see
        :meth:`closest` (``selection`` of the result is the one used). Derivatives with the
        closest point sliding along the partner curve (:func:`evaluate_into`, the compiled
        kernel that Newton calls at every iterate).

        Raises ValueError on bad shapes or values, or coincident centreline points.
        """
        r = self._check_field("positions", positions)
        v = self._check_field("velocities", velocities)
        if cand is None or not cand.runs:
            return _empty_evaluation()
        ev = evaluation_arrays(cand.runs)
        fz = (np.full(0, -1, np.intp) if frozen is None
              else np.ascontiguousarray(frozen, dtype=np.intp))
        p = evaluate_into(r, v, cand.arrays, fz, self.kernel_data, ev)
        if p < 0:
            raise ValueError("SelfContact.evaluate: coincident centreline points in a pair")
        if p == 0:
            return _empty_evaluation(ev.selection)
        return ContactEvaluation(ev.owner[:p], ev.segment[:p], ev.t[:p], ev.nodes[:p],
                                 ev.weights[:p], ev.coef[:p], ev.force[:p], ev.dF_dr[:p],
                                 ev.dF_dv[:p], ev.dt_dr[:p], ev.dw_dt[:p], ev.gap[:p],
                                 ev.distance[:p], float(ev.gap[:p].min()), int(p), ev.selection,
                                 self.closed)


@numba.njit(cache=True)
def evaluation_potential(ev, P, data):
    """The contact law's stored energy (J) of the first P contacts of an evaluation ev
    (:func:`evaluation_arrays`, filled by :func:`evaluate_into`: owner i (R,), partner
    segment j (R,), its parameter t (R,), centreline distance d (R,) m): Σ_p ½ Δs_i ρĀ
    Ψ(d_p; D̄) with ρĀ (kg/m) and D̄ (m) at the contact and Ψ the law's potential
    (:func:`~.laws.law_potential`; docs/contact.md § 1, "Stored energy and the energy
    check"). Each term and the order of the sum are those of :func:`candidate_potential`,
    so that where the evaluation selected its closest points afresh (no frozen selection)
    at positions r the two are equal, bit for bit, to candidate_potential at r. data:
    :attr:`SelfContact.kernel_data`. Raises nothing."""
    pi, pj, pt, dist = ev.owner, ev.segment, ev.t, ev.distance
    diameter, rho_a, w, law = data.diameter, data.rho_a, data.weights, data.law
    out = 0.0
    for p in range(P):
        i = pi[p]
        j = pj[p]
        t = pt[p]
        dbar = _at_contact(diameter, i, j, t)
        out += 0.5 * w[i] * _at_contact(rho_a, i, j, t) * law_potential(law, dist[p], dbar)
    return out


@numba.njit(cache=True)
def _swept_reach(r0, r1, s, diameter, min_separation):
    """:meth:`SelfContact.passes_through`'s pre-test: the reach ½D_max + 2 max_k |r1_k −
    r0_k| + the longest chord of r1 (m) within which a node pair of r1 (N, 3) must lie
    for the pair, or segments at its nodes, to come closer than ½D over the step, or −1
    when the test of :func:`_may_touch_kernel` (tangents: the chords of r1, the last
    one repeated) rules every pair out at that distance."""
    n = r1.shape[0]
    chord = 0.0
    for k in range(n - 1):
        d0 = r1[k + 1, 0] - r1[k, 0]
        d1 = r1[k + 1, 1] - r1[k, 1]
        d2 = r1[k + 1, 2] - r1[k, 2]
        chord = max(chord, math.sqrt(d0 * d0 + d1 * d1 + d2 * d2))
    radius = 0.5 * np.max(diameter) + 2.0 * max_distance(r1, r0) + chord
    t = np.empty((n, 3))
    for k in range(n):
        lo = min(k, n - 2)
        for c in range(3):
            t[k, c] = r1[lo + 1, c] - r1[lo, c]
    if not _may_touch_kernel(r1, t, s, min_separation, radius):
        return -1.0
    return radius


@numba.njit(cache=True)
def _swept_any_within(r0, r1, a, b, diameter, s, cut, period):
    """Whether any node pair (a, b) (P,) moving linearly from r0 to r1 (N, 3) comes
    closer than ½ · ½(D_a + D_b) within the step (:func:`~.geometry._swept_kernel`'s
    closest approach), or segments at such nodes do (:func:`_swept_segments_within`;
    s (N,) m, ``cut`` (m) its arclength exclusion, ``period`` a ring's length or inf),
    over the pairs that :func:`_pairs_that_may_meet` keeps."""
    a, b = _pairs_that_may_meet(r0, r1, a, b, diameter, period < np.inf)
    closest = np.empty(a.shape[0])
    _swept_kernel(r0, r1, a, b, closest)
    for p in range(a.shape[0]):
        if closest[p] < 0.5 * (0.5 * (diameter[a[p]] + diameter[b[p]])):
            return True
    return _swept_segments_within(r0, r1, a, b, diameter, s, cut, period)


@numba.njit(cache=True)
def _pairs_that_may_meet(r0, r1, a, b, diameter, ring):
    """The node pairs of (a, b) (P,) that, moving linearly from r0 to r1 (N, 3) m, may
    come within the collision tests' thresholds (at most ½ D_max) at some time of the
    step, themselves or segments at them: (a', b') (P',). At sub-time t the nodes'
    separation is r1_a − r1_b − (1 − t)(Δr_a − Δr_b), at least |r1_a − r1_b| −
    |Δr_a − Δr_b|, and every point of a segment at node k is within ℓ_k of r_k, ℓ_k the
    longest of k's segments at the step's start or end (a segment's length is convex
    along the linear motion): a pair with |r1_a − r1_b| − |Δr_a − Δr_b| − ℓ_a − ℓ_b ≥
    ½ D_max cannot meet and is dropped. The reach of :func:`_swept_reach` is set by the
    largest absolute displacement; a rod that moves nearly rigidly keeps most pairs
    within it while their relative motion is small. ``ring``: node N − 1 joins node 0."""
    n = r0.shape[0]
    reach = np.zeros(n)
    for k in range(n if ring else n - 1):
        k1 = (k + 1) % n
        ln = 0.0
        for r in (r0, r1):
            d0 = r[k1, 0] - r[k, 0]
            d1 = r[k1, 1] - r[k, 1]
            d2 = r[k1, 2] - r[k, 2]
            ln = max(ln, math.sqrt(d0 * d0 + d1 * d1 + d2 * d2))
        reach[k] = max(reach[k], ln)
        reach[k1] = max(reach[k1], ln)
    thr = 0.5 * np.max(diameter)
    keep = np.empty(a.shape[0], np.bool_)
    count = 0
    for p in range(a.shape[0]):
        i = a[p]
        j = b[p]
        sep = 0.0
        for c in range(3):
            x = r1[i, c] - r1[j, c]
            sep += x * x
        keep[p] = (math.sqrt(sep) - _relative_move(r0, r1, i, j) - reach[i] - reach[j]
                   < thr)
        if keep[p]:
            count += 1
    a_out = np.empty(count, a.dtype)
    b_out = np.empty(count, b.dtype)
    q = 0
    for p in range(a.shape[0]):
        if keep[p]:
            a_out[q] = a[p]
            b_out[q] = b[p]
            q += 1
    return a_out, b_out


#: the most sub-times :func:`_swept_segments_within` takes in one step
SWEPT_SUBSTEPS = 256


@numba.njit(cache=True)
def _segment_distance(r0, r1, i, i1, j, j1, t):
    """The distance (m) between the segments [r_i, r_i1] and [r_j, r_j1] at the sub-time
    t ∈ [0, 1] of a step in which the nodes move linearly from r0 to r1 (N, 3):
    Lumelsky's clamped minimisation (Inf. Process. Lett. 21, 1985;
    :func:`~.geometry.segment_segment` for one pair), on scalars (no temporaries)."""
    d1 = np.empty(3)
    d2 = np.empty(3)
    rr = np.empty(3)
    for c in range(3):
        pa = r0[i, c] + t * (r1[i, c] - r0[i, c])
        pb = r0[i1, c] + t * (r1[i1, c] - r0[i1, c])
        qa = r0[j, c] + t * (r1[j, c] - r0[j, c])
        qb = r0[j1, c] + t * (r1[j1, c] - r0[j1, c])
        d1[c] = pb - pa
        d2[c] = qb - qa
        rr[c] = pa - qa
    a = d1[0] * d1[0] + d1[1] * d1[1] + d1[2] * d1[2]
    e = d2[0] * d2[0] + d2[1] * d2[1] + d2[2] * d2[2]
    f = d2[0] * rr[0] + d2[1] * rr[1] + d2[2] * rr[2]
    cc = d1[0] * rr[0] + d1[1] * rr[1] + d1[2] * rr[2]
    b = d1[0] * d2[0] + d1[1] * d2[1] + d1[2] * d2[2]
    denom = a * e - b * b
    sv = 0.0
    if denom > 1e-14 * a * e and denom > 0.0:
        sv = min(max((b * f - cc * e) / denom, 0.0), 1.0)
    tv = (b * sv + f) / e if e > 0.0 else 0.0
    if tv < 0.0:
        tv = 0.0
        sv = min(max(-cc / a, 0.0), 1.0) if a > 0.0 else 0.0
    elif tv > 1.0:
        tv = 1.0
        sv = min(max((b - cc) / a, 0.0), 1.0) if a > 0.0 else 0.0
    out = 0.0
    for c in range(3):
        diff = rr[c] + sv * d1[c] - tv * d2[c]
        out += diff * diff
    return math.sqrt(out)


@numba.njit(cache=True)
def _relative_move(r0, r1, u, w):
    """|Δr_u − Δr_w| (m): the relative displacement of nodes u and w over the step."""
    out = 0.0
    for c in range(3):
        d = (r1[u, c] - r0[u, c]) - (r1[w, c] - r0[w, c])
        out += d * d
    return math.sqrt(out)


@numba.njit(cache=True)
def _swept_segments_within(r0, r1, a, b, diameter, s, cut, period):
    """Whether two segments, one at each node of a pair (a, b) (P,) (k − 1 → k and
    k → k + 1 at node k; on a ring of length ``period`` (m; inf for an open rod) of the
    N distinct nodes, N − 1 → 0 too), their nodes beyond ``cut`` (m) in arclength s (N,)
    from the other segment's (:func:`_separation`), come closer than the node test's
    threshold, ½ of their four diameters' mean, at the step's start, its end or one of
    its sub-times t_k = k/K, the nodes moving linearly from r0 to r1 (N, 3). The
    distance of two segments changes at most by their points' relative displacement,
    at most m = the largest |Δr_u − Δr_w| of their nodes u, w over the step: a pair
    whose distances d0 at the start and d1 at the end have (d0 + d1 − m)/2 ≥ the
    threshold stays beyond it throughout (skipped), and K = ⌈2m / threshold⌉ (at most
    SWEPT_SUBSTEPS) puts a sub-time within a quarter of the threshold of every
    crossing."""
    n = r0.shape[0]
    ring = period < np.inf
    for p in range(a.shape[0]):
        for i in (a[p] - 1, a[p]):
            if ring:
                i = i % n
            elif i < 0 or i + 1 >= n:
                continue
            i1 = (i + 1) % n
            for j in (b[p] - 1, b[p]):
                if ring:
                    j = j % n
                elif j < 0 or j + 1 >= n:
                    continue
                j1 = (j + 1) % n
                if (_separation(s, i, j, period) <= cut or _separation(s, i1, j, period) <= cut
                        or _separation(s, i, j1, period) <= cut
                        or _separation(s, i1, j1, period) <= cut):
                    continue
                thr = 0.125 * (diameter[i] + diameter[i1] + diameter[j] + diameter[j1])
                d0 = _segment_distance(r0, r1, i, i1, j, j1, 0.0)
                d1 = _segment_distance(r0, r1, i, i1, j, j1, 1.0)
                if d0 < thr or d1 < thr:
                    return True
                m = max(_relative_move(r0, r1, i, j), _relative_move(r0, r1, i, j1),
                        _relative_move(r0, r1, i1, j), _relative_move(r0, r1, i1, j1))
                if 0.5 * (d0 + d1 - m) >= thr:
                    continue
                steps = min(SWEPT_SUBSTEPS, max(2, int(math.ceil(2.0 * m / thr))))
                for k in range(1, steps):
                    if _segment_distance(r0, r1, i, i1, j, j1, k / steps) < thr:
                        return True
    return False


@numba.njit(cache=True)
def _may_touch_kernel(r, t, s, min_separation, reach):
    """:meth:`SelfContact.may_touch`'s test: with e the normalised mean tangent and c the
    smallest (r_{k+1} − r_k)·e/(s_{k+1} − s_k), False only when c > 0 and
    c·min_separation ≥ reach (tolerance + reach, m). r, t (N, 3), s (N,)."""
    n = r.shape[0]
    e0 = e1 = e2 = 0.0
    for k in range(n):
        e0 += t[k, 0]
        e1 += t[k, 1]
        e2 += t[k, 2]
    e0 /= n
    e1 /= n
    e2 /= n
    norm = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    if norm == 0.0:
        return True
    e0 /= norm
    e1 /= norm
    e2 /= norm
    c = np.inf
    for k in range(n - 1):
        v = ((r[k + 1, 0] - r[k, 0]) * e0 + (r[k + 1, 1] - r[k, 1]) * e1
             + (r[k + 1, 2] - r[k, 2]) * e2) / (s[k + 1] - s[k])
        if v < c:
            c = v
    return not (c > 0.0 and c * min_separation >= reach)


@numba.njit(cache=True, inline="always")
def _separation(s, a, b, period):
    """The arclength separation (m) of nodes a and b of the grid s: |s_a − s_b|, of a
    ring of length ``period`` the shorter way round, min(|Δs|, L − |Δs|) (inf for an
    open rod: |Δs| exactly)."""
    d = abs(s[a] - s[b])
    return min(d, period - d)


@numba.njit(cache=True)
def _runs_kernel(own, par, s, cut, n, sorted_unique, period):
    """The body of :meth:`SelfContact._runs`: node pairs (own, par) (M,) of nodes
    0 .. n − 1 into runs, as (owner (K,), segment (K,), run_start (R,),
    first_vertex_is_end, last_vertex_is_end (R,) bool). Unsorted pairs are deduplicated
    and sorted by owner, then partner. Of a ring (``period`` its length, m; n its
    distinct nodes) the partners are ordered round the ring from the owner, index
    (p − o) mod n, so that a run runs on across the join (its segments N − 1, 0, …,
    segment N − 1 ending at node N, node 0 again), the separations are periodic
    (:func:`_separation`) and no run ends at a rod end."""
    m = own.shape[0]
    closed = period < np.inf
    if not sorted_unique and m:
        keys = np.sort(own * n + par)
        uniq = 1
        for q in range(1, m):
            if keys[q] != keys[uniq - 1]:
                keys[uniq] = keys[q]
                uniq += 1
        m = uniq
        own = keys[:m] // n
        par = keys[:m] % n
    if closed and m:
        # each owner's partners in ring order from it (the owner's own index is 0,
        # inside the exclusion, so a run never wraps past it)
        keys = np.sort(own[:m] * n + (par[:m] - own[:m]) % n)
        own = keys // n
        par = keys % n
    if m == 0:
        return (np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros(0, np.intp),
                np.zeros(0, np.bool_), np.zeros(0, np.bool_))
    # runs: a new one where the owner changes or the partner jumps by more than 3
    n_runs = 1
    for q in range(1, m):
        if own[q] != own[q - 1] or par[q] > par[q - 1] + 3:
            n_runs += 1
    ro = np.empty(n_runs, np.intp)
    lo = np.empty(n_runs, np.intp)
    hi = np.empty(n_runs, np.intp)
    r = 0
    ro[0] = own[0]
    lo[0] = par[0]
    for q in range(1, m):
        if own[q] != own[q - 1] or par[q] > par[q - 1] + 3:
            hi[r] = par[q - 1]
            r += 1
            ro[r] = own[q]
            lo[r] = par[q]
    hi[r] = par[m - 1]
    # extend by one node each side where that node is in the rod and beyond the
    # exclusion from the owner; keep runs of at least one segment
    total = 0
    keep = 0
    shift = 1 if closed else 0              # back from ring order to node indices
    for q in range(n_runs):
        o = ro[q]
        if lo[q] - 1 >= 0 and _separation(s, o, (lo[q] - 1 + shift * o) % n, period) > cut:
            lo[q] -= 1
        if hi[q] + 1 < n and _separation(s, o, (hi[q] + 1 + shift * o) % n, period) > cut:
            hi[q] += 1
        if hi[q] - lo[q] > 0:
            ro[keep] = o
            lo[keep] = lo[q]
            hi[keep] = hi[q]
            keep += 1
            total += hi[q] - lo[q]
    owner = np.empty(total, np.intp)
    segment = np.empty(total, np.intp)
    start = np.empty(keep, np.intp)
    first = np.empty(keep, np.bool_)
    last = np.empty(keep, np.bool_)
    k = 0
    for q in range(keep):
        start[q] = k
        first[q] = lo[q] == 0 and not closed
        last[q] = hi[q] == n - 1 and not closed
        for j in range(lo[q], hi[q]):
            owner[k] = ro[q]
            segment[k] = (j + shift * ro[q]) % n
            k += 1
    return owner, segment, start, first, last


@numba.njit(cache=True)
def _search_kernel(r, t, a, b, s, cut, sin_half_aperture, period):
    """Node pairs (a, b) of a k-d tree search into the candidates' arrays
    (:meth:`SelfContact.search`): the tangents t (N, 3) normalised, the aperture cones
    and the ordering (:func:`~.geometry._candidate_pairs_kernel`), then the runs
    (:func:`_runs_kernel`; ``period`` a ring's length, inf for an open rod)."""
    n = r.shape[0]
    tu = np.empty((n, 3))
    for k in range(n):
        nrm = np.sqrt(t[k, 0] ** 2 + t[k, 1] ** 2 + t[k, 2] ** 2)
        for c in range(3):
            tu[k, c] = t[k, c] / nrm if nrm > 0.0 else 0.0
    own, par = _candidate_pairs_kernel(r, tu, a, b, sin_half_aperture)
    return _runs_kernel(own, par, s, cut, n, true_at_run_time(r), period)


@numba.njit(cache=True)
def _search_all_pairs(r, t, s, min_separation, radius, cut, sin_half_aperture, period):
    """:meth:`SelfContact.search` on a grid of at most ALL_PAIRS_NODES nodes, in one
    call: the pre-test (:func:`_may_touch_kernel` at ``radius`` = tolerance + reach), the
    finiteness check, all node pairs within radius (:func:`~.geometry._block_pairs_kernel`
    on the whole grid, as :func:`~.geometry.close_node_pairs` takes them) and
    :func:`_search_kernel` (``period``: a ring's length, inf for an open rod). Returns
    (searched, owner, segment, run_start, first, last): searched False (and no
    candidates) where the pre-test or the finiteness check stopped the search."""
    n = r.shape[0]
    searched = _may_touch_kernel(r, t, s, min_separation, radius)
    if searched:
        for k in range(n):
            for c in range(3):
                if not np.isfinite(r[k, c]):
                    searched = False
    if searched:
        a, b = _block_pairs_kernel(r, s, n, np.zeros((0, 2), np.intp), np.zeros(1),
                                   radius, cut, period)
    else:
        a, b = np.zeros(0, np.intp), np.zeros(0, np.intp)
    owner, segment, start, first, last = _search_kernel(r, t, a, b, s, cut, sin_half_aperture,
                                                        period)
    return searched, owner, segment, start, first, last


@numba.njit(cache=True)
def _passes_through_all_pairs(r0, r1, s, diameter, min_separation, cut, period):
    """:meth:`SelfContact.passes_through` on a grid of at most ALL_PAIRS_NODES nodes, in
    one call: :func:`_swept_reach`, the node pairs within it (as
    :func:`~.geometry.close_node_pairs` takes them, ``period`` a ring's length) and
    :func:`_swept_any_within`."""
    radius = _swept_reach(r0, r1, s, diameter, min_separation)
    if radius < 0.0:
        return False
    a, b = _block_pairs_kernel(r1, s, r1.shape[0], np.zeros((0, 2), np.intp), np.zeros(1),
                               radius, cut, period)
    return a.size > 0 and _swept_any_within(r0, r1, a, b, diameter, s, cut, period)


@numba.njit(cache=True)
def _merge_nodes_kernel(own1, seg1, own2, seg2, s, cut, period, ring):
    """The node pairs of :meth:`SelfContact.merge`: (owner, segment) and (owner,
    segment + 1) of both sets, those further apart in arclength than ``cut`` (m). Of a
    ring (``period`` its length, m; ``ring`` its distinct nodes) segment + 1 = N is node
    0 and the separation is periodic (:func:`_separation`); an open rod passes inf and
    its node count."""
    m = 2 * (own1.shape[0] + own2.shape[0])
    own = np.empty(m, np.intp)
    par = np.empty(m, np.intp)
    k = 0
    for oa, sa in ((own1, seg1), (own2, seg2)):
        for q in range(oa.shape[0]):
            for d in range(2):
                o = oa[q]
                p = sa[q] + d
                if p >= ring:
                    p -= ring
                if _separation(s, o, p, period) > cut:
                    own[k] = o
                    par[k] = p
                    k += 1
    return own[:k], par[:k]


@numba.njit(cache=True)
def _covers_kernel(own1, seg1, own2, seg2, n):
    """Whether every (owner, segment) combination of the second set is in the first."""
    have = np.sort(own1 * n + seg1)
    for q in range(own2.shape[0]):
        key = own2[q] * n + seg2[q]
        j = np.searchsorted(have, key)
        if j >= have.shape[0] or have[j] != key:
            return False
    return True


def evaluation_arrays(capacity: int):
    """Work arrays for :func:`evaluate_into` with room for ``capacity`` runs (one contact
    at most per run; :class:`solver.kernel_data.EvaluationArrays`). The per-run gaps
    (``run_gap``) are :func:`candidate_gaps_into`'s values when the selection was made
    afresh."""
    r = int(capacity)
    return EvaluationArrays(
        selection=np.empty(r, np.intp), owner=np.empty(r, np.intp),
        segment=np.empty(r, np.intp), t=np.empty(r), nodes=np.empty((r, 5), np.intp),
        weights=np.empty((r, 5)), coef=np.empty((r, 5)), force=np.empty((r, 3)),
        dF_dr=np.empty((r, 5, 3, 3)), dF_dv=np.empty((r, 5, 3, 3)), dt_dr=np.empty((r, 5, 3)),
        dw_dt=np.empty((r, 5)), gap=np.empty(r), distance=np.empty(r), run_gap=np.empty(r))


@numba.njit(cache=True, inline="always")
def _run_bounds(cand, q):
    """(first, last) combination index of run q and whether its outer vertices are rod
    ends, from the candidates' arrays (:class:`solver.kernel_data.CandidateArrays`)."""
    start = cand.run_start
    lo = start[q]
    hi = (start[q + 1] if q + 1 < start.shape[0] else cand.owner.shape[0]) - 1
    return lo, hi, cand.first_is_end[q], cand.last_is_end[q]


@numba.njit(cache=True, inline="always")
def _at_contact(prop, i, j, t):
    """½(p_i + (1 − t) p_j + t p_{j+1}): a nodal property (N,) between owner i and the
    partner point at t on segment (j, j+1)."""
    return 0.5 * (prop[i] + (1.0 - t) * prop[j] + t * prop[j + 1])


@numba.njit(cache=True)
def candidate_gaps_into(r, cand, data, out):
    """Surface gaps (R,) m of the candidates' closest points at positions r (N, 3), inf
    for a minimum at an interior run edge (:meth:`SelfContact.gaps`), into out; the
    selection is made afresh (not frozen). cand: :attr:`ContactCandidates.arrays`; data:
    :attr:`SelfContact.kernel_data`. Returns nothing."""
    own, seg = cand.owner, cand.segment
    seg_nodes, seg_mats, diameter = data.seg_nodes, data.seg_mats, data.diameter
    tb0 = np.empty((3, 4))
    tb1 = np.empty((3, 4))
    # no frozen segment (-1) and the search's iterations as run-time integers (one
    # compiled _run_point for every caller: solver.banded.int_at_run_time)
    not_frozen, iterations = int_at_run_time(r, -1), int_at_run_time(r, 3)
    for q in range(out.shape[0]):
        lo, hi, first_end, last_end = _run_bounds(cand, q)
        k, t, x0, x1, x2, d, c0, c1, c2, g, row = _run_point(
            r, own, seg, lo, hi, not_frozen, iterations, seg_nodes, seg_mats, tb0, tb1)
        if (k == lo and t == 0.0 and not first_end) or (k == hi and t == 1.0
                                                        and not last_end):
            out[q] = np.inf
        else:
            out[q] = d - _at_contact(diameter, own[k], seg[k], t)


@numba.njit(cache=True)
def candidate_potential(r, cand, data):
    """The contact law's stored energy (J) at positions r (N, 3) over the candidates
    (:meth:`SelfContact.potential`): per run, the closest point made afresh (as
    :func:`candidate_gaps_into`), kept as :func:`evaluate_into` keeps it (not an interior
    run edge, closer than the law's cut-off), ½ Δs_i ρĀ Ψ(d; D̄) with ρĀ and D̄ at the
    contact as the force takes them."""
    own, seg = cand.owner, cand.segment
    seg_nodes, seg_mats, diameter = data.seg_nodes, data.seg_mats, data.diameter
    rho_a, w, law = data.rho_a, data.weights, data.law
    tb0 = np.empty((3, 4))
    tb1 = np.empty((3, 4))
    out = 0.0
    not_frozen, iterations = int_at_run_time(r, -1), int_at_run_time(r, 3)
    for q in range(cand.run_start.shape[0]):
        lo, hi, first_end, last_end = _run_bounds(cand, q)
        k, t, x0, x1, x2, d, c0, c1, c2, g, row = _run_point(
            r, own, seg, lo, hi, not_frozen, iterations, seg_nodes, seg_mats, tb0, tb1)
        if (k == lo and t == 0.0 and not first_end) or (k == hi and t == 1.0
                                                        and not last_end):
            continue
        i = own[k]
        j = seg[k]
        dbar = _at_contact(diameter, i, j, t)
        if not d < law_cutoff(law, dbar)[1]:
            continue
        out += 0.5 * w[i] * _at_contact(rho_a, i, j, t) * law_potential(law, d, dbar)
    return out


@numba.njit(cache=True)
def evaluate_into(r, v, cand, frozen, data, ev):
    """The compiled body of :meth:`SelfContact.evaluate`: the active contacts of the
    candidates at positions r and velocities v (N, 3) (global, m and m/s) written into
    the arrays ev of :func:`evaluation_arrays`; returns their number P (the first P
    entries of each array after the selection), or −1 when a kept pair has coincident
    centreline points.

    Per run: the closest point on the partner curve (:func:`~.geometry._run_point`; the
    combination frozen[q] when ``frozen`` is non-empty), kept when it is not an interior
    run edge and closer than the law's cut-off. Per contact, with x = Σ c_a r_a
    (c_a = 1 for the owner, −β_a(t) for the curve's nodes), d = |x|, n = x/d,
    u = Σ c_a v_a, ḋ = n·u, u_t = Σ ∂c_a/∂t v_a and f, f_d, f_ḋ from
    :func:`~.laws.law_force`: F = f n, G = ∂F/∂x|_u = n (f_d nᵀ + f_ḋ (u − ḋ n)ᵀ/d) +
    (f/d)(I − n nᵀ), G_u = f_ḋ n nᵀ; for 0 < t < 1 the stationarity c'·x = 0
    differentiated, g dt = Σ_a (c_a c' − ∂c_a/∂t x)·dr_a (g = |c'|² − x·c''), gives
    ∂t/∂r_a = (c_a c' − ∂c_a/∂t x)/g; with H = G_u u_t − G c', ∂F/∂r_a = c_a G +
    H (∂t/∂r_a)ᵀ and ∂F/∂v_a = c_a G_u; load weights w_a = ½ c_a Δs_i/Δs_a and
    ∂w_a/∂t = ½ ∂c_a/∂t Δs_i/Δs_a (docs/contact.md § 1). The mean diameter and ρA at
    the contact are interpolated linearly on the segment; how they move with t is left
    out of the derivatives."""
    sel, pi, pj, pt, nodes = ev.selection, ev.owner, ev.segment, ev.t, ev.nodes
    weights, coef, force, d_dr, d_dv = ev.weights, ev.coef, ev.force, ev.dF_dr, ev.dF_dv
    dt_dr, dw_dt, gap, dist, run_gap = ev.dt_dr, ev.dw_dt, ev.gap, ev.distance, ev.run_gap
    own, seg = cand.owner, cand.segment
    seg_nodes, seg_mats, diameter = data.seg_nodes, data.seg_mats, data.diameter
    rho_a, w, law = data.rho_a, data.weights, data.law
    tb0 = np.empty((3, 4))
    tb1 = np.empty((3, 4))
    dcoef = np.empty(5)
    G = np.empty((3, 3))
    Gu = np.empty((3, 3))
    n = np.empty(3)
    u = np.empty(3)
    ut = np.empty(3)
    c1 = np.empty(3)
    xv = np.empty(3)
    H = np.empty(3)
    tang = np.empty(3)
    p = 0
    iterations = int_at_run_time(r, 3)
    for q in range(cand.run_start.shape[0]):
        lo, hi, first_end, last_end = _run_bounds(cand, q)
        fk = frozen[q] if frozen.shape[0] else -1
        k, t, x0, x1, x2, d, c10, c11, c12, g, row = _run_point(
            r, own, seg, lo, hi, fk, iterations, seg_nodes, seg_mats, tb0, tb1)
        sel[q] = k
        if (k == lo and t == 0.0 and not first_end) or (k == hi and t == 1.0
                                                        and not last_end):
            run_gap[q] = np.inf
            continue
        i = own[k]
        j = seg[k]
        dbar = _at_contact(diameter, i, j, t)
        run_gap[q] = d - dbar
        if not d < law_cutoff(law, dbar)[1]:
            continue
        if d == 0.0:
            return -1
        nodes[p, 0] = i
        coef[p, 0] = 1.0
        dcoef[0] = 0.0
        for b in range(4):
            nodes[p, b + 1] = seg_nodes[j, b]
            coef[p, b + 1] = -tb0[row, b]
            dcoef[b + 1] = -tb1[row, b]
        xv[0], xv[1], xv[2] = x0, x1, x2
        c1[0], c1[1], c1[2] = c10, c11, c12
        for c in range(3):
            u[c] = 0.0
            ut[c] = 0.0
        for a in range(5):
            b = nodes[p, a]
            for c in range(3):
                u[c] += coef[p, a] * v[b, c]
                ut[c] += dcoef[a] * v[b, c]
        ddot = 0.0
        for c in range(3):
            n[c] = xv[c] / d
            ddot += n[c] * u[c]
        rho = _at_contact(rho_a, i, j, t)
        f, fd, fdd, gp = law_force(law, d, ddot, dbar, rho)
        for c in range(3):
            force[p, c] = f * n[c]
            tang[c] = (u[c] - ddot * n[c]) / d
        for a in range(3):
            for b in range(3):
                nn = n[a] * n[b]
                eye = 1.0 if a == b else 0.0
                G[a, b] = n[a] * (fd * n[b] + fdd * tang[b]) + (f / d) * (eye - nn)
                Gu[a, b] = fdd * nn
        interior = 0.0 < t < 1.0
        gs = g if g > 0.0 else np.inf
        for a in range(3):
            H[a] = (Gu[a, 0] * ut[0] + Gu[a, 1] * ut[1] + Gu[a, 2] * ut[2]) - (
                G[a, 0] * c1[0] + G[a, 1] * c1[1] + G[a, 2] * c1[2])
        wi = w[i]
        for m in range(5):
            ck = coef[p, m]
            for c in range(3):
                dt_dr[p, m, c] = (ck * c1[c] - dcoef[m] * xv[c]) / gs if interior else 0.0
            for a in range(3):
                for b in range(3):
                    d_dr[p, m, a, b] = ck * G[a, b] + H[a] * dt_dr[p, m, b]
                    d_dv[p, m, a, b] = ck * Gu[a, b]
            ratio = wi / w[nodes[p, m]]
            weights[p, m] = 0.5 * ck * ratio
            dw_dt[p, m] = 0.5 * dcoef[m] * ratio
        pi[p] = i
        pj[p] = j
        pt[p] = t
        gap[p] = gp
        dist[p] = d
        p += 1
    return p


def _empty_evaluation(selection=None) -> ContactEvaluation:
    z = np.zeros(0)
    zi = np.zeros(0, dtype=np.intp)
    return ContactEvaluation(zi, zi.copy(), z, np.zeros((0, 5), np.intp), np.zeros((0, 5)),
                             np.zeros((0, 5)), np.zeros((0, 3)), np.zeros((0, 5, 3, 3)),
                             np.zeros((0, 5, 3, 3)), np.zeros((0, 5, 3)), np.zeros((0, 5)),
                             z.copy(), z.copy(), float("inf"), 0, selection)
