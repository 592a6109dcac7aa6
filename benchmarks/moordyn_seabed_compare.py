"""hockle and MoorDyn on a seabed (issue 43): a cable hanging from a fairlead onto a flat
bottom, the catenary with touchdown, at rest and while the fairlead moves away.

Run: ``nice -n 10 python -m benchmarks.moordyn_seabed_compare [--quick] [--formulation
centreline]`` (hockle's scheme; the results file and figures are the default's; MoorDyn-C's
Python package, ``pip install moordyn==2.7.2``; benchmark-only). It prints a Markdown
section and writes ``benchmarks/results/moordyn_seabed_compare.json``.

The case both codes can express (no torsion, no friction: MoorDyn-C has one isotropic
friction coefficient, hockle an axial and a lateral one, so both are left at zero):

* cable: L = 4 m, D = 0.02 m, ρ = 1500 kg/m³ in water (ρ_f = 1000 kg/m³, g = 9.81 m/s²:
  submerged weight w = 1.541 N/m), EI = 9.8e-4 N·m² (the soft cable of
  ``cases/catenary-touchdown.yaml``: bending length √(EI/H) ≈ 2 cm, so it hangs as a
  catenary); the same Morison drag and added mass as ``benchmarks/moordyn_compare.py``;
  MoorDyn's axial stiffness EA = 2e4 N (stretch < 4e-4; hockle is inextensible) with
  half-critical axial damping;
* anchor (s = 0) pinned on the bottom at the origin, fairlead (s = L) pinned h = 1 m above
  it at x = X₀ (the catenary of a = H/w = 1 m: 2.27 m on the bottom), both free to turn;
  t in [0, T_MOVE]: at rest (settling); the fairlead then moves along +x by DX over
  [T_MOVE, T_MOVE + T_RAMP] (smoothstep: the speed rises from and returns to zero; hockle
  a global velocity table of RAMP_KNOTS knots) and is held to T_END; hockle starts from the
  catenary with its curvature jump smoothed (:func:`start_shape`), MoorDyn from its own
  initial-condition solve;
* the seabed: MoorDyn's law, vertical force per node (kBot p − cBot ż)·d·l with p the
  depth of the node (the *centreline*) below WtrDpth (MoorDyn-C ``Line.cpp``, v2.7; its
  input docs: "a pressure applied to the cross-sectional area d·l"), i.e. per unit length
  k = kBot·D, c = cBot·D; hockle's ``normal_stiffness``/``normal_damping`` are per unit
  length (Pa, Pa·s) and act on the penetration of the *surface*, p = ρ − d. So hockle's
  bottom is laid ρ = D/2 below MoorDyn's (both put the centreline of the laid cable on
  z = 0) and k = kBot·D, c = cBot·D with MoorDyn's defaults kBot = 3e6 Pa/m,
  cBot = 3e5 Pa·s/m.

Measured at the end of the rest (means over its last REST_WINDOW s) and of the run (over
its last END_WINDOW s), against each other and against the inextensible catenary with
touchdown (a = H/w from L − √(h² + 2ah) + a·acosh(1 + h/a) = X):

* touchdown s_TD: the arclength from the anchor where the centreline rises δ = 10 mm
  above the laid cable's plane (the nodes' heights by a cubic spline in s); the
  formula's touchdown moved by the same δ, √(δ² + 2aδ). At δ = 1 mm the reading moved
  by 1-2 cm with where the nodes fell, the curve being flat there;
* suspended length L − s_TD;
* fairlead tension (hockle: |reaction_force_end|; MoorDyn: |``GetPointForce``| of the
  coupled fairlead point, the line's end force with its end node's weight and drag);
* the shape at the window's last output, max over s of |r(s) − r_ref(s)| / L.

During the motion: the largest difference of
the fairlead tension and of the touchdown point between the two codes' histories.

Timing: both codes in this process, alternating over rounds after a warm-up, one thread
each, ``os.getloadavg()`` before and after each run; MoorDyn's wall includes its
initial-condition solve (``Init``, dynamic relaxation) and its ``Step`` calls, hockle's is
``integrate()``.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
from benchmarks.moordyn_compare import loadavg, to_json

NAME = "moordyn_seabed_compare"
#: hockle's scheme (``numerics.formulation``; ``--formulation``): the results file and
#: the figures are the default scheme's; another scheme's run only prints
FORMULATION = "goyal"
LENGTH, DIAMETER, DENSITY = 4.0, 0.02, 1500.0
RADIUS = DIAMETER / 2
AREA = math.pi * DIAMETER**2 / 4
YOUNG = 1.25e5
EI = YOUNG * math.pi * DIAMETER**4 / 64
RHO_FLUID, GRAVITY = 1000.0, 9.81
W = (DENSITY - RHO_FLUID) * AREA * GRAVITY        # submerged weight, N/m
CDN, CDT, CA = 1.2, 0.01, 1.0
EA, BA = 2.0e4, -0.5
KBOT, CBOT = 3.0e6, 3.0e5                          # MoorDyn's defaults, Pa/m, Pa s/m
Z0 = -10.0                                         # laid centreline's plane (MoorDyn's bottom)
HEIGHT, A0, DX = 1.0, 1.0, 0.15
OUT_DT, DELTA = 0.02, 1.0e-2
REST_WINDOW, END_WINDOW = 2.0, 5.0     # s: readings averaged over the last of each phase
T_MOVE, T_RAMP, T_END = 10.0, 5.0, 25.0

# hockle at Δt = 0.01-0.02 s (Δt = 0.05 s also completes: N = 40 to 25 s in 1.2 s, its
# output centreline then up to 2.9 mm from the nodes' time route the seabed acts on,
# 1.6 mm at 0.02 s); MoorDyn at Δt/Δs = 0.002 s/m, below its axial wave's Δs/c and its
# bottom damper's 2m/(cBot·D)
FULL = {"t_end": T_END, "hockle": [(40, 0.02), (80, 0.02), (80, 0.01), (160, 0.01)],
        "moordyn": [(40, 0.002), (80, 0.002), (160, 0.002)], "repeats": 3}
QUICK = {"t_end": 12.0, "hockle": [(40, 0.02)], "moordyn": [(40, 0.002)], "repeats": 1}


def span(a: float, h: float = HEIGHT, length: float = LENGTH) -> float:
    """Horizontal distance anchor to fairlead (m) of the inextensible catenary with
    touchdown of parameter a = H/w (m): L − √(h² + 2ah) + a·acosh(1 + h/a)."""
    return length - math.sqrt(h * h + 2 * a * h) + a * math.acosh(1 + h / a)


def catenary(x_fair: float, h: float = HEIGHT, length: float = LENGTH) -> dict:
    """The catenary with touchdown through the anchor (0, 0) and the fairlead (x_fair, h)
    on a frictionless bottom: a (m), H = w a and fairlead tension T = w (a + h) (N),
    suspended length √(h² + 2ah), touchdown arclength s_TD = L − that (m)."""
    a = brentq(lambda a: span(a, h, length) - x_fair, 1e-3, 1e3, xtol=1e-12)
    sus = math.sqrt(h * h + 2 * a * h)
    return {"a": a, "H": W * a, "T": W * (a + h), "suspended": sus, "s_td": length - sus}


def catenary_shape(s: np.ndarray, cat: dict) -> np.ndarray:
    """(len(s), 3) m: points of the catenary at arclengths s from the anchor (z from the
    laid cable's plane)."""
    a, std = cat["a"], cat["s_td"]
    u = np.maximum(s - std, 0.0)
    x = np.where(s < std, s, std + a * np.arcsinh(u / a))
    z = np.sqrt(a * a + u * u) - a
    return np.stack([x, np.zeros_like(s), z], 1)


X0 = span(A0)
X1 = X0 + DX
#: knots of hockle's velocity table over the ramp: piecewise linear through the
#: smoothstep's speed, its displacement DX within DX·(T_RAMP/(RAMP_KNOTS − 1))²/T_RAMP²
#: = 1.5e-5 m (a position table's piecewise-constant speed jolted the tension at
#: every knot)
RAMP_KNOTS = 101
SMOOTH = 0.2                     # m: length over which the start's curvature rises


def _smoothstep(u):
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def fairlead_x(t: float) -> float:
    """The fairlead's x (m) at time t (s): X0, then X0 + DX·S((t − T_MOVE)/T_RAMP) with
    the smoothstep S(u) = 3u² − 2u³ (velocity continuous, zero at both ends), then X1."""
    return float(X0 + DX * _smoothstep((t - T_MOVE) / T_RAMP))


def fairlead_v(t: float) -> float:
    """d/dt of :func:`fairlead_x` (m/s)."""
    u = (t - T_MOVE) / T_RAMP
    return float(DX / T_RAMP * 6.0 * u * (1.0 - u)) if 0.0 < u < 1.0 else 0.0


def start_shape(m: int = 20001) -> np.ndarray:
    """(m, 3) points, uniform in arclength, of hockle's start: the catenary's curvature
    a/(a² + u²) (u = s − s_c) times the smoothstep of u/SMOOTH, integrated from the
    anchor (flat), with (a, s_c) solved so that s = L lands on the fairlead (X0, HEIGHT).
    The catenary itself has a curvature jump 1/a at the touchdown; the smoothed start
    keeps the curvature continuous, so that hockle's start is within O(Δs²) of it however
    the resampling treats a jump (with the curvature taken at the nodes, the jump had put
    the far end 9.9 mm off at N = 80, and the held end then stays there; the node
    curvatures are now dual-cell means, solver/initial.py)."""
    from scipy.integrate import cumulative_trapezoid
    from scipy.optimize import fsolve
    s = np.linspace(0.0, LENGTH, m)

    def curve(p):
        a, sc = p
        u = s - sc
        kap = np.where(u > 0, a / (a * a + u * u), 0.0) * _smoothstep(u / SMOOTH)
        th = cumulative_trapezoid(kap, s, initial=0.0)
        return (cumulative_trapezoid(np.cos(th), s, initial=0.0),
                cumulative_trapezoid(np.sin(th), s, initial=0.0))
    cat = catenary(X0)
    sol = fsolve(lambda p: [curve(p)[0][-1] - X0, curve(p)[1][-1] - HEIGHT],
                 [cat["a"], cat["s_td"] - 0.5 * SMOOTH], xtol=1e-13)
    x, z = curve(sol)
    return np.stack([x, np.zeros_like(x), z], 1)


def hockle_case(n: int, dt: float, t_end: float):
    """The cable as a hockle Case, n segments, step dt (s), outputs every OUT_DT, starting
    on the formula's catenary at X0 (the laid part's centreline on z = Z0)."""
    from solver import Case
    pts = start_shape()[::50].copy()          # 401 points, 1 cm apart
    pts[:, 2] += Z0
    knots = np.linspace(T_MOVE, T_MOVE + T_RAMP, RAMP_KNOTS)
    mom0 = [{"moment": 0.0}] * 3
    return Case.model_validate({
        "schema_version": 1, "name": "moordyn-seabed-compare cable",
        "rod": {"length": LENGTH, "youngs_modulus": YOUNG, "shear_modulus": YOUNG / 2.5,
                "density": DENSITY, "diameter": DIAMETER},
        "fluid": {"density": RHO_FLUID, "added_mass_coefficient": CA,
                  "drag_coefficient_normal": CDN, "drag_coefficient_tangential": CDT},
        "gravity": [0.0, 0.0, -GRAVITY],
        "seabed": {"elevation": Z0 - RADIUS, "normal_stiffness": KBOT * DIAMETER,
                   "normal_damping": CBOT * DIAMETER},
        "initial": {"normal": [0.0, 1.0, 0.0], "centreline": {"points": pts.tolist()}},
        "boundary": {
            "start": {"frame": "global", "translation": [{"position": 0.0},
                      {"position": 0.0}, {"position": Z0}], "rotation": mom0},
            "end": {"frame": "global", "translation": [
                {"velocity": {"t": knots.tolist(),
                              "value": [fairlead_v(t) for t in knots]}},
                {"velocity": 0.0}, {"velocity": 0.0}], "rotation": mom0}},
        "numerics": {"n_segments": int(n), "dt": float(dt), "t_end": float(t_end),
                     "rho_inf": 0.0, "formulation": FORMULATION},
        "output": {"every": max(1, int(round(OUT_DT / dt))),
                   "fields": ["position", "reactions"]},
    })


def measures(t, pos, tension) -> dict:
    """From node positions (T, N+1, 3) (relative to the anchor, material arclengths
    uniform) and fairlead tensions (T,): touchdown s_TD(t) (m) by the δ rule of the
    module docstring, tension (N)."""
    from scipy.interpolate import CubicSpline
    n = pos.shape[1] - 1
    s = np.linspace(0.0, LENGTH, n + 1)
    td = np.full(len(t), np.nan)
    for k in range(len(t)):
        z = pos[k, :, 2]
        above = np.nonzero(z >= DELTA)[0]
        if len(above) == 0 or above[0] == 0:
            continue
        j = above[0]                       # first node from the anchor at δ or higher
        lo, hi = max(j - 3, 0), min(j + 3, n) + 1
        if hi - lo < 4:
            td[k] = s[j - 1] + (DELTA - z[j - 1]) / (z[j] - z[j - 1]) * (s[j] - s[j - 1])
            continue
        roots = CubicSpline(s[lo:hi], z[lo:hi] - DELTA).solve(0.0, extrapolate=False)
        roots = roots[(roots >= s[j - 1] - 1e-12) & (roots <= s[j] + 1e-12)]
        td[k] = roots[0] if len(roots) else \
            s[j - 1] + (DELTA - z[j - 1]) / (z[j] - z[j - 1]) * (s[j] - s[j - 1])
    return {"t": np.asarray(t), "td": td, "tension": np.asarray(tension), "pos": pos}


def run_hockle(n: int, dt: float, t_end: float) -> dict:
    from solver import SolverDivergence, integrate
    case = hockle_case(n, dt, t_end)
    status = "completed"
    t0 = time.perf_counter()
    try:
        ds = integrate(case)
    except SolverDivergence as exc:
        ds, status = exc.partial, f"diverged at t = {exc.t:.3f} s"
    wall = time.perf_counter() - t0
    pos = ds.position.values - np.array([0.0, 0.0, Z0])
    ten = np.linalg.norm(ds.reaction_force_end.values, axis=1)
    out = measures(ds.time.values, pos, ten)
    out.update(wall=wall, status=status, dt=dt)
    if "seabed_touchdown" in ds:
        out["td_own"] = ds.seabed_touchdown.values
    return out


def moordyn_step(n: int, ratio: float) -> float:
    """MoorDyn's time step (s): the largest ≤ ratio·Δs that divides OUT_DT."""
    return OUT_DT / math.ceil(OUT_DT / (ratio * LENGTH / n) - 1e-9)


def moordyn_input(n: int, ratio: float) -> str:
    """MoorDyn v2 input text: the cable from a fixed anchor to a coupled fairlead, the
    bottom at WtrDpth = −Z0 with kBot, cBot, no friction."""
    m = DENSITY * AREA
    return f"""--------------------- MoorDyn Input File ------------------------------------
hockle moordyn_seabed_compare cable
---------------------- LINE TYPES ------------------------------------------
TypeName Diam Mass/m EA BA/-zeta EI Cd Ca CdAx CaAx
(name) (m) (kg/m) (N) (N-s/-) (N-m^2) (-) (-) (-) (-)
cable {DIAMETER!r} {m!r} {EA!r} {BA!r} {EI!r} {CDN!r} {CA!r} {CDT!r} 0.0
---------------------- POINTS --------------------------------
ID Attachment X Y Z Mass Volume CdA Ca
(#) (-) (m) (m) (m) (kg) (m^3) (m^2) (-)
1 Fixed 0 0 {Z0!r} 0 0 0 0
2 Coupled {X0!r} 0 {Z0 + HEIGHT!r} 0 0 0 0
---------------------- LINES --------------------------------------
ID LineType AttachA AttachB UnstrLen NumSegs LineOutputs
(#) (name) (#) (#) (m) (-) (-)
1 cable 1 2 {LENGTH!r} {int(n)} -
---------------------- OPTIONS -----------------------------------------
0 writeLog
{moordyn_step(n, ratio)!r} dtM
{RHO_FLUID!r} rho
{GRAVITY!r} g
{-Z0!r} WtrDpth
{KBOT!r} kBot
{CBOT!r} cBot
0.0 FrictionCoefficient
1 disableOutput
1 disableOutTime
------------------------- need this line --------------------------------------
"""


def run_moordyn(n: int, ratio: float, t_end: float) -> dict:
    """One MoorDyn run: its initial-condition solve (dynamic relaxation) at X0, then
    Step calls of OUT_DT with the fairlead's prescribed position and velocity."""
    import moordyn
    with tempfile.TemporaryDirectory(prefix="hockle-moordyn-") as tmp:
        path = Path(tmp) / "cable.txt"
        path.write_text(moordyn_input(n, ratio))
        fd = os.dup(1)
        t0 = time.perf_counter()
        try:
            with open(os.devnull, "w") as null:
                os.dup2(null.fileno(), 1)
                system = moordyn.Create(str(path))
                moordyn.Init(system, [X0, 0.0, Z0 + HEIGHT], [0.0, 0.0, 0.0])
        finally:
            os.dup2(fd, 1)
            os.close(fd)
        line = moordyn.GetLine(system, 1)
        nn = moordyn.GetLineNumberNodes(line)
        fair = moordyn.GetPoint(system, 2)

        def sample():
            return (np.array([moordyn.GetLineNodePos(line, i) for i in range(nn)]),
                    float(np.linalg.norm(moordyn.GetPointForce(fair))))
        steps = int(round(t_end / OUT_DT))
        p, T = sample()
        ts, ps, tens = [0.0], [p], [T]
        t = 0.0
        for k in range(steps):
            t1 = (k + 1) * OUT_DT
            moordyn.Step(system, [fairlead_x(t1), 0.0, Z0 + HEIGHT],
                         [fairlead_v(t1), 0.0, 0.0], t, OUT_DT)
            t = t1
            p, T = sample()
            ts.append(t)
            ps.append(p)
            tens.append(T)
        wall = time.perf_counter() - t0
        moordyn.Close(system)
    pos = np.array(ps) - np.array([0.0, 0.0, Z0])
    out = measures(np.array(ts), pos, np.array(tens))
    ok = bool(np.isfinite(pos).all())
    out.update(wall=wall, dt=moordyn_step(n, ratio),
               status="completed" if ok else "non-finite state")
    return out


def at(run, t):
    k = int(np.argmin(np.abs(run["t"] - t)))
    return k


def shape_error(run, k, ref_shape_fn) -> float:
    """max over the run's nodes of |r − r_ref(s)| / L at output k."""
    n = run["pos"].shape[1] - 1
    s = np.linspace(0.0, LENGTH, n + 1)
    return float(np.max(np.linalg.norm(run["pos"][k] - ref_shape_fn(s), axis=1)) / LENGTH)


def interp_shape(run, k):
    n = run["pos"].shape[1] - 1
    s_run = np.linspace(0.0, LENGTH, n + 1)
    P = run["pos"][k]
    return lambda s: np.stack([np.interp(s, s_run, P[:, j]) for j in range(3)], 1)


def summarise(run, ref_other, cfg) -> dict:
    """The run's readings at T_MOVE and at the end, against the formula and against
    ref_other (the other code's finest run)."""
    out = {}
    for label, t, xf, win in (("rest", T_MOVE, X0, REST_WINDOW),
                              ("end", cfg["t_end"], fairlead_x(cfg["t_end"]), END_WINDOW)):
        cat = catenary(xf)
        k = at(run, t)
        w = (run["t"] >= t - win - 1e-9) & (run["t"] <= t + 1e-9)
        td_formula = cat["s_td"] + math.sqrt(DELTA**2 + 2 * cat["a"] * DELTA)
        ko = at(ref_other, t)
        td = float(np.mean(run["td"][w]))
        out[label] = {
            "t": float(run["t"][k]), "td": td, "td_range": float(np.ptp(run["td"][w])),
            "suspended": float(LENGTH - td), "tension": float(np.mean(run["tension"][w])),
            "tension_range": float(np.ptp(run["tension"][w])),
            "td_formula": td_formula, "suspended_formula": LENGTH - td_formula,
            "s_td_exact": cat["s_td"], "tension_formula": cat["T"], "a": cat["a"],
            "shape_vs_formula": shape_error(run, k, lambda s: catenary_shape(s, cat)),
            "shape_vs_other": shape_error(run, k, interp_shape(ref_other, ko)),
        }
        if "td_own" in run:
            out[label]["td_own"] = float(run["td_own"][k])
    move = (run["t"] >= T_MOVE - 1e-9) & (run["t"] <= T_MOVE + T_RAMP + 1e-9)
    tt = run["t"][move]
    ten_o = np.interp(tt, ref_other["t"], ref_other["tension"])
    td_o = np.interp(tt, ref_other["t"], ref_other["td"])
    out["move"] = {"max_dT": float(np.max(np.abs(run["tension"][move] - ten_o))),
                   "max_dtd": float(np.nanmax(np.abs(run["td"][move] - td_o)))}
    return out


def collect(cfg: dict, log=print) -> dict:
    import numba
    from threadpoolctl import threadpool_limits
    import solver.compiled
    limiter = threadpool_limits(limits=1)
    numba.set_num_threads(1)
    t_all = time.perf_counter()
    res = {"config": dict(cfg), "load_start": loadavg(), "log": []}
    solver.compiled.warm_up()
    run_hockle(cfg["hockle"][0][0], cfg["hockle"][0][1], 1.0)
    run_moordyn(cfg["moordyn"][0][0], cfg["moordyn"][0][1], 1.0)
    data, walls = {}, {}

    def timed(code, a, b):
        before = loadavg()
        run = (run_hockle if code == "hockle" else run_moordyn)(a, b, cfg["t_end"])
        k = f"{code}:{a:g}:{b:g}"
        walls.setdefault(k, []).append(run["wall"])
        res["log"].append({"run": k, "wall": run["wall"], "load_before": before,
                           "load_after": loadavg()})
        log(f"  {k}: {run['wall']:.3f} s, load {before[0]:.2f}, {run['status']}")
        if k not in data:
            data[k] = dict(run, code=code, a=a, b=b)

    hs = [("hockle",) + s for s in cfg["hockle"]]
    ms = [("MoorDyn",) + s for s in cfg["moordyn"]]
    order = [x for pair in zip(hs, ms) for x in pair] + hs[len(ms):] + ms[len(hs):]
    for rnd in range(cfg["repeats"]):
        for job in order:
            timed(*job)
    finest = {"hockle": "hockle:%g:%g" % hs[-1][1:], "MoorDyn": "MoorDyn:%g:%g" % ms[-1][1:]}
    runs = {}
    for k, d in data.items():
        other = data[finest["MoorDyn" if d["code"] == "hockle" else "hockle"]]
        runs[k] = {"code": d["code"], "a": d["a"], "b": d["b"], "dt": d["dt"],
                   "status": d["status"], "walls": walls[k],
                   "wall": statistics.median(walls[k]),
                   **summarise(d, other, cfg)}
    fin = {c: data[k] for c, k in finest.items()}
    res["history"] = {c: {"t": d["t"], "td": d["td"], "tension": d["tension"]}
                      for c, d in fin.items()}
    res.update(finest=finest, runs=runs, load_end=loadavg(),
               total_s=time.perf_counter() - t_all)
    limiter.restore_original_limits()
    return res


def _f(x, fmt="{:.3f}"):
    return "–" if x is None or (isinstance(x, float) and not np.isfinite(x)) else fmt.format(x)


def render(res: dict) -> str:
    cfg, runs = res["config"], res["runs"]
    L = ["### MoorDyn: a cable hanging onto the seabed (catenary with touchdown)", ""]
    scheme = res.get("formulation", "goyal")
    flag = "" if scheme == "goyal" else f" --formulation {scheme}"
    L.append(
        f"`nice -n 10 python -m benchmarks.moordyn_seabed_compare{flag}` (MoorDyn "
        f"{res.get('moordyn_version', '?')}; hockle's {scheme} scheme). A 4-m cable (D = 0.02 m, 1500 kg/m³ in water, "
        "w = 1.541 N/m, EI = 9.8e-4 N·m², no friction) pinned on a flat bottom at one end "
        f"and {HEIGHT:g} m above it at the other, X₀ = {X0:.4f} m away (the catenary of "
        f"a = H/w = {A0:g} m); at rest to {T_MOVE:g} s, then the fairlead moves {DX:g} m "
        f"away over {T_RAMP:g} s and is held to {cfg['t_end']:g} s. The same seabed law "
        "in both: MoorDyn's defaults kBot = 3e6 Pa/m, cBot = 3e5 Pa·s/m act on the "
        "centreline's depth times the diameter, so hockle's per-length "
        f"normal_stiffness = kBot·D = {KBOT * DIAMETER:g} Pa and normal_damping = cBot·D = "
        f"{CBOT * DIAMETER:g} Pa·s on the surface's penetration, its bottom laid D/2 lower. "
        f"Interleaved, one thread each, {res['total_s']:.0f} s in all; load "
        f"{res['load_start']} at the start, {res['load_end']} at the end (2 shared cores). "
        f"Readings: means over the last {REST_WINDOW:g} s of the rest and the last "
        f"{END_WINDOW:g} s of the run (in brackets the range of T there); touchdown s_TD: "
        "the arclength from the anchor where the centreline rises 10 mm above the laid "
        "plane (the formula's touchdown moved by the same rule); shape: max over s of "
        "|r − r_ref| / L at the window's end; 'other': the other code's finest run.")
    L.append("")
    L.append("| code | N | Δt (s) | wall median (s) | runs | s_TD rest (m) | T rest (N) | "
             "shape rest vs formula / other (%) | s_TD end (m) | T end (N) | "
             "shape end vs formula / other (%) | moving: max ΔT (N), max Δs_TD (m) vs other "
             "| status |")
    L.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for k, d in sorted(runs.items(), key=lambda kv: (kv[1]["code"] != "hockle",
                                                    kv[1]["a"], -kv[1]["b"])):
        r, e, m = d["rest"], d["end"], d["move"]
        fin = " (finest)" if k in res["finest"].values() else ""
        L.append(
            f"| {d['code']}{fin} | {d['a']} | {d['dt']:.3g} | {d['wall']:.2f} | "
            f"{len(d['walls'])} | {_f(r['td'])} | {_f(r['tension'])} ({_f(r['tension_range'])}) | "
            f"{_f(100 * r['shape_vs_formula'], '{:.2f}')} / "
            f"{_f(100 * r['shape_vs_other'], '{:.2f}')} | {_f(e['td'])} | "
            f"{_f(e['tension'])} ({_f(e['tension_range'])}) | "
            f"{_f(100 * e['shape_vs_formula'], '{:.2f}')} / "
            f"{_f(100 * e['shape_vs_other'], '{:.2f}')} | {_f(m['max_dT'])}, "
            f"{_f(m['max_dtd'])} | {d['status']} |")
    any_run = next(iter(runs.values()))
    r, e = any_run["rest"], any_run["end"]
    L.append(
        f"| formula | – | – | – | – | {_f(r['td_formula'])} | {_f(r['tension_formula'])} "
        f"| 0 | {_f(e['td_formula'])} | {_f(e['tension_formula'])} | 0 | – | a = "
        f"{r['a']:.4f} m, {e['a']:.4f} m; touchdown {r['s_td_exact']:.3f} m, "
        f"{e['s_td_exact']:.3f} m |")
    fh, fm = runs[res["finest"]["hockle"]], runs[res["finest"]["MoorDyn"]]
    L.append("")

    def rel(x, ref):
        return f"{100 * (x - ref) / ref:+.2f} %"
    L.append(
        f"Reading (finest runs). At rest the touchdown is {fh['rest']['td']:.3f} m "
        f"(hockle) and {fm['rest']['td']:.3f} m (MoorDyn) against {r['td_formula']:.3f} m, "
        f"the tension {fh['rest']['tension']:.3f} and {fm['rest']['tension']:.3f} N against "
        f"{r['tension_formula']:.3f} N ({rel(fh['rest']['tension'], r['tension_formula'])}, "
        f"{rel(fm['rest']['tension'], r['tension_formula'])}), the shapes within "
        f"{100 * fh['rest']['shape_vs_other']:.2f} % of L of each other. After the move: "
        f"touchdown {fh['end']['td']:.3f} and {fm['end']['td']:.3f} m against "
        f"{e['td_formula']:.3f} m, tension {fh['end']['tension']:.3f} and "
        f"{fm['end']['tension']:.3f} N against {e['tension_formula']:.3f} N "
        f"({rel(fh['end']['tension'], e['tension_formula'])}, "
        f"{rel(fm['end']['tension'], e['tension_formula'])}); MoorDyn's tension still swings "
        f"by {fm['end']['tension_range']:.3f} N over the last {END_WINDOW:g} s (hockle's by "
        f"{fh['end']['tension_range']:.3f} N): its extensible line on a frictionless bottom, "
        "damped along the axis only by the small tangential drag. While the fairlead moves "
        f"the two histories differ by at most {fh['move']['max_dT']:.3f} N in tension "
        "(MoorDyn's tension jolts where the motion starts and stops, the figure) and "
        f"{fh['move']['max_dtd']:.3f} m in touchdown. hockle's touchdown swings by about "
        "2 cm in the first seconds: it starts from the smoothed catenary, not its own "
        "equilibrium, MoorDyn from its initial-condition solve.")
    walls = []
    for n in sorted({d["a"] for d in runs.values()}):
        h = [d for d in runs.values() if d["code"] == "hockle" and d["a"] == n]
        m = [d for d in runs.values() if d["code"] == "MoorDyn" and d["a"] == n]
        if h and m:
            hb = max(h, key=lambda d: d["b"])
            walls.append(f"N = {n}: {m[0]['wall'] / hb['wall']:.1f} (hockle Δt = "
                         f"{hb['b']:g} s)")
    if walls:
        L.append("")
        L.append("Wall time, MoorDyn's median over hockle's at the same N (the table's settings, "
                 "not a matched-accuracy ratio): " + "; ".join(walls)
                 + ".")
    L.append("")
    L.append(f"![Tension and touchdown histories](figures/benchmarks/{FIGURE})")
    L.append("")
    L.append(
        "Remaining differences of the seabed laws (MoorDyn-C 2.7 `Line.cpp` against "
        "`solver/seabed.py`; docs/seabed.md): MoorDyn's contact is at the centreline (a "
        "node deeper than WtrDpth) and its force vertical, hockle's at the surface "
        "(centreline distance minus the radius) along the bottom's normal: the same on a "
        "flat bottom once hockle's bottom is laid D/2 lower, as here, but not on a slope. "
        "MoorDyn's kBot, cBot are pressures per metre of penetration on the projected area "
        "d·l, so its stiffness per unit length is kBot·D; hockle's normal_stiffness is per "
        "unit length (k = kBot·D here; hockle's default 3e6 Pa equals MoorDyn's default "
        "only for D = 1 m, and is 1/D times stiffer otherwise). MoorDyn's damper "
        "−cBot·D·ż is unclamped (it jumps at first touch and pulls a lifting cable down); "
        "hockle's is clamped to the spring's force. Friction (off here): MoorDyn-C has one "
        "isotropic coefficient acting on the node's velocity with a saturated linear law "
        "(FricDamp), MoorDyn-F axial and transverse coefficients; hockle has axial and "
        "lateral ones, a C¹ regularised law, at the contact point of the rotating section.")
    return "\n".join(L) + "\n"


FIGURE = "moordyn_seabed.png"


def figure(res: dict, figdir: Path) -> str:
    """Fairlead tension and touchdown of both codes' finest runs against time, with the
    quasi-static catenary of the fairlead's position; written to figdir/FIGURE."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
    t = np.linspace(0.0, res["config"]["t_end"], 501)
    cats = [catenary(fairlead_x(x)) for x in t]
    a1.plot(t, [c["T"] for c in cats], color="0.5", lw=2.5, alpha=0.5,
            label="catenary of the fairlead's position (quasi-static)")
    a2.plot(t, [c["s_td"] + math.sqrt(DELTA**2 + 2 * c["a"] * DELTA) for c in cats],
            color="0.5", lw=2.5, alpha=0.5)
    for (code, h), col in zip(res["history"].items(), ("C0", "C3")):
        key = res["finest"][code]
        lab = f"{code} N = {key.split(':')[1]}"
        a1.plot(h["t"][1:], h["tension"][1:], color=col, lw=1.0, label=lab)
        a2.plot(h["t"], h["td"], color=col, lw=1.0)
    a1.set_ylabel("fairlead tension (N)")
    a2.set_ylabel(f"touchdown s (m), {1e3 * DELTA:g} mm rule")
    a2.set_xlabel("t (s)")
    a1.legend(fontsize=8)
    for a in (a1, a2):
        a.grid(alpha=0.3)
    a1.set_title("Cable onto the seabed: hockle and MoorDyn, fairlead moved 10-15 s")
    fig.tight_layout()
    Path(figdir).mkdir(parents=True, exist_ok=True)
    fig.savefig(Path(figdir) / FIGURE, dpi=110)
    plt.close(fig)
    return FIGURE


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--render", action="store_true", help="rebuild from the saved JSON")
    ap.add_argument("--formulation", choices=["goyal", "centreline"], default="goyal",
                    help="hockle's scheme (default goyal; centreline only prints)")
    args = ap.parse_args()
    global FORMULATION
    FORMULATION = args.formulation
    path = HERE / "results" / f"{NAME}.json"
    figdir = ROOT / "docs" / "figures" / "benchmarks"
    if args.render:
        res = json.loads(path.read_text())
        figure(res, figdir)
        print(render(res))
        return
    from importlib.metadata import version
    res = collect(QUICK if args.quick else FULL,
                  log=lambda m: print(m, file=sys.stderr, flush=True))
    res["moordyn_version"] = version("moordyn")
    res["quick"] = args.quick
    res["utc"] = time.strftime("%Y-%m-%d %H:%M", time.gmtime())
    res["formulation"] = FORMULATION
    js = to_json(res)
    if not args.quick and FORMULATION == "goyal":
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(js))
        figure(js, figdir)
    print(render(js))


if __name__ == "__main__":
    for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS"):
        os.environ[_var] = "1"
    main()
