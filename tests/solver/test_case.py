"""Tests for solver.case: the case spec, schema_version 1 (docs/case-spec.md)."""
from __future__ import annotations

import copy
import json
import math

import numpy as np
import pydantic
import pytest
import yaml

from solver.case import (
    Case,
    CaseError,
    Condition,
    EndCondition,
    Initial,
    Output,
    Profile,
    Rod,
    Table,
    format_loc,
    format_validation_errors,
    parse_text,
)

# The example case of docs/case-spec.md, "A complete example", verbatim (checked below).
EXAMPLE_YAML = """\
schema_version: 1
name: goyal-writhing            # free text
rod:
  length: 1.0                   # m
  youngs_modulus: 1.25e7        # Pa
  shear_modulus: 5.0e6          # Pa
  density: 1500.0               # kg/m^3
  diameter: 0.02                # m: a number, or a piecewise-linear profile
  #   {s: [0, 0.4, 0.5, 0.6, 1.0], value: [0.02, 0.02, 0.018, 0.02, 0.02]}
fluid:                          # omit: vacuum, and no fluid terms are assembled
  density: 1000.0
  added_mass_coefficient: 1.0
  drag_coefficient_normal: 1.0
  drag_coefficient_tangential: 0.0
gravity: [0.0, 0.0, 0.0]        # m/s^2, global frame; omit: none
distributed_forces:             # N/m, global frame, on [start, end) seconds
  - {value: [1.0e-4, 0.0, 0.0], start: 0.0, end: 20.0}
  - {value: [0.0, 1.0e-4, 0.0], factor: {t: [0.0, 1.0], value: [0.0, 1.0]}}  # ramped on
initial:                        # straight and stress-free, start end at the origin
  tangent: [0.0, 0.0, 1.0]      # global direction of a3 along the rod
  normal: [1.0, 0.0, 0.0]       # global direction of a1
boundary:                       # six conditions per end, body frame components 1,2,3
  start:                        # s = 0
    translation: [{velocity: 0}, {velocity: 0}, {velocity: 0}]
    rotation:    [{angular_velocity: 0}, {angular_velocity: 0},
                  {angular_velocity: {t: [0, 5, 40], value: [0, 3.0, 3.0]}}]
  end:                          # s = L
    translation: [{velocity: 0}, {velocity: 0},
                  [{until: 30.0, force: 0}, {velocity: 0}]]
    rotation:    [{angular_velocity: 0}, {angular_velocity: 0}, {angular_velocity: 0}]
contact:                        # omit: no self-contact search at all
  aperture: 90.0                # degrees
  tolerance: 0.03               # m, centreline distance below which pairs are tested
  k1: 1.0e-7                    # m^(1+k2)/s^2, so rho*A*k1/gap^k2 is N/m
  k2: 3.0
  k3: 1.0e-6
  k4: 1.0
numerics:
  ds: 1.0e-3                    # m (or n_segments)
  dt: 0.1                       # s
  t_end: 32.0                   # s
  rho_inf: 0.5                  # spectral radius at infinite frequency, in [0, 1]
  newton: {tolerance: 1.0e-9, max_iterations: 25}
output:
  every: 1                      # keep every n-th step
  fields: [v, omega, f, kappa, position, energies, topology]
"""


def test_the_docs_example_is_this_one():
    """docs/case-spec.md shows the same example, so what it shows validates."""
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[2] / "docs" / "case-spec.md").read_text()
    block = doc.split("## A complete example", 1)[1].split("```yaml\n", 1)[1].split("```", 1)[0]
    assert block == EXAMPLE_YAML


@pytest.fixture
def data() -> dict:
    """A fresh mapping of the example case, to be mutated by a test."""
    return parse_text(EXAMPLE_YAML, "yaml")


def refuse(data: dict) -> list[dict]:
    """Validate ``data`` through the JSON text path; it must be refused. Returns .errors."""
    with pytest.raises(CaseError) as info:
        Case.from_text(json.dumps(data), "json")
    errors = info.value.errors
    assert errors, "a CaseError must carry at least one error"
    for e in errors:
        assert set(e) == {"loc", "msg", "type"}
        assert all(isinstance(v, str) for v in e.values())
    return errors


def assert_refused(data: dict, loc: str, fragment: str, etype: str | None = None) -> dict:
    errors = refuse(data)
    matching = [e for e in errors if e["loc"] == loc]
    assert matching, f"no error at {loc!r}; got {errors}"
    assert any(fragment in e["msg"] for e in matching), f"{fragment!r} not in {matching}"
    if etype is not None:
        assert any(e["type"] == etype for e in matching), f"type {etype!r} not in {matching}"
    return matching[0]


# --------------------------------------------------------------------------- loading


def test_docs_example_loads():
    case = Case.from_text(EXAMPLE_YAML)
    assert case.schema_version == 1
    assert case.name == "goyal-writhing"
    assert case.rod.length == 1.0
    assert case.rod.youngs_modulus == 1.25e7
    assert case.fluid is not None and case.fluid.density == 1000.0
    assert case.gravity == [0.0, 0.0, 0.0]
    assert case.distributed_forces[0].value == [1e-4, 0.0, 0.0]
    assert case.distributed_forces[0].end == 20.0
    assert case.distributed_forces[0].s_range is None
    assert case.initial.tangent == [0.0, 0.0, 1.0]
    assert case.contact is not None and case.contact.aperture == 90.0 and case.contact.exclusion is None
    # ds given: n_segments derived, both filled
    assert case.numerics.n_segments == 1000
    assert case.numerics.ds == pytest.approx(1e-3, rel=1e-15)
    assert case.numerics.newton.max_iterations == 25
    assert case.numerics.max_dt_cuts == 6 and case.numerics.dt_cut_factor == 4.0
    assert case.numerics.wall_clock_budget is None
    assert case.grid_points == 1001
    assert case.n_steps == 320
    # single condition mappings are stored as one-item lists
    end = case.boundary.end
    assert [len(item) for item in end.translation] == [1, 1, 2]
    assert end.translation[2][0].kind == "force" and end.translation[2][0].until == 30.0
    table = case.boundary.start.rotation[2][0].angular_velocity
    assert isinstance(table, Table) and table.t == [0.0, 5.0, 40.0]


def test_from_file_yaml_yml_json(tmp_path, data):
    a = tmp_path / "case.yaml"
    a.write_text(EXAMPLE_YAML)
    b = tmp_path / "case.YML"
    b.write_text(EXAMPLE_YAML)
    c = tmp_path / "case.json"
    c.write_text(json.dumps(data, indent=2))
    hashes = {Case.from_file(p).spec_hash() for p in (a, b, c)}
    assert len(hashes) == 1


def test_from_file_unknown_suffix_and_missing(tmp_path):
    p = tmp_path / "case.toml"
    p.write_text(EXAMPLE_YAML)
    with pytest.raises(CaseError) as info:
        Case.from_file(p)
    assert info.value.errors[0]["type"] == "unknown_format"
    assert ".toml" in info.value.errors[0]["msg"]
    with pytest.raises(CaseError) as info:
        Case.from_file(tmp_path / "nope.yaml")
    assert info.value.errors[0]["type"] == "file_not_found"
    assert isinstance(info.value, ValueError)


def test_yaml_syntax_error():
    with pytest.raises(CaseError) as info:
        Case.from_text("rod: {length: 1.0\nname: [unclosed", "yaml")
    (err,) = info.value.errors
    assert err["loc"] == "" and err["type"] == "yaml_syntax"
    assert "line" in err["msg"]


def test_json_syntax_error_and_unknown_format():
    with pytest.raises(CaseError) as info:
        Case.from_text('{"schema_version": 1,', "json")
    assert info.value.errors[0]["type"] == "json_syntax"
    with pytest.raises(CaseError) as info:
        Case.from_text(EXAMPLE_YAML, "toml")
    assert info.value.errors[0]["type"] == "unknown_format"


def test_document_must_be_a_mapping():
    with pytest.raises(CaseError) as info:
        Case.from_text("- 1\n- 2\n")
    assert info.value.errors[0]["type"] == "dict_type"


def test_yaml_duplicate_key_refused():
    text = EXAMPLE_YAML.replace("  density: 1500.0", "  density: 1500.0\n  density: 1600.0")
    with pytest.raises(CaseError) as info:
        Case.from_text(text)
    assert "duplicate key 'density'" in info.value.errors[0]["msg"]


def test_json_duplicate_key_refused():
    with pytest.raises(CaseError) as info:
        Case.from_text('{"name": "a", "name": "b"}', "json")
    assert "duplicate key 'name'" in info.value.errors[0]["msg"]


def test_yaml_numbers_follow_yaml_1_2():
    # PyYAML's YAML 1.1 rules read 1.25e7 (no exponent sign) as a string.
    assert yaml.safe_load("x: 1.25e7")["x"] == "1.25e7"
    assert parse_text("x: 1.25e7\ny: 1e-3\nz: 7\nw: .5\nv: -2.5E+3")  == {"x": 1.25e7, "y": 1e-3, "z": 7, "w": 0.5, "v": -2500.0}
    assert isinstance(parse_text("z: 7")["z"], int)


def test_yaml_exponent_without_dot_is_a_float():
    # PyYAML (YAML 1.1) reads 1e-3 as a string; the loader follows YAML 1.2.
    text = EXAMPLE_YAML.replace("ds: 1.0e-3", "ds: 1e-3").replace("youngs_modulus: 1.25e7", "youngs_modulus: 125e5")
    case = Case.from_text(text)
    assert case.numerics.n_segments == 1000
    assert case.rod.youngs_modulus == 1.25e7


# --------------------------------------------------------------------------- identity


def test_canonical_round_trip_same_case_and_hash():
    case = Case.from_text(EXAMPLE_YAML)
    text = case.canonical_json()
    assert " " not in text.replace("goyal-writhing", "")
    again = Case.model_validate(json.loads(text))
    assert again == case
    assert again.canonical_json() == text
    assert again.spec_hash() == case.spec_hash()
    assert len(case.spec_hash()) == 64 and int(case.spec_hash(), 16) >= 0


def test_canonical_json_fills_defaults(data):
    del data["output"], data["initial"], data["distributed_forces"]
    del data["numerics"]["rho_inf"], data["numerics"]["newton"]
    out = json.loads(Case.model_validate(data).canonical_json())
    assert out["output"] == {"every": 1, "interval": None, "interpolate": True,
                             "fields": ["v", "omega", "f", "kappa", "position", "energies", "topology"]}
    assert out["initial"] == {"tangent": [0.0, 0.0, 1.0], "normal": [1.0, 0.0, 0.0]}
    assert out["numerics"]["rho_inf"] == 0.5
    assert out["numerics"]["newton"] == {"tolerance": 1e-9, "max_iterations": 25}
    # fixed steps unless a tolerance is given; the growth guard is on
    assert out["numerics"]["tolerance"] is None and out["numerics"]["dt_max"] is None
    assert out["numerics"]["growth_guard"] == 1.0
    assert out["distributed_forces"] == []


def test_hash_changes_when_a_value_changes(data):
    base = Case.model_validate(data).spec_hash()
    data["rod"]["density"] = 1500.5
    assert Case.model_validate(data).spec_hash() != base
    data["rod"]["density"] = 1500.0
    assert Case.model_validate(data).spec_hash() == base
    data["boundary"]["end"]["translation"][2][0]["until"] = 30.5
    assert Case.model_validate(data).spec_hash() != base


def test_hash_ignores_form_but_not_meaning(data):
    """Equivalent spellings (single dict vs one-item list, ds vs n_segments, field
    order) give the same hash."""
    base = Case.model_validate(data).spec_hash()
    data["boundary"]["start"]["translation"][0] = [{"velocity": 0}]
    data["numerics"] = {**data["numerics"], "n_segments": 1000}
    del data["numerics"]["ds"]
    data["output"]["fields"] = list(reversed(data["output"]["fields"]))
    assert Case.model_validate(data).spec_hash() == base


def test_round_trip_with_profiles_tables_and_awkward_numbers(data):
    data["rod"]["length"] = 0.7
    data["rod"]["diameter"] = {"s": [0, 0.3, 0.35, 0.7], "value": [0.02, 0.02, 0.0181, 0.02]}
    data["numerics"]["ds"] = 0.007
    data["initial"] = {"tangent": [0.3, -1.7, 2.9], "normal": [1.7, 0.3, 0.0]}
    data["distributed_forces"][0]["s_range"] = [0.1, 0.6]
    data["boundary"]["end"]["translation"][0] = [
        {"force": {"t": [0, 1.1], "value": [0, 0.3]}, "until": 2.5},
        {"velocity": 0.1, "until": 7.25},
        {"force": 0},
    ]
    case = Case.model_validate(data)
    assert case.numerics.n_segments == 100
    again = Case.model_validate(json.loads(case.canonical_json()))
    assert again == case and again.spec_hash() == case.spec_hash()


def test_initial_normalisation_is_idempotent():
    rng = np.random.default_rng(12345)
    for _ in range(200):
        q, _r = np.linalg.qr(rng.normal(size=(3, 3)))
        t = q[:, 0] * rng.uniform(1e-3, 1e3)
        n = q[:, 1] * rng.uniform(1e-3, 1e3)
        ini = Initial(tangent=t.tolist(), normal=n.tolist())
        assert math.hypot(*ini.tangent) == pytest.approx(1.0, abs=1e-15)
        assert math.hypot(*ini.normal) == pytest.approx(1.0, abs=1e-15)
        assert abs(float(np.dot(ini.tangent, ini.normal))) < 1e-15
        again = Initial.model_validate(ini.model_dump(mode="json"))
        assert again.tangent == ini.tangent and again.normal == ini.normal


def test_initial_binormal():
    ini = Initial()
    assert ini.binormal == [0.0, 1.0, 0.0]  # a2 = a3 x a1 with a3 = z, a1 = x


# --------------------------------------------------------------------------- numerics


def test_n_segments_only_fills_ds(data):
    del data["numerics"]["ds"]
    data["numerics"]["n_segments"] = 400
    case = Case.model_validate(data)
    assert case.numerics.ds == 1.0 / 400
    assert case.grid_points == 401


def test_both_agreeing_accepted(data):
    data["numerics"]["n_segments"] = 1000
    assert Case.model_validate(data).numerics.n_segments == 1000


def test_n_steps_rounding(data):
    data["numerics"]["dt"] = 0.1
    data["numerics"]["t_end"] = 0.3  # 0.3 / 0.1 = 2.9999999999999996
    assert Case.model_validate(data).n_steps == 3
    data["numerics"]["t_end"] = 0.35
    assert Case.model_validate(data).n_steps == 4


# --------------------------------------------------------------------------- refusals


@pytest.mark.parametrize(
    "field, value, fragment",
    [
        ("length", 0.0, "greater than 0"),
        ("length", -1.0, "greater than 0"),
        ("youngs_modulus", 0.0, "must be > 0"),
        ("shear_modulus", -5.0e6, "must be > 0"),
        ("density", 0, "must be > 0"),
        ("diameter", -0.02, "must be > 0"),
    ],
)
def test_non_positive_rod_numbers(data, field, value, fragment):
    data["rod"][field] = value
    assert_refused(data, f"rod.{field}", fragment)


def test_non_positive_profile_value(data):
    data["rod"]["diameter"] = {"s": [0, 0.4, 0.5, 0.6, 1.0], "value": [0.02, 0.02, 0.0, 0.02, 0.02]}
    err = assert_refused(data, "rod.diameter.value[2]", "must be > 0")
    assert err["type"] == "greater_than"
    # and the message names the path
    with pytest.raises(CaseError) as info:
        Case.from_text(json.dumps(data), "json")
    assert "rod.diameter.value[2]: must be > 0" in str(info.value)


def test_profile_accepted_and_evaluated(data):
    data["rod"]["diameter"] = {"s": [0, 0.4, 0.5, 0.6, 1.0], "value": [0.02, 0.02, 0.018, 0.02, 0.02]}
    data["rod"]["youngs_modulus"] = {"s": [0.2, 0.8], "value": [1.0e7, 2.0e7]}
    rod = Case.model_validate(data).rod
    assert isinstance(rod.diameter, Profile)
    s = np.array([0.0, 0.45, 0.5, 0.55, 1.0])
    np.testing.assert_allclose(rod.evaluate("diameter", s), [0.02, 0.019, 0.018, 0.019, 0.02])
    # held constant outside the stations
    np.testing.assert_allclose(rod.evaluate("youngs_modulus", [0.0, 0.1, 0.5, 0.9, 1.0]), [1e7, 1e7, 1.5e7, 2e7, 2e7])
    # a number is broadcast to the shape of s
    out = rod.evaluate("density", np.zeros((2, 3)))
    assert out.shape == (2, 3) and np.all(out == 1500.0)
    with pytest.raises(ValueError, match="unknown rod property"):
        rod.evaluate("colour", s)


def test_profile_s_not_increasing(data):
    data["rod"]["diameter"] = {"s": [0, 0.5, 0.5, 1.0], "value": [0.02, 0.02, 0.02, 0.02]}
    assert_refused(data, "rod.diameter.s[2]", "strictly increasing", "not_increasing")


def test_profile_s_outside_rod(data):
    data["rod"]["density"] = {"s": [0, 0.5, 1.2], "value": [1500, 1500, 1500]}
    assert_refused(data, "rod.density.s[2]", "within [0, length]", "out_of_range")


def test_profile_length_mismatch_and_too_short(data):
    data["rod"]["diameter"] = {"s": [0, 0.5, 1.0], "value": [0.02, 0.02]}
    assert_refused(data, "rod.diameter.value", "has 2 points but s has 3")
    data["rod"]["diameter"] = {"s": [0], "value": [0.02]}
    assert_refused(data, "rod.diameter.s", "at least 2")


@pytest.mark.parametrize("value, fragment", [(-0.1, "greater than or equal to 0"), (1.1, "less than or equal to 1")])
def test_contact_rho_inf_out_of_range(data, value, fragment):
    data["numerics"]["contact_rho_inf"] = value
    assert_refused(data, "numerics.contact_rho_inf", fragment)


def test_contact_rho_inf_defaults_to_null(data):
    """Unset, contact steps take numerics.rho_inf (solver.step_problem.ProblemAssembly.step_problem)."""
    data["numerics"].pop("contact_rho_inf", None)
    case = Case.model_validate(data)
    assert case.numerics.contact_rho_inf is None
    # written only when given: a case without it keeps its canonical JSON and spec_hash
    assert "contact_rho_inf" not in case.canonical_json()
    data["numerics"]["contact_rho_inf"] = 0.0
    given = Case.model_validate(data)
    assert '"contact_rho_inf":0.0' in given.canonical_json()
    assert given.spec_hash() != case.spec_hash()
    assert Case.model_validate(json.loads(given.canonical_json())).numerics.contact_rho_inf == 0.0


def test_backward_euler_retry_is_on_by_default_for_fixed_steps_only(data):
    """Unset, a fixed-step retry after a Newton or energy refusal is a backward-Euler step
    and the field stays out of the canonical JSON (a case without it keeps its spec_hash);
    false is written and re-validates; with numerics.tolerance the default does not apply
    (the field reads false and is not written) and true given is refused, naming the
    field (the error estimate is generalized-α's)."""
    case = Case.model_validate(data)
    assert case.numerics.backward_euler_retry is True
    assert "backward_euler_retry" not in case.canonical_json()
    data["numerics"]["backward_euler_retry"] = True
    assert Case.model_validate(data).spec_hash() == case.spec_hash()
    data["numerics"]["backward_euler_retry"] = False
    given = Case.model_validate(data)
    assert '"backward_euler_retry":false' in given.canonical_json()
    assert given.spec_hash() != case.spec_hash()
    again = Case.model_validate(json.loads(given.canonical_json()))
    assert again.numerics.backward_euler_retry is False
    data["numerics"]["backward_euler_retry"] = "yes"
    assert_refused(data, "numerics.backward_euler_retry", "valid boolean")
    del data["numerics"]["backward_euler_retry"]
    data["numerics"]["tolerance"] = {"relative": 1e-3}
    controlled = Case.model_validate(data)
    assert controlled.numerics.backward_euler_retry is False
    assert "backward_euler_retry" not in controlled.canonical_json()
    again = Case.model_validate(json.loads(controlled.canonical_json()))
    assert again.spec_hash() == controlled.spec_hash()
    data["numerics"]["backward_euler_retry"] = False
    assert Case.model_validate(data).spec_hash() == controlled.spec_hash()
    data["numerics"]["backward_euler_retry"] = True
    assert_refused(data, "numerics.backward_euler_retry", "fixed steps only", "unsupported")


def test_end_drift_tolerance_defaults_to_the_diameter_and_keeps_the_hash(data):
    """contact.end_drift_tolerance: unset (null: the rod's largest diameter, read by the
    run) it stays out of the canonical JSON, so a case without it keeps its spec_hash; a
    value is written and re-validates; 0 and a negative value are refused, naming the
    field."""
    from solver.run import RodRun

    case = Case.model_validate(data)
    assert case.contact.end_drift_tolerance is None
    assert "end_drift_tolerance" not in case.canonical_json()
    assert RodRun(case).assembly.end_drift_tolerance() == pytest.approx(case.rod.diameter)
    data["contact"]["end_drift_tolerance"] = 0.005
    given = Case.model_validate(data)
    assert '"end_drift_tolerance":0.005' in given.canonical_json()
    assert given.spec_hash() != case.spec_hash()
    again = Case.model_validate(json.loads(given.canonical_json()))
    assert again.spec_hash() == given.spec_hash()
    assert RodRun(again).assembly.end_drift_tolerance() == 0.005
    for bad in (0.0, -1.0):
        data["contact"]["end_drift_tolerance"] = bad
        assert_refused(data, "contact.end_drift_tolerance", "greater than 0")


@pytest.mark.parametrize("rho_inf, fragment", [(-0.1, "greater than or equal to 0"), (1.1, "less than or equal to 1")])
def test_rho_inf_out_of_range(data, rho_inf, fragment):
    data["numerics"]["rho_inf"] = rho_inf
    assert_refused(data, "numerics.rho_inf", fragment)


def test_boundary_table_times_not_increasing(data):
    data["boundary"]["start"]["rotation"][2] = {"angular_velocity": {"t": [0, 5, 5], "value": [0, 3, 3]}}
    assert_refused(
        data, "boundary.start.rotation[2][0].angular_velocity.t[2]", "strictly increasing", "not_increasing"
    )


def test_boundary_table_length_mismatch(data):
    data["boundary"]["start"]["rotation"][2] = {"angular_velocity": {"t": [0, 5, 40], "value": [0, 3]}}
    assert_refused(data, "boundary.start.rotation[2][0].angular_velocity.value", "has 2 points but t has 3")


def test_two_conditions_for_one_dof(data):
    data["boundary"]["start"]["translation"][0] = {"velocity": 0, "force": 0}
    assert_refused(data, "boundary.start.translation[0][0]", "two conditions for one DOF", "two_conditions")


def test_no_condition_for_a_dof(data):
    data["boundary"]["start"]["translation"][0] = {}
    assert_refused(data, "boundary.start.translation[0][0]", "no condition given")
    data["boundary"]["start"]["translation"][0] = []
    assert_refused(data, "boundary.start.translation[0]", "at least 1")


def test_last_item_with_until_leaves_dof_without_condition(data):
    data["boundary"]["end"]["translation"][2] = [{"until": 30.0, "force": 0}, {"velocity": 0, "until": 40.0}]
    assert_refused(
        data, "boundary.end.translation[2][1].until", "boundary DOF has no condition after t=40.0", "no_condition_after"
    )


def test_single_condition_with_until_refused(data):
    data["boundary"]["end"]["rotation"][1] = {"angular_velocity": 0, "until": 3.0}
    assert_refused(data, "boundary.end.rotation[1][0].until", "no condition after t=3.0")


def test_until_required_and_increasing(data):
    data["boundary"]["end"]["translation"][2] = [{"force": 0}, {"velocity": 0}]
    assert_refused(data, "boundary.end.translation[2][0].until", "required", "until_required")
    data["boundary"]["end"]["translation"][2] = [{"force": 0, "until": 5.0}, {"velocity": 0, "until": 5.0}, {"force": 0}]
    assert_refused(data, "boundary.end.translation[2][1].until", "must increase", "not_increasing")


def test_until_must_be_positive(data):
    data["boundary"]["end"]["translation"][2][0]["until"] = 0.0
    assert_refused(data, "boundary.end.translation[2][0].until", "greater than 0")


def test_rotation_item_given_velocity(data):
    data["boundary"]["start"]["rotation"][0] = {"velocity": 0}
    err = assert_refused(data, "boundary.start.rotation[0][0].velocity", "allowed keys: angular_velocity, moment")
    assert err["type"] == "wrong_group"


def test_translation_item_given_moment(data):
    data["boundary"]["end"]["translation"][1] = {"moment": 1.0}
    assert_refused(data, "boundary.end.translation[1][0].moment", "allowed keys: velocity, force")


def test_end_needs_exactly_three_items(data):
    data["boundary"]["start"]["translation"] = [{"velocity": 0}, {"velocity": 0}]
    assert_refused(data, "boundary.start.translation", "at least 3")
    data["boundary"]["start"]["translation"] = [{"velocity": 0}] * 4
    assert_refused(data, "boundary.start.translation", "at most 3")


def test_unknown_output_field(data):
    data["output"]["fields"] = ["v", "temperature"]
    err = assert_refused(data, "output.fields[1]", "unknown output field 'temperature'")
    assert "allowed: v, omega, f, kappa, moment, position, orientation, energies, topology, contact" in err["msg"]


def test_duplicate_output_field(data):
    data["output"]["fields"] = ["v", "kappa", "v"]
    assert_refused(data, "output.fields[2]", "listed twice", "duplicate")


def test_output_fields_canonical_order():
    assert Output(fields=["contact", "v", "energies"]).fields == ["v", "energies", "contact"]
    assert Output(fields=[]).fields == []


def test_output_every_at_least_one(data):
    data["output"]["every"] = 0
    assert_refused(data, "output.every", "greater than or equal to 1")


def test_ds_not_dividing_length(data):
    data["numerics"]["ds"] = 3.0e-4
    err = assert_refused(data, "numerics.ds", "does not divide", "ds_not_dividing")
    assert "n_segments" in err["msg"]
    data["numerics"]["ds"] = 2.0  # longer than the rod
    assert_refused(data, "numerics.ds", "does not divide")


def test_n_segments_and_ds_disagree(data):
    data["numerics"]["n_segments"] = 999
    assert_refused(data, "numerics.n_segments", "disagrees with ds", "inconsistent")


def test_neither_ds_nor_n_segments(data):
    del data["numerics"]["ds"]
    assert_refused(data, "numerics.ds", "n_segments")


def test_unknown_top_level_field(data):
    data["colour"] = "red"
    assert_refused(data, "colour", "unknown field", "extra_forbidden")


def test_unknown_nested_field(data):
    data["rod"]["poisson_ratio"] = 0.3
    assert_refused(data, "rod.poisson_ratio", "unknown field", "extra_forbidden")
    del data["rod"]["poisson_ratio"]
    data["numerics"]["newton"]["tol"] = 1e-8
    assert_refused(data, "numerics.newton.tol", "unknown field", "extra_forbidden")


def test_string_for_length_is_a_type_error(data):
    data["rod"]["length"] = "1.0"
    assert_refused(data, "rod.length", "number", "float_type")
    data["rod"]["length"] = True
    assert_refused(data, "rod.length", "number", "float_type")


def test_string_for_material_and_integer(data):
    data["rod"]["diameter"] = "0.02"
    assert_refused(data, "rod.diameter", "number", "float_type")
    data["rod"]["diameter"] = 0.02
    data["numerics"]["newton"]["max_iterations"] = "25"
    assert_refused(data, "numerics.newton.max_iterations", "integer", "int_type")


def test_nan_length_refused(data):
    data["rod"]["length"] = float("nan")  # json.dumps writes NaN, json.loads reads it back
    assert_refused(data, "rod.length", "finite", "finite_number")


def test_nan_and_inf_refused_everywhere(data):
    cases = [
        (("gravity",), 1, float("nan"), "gravity[1]"),
        (("numerics",), "dt", float("inf"), "numerics.dt"),
        (("rod",), "youngs_modulus", float("inf"), "rod.youngs_modulus"),
        (("distributed_forces", 0), "end", float("inf"), "distributed_forces[0].end"),
    ]
    for path, key, value, loc in cases:
        d = copy.deepcopy(data)
        target = d
        for p in path:
            target = target[p]
        target[key] = value
        assert_refused(d, loc, "finite")
    d = copy.deepcopy(data)
    d["boundary"]["start"]["translation"][0] = {"velocity": float("nan")}
    assert_refused(d, "boundary.start.translation[0][0].velocity", "finite")
    d = copy.deepcopy(data)
    d["rod"]["diameter"] = {"s": [0, 1], "value": [0.02, float("nan")]}
    assert_refused(d, "rod.diameter.value[1]", "finite")


def test_yaml_nan_refused():
    text = EXAMPLE_YAML.replace("t_end: 32.0", "t_end: .nan")
    with pytest.raises(CaseError) as info:
        Case.from_text(text)
    assert info.value.errors[0]["loc"] == "numerics.t_end"


def test_vectors_need_three_components(data):
    data["gravity"] = [0.0, -9.81]
    assert_refused(data, "gravity", "at least 3")
    data["gravity"] = [0.0, -9.81, 0.0, 1.0]
    assert_refused(data, "gravity", "at most 3")


def test_schema_version_must_be_1(data):
    data["schema_version"] = 2
    assert_refused(data, "schema_version", "unsupported schema_version 2", "unsupported_schema_version")
    del data["schema_version"]
    assert_refused(data, "schema_version", "required", "missing")


def test_initial_refusals(data):
    data["initial"] = {"tangent": [0, 0, 1], "normal": [1, 0, 0.01]}
    assert_refused(data, "initial.normal", "orthogonal", "not_orthogonal")
    data["initial"] = {"tangent": [0, 0, 0], "normal": [1, 0, 0]}
    assert_refused(data, "initial.tangent", "non-zero", "zero_vector")


def test_initial_normalised_and_made_orthogonal(data):
    data["initial"] = {"tangent": [0, 0, 2], "normal": [3, 0, 1e-10]}
    ini = Case.model_validate(data).initial
    assert ini.tangent == [0.0, 0.0, 1.0]
    assert ini.normal == [1.0, 0.0, 0.0]


def test_distributed_force_refusals(data):
    data["distributed_forces"][0]["end"] = 0.0
    assert_refused(data, "distributed_forces[0].end", "must be > start")
    data["distributed_forces"][0]["end"] = 20.0
    data["distributed_forces"][0]["s_range"] = [0.5, 1.5]
    assert_refused(data, "distributed_forces[0].s_range[1]", "within [0, rod.length]")
    data["distributed_forces"][0]["s_range"] = [0.5, 0.2]
    assert_refused(data, "distributed_forces[0].s_range[1]", "must be > s_range[0]")


def test_distributed_force_window(data):
    force = Case.model_validate(data).distributed_forces[0]
    assert force.is_active(0.0) and force.is_active(19.99) and not force.is_active(20.0)
    data["distributed_forces"][0].pop("end")
    assert Case.model_validate(data).distributed_forces[0].is_active(1e9)


@pytest.mark.parametrize(
    "key, value, loc",
    [
        ("aperture", 0.0, "contact.aperture"),
        ("aperture", 180.5, "contact.aperture"),
        ("tolerance", 0.0, "contact.tolerance"),
        ("k1", -1.0, "contact.k1"),
        ("k2", 0.0, "contact.k2"),
        ("k3", -1e-6, "contact.k3"),
        ("k4", -1.0, "contact.k4"),
        ("exclusion", -0.01, "contact.exclusion"),
    ],
)
def test_contact_refusals(data, key, value, loc):
    data["contact"][key] = value
    assert_refused(data, loc, "Input should be")


def test_fluid_and_numerics_refusals(data):
    d = copy.deepcopy(data)
    d["fluid"]["density"] = 0.0
    assert_refused(d, "fluid.density", "greater than 0")
    d = copy.deepcopy(data)
    d["fluid"]["drag_coefficient_normal"] = -1.0
    assert_refused(d, "fluid.drag_coefficient_normal", "greater than or equal to 0")
    d = copy.deepcopy(data)
    d["numerics"]["dt_cut_factor"] = 1.0
    assert_refused(d, "numerics.dt_cut_factor", "greater than 1")
    d = copy.deepcopy(data)
    d["numerics"]["max_dt_cuts"] = -1
    assert_refused(d, "numerics.max_dt_cuts", "greater than or equal to 0")
    d = copy.deepcopy(data)
    d["numerics"]["wall_clock_budget"] = 0
    assert_refused(d, "numerics.wall_clock_budget", "greater than 0")
    d = copy.deepcopy(data)
    d["numerics"]["newton"]["max_iterations"] = 0
    assert_refused(d, "numerics.newton.max_iterations", "greater than or equal to 1")


def test_several_errors_reported_together(data):
    data["rod"]["length"] = -1
    data["rod"]["density"] = 0
    data["output"]["fields"] = ["nope"]
    locs = {e["loc"] for e in refuse(data)}
    assert {"rod.length", "rod.density", "output.fields[0]"} <= locs


# --------------------------------------------------------------------------- error formatting


def test_format_validation_errors_and_loc(data):
    data["boundary"]["end"]["translation"][2][0]["until"] = "soon"
    with pytest.raises(pydantic.ValidationError) as info:
        Case.model_validate(data)
    errors = format_validation_errors(info.value)
    assert errors == [
        {"loc": "boundary.end.translation[2][0].until",
         "msg": "Input should be a number, not the text 'soon': case values are plain numbers "
                "in SI units (m, s, kg, N, Pa, rad), written without a unit",
         "type": "float_type"}
    ]
    assert format_loc(("rod", "diameter", "value", 2)) == "rod.diameter.value[2]"
    assert format_loc(()) == ""


def test_case_error_str_is_readable():
    err = CaseError([{"loc": "rod.length", "msg": "bad", "type": "x"}, {"loc": "", "msg": "worse", "type": "y"}], "c.yaml")
    text = str(err)
    assert text.splitlines() == ["invalid case spec (c.yaml): 2 errors", "  rod.length: bad", "  (case): worse"]


# --------------------------------------------------------------------------- conditions in time


def test_active_switches_at_until():
    end = EndCondition.model_validate(
        {
            "translation": [
                {"velocity": 0},
                {"velocity": 0},
                [{"force": 1.0, "until": 30.0}, {"velocity": 0.5, "until": 35.0}, {"force": -2.0}],
            ],
            "rotation": [{"angular_velocity": 0}, {"moment": 0}, {"angular_velocity": 0}],
        }
    )
    kinds = [end.active("translation", 2, t).kind for t in (0.0, 29.999, 30.0, 30.0 * (1 + 1e-13), 30.001, 35.0, 36.0)]
    assert kinds == ["force", "force", "force", "force", "velocity", "velocity", "force"]
    assert end.active("translation", 2, 40.0).value_at(40.0) == -2.0
    assert end.active("translation", 0, 1e6).kinematic is True
    assert end.active("rotation", 1, 0.0).kinematic is False
    assert end.active("translation", 2, 0.0).kinematic is False
    with pytest.raises(ValueError):
        end.active("twist", 0, 0.0)
    with pytest.raises(IndexError):
        end.active("rotation", 3, 0.0)


def test_value_at_interpolates_and_holds():
    cond = Condition.model_validate({"angular_velocity": {"t": [0, 5, 40], "value": [0, 3.0, 3.0]}})
    assert cond.kinematic is True and cond.kind == "angular_velocity"
    assert cond.value_at(-1.0) == 0.0
    assert cond.value_at(0.0) == 0.0
    assert cond.value_at(2.5) == pytest.approx(1.5)
    assert cond.value_at(5.0) == 3.0
    assert cond.value_at(100.0) == 3.0
    table = Condition.model_validate({"force": {"t": [1, 2], "value": [10, -10]}})
    assert table.value_at(0.0) == 10.0 and table.value_at(1.25) == pytest.approx(5.0) and table.value_at(9) == -10.0
    const = Condition.model_validate({"moment": 0.25})
    assert const.kinematic is False and const.value_at(123.0) == 0.25
    assert isinstance(const.value_at(0), float)


def test_condition_dump_omits_absent_keys():
    cond = Condition.model_validate({"until": 3.0, "force": 2})
    assert cond.model_dump(mode="json") == {"force": 2.0, "until": 3.0}


def test_models_accept_python_objects():
    """Constructing from models (the Python API) works as well as from mappings."""
    rod = Rod(length=2.0, youngs_modulus=1e7, shear_modulus=4e6, density=1000,
              diameter=Profile(s=[0, 2], value=[0.01, 0.02]))
    assert rod.evaluate("diameter", [1.0])[0] == pytest.approx(0.015)
    with pytest.raises(pydantic.ValidationError) as info:
        Rod(length=2.0, youngs_modulus=1e7, shear_modulus=4e6, density=1000,
            diameter=Profile(s=[0, 2], value=[0.01, -0.02]))
    assert format_validation_errors(info.value)[0]["loc"] == "diameter.value[1]"


def test_json_schema_generates():
    schema = Case.model_json_schema()
    assert schema["additionalProperties"] is False
    assert "Rod" in schema["$defs"] and "Condition" in schema["$defs"]
    assert Case.model_json_schema(mode="serialization")["$defs"]["Rod"]["properties"]["diameter"]


def test_contact_tolerance_must_exceed_the_largest_diameter():
    from rodcases import make_case

    with pytest.raises(pydantic.ValidationError) as info:
        make_case(diameter=0.02, contact={"aperture": 90.0, "tolerance": 0.02, "k1": 1e-7,
                                          "k2": 3.0, "k3": 1e-6, "k4": 1.0})
    errors = format_validation_errors(info.value)
    assert any(e["loc"] == "contact.tolerance" and "diameter" in e["msg"] for e in errors)


@pytest.mark.parametrize("change, loc, words", [
    (lambda d: d["numerics"].update(dt=5e-324), "numerics.dt", "steps"),
    (lambda d: d["numerics"].update(dt=1e-300, t_end=1e12), "numerics.dt", "steps"),
    (lambda d: d["numerics"].update(max_dt_cuts=1_000_000), "numerics.max_dt_cuts", "50"),
    (lambda d: d["numerics"].update(dt_cut_factor=1e300), "numerics.dt_cut_factor", "1000"),
    (lambda d: (d["numerics"].pop("ds", None), d["numerics"].update(n_segments=10**9)),
     "numerics.n_segments", "1000000"),
    (lambda d: (d["numerics"].pop("n_segments", None), d["numerics"].update(ds=1e-9)),
     "numerics.ds", "segments"),
    (lambda d: d.update(name="x" * 201), "name", "200"),
    (lambda d: d.update(name="a\x00b"), "name", "control characters"),
])
def test_inputs_that_validated_but_could_not_run_are_refused(data, change, loc, words):
    # found by the service audit: these validated and then overflowed (5e-324 s steps,
    # 1e6 cuts), ran out of memory (1e9 segments) or broke the PostgreSQL registry (a name
    # over 200 characters, a NUL byte); each is refused at its field with the reason
    change(data)
    with pytest.raises(pydantic.ValidationError) as info:
        Case.model_validate(data)
    errors = info.value.errors()
    assert any(".".join(str(x) for x in e["loc"]) == loc and words in e["msg"] for e in errors), errors


@pytest.mark.parametrize("fmt", ["json", "yaml"])
def test_too_deep_documents_are_a_case_error(fmt):
    text = "[" * 5000 + "]" * 5000
    with pytest.raises(CaseError) as info:
        parse_text(text, fmt, "deep")
    assert "too deeply" in str(info.value)


def test_an_error_inside_a_section_does_not_hide_the_checks_across_sections():
    """A broken initial.tangent used to stop validation before the checks across
    sections: the point load off the rod and the over-constrained ends went unreported.
    Each check is reported where the sections it reads are valid, and skipped where they
    are not (the ends' check reads initial, which is broken)."""
    spec = parse_text(EXAMPLE_YAML)
    spec.pop("contact", None)
    spec["initial"]["tangent"] = [0.0, 0.0, 0.0]
    spec["point_loads"] = [{"s": 5.0, "value": [0.0, 0.0, 1.0]}]
    with pytest.raises(CaseError) as info:
        Case.from_text(json.dumps(spec), fmt="json")
    locs = [e["loc"] for e in info.value.errors]
    assert locs == ["initial.tangent", "point_loads[0].s"], locs
    spec["initial"]["tangent"] = [0.0, 0.0, 1.0]
    spec["rod"]["density"] = -1.0
    spec["boundary"]["end"]["translation"][2] = {"velocity": 0}
    with pytest.raises(CaseError) as info:
        Case.from_text(json.dumps(spec), fmt="json")
    locs = [e["loc"] for e in info.value.errors]
    assert locs[0] == "rod.density" and "boundary.end.translation[2]" in locs, locs
