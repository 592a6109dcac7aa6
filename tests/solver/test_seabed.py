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
from solver.simulation import integrate

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


@pytest.mark.parametrize("friction", [False, True])
def test_space_route_operator_is_the_jacobian_with_the_seabed(friction):
    """With self-contact configured the pose is the space route (integrated along s from
    κ), so a touching cell's seabed load depends on κ upstream of it: the operator GMRES
    solves with (the band plus the exact product, :func:`solver.scheme.exact_loads_product`)
    against central differences of the step's residual along random directions, at a
    random state (twisted, some cells under a flat bottom, no strands near)."""
    from solver.boundary import BoundaryRows
    from solver.scheme import alpha_parameters

    seabed = {"elevation": 0.0, "normal_stiffness": 5e4, "normal_damping": 5e2}
    if friction:
        seabed["friction"] = {"axial": 0.3, "lateral": 0.7, "static_to_kinetic": 1.5,
                              "slip_velocity": 0.8}
    spec = _spec(seabed, n=12, start={"translation": [{"velocity": 0}] * 3,
                                      "rotation": [{"moment": 0.01}] * 3})
    spec["rod"]["diameter"] = 0.4
    spec["initial"] = {"tangent": [1, 0, 0], "normal": [0, 1, 0],
                       "centreline": {"points": [[0, 0, 5.0], [1.0, 0, 5.0]]}}
    spec["contact"] = {"aperture": 90.0, "tolerance": 0.5, "k1": 1e-7, "k2": 3.0,
                       "k3": 1e-6, "k4": 1.0}
    run = RodRun(Case.model_validate(spec))
    sysm, newton = run.system, run.newton
    rng = np.random.default_rng(7)
    n1 = sysm.n_nodes
    scale = np.repeat([0.3, 1.0, 0.5, 2.0], 3)
    Y_old = rng.standard_normal((n1, 12)) * scale
    Ydot_old = rng.standard_normal((n1, 12)) * scale * 10
    Y = rng.standard_normal((n1, 12)) * scale
    q_old = rng.standard_normal((n1, 4))
    q_old /= np.linalg.norm(q_old, axis=1)[:, None]
    r_old, v_old = 0.3 * rng.standard_normal((n1, 3)), rng.standard_normal((n1, 3))
    bc = BoundaryRows(run.case, run.props, 0.43, sysm.n)
    F_old, _ = sysm.node_terms(Y_old, False, None, None)
    sysm.begin_step(0.01, alpha_parameters(0.5), 0.43, Y_old, Ydot_old, F_old, bc,
                    q_old=q_old, r_old=r_old, v_old_global=v_old)
    newton.linearize(Y)
    touching = int(sysm.buf.seabed_count[0])
    assert newton.coupled and 2 <= touching < sysm.n_cells, touching
    for _ in range(3):
        x = rng.standard_normal(sysm.n)
        dY = (x * newton.col_scale).reshape(Y.shape)
        eps = 1e-6
        central = newton.row_scale * (sysm.residual(Y + eps * dY)[0]
                                      - sysm.residual(Y - eps * dY)[0]) / (2.0 * eps)
        product = newton.operator(x)
        assert np.max(np.abs(product - central)) <= 1e-6 * np.max(np.abs(central))
        # without the product's seabed part (the band's two-node derivative) it is not
        count = newton._state["op"].exact.seabed_count
        count[0] = 0
        band = newton.operator(x)
        count[0] = touching
        assert np.max(np.abs(band - central)) > 1e-3 * np.max(np.abs(central))


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


# --------------------------------------------------------------------------- friction
V_DRAG = 0.02                           # m/s, 20 slip velocities: kinetic friction
_TT = np.linspace(0.0, 0.5, 51)
RAMP = {"t": _TT.tolist(), "value": (V_DRAG * (3 * (_TT / 0.5) ** 2
                                              - 2 * (_TT / 0.5) ** 3)).tolist()}
FRICTION = {"axial": 0.3, "lateral": 0.6, "slip_velocity": 1e-3}
NO_DRAG = {"density": RHO_F, "drag_coefficient_normal": 0.0, "drag_coefficient_tangential": 0.0}


def _drag_case(direction):
    """A stiff cable on the bottom dragged at V_DRAG along its axis (the s = L end) or
    across it (both ends), the ends free to tilt (so that the bottom carries the whole
    weight) and, across, held about the axis (so that it slides, not rolls); no Morison
    drag; ρ∞ = 0 damps the bending vibration the start excites."""
    seabed = {"elevation": -D / 2, "friction": FRICTION}
    if direction == "axial":
        end = {"translation": [{"force": 0}, {"force": 0}, {"velocity": RAMP}],
               "rotation": FREE_ROT}
        spec = _spec(seabed, end=end, fluid=NO_DRAG)
    else:
        # a2 = a3 × a1 = x × z = −y: a velocity −V along a2 moves the ends along +y
        ends = {"translation": [{"force": 0}, {"velocity": {"t": RAMP["t"], "value": [
            -v for v in RAMP["value"]]}}, {"force": 0}],
            "rotation": [{"moment": 0}, {"moment": 0}, {"angular_velocity": 0}]}
        spec = _spec(seabed, start=ends, end=ends, fluid=NO_DRAG)
    spec["rod"].update(youngs_modulus=1.25e12, shear_modulus=5e11)
    spec["numerics"]["rho_inf"] = 0.0
    spec["numerics"]["t_end"] = 1.5
    return Case.model_validate(spec)


@pytest.mark.parametrize("direction, axis, mu", [("axial", 0, 0.3), ("lateral", 1, 0.6)])
def test_cable_dragged_along_the_bottom_pulls_with_mu_w_l(direction, axis, mu):
    from solver.loads import end_reactions

    run = _run_to(_drag_case(direction), 1.5)
    assert np.allclose(run.state.v_global_time[:, axis], V_DRAG, rtol=1e-3)
    re = end_reactions(run.state.Y, run.state.q, run.props.stiffness)
    pull = re["reaction_force_start"][axis] + re["reaction_force_end"][axis]
    assert abs(pull / (mu * W * 1.0) - 1.0) < 0.01, (pull, mu * W)
    # the seabed's work account: friction over the distance slid, V (1.5 − 0.25) s (the
    # smoothstep ramp covers half its duration's distance); the few millimetres slid below
    # 2 slip velocities at the start take less than their share
    slid = V_DRAG * (1.5 - 0.25)
    assert -run.state.seabed_work / (mu * W * 1.0 * slid) == pytest.approx(1.0, abs=0.01)


def test_a_spinning_cable_rolls_without_slip_at_spin_times_radius():
    spin = {"t": [0.0, 0.25], "value": [0.0, 2.0]}          # rad/s about a3 = +x
    ends = {"translation": [{"force": 0}] * 3,
            "rotation": [{"moment": 0}, {"moment": 0}, {"angular_velocity": spin}]}
    spec = _spec({"elevation": -D / 2, "friction": FRICTION}, start=ends, end=ends,
                 fluid=NO_DRAG)
    spec["rod"].update(youngs_modulus=1.25e12, shear_modulus=5e11)
    spec["numerics"]["rho_inf"] = 0.0
    run = _run_to(Case.model_validate(spec), 1.0)
    # the contact point (−ρ z) at rest: ṙ = −Ω × (−ρ z) = ρ Ω x × z = −ρ Ω y
    spin_now = run.state.Y[:, 5]
    assert np.allclose(spin_now, 2.0, rtol=1e-4), spin_now
    assert np.allclose(run.state.v_global_time[:, 1], -spin_now * D / 2, rtol=1e-3), run.state.v_global_time
    assert np.allclose(run.state.v_global_time[:, [0, 2]], 0.0, atol=1e-6)


# --------------------------------------------------------------------------- bathymetry
def test_a_sloped_grid_gives_the_plane_it_represents():
    """A cable resting across a bottom inclined in y (slope 0.1), its ends held across it
    (a2 = −y) and about its axis (so that it does not roll): the grid (bilinear, exact for
    a plane) reacts along the plane's normal and gives the penetrations of the analytic
    plane (the same case turned onto a flat bottom)."""
    slope = 0.1
    ys = (-1.0, 0.5, 1.0)
    grid = {"x": [-1.0, 0.3, 2.0], "y": list(ys),
            "z": [[-D / 2 * math.sqrt(1 + slope**2) + slope * y for y in ys]] * 3}
    ends = {"translation": [{"force": 0}, {"velocity": 0}, {"force": 0}],
            "rotation": [{"moment": 0}, {"moment": 0}, {"angular_velocity": 0}]}
    def stiff(spec):             # no sag down the frictionless slope, ρ∞ = 0: it settles
        spec["rod"].update(youngs_modulus=1.25e12, shear_modulus=5e11)
        spec["numerics"]["rho_inf"] = 0.0
        return Case.model_validate(spec)

    run = _run_to(stiff(_spec({"bathymetry": grid}, start=ends, end=ends)), 1.0)
    c = 1.0 / math.sqrt(1 + slope**2)
    n = np.array([0.0, -slope * c, c])
    Fn, _, _, pen = run.seabed_loads()
    total_n = Fn.T @ run.props.quad_weights
    # the ends hold horizontally: the bottom carries the whole weight, N c = W
    assert np.allclose(total_n, W / c * n, rtol=1e-3, atol=1e-12), (total_n, W / c * n)
    assert np.allclose(pen, W / c / 3e6, rtol=1e-3)
    # the same case turned by the slope's angle θ about x onto a flat bottom: gravity
    # and the initial normal turned by R_x(−θ) (which takes n to z)
    sn = slope * c
    spec = _spec({"elevation": -D / 2}, start=ends, end=ends, gravity=[0.0, -G * sn, -G * c])
    spec["initial"]["normal"] = [0.0, sn, c]
    flat = _run_to(stiff(spec), 1.0)
    _, _, _, pen2 = flat.seabed_loads()
    assert np.allclose(pen, pen2, rtol=1e-4), (pen, pen2)


# --------------------------------------------------------------------------- outputs
def test_outputs_with_a_seabed_and_none_without():
    from solver.seabed import contact_length, touchdown

    spec = _spec(t_end=0.3)
    ds = integrate(Case.model_validate(spec))
    assert ds["seabed_force"].dims == ("time", "s", "xyz")
    assert ds["seabed_force"].attrs["units"] == "N m-1"
    last = ds.isel(time=-1)
    total = np.trapezoid(last["seabed_force"].values[:, 2], ds["s"].values)
    assert abs(total / W - 1.0) < 0.02, total / W
    assert np.all(last["seabed_friction"].values == 0.0)
    assert float(last["seabed_contact_length"]) == pytest.approx(1.0)
    assert math.isnan(float(last["seabed_touchdown"]))          # the whole rod touches
    assert "seabed_work" in ds
    spec.pop("seabed")
    assert not any(name.startswith("seabed") for name in integrate(Case.model_validate(spec)))
    s = np.linspace(0.0, 1.0, 5)
    pen = np.array([1.0, 1.0, -1.0, -1.0, -1.0])
    assert contact_length(pen, s) == pytest.approx(0.25 + 0.125)
    assert touchdown(pen, s) == pytest.approx(0.375)
    assert touchdown(pen[::-1], s) == pytest.approx(0.625)
    assert math.isnan(touchdown(-pen ** 2, s))


def test_contact_length_bridges_nodes_hovering_between_touching_ones():
    """A cable lying on the bottom whose every other node hovers up to 0.1 mm above it
    (the box rule's odd-even mode in the node heights, measured on
    cases/catenary-touchdown.yaml: up to 0.15 mm) reports its lying length, not the
    slivers around the touching nodes; a cable lifted clear, or more than the gap, reports
    0 and a contact's ends (the touchdown) stay the zeros of p."""
    from solver.seabed import CONTACT_GAP, contact_length, hover_gap, touchdown

    s = np.linspace(0.0, 4.0, 81)
    D = 0.02
    gap = hover_gap(np.full(s.size, D))
    assert np.allclose(gap, CONTACT_GAP * D)
    rng = np.random.default_rng(3)
    lying = s <= 2.0                                        # 2 m on the bottom, then the span
    pen = np.where(lying, 0.0, -0.5 * (s - 2.0) ** 2)
    pen[lying] = np.where(np.arange(lying.sum()) % 2 == 0, 1.03e-6,
                          -rng.uniform(3.5e-5, 1.05e-4, lying.sum()))
    pen[40] = 1.03e-6                                       # the last touching node, s = 2
    assert contact_length(pen, s) < 0.1                     # without the gap: slivers
    assert contact_length(pen, s, gap) == pytest.approx(2.0, rel=0.02)
    assert touchdown(pen, s) == pytest.approx(2.0, abs=0.05)
    assert contact_length(pen - 0.01, s, gap) == 0.0        # lifted clear
    assert contact_length(np.full(s.size, -0.01), s, gap) == 0.0
    hover = np.where(np.arange(s.size) % 2 == 0, 1e-6, -2.0 * CONTACT_GAP * D)
    assert contact_length(hover, s, gap) < 0.1              # hovering more than the gap
    lifted = pen.copy()
    lifted[10:20] = -0.01                   # nodes 10-19 lifted: contact to s8 and from s20
    assert contact_length(lifted, s, gap) == pytest.approx(1.4, abs=0.01)


# --------------------------------------------------------------------------- catenary
def test_catenary_with_touchdown_matches_its_suspended_length_and_span():
    """A cable pinned at height h = 1 m, its other end on the bottom pulled horizontally
    with H = 2 N (a dead force, free to turn; no friction, so the tension along the bottom
    is H), bending length λ = √(EI/H) = 2.2 cm: the suspended span is the catenary
    a(cosh(x/a) − 1), a = H/w, of length √(h² + 2ah), reaching the bottom a·acosh(1 + h/a)
    from the pin, within 1.5 %: the catenary has no bending stiffness, and the bending
    boundary layer at touchdown makes the suspended length +0.85 % (0.7 λ) and the span
    +1.06 % longer at 160 and at 320 segments (80 segments, Δs = 5 cm, coarser than λ:
    +1.5 %). It starts on the catenary and settles (ρ∞ = 0, Morison drag).
    (Before the initial κ were dual-cell means, solver/initial.py, the curvature jump at
    touchdown had put the pinned end 2 cm off, 1.7 cm low, and 80 segments read +0.2 %.)"""
    from solver.seabed import touchdown

    L, h, H = 4.0, 1.0, 2.0
    a = H / W
    span = a * math.acosh(1 + h / a)
    suspended = math.sqrt(h * h + 2 * a * h)
    x_td = L - suspended
    xs = np.concatenate([np.linspace(0.0, x_td, 60, endpoint=False),
                         x_td + np.linspace(0.0, span, 200)])
    pts = np.column_stack([xs, np.zeros_like(xs),
                           np.where(xs < x_td, 0.0, a * (np.cosh((xs - x_td) / a) - 1.0))])
    top = pts[-1]
    start = {"frame": "global", "translation": [{"force": H}, {"force": 0}, {"force": 0}],
             "rotation": FREE_ROT}
    end = {"frame": "global", "translation": [{"position": float(top[0])}, {"position": 0.0},
                                              {"position": float(top[2])}],
           "rotation": FREE_ROT}
    spec = _spec(length=L, n=160, dt=0.05, t_end=30.0, start=start, end=end)
    spec["rod"].update(youngs_modulus=1.25e5, shear_modulus=5e4)
    spec["initial"] = {"centreline": {"points": pts.tolist()}, "normal": [0, 1, 0]}
    spec["numerics"]["rho_inf"] = 0.0
    run = _run_to(Case.model_validate(spec), 30.0)
    _, _, _, pen = run.seabed_loads()
    s_td = touchdown(pen, run.props.s)
    x_at = np.interp(s_td, run.props.s, run.state.r_time[:, 0])
    assert np.linalg.norm(run.state.r_time[-1] - top) < 1e-3       # pinned where the case says
    assert abs((L - s_td) / suspended - 1.0) < 0.015, (L - s_td, suspended)
    assert abs((top[0] - x_at) / span - 1.0) < 0.015, (top[0] - x_at, span)


@pytest.mark.parametrize("seed", range(6))
def test_node_law_derivative_matches_finite_differences(seed):
    """The per-node law's forward-propagated derivative (solver.seabed._node) against
    central differences, through random linear maps from six unknowns to the position,
    velocity, angular velocity and tangent, on a twisted grid, with every friction regime
    (speeds below, across and above the slip velocity) and the damper's cap."""
    from solver.case import Seabed
    from solver.seabed import SeabedContact, _node

    rng = np.random.default_rng(seed)
    spec = Seabed.model_validate({
        "bathymetry": {"x": [-2.0, 0.1, 2.0], "y": [-2.0, -0.2, 2.0],
                       "z": [[0.1, -0.3, 0.2], [-0.2, 0.4, 0.1], [0.3, -0.1, -0.2]]},
        "normal_stiffness": 80.0, "normal_damping": 10.0 * rng.uniform(0.1, 3.0),
        "friction": {"axial": 0.4, "lateral": 0.7, "static_to_kinetic": 1.6,
                     "slip_velocity": 0.5}})
    rho = 0.3
    data = SeabedContact(spec, np.full(2, 2 * rho)).data
    Dr, Du, DOm, Dt = (rng.standard_normal((3, 6)) for _ in range(4))
    r0 = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-0.1, 0.3)])
    u0, Om0 = 0.6 * rng.standard_normal(3), rng.standard_normal(3)
    t0 = np.array([1.0, 0.3, 0.2]) + 0.2 * rng.standard_normal(3)
    wk = np.zeros((9, 3, 6))

    def law(X, want=False):
        Fn, Ff, M, DF, DM = np.zeros(3), np.zeros(3), np.zeros(3), np.zeros((3, 6)), np.zeros((3, 6))
        p = _node(r0 + Dr @ X, u0 + Du @ X, Om0 + DOm @ X, t0 + Dt @ X, rho, data, want,
                  Dr, Du, DOm, Dt, Fn, Ff, M, DF, DM, wk)
        return p, np.concatenate([Fn + Ff, M]), np.vstack([DF, DM])

    X = 0.05 * rng.standard_normal(6)
    p, _, J = law(X, True)
    assert p > 0
    h = 1e-7
    J_fd = np.column_stack([(law(X + h * e)[1] - law(X - h * e)[1]) / (2 * h)
                            for e in np.eye(6)])
    assert np.allclose(J, J_fd, rtol=1e-5, atol=1e-6 * np.abs(J_fd).max()), (J - J_fd)


def test_error_controlled_run_with_dense_outputs_rolls_the_cable():
    """numerics.tolerance with output.interval: the dense output of the seabed's fields
    (on the interpolated time route) and the refusals of doubled steps counted by
    reason."""
    spin = {"t": [0.0, 0.25], "value": [0.0, 2.0]}
    ends = {"translation": [{"force": 0}] * 3,
            "rotation": [{"moment": 0}, {"moment": 0}, {"angular_velocity": spin}]}
    spec = _spec({"elevation": -D / 2, "friction": FRICTION}, start=ends, end=ends,
                 fluid=NO_DRAG, t_end=0.6)
    spec["numerics"]["tolerance"] = {"relative": 1e-3}
    spec["output"] = {"interval": 0.1, "fields": ["position"]}
    ds = integrate(Case.model_validate(spec))
    assert ds.attrs["hockle_status"] == "completed"
    assert "None" not in ds.attrs["hockle_refused_attempts"]
    # rolled by ρ × the spin's integral (0.25 s ramp: 0.25 rad, then 2 rad/s)
    rolled = D / 2 * (0.25 + 2.0 * (0.6 - 0.25))
    assert np.allclose(ds["position"].values[-1, :, 1], -rolled, rtol=0.01)
    force = np.trapezoid(ds["seabed_force"].values[:, :, 2], ds["s"].values, axis=1)
    assert np.allclose(force[1:], W, rtol=0.01), force


def _falling_case(dt, t_end, tolerance):
    """The cable started 1 mm above a flat bottom: it falls under its submerged weight
    and lands (the seabed's spring, damping and the drag take its kinetic energy)."""
    spec = _spec({"elevation": -D / 2 - 1e-3}, dt=dt, t_end=t_end)
    spec["numerics"]["energy_tolerance"] = tolerance
    return Case.model_validate(spec)


def test_seabed_account_is_the_springs_work_and_the_runs_seabed_work_without_damping():
    """The energy balance's seabed account (solver.balance.SeabedWork, minus the change
    of the spring's ½kp²) summed over the steps of an undamped, frictionless bounce off
    the bottom follows the run's own ``seabed_work`` (the trapezoid of the seabed's
    power) within 2 % of the largest stored energy at every step, at 30 steps a period
    of the spring (measured 0.76 %; 0.027 % at Δt = 2e-5 s: second order); the first
    step, the consistent restart, is not measured."""
    dt = 1e-4
    spec = _spec({"elevation": -D / 2 - 1e-3, "normal_damping": 0.0}, dt=dt, t_end=0.04)
    spec["numerics"]["energy_tolerance"] = 1e6              # measures, refuses nothing
    run = RodRun(Case.model_validate(spec))
    run.advance(dt)
    w0, work, account, trapezoid = run.state.seabed_work, 0.0, [], []
    while run.state.t < 0.04 - 1e-12:
        run.advance(run.state.t + dt)
        work += run.last_balance.work["seabed"]
        account.append(work)
        trapezoid.append(run.state.seabed_work - w0)
    account, trapezoid = np.array(account), np.array(trapezoid)
    assert np.abs(account).max() > 1e-3                     # it landed: W·1 mm = 4.9e-3 J
    assert np.abs(account - trapezoid).max() < 0.02 * np.abs(account).max()


def test_energy_check_with_a_seabed_completes_a_landing():
    """With ``energy_tolerance`` the landing (falling 1 mm, the seabed's spring and
    damper stopping it) completes with no step refused for energy, and the check
    changes nothing: the same seabed work as without it."""
    dt, t_end = 1e-4, 0.05
    ds = integrate(_falling_case(dt, t_end, 0.05))
    assert ds.attrs["hockle_status"] == "completed"
    assert "energy" not in ds.attrs["hockle_refused_attempts"]
    err = ds.step_energy_error.values
    assert np.nanmax(err) <= 0.05
    spec = json.loads(_falling_case(dt, t_end, 0.05).canonical_json())
    spec["numerics"].pop("energy_tolerance")
    plain = integrate(Case.model_validate(spec))
    assert float(ds.seabed_work[-1]) == float(plain.seabed_work[-1])
