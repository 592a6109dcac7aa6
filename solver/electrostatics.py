"""Screened electrostatics (Debye–Hückel) between non-adjacent parts of one rod.

A rod carrying a line charge ν (C/m) in an electrolyte of Debye length λ (m) and relative
permittivity ε_r stores the linearised Poisson–Boltzmann (Debye–Hückel) energy of each
pair of its line elements (Debye & Hückel, Phys. Z. 24, 185 (1923); for DNA as a line
charge, Stigter, Biopolymers 16, 1435 (1977); Vologodskii & Cozzarelli, Biopolymers 35,
289 (1995))::

    U = A Σ_{pairs k < l kept} ∫_k ∫_l φ(|r(s) − r(s')|) ds ds',    A = ν² / (4π ε₀ ε_r)
    φ(ρ) = S(ρ) e^{−ρ/λ} / ρ

over the segments k (nodes k, k+1) of the polygon through the nodes r (N+1, 3), each
unordered pair once, ds the arclength of the rod's grid (s_{k+1} − s_k: the charge sits
on the material, and the rod is inextensible). Two straight parallel lines at distance d
store A · 2 K₀(d/λ) per unit length (∫ e^{−√(d²+x²)/λ}/√(d²+x²) dx = 2 K₀(d/λ) by x = d sinh t
in K₀(z) = ∫₀^∞ e^{−z cosh t} dt, DLMF 10.32.9), i.e. ν²/(2π ε₀ ε_r) K₀(d/λ), and repel with ν²/(2π ε₀ ε_r λ) K₁(d/λ)
per unit length.

* **Cut-off.** S is the C² quintic switch of the contact laws
  (:func:`solver.contact.laws.smoothstep_off`) from 1 at ρ_on = r_c − λ to 0 at the
  cut-off r_c = ``cutoff`` · λ, so the energy, its forces and their Jacobian are continuous
  as pairs cross it. What it leaves out is bounded for straight lines: two lines at any
  distance lose at most ν²/(2π ε₀ ε_r) K₀(ρ_on/λ) of energy per unit length (1 − S ≤ 1
  vanishes for ρ < ρ_on, and the arclength dx/dρ = ρ/√(ρ² − d²) that a line at d < ρ_on
  puts beyond ρ_on is at most that of the line at d = ρ_on), K₀(5) = 3.7e-3 at the
  default cut-off of 6 λ (:func:`tail_bound`). Measured on two parallel lines at the
  default (quadrature of the switched kernel against K₀ and K₁): the energy per length
  falls short of ν²/(2π ε₀ ε_r) K₀(d/λ) by 0.16 %, 0.61 % and 2.2 % at d = λ, 2λ, 3λ, and
  the force per length exceeds ν²/(2π ε₀ ε_r λ) K₁(d/λ) by 3e-5, 3e-4 and 2e-3 relative
  (the switch's slope pushes); a cut-off of 8 λ gives 1.6e-4 and 1.7e-6 at d = λ.
* **Exclusion.** A pair of segments is kept when the arclength between them,
  s_l − s_{k+1} (l > k), is at least ``exclusion`` (m): near neighbours along the rod are
  left out, their screened repulsion being part of the measured bending stiffness (the
  electrostatic persistence length of Odijk, J. Polym. Sci. Polym. Phys. 15, 477 (1977)
  and Skolnick & Fixman, Macromolecules 10, 944 (1977), which a measured persistence
  length includes; the DNA chain models of Vologodskii & Cozzarelli 1995 leave out
  neighbouring segments, a rule not checked here against the paper). The default, the
  cut-off r_c, leaves out every pair that would interact on a straight rod, so a straight
  rod stores no electrostatic energy and the term acts only between parts that the rod's
  shape brings together (a loop, a plectoneme, a hairpin). Adjacent segments (gap 0) are
  always left out (the exclusion is > 0). On a closed rod (``closed``, node N node 0
  again) the gap is measured round the ring, the shorter way, min(s_l − s_{k+1},
  L − (s_{l+1} − s_k)): segments N − 1 and 0 are adjacent.
* **Quadrature.** Gauss–Legendre with ``points`` nodes on each segment of a pair
  (``points``² evaluations of φ per pair). The integrand is analytic away from the
  switch, and the error falls geometrically with the points at a rate set by the ratio
  of the segment length h to the pair's distance d and to λ. Measured on single pairs of
  straight segments (parallel, at 45° and crossed, side by side or offset by h/2 and h)
  against 64 points, the worst relative error of the pair's energy with the default 6
  points is below 2e-7 for d ≥ h and λ ≥ h/2, 1e-6 for d ≥ h and λ ≥ h/4, 5e-5 for
  d ≥ h/2 and λ ≥ h/2, 5e-4 for d ≥ h/3 and λ ≥ h/2 (measured 1.0e-7, 5.0e-7, 3.0e-5,
  4.4e-4), and 4e-3 at d = h/4 and λ = h/4
  (:func:`quadrature_error`; tests/solver/test_electrostatics.py). Keep the segments no
  longer than the closest approach the case expects (for DNA, its diameter) and twice
  the Debye length. Where a pair straddles the switch the integrand is C² only there,
  and that part of the error falls algebraically, on terms below e^{−(cutoff−1)}. The
  energy is that of the quadrature rule, and the forces and the Jacobian are its exact
  derivatives.
* **Candidates.** The segment pairs are found by the contact module's node-pair search
  (:func:`solver.contact.geometry.close_node_pairs`, the blocked k-d tree): node pairs
  within r_c plus the longest chord, whose segments are then tested by their midpoints.
* **Loads.** The nodal force F_i = −∂U/∂r_i (N) as a load density per length at the
  node, L_i = F_i / w_i (N/m), w_i the node's share of the grid (the trapezoid weights,
  :func:`solver.contact.nodal_weights`), which the box rule's force rows take as
  h/2 (L_i + L_{i+1}) per cell (:func:`solver.statics.residual`), and the Jacobian
  ∂L/∂r (3(N+1), 3(N+1)) sparse from the kernel's exact second derivatives. Of a closed
  rod node N's force is node 0's, its weight the ring's (h_0 + h_{N−1})/2, and the
  density at both (:func:`solver.contact.model.close_join`).

Pure: no I/O, no state between calls.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

__all__ = ["VACUUM_PERMITTIVITY", "ELEMENTARY_CHARGE", "BOLTZMANN", "AVOGADRO",
           "WATER_PERMITTIVITY", "DEFAULT_CUTOFF", "DEFAULT_POINTS", "debye_length",
           "ScreenedElectrostatics", "ElectrostaticLoads", "screened_kernel", "tail_bound",
           "quadrature_error"]

#: ε₀, F/m (CODATA 2018)
VACUUM_PERMITTIVITY = 8.8541878128e-12
#: e, C (exact in the SI since 2019)
ELEMENTARY_CHARGE = 1.602176634e-19
#: k_B, J/K (exact)
BOLTZMANN = 1.380649e-23
#: N_A, 1/mol (exact)
AVOGADRO = 6.02214076e23
#: ε_r of water at 25 °C and 0.1 MPa (the IAPWS formulation: Fernández et al., J. Phys.
#: Chem. Ref. Data 26, 1125 (1997)); older tables give 78.3 to 78.5
WATER_PERMITTIVITY = 78.4
#: the default cut-off r_c, in Debye lengths
DEFAULT_CUTOFF = 6.0
#: the default Gauss–Legendre points per segment
DEFAULT_POINTS = 6


def debye_length(salt_concentration: float, temperature: float,
                 relative_permittivity: float = WATER_PERMITTIVITY) -> float:
    """The Debye length λ (m) of a 1:1 salt of molar concentration c (mol/L) at the
    temperature T (K): λ = √(ε₀ ε_r k_B T / (2 N_A e² · 1000 c)) (the ionic strength of a
    1:1 salt is c; Debye & Hückel 1923). 0.1 mol/L at 25 °C in water: 0.96 nm. Raises
    ValueError for a value that is not finite and > 0."""
    for name, v in (("salt_concentration", salt_concentration), ("temperature", temperature),
                    ("relative_permittivity", relative_permittivity)):
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"debye_length: {name} must be finite and > 0, got {v!r}")
    n = 2.0 * AVOGADRO * 1000.0 * float(salt_concentration)          # ions per m³, ×e²
    return float(np.sqrt(VACUUM_PERMITTIVITY * relative_permittivity * BOLTZMANN
                         * temperature / (n * ELEMENTARY_CHARGE ** 2)))


def screened_kernel(rho, debye: float, r_on: float, r_cut: float):
    """φ(ρ) = S(ρ) e^{−ρ/λ}/ρ and its first two derivatives (1/m, 1/m², 1/m³), S the C²
    quintic switch 1 − (10t³ − 15t⁴ + 6t⁵), t = (ρ − r_on)/(r_cut − r_on) clipped to
    [0, 1] (:func:`solver.contact.laws.smoothstep_off`'s). rho: array (m), > 0;
    debye λ, r_on < r_cut (m). Returns three arrays shaped like rho."""
    rho = np.asarray(rho, dtype=float)
    g = np.exp(-rho / debye) / rho
    a = 1.0 / debye + 1.0 / rho
    g1 = -g * a
    g2 = g * (a * a + 1.0 / (rho * rho))
    w = r_cut - r_on
    t = np.clip((rho - r_on) / w, 0.0, 1.0)
    S = 1.0 - t ** 3 * (10.0 - 15.0 * t + 6.0 * t * t)
    S1 = -30.0 * t * t * (1.0 - t) ** 2 / w
    S2 = -60.0 * t * (1.0 - t) * (1.0 - 2.0 * t) / (w * w)
    return g * S, g1 * S + g * S1, g2 * S + 2.0 * g1 * S1 + g * S2


def tail_bound(charge_per_length: float, debye: float, cutoff: float,
               relative_permittivity: float = WATER_PERMITTIVITY) -> float:
    """The most energy per unit length (J/m) the cut-off leaves out between two straight
    lines at any distance: ν²/(2π ε₀ ε_r) K₀((cutoff − 1)) (module docstring, "Cut-off");
    cutoff in Debye lengths (> 1)."""
    from scipy.special import k0

    return float(charge_per_length ** 2 / (2.0 * np.pi * VACUUM_PERMITTIVITY
                                           * relative_permittivity) * k0(cutoff - 1.0))


@dataclass(frozen=True)
class ElectrostaticLoads:
    """The screened electrostatics at one set of positions.

    energy : float, J
    loads : (N+1, 3) N/m, global: the nodal forces −∂U/∂r_i over the nodes' weights w_i
    jacobian : (3(N+1), 3(N+1)) scipy CSR, N/m², ∂L/∂r (row 3i + a: L_i,a), or None when
               not asked for
    pairs : (P, 2) int, the segment pairs (k < l) within the cut-off, kept
    """

    energy: float
    loads: np.ndarray
    jacobian: object
    pairs: np.ndarray


class ScreenedElectrostatics:
    """Debye–Hückel repulsion between the non-adjacent segments of one rod (module doc).

    Parameters
    ----------
    s : (N+1,) m, strictly increasing: the rod's grid
    charge_per_length : ν, C/m (its sign does not matter: U ∝ ν²)
    debye_length : λ, m, > 0
    relative_permittivity : ε_r, > 0 (default water at 25 °C)
    cutoff : r_c / λ, > 1 (the switch runs over the last Debye length)
    exclusion : m, > 0, or None (the cut-off r_c): the least arclength between kept segments
    points : Gauss–Legendre points per segment, ≥ 1
    closed : a closed rod, its node N node 0 again: the exclusion measured round the ring
             and node N's loads node 0's (module doc)

    Raises
    ------
    ValueError
        A grid that is not 1-D, finite and increasing, or a parameter out of its range.
    """

    def __init__(self, s, charge_per_length: float, debye_length: float,
                 relative_permittivity: float = WATER_PERMITTIVITY,
                 cutoff: float = DEFAULT_CUTOFF, exclusion: float | None = None,
                 points: int = DEFAULT_POINTS, closed: bool = False):
        from .contact.model import nodal_weights

        s = np.asarray(s, dtype=float)
        if s.ndim != 1 or s.size < (4 if closed else 2) or not np.all(np.isfinite(s)) or np.any(np.diff(s) <= 0):
            raise ValueError("ScreenedElectrostatics: s must be 1-D, finite, strictly "
                             "increasing, with at least 2 nodes")
        checks = (("charge_per_length", charge_per_length, None),
                  ("debye_length", debye_length, 0.0),
                  ("relative_permittivity", relative_permittivity, 0.0),
                  ("cutoff", cutoff, 1.0))
        for name, v, lo in checks:
            if not np.isfinite(v) or (lo is not None and not v > lo):
                raise ValueError(f"ScreenedElectrostatics: {name} = {v!r} must be finite"
                                 + ("" if lo is None else f" and > {lo:g}"))
        if exclusion is not None and not (np.isfinite(exclusion) and exclusion > 0):
            raise ValueError(f"ScreenedElectrostatics: exclusion = {exclusion!r} must be "
                             "finite and > 0")
        if int(points) != points or points < 1:
            raise ValueError(f"ScreenedElectrostatics: points = {points!r} must be an "
                             "integer >= 1")
        self.s = s
        self.debye = float(debye_length)
        self.r_cut = float(cutoff) * self.debye
        self.r_on = self.r_cut - self.debye
        self.exclusion = self.r_cut if exclusion is None else float(exclusion)
        #: A = ν²/(4π ε₀ ε_r), J m
        self.prefactor = float(charge_per_length) ** 2 / (
            4.0 * np.pi * VACUUM_PERMITTIVITY * float(relative_permittivity))
        self.seg = np.diff(s)                          # segment arclengths h_k, m
        self.closed = bool(closed)
        self.weights = nodal_weights(s, self.closed)   # nodal shares w_i, m
        #: the pair rule: (coef (n, n, 4), ww (n, n)), x_ab = Σ_m coef[a, b, m] r_m over
        #: the nodes (k, k+1, l, l+1) and the product weights (:func:`_pair_rule`)
        self.rule = _pair_rule(int(points))

    def with_points(self, points: int) -> "ScreenedElectrostatics":
        """A copy of this model with another number of Gauss–Legendre points per segment
        (the same grid, charge, cut-off and exclusion)."""
        import copy

        if int(points) != points or points < 1:
            raise ValueError(f"ScreenedElectrostatics: points = {points!r} must be an "
                             "integer >= 1")
        out = copy.copy(self)
        out.rule = _pair_rule(int(points))
        return out

    def pairs(self, r) -> np.ndarray:
        """The kept segment pairs (P, 2) (k < l) that may come within the cut-off at the
        node positions r (N+1, 3) m: the node pairs within r_c plus the longest chord
        further apart in arclength than the exclusion
        (:func:`solver.contact.geometry.close_node_pairs`), their segments, those at
        least the exclusion apart in arclength, and of those the pairs whose midpoints
        are closer than r_c plus their half chords (of a closed rod, the node pairs of
        nodes 0 .. N − 1 and the gaps round the ring). Raises ValueError for non-finite
        positions."""
        from .contact.geometry import close_node_pairs

        r = np.ascontiguousarray(r, dtype=float)
        if not np.all(np.isfinite(r)):
            raise ValueError("ScreenedElectrostatics: positions must be finite")
        n_seg = self.seg.size
        chord = np.linalg.norm(np.diff(r, axis=0), axis=1)
        slack = 1e-9 * float(self.seg.mean())
        cut = max(self.exclusion - 2.0 * slack, 0.0)
        radius = self.r_cut + float(chord.max())
        if self.closed:
            s = self.s
            a, b = close_node_pairs(r[:-1], radius, s[:-1], cut, float(s[-1] - s[0]))
            # the segments either side of each node, round the ring
            k = np.concatenate([(a - 1) % n_seg, (a - 1) % n_seg, a, a])
            m = np.concatenate([(b - 1) % n_seg, b, (b - 1) % n_seg, b])
            k, m = np.minimum(k, m), np.maximum(k, m)
            ok = m > k
            k, m = k[ok], m[ok]
            gap = np.minimum(s[m] - s[k + 1], (s[-1] - s[0]) - (s[m + 1] - s[k]))
        else:
            a, b = close_node_pairs(r, radius, self.s, cut)
            lo, hi = np.minimum(a, b), np.maximum(a, b)
            k = np.concatenate([lo - 1, lo - 1, lo, lo])
            m = np.concatenate([hi - 1, hi, hi - 1, hi])
            ok = (k >= 0) & (m < n_seg) & (m > k)
            k, m = k[ok], m[ok]
            gap = self.s[m] - self.s[k + 1]
        ok = gap >= self.exclusion - slack
        key = np.unique(k[ok] * n_seg + m[ok])
        k, m = key // n_seg, key % n_seg
        mid = 0.5 * (r[:-1] + r[1:])
        near = (np.linalg.norm(mid[k] - mid[m], axis=1) - 0.5 * (chord[k] + chord[m])
                < self.r_cut)
        return np.stack([k[near], m[near]], axis=1).astype(np.intp)

    def energy(self, r) -> float:
        """U (J) at the node positions r (N+1, 3) m (module docstring)."""
        return self.evaluate(r, want_jacobian=False).energy

    def evaluate(self, r, want_jacobian: bool = True) -> ElectrostaticLoads:
        """The energy, the nodal loads L (N+1, 3) N/m and, with ``want_jacobian``, ∂L/∂r
        at the node positions r (N+1, 3) m (:class:`ElectrostaticLoads`). Per pair and
        quadrature point, with x the vector between the points, ρ = |x|, n = x/ρ:
        ∂U/∂x = A h_k h_l w_a w_b φ'(ρ) n and ∂²U/∂x² = A h_k h_l w_a w_b (φ'' n nᵀ +
        (φ'/ρ)(I − n nᵀ)), chained by x = Σ_m c_m r_m. Raises ValueError for non-finite
        positions or two kept segments that meet (ρ = 0). Of a closed rod the loads and
        rows of node N are node 0's (:func:`solver.contact.model.close_join`)."""
        from .contact.model import close_join, close_join_jacobian

        r = np.ascontiguousarray(r, dtype=float)
        n1 = r.shape[0]
        if r.shape != (self.s.size, 3):
            raise ValueError(f"ScreenedElectrostatics: positions must have shape "
                             f"({self.s.size}, 3), got {r.shape}")
        pairs = self.pairs(r)
        loads = np.zeros((n1, 3))
        if pairs.shape[0] == 0:
            jac = sp.csr_matrix((3 * n1, 3 * n1)) if want_jacobian else None
            return ElectrostaticLoads(0.0, loads, jac, pairs)
        k, m = pairs[:, 0], pairs[:, 1]
        nodes = np.stack([k, k + 1, m, m + 1], axis=1)                  # (P, 4)
        coef, ww = self.rule
        x = np.einsum("abq,pqi->pabi", coef, r[nodes])             # (P, n, n, 3)
        rho = np.linalg.norm(x, axis=-1)
        if not np.all(rho > 0.0):
            raise ValueError("ScreenedElectrostatics: two kept segments meet")
        phi, d1, d2 = screened_kernel(rho, self.debye, self.r_on, self.r_cut)
        scale = self.prefactor * (self.seg[k] * self.seg[m])[:, None, None] * ww
        energy = float(np.sum(scale * phi))
        n = x / rho[..., None]
        grad = (scale * d1)[..., None] * n                              # ∂U/∂x
        node_grad = np.einsum("pabi,abq->pqi", grad, coef)         # (P, 4, 3)
        np.add.at(loads, nodes, -node_grad)
        loads /= self.weights[:, None]
        if self.closed:
            loads = close_join(loads)
        jac = None
        if want_jacobian:
            eye = np.eye(3)
            nn = n[..., :, None] * n[..., None, :]
            hess = (scale * d2)[..., None, None] * nn + (scale * d1 / rho)[..., None, None] * (
                eye - nn)
            block = np.einsum("pabij,abq,abt->pqtij", hess, coef, coef)
            # ∂L_q/∂r_t = −∂²U/∂r_q∂r_t / w_q
            block = -block / self.weights[nodes][:, :, None, None, None]
            shape = block.shape
            rows = 3 * nodes[:, :, None, None, None] + np.arange(3)[:, None]
            cols = 3 * nodes[:, None, :, None, None] + np.arange(3)[None, :]
            rows = np.broadcast_to(rows, shape).ravel()
            cols = np.broadcast_to(cols, shape).ravel()
            jac = sp.csr_matrix((block.ravel(), (rows, cols)), shape=(3 * n1, 3 * n1))
            if self.closed:
                jac = close_join_jacobian(jac)
        return ElectrostaticLoads(energy, loads, jac, pairs)


def _pair_rule(points: int):
    """Gauss–Legendre's product rule on a pair of segments, u_a on [0, 1] with weights
    w_a (Σ w_a = 1): coef (n, n, 4) = (1 − u_a, u_a, −(1 − u_b), −u_b), the coefficients
    of the nodes (k, k+1, l, l+1) in the vector between the points, and w_a w_b (n, n)."""
    x, w = np.polynomial.legendre.leggauss(points)
    u, w = 0.5 * (x + 1.0), 0.5 * w
    ua, ub = np.meshgrid(u, u, indexing="ij")
    return np.stack([1.0 - ua, ua, -(1.0 - ub), -ub], axis=-1), np.outer(w, w)


def quadrature_error(electrostatics: ScreenedElectrostatics, r,
                     reference_points: int = 48) -> float:
    """The relative error |U_n − U_ref| / |U_ref| of the energy at the node positions r
    (N+1, 3) m with the model's Gauss–Legendre points against ``reference_points`` of them
    (the same pairs, cut-off and exclusion: :meth:`ScreenedElectrostatics.with_points`);
    nan where U_ref = 0."""
    u_ref = electrostatics.with_points(reference_points).energy(r)
    u = electrostatics.energy(r)
    return float(abs(u - u_ref) / abs(u_ref)) if u_ref != 0.0 else float("nan")
