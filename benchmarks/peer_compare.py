"""hockle and PyElastica interleaved on the same physics: a clamped rod twisted into a
plectoneme with self-contact (issue 43; PyElastica's ``PlectonemesCase`` example).

Run: ``nice -n 10 python -m benchmarks.peer_compare`` (prints the Markdown section, writes
``benchmarks/results/peer_compare.json`` and the figure), or as the ``pyelastica`` section
of ``python -m benchmarks.report``. ``--quick``: a smoke run of the pipeline (short
horizon, coarse grids, one repeat; not figures to quote). ``--render``: rebuild the
section from the saved JSON without running anything. ``--check-harness``: the lean
PyElastica harness against the one of ``benchmarks/pyelastica_compare.py`` (identical
positions, and its wall time against that harness's, interleaved).

Method (the section written by :func:`render` states it with the figures):

* **Same physics.** The rod, the clamped start, the end held laterally, free axially and
  turned about the axis (ramped over 0.5 s to 2π·10/50 rad/s), the 1e-4 N/m imperfection:
  as in ``benchmarks/pyelastica_compare.py``. Damping: the *same Morison drag* in both
  codes, −½ρ_f D C_dn |v_n| v_n − ½ρ_f πD C_dt |v_t| v_t per unit length (hockle's
  ``fluid`` with no added mass; for PyElastica the forcing class :class:`MorisonLoads`,
  numba-compiled, with the tangent from the neighbouring nodes). hockle's case language
  has no linear damper, so the drag is the common law. PyElastica also gets its
  ``LaplaceDissipationFilter`` (FILTER_ORDER), the counterpart of hockle's
  generalized-α dissipation of the highest frequencies: without it position Verlet blew
  up in the interwinding. Contact: the codes' own laws
  (PyElastica's linear penalty k = 1e4 N/m with pair damper ν = 10 N·s/m while elements
  overlap; hockle's ρA k1/gap³ barrier with k3 damping on pairs within the tolerance),
  the remaining difference, stated in the section.
* **Interleaved timing.** Both codes run in this one process, one thread each
  (NUMBA_NUM_THREADS = OMP_NUM_THREADS = 1 set before numba loads, and threadpoolctl's
  limit), alternating hockle and PyElastica runs (A B A B …) over repeated rounds, after a
  warm-up of each (``solver.compiled.warm_up`` and a full run of each code's cheapest
  setting; PyElastica's numba compilation is its first warm-up call). Walls: hockle's
  ``integrate()`` (positions every 0.02 s as output), PyElastica's time-step loop with the
  position copies every 0.02 s; Wr and gaps are computed afterwards for both, untimed.
  ``os.getloadavg()`` is recorded before and after every timed run.
* **Accuracy.** The writhe history Wr(t) over the whole run (Lk is the prescribed end
  turn in both codes, Tw = Lk − Wr): relative L1 error ∫|Wr − Wr_ref| dt / ∫|Wr_ref| dt on
  the reference's 0.02-s output grid, against (a) the code's own finest run
  (self-convergence) and (b) a common yardstick: each code's finest run, i.e. both
  settings of both codes are also measured against the other code's reference.
* **Counting rule.** A setting counts at a level only if its error is within the level
  and so is the error of its next refinement (Δs and Δt both halved: hockle (2N, Δt/2),
  PyElastica (2n, same Δt/Δs)); the reference is the last refinement (error 0 by
  definition against its own code). The ratio at a level is PyElastica's cheapest counting
  median wall over hockle's.
"""
from __future__ import annotations

import os

if __name__ == "__main__":       # one thread each, set before numba loads (collect() also
    for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                 "MKL_NUM_THREADS"):       # limits them at run time, for report.py)
        os.environ[_var] = "1"

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numba
import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
from benchmarks import pyelastica_compare as pc
from solver.topology import writhe

NAME = "peer_compare"
OUT_DT = 0.02                    # s, output interval of both codes
#: PyElastica's LaplaceDissipationFilter order in the comparison. Without a dissipation of
#: its own (the example's linear damper replaced by the Morison drag) position Verlet blew
#: up in the interwinding phase: n = 25 at 10.7, 14.8 and 15.6 s for Δt/Δs = 0.011, 0.0055
#: and 0.0025 s/m, n = 50 at 19.4 s (0.011); with the filter (order 5, the weak end of the
#: 3-7 PyElastica recommends) both ran to 20 s, and orders 3 and 5 gave the same buckling
#: and contact times to 1 ms at n = 25. It plays the part of hockle's generalized-α
#: dissipation of the highest frequencies (ρ∞ = 0.5).
FILTER_ORDER = 5

# --------------------------------------------------------------------------- settings
FULL = {
    "t_end": 12.0,
    # hockle (N, Δt s); refinement of (N, Δt) is (2N, Δt/2)
    "hockle": [(25, 0.1), (25, 0.05), (50, 0.05), (25, 0.025), (50, 0.025), (100, 0.025),
               (50, 0.0125), (100, 0.0125), (100, 0.00625), (200, 0.00625)],
    "hockle_ref": (400, 0.003125),
    # PyElastica (n, Δt/Δs s/m); refinement of (n, r) is (2n, r)
    # 0.015 s/m: n = 25 blew up there (in contact), n = 50 ran; Δt/Δs changed Wr by 0.13 %
    # (n = 25, 0.011 against 0.0055) and 0.01 % (n = 50, 0.015 against 0.011) to 9 s, Δs
    # by 2.8 % (n = 25 against 50): the Δs refinement is the one that matters. n = 20-160:
    # to 12 s at load 7 n = 100 took ~150 s and n = 200 ~980 s (extrapolated from 1 and
    # 0.5 s), beyond one run's budget with the rest of the grid. In the run of 2026-11-27
    # (load 1, AMD EPYC) n = 80 took 18 s, n = 160 108 s and n = 320 770 s: n = 160 is
    # the finest candidate whose refinement one run can afford as the reference
    "pyelastica": [(20, 0.015), (20, 0.011), (20, 0.0055), (40, 0.015), (40, 0.011),
                   (80, 0.011), (160, 0.011)],
    "pyelastica_ref": (320, 0.011),
    "repeats": 3,                  # rounds for settings whose single run is cheap
    "repeat_below_s": 20.0,        # settings slower than this (first round) run twice only
    "stop_after_s": 1200.0,        # no repeat starts after this (the budget of one run)
}
QUICK = {
    "t_end": 8.0,
    "hockle": [(25, 0.05), (50, 0.025)], "hockle_ref": (100, 0.0125),
    "pyelastica": [(25, 0.011), (50, 0.011)], "pyelastica_ref": (100, 0.011),
    "repeats": 2, "repeat_below_s": 5.0, "stop_after_s": 600.0,
}
LEVELS = (0.01, 0.001)


# --------------------------------------------------------------------------- schedules
def end_rate(t: float) -> float:
    """Prescribed end angular velocity ω3 (rad/s) at time t (s), plain float: the ramp of
    ``pyelastica_compare.end_rate`` (linear to Ω over T_RAMP, then constant)."""
    return pc.OMEGA * min(t / pc.T_RAMP, 1.0)


def end_angle(t: float) -> float:
    """Prescribed end rotation φ(t) (rad), the integral of :func:`end_rate`, plain float;
    the same expression as ``pyelastica_compare.end_angle``."""
    if t < pc.T_RAMP:
        return 0.5 * pc.OMEGA * t**2 / pc.T_RAMP
    return pc.OMEGA * (t - 0.5 * pc.T_RAMP)


# --------------------------------------------------------------------------- PyElastica
@numba.njit(cache=True)
def _morison_into(x, v, w, cn, ct, f0, out):
    """Add the Morison drag and a constant global force to PyElastica's external forces.
    x, v: (3, n+1) node positions m and velocities m/s; w: (n+1,) nodal lengths m;
    cn = ½ρ_f D C_dn, ct = ½ρ_f πD C_dt (kg/m²); f0: (3,) N/m; out: (3, n+1) N, added to.
    Drag per unit length −cn |v_n| v_n − ct |v_t| v_t (solver/loads.py's law) with the
    tangent t along x_{i+1} − x_{i−1} (one-sided at the ends), v_t = (v·t) t."""
    m = x.shape[1]
    for i in range(m):
        a = i - 1 if i > 0 else 0
        b = i + 1 if i < m - 1 else m - 1
        t0 = x[0, b] - x[0, a]
        t1 = x[1, b] - x[1, a]
        t2 = x[2, b] - x[2, a]
        inv = 1.0 / math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        t0 *= inv
        t1 *= inv
        t2 *= inv
        vt = v[0, i] * t0 + v[1, i] * t1 + v[2, i] * t2
        n0 = v[0, i] - vt * t0
        n1 = v[1, i] - vt * t1
        n2 = v[2, i] - vt * t2
        sn = cn * math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        st = ct * abs(vt) * vt
        out[0, i] += w[i] * (f0[0] - sn * n0 - st * t0)
        out[1, i] += w[i] * (f0[1] - sn * n1 - st * t1)
        out[2, i] += w[i] * (f0[2] - sn * n2 - st * t2)


def nodal_lengths(n: int) -> np.ndarray:
    """(n+1,) lengths (m) each node of an n-element rod of length L stands for."""
    w = np.full(n + 1, pc.LENGTH / n)
    w[0] = w[-1] = 0.5 * pc.LENGTH / n
    return w


def pyelastica_sim(n: int, dt: float, damping: str = "morison", contact: bool = True,
                   filter_order: int | None = None):
    """The lean PyElastica plectoneme simulator: n elements along z from the origin
    (d1 = x, d3 = z); s = 0 clamped; s = L held laterally, free axially, its director
    turned about z to :func:`end_angle` with rate :func:`end_rate` (plain floats, one
    evaluation per call); the imperfection pc.IMPERFECTION N/m along x. ``damping``:
    ``"morison"`` (:class:`MorisonLoads`: the hockle case's drag and the imperfection in
    one numba kernel) or ``"linear"`` (``AnalyticalLinearDamper`` with
    ``uniform_damping_constant`` ν = 2/(ρA) and the imperfection as a precomputed force:
    the physics of ``pyelastica_compare``, for the identity check). Returns (simulator,
    rod, stepper)."""
    import elastica as ea

    class Sim(ea.BaseSystemCollection, ea.Constraints, ea.Contact, ea.Forcing,
              ea.CallBacks, ea.Damping):
        pass

    class TwistedEnds(ea.ConstraintBase):
        def __init__(self, p0, p1, d0, d1, **kw):
            super().__init__(**kw)
            self.p0, self.d0 = p0.copy(), d0.copy()
            self.e1, self.e2, self.e3 = d1[0].copy(), d1[1].copy(), d1[2].copy()

        def constrain_values(self, system, time):
            phi = end_angle(float(time))
            c, s = math.cos(phi), math.sin(phi)
            pos, dirs = system.position_collection, system.director_collection
            pos[:, 0] = self.p0
            pos[0, -1] = 0.0
            pos[1, -1] = 0.0
            dirs[..., 0] = self.d0
            dirs[0, :, -1] = c * self.e1 + s * self.e2
            dirs[1, :, -1] = c * self.e2 - s * self.e1
            dirs[2, :, -1] = self.e3

        def constrain_rates(self, system, time):
            vel, om = system.velocity_collection, system.omega_collection
            vel[:, 0] = 0.0
            om[:, 0] = 0.0
            vel[0, -1] = 0.0
            vel[1, -1] = 0.0
            om[0, -1] = 0.0
            om[1, -1] = 0.0
            om[2, -1] = end_rate(float(time))

    class Imperfection(ea.NoForces):
        def __init__(self):
            super().__init__()
            w = nodal_lengths(n)
            f = np.zeros((3, n + 1))
            f[0] = pc.IMPERFECTION
            self.f = f * w

        def apply_forces(self, system, time=0.0):
            system.external_forces += self.f

    class MorisonLoads(ea.NoForces):
        def __init__(self):
            super().__init__()
            self.w = nodal_lengths(n)
            self.cn = 0.5 * pc.RHO_FLUID * pc.DIAMETER * pc.CD_NORMAL
            self.ct = 0.5 * pc.RHO_FLUID * np.pi * pc.DIAMETER * pc.CD_NORMAL / np.pi
            self.f0 = np.array([pc.IMPERFECTION, 0.0, 0.0])

        def apply_forces(self, system, time=0.0):
            _morison_into(system.position_collection, system.velocity_collection, self.w,
                          self.cn, self.ct, self.f0, system.external_forces)

    sim = Sim()
    rod = ea.CosseratRod.straight_rod(n, np.zeros(3), np.array([0.0, 0.0, 1.0]),
                                      np.array([1.0, 0.0, 0.0]), pc.LENGTH, pc.RADIUS, pc.RHO,
                                      youngs_modulus=pc.YOUNG, shear_modulus=pc.SHEAR)
    sim.append(rod)
    if damping == "linear":
        sim.dampen(rod).using(ea.AnalyticalLinearDamper, uniform_damping_constant=pc.NU,
                              time_step=dt)
    if filter_order:
        sim.dampen(rod).using(ea.LaplaceDissipationFilter, filter_order=int(filter_order))
    sim.constrain(rod).using(TwistedEnds, constrained_position_idx=(0, -1),
                             constrained_director_idx=(0, -1))
    sim.add_forcing_to(rod).using(MorisonLoads if damping == "morison" else Imperfection)
    if contact:
        sim.detect_contact_between(rod, rod).using(ea.RodSelfContact, k=pc.K_CONTACT,
                                                   nu=pc.NU_CONTACT)
    sim.finalize()
    return sim, rod, ea.PositionVerlet()


def pyelastica_step(n: int, ratio: float) -> float:
    """PyElastica's time step (s) for n elements and the nominal Δt/Δs ``ratio`` (s/m):
    the largest Δt ≤ ratio·Δs that divides OUT_DT, so that outputs fall on the same
    0.02-s grid as hockle's."""
    return OUT_DT / math.ceil(OUT_DT / (ratio * pc.LENGTH / n) - 1e-9)


def run_pyelastica(n: int, ratio: float, t_end: float, damping: str = "morison",
                   old_harness: bool = False, filter_order: int | None = FILTER_ORDER) -> dict:
    """One PyElastica run: n elements, Δt = ratio·Δs (s), to t_end (s), positions every
    OUT_DT, with the LaplaceDissipationFilter of ``filter_order`` (None: none).
    ``old_harness``: build it with ``pyelastica_compare._pyelastica_sim`` (linear damper)
    instead. Returns {"t" (T,) s, "pos" (T, n+1, 3) m, "wall" s (the step loop
    with the copies), "steps", "finite"}."""
    dt = pyelastica_step(n, ratio)
    if old_harness:
        def force(t, s):
            f = np.zeros((3, len(s)))
            f[0] = pc.IMPERFECTION
            return f
        sim, rod, stepper = pc._pyelastica_sim(n, dt, angle=pc.end_angle, rate=pc.end_rate,
                                               force=force, damping=pc.NU, contact=True)
    else:
        sim, rod, stepper = pyelastica_sim(n, dt, damping=damping, filter_order=filter_order)
    every = max(1, int(round(OUT_DT / dt)))
    steps = int(round(t_end / dt))
    ts, pos = [0.0], [rod.position_collection.copy()]
    t = 0.0
    t0 = time.perf_counter()
    for k in range(1, steps + 1):
        t = stepper.step(sim, t, dt)
        if k % every == 0:
            ts.append(t)
            pos.append(rod.position_collection.copy())
    wall = time.perf_counter() - t0
    p = np.array(pos).transpose(0, 2, 1)
    return {"t": np.array(ts), "pos": p, "wall": wall, "steps": steps,
            "finite": bool(np.isfinite(p).all())}


# --------------------------------------------------------------------------- hockle
def hockle_case(n: int, dt: float, t_end: float):
    """The plectoneme as a hockle Case (pyelastica_compare's problem, contact law and
    Morison drag), positions every OUT_DT as the only output."""
    from solver import Case
    every = max(1, int(round(OUT_DT / dt)))
    spec = pc._hockle_spec(n, dt, t_end, every,
                           end_rate_table={"t": [0.0, pc.T_RAMP], "value": [0.0, pc.OMEGA]},
                           fluid=True, forces=[{"value": [pc.IMPERFECTION, 0.0, 0.0]}],
                           contact=True, fields=["position"])
    return Case.model_validate(spec)


def run_hockle(n: int, dt: float, t_end: float) -> dict:
    """One hockle run; the same dict as :func:`run_pyelastica` (wall: ``integrate()``),
    plus "status" (completed, or where it diverged)."""
    from solver import SolverDivergence, integrate
    case = hockle_case(n, dt, t_end)
    status = "completed"
    t0 = time.perf_counter()
    try:
        ds = integrate(case)
    except SolverDivergence as exc:
        ds, status = exc.partial, f"diverged at t = {exc.t:.3f} s"
    wall = time.perf_counter() - t0
    p = ds.position.values
    return {"t": ds.time.values, "pos": p, "wall": wall, "steps": int(ds.sizes["step"]),
            "finite": bool(np.isfinite(p).all()) and status == "completed",
            "status": status}


# --------------------------------------------------------------------------- measures
def post(run: dict) -> dict:
    """Untimed post-processing of a run: Wr (T,) (solver.topology.writhe of the nodes),
    lateral deflection (T,) m, buckling and first-contact times (s) as in
    pyelastica_compare.events."""
    pos = run["pos"]
    if not run["finite"]:
        nan = np.full(len(run["t"]), np.nan)
        return {"Wr": nan, "t_buckle": float("nan"), "t_contact": float("nan")}
    wr = np.array([writhe(p) for p in pos])
    gap = np.array([pc.min_surface_gap(p) for p in pos])
    return {"Wr": wr, **pc.events(run["t"], pc.lateral(pos), gap)}


def wr_error(t, wr, t_ref, wr_ref) -> float:
    """Relative L1 error of a writhe history against a reference: ∫|Wr − Wr_ref| dt /
    ∫|Wr_ref| dt over the reference's output times (the run interpolated linearly onto
    them). NaN if the run has non-finite values or ends before the reference."""
    if not np.isfinite(wr).all() or t[-1] < t_ref[-1] - 0.5 * OUT_DT:
        return float("nan")
    w = np.interp(t_ref, t, wr)
    return float(np.trapezoid(np.abs(w - wr_ref), t_ref) / np.trapezoid(np.abs(wr_ref), t_ref))


def loadavg() -> list[float]:
    return [round(x, 2) for x in os.getloadavg()]


# --------------------------------------------------------------------------- the study
def _key(code, a, b):
    return f"{code}:{a:g}:{b:g}"


def refinement(code: str, a, b):
    """The next refinement of a setting: hockle (N, Δt) -> (2N, Δt/2), PyElastica
    (n, Δt/Δs) -> (2n, Δt/Δs)."""
    return (2 * a, b / 2) if code == "hockle" else (2 * a, b)


def collect(cfg: dict, log=print, stop_after: float = float("inf")) -> dict:
    """Warm up both codes, run the interleaved rounds (the first round, then the two
    references, then the further rounds; no run of a further round starts after
    ``stop_after`` seconds), measure. Returns the JSON-ready results."""
    from threadpoolctl import threadpool_limits
    import solver.compiled
    limiter = threadpool_limits(limits=1)
    numba.set_num_threads(1)
    t_all = time.perf_counter()
    res = {"config": {k: v for k, v in cfg.items()}, "load_start": loadavg(),
           "threads": {"numba": numba.get_num_threads(),
                       "blas/openmp": "threadpoolctl limit 1"},
           "pyelastica_version": pc._pyelastica_version(), "runs": {}, "log": []}
    log(f"load {res['load_start']}; warm-up")
    t0 = time.perf_counter()
    solver.compiled.warm_up()
    res["hockle_warmup_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    run_pyelastica(10, 0.011, 0.05)
    res["pyelastica_compile_s"] = time.perf_counter() - t0
    h0, p0 = cfg["hockle"][0], cfg["pyelastica"][0]
    run_hockle(*h0, cfg["t_end"])          # full warm-up runs, untimed
    run_pyelastica(*p0, cfg["t_end"])
    settings = ([("hockle",) + s for s in cfg["hockle"]],
                [("PyElastica",) + s for s in cfg["pyelastica"]])
    walls = {}
    data = {}

    def timed(code, a, b):
        before = loadavg()
        run = (run_hockle if code == "hockle" else run_pyelastica)(a, b, cfg["t_end"])
        after = loadavg()
        k = _key(code, a, b)
        walls.setdefault(k, []).append(run["wall"])
        res["log"].append({"run": k, "wall": run["wall"], "load_before": before,
                           "load_after": after, "utc": time.strftime("%H:%M:%S",
                                                                     time.gmtime())})
        log(f"  {k}: {run['wall']:.2f} s, load {before[0]:.2f} -> {after[0]:.2f}")
        if k not in data:
            data[k] = {"code": code, "a": a, "b": b, "steps": run["steps"],
                       "status": run.get("status", "completed" if run["finite"]
                                         else "non-finite state"),
                       "t": run["t"], **post(run)}

    def references():
        log("references")
        for code, (a, b) in (("hockle", cfg["hockle_ref"]),
                             ("PyElastica", cfg["pyelastica_ref"])):
            timed(code, a, b)

    for rnd in range(cfg["repeats"]):
        if rnd == 1:
            references()
        if rnd >= 1 and time.perf_counter() - t_all > stop_after:
            log(f"round {rnd + 1} skipped: {stop_after:.0f} s spent")
            res["rounds_skipped"] = cfg["repeats"] - rnd
            break
        hs, ps = settings
        order = []
        for i in range(max(len(hs), len(ps))):      # A B A B ...
            if i < len(hs):
                order.append(hs[i])
            if i < len(ps):
                order.append(ps[i])
        for code, a, b in order:
            k = _key(code, a, b)
            if rnd >= 2 and min(walls.get(k, [0.0])) > cfg["repeat_below_s"]:
                continue
            if time.perf_counter() - t_all > stop_after and rnd >= 1:
                continue
            timed(code, a, b)
    if cfg["repeats"] == 1:
        references()
    refs = {"hockle": _key("hockle", *cfg["hockle_ref"]),
            "PyElastica": _key("PyElastica", *cfg["pyelastica_ref"])}
    for k, d in data.items():
        w = walls[k]
        d["walls"] = w
        d["wall"] = statistics.median(w)
        for name, rk in refs.items():
            r = data[rk]
            d["err_vs_" + name] = wr_error(d["t"], d["Wr"], r["t"], r["Wr"])
        d["err_self"] = d["err_vs_" + d["code"]]
        d["err_common"] = max(d["err_vs_hockle"], d["err_vs_PyElastica"])
    res["refs"] = refs
    res["runs"] = data
    res["ratios"] = matched_ratios(data, refs)
    res["load_end"] = loadavg()
    res["total_s"] = time.perf_counter() - t_all
    limiter.restore_original_limits()
    return res


def counts(data: dict, k: str, level: float, measure: str) -> bool:
    """True if the setting k and its next refinement are within ``level`` by
    ``measure`` ("err_self", "err_vs_hockle", "err_vs_PyElastica")."""
    d = data[k]
    e = d[measure]
    if not (np.isfinite(e) and e <= level):
        return False
    rk = _key(d["code"], *refinement(d["code"], d["a"], d["b"]))
    if rk not in data:
        return False
    er = data[rk][measure]
    return bool(np.isfinite(er) and er <= level)


def matched_ratios(data: dict, refs: dict) -> dict:
    """For each level and measure: each code's cheapest counting setting (references
    excluded as candidates) and PyElastica's median wall over hockle's, with the spread
    (ratio of the fastest PyElastica repeat to the slowest hockle one, and the converse)."""
    out = {}
    for measure in ("err_self", "err_vs_hockle", "err_vs_PyElastica"):
        for level in LEVELS:
            best = {}
            for code in ("hockle", "PyElastica"):
                ok = [k for k, d in data.items() if d["code"] == code and k != refs[code]
                      and counts(data, k, level, measure)]
                best[code] = min(ok, key=lambda k: data[k]["wall"]) if ok else None
            item = {"hockle": best["hockle"], "PyElastica": best["PyElastica"],
                    "ratio": None, "low": None, "high": None}
            if best["hockle"] and best["PyElastica"]:
                h, p = data[best["hockle"]], data[best["PyElastica"]]
                item.update(ratio=p["wall"] / h["wall"], low=min(p["walls"]) / max(h["walls"]),
                            high=max(p["walls"]) / min(h["walls"]))
            elif best["hockle"]:
                # every PyElastica setting up to n* fails: one that counts needs n > n*,
                # and costs at least its cheapest n* run (cost grows with n)
                fail = [d for k, d in data.items() if d["code"] == "PyElastica"
                        and k != refs["PyElastica"]]
                if fail:
                    nstar = max(d["a"] for d in fail)
                    w = min(d["wall"] for d in fail if d["a"] == nstar)
                    item.update(bound=w / data[best["hockle"]]["wall"], bound_n=nstar)
            out[f"{measure}@{level:g}"] = item
    return out


# --------------------------------------------------------------------------- JSON / text
def to_json(res: dict) -> dict:
    def clean(x):
        if isinstance(x, dict):
            return {str(k): clean(v) for k, v in x.items()}
        if isinstance(x, (list, tuple)):
            return [clean(v) for v in x]
        if isinstance(x, np.ndarray):
            return clean(x.tolist())
        if isinstance(x, (float, np.floating)):
            return float(x) if np.isfinite(x) else None
        if isinstance(x, np.integer):
            return int(x)
        return x
    out = dict(res)
    out["runs"] = {k: {kk: vv for kk, vv in d.items()} for k, d in res["runs"].items()}
    return clean(out)


def _f(x, fmt="{:.3f}"):
    return "–" if x is None or not np.isfinite(x) else fmt.format(x)


def _pct(x):
    return "–" if x is None or not np.isfinite(x) else f"{100 * x:.2f}"


def figure(res: dict, figdir: Path) -> str:
    """Wr(t) of both references and Wr differences of selected settings; file name."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    runs, refs = res["runs"], res["refs"]
    fig, ax = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for code, ls in (("hockle", "-"), ("PyElastica", "--")):
        r = runs[refs[code]]
        ax[0].plot(r["t"], r["Wr"], ls, label=f"{code} {refs[code].split(':', 1)[1]}")
    t = np.asarray(runs[refs["hockle"]]["t"], float)
    ax[0].plot(t, [end_angle(x) / (2 * np.pi) for x in t], ":k", lw=1, label="Lk = φ/2π")
    ax[0].set_ylabel("turns")
    ax[0].legend(fontsize=8)
    ax[0].set_title("Writhe against time (the references)")
    for k, d in runs.items():
        if d["Wr"] is None or k in refs.values():
            continue
        tt = np.asarray(d["t"], float)
        w = np.asarray([np.nan if v is None else v for v in d["Wr"]], float)
        rr = runs[refs["hockle"]]
        ax[1].plot(rr["t"], np.interp(rr["t"], tt, w) - np.asarray(rr["Wr"]),
                   "-" if d["code"] == "hockle" else "--", lw=0.8,
                   label=f"{d['code']} {k.split(':', 1)[1]}")
    ax[1].set_ylabel("Wr − Wr(hockle reference)")
    ax[1].set_xlabel("t (s)")
    ax[1].legend(fontsize=6, ncol=3)
    fig.tight_layout()
    name = "peer_writhe.png"
    fig.savefig(Path(figdir) / name, dpi=110)
    plt.close(fig)
    return name


def render(res: dict, fig_name: str | None) -> str:
    """The Markdown section (starts with '## ') from the JSON results."""
    cfg, runs, refs = res["config"], res["runs"], res["refs"]
    quick = res.get("quick", False)
    loads = [x for e in res.get("log", []) for x in (e["load_before"][0], e["load_after"][0])]
    L = ["## hockle and PyElastica side by side: twisted rod to plectoneme", ""]
    L.append(f"`nice -n 10 python -m benchmarks.peer_compare{' --quick' if quick else ''}` "
             f"(PyElastica {res['pyelastica_version']}, `pip install -r "
             "benchmarks/requirements-pyelastica.txt`). Measured "
             f"{res.get('utc_start', '?')}-{res.get('utc_end', '?')} UTC in one process, "
             f"{res['total_s']:.0f} s in all, on 2 cores **shared with other jobs**: load "
             f"average (1, 5, 15 min) {res['load_start']} at the start, {res['load_end']} at "
             "the end; every timed run's load before and after is in "
             "`benchmarks/results/peer_compare.json`"
             + (f" (1-min load over the {len(loads)} timed runs: {min(loads):.1f}-"
                f"{max(loads):.1f}, median {statistics.median(loads):.1f})" if loads else "")
             + (f"; {res['rounds_skipped']} round(s) skipped at the time budget"
                if res.get("rounds_skipped") else "")
             + ". The same figures in another hour: `nice -n 10 python "
             "benchmarks/report.py --only pyelastica`."
             + (" **Quick mode: a smoke run, not figures to quote.**" if quick else ""))
    L.append("")
    L.append("**Problem and physics.** PyElastica's `PlectonemesCase` rod (L = 1 m, r = "
             f"0.025 m, 1 kg, E = 1 MPa, G = E/1.5), clamped at s = 0, the end s = L held "
             "laterally, free to slide axially and turned about the axis at 2π·10/50 rad/s "
             f"(ramped over {pc.T_RAMP} s), a 1e-4 N/m imperfection along x, to "
             f"**t = {cfg['t_end']:g} s** (Lk = {end_angle(cfg['t_end']) / (2 * np.pi):.2f} "
             "turns: buckling at about 6.7 s, the collapse into a loop in self-contact at "
             "7.2 s, then the loop interwinding while the twist goes on). **Damping: the same "
             f"Morison drag in both codes** (ρ_f = {pc.RHO_FLUID:g} kg/m³, C_dn = "
             f"{pc.CD_NORMAL}, C_dt = C_dn/π, no added mass; hockle's `fluid`, PyElastica a "
             "numba forcing class, `MorisonLoads` in the script); hockle's case language has "
             "no linear damper, so the example's linear damper is replaced on both sides. "
             f"PyElastica also gets its `LaplaceDissipationFilter` (order {FILTER_ORDER}, "
             "the weak end of the recommended 3-7), the counterpart of hockle's numerical "
             "dissipation of the highest frequencies (generalized-α, ρ∞ = 0.5): without it "
             "position Verlet blew up in the interwinding phase at every Δt tried (n = 25 "
             "at 10.7, 14.8 and 15.6 s for Δt/Δs = 0.011, 0.0055 and 0.0025 s/m; n = 50 at "
             "19.4 s), with it the runs went to 20 s and orders 3 and 5 gave the same event "
             "times to 1 ms. "
             "**Contact: each code's own law**, the remaining physical difference: PyElastica's "
             f"`RodSelfContact` (linear penalty k = {pc.K_CONTACT:g} N/m on overlap, pair "
             f"damper ν = {pc.NU_CONTACT:g} N·s/m while elements overlap) against hockle's "
             f"barrier ρA·k1/gap³ (k1 = {pc.CONTACT['k1']:g} m⁴/s², about a 1-mm gap at the "
             "load of the loop) with a linear damper k3 = "
             f"{pc.CONTACT['k3']:g} acting on all pairs within the {pc.CONTACT['tolerance']:g}-m "
             "tolerance. Neither code can write the other's law. The rod models differ too: "
             "hockle is Kirchhoff (inextensible, unshearable, implicit generalized-α with "
             "ρ∞ = 0.5, Newton, automatic Δt cuts in contact), PyElastica a Cosserat rod "
             "(shear and stretch compliant, explicit position Verlet).")
    L.append("")
    L.append("**Method.** Both codes run in one process, one thread each (NUMBA_NUM_THREADS = "
             "OMP_NUM_THREADS = 1 before numba loads, threadpoolctl limit 1), after a warm-up "
             f"(`solver.compiled.warm_up`, {res['hockle_warmup_s']:.1f} s; PyElastica's numba "
             f"compilation and first call, {res['pyelastica_compile_s']:.1f} s; then one full "
             "run of each code's cheapest setting, untimed), alternating hockle and PyElastica "
             f"settings (A B A B …) over {cfg['repeats']} rounds (settings slower than "
             f"{cfg['repeat_below_s']:g} s run in two rounds only). Wall times: hockle's "
             "`integrate()` with positions every 0.02 s as its only output; PyElastica's "
             "time-step loop with the position copies every 0.02 s; the writhe and the gaps "
             "are computed afterwards for both codes, untimed. The PyElastica harness is the "
             "lean one (plain-float end schedules, one evaluation per call; "
             "`--check-harness`). **Accuracy** is measured on the writhe history over the "
             "whole run (Lk is the prescribed end turn in both codes and Tw = Lk − Wr): "
             "e = ∫|Wr − Wr_ref| dt / ∫|Wr_ref| dt on the reference's output times, against "
             "(a) the code's own finest run (*self*) and (b) the other code's finest run as "
             "well (*common yardstick*: a setting's common error is the larger of its errors "
             "against the two references; the two references differ by the model and "
             "contact-law gap, given below). A setting **counts at a level** only if its "
             "error and the error of its next refinement (hockle (2N, Δt/2), PyElastica "
             "(2n, same Δt/Δs)) are both within it; references are not candidates. Grids: "
             f"hockle {len(cfg['hockle'])} settings (N, Δt) plus the reference "
             f"{tuple(cfg['hockle_ref'])}; PyElastica {len(cfg['pyelastica'])} settings "
             "(n, Δt/Δs) from 0.0055 to 0.015 s/m (in probe runs n = 25 blew up at 0.015 s/m once "
             "in contact, n = 50 ran; Δt/Δs moved Wr by 0.13 % at n = 25 between 0.011 and "
             "0.0055 and by 0.01 % at n = 50 between 0.015 and 0.011, halving Δs by 2.8 %, "
             "so the grid spends its budget on Δs) plus the reference "
             f"{tuple(cfg['pyelastica_ref'])}; PyElastica's n = 160 and 320 runs cost "
             "minutes each, which bounds its grid.")
    L.append("")
    hr, pr = runs[refs["hockle"]], runs[refs["PyElastica"]]
    T = cfg["t_end"]
    total = sum(sum(d["walls"]) for d in runs.values())
    L.append(f"**Horizon.** The example runs 100 s (10 turns in 50 s, then 50 s held); here "
             f"{T:g} s, which covers buckling, the collapse into a loop and the "
             + (f"interwinding (Wr from about 1 to {_f(hr['Wr'][-1], '{:.2f}')} turns in the "
                f"last {T - 10:g} s)" if T > 10 else "loop (the interwinding starts at about "
                "10 s, after this horizon)")
             + ". At this run's rates the PyElastica reference alone would take "
             f"about {pr['wall'] * 100 / T / 60:.0f} min to 100 s (its cost per step hardly "
             "depends on the state: an all-pairs contact check every step) and the timed runs "
             f"of this table about {total * 100 / T / 60:.0f} min, against the ~25 min one "
             "measurement on this shared machine is given; hockle's cost grows in the "
             "interwinding "
             "(in probe runs N = 50, Δt = 0.025 s took 20.9 s to 20 s, N = 200, Δt = 0.00625 s "
             "17.6 s to 12 s, both at load 6-8), so the 100-s figure is a lower bound for it "
             "too. Probe runs to 20 s also found hockle N = 25, Δt = 0.05 s stopping with a "
             "divergence at 17.7 s. The whole 100 s is compared untimed, on the writhe, "
             "below (*The whole horizon*, `benchmarks/peer_long.py`).")
    L.append("")
    L.append(f"Gap between the references: e(PyElastica reference vs hockle reference) = "
             f"**{_pct(pr['err_vs_hockle'])} %**; buckling at {_f(hr['t_buckle'])} s "
             f"(hockle) and {_f(pr['t_buckle'])} s (PyElastica), first contact at "
             f"{_f(hr['t_contact'])} and {_f(pr['t_contact'])} s; final Wr "
             f"{_f(hr['Wr'][-1])} and {_f(pr['Wr'][-1])}. No setting of either code can be "
             "much closer than this to the other code's reference.")
    L.append("")
    L.append("| code | N | Δt (s) | Δt/Δs (s/m) | wall median (s) | min-max (s) | runs | "
             "e self (%) | e vs hockle ref (%) | e vs PyElastica ref (%) | t buckle (s) | "
             "t contact (s) | status |")
    L.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|")

    def sortkey(kv):
        d = kv[1]
        return (d["code"] != "hockle", d["a"], -d["b"])
    for k, d in sorted(runs.items(), key=sortkey):
        n = d["a"]
        if d["code"] == "hockle":
            dt = d["b"]
        else:
            dt = pyelastica_step(n, d["b"])
        ratio = dt * n / pc.LENGTH
        ref = " (ref.)" if k in refs.values() else ""
        L.append(f"| {d['code']}{ref} | {n} | {dt:.3g} | {ratio:.3g} | {d['wall']:.2f} | "
                 f"{min(d['walls']):.2f}-{max(d['walls']):.2f} | {len(d['walls'])} | "
                 f"{_pct(d['err_self'])} | {_pct(d['err_vs_hockle'])} | "
                 f"{_pct(d['err_vs_PyElastica'])} | "
                 f"{_f(d['t_buckle'], '{:.4f}')} | {_f(d['t_contact'], '{:.4f}')} | "
                 f"{d['status']} |")
    L.append("")
    L.append("**Wall time at matched accuracy** (cheapest counting setting of each code; "
             "ratio = PyElastica median / hockle median, in brackets the fastest PyElastica "
             "repeat over the slowest hockle one and the converse):")
    L.append("")
    L.append("| yardstick | level | hockle | PyElastica | PyElastica / hockle |")
    L.append("|---|---|---|---|---|")
    names = {"err_self": "own reference (self-convergence)",
             "err_vs_hockle": "hockle's reference (common)",
             "err_vs_PyElastica": "PyElastica's reference (common)"}
    for measure, label in names.items():
        for level in LEVELS:
            it = res["ratios"][f"{measure}@{level:g}"]

            def desc(k):
                if not k:
                    return "none counts"
                d = runs[k]
                return f"{k.split(':', 1)[1]}: {d['wall']:.2f} s"
            if it["ratio"]:
                r = f"**{it['ratio']:.1f}** ({it['low']:.1f}-{it['high']:.1f})"
            elif it.get("bound"):
                r = (f"> {it['bound']:.1f} (no PyElastica setting up to n = {it['bound_n']} "
                     "counts; the bound is its cheapest run at that n)")
            else:
                r = "–"
            L.append(f"| {label} | {100 * level:g} % | {desc(it['hockle'])} | "
                     f"{desc(it['PyElastica'])} | {r} |")
    L.append("")
    prev = res.get("previous") or {}
    if prev.get("ratios"):
        def rr(rs, key):
            x = rs.get(key) or {}
            if x.get("ratio"):
                return f"{x['ratio']:.1f}"
            return f"> {x['bound']:.1f}" if x.get("bound") else "–"
        L.append(f"Reproduced: the previous full run ({prev.get('utc')} UTC, load "
                 f"{prev.get('load_start')}) gave at 1 % and 0.1 % "
                 + ", ".join(f"{rr(prev['ratios'], f'{m}@{lv:g}')}" for m in
                             ("err_self", "err_vs_hockle") for lv in LEVELS)
                 + " (self-convergence 1 %, 0.1 %; hockle's reference 1 %, 0.1 %) against "
                 + ", ".join(f"{rr(res['ratios'], f'{m}@{lv:g}')}" for m in
                             ("err_self", "err_vs_hockle") for lv in LEVELS) + " here.")
        L.append("")
    if fig_name:
        L.append(f"![Writhe histories](figures/benchmarks/{fig_name})")
        L.append("")
    long_path = HERE / "results" / "peer_long.json"
    if long_path.exists():                 # benchmarks/peer_long.py writes it; not re-run
        L.append(render_long(json.loads(long_path.read_text())))
    hc = res.get("harness_check")
    if hc:
        L.append(f"**The lean harness** (`--check-harness`, n = {hc['n']}, "
                 f"{hc['t_end']:g} s, the old harness's linear damper): final positions differ "
                 f"from `pyelastica_compare`'s harness by at most {hc['max_diff']:.1e} m; wall "
                 f"{hc['lean']:.2f} s against {hc['old']:.2f} s (medians of "
                 f"{hc['repeats']}, interleaved).")
        L.append("")
    L.append(second_peer_text())
    L.append("`benchmarks/pyelastica_compare.py` keeps the physics study of the two codes "
             "(Greenhill thresholds, undamped buckling, the contact-damping sweep, energies); "
             "its wall-time ratios, measured one code after the other with different damping "
             "laws, are superseded by this section.")
    return "\n".join(L) + "\n"


# --------------------------------------------------------------------------- the whole horizon
#: s: the example's time_twist (10 turns; benchmarks.peer_long runs to 100 s)
LONG_T_TWIST = 50.0

#: turns: a writhe jump between two outputs (0.02 s apart) larger than this, in a run that
#: stopped, marks its blow-up; the outputs from there on are left out
BLOWUP_JUMP = 0.5


def trimmed(d: dict) -> dict:
    """The run with t and Wr as arrays, cut before its blow-up (a run that did not
    complete: the first jump of Wr above BLOWUP_JUMP between outputs)."""
    t, wr = np.asarray(d["t"], float), np.asarray(d["Wr"], float)
    if d["status"] != "completed":
        jump = np.flatnonzero(~(np.abs(np.diff(wr)) <= BLOWUP_JUMP))
        if len(jump):
            t, wr = t[:jump[0] + 1], wr[:jump[0] + 1]
    return dict(d, t=t, Wr=wr)


def _compare_wr(a: dict, b: dict, t0: float = 0.0) -> float:
    """max |Wr_a − Wr_b| (turns) over the common outputs with t ≥ t0 (b interpolated)."""
    t_hi = min(a["t"][-1], b["t"][-1])
    m = (a["t"] >= t0) & (a["t"] <= t_hi + 1e-9)
    if not m.any():
        return float("nan")
    return float(np.max(np.abs(a["Wr"][m] - np.interp(a["t"][m], b["t"], b["Wr"]))))


def long_pairs(res: dict) -> dict:
    """Each pair of the long runs' writhe differences (:data:`render_long`'s table)."""
    keys = list(res["runs"])
    pairs = {}
    for i, ka in enumerate(keys):
        for kb in keys[i + 1:]:
            ra, rb = trimmed(res["runs"][ka]), trimmed(res["runs"][kb])
            early = ra["t"] <= 12.0 + 1e-9
            t_hi = min(ra["t"][-1], rb["t"][-1])
            mb = rb["t"] <= t_hi + 1e-9
            pairs[f"{ka} vs {kb}"] = {"t_common": float(t_hi), "all": _compare_wr(ra, rb),
                                      "e_l1": wr_error(ra["t"], ra["Wr"], rb["t"][mb],
                                                            rb["Wr"][mb]),
                                      "held": _compare_wr(ra, rb, LONG_T_TWIST + pc.T_RAMP),
                                      "to_12s": _compare_wr(dict(ra, t=ra["t"][early],
                                                             Wr=ra["Wr"][early]), rb)}
    return pairs


def render_long(res: dict, fig_name: str | None = "peer_long_writhe.png") -> str:
    """The section's part on the whole horizon, from ``benchmarks.peer_long``'s results."""
    runs = {k: trimmed(d) for k, d in res["runs"].items()}
    pairs = long_pairs({"runs": runs})
    L = ["### The whole horizon: writhe toward 100 s (untimed)", ""]
    L.append(
        f"`nice -n 10 python -m benchmarks.peer_long` (PyElastica "
        f"{res.get('pyelastica_version', '?')}). The physics of the section above (same "
        "Morison drag, each code's contact law) with the example's whole schedule: 10 "
        f"turns in {LONG_T_TWIST:g} s (the rate ramped down over 0.5 s), then held to "
        f"{res['t_end']:g} s. One run per setting, one after the other, one thread each; "
        f"{res['total_s']:.0f} s in all, load {res['load_start']} at the start, "
        f"{res['load_end']} at the end (2 shared cores; walls for orientation only).")
    L.append("")
    L.append("| run | status | wall (s) | buckling (s) | first contact (s) | Wr at 12 s | "
             f"Wr at {LONG_T_TWIST:g} s | Wr at the end |")
    L.append("|---|---|---|---|---|---|---|---|")

    def wr_at(d, t):
        return float(np.interp(t, d["t"], d["Wr"])) if d["t"][-1] >= t - 1e-9 else float("nan")
    for k, d in runs.items():
        raw_end = float(np.asarray(res["runs"][k]["t"], float)[-1])
        cut = "" if d["t"][-1] >= raw_end - 1e-9 else ", its blow-up after it left out"
        L.append(f"| {k} | {d['status']} | {d['wall']:.1f} | {_f(d['t_buckle'])} | "
                 f"{_f(d['t_contact'])} | {_f(wr_at(d, 12.0))} | "
                 f"{_f(wr_at(d, LONG_T_TWIST))} | {_f(float(d['Wr'][-1]))} "
                 f"(t = {d['t'][-1]:.2f} s{cut}) |")
    L.append("")
    L.append("| pair | common horizon (s) | max \\|ΔWr\\| to 12 s (turns) | "
             "max \\|ΔWr\\| over the common horizon | "
             f"max \\|ΔWr\\| held ({LONG_T_TWIST + pc.T_RAMP:g} s on) | "
             "e = ∫\\|ΔWr\\| dt / ∫\\|Wr\\| dt over it (%) |")
    L.append("|---|---|---|---|---|---|")
    for k, p in pairs.items():
        L.append(f"| {k} | {_f(p.get('t_common'), '{:.1f}')} | {_f(p['to_12s'])} | "
                 f"{_f(p['all'])} | {_f(p['held'])} | {_pct(p.get('e_l1'))} |")
    ends = {k: float(np.asarray(d["t"], float)[-1]) for k, d in runs.items()}
    done = [k for k in runs if runs[k]["status"] == "completed"]
    if len(done) < len(runs):
        L.append("")
        L.append(
            "Reading. " + ("No run" if not done else f"Only {', '.join(done)}") +
            f" reached {res['t_end']:g} s on this physics (the Morison drag in place of the "
            "example's linear damper; the linear damper was not run this long): hockle's Newton "
            "stopped (diverged; `solver_diverged` where the reason is recorded) and PyElastica's "
            "state went non-finite, each "
            "between " + f"{min(ends.values()):.1f} and {max(ends.values()):.1f} s, as the "
            "plectoneme kept winding (Wr "
            f"{min(float(d['Wr'][-1]) for d in runs.values()):.1f}-"
            f"{max(float(d['Wr'][-1]) for d in runs.values()):.1f} turns at the stops); "
            "halving a setting's step (the runs that share N or n) moved its stop little. "
            "The comparison therefore runs to where both "
            "runs of a pair had got: the codes agree on the buckling and first-contact "
            "times within the figures of the table, and their writhe drifts apart in "
            "the interwinding, by the max |ΔWr| of the pair table.")
    if fig_name:
        L.append("")
        L.append(f"![Writhe to 100 s](figures/benchmarks/{fig_name})")
    return "\n".join(L) + "\n"



def second_peer_text() -> str:
    """The second peer's part of the section: why DiSMech-Newton is not measured, and
    MoorDyn's no-torsion cable comparisons (in water; onto the seabed) read back from
    their own results files (``benchmarks/moordyn_compare.py`` and
    ``benchmarks/moordyn_seabed_compare.py`` write them; not re-run here)."""
    L = ["**Second peer.** *DiSMech-Newton* (`pip install dismech-newton`, 0.1.0.post4 "
         "with newton 1.6.1 and warp-lang 1.19.0; it has a plectoneme example with "
         "self-contact) installs but does not import on this Python 3.11.7: `python -c "
         "'import dismech_newton'` stops in `dismech_newton/contact.py` line 77, `def "
         "snapshot(self) -> Slots | None:` with `TypeError: unsupported operand type(s) "
         "for |: 'Struct' and 'NoneType'` (an annotation evaluated at class creation; the "
         "package declares Python >= 3.10). *MoorDyn* has no torsion and no self-contact, "
         "so it cannot run this plectoneme; the case both it and hockle can express is "
         "measured the same way by `benchmarks/moordyn_compare.py` "
         "(`pip install -r benchmarks/requirements-moordyn.txt`):", ""]
    path = HERE / "results" / "moordyn_compare.json"
    if path.exists():
        from benchmarks import moordyn_compare
        L.append(moordyn_compare.render(json.loads(path.read_text())))
    else:
        L.append("(not run yet)\n")
    path = HERE / "results" / "moordyn_seabed_compare.json"
    if path.exists():                      # benchmarks/moordyn_seabed_compare.py writes it
        from benchmarks import moordyn_seabed_compare
        L.append(moordyn_seabed_compare.render(json.loads(path.read_text())))
    return "\n".join(L)


def headline(res: dict) -> list[str]:
    parts = []
    for level in LEVELS:
        a = res["ratios"][f"err_self@{level:g}"]
        b = res["ratios"][f"err_vs_hockle@{level:g}"]
        def fmt(x):
            if x["ratio"]:
                return f"{x['ratio']:.1f}"
            if x.get("bound"):
                return f"> {x['bound']:.1f}"
            return "n/a (no counting setting)"
        fa, fb = fmt(a), fmt(b)
        parts.append(f"{100 * level:g} %: {fa} (self-convergence), {fb} (against hockle's "
                     "reference)")
    return [f"PyElastica side by side (plectoneme example to {res['config']['t_end']:g} s, "
            "same drag law, interleaved, one thread each; 1-min load "
            f"{res['load_start'][0]:.1f} at the start, {res['load_end'][0]:.1f} at the end): "
            "wall time of PyElastica over hockle at matched writhe-history accuracy, "
            + "; ".join(parts)
            + (" (quick mode)" if res.get("quick") else "") + "."]


def section(figdir: Path, quick: bool = False, stop_after: float | None = None) -> str:
    """Run the study, write benchmarks/results/peer_compare.json and the figure, return
    the Markdown section. stop_after: seconds after which no repeat starts (None: the
    configuration's ``stop_after_s``)."""
    cfg = QUICK if quick else FULL
    stop_after = cfg["stop_after_s"] if stop_after is None else stop_after
    start = time.strftime("%Y-%m-%d %H:%M", time.gmtime())
    res = collect(cfg, log=lambda m: print(m, file=sys.stderr, flush=True),
                  stop_after=stop_after)
    res["harness_check"] = check_harness(t_end=2.0 if quick else 8.0,
                                         repeats=1 if quick else 3)
    res["quick"] = quick
    res["utc_start"], res["utc_end"] = start, time.strftime("%H:%M", time.gmtime())
    res["headline"] = headline(res)
    out = HERE / "results" / f"{NAME}.json"
    if out.exists():                       # the previous full run's ratios, to compare
        old = json.loads(out.read_text())
        if not old.get("quick") and not quick:
            res["previous"] = {"utc": old.get("utc_start"), "ratios": old.get("ratios"),
                               "load_start": old.get("load_start")}
    js = to_json(res)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(js))
    Path(figdir).mkdir(parents=True, exist_ok=True)
    return render(js, figure(js, figdir))


def check_harness(n=25, t_end=8.0, repeats=3) -> dict:
    """The lean harness against pyelastica_compare's (linear damper, same imperfection):
    largest final position difference (m) and the medians of interleaved wall times."""
    run_pyelastica(10, 0.011, 0.05, damping="linear", filter_order=None)
    run_pyelastica(10, 0.011, 0.05, old_harness=True)
    lean, old = [], []
    for _ in range(repeats):
        a = run_pyelastica(n, 0.011, t_end, damping="linear", filter_order=None)
        b = run_pyelastica(n, 0.011, t_end, old_harness=True)
        lean.append(a["wall"])
        old.append(b["wall"])
    return {"n": n, "t_end": t_end, "repeats": repeats,
            "max_diff": float(np.abs(a["pos"] - b["pos"]).max()),
            "lean": statistics.median(lean), "old": statistics.median(old),
            "lean_walls": lean, "old_walls": old, "load": loadavg()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--render", action="store_true", help="rebuild from the saved JSON")
    ap.add_argument("--check-harness", action="store_true")
    ap.add_argument("--stop-after", type=float, default=None,
                    help="seconds after which no repeat of the second and later rounds starts")
    ap.add_argument("--figdir", default=str(ROOT / "docs" / "figures" / "benchmarks"))
    args = ap.parse_args()
    path = HERE / "results" / f"{NAME}.json"
    if args.check_harness:
        hc = check_harness()
        print(json.dumps(hc, indent=1))
        if path.exists():
            js = json.loads(path.read_text())
            js["harness_check"] = hc
            path.write_text(json.dumps(js))
        return
    if args.render:
        js = json.loads(path.read_text())
        print(render(js, figure(js, Path(args.figdir))))
        return
    print(section(Path(args.figdir), quick=args.quick, stop_after=args.stop_after))


if __name__ == "__main__":
    main()
