"""The tension reading's threshold measured with hockle itself (docs/seed-example.md,
"The tension reading", computation (b)).

The seed case's rod (cases/goyal-writhing.yaml: D(s), E, G, ρ, water) without contact, at
reduced resolution, is twisted quickly (sin² rate over 2 s) to exactly Lk = 4 turns of
end rotation and held there, with a dead tension T on the sliding end (f3 = T, v1 = v2 =
0, all rotations held; start clamped). A small lateral force pulse then disturbs it (as in
tests/test_greenhill.py). Above the critical tension the straight rod is stable (the
deflection stays bounded); below it the deflection grows exponentially at a rate σ with
σ² linear in (T_cr − T) near the threshold (a conservative system's eigenvalue crossing
zero; the same extrapolation as tests/test_greenhill.py::test_greenhill_sharp). We fit
σ² against T at three tensions below the threshold and read T_cr at σ² = 0, and check the
stable side directly.

    python benchmarks/seed_tension_threshold.py [n_segments ...]

Prints σ for each T and the extrapolated T_cr, per resolution. A few seconds per run at
100 segments on the 2-core machine.
"""
from __future__ import annotations

import copy
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
LK = 4.0                                   # turns held
RAMP, PUSH_AT, PUSH = 2.0, 2.5, 0.2        # s: twist ramp, start and length of the push


def hold_case(tension, n_segments=100, dt=0.02, t_end=8.0, push=1e-5):
    """The seed case's rod held at Lk = 4 turns under dead tension ``tension`` (N)."""
    from solver.case import Case, parse_text

    spec = copy.deepcopy(parse_text((ROOT / "cases/goyal-writhing.yaml").read_text()))
    phi = 2 * math.pi * LK                          # end rotation; −ω3 gives Lk > 0
    tt = np.linspace(0.0, RAMP, 401)
    rate = -(phi / RAMP) * (1 - np.cos(2 * np.pi * tt / RAMP))
    n = int(round(PUSH / dt))
    spec["distributed_forces"] = [
        {"value": [push * np.sin(np.pi * k / n) ** 2, 0.0, 0.0],
         "start": PUSH_AT + (k - 0.5) * dt, "end": PUSH_AT + (k + 0.5) * dt,
         "s_range": [0.2, 0.45]} for k in range(1, n)]
    spec["boundary"]["start"]["rotation"][2] = {
        "angular_velocity": {"t": tt.tolist(), "value": rate.tolist()}}
    spec["boundary"]["end"]["translation"][2] = {"force": float(tension)}
    spec.pop("contact", None)
    spec["numerics"].update({"n_segments": n_segments, "dt": dt, "t_end": t_end,
                             "newton": {"tolerance": 1e-11, "max_iterations": 30}})
    spec["output"] = {"every": 1, "fields": ["position", "topology"]}
    return Case.model_validate(spec)


def lateral_history(tension, **kw):
    from solver.simulation import integrate

    ds = integrate(hold_case(tension, **kw))
    t = ds.time.values
    lateral = np.linalg.norm(ds.position.values[:, :, :2], axis=2).max(axis=1)
    return t, lateral, ds


def growth_rate(t, lateral, t0=PUSH_AT + PUSH + 0.3, cap=1e-4):
    """σ (1/s): least-squares slope of log(deflection) from t0 (after the push) until the
    deflection first reaches ``cap`` (m, still linear) or the run ends. For a stable rod
    the response oscillates with a bounded amplitude and σ ≈ 0 (or < 0 with damping)."""
    m = t >= t0
    tt, ww = t[m], lateral[m]
    over = np.nonzero(ww >= cap)[0]
    if over.size:
        tt, ww = tt[:over[0]], ww[:over[0]]
    return np.polyfit(tt, np.log(ww), 1)[0], ww.max() / ww[0]


def measure(n_segments, tensions, stable_tension):
    out = []
    for T in tensions:
        t0 = time.perf_counter()
        t, lat, ds = lateral_history(T, n_segments=n_segments)
        sigma, gain = growth_rate(t, lat)
        lk = float(ds.linking_number.values[-1])
        print(f"N={n_segments} T={T:.3f} N: sigma={sigma:.4f} 1/s (gain {gain:.3g}), "
              f"Lk={lk:.4f} ({time.perf_counter() - t0:.0f} s)", flush=True)
        out.append(sigma)
    sig = np.array(out)
    t_cr = np.polyfit(np.square(sig), tensions, 1)[1]
    print(f"N={n_segments}: T_cr from sigma^2 -> 0: {t_cr:.3f} N", flush=True)
    t, lat, _ = lateral_history(stable_tension, n_segments=n_segments)
    sigma, gain = growth_rate(t, lat)
    print(f"N={n_segments} T={stable_tension:.3f} N (stable side): sigma={sigma:.4f} 1/s, "
          f"max/first deflection after the push {gain:.2f}", flush=True)
    return t_cr


if __name__ == "__main__":
    ns = [int(a) for a in sys.argv[1:]] or [100]
    for n in ns:
        measure(n, np.array([8.8, 8.95, 9.05]), 9.2)
