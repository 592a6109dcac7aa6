"""A free DNA chain at 298 K on the centreline scheme with ``thermal``: its tangent
correlation, twist variance and bending modes' equipartition at steps over a decade,
against the worm-like chain's Boltzmann statistics and against the scheme's own
prediction for the modes (solver.thermal.stationary_variance_ratio). Prints figures;
docs/thermal.md § 4 quotes them.

    PYTHONPATH=. python3 benchmarks/thermal_chain.py [--steps 3000] [--dt 1e-10 3e-10 1e-9]
        [--rho-inf 0.5] [--seed 1] [--isotropic]

The chain: 100 nm of DNA in SI units (B = 50 nm kT, C = 100 nm kT, radius 1 nm, water
8.9e-4 Pa s), 40 segments (Δs = 2.5 nm), free ends, ρ∞ 0.5. It is brought near
equilibrium by 1000 steps of 10 ns (four relaxation times of its lowest free bending
mode, ζ_n L⁴/(4.73⁴ B) = 2.3 µs), then run ``--steps`` steps of each Δt, the first fifth
discarded. Statistics are averages over the chain and the steps; the standard error is
that of 8 consecutive blocks of the run (block means' spread / √8).

Figures:
- tangent correlation <a3(s)·a3(0)> at lags s = j Δs over exp(−s/ℓp), ℓp = B/kT;
- twist: the variance of the twist angle ∫ κ3 ds over a length ℓ (cell averages of the
  nodal κ3, the box rule's own rotation per cell) over ℓ kT/C;
- bending modes: the cell curvatures κ1, κ2 in the orthonormal cosine basis over the
  cells (DCT-II; in the Boltzmann distribution of the free chain each cell's curvature is
  independent, variance kT/(B Δs), so every mode has that variance), each mode's
  variance over kT/(B Δs), beside the scheme's cooling factor r(λ_j Δt) of
  :func:`solver.thermal.stationary_variance_ratio` with the box rule's relaxation rate
  λ_j = (B/ζ_n) ((2/Δs) tan(jπ/(2N)))⁴.
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np

from solver import statics as st
from solver.case import Case
from solver.centreline_run import CentrelineRun
from solver.stepping.control import SolverDivergence
from solver.thermal import BOLTZMANN, ThermalForcing, stationary_variance_ratio

T = 298.0
KT = BOLTZMANN * T
LP, LT = 50e-9, 100e-9          # persistence lengths of bend and twist, m
BLOCKS = 8


def chain_case(n=40, length=1e-7, dt=1e-9, rho_inf=0.5, seed=1) -> Case:
    d = 2e-9
    free = {"translation": [{"force": 0.0}] * 3, "rotation": [{"moment": 0.0}] * 3}
    return Case.model_validate({
        "schema_version": 1, "name": "thermal-chain",
        "rod": {"length": length, "youngs_modulus": LP * KT / (math.pi * d**4 / 64),
                "shear_modulus": LT * KT / (math.pi * d**4 / 32), "density": 1700.0,
                "diameter": d},
        "fluid": {"density": 1000.0, "viscosity": 8.9e-4, "drag_coefficient_normal": 0.0},
        "boundary": {"start": free, "end": free},
        "thermal": {"temperature": T, "seed": seed},
        "numerics": {"n_segments": n, "dt": dt, "t_end": 1e-3, "rho_inf": rho_inf,
                     "formulation": "centreline", "max_dt_cuts": 8}})


def _dct_basis(n: int) -> np.ndarray:
    """(n, n) the orthonormal DCT-II basis over n cells, row j the mode j."""
    i = np.arange(n)
    basis = np.cos(np.pi * np.outer(np.arange(n), i + 0.5) / n)
    basis[0] /= math.sqrt(2.0)
    return basis * math.sqrt(2.0 / n)


#: steps whose impulses were redrawn because every cut of them failed (a rejection)
REDRAWN = {"steps": 0}


def sample(run, dt, steps):
    """Run ``steps`` steps of dt (:meth:`solver.centreline_run.CentrelineRun.advance`,
    cut where Newton fails); per step the nodes' tangents (N+1, 3) and the cells'
    body-frame curvature (N, 3) 1/m."""
    tangents, curv = [], []
    rod = run.rod
    for _ in range(steps):
        for _ in range(5):
            try:
                run.advance(run.level.t + dt)
                break
            except SolverDivergence:
                # every cut failed: redraw the step's impulses (a rejection, counted)
                REDRAWN["steps"] += 1
                rod.thermal.begin(run.level.t, run.level.t + dt)
                run._cut_level = 0
        else:
            raise RuntimeError(f"five draws of the step at t = {run.level.t:.6g} s failed")
        state = run.level
        kappa = rod.body_fields(state)["kappa"]
        tangents.append(st._rot(state.Y[:, 3:7])[:, :, 2])
        curv.append(0.5 * (kappa[:-1] + kappa[1:]))
    return np.array(tangents), np.array(curv)


def _blocks(values):
    """(mean, standard error) over BLOCKS consecutive blocks of a (steps, ...) series's
    per-step figure."""
    parts = np.array_split(values, BLOCKS)
    means = np.array([p.mean(axis=0) for p in parts])
    return values.mean(axis=0), means.std(axis=0, ddof=1) / math.sqrt(BLOCKS)


def figures(rod, tangents, curv, dt):
    ds, n = rod.h, rod.n - 1
    out = {"tangent": [], "twist": [], "modes": []}
    for j in (1, 2, 4, 8, 20):
        c = np.mean(np.sum(tangents[:, :-j] * tangents[:, j:], axis=2), axis=1)
        m, se = _blocks(c)
        ref = math.exp(-j * ds / LP)
        out["tangent"].append((j * ds, m / ref, se / ref))
    for j in (1, 4, 10, 20):
        windows = np.array([curv[:, i:i + j, 2].sum(axis=1) * ds for i in range(0, n - j + 1)])
        var = np.mean(windows ** 2, axis=0)          # per step, averaged over windows
        m, se = _blocks(var)
        ref = j * ds * KT / (LT * KT)
        out["twist"].append((j * ds, m / ref, se / ref))
    basis = _dct_basis(n)
    zn = float(rod.stokes[0][1])
    bend = float(rod.props.stiffness[1, 0])
    for axis in (0, 1):
        amp = curv[:, :, axis] @ basis.T                 # (steps, n)
        m, se = _blocks(amp ** 2)
        ref = KT / (bend * ds)
        out["modes"].append((m / ref, se / ref))
    inertia = rod.inertial_time() / dt
    lam = (bend / zn) * ((2.0 / ds) * np.tan(np.arange(n) * np.pi / (2 * n))) ** 4
    out["predicted"] = np.array([stationary_variance_ratio(rod.params, x * dt, inertia)
                                 if x > 0 else 1.0 for x in lam])
    out["lam_h"] = lam * dt
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--dt", type=float, nargs="+", default=[1e-10, 3e-10, 1e-9])
    ap.add_argument("--rho-inf", type=float, default=0.5)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--isotropic", action="store_true",
                    help="the drag and noise with zeta_t = zeta_n: no dependence on a3")
    args = ap.parse_args(argv)
    run = CentrelineRun(chain_case(dt=min(args.dt), rho_inf=args.rho_inf, seed=args.seed))
    rod = run.rod
    if args.isotropic:
        zn, _, zr = rod.stokes
        rod.stokes = (zn, zn.copy(), zr)
        rod.thermal = ThermalForcing(T, args.seed, rod.stokes, rod.props.quad_weights)
    ds = rod.h
    zn, zr = float(rod.stokes[0][1]), float(rod.stokes[2][1])
    bend, twist = (float(x) for x in rod.props.stiffness[1, [0, 2]])
    explicit = min(zn * ds**4 / (8 * bend), zr * ds**2 / (2 * twist))
    drag = ", isotropic drag" if args.isotropic else ""
    print(f"free chain: L = 100 nm, N = {rod.n - 1}, ds = {ds * 1e9:.3g} nm, rho_inf "
          f"{args.rho_inf}, seed {args.seed}{drag}; explicit (forward Euler) limit "
          f"min(zeta_n ds^4/(8B), zeta_r ds^2/(2C)) = {explicit:.3g} s; inertial time "
          f"{rod.inertial_time():.3g} s")
    t0 = time.time()
    sample(run, 1e-8, 1000)
    print(f"burn-in: 1000 steps of 1e-8 s, {time.time() - t0:.0f} s of wall")
    for dt in args.dt:
        t0 = time.time()
        cuts, redrawn = sum(run.control.refusals.values()), REDRAWN["steps"]
        tangents, curv = sample(run, dt, args.steps)
        cuts = sum(run.control.refusals.values()) - cuts
        redrawn = REDRAWN["steps"] - redrawn
        keep = args.steps // 5
        f = figures(rod, tangents[keep:], curv[keep:], dt)
        print(f"\ndt = {dt:.3g} s = {dt / explicit:.3g} explicit limits, {args.steps} steps, "
              f"{time.time() - t0:.0f} s of wall, {cuts} attempts cut, {redrawn} "
              f"steps redrawn after all cuts failed")
        print("  tangent correlation / exp(-s/lp):  " + "  ".join(
            f"s={s * 1e9:.4g}nm {m:.4f}±{e:.4f}" for s, m, e in f["tangent"]))
        print("  twist variance / (l kT/C):         " + "  ".join(
            f"l={s * 1e9:.4g}nm {m:.4f}±{e:.4f}" for s, m, e in f["twist"]))
        print("  bending modes j: variance / (kT/(B ds)) [kappa1, kappa2], "
              "predicted r(lambda_j dt):")
        for j in (1, 2, 3, 5, 8, 12, 20, 30, 39):
            (m1, e1), (m2, e2) = ((m[j], e[j]) for m, e in f["modes"])
            print(f"    j={j:2d} lambda_j dt={f['lam_h'][j]:9.3g}  {m1:.4f}±{e1:.4f}  "
                  f"{m2:.4f}±{e2:.4f}  predicted {f['predicted'][j]:.4f}")


if __name__ == "__main__":
    main()
