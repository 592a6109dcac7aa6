"""The events of a run (:func:`solver.results.run_events`): the buckling onset means the
same on a curved lay as on a straight start, and every list of events comes in the order
the events happened (``run_events``' keys, ``events_summary``, a result's
``hockle_events``), on synthetic series whose events are known by construction."""
from __future__ import annotations

import numpy as np
import pytest

from hockle.api import clamped, free, make_case
from solver.results import events_summary, run_events, shape_departure, build_dataset

N = 81
S = np.linspace(0.0, 4.0, N)
TIMES = np.round(np.arange(0.0, 3.01, 0.1), 10)
CASE = make_case("lay", length=4.0, start=clamped(), end=free(), n_segments=N - 1, dt=0.1,
                 t_end=3.0)                               # a 2-cm cable, 4 m
D = 0.02


def _lay(t: float, amplitude: float = 0.05, pull: float = 0.0) -> np.ndarray:
    """A 4-m cable along x with a lateral half-sine of ``amplitude`` (the lay of
    cases/seabed-hockle.yaml), its far end pulled in by ``pull`` m (the whole lay
    squeezed along x), and from 1 s a bump rising out of the plane at 4.5 cm/s."""
    r = np.zeros((N, 3))
    r[:, 0] = S * (1.0 - pull / S[-1])
    r[:, 1] = amplitude * np.sin(np.pi * S / S[-1])
    r[:, 2] = max(t - 1.0, 0.0) * 0.045 * np.sin(np.pi * S / S[-1]) ** 4
    return r


def _dataset(shapes, **series):
    data = {"position": np.stack(shapes)}
    data.update({k: np.asarray(v, dtype=float) for k, v in series.items()})
    return build_dataset(CASE, S, TIMES[:len(shapes)], data, {}, "completed")


def test_onset_on_a_curved_lay_is_its_departure_from_the_lay():
    """The lay starts 5 cm (2.5 diameters) off its chord: the chord rule (a diameter off
    the line through the ends, having started closer) never fired on it. Measured
    against the lay, the bump rising 4.5 cm/s from 1 s passes one diameter (2 cm) at
    1.44 s: the output at 1.5 s."""
    ds = _dataset([_lay(t) for t in TIMES])
    dev = shape_departure(ds["position"].transpose("time", "s", "xyz").values)
    assert dev[0] == 0.0 and dev[TIMES <= 1.0].max() == pytest.approx(0.0, abs=1e-12)
    assert TIMES[run_events(ds)["buckling_onset"]] == pytest.approx(1.5)


def test_the_ends_moving_along_the_chord_is_not_buckling():
    """The far end pulled in by 0.5 m with the lay keeping its shape across the chord:
    no onset; the same lay growing sideways by a diameter is one."""
    still = _dataset([_lay(0.0, pull=0.5 * t / 3.0) for t in TIMES])
    assert run_events(still)["buckling_onset"] is None
    grows = _dataset([_lay(0.0, amplitude=0.05 + 0.011 * t) for t in TIMES])
    assert TIMES[run_events(grows)["buckling_onset"]] == pytest.approx(1.9)   # 1.82 s


def test_a_straight_start_reads_as_before():
    """From a straight start the measure is the distance from the chord, the rule
    hockle used before."""
    ds = _dataset([_lay(t, amplitude=0.0) for t in TIMES])
    pos = ds["position"].transpose("time", "s", "xyz").values
    chord = np.max(np.abs(pos[:, :, 2]), axis=1)       # the chord is the x axis
    assert shape_departure(pos) == pytest.approx(chord)
    assert TIMES[run_events(ds)["buckling_onset"]] == pytest.approx(1.5)


def test_events_come_in_the_order_they_happened():
    """Contact at 0.5 s, |Wr| through 1 at 0.8 s, the onset at 1.5 s: run_events' keys,
    the summary and the result attribute list them in that order, those that did not
    happen last."""
    wr = np.clip(TIMES - 0.1, 0.0, None) * 1.5          # 1 at 0.77 s -> output 0.8 s
    contact = np.where(TIMES >= 0.5 - 1e-9, 2, 0)
    ds = _dataset([_lay(t) for t in TIMES], writhe=wr, contact_count=contact)
    events = run_events(ds)
    happened = [k for k, i in events.items() if i is not None]
    assert happened == ["first_contact", "loop_formed", "writhe_1", "buckling_onset",
                        "writhe_2", "writhe_3", "writhe_4"]
    assert [events[k] for k in happened] == sorted(events[k] for k in happened)
    summary = events_summary(ds)
    assert summary.startswith("first contact at 0.5 s, loop formed at 0.5 s, "
                              "|Wr| reaches 1 at 0.8 s, buckling onset at 1.5 s")
    assert "did not happen" not in summary
    quiet = _dataset([_lay(0.0)] * 3)
    assert events_summary(quiet) == ("none happened; did not happen: buckling onset, "
                                     "first contact, loop formed")


def test_a_run_carries_its_events_in_order(tmp_path):
    """A finished run's ``hockle_events`` is :func:`events_summary` of its dataset."""
    from hockle.api import simulate

    case = make_case("short", start=clamped(), end=free(), n_segments=4, dt=0.01,
                     t_end=0.02)
    ds = simulate(case)
    assert ds.attrs["hockle_events"] == events_summary(ds)
    assert ds.attrs["hockle_events"].startswith("none happened; did not happen:")
