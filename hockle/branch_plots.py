"""The bifurcation diagram of a continuation's branch file (``hockle continue``,
solver/continuation.py ``branch_dataset``): ``hockle plot branch.nc``.

One figure with a panel per measure that changes along the branch, against the parameter
(up to four, picked in this order from :data:`service.branch_view.MEASURES`: the largest
lateral excursion of the centreline from the line through its ends, the end-to-end
distance, the end force and moment along the start tangent, the writhe, the twist, the
total energy); the measures that keep one value along the whole branch are named with that
value under the panels instead of being drawn flat. Round-off is drawn as zero
(:func:`service.branch_view.measures`) and every axis carries its unit. Stable parts (no
unstable mode) are solid, unstable parts dashed and red; folds are marked with triangles,
branch points with circles (open: a pair of modes at once); the branch switched onto at a
branch point starts at that point. A second figure draws the shapes of up to eight stored
points in three views.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from service.branch_view import excursion, measures, parameter_label, parameter_unit

__all__ = ["plot_branch", "excursion"]

#: at most this many panels in the bifurcation diagram
MAX_PANELS = 4


def _bifurcation_y(lam, y, after, p):
    """The measure at a located bifurcation: interpolated between the nearest points on
    either side where it is defined."""
    ok = np.flatnonzero(np.isfinite(y))
    if not ok.size:
        return float("nan")
    before, later = ok[ok <= after], ok[ok > after]
    i = int(before[-1]) if before.size else int(later[0])
    j = int(later[0]) if later.size else i
    if i != j and lam[i] != lam[j]:
        return float(y[i] + (y[j] - y[i]) * (p - lam[i]) / (lam[j] - lam[i]))
    return float(y[i])


def _segments(ax, x, y, stable, part, start=None):
    """Draw y(x) solid where stable, dashed red where not (the joins drawn in both), each
    part of the branch (before and after a switch) on its own, over the points where y is
    defined (a measure of the shape: where it is stored); ``start``: the (x, y) the part
    after a switch leaves from (its branch point)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    for k, p in enumerate(np.unique(part)):
        sel = (part == p) & np.isfinite(y)
        xs, ys, st = x[sel], y[sel], stable[sel]
        if not xs.size:
            continue
        if p > 0 and start is not None:
            xs, ys, st = np.r_[start[0], xs], np.r_[start[1], ys], np.r_[st[:1], st]
        ok = np.isfinite(ys)
        for flag, style in ((True, dict(color="C0", ls="-")), (False, dict(color="C3", ls="--"))):
            yy = np.where(ok & ((st == flag) | np.r_[st[1:] == flag, False]), ys, np.nan)
            ax.plot(xs, yy, lw=1.6, **style,
                    label=("stable" if flag else "unstable") if k == 0 else None)


def _fmt(value: float, units: str) -> str:
    return f"{value:.4g} {units}".strip()


def plot_branch(ds: xr.Dataset, out_dir: Path, stem: str = "branch") -> list[Path]:
    """Write ``<stem>_bifurcation.png`` and ``<stem>_shapes.png`` into ``out_dir``;
    returns their paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    lam = ds["parameter"].values
    path = str(ds.attrs.get("parameter_path", "")) or "parameter"
    xlabel = parameter_label(ds)
    unit = parameter_unit(path)
    unstable = ds["unstable_modes"].values
    stable = unstable == 0
    part = ds["branch"].values if "branch" in ds else np.zeros(lam.size, int)
    found = measures(ds)
    varying = [name for name, m in found.items() if not m["constant"]]
    flat = [name for name, m in found.items() if m["constant"]]
    shown = varying[:MAX_PANELS] or ["excursion"]
    blam = ds["bifurcation_parameter"].values
    bkind = ds["bifurcation_kind"].values
    bafter = ds["bifurcation_after"].values
    bsimple = ds["bifurcation_simple"].values
    switched = int(ds.attrs.get("switched_at", -1))
    leave = [k for k, a in enumerate(bafter) if 0 <= switched and a < switched]

    n = len(shown)
    rows, cols = (2, 2) if n == 4 else (1, n)
    fig = Figure(figsize=(10, 7.5) if rows == 2 else (5 * cols + 0.5, 4.6))
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    for ax, name in zip(axes, shown):
        m = found[name]
        y = m["values"]
        start = None
        if leave:
            k = leave[-1]
            start = (blam[k], _bifurcation_y(lam, y, bafter[k], blam[k]))
        _segments(ax, lam, y, stable, part, start)
        for p, kind, i, simple in zip(blam, bkind, bafter, bsimple):
            yb = _bifurcation_y(lam, y, i, p)
            if kind == "fold":
                ax.plot([p], [yb], "k^", ms=7)
            else:
                ax.plot([p], [yb], "ko", ms=7, mfc="k" if simple else "none")
        ax.set_xlabel(xlabel)
        ax.set_ylabel(f"{m['label']} ({m['units']})")
        ax.grid(alpha=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    from matplotlib.lines import Line2D
    handles += [Line2D([], [], color="k", marker="o", ls=""), Line2D([], [], color="k",
                marker="o", mfc="none", ls=""), Line2D([], [], color="k", marker="^", ls="")]
    labels += ["branch point", "branch point (pair)", "fold"]
    fig.legend(handles, labels, loc="upper center", ncol=5, frameon=False,
               bbox_to_anchor=(0.5, 0.955 if rows == 2 else 0.93))
    fig.suptitle(f"branch in {path}", y=0.995)
    bottom = 0.0
    if flat:
        notes = []
        for name in flat:
            m = found[name]
            v = m["values"][np.isfinite(m["values"])]
            notes.append(f"{m['label']} {_fmt(v[0], m['units'])}" if v.size else
                         f"{m['label']} not stored")
        fig.text(0.5, 0.01, "the same at every point: " + "; ".join(notes), ha="center",
                 va="bottom", fontsize=8, wrap=True)
        bottom = 0.05 if rows == 2 else 0.08
    fig.tight_layout(rect=(0, bottom, 1, 0.92 if rows == 2 else 0.88))
    paths = [_save(fig, out_dir / f"{stem}_bifurcation.png")]

    r = ds["position"].values
    stored = np.flatnonzero(np.all(np.isfinite(r[:, :, 0]), axis=1))
    if stored.size:
        pick = stored[np.unique(np.linspace(0, stored.size - 1, min(8, stored.size)).astype(int))]
        fig = Figure(figsize=(12, 4.2))
        views = fig.subplots(1, 3)
        for (a, b), ax in zip(((0, 1), (0, 2), (1, 2)), views):
            for i in pick:
                ax.plot(r[i, :, a], r[i, :, b], "-" if stable[i] else "--",
                        label=f"{path} = {_fmt(lam[i], unit)}"
                        + ("" if stable[i] else " (unstable)"))
            ax.set_xlabel("xyz"[a] + " (m)")
            ax.set_ylabel("xyz"[b] + " (m)")
            ax.set_aspect("equal", adjustable="datalim")
            ax.grid(alpha=0.3)
        views[0].legend(fontsize=7)
        fig.tight_layout()
        paths.append(_save(fig, out_dir / f"{stem}_shapes.png"))
    return paths


def _save(fig: Figure, path: Path) -> Path:
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=110)
    return path
