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
"""
from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

__all__ = ["SeedLaw", "BarrierLaw", "smoothstep_off"]


def smoothstep_off(d, d_on, d_off):
    """C² cut-off φ(d) and φ'(d): 1 for d ≤ d_on, 0 for d ≥ d_off, the quintic
    1 − (10x³ − 15x⁴ + 6x⁵), x = (d − d_on)/(d_off − d_on), in between.

    d, d_on, d_off: arrays of one shape (m). Returns (φ, dφ/dd (1/m)).
    """
    w = d_off - d_on
    x = np.clip((d - d_on) / w, 0.0, 1.0)
    x2 = x * x
    phi = 1.0 - x2 * x * (10.0 - 15.0 * x + 6.0 * x2)
    dphi = -30.0 * x2 * (1.0 - x) ** 2 / w
    return phi, dphi


class _Law(ABC):
    """Shared damping and cut-off; subclasses give the repulsion P(g) and P'(g)."""

    #: whether φ multiplies the repulsion too (the seed's law) or only the damping (the
    #: barrier, already C² at its activation gap)
    cut_repulsion = True

    def __init__(self, k3: float, k4: float):
        self.k3, self.k4 = float(k3), float(k4)

    @abstractmethod
    def cutoff(self, mean_diameter):
        """(d_on, d_off) (m), each shaped like mean_diameter: where φ leaves 1 and reaches 0."""

    @abstractmethod
    def repulsion(self, gap):
        """P(g) (m/s²) and P'(g) (1/s²) for gaps g (m), same shape."""

    def __call__(self, d, ddot, mean_diameter, rho):
        """f, ∂f/∂d, ∂f/∂ḋ per pair; d, ddot, mean_diameter (m), rho (kg/m): (P,)."""
        gap = d - mean_diameter
        rep, rep_slope = self.repulsion(gap)
        d_on, d_off = self.cutoff(mean_diameter)
        phi, dphi = smoothstep_off(d, d_on, d_off)
        absd = np.abs(ddot)
        powk = absd ** self.k4 if self.k4 != 0.0 else np.ones_like(absd)
        damp = self.k3 * ddot * powk / d
        if self.cut_repulsion:
            core = rep - damp
            f = rho * phi * core
            f_d = rho * (dphi * core + phi * (rep_slope + damp / d))
        else:
            f = rho * (rep - phi * damp)
            f_d = rho * (rep_slope - dphi * damp + phi * damp / d)
        f_dd = -rho * phi * self.k3 * (1.0 + self.k4) * powk / d
        return f, f_d, f_dd, gap


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

    def cutoff(self, mean_diameter):
        return 0.5 * (mean_diameter + self.tolerance), np.full_like(mean_diameter, self.tolerance)

    def repulsion(self, gap):
        """P(g) (m/s²) and P'(g) (1/s²): k1/g^k2 above the floor, linear below."""
        gap = np.asarray(gap, dtype=float)
        gf = self.gap_floor
        g = np.maximum(gap, gf)
        val = self.k1 * g ** (-self.k2)
        slope = -self.k2 * val / g
        below = gap < gf
        return np.where(below, val + slope * (gap - gf), val), slope

    def equilibrium_gap(self, pressure):
        """The gap g (m) at which P(g) equals ``pressure`` (m/s²), inverting k1/g^k2."""
        return (self.k1 / pressure) ** (1.0 / self.k2)


class BarrierLaw(_Law):
    """IPC's compact-support barrier (module doc): activation gap ĝ (m), stiffness κ (1/s²),
    damping k3, k4 as the seed's; gap_floor (m): below it P continues linearly."""

    name = "barrier"
    cut_repulsion = False

    def __init__(self, d_hat, stiffness, k3, k4, gap_floor):
        super().__init__(k3, k4)
        self.d_hat, self.kappa = float(d_hat), float(stiffness)
        self.gap_floor = float(gap_floor)

    def cutoff(self, mean_diameter):
        return mean_diameter + 0.5 * self.d_hat, mean_diameter + self.d_hat

    def _p(self, g):
        h = self.d_hat
        lg = np.log(g / h)
        val = self.kappa * (2.0 * (g - h) * lg + (g - h) ** 2 / g)
        slope = self.kappa * (2.0 * lg + 4.0 * (g - h) / g - ((g - h) / g) ** 2)
        return val, slope

    def repulsion(self, gap):
        gap = np.asarray(gap, dtype=float)
        gf = self.gap_floor
        inside = gap < self.d_hat
        g = np.clip(gap, gf, self.d_hat)
        val, slope = self._p(g)
        val = np.where(gap < gf, val + slope * (gap - gf), val)
        return np.where(inside, val, 0.0), np.where(inside, slope, 0.0)

    def equilibrium_gap(self, pressure):
        """The gap g (m) with P(g) = pressure (m/s²), by bisection on (0, ĝ)."""
        lo, hi = 1e-12 * self.d_hat, self.d_hat
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if self._p(np.array(mid))[0] > pressure:
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)
