"""Work-precision: error against wall time for three reference problems (issue 5).

Each problem is run over a grid of Δt, Δs (n_segments) and ρ∞ ∈ {0, 0.5, 1}; every run
records its wall time (median of 3 for runs under 1 s) and its error:

1. **vibration**: a clamped-clamped rod in vacuum (L = 1 m, D = 10 mm, the seed's material,
   the far end free to slide axially), struck by a uniform lateral load on 0 ≤ t < 0.6 s and
   left to vibrate to 3.9 s (about 2.7 periods). The deflection is projected on the exact
   first mode shape; a damped sinusoid fitted to that modal coordinate gives the discrete
   eigenvalue λ_h = −ζ_h + iω_h. Error: |λ_h − iω₁|/ω₁ (frequency error and numerical
   damping together) against the exact first eigenvalue of the continuum (the Rayleigh beam:
   Euler-Bernoulli with rotary inertia, which is what the Kirchhoff rod reduces to at small
   amplitude; βL = 4.7300 without rotary inertia is 3.8e-5 higher).
2. **greenhill**: the same rod twisted at s = 0 (sin² rate over 1 s) to a torque
   M = 1.1 M_cr, M_cr L/B = 8.9868 (Greenhill, zero end force), so that the straight rod is
   unstable, with a tiny lateral load during the ramp as perturbation. The lateral
   deflection w = x + iy is projected on the exact unstable mode and A e^{σt} + B e^{−σt}
   fitted while the deflection is below 1e-3 L. Error: |σ_h/σ − 1| against the exact growth
   rate σ of the continuum. σ² grows about linearly with M − M_cr, so an error δ in the
   discrete buckling moment shows up as ≈ 6δ in σ; the buckling moment implied by σ_h
   (the torque at which the exact σ equals σ_h, rescaled) is reported for the finest Δt.
3. **seed**: the seed example (``cases/goyal-writhing.yaml``) without contact, to 18 s
   (buckling near 17.3 s, first contact in the full case at 18.3 s). Error:
   max(|t_b − t_b,ref|/t_b,ref, |U_peak − U_peak,ref|/U_peak,ref) with t_b the buckling
   onset (bending energy reaches 1 % of the torsional energy, interpolated in log between
   outputs: the growth is exponential) and U_peak the torsional energy at its peak
   (parabola through the largest output and its neighbours), against a fine reference run
   (1000 segments, Δt = 3.125 ms) cached in ``benchmarks/results/``. Both numbers stay
   meaningful after the instability: t_b is when the twisted rod lets go, U_peak how much
   twist it holds when it does; the state after buckling depends on both, and a time
   history compared point by point would mostly measure the shift of the collapse in time.

Observed orders come from successive differences of the measured quantity along each sweep
(no reference needed, and the other direction's fixed error cancels); the cheapest setting
for a threshold is the run with the lowest wall time whose error *and the error of every
refinement of it that was run* (same ρ∞, Δt' ≤ Δt, n' ≥ n) are below the threshold, so a
lucky cancellation of a spatial and a temporal error of opposite signs does not count.

Run: ``python -m benchmarks.work_precision [--quick] [--recompute-reference]``; writes
``benchmarks/results/work_precision.json`` and the figures under
``docs/figures/benchmarks/``.
"""
from __future__ import annotations

import argparse
import functools
import hashlib
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import brentq, least_squares, minimize_scalar

from solver import Case, SolverDivergence, integrate

ROOT = Path(__file__).resolve().parents[1]
SEED = ROOT / "cases" / "goyal-writhing.yaml"
RESULTS = ROOT / "benchmarks" / "results" / "work_precision.json"
REFERENCE = ROOT / "benchmarks" / "results" / "work_precision_seed_reference.json"
FIGDIR = ROOT / "docs" / "figures" / "benchmarks"

# the seed's material (seed Table 1), a thin rod for problems 1 and 2 (L/D = 100)
E, G, RHO = 1.25e7, 5.0e6, 1500.0
L, D = 1.0, 0.01
AREA = np.pi * D**2 / 4
J = np.pi * D**4 / 64                      # second moment of area, m⁴
B = E * J                                  # bending stiffness EJ, N·m²
GJ3 = G * 2 * J                            # torsional stiffness GJ₃, N·m²
RHO_A, RHO_J = RHO * AREA, RHO * J         # mass and rotary inertia per length
T_C = L**2 * np.sqrt(RHO_A / B)            # bending time scale, s
RHO_INFS = (0.0, 0.5, 1.0)
THRESHOLDS = (1e-2, 1e-3)
REPEAT_BELOW_S = 1.0                       # runs shorter than this are timed 3 times

KIN = {"velocity": 0.0}
ROT0 = {"angular_velocity": 0.0}
CLAMPED = {"translation": [KIN, KIN, KIN], "rotation": [ROT0, ROT0, ROT0]}
# clamped laterally and in rotation, free to slide axially (f3 = 0): an inextensible
# straight rod held axially at both ends has an undetermined tension
SLIDING = {"translation": [KIN, KIN, {"force": 0.0}], "rotation": [ROT0, ROT0, ROT0]}


# --------------------------------------------------------------------------- oracle
def _boundary_matrix(s2: float, torque: float, rho_j: float = RHO_J):
    """Clamped-clamped boundary matrix of the linearised twisted rod.

    Lateral deflection w = x + iy of a straight rod under end torque M (zero axial force),
    in the form w ∝ e^{st}: B w'''' − iM w''' − ρJ s² w'' + ρA s² w = 0 (Greenhill's
    equation, numerics-notes §5 V1, with the Rayleigh rotary-inertia term; s² = −ω² for a
    vibration, s² = σ² for a growing mode). w = Σ c_j exp(λ_j s) with λ_j the four roots of
    Bλ⁴ − iMλ³ − ρJs²λ² + ρAs² = 0; w = w' = 0 at s = 0 and s = L. Columns are scaled to
    unit norm (exponentials of roots with Re λ > 0 are taken relative to s = L).

    Returns (matrix 4×4 complex, roots λ (4,), shifts (4,) in m, column scales (4,)).
    """
    lam = np.roots([B, -1j * torque, -rho_j * s2, 0.0, RHO_A * s2])
    shift = np.where(lam.real > 0, L, 0.0)
    ends = np.exp(lam[None, :] * (np.array([0.0, L])[:, None] - shift[None, :]))
    mat = np.vstack([ends[0], lam * ends[0], ends[1], lam * ends[1]])
    scale = np.linalg.norm(mat, axis=0)
    return mat / scale, lam, shift, scale


def _singularity(s2: float, torque: float, rho_j: float = RHO_J) -> float:
    """Smallest over largest singular value of the boundary matrix (0 at an eigenvalue)."""
    sv = np.linalg.svd(_boundary_matrix(s2, torque, rho_j)[0], compute_uv=False)
    return float(sv[-1] / sv[0])


def lateral_eigenvalue(torque: float, lo: float, hi: float, n: int = 1500,
                       rho_j: float = RHO_J) -> float:
    """The eigenvalue s² (1/s²) of the clamped-clamped twisted rod in [lo, hi].

    Scans the singularity measure on n points and refines its minimum (bounded Brent);
    [lo, hi] must hold exactly one eigenvalue and exclude s² = 0 (a double root there
    makes the matrix singular for any M). rho_j: rotary inertia per length (kg·m); 0
    gives the Euler-Bernoulli beam. Checked in tests/benchmarks/test_work_precision.py: M = 0 and
    rho_j = 0 give βL = 4.7300; σ² → 0 at M L/B = 8.9868 (tan x = x, x = ML/2B).
    """
    xs = np.linspace(lo, hi, n)
    vals = np.array([_singularity(x, torque, rho_j) for x in xs])
    k = int(np.clip(np.argmin(vals), 1, n - 2))
    res = minimize_scalar(lambda x: _singularity(x, torque, rho_j),
                          bounds=(xs[k - 1], xs[k + 1]),
                          method="bounded",
                          options={"xatol": 1e-13 * max(abs(xs[k]), 1e-30)})
    if res.fun > 1e-8:
        raise RuntimeError(f"no eigenvalue found in [{lo}, {hi}] (min {res.fun:.2e})")
    return float(res.x)


def lateral_mode(s2: float, torque: float):
    """Mode shape φ(s) (complex, arbitrary normalisation) of the eigenvalue s², as a
    function of arclength s (m, array) returning an array of the same shape."""
    mat, lam, shift, scale = _boundary_matrix(s2, torque)
    coef = np.linalg.svd(mat)[2][-1].conj() / scale

    def phi(s):
        s = np.asarray(s, dtype=float)
        return np.exp(lam[None, :] * (s[:, None] - shift[None, :])) @ coef
    return phi


def critical_moment() -> float:
    """M_cr L/B of the clamped rod with zero end force: 2x with tan x = x (Greenhill)."""
    return 2.0 * brentq(lambda x: np.tan(x) - x, 4.0, 4.6, xtol=1e-14)


def _trapezoid_weights(s: np.ndarray) -> np.ndarray:
    w = np.full(s.size, s[1] - s[0])
    w[0] = w[-1] = 0.5 * (s[1] - s[0])
    return w


def _project(w: np.ndarray, s: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Modal coordinate a(t) = ∫ conj(φ) w ds / ∫ |φ|² ds (trapezoid); w (n_t, n_s)."""
    q = _trapezoid_weights(s)
    return (w * np.conj(phi) * q).sum(axis=1) / np.dot(np.abs(phi) ** 2, q)


# --------------------------------------------------------------------------- timing
@functools.cache
def _warm() -> None:
    """Load the solver's compiled kernels once per process before the first timed run
    (about 1 s, which would otherwise land on whichever run comes first)."""
    from solver import warm_up

    warm_up()


def timed_simulate(spec: dict, repeats: int) -> tuple[object, float, list[float], str]:
    """Run a case spec; returns (dataset or None, median wall s, walls, status).

    Runs shorter than REPEAT_BELOW_S are repeated up to ``repeats`` times (median).
    A run that raises SolverDivergence is reported with status "failed: <reason>".
    """
    case = Case.model_validate(spec)
    _warm()
    walls = []
    ds = None
    status = "completed"
    while True:
        t0 = time.perf_counter()
        try:
            ds = integrate(case)
        except SolverDivergence as exc:
            walls.append(time.perf_counter() - t0)
            return exc.partial, walls[-1], walls, f"failed: {exc.reason} at t = {exc.t:.3g} s"
        walls.append(time.perf_counter() - t0)
        if len(walls) >= repeats or walls[0] >= REPEAT_BELOW_S:
            break
    return ds, statistics.median(walls), walls, status


def _base_spec(name: str, n: int, dt: float, t_end: float, rho_inf: float) -> dict:
    return {"schema_version": 1, "name": name,
            "rod": {"length": L, "youngs_modulus": E, "shear_modulus": G, "density": RHO,
                    "diameter": D},
            "numerics": {"n_segments": n, "dt": dt, "t_end": t_end, "rho_inf": rho_inf,
                         "newton": {"tolerance": 1e-12, "max_iterations": 30}},
            "output": {"every": 1, "fields": ["position"]}}


def grid_plan(ns: list[int], dts: list[float]):
    """Every (n, Δt) for every ρ∞; sweeps: Δt at the finest n, Δs at the finest Δt."""
    runs = [(n, dt, rho) for rho in RHO_INFS for n in ns for dt in dts]
    sweeps = []
    for rho in RHO_INFS:
        sweeps.append({"rho_inf": rho, "direction": "dt", "n_segments": max(ns)})
        sweeps.append({"rho_inf": rho, "direction": "ds", "dt": min(dts)})
    return runs, sweeps


# --------------------------------------------------------------------------- problem 1
VIB_LOAD, VIB_LOAD_END, VIB_T_END = 3e-4, 0.6, 3.9      # N/m, s, s


class Vibration:
    """Problem 1: first bending eigenvalue of the clamped-clamped rod in vacuum."""

    name = "vibration"
    title = "Small-amplitude vibration: first bending eigenvalue (analytic)"

    def __init__(self):
        self.s2 = lateral_eigenvalue(0.0, -520.0 / T_C**2, -480.0 / T_C**2)
        self.omega = float(np.sqrt(-self.s2))                  # rad/s, Rayleigh beam
        self.omega_eb = 4.730040744862704**2 * np.sqrt(B / RHO_A) / L**2
        self.phi = lateral_mode(self.s2, 0.0)

    def plan(self, quick: bool):
        if quick:
            return grid_plan([16, 32, 64], [0.1, 0.05, 0.025])
        return grid_plan([16, 32, 64, 128, 256], [0.2, 0.1, 0.05, 0.025, 0.0125, 0.00625])

    def spec(self, n: int, dt: float, rho_inf: float) -> dict:
        spec = _base_spec("wp-vibration", n, dt, VIB_T_END, rho_inf)
        spec["boundary"] = {"start": CLAMPED, "end": SLIDING}
        spec["distributed_forces"] = [{"value": [VIB_LOAD, 0.0, 0.0], "start": 0.0,
                                       "end": VIB_LOAD_END}]
        return spec

    def measure(self, ds) -> dict:
        """Fit a(t) ≈ e^{−ζt}(c₁ cos ωt + c₂ sin ωt) to the modal coordinate after the
        load; returns ω_h, ζ_h (1/s) and the rms misfit relative to the amplitude."""
        s, t = ds.s.values, ds.time.values
        a = _project(ds.position.values[:, :, 0], s, self.phi(s)).real
        m = t > VIB_LOAD_END + 1e-9
        tt, aa = t[m] - VIB_LOAD_END, a[m]
        amp = float(np.abs(aa).max())

        def res(p):
            return np.exp(-p[3] * tt) * (p[0] * np.cos(p[2] * tt) + p[1] * np.sin(p[2] * tt)) - aa

        p = least_squares(res, [aa[0], 0.0, self.omega, 0.0],
                          x_scale=[amp, amp, self.omega, 0.1 * self.omega],
                          xtol=1e-15, ftol=1e-15, gtol=1e-15).x
        return {"omega": float(p[2]), "zeta": float(p[3]),
                "misfit": float(np.sqrt(np.mean(res(p) ** 2)) / amp)}

    def value(self, obs: dict) -> complex:
        """The measured quantity whose convergence is studied: λ_h / ω (complex)."""
        return complex(-obs["zeta"], obs["omega"]) / self.omega

    def error(self, obs: dict) -> float:
        return abs(self.value(obs) - 1j)

    def oracle(self) -> dict:
        return {"omega_rad_s": self.omega, "omega_euler_bernoulli_rad_s": self.omega_eb,
                "rayleigh_over_euler_bernoulli_minus_1": self.omega / self.omega_eb - 1}


# --------------------------------------------------------------------------- problem 2
GH_FACTOR, GH_RAMP, GH_T_END = 1.1, 1.0, 4.5
GH_PUSH, GH_PUSH_RANGE = 1e-6, (0.2, 0.45)          # N/m during the ramp, on s in range
GH_FIT_START, GH_AMAX = GH_RAMP + 0.2, 1e-3         # s; lateral deflection limit / L


class Greenhill:
    """Problem 2: growth rate of the twisted rod just past Greenhill buckling."""

    name = "greenhill"
    title = "Twisted rod past Greenhill buckling: growth rate at 1.1 M_cr (analytic)"

    def __init__(self):
        self.mcr = critical_moment()                         # M_cr L / B
        self.torque = GH_FACTOR * self.mcr * B / L           # N·m
        self.s2 = lateral_eigenvalue(self.torque, 100.0 / T_C**2, 250.0 / T_C**2)
        self.sigma = float(np.sqrt(self.s2))                 # 1/s
        # the mode for either sense of the torque (a helix of either hand); the one
        # that grows is used
        self.modes = [lateral_mode(self.s2, self.torque), lateral_mode(self.s2, -self.torque)]
        self._sigma_of_factor = None

    def plan(self, quick: bool):
        if quick:
            return grid_plan([25, 50, 100], [0.1, 0.05, 0.025])
        return grid_plan([50, 100, 200, 400, 800], [0.1, 0.05, 0.025, 0.0125, 0.00625])

    def spec(self, n: int, dt: float, rho_inf: float) -> dict:
        phi_end = self.torque * L / GJ3                       # end rotation, rad
        tt = np.linspace(0.0, GH_RAMP, 401)
        rate = (phi_end / GH_RAMP) * (1 - np.cos(2 * np.pi * tt / GH_RAMP))
        spec = _base_spec("wp-greenhill", n, dt, GH_T_END, rho_inf)
        start = {"translation": [KIN, KIN, KIN],
                 "rotation": [ROT0, ROT0, {"angular_velocity": {"t": tt.tolist(),
                                                                "value": rate.tolist()}}]}
        spec["boundary"] = {"start": start, "end": SLIDING}
        spec["distributed_forces"] = [{"value": [GH_PUSH, 0.0, 0.0], "start": 0.0,
                                       "end": GH_RAMP, "s_range": list(GH_PUSH_RANGE)}]
        return spec

    def measure(self, ds) -> dict:
        """Fit a(t) ≈ A e^{σt} + B e^{−σt} (A, B complex) to the modal coordinate of the
        unstable mode on t ≥ 1.2 s while max |w| < 1e-3 L; returns σ_h (1/s), misfit."""
        s, t = ds.s.values, ds.time.values
        pos = ds.position.values
        w = pos[:, :, 0] + 1j * pos[:, :, 1]
        lateral = np.abs(w).max(axis=1)
        m = t >= GH_FIT_START
        over = np.flatnonzero(lateral >= GH_AMAX * L)
        if over.size:
            m &= t < t[over[0]]
        tt = t[m] - GH_FIT_START
        best = None
        for phi in self.modes:
            a = _project(w, s, phi(s))[m]

            def cost(sig, a=a):
                X = np.stack([np.exp(sig * tt), np.exp(-sig * tt)], axis=1)
                coef = np.linalg.lstsq(X, a, rcond=None)[0]
                return float(np.sum(np.abs(X @ coef - a) ** 2) / np.sum(np.abs(a) ** 2))

            r = minimize_scalar(cost, bounds=(0.5 * self.sigma, 1.6 * self.sigma),
                                method="bounded", options={"xatol": 1e-12 * self.sigma})
            if best is None or abs(a[-1]) > best[2]:
                best = (float(r.x), float(np.sqrt(r.fun)), abs(a[-1]))
        return {"sigma": best[0], "misfit": best[1], "fit_points": int(m.sum()),
                "fit_end_s": float(t[m][-1])}

    def value(self, obs: dict) -> float:
        return obs["sigma"] / self.sigma

    def error(self, obs: dict) -> float:
        return abs(self.value(obs) - 1)

    def implied_mcr(self, sigma_h: float) -> float:
        """Buckling moment M_cr L/B implied by a measured growth rate: the factor f with
        exact σ(f M_cr) = σ_h gives M_cr,h = (1.1/f) M_cr (the discrete rod behaves as the
        continuum with a shifted M_cr; valid where the Δt error is small)."""
        if self._sigma_of_factor is None:
            fs = np.linspace(1.02, 1.25, 24)
            sig2 = []
            for f in fs:
                # σ² grows about linearly with f − 1: bracket around that guess
                guess = self.s2 * (f - 1) / (GH_FACTOR - 1)
                sig2.append(lateral_eigenvalue(f * self.mcr * B / L, 0.6 * guess, 1.6 * guess,
                                               n=300))
            self._sigma_of_factor = (fs, np.sqrt(sig2))
        fs, sig = self._sigma_of_factor
        if not sig[0] <= sigma_h <= sig[-1]:
            return float("nan")
        from scipy.interpolate import CubicSpline

        f = brentq(lambda x: CubicSpline(fs, sig)(x) - sigma_h, fs[0], fs[-1], xtol=1e-14)
        return float(GH_FACTOR / f * self.mcr)

    def oracle(self) -> dict:
        return {"mcr_L_over_B": self.mcr, "torque_factor": GH_FACTOR,
                "sigma_1_s": self.sigma}


# --------------------------------------------------------------------------- problem 3
SEED_T_END = 18.0
SEED_REF = {"n_segments": 1000, "dt": 0.003125, "rho_inf": 0.5}
# runs that estimate the reference's own error: twice its Δt; twice its Δt and n
SEED_REF_CHECK_DT = {"n_segments": 1000, "dt": 0.00625, "rho_inf": 0.5}
SEED_REF_CHECK_DS = {"n_segments": 2000, "dt": 0.00625, "rho_inf": 0.5}
# stand-in when quick mode finds no cached reference (not written to the cache)
SEED_QUICK_REF = {"n_segments": 500, "dt": 0.0125, "rho_inf": 0.5}


def seed_spec(n: int, dt: float, rho_inf: float, t_end: float = SEED_T_END) -> dict:
    """The seed example without contact (it is contact-free before 18.3 s), energies
    only, at the given resolution."""
    spec = Case.from_file(SEED).model_dump(mode="json")
    spec.pop("contact")
    spec["numerics"].pop("ds")
    spec["numerics"].update(n_segments=n, dt=dt, t_end=t_end, rho_inf=rho_inf)
    spec["output"].update(fields=["energies"], every=1)
    return spec


def seed_observables(ds) -> dict:
    """Buckling onset t_b (s), torsional-energy peak U_peak (J) and its time (s).

    t_b: first time after 5 s (before, the twist is still being put in and the ratio means
    nothing) that U_bending/U_torsion reaches 1 % (the event of benchmarks/seed_events.py),
    interpolated linearly in log(U_b/U_t) between the two outputs around it (the bending
    energy grows exponentially there). U_peak: vertex of the parabola through the largest
    output value of U_torsion and its two neighbours (the peak is smooth; the plain maximum
    would carry a sampling error of order Δt·dU/dt).
    """
    t = ds.time.values
    ub, ut = ds.energy_bending.values, ds.energy_torsion.values
    out = {"t_b": float("nan"), "U_peak": float("nan"), "t_peak": float("nan")}
    m = (t > 5.0) & (ut > 0)
    tm, r = t[m], np.log(np.maximum(ub[m], 1e-300) / ut[m])
    k = np.flatnonzero(r >= np.log(0.01))
    if k.size and k[0] > 0:
        k = k[0]
        out["t_b"] = float(tm[k - 1] + (np.log(0.01) - r[k - 1]) / (r[k] - r[k - 1])
                           * (tm[k] - tm[k - 1]))
    i = int(np.argmax(ut))
    if 0 < i < t.size - 1:
        (t0, t1, t2), (u0, u1, u2) = t[i - 1:i + 2], ut[i - 1:i + 2]
        c = np.polyfit([t0 - t1, 0.0, t2 - t1], [u0, u1, u2], 2)
        tv = float(np.clip(-c[1] / (2 * c[0]), t0 - t1, t2 - t1)) if c[0] < 0 else 0.0
        out["U_peak"] = float(np.polyval(c, tv))
        out["t_peak"] = float(t1 + tv)
    else:
        out["U_peak"], out["t_peak"] = float(ut[i]), float(t[i])
    return out


def _seed_hash() -> str:
    return hashlib.sha256(json.dumps(seed_spec(1, 1.0, 0.5), sort_keys=True)
                          .encode()).hexdigest()[:16]


def _seed_reference_run(res: dict, history: bool = False) -> dict:
    print(f"  seed reference: {res['n_segments']} segments, Δt = {res['dt']} s ...", flush=True)
    ds, wall, _, status = timed_simulate(seed_spec(res["n_segments"], res["dt"],
                                                   res["rho_inf"]), repeats=1)
    if status != "completed":
        raise RuntimeError(f"seed reference run {status}")
    out = dict(res, wall_s=wall, **seed_observables(ds))
    if history:
        stride = max(1, int(round(0.05 / res["dt"])))
        out["history"] = {"time": ds.time.values[::stride].round(6).tolist(),
                          "energy_torsion": ds.energy_torsion.values[::stride].tolist(),
                          "energy_bending": ds.energy_bending.values[::stride].tolist()}
    return out


def seed_reference(recompute: bool = False, quick: bool = False) -> dict:
    """Observables of the fine reference run of problem 3.

    Cached in REFERENCE (with the energy histories every 0.05 s); recomputed when asked,
    when missing, or when the seed case changed. Its own error is estimated by
    Richardson (order 2) from two more runs: temporal |v(Δt) − v(2Δt)|/3 and spatial
    (4/3)|v(n, 2Δt) − v(2n, 2Δt)|, summed. In quick mode without a cache a cheap stand-in
    (500 segments, Δt = 0.0125 s) is used and not stored.
    """
    if REFERENCE.exists() and not recompute:
        ref = json.loads(REFERENCE.read_text())
        if ref.get("seed_hash") == _seed_hash():
            return ref
    if quick and not recompute:
        ref = _seed_reference_run(SEED_QUICK_REF)
        return {**ref, "stand_in": True,
                "estimated_error": {"t_b": float("nan"), "U_peak": float("nan")}}
    ref = _seed_reference_run(SEED_REF, history=True)
    check_dt = _seed_reference_run(SEED_REF_CHECK_DT)
    check_ds = _seed_reference_run(SEED_REF_CHECK_DS)
    est = {k: abs(ref[k] - check_dt[k]) / 3 + 4 / 3 * abs(check_dt[k] - check_ds[k])
           for k in ("t_b", "U_peak")}
    ref = {"seed_hash": _seed_hash(), "t_end": SEED_T_END, **ref,
           "check_dt": check_dt, "check_ds": check_ds, "estimated_error": est}
    REFERENCE.parent.mkdir(parents=True, exist_ok=True)
    REFERENCE.write_text(json.dumps(ref, indent=1))
    return ref


class Seed:
    """Problem 3: the seed example up to first contact, against a fine reference."""

    name = "seed"
    title = "Seed example to 18 s (buckling, before contact) against a fine reference"

    def __init__(self, recompute: bool = False, quick: bool = False):
        self.ref = seed_reference(recompute, quick)

    def plan(self, quick: bool):
        """A Δt sweep at n_sweep segments for each ρ∞; for ρ∞ = 0.5 (the seed's) also
        coarser and finer grids at every Δt but the finest (the seed's 1000 segments down
        to Δt = 0.025 s) and a Δs sweep at Δt = 0.025 s."""
        if quick:
            n_sweep, dts, ns, dt_s = 250, [0.4, 0.2, 0.1], [125, 250, 500], 0.1
            extra = []
        else:
            n_sweep, dts = 500, [0.4, 0.2, 0.1, 0.05, 0.025, 0.0125, 0.00625]
            ns, dt_s = [125, 250, 500, 1000], 0.025
            extra = [(n, dt, 0.5) for n in (125, 250) for dt in dts[:-1]]
            extra += [(1000, dt, 0.5) for dt in dts if dt >= dt_s]
        runs = {(n_sweep, dt, rho) for rho in RHO_INFS for dt in dts}
        runs |= {(n, dt_s, 0.5) for n in ns} | set(extra)
        sweeps = [{"rho_inf": rho, "direction": "dt", "n_segments": n_sweep}
                  for rho in RHO_INFS]
        sweeps.append({"rho_inf": 0.5, "direction": "ds", "dt": dt_s})
        return sorted(runs, key=lambda r: (r[2], r[0], -r[1])), sweeps

    def spec(self, n: int, dt: float, rho_inf: float) -> dict:
        return seed_spec(n, dt, rho_inf)

    @staticmethod
    def history(ds) -> dict:
        """Bending energy history (J), at most every 0.05 s, for the history figure."""
        t = ds.time.values
        stride = max(1, int(round(0.05 / float(t[1] - t[0]))))
        return {"time": t[::stride], "energy_bending": ds.energy_bending.values[::stride]}

    def measure(self, ds) -> dict:
        return seed_observables(ds)

    def error(self, obs: dict) -> float:
        return max(abs(obs["t_b"] / self.ref["t_b"] - 1),
                   abs(obs["U_peak"] / self.ref["U_peak"] - 1))

    def oracle(self) -> dict:
        return {k: self.ref[k] for k in ("n_segments", "dt", "rho_inf", "t_b", "U_peak",
                                         "t_peak", "wall_s", "estimated_error", "stand_in",
                                         "history") if k in self.ref}


# --------------------------------------------------------------------------- analysis
def observed_order(h: list[float], values: list, n_fit: int = 3) -> dict:
    """Observed order from successive differences along a sweep.

    h: step sizes (Δt in s or Δs in m), coarse to fine, each half the previous;
    values: the measured quantity at each (real or complex). d_k = |v_k − v_{k+1}| ∝ h_k^p
    in the asymptotic range, so p is the slope of log d against log h, fitted over the
    finest n_fit differences; local orders log2(d_k/d_{k+1}) are returned too.
    """
    v = np.asarray(values)
    ok = np.isfinite(v)
    h = np.asarray(h, dtype=float)[ok]
    v = v[ok]
    d = np.abs(np.diff(v))
    hd = h[:-1]
    local = [float(np.log2(d[k] / d[k + 1])) if d[k + 1] > 0 else float("nan")
             for k in range(d.size - 1)]
    use = slice(max(0, d.size - n_fit), d.size)
    p = float(np.polyfit(np.log(hd[use]), np.log(d[use]), 1)[0]) if d[use].size >= 2 \
        else float("nan")
    return {"order": p, "local_orders": local, "h": hd.tolist(), "differences": d.tolist()}


def cheapest(runs: list[dict], threshold: float, rho_inf: float | None = None):
    """Cheapest run (lowest wall time) whose error and the errors of all its refinements
    that were run (same ρ∞, Δt' ≤ Δt, n' ≥ n) are below the threshold; None if none."""
    pool = [r for r in runs if np.isfinite(r["error"])
            and (rho_inf is None or r["rho_inf"] == rho_inf)]
    good = []
    for r in pool:
        finer = [q for q in pool if q["rho_inf"] == r["rho_inf"] and q["dt"] <= r["dt"]
                 and q["n_segments"] >= r["n_segments"]]
        if all(q["error"] < threshold for q in finer):
            good.append(r)
    return min(good, key=lambda r: r["wall_s"]) if good else None


def run_problem(prob, runs_wanted, repeats: int) -> list[dict]:
    out = []
    for n, dt, rho in runs_wanted:
        spec = prob.spec(n, dt, rho)
        ds, wall, walls, status = timed_simulate(spec, repeats)
        row = {"n_segments": n, "ds": spec["rod"]["length"] / n, "dt": dt,
               "rho_inf": rho, "wall_s": wall, "walls_s": walls, "status": status,
               "steps": int(ds.sizes["step"]),
               "newton_per_step": float(ds.step_newton_iterations.sum()) / ds.sizes["step"]}
        if status == "completed":
            obs = prob.measure(ds)
            row.update(obs)
            row["error"] = prob.error(obs)
            if hasattr(prob, "history"):
                row["_history"] = prob.history(ds)      # for a figure, not stored
        else:
            row["error"] = float("nan")
        out.append(row)
        print(f"  {prob.name:9s} rho_inf={rho:3.1f} n={n:5d} dt={dt:<8g} wall={wall:7.3f} s "
              f"error={row['error']:.3e} {'' if status == 'completed' else status}",
              flush=True)
    return out


def sweep_line(runs: list[dict], sweep: dict) -> list[dict]:
    """The completed runs of one sweep, coarse to fine."""
    rr = [r for r in runs if r["rho_inf"] == sweep["rho_inf"] and np.isfinite(r["error"])]
    if sweep["direction"] == "dt":
        return sorted([r for r in rr if r["n_segments"] == sweep["n_segments"]],
                      key=lambda r: -r["dt"])
    return sorted([r for r in rr if r["dt"] == sweep["dt"]], key=lambda r: r["n_segments"])


def sweep_label(sweep: dict) -> str:
    if sweep["direction"] == "dt":
        return f"Δt sweep, n = {sweep['n_segments']}"
    return f"Δs sweep, Δt = {sweep['dt']:g} s"


def analyse(runs: list[dict], sweeps: list[dict], quantities) -> dict:
    """Observed orders along each sweep (at least 3 levels) of each named quantity, and
    the cheapest settings per threshold, per ρ∞ and over all ρ∞."""
    orders = []
    for sw in sweeps:
        line = sweep_line(runs, sw)
        if len(line) < 3:
            continue
        h = [r["dt"] if sw["direction"] == "dt" else r["ds"] for r in line]
        for qname, fn in quantities:
            o = observed_order(h, [fn(r) for r in line])
            orders.append({**sw, "label": sweep_label(sw), "quantity": qname, **o,
                           "errors": [r["error"] for r in line]})
    best = {}
    for thr in THRESHOLDS:
        best[str(thr)] = {"any": _brief(cheapest(runs, thr))}
        for rho in RHO_INFS:
            best[str(thr)][str(rho)] = _brief(cheapest(runs, thr, rho))
    return {"sweeps": sweeps, "orders": orders, "cheapest": best}


def _brief(r):
    if r is None:
        return None
    return {k: r[k] for k in ("n_segments", "dt", "rho_inf", "wall_s", "error")}


# --------------------------------------------------------------------------- figures
COLORS = {0.0: "tab:blue", 0.5: "tab:orange", 1.0: "tab:green"}


def figure(title: str, runs: list[dict], analysis: dict, path: Path) -> None:
    """Three panels: error against wall time (every run grey, each sweep as a line coloured
    by ρ∞, solid for Δt sweeps and dashed for Δs sweeps, the cheapest 1 % / 0.1 % settings
    marked); error against Δt along the Δt sweeps; error against Δs along the Δs sweeps
    (each with a slope-2 guide)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    fig, axes = plt.subplots(1, 3, figsize=(16, 4.8))
    ok = [r for r in runs if np.isfinite(r["error"]) and r["error"] > 0]
    ax = axes[0]
    ax.loglog([r["wall_s"] for r in ok], [r["error"] for r in ok], ".", color="0.7", zorder=1)
    panel_data = {1: [], 2: []}
    for sw in analysis["sweeps"]:
        line = [r for r in sweep_line(runs, sw) if r["error"] > 0]
        if not line:
            continue
        style = "-o" if sw["direction"] == "dt" else "--s"
        color = COLORS[sw["rho_inf"]]
        ax.loglog([r["wall_s"] for r in line], [r["error"] for r in line], style,
                  color=color, ms=4, lw=1.2, zorder=2)
        k = 1 if sw["direction"] == "dt" else 2
        hs = [r["dt"] if k == 1 else r["ds"] for r in line]
        errs = [r["error"] for r in line]
        axes[k].loglog(hs, errs, style, color=color, ms=4,
                       label=f"ρ∞ = {sw['rho_inf']:g}, {sweep_label(sw)}")
        panel_data[k].append((hs, errs))
    handles = [Line2D([], [], color=COLORS[r], lw=2, label=f"ρ∞ = {r:g}") for r in RHO_INFS]
    handles += [Line2D([], [], color="k", ls="-", marker="o", ms=4, label="Δt sweep"),
                Line2D([], [], color="k", ls="--", marker="s", ms=4, label="Δs sweep"),
                Line2D([], [], color="0.7", ls="", marker=".", label="other runs")]
    for thr, mk in zip(THRESHOLDS, ("*", "P")):
        ax.axhline(thr, color="k", lw=0.6, ls=":")
        c = analysis["cheapest"][str(thr)]["any"]
        if c:
            label = (f"cheapest < {thr * 100:g} %: n = {c['n_segments']}, Δt = {c['dt']:g} s, "
                     f"ρ∞ = {c['rho_inf']:g}")
            ax.plot(c["wall_s"], c["error"], mk, color="crimson", ms=13, mfc="none", mew=1.5,
                    zorder=3)
            handles.append(Line2D([], [], color="crimson", ls="", marker=mk, ms=9, mfc="none",
                                  label=label))
    ax.set_xlabel("wall time of simulate (s)")
    ax.set_ylabel("error")
    ax.set_title(title, fontsize=9)
    ax.legend(handles=handles, fontsize=6, loc="lower left")
    for k, xl, ttl in ((1, "Δt (s)", "error against Δt (successive sweeps)"),
                       (2, "Δs (m)", "error against Δs")):
        axx = axes[k]
        for thr in THRESHOLDS:
            axx.axhline(thr, color="k", lw=0.6, ls=":")
        if panel_data[k]:
            x0 = min(min(h) for h, _ in panel_data[k])
            y0 = min(min(e) for _, e in panel_data[k])
            xx = np.array([x0, 4 * x0])
            axx.loglog(xx, y0 * (xx / x0) ** 2, "k-", lw=0.8)
            axx.text(4 * x0, 16 * y0, " slope 2", fontsize=7, va="center")
            axx.legend(fontsize=6, loc="lower right")
        axx.set_xlabel(xl)
        axx.set_ylabel("error")
        axx.set_title(ttl.replace(" (successive sweeps)", ""), fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def history_figure(runs: list[dict], ref: dict, n_sweep: int, path: Path) -> None:
    """Bending energy (log) against time for the Δt sweep at n_sweep segments, ρ∞ = 0 and
    1, every other Δt, with the reference: why the onset time converges unevenly."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(13, 4.3), sharey=True)
    for ax, rho in zip(axes, (0.0, 1.0)):
        line = [r for r in runs if r["rho_inf"] == rho and r["n_segments"] == n_sweep
                and "_history" in r]
        line.sort(key=lambda r: -r["dt"])
        cmap = plt.get_cmap("viridis")
        for k, r in enumerate(line[::2]):
            h = r["_history"]
            ax.semilogy(h["time"], np.maximum(h["energy_bending"], 1e-20), lw=1,
                        color=cmap(k / max(1, len(line[::2]) - 1)),
                        label=f"Δt = {r['dt']:g} s")
        if "history" in ref:
            ax.semilogy(ref["history"]["time"], np.maximum(ref["history"]["energy_bending"],
                                                           1e-20),
                        "k--", lw=1, label=f"reference ({ref['n_segments']}, {ref['dt']:g} s)")
        ax.set_xlim(0, SEED_T_END)
        ax.set_ylim(1e-16, 10)
        ax.set_xlabel("t (s)")
        ax.set_title(f"seed example without contact, n = {n_sweep}, ρ∞ = {rho:g}", fontsize=9)
        ax.legend(fontsize=7, loc="upper left")
    axes[0].set_ylabel("bending energy (J)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------- driver
def run(quick: bool = False, recompute_reference: bool = False) -> dict:
    t_start = time.perf_counter()
    repeats = 1 if quick else 3
    integrate(Case.model_validate(dict(Vibration().spec(8, 0.1, 0.5),
                                      numerics={"n_segments": 8, "dt": 0.1, "t_end": 0.3})))
    results = {"quick": quick, "repeats": repeats, "repeat_below_s": REPEAT_BELOW_S,
               "problems": {}}
    for prob in (Vibration(), Greenhill(), Seed(recompute_reference, quick)):
        t0 = time.perf_counter()
        print(f"== {prob.name}", flush=True)
        wanted, sweeps = prob.plan(quick)
        if isinstance(prob, Seed):
            quantities = [("t_b", lambda r: r["t_b"]), ("U_peak", lambda r: r["U_peak"])]
        else:
            quantities = [("λ_h/ω" if prob.name == "vibration" else "σ_h/σ",
                           lambda r, p=prob: p.value(r))]
        runs = run_problem(prob, wanted, repeats)
        res = {"title": prob.title, "oracle": prob.oracle(), "runs": runs,
               **analyse(runs, sweeps, quantities)}
        if isinstance(prob, Greenhill):
            dt_min = min(r["dt"] for r in runs)
            res["implied_mcr"] = [
                {"rho_inf": r["rho_inf"], "n_segments": r["n_segments"], "dt": r["dt"],
                 "mcr_L_over_B": prob.implied_mcr(r["sigma"])}
                for r in runs if r["dt"] == dt_min and np.isfinite(r["error"])]
        res["wall_total_s"] = time.perf_counter() - t0
        results["problems"][prob.name] = res
    results["wall_total_s"] = time.perf_counter() - t_start
    results["headline"] = headline(results)
    return results


def _setting(c) -> str:
    if c is None:
        return "none of the runs"
    return (f"n = {c['n_segments']}, Δt = {c['dt']:g} s, ρ∞ = {c['rho_inf']:g} "
            f"({c['wall_s']:.2f} s, error {c['error']:.1e})")


def headline(results: dict) -> list[str]:
    out = []
    for name, res in results["problems"].items():
        c1 = res["cheapest"]["0.01"]["any"]
        c2 = res["cheapest"]["0.001"]["any"]
        out.append(f"Work-precision, {name}: cheapest below 1 %: {_setting(c1)}; "
                   f"below 0.1 %: {_setting(c2)}.")
    return out


def _order_table(res: dict) -> list[str]:
    lines = ["| ρ∞ | sweep | held fixed | quantity | observed order (finest 3 differences) "
             "| local orders, coarse → fine | errors, coarse → fine |",
             "|---|---|---|---|---:|---|---|"]
    for o in res["orders"]:
        fixed = f"n = {o['n_segments']}" if o["direction"] == "dt" else f"Δt = {o['dt']:g} s"
        lines.append(f"| {o['rho_inf']:g} | {'Δt' if o['direction'] == 'dt' else 'Δs'} | "
                     f"{fixed} | {o['quantity']} | {o['order']:.2f} | "
                     + ", ".join(f"{x:.2f}" for x in o["local_orders"]) + " | "
                     + ", ".join(f"{x:.1e}" for x in o["errors"]) + " |")
    return lines


def _cheapest_table(res: dict) -> list[str]:
    lines = ["| ρ∞ | cheapest below 1 % | wall (s) | error | cheapest below 0.1 % | wall (s) "
             "| error |", "|---|---|---:|---:|---|---:|---:|"]
    for key in [str(r) for r in RHO_INFS] + ["any"]:
        cells = []
        for thr in THRESHOLDS:
            c = res["cheapest"][str(thr)][key]
            if c is None:
                cells += ["none of the runs", "", ""]
            else:
                cells += [f"n = {c['n_segments']}, Δt = {c['dt']:g} s"
                          + (f", ρ∞ = {c['rho_inf']:g}" if key == "any" else ""),
                          f"{c['wall_s']:.2f}", f"{c['error']:.1e}"]
        lines.append(f"| {'best of all' if key == 'any' else key} | " + " | ".join(cells)
                     + " |")
    return lines


def section(figdir: Path, quick: bool = False, recompute_reference: bool = False) -> str:
    """Run the work-precision study, save its figures (PNG) into figdir, write
    benchmarks/results/work_precision.json and return the Markdown section."""
    res = run(quick, recompute_reference)
    figdir = Path(figdir)
    for name, p in res["problems"].items():
        fig_path = figdir / f"work_precision_{name}.png"
        figure(p["title"], p["runs"], p, fig_path)
        print(f"figure: {fig_path}")
    seed = res["problems"]["seed"]
    n_sweep = [sw for sw in seed["sweeps"] if sw["direction"] == "dt"][0]["n_segments"]
    fig_path = figdir / "work_precision_seed_history.png"
    history_figure(seed["runs"], seed["oracle"], n_sweep, fig_path)
    print(f"figure: {fig_path}")
    for p in res["problems"].values():
        for r in p["runs"]:
            r.pop("_history", None)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(res, indent=1, default=float))
    return markdown(res)


def markdown(res: dict) -> str:
    P = res["problems"]
    vib, gh, seed = P["vibration"], P["greenhill"], P["seed"]
    lines = ["## Work-precision: error against wall time, observed orders", "",
             "Written by `benchmarks/work_precision.py` (docstring: problem set-ups and error "
             "definitions). Wall time of `simulate` alone"
             + (f", median of {res['repeats']} runs for runs under {res['repeat_below_s']:g} s, "
                "single runs otherwise" if res["repeats"] > 1 else ", single runs")
             + "; the machine is shared, so single timings carry some noise. Observed "
             "orders are slopes of log |v_k − v_{k+1}| against log h over the finest three "
             "differences of each sweep (v the measured quantity, so the fixed error of the "
             "other direction cancels). The cheapest setting for a threshold is the run with "
             "the lowest wall time whose error, and the error of every refinement of it that "
             "was run (same ρ∞, smaller or equal Δt, as many or more segments), is below the "
             "threshold: a lucky cancellation of spatial and temporal errors of opposite sign "
             "does not count. Total time of this section: "
             f"{res['wall_total_s']:.0f} s.", ""]
    if res["quick"]:
        lines += ["**Quick mode: small grids and single runs; not the figures to quote.**", ""]
    o = vib["oracle"]
    lines += [f"### 1. {vib['title']}", "",
              "Clamped-clamped rod in vacuum, L = 1 m, D = 10 mm, the seed's material, the "
              "far end free to slide axially; a uniform lateral load of 3e-4 N/m on "
              "0 ≤ t < 0.6 s, then free vibration to 3.9 s. Error: |λ_h − iω₁|/ω₁ with "
              "λ_h = −ζ_h + iω_h fitted to the deflection projected on the exact mode shape "
              "(frequency error and numerical damping together). Exact ω₁ = "
              f"{o['omega_rad_s']:.6f} rad/s (Rayleigh beam; Euler-Bernoulli βL = 4.7300 gives "
              f"{o['omega_euler_bernoulli_rad_s']:.6f} rad/s, "
              f"{-o['rayleigh_over_euler_bernoulli_minus_1'] * 100:.4f} % higher: the rotary "
              "inertia the rod model carries).", "",
              "![work-precision, vibration](figures/benchmarks/work_precision_vibration.png)",
              ""]
    lines += _cheapest_table(vib) + [""] + _order_table(vib) + [""]
    o = gh["oracle"]
    lines += [f"### 2. {gh['title']}", "",
              "The same rod twisted at s = 0 over 1 s (sin² rate) to M = 1.1 M_cr, "
              f"M_cr L/B = {o['mcr_L_over_B']:.4f} (Greenhill, zero end force, far end "
              "sliding), with a lateral load of 1e-6 N/m on 0.2 ≤ s ≤ 0.45 m during the ramp "
              "as perturbation. Error: |σ_h/σ − 1| with σ_h fitted (A e^{σt} + B e^{−σt}) to "
              "the deflection projected on the exact unstable mode, from 1.2 s while the "
              f"deflection is below 1 mm; exact σ = {o['sigma_1_s']:.5f} 1/s (vacuum, with "
              "rotary inertia). σ² is about linear in M − M_cr, so a relative error δ in the "
              "discrete buckling moment shows as about 6δ in σ: this is a sharp test of the "
              "buckling moment.", "",
              "![work-precision, Greenhill](figures/benchmarks/work_precision_greenhill.png)",
              ""]
    lines += _cheapest_table(gh) + [""] + _order_table(gh) + [""]
    imp = [x for x in gh.get("implied_mcr", []) if x["rho_inf"] == 1.0] or gh.get("implied_mcr", [])
    if imp:
        lines += ["Buckling moment implied by the measured growth rate at the finest Δt "
                  f"(ρ∞ = {imp[0]['rho_inf']:g}, Δt = {imp[0]['dt']:g} s; M_cr L/B exact "
                  f"{o['mcr_L_over_B']:.4f}):", "",
                  "| n | " + " | ".join(str(x["n_segments"]) for x in imp) + " |",
                  "|---|" + "---:|" * len(imp),
                  "| M_cr L/B | " + " | ".join(f"{x['mcr_L_over_B']:.4f}" for x in imp) + " |",
                  "| relative error | " + " | ".join(
                      f"{x['mcr_L_over_B'] / o['mcr_L_over_B'] - 1:+.2e}" for x in imp) + " |",
                  ""]
    o = seed["oracle"]
    est = o["estimated_error"]
    lines += [f"### 3. {seed['title']}", "",
              "`cases/goyal-writhing.yaml` without `contact`, energies only, to 18 s. Error: "
              "max(|t_b − t_b,ref|/t_b,ref, |U_peak − U_peak,ref|/U_peak,ref): t_b the "
              "buckling onset (bending energy reaches 1 % of the torsional energy, "
              "interpolated in log between outputs), U_peak the peak torsional energy "
              "(parabola through the largest output and its neighbours). After the "
              "instability the state is set by when the rod lets go and how much twist it "
              "holds then; a history compared point by point would mostly measure the "
              "shift in time of a fast collapse. Reference: "
              f"{o['n_segments']} segments, Δt = {o['dt']:g} s, ρ∞ = {o['rho_inf']:g} "
              f"(cached in `benchmarks/results/work_precision_seed_reference.json`, "
              f"`--recompute-reference` reruns it; {o['wall_s']:.0f} s): t_b = "
              f"{o['t_b']:.4f} s, U_peak = {o['U_peak']:.5f} J; its own error, estimated by "
              "Richardson extrapolation (order 2) from runs at twice its Δt and at twice its "
              f"Δt with 2000 segments, about {est['t_b']:.1e} s and {est['U_peak']:.1e} J "
              f"({est['t_b'] / o['t_b']:.1e} and {est['U_peak'] / o['U_peak']:.1e} relative)."
              + (" **No cached reference: quick mode used a stand-in (500 segments, "
                 "Δt = 0.0125 s).**" if o.get("stand_in") else ""),
              "",
              "![work-precision, seed](figures/benchmarks/work_precision_seed.png)", ""]
    lines += _cheapest_table(seed) + [""] + _order_table(seed) + [""]
    lines += reading(res)
    return "\n".join(lines) + "\n"


def _find(runs, n, dt, rho):
    for r in runs:
        if r["n_segments"] == n and r["dt"] == dt and r["rho_inf"] == rho \
                and np.isfinite(r["error"]):
            return r
    return None


def _orders(res, direction, quantity=None):
    return {o["rho_inf"]: o["order"] for o in res["orders"] if o["direction"] == direction
            and (quantity is None or o["quantity"] == quantity)}


def _short(c) -> str:
    if c is None:
        return "none"
    return f"n = {c['n_segments']}, Δt = {c['dt']:g} s ({c['wall_s']:.2f} s)"


def reading(res: dict) -> list[str]:
    """The reading of the results, written from the numbers of this run (sentences whose
    runs are missing, as in quick mode, are left out)."""
    P = res["problems"]
    out = ["### Reading", ""]
    vib, gh, seed = P["vibration"], P["greenhill"], P["seed"]

    def fmt_orders(d):
        return ", ".join(f"{v:.2f} (ρ∞ = {k:g})" for k, v in sorted(d.items()))

    # orders
    lines = []
    for name, res_p, q in (("vibration", vib, None), ("Greenhill", gh, None),
                           ("seed, t_b", seed, "t_b")):
        dt_o, ds_o = _orders(res_p, "dt", q), _orders(res_p, "ds", q)
        lines.append(f"{name}: Δt {fmt_orders(dt_o)}; Δs {fmt_orders(ds_o)}")
    analytic = [o["order"] for p in (vib, gh) for o in p["orders"]]
    out += ["* **Observed orders** (finest three differences): " + "; ".join(lines) + ". "
            f"The two analytic problems give orders between {min(analytic):.2f} and "
            f"{max(analytic):.2f} in both Δt and Δs for every ρ∞: second order, as the scheme "
            "is built to (`docs/numerics.md` §5; above 2 where the sweep is still "
            "pre-asymptotic). The seed problem's Δt differences are not monotone (below), so "
            "its Δt orders describe the finest steps only.", ""]
    # vibration
    n_max = max(r["n_segments"] for r in vib["runs"])
    errs = {rho: _find(vib["runs"], n_max, 0.05, rho) for rho in RHO_INFS}
    if all(errs.values()):
        parts = [f"{errs[r]['error']:.1e} (ρ∞ = {r:g}; frequency "
                 f"{errs[r]['omega'] / vib['oracle']['omega_rad_s'] - 1:+.1e}, damping "
                 f"ζ/ω = {errs[r]['zeta'] / vib['oracle']['omega_rad_s']:.1e})" for r in RHO_INFS]
        out += [f"* **Vibration.** At Δt = 0.05 s (about 25 steps per period) and n = {n_max} "
                "the eigenvalue error is " + ", ".join(parts) + ": the period elongation of "
                "the trapezoidal family, (ωΔt)²/12 at ρ∞ = 1, dominates, and ρ∞ < 1 adds "
                "numerical damping and a larger frequency error. The spatial error is the "
                "box rule's, a raised frequency of about (βΔs)²/6, opposite in sign to the "
                "temporal one (hence the dips where they cancel, which the cheapest-setting "
                "rule does not count). Cheapest below 1 % / 0.1 % per ρ∞: "
                + "; ".join(f"ρ∞ = {r:g}: " + " / ".join(
                    _short(vib["cheapest"][str(t)][str(r)]) for t in THRESHOLDS)
                    for r in RHO_INFS) + ".", ""]
    # Greenhill
    n_max = max(r["n_segments"] for r in gh["runs"])
    dt_max = max(r["dt"] for r in gh["runs"])
    coarse = {rho: _find(gh["runs"], n_max, dt_max, rho) for rho in RHO_INFS}
    imp = {x["n_segments"]: x["mcr_L_over_B"] for x in gh.get("implied_mcr", [])
           if x["rho_inf"] == 1.0}
    if all(coarse.values()):
        parts = ", ".join(f"{coarse[r]['sigma'] / gh['oracle']['sigma_1_s'] - 1:+.1e} "
                          f"(ρ∞ = {r:g})" for r in RHO_INFS)
        out += [f"* **Greenhill.** At Δt = {dt_max:g} s (σΔt = "
                f"{gh['oracle']['sigma_1_s'] * dt_max:.2f}), n = {n_max}, σ_h/σ − 1 is {parts}: "
                "the numerical dissipation that damps oscillations for ρ∞ < 1 *amplifies* a "
                "growing mode at moderate σΔt (its amplification factor exceeds e^{σΔt}, as "
                "backward Euler's 1/(1 − σΔt) does for σΔt < 1), so an instability grows too "
                "fast and a buckling event comes early unless Δt resolves the growth; at "
                "ρ∞ = 1 the error is the trapezoid's small (σΔt)²/12. (For σΔt ≫ 1 the same "
                "factor drops below one and the instability is suppressed instead: "
                "`docs/numerics.md` §6.) Cheapest below 1 % / 0.1 % per "
                "ρ∞: " + "; ".join(f"ρ∞ = {r:g}: " + " / ".join(
                    _short(gh["cheapest"][str(t)][str(r)]) for t in THRESHOLDS)
                    for r in RHO_INFS) + "."
                + (f" The buckling moment implied by σ_h converges at second order to "
                   f"M_cr L/B = 8.9868: {imp[min(imp)] / gh['oracle']['mcr_L_over_B'] - 1:+.1e}"
                   f" at n = {min(imp)}, "
                   + ", ".join(f"{imp[n] / gh['oracle']['mcr_L_over_B'] - 1:+.1e} at n = {n}"
                               for n in sorted(imp)[1:]) + " (about "
                   f"{(imp[100] / gh['oracle']['mcr_L_over_B'] - 1) * 100**2:.0f}/n²), so "
                   "1 % on the buckling moment needs about "
                   f"{np.sqrt((imp[100] / gh['oracle']['mcr_L_over_B'] - 1) * 100**2 / 1e-2):.0f}"
                   " segments and 0.1 % about "
                   f"{np.sqrt((imp[100] / gh['oracle']['mcr_L_over_B'] - 1) * 100**2 / 1e-3):.0f}"
                   "; the growth rate, about 6 times more sensitive, needs more."
                   if 100 in imp else ""), ""]
    # seed
    ref = seed["oracle"]
    base = _find(seed["runs"], 1000, 0.1, 0.5)
    dt_sw = [o for o in seed["orders"] if o["direction"] == "dt" and o["quantity"] == "t_b"]
    ds_sw = [o for o in seed["orders"] if o["direction"] == "ds" and o["quantity"] == "t_b"]
    text = "* **Seed example.** "
    if base:
        text += (f"At the seed's resolution (1000 segments, Δt = 0.1 s, ρ∞ = 0.5) the onset "
                 f"is at {base['t_b']:.3f} s against {ref['t_b']:.3f} s "
                 f"({base['t_b'] - ref['t_b']:+.3f} s) and U_peak {base['U_peak']:.4f} J against "
                 f"{ref['U_peak']:.4f} J: error {base['error']:.1e}. ")
    if ds_sw:
        e = ds_sw[0]["errors"]
        ns = [r["n_segments"] for r in sweep_line(seed["runs"], ds_sw[0])]
        text += ("The spatial error is small: at Δt = " f"{ds_sw[0]['dt']:g} s the error is "
                 + ", ".join(f"{x:.1e}" for x in e) + " for " + ", ".join(map(str, ns))
                 + " segments (mostly the Δt error, which they share), so before contact "
                 "the seed's 1 mm grid is finer than its Δt warrants and 250-500 segments do "
                 "as well. ")
    if dt_sw:
        signs = []
        for o in dt_sw:
            line = sweep_line(seed["runs"], o)
            tb = [r["t_b"] - ref["t_b"] for r in line]
            signs.append(f"ρ∞ = {o['rho_inf']:g}: " + ", ".join(f"{x:+.3f}" for x in tb))
        text += ("In Δt the onset converges unevenly; t_b − t_b,ref (s) along the Δt sweeps, "
                 "Δt = " + ", ".join(f"{r['dt']:g}" for r in sweep_line(seed["runs"],
                                                                          dt_sw[0]))
                 + " s: " + "; ".join(signs) + ". The reason is in the bending-energy "
                 "history (figure below): the perturbation applied on 0-2 s leaves a lateral "
                 "oscillation of the straight twisted rod (about 1e-11 J) whose frequency "
                 "falls as the twist approaches Greenhill's; when the rod crosses it (about "
                 "13 s) the phase and amplitude of that oscillation set the start of the "
                 "exponential growth. A coarse Δt errs in that phase (period elongation over "
                 "some 20 cycles) and, for ρ∞ < 1, damps the amplitude, and the onset time "
                 "inherits both: it reaches its asymptotic range only at the finest steps of "
                 "the sweep. "
                 "Its errors still fall by orders of magnitude over the sweep; 1 % is 0.17 s "
                 "in t_b. Cheapest below 1 % / 0.1 % per ρ∞: "
                 + "; ".join(f"ρ∞ = {r:g}: " + " / ".join(
                     _short(seed["cheapest"][str(t)][str(r)]) for t in THRESHOLDS)
                     for r in RHO_INFS) + ".")
    out += [text, "",
            "![bending energy against time](figures/benchmarks/work_precision_seed_history.png)",
            ""]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--recompute-reference", action="store_true",
                    help="rerun the fine reference of the seed problem (cached otherwise)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    text = section(FIGDIR, quick=args.quick, recompute_reference=args.recompute_reference)
    print(text)
    print(f"work_precision: {time.perf_counter() - t0:.0f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
