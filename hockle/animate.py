"""An animation of a result: the rod in 3-D beside its energies and Tw/Wr/Lk growing in time.

:func:`animate` draws, for evenly spaced stored outputs of a result file (or an
:class:`xarray.Dataset`), one frame each: on the left the rod in a 3-D view as
``hockle plot`` draws it (a tube of its real, varying diameter, contact sites as orange
dots, the start end a red circle and the far end a green square, named in a legend; the
drawing is :func:`hockle.plots.draw_rod`), in one fixed cube that holds every frame,
zoomed as ``hockle plot``'s snapshots are to where the rod moves when that is a small
part of it (:func:`hockle.plots.action_box`: a loop rising out of a cable on the sea
floor), the title then naming the stretch of the rod shown; on the right the energies and twist, writhe and linking number (:func:`hockle.plots.energy_lines`,
:func:`hockle.plots.topology_lines`) drawn up to the frame's time, with a vertical cursor
at it, on axes that cover the whole time window; the figure's title gives t.

The writer follows the output's suffix: ``.gif`` with Pillow (matplotlib's
:class:`~matplotlib.animation.PillowWriter`, no ffmpeg needed), ``.mp4`` with ffmpeg
(:class:`~matplotlib.animation.FFMpegWriter`, H.264); when ffmpeg is missing an
``.mp4`` is refused up front with :class:`AnimationError`, which suggests a ``.gif``.

Memory stays bounded: the file is opened lazily and the rod's positions are read a few
outputs at a time (:data:`BATCH`), one frame is drawn at a time into one figure (the
previous rod's artists are removed), and an ``.mp4`` is streamed to ffmpeg. The box is
found from the frames' shapes, kept for that (frames x grid points x 3 numbers). A GIF is
written by Pillow in one go at the end, so its frames are kept until then, as 8-bit
palette images (width x height bytes each: about 0.3 MB at the default size and dpi).
The output is written to a temporary file beside it and moved into place when complete.

Figures are drawn on :class:`matplotlib.figure.Figure` objects with the Agg canvas, never
through pyplot.
"""
from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import xarray as xr
from matplotlib import animation
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from hockle.plots import (
    ZOOM_BELOW,
    _title,
    action_box,
    contact_sites,
    draw_rod,
    draw_seabed,
    seabed_of,
    energy_lines,
    rod_box,
    rod_diameter,
    rod_legend_handles,
    setup_rod_axes,
    topology_lines,
)

__all__ = [
    "animate",
    "animation_frames",
    "AnimationError",
    "NothingToAnimate",
    "DEFAULT_FRAMES",
    "DEFAULT_FPS",
    "DEFAULT_DPI",
]

DEFAULT_FRAMES = 150    # frames at most: the stored outputs are subsampled evenly
DEFAULT_FPS = 15
DEFAULT_DPI = 80
BATCH = 16              # stored outputs of `position` read from the file at once
FIGSIZE = (11.0, 5.6)   # inches; 880 x 448 pixels at the default dpi
ZOOM = 1.15             # the 3-D box, larger than matplotlib's default

FFMPEG_SUFFIXES = (".mp4",)
PILLOW_SUFFIXES = (".gif",)

Progress = Callable[[int, int], None]


class AnimationError(ValueError):
    """The animation cannot be made as asked: an output format this machine cannot write
    (``.mp4`` without ffmpeg, an unknown suffix), bad options, or a time window without a
    stored output. The message says what to do instead."""


class NothingToAnimate(AnimationError):
    """The dataset has nothing to animate: no ``position``, or no stored output."""


class _PaletteGifWriter(animation.PillowWriter):
    """matplotlib's PillowWriter, keeping each frame as an 8-bit palette image (a third of
    the memory of the RGB frame it replaces) until :meth:`finish` writes the GIF, which
    Pillow does in one go. No dithering: flat plot colours compress better."""

    def grab_frame(self, **savefig_kwargs):
        from PIL import Image

        super().grab_frame(**savefig_kwargs)
        frame = self._frames[-1]
        self._frames[-1] = frame.convert("RGB").quantize(
            colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE
        )


def _writer(out: Path, fps: float, title: str):
    """The matplotlib movie writer for ``out``'s suffix, or AnimationError saying why not."""
    suffix = out.suffix.lower()
    if suffix in PILLOW_SUFFIXES:
        return _PaletteGifWriter(fps=fps)
    if suffix in FFMPEG_SUFFIXES:
        if not animation.writers.is_available("ffmpeg"):
            raise AnimationError(
                f"cannot write {out}: {suffix} needs ffmpeg, which is not installed here "
                "(not on PATH, nor at matplotlib's rcParams['animation.ffmpeg_path']); "
                f"write a GIF instead (Pillow, no ffmpeg needed): -o {out.with_suffix('.gif')}"
            )
        return animation.FFMpegWriter(fps=fps, metadata={"title": title})
    raise AnimationError(
        f"cannot write {out}: unknown animation format {suffix or '(no suffix)'}; "
        "use .gif (Pillow) or .mp4 (ffmpeg)"
    )


def animation_frames(
    times: np.ndarray, frames: int = DEFAULT_FRAMES, window: Sequence[float] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Which stored outputs to draw: ``(window, frames)``, indices into ``times``.

    ``window`` are the outputs with ``T0 <= t <= T1`` (all of them without a window; the
    bounds are widened by 1e-9 of the run's span against round-off), the curves' range;
    ``frames`` at most ``frames`` of those, evenly spaced, the first and last included.
    Raises :class:`AnimationError` for a window that holds no stored output or whose
    bounds are reversed, :class:`NothingToAnimate` when there is no stored time.
    """
    times = np.asarray(times, dtype=float)
    if times.size == 0:
        raise NothingToAnimate("the result has no stored time")
    if frames < 1:
        raise AnimationError(f"--frames must be at least 1 (got {frames})")
    if window is None:
        inside = np.arange(times.size)
    else:
        t0, t1 = (float(x) for x in window)
        if not t0 <= t1:
            raise AnimationError(f"--times T0 T1: T0 ({t0:g} s) is after T1 ({t1:g} s)")
        eps = 1e-9 * max(float(times[-1] - times[0]), 1.0)
        inside = np.flatnonzero((times >= t0 - eps) & (times <= t1 + eps))
        if inside.size == 0:
            raise AnimationError(
                f"no stored output between {t0:g} and {t1:g} s (the result holds "
                f"{times[0]:g} ... {times[-1]:g} s)"
            )
    if inside.size <= frames:
        return inside, inside
    pick = np.unique(np.round(np.linspace(0, inside.size - 1, frames)).astype(int))
    return inside, inside[pick]


def _batches(indices: np.ndarray, size: int = BATCH):
    for k in range(0, len(indices), size):
        yield indices[k:k + size]


def _positions(ds: xr.Dataset, indices: np.ndarray):
    """Yield ``(index, r (N, 3))`` for the outputs ``indices``, read BATCH at a time."""
    pos = ds["position"].transpose("time", "s", "xyz")
    for batch in _batches(indices):
        block = np.asarray(pos.isel(time=batch).values, dtype=float)
        yield from zip(batch, block)


def _curve_axes(ax, drawn: list, t: np.ndarray) -> None:
    """Fixed limits for curves that grow: the whole window in t, every value in y, with
    room above the data for a legend of the curves in the upper left corner."""
    lo_t, hi_t = float(t[0]), float(t[-1])
    if hi_t <= lo_t:
        lo_t, hi_t = lo_t - 0.5, hi_t + 0.5
    ax.set_xlim(lo_t, hi_t)
    ncol = 2 if len(drawn) > 2 else 1
    rows = math.ceil(len(drawn) / ncol)
    values = np.concatenate([y for _, y in drawn]) if drawn else np.zeros(0)
    values = values[np.isfinite(values)]
    if values.size:
        lo, hi = float(values.min()), float(values.max())
        span = hi - lo if hi > lo else max(abs(hi), 1.0)
        ax.set_ylim(lo - 0.05 * span, hi + (0.08 + 0.11 * rows) * span)
    ax.legend(fontsize=7, loc="upper left", ncol=ncol)


def _time_format(t: np.ndarray) -> str:
    """Format of the frames' times: the fewest decimals (at most 4) that write every one
    exactly, fixed so that the title keeps its width."""
    t = np.asarray(t, dtype=float)
    t = t[np.isfinite(t)]
    scale = max(float(np.max(np.abs(t))) if t.size else 0.0, 1.0)
    for decimals in range(5):
        if np.all(np.abs(np.round(t, decimals) - t) <= 1e-9 * scale):
            return f".{decimals}f"
    return ".4f"


def animate(
    source: str | os.PathLike[str] | xr.Dataset,
    out: str | os.PathLike[str],
    *,
    frames: int = DEFAULT_FRAMES,
    fps: float = DEFAULT_FPS,
    dpi: float = DEFAULT_DPI,
    window: Sequence[float] | None = None,
    progress: Progress | None = None,
    zoom: bool | None = None,
) -> Path:
    """Write an animation of the result ``source`` (a file, opened lazily, or a dataset).

    One frame for each of at most ``frames`` stored outputs spread evenly over the run, or
    over ``window = (T0, T1)`` in s (:func:`animation_frames`), shown at ``fps`` frames per
    second, rendered at ``dpi`` (the figure is 11 x 5.6 inches). The format follows
    ``out``'s suffix (``.gif``: Pillow; ``.mp4``: ffmpeg). ``progress(done, total)`` is
    called after every frame. Needs ``position``; energies and Tw/Wr/Lk panels are drawn
    when the dataset has them. ``zoom`` as for :func:`hockle.plots.plot_snapshots`: None
    zooms the rod's box to where it moves when that is a small part of it
    (:func:`hockle.plots.action_box` over the frames' shapes), False draws the whole rod,
    True zooms where ``action_box`` finds an action at all.

    Returns ``out`` as a :class:`~pathlib.Path`. Raises :class:`AnimationError` when the
    format cannot be written here or the options are bad (before anything is drawn),
    :class:`NothingToAnimate` when the dataset has no ``position`` or no stored output,
    :class:`OSError` when the file cannot be written (``out`` is then left untouched).
    """
    out = Path(out)
    if not (isinstance(fps, (int, float)) and fps > 0):
        raise AnimationError(f"--fps must be positive (got {fps})")
    if not (isinstance(dpi, (int, float)) and dpi > 0):
        raise AnimationError(f"--dpi must be positive (got {dpi})")
    if isinstance(source, xr.Dataset):
        return _animate(source, out, frames, fps, dpi, window, progress, zoom)
    with xr.open_dataset(source, engine="netcdf4") as ds:
        return _animate(ds, out, frames, fps, dpi, window, progress, zoom)


def _animate(ds, out, frames, fps, dpi, window, progress, zoom=None) -> Path:
    title = _title(ds) or out.stem
    writer = _writer(out, fps, title)
    if "position" not in ds:
        raise NothingToAnimate("the result has no 'position' variable: no rod to draw")
    times = np.asarray(ds["time"].values, dtype=float) if "time" in ds.coords else np.zeros(0)
    inside, chosen = animation_frames(times, frames, window)
    t_win = times[inside]
    window_index = slice(int(inside[0]), int(inside[-1]) + 1)   # contiguous by construction

    s = np.asarray(ds["s"].values, dtype=float)
    diameter = rod_diameter(ds, s)
    counts = None
    if "contact_count" in ds:
        counts = np.nan_to_num(np.asarray(ds["contact_count"].values, dtype=float))

    # one cube for every frame: a first pass over the chosen outputs, BATCH at a time
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    shapes = []
    for _, r in _positions(ds, chosen):
        shapes.append(r)
        if np.any(np.isfinite(r)):
            lo = np.fmin(lo, np.nanmin(r, axis=0))
            hi = np.fmax(hi, np.nanmax(r, axis=0))
    if not np.all(np.isfinite(lo)):
        raise NothingToAnimate("the rod's positions are not finite at any chosen output")
    lims = rod_box(np.stack([lo, hi]), diameter)
    focus = None          # zoomed to the action, as hockle plot's snapshots are
    if zoom is not False:
        focus = action_box(ds, np.stack(shapes), s, diameter,
                           below=np.inf if zoom else ZOOM_BELOW)
    del shapes
    zoomed = ""
    if focus is not None:
        lims, (s0, s1) = focus
        zoomed = f", zoomed to s = {s0:.3g}-{s1:.3g} m of {s[-1]:g} m, where it moves most"

    fig = Figure(figsize=FIGSIZE, layout="constrained")
    FigureCanvasAgg(fig)
    panels = []
    if any(name in ds for name in ("energy_bending", "energy_torsion", "energy_kinetic",
                                   "energy_total")):
        panels.append(energy_lines)
    if any(name in ds for name in ("twist", "writhe", "linking_number")):
        panels.append(topology_lines)
    grid = fig.add_gridspec(max(len(panels), 1), 2 if panels else 1,
                            width_ratios=(1.2, 1) if panels else None)
    ax3 = fig.add_subplot(grid[:, 0], projection="3d")
    setup_rod_axes(ax3, lims, zoom=ZOOM)
    ax3.computed_zorder = False     # ends and contact sites stay visible on the tube
    seabed = seabed_of(ds)
    if seabed is not None:          # drawn once: the bottom does not move
        draw_seabed(ax3, lims, seabed)

    curves = []      # (line, values) of every panel
    cursors = []
    first = None
    for row, draw in enumerate(panels):
        ax = fig.add_subplot(grid[row, 1], sharex=first)
        first = first or ax
        drawn = draw(ax, ds, t_win, index=window_index)
        _curve_axes(ax, drawn, t_win)
        if row == len(panels) - 1:
            ax.set_xlabel("time (s)")
        else:
            ax.tick_params(labelbottom=False)
        cursors.append(ax.axvline(t_win[0], color="0.4", lw=0.8, ls=":"))
        curves += drawn

    contact = diameter is not None and (counts is None or bool(np.any(counts[inside] > 0)))
    fig.legend(handles=rod_legend_handles(s, diameter, contact),
               loc="outside lower center", ncol=4, fontsize=8)
    tfmt = _time_format(times[chosen])

    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{out.name}.", suffix=out.suffix,
                                    dir=out.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        rod: list = []
        with writer.saving(fig, str(tmp), dpi):
            for done, (i, r) in enumerate(_positions(ds, chosen), start=1):
                t = float(times[i])
                for artist in rod:
                    artist.remove()
                touching = None
                if counts is None or counts[i] > 0:
                    touching = contact_sites(ds, r, s, diameter)
                rod = draw_rod(ax3, r, diameter, touching,
                               clip=lims if focus is not None else None)
                k = int(np.searchsorted(t_win, t, side="right"))
                for line, y in curves:
                    line.set_data(t_win[:k], y[:k])
                for cursor in cursors:
                    cursor.set_xdata([t, t])
                fig.suptitle(f"{title}: t = {t:{tfmt}} s{zoomed}")
                if done == 1:
                    # lay out once, then keep it: the frames must not shift
                    fig.canvas.draw()
                    fig.set_layout_engine("none")
                writer.grab_frame()
                if progress:
                    progress(done, len(chosen))
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, out)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return out
