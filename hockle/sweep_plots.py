"""Figures of a sweep's combined dataset (:func:`service.sweeps.combine_results`).

* the **threshold map** (``<stem>_threshold.png``): each event's time (onset of buckling,
  first contact, Wr reaching 1, 2, ...) against the varied parameter, and the linking
  number at the onset of buckling (the twist a rod takes before it buckles), one curve per
  event with one varied parameter (or a zipped sweep), one colour map per event with two;
* the **writhe of every member** over time (``<stem>_writhe.png``).

Members that failed are marked (a cross) where their value would be. Drawn on
:class:`matplotlib.figure.Figure` objects with the Agg canvas, as :mod:`hockle.plots` does.
"""
from __future__ import annotations

import json
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import xarray as xr
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = ["plot_sweep", "plot_threshold_map", "plot_sweep_writhe", "sweep_axes"]

Notify = Callable[[str], None]
MAX_EVENT_CURVES = 5          # buckling, contact and Wr = 1, 2, 3
MAX_WRITHE_MEMBERS = 24


def _stderr(msg: str) -> None:
    print(msg, file=sys.stderr)


def _save(fig: Figure, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=120)
    return path


def sweep_axes(ds: xr.Dataset) -> list[str]:
    """The coordinates to draw against: the grid's parameter dimensions in order, or for a
    zipped sweep its parameters on ``member`` (the numeric ones; ``member`` when none)."""
    if ds.attrs.get("hockle_sweep_combine") == "zip":
        params = [p["path"] for p in json.loads(ds.attrs.get("hockle_sweep_parameters", "[]"))]
        numeric = [p for p in params if p in ds.coords and ds[p].dtype.kind in "fiu"]
        return numeric[:1] or ["member"]
    return [str(d) for d in ds["member_index"].dims]


def _label(ds: xr.Dataset, name: str) -> str:
    units = ds[name].attrs.get("units") if name in ds.coords else None
    return f"{name} ({units})" if units else name


def _positions(ds: xr.Dataset, name: str) -> tuple[np.ndarray, list[str] | None]:
    values = ds[name].values
    if values.dtype.kind in "fiu":
        return values.astype(float), None
    return np.arange(values.size, dtype=float), [str(v) for v in values]


def _events(ds: xr.Dataset) -> list[str]:
    names = [str(e) for e in ds["event"].values] if "event" in ds.coords else []
    have = [e for e in names if np.isfinite(ds["event_time"].sel(event=e).values).any()]
    return have[:MAX_EVENT_CURVES]


def _failed(ds: xr.Dataset) -> np.ndarray:
    return np.asarray(ds["member_status"].values != "successful")


def plot_threshold_map(ds: xr.Dataset, out_dir: str | Path, stem: str = "sweep",
                       on_skip: Notify | None = _stderr) -> list[Path]:
    """Event times and the linking number at buckling against the varied parameter(s).

    One varied dimension (or a zipped sweep): curves over it. Two: a colour map per event
    (time in s) and one of the linking number at buckling. More: skipped with a message
    (select two with ``ds.sel`` or ``ds.isel`` and call this again)."""
    axes = sweep_axes(ds)
    events = _events(ds)
    if not events:
        if on_skip:
            on_skip("threshold map skipped: no member buckled, touched itself or writhed a "
                    "full turn in its stored outputs")
        return []
    lk = ds.get("event_linking_number")
    lk_onset = (lk.sel(event="buckling_onset") if lk is not None and "buckling_onset" in events
                else None)
    failed = _failed(ds)
    title = str(ds.attrs.get("hockle_sweep_name") or ds.attrs.get("title", "sweep"))
    if len(axes) == 1:
        name = axes[0]
        x, ticks = _positions(ds, name)
        panels = 2 if lk_onset is not None else 1
        fig = Figure(figsize=(7.5, 3.6 * panels), layout="constrained")
        ax = fig.add_subplot(panels, 1, 1)
        for event in events:
            y = ds["event_time"].sel(event=event).values.ravel()
            ax.plot(x, y, "o-", ms=4, label=event.replace("_", " "))
        if failed.any():
            ax.plot(x[failed.ravel()], np.zeros(int(failed.sum())), "x", color="k", ms=8,
                    label="failed member")
        ax.set_ylabel("event time (s)")
        ax.set_title(f"{title}: when each event happens")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        if ticks:
            ax.set_xticks(x, ticks, rotation=30, fontsize=7)
        ax.set_xlabel(_label(ds, name))
        if lk_onset is not None:
            ax2 = fig.add_subplot(panels, 1, 2, sharex=ax)
            ax2.plot(x, lk_onset.values.ravel(), "s-", color="C3", ms=4)
            ax2.set_ylabel("Lk at buckling onset (turns)")
            ax2.set_xlabel(_label(ds, name))
            ax2.set_title("the twist the rod took before it buckled")
            ax2.grid(alpha=0.3)
        return [_save(fig, Path(out_dir) / f"{stem}_threshold.png")]
    if len(axes) != 2:
        if on_skip:
            on_skip(f"threshold map skipped: {len(axes)} varied parameters; it draws one or "
                    "two (select the others with xarray: ds.isel(...))")
        return []
    ydim, xdim = axes
    x, xticks = _positions(ds, xdim)
    y, yticks = _positions(ds, ydim)
    maps = [(f"{e.replace('_', ' ')} (s)", ds["event_time"].sel(event=e)) for e in events[:3]]
    if lk_onset is not None:
        maps.append(("Lk at buckling onset (turns)", lk_onset))
    fig = Figure(figsize=(4.6 * len(maps), 4.0), layout="constrained")
    for k, (label, var) in enumerate(maps):
        ax = fig.add_subplot(1, len(maps), k + 1)
        values = var.transpose(ydim, xdim).values.astype(float)
        mesh = ax.pcolormesh(_edges(x), _edges(y), np.ma.masked_invalid(values),
                             shading="flat", cmap="viridis")
        fig.colorbar(mesh, ax=ax, label=label)
        bad = failed if failed.shape == values.shape else failed.T
        yy, xx = np.nonzero(bad)
        if yy.size:
            ax.plot(x[xx], y[yy], "x", color="r", ms=9, label="failed member")
            ax.legend(fontsize=7, loc="upper right")
        never = np.isnan(values) & ~bad
        yy, xx = np.nonzero(never)
        if yy.size:
            ax.plot(x[xx], y[yy], ".", color="0.5", ms=6)
        if xticks:
            ax.set_xticks(x, xticks, rotation=30, fontsize=7)
        if yticks:
            ax.set_yticks(y, yticks, fontsize=7)
        ax.set_xlabel(_label(ds, xdim))
        ax.set_ylabel(_label(ds, ydim))
        ax.set_title(label.split(" (")[0] + ("" if k else f"\n{title}"), fontsize=9)
    return [_save(fig, Path(out_dir) / f"{stem}_threshold.png")]


def _edges(c: np.ndarray) -> np.ndarray:
    """Cell edges around centres ``c`` (for pcolormesh)."""
    if c.size == 1:
        return np.array([c[0] - 0.5, c[0] + 0.5])
    mid = 0.5 * (c[1:] + c[:-1])
    return np.concatenate([[c[0] - (mid[0] - c[0])], mid, [c[-1] + (c[-1] - mid[-1])]])


def plot_sweep_writhe(ds: xr.Dataset, out_dir: str | Path, stem: str = "sweep",
                      on_skip: Notify | None = _stderr) -> list[Path]:
    """The writhe of every member (up to 24) over time, labelled by its values."""
    if "writhe" not in ds or ds.sizes.get("time", 0) == 0:
        if on_skip:
            on_skip("members' writhe skipped: the sweep has no writhe series")
        return []
    params = [p["path"] for p in json.loads(ds.attrs.get("hockle_sweep_parameters", "[]"))]
    flat = ds["writhe"].stack(_m=[d for d in ds["writhe"].dims if d != "time"])
    n = flat.sizes["_m"]
    fig = Figure(figsize=(8.0, 4.6), layout="constrained")
    ax = fig.add_subplot()
    t = ds["time"].values
    for k in range(min(n, MAX_WRITHE_MEMBERS)):
        member = flat.isel(_m=k)
        label = ", ".join(f"{p.rsplit('.', 1)[-1]}={_fmt(member[p].values)}" for p in params
                          if p in member.coords)
        ax.plot(t, member.values, lw=1.2, label=label or f"member {k}")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("writhe Wr (turns)")
    shown = "" if n <= MAX_WRITHE_MEMBERS else f" (first {MAX_WRITHE_MEMBERS} of {n})"
    ax.set_title(f"writhe of each member{shown}")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2 if n > 8 else 1)
    return [_save(fig, Path(out_dir) / f"{stem}_writhe.png")]


def _fmt(value) -> str:
    value = np.asarray(value).item()
    return f"{value:g}" if isinstance(value, float) else str(value)


def plot_sweep(ds: xr.Dataset, out_dir: str | Path, stem: str = "sweep",
               on_skip: Notify | None = _stderr) -> list[Path]:
    """The threshold map and the members' writhe; returns the paths written."""
    return (plot_threshold_map(ds, out_dir, stem=stem, on_skip=on_skip)
            + plot_sweep_writhe(ds, out_dir, stem=stem, on_skip=on_skip))
