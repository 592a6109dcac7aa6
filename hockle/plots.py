"""Figures of a result dataset, after the seed paper's Figs. 6, 7 and 8.

* :func:`plot_snapshots` (Fig. 6): the rod at chosen times, each as a 3-D view with its
  three orthogonal projections (x-y, x-z, y-z) beside it, all at equal scale. The rod is
  drawn as a tube of its real, possibly varying diameter (from the case in the file), with
  its contact sites and its two ends marked and named in a legend.
* :func:`event_times`: the times worth drawing, from what happened in the run: the onset of
  buckling, the first self-contact, each unit step of the writhe, the end.
  :func:`snapshot_times` uses them unless times are given.
* :func:`plot_energies` (Fig. 7): bending, torsional, kinetic and total energy vs time.
* :func:`plot_topology` (Fig. 8): Tw, Wr and Lk vs time, with |Tw + Wr - Lk| below.

The drawing of the rod (:func:`rod_box`, :func:`setup_rod_axes`, :func:`draw_rod`,
:func:`rod_legend_handles`) and of the curves (:func:`energy_lines`,
:func:`topology_lines`) is shared with the animation (:mod:`hockle.animate`).

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

import json

import numpy as np
import xarray as xr
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import NullFormatter

from solver.results import minimum_bend_radius_of, run_events

__all__ = [
    "plot_all",
    "plot_snapshots",
    "plot_energies",
    "plot_topology",
    "snapshot_times",
    "event_times",
    "contact_sites",
    "rod_diameter",
    "rod_box",
    "setup_rod_axes",
    "draw_rod",
    "rod_legend_handles",
    "seabed_of",
    "draw_seabed",
    "energy_lines",
    "topology_lines",
]

MAX_EVENTS = 8             # snapshot rows at most, when chosen from the events

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


def _rod_property(ds: xr.Dataset, name: str) -> dict | float | None:
    """A rod property of the case stored in the file (number or ``{s, value}``), or None."""
    try:
        return json.loads(str(ds.attrs["case"]))["rod"][name]
    except (KeyError, TypeError, ValueError):
        return None


def rod_diameter(ds: xr.Dataset, s: np.ndarray) -> np.ndarray | None:
    """Diameter (m) at arclengths ``s`` from the case in the file (a number or a profile,
    piecewise linear and held outside), or None when the file does not say."""
    d = _rod_property(ds, "diameter")
    s = np.asarray(s, dtype=float)
    if isinstance(d, (int, float)) and not isinstance(d, bool):
        return np.full(s.shape, float(d))
    if isinstance(d, dict) and "s" in d and "value" in d:
        return np.interp(s, np.asarray(d["s"], float), np.asarray(d["value"], float))
    return None


def seabed_of(ds: xr.Dataset):
    """The case's sea floor (:class:`solver.case.Seabed`, whose ``bottom(x, y)`` gives its
    elevation in m) from the case stored in the file, or None when it has none."""
    try:
        spec = json.loads(str(ds.attrs["case"])).get("seabed")
    except (KeyError, TypeError, ValueError, AttributeError):
        return None
    if not spec:
        return None
    from solver.case import Seabed

    return Seabed.model_validate(spec)


def draw_seabed(ax3, lims: Sequence[tuple[float, float]], seabed, n: int = 25) -> list:
    """Draw the sea floor ``seabed`` (:func:`seabed_of`) into the 3-D axes ``ax3`` over the
    x-y square of ``lims`` (:func:`rod_box`): a translucent sand-coloured surface of its
    elevation (the plane of a flat bottom, the bilinear bathymetry otherwise) on an
    ``n`` × ``n`` grid, cut where it leaves the box's z range. Returns the artists."""
    X, Y = np.meshgrid(np.linspace(*lims[0], n), np.linspace(*lims[1], n), indexing="ij")
    Z = np.asarray(seabed.bottom(X, Y), dtype=float)
    Z = np.where((Z >= lims[2][0]) & (Z <= lims[2][1]), Z, np.nan)
    if not np.isfinite(Z).any():
        return []
    return [ax3.plot_surface(X, Y, Z, color="tan", alpha=0.35, linewidth=0, shade=False,
                             antialiased=False, rcount=n, ccount=n)]


def _seabed_under(seabed, r: np.ndarray) -> np.ndarray:
    """(N,) m, the bottom's elevation under each point of the centreline ``r`` (N, 3)."""
    return np.asarray(seabed.bottom(r[:, 0], r[:, 1]), dtype=float)


def _contact_spec(ds: xr.Dataset) -> dict | None:
    try:
        return json.loads(str(ds.attrs["case"])).get("contact")
    except (KeyError, TypeError, ValueError):
        return None


def event_times(ds: xr.Dataset, max_events: int = MAX_EVENTS) -> list[tuple[float, str]]:
    """The stored times at which something happened, with what: ``[(t, label), ...]``.

    * **onset of buckling**: the first time a point of the centreline has moved more than
      one rod diameter across the line through its ends from where it was at the first
      output (``position`` and the case's diameter; 1 % of the length when the file has
      no diameter): a curved lay's own shape does not count
      (:func:`solver.results.shape_departure`); without ``position``, the first time the
      writhe has changed by 0.05 turns;
    * **first contact**: the first time ``contact_count`` > 0;
    * **loop formed**: the first self-contact or |Wr| rising through 1 (with a seabed:
      while the rod lies on it), when it is not already the first contact or Wr reaching 1;
    * **MBR below X m**: the first time the smallest bend radius is below the case's
      ``rod.minimum_bend_radius`` X;
    * **Wr reaches k**: the first time |Wr| >= k, for k = 1, 2, ... (``writhe``);
    * **end**: the last stored time.

    Events at the same stored time are merged (labels joined with "; "). With more than
    ``max_events``, the unit steps of Wr are thinned evenly (the others are kept). Returns
    ``[]`` for an empty run, and only the end when nothing else can be detected.
    """
    t = np.asarray(ds["time"].values, dtype=float) if "time" in ds.coords else np.zeros(0)
    if t.size == 0:
        return []
    fixed: list[tuple[int, str]] = []
    steps: list[tuple[int, str]] = []
    events = run_events(ds)                   # the one definition (solver.results)
    if events["buckling_onset"] is not None:
        fixed.append((events["buckling_onset"], "onset of buckling"))
    if events["first_contact"] is not None:
        fixed.append((events["first_contact"], "first contact"))
    loop = events.get("loop_formed")
    if loop is not None and loop not in (events["first_contact"], events.get("writhe_1")):
        fixed.append((loop, "loop formed"))   # in free space it is one of those two
    if events.get("bend_radius_below_mbr") is not None:
        fixed.append((events["bend_radius_below_mbr"],
                      f"MBR below {minimum_bend_radius_of(ds):g} m"))
    wr = np.asarray(ds["writhe"].values, dtype=float) if "writhe" in ds else None
    k = 1
    while f"writhe_{k}" in events:
        i = events[f"writhe_{k}"]
        if i is not None:
            sign = "-" if wr[i] < 0 else ""
            steps.append((i, f"Wr reaches {sign}{k}"))
        k += 1

    status = ds.attrs.get("hockle_status")
    fixed.append((t.size - 1, "end" if status in (None, "completed") else f"end ({status})"))

    taken = {i for i, _ in fixed}
    merged = [(i, label) for i, label in steps if i in taken]      # no row of their own
    others = [(i, label) for i, label in steps if i not in taken]
    room = max(max_events - len(taken), 0)
    if len(others) > room:
        keep = np.unique(np.round(np.linspace(0, len(others) - 1, room)).astype(int)) if room else []
        others = [others[k] for k in keep]
    by_index: dict[int, list[str]] = {}
    for i, label in sorted(fixed, key=lambda e: e[0]) + merged + others:
        by_index.setdefault(i, [])
        if label not in by_index[i]:
            by_index[i].append(label)
    return [(float(t[i]), "; ".join(labels)) for i, labels in sorted(by_index.items())]


def snapshot_times(
    ds: xr.Dataset,
    times: Sequence[float] | None = None,
    count: int = 5,
    on_skip: Notify | None = _stderr,
) -> list[float]:
    """Output times to draw: the nearest stored time to each requested one.

    Without ``times``, the times of :func:`event_times` (onset of buckling, first contact,
    each unit step of Wr, the end); when it finds nothing but the end, ``count`` times
    spread evenly over the run (first and last included). Requested times outside the
    stored range by more than one output interval are dropped with a message. Duplicates
    are removed; the result is sorted.
    """
    return [t for t, _ in _snapshot_events(ds, times, count, on_skip)]


def _snapshot_events(
    ds: xr.Dataset,
    times: Sequence[float] | None,
    count: int,
    on_skip: Notify | None,
) -> list[tuple[float, str]]:
    stored = np.asarray(ds["time"].values, dtype=float) if "time" in ds.coords else np.zeros(0)
    if stored.size == 0:
        return []
    if times is None:
        events = event_times(ds)
        if len(events) > 1:
            return events
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
    return [(t, "") for t in sorted(set(chosen))]


TOUCH_GAP = 0.25          # surface gap, in diameters, below which two strands are drawn touching


def contact_sites(
    ds: xr.Dataset, r: np.ndarray, s: np.ndarray, d: np.ndarray | None
) -> np.ndarray:
    """Indices of the grid points where the rod touches itself in the shape ``r`` (N, 3), m.

    Two grid points touch when their surface gap is at most :data:`TOUCH_GAP` times their
    mean diameter, plus half a segment (the closest points of two strands lie between grid
    points); pairs closer along the rod than the case's contact ``exclusion`` (default
    twice the largest diameter, as the solver uses), or than that reach (a grid coarser
    than the exclusion), are neighbours, not contacts. On the
    seed's rod this marks about as many points as the solver counts contact pairs
    (``contact_count``). Returns ``[]`` when the file gives no diameter.
    """
    from scipy.spatial import cKDTree

    if d is None or r.shape[0] < 2 or not np.all(np.isfinite(r)):
        return np.zeros(0, dtype=int)
    d_max = float(np.max(d))
    exclusion = (_contact_spec(ds) or {}).get("exclusion")
    exclusion = float(exclusion) if exclusion is not None else 2.0 * d_max
    half_segment = 0.5 * float(np.max(np.diff(s)))
    reach = (1.0 + TOUCH_GAP) * d_max + half_segment
    # two points closer along the rod than the reach are within it on any shape (a chord
    # is no longer than its arc): on a grid coarser than the exclusion, neighbours
    exclusion = max(exclusion, reach)
    pairs = cKDTree(r).query_pairs(reach, output_type="ndarray")
    if pairs.size == 0:
        return np.zeros(0, dtype=int)
    pairs = pairs[np.abs(s[pairs[:, 0]] - s[pairs[:, 1]]) > exclusion]
    dist = np.linalg.norm(r[pairs[:, 0]] - r[pairs[:, 1]], axis=1)
    mean_d = 0.5 * (d[pairs[:, 0]] + d[pairs[:, 1]])
    pairs = pairs[dist <= (1.0 + TOUCH_GAP) * mean_d + half_segment]
    return np.unique(pairs.ravel())


def _tube_mesh(r: np.ndarray, d: np.ndarray, around: int = 12):
    """X, Y, Z (N, around + 1) of a tube of diameter ``d`` around the polyline ``r``,
    on a rotation-minimising frame (parallel transport of a normal along the tangents)."""
    tangent = np.gradient(r, axis=0)
    norm = np.linalg.norm(tangent, axis=1, keepdims=True)
    tangent = np.divide(tangent, norm, out=np.tile([0.0, 0.0, 1.0], (len(r), 1)), where=norm > 0)
    seed = np.array([1.0, 0.0, 0.0]) if abs(tangent[0, 0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    normal = np.empty_like(r)
    n = seed - np.dot(seed, tangent[0]) * tangent[0]
    for i in range(len(r)):
        m = n - np.dot(n, tangent[i]) * tangent[i]
        size = np.linalg.norm(m)
        if size > 1e-12:
            n = m / size
        normal[i] = n
    binormal = np.cross(tangent, normal)
    theta = np.linspace(0.0, 2.0 * np.pi, around + 1)
    ring = (np.cos(theta)[None, :, None] * normal[:, None, :]
            + np.sin(theta)[None, :, None] * binormal[:, None, :])
    pts = r[:, None, :] + 0.5 * d[:, None, None] * ring
    return pts[..., 0], pts[..., 1], pts[..., 2]


def _thin(n: int, most: int) -> np.ndarray:
    """Indices 0..n-1 thinned to at most ``most``, the ends kept."""
    if n <= most:
        return np.arange(n)
    return np.unique(np.round(np.linspace(0, n - 1, most)).astype(int))


def _cube_limits(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and half-width of an axis-aligned cube around (..., 3) points."""
    lo = np.nanmin(points.reshape(-1, 3), axis=0)
    hi = np.nanmax(points.reshape(-1, 3), axis=0)
    centre = 0.5 * (lo + hi)
    half = 0.5 * float(np.max(hi - lo)) * 1.05
    return centre, max(half, 1e-9)


def rod_box(shapes: np.ndarray, diameter: np.ndarray | None) -> list[tuple[float, float]]:
    """Limits ``[(x0, x1), (y0, y1), (z0, z1)]`` (m) of one cube that holds every shape in
    ``shapes`` (..., 3) and the tube of ``diameter`` around it, so that shapes drawn in it
    compare at equal, undistorted scale."""
    centre, half = _cube_limits(shapes)
    if diameter is not None:
        half += 0.5 * float(np.max(diameter))
    return [(c - half, c + half) for c in centre]


def setup_rod_axes(ax3, lims: Sequence[tuple[float, float]], zoom: float = 1.0) -> None:
    """Prepare a 3-D axes for :func:`draw_rod`: the cube ``lims`` (from :func:`rod_box`),
    equal box aspect (drawn ``zoom`` times the default size), axis labels in m and small
    tick labels."""
    ax3.set_xlim(*lims[0])
    ax3.set_ylim(*lims[1])
    ax3.set_zlim(*lims[2])
    ax3.set_box_aspect((1, 1, 1), zoom=zoom)
    ax3.set_xlabel("x (m)")
    ax3.set_ylabel("y (m)")
    ax3.set_zlabel("z (m)")
    ax3.tick_params(labelsize=7)


def draw_rod(ax3, r: np.ndarray, diameter: np.ndarray | None,
             touching: np.ndarray | None = None) -> list:
    """Draw the rod of centreline ``r`` (N, 3), m, into the 3-D axes ``ax3``.

    A shaded tube of ``diameter`` (N,), m (thinned to 400 rings), or the bare centreline
    when ``diameter`` is None; the start end (s = 0) a red circle, the far end a green
    square, the grid points ``touching`` (from :func:`contact_sites`) orange dots; the
    styles :func:`rod_legend_handles` names. Returns the artists drawn, so that an
    animation can remove them before drawing the next shape.
    """
    artists: list = []
    if diameter is not None:
        keep = _thin(len(r), 400)
        X, Y, Z = _tube_mesh(r[keep], diameter[keep])
        artists.append(ax3.plot_surface(X, Y, Z, color="C0", shade=True, linewidth=0,
                                        antialiased=False, rcount=len(keep),
                                        ccount=X.shape[1]))
    else:
        artists += ax3.plot(r[:, 0], r[:, 1], r[:, 2], color="C0", lw=1.5)
    artists.append(ax3.scatter(*r[0], color="C3", marker="o", s=22, depthshade=False))
    artists.append(ax3.scatter(*r[-1], color="C2", marker="s", s=22, depthshade=False))
    if touching is not None and len(touching):
        artists.append(ax3.scatter(*r[touching].T, color="orange", marker=".", s=6,
                                   depthshade=False))
    return artists


def rod_legend_handles(s: np.ndarray, diameter: np.ndarray | None,
                       contact: bool) -> list[Line2D]:
    """Legend entries for what :func:`draw_rod` draws: the rod (tube or centreline), the
    two ends (named by their arclength, from ``s``) and, when ``contact``, the contact
    sites."""
    handles = [
        Line2D([], [], color="C0", lw=6 if diameter is not None else 1.5,
               label="rod (tube of its diameter)" if diameter is not None else "centreline"),
        Line2D([], [], color="C3", marker="o", ls="", label="start end (s = 0)"),
        Line2D([], [], color="C2", marker="s", ls="", label=f"far end (s = {s[-1]:g} m)"),
    ]
    if contact:
        handles.append(Line2D([], [], color="orange", marker=".", ls="",
                              label="self-contact (grid points)"))
    return handles


def plot_snapshots(
    ds: xr.Dataset,
    out_dir: str | Path,
    times: Sequence[float] | None = None,
    stem: str = "result",
    on_skip: Notify | None = _stderr,
) -> list[Path]:
    """Fig. 6: the rod at chosen times, one row per time: 3-D view, then x-y, x-z, y-z.

    Needs ``position`` (time, s, xyz) in m. Without ``times`` the rows are the run's events
    (:func:`event_times`: onset of buckling, first contact, each unit step of Wr, the end),
    named in each row's title. The rod is a tube of its real diameter (from the case in the
    file; a plain centreline when the file has none): a shaded tube in the 3-D view, a band
    of the diameter's width at the axes' scale in the projections. Grid points in
    self-contact (:func:`contact_sites`) are orange dots; the start end (s = 0) is a circle,
    the far end (s = L) a square; a legend names them. With a seabed in the case the bottom
    is drawn too: a surface in the 3-D view (:func:`draw_seabed`), and in the x-z and y-z
    views the bottom's elevation under the rod. All panels share one cubic box
    that holds every drawn snapshot, so shapes compare at equal, undistorted scale.
    Writes ``<stem>_snapshots.png``.
    """
    if "position" not in ds:
        if on_skip:
            on_skip("snapshots (Fig. 6) skipped: the dataset has no 'position' variable")
        return []
    chosen = _snapshot_events(ds, times, 5, on_skip)
    if not chosen:
        if on_skip:
            on_skip("snapshots (Fig. 6) skipped: no stored time to draw")
        return []
    pos = ds["position"].transpose("time", "s", "xyz")
    s = np.asarray(ds["s"].values, dtype=float)
    diameter = rod_diameter(ds, s)
    shapes = [np.asarray(pos.sel(time=t).values, dtype=float) for t, _ in chosen]
    lims = rod_box(np.stack(shapes), diameter)
    counts = None
    if "contact_count" in ds:
        counts = ds["contact_count"]
    seabed = seabed_of(ds)

    n = len(chosen)
    fig = Figure(figsize=(15.0, 3.4 * n + 1.0), layout="constrained")
    FigureCanvasAgg(fig)
    fig.suptitle(f"{_title(ds)}: the rod at the run's events" if times is None
                 else f"{_title(ds)}: the rod at chosen times")
    grid = fig.add_gridspec(n, 4, width_ratios=(1.35, 1, 1, 1), wspace=0.08)
    views = (("x", "y", 0, 1), ("x", "z", 0, 2), ("y", "z", 1, 2))
    bands = []   # (axes, x, y) of the projections, drawn once the layout is fixed
    any_contact = False
    for row, ((t, label), r) in enumerate(zip(chosen, shapes)):
        title = f"t = {t:g} s" + (f": {label}" if label else "")
        touching = np.zeros(0, dtype=int)
        if counts is None or float(np.nan_to_num(counts.sel(time=t).values)) > 0:
            touching = contact_sites(ds, r, s, diameter)
        any_contact = any_contact or touching.size > 0
        ax3 = fig.add_subplot(grid[row, 0], projection="3d")
        setup_rod_axes(ax3, lims)
        if seabed is not None:
            draw_seabed(ax3, lims, seabed)
        draw_rod(ax3, r, diameter, touching)
        ax3.set_title(title, fontsize=10)
        for col, (a, b, i, j) in enumerate(views, start=2):
            ax = fig.add_subplot(grid[row, col - 1])
            if seabed is not None and j == 2:           # the bottom under the rod
                ax.plot(r[:, i], _seabed_under(seabed, r), color="saddlebrown", lw=1.0,
                        zorder=0)
            if diameter is None:
                ax.plot(r[:, i], r[:, j], color="C0", lw=1.2)
            else:
                bands.append((ax, r[:, i], r[:, j]))
                ax.plot(r[:, i], r[:, j], color="navy", lw=0.4, zorder=2)
            ax.plot(r[0, i], r[0, j], "o", color="C3", ms=5, zorder=4)
            ax.plot(r[-1, i], r[-1, j], "s", color="C2", ms=5, zorder=4)
            if touching.size:
                ax.plot(r[touching, i], r[touching, j], ".", color="orange", ms=3, zorder=3)
            ax.set_xlim(*lims[i])
            ax.set_ylim(*lims[j])
            ax.set_aspect("equal", adjustable="box")
            ax.set_xlabel(f"{a} (m)")
            ax.set_ylabel(f"{b} (m)")
            ax.set_title(f"{a}-{b} view, " + title, fontsize=9)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)

    handles = rod_legend_handles(s, diameter, any_contact)
    if seabed is not None:
        handles.append(Line2D([], [], color="saddlebrown", lw=4, alpha=0.6,
                              label="seabed (x-z, y-z: the bottom under the rod)"))
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=9)
    if bands:
        fig.canvas.draw()   # fixes the layout, so the band widths are true to scale
        for ax, x, y in bands:
            box = ax.get_window_extent()
            xlo, xhi = ax.get_xlim()
            points_per_m = box.width / (xhi - xlo) * 72.0 / fig.dpi
            seg = np.stack([np.column_stack([x[:-1], y[:-1]]),
                            np.column_stack([x[1:], y[1:]])], axis=1)
            width = 0.5 * (diameter[:-1] + diameter[1:]) * points_per_m
            ax.add_collection(LineCollection(seg, linewidths=width, colors="C0",
                                             capstyle="round", joinstyle="round", zorder=1,
                                             alpha=0.9))
    return [_save(fig, Path(out_dir) / f"{stem}_snapshots.png")]


_ENERGIES = (
    ("energy_bending", "bending strain energy", "C0", "-"),
    ("energy_torsion", "torsional strain energy", "C1", "-"),
    ("energy_kinetic", "kinetic energy", "C2", "-"),
    ("energy_kinetic_fluid", "kinetic energy of added fluid mass", "C2", ":"),
    ("energy_total", "total energy", "k", "-"),
    ("work_in", "work put in at the ends", "0.5", "--"),
)


def energy_lines(ax, ds: xr.Dataset, t: np.ndarray, index=slice(None)) -> list:
    """Draw the energies of ``ds`` (whichever of :data:`_ENERGIES` it has) against the
    times ``t`` into ``ax`` (y label in J, grid), labelled for a legend.

    ``index`` selects the outputs read (``t`` are their times). Returns
    ``[(line, values), ...]``, so that an animation can show each curve up to a time.
    """
    drawn = []
    marker = "o" if t.size < 3 else None
    for name, label, color, style in _ENERGIES:
        if name in ds:
            y = np.asarray(ds[name].values[index], dtype=float)
            (line,) = ax.plot(t, y, style, color=color, label=label, marker=marker, ms=3)
            drawn.append((line, y))
    ax.set_ylabel("energy (J)")
    ax.grid(alpha=0.3)
    return drawn


_TOPOLOGY = (
    ("twist", "Tw (twist)", "C0"),
    ("writhe", "Wr (writhe)", "C1"),
    ("linking_number", "Lk (linking number)", "k"),
)


def topology_lines(ax, ds: xr.Dataset, t: np.ndarray, index=slice(None)) -> list:
    """Draw twist, writhe and linking number (whichever ``ds`` has), and Tw + Wr dashed
    when both are there, against the times ``t`` into ``ax`` (y label in turns, grid).

    ``index`` selects the outputs read. Returns ``[(line, values), ...]`` as
    :func:`energy_lines` does.
    """
    drawn = []
    marker = "o" if t.size < 3 else None
    for name, label, color in _TOPOLOGY:
        if name in ds:
            y = np.asarray(ds[name].values[index], dtype=float)
            (line,) = ax.plot(t, y, color=color, label=label, marker=marker, ms=3)
            drawn.append((line, y))
    if "twist" in ds and "writhe" in ds:
        y = np.asarray(ds["twist"].values[index] + ds["writhe"].values[index], dtype=float)
        (line,) = ax.plot(t, y, "--", color="C3", label="Tw + Wr")
        drawn.append((line, y))
    ax.set_ylabel("Tw, Wr, Lk (turns)")
    ax.grid(alpha=0.3)
    return drawn


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
    energy_lines(ax, ds, t)
    ax.set_xlabel("time (s)")
    ax.set_title(f"{_title(ds)}: energies")
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
    topology_lines(ax, ds, t)
    ax.set_title(f"{_title(ds)}: exchange of twist and writhe")
    ax.legend(fontsize=8)
    if ax_err is not None:
        positive = np.where(err > 0, err, np.nan)
        ax_err.plot(t, positive, color="C4", marker=marker, ms=3)
        if np.any(np.isfinite(positive)):
            ax_err.set_yscale("log")
            ax_err.yaxis.set_minor_formatter(NullFormatter())
        ax_err.set_ylabel("|Tw + Wr - Lk| (turns)")
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
