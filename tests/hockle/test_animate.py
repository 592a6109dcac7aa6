"""hockle animate (hockle.animate): GIFs of synthetic results with the expected number of
frames, the time window, reading the file frame by frame, and the clear errors (an .mp4
without ffmpeg, an unknown format, a result without positions, an empty window)."""
from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from matplotlib import animation
from PIL import Image

import hockle.animate as anim
from hockle.cli import main
from hockle.io import write_netcdf
from test_cli import synthetic_result
from test_plots import _lay_dataset
from test_plots import dataset as events_dataset


def gif_frames(path) -> int:
    with Image.open(path) as im:
        assert im.format == "GIF"
        return im.n_frames


def test_animate_a_result_to_a_gif_with_the_frames_asked_for(tmp_path, capsys):
    nc = synthetic_result(tmp_path)                       # 12 outputs, 0 ... 1.1 s
    out = tmp_path / "anim" / "run.gif"
    assert main(["animate", str(nc), "-o", str(out), "--frames", "5", "--dpi", "30",
                 "--fps", "4"]) == 0
    captured = capsys.readouterr()
    assert captured.out.strip() == str(out)
    assert "frame 5/5" in captured.err                    # progress lines
    assert gif_frames(out) == 5
    with Image.open(out) as im:
        assert im.size == (330, 168)                      # 11 x 5.6 inches at 30 dpi
        assert im.info["duration"] == 250                 # 4 frames per second
    assert [p.name for p in out.parent.iterdir()] == ["run.gif"]   # no temporary left


def test_default_output_is_a_gif_next_to_the_result_every_output_a_frame(tmp_path, capsys):
    nc = synthetic_result(tmp_path)
    assert main(["animate", str(nc), "-q", "--dpi", "30"]) == 0
    assert capsys.readouterr().err == ""
    assert gif_frames(tmp_path / "synthetic.gif") == 12   # fewer outputs than --frames


def test_time_window_and_contact_sites_of_a_run_with_events(tmp_path):
    # tests/hockle/test_plots.py's run: buckles at 1.4 s, touches from 1.8 s; 31 outputs 0 ... 3 s
    nc = write_netcdf(events_dataset(), tmp_path / "events.nc")
    out = tmp_path / "window.gif"
    assert main(["animate", str(nc), "-o", str(out), "--times", "1.0", "2.0",
                 "--dpi", "30", "-q"]) == 0
    assert gif_frames(out) == 11                           # 1.0, 1.1, ..., 2.0


def test_frames_are_spread_evenly_over_the_window():
    times = np.round(np.arange(0.0, 3.01, 0.1), 10)
    inside, chosen = anim.animation_frames(times, 4)
    assert inside.tolist() == list(range(31))
    assert chosen.tolist() == [0, 10, 20, 30]
    inside, chosen = anim.animation_frames(times, 3, window=(0.95, 1.5))
    assert times[inside] == pytest.approx(np.arange(1.0, 1.51, 0.1))
    assert chosen.tolist() == [10, 12, 15]
    inside, chosen = anim.animation_frames(times, 150, window=(2.0, 2.0))
    assert chosen.tolist() == [20]


def test_positions_are_read_from_the_file_a_few_outputs_at_a_time(tmp_path, monkeypatch):
    nc = write_netcdf(events_dataset(), tmp_path / "events.nc")
    monkeypatch.setattr(anim, "BATCH", 4)
    read = []
    original = anim._positions

    def spy(ds, indices):
        for i, r in original(ds, indices):
            read.append(i)
            yield i, r

    monkeypatch.setattr(anim, "_positions", spy)
    with xr.open_dataset(nc, engine="netcdf4") as ds:
        anim.animate(ds, tmp_path / "lazy.gif", frames=6, dpi=30)
        assert not ds["position"].variable._in_memory     # never loaded whole
    assert len(read) == 2 * 6                              # the box, then the frames
    assert gif_frames(tmp_path / "lazy.gif") == 6


def _rod_axes_limits(monkeypatch, ds, out, **kw):
    """The 3-D axes' limits after animating ``ds`` (the axes caught as they are set up)."""
    caught = []
    original = anim.setup_rod_axes

    def spy(ax3, lims, **kwargs):
        caught.append(ax3)
        return original(ax3, lims, **kwargs)

    monkeypatch.setattr(anim, "setup_rod_axes", spy)
    anim.animate(ds, out, frames=3, dpi=20, **kw)
    [ax3] = caught
    return [ax3.get_xlim(), ax3.get_ylim(), ax3.get_zlim()]


def test_a_loop_on_a_long_cable_is_animated_zoomed_as_hockle_plot_draws_it(tmp_path,
                                                                           monkeypatch):
    """tests/hockle/test_plots.py's 4-m cable with a loop rising out of s = 3.2-3.6 m: the
    animation's box is hockle plot's zoom to the loop (hockle.plots.action_box over the
    frames drawn), under half a metre; zoom=False and a rod that moves all along keep the
    whole rod's box."""
    from hockle.plots import action_box, rod_box

    ds = _lay_dataset()
    s = ds["s"].values
    shapes = ds["position"].transpose("time", "s", "xyz").values[[0, 15, 30]]  # the 3 frames
    diameter = np.full(s.size, 0.02)
    lims, _ = action_box(ds, shapes, s, diameter)
    got = _rod_axes_limits(monkeypatch, ds, tmp_path / "lay.gif")
    assert np.allclose(got, lims)
    assert max(hi - lo for lo, hi in got) < 0.5 and got[0][0] > 3.0   # around the loop
    whole = _rod_axes_limits(monkeypatch, ds, tmp_path / "whole.gif", zoom=False)
    assert np.allclose(whole, rod_box(shapes, diameter))
    bow = events_dataset()                                  # the whole rod moves: no zoom
    bow_shapes = bow["position"].transpose("time", "s", "xyz").values[[0, 15, 30]]
    assert np.allclose(_rod_axes_limits(monkeypatch, bow, tmp_path / "bow.gif"),
                       rod_box(bow_shapes, np.full(bow_shapes.shape[1], 0.02)))


def test_mp4_without_ffmpeg_is_refused_with_a_pointer_to_gif(tmp_path, monkeypatch, capsys):
    nc = synthetic_result(tmp_path)
    available = animation.writers.is_available
    monkeypatch.setattr(animation.writers, "is_available",
                        lambda name: False if name == "ffmpeg" else available(name))
    out = tmp_path / "run.mp4"
    assert main(["animate", str(nc), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "needs ffmpeg, which is not installed" in err
    assert str(tmp_path / "run.gif") in err
    assert list(tmp_path.glob("*.mp4")) == [] and list(tmp_path.glob(".run.mp4*")) == []


def test_mp4_uses_ffmpeg_when_it_is_there(monkeypatch):
    monkeypatch.setattr(animation.writers, "is_available", lambda name: True)
    writer = anim._writer(anim.Path("run.mp4"), 10, "title")
    assert isinstance(writer, animation.FFMpegWriter)
    assert isinstance(anim._writer(anim.Path("run.GIF"), 10, "t"), animation.PillowWriter)


def test_clear_errors(tmp_path, capsys):
    nc = synthetic_result(tmp_path)
    assert main(["animate", str(nc), "-o", str(tmp_path / "run.avi")]) == 2
    assert "unknown animation format .avi; use .gif (Pillow) or .mp4 (ffmpeg)" in (
        capsys.readouterr().err)
    assert main(["animate", str(nc), "--times", "5", "6"]) == 2
    assert "no stored output between 5 and 6 s" in capsys.readouterr().err
    assert main(["animate", str(nc), "--times", "1", "0.5"]) == 2
    assert main(["animate", str(nc), "--frames", "0"]) == 2
    assert main(["animate", str(nc), "--fps", "0"]) == 2
    capsys.readouterr()
    no_rod = synthetic_result(tmp_path / "bare", fields=("energies",))
    assert main(["animate", str(no_rod)]) == 1
    assert "nothing to animate" in capsys.readouterr().err
    junk = tmp_path / "junk.nc"
    junk.write_text("not a netcdf file")
    assert main(["animate", str(junk)]) == 2
    assert "cannot read" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.gif"))


def test_cli_defaults_are_the_modules():
    from hockle.cli import build_parser

    parser, _ = build_parser()
    args = parser.parse_args(["animate", "x.nc"])
    assert (args.frames, args.fps, args.dpi) == (
        anim.DEFAULT_FRAMES, anim.DEFAULT_FPS, anim.DEFAULT_DPI)
