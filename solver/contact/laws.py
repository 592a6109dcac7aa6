"""Contact laws: pressure per unit length as a function of the surface gap.

Both laws give the force per unit length on one strand of a pair at centreline distance d
(m) and normal approach rate ḋ (m/s):

    f(d, ḋ) = ρĀ φ(d) [ P(g) − (k3/d) ḋ|ḋ|^k4 ],     g = d − (D_i + D_j)/2,

(the barrier's P is not multiplied by φ: it is C² at its activation gap already)

with ρĀ the mean mass per unit length of the pair (kg/m), P(g) the repulsion (m/s²) of the
law, the seed's damping (Goyal, Perkins & Lee, eq. 6) and φ a C² cut-off that takes the
whole law smoothly to zero at the outer distance d_off, so a pair can enter and leave the
active set inside a Newton iteration without a jump in the residual or its slope.

* ``SeedLaw``: P(g) = k1/g^k2 (seed eq. 6) for g ≥ g_floor, continued linearly below it
  (finite and still rising for g ≤ 0, where the step is rejected); φ goes from 1 at
  d_on = ½(D̄ + tolerance) to 0 at d_off = tolerance. Beyond d_on the seed's law is
  changed: at the seed example's parameters P(d_on) = 0.1 m/s², 2 % of the pressure at the
  equilibrium gap of 0.35 mm.
* ``BarrierLaw``: IPC's compact-support log barrier (Li et al., ACM TOG 39(4), 2020, eq. 6)
  b(g) = −(g − ĝ)² ln(g/ĝ) for 0 < g < ĝ; P(g) = −κ b'(g) = κ[2(g − ĝ) ln(g/ĝ) +
  (g − ĝ)²/g], which is C² at ĝ (P = P' = 0 there) and grows like −2ĝκ ln(g/ĝ) + κĝ²/g
  as g → 0. Only the damping term is cut off, with d_on = D̄ + ½ĝ, d_off = D̄ + ĝ.

A law returns, per pair, f (N/m), ∂f/∂d (N/m²) and ∂f/∂ḋ (N·s/m²).

**Stored potential.** The conservative part ρĀ φ(d) P(g) of both laws is −ρĀ dΨ/dd with

    Ψ(d) = ∫_d^{d_off} φ(x) P(x − D̄) dx      (m²/s²; the barrier's P without φ)

(:func:`law_potential`), the energy per unit length per unit ρĀ the pair stores; the
damping only dissipates and has none. The seed's Ψ is the power law's primitive
k1 g^{1−k2}/(1−k2) (k1 ln g for k2 = 1) from g up to d_on − D̄, the linear continuation's
exact integral below the floor, and the cut-off band [d_on, d_off] by 24-point
Gauss-Legendre in ln g (a quintic times a power of g: exact to round-off at the seed
example's parameters); the barrier's is κ b(g) (P = −κ b'), continued by the linear part's
integral below the floor. :class:`solver.balance.ContactWork` books it.
"""
from __future__ import annotations

from abc import ABC, abstractmethod

import math

import numba
import numpy as np

__all__ = ["SeedLaw", "BarrierLaw", "smoothstep_off", "law_force", "law_potential", "SEED",
           "BARRIER"]

#: the law kinds of a parameter vector (:attr:`_Law.params`)
SEED, BARRIER = 0, 1
#: the layout of a law's parameter vector as the compiled kernels take it
_KIND, _K1, _K2, _K3, _K4, _TOL, _FLOOR, _DHAT, _KAPPA = range(9)


@numba.njit(cache=True, inline="always")
def _smoothstep(d, d_on, d_off):
    """φ(d), φ'(d) of the C² cut-off (:func:`smoothstep_off`) for one distance."""
    w = d_off - d_on
    x = min(max((d - d_on) / w, 0.0), 1.0)
    x2 = x * x
    return 1.0 - x2 * x * (10.0 - 15.0 * x + 6.0 * x2), -30.0 * x2 * (1.0 - x) ** 2 / w


@numba.njit(cache=True, inline="always")
def _barrier_p(kappa, h, g):
    """IPC's barrier pressure P(g) = κ[2(g − ĝ) ln(g/ĝ) + (g − ĝ)²/g] and P'(g) for one
    gap 0 < g ≤ ĝ (module doc)."""
    lg = math.log(g / h)
    val = kappa * (2.0 * (g - h) * lg + (g - h) ** 2 / g)
    slope = kappa * (2.0 * lg + 4.0 * (g - h) / g - ((g - h) / g) ** 2)
    return val, slope


@numba.njit(cache=True, inline="always")
def _repulsion(law, gap):
    """P(g) (m/s²) and P'(g) (1/s²) of the law ``law`` (its parameter vector) for one gap
    (m), with the linear continuation below the gap floor (module doc)."""
    gf = law[_FLOOR]
    if law[_KIND] == SEED:
        g = max(gap, gf)
        val = law[_K1] * g ** (-law[_K2])
        slope = -law[_K2] * val / g
        if gap < gf:
            val = val + slope * (gap - gf)
        return val, slope
    h = law[_DHAT]
    if gap >= h:
        return 0.0, 0.0
    val, slope = _barrier_p(law[_KAPPA], h, min(max(gap, gf), h))
    if gap < gf:
        val = val + slope * (gap - gf)
    return val, slope


@numba.njit(cache=True, inline="always")
def law_cutoff(law, mean_diameter):
    """(d_on, d_off) (m) of the law's cut-off φ for a pair of mean diameter D̄ (m): the
    seed's ½(D̄ + tolerance) and tolerance, the barrier's D̄ + ½ĝ and D̄ + ĝ."""
    if law[_KIND] == SEED:
        return 0.5 * (mean_diameter + law[_TOL]), law[_TOL]
    return mean_diameter + 0.5 * law[_DHAT], mean_diameter + law[_DHAT]


@numba.njit(cache=True, inline="always")
def law_force(law, d, ddot, mean_diameter, rho):
    """The force per unit length of one pair and its derivatives (module doc):
    f = ρĀ φ(d)[P(g) − (k3/d) ḋ|ḋ|^k4] (the barrier's P not cut off), for centreline
    distance d (m), approach rate ḋ (m/s), mean diameter D̄ (m) and ρĀ (kg/m). ``law``:
    the parameter vector (:attr:`_Law.params`). Returns (f (N/m), ∂f/∂d (N/m²),
    ∂f/∂ḋ (N·s/m²), gap g = d − D̄ (m)). The one implementation of both laws: the
    classes below and the contact kernels of :mod:`solver.contact.model` call it."""
    gap = d - mean_diameter
    rep, rep_slope = _repulsion(law, gap)
    d_on, d_off = law_cutoff(law, mean_diameter)
    phi, dphi = _smoothstep(d, d_on, d_off)
    k3 = law[_K3]
    k4 = law[_K4]
    absd = abs(ddot)
    powk = absd ** k4 if k4 != 0.0 else 1.0
    damp = k3 * ddot * powk / d
    if law[_KIND] == SEED:
        core = rep - damp
        f = rho * phi * core
        f_d = rho * (dphi * core + phi * (rep_slope + damp / d))
    else:
        f = rho * (rep - phi * damp)
        f_d = rho * (rep_slope - dphi * damp + phi * damp / d)
    f_dd = -rho * phi * k3 * (1.0 + k4) * powk / d
    return f, f_d, f_dd, gap


#: Gauss-Legendre nodes and weights on [−1, 1] for the seed law's cut-off band
_GL_X, _GL_W = np.polynomial.legendre.leggauss(24)


@numba.njit(cache=True, inline="always")
def _repulsion_integral(law, g1, g2):
    """∫_{g1}^{g2} P(g) dg (m²/s²) of the law's repulsion without the cut-off, g1 ≤ g2
    (m): the power law's (seed) or barrier's primitive above the gap floor, the linear
    continuation's exact integral below it."""
    gf = law[_FLOOR]
    out = 0.0
    if g1 < gf:
        hi = min(g2, gf)
        p0, slope = _repulsion(law, gf)
        # ∫ p0 + slope (g − gf) dg over [g1, hi]
        out += p0 * (hi - g1) + 0.5 * slope * ((hi - gf) ** 2 - (g1 - gf) ** 2)
        g1 = hi
    if g2 > g1:
        if law[_KIND] == SEED:
            k1, k2 = law[_K1], law[_K2]
            if k2 == 1.0:
                out += k1 * math.log(g2 / g1)
            else:
                out += k1 * (g2 ** (1.0 - k2) - g1 ** (1.0 - k2)) / (1.0 - k2)
        else:
            h = law[_DHAT]
            a, b = min(g1, h), min(g2, h)
            # P = −κ b'(g), b(g) = −(g − ĝ)² ln(g/ĝ): κ (b(a) − b(b))
            out += law[_KAPPA] * ((b - h) ** 2 * math.log(b / h)
                                  - (a - h) ** 2 * math.log(a / h))
    return out


@numba.njit(cache=True, inline="always")
def law_potential(law, d, mean_diameter):
    """Ψ(d) = ∫_d^{d_off} φ(x) P(x − D̄) dx (m²/s²; the barrier's P not cut off), the
    stored potential per unit length per unit ρĀ of one pair at centreline distance d
    (m), mean diameter D̄ (m) (module doc): −ρĀ dΨ/dd is :func:`law_force`'s f at ḋ = 0.
    ``law``: the parameter vector (:attr:`_Law.params`)."""
    d_on, d_off = law_cutoff(law, mean_diameter)
    if d >= d_off:
        return 0.0
    gap = d - mean_diameter
    if law[_KIND] != SEED:
        return _repulsion_integral(law, gap, law[_DHAT])
    g_on = d_on - mean_diameter
    out = 0.0
    if gap < g_on:
        out += _repulsion_integral(law, gap, g_on)
    # the cut-off band [max(d, d_on), d_off] in u = ln g
    a = max(d, d_on) - mean_diameter
    b = d_off - mean_diameter
    if a > 0.0:
        ua, ub = math.log(a), math.log(b)
        half, mid = 0.5 * (ub - ua), 0.5 * (ub + ua)
        for k in range(_GL_X.shape[0]):
            g = math.exp(mid + half * _GL_X[k])
            phi = _smoothstep(g + mean_diameter, d_on, d_off)[0]
            out += half * _GL_W[k] * phi * _repulsion(law, g)[0] * g
    else:
        half, mid = 0.5 * (b - a), 0.5 * (b + a)
        for k in range(_GL_X.shape[0]):
            g = mid + half * _GL_X[k]
            phi = _smoothstep(g + mean_diameter, d_on, d_off)[0]
            out += half * _GL_W[k] * phi * _repulsion(law, g)[0]
    return out


@numba.njit(cache=True)
def _potential_kernel(law, d, mean_diameter, out):
    for m in range(d.shape[0]):
        out[m] = law_potential(law, d[m], mean_diameter[m])


@numba.njit(cache=True)
def _law_kernel(law, d, ddot, mean_diameter, rho, out):
    for m in range(d.shape[0]):
        out[0, m], out[1, m], out[2, m], out[3, m] = law_force(law, d[m], ddot[m],
                                                               mean_diameter[m], rho[m])


@numba.njit(cache=True)
def _repulsion_kernel(law, gap, out):
    for m in range(gap.shape[0]):
        out[0, m], out[1, m] = _repulsion(law, gap[m])


@numba.njit(cache=True)
def _cutoff_kernel(law, mean_diameter, out):
    for m in range(mean_diameter.shape[0]):
        out[0, m], out[1, m] = law_cutoff(law, mean_diameter[m])


@numba.njit(cache=True)
def _smoothstep_kernel(d, d_on, d_off, out):
    for m in range(d.shape[0]):
        out[0, m], out[1, m] = _smoothstep(d[m], d_on[m], d_off[m])


def _flat(*arrays):
    shape = np.broadcast_shapes(*(np.shape(a) for a in arrays))
    return shape, [np.ascontiguousarray(np.broadcast_to(np.asarray(a, float), shape)).ravel()
                   for a in arrays]


def smoothstep_off(d, d_on, d_off):
    """C² cut-off φ(d) and φ'(d): 1 for d ≤ d_on, 0 for d ≥ d_off, the quintic
    1 − (10x³ − 15x⁴ + 6x⁵), x = (d − d_on)/(d_off − d_on), in between.

    d, d_on, d_off: arrays of one shape (m). Returns (φ, dφ/dd (1/m)).
    """
    shape, (d, d_on, d_off) = _flat(d, d_on, d_off)
    out = np.empty((2, d.size))
    _smoothstep_kernel(d, d_on, d_off, out)
    return out[0].reshape(shape), out[1].reshape(shape)


class _Law(ABC):
    """Shared damping and cut-off; subclasses give the parameter vector ``params`` (9,)
    that the compiled :func:`law_force` reads: kind, k1, k2, k3, k4, tolerance,
    gap_floor, ĝ, κ."""

    def __init__(self, k3: float, k4: float):
        self.k3, self.k4 = float(k3), float(k4)

    @property
    @abstractmethod
    def params(self) -> np.ndarray:
        """The law as the compiled kernels take it, (9,) float."""

    def cutoff(self, mean_diameter):
        """(d_on, d_off) (m), each shaped like mean_diameter: where φ leaves 1 and reaches 0."""
        shape, (dbar,) = _flat(mean_diameter)
        out = np.empty((2, dbar.size))
        _cutoff_kernel(self.params, dbar, out)
        return out[0].reshape(shape), out[1].reshape(shape)

    def repulsion(self, gap):
        """P(g) (m/s²) and P'(g) (1/s²) for gaps g (m), same shape."""
        shape, (g,) = _flat(gap)
        out = np.empty((2, g.size))
        _repulsion_kernel(self.params, g, out)
        return out[0].reshape(shape), out[1].reshape(shape)

    def potential(self, d, mean_diameter):
        """Ψ(d) (m²/s²) per pair (:func:`law_potential`); d, mean_diameter (m) of one
        shape: the stored energy per unit length of a pair is ρĀ Ψ."""
        shape, (d, dbar) = _flat(d, mean_diameter)
        out = np.empty(d.size)
        _potential_kernel(self.params, d, dbar, out)
        return out.reshape(shape)

    def __call__(self, d, ddot, mean_diameter, rho):
        """f, ∂f/∂d, ∂f/∂ḋ, gap per pair; d, ddot, mean_diameter (m), rho (kg/m): (P,)."""
        shape, (d, ddot, dbar, rho) = _flat(d, ddot, mean_diameter, rho)
        out = np.empty((4, d.size))
        _law_kernel(self.params, d, ddot, dbar, rho, out)
        return tuple(o.reshape(shape) for o in out)


class SeedLaw(_Law):
    """Seed eq. 6 with the linear floor and the C² cut-off at the tolerance (module doc).

    k1 (m^(1+k2)/s²), k2 (−), k3, k4: the seed's constants; tolerance (m): outer cut-off
    distance; gap_floor (m): below it P continues linearly.
    """

    name = "seed"

    def __init__(self, k1, k2, k3, k4, tolerance, gap_floor):
        super().__init__(k3, k4)
        self.k1, self.k2 = float(k1), float(k2)
        self.tolerance = float(tolerance)
        self.gap_floor = float(gap_floor)
        self._params = np.array([SEED, self.k1, self.k2, self.k3, self.k4, self.tolerance,
                                 self.gap_floor, 0.0, 0.0])

    @property
    def params(self):
        return self._params

    def equilibrium_gap(self, pressure):
        """The gap g (m) at which P(g) equals ``pressure`` (m/s²), inverting k1/g^k2."""
        return (self.k1 / pressure) ** (1.0 / self.k2)


class BarrierLaw(_Law):
    """IPC's compact-support barrier (module doc): activation gap ĝ (m), stiffness κ (1/s²),
    damping k3, k4 as the seed's; gap_floor (m): below it P continues linearly."""

    name = "barrier"

    def __init__(self, d_hat, stiffness, k3, k4, gap_floor):
        super().__init__(k3, k4)
        self.d_hat, self.kappa = float(d_hat), float(stiffness)
        self.gap_floor = float(gap_floor)
        self._params = np.array([BARRIER, 0.0, 0.0, self.k3, self.k4, 0.0, self.gap_floor,
                                 self.d_hat, self.kappa])

    @property
    def params(self):
        return self._params

    def equilibrium_gap(self, pressure):
        """The gap g (m) with P(g) = pressure (m/s²), by bisection on (0, ĝ)."""
        lo, hi = 1e-12 * self.d_hat, self.d_hat
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if _barrier_p(self.kappa, self.d_hat, mid)[0] > pressure:
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)
