"""Resistive-force theory: the Stokes drag per length of a slender rod in a viscous fluid.

At Reynolds numbers far below 1 (DNA in water moves at about 1e-8) the fluid's force on
a slender body is linear in its velocity and the fluid's inertia plays no part: each
element of the rod feels a drag per length against its own velocity relative to the
still fluid, with different coefficients along and across its axis (resistive-force
theory; Gray & Hancock, J. Exp. Biol. 32, 802, 1955; Lighthill, "Flagellar
hydrodynamics", SIAM Rev. 18, 161, 1976). With the body velocity v = Rᵀṙ split into
its axial part v_t = v·e3 and the rest v_n, and W3 the spin about the axis::

    f_viscous = −R (ζ_n v_n + ζ_t v_t e3)        N/m
    m_viscous = −R (ζ_r W3 e3) = −ζ_r W3 a3      N m/m

    ζ_n = 4πμ / (ln(ℓ/d) + 0.84)     ζ_t = 2πμ / (ln(ℓ/d) − 0.20)     ζ_r = πμd² = 4πμa²

μ the viscosity (Pa s), d = 2a the local diameter (m), ℓ the length of the slenderness
factor ln(ℓ/d) (m; the rod's length unless the case gives ``fluid.slenderness_length``).

Sources. The leading terms 4πμ/ln and 2πμ/ln (the normal coefficient twice the
tangential one) are slender-body theory's (Batchelor, J. Fluid Mech. 44, 419, 1970;
Cox, J. Fluid Mech. 44, 791, 1970); the O(1) constants beside the logarithm depend on the
body's shape and ends. The constants here are the end-effect corrections of a rigid
circular cylinder of length L and diameter d with flat ends in the limit of long
cylinders, ν = ln p + γ with p = L/d, γ_⊥ = 0.84 and γ_∥ = −0.20 (Tirado & García de la
Torre, J. Chem. Phys. 71, 2581, 1979, Table I, the row p⁻¹ = 0): the friction of the
whole cylinder is 4πμL/(ln p + 0.84) across and 2πμL/(ln p − 0.20) along its axis, so a
straight rod translating as a whole feels exactly that cylinder's drag. In terms of the
radius a, ln(ℓ/d) + 0.84 = ln(ℓ/a) + 0.15 and ln(ℓ/d) − 0.20 = ln(ℓ/a) − 0.89. A bent rod
has no exact local law: the coefficients of a flexible filament with a wave of length λ
are those with ℓ of the order of λ (Lighthill 1976 takes ln(0.18λ/a)), which is what
``fluid.slenderness_length`` sets.

The rotational coefficient is exact: the Stokes flow around a circular cylinder turning at
Ω about its axis is u_θ = Ωa²/r (circular Couette flow with the outer cylinder at
infinity), whose shear stress at the wall, μ r ∂(u_θ/r)/∂r = −2μΩ, gives the moment
2μΩ · 2πa · a = 4πμa²Ω per length.

Left out: the moment against rotation about a normal (W1, W2). For a section turning
about a normal it is O(μa²) per length, while a bend of wavelength λ turning the sections
moves them sideways and meets the translational drag's moment, O(μλ²/ln(λ/a)): the share
is (a/λ)² ln(λ/a), below the precision of the logarithmic coefficients themselves
(Lighthill 1976 and Cox 1970 keep only the O(1/ln) terms). The hydrodynamic interaction
between distant parts of the rod (slender-body theory's non-local terms) is left out too:
the drag is local.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["END_CORRECTION_NORMAL", "END_CORRECTION_TANGENTIAL", "SMALLEST_SLENDERNESS",
           "resistive_force_coefficients"]

#: γ_⊥ of Tirado & García de la Torre (1979), Table I at p⁻¹ = 0: ζ_n = 4πμ/(ln(ℓ/d) + γ_⊥)
END_CORRECTION_NORMAL = 0.84
#: γ_∥ of the same row: ζ_t = 2πμ/(ln(ℓ/d) + γ_∥)
END_CORRECTION_TANGENTIAL = -0.20
#: the smallest ℓ/d taken: Tirado & García de la Torre's Table I runs from p = 2 (p⁻¹ = 0.5)
#: up; below it the rod is no slender body, and ln(ℓ/d) − 0.20 turns negative at 1.22
SMALLEST_SLENDERNESS = 2.0


def resistive_force_coefficients(viscosity: float, diameter, slenderness_length: float):
    """The resistive-force theory's drag coefficients per length (module docstring).

    Parameters
    ----------
    viscosity : float
        The fluid's dynamic viscosity μ, Pa s; > 0.
    diameter : array_like, shape (N+1,)
        The rod's local diameter d at the nodes, m; > 0.
    slenderness_length : float
        ℓ of the slenderness factor ln(ℓ/d), m; ℓ/d >= :data:`SMALLEST_SLENDERNESS`.

    Returns
    -------
    (zeta_n, zeta_t, zeta_r) : three arrays of shape (N+1,)
        ζ_n = 4πμ/(ln(ℓ/d) + 0.84) and ζ_t = 2πμ/(ln(ℓ/d) − 0.20), N s/m² (force per
        length per velocity, across and along the axis; Tirado & García de la Torre,
        J. Chem. Phys. 71, 2581, 1979, Table I, p⁻¹ = 0), and ζ_r = πμd² = 4πμa², N s
        (moment per length per angular velocity about the axis; the exact Stokes flow
        u_θ = Ωa²/r).

    Raises
    ------
    ValueError
        For μ <= 0, a diameter <= 0, or ℓ/d below :data:`SMALLEST_SLENDERNESS` (the case
        refuses these first, naming ``fluid.viscosity`` or ``fluid.slenderness_length``).
    """
    mu = float(viscosity)
    d = np.asarray(diameter, float)
    ell = float(slenderness_length)
    if not (math.isfinite(mu) and mu > 0.0):
        raise ValueError(f"fluid.viscosity: {mu!r} Pa s is not > 0")
    if not np.all(d > 0.0):
        raise ValueError("rod.diameter: must be > 0 along the rod")
    slender = ell / d
    if not np.all(slender >= SMALLEST_SLENDERNESS):
        raise ValueError(f"fluid.slenderness_length: ℓ/d = {float(slender.min()):.6g} is below "
                         f"{SMALLEST_SLENDERNESS:g}: the rod is no slender body there")
    log = np.log(slender)
    zeta_n = 4.0 * math.pi * mu / (log + END_CORRECTION_NORMAL)
    zeta_t = 2.0 * math.pi * mu / (log + END_CORRECTION_TANGENTIAL)
    zeta_r = math.pi * mu * d * d
    return zeta_n, zeta_t, zeta_r
