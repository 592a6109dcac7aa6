"""hockle.api: callbacks at a cadence that may stop a run, custom distributed loads, the case
builders, and the local sweep runner; each against the solver's own time loop (solver.integrate) or the case
spec's own loads."""
from __future__ import annotations

import numpy as np
import pytest

from hockle.api import (
    Callback,
    DistributedLoad,
    Recorder,
    clamped,
    free,
    make_case,
    pinned,
    ramp,
    simulate,
    sliding,
    switch,
    sweep,
    twisted,
)
from solver import integrate

KW = dict(start=twisted(1.0), end=sliding(0.0), n_segments=20, dt=0.02, t_end=0.4)


def _identical(a, b, rtol: float = 0.0) -> None:
    assert dict(a.sizes) == dict(b.sizes)
    for name in a.data_vars:
        if rtol:
            assert np.allclose(a[name].values, b[name].values, rtol=rtol, atol=1e-300,
                               equal_nan=True), name
        else:
            assert np.array_equal(a[name].values, b[name].values, equal_nan=True), name
    assert a.attrs["hockle_status"] == b.attrs["hockle_status"]


def test_callbacks_watch_without_changing_the_run():
    """The driver with callbacks is the solver's loop: with callbacks that read every field
    at every step the result is the solver's to the bit (fixed and error-controlled steps)."""
    case = make_case("watched", **KW)
    seen = []

    def look(state):
        seen.append((state.step, state.t))
        state.position, state.kappa, state.writhe, state.energies  # noqa: B018 - read them
        return np.zeros(3)           # not True or a string: ignored

    _identical(integrate(case), simulate(case, callbacks=[look]))
    assert seen[0] == (0, 0.0) and len(seen) == 21 and seen[-1][1] == pytest.approx(0.4)

    adaptive = make_case("adaptive", **KW,
                         numerics={"tolerance": {"relative": 1e-2, "absolute": 1e-6}})
    _identical(integrate(adaptive), simulate(adaptive, callbacks=[look]))


def test_cadence_in_steps_and_in_simulated_time():
    case = make_case("cadence", **KW)
    by_step = Recorder(["writhe", "energy_total"], every=5)
    by_time = Recorder(["position"], interval=0.1)
    ds = simulate(case, callbacks=[by_step, by_time])
    assert by_step.steps == [0, 5, 10, 15, 20]
    assert by_time.times == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4])
    arrays = by_time.arrays()
    assert arrays["position"].shape == (5, 21, 3)
    # the recorded state is the stored one
    assert arrays["position"][2] == pytest.approx(ds["position"].sel(time=0.2).values)
    assert by_step.data["energy_total"][-1] == pytest.approx(float(ds["energy_total"][-1]))


def test_a_callback_stops_the_run():
    case = make_case("stop", **KW)
    stop = Callback.when(lambda st: st.t >= 0.1 - 1e-12, reason="enough", every=5)
    ds = simulate(case, callbacks=[stop])
    assert ds.attrs["hockle_status"] == "stopped" and ds.attrs["hockle_stop_reason"] == "enough"
    assert float(ds["time"][-1]) == pytest.approx(0.1) and ds.sizes["time"] == 6

    class Halt(Callback):
        def __call__(self, state):
            return state.step == 3

    ds = simulate(case, callbacks=[Halt()])
    assert ds.attrs["hockle_stop_reason"] == "callback" and ds.sizes["time"] == 4

    with pytest.raises(ValueError, match="every"):
        Callback(print, every=0)
    with pytest.raises(ValueError, match="not both"):
        Callback(print, every=2, interval=0.1)


def test_custom_loads_are_the_case_loads_written_as_code():
    """A function returning the force of a case's distributed_forces entry gives that case's
    run (uniform, and on an arclength window; the work put in differs by round-off: the
    load is not in the run's initial state, whose velocity is zero); a zero load changes
    nothing."""
    plain = make_case("plain", **KW)
    force = [1e-2, 0.0, 0.0]
    _identical(integrate(make_case("f", distributed_forces=[{"value": force}], **KW)),
               _without_attr(simulate(plain, loads=[lambda t, s: force])), rtol=1e-10)
    window = make_case("w", distributed_forces=[{"value": force, "s_range": [0.25, 0.75]}], **KW)

    def windowed(t, s):
        inside = (s >= 0.25 - 1e-12) & (s <= 0.75 + 1e-12)
        return np.where(inside[:, None], force, 0.0)

    ds = simulate(plain, loads=[DistributedLoad(windowed, name="window")])
    assert ds.attrs["hockle_custom_loads"] == "window"
    _identical(integrate(window), _without_attr(ds), rtol=1e-10)
    _identical(integrate(plain),
               _without_attr(simulate(plain, loads=[lambda t, s: np.zeros((s.size, 3))])))

    # a state-aware load (a spring back to the axis) runs and pulls the rod back
    spring = DistributedLoad(lambda t, s, st: -50.0 * st.position * [1.0, 1.0, 0.0],
                             uses_state=True)
    pushed = simulate(plain, loads=[lambda t, s: force])
    held = simulate(plain, loads=[lambda t, s: force, spring])
    assert (np.abs(held["position"].sel(xyz=1)).max() < np.abs(pushed["position"].sel(xyz=1)).max())

    with pytest.raises(ValueError, match="'bad' returned shape"):
        simulate(plain, loads=[DistributedLoad(lambda t, s: np.zeros(2), name="bad")])


def _without_attr(ds):
    ds.attrs.pop("hockle_custom_loads", None)
    return ds


def test_case_builders_make_valid_cases():
    case = make_case("built", start=pinned(), end=free(), n_segments=4, dt=0.1, t_end=1.0)
    assert case.boundary.start.rotation[0][0].kind == "moment"
    assert case.boundary.end.translation[2][0].kind == "force"
    seed_like = make_case("seed-like", start=twisted(-2.0, ramp_time=1.0),
                          end=sliding(0.0, held_after=30.0), n_segments=10, dt=0.1, t_end=40.0,
                          fluid={"density": 1000.0})
    spin = seed_like.boundary.start.rotation[2][0]
    assert spin.value_at(0.5) == pytest.approx(-1.0) and spin.value_at(3.0) == -2.0
    axial = seed_like.boundary.end.translation[2]
    assert [c.kind for c in axial] == ["force", "velocity"] and axial[0].until == 30.0
    assert clamped()["rotation"][2] == {"angular_velocity": 0.0}
    assert switch(({"force": 1.0}, 2.0), {"velocity": 0.0})[0] == {"force": 1.0, "until": 2.0}
    assert ramp([0, 1], [0, 2]) == {"t": [0.0, 1.0], "value": [0.0, 2.0]}
    with pytest.raises(Exception, match="rod.diameter"):
        make_case("bad", start=clamped(), end=free(), n_segments=4, dt=0.1, t_end=1.0,
                  diameter=-1.0)


def test_local_sweep_runs_and_combines():
    """hockle.api.sweep in this process: a 2 x 2 grid, each cell equal to the member's own
    run; a bad member value refused before anything runs."""
    from service.sweeps import SweepError

    base = make_case("sweep-base", **{**KW, "t_end": 0.1})
    params = {"boundary.end.translation.2.force": [0.0, 1.0],
              "boundary.start.rotation[2].angular_velocity": [1.0, 2.0]}
    ds = sweep(base, params, workers=1)
    assert ds["writhe"].dims == ("boundary.end.translation.2.force",
                                 "boundary.start.rotation.2.angular_velocity", "time")
    assert (ds["member_status"].values == "successful").all()
    alone = integrate(make_case("alone", **{**KW, "t_end": 0.1, "end": sliding(1.0),
                                                  "start": twisted(2.0)}))
    cell = ds.isel({"boundary.end.translation.2.force": 1,
                    "boundary.start.rotation.2.angular_velocity": 1})
    assert cell["energy_total"].values == pytest.approx(alone["energy_total"].values, abs=0)
    with pytest.raises(SweepError, match=r"members\[1\]\.rod\.diameter"):
        sweep(base, {"rod.diameter": [0.02, -0.02]}, workers=1)


def test_a_local_sweeps_successful_member_keeps_its_warning():
    """A member whose result carries hockle_warning (the thin-rod plectoneme at 10x its
    Δt: its loop sweeps across an end's closure, docs/numerics.md § 6) is successful with
    the warning as its member_message; the member at the case's own Δt has none."""
    from rodcases import thin_plectoneme_case

    ds = sweep(thin_plectoneme_case(0.02, 10.0), {"numerics.dt": [0.02, 0.2]}, workers=1)
    assert (ds["member_status"].values == "successful").all()
    assert str(ds["member_message"].values[0]) == ""
    assert "crossed the closure of the end tangents" in str(ds["member_message"].values[1])
