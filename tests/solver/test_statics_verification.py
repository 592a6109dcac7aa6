"""The two rows of docs/statics.md's verification that no faster test covers, asserted
as the page quotes them (slow; research/statics_verification.py prints them with the
rest of the table and draws the Euler column's figure):

* Greenhill with a dead tension T: the branch point's twisting moment over 2√(BT) at
  TL²/B = 4, 25, 100 (40 segments per unit length) is 2.395, 1.247, 1.049, tending to 1
  as the rod grows long;
* the seed's rod (cases/goyal-writhing.yaml at 200 segments, its perturbing force left
  out, the start's twist as the parameter) loses stability to a pair of helical modes at
  a start twist of −10.699 rad, |Lk| = 1.703 turns, which the seed's twist schedule
  reaches at t = 13.50 s.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from solver import statics as st
from solver.continuation import continuation

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
@pytest.mark.parametrize("length, ratio", [(2.0, 2.395), (5.0, 1.247), (10.0, 1.049)])
def test_greenhill_with_tension_tends_to_the_long_rod_limit(length, ratio):
    B, C, T = 1.0, 1.0 / 1.3, 1.0
    mg = 2 * np.sqrt(B * T)
    n = int(40 * length)

    def prob(th):
        return st.uniform(length, n, (B, B, C), st.clamp([0, 0, 0], [1, 0, 0, 0]),
                          st.clamp([0, 0, length], st.quat_axis_angle([0, 0, 1], th), th,
                                   held=(True, True, False), force=(0, 0, T)))

    br = continuation(prob, 0.0, (1.2 * mg + 10 * B / length) * length / C, max_points=80)
    bp = [b for b in br.bifurcations if b.kind == "branch_point"][0]
    assert bp.parameter * C / length / mg == pytest.approx(ratio, abs=6e-4)


@pytest.mark.slow
def test_the_seed_rods_threshold_and_when_the_schedule_reaches_it():
    from hockle.api import continue_branch
    from solver.case import parse_text

    doc = parse_text((ROOT / "cases" / "goyal-writhing.yaml").read_text(), "yaml")
    table = doc["boundary"]["start"]["rotation"][2]["angular_velocity"]
    doc["numerics"]["n_segments"] = 200
    doc["distributed_forces"] = []
    doc["boundary"]["start"]["rotation"][2] = {"angular_velocity": 0.0}
    # with time 1 s the constant angular velocity (rad/s) is the twist angle (rad)
    ds = continue_branch(doc, "boundary.start.rotation.2.angular_velocity", -16.0, time=1.0,
                         max_points=60)
    phi = float(ds["bifurcation_parameter"][0])
    assert phi == pytest.approx(-10.699, abs=6e-4)
    assert abs(phi) / (2 * np.pi) == pytest.approx(1.703, abs=6e-4)
    assert not bool(ds["bifurcation_simple"][0])          # a pair of helical modes
    tt = np.linspace(0.0, 45.0, 450001)
    w = np.interp(tt, table["t"], table["value"])
    angle = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(tt))])
    assert float(np.interp(-phi, -angle, tt)) == pytest.approx(13.50, abs=6e-3)
