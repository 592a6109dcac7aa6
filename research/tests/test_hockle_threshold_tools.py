"""The hockle threshold maps' set-up (research/hockle_threshold.py): the end's slack, the
three settings' bottoms and that every member is a valid case; no run."""
from __future__ import annotations

import json

import numpy as np
import pytest

from research import hockle_threshold as ht


@pytest.mark.parametrize("slack", [0.2, 0.5, 0.8])
def test_the_velocity_trapezoid_moves_the_end_in_by_the_slack(slack):
    table = ht.slack_velocity(slack)
    assert table["t"] == list(ht.RAMP)
    assert np.trapezoid(table["value"], table["t"]) == pytest.approx(-slack, abs=1e-8)
    assert ht.slack_of(table) == pytest.approx(slack, abs=1e-8)
    assert ht.slack_of(json.dumps(table, sort_keys=True)) == pytest.approx(slack, abs=1e-8)


@pytest.mark.parametrize("make", [ht.base, ht.slack_base])
def test_each_setting_has_its_own_bottom(make):
    """Free space: no seabed, no gravity; "frictionless" (whose name holds "friction"):
    a seabed without friction; "friction 0.5": mu = 0.5 both ways."""
    free, smooth, rough = (make(s) for s in ht.SETTINGS)
    assert "seabed" not in free and "gravity" not in free
    assert "friction" not in smooth["seabed"] and smooth["gravity"][2] < 0
    assert rough["seabed"]["friction"]["axial"] == rough["seabed"]["friction"]["lateral"] == 0.5


def test_slack_members_are_valid_cases():
    from service import sweeps as sw

    for setting in ht.SETTINGS:
        members = sw.expand(ht.slack_base(setting),
                            {ht.SLACK: [ht.slack_velocity(0.2), ht.slack_velocity(0.8)],
                             ht.TWIST: [3.0, 12.0]})
        cases = sw.validate_members(members)
        assert len(cases) == 4
        assert cases[0].numerics.n_segments == ht.SLACK_SEGMENTS[setting]
        assert (cases[0].contact is not None) and cases[0].numerics.t_end == 8.0


def test_a_slack_map_on_another_grid():
    """``--grid N:DT``: every member on N segments with step DT, outputs still every 0.1 s."""
    from service import sweeps as sw

    base = ht.slack_base("seabed, friction 0.5", (240, 0.025))
    assert base["numerics"]["n_segments"] == 240 and base["numerics"]["dt"] == 0.025
    assert base["output"]["every"] == 4
    members = sw.expand(base, {ht.SLACK: [ht.slack_velocity(0.8)], ht.TWIST: [9.42]})
    (case,) = sw.validate_members(members)
    assert (case.numerics.n_segments, case.numerics.dt) == (240, 0.025)
