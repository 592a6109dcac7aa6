"""Plausibility of a valid case: inputs that are allowed but look wrong by a unit.

A case that validates may still describe something no one means: a Young's modulus of
12.5 Pa (meant as 12.5 MPa), a density of 1.5 kg/m³ (g/cm³), a rod 1000 m long with a
diameter profile over its first metre (millimetres), a step of 10 s on a rod whose
slowest bending mode swings in 2 s. Such a case runs, to a "completed" that means
nothing, or to a bare "Newton did not converge". :func:`plausibility_warnings` names
each such input with its number, the reason and the range it was compared with; they
are warnings, not errors: the case runs as given (``hockle validate`` and ``hockle run``
print them, the REST service answers them with a submission, a result keeps them as
``hockle_input_warnings``). :func:`suspects` turns them into the sentence a failed run
adds to its message.

The ranges are those of materials and of the model, wide on purpose (a warning means
an input outside them by about an order of magnitude or more):

* Young's and shear modulus 1e3 Pa (soft gels) to 1e13 Pa (diamond's 1.2e12 Pa is the
  stiffest solid); G/E 0.01 to 10 (isotropic solids: 1/3 to 1/2);
* rod density 10 kg/m³ (the lightest foams) to 3e4 kg/m³ (osmium 2.26e4); a fluid
  density at most 3e4 kg/m³ (mercury 1.35e4);
* diameter at most 10 m; slenderness L/D from 10 (a Kirchhoff rod is slender) to 1e7;
* a profile, a load's ``s_range`` or a point load's ``s`` that spans less than a
  hundredth of a rod 100 times longer than it (the rod's length in mm, its stations in m);
  with ``contact``, segments longer than 10 diameters (the loops that contact holds
  apart are a few diameters across: the seed has 0.05, the seabed case 1.25);
* gravity above 100 m/s² (10 g; mm/s² gives 9810);
* a fixed ``numerics.dt`` (or ``dt_max``) above the period of the rod's lowest bending
  mode (:func:`lowest_bending_period`): not one bending motion is resolved; in a viscous
  fluid (``fluid.viscosity``) where that mode is overdamped, above its relaxation time
  instead (:func:`lowest_bending_relaxation_time`: the mode creeps, and steps far beyond
  the inertial times are what the overdamped limit is for);
* an end's axial compression above 100 times the largest Euler load 4π²EI/L² (both ends
  clamped), or a tension that strains the rod by more than 10 % (T/EA): the
  inextensible rod holds for strains of a few per cent.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["plausibility_warnings", "suspects", "lowest_bending_period",
           "lowest_bending_relaxation_time", "RANGES"]

#: (low, high) of each checked quantity, SI; None: not bounded on that side
RANGES = {
    "modulus": (1e3, 1e13),            # Pa
    "shear_to_young": (0.01, 10.0),
    "density": (10.0, 3e4),            # kg/m^3
    "fluid_density": (None, 3e4),      # kg/m^3
    "diameter": (None, 10.0),          # m
    "slenderness": (10.0, 1e7),
    "gravity": (None, 100.0),          # m/s^2
    "span_share": 0.01,                # a profile's span against the rod's length
    "contact_ds": 10.0,                # numerics.ds in diameters, with contact
    "compression": 100.0,              # times 4 pi^2 EI / L^2
    "strain": 0.1,                     # T / EA
}

#: unit slips to suggest: (factor the value is multiplied by, the unit it was given in)
_MODULUS_UNITS = ((1e6, "MPa"), (1e9, "GPa"), (1e3, "kPa"))
_DENSITY_UNITS = ((1e3, "g/cm³ or t/m³"),)


def _warn(loc: str, etype: str, msg: str) -> dict:
    return {"loc": loc, "msg": msg, "type": etype}


def _extremes(value: Any) -> tuple[float, float]:
    """(min, max) of a number or a profile's values."""
    values = getattr(value, "value", None)
    if values is None:
        return float(value), float(value)
    return float(min(values)), float(max(values))


def _unit_hint(value: float, units, lo: float, hi: float) -> str:
    """ "; given in MPa? 12.5 MPa is 1.25e+07 Pa" for the first unit that puts ``value``
    in [lo, hi], or ""."""
    for factor, unit in units:
        if lo <= value * factor <= hi:
            return f"; given in {unit}? {value:g} {unit} is {value * factor:.4g} in SI"
    return ""


def _material(rod) -> list[dict]:
    out = []
    lo, hi = RANGES["modulus"]
    for field, word in (("youngs_modulus", "Young's modulus"),
                        ("shear_modulus", "shear modulus")):
        small, large = _extremes(getattr(rod, field))
        if small < lo:
            out.append(_warn(f"rod.{field}", "implausible_modulus",
                             f"a {word} of {small:g} Pa is softer than any solid a rod is "
                             f"made of (soft gels about {lo:g} Pa, rubber 1e6, the seed's "
                             f"cable 1.25e7, steel 2e11); values are in Pa"
                             + _unit_hint(small, _MODULUS_UNITS, 1e5, 1e12)))
        elif large > hi:
            out.append(_warn(f"rod.{field}", "implausible_modulus",
                             f"a {word} of {large:g} Pa is stiffer than any material "
                             f"(diamond 1.2e12 Pa); values are in Pa"))
    e_lo, e_hi = _extremes(rod.youngs_modulus)
    g_lo, g_hi = _extremes(rod.shear_modulus)
    r_lo, r_hi = RANGES["shear_to_young"]
    ratio_lo, ratio_hi = g_lo / e_hi, g_hi / e_lo
    if ratio_hi < r_lo or ratio_lo > r_hi:
        ratio = ratio_hi if ratio_hi < r_lo else ratio_lo
        out.append(_warn("rod.shear_modulus", "implausible_moduli_ratio",
                         f"G/E = {ratio:.3g} (shear modulus over Young's modulus): isotropic "
                         f"solids have 1/3 to 1/2 (Poisson's ratio 0.5 to 0), a cable's "
                         f"effective moduli stay within {r_lo:g} to {r_hi:g}; are both "
                         f"in Pa?"))
    lo, hi = RANGES["density"]
    small, large = _extremes(rod.density)
    if small < lo:
        out.append(_warn("rod.density", "implausible_density",
                         f"a density of {small:g} kg/m³ is lighter than any solid a rod is "
                         f"made of (foams from about {lo:g} kg/m³, polymers 900-2000, "
                         f"steel 7850); values are in kg/m³"
                         + _unit_hint(small, _DENSITY_UNITS, 100.0, hi)))
    elif large > hi:
        out.append(_warn("rod.density", "implausible_density",
                         f"a density of {large:g} kg/m³ is denser than any material "
                         f"(osmium 22,590 kg/m³); values are in kg/m³"))
    return out


def _geometry(case) -> list[dict]:
    rod, out = case.rod, []
    length = float(rod.length)
    d_lo, d_hi = _extremes(rod.diameter)
    if d_hi > RANGES["diameter"][1]:
        out.append(_warn("rod.diameter", "implausible_diameter",
                         f"a diameter of {d_hi:g} m: a rod over {RANGES['diameter'][1]:g} m "
                         f"thick; lengths are in m (a diameter in mm? {d_hi:g} mm is "
                         f"{d_hi * 1e-3:g} m)"))
    slender = length / d_hi
    lo, hi = RANGES["slenderness"]
    if slender < lo:
        out.append(_warn("rod.length", "not_slender",
                         f"a rod {length:g} m long and {d_hi:g} m thick has L/D = "
                         f"{slender:.3g}: the rod model is for slender rods, L/D of "
                         f"{lo:g} and more (the seed example 50, the seabed case 200); "
                         "are both lengths in m?"))
    elif slender > hi:
        out.append(_warn("rod.length", "not_slender",
                         f"L/D = {slender:.3g} ({length:g} m over {d_lo:g} m): beyond "
                         f"{hi:g}, a rod that thin is a string to any grid; are both "
                         "lengths in m?"))
    share = RANGES["span_share"]
    spans = []
    for name in ("youngs_modulus", "shear_modulus", "density", "diameter"):
        prop = getattr(rod, name)
        if hasattr(prop, "s"):
            spans.append((f"rod.{name}.s", max(abs(v) for v in prop.s), "its profile's stations"))
    for k, force in enumerate(case.distributed_forces):
        if force.s_range is not None:
            spans.append((f"distributed_forces[{k}].s_range", max(force.s_range), "its s_range"))
    if case.point_loads:
        far = max(p.s for p in case.point_loads)
        spans.append(("point_loads", far, "the point loads' s"))
    for loc, reach, what in spans:
        if 0.0 < reach < share * length:
            out.append(_warn(loc, "length_units",
                             f"{what} reach s = {reach:g} m of a rod {length:g} m long "
                             f"({reach / length:.2g} of it): rod.length and the stations "
                             f"in different units (mm and m?)"))
    if case.contact is not None:
        ds = float(case.numerics.ds)
        if ds > RANGES["contact_ds"] * d_hi:
            out.append(_warn("numerics.ds", "coarse_for_contact",
                             f"segments of {ds:g} m are {ds / d_hi:.3g} diameters long, "
                             f"with self-contact: the loops it holds apart are a few "
                             f"diameters across, so segments of about a diameter (the "
                             f"seed 0.05, the seabed case 1.25; at most "
                             f"{RANGES['contact_ds']:g}) are needed; rod.length = "
                             f"{length:g} m in m?"))
    return out


def _surroundings(case) -> list[dict]:
    out = []
    if case.gravity is not None:
        g = float(np.linalg.norm(case.gravity))
        if g > RANGES["gravity"][1]:
            out.append(_warn("gravity", "implausible_gravity",
                             f"|gravity| = {g:g} m/s² is {g / 9.81:.3g} g: values are in "
                             f"m/s² (in mm/s²? {g:g} mm/s² is {g * 1e-3:g} m/s²)"))
    if case.fluid is not None and case.fluid.density > RANGES["fluid_density"][1]:
        rho = float(case.fluid.density)
        out.append(_warn("fluid.density", "implausible_density",
                         f"a fluid density of {rho:g} kg/m³ is denser than any liquid "
                         f"(mercury 13,534 kg/m³; water 1000); values are in kg/m³"))
    return out


def _bending(case) -> tuple[float, float, float]:
    """(EI, m, EA) of the rod's stiffest, lightest section: the bending stiffness (N m²),
    the mass per length with the added fluid mass (kg/m) and the axial stiffness (N)."""
    rod = case.rod
    s = np.linspace(0.0, float(rod.length), 201)
    d = rod.evaluate("diameter", s)
    e = rod.evaluate("youngs_modulus", s)
    rho = rod.evaluate("density", s)
    area = np.pi * d**2 / 4.0
    ei = e * np.pi * d**4 / 64.0
    added = 0.0 if case.fluid is None else case.fluid.added_mass_coefficient * case.fluid.density
    mass = (rho + added) * area
    return float(ei.max()), float(mass.min()), float((e * area).min())


def lowest_bending_period(case) -> float:
    """The period (s) of the rod's lowest bending mode, both ends pinned:
    2π / ((π/L)² √(EI/m)), with the stiffest EI and the lightest m (the added fluid mass
    included) of the rod's sections. The slowest motion of a bent rod: clamped ends make
    it 2.3 times faster, a free end 2.8 times slower, tension and twist change it; a
    fixed step above it resolves no bending motion at all."""
    ei, mass, _ = _bending(case)
    omega = (math.pi / float(case.rod.length)) ** 2 * math.sqrt(ei / mass)
    return 2.0 * math.pi / omega


def lowest_bending_relaxation_time(case) -> float | None:
    """With ``fluid.viscosity``, the time (s) in which the rod's lowest bending mode
    (both ends pinned, k = π/L) relaxes, ζ_n/(EI k⁴), where that mode is overdamped,
    ζ_n² > 4 m EI k⁴ (of m ẅ + ζ_n ẇ + EI k⁴ w = 0), with the stiffest EI,
    the lightest m and the smallest resistive-force coefficient ζ_n of the rod's sections
    (:mod:`solver.resistive_force`); None without viscosity or where the mode swings
    (then :func:`lowest_bending_period` is the slowest motion)."""
    fluid = case.fluid
    if fluid is None or fluid.viscosity is None:
        return None
    from .resistive_force import resistive_force_coefficients

    ei, mass, _ = _bending(case)
    rod = case.rod
    s = np.linspace(0.0, float(rod.length), 201)
    ell = float(rod.length if fluid.slenderness_length is None else fluid.slenderness_length)
    zeta_n = float(resistive_force_coefficients(fluid.viscosity, rod.evaluate("diameter", s),
                                                ell)[0].min())
    stiffness = ei * (math.pi / float(rod.length)) ** 4
    if zeta_n**2 <= 4.0 * mass * stiffness:
        return None
    return zeta_n / stiffness


def _steps(case) -> list[dict]:
    num = case.numerics
    if num.tolerance is not None:
        step, where = num.dt_max, "numerics.dt_max"
        if step is None:
            return []
    else:
        step, where = num.dt, "numerics.dt"
    relaxation = lowest_bending_relaxation_time(case)
    if relaxation is not None:
        # overdamped in the viscous fluid: the mode creeps, its inertial period is no scale
        if step > relaxation:
            return [_warn(where, "dt_unresolved",
                          f"a step of {step:g} s is {step / relaxation:.3g} times the "
                          f"relaxation time of the rod's lowest bending mode in the viscous "
                          f"fluid ({relaxation:.3g} s, pinned ends: ζ_n/(EI (π/L)⁴), "
                          f"overdamped): no bending motion is resolved; a tenth of it, "
                          f"{relaxation / 10:.2g} s, resolves that mode")]
        return []
    period = lowest_bending_period(case)
    if step > period:
        return [_warn(where, "dt_unresolved",
                      f"a step of {step:g} s is {step / period:.3g} times the period of the "
                      f"rod's lowest bending mode ({period:.3g} s, pinned ends: "
                      f"2π/((π/L)²√(EI/m)), m with the added fluid mass): no bending motion "
                      f"is resolved; a tenth of it, {period / 10:.2g} s, resolves that mode "
                      "(the seed example steps 0.1 s against its 1.8 s)")]
    return []


def _forces(case) -> list[dict]:
    ei, _, ea = _bending(case)
    length = float(case.rod.length)
    euler = 4.0 * math.pi**2 * ei / length**2
    out = []
    for end_name in ("start", "end"):
        end = getattr(case.boundary, end_name)
        for item, conditions in enumerate(end.translation):
            for k, cond in enumerate(conditions):
                if cond.kind != "force":
                    continue
                value = cond.value
                values = [float(v) for v in getattr(value, "value", [value])]
                loc = f"boundary.{end_name}.translation[{item}][{k}].force"
                axial = end.frame == "body" and item == 2
                if axial and -min(values) > RANGES["compression"] * euler:
                    p = -min(values)
                    out.append(_warn(loc, "above_buckling_load",
                                     f"a compression of {p:g} N is {p / euler:.3g} times the "
                                     f"rod's largest Euler load (4π²EI/L² = {euler:.3g} N, "
                                     "both ends clamped): it buckles at once; forces are in "
                                     "N (in kN or mN?)"))
                if end.frame == "body" and item != 2:
                    continue                    # a shear force: no strain to speak of
                big = max(values) if axial else max(abs(v) for v in values)
                if big > RANGES["strain"] * ea:
                    out.append(_warn(loc, "strains_rod",
                                     f"a force of {big:g} N strains the rod by "
                                     f"{big / ea:.2g} (T/EA, EA = {ea:.3g} N): the "
                                     "inextensible rod holds for strains of a few per cent; "
                                     "forces are in N (in mN or kN?)"))
    return out


def plausibility_warnings(case) -> list[dict]:
    """The inputs of a valid :class:`solver.case.Case` that look wrong by a unit or lie
    outside what the model is for: ``[{"loc", "msg", "type"}, ...]`` as validation errors
    are (``loc`` the field, ``msg`` its number, the reason and the range it was compared
    with), in the order rod, geometry, surroundings, steps, forces; ``[]`` for a plausible
    case (every case in ``cases/``). Types: ``implausible_modulus``,
    ``implausible_moduli_ratio``, ``implausible_density``, ``implausible_diameter``, ``not_slender``, ``length_units``,
    ``coarse_for_contact``, ``implausible_gravity``, ``dt_unresolved``,
    ``above_buckling_load``, ``strains_rod``. The ranges: the module docstring and
    :data:`RANGES`."""
    return (_material(case.rod) + _geometry(case) + _surroundings(case) + _steps(case)
            + _forces(case))


def suspects(case) -> str | None:
    """The sentence a failed run adds to its message: the inputs it suspects
    (:func:`plausibility_warnings`), or None where every input looks plausible."""
    found = plausibility_warnings(case)
    if not found:
        return None
    return ("inputs that look wrong and may be why: "
            + "; ".join(f"{w['loc']}: {w['msg']}" for w in found))
