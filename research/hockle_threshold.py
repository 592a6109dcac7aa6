"""Where a twisted cable forms a loop (docs/hockle.md), two protocols on the seed's cable
(2 cm, E 12.5 MPa, G 5 MPa, 1500 kg/m³) 4 m long in water, in free space, on a frictionless
seabed and on a frictional one (μ = 0.5 axially and laterally; submerged weight 1.54 N/m).

**Slack × twist** (the default): the member is ``cases/seabed-hockle.yaml`` (its lay
imperfection, self-contact law and seabed) with the far end moved inward by the slack δ
(a trapezoid of end velocity, ramps of 1 s, from 1 s to 5 s, as in the case), then held to
8 s: no pull-back. Swept: δ × the residual twist τ (``initial.twist_rate``, both ends held
in rotation so Lk = τL/2π is kept), 120 segments on the bottom and 160 in free space
(:data:`SLACK_SEGMENTS`), Δt = 0.05 s. A loop forms where ``loop_formed`` fires
(the first self-contact or |Wr| through 1 turn; on the seabed only while the cable touches
it: ``solver.results.run_events``); the figure also writes the smallest bend radius of the
run. Free-space reference: a rod clamped at both ends under no end force buckles under its
twisting moment M = Cτ at ML/B = 8.9868 (Greenhill's problem with clamped ends: the root
μ of tan(μ/2) = μ/2; docs/benchmarks.md §2 verifies it), i.e. τ = 8.99 B/(C L) =
2.81 rad/m; an end moved in adds compression and lowers it. Buckling is not yet a loop.

**Tension × twist** (``--tension``): straight along x with the twist, the start held, the far
end held sideways and in rotation and pulled along the axis by a constant tension T (a
sliding end), a lateral push of 1e-3 N/m for the first 2 s as the imperfection; 40
segments, Δt = 0.05 s, 20 s, no self-contact. The line is Greenhill's threshold of a long
rod, M = 2√(B T), i.e. τ = 2√(B T)/C (B = EI, C = GJ).

Run: ``PYTHONPATH=$PWD nice -n 10 python3 -m research.hockle_threshold`` (prints the
table and writes docs/figures/hockle-slack-threshold.png; 3 sweeps of 3 × 4 members in one
process, about 12 minutes at a load of 6 to 8 on 2 cores; ``--save DIR`` keeps the sweeps'
NetCDF files, ``--load DIR`` redraws from them, ``--only SETTING --save DIR`` re-runs one);
``--tension`` (writes docs/figures/hockle-threshold.png; about 11 s); ``--quick``: 2 × 2
members per setting, no figure; ``--grid N:DT``: the slack map's members on N segments with
step DT (s), no figure (``--only "seabed, friction 0.5" --grid 240:0.025``: the map with
friction on a grid twice as fine in s and t, against the resolution the map's figure has;
docs/hockle.md, "Resolution").
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
from hockle.api import sweep

L, D, E, G, RHO = 4.0, 0.02, 1.25e7, 5.0e6, 1500.0
B = E * math.pi * D**4 / 64          # N m², bending stiffness
C = G * math.pi * D**4 / 32          # N m², torsional stiffness
TENSION = "boundary.end.translation.2.force"
TWIST = "initial.twist_rate"
SLACK = "boundary.end.translation.0.velocity"
CASE = ROOT / "cases" / "seabed-hockle.yaml"
RAMP = (1.0, 2.0, 4.0, 5.0)          # s: knots of the end's velocity trapezoid
#: segments of a slack member: on the bottom 120 (3.3 cm; at 80 the case's loop cannot be
#: closed by Newton); in free space, where a member costs seconds, 160 (at 120 Newton fails
#: there at 8 turns before |Wr| reaches 1)
SLACK_SEGMENTS = {"free space": 160, "seabed, frictionless": 120, "seabed, friction 0.5": 120}
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
        if setting == "seabed, friction 0.5":
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
                 "research/hockle_threshold.py", fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def slack_velocity(slack: float) -> dict:
    """The end's velocity table (m/s along x, global) that moves it inward by ``slack`` (m):
    a trapezoid over :data:`RAMP`, whose area is ``slack``."""
    t = RAMP
    v = slack / (0.5 * (t[1] - t[0]) + (t[2] - t[1]) + 0.5 * (t[3] - t[2]))
    return {"t": list(t), "value": [0.0, -round(v, 9), -round(v, 9), 0.0]}


def slack_of(value) -> float:
    """The slack (m) of a sweep coordinate value of :data:`SLACK` (the table's JSON text)."""
    import json

    table = json.loads(value) if isinstance(value, str) else value
    t, v = table["t"], table["value"]
    return float(-np.trapezoid(v, t)) if hasattr(np, "trapezoid") else float(-np.trapz(v, t))


def slack_base(setting: str, grid: tuple | None = None) -> dict:
    """The slack-protocol member of a setting: cases/seabed-hockle.yaml moved in and held
    (a dict; the end's velocity table and the twist are set by the sweep); ``grid``:
    (segments, Δt s) in place of :data:`SLACK_SEGMENTS` and the case's Δt."""
    from solver.case import parse_text

    doc = parse_text(CASE.read_bytes(), CASE.suffix, str(CASE))
    doc["name"] = f"hockle slack threshold: {setting}"
    doc["boundary"]["end"]["translation"][0] = {"velocity": slack_velocity(0.8)}
    doc["numerics"].update(n_segments=SLACK_SEGMENTS[setting], t_end=8.0)
    if grid is not None:              # the same output times on the other step
        interval = doc["output"]["every"] * doc["numerics"]["dt"]
        doc["numerics"].update(n_segments=grid[0], dt=grid[1])
        doc["output"]["every"] = max(1, round(interval / grid[1]))
    doc["output"]["fields"] = ["position", "topology", "contact", "bend_radius"]
    if setting == "free space":
        doc.pop("seabed")
        doc.pop("gravity")
    elif setting == "seabed, frictionless":
        doc["seabed"].pop("friction")
    return doc


def run_slack(slacks, twists, save: Path | None = None, settings=SETTINGS,
              grid: tuple | None = None) -> dict:
    """{setting: combined sweep dataset} of the slack protocol, with each sweep's wall time;
    each sweep is written to ``save``/<setting>.nc when given; ``grid`` as
    :func:`slack_base`'s."""
    out = {}
    for setting in settings:
        t0 = time.perf_counter()
        ds = sweep(slack_base(setting, grid), {SLACK: [slack_velocity(x) for x in slacks],
                                         TWIST: list(twists)}, workers=1)
        ds.attrs["wall_s"] = time.perf_counter() - t0
        print(f"{setting}: {ds.attrs['wall_s']:.0f} s", flush=True)
        if save is not None:
            save.mkdir(parents=True, exist_ok=True)
            ds.to_netcdf(save / f"{setting.replace(' ', '_').replace(',', '')}.nc")
        out[setting] = ds
    return out


def load_slack(folder: Path) -> dict:
    import xarray as xr

    return {setting: xr.load_dataset(folder / f"{setting.replace(' ', '_').replace(',', '')}.nc")
            for setting in SETTINGS}


def _slack_cells(ds):
    """(slacks (m), twists (rad/m), loop time, smallest bend radius, largest |Wr|, failed,
    last time reached), the arrays over (slack, twist); a failed member's values are those
    of its run up to the failure."""
    ds = ds.transpose(SLACK, TWIST, ...)
    slacks = np.array([slack_of(v) for v in ds[SLACK].values])
    twists = np.asarray(ds[TWIST].values, dtype=float)
    loop = ds["event_time"].sel(event="loop_formed").values
    radius = ds["bend_radius_min"].min("time").values
    wr = np.abs(ds["writhe"]).max("time").values
    failed = ds["member_status"].values != "successful"
    reached = ds["member_t_reached"].values
    return slacks, twists, loop, radius, wr, failed, reached


def slack_table(results: dict) -> None:
    for setting, ds in results.items():
        slacks, twists, loop, radius, wr, failed, reached = _slack_cells(ds)
        wall = ds.attrs.get("wall_s", float("nan"))
        print(f"\n{setting} (sweep wall time {wall:.0f} s): loop formed at t (s) "
              f"[smallest bend radius m, largest |Wr|], rows slack (m), columns tau (rad/m); "
              f"fN: the member failed at t = N s")
        print(f"{'slack/tau':>9} " + " ".join(f"{tw:>24.2f}" for tw in twists))
        for i, x in enumerate(slacks):
            cells = []
            for j in range(twists.size):
                t = loop[i, j]
                mark = "-" if np.isnan(t) else f"{t:.1f}"
                if failed[i, j]:
                    mark += f" f{reached[i, j]:.1f}"
                cells.append(f"{mark:>10} [{radius[i, j]:5.3f} {wr[i, j]:4.2f}]")
            print(f"{x:9.2f} " + " ".join(f"{c:>24}" for c in cells))
        for i, j in zip(*np.nonzero(failed)):
            print(f"  failed at slack {slacks[i]:.2f}, tau {twists[j]:.2f}: "
                  f"{ds.transpose(SLACK, TWIST, ...)['member_message'].values[i, j][:160]}")
    print(f"Greenhill, clamped ends, no end force: tau = 8.99 B/(C L) = "
          f"{8.9868 * B / (C * L):.2f} rad/m")


def slack_figure(results: dict, path: Path) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(14.0, 5.0), layout="constrained")
    FigureCanvasAgg(fig)
    tau_c = 8.9868 * B / (C * L)
    for k, (setting, ds) in enumerate(results.items()):
        ax = fig.add_subplot(1, len(results), k + 1)
        slacks, twists, loop, radius, wr, failed, reached = _slack_cells(ds)
        for i in range(slacks.size):
            for j in range(twists.size):
                formed = np.isfinite(loop[i, j])
                ax.plot(slacks[i], twists[j], "o", ms=11, mfc="C3" if formed else "white",
                        mec="C3" if formed else "0.4")
                lines = [f"R {100 * radius[i, j]:.0f} cm"]
                if formed:
                    lines.insert(0, f"loop {loop[i, j]:.1f} s")
                if failed[i, j]:
                    ax.plot(slacks[i], twists[j], "x", color="k", ms=9)
                    lines.insert(0, f"failed {reached[i, j]:.1f} s")
                ax.annotate("\n".join(lines), (slacks[i], twists[j]),
                            textcoords="offset points", xytext=(0, 9), ha="center",
                            va="bottom", fontsize=6.5, linespacing=1.0)
        ax.axhline(tau_c, color="k", ls="--", lw=1,
                   label="Greenhill, clamped, no end force: ML/B = 8.99")
        ax.set_xlim(slacks.min() - 0.12, slacks.max() + 0.12)
        ax.set_ylim(0.0, twists.max() * 1.22)
        ax.set_xlabel("end slack δ (m, end moved in over 1-5 s)")
        ax.set_ylabel("residual twist τ (rad/m)")
        ax.set_title(setting, fontsize=10)
        ax.grid(alpha=0.3)
        if k == 0:
            ax.plot([], [], "o", mfc="C3", mec="C3", label="loop formed (label: when)")
            ax.plot([], [], "o", mfc="white", mec="0.4", label="no loop by 8 s")
            ax.plot([], [], "x", color="k", label="run failed (values up to then)")
            ax.legend(fontsize=7, loc="lower right")
    fig.suptitle("Where a twisted 4 m cable loops under end slack (R: smallest bend radius); "
                 "research/hockle_threshold.py", fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.partition("\n")[0])
    parser.add_argument("--quick", action="store_true", help="2 x 2 members, no figure")
    parser.add_argument("--tension", action="store_true",
                        help="the tension x twist protocol instead of slack x twist")
    parser.add_argument("--save", type=Path, help="write the slack sweeps' NetCDF files here")
    parser.add_argument("--load", type=Path, help="redraw the slack map from --save's files")
    parser.add_argument("--only", choices=SETTINGS, action="append",
                        help="run only this setting of the slack map (with --save: to "
                             "replace one sweep's file before --load)")
    parser.add_argument("--grid", metavar="N:DT",
                        help="the slack map's members on N segments with step DT (s) "
                             "instead of the map's (a resolution check; no figure)")
    args = parser.parse_args(argv)
    grid = None
    if args.grid:
        n, dt = args.grid.split(":")
        grid = (int(n), float(dt))
    if args.tension:
        tensions = [0.1, 1.0] if args.quick else [0.0, 0.2, 0.5, 1.0]
        twists = [4.0, 16.0] if args.quick else [4.0, 8.0, 12.0, 16.0]
        results = run(tensions, twists)
        table(results)
        if not args.quick:
            print(f"\nwrote {figure(results, ROOT / 'docs' / 'figures' / 'hockle-threshold.png')}")
        return 0
    slacks = [0.2, 0.8] if args.quick else [0.2, 0.5, 0.8]
    twists = ([2 * math.pi * n / L for n in (2, 6)] if args.quick
              else [2 * math.pi * n / L for n in (2, 4, 6, 8)])
    results = (load_slack(args.load) if args.load
               else run_slack(slacks, twists, args.save, tuple(args.only or SETTINGS), grid))
    slack_table(results)
    if not args.quick and not args.only and grid is None:
        out = ROOT / "docs" / "figures" / "hockle-slack-threshold.png"
        print(f"\nwrote {slack_figure(results, out)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
