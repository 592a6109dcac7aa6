"""hockle and MoorDyn interleaved on a no-torsion cable case (issue 43's second peer): a
1-m cable pinned at one end, released horizontal, swinging down through still water.

Run: ``nice -n 10 python -m benchmarks.moordyn_compare [--quick]`` (MoorDyn-C's Python
package, ``pip install moordyn==2.7.2``; benchmark-only). It prints a Markdown section and
writes ``benchmarks/results/moordyn_compare.json``.

MoorDyn has neither torsion nor self-contact, so it cannot run the plectoneme of
``benchmarks/peer_compare.py``; this case is what both codes can express:

* cable: L = 1 m, D = 0.02 m, ρ = 4000 kg/m³ (1.257 kg/m), bending stiffness
  EI = 0.01 N·m² (hockle: E = EI/(πD⁴/64), G = E/3; MoorDyn: its ``EI`` column);
  MoorDyn's axial stiffness EA = 1e5 N (stretch ~1e-4 under the weight; hockle is
  inextensible) with its axial damping at half critical (BA = −0.5);
* water ρ_f = 1000 kg/m³ at rest, gravity 9.81 m/s² (buoyant weight 9.25 N/m in both);
  Morison loads in both codes with the same coefficients: C_dn = 1.2 on D·l, C_dt = 0.01
  on πD·l, normal added mass C_a = 1, no axial added mass;
* s = 0 pinned (hockle: zero velocity, zero moment; MoorDyn: a fixed point), s = L free
  (hockle: zero force and moment; MoorDyn: a free point of no mass or volume), the cable
  straight and horizontal at t = 0, both at rest; run to T_END.

Timing: both codes in this process, alternating (A B A B …) over rounds after a warm-up,
one thread each, ``os.getloadavg()`` before and after each run. hockle's wall is
``integrate()`` with positions every 0.02 s; MoorDyn's is its ``Step`` calls, one per
0.02 s, with the tip position read after each (its own time step inside,
:func:`moordyn_step`). Accuracy: the tip's path, e = mean over the outputs of
|r_tip − r_tip,ref| / L, against each code's finest run and against the other's; a
setting counts at a level only if its refinement is within it too (hockle (2N, Δt/2),
MoorDyn (2n, same Δt/Δs)).
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

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
NAME = "moordyn_compare"
LENGTH, DIAMETER, DENSITY = 1.0, 0.02, 4000.0
AREA = math.pi * DIAMETER**2 / 4
EI = 0.01
YOUNG = EI / (math.pi * DIAMETER**4 / 64)
RHO_FLUID, GRAVITY = 1000.0, 9.81
CDN, CDT, CA = 1.2, 0.01, 1.0
EA, BA = 1.0e5, -0.5
DEPTH, Z0 = 50.0, -5.0
OUT_DT = 0.02
T_END = 5.0

FULL = {"t_end": T_END, "hockle": [(10, 0.02), (20, 0.02), (20, 0.01), (40, 0.01),
                                   (40, 0.005), (80, 0.005), (80, 0.0025)],
        "hockle_ref": (160, 0.00125),
        # (n, Δt/Δs s/m); the axial wave crosses a segment in Δs/√(EA/m) = 3.5e-3 Δs s
        "moordyn": [(10, 0.002), (20, 0.002), (40, 0.002), (80, 0.002), (20, 0.001),
                    (40, 0.001)],
        "moordyn_ref": (160, 0.002), "repeats": 3}
QUICK = {"t_end": 1.0, "hockle": [(10, 0.02)], "hockle_ref": (20, 0.01),
         "moordyn": [(10, 0.002)], "moordyn_ref": (20, 0.002), "repeats": 1}
LEVELS = (0.01, 0.001)


def hockle_case(n: int, dt: float, t_end: float):
    """The cable as a hockle Case: n segments, step dt (s), positions every OUT_DT."""
    from solver import Case
    zero_v, zero_f, zero_m = {"velocity": 0.0}, {"force": 0.0}, {"moment": 0.0}
    return Case.model_validate({
        "schema_version": 1, "name": "moordyn-compare cable",
        "rod": {"length": LENGTH, "youngs_modulus": YOUNG, "shear_modulus": YOUNG / 3.0,
                "density": DENSITY, "diameter": DIAMETER},
        "fluid": {"density": RHO_FLUID, "added_mass_coefficient": CA,
                  "drag_coefficient_normal": CDN, "drag_coefficient_tangential": CDT},
        "gravity": [0.0, 0.0, -GRAVITY],
        "initial": {"tangent": [1.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]},
        "boundary": {"start": {"translation": [zero_v] * 3, "rotation": [zero_m] * 3},
                     "end": {"translation": [zero_f] * 3, "rotation": [zero_m] * 3}},
        "numerics": {"n_segments": int(n), "dt": float(dt), "t_end": float(t_end)},
        "output": {"every": max(1, int(round(OUT_DT / dt))), "fields": ["position"]},
    })


def run_hockle(n: int, dt: float, t_end: float) -> dict:
    """One hockle run: {"t" (T,) s, "tip" (T, 3) m from the pin, "wall" s, "status"}."""
    from solver import SolverDivergence, integrate
    case = hockle_case(n, dt, t_end)
    status = "completed"
    t0 = time.perf_counter()
    try:
        ds = integrate(case)
    except SolverDivergence as exc:
        ds, status = exc.partial, f"diverged at t = {exc.t:.3f} s"
    wall = time.perf_counter() - t0
    return {"t": ds.time.values, "tip": ds.position.values[:, -1, :], "wall": wall,
            "status": status}


def moordyn_step(n: int, ratio: float) -> float:
    """MoorDyn's time step (s): the largest ≤ ratio·Δs that divides OUT_DT."""
    return OUT_DT / math.ceil(OUT_DT / (ratio * LENGTH / n) - 1e-9)


def moordyn_input(n: int, ratio: float) -> str:
    """MoorDyn v2 input text of the cable with n segments and time step
    :func:`moordyn_step` (no CFL factor given: MoorDyn then takes dtM as it is)."""
    m = DENSITY * AREA
    return f"""--------------------- MoorDyn Input File ------------------------------------
hockle moordyn_compare cable
---------------------- LINE TYPES ------------------------------------------
TypeName Diam Mass/m EA BA/-zeta EI Cd Ca CdAx CaAx
(name) (m) (kg/m) (N) (N-s/-) (N-m^2) (-) (-) (-) (-)
cable {DIAMETER!r} {m!r} {EA!r} {BA!r} {EI!r} {CDN!r} {CA!r} {CDT!r} 0.0
---------------------- POINTS --------------------------------
ID Attachment X Y Z Mass Volume CdA Ca
(#) (-) (m) (m) (m) (kg) (m^3) (m^2) (-)
1 Fixed 0 0 {Z0!r} 0 0 0 0
2 Free {LENGTH!r} 0 {Z0!r} 0 0 0 0
---------------------- LINES --------------------------------------
ID LineType AttachA AttachB UnstrLen NumSegs LineOutputs
(#) (name) (#) (#) (m) (-) (-)
1 cable 1 2 {LENGTH!r} {int(n)} -
---------------------- OPTIONS -----------------------------------------
0 writeLog
{moordyn_step(n, ratio)!r} dtM
{RHO_FLUID!r} rho
{GRAVITY!r} g
{DEPTH!r} WtrDpth
1 disableOutput
1 disableOutTime
------------------------- need this line --------------------------------------
"""


def run_moordyn(n: int, ratio: float, t_end: float) -> dict:
    """One MoorDyn run (no initial-condition solve: the straight cable at rest); the same
    dict as :func:`run_hockle`, tip relative to the pin, plus "dt" (its step, s)."""
    import moordyn
    with tempfile.TemporaryDirectory(prefix="hockle-moordyn-") as tmp:
        path = Path(tmp) / "cable.txt"
        path.write_text(moordyn_input(n, ratio))
        fd = os.dup(1)                          # MoorDyn prints its set-up to stdout
        try:
            with open(os.devnull, "w") as null:
                os.dup2(null.fileno(), 1)
                system = moordyn.Create(str(path))
                moordyn.Init_NoIC(system, [], [])
        finally:
            os.dup2(fd, 1)
            os.close(fd)
        line = moordyn.GetLine(system, 1)
        last = moordyn.GetLineNumberNodes(line) - 1
        steps = int(round(t_end / OUT_DT))
        ts, tips = [0.0], [moordyn.GetLineNodePos(line, last)]
        t = 0.0
        t0 = time.perf_counter()
        for _ in range(steps):
            moordyn.Step(system, [], [], t, OUT_DT)
            t += OUT_DT
            ts.append(t)
            tips.append(moordyn.GetLineNodePos(line, last))
        wall = time.perf_counter() - t0
        moordyn.Close(system)
    dt = moordyn_step(n, ratio)
    tip = np.array(tips) - np.array([0.0, 0.0, Z0])
    ok = bool(np.isfinite(tip).all())
    return {"t": np.array(ts), "tip": tip, "wall": wall, "dt": dt,
            "status": "completed" if ok else "non-finite state"}


def tip_error(run: dict, ref: dict) -> float:
    """Mean over the reference's output times of |r_tip − r_tip,ref| / L (the run's tip
    interpolated linearly onto them); NaN for a failed or short run."""
    if not np.isfinite(run["tip"]).all() or run["t"][-1] < ref["t"][-1] - 0.5 * OUT_DT:
        return float("nan")
    tip = np.stack([np.interp(ref["t"], run["t"], run["tip"][:, k]) for k in range(3)], 1)
    return float(np.mean(np.linalg.norm(tip - ref["tip"], axis=1)) / LENGTH)


def loadavg():
    return [round(x, 2) for x in os.getloadavg()]


def _key(code, a, b):
    return f"{code}:{a:g}:{b:g}"


def refinement(code, a, b):
    return (2 * a, b / 2) if code == "hockle" else (2 * a, b)


def collect(cfg: dict, log=print) -> dict:
    """Warm up, run the interleaved rounds and the references, measure."""
    import numba
    from threadpoolctl import threadpool_limits
    import solver.compiled
    limiter = threadpool_limits(limits=1)
    numba.set_num_threads(1)
    t_all = time.perf_counter()
    res = {"config": dict(cfg), "load_start": loadavg(), "log": []}
    solver.compiled.warm_up()
    run_hockle(*cfg["hockle"][0], cfg["t_end"])
    run_moordyn(*cfg["moordyn"][0], cfg["t_end"])
    data, walls = {}, {}

    def timed(code, a, b):
        before = loadavg()
        run = (run_hockle if code == "hockle" else run_moordyn)(a, b, cfg["t_end"])
        k = _key(code, a, b)
        walls.setdefault(k, []).append(run["wall"])
        res["log"].append({"run": k, "wall": run["wall"], "load_before": before,
                           "load_after": loadavg()})
        log(f"  {k}: {run['wall']:.3f} s, load {before[0]:.2f}")
        data.setdefault(k, {"code": code, "a": a, "b": b, "t": run["t"], "tip": run["tip"],
                            "status": run["status"], "dt": run.get("dt", b)})

    hs = [("hockle",) + s for s in cfg["hockle"]]
    ms = [("MoorDyn",) + s for s in cfg["moordyn"]]
    order = [x for pair in zip(hs, ms) for x in pair] + hs[len(ms):] + ms[len(hs):]
    for rnd in range(cfg["repeats"]):
        for job in order:
            timed(*job)
        if rnd == 0:
            timed("hockle", *cfg["hockle_ref"])
            timed("MoorDyn", *cfg["moordyn_ref"])
    refs = {"hockle": _key("hockle", *cfg["hockle_ref"]),
            "MoorDyn": _key("MoorDyn", *cfg["moordyn_ref"])}
    for k, d in data.items():
        d["walls"] = walls[k]
        d["wall"] = statistics.median(walls[k])
        for name, rk in refs.items():
            d["err_vs_" + name] = tip_error(d, data[rk])
        d["err_self"] = d["err_vs_" + d["code"]]
    res.update(refs=refs, runs=data, load_end=loadavg(), total_s=time.perf_counter() - t_all)
    res["ratios"] = ratios(data, refs)
    limiter.restore_original_limits()
    return res


def counts(data, k, level, measure):
    d = data[k]
    rk = _key(d["code"], *refinement(d["code"], d["a"], d["b"]))
    return bool(np.isfinite(d[measure]) and d[measure] <= level and rk in data
                and np.isfinite(data[rk][measure]) and data[rk][measure] <= level)


def ratios(data, refs):
    """MoorDyn's cheapest counting median wall over hockle's, per level and yardstick."""
    out = {}
    for measure in ("err_self", "err_vs_hockle", "err_vs_MoorDyn"):
        for level in LEVELS:
            best = {}
            for code in ("hockle", "MoorDyn"):
                ok = [k for k, d in data.items() if d["code"] == code and k != refs[code]
                      and counts(data, k, level, measure)]
                best[code] = min(ok, key=lambda k: data[k]["wall"]) if ok else None
            item = dict(best, ratio=None)
            if best["hockle"] and best["MoorDyn"]:
                h, m = data[best["hockle"]], data[best["MoorDyn"]]
                item.update(ratio=m["wall"] / h["wall"], low=min(m["walls"]) / max(h["walls"]),
                            high=max(m["walls"]) / min(h["walls"]))
            out[f"{measure}@{level:g}"] = item
    return out


def _pct(x):
    return "–" if x is None or not np.isfinite(x) else f"{100 * x:.3f}"


def render(res: dict) -> str:
    """The Markdown text of the results."""
    cfg, runs, refs = res["config"], res["runs"], res["refs"]
    L = ["### MoorDyn: a no-torsion cable swinging down in water", ""]
    L.append(f"`nice -n 10 python -m benchmarks.moordyn_compare` (MoorDyn "
             f"{res.get('moordyn_version', '?')}, Python package `moordyn`). MoorDyn has no "
             "torsion and no self-contact, so it cannot run the plectoneme; the case both can "
             "express is a cable pinned at one end, released horizontal and swinging down "
             "through still water (L = 1 m, D = 0.02 m, 4000 kg/m³, EI = 0.01 N·m², the same "
             "Morison drag and added mass, buoyant weight 9.25 N/m; MoorDyn's line is "
             "extensible, EA = 1e5 N, with half-critical axial damping; hockle is "
             f"inextensible), to {cfg['t_end']:g} s. Interleaved, one thread each, "
             f"{res['total_s']:.0f} s in all; load {res['load_start']} at the start, "
             f"{res['load_end']} at the end (2 shared cores). Error: the tip's path, mean "
             "|r_tip − r_tip,ref| / L over the outputs every 0.02 s; counting rule and "
             "yardsticks as above (hockle (2N, Δt/2), MoorDyn (2n, same Δt/Δs)).")
    L.append("")
    L.append("| code | N | Δt (s) | wall median (s) | min-max (s) | runs | e self (%) | "
             "e vs hockle ref (%) | e vs MoorDyn ref (%) | status |")
    L.append("|---|---|---|---|---|---|---|---|---|---|")
    for k, d in sorted(runs.items(), key=lambda kv: (kv[1]["code"] != "hockle",
                                                    kv[1]["b"] if kv[1]["code"] == "MoorDyn"
                                                    else 0, kv[1]["a"], -kv[1]["b"])):
        dt = d["b"] if d["code"] == "hockle" else d["dt"]
        extra = "" if d["code"] == "hockle" else f" ({d['b']:g}·Δs)"
        L.append(f"| {d['code']}{' (ref.)' if k in refs.values() else ''} | {d['a']} | "
                 f"{dt:.3g}{extra} | {d['wall']:.3f} | {min(d['walls']):.3f}-"
                 f"{max(d['walls']):.3f} | {len(d['walls'])} | {_pct(d['err_self'])} | "
                 f"{_pct(d['err_vs_hockle'])} | {_pct(d['err_vs_MoorDyn'])} | {d['status']} |")
    L.append("")
    L.append("| yardstick | level | hockle | MoorDyn | MoorDyn / hockle |")
    L.append("|---|---|---|---|---|")
    names = {"err_self": "own reference", "err_vs_hockle": "hockle's reference",
             "err_vs_MoorDyn": "MoorDyn's reference"}
    for measure, label in names.items():
        for level in LEVELS:
            it = res["ratios"][f"{measure}@{level:g}"]

            def desc(k):
                return "none counts" if not k else \
                    f"{k.split(':', 1)[1]}: {runs[k]['wall']:.3f} s"
            r = (f"**{it['ratio']:.2f}** ({it['low']:.2f}-{it['high']:.2f})"
                 if it["ratio"] else "–")
            L.append(f"| {label} | {100 * level:g} % | {desc(it['hockle'])} | "
                     f"{desc(it['MoorDyn'])} | {r} |")
    prev = res.get("previous") or {}
    if prev.get("ratios"):
        def ratio(rs, key):
            x = (rs.get(key) or {}).get("ratio")
            return "–" if x is None else f"{x:.2f}"
        L.append("")
        L.append(f"Reproduced: this run ({res.get('utc', '?')} UTC) against the previous one "
                 f"({prev.get('utc') or '?'} UTC), MoorDyn / hockle at 1 % and 0.1 % "
                 "(self-convergence): "
                 f"{ratio(res['ratios'], 'err_self@0.01')} and "
                 f"{ratio(res['ratios'], 'err_self@0.001')} against "
                 f"{ratio(prev['ratios'], 'err_self@0.01')} and "
                 f"{ratio(prev['ratios'], 'err_self@0.001')}.")
    return "\n".join(L) + "\n"


def to_json(res):
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
    return clean(res)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--render", action="store_true", help="rebuild from the saved JSON")
    args = ap.parse_args()
    path = HERE / "results" / f"{NAME}.json"
    if args.render:
        print(render(json.loads(path.read_text())))
        return
    from importlib.metadata import version
    res = collect(QUICK if args.quick else FULL,
                  log=lambda m: print(m, file=sys.stderr, flush=True))
    res["moordyn_version"] = version("moordyn")
    res["quick"] = args.quick
    res["utc"] = time.strftime("%Y-%m-%d %H:%M", time.gmtime())
    if path.exists():                      # the previous run's ratios, for reproducibility
        old = json.loads(path.read_text())
        res["previous"] = {"utc": old.get("utc"), "ratios": old.get("ratios")}
    js = to_json(res)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(js))
    print(render(js))


if __name__ == "__main__":
    for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS"):
        os.environ[_var] = "1"
    main()
