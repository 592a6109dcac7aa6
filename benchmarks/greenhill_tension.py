"""Greenhill buckling threshold of a twisted, clamped, non-uniform rod under dead tension.

Used for the tension reading of the seed example (docs/seed-example.md, "The tension
reading"): which dead axial tension T at the sliding end puts the buckling threshold of
the case's rod at Lk = 4 turns of pure twist.

Model (linear stability of the straight twisted rod; Greenhill 1883, and e.g. Love,
*Treatise on the Mathematical Theory of Elasticity*, 4th ed., §272; the clamped
determinant below is the one of tests/test_greenhill.py). The straight rod along a3
carries the twisting moment M (constant along s: no distributed torque, so C(s) κ3(s) = M)
and the axial force T (> 0 tension). A small lateral deflection w = x + i y, with
bending moment m⊥ = i B w'' + M w' and lateral shear F, satisfies in the static limit
m⊥' + e3 × F − T e3 × w' = 0 and F' = 0, i.e.

    (B(s) w'')' − i M w'' − T w' = −F        (F a complex constant).

Clamped at s = 0, and at s = L held laterally and in rotation about a1, a2 while sliding
axially under T: w = w' = 0 at both ends. With the slope u = w' this is the second-order
problem

    −(B u')' + T u − F = −M (−i u'),   u(0) = u(L) = 0,   ∫₀ᴸ u ds = 0,

a Hermitian-definite pencil K u = M G u on {∫u = 0} (K = −(B·)' + T positive for T ≥ 0,
G = −i d/ds Hermitian), so the critical moments are real, come in ± pairs, and the
threshold is M_cr = 1/λ_max of G u = λ K u. We discretise it with second-order finite
differences (B at the mid-points, central first derivative, the constraint by a
null-space basis) and remove the O(h²) error by Richardson extrapolation.

For a uniform rod, u = e^{iks} gives k²(B k² − M k + T) = 0 and the clamped determinant

    2b [cos bL − cos aL] = (T L/B) sin bL,   a = M/2B,  b = √(M² − 4BT)/2B,

(at T = 0: tan(ML/2B) = ML/2B, M_cr L/B = 8.9868); :func:`uniform_mcr` solves it and
serves as the check of :func:`critical_moment`.

Before buckling the rod is straight and all of Lk is twist: Φ = M ∫₀ᴸ ds/C(s) is the end
rotation, Lk = Φ/2π (docs/topology.md).

Run ``python benchmarks/greenhill_tension.py`` for the table of docs/seed-example.md.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy.linalg import eigh, null_space
from scipy.optimize import brentq

ROOT = Path(__file__).resolve().parents[1]


def uniform_mcr(t: float) -> float:
    """m_cr = M_cr L/B of the uniform clamped-clamped rod for t = T L²/B ≥ 0 (smallest
    root of the determinant in the module docstring)."""
    if t == 0.0:
        return 2.0 * brentq(lambda x: math.tan(x) - x, 4.0, 4.6, xtol=1e-14)

    def det(m):
        a = m / 2
        b = np.sqrt(m * m - 4 * t) / 2
        return 2 * b * (np.cos(b) - np.cos(a)) - t * np.sin(b)

    m = np.linspace(2 * math.sqrt(t) + 1e-9, 2 * math.sqrt(t) + 40.0, 80001)
    f = det(m)
    i = np.nonzero(np.sign(f[1:]) != np.sign(f[:-1]))[0][0]
    return brentq(det, m[i], m[i + 1], xtol=1e-14)


def _mcr_fd(bending, length: float, tension: float, n: int) -> float:
    """M_cr (N m) of the n-interval finite-difference pencil; bending(s) -> B (N m²)."""
    h = length / n
    s_mid = (np.arange(n) + 0.5) * h
    bm = np.asarray(bending(s_mid), float)                     # B at the n mid-points
    m = n - 1                                                  # interior slope nodes
    main = (bm[:-1] + bm[1:]) / h**2 + tension
    K = np.diag(main) - np.diag(bm[1:-1] / h**2, 1) - np.diag(bm[1:-1] / h**2, -1)
    D = (np.eye(m, k=1) - np.eye(m, k=-1)) / (2 * h)           # skew: −iD is Hermitian
    G = -1j * D
    Q = null_space(np.ones((1, m)) * h)                        # ∫ u ds = 0 (trapezoid)
    Kq = Q.T @ K @ Q
    Gq = Q.T @ G @ Q
    lam = eigh(Gq, Kq, eigvals_only=True, subset_by_index=[m - 2, m - 2])[0]
    return 1.0 / lam


def critical_moment(bending, length: float, tension: float = 0.0, n: int = 400) -> float:
    """Critical twisting moment M_cr (N m) of the clamped-clamped rod with bending
    stiffness B(s) = bending(s) (N m², vectorised callable) under dead axial tension
    ``tension`` (N, ≥ 0), from the finite-difference pencil at n and 2n intervals with
    Richardson extrapolation (second order). Relative error ~1e-6 at n = 400 for the
    uniform rod (tests/test_greenhill_tension.py)."""
    m1 = _mcr_fd(bending, length, tension, n)
    m2 = _mcr_fd(bending, length, tension, 2 * n)
    return (4.0 * m2 - m1) / 3.0


def case_stiffness(case):
    """(B(s), C(s), L) of a solver.case.Case: B = E π D⁴/64, C = G π D⁴/32 with the case's
    piecewise-linear profiles (solver/properties.py, seed Table 2)."""
    rod = case.rod

    def B(s):
        d = np.asarray(rod.evaluate("diameter", s), float)
        return np.asarray(rod.evaluate("youngs_modulus", s), float) * np.pi * d**4 / 64

    def C(s):
        d = np.asarray(rod.evaluate("diameter", s), float)
        return np.asarray(rod.evaluate("shear_modulus", s), float) * np.pi * d**4 / 32

    return B, C, rod.length


def compliance(torsion, length: float, n: int = 20000) -> float:
    """∫₀ᴸ ds/C(s) (1/(N m²)) by the composite Simpson rule (n even)."""
    from scipy.integrate import simpson
    s = np.linspace(0.0, length, n + 1)
    return float(simpson(1.0 / np.asarray(torsion(s), float), x=s))


def critical_lk(case, tension: float, n: int = 400) -> float:
    """Lk (turns) of pure twist at the Greenhill threshold of the case's rod under T."""
    B, C, L = case_stiffness(case)
    return critical_moment(B, L, tension, n) * compliance(C, L) / (2 * math.pi)


def tension_for_lk(case, lk: float, n: int = 400, bracket=(0.0, 40.0)) -> float:
    """Dead tension T (N) at which the threshold of the case's rod is Lk = ``lk`` turns."""
    return brentq(lambda t: critical_lk(case, t, n) - lk, *bracket, xtol=1e-6)


def load_case(path):
    """A validated solver.case.Case from a YAML case file."""
    from solver.case import Case, parse_text
    return Case.model_validate(parse_text(Path(path).read_text(), "yaml"))


def main() -> None:
    case = load_case(ROOT / "cases/goyal-writhing.yaml")
    B, C, L = case_stiffness(case)
    b_end = float(B(np.array([0.0]))[0])
    print(f"B ends {b_end:.5f} N m^2, middle {float(B(np.array([0.5]))[0]):.5f}; "
          f"int ds/C = {compliance(C, L):.4f} 1/(N m^2)")
    for t in (0.0, 10.0, 100.0):
        uni = critical_moment(lambda s: np.full_like(s, b_end), L, t * b_end / L**2) * L / b_end
        print(f"uniform check t={t:5.1f}: FD {uni:.5f}  exact {uniform_mcr(t):.5f}")
    print("   T (N)   TL^2/B_end   M_cr (N m)   M_cr L/B_end   Lk_cr (turns)")
    for T in (0.0, 2.0, 4.0, 6.0, 8.0, 9.0, 10.0, 12.0):
        mc = critical_moment(B, L, T)
        print(f"{T:8.2f} {T * L**2 / b_end:12.2f} {mc:12.5f} {mc * L / b_end:13.4f} "
              f"{mc * compliance(C, L) / (2 * math.pi):14.4f}")
    for lk in (3.5, 4.0, 4.5):
        T = tension_for_lk(case, lk)
        print(f"Lk_cr = {lk}: T = {T:.4f} N (TL^2/B_end = {T * L**2 / b_end:.2f})")
    for n in (200, 400):
        print(f"n = {n}: T(Lk=4) = {tension_for_lk(case, 4.0, n):.5f} N")


if __name__ == "__main__":
    main()
