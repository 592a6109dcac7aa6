"""Sizes that cannot be meant are refused by the case itself (CLI, Python API and service
alike), each naming its field: a step longer than the run, a diameter larger than the rod, an
output cadence beyond the step count, an integer too large for a float."""
from __future__ import annotations

import copy
import json

import pytest

from rodcases import tiny_spec
from solver.case import Case, CaseError

BASE = tiny_spec("limits")


def _with(section: str, key: str, value) -> dict:
    spec = copy.deepcopy(BASE)
    spec.setdefault(section, {})[key] = value
    return spec


def _locs(spec) -> list[str]:
    with pytest.raises(CaseError) as info:
        Case.from_text(json.dumps(spec), "json")
    return [e["loc"] for e in info.value.errors]


@pytest.mark.parametrize("section,key,value,loc", [
    ("numerics", "dt", 1e308, "numerics.dt"),
    ("numerics", "dt", 0.0500001, "numerics.dt"),
    ("rod", "diameter", 1e300, "rod.diameter"),
    ("rod", "diameter", {"s": [0.0, 1.0], "value": [0.02, 1.5]}, "rod.diameter"),
    ("output", "every", 10**12, "output.every"),
    ("output", "every", 6, "output.every"),
])
def test_sizes_beyond_sense_are_refused(section, key, value, loc):
    assert loc in _locs(_with(section, key, value))


@pytest.mark.parametrize("section,key,value", [
    ("numerics", "dt", 0.05),            # one step
    ("rod", "diameter", 1.0),            # as thick as long: odd, but a body
    ("output", "every", 5),              # the first and last states
])
def test_the_limits_themselves_are_accepted(section, key, value):
    Case.from_text(json.dumps(_with(section, key, value)), "json")


def test_an_every_beyond_the_steps_with_error_control_is_not_counted():
    spec = _with("output", "every", 1000)
    spec["numerics"]["tolerance"] = {"relative": 1e-3}   # the controller chooses the steps
    Case.from_text(json.dumps(spec), "json")


@pytest.mark.parametrize("fmt", ["json", "yaml"])
def test_an_integer_too_large_for_a_float_names_its_field(fmt):
    text = json.dumps(_with("rod", "youngs_modulus", 12345)).replace("12345", "1" + "0" * 400)
    with pytest.raises(CaseError) as info:
        Case.from_text(text, fmt)
    assert [e["loc"] for e in info.value.errors] == ["rod.youngs_modulus"]
    assert "too large for a float" in info.value.errors[0]["msg"]
