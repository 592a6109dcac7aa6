"""The bifurcation diagram of a continuation's branch file (``hockle continue``,
solver/continuation.py ``branch_dataset``): ``hockle plot branch.nc``.

One figure of four panels against the parameter: the largest lateral excursion of the
centreline from the line through its ends, the end force and moment along the start
tangent, the writhe and twist (turns) and the total energy. Stable parts (no unstable
mode) are solid, unstable parts dashed and red; folds are marked with triangles, branch
points with circles (open: a pair of modes at once). A second figure draws the shapes of
up to eight stored points in three views.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = ["plot_branch", "excursion"]


def excursion(ds: xr.Dataset) -> np.ndarray:
    """(point,) the largest distance (m) of a node from the straight line through the
    rod's ends (NaN where the shape is not stored)."""
    r = ds["position"].values
    a, b = r[:, :1, :], r[:, -1:, :]
    axis = b - a
    norm = np.linalg.norm(axis, axis=-1, keepdims=True)
    u = np.where(norm > 0, axis / np.where(norm > 0, norm, 1.0), 0.0)
    d = r - a
    perp = d - np.sum(d * u, axis=-1, keepdims=True) * u
    return np.max(np.linalg.norm(perp, axis=-1), axis=-1)


def _segments(ax, x, y, stable, part):
    """Draw y(x) solid where stable, dashed red where not (the joins drawn in both), each
    part of the branch (before and after a switch) on its own."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    if np.nanmax(np.abs(y), initial=0.0) < 1e-20:
        y = np.zeros_like(y)              # rounding noise of an exactly zero quantity
    for k, p in enumerate(np.unique(part)):
        sel = part == p
        xs, ys, st = x[sel], y[sel], stable[sel]
        ok = np.isfinite(ys)
        for flag, style in ((True, dict(color="C0", ls="-")), (False, dict(color="C3", ls="--"))):
            yy = np.where(ok & ((st == flag) | np.r_[st[1:] == flag, False]), ys, np.nan)
            ax.plot(xs, yy, lw=1.6, **style,
                    label=("stable" if flag else "unstable") if k == 0 else None)


def plot_branch(ds: xr.Dataset, out_dir: Path, stem: str = "branch") -> list[Path]:
    """Write ``<stem>_bifurcation.png`` and ``<stem>_shapes.png`` into ``out_dir``;
    returns their paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    lam = ds["parameter"].values
    name = str(ds.attrs.get("parameter_path", "parameter")) or "parameter"
    unstable = ds["unstable_modes"].values
    stable = unstable == 0
    part = ds["branch"].values if "branch" in ds else np.zeros(lam.size, int)
    r = ds["position"].values
    t0 = r[:, 1, :] - r[:, 0, :]
    t0 /= np.maximum(np.linalg.norm(t0, axis=-1, keepdims=True), 1e-300)
    curves = [
        ("largest lateral excursion (m)", excursion(ds)),
        ("end force along the start tangent (N)", np.sum(ds["end_force"].values * t0, axis=-1)),
        ("end moment along the start tangent (N m)", np.sum(ds["end_moment"].values * t0, axis=-1)),
        ("writhe Wr (turns)", ds["writhe"].values),
    ]
    fig = Figure(figsize=(10, 7.5))
    axes = fig.subplots(2, 2)
    blam = ds["bifurcation_parameter"].values
    bkind = ds["bifurcation_kind"].values
    bafter = ds["bifurcation_after"].values
    bsimple = ds["bifurcation_simple"].values
    for ax, (label, y) in zip(axes.ravel(), curves):
        _segments(ax, lam, y, stable, part)
        for p, k, i, simple in zip(blam, bkind, bafter, bsimple):
            j = int(min(max(i, 0), lam.size - 1))
            yb = np.interp(p, lam[j:j + 2], y[j:j + 2]) if j + 1 < lam.size and \
                lam[j] != lam[j + 1] else y[j]
            if k == "fold":
                ax.plot([p], [yb], "k^", ms=7)
            else:
                ax.plot([p], [yb], "ko", ms=7, mfc="k" if simple else "none")
        ax.set_xlabel(name)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    from matplotlib.lines import Line2D
    handles += [Line2D([], [], color="k", marker="o", ls=""), Line2D([], [], color="k",
                marker="o", mfc="none", ls=""), Line2D([], [], color="k", marker="^", ls="")]
    labels += ["branch point", "branch point (pair)", "fold"]
    fig.legend(handles, labels, loc="upper center", ncol=5, frameon=False,
               bbox_to_anchor=(0.5, 0.955))
    fig.suptitle(f"branch in {name}", y=0.995)
    fig.tight_layout(rect=(0, 0, 1, 0.92))
    paths = [_save(fig, out_dir / f"{stem}_bifurcation.png")]

    stored = np.flatnonzero(np.all(np.isfinite(r[:, :, 0]), axis=1))
    if stored.size:
        pick = stored[np.unique(np.linspace(0, stored.size - 1, min(8, stored.size)).astype(int))]
        fig = Figure(figsize=(12, 4.2))
        views = fig.subplots(1, 3)
        for (a, b), ax in zip(((0, 1), (0, 2), (1, 2)), views):
            for i in pick:
                ax.plot(r[i, :, a], r[i, :, b], "-" if stable[i] else "--",
                        label=f"{name} = {lam[i]:.4g}" + ("" if stable[i] else " (unstable)"))
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
