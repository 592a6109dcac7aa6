"""Figures of a result dataset, after the seed paper's Figs. 6, 7 and 8.

* :func:`plot_snapshots` (Fig. 6): the centreline at chosen times, each as a 3-D view
  with its three orthogonal projections (x-y, x-z, y-z) beside it, all at equal scale.
* :func:`plot_energies` (Fig. 7): bending, torsional, kinetic and total energy vs time.
* :func:`plot_topology` (Fig. 8): Tw, Wr and Lk vs time, with |Tw + Wr - Lk| below.

Each function takes an :class:`xarray.Dataset` in the layout of :mod:`solver.results` and
an output directory, writes PNG files and returns their paths; when the dataset lacks
the variables a figure needs, it reports that through ``on_skip`` and returns ``[]``.

Figures are drawn on :class:`matplotlib.figure.Figure` objects with the Agg canvas, never
through pyplot, so importing this module changes no global matplotlib state.
"""
from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import xarray as xr
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter

__all__ = [
    "plot_all",
    "plot_snapshots",
    "plot_energies",
    "plot_topology",
    "snapshot_times",
]

Notify = Callable[[str], None]


def _stderr(msg: str) -> None:
    print(msg, file=sys.stderr)


def _save(fig: Figure, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=120)
    return path


def _title(ds: xr.Dataset) -> str:
    title = str(ds.attrs.get("title", "")).strip()
    status = ds.attrs.get("hockle_status")
    if status and status != "completed":
        title = f"{title} ({status})" if title else f"({status})"
    return title


def snapshot_times(
    ds: xr.Dataset,
    times: Sequence[float] | None = None,
    count: int = 5,
    on_skip: Notify | None = _stderr,
) -> list[float]:
    """Output times to draw: the nearest stored time to each requested one.

    Without ``times``, ``count`` times spread evenly over the run (first and last
    included). Requested times outside the stored range by more than one output interval
    are dropped with a message. Duplicates are removed; the result is sorted.
    """
    stored = np.asarray(ds["time"].values, dtype=float)
    if stored.size == 0:
        return []
    if times is None:
        wanted = np.linspace(stored[0], stored[-1], min(count, stored.size))
    else:
        wanted = np.asarray(list(times), dtype=float)
    spacing = float(np.max(np.diff(stored))) if stored.size > 1 else 0.0
    chosen: list[float] = []
    for t in wanted:
        if t < stored[0] - spacing or t > stored[-1] + spacing:
            if on_skip:
                on_skip(
                    f"snapshots: t = {t:g} s is outside the stored times "
                    f"[{stored[0]:g}, {stored[-1]:g}] s; skipped"
                )
            continue
        chosen.append(float(stored[int(np.argmin(np.abs(stored - t)))]))
    return sorted(set(chosen))


def _cube_limits(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and half-width of an axis-aligned cube around (..., 3) points."""
    lo = np.nanmin(points.reshape(-1, 3), axis=0)
    hi = np.nanmax(points.reshape(-1, 3), axis=0)
    centre = 0.5 * (lo + hi)
    half = 0.5 * float(np.max(hi - lo)) * 1.05
    return centre, max(half, 1e-9)


def plot_snapshots(
    ds: xr.Dataset,
    out_dir: str | Path,
    times: Sequence[float] | None = None,
    stem: str = "result",
    on_skip: Notify | None = _stderr,
) -> list[Path]:
    """Fig. 6: centreline snapshots, one row per time: 3-D view, then x-y, x-z, y-z.

    Needs ``position`` (time, s, xyz) in m. All panels share one cubic box that holds
    every drawn snapshot, so shapes compare at equal, undistorted scale. The start end
    (s = 0) is marked with a circle, the far end (s = L) with a square.
    Writes ``<stem>_snapshots.png``.
    """
    if "position" not in ds:
        if on_skip:
            on_skip("snapshots (Fig. 6) skipped: the dataset has no 'position' variable")
        return []
    chosen = snapshot_times(ds, times, on_skip=on_skip)
    if not chosen:
        if on_skip:
            on_skip("snapshots (Fig. 6) skipped: no stored time to draw")
        return []
    pos = ds["position"].transpose("time", "s", "xyz")
    shapes = [np.asarray(pos.sel(time=t).values, dtype=float) for t in chosen]
    centre, half = _cube_limits(np.stack(shapes))
    lims = [(c - half, c + half) for c in centre]

    n = len(chosen)
    fig = Figure(figsize=(15.0, 3.4 * n + 0.6), layout="constrained")
    fig.suptitle(f"{_title(ds)}: centreline snapshots")
    grid = fig.add_gridspec(n, 4, width_ratios=(1.35, 1, 1, 1), wspace=0.08)
    views = (("x", "y", 0, 1), ("x", "z", 0, 2), ("y", "z", 1, 2))
    for row, (t, r) in enumerate(zip(chosen, shapes)):
        ax3 = fig.add_subplot(grid[row, 0], projection="3d")
        ax3.plot(r[:, 0], r[:, 1], r[:, 2], color="C0", lw=1.5)
        ax3.scatter(*r[0], color="C3", marker="o", s=18)
        ax3.scatter(*r[-1], color="C2", marker="s", s=18)
        ax3.set_xlim(*lims[0])
        ax3.set_ylim(*lims[1])
        ax3.set_zlim(*lims[2])
        ax3.set_box_aspect((1, 1, 1))
        ax3.set_xlabel("x (m)")
        ax3.set_ylabel("y (m)")
        ax3.set_zlabel("z (m)")
        ax3.set_title(f"t = {t:g} s")
        ax3.tick_params(labelsize=7)
        for col, (a, b, i, j) in enumerate(views, start=2):
            ax = fig.add_subplot(grid[row, col - 1])
            ax.plot(r[:, i], r[:, j], color="C0", lw=1.2)
            ax.plot(r[0, i], r[0, j], "o", color="C3", ms=4)
            ax.plot(r[-1, i], r[-1, j], "s", color="C2", ms=4)
            ax.set_xlim(*lims[i])
            ax.set_ylim(*lims[j])
            ax.set_aspect("equal", adjustable="box")
            ax.set_xlabel(f"{a} (m)")
            ax.set_ylabel(f"{b} (m)")
            ax.set_title(f"{a}-{b} view, t = {t:g} s", fontsize=9)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
    return [_save(fig, Path(out_dir) / f"{stem}_snapshots.png")]


_ENERGIES = (
    ("energy_bending", "bending strain energy", "C0", "-"),
    ("energy_torsion", "torsional strain energy", "C1", "-"),
    ("energy_kinetic", "kinetic energy", "C2", "-"),
    ("energy_kinetic_fluid", "kinetic energy of added fluid mass", "C2", ":"),
    ("energy_total", "total energy", "k", "-"),
    ("work_in", "work put in at the ends", "0.5", "--"),
)


def plot_energies(
    ds: xr.Dataset, out_dir: str | Path, stem: str = "result", on_skip: Notify | None = _stderr
) -> list[Path]:
    """Fig. 7: bending, torsional, kinetic and total energy (J) against time (s).

    Draws whichever of ``energy_bending``, ``energy_torsion``, ``energy_kinetic``,
    ``energy_total`` are present (plus ``energy_kinetic_fluid`` and the cumulative
    ``work_in`` for the energy balance, when present). Writes ``<stem>_energies.png``.
    """
    needed = ("energy_bending", "energy_torsion", "energy_kinetic", "energy_total")
    if not any(name in ds for name in needed):
        if on_skip:
            on_skip(
                "energies (Fig. 7) skipped: the dataset has none of energy_bending, "
                "energy_torsion, energy_kinetic, energy_total"
            )
        return []
    if ds.sizes.get("time", 0) == 0:
        if on_skip:
            on_skip("energies (Fig. 7) skipped: no stored time")
        return []
    t = np.asarray(ds["time"].values, dtype=float)
    fig = Figure(figsize=(8.0, 4.8), layout="constrained")
    ax = fig.add_subplot()
    for name, label, color, style in _ENERGIES:
        if name in ds:
            marker = "o" if t.size < 3 else None
            ax.plot(t, ds[name].values, style, color=color, label=label, marker=marker, ms=3)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("energy (J)")
    ax.set_title(f"{_title(ds)}: energies")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return [_save(fig, Path(out_dir) / f"{stem}_energies.png")]


def plot_topology(
    ds: xr.Dataset, out_dir: str | Path, stem: str = "result", on_skip: Notify | None = _stderr
) -> list[Path]:
    """Fig. 8: twist Tw, writhe Wr and linking number Lk (turns) against time (s).

    Draws whichever of ``twist``, ``writhe``, ``linking_number`` are present, plus
    Tw + Wr when both are; a small lower panel shows |Tw + Wr - Lk| (``topology_error``,
    or computed from the three when it is absent) on a log scale.
    Writes ``<stem>_topology.png``.
    """
    present = [n for n in ("twist", "writhe", "linking_number") if n in ds]
    if not present:
        if on_skip:
            on_skip(
                "topology (Fig. 8) skipped: the dataset has none of twist, writhe, "
                "linking_number"
            )
        return []
    if ds.sizes.get("time", 0) == 0:
        if on_skip:
            on_skip("topology (Fig. 8) skipped: no stored time")
        return []
    t = np.asarray(ds["time"].values, dtype=float)
    if "topology_error" in ds:
        err = np.asarray(ds["topology_error"].values, dtype=float)
    elif len(present) == 3:
        err = np.abs(ds["twist"].values + ds["writhe"].values - ds["linking_number"].values)
    else:
        err = None
    fig = Figure(figsize=(8.0, 6.0 if err is not None else 4.8), layout="constrained")
    if err is not None:
        ax, ax_err = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1))
    else:
        ax, ax_err = fig.add_subplot(), None
    marker = "o" if t.size < 3 else None
    labels = {
        "twist": "Tw (twist)",
        "writhe": "Wr (writhe)",
        "linking_number": "Lk (linking number)",
    }
    colors = {"twist": "C0", "writhe": "C1", "linking_number": "k"}
    for name in present:
        ax.plot(t, ds[name].values, color=colors[name], label=labels[name], marker=marker, ms=3)
    if "twist" in ds and "writhe" in ds:
        ax.plot(
            t, ds["twist"].values + ds["writhe"].values, "--", color="C3", label="Tw + Wr"
        )
    ax.set_ylabel("turns")
    ax.set_title(f"{_title(ds)}: exchange of twist and writhe")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    if ax_err is not None:
        positive = np.where(err > 0, err, np.nan)
        ax_err.plot(t, positive, color="C4", marker=marker, ms=3)
        if np.any(np.isfinite(positive)):
            ax_err.set_yscale("log")
            ax_err.yaxis.set_minor_formatter(NullFormatter())
        ax_err.set_ylabel("|Tw + Wr - Lk|")
        ax_err.set_xlabel("time (s)")
        ax_err.grid(alpha=0.3)
    else:
        ax.set_xlabel("time (s)")
    return [_save(fig, Path(out_dir) / f"{stem}_topology.png")]


def plot_all(
    ds: xr.Dataset,
    out_dir: str | Path,
    times: Sequence[float] | None = None,
    stem: str = "result",
    on_skip: Notify | None = _stderr,
) -> list[Path]:
    """Figs. 6, 7 and 8 for ``ds`` into ``out_dir``; returns the paths written."""
    paths = plot_snapshots(ds, out_dir, times=times, stem=stem, on_skip=on_skip)
    paths += plot_energies(ds, out_dir, stem=stem, on_skip=on_skip)
    paths += plot_topology(ds, out_dir, stem=stem, on_skip=on_skip)
    return paths
