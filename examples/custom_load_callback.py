"""Custom loads and callbacks
============================

Your own forces and observers, as in PyElastica: a distributed load written as a Python
function, a state-aware load, callbacks at a cadence, and a callback that ends the run.

::

    python examples/custom_load_callback.py            # 100 segments
    python examples/custom_load_callback.py --quick    # 30 segments: seconds
    python examples/custom_load_callback.py --quick --plot   # with the deflections

A twisted rod is pushed sideways by a "finger" (a Gaussian load at mid-span for the first
second) and rests on an elastic foundation that pulls it back to its axis (a load that reads
the rod's position: -k (x, y, 0) N/m). The same rod is run with and without the foundation:
with it, the rod stores more twist before it buckles. A Recorder keeps the mid-span
deflection every half second; a callback stops each run once the writhe passes half a turn.
Loads that are code run in this process only (the service takes case data, never code).
"""
from __future__ import annotations

import argparse

import numpy as np

from hockle.api import Callback, DistributedLoad, Recorder, make_case, simulate, sliding, twisted


def finger(t: float, s: np.ndarray) -> np.ndarray:
    """N/m, global frame: 50 mN/m at mid-span, 5 cm wide, during the first second."""
    if t >= 1.0:
        return np.zeros((s.size, 3))
    bump = 5e-2 * np.exp(-((s - 0.5) / 0.05) ** 2)
    return np.column_stack([bump, np.zeros_like(s), np.zeros_like(s)])


def foundation(k: float) -> DistributedLoad:
    """An elastic foundation of stiffness k (N/m²) toward the rod's initial axis (z)."""
    return DistributedLoad(lambda t, s, state: -k * state.position * [1.0, 1.0, 0.0],
                           uses_state=True, name=f"foundation k={k:g} N/m2")


def run(quick: bool, loads: list) -> tuple:
    case = make_case("finger and foundation", start=twisted(-2.0), end=sliding(0.0),
                     n_segments=30 if quick else 100, dt=0.05, t_end=12.0,
                     fluid={"density": 1000.0},
                     output={"fields": ["position", "energies", "topology"]})
    mid = Recorder(["position", "linking_number"], interval=0.5)
    stop = Callback.when(lambda st: abs(st.writhe) > 0.5, reason="writhe past half a turn")
    ds = simulate(case, callbacks=[mid, stop], loads=loads)
    return ds, mid.arrays()


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").partition("\n")[0])
    parser.add_argument("--quick", action="store_true", help="30 segments")
    parser.add_argument("--plot", action="store_true", help="draw a figure (matplotlib)")
    args = parser.parse_args()
    curves = []
    for label, loads in (("finger only", [finger]),
                         ("finger + foundation", [finger, foundation(2.0)])):
        ds, rec = run(args.quick, loads)
        n = rec["position"].shape[1]
        deflection = np.hypot(rec["position"][:, n // 2, 0], rec["position"][:, n // 2, 1])
        print(f"{label}: {ds.attrs['hockle_status']} at t = {float(ds['time'][-1]):.2f} s "
              f"({ds.attrs.get('hockle_stop_reason', 'to t_end')}), |Lk| then "
              f"{abs(float(ds['linking_number'][-1])):.2f} turns; loads: "
              f"{ds.attrs['hockle_custom_loads']}")
        print("   mid-span deflection (mm) every 0.5 s: "
              + " ".join(f"{1e3 * d:.1f}" for d in deflection))
        curves.append((label, rec["time"], deflection))
    if args.plot:
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7, 4))
        for label, t, d in curves:
            ax.plot(t, 1e3 * d, "o-", label=label)
        ax.set_xlabel("t (s)")
        ax.set_ylabel("mid-span deflection (mm)")
        ax.legend()


if __name__ == "__main__":
    main()
