"""Figures of a result dataset, after the seed paper's Figs. 6, 7 and 8.

* :func:`plot_snapshots` (Fig. 6): the rod at chosen times, each as a 3-D view with its
  three orthogonal projections (x-y, x-z, y-z) beside it, all at equal scale. The rod is
  drawn as a tube of its real, possibly varying diameter (from the case in the file), with
  its contact sites and its two ends marked and named in a legend.
  Where the rod moves in a small part of it (a loop on the sea floor) the views zoom to
  that part (:func:`action_box`), with the whole rod as an inset.
* :func:`event_times`: the times worth drawing, from what happened in the run: the onset of
  buckling, the first self-contact, each unit step of the writhe, its largest fast jumps
  (:func:`writhe_jumps`), the end. :func:`snapshot_times` uses them unless times are given.
* :func:`plot_energies` (Fig. 7): bending, torsional, kinetic and total energy vs time,
  and the balance that adds up to the work put in (:func:`energy_balance`: stored +
  kinetic + taken by the seabed + dissipated = energy at the start + work in).
* :func:`plot_topology` (Fig. 8): Tw, Wr and Lk vs time (the dashboard's colours,
  :data:`TOPOLOGY_COLOURS`), with |Tw + Wr - Lk| below.
* :func:`plot_tweezers`: for a magnetic-tweezers run (:func:`solver.results.
  tweezers_protocol`), the extension against turns (the hat curve) and the torque against
  turns, from :func:`solver.results.tweezers_series` (docs/tweezers.md).

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
from matplotlib.patches import Rectangle
from matplotlib.ticker import NullFormatter

from solver.results import minimum_bend_radius_of, node_departure, run_events, tweezers_series

__all__ = [
    "plot_all",
    "plot_snapshots",
    "plot_energies",
    "plot_topology",
    "plot_tweezers",
    "tweezers_units",
    "snapshot_times",
    "event_times",
    "writhe_jumps",
    "contact_sites",
    "rod_diameter",
    "rod_box",
    "action_box",
    "setup_rod_axes",
    "draw_rod",
    "rod_legend_handles",
    "seabed_of",
    "draw_seabed",
    "energy_lines",
    "energy_balance",
    "largest_fall",
    "topology_lines",
    "TOPOLOGY_COLOURS",
]

MAX_EVENTS = 8             # snapshot rows at most, when chosen from the events
WRITHE_JUMP = 0.25         # turns: the smallest jump of Wr that gets a snapshot row
MAX_JUMPS = 2              # snapshot rows for jumps of Wr at most (the largest)

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


def writhe_jumps(writhe: np.ndarray, time: np.ndarray | None = None,
                 min_jump: float = WRITHE_JUMP, spread: float = 0.1,
                 longest: float = 0.05) -> list[tuple[int, int]]:
    """The fast jumps of the writhe series ``writhe`` (turns, one per output time
    ``time``, s), largest first: ``[(i0, i1), ...]``, output indices where each starts
    and ends.

    A jump grows from the output interval where Wr changes fastest, to the neighbouring
    intervals where it changes the same way at least ``spread`` times as fast, so the slow
    drift before and after is not part of it; the next is grown from the fastest interval
    left, and so on. Kept: those that change Wr by ``min_jump`` turns or more within
    ``longest`` of the run's duration (a twentieth: a slow unwinding is not a jump), in
    the order of their size. The seed example's wrap (the plies wrapping round each
    other) is one: Wr 1.22 -> 1.88 over 25.2-25.6 s; so is its collapse into the loop,
    0.03 -> 1.02 over 17.4-18.1 s."""
    wr = np.nan_to_num(np.asarray(writhe, dtype=float))
    t = np.arange(wr.size, dtype=float) if time is None else np.asarray(time, dtype=float)
    span = longest * float(t[-1] - t[0]) if wr.size > 1 else 0.0
    if wr.size < 2:
        return []
    change = np.diff(wr)
    rate = np.abs(change)
    free = np.ones(change.size, dtype=bool)
    found: list[tuple[int, int]] = []
    for _ in range(64):                           # enough for any run's few big jumps
        left = np.where(free, rate, -1.0)
        k = int(np.argmax(left))
        if left[k] <= 0.0 or left[k] < 0.1 * min_jump * spread:
            break
        sign, floor = np.sign(change[k]), spread * rate[k]
        a = b = k
        while a > 0 and free[a - 1] and np.sign(change[a - 1]) == sign and rate[a - 1] >= floor:
            a -= 1
        while (b + 1 < change.size and free[b + 1] and np.sign(change[b + 1]) == sign
               and rate[b + 1] >= floor):
            b += 1
        free[a:b + 1] = False
        if abs(wr[b + 1] - wr[a]) >= min_jump and t[b + 1] - t[a] <= span * (1 + 1e-9):
            found.append((a, b + 1))
    return sorted(found, key=lambda j: -abs(wr[j[1]] - wr[j[0]]))


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
    * **Wr jumps a → b**: the end of each of the :data:`MAX_JUMPS` largest fast jumps of
      the writhe (:func:`writhe_jumps`: at least :data:`WRITHE_JUMP` turns within a
      twentieth of the run) during which
      none of the events above happened (a jump that holds one is already drawn): the
      moments the loop wraps, the plies wrap round each other, a loop is pulled through;
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

    if wr is not None:
        shown = [i for i, _ in fixed + steps]
        jumps = [(a, b) for a, b in writhe_jumps(wr, t)
                 if not any(a <= i <= b for i in shown)][:MAX_JUMPS]
        for a, b in jumps:
            fixed.append((b, f"Wr jumps {wr[a]:.2f} → {wr[b]:.2f} over {t[a]:g}-{t[b]:g} s"))

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


ZOOM_SHARE = 0.5   # grid points that move at least this share of the most are the action
ZOOM_BELOW = 0.4   # zoom when the action's cube is at most this share of the whole rod's


def action_box(ds: xr.Dataset, shapes: np.ndarray, s: np.ndarray,
               diameter: np.ndarray | None, below: float = ZOOM_BELOW):
    """Where the shapes ``shapes`` (K, N, 3) of ``ds`` move most, when that is a small part
    of the rod: ``(lims, (s0, s1))`` (the cube of :func:`rod_box`'s form around it, and the
    stretch of arclength in it, m), or None to draw the whole rod.

    A grid point's motion is its departure from the first stored shape across the chord
    (:func:`solver.results.node_departure`, the measure of the buckling onset), the most
    of it over the shapes drawn. The action is the stretch from the first to the last
    grid point that moves at least :data:`ZOOM_SHARE` of the most any point moves (two
    diameters added either side); its cube holds that stretch in every shape drawn. None
    when nothing moved a diameter (1 % of the length without one) or when that cube is
    more than ``below`` (:data:`ZOOM_BELOW`) of the whole rod's (the seed example folds
    its whole rod; the seabed case's loop is a few tenths of a metre of its 4 m)."""
    if "position" not in ds or ds.sizes.get("time", 0) == 0 or len(shapes) == 0:
        return None
    first = np.asarray(ds["position"].transpose("time", "s", "xyz").values[0], dtype=float)
    moved = node_departure(np.concatenate([first[None], np.asarray(shapes, float)]))[1:]
    most = np.nan_to_num(moved, nan=0.0).max(axis=0)
    d_max = float(np.max(diameter)) if diameter is not None else 0.01 * float(s[-1] - s[0])
    if most.size == 0 or most.max() < d_max:
        return None
    hit = np.flatnonzero(most >= ZOOM_SHARE * most.max())
    s0, s1 = s[hit[0]] - 2.0 * d_max, s[hit[-1]] + 2.0 * d_max
    keep = (s >= s0) & (s <= s1)
    part = np.asarray(shapes, float)[:, keep]
    centre, half = _cube_limits(part)
    half = 1.1 * (half + 0.5 * d_max)
    _, whole = _cube_limits(np.asarray(shapes, float))
    if not np.isfinite(half) or half > below * whole:
        return None
    return ([(c - half, c + half) for c in centre],
            (float(max(s0, s[0])), float(min(s1, s[-1]))))


def _inside(r: np.ndarray, lims: Sequence[tuple[float, float]], pad: float) -> np.ndarray:
    """(N,) whether each point of ``r`` (N, 3) lies within ``lims`` widened by ``pad``."""
    lo = np.array([a for a, _ in lims]) - pad
    hi = np.array([b for _, b in lims]) + pad
    return np.all((r >= lo) & (r <= hi), axis=1)


def _runs(mask: np.ndarray) -> list[np.ndarray]:
    """The index runs (arrays of consecutive indices) where ``mask`` is True."""
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return []
    return np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)


def _whole_rod_inset(ax, r: np.ndarray, lims: Sequence[tuple[float, float]], i: int,
                     j: int, a: str, b: str) -> None:
    """An inset in the 2-D axes ``ax`` (its view ``a``-``b``, components ``i``, ``j``) with
    the whole centreline ``r`` (N, 3) and the zoomed box ``lims`` outlined, in the corner
    of ``ax`` where the zoomed drawing has the fewest points."""
    (x0, x1), (y0, y1) = lims[i], lims[j]
    w, h = 0.42, 0.30
    inside = _inside(r, lims, 0.0)
    u = (r[inside, i] - x0) / (x1 - x0)
    v = (r[inside, j] - y0) / (y1 - y0)
    corners = [(0.02, 0.02), (0.56, 0.02), (0.02, 0.68), (0.56, 0.68)]
    crowd = [np.count_nonzero((u >= cx) & (u <= cx + w) & (v >= cy) & (v <= cy + h))
             for cx, cy in corners]
    cx, cy = corners[int(np.argmin(crowd))]
    ins = ax.inset_axes([cx, cy, w, h])
    ins.plot(r[:, i], r[:, j], color="C0", lw=1.0)
    ins.plot(r[0, i], r[0, j], "o", color="C3", ms=3)
    ins.plot(r[-1, i], r[-1, j], "s", color="C2", ms=3)
    ins.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ec="C3", lw=1.0))
    ins.set_aspect("equal", adjustable="datalim")
    ins.set_xticks([])
    ins.set_yticks([])
    ins.set_facecolor((1.0, 1.0, 1.0, 0.85))
    ins.set_title(f"whole rod, {a}-{b}", fontsize=7, pad=2)


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
             touching: np.ndarray | None = None,
             clip: Sequence[tuple[float, float]] | None = None) -> list:
    """Draw the rod of centreline ``r`` (N, 3), m, into the 3-D axes ``ax3``.

    A shaded tube of ``diameter`` (N,), m (thinned to 400 rings), or the bare centreline
    when ``diameter`` is None; the start end (s = 0) a red circle, the far end a green
    square, the grid points ``touching`` (from :func:`contact_sites`) orange dots; the
    styles :func:`rod_legend_handles` names. With ``clip`` (a box of :func:`rod_box`'s
    form) only the parts of the rod inside it are drawn (matplotlib's 3-D axes do not
    clip). Returns the artists drawn, so that an animation can remove them before
    drawing the next shape.
    """
    artists: list = []
    keep_mask = np.ones(len(r), dtype=bool)
    if clip is not None:
        pad = 0.5 * float(np.max(diameter)) if diameter is not None else 0.0
        keep_mask = _inside(r, clip, pad)
    for run in _runs(keep_mask):
        if run.size < 2:
            continue
        part = r[run]
        if diameter is not None:
            keep = _thin(len(part), 400)
            X, Y, Z = _tube_mesh(part[keep], diameter[run][keep])
            artists.append(ax3.plot_surface(X, Y, Z, color="C0", shade=True, linewidth=0,
                                            antialiased=False, rcount=len(keep),
                                            ccount=X.shape[1]))
        else:
            artists += ax3.plot(part[:, 0], part[:, 1], part[:, 2], color="C0", lw=1.5)
    if keep_mask[0]:
        artists.append(ax3.scatter(*r[0], color="C3", marker="o", s=22, depthshade=False))
    if keep_mask[-1]:
        artists.append(ax3.scatter(*r[-1], color="C2", marker="s", s=22, depthshade=False))
    if touching is not None and len(touching):
        touching = np.asarray(touching)[keep_mask[np.asarray(touching)]]
        if len(touching):
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
    zoom: bool | None = None,
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

    Where the rod moves in a small part of it (:func:`action_box`: the loop of a cable
    on the sea floor, a few tenths of a metre of its 4 m) that box is zoomed to it: each
    x-y view then holds an inset of the whole rod with the zoomed box outlined, and the
    title says which stretch of the rod is shown. ``zoom``: None decides so, False
    draws the whole rod, True zooms where :func:`action_box` finds an action at all.
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
    focus = None
    if zoom is not False:
        focus = action_box(ds, np.stack(shapes), s, diameter,
                           below=np.inf if zoom else ZOOM_BELOW)
    if focus is not None:
        lims, (s0, s1) = focus
    counts = None
    if "contact_count" in ds:
        counts = ds["contact_count"]
    seabed = seabed_of(ds)

    n = len(chosen)
    fig = Figure(figsize=(15.0, 3.4 * n + 1.0), layout="constrained")
    FigureCanvasAgg(fig)
    heading = (f"{_title(ds)}: the rod at the run's events" if times is None
               else f"{_title(ds)}: the rod at chosen times")
    if focus is not None:
        heading += (f", zoomed to s = {s0:.3g}-{s1:.3g} m of {s[-1]:g} m, where it moves "
                    "most (inset: the whole rod, the zoomed box in red)")
    fig.suptitle(heading)
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
        draw_rod(ax3, r, diameter, touching, clip=lims if focus is not None else None)
        ax3.set_title(title, fontsize=10)
        shown = np.ones(len(r), dtype=bool)        # zoomed: the part inside the box
        if focus is not None:
            shown = _inside(r, lims, 0.5 * float(np.max(diameter)) if diameter is not None
                            else 0.0)
        runs = [run for run in _runs(shown) if run.size > 1]
        for col, (a, b, i, j) in enumerate(views, start=2):
            ax = fig.add_subplot(grid[row, col - 1])
            for run in runs:
                if seabed is not None and j == 2:       # the bottom under the rod
                    ax.plot(r[run, i], _seabed_under(seabed, r[run]), color="saddlebrown",
                            lw=1.0, zorder=0)
                if diameter is None:
                    ax.plot(r[run, i], r[run, j], color="C0", lw=1.2)
                else:
                    bands.append((ax, r[run, i], r[run, j], diameter[run]))
                    ax.plot(r[run, i], r[run, j], color="navy", lw=0.4, zorder=2)
            if shown[0]:
                ax.plot(r[0, i], r[0, j], "o", color="C3", ms=5, zorder=4)
            if shown[-1]:
                ax.plot(r[-1, i], r[-1, j], "s", color="C2", ms=5, zorder=4)
            marked = touching[shown[touching]] if touching.size else touching
            if marked.size:
                ax.plot(r[marked, i], r[marked, j], ".", color="orange", ms=3, zorder=3)
            ax.set_xlim(*lims[i])
            ax.set_ylim(*lims[j])
            ax.set_aspect("equal", adjustable="box")
            ax.set_xlabel(f"{a} (m)")
            ax.set_ylabel(f"{b} (m)")
            ax.set_title(f"{a}-{b} view, t = {t:g} s", fontsize=9)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
            if focus is not None and (i, j) == (0, 1):
                _whole_rod_inset(ax, r, lims, i, j, a, b)

    handles = rod_legend_handles(s, diameter, any_contact)
    if seabed is not None:
        handles.append(Line2D([], [], color="saddlebrown", lw=4, alpha=0.6,
                              label="seabed (x-z, y-z: the bottom under the rod)"))
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=9)
    if bands:
        fig.canvas.draw()   # fixes the layout, so the band widths are true to scale
        for ax, x, y, dia in bands:
            box = ax.get_window_extent()
            xlo, xhi = ax.get_xlim()
            points_per_m = box.width / (xhi - xlo) * 72.0 / fig.dpi
            seg = np.stack([np.column_stack([x[:-1], y[:-1]]),
                            np.column_stack([x[1:], y[1:]])], axis=1)
            width = 0.5 * (dia[:-1] + dia[1:]) * points_per_m
            ax.add_collection(LineCollection(seg, linewidths=width, colors="C0",
                                             capstyle="round", joinstyle="round", zorder=1,
                                             alpha=0.9))
    return [_save(fig, Path(out_dir) / f"{stem}_snapshots.png")]


_ENERGIES = (
    ("energy_bending", "bending strain energy", "C0", "-"),
    ("energy_torsion", "torsional strain energy", "C1", "-"),
    ("energy_kinetic", "kinetic energy of the rod", "C2", "-"),
    ("energy_kinetic_fluid", "kinetic energy of the added fluid mass", "C2", ":"),
    ("energy_total", "total: strain + kinetic", "k", "-"),
)
#: the energy balance's series (:func:`energy_balance`) drawn beside them
_BALANCE = (
    ("supplied", "energy at the start + work in since", "0.45", "--"),
    ("seabed", "taken by the seabed (−seabed_work)", "saddlebrown", "-."),
    ("dissipated", "dissipated: the rest of the work in", "C3", "-"),
)


def energy_balance(ds: xr.Dataset) -> dict[str, np.ndarray] | None:
    """The energy balance of a result, each (T,) J, or None without ``energy_total`` and
    ``work_in``:

    * ``strain`` = ``energy_bending`` + ``energy_torsion`` (None without them) and
      ``kinetic`` = ``energy_kinetic`` + ``energy_kinetic_fluid`` (the rod's own and the
      entrained water's; ``energy_total`` − strain without them): the rod's energy, whose
      sum is ``total`` = ``energy_total``;
    * ``supplied``: the energy at the first output plus the work put in since
      (``work_in``: at the ends and by the loads, gravity included);
    * ``seabed``: what the sea floor took since the first output (−``seabed_work``:
      friction, its damper and its spring), None without a seabed;
    * ``dissipated`` = supplied − total − seabed: what the fluid's drag, the contact law's
      damping and the scheme's damping (ρ∞ < 1) took, the remainder that closes the
      balance. It only grows where the run is passive and its balance holds; where it
      falls, energy came from nowhere (``step_energy_error`` says by how much per step).

    So total + seabed + dissipated = supplied at every output."""
    if "energy_total" not in ds or "work_in" not in ds or ds.sizes.get("time", 0) == 0:
        return None

    def series(name):
        return np.asarray(ds[name].values, dtype=float) if name in ds else None

    total, work = series("energy_total"), series("work_in")
    out: dict[str, np.ndarray | None] = {"total": total}
    bending, torsion = series("energy_bending"), series("energy_torsion")
    out["strain"] = bending + torsion if bending is not None and torsion is not None else None
    kinetic = series("energy_kinetic")
    if kinetic is not None:
        fluid = series("energy_kinetic_fluid")
        out["kinetic"] = kinetic + (fluid if fluid is not None else 0.0)
    elif out["strain"] is not None:
        out["kinetic"] = total - out["strain"]
    else:
        out["kinetic"] = None
    out["supplied"] = total[0] + (work - work[0])
    sea = series("seabed_work")
    out["seabed"] = -(sea - sea[0]) if sea is not None else None
    out["dissipated"] = out["supplied"] - total - (out["seabed"] if sea is not None else 0.0)
    return out


def largest_fall(t: np.ndarray, energy: np.ndarray, within: float) -> tuple[int, int] | None:
    """The output indices (i, j), i < j, t[j] − t[i] <= ``within`` s, over which
    ``energy`` (T,) falls most, or None where it never falls. Evaluated on at most 2000
    outputs (thinned evenly beyond)."""
    keep = _thin(t.size, 2000)
    tt, e = t[keep], np.nan_to_num(energy[keep], nan=-np.inf)
    best, where = 0.0, None
    for lag in range(1, tt.size):
        ok = (tt[lag:] - tt[:-lag]) <= within * (1 + 1e-9)
        if not ok.any():
            break
        fall = np.where(ok, e[:-lag] - e[lag:], -np.inf)
        k = int(np.argmax(fall))
        if fall[k] > best:
            best, where = float(fall[k]), (int(keep[k]), int(keep[k + lag]))
    return where


def energy_lines(ax, ds: xr.Dataset, t: np.ndarray, index=slice(None)) -> list:
    """Draw the energies of ``ds`` (whichever of :data:`_ENERGIES` it has) and its
    balance (:func:`energy_balance`: the energy at the start plus the work in since, what
    the seabed took, what was dissipated) against the times ``t`` into ``ax`` (y label in
    J, grid), labelled for a legend.

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
    balance = energy_balance(ds)
    for name, label, color, style in _BALANCE if balance is not None else ():
        if balance[name] is not None:
            y = balance[name][index]
            (line,) = ax.plot(t, y, style, color=color, label=label, marker=marker, ms=3)
            drawn.append((line, y))
    ax.set_ylabel("energy (J)")
    ax.grid(alpha=0.3)
    return drawn


#: Tw, Wr and Lk in the dashboard's colours (its plot palette, service/dashboard/static/
#: app.js COLORS, in the order of its topology plot's names: twist, writhe, linking_number),
#: so a curve has one colour wherever it is drawn
TOPOLOGY_COLOURS = {"twist": "#1f5fa8", "writhe": "#c0392b", "linking_number": "#27ae60"}

_TOPOLOGY = (
    ("twist", "Tw (twist)", TOPOLOGY_COLOURS["twist"]),
    ("writhe", "Wr (writhe)", TOPOLOGY_COLOURS["writhe"]),
    ("linking_number", "Lk (linking number)", TOPOLOGY_COLOURS["linking_number"]),
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
        (line,) = ax.plot(t, y, "--", color="k", lw=1.0, label="Tw + Wr")
        drawn.append((line, y))
    ax.set_ylabel("Tw, Wr, Lk (turns)")
    ax.grid(alpha=0.3)
    return drawn


ENERGY_FALL_WITHIN = 0.05   # share of the run over which the largest fall is looked for


def plot_energies(
    ds: xr.Dataset, out_dir: str | Path, stem: str = "result", on_skip: Notify | None = _stderr
) -> list[Path]:
    """Fig. 7: the energies (J) against time (s), and their balance.

    Above: whichever of ``energy_bending``, ``energy_torsion``, ``energy_kinetic``,
    ``energy_kinetic_fluid``, ``energy_total`` are present, and with ``work_in`` the
    balance's curves (:func:`energy_balance`): the energy at the start plus the work in
    since, what the seabed took (with a seabed) and what was dissipated. Below (with
    ``work_in``): the balance stacked, strain + kinetic + seabed + dissipated, whose top is
    the energy at the start plus the work in, each share its own colour; the largest fall
    of the total energy within a twentieth of the run (:func:`largest_fall`) is shaded
    and its account written out (the seed example's collapse into its loop at 18 s: the
    total falls 1.9 J while the work in grows 0.1 J, and the dissipated energy grows by
    the difference). Writes ``<stem>_energies.png``.
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
    balance = energy_balance(ds)
    stacked = balance is not None and balance["strain"] is not None
    fig = Figure(figsize=(9.0, 7.6 if stacked else 4.8), layout="constrained")
    if stacked:
        ax, ax_sum = fig.subplots(2, 1, sharex=True, height_ratios=(1, 1))
    else:
        ax, ax_sum = fig.add_subplot(), None
    energy_lines(ax, ds, t)
    ax.set_title(f"{_title(ds)}: energies")
    ax.legend(fontsize=7, loc="upper left", ncol=2)
    if ax_sum is None:
        ax.set_xlabel("time (s)")
        return [_save(fig, Path(out_dir) / f"{stem}_energies.png")]

    layers = [("strain (bending + torsion)", balance["strain"], "C0"),
              ("kinetic (rod + added fluid)", balance["kinetic"], "C2")]
    if balance["seabed"] is not None:
        layers.append(("taken by the seabed", balance["seabed"], "saddlebrown"))
    layers.append(("dissipated (drag, contact, scheme)", balance["dissipated"], "C3"))
    base = np.zeros_like(t)
    for label, y, color in layers:
        top = base + np.nan_to_num(y)
        ax_sum.fill_between(t, base, top, color=color, alpha=0.45, lw=0, label=label)
        base = top
    ax_sum.plot(t, balance["supplied"], "--", color="k", lw=1.2,
                label="energy at the start + work in since")
    ax_sum.set_ylabel("energy (J)")
    ax_sum.set_xlabel("time (s)")
    ax_sum.grid(alpha=0.3)
    ax_sum.set_title("where the energy went: the shares add up to the energy at the start "
                     "plus the work in", fontsize=9)
    span = ENERGY_FALL_WITHIN * float(t[-1] - t[0]) if t.size > 1 else 0.0
    fall = largest_fall(t, balance["total"], max(span, 2.0 * float(np.max(np.diff(t)))
                                                 if t.size > 1 else 0.0))
    if fall is not None:
        i, j = fall

        def change(y):
            return float(y[j] - y[i])

        words = [f"{t[i]:g}-{t[j]:g} s: total {change(balance['total']):+#.3g} J",
                 f"work in {change(balance['supplied']):+#.3g} J"]
        if balance["seabed"] is not None:
            words.append(f"seabed took {change(balance['seabed']):+#.3g} J")
        words.append(f"dissipated {change(balance['dissipated']):+#.3g} J")
        for a in (ax, ax_sum):
            a.axvspan(t[i], t[j], color="0.5", alpha=0.15, lw=0)
        ax_sum.text(0.01, 0.97, "largest fall of the total, " + ", ".join(words),
                    transform=ax_sum.transAxes, va="top", fontsize=8,
                    bbox={"facecolor": "white", "alpha": 0.85, "edgecolor": "0.7"})
    ax_sum.legend(fontsize=7, loc="center left")
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
    """Figs. 6, 7 and 8 for ``ds`` into ``out_dir``, and the tweezers curves of a
    tweezers run (:func:`plot_tweezers`); returns the paths written."""
    paths = plot_snapshots(ds, out_dir, times=times, stem=stem, on_skip=on_skip)
    paths += plot_energies(ds, out_dir, stem=stem, on_skip=on_skip)
    paths += plot_topology(ds, out_dir, stem=stem, on_skip=on_skip)
    paths += plot_tweezers(ds, out_dir, stem=stem, on_skip=on_skip)
    return paths


#: a rod shorter than this (m) is drawn in the single-molecule units nm, pN and pN nm
MOLECULAR_LENGTH = 1e-5


def tweezers_units(length: float) -> dict[str, tuple[str, float]]:
    """The units :func:`plot_tweezers` labels its axes in, for a rod of ``length`` (m):
    ``{"extension": (label, factor), "torque": ..., "force": ...}``, the factor turning
    the SI value into the label's unit. Below :data:`MOLECULAR_LENGTH` (10 µm, a
    molecule) nm, pN nm and pN, the SI multiples a single-molecule experiment reports
    (1 nm = 1e-9 m, 1 pN nm = 1e-21 N m); above it m, N m and N. The data stay SI."""
    if length < MOLECULAR_LENGTH:
        return {"extension": ("nm", 1e9), "torque": ("pN nm", 1e21), "force": ("pN", 1e12)}
    return {"extension": ("m", 1.0), "torque": ("N m", 1.0), "force": ("N", 1.0)}


def plot_tweezers(
    ds: xr.Dataset, out_dir: str | Path, stem: str = "result", on_skip: Notify | None = _stderr
) -> list[Path]:
    """The magnetic-tweezers curves of a tweezers run, against the turns put in.

    ``<stem>_extension.png``: the extension along the force (the hat curve; needs
    ``position``); ``<stem>_torque.png``: the rod's torque about the force's axis at the
    pulled end (needs the ``reactions`` output), with the straight rod's 2π G J3 n / L
    dashed for a uniform rod. Both from :func:`solver.results.tweezers_series`, in the
    units of :func:`tweezers_units`. A result whose case is not a tweezers run
    (:data:`solver.results.TWEEZERS_RULE`) draws nothing and says nothing; a tweezers run
    without the variables a figure needs reports it through ``on_skip``.
    """
    series = tweezers_series(ds)
    if series is None:
        return []
    units = tweezers_units(series["length"])
    turns = series["turns"]
    force_unit, force_factor = units["force"]
    pull = f"{series['force'] * force_factor:.3g} {force_unit}"
    marker = "o" if turns.size < 30 else None
    paths = []
    if series["extension"] is None:
        if on_skip:
            on_skip("tweezers extension skipped: the dataset has no 'position' variable")
    else:
        unit, factor = units["extension"]
        fig = Figure(figsize=(7.0, 4.8), layout="constrained")
        ax = fig.add_subplot()
        ax.plot(turns, series["extension"] * factor, color="C0", marker=marker, ms=3)
        ax.set_xlabel("turns n (prescribed end rotation / 2π)")
        ax.set_ylabel(f"extension along the force ({unit})")
        ax.set_title(f"{_title(ds)}: extension at a force of {pull}")
        ax.grid(alpha=0.3)
        paths.append(_save(fig, Path(out_dir) / f"{stem}_extension.png"))
    if series["torque"] is None:
        if on_skip:
            on_skip("tweezers torque skipped: the dataset has no reaction_moment_* variables "
                    "(output.fields: reactions)")
    else:
        unit, factor = units["torque"]
        fig = Figure(figsize=(7.0, 4.8), layout="constrained")
        ax = fig.add_subplot()
        ax.plot(turns, series["torque"] * factor, color="C3", marker=marker, ms=3,
                label="torque at the pulled end")
        if series["twist_torque"] is not None:
            ax.plot(turns, series["twist_torque"] * factor, color="0.4", ls="--", lw=1,
                    label="straight rod, 2π G J n / L")
        ax.set_xlabel("turns n (prescribed end rotation / 2π)")
        ax.set_ylabel(f"torque about the force's axis ({unit})")
        ax.set_title(f"{_title(ds)}: torque at a force of {pull}")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        paths.append(_save(fig, Path(out_dir) / f"{stem}_torque.png"))
    return paths
