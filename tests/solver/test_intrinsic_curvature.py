"""The intrinsic curvature κ⁰ (``rod.intrinsic_curvature``): the law m = R K (κ − κ⁰) in
the statics' and the centreline scheme's rows. Oracles: an unloaded rod takes its
natural shape (a circular arc, second order in Δs) with no moment; a straight rod with
intrinsic twist stays straight; a naturally curved rod held straight carries the moment
−K κ⁰ and the energy ½ EJ κ⁰² L, in the statics and through a dynamic run's outputs; the
intrinsic twist of a rod clamped at both ends buckles it at Greenhill's torque (the
continuation's branch point at GJ κ⁰3 = 8.9868 EJ/L); a static equilibrium is a dynamic
rest; the spec's errors name the field."""
import math

import numpy as np
import pytest
from pydantic import ValidationError

from rodcases import E, G, free_end, make_case
from solver import statics as st
from solver.case import Case
from solver.centreline import CentrelineRod
from solver.continuation import continuation

Q0 = np.array([1.0, 0.0, 0.0, 0.0])


def _arc(n, k0=math.pi, length=1.0):
    """A cantilever along z (clamped at s = 0, free end) whose κ⁰1 = k0: the half circle."""
    kappa0 = np.zeros((n + 1, 3))
    kappa0[:, 0] = k0
    prob = st.uniform(length, n, [1.0, 1.0, 0.8], st.clamp(np.zeros(3), Q0), st.free_end(),
                      intrinsic_curvature=kappa0)
    return prob, st.solve(prob)


def test_an_unloaded_rod_takes_its_natural_shape_to_second_order():
    """κ⁰1 = π/L on a free cantilever: m = 0 and the centreline is the half circle of
    radius L/π, its chord 2L/π; the box rule's error in the chord falls as Δs²."""
    errors = []
    for n in (10, 20, 40):
        prob, sol = _arc(n)
        assert np.abs(sol.Y[:, 10:13]).max() < 1e-10
        fl = st.fields(sol.Y, prob)
        assert np.allclose(fl["kappa"][:, 0], math.pi) and fl["elastic_energy"] < 1e-20
        # every node on the circle through the origin, centre (0, −1/π, 0)
        centre = np.array([0.0, -1.0 / math.pi, 0.0])
        assert np.abs(np.linalg.norm(sol.Y[:, 0:3] - centre, axis=1)
                      - 1.0 / math.pi).max() < 2.0 / n**2
        errors.append(abs(np.linalg.norm(sol.Y[-1, 0:3]) - 2.0 / math.pi))
    order = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(order - 2.0) < 0.05), (errors, order)


def test_an_intrinsic_twist_leaves_a_free_rod_straight():
    """κ⁰3 = τ only: the free rod stays straight, its frames turn by τL, no moment."""
    n, tau = 20, 3.0
    kappa0 = np.zeros((n + 1, 3))
    kappa0[:, 2] = tau
    prob = st.uniform(1.0, n, [1.0, 1.0, 0.8], st.clamp(np.zeros(3), Q0), st.free_end(),
                      intrinsic_curvature=kappa0)
    Y = st.solve(prob).Y
    assert np.abs(Y[:, 0:2]).max() < 1e-12 and abs(Y[-1, 2] - 1.0) < 1e-12
    assert np.abs(Y[:, 10:13]).max() < 1e-10
    # the Cayley map turns each cell by 4 atan(h τ / 4)
    angle = 2.0 * math.atan2(Y[-1, 6], Y[-1, 3])
    assert abs(angle - n * 4.0 * math.atan(tau / n / 4.0)) < 1e-12
    assert abs(angle - tau) < 2e-3


def test_a_curved_rod_held_straight_carries_its_moment():
    """κ⁰1 = c, both ends clamped on the straight line (the s = L end free to slide
    along it: held at both, the rod's tension is indeterminate): m = −EJ c a1
    everywhere, the elastic energy ½ EJ c² L."""
    n, c, B = 20, 2.0, 1.5
    kappa0 = np.zeros((n + 1, 3))
    kappa0[:, 0] = c
    end = st.clamp([0.0, 0.0, 1.0], Q0, held=(True, True, False))
    prob = st.uniform(1.0, n, [B, B, 0.8 * B], st.clamp(np.zeros(3), Q0), end,
                      intrinsic_curvature=kappa0)
    Y = st.solve(prob).Y
    assert np.abs(Y[:, 0:2]).max() < 1e-12
    assert np.allclose(Y[:, 10], -B * c, rtol=1e-12) and np.abs(Y[:, 11:13]).max() < 1e-12
    fl = st.fields(Y, prob)
    assert np.abs(fl["kappa"]).max() < 1e-12
    assert fl["elastic_energy"] == pytest.approx(0.5 * B * c * c, rel=1e-12)


def test_an_intrinsic_twist_buckles_a_clamped_rod_at_greenhills_torque():
    """Both ends clamped, the s = L end free to slide along the axis under no force: the
    intrinsic twist κ⁰3 = τ of the rod held straight is the torque M = −GJ τ, and the
    continuation in τ finds the branch point, a pair of modes of the round rod (two
    become unstable together), at |M| L/EJ = 8.9868 (tan(x/2) = x/2,
    tests/solver/test_greenhill.py), here within the box rule's O(Δs²)."""
    n, B, C = 40, 1.0, 0.8
    end = st.clamp([0.0, 0.0, 1.0], Q0, held=(True, True, False))

    def problem_at(tau):
        kappa0 = np.zeros((n + 1, 3))
        kappa0[:, 2] = tau
        return st.uniform(1.0, n, [B, B, C], st.clamp(np.zeros(3), Q0), end,
                          intrinsic_curvature=kappa0)

    br = continuation(problem_at, 0.0, 14.0, max_points=60)
    bps = [b for b in br.bifurcations if b.kind == "branch_point"]
    assert len(bps) == 1 and not bps[0].simple, br.stopped
    assert C * bps[0].parameter / B == pytest.approx(8.9868, rel=5e-3)
    u = np.asarray(br.unstable)
    assert set(u[: bps[0].after + 1]) == {0} and set(u[bps[0].after + 1:]) == {2}
    # on the straight branch the moment is −GJ τ and the rod untwisted (κ3 = 0)
    k = bps[0].after
    assert br.Y[k][:, 12] == pytest.approx(-C * br.parameter[k], rel=1e-9)


# ------------------------------------------------------------------ the centreline scheme

def _curved_case(**kw):
    case = make_case(n_segments=20, dt=0.01, t_end=0.1, end=free_end(),
                     gravity=(-9.81, 0.0, 0.0), **kw)
    spec = case.model_dump(mode="json")
    spec["rod"]["intrinsic_curvature"] = [1.5, {"s": [0.0, 1.0], "value": [0.0, 1.0]}, 0.5]
    spec["numerics"]["formulation"] = "centreline"
    spec["numerics"].pop("tolerance", None)
    return Case.model_validate(spec)


def test_a_static_equilibrium_of_a_curved_rod_is_a_dynamic_rest():
    """The curved cantilever (κ⁰ with a profile, twist) under its weight: the statics'
    equilibrium starts a run with no acceleration that stays there."""
    case = _curved_case()
    rod = CentrelineRod.from_case(case)
    prob = rod.problem(0.0)
    assert prob.kappa0[-1].tolist() == [1.5, 1.0, 0.5]
    sol = st.solve(prob)
    state = rod.start(sol.Y)
    assert np.abs(state.Xd).max() < 1e-6
    for _ in range(10):
        state, _, _ = rod.step(state, 0.01)
    assert np.abs(state.Y[:, 0:3] - sol.Y[:, 0:3]).max() < 1e-9
    fl = rod.body_fields(state)
    strain = st.fields(sol.Y, prob)["kappa"] - prob.kappa0
    assert np.abs(fl["kappa"] - prob.kappa0 - strain).max() < 1e-6
    # its weight bends it away from its natural shape: a moment, an elastic energy
    assert rod.energies(state)["elastic"] > 1e-3


def test_a_curved_rod_released_straight_keeps_its_energy_at_rho_inf_1():
    """A cantilever whose κ⁰1, κ⁰3 fall linearly from (2, 0.5) 1/m at the clamp to 0 at
    the free end, released straight in vacuum at ρ∞ = 1: its elastic energy
    ½∫(κ − κ⁰)·K(κ − κ⁰) ds turns into motion (the kinetic energy reaches 98 % of it)
    and the total stays at its start within 1 % of the largest kinetic energy over 1 s
    at Δt = 0.01 s (measured 1.7 %, 0.54 %, 0.44 % on 10, 20, 40 segments)."""
    case = make_case(n_segments=20, dt=0.01, t_end=1.0, end=free_end(), rho_inf=1.0)
    spec = case.model_dump(mode="json")
    spec["rod"]["intrinsic_curvature"] = [{"s": [0.0, 1.0], "value": [2.0, 0.0]}, 0.0,
                                          {"s": [0.0, 1.0], "value": [0.5, 0.0]}]
    spec["numerics"]["formulation"] = "centreline"
    spec["numerics"].pop("tolerance", None)
    rod = CentrelineRod.from_case(Case.model_validate(spec))
    state = rod.start()
    e = rod.energies(state)
    ej, gj = E * math.pi * 0.02**4 / 64, G * math.pi * 0.02**4 / 32
    # straight at rest: the elastic energy is ½∫K κ⁰² ds (trapezoid of a quadratic)
    exact = 0.5 * (ej * 4.0 + gj * 0.25) / 3.0
    assert e["kinetic"] == 0.0 and e["elastic"] == pytest.approx(exact, rel=2e-3)
    start, worst, kmax = e["elastic"], 0.0, 0.0
    for _ in range(100):
        state, _, _ = rod.step(state, 0.01)
        e = rod.energies(state)
        worst = max(worst, abs(e["kinetic"] + e["elastic"] - start))
        kmax = max(kmax, e["kinetic"])
    assert kmax > 0.9 * start and worst < 0.01 * kmax, (worst / kmax, kmax / start)


def test_a_run_reports_the_moment_and_energy_about_the_natural_shape():
    """A rod with κ⁰1 = c clamped straight at both ends (the s = L end free to slide
    along the axis), run on the centreline scheme: it stays straight, and the outputs say moment −EJ c, bending energy ½ EJ c² L and
    end reactions ∓ the moment (module docstring of solver.loads)."""
    from solver.simulation import integrate

    slide = {"translation": [{"velocity": 0.0}] * 2 + [{"force": 0.0}],
             "rotation": [{"angular_velocity": 0.0}] * 3}
    case = make_case(n_segments=10, dt=0.01, t_end=0.05, end=slide,
                     fields=("position", "kappa", "moment", "energies", "reactions"))
    spec = case.model_dump(mode="json")
    c = 2.0
    spec["rod"]["intrinsic_curvature"] = [c, 0.0, 0.0]
    spec["numerics"]["formulation"] = "centreline"
    spec["numerics"].pop("tolerance", None)
    ds = integrate(Case.model_validate(spec))
    assert ds.attrs["hockle_status"] == "completed"
    ej = E * math.pi * 0.02**4 / 64
    assert np.abs(ds.position.values[:, :, :2]).max() < 1e-12
    assert np.abs(ds.kappa.values).max() < 1e-9
    assert np.allclose(ds.moment.values[..., 0], -ej * c, rtol=1e-9)
    assert float(ds.energy_bending[-1]) == pytest.approx(0.5 * ej * c * c, rel=1e-9)
    assert float(ds.energy_torsion[-1]) < 1e-12 * ej
    # the surroundings hold the start with +EJ c a1 and the end with −EJ c a1
    assert float(ds.reaction_moment_start[-1, 0]) == pytest.approx(ej * c, rel=1e-9)
    assert float(ds.reaction_moment_end[-1, 0]) == pytest.approx(-ej * c, rel=1e-9)


# ------------------------------------------------------------------ the case spec

def _spec(**rod):
    spec = make_case(end=free_end()).model_dump(mode="json")
    spec["rod"].update(rod)
    spec["numerics"]["formulation"] = "centreline"
    spec["numerics"].pop("tolerance", None)
    return spec


def test_the_spec_names_the_field_of_a_bad_intrinsic_curvature():
    with pytest.raises(ValidationError, match=r"rod.intrinsic_curvature"):
        Case.model_validate(_spec(intrinsic_curvature=[1.0, 2.0]))
    with pytest.raises(ValidationError, match=r"intrinsic_curvature.1.s.1"):
        Case.model_validate(_spec(intrinsic_curvature=[0.0, {"s": [0.0, 2.0],
                                                             "value": [1.0, 1.0]}, 0.0]))
    with pytest.raises(ValidationError, match=r"intrinsic_curvature.2"):
        Case.model_validate(_spec(intrinsic_curvature=[0.0, 0.0, float("nan")]))
    goyal = _spec(intrinsic_curvature=[1.0, 0.0, 0.0])
    goyal["numerics"]["formulation"] = "goyal"
    with pytest.raises(ValidationError, match=r"rod.intrinsic_curvature[\s\S]*centreline"):
        Case.model_validate(goyal)


def test_a_case_without_it_keeps_its_canonical_json():
    plain = Case.model_validate(_spec())
    assert "intrinsic_curvature" not in plain.canonical_json()
    curved = Case.model_validate(_spec(intrinsic_curvature=[1.0, -2.0, 0.5]))
    assert "intrinsic_curvature" in curved.canonical_json()
    assert curved.rod.evaluate_intrinsic_curvature([0.0, 0.5]).tolist() == \
        [[1.0, -2.0, 0.5]] * 2
