"""Where a twisted cable forms a loop: a sweep over end tension × residual twist, in free
space, on a frictionless seabed and on a frictional one (docs/hockle.md).

Each member: the seed's cable (2 cm, E 12.5 MPa, G 5 MPa, 1500 kg/m³), 4 m, in water,
straight along x with the residual twist ``initial.twist_rate`` τ, its start held, its far
end held sideways and in rotation and pulled along the axis by a constant tension T (a
sliding end), a lateral push of 1e-3 N/m for the first 2 s as the imperfection; 40
segments, Δt = 0.05 s, 20 s. On the seabed the cable lies on a flat bottom under gravity
(submerged weight 1.54 N/m); with friction μ = 0.5 axially and laterally. A loop forms
where the run's ``loop_formed`` event fires (|Wr| rising through 1 turn; on the seabed
only while the cable touches it: ``solver.results.run_events``); the figure also marks
the largest |Wr| of each member. The line is Greenhill's threshold of a long rod,
M = 2√(B T), i.e. τ = 2√(B T)/C (B = EI, C = GJ).

Run: ``PYTHONPATH=$PWD python3 benchmarks/hockle_threshold.py`` (prints the table and
writes docs/figures/hockle-threshold.png; about a minute of runs on a 2-core machine).
``--quick``: 2 × 2 members per setting, no figure.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hockle.api import sweep  # noqa: E402

L, D, E, G, RHO = 4.0, 0.02, 1.25e7, 5.0e6, 1500.0
B = E * math.pi * D**4 / 64          # N m², bending stiffness
C = G * math.pi * D**4 / 32          # N m², torsional stiffness
TENSION = "boundary.end.translation.2.force"
TWIST = "initial.twist_rate"
SETTINGS = ("free space", "seabed, frictionless", "seabed, friction 0.5")


def base(setting: str) -> dict:
    """The member case of a setting (a dict; tension and twist are set by the sweep)."""
    doc = {"schema_version": 1, "name": f"hockle threshold: {setting}",
           "rod": {"length": L, "youngs_modulus": E, "shear_modulus": G, "density": RHO,
                   "diameter": D},
           "fluid": {"density": 1000.0, "drag_coefficient_normal": 1.2,
                     "drag_coefficient_tangential": 0.02},
           "distributed_forces": [{"value": [0.0, 1e-3, 0.0], "start": 0.0, "end": 2.0}],
           "initial": {"tangent": [1.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0],
                       "twist_rate": 1.0},
           "boundary": {
               "start": {"translation": [{"velocity": 0}] * 3,
                         "rotation": [{"angular_velocity": 0}] * 3},
               "end": {"translation": [{"velocity": 0}, {"velocity": 0}, {"force": 1.0}],
                       "rotation": [{"angular_velocity": 0}] * 3}},
           "numerics": {"n_segments": 40, "dt": 0.05, "t_end": 20.0, "rho_inf": 0.5},
           "output": {"every": 2, "fields": ["position", "kappa", "topology", "bend_radius"]}}
    if setting != "free space":
        doc["gravity"] = [0.0, 0.0, -9.81]
        doc["seabed"] = {"elevation": -D / 2, "normal_damping": 3.0e3}
        if "friction" in setting:
            doc["seabed"]["friction"] = {"axial": 0.5, "lateral": 0.5,
                                         "static_to_kinetic": 1.0, "slip_velocity": 0.01}
    return doc


def run(tensions, twists) -> dict:
    """{setting: combined sweep dataset} and the wall time of each sweep."""
    out = {}
    for setting in SETTINGS:
        t0 = time.perf_counter()
        ds = sweep(base(setting), {TENSION: list(tensions), TWIST: list(twists)}, workers=1)
        ds.attrs["wall_s"] = time.perf_counter() - t0
        out[setting] = ds
    return out


def table(results: dict) -> None:
    for setting, ds in results.items():
        loop = ds["event_time"].sel(event="loop_formed")
        wr = np.abs(ds["writhe"]).max("time")
        print(f"\n{setting} (sweep wall time {ds.attrs['wall_s']:.0f} s): loop formed at t (s) "
              f"[max |Wr|], rows T (N), columns tau (rad/m)")
        print(f"{'T/tau':>8} " + " ".join(f"{tw:>14.2f}" for tw in ds[TWIST].values))
        for i, T in enumerate(ds[TENSION].values):
            cells = []
            for j in range(ds.sizes[TWIST]):
                t = float(loop[i, j])
                status = str(ds["member_status"].values[i, j])
                mark = "failed" if status != "successful" else (
                    "-" if np.isnan(t) else f"{t:.1f}")
                cells.append(f"{mark:>7} [{float(wr[i, j]):4.2f}]")
            print(f"{T:8.2f} " + " ".join(cells))
        print("Greenhill tau_cr(T) = 2 sqrt(B T)/C: " + ", ".join(
            f"{2 * math.sqrt(B * T) / C:.2f}" for T in ds[TENSION].values))


def figure(results: dict, path: Path) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(13.0, 4.2), layout="constrained")
    FigureCanvasAgg(fig)
    for k, (setting, ds) in enumerate(results.items()):
        ax = fig.add_subplot(1, len(results), k + 1)
        T = ds[TENSION].values
        tw = ds[TWIST].values
        loop = ds["event_time"].sel(event="loop_formed").transpose(TENSION, TWIST).values
        wr = np.abs(ds["writhe"]).max("time").transpose(TENSION, TWIST).values
        failed = ds["member_status"].transpose(TENSION, TWIST).values != "successful"
        for i in range(T.size):
            for j in range(tw.size):
                if failed[i, j]:
                    ax.plot(T[i], tw[j], "x", color="r", ms=10)
                    continue
                formed = np.isfinite(loop[i, j])
                ax.plot(T[i], tw[j], "o", ms=11, mfc="C3" if formed else "white",
                        mec="C3" if formed else "0.4")
                ax.annotate(f"{wr[i, j]:.2f}", (T[i], tw[j]), textcoords="offset points",
                            xytext=(0, 9), ha="center", fontsize=7)
        tt = np.linspace(0.0, T.max() * 1.05, 100)
        ax.plot(tt, 2.0 * np.sqrt(B * tt) / C, "k--", lw=1,
                label="Greenhill, long rod: M = 2√(BT)")
        ax.set_xlabel("end tension T (N)")
        ax.set_ylabel("residual twist τ (rad/m)")
        ax.set_title(setting, fontsize=10)
        ax.grid(alpha=0.3)
        if k == 0:
            ax.plot([], [], "o", mfc="C3", mec="C3", label="loop formed (|Wr| through 1)")
            ax.plot([], [], "o", mfc="white", mec="0.4", label="no loop in 20 s")
            ax.legend(fontsize=7, loc="upper left")
    fig.suptitle("Where a twisted 4 m cable loops (label: largest |Wr| in turns); "
                 "benchmarks/hockle_threshold.py", fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.partition("\n")[0])
    parser.add_argument("--quick", action="store_true", help="2 x 2 members, no figure")
    args = parser.parse_args(argv)
    tensions = [0.1, 1.0] if args.quick else [0.0, 0.2, 0.5, 1.0]
    twists = [4.0, 16.0] if args.quick else [4.0, 8.0, 12.0, 16.0]
    results = run(tensions, twists)
    table(results)
    if not args.quick:
        print(f"\nwrote {figure(results, ROOT / 'docs' / 'figures' / 'hockle-threshold.png')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
