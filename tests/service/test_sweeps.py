"""service.sweeps: parameter paths, expansion and validation of members, the sweep's state,
and combine_results on synthetic member datasets whose values and events are known."""
from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from rodcases import tiny_spec
from service.sweeps import (
    MemberResult,
    SweepError,
    combine_results,
    expand,
    member_events,
    normalize_path,
    parse_request,
    set_path,
    sweep_state,
    validate_members,
)
from solver.case import Case
from solver.results import build_dataset

BASE = tiny_spec("sweep unit", n_segments=10, dt=0.1, t_end=3.0)
BASE["boundary"]["end"]["translation"][2] = [{"force": 0}]     # a one-item switch list
FORCE = "boundary.end.translation.2.force"
SPIN = "boundary.start.rotation.2.angular_velocity"
PARAMS = {FORCE: [0.0, 2.0], SPIN: [1.0, 2.0, 3.0]}
S = np.linspace(0.0, 1.0, 11)


def fake_result(force: float, spin: float, dt: float = 0.1, t_end: float = 3.0,
                status: str = "completed"):
    """A member's dataset: it buckles (the mid-point leaves the axis by a diameter) at
    t = 1/spin + force/10, touches itself 0.5 s later, and its writhe grows as
    spin * (t - onset) turns; energy_total = force + spin * t."""
    case = copy.deepcopy(BASE)
    set_path(case, FORCE, force)
    set_path(case, SPIN, spin)
    case["numerics"].update(dt=dt, t_end=t_end)
    times = np.round(np.arange(0.0, t_end + 1e-9, dt), 10)
    onset = 1.0 / spin + force / 10.0
    amp = np.where(times >= onset - 1e-9, 0.03, 0.0)
    pos = np.zeros((times.size, S.size, 3))
    pos[:, :, 2] = S
    pos[:, :, 0] = amp[:, None] * np.sin(np.pi * S)[None, :]
    writhe = np.clip(spin * (times - onset), 0.0, None)
    data = {
        "position": pos,
        "writhe": writhe,
        "twist": spin * times - writhe,
        "linking_number": spin * times,
        "energy_total": force + spin * times,
        "contact_count": np.where(times >= onset + 0.5 - 1e-9, 3, 0),
    }
    return build_dataset(Case.model_validate(case), S, times, data, {}, status)


def results(params=PARAMS, combine="grid", **kw):
    members = expand(BASE, params, combine)
    return members, [MemberResult(m.index, m.values, "successful",
                                  fake_result(m.values.get(FORCE, 0.0), m.values.get(SPIN, 1.0),
                                              **kw), job_id=f"job-{m.index}")
                     for m in members]


def test_paths_expansion_and_validation():
    assert normalize_path("boundary.end.translation[2].force") == FORCE
    doc = copy.deepcopy(BASE)
    set_path(doc, FORCE, 5.0)              # looks through the one-item list
    assert doc["boundary"]["end"]["translation"][2] == [{"force": 5.0}]
    set_path(doc, "numerics.rho_inf", 0.3)  # a field the base leaves to its default
    assert doc["numerics"]["rho_inf"] == 0.3
    with pytest.raises(SweepError, match="out of range"):
        set_path(doc, "boundary.end.translation.3.force", 1.0)
    with pytest.raises(SweepError, match="is a field name but the value here is a list of 3"):
        set_path(doc, "boundary.end.translation.force", 1.0)

    members = expand(BASE, PARAMS)
    assert [m.values for m in members[:2]] == [{FORCE: 0.0, SPIN: 1.0}, {FORCE: 0.0, SPIN: 2.0}]
    assert len(members) == 6 and members[5].case["boundary"]["start"]["rotation"][2] == {
        "angular_velocity": 3.0}
    assert BASE["boundary"]["end"]["translation"][2] == [{"force": 0}]   # untouched
    zipped = expand(BASE, {FORCE: [0.0, 1.0], SPIN: [2.0, 3.0]}, "zip")
    assert [m.values[SPIN] for m in zipped] == [2.0, 3.0]
    with pytest.raises(SweepError, match="zip needs the same number"):
        expand(BASE, {FORCE: [0.0, 1.0], SPIN: [2.0]}, "zip")
    with pytest.raises(SweepError, match="at most 10"):
        expand(BASE, {FORCE: list(range(4)), SPIN: list(range(3))}, max_members=10)

    cases = validate_members(members)
    assert cases[4].boundary.end.translation[2][0].force == 2.0
    bad = expand(BASE, {FORCE: [0.0, 1.0], "rod.diameter": [0.02, -1.0]})
    with pytest.raises(SweepError) as info:
        validate_members(bad)
    errors = info.value.errors
    assert [e["loc"] for e in errors] == ["members[1].rod.diameter", "members[3].rod.diameter"]
    assert f"member 3 ({FORCE} = 1.0, rod.diameter = -1.0)" in errors[1]["msg"]

    with pytest.raises(SweepError) as info:
        parse_request({"base": BASE, "parameters": {FORCE: []}, "combine": "cross", "x": 1})
    assert {e["loc"] for e in info.value.errors} == {"x", f"parameters.{FORCE}", "combine"}


def test_sweep_state_in_the_job_states_vocabulary():
    assert sweep_state(["accepted"] * 3) == "accepted"
    assert sweep_state(["successful", "accepted"]) == "running"
    assert sweep_state(["successful", "successful"]) == "successful"
    assert sweep_state(["successful", "failed"]) == "failed"
    assert sweep_state(["successful", "dismissed"], dismissed=True) == "dismissed"


def test_events_of_one_member():
    ev = member_events(fake_result(0.0, 2.0))          # onset 0.5 s, Wr = 2 (t - 0.5)
    assert ev == {"buckling_onset": 5, "first_contact": 10, "loop_formed": 10, "writhe_1": 10,
                  "writhe_2": 15, "writhe_3": 20, "writhe_4": 25, "writhe_5": 30}


def test_combine_a_grid():
    members, res = results()
    ds = combine_results(res, PARAMS, fields=["position"])
    assert ds["writhe"].dims == (FORCE, SPIN, "time")
    assert ds.sizes == {FORCE: 2, SPIN: 3, "time": 31, "s": 11, "xyz": 3, "event": 11}
    assert list(ds[FORCE].values) == [0.0, 2.0] and list(ds[SPIN].values) == [1.0, 2.0, 3.0]
    assert ds[FORCE].attrs["units"] == "N" and ds[SPIN].attrs["units"] == "rad s-1"
    assert ds.attrs["hockle_sweep_time_grid"] == "common"
    for m, r in zip(members, res):
        cell = ds.sel({FORCE: m.values[FORCE], SPIN: m.values[SPIN]})
        for name in ("writhe", "energy_total", "contact_count", "position"):
            assert np.array_equal(cell[name].values, r.dataset[name].values), name
        assert int(cell["member_index"]) == m.index and str(cell["job_id"].values) == r.job_id
        # the first stored time (every 0.1 s) at or after the event
        onset = np.ceil((1.0 / m.values[SPIN] + m.values[FORCE] / 10.0) / 0.1 - 1e-9) * 0.1
        assert float(cell["event_time"].sel(event="buckling_onset")) == pytest.approx(onset)
        assert float(cell["event_time"].sel(event="first_contact")) == pytest.approx(
            np.ceil((1.0 / m.values[SPIN] + m.values[FORCE] / 10.0 + 0.5) / 0.1 - 1e-9) * 0.1)
        assert float(cell["event_linking_number"].sel(event="buckling_onset")) == pytest.approx(
            m.values[SPIN] * onset)
    # Wr reaches 5 only for spin 3 with no tension (3 (3 - 1/3) = 8 turns at the end) ...
    at5 = ds["event_time"].sel(event="writhe_5")
    assert np.isnan(float(at5.sel({FORCE: 0.0, SPIN: 1.0})))
    assert float(at5.sel({FORCE: 0.0, SPIN: 3.0})) == pytest.approx(1.0 / 3.0 + 5.0 / 3.0, abs=0.1)


def test_a_failed_member_is_marked_not_fatal_and_time_grids_may_differ(tmp_path):
    members, res = results()
    res[1] = MemberResult(1, members[1].values, "failed", None, job_id="job-1",
                          message="solver_diverged at t = 0")
    # member 2 stopped at 1.5 s; member 3 ran with dt = 0.05 s
    res[2] = MemberResult(2, members[2].values, "failed",
                          fake_result(0.0, 3.0, t_end=1.5, status="stopped"), message="timeout")
    res[3] = MemberResult(3, members[3].values, "successful", fake_result(2.0, 1.0, dt=0.05))
    ds = combine_results(res, PARAMS)
    assert ds.attrs["hockle_sweep_time_grid"] == "union_interpolated"
    assert ds.sizes["time"] == 61           # the union: every 0.05 s
    status = ds["member_status"].values
    assert status[0, 1] == "failed" and status[0, 2] == "failed" and status[1, 0] == "successful"
    assert np.isnan(ds["writhe"].values[0, 1]).all()             # no result
    assert str(ds["member_message"].values[0, 1]).startswith("solver_diverged")
    stopped = ds["energy_total"].values[0, 2]
    t = ds["time"].values
    assert np.isnan(stopped[t > 1.5 + 1e-9]).all()
    assert stopped[t <= 1.5 + 1e-9] == pytest.approx(3.0 * t[t <= 1.5 + 1e-9])   # linear: exact
    own = res[0].dataset
    on_own = ds["writhe"].values[0, 0][np.isin(np.round(t, 9), np.round(own.time.values, 9))]
    assert on_own == pytest.approx(own["writhe"].values)          # own outputs kept
    assert float(ds["member_t_reached"].values[0, 2]) == pytest.approx(1.5)
    # counts take the last stored value between outputs
    assert set(np.unique(ds["contact_count"].values[0, 0][~np.isnan(ds["contact_count"].values[0, 0])])) <= {0.0, 3.0}
    path = tmp_path / "sweep.nc"
    ds.to_netcdf(path, engine="netcdf4")
    import xarray as xr

    with xr.open_dataset(path, engine="netcdf4") as back:
        assert back["member_status"].values[0, 1] == "failed"
        assert json.loads(back.attrs["hockle_sweep_parameters"])[0]["path"] == FORCE


def test_combine_zipped_and_fields_need_one_grid():
    params = {FORCE: [0.0, 2.0], SPIN: [3.0, 1.0]}
    members, res = results(params, "zip")
    ds = combine_results(res, params, "zip")
    assert ds["writhe"].dims == ("member", "time")
    assert list(ds[FORCE].values) == [0.0, 2.0] and ds[SPIN].dims == ("member",)
    assert ds["writhe"].values[1] == pytest.approx(res[1].dataset["writhe"].values)
    with pytest.raises(SweepError, match="no member's result has 'kappa'"):
        combine_results(res, params, "zip", fields=["kappa"])
    coarse = fake_result(2.0, 1.0)
    res[1].dataset = coarse.isel(s=slice(None, None, 2))
    with pytest.raises(SweepError, match="another s grid"):
        combine_results(res, params, "zip", fields=["position"])
    # the scalar series still combine
    assert combine_results(res, params, "zip")["writhe"].shape == (2, 31)


def test_hockle_sweep_here_and_its_threshold_map(tmp_path, capsys):
    """hockle sweep without --url runs the members here, writes the combined file, and
    hockle plot draws its threshold map; a bad value is refused with exit status 2."""
    from hockle.cli import main
    from hockle.sweep_command import parse_values

    assert parse_values("0:1:5") == [0.0, 0.25, 0.5, 0.75, 1.0]
    assert parse_values('1,2.5,x,[1]') == [1, 2.5, "x", [1]]
    assert parse_values('[0, {"t": [0, 1], "value": [0, 2]}]')[1]["t"] == [0, 1]
    base = copy.deepcopy(BASE)
    base["numerics"].update(t_end=0.3)
    path = tmp_path / "base.json"
    path.write_text(json.dumps(base))
    out = tmp_path / "sweep.nc"
    code = main(["sweep", str(path), "--set", f"{FORCE}=0,1", "--set", f"{SPIN}=1:3:3",
                 "--workers", "1", "-q", "-o", str(out)])
    assert code == 0, capsys.readouterr()
    assert "6 members (6 successful)" in capsys.readouterr().out
    from hockle.io import open_result

    ds = open_result(out)
    assert ds["energy_total"].dims == (FORCE, SPIN, "time") and ds.sizes["time"] == 4
    # nothing buckles in 0.3 s: the map says so, the members' writhe is drawn
    assert main(["plot", str(out), "-o", str(tmp_path / "plots")]) == 0
    assert [p.name for p in (tmp_path / "plots").iterdir()] == ["sweep_writhe.png"]
    # a synthetic sweep with events gets its map
    members, res = results()
    synthetic = tmp_path / "synthetic.nc"
    combine_results(res, PARAMS).to_netcdf(synthetic, engine="netcdf4")
    assert main(["plot", str(synthetic), "-o", str(tmp_path / "plots2")]) == 0
    assert sorted(p.name for p in (tmp_path / "plots2").iterdir()) == [
        "synthetic_threshold.png", "synthetic_writhe.png"]
    code = main(["sweep", str(path), "--set", "rod.diameter=0.02,-1", "--workers", "1", "-q",
                 "-o", str(tmp_path / "bad.nc")])
    assert code == 2 and "members[1].rod.diameter" in capsys.readouterr().err
    assert not (tmp_path / "bad.nc").exists()


def test_members_on_other_output_times_keep_their_infinite_values():
    """min_surface_gap is +inf at an output without a near pair: a member whose outputs
    are a subset of the union grid keeps it there (it had read NaN: 0·inf), and between
    a finite and an infinite output it reads inf."""
    members, res = results()
    fine = fake_result(2.0, 1.0, dt=0.05)
    fine["min_surface_gap"] = ("time", np.full(fine.sizes["time"], np.inf))
    coarse = res[0].dataset.copy()
    gap = np.full(coarse.sizes["time"], np.inf)
    gap[:5] = 0.01
    coarse["min_surface_gap"] = ("time", gap)
    res[0] = MemberResult(0, members[0].values, "successful", coarse)
    res[3] = MemberResult(3, members[3].values, "successful", fine)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        ds = combine_results(res, PARAMS)
    assert ds.attrs["hockle_sweep_time_grid"] == "union_interpolated"
    assert np.isposinf(ds["min_surface_gap"].values[1, 0]).all()
    t = ds["time"].values
    own = ds["min_surface_gap"].values[0, 0]
    stored = coarse.time.values
    assert own[np.isclose(t, stored[4])] == pytest.approx(0.01)
    assert np.isposinf(own[np.isclose(t, stored[5])]).all()
    halfway = (stored[4] + stored[5]) / 2
    assert np.isposinf(own[np.isclose(t, halfway)]).all()
    assert own[np.isclose(t, (stored[0] + stored[1]) / 2)] == pytest.approx(0.01)
