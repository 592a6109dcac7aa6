"""What a branch shows (service/branch_view.py, issue 80): the parameter's unit from the case
spec, round-off drawn as zero, the measures that stay constant named as such, and the events
with the mode counts on either side. On a small branch dataset made by hand, no solve."""
from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr

from service.branch_view import measures, overview, parameter_label, parameter_unit


@pytest.mark.parametrize("path, unit", [
    ("boundary.end.translation.2.force", "N"),
    ("boundary.end.translation[2].velocity", "m/s"),
    ("boundary.start.rotation.2.angular_velocity", "rad/s"),
    ("boundary.end.rotation.2.moment", "N m"),
    ("rod.youngs_modulus", "Pa"),
    ("rod.density", "kg/m^3"),
    ("rod.length", "m"),
    ("gravity.2", "m/s^2"),
    ("distributed_forces.0.value.1", "N/m"),
    ("initial.twist_rate", "rad/m"),
    ("seabed.normal_damping", "Pa s"),
    ("contact.aperture", "°"),
    ("fluid.added_mass_coefficient", "1"),
    ("rod.nowhere", ""),
])
def test_the_unit_of_a_parameter_comes_from_the_case_spec(path, unit):
    assert parameter_unit(path) == unit


def _branch(n=6, nodes=101):
    """A straight column (points 0-2) and a buckled one in the plane x = y (points 3-5),
    with round-off where exact arithmetic has zeros."""
    s = np.linspace(0.0, 1.0, nodes)
    lam = -np.linspace(0.1, 0.4, n)
    pos = np.zeros((n, nodes, 3))
    pos[:, :, 2] = s
    amp = np.r_[0, 0, 0, 0.05, 0.1, 0.2]
    pos[:, :, 0] = pos[:, :, 1] = amp[:, None] * (1 - np.cos(2 * np.pi * s))[None, :] / (2 * np.sqrt(2))
    end_force = np.zeros((n, 3))
    end_force[:, 2] = lam
    end_moment = np.zeros((n, 3))
    end_moment[:, 2] = 1e-17 * np.r_[1, -2, 3, -1, 2, -3]         # round-off
    modes = np.r_[0, 0, 2, 0, 0, 1]
    data = {
        "parameter": ("point", lam, {"path": "boundary.end.translation.2.force"}),
        "unstable_modes": ("point", modes), "branch": ("point", np.r_[0, 0, 0, 1, 1, 1]),
        "position": (("point", "node", "xyz"), pos),
        "end_force": (("point", "xyz"), end_force),
        "end_moment": (("point", "xyz"), end_moment),
        "end_to_end": ("point", np.r_[1.0, 1.0, 1.0, 0.99, 0.97, 0.9]),
        "writhe": ("point", 1e-12 * np.r_[0, 1, -7, 4, -2, 6]),          # round-off
        "twist": ("point", np.zeros(n)),
        "elastic_energy": ("point", np.r_[0, 0, 0, 0.01, 0.03, 0.06]),
        "load_potential": ("point", lam * 0.5),
        "total_energy": ("point", np.r_[0, 0, 0, 0.01, 0.03, 0.06] + lam * 0.5),
        "bifurcation_parameter": ("bifurcation", np.r_[-0.24]),
        "bifurcation_kind": ("bifurcation", np.array(["branch_point"])),
        "bifurcation_after": ("bifurcation", np.r_[1]),
        "bifurcation_simple": ("bifurcation", np.r_[0]),
    }
    case = {"rod": {"length": 1.0}, "initial": {"tangent": [0, 0, 1]}}
    return xr.Dataset(data, attrs={"hockle_kind": "branch", "case": json.dumps(case),
                                   "parameter_path": "boundary.end.translation.2.force",
                                   "switched_at": 2, "stopped": "reached the target value",
                                   "target": -0.4})


def test_round_off_is_zero_and_constant_measures_are_named():
    found = measures(_branch())
    assert np.all(found["end_moment_axial"]["values"] == 0.0)
    assert np.all(found["writhe"]["values"] == 0.0)
    assert found["end_moment_axial"]["constant"] and found["writhe"]["constant"]
    assert found["twist"]["constant"]
    ex = found["excursion"]
    assert not ex["constant"] and ex["units"] == "m"
    np.testing.assert_allclose(ex["values"], [0, 0, 0, 0.05, 0.1, 0.2], atol=1e-12)
    assert not found["end_to_end"]["constant"] and not found["end_force_axial"]["constant"]
    # the column clamped at s = 0: the end force along its start tangent is the parameter
    np.testing.assert_allclose(found["end_force_axial"]["values"], _branch()["parameter"],
                               rtol=2e-3)
    # a value well above round-off stays as it is
    ds = _branch()
    ds["writhe"].values[4] = 1e-3            # a thousandth of a turn: no round-off
    assert measures(ds)["writhe"]["values"][4] > 0


def test_the_overview_has_units_events_and_mode_counts():
    view = overview(_branch())
    assert view["parameter"]["unit"] == "N"
    assert view["parameter"]["label"] == "boundary.end.translation.2.force (N)"
    assert view["n_points"] == 6 and view["stored"] == list(range(6))
    assert view["unstable_modes"] == [0, 0, 2, 0, 0, 1] and view["switched_at"] == 2
    [event] = view["events"]
    assert event["kind"] == "branch_point" and not event["simple"]
    assert (event["modes_before"], event["modes_after"]) == (0, 2)
    assert event["switched_here"] and "pair" in event["label"]
    names = [m["name"] for m in view["measures"]]
    assert names[0] == "excursion" and all(m["units"] for m in view["measures"])
    json.dumps(view)                                      # plain JSON, no NaN objects


def test_a_label_that_carries_its_unit_is_kept():
    ds = _branch()
    ds.attrs["parameter_path"] = "P (N)"
    assert parameter_label(ds) == "P (N)"


def test_points_without_a_shape():
    """--shapes-every K: the shape-based measure is null there, the others are defined
    (the start tangent carried from the last stored shape), and ``stored`` lists the rest."""
    ds = _branch()
    ds["position"].values[[1, 4]] = np.nan
    view = overview(ds)
    assert view["stored"] == [0, 2, 3, 5]
    by_name = {m["name"]: m for m in view["measures"]}
    assert by_name["excursion"]["values"][1] is None and by_name["excursion"]["values"][4] is None
    assert None not in by_name["end_force_axial"]["values"]
