"""Initial shapes (``initial.centreline``, ``initial.twist_rate``; solver/initial.py) and
their builders in hockle.api: validation, the resampled curvatures and pose against the
closed forms of the arc and the helix, and a curved start that is an equilibrium."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hockle.api import (catenary, catenary_parameter, circular_arc, clamped, end, free,
                        helix, make_case)
from rodcases import hairpin
from solver.case import Case, CaseError
from solver.initial import initial_pose, start_offset
from solver.simulation import integrate

ROOT = Path(__file__).resolve().parents[2]
E, D = 1.25e7, 0.02
EI = E * np.pi * D**4 / 64


def _case(initial, n=20, **kw):
    return make_case("shape", start=clamped(), end=free(), n_segments=n, dt=0.01,
                     t_end=0.05, initial=initial, **kw)


def _spec(initial):
    return {"schema_version": 1, "name": "v",
            "rod": {"length": 1.0, "youngs_modulus": E, "shear_modulus": 5e6,
                    "density": 1500.0, "diameter": D},
            "initial": initial,
            "boundary": {"start": clamped(), "end": free()},
            "numerics": {"n_segments": 10, "dt": 0.1, "t_end": 1.0}}


@pytest.mark.parametrize("initial, loc, etype", [
    ({"centreline": {"points": [[0, 0, 0]]}}, "initial.centreline.points", "too_short"),
    ({"centreline": {"points": [[0, 0, 0], [0, 0, 0.5], [0, 0, 0.5], [0, 0, 1]]}},
     "initial.centreline.points[2]", "zero_segment"),
    ({"centreline": {"points": [[0, 0, 0], [0, 0, 0.9]]}}, "initial.centreline.points",
     "length_mismatch"),
    ({"centreline": {"points": [[0, 0, 0], [0, 0, 1]]}, "tangent": [1, 0, 0]},
     "initial.tangent", "inconsistent"),
    ({"centreline": {"points": [[0, 0, 0], [0, 0, 1]]}, "normal": [0, 0, 2]},
     "initial.normal", "not_orthogonal"),
    ({"centreline": {"points": [[0, 0, 0], [0, 0, "1"]]}},
     "initial.centreline.points[1][2]", "float_type"),
    ({"twist_rate": "fast"}, "initial.twist_rate", "float_type"),
])
def test_bad_initial_shape_is_refused_naming_the_field(initial, loc, etype):
    with pytest.raises(CaseError) as info:
        Case.from_text(json.dumps(_spec(initial)), fmt="json")
    errors = info.value.errors
    assert any(e["loc"] == loc and e["type"] == etype for e in errors), errors


def test_wrong_length_error_says_both_lengths():
    with pytest.raises(CaseError) as info:
        Case.from_text(json.dumps(_spec({"centreline": circular_arc(1.2, 0.5)})), fmt="json")
    assert "1.2 m long but rod.length is 1.0 m" in str(info.value)


def test_default_and_canonical_json_unchanged_and_stable():
    plain = Case.model_validate(_spec({}))
    text = plain.canonical_json()
    assert "centreline" not in text and "twist_rate" not in text
    arc = Case.model_validate(_spec({"centreline": circular_arc(1.0, 0.5),
                                     "twist_rate": 0.3}))
    again = Case.model_validate_json(arc.canonical_json())
    assert again.spec_hash() == arc.spec_hash()
    assert np.allclose(arc.initial.tangent, [0, 0, 1], atol=1e-7)
    assert np.allclose(arc.initial.normal, [1, 0, 0], atol=1e-7)


def test_arc_curvature_and_pose_second_order():
    """A circular arc, R = 0.5 m: κ = (0, 1/R, 0) within 2e-5 relative (the spline of
    401 points), and the start pose (the space route of κ) on the circle within
    O(Δs²) (errors ×1/4 per halving)."""
    R = 0.5
    errs = []
    for n in (20, 40):
        case = _case({"centreline": circular_arc(1.0, R)}, n)
        s = np.linspace(0.0, 1.0, n + 1)
        q, r, kappa = initial_pose(case, s)
        assert np.abs(kappa - [0.0, 1.0 / R, 0.0]).max() < 2e-5 / R
        exact = np.stack([R * (1 - np.cos(s / R)), 0 * s, R * np.sin(s / R)], axis=1)
        errs.append(np.abs(r - exact).max())
        assert np.allclose(np.linalg.norm(q, axis=1), 1.0)
    assert 3.8 < errs[0] / errs[1] < 4.2, errs


def test_a_curvature_jump_inside_a_cell_keeps_the_pose_second_order():
    """A hairpin (two 0.42-m legs and a 5-cm half circle): its curvature jumps from 0 to
    20 1/m inside cells. The node curvatures are dual-cell means, so the pose after the
    bend is not turned by the jump: the far end within 2 mm at 100 segments (1.1 mm; 61
    mm with the curvature at the nodes) and errors ×1/4 or better per halving."""
    pts = hairpin(0.05)
    errs = []
    for n in (100, 200, 400):
        case = _case({"centreline": {"points": pts.tolist()}}, n)
        s = np.linspace(0.0, 1.0, n + 1)
        q, r, kappa = initial_pose(case, s)
        errs.append(np.linalg.norm(r[-1] - pts[-1]))
    assert errs[0] < 2e-3, errs
    assert errs[1] < errs[0] / 3.5 and errs[2] < errs[1] / 3.0, errs


def test_helix_with_its_torsion_as_twist_has_constant_curvature():
    R, p = 0.2, 0.3
    h = p / (2 * np.pi)
    tau = h / (R**2 + h**2)
    case = _case({"centreline": helix(1.0, R, p), "twist_rate": tau}, 40)
    s = np.linspace(0.0, 1.0, 41)
    q, r, kappa = initial_pose(case, s)
    k_ref = R / (R**2 + h**2)
    # constant along the rod but at the ends, where the spline's not-a-knot ends are
    # 1.5e-5 off (measured)
    assert np.ptp(kappa[1:-1], axis=0).max() < 1e-6 * k_ref
    # the node values are rotations across each node's dual cell of the rotation-
    # minimising frame, whose bending axis turns with the torsion: (½τΔs)²/6 = 3.3e-5
    # shorter (solver/initial.py, _dual_cell_curvatures)
    shrink = (0.5 * tau * 0.025) ** 2 / 6
    assert np.abs(np.hypot(kappa[:, 0], kappa[:, 1]) / k_ref - 1).max() < shrink + 2e-5
    assert np.allclose(kappa[:, 2], tau)
    th = s / np.hypot(R, h)
    exact = np.stack([R * (np.cos(th) - 1), R * np.sin(th), h * th], axis=1)
    assert np.abs(r - exact).max() < 1e-3


def test_catenary_builder_has_the_closed_form_length_and_sag():
    L, X = 1.0, 0.8
    a = catenary_parameter(L, X)
    assert abs(2 * a * np.sinh(X / (2 * a)) - L) < 1e-12
    pts = np.array(catenary(L, X)["points"])
    assert abs(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum() - L) < 1e-5
    assert abs(-pts[:, 2].min() - a * (np.cosh(X / (2 * a)) - 1)) < 1e-6
    with pytest.raises(ValueError):
        catenary(1.0, 1.2)


def test_straight_twisted_start():
    case = _case({"twist_rate": 2.0}, 10)
    q, r, kappa = initial_pose(case, np.linspace(0, 1, 11))
    assert np.allclose(kappa, [0, 0, 2.0]) and np.allclose(r[:, :2], 0)
    assert np.allclose(r[:, 2], np.linspace(0, 1, 11))


def test_arc_under_its_end_moment_is_an_equilibrium_and_without_it_moves():
    """A cantilever started on a circular arc (R = 0.5 m) with the end moment EI/R that
    holds it there stays put (max |v| measured 4.9e-6 m/s over 1 s, from the resampled
    κ's 2e-5 error); without the moment the same start springs back (max |v| ~5 m/s)."""
    R = 0.5
    speeds = []
    for M in (EI / R, 0.0):
        case = make_case("arc", start=clamped(),
                         end=end([{"force": 0}] * 3, [{"moment": 0}, {"moment": M},
                                                      {"moment": 0}]),
                         n_segments=40, dt=0.01, t_end=0.3,
                         initial={"centreline": circular_arc(1.0, R)},
                         output={"fields": ["v"]})
        speeds.append(np.abs(integrate(case).v.values).max())
    assert speeds[0] < 1e-4 and speeds[1] > 1.0, speeds


def test_a_twisted_start_has_its_twist_as_linking_number():
    """Lk counts from the untwisted straight rod: a start with 2 rad/m of twist over 1 m
    has Lk = Tw = 2/(2π) turns and Wr = 0 at t = 0 (it started at 0, and with self-contact
    the closure-passage rule then shifted the writhe), and a helix start Lk = Tw + Wr."""
    ds = integrate(_case({"twist_rate": 2.0}, 10, output={"fields": ["topology"]}))
    assert float(ds.linking_number[0]) == pytest.approx(2.0 / (2 * np.pi), rel=1e-9)
    assert float(ds.topology_error.max()) < 1e-6
    R, p = 0.2, 0.3
    tau = (p / (2 * np.pi)) / (R**2 + (p / (2 * np.pi))**2)
    ds = integrate(_case({"centreline": helix(1.0, R, p), "twist_rate": tau}, 40,
                        output={"fields": ["topology"]}))
    assert float(ds.topology_error[0]) < 1e-9
    assert abs(float(ds.writhe[0])) > 0.1


def _seabed_hockle(n, twist=None):
    doc = Case.from_file(ROOT / "cases" / "seabed-hockle.yaml").model_dump(mode="json")
    doc["numerics"]["n_segments"] = n
    doc["numerics"].pop("ds", None)
    if twist is not None:
        doc["initial"]["twist_rate"] = twist
    return Case.model_validate(doc)


def test_a_twisted_lays_start_offset_falls_as_ds2_and_is_advised_past_a_tenth_of_d():
    """cases/seabed-hockle.yaml's half-sine lay with τ0 = 9.42 rad/m (D = 2 cm) starts
    22.4 / 5.79 / 1.46 mm off at its s = L end on 40 / 80 / 160 segments (the figures of
    research/hockle_resolution.py, where the 40- and 80-segment runs fail), ratio 4 per
    halving; the advice names the field and a grid at 40 and 80 and is silent at 160;
    without the twist the same lay starts within 0.1 mm."""
    offs = {n: start_offset(_seabed_hockle(n)) for n in (40, 80, 160)}
    assert [round(offs[n].distance * 1e3, 2) for n in (40, 80, 160)] == [22.37, 5.79, 1.46]
    assert all(offs[n].s == 4.0 for n in offs)
    assert offs[80].distance / offs[160].distance == pytest.approx(4.0, rel=0.02)
    assert offs[160].share == pytest.approx(0.073, abs=1e-3)
    assert offs[160].advice() is None
    for n in (40, 80):
        advice = offs[n].advice()
        assert advice.startswith("initial.centreline: on ")
        assert "numerics.n_segments of about 140" in advice and "Δs·τ0" in advice
    flat = start_offset(_seabed_hockle(40, twist=0.0))
    assert flat.distance < 1e-4 and flat.twist_step == 0.0 and flat.advice() is None


def test_start_offset_is_none_for_a_straight_start_and_in_the_result_of_a_curved_one():
    """A straight start is exact (None, twisted or not); a run from a curved one carries
    the offset (``hockle_start_offset``, its s) and, past a tenth of the diameter, the
    advice (``hockle_advice``), which a run within it does not carry."""
    assert start_offset(_case({"twist_rate": 2.0}, 10)) is None
    assert start_offset(_case({}, 10)) is None
    ds = integrate(_case({"centreline": circular_arc(1.0, 0.5)}, 40))
    assert 0.0 < ds.attrs["hockle_start_offset"] < 1e-3
    assert ds.attrs["hockle_start_offset_s"] == 1.0 and "hockle_advice" not in ds.attrs
    ds = integrate(_case({"centreline": circular_arc(1.0, 0.5), "twist_rate": 20.0}, 40))
    assert ds.attrs["hockle_start_offset"] == pytest.approx(0.037, rel=0.01)
    assert "numerics.n_segments of about 180" in ds.attrs["hockle_advice"]
