"""Ends in the global frame (``boundary.<end>.frame: global``; solver/boundary.py
``global_translation``, solver/loads.py ``_EndForce``): the refused combinations, and
verification against the catenary, Morison drag and the elastica."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from hockle.api import catenary_parameter
from solver.case import Case, CaseError
from solver.simulation import integrate

FIXED = [{"angular_velocity": 0}] * 3
FREE_ROT = [{"moment": 0}] * 3
FREE = {"translation": [{"force": 0}] * 3, "rotation": FREE_ROT}
CLAMPED = {"translation": [{"velocity": 0}] * 3, "rotation": FIXED}


def _spec(start, end, **extra):
    spec = {"schema_version": 1, "name": "g",
            "rod": {"length": 1.0, "youngs_modulus": 1.25e7, "shear_modulus": 5e6,
                    "density": 1500.0, "diameter": 0.02},
            "boundary": {"start": start, "end": end},
            "numerics": {"n_segments": 10, "dt": 0.1, "t_end": 1.0}}
    spec.update(extra)
    return spec


def _refused(spec):
    with pytest.raises(CaseError) as info:
        Case.from_text(json.dumps(spec), fmt="json")
    return info.value.errors


@pytest.mark.parametrize("start, loc, etype", [
    ({"translation": [{"position": 0}] * 3, "rotation": FIXED},
     "boundary.start.translation[0][0].position", "wrong_frame"),
    ({"frame": "global", "translation": [{"velocity": 0}, {"force": 0}, {"velocity": 0}],
      "rotation": FIXED}, "boundary.start.translation", "mixed_frame_conditions"),
    ({"frame": "global", "translation": [{"velocity": 0}] * 3,
      "rotation": [{"angular_velocity": 0}, {"moment": 0}, {"angular_velocity": 0}]},
     "boundary.start.rotation", "unsupported"),
    ({"frame": "global", "translation": [{"velocity": 0}] * 3,
      "rotation": [{"angular_velocity": 1.0}] * 3}, "boundary.start.rotation", "unsupported"),
    ({"frame": "global", "translation": [{"velocity": 0.1}, {"velocity": 0}, {"velocity": 0}],
      "rotation": [{"moment": 1.0}] + FREE_ROT[1:]}, "boundary.start.rotation", "unsupported"),
    ({"frame": "global", "translation": [{"velocity": 0.1}, {"force": 0}, {"velocity": 0}],
      "rotation": FREE_ROT}, "boundary.start.translation", "mixed_frame_conditions"),
    ({"frame": "global", "translation": [[{"velocity": 0.1, "until": 1}, {"velocity": 0}],
                                         {"velocity": 0}, {"velocity": 0}],
      "rotation": FREE_ROT}, "boundary.start.translation", "unsupported"),
    ({"frame": "global", "translation": [[{"velocity": 0, "until": 1}, {"force": 0}],
                                         {"velocity": 0}, {"velocity": 0}],
      "rotation": FIXED}, "boundary.start.translation", "unsupported"),
    ({"frame": "global", "translation": [[{"velocity": 0, "until": 1}, {"force": 0}]] * 2
      + [[{"velocity": 0, "until": 1}, {"velocity": 0}]], "rotation": FIXED},
     "boundary.start.translation", "mixed_frame_conditions"),
    ({"frame": "global", "translation": [{"velocity": 0}] * 3,
      "rotation": [[{"angular_velocity": 0, "until": 1}, {"moment": 0}]] + FIXED[1:]},
     "boundary.start.rotation[0]", "unsupported"),
    ({"frame": "sideways", "translation": [{"velocity": 0}] * 3, "rotation": FIXED},
     "boundary.start.frame", "literal_error"),
    ({"frame": "global", "translation": [{"position": 0.5}, {"position": 0}, {"position": 0}],
      "rotation": FREE_ROT}, "boundary.start.translation", "inconsistent"),
])
def test_refused_global_end_names_the_field(start, loc, etype):
    errors = _refused(_spec(start, FREE))
    assert any(e["loc"] == loc and e["type"] == etype for e in errors), errors


def test_positions_that_would_stretch_the_rod_are_refused():
    start = {"frame": "global", "translation": [{"position": 0}] * 3, "rotation": FREE_ROT}
    pull = {"t": [0.0, 1.0], "value": [0.9, 1.2]}
    end = {"frame": "global", "translation": [{"position": pull}, {"position": 0},
                                              {"position": 0}], "rotation": FIXED}
    arc = {"centreline": {"points": _arc_points(1.0, 0.9)}}
    errors = _refused(_spec(start, end, initial=arc))
    assert [e["type"] for e in errors] == ["stretches_rod"], errors
    assert errors[0]["loc"] == "boundary.end.translation"
    assert "1.2 m apart at t = 1 s" in errors[0]["msg"]


def test_body_frame_cases_keep_their_canonical_json():
    case = Case.model_validate(_spec(CLAMPED, FREE))
    assert '"frame"' not in case.canonical_json()
    glob = Case.model_validate(_spec({**CLAMPED, "frame": "global"}, FREE))
    again = Case.model_validate_json(glob.canonical_json())
    assert again.spec_hash() == glob.spec_hash() and '"frame":"global"' in glob.canonical_json()


# --------------------------------------------------------------------------- verification
def test_towed_end_tension_is_the_integrated_morison_drag():
    """One end of a rod lying along (1, 0, 1)/√2 towed at U = 0.5 m/s backwards along
    that direction (global velocity table, rotation held fixed in space), the other end
    free, through still water: once the tow speed is reached the rod slides along its
    axis and the tension at the tow point is the tangential drag on the whole rod,
    ½ρ_f πD C_dt U² L (measured ratio 1.0000000016)."""
    U, L, D, rho_f, cdt = 0.5, 1.0, 0.02, 1000.0, 0.05
    d = np.array([1.0, 0.0, 1.0]) / math.sqrt(2)
    V = -U * d
    start = {"frame": "global",
             "translation": [{"velocity": {"t": [0.0, 1.0], "value": [0.0, v]}} for v in V],
             "rotation": FIXED}
    spec = _spec(start, FREE,
                 fluid={"density": rho_f, "added_mass_coefficient": 1.0,
                        "drag_coefficient_normal": 1.2, "drag_coefficient_tangential": cdt},
                 initial={"tangent": d.tolist(), "normal": [d[2], 0.0, -d[0]]},
                 output={"fields": ["f", "position", "reactions"]})
    spec["numerics"] = {"n_segments": 20, "dt": 0.05, "t_end": 3.0, "rho_inf": 0.5}
    ds = integrate(Case.model_validate(spec))
    expected = 0.5 * rho_f * math.pi * D * cdt * U**2 * L
    f0 = ds.f.values[-1, 0]
    assert abs(f0[2] / expected - 1) < 0.01 and np.abs(f0[:2]).max() < 1e-6 * expected
    # the tow line's pull in the global frame, along the tow: the reaction output
    pull = ds.reaction_force_start.values[-1]
    assert np.allclose(pull, -expected * d, rtol=0.01, atol=1e-6 * expected), pull
    assert np.allclose(ds.reaction_force_end.values[-1], 0.0, atol=1e-9)
    # the towed end went where the velocity table takes it: U (t_end − ½ s) along −d
    assert np.allclose(ds.position.values[-1, 0], V * (3.0 - 0.5), atol=1e-9)


def _arc_points(L, X, m=401):
    """A circular arc of length L between (0, 0, 0) and (X, 0, 0), sagging towards −z:
    a start that is not the catenary."""
    R = brentq(lambda R: 2 * R * math.sin(L / (2 * R)) - X, L / (2 * math.pi) * 1.0001,
               100 * L)
    phi0 = L / (2 * R)
    phi = np.linspace(-phi0, phi0, m)
    x = X / 2 + R * np.sin(phi)
    z = -(R * np.cos(phi) - R * math.cos(phi0))
    x[0], x[-1], z[0], z[-1] = 0.0, X, 0.0, 0.0
    return np.stack([x, 0 * x, z], 1).tolist()


def test_hanging_cable_settles_on_the_catenary():
    """A 1-m cable (steel density, D = 1 cm, E = 1e5 Pa: bending length √(EI/H) = 4 mm)
    pinned at two points 0.8 m apart (frame: global, held positions, free to turn),
    started on a circular arc, settles in water under gravity (ρ∞ = 0, Δt = 0.2 s) on
    the catenary a = H/w, X = 2a asinh(L/(2a)): sag a(cosh(X/(2a)) − 1) and end tension
    w a cosh(X/(2a)) within 0.5 % (measured −0.22 % and +0.03 % at 40 segments)."""
    L, X, D, rho, rho_f = 1.0, 0.8, 0.01, 7800.0, 1000.0
    start = {"frame": "global", "translation": [{"position": 0.0}] * 3, "rotation": FREE_ROT}
    end = {"frame": "global", "translation": [{"position": X}, {"position": 0.0},
                                              {"position": 0.0}], "rotation": FREE_ROT}
    spec = _spec(start, end, gravity=[0.0, 0.0, -9.81],
                 fluid={"density": rho_f, "added_mass_coefficient": 1.0,
                        "drag_coefficient_normal": 1.2},
                 initial={"centreline": {"points": _arc_points(L, X)}},
                 output={"fields": ["f", "position", "reactions"]})
    spec["rod"].update({"youngs_modulus": 1e5, "shear_modulus": 1e5 / 2.6, "density": rho,
                        "diameter": D})
    spec["numerics"] = {"n_segments": 40, "dt": 0.2, "t_end": 16.0, "rho_inf": 0.0,
                        "growth_guard": None}
    ds = integrate(Case.model_validate(spec))
    a = catenary_parameter(L, X)
    sag = a * (math.cosh(X / (2 * a)) - 1)
    w = (rho - rho_f) * math.pi * D**2 / 4 * 9.81
    tension = w * a * math.cosh(X / (2 * a))
    z = ds.position.values[:, :, 2]
    assert abs(-z[0].min() / sag - 1) > 0.03            # the start is not the catenary
    assert abs(-z[-1].min() / sag - 1) < 5e-3, -z[-1].min() / sag
    f = ds.f.values[-1]
    for node in (0, -1):
        assert abs(np.linalg.norm(f[node]) / tension - 1) < 5e-3, np.linalg.norm(f[node])
    # the pins carry the weight half each and pull apart with H = w a (global frame)
    a_start, a_end = ds.reaction_force_start.values[-1], ds.reaction_force_end.values[-1]
    assert abs((a_start[2] + a_end[2]) / (w * L) - 1) < 1e-3     # measured 1.6e-4
    assert abs(-a_start[0] / (w * a) - 1) < 5e-3 and abs(a_end[0] / (w * a) - 1) < 5e-3


def test_dead_end_force_on_an_end_free_to_turn_is_the_tip_load():
    """frame: global with a force on an end free to turn is a dead tip load: the
    cantilever settles where the elastica puts it (P L²/EI = 2; the point-load test's
    settling, within 0.05 % at 50 segments)."""
    from test_point_loads import EI, SETTLE_DT, tip_elastica

    dt = SETTLE_DT[2]
    P = {"t": [0.0, 20 * dt], "value": [0.0, 2 * EI]}
    end = {"frame": "global", "translation": [{"force": P}, {"force": 0}, {"force": 0}],
           "rotation": FREE_ROT}
    spec = _spec(CLAMPED, end, output={"fields": ["position"]})
    spec["numerics"] = {"n_segments": 50, "dt": dt, "t_end": 60 * dt, "rho_inf": 0.0,
                        "growth_guard": None, "newton": {"tolerance": 1e-12}}
    tip = integrate(Case.model_validate(spec)).position.values[-1, -1]
    x_ref, z_ref = tip_elastica(2.0)
    assert abs(tip[0] / x_ref - 1) < 5e-4 and abs(tip[2] / z_ref - 1) < 5e-4, tip


def test_position_table_moves_the_end_along_it():
    """A position table (rotation fixed in space) drives the end with the slope of each
    piece; the knots are breakpoints, so the end reaches every knot's position (the
    restart steps after a knot cost about 1e-4 Δt × the jump of the velocity: measured
    5e-7 m)."""
    table = {"t": [0.0, 1.0, 1.5], "value": [0.0, 0.1, 0.05]}
    start = {"frame": "global", "translation": [{"position": table}, {"position": 0.0},
                                                {"position": 0.0}], "rotation": FIXED}
    spec = _spec(start, FREE, output={"fields": ["position"]})
    spec["numerics"] = {"n_segments": 10, "dt": 0.1, "t_end": 2.0, "rho_inf": 0.5}
    ds = integrate(Case.model_validate(spec))
    x0 = ds.position.values[:, 0, 0]
    t = ds.time.values
    want = np.interp(t, table["t"], table["value"])
    assert np.abs(x0 - want).max() < 1e-5, np.abs(x0 - want).max()


def test_a_global_end_switches_in_time_like_a_body_frame_one():
    """A rod clamped at s = 0 (sliding axially) with its tip held at its point, free to
    turn (frame: global), released at t = 0.2 s (force 0): the same run, bit for bit, as
    the body-frame conditions that mean the same (velocity 0, then force 0); gravity
    bends the rod while held and swings it after."""
    sliding = {"translation": [{"velocity": 0}, {"velocity": 0}, {"force": 0}],
               "rotation": FIXED}          # both ends held would leave the tension open

    def run(end):
        spec = _spec(sliding, end, gravity=[9.81, 0.0, 0.0],
                     output={"fields": ["v", "f", "kappa", "position"]})
        spec["numerics"] = {"n_segments": 10, "dt": 0.05, "t_end": 0.5}
        return integrate(Case.model_validate(spec))

    switch = [{"velocity": 0, "until": 0.2}, {"force": 0}]
    body = run({"translation": [switch] * 3, "rotation": FREE_ROT})
    held = [[{"position": 0.0, "until": 0.2}, {"force": 0}],
            [{"position": 0.0, "until": 0.2}, {"force": 0}],
            [{"position": 1.0, "until": 0.2}, {"force": 0}]]
    glob = run({"frame": "global", "translation": held, "rotation": FREE_ROT})
    for name in ("v", "f", "kappa", "position"):
        assert np.array_equal(body[name].values, glob[name].values), name
    tip = glob.position.values[:, -1, 0]
    # held until 0.2 s (the centreline integrated from κ, within 2.5e-4 m of the held
    # point), swinging after
    assert np.abs(tip[:5]).max() < 1e-3 and tip[-1] > 0.5


# --------------------------------------------------------------- towed, free to turn
def _pendulum(V, dt, n=10, t_end=1.0):
    """A 1-m rod hanging from its s = 0 end, pinned there (frame: global, moment 0),
    in vacuum under gravity 0.5 rad off its axis (it swings 0.84 m at the tip), the pin
    moving at the constant global velocity V (m/s) and the whole rod starting with it
    (every node's body velocity Rᵀ V)."""
    from solver.initial import StartState, initial_pose
    from solver.kinematics import quat_to_matrix

    start = {"frame": "global", "translation": [{"velocity": float(x)} for x in V],
             "rotation": FREE_ROT}
    spec = _spec(start, FREE, gravity=[9.81 * math.sin(0.5), 0.0, 9.81 * math.cos(0.5)],
                 output={"fields": ["position", "omega", "kappa"]})
    spec["numerics"] = {"n_segments": n, "dt": dt, "t_end": t_end,
                        "newton": {"tolerance": 1e-10}}
    case = Case.model_validate(spec)
    q, r, _ = initial_pose(case, np.linspace(0.0, 1.0, n + 1))
    v = np.einsum("nji,j->ni", quat_to_matrix(q), np.asarray(V, float))
    zero = np.zeros((n + 1, 3))
    return integrate(case, start=StartState(t=0.0, v=v, omega=zero, f=zero.copy(),
                                           kappa=zero.copy(), q=q, r=r))


def test_an_end_towed_free_to_turn_is_the_pinned_rod_moved_along():
    """Towed at constant V from t = 0 with the rod moving with it, the pendulum is the
    pinned one shifted by V t (Galilean invariance): the pin exactly on its path, the
    end moment 0 (κ = 0 at s = 0) while its frame turns with the swing, and the shapes
    equal up to the scheme's O(Δt²) (the body-frame inertia M(v̇ + ω×v) of R(t)ᵀV is not
    discretely invariant). Measured at 10 segments: 1.00e-4 m at Δt = 0.02 s,
    2.43e-5 m at 0.01 s (ratio 4.1)."""
    V = np.array([0.7, -0.3, 0.2])
    gaps = []
    for dt in (0.02, 0.01):
        pinned, towed = _pendulum([0.0, 0.0, 0.0], dt), _pendulum(V, dt)
        t = towed.time.values
        r = towed.position.values
        assert np.abs(r[:, 0] - t[:, None] * V).max() < 1e-9       # measured 1.3e-11
        assert np.array_equal(towed.kappa.values[:, 0], np.zeros_like(t[:, None] * V))
        assert np.abs(towed.omega.values[:, 0, 1]).max() > 1.0      # the pin turns
        assert np.ptp(r[:, -1, 0] - t * V[0]) > 0.5                 # the rod swings
        gaps.append(np.abs(r - t[:, None, None] * V - pinned.position.values).max())
    assert gaps[1] < 5e-5 and 3.5 < gaps[0] / gaps[1] < 4.5, gaps


def test_a_position_table_tows_an_end_free_to_turn_along_it():
    """A pin free to turn moved by a position table (a 1-m rod hanging under gravity,
    the pin dragged 0.3 m sideways and back): the pin is on the table at every output
    (the knots are breakpoints; as with the rotation fixed, the restart steps after a knot
    cost about 1e-4 Δt × the jump of the velocity: measured 1.5e-6 m), κ = 0 there, and
    the rod lags behind it and swings (its tip off the pin's x by more than 5 cm)."""
    table = {"t": [0.0, 0.5, 1.0, 1.5], "value": [0.0, 0.0, 0.3, 0.0]}
    start = {"frame": "global", "translation": [{"position": table}, {"position": 0.0},
                                                {"position": 0.0}], "rotation": FREE_ROT}
    spec = _spec(start, FREE, gravity=[0.0, 0.0, 9.81],
                 output={"fields": ["position", "kappa"]})
    spec["numerics"] = {"n_segments": 10, "dt": 0.05, "t_end": 2.0}
    ds = integrate(Case.model_validate(spec))
    r = ds.position.values
    want = np.interp(ds.time.values, table["t"], table["value"])
    assert np.abs(r[:, 0, 0] - want).max() < 1e-5, np.abs(r[:, 0, 0] - want).max()
    assert np.abs(r[:, 0, 1:]).max() < 1e-9
    assert not ds.kappa.values[:, 0].any()
    assert np.abs(r[:, -1, 0] - r[:, 0, 0]).max() > 0.05


@pytest.mark.parametrize("where", ["start", "end"])
def test_a_towed_end_free_to_turn_has_the_exact_jacobian(where):
    """The rows v − R^{n+1}ᵀ V of a towed end free to turn on its ω^{n+1}: the block
    −½Δt [b]× J_r(θ) (solver/scheme.py ``residual_into``) against central differences
    at a perturbed iterate (measured 4-5e-11 against entries of 7e-3)."""
    from solver.run import RodRun

    tow = {"frame": "global", "translation": [{"velocity": x} for x in (0.7, -0.3, 0.2)],
           "rotation": FREE_ROT}
    spec = _spec(tow if where == "start" else FREE, FREE if where == "start" else tow,
                 gravity=[3.0, 0.0, 9.0])
    run = RodRun(Case.model_validate(spec))
    for _ in range(3):
        assert run.try_step(0.02).ok
    prob = run.assembly.step_problem(run.state, 0.02)
    sysm = run.system
    sysm.begin_step(prob.h, prob.params, prob.t_new, run.state.Y, run.state.Ydot, run.state.F_old, prob.bc,
                    q_old=run.state.q, r_old=run.state.r, v_old_global=run.state.v_global)
    Y = prob.guess + 0.3 * np.random.default_rng(1).standard_normal(prob.guess.shape)
    e = 0 if where == "start" else 1
    assert list(prob.bc.turning) == [e == 0, e == 1]
    sysm.evaluate(Y, True)
    block = sysm.buf.bc_jac[e].copy()
    rows, k = prob.bc.rows[6 * e:6 * e + 3], 0 if e == 0 else Y.shape[0] - 1
    fd = np.empty((3, 3))
    for j in range(3):
        side = []
        for step in (1e-6, -1e-6):
            Yj = Y.copy()
            Yj[k, 3 + j] += step
            sysm.evaluate(Yj)
            side.append(sysm.buf.R[rows].copy())
        fd[:, j] = (side[0] - side[1]) / 2e-6
    assert np.abs(block).max() > 1e-3
    assert np.abs(block - fd).max() < 1e-6 * np.abs(block).max(), np.abs(block - fd).max()


def test_error_controlled_run_with_a_position_table_ends_with_its_refusals_named():
    """An error-controlled run across a position table's knots (restart steps, doubled
    steps) completes and names every refused attempt's reason; a failed first leg of a
    doubled step used to lose its reason and the run crashed when writing the result."""
    table = {"t": [0.0, 1.0, 1.5], "value": [0.0, 0.1, 0.05]}
    sp = _spec({"frame": "global", "translation": [{"position": table}, {"position": 0.0},
                                                     {"position": 0.0}], "rotation": FIXED},
               FREE, gravity=[0, 3.0, 0])
    sp["numerics"] = {"n_segments": 10, "dt": 0.1, "t_end": 2.0, "rho_inf": 0.5,
                      "tolerance": {"relative": 1e-3}}
    ds = integrate(Case.model_validate(sp))
    assert ds.attrs["hockle_status"] == "completed"
    refused = dict(item.rsplit(" ", 1) for item in ds.attrs["hockle_refused_attempts"].split(", "))
    assert "None" not in refused and int(refused["error"]) > 0


def catenary_spec(dt=0.2, energy_tolerance=None):
    """The soft hanging cable's case (dict): E = 1e5 Pa, 40 segments, both ends held in
    position in the global frame 0.8 m apart, started from an arc of L = 1 m, ρ∞ = 0,
    to 16 s (research/energy_check.py runs it with and without the energy check;
    tests/solver/test_energy_check.py at Δt = 0.1 s)."""
    L, X, D, rho, rho_f = 1.0, 0.8, 0.01, 7800.0, 1000.0
    start = {"frame": "global", "translation": [{"position": 0.0}] * 3,
             "rotation": FREE_ROT}
    end = {"frame": "global", "translation": [{"position": X}, {"position": 0.0},
                                              {"position": 0.0}], "rotation": FREE_ROT}
    spec = _spec(start, end, gravity=[0.0, 0.0, -9.81],
                 fluid={"density": rho_f, "added_mass_coefficient": 1.0,
                        "drag_coefficient_normal": 1.2},
                 initial={"centreline": {"points": _arc_points(L, X)}},
                 output={"fields": ["f", "position", "reactions"]})
    spec["rod"].update({"youngs_modulus": 1e5, "shear_modulus": 1e5 / 2.6, "density": rho,
                        "diameter": D})
    spec["numerics"] = {"n_segments": 40, "dt": dt, "t_end": 16.0, "rho_inf": 0.0,
                        "growth_guard": None, "energy_tolerance": energy_tolerance}
    return spec
