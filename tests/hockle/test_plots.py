"""Figures at the events: hockle.plots.event_times, snapshot_times, contact_sites and the
snapshot figure, on synthetic datasets whose events are known by construction."""
from __future__ import annotations

import copy

import numpy as np
import pytest

from rodcases import tiny_spec
from hockle.plots import (
    MAX_EVENTS,
    TOUCH_GAP,
    contact_sites,
    event_times,
    plot_snapshots,
    rod_diameter,
    snapshot_times,
)
from solver.case import Case
from solver.results import build_dataset

CASE = tiny_spec("synthetic events", n_segments=100, dt=0.1, t_end=3.0,
                 diameter={"s": [0.0, 0.4, 0.6, 1.0], "value": [0.02, 0.018, 0.018, 0.02]})

N = 101
TIMES = np.round(np.arange(0.0, 3.01, 0.1), 10)     # 31 outputs, 0 ... 3 s
S = np.linspace(0.0, 1.0, N)


def _shape(t: float) -> np.ndarray:
    """Straight along z (a 1e-4 m wiggle) until 1 s, then a bow growing 5.5 cm per second."""
    r = np.zeros((N, 3))
    r[:, 2] = S
    amp = 1e-4 + (0.055 * (t - 1.0) if t > 1.0 else 0.0)
    r[:, 0] = amp * np.sin(np.pi * S)
    return r


def dataset(writhe=None, contact_from=1.8, status="completed", case=CASE):
    """Buckles at 1.4 s (the bow, 1e-4 m + 5.5 cm/s after 1 s, has grown by one diameter,
    0.02 m, at 1.36 s), first contact at ``contact_from``, and a writhe that rises from 1.2 s to 2.6
    turns at 3 s (reaching 1 at 1.9 s and 2 at 2.6 s)."""
    if writhe is None:
        writhe = np.clip((TIMES - 1.2) / (3.0 - 1.2) * 2.6, 0.0, None)
    data = {
        "position": np.stack([_shape(t) for t in TIMES]),
        "writhe": writhe,
        "twist": 3.0 - writhe,
        "linking_number": np.full(TIMES.size, 3.0),
        "contact_count": np.where(TIMES >= contact_from - 1e-9, 4, 0),
    }
    return build_dataset(Case.model_validate(case), S, TIMES, data, {}, status)


def test_events_of_a_run_in_order_with_their_names():
    events = event_times(dataset())
    assert events == [
        (pytest.approx(1.4), "onset of buckling"),
        (pytest.approx(1.8), "first contact"),
        (pytest.approx(1.9), "Wr reaches 1"),
        (pytest.approx(2.6), "Wr reaches 2"),
        (pytest.approx(3.0), "end"),
    ]
    # the default snapshot times are these events
    assert snapshot_times(dataset()) == pytest.approx([1.4, 1.8, 1.9, 2.6, 3.0])


def test_events_at_one_stored_time_are_merged_and_a_stopped_run_says_so():
    events = event_times(dataset(contact_from=1.9, status="stopped"))
    assert (pytest.approx(1.9), "first contact; Wr reaches 1") in events
    assert events[-1] == (pytest.approx(3.0), "end (stopped)")


def test_negative_writhe_and_many_unit_steps_are_thinned():
    wr = -np.clip((TIMES - 1.2) * 12.0, 0.0, None)       # to -21.6 turns
    events = event_times(dataset(writhe=wr))
    labels = [label for _, label in events]
    assert len(events) == MAX_EVENTS
    # buckling, contact and the end keep their rows; a unit step of Wr at one of their
    # times shares the row, the others are thinned evenly to fill the rest
    assert labels[1] == "onset of buckling; Wr reaches -2"
    assert labels[3] == "first contact; Wr reaches -7"
    assert labels[-1] == "end; Wr reaches -21"
    own = [label for label in labels if label.startswith("Wr reaches")]
    assert own[0] == "Wr reaches -1" and len(own) == MAX_EVENTS - 3
    assert [t for t, _ in events] == sorted(t for t, _ in events)


def test_without_position_the_writhe_marks_the_buckling():
    ds = dataset().drop_vars("position")
    assert event_times(ds)[0] == (pytest.approx(1.3), "onset of buckling")  # Wr > 0.05 turns


def test_nothing_happened_falls_back_to_evenly_spaced_times():
    ds = dataset(writhe=np.zeros(TIMES.size), contact_from=99.0)
    ds["position"].values[:] = np.stack([_shape(0.0)] * TIMES.size)
    assert event_times(ds) == [(pytest.approx(3.0), "end")]
    chosen = snapshot_times(ds)
    assert chosen == pytest.approx([0.0, 0.7, 1.5, 2.2, 3.0])   # nearest to 0.75, 2.25
    # asked-for times still win over the events
    assert snapshot_times(dataset(), [0.31, 2.0]) == pytest.approx([0.3, 2.0])


def test_rod_diameter_from_the_case_in_the_file():
    ds = dataset()
    d = rod_diameter(ds, np.array([0.0, 0.2, 0.5, 1.0]))
    assert d == pytest.approx([0.02, 0.019, 0.018, 0.02])
    ds.attrs["case"] = "not json"
    assert rod_diameter(ds, S) is None


def test_contact_sites_of_a_hairpin():
    # two straight strands 0.019 m apart (touching: diameter 0.018-0.02 m) joined by a fold
    r = np.zeros((N, 3))
    half = N // 2
    r[:half, 2] = S[:half]
    r[half:, 2] = S[half - 1] - (S[half:] - S[half - 1])
    r[half:, 0] = 0.019
    ds = dataset()
    d = rod_diameter(ds, S)
    sites = contact_sites(ds, r, S, d)
    assert sites.size > 0.8 * N
    assert np.any(sites < half) and np.any(sites >= half)        # both strands
    # neighbours along the rod are not contacts: a straight rod touches nothing
    straight = np.column_stack([np.zeros(N), np.zeros(N), S])
    assert contact_sites(ds, straight, S, d).size == 0
    # a gap of a quarter diameter still touches (within half a segment), two diameters not
    r[half:, 0] = 0.019 + 0.25 * 0.018
    assert contact_sites(ds, r, S, d).size > 0
    r[half:, 0] = 0.06
    assert contact_sites(ds, r, S, d).size == 0
    # the case's exclusion decides what is a neighbour: 2 m leaves no pair
    r[half:, 0] = 0.019
    case = copy.deepcopy(CASE)
    case["contact"] = {"aperture": 90.0, "tolerance": 0.04, "k1": 1e-7, "k2": 3.0,
                       "k3": 1e-6, "k4": 1.0, "exclusion": 2.0}
    assert contact_sites(dataset(case=case), r, S, d).size == 0
    # no diameter in the file: nothing is marked
    assert contact_sites(ds, r, S, None).size == 0


def test_contact_sites_on_a_grid_coarser_than_the_exclusion():
    """Segments longer than the default exclusion (2 diameters) but within the touching
    reach ((1 + TOUCH_GAP) d + half a segment) of each other: neighbours are still not
    contacts (a straight rod of 23 segments of 2.2 diameters marks nothing; every node was
    marked before), and a hairpin on that grid still touches on both strands."""
    s = np.linspace(0.0, 1.0, 24)                       # h = 0.0435 m, d 0.018-0.02 m
    ds = dataset()
    d = rod_diameter(ds, s)
    assert 2.0 * d.max() < s[1] < (1.0 + TOUCH_GAP) * d.min() + 0.5 * s[1]
    straight = np.column_stack([np.zeros(s.size), np.zeros(s.size), s])
    assert contact_sites(ds, straight, s, d).size == 0
    half = s.size // 2
    r = straight.copy()
    r[half:, 2] = s[half - 1] - (s[half:] - s[half - 1])
    r[half:, 0] = 0.019
    sites = contact_sites(ds, r, s, d)
    assert np.any(sites < half - 2) and np.any(sites > half + 2)


def test_snapshot_figure_at_the_events(tmp_path):
    paths = plot_snapshots(dataset(), tmp_path, stem="events", on_skip=None)
    assert [p.name for p in paths] == ["events_snapshots.png"]
    assert paths[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # without a diameter in the file it draws the centreline
    ds = dataset()
    ds.attrs["case"] = "{}"
    assert plot_snapshots(ds, tmp_path, stem="bare", on_skip=None)


def test_a_branch_with_sparse_shapes_is_drawn_through_its_stored_points():
    """A measure of the shape (the lateral excursion) is defined only where the shape is
    stored (--shapes-every K): the curve joins those points instead of vanishing."""
    import numpy as np
    from matplotlib.figure import Figure

    from hockle.branch_plots import _bifurcation_y, _segments

    lam = np.linspace(0.0, 1.0, 7)
    y = np.array([0.0, np.nan, np.nan, 0.3, np.nan, np.nan, 0.6])
    stable = np.array([True] * 4 + [False] * 3)
    ax = Figure().subplots()
    _segments(ax, lam, y, stable, np.zeros(7, int))
    drawn = [line.get_xydata() for line in ax.get_lines()]
    finite = [xy[np.isfinite(xy[:, 1])] for xy in drawn]
    assert sum(len(xy) for xy in finite) >= 4             # both parts, the join in both
    assert any(len(xy) >= 2 for xy in finite)
    assert _bifurcation_y(lam, y, 4, 0.75) == pytest.approx(0.45)


# --------------------------------------------------------------------------- the point of a run


def test_a_fast_jump_of_the_writhe_gets_its_own_row():
    """Wr creeps 1.05 -> 1.2 over 1.3-2.5 s, then jumps 1.2 -> 1.85 within 2.5-2.6 s (the
    seed's plies wrapping at 25.5 s): no unit step is crossed there, so the jump is its
    own row, at its end; a rise of the same size spread over the run is not a jump."""
    from hockle.plots import writhe_jumps

    wr = np.interp(TIMES, [0.0, 1.2, 1.3, 2.5, 2.6, 3.0], [0.0, 0.0, 1.05, 1.2, 1.85, 1.9])
    jumps = writhe_jumps(wr, TIMES)
    assert [(TIMES[a], TIMES[b]) for a, b in jumps] == [pytest.approx((1.2, 1.3)),
                                                       pytest.approx((2.5, 2.6))]
    rows = event_times(dataset(writhe=wr, contact_from=1.3))
    assert (pytest.approx(2.6), "Wr jumps 1.20 → 1.85 over 2.5-2.6 s") in rows
    # the jump 0 -> 1.05 over 1.2-1.3 s holds the first contact and Wr reaching 1,
    # already a row: not drawn again
    assert (pytest.approx(1.3), "first contact; Wr reaches 1") in rows
    assert not any("0.00 →" in label for _, label in rows)
    # the same rise spread over the whole run is a drift, not a jump
    assert writhe_jumps(np.linspace(0.0, 0.65, TIMES.size), TIMES) == []


def _lay_with_a_loop(t: float) -> np.ndarray:
    """A 4-m cable lying along x; from 1 s a loop of 5 cm radius rises out of it over
    s = 3.2-3.6 m (a seabed hockle in miniature); the rest stays put."""
    n = 161
    s = np.linspace(0.0, 4.0, n)
    r = np.zeros((n, 3))
    r[:, 0] = s
    grow = min(max(t - 1.0, 0.0), 1.0)
    part = (s >= 3.2) & (s <= 3.6)
    phase = (s[part] - 3.2) / 0.4 * 2 * np.pi
    r[part, 0] = 3.2 + grow * 0.05 * np.sin(phase) + (1 - grow) * (s[part] - 3.2)
    r[part, 2] = grow * 0.05 * (1 - np.cos(phase))
    r[part, 1] = grow * 0.02 * np.sin(phase / 2)
    return r


def _lay_dataset():
    case = copy.deepcopy(CASE)
    case["rod"] = dict(case["rod"], length=4.0, diameter=0.02)
    case["numerics"] = {"n_segments": 160, "dt": 0.1, "t_end": 3.0}
    s = np.linspace(0.0, 4.0, 161)
    data = {"position": np.stack([_lay_with_a_loop(t) for t in TIMES])}
    return build_dataset(Case.model_validate(case), s, TIMES, data, {}, "completed")


def test_snapshots_zoom_to_the_loop_of_a_long_cable(tmp_path):
    """Only s = 3.2-3.6 m of the 4-m cable moves: the snapshots' box is the loop's
    neighbourhood (under half a metre, the whole cable's cube is 4 m), and the figure is
    drawn with the whole cable as an inset; the seed's rod, which moves all along, and
    zoom=False keep the whole rod."""
    from hockle.plots import action_box

    ds = _lay_dataset()
    s = ds["s"].values
    shapes = ds["position"].transpose("time", "s", "xyz").values[[0, 15, 30]]
    lims, (s0, s1) = action_box(ds, shapes, s, np.full(s.size, 0.02))
    assert 3.1 <= s0 <= 3.3 and 3.5 <= s1 <= 3.7
    assert max(hi - lo for lo, hi in lims) < 0.5
    assert lims[0][0] > 3.0                               # x: around the loop only
    # the whole rod moving (the test's bowed 1-m rod) is not zoomed
    bow = dataset()
    assert action_box(bow, bow["position"].transpose("time", "s", "xyz").values[[0, 30]],
                      S, np.full(N, 0.02)) is None
    paths = plot_snapshots(ds, tmp_path, times=[0.0, 1.5, 3.0], stem="lay", on_skip=None)
    assert paths and paths[0].stat().st_size > 10_000
    assert plot_snapshots(ds, tmp_path, times=[3.0], stem="whole", on_skip=None, zoom=False)


def test_draw_rod_clipped_draws_only_what_is_inside():
    """matplotlib's 3-D axes do not clip: clipped to a box, only the runs of the rod
    inside it are drawn (one tube per run), and an end outside it gets no marker."""
    from matplotlib.figure import Figure

    from hockle.plots import draw_rod

    r = _lay_with_a_loop(3.0)
    d = np.full(len(r), 0.02)
    ax3 = Figure().add_subplot(projection="3d")
    whole = draw_rod(ax3, r, d)
    clipped = draw_rod(ax3, r, d, clip=[(3.0, 3.8), (-0.4, 0.4), (-0.4, 0.4)])
    assert len(whole) == 3                                # tube, start end, far end
    assert len(clipped) == 1                              # the tube near the loop only


def _energy_dataset(seabed_work=None, work0=0.0):
    """Energies of a made-up run: 1 J stored at the start, 2 J of work put in at a steady
    rate, a 0.8-J fall of the strain energy at 1.5 s of which the seabed takes 0.3 J."""
    strain = 1.0 + (2.0 / 3.0) * TIMES - 0.8 * (TIMES >= 1.5)
    data = {"energy_bending": 0.25 * strain, "energy_torsion": 0.75 * strain,
            "energy_kinetic": np.full(TIMES.size, 0.01),
            "energy_kinetic_fluid": np.full(TIMES.size, 0.005),
            "work_in": work0 + (2.0 / 3.0) * TIMES}
    data["energy_total"] = strain + 0.015
    if seabed_work is not None:
        data["seabed_work"] = seabed_work
    return build_dataset(Case.model_validate(CASE), S, TIMES, data, {}, "completed")


def test_the_energy_balance_adds_up_to_the_work_in():
    """stored + kinetic + taken by the seabed + dissipated = energy at the start + work
    in, at every output; the dissipated energy is the 0.8-J fall less what the seabed
    took; a start from an earlier result (work_in not 0 at the first output) counts the
    work from there."""
    from hockle.plots import energy_balance, largest_fall

    seabed = -0.3 * (TIMES >= 1.5)
    for ds in (_energy_dataset(seabed), _energy_dataset(seabed, work0=5.0)):
        b = energy_balance(ds)
        assert b["strain"] + b["kinetic"] + b["seabed"] + b["dissipated"] == \
            pytest.approx(b["supplied"], abs=1e-12)
        assert b["supplied"][0] == pytest.approx(1.015)
        assert b["supplied"][-1] == pytest.approx(1.015 + 2.0)
        assert b["dissipated"][-1] == pytest.approx(0.5)
        assert b["seabed"][-1] == pytest.approx(0.3)
    assert energy_balance(_energy_dataset())["seabed"] is None
    assert energy_balance(_energy_dataset().drop_vars("work_in")) is None
    i, j = largest_fall(TIMES, _energy_dataset()["energy_total"].values, 0.15)
    assert (TIMES[i], TIMES[j]) == pytest.approx((1.4, 1.5))


def test_energy_figure_draws_every_share(tmp_path):
    from hockle.plots import plot_energies

    path, = plot_energies(_energy_dataset(-0.3 * (TIMES >= 1.5)), tmp_path, stem="e")
    assert path.stat().st_size > 10_000


def test_writhe_and_linking_number_in_the_dashboards_colours():
    """hockle plot draws Tw, Wr and Lk in the colours the dashboard gives them: its
    palette (COLORS) in the order of its topology plot's names."""
    import re
    from pathlib import Path

    from hockle.plots import TOPOLOGY_COLOURS

    app = (Path(__file__).resolve().parents[2] / "service" / "dashboard" / "static"
           / "app.js").read_text()
    palette = re.findall(r'"(#[0-9a-fA-F]{6})"', re.search(r"var COLORS = \[(.*?)\]",
                                                            app).group(1))
    names = re.findall(r'"(\w+)"', re.search(r'id: "topology".*?names: \[(.*?)\]',
                                             app).group(1))
    assert names == ["twist", "writhe", "linking_number"]
    assert {n: palette[k] for k, n in enumerate(names)} == TOPOLOGY_COLOURS
