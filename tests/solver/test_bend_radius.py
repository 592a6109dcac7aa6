"""The smallest bend radius (output group ``bend_radius``: ``bend_radius_min``,
``bend_radius_min_s``; :func:`solver.kinematics.min_bend_radius`), the case's
``rod.minimum_bend_radius`` and the events ``loop_formed`` and ``bend_radius_below_mbr``
(:func:`solver.results.run_events`), against closed forms: a circular arc's radius, a
cantilever bent by an end moment M into an arc of radius EI/M."""
from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr

from hockle.api import circular_arc, clamped, end, free, make_case, ramp
from hockle.plots import event_times
from solver.case import Case, CaseError
from solver.kinematics import min_bend_radius
from solver.results import build_dataset, run_events
from solver.simulation import integrate

E, D = 1.25e7, 0.02
EI = E * np.pi * D**4 / 64


def _with_mbr(case, mbr):
    doc = case.model_dump(mode="json")
    doc["rod"]["minimum_bend_radius"] = mbr
    return Case.model_validate(doc)


def test_min_bend_radius_of_known_curvatures():
    s = np.linspace(0.0, 1.0, 5)
    kappa = np.zeros((2, 5, 3))
    kappa[0, :, 2] = 3.0                      # twisted but straight: no bend
    kappa[1, :, 0] = [0.0, 1.0, 0.0, 0.0, 3.0]
    kappa[1, :, 1] = [0.0, 0.0, 0.0, 3.0, -4.0]   # |κ_b| = 5 at s = 1
    kappa[1, :, 2] = 100.0                    # twist does not count
    radius, at = min_bend_radius(kappa, s)
    assert radius[0] == np.inf and np.isnan(at[0])
    assert radius[1] == pytest.approx(0.2) and at[1] == 1.0
    bad = kappa[1].copy()
    bad[2, 0] = np.nan
    r, a = min_bend_radius(bad, s)
    assert np.isnan(r) and np.isnan(a)


def test_minimum_bend_radius_is_validated_and_optional_in_the_canonical_json():
    case = make_case("m", start=clamped(), end=free(), n_segments=4, dt=0.1, t_end=1.0)
    assert "minimum_bend_radius" not in case.canonical_json()   # the hash is unchanged
    assert _with_mbr(case, 0.3).rod.minimum_bend_radius == 0.3
    with pytest.raises(CaseError) as info:
        doc = json.loads(case.canonical_json())
        doc["rod"]["minimum_bend_radius"] = -1.0
        Case.from_text(json.dumps(doc), fmt="json")
    assert any(e["loc"] == "rod.minimum_bend_radius" for e in info.value.errors)


def test_an_arc_held_by_its_end_moment_has_its_radius():
    """A cantilever started on a circular arc of R = 0.5 m, held there by the end moment
    EI/R: bend_radius_min = R within 1e-4 relative at every stored time (the resampled κ
    is 2e-5 off, tests/solver/test_initial_shapes.py)."""
    R = 0.5
    case = make_case("arc", start=clamped(),
                     end=end([{"force": 0}] * 3, [{"moment": 0}, {"moment": EI / R},
                                                  {"moment": 0}]),
                     n_segments=40, dt=0.01, t_end=0.1,
                     initial={"centreline": circular_arc(1.0, R)},
                     output={"fields": ["kappa", "bend_radius"]})
    ds = integrate(case)
    radius = ds["bend_radius_min"].values
    assert ds["bend_radius_min"].attrs["units"] == "m"
    assert np.abs(radius / R - 1).max() < 1e-4, radius
    s = ds["bend_radius_min_s"].values
    assert np.all((s >= 0) & (s <= 1.0))
    # the same from the stored κ (what run_events uses when the group is not stored)
    from solver.results import bend_radius_series
    assert np.allclose(bend_radius_series(ds.drop_vars(["bend_radius_min"])), radius,
                       rtol=1e-12)


def test_mbr_event_fires_when_the_end_moment_bends_the_rod_below_it():
    """A 0.2 m cantilever whose end moment rises slowly (ramp 0 -> M1 over 2 s, first
    bending period 0.16 s, so nearly static) bends into an arc of radius EI/M(t): the
    smallest radius is EI/M(t) within 7 % after 0.5 s (the ramp's ripple: measured 6.0 %
    at 0.55 s, 1.6 % at 2 s). With an MBR X the event fires at the first stored time at
    which bend_radius_min < X, and that time is where EI/M(t) = X within two outputs
    (0.1 s)."""
    L, M1, t_ramp, X = 0.2, 0.5, 2.0, 0.4        # EI/M1 = 0.196 m at the end of the ramp
    case = make_case("moment", length=L, start=clamped(),
                     end=end([{"force": 0}] * 3,
                             [{"moment": 0}, {"moment": ramp([0.0, t_ramp], [0.0, M1])},
                              {"moment": 0}]),
                     n_segments=10, dt=0.01, t_end=2.0,
                     output={"fields": ["kappa", "bend_radius"], "every": 5})
    ds = integrate(_with_mbr(case, X))
    t = ds.time.values
    radius = ds["bend_radius_min"].values
    M = np.interp(t, [0.0, t_ramp], [0.0, M1])
    late = t > 0.5
    assert np.abs(radius[late] * M[late] / EI - 1).max() < 0.07
    ev = run_events(ds)
    expected = EI / X / M1 * t_ramp                        # M(t*) = EI/X
    assert ev["bend_radius_below_mbr"] == int(np.flatnonzero(radius < X)[0])
    assert abs(t[ev["bend_radius_below_mbr"]] - expected) <= 0.1 + 1e-9
    assert ev["loop_formed"] is None
    labels = [label for _, label in event_times(ds)]
    assert "MBR below 0.4 m" in labels
    # without the MBR in the case there is no such event
    assert "bend_radius_below_mbr" not in run_events(integrate(case))


def _series(case, **series):
    n = len(next(iter(series.values())))
    return build_dataset(case, np.linspace(0.0, 1.0, 5), 0.1 * np.arange(n),
                         {k: np.asarray(v, dtype=float) for k, v in series.items()}, {},
                         "completed")


def test_loop_formed_is_the_first_contact_or_the_writhe_rising_through_one():
    case = make_case("m", start=clamped(), end=free(), n_segments=4, dt=0.1, t_end=1.0)
    wr = [0.0, 0.4, 0.9, 1.1, 1.3, 0.8]
    assert run_events(_series(case, writhe=wr))["loop_formed"] == 3
    # contact first
    assert run_events(_series(case, writhe=wr, contact_count=[0, 0, 2, 3, 3, 0]))[
        "loop_formed"] == 2
    # negative writhe counts by its size
    assert run_events(_series(case, writhe=-np.asarray(wr)))["loop_formed"] == 3
    # a run that starts with |Wr| above 1 has not formed a loop until it drops and rises
    assert run_events(_series(case, writhe=[1.5, 1.2, 1.4]))["loop_formed"] is None
    assert run_events(_series(case, writhe=[1.5, 0.7, 1.4]))["loop_formed"] == 2
    assert run_events(_series(case, writhe=[0.0, 0.5]))["loop_formed"] is None


def test_mbr_event_from_the_stored_series_and_its_absence_without_one():
    case = _with_mbr(make_case("m", start=clamped(), end=free(), n_segments=4, dt=0.1,
                               t_end=1.0), 0.5)
    ds = _series(case, bend_radius_min=[np.inf, 2.0, 0.6, 0.49, 0.3, 0.7])
    assert run_events(ds)["bend_radius_below_mbr"] == 3
    assert run_events(_series(case, bend_radius_min=[np.inf, 0.6]))["bend_radius_below_mbr"] \
        is None
    # a file with neither bend_radius_min nor kappa cannot say: no index
    assert run_events(_series(case, writhe=[0.0, 0.2]))["bend_radius_below_mbr"] is None
    assert isinstance(ds, xr.Dataset)
