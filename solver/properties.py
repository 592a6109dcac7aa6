"""Cross-section and material properties on the grid (seed Table 2).

For a solid circular section of diameter D (m):

* area A = πD²/4 (m²);
* bending area moments J1 = J2 = A D²/16 = πD⁴/64 (m⁴), torsion J3 = A D²/8 = πD⁴/32;
* stiffness diag(EJ1, EJ2, GJ3) (N m²), the constitutive law of seed eq. (1), q = Bκ,
  about the intrinsic curvature κ⁰ (1/m, ``rod.intrinsic_curvature``) where one is
  given: q = B(κ − κ⁰);
* mass per length ρA (kg/m), mass moment of inertia per length I = ρ·diag(J1, J2, J3)
  (kg m);
* with a fluid (Morison, numerics-notes §2.3): added mass C_a ρ_f A on the normal
  (a1, a2) components of the acceleration, so the translational mass matrix per length
  is diag(ρA + C_a ρ_f A, ρA + C_a ρ_f A, ρA), constant in body axes.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Optional

import numpy as np

__all__ = ["RodProperties"]


@dataclass(frozen=True)
class RodProperties:
    """Properties at the N+1 grid nodes s_k = k·Δs.

    Arrays have shape (N+1,) unless noted. Units SI.
    """

    s: np.ndarray            # (N+1,) arclength, m
    ds: float                # m
    diameter: np.ndarray     # m
    area: np.ndarray         # m²
    stiffness: np.ndarray    # (N+1, 3) EJ1, EJ2, GJ3, N m²
    rho_a: np.ndarray        # kg/m
    inertia: np.ndarray      # (N+1, 3) ρJ1, ρJ2, ρJ3, kg m
    mass_t: np.ndarray       # (N+1, 3) translational mass incl. added mass, kg/m
    added_mass: np.ndarray   # (N+1,) C_a ρ_f A on the normal components, kg/m
    quad_weights: np.ndarray  # (N+1,) trapezoid weights for ∫ ds, m
    intrinsic_curvature: Optional[np.ndarray] = None  # (N+1, 3) κ⁰, 1/m; None: zero

    @classmethod
    def from_case(cls, case) -> "RodProperties":
        """Evaluate the case's (possibly non-uniform) rod on its grid.

        Raises ValueError if an evaluated property is not positive and finite (the case
        validation should already have refused such input).
        """
        rod = case.rod
        n = case.numerics.n_segments
        length = rod.length
        ds = length / n
        s = np.linspace(0.0, length, n + 1)
        d = np.asarray(rod.evaluate("diameter", s), float)
        e = np.asarray(rod.evaluate("youngs_modulus", s), float)
        g = np.asarray(rod.evaluate("shear_modulus", s), float)
        rho = np.asarray(rod.evaluate("density", s), float)
        for name, arr in (("rod.diameter", d), ("rod.youngs_modulus", e),
                          ("rod.shear_modulus", g), ("rod.density", rho)):
            if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
                raise ValueError(f"{name}: must be positive and finite along the rod")
        area = np.pi * d**2 / 4.0
        j1 = area * d**2 / 16.0
        j3 = area * d**2 / 8.0
        stiffness = np.stack([e * j1, e * j1, g * j3], axis=1)
        rho_a = rho * area
        inertia = np.stack([rho * j1, rho * j1, rho * j3], axis=1)
        if case.fluid is not None:
            added = case.fluid.added_mass_coefficient * case.fluid.density * area
        else:
            added = np.zeros_like(area)
        mass_t = np.stack([rho_a + added, rho_a + added, rho_a], axis=1)
        w = np.full(n + 1, ds)
        w[0] = w[-1] = 0.5 * ds
        kappa0 = None
        if getattr(rod, "intrinsic_curvature", None) is not None:
            kappa0 = np.ascontiguousarray(rod.evaluate_intrinsic_curvature(s), dtype=float)
        return cls(s=s, ds=ds, diameter=d, area=area, stiffness=stiffness, rho_a=rho_a,
                   inertia=inertia, mass_t=mass_t, added_mass=added, quad_weights=w,
                   intrinsic_curvature=kappa0)

    @cached_property
    def fastest_wave_period(self) -> float:
        """The period (s) of the fastest wave the grid carries: 2π/ω_max, ω_max the largest,
        over the nodes, of the bending frequency at wavelength 2Δs (wavenumber k = π/Δs),
        with the rotary inertia of a Rayleigh beam, ω² = EJ1 k⁴/(m + ρJ1 k²) (m the
        translational mass per length with added mass), and the torsional frequency
        ω = k·√(GJ3/ρJ3) of the wave equation GJ3 ∂²φ/∂s² = ρJ3 ∂²φ/∂t² (both: Graff,
        Wave Motion in Elastic Solids, 1975). What :meth:`solver.step_problem.ProblemAssembly.end_correction`
        floors its time constant with. Raises nothing (the properties are positive)."""
        k = np.pi / self.ds
        bending = np.sqrt(self.stiffness[:, 0] * k**4
                          / (self.mass_t[:, 0] + self.inertia[:, 0] * k**2))
        torsion = k * np.sqrt(self.stiffness[:, 2] / self.inertia[:, 2])
        return float(2.0 * np.pi / max(bending.max(), torsion.max()))
