"""Self-contact force kernel of the rod (seed §3, eq. 6), pure numpy/scipy.

Seed eq. 6 gives a distributed (per unit length) repulsion between two grid points of the
rod at centreline distance d:

    B_contact = ρA ( k1/(d − ½D)^k2 + (k3/d) ḋ|ḋ|^k4 )

along the line joining them.  The decisions that turn it into a kernel (reasoning in
``docs/contact.md``):

1. Gap.  ``gap = d − (D_i + D_j)/2``: the seed's ½D read as half the *sum* of the two
   diameters, so the repulsion is singular exactly at touching.
2. Direction and damping sign.  With ``n = (r_i − r_j)/d`` and ``ḋ = n·(v_i − v_j)``
   (global velocities), the force per unit length on i is

       F_i = ρĀ [ R(gap) − (k3/d) ḋ|ḋ|^k4 ] n,      ρĀ = (ρA_i + ρA_j)/2,

   so the damper opposes the relative normal motion both ways (it is odd in ḋ as printed:
   approach, ḋ < 0, adds repulsion; separation, ḋ > 0, reduces it).
3. Floor.  ``R(gap) = k1/gap^k2`` for gap > gap_floor; below it R continues linearly with
   the value and slope at gap_floor, so the residual stays finite (and keeps growing) for
   gap ≤ 0.  ``gap_floor = 1e-3 × mean diameter``.  The solver treats gap < 0 as
   penetration and rejects the step (``ContactEvaluation.min_gap``).
4. Pair selection.  Grid points i, j with |s_i − s_j| > exclusion (default 2 × max
   diameter), centreline distance d < tolerance (the case's tolerance is a *distance*
   below which pairs are tested, and must exceed the diameter, else touching pairs are
   missed: checked at construction), and each inside the other's aperture:
   |a3_i · n| ≤ sin(θ/2) and |a3_j · n| ≤ sin(θ/2) (θ → 0: the cross-section plane,
   θ = 180°: all space).
5. Grid independence.  A contact spans many grid points (Δs = 1 mm, D = 2 cm).  Each node
   i keeps only its closest qualifying partner on each separately approaching strand: a
   qualifying j is kept only if d(i, j) is a local minimum along the partner index
   (d(i, j) ≤ d(i, j ± 1) for the neighbours that exist and are not i itself, tested
   whether they qualify or not) and the smallest
   in its contiguous run of such partners.  So the force per unit length is the law at the
   local closest distance, not a sum over partners, and a partner at the edge of a cut
   (exclusion or aperture), whose neighbour is closer, gives no spurious oblique force.  A kept ordered pair (i, j) (i the owner) puts ``wi = ½`` of F on i and
   ``−wj F`` with ``wj = ½ Δs_i/Δs_j`` on j, Δs the nodal quadrature weights (half cells
   at the ends), so Σ_nodes Δs·force = 0 and each strand receives ≈ F per unit length in
   total from the pairs its nodes own and those its partner's nodes own.

Contact acts through the centreline without friction: no contact moment.

API (docs/interfaces.md, ``solver.contact``)::

    sc = SelfContact(spec, s, diameter, rho_a)
    sc.may_touch(positions, tangents) -> bool
    pairs = sc.find_pairs(positions, tangents)           # ContactPairs
    ev = sc.evaluate(pairs, positions, velocities)        # ContactEvaluation
    nodal = assemble_nodal(ev, n_nodes)                   # (N, 3) N/m
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

__all__ = [
    "SelfContact",
    "ContactPairs",
    "ContactEvaluation",
    "assemble_nodal",
    "nodal_weights",
    "GAP_FLOOR_FRACTION",
]

#: gap_floor = GAP_FLOOR_FRACTION × mean diameter (decision 3).
GAP_FLOOR_FRACTION = 1.0e-3

#: default exclusion = EXCLUSION_DIAMETERS × max diameter (decision 4).
EXCLUSION_DIAMETERS = 2.0


@dataclass(frozen=True)
class ContactPairs:
    """Ordered contact pairs found by :meth:`SelfContact.find_pairs`.

    Attributes
    ----------
    i : (P,) int
        Owner node of each pair (receives ``wi × force``).
    j : (P,) int
        Partner node (receives ``−wj × force``).  (i, j) and (j, i) may both appear: each
        node owns its own closest partner on the other strand.
    distance : (P,) float, m
        Centreline distance at detection.
    """

    i: np.ndarray
    j: np.ndarray
    distance: np.ndarray

    @property
    def count(self) -> int:
        return int(self.i.size)

    def __len__(self) -> int:
        return self.count


@dataclass(frozen=True)
class ContactEvaluation:
    """Contact forces of a set of pairs, with their derivatives.

    Attributes
    ----------
    i, j : (P,) int
        Owner and partner nodes.
    force : (P, 3) float, N/m, global frame
        Force per unit length F on the owner i (pushing i away from j when positive
        repulsion dominates).  Node i receives ``wi·F``, node j receives ``−wj·F``.
    wi, wj : (P,) float
        Weights: ``wi = ½``, ``wj = ½ Δs_i/Δs_j`` (so ``Δs_i wi = Δs_j wj``).
    d_force_d_dr : (P, 3, 3) float, N/m²
        ∂F/∂(r_i − r_j) (positions global, m).
    d_force_d_dv : (P, 3, 3) float, N·s/m²
        ∂F/∂(v_i − v_j) (global velocities, m/s).
    gap : (P,) float, m
        Surface gap d − (D_i + D_j)/2 (negative: penetration).
    distance : (P,) float, m
        Centreline distance d.
    min_gap : float, m
        Smallest gap among the pairs, ``inf`` if there are none.
    count : int
        Number of pairs P.
    """

    i: np.ndarray
    j: np.ndarray
    force: np.ndarray
    wi: np.ndarray
    wj: np.ndarray
    d_force_d_dr: np.ndarray
    d_force_d_dv: np.ndarray
    gap: np.ndarray
    distance: np.ndarray
    min_gap: float
    count: int


def nodal_weights(s) -> np.ndarray:
    """Nodal quadrature weights Δs (m) of a grid s: half cells at the ends.

    ``Δs_k = (s_{k+1} − s_{k−1})/2`` inside, ``(s_1 − s_0)/2`` and ``(s_{N−1} − s_{N−2})/2``
    at the ends, so Σ Δs = s_{N−1} − s_0 (the trapezoid rule).  N = 1 gives [0].
    """
    s = np.asarray(s, dtype=float)
    w = np.zeros_like(s)
    if s.size >= 2:
        h = np.diff(s)
        w[:-1] += 0.5 * h
        w[1:] += 0.5 * h
    return w


def assemble_nodal(ev: ContactEvaluation, n_nodes: int) -> np.ndarray:
    """Nodal contact force density (N/m, global, shape (n_nodes, 3)).

    Node i of each pair gets ``+wi·force``, node j gets ``−wj·force``; contributions of
    several pairs to one node add.  With Δs the nodal weights, Σ_k Δs_k·out_k = 0 up to
    round-off (momentum balance of the pairs).

    Raises
    ------
    ValueError if a pair index is outside [0, n_nodes).
    """
    out = np.zeros((int(n_nodes), 3))
    if ev.count == 0:
        return out
    if min(ev.i.min(), ev.j.min()) < 0 or max(ev.i.max(), ev.j.max()) >= n_nodes:
        raise ValueError(f"assemble_nodal: pair index outside [0, {n_nodes})")
    np.add.at(out, ev.i, ev.wi[:, None] * ev.force)
    np.add.at(out, ev.j, -ev.wj[:, None] * ev.force)
    return out


def _spec_value(spec, name, default=None):
    if isinstance(spec, dict):
        return spec.get(name, default)
    return getattr(spec, name, default)


class SelfContact:
    """Self-contact of one rod: pair detection and the seed's eq.-6 force law.

    Parameters
    ----------
    spec
        Object (or dict) with ``aperture`` (deg, in (0, 180]), ``tolerance`` (m, centreline
        distance below which pairs are tested; must exceed max diameter), ``k1``
        (m^(1+k2)/s², ≥ 0), ``k2`` (≥ 0), ``k3`` (m^(1−k4)·s^(k4−1), ≥ 0), ``k4`` (≥ 0) and
        ``exclusion`` (None or m ≥ 0: minimum arclength separation of a pair; default
        2 × max diameter).  Typically ``case.contact``.
    s : (N,) float, m
        Node arclengths, strictly increasing.
    diameter : (N,) float, m, > 0
        Cable diameter D at the nodes.
    rho_a : (N,) float, kg/m, > 0
        Mass per unit length ρA at the nodes.

    Raises
    ------
    ValueError
        Bad shapes, non-finite or out-of-range values, or tolerance ≤ max diameter.

    Attributes
    ----------
    weights : (N,) nodal quadrature weights Δs (m).
    exclusion, tolerance, gap_floor (m); sin_half_aperture; separation_cut (m): pairs
    need |s_i − s_j| > separation_cut (the exclusion plus 1e-9 of a mean cell, so that
    rounding in s never decides); min_separation (m): the smallest such node separation.
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
                raise ValueError(f"SelfContact: spec.{name} = {v} must be {'>' if lo_open else '>='} {lo}")
            if hi is not None and v > hi:
                raise ValueError(f"SelfContact: spec.{name} = {v} must be <= {hi}")
            return v

        self.aperture = num("aperture", lo=0.0, lo_open=True, hi=180.0)
        self.tolerance = num("tolerance", lo=0.0, lo_open=True)
        self.k1 = num("k1", lo=0.0)
        self.k2 = num("k2", lo=0.0)
        self.k3 = num("k3", lo=0.0)
        self.k4 = num("k4", lo=0.0)
        excl = num("exclusion", lo=0.0, optional=True)
        self.exclusion = EXCLUSION_DIAMETERS * float(diameter.max()) if excl is None else excl
        if self.tolerance <= float(diameter.max()):
            raise ValueError(
                f"SelfContact: tolerance ({self.tolerance} m) must exceed the largest diameter "
                f"({float(diameter.max())} m): pairs are tested only for centreline distance "
                "d < tolerance, so touching pairs (d = D) would be missed")

        self.s = s
        self.diameter = diameter
        self.rho_a = rho_a
        self.n_nodes = s.size
        self.weights = nodal_weights(s)
        self.gap_floor = GAP_FLOOR_FRACTION * float(diameter.mean())
        # smallest node separation in arclength that passes the exclusion (m); inf if none
        # pairs must be further apart than the exclusion by more than rounding (1e-9 of a
        # mean cell): a separation equal to the exclusion is excluded whatever the last
        # bit of s, so the same pair never qualifies at one node and not at another.
        # s_sep uses the same test as find_pairs, s_j − s_i > separation_cut.
        self.separation_cut = self.exclusion + 1e-9 * (s[-1] - s[0]) / (s.size - 1)
        partner = np.searchsorted(s, s + self.separation_cut, side="right")
        node = np.arange(s.size)
        cand = np.concatenate([partner - 1, partner])
        own = np.concatenate([node, node])
        valid = (cand > own) & (cand < s.size)
        sep = s[cand[valid]] - s[own[valid]]
        sep = sep[sep > self.separation_cut]
        self.min_separation = float(sep.min()) if sep.size else float("inf")
        # sin(θ/2); θ = 180° gives exactly 1 (all space)
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

    def may_touch(self, positions, tangents) -> bool:
        """O(N) rigorous pre-test: False only if no pair can qualify.

        Let e be the normalised mean tangent and c = min_k (r_{k+1} − r_k)·e / (s_{k+1} − s_k)
        over the chords of the node polyline.  For j > i, summing the chords gives
        (r_j − r_i)·e ≥ c (s_j − s_i), hence |r_j − r_i| ≥ c |s_j − s_i| ≥ c·s_sep for
        every pair that passes the exclusion, where s_sep is the smallest arclength
        separation of two grid nodes that exceeds the exclusion (on a uniform grid the
        next multiple of Δs: with the seed's exclusion = tolerance, the bound with the
        exclusion itself could never rule a pair out).  If c·s_sep ≥ tolerance no pair has
        d < tolerance and the answer is False.  The bound uses the actual chords, so it is
        exact for the discrete positions whatever the tangents (used only for e).

        Parameters
        ----------
        positions : (N, 3) m;  tangents : (N, 3) unit a3 (global).

        Raises
        ------
        ValueError on bad shapes or non-finite values.
        """
        r = self._check_field("positions", positions)
        t = self._check_field("tangents", tangents)
        e = t.mean(axis=0)
        norm = float(np.linalg.norm(e))
        if norm == 0.0:
            return True
        e = e / norm
        c = float(np.min((np.diff(r, axis=0) @ e) / np.diff(self.s)))
        return not (c > 0.0 and c * self.min_separation >= self.tolerance)

    # ------------------------------------------------------------------ find_pairs

    def find_pairs(self, positions, tangents) -> ContactPairs:
        """Qualifying ordered pairs (owner, partner), one per owner and approaching strand.

        Candidates come from ``cKDTree.query_pairs(r=tolerance)`` (never all pairs), then:
        d < tolerance, |s_i − s_j| > exclusion, each node inside the other's aperture
        (|a3·n| ≤ sin(θ/2) at both ends), then for every node the partners that are local
        minima of d along the partner index, one (the closest) per contiguous run
        (decision 5).

        Parameters
        ----------
        positions : (N, 3) m (global);  tangents : (N, 3) a3 (global; normalised here).

        Returns
        -------
        ContactPairs, sorted by owner then partner.

        Raises
        ------
        ValueError on bad shapes, non-finite values or zero tangents.
        """
        r = self._check_field("positions", positions)
        t = self._check_field("tangents", tangents)
        tn = np.linalg.norm(t, axis=1)
        if np.any(tn == 0.0):
            raise ValueError("SelfContact: tangents must be non-zero")
        t = t / tn[:, None]
        empty = ContactPairs(np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp), np.zeros(0))
        cand = cKDTree(r).query_pairs(r=self.tolerance, output_type="ndarray")
        if cand.size == 0:
            return empty
        a, b = cand[:, 0].astype(np.intp), cand[:, 1].astype(np.intp)
        keep = np.abs(self.s[a] - self.s[b]) > self.separation_cut
        a, b = a[keep], b[keep]
        if a.size == 0:
            return empty
        dr = r[a] - r[b]
        d = np.sqrt(np.einsum("ij,ij->i", dr, dr))
        keep = (d < self.tolerance) & (d > 0.0)
        a, b, dr, d = a[keep], b[keep], dr[keep], d[keep]
        if a.size == 0:
            return empty
        n = dr / d[:, None]
        lim = self.sin_half_aperture
        keep = ((np.abs(np.einsum("ij,ij->i", t[a], n)) <= lim)
                & (np.abs(np.einsum("ij,ij->i", t[b], n)) <= lim))
        a, b, d = a[keep], b[keep], d[keep]
        if a.size == 0:
            return empty
        # both orientations: every node looks for its own partners
        own = np.concatenate([a, b])
        par = np.concatenate([b, a])
        dd = np.concatenate([d, d])
        # keep true local minima of d(i, ·) along the partner strand: a partner whose
        # neighbour j ± 1 is closer is the edge of a cut (exclusion or aperture), not the
        # closest approach, and would give a spurious oblique force
        keep = np.ones(own.size, dtype=bool)
        for step in (-1, 1):
            nb = par + step
            ok = (nb >= 0) & (nb < self.n_nodes) & (nb != own)
            dn = np.linalg.norm(r[own[ok]] - r[nb[ok]], axis=1)
            keep[ok] &= dd[ok] <= dn
        own, par, dd = own[keep], par[keep], dd[keep]
        if own.size == 0:
            return empty
        order = np.lexsort((par, own))
        own, par, dd = own[order], par[order], dd[order]
        new_run = np.ones(own.size, dtype=bool)
        new_run[1:] = (own[1:] != own[:-1]) | (par[1:] != par[:-1] + 1)
        run = np.cumsum(new_run) - 1
        # the closest partner of each run (ties: the lower partner index)
        pick = np.lexsort((par, dd, run))
        first = np.ones(pick.size, dtype=bool)
        first[1:] = run[pick[1:]] != run[pick[:-1]]
        sel = np.sort(pick[first])
        return ContactPairs(own[sel].copy(), par[sel].copy(), dd[sel].copy())

    # ------------------------------------------------------------------ evaluate

    def repulsion(self, gap):
        """R(gap) (m/s²) and dR/dgap (1/s²): k1/gap^k2 above gap_floor, linear below."""
        gap = np.asarray(gap, dtype=float)
        gf = self.gap_floor
        g = np.maximum(gap, gf)
        val = self.k1 * g ** (-self.k2)
        slope = -self.k2 * val / g
        below = gap < gf
        val = np.where(below, val + slope * (gap - gf), val)
        return val, slope

    def evaluate(self, pairs: ContactPairs, positions, velocities) -> ContactEvaluation:
        """Forces of the pairs at the given state (seed eq. 6 with decisions 1–3, 5).

        ``F = ρĀ [R(gap) − (k3/d) ḋ|ḋ|^k4] n``, n = (r_i − r_j)/d, ḋ = n·(v_i − v_j).
        Derivatives, with x = r_i − r_j, u = v_i − v_j, P = I − n nᵀ:

            ∂F/∂x = n (f_d nᵀ + f_ḋ (u − ḋ n)ᵀ/d) + f P/d,     ∂F/∂u = f_ḋ n nᵀ,
            f_d = ρĀ [R'(gap) + k3 ḋ|ḋ|^k4/d²],  f_ḋ = −ρĀ k3 (1 + k4)|ḋ|^k4 / d.

        Parameters
        ----------
        pairs : ContactPairs (from :meth:`find_pairs`, possibly at another iterate)
        positions : (N, 3) m, global;  velocities : (N, 3) m/s, global.

        Returns
        -------
        ContactEvaluation (``min_gap = inf`` and empty arrays if there are no pairs).

        Raises
        ------
        ValueError on bad shapes, non-finite values, pair indices out of range, or
        coincident centrelines (d = 0) of a pair.
        """
        r = self._check_field("positions", positions)
        v = self._check_field("velocities", velocities)
        i = np.asarray(pairs.i, dtype=np.intp)
        j = np.asarray(pairs.j, dtype=np.intp)
        p = i.size
        if p == 0:
            z = np.zeros(0)
            return ContactEvaluation(i, j, np.zeros((0, 3)), z, z.copy(), np.zeros((0, 3, 3)),
                                     np.zeros((0, 3, 3)), z.copy(), z.copy(), float("inf"), 0)
        if j.shape != i.shape or min(i.min(), j.min()) < 0 or max(i.max(), j.max()) >= self.n_nodes:
            raise ValueError("SelfContact.evaluate: pair indices out of range or mismatched")
        x = r[i] - r[j]
        u = v[i] - v[j]
        d = np.sqrt(np.einsum("ij,ij->i", x, x))
        if np.any(d == 0.0):
            raise ValueError("SelfContact.evaluate: coincident centreline points in a pair")
        n = x / d[:, None]
        ddot = np.einsum("ij,ij->i", n, u)
        gap = d - 0.5 * (self.diameter[i] + self.diameter[j])
        rho = 0.5 * (self.rho_a[i] + self.rho_a[j])
        rep, rep_slope = self.repulsion(gap)
        absd = np.abs(ddot)
        powk = absd ** self.k4 if self.k4 != 0.0 else np.ones_like(absd)
        damp = self.k3 * ddot * powk / d
        f = rho * (rep - damp)
        f_d = rho * (rep_slope + damp / d)
        f_dd = -rho * self.k3 * (1.0 + self.k4) * powk / d
        force = f[:, None] * n
        nn = n[:, :, None] * n[:, None, :]
        eye = np.eye(3)[None]
        tang = (u - ddot[:, None] * n) / d[:, None]
        d_dr = (n[:, :, None] * (f_d[:, None, None] * n[:, None, :]
                                 + f_dd[:, None, None] * tang[:, None, :])
                + (f / d)[:, None, None] * (eye - nn))
        d_dv = f_dd[:, None, None] * nn
        wi = np.full(p, 0.5)
        wj = 0.5 * self.weights[i] / self.weights[j]
        return ContactEvaluation(i, j, force, wi, wj, d_dr, d_dv, gap, d,
                                 float(gap.min()), int(p))
