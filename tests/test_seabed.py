"""The sea floor (case section ``seabed``, solver/seabed.py): normal contact and Coulomb
friction against analytic results, its Jacobian against finite differences, a bathymetry
grid against the plane it represents, and the refused inputs (docs/seabed.md)."""
from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from rodcases import jacobian_fd_error
from solver.case import Case, CaseError
from solver.run import RodRun
from solver.simulation import simulate

D, RHO, RHO_F, G = 0.02, 1500.0, 1000.0, 9.81
AREA = math.pi * D**2 / 4
W = (RHO - RHO_F) * AREA * G           # submerged weight per length, N/m
FREE = {"translation": [{"force": 0}] * 3, "rotation": [{"moment": 0}] * 3}
FREE_ROT = [{"moment": 0}] * 3
HELD_ROT = [{"angular_velocity": 0}] * 3


def _spec(seabed=None, length=1.0, n=20, dt=0.01, t_end=1.0, start=None, end=None, **extra):
    spec = {"schema_version": 1, "name": "floor",
            "rod": {"length": length, "youngs_modulus": 1.25e7, "shear_modulus": 5e6,
                    "density": RHO, "diameter": D},
            "fluid": {"density": RHO_F}, "gravity": [0, 0, -G],
            "initial": {"tangent": [1, 0, 0], "normal": [0, 0, 1]},
            "seabed": {"elevation": -D / 2} if seabed is None else seabed,
            "boundary": {"start": start or FREE, "end": end or FREE},
            "numerics": {"n_segments": n, "dt": dt, "t_end": t_end}}
    spec.update(extra)
    return spec


def _refused(spec):
    with pytest.raises(CaseError) as info:
        Case.from_text(json.dumps(spec), fmt="json")
    return info.value.errors


def _run_to(case, t_end):
    run = RodRun(case)
    dt = case.numerics.dt
    for k in range(1, int(round(t_end / dt)) + 1):
        run.advance(k * dt)
    return run


# --------------------------------------------------------------------------- the case
def test_absent_seabed_keeps_the_canonical_json():
    spec = _spec()
    spec.pop("seabed")
    assert "seabed" not in json.loads(Case.model_validate(spec).canonical_json())
    case = Case.model_validate(_spec())
    assert json.loads(case.canonical_json())["seabed"] == {
        "elevation": -D / 2, "normal_stiffness": 3e6, "normal_damping": 3e5}
    assert Case.model_validate_json(case.canonical_json()).spec_hash() == case.spec_hash()


GRID = {"x": [0.0, 1.0], "y": [0.0, 1.0], "z": [[-1.0, -1.0], [-1.0, -1.0]]}


@pytest.mark.parametrize("change, loc, etype", [
    ({"bathymetry": {**GRID, "x": [1.0, 0.0]}}, "seabed.bathymetry.x[1]", "not_increasing"),
    ({"bathymetry": {**GRID, "y": [0.0, 0.0]}}, "seabed.bathymetry.y[1]", "not_increasing"),
    ({"bathymetry": {**GRID, "z": [[-1.0, -1.0]]}}, "seabed.bathymetry.z", "wrong_shape"),
    ({"bathymetry": {**GRID, "z": [[-1.0], [-1.0]]}}, "seabed.bathymetry.z[0]", "wrong_shape"),
    ({"bathymetry": {"x": list(range(1001)), "y": list(range(1001)), "z": [[0.0]]}},
     "seabed.bathymetry.z", "too_many_points"),
    ({"normal_stiffness": -1.0}, "seabed.normal_stiffness", "greater_than_equal"),
    ({"normal_damping": -1.0}, "seabed.normal_damping", "greater_than_equal"),
    ({"friction": {"axial": -0.1, "lateral": 0.5}}, "seabed.friction.axial", "greater_than_equal"),
    ({"friction": {"axial": 0.1, "lateral": -0.5}}, "seabed.friction.lateral",
     "greater_than_equal"),
    ({"friction": {"axial": 0.1, "lateral": 0.5, "static_to_kinetic": 0.9}},
     "seabed.friction.static_to_kinetic", "greater_than_equal"),
    ({"friction": {"axial": 0.1, "lateral": 0.5, "slip_velocity": 0.0}},
     "seabed.friction.slip_velocity", "greater_than"),
    ({"elevation": 0.5}, "seabed.elevation", "starts_below_seabed"),
])
def test_bad_seabed_input_is_refused_naming_the_field(change, loc, etype):
    seabed = {"elevation": -D / 2}
    seabed.update(change)
    if "bathymetry" in change:
        seabed.pop("elevation")
    errors = _refused(_spec(seabed))
    assert any(e["loc"] == loc and e["type"] == etype for e in errors), errors


def test_nan_in_bathymetry_is_refused():
    text = json.dumps(_spec({"bathymetry": GRID})).replace("[-1.0, -1.0], [-1.0", "[NaN, -1.0], [-1.0")
    with pytest.raises(CaseError) as info:
        Case.from_text(text, fmt="json")
    assert any(e["loc"].startswith("seabed.bathymetry.z[0][0]") for e in info.value.errors), \
        info.value.errors


def test_both_or_neither_bottom_and_gravity_away_are_refused():
    errors = _refused(_spec({"elevation": -1.0, "bathymetry": GRID}))
    assert any(e["loc"] == "seabed" and e["type"] == "one_bottom" for e in errors), errors
    errors = _refused(_spec({}))
    assert any(e["loc"] == "seabed" and e["type"] == "one_bottom" for e in errors), errors
    errors = _refused(_spec(gravity=[0, 0, 9.81]))
    assert any(e["loc"] == "gravity" and e["type"] == "away_from_seabed" for e in errors), errors
    # a cable starting inside a bathymetry grid's hill
    hill = {"x": [0.0, 1.0], "y": [-1.0, 1.0], "z": [[-1.0, -1.0], [0.2, 0.2]]}
    errors = _refused(_spec({"bathymetry": hill}))
    assert any(e["loc"] == "seabed.bathymetry" and e["type"] == "starts_below_seabed"
               for e in errors), errors


# --------------------------------------------------------------------------- Jacobian
@pytest.mark.parametrize("seabed", [
    {"elevation": 0.0, "normal_stiffness": 50.0, "normal_damping": 5.0,
     "friction": {"axial": 0.3, "lateral": 0.7, "static_to_kinetic": 1.5, "slip_velocity": 0.8}},
    {"bathymetry": {"x": [-3.0, -0.5, 0.4, 3.0], "y": [-3.0, 0.1, 3.0],
                    "z": [[-2.0, -1.5, -2.5], [0.3, -0.2, 0.1], [-0.4, 0.5, -0.3],
                          [-2.0, -2.2, -2.5]]},
     "normal_stiffness": 50.0, "normal_damping": 5.0,
     "friction": {"axial": 0.4, "lateral": 0.6, "slip_velocity": 0.5}},
])
def test_seabed_jacobian_matches_finite_differences(seabed):
    spec = _spec(seabed, n=8, start={"translation": [{"velocity": 0}] * 3,
                                     "rotation": [{"moment": 0.01}] * 3})
    spec["rod"]["diameter"] = 0.4             # a thick rod: the contact point's lever counts
    spec["initial"] = {"tangent": [1, 0, 0], "normal": [0, 1, 0],
                       "centreline": {"points": [[0, 0, 5.0], [1.0, 0, 5.0]]}}
    run = RodRun(Case.model_validate(spec))
    err = jacobian_fd_error(run, 20261125)
    assert err.max() < 1e-7, (err.max(), int(np.argmax(err)))


# --------------------------------------------------------------------------- at rest
def test_cable_at_rest_on_a_flat_bottom_carries_its_submerged_weight():
    case = Case.model_validate(_spec(t_end=2.0))
    run = _run_to(case, 2.0)
    Fn, Ff, _, pen = run.seabed_loads()
    total = Fn.T @ run.props.quad_weights
    assert abs(total[2] / (W * 1.0) - 1.0) < 1e-3, total
    assert np.allclose(total[:2], 0.0, atol=1e-12) and np.all(Ff == 0.0)
    k = case.seabed.normal_stiffness
    assert np.allclose(pen, W / k, rtol=1e-3), (pen, W / k)
