"""Screened electrostatics (``electrostatics``, solver/electrostatics.py): the Debye–Hückel
energy between non-adjacent segments against its analytic limits (two long parallel
lines: ν²/(2π ε₀ ε_r) K₀(d/λ) per length, repelling with ν²/(2π ε₀ ε_r λ) K₁(d/λ)), the
quadrature against a high-order reference within the module's stated error, forces as the
energy's gradient and an exact Jacobian, the cut-off and the exclusion, the case's
refusals naming the field, and the solver's use of it: a hairpin whose arms are pressed
together settles where the load balances the K₁ repulsion, in the statics and as a rest
of the centreline scheme, whose step Jacobian with the pairs is exact."""
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.special import k0, k1

from rodcases import clamped_end, free_end, hairpin, refused, step_jacobian_fd
from solver import statics
from solver.case import Case
from solver.centreline import CentrelineRod
from solver.electrostatics import (VACUUM_PERMITTIVITY, WATER_PERMITTIVITY,
                                   ScreenedElectrostatics, debye_length, quadrature_error,
                                   tail_bound)
from solver.static_band import KL, band_to_sparse

LAM = 1e-9                   # Debye length, m
NU = 1e-10                   # line charge, C/m
LINE = NU**2 / (2 * math.pi * VACUUM_PERMITTIVITY * WATER_PERMITTIVITY)   # J/m


def two_strands(d, length, h, turn=None):
    """Nodes (N+1, 3) and grid s (N+1,) of one rod that runs ``length`` along +x at y = 0,
    turns by a straight piece of length d along y, and runs back along −x at y = d: two
    parallel strands at distance d (m), h (m) apart along each."""
    n = int(round(length / h))
    nd = max(1, int(round(d / h)))
    out = [(i * h, 0.0, 0.0) for i in range(n + 1)]
    out += [(length, j * d / nd, 0.0) for j in range(1, nd + 1)]
    out += [(length - i * h, d, 0.0) for i in range(1, n + 1)]
    r = np.array(out)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(r, axis=0), axis=1))])
    return r, s


def model(s, **kw):
    kw.setdefault("exclusion", 8 * LAM)
    return ScreenedElectrostatics(s, NU, LAM, **kw)


# ------------------------------------------------------------------ the analytic limits

@pytest.mark.parametrize("d", [0.5, 1.0, 2.0])
def test_parallel_lines_repel_with_k1(d):
    """The force per length on the middle of one of two 40-λ strands d apart is
    ν²/(2π ε₀ ε_r λ) K₁(d/λ) within the cut-off's measured excess at the default 6 λ
    (3e-5 at d = λ, 3e-4 at 2λ; module docstring) plus the quadrature's, and no
    force acts along the strand; the same on grids of λ/2 and λ/4."""
    tol = {0.5: 2e-5, 1.0: 6e-5, 2.0: 5e-4}[d]
    for h in (0.5 * LAM, 0.25 * LAM):
        r, s = two_strands(d * LAM, 40 * LAM, h)
        ev = model(s).evaluate(r, want_jacobian=False)
        mid = int(round(20 * LAM / h))
        expected = LINE / LAM * k1(d)
        assert -ev.loads[mid, 1] == pytest.approx(expected, rel=tol)
        assert abs(ev.loads[mid, 0]) < 1e-9 * expected
        other = len(r) - 1 - mid                         # the partner node, pushed +y
        assert ev.loads[other, 1] == pytest.approx(expected, rel=tol)


@pytest.mark.parametrize("d", [1.0, 2.0])
def test_parallel_lines_store_k0_per_length_and_converge(d):
    """The energy per length, from two strand lengths (the ends and the turn cancel),
    is ν²/(2π ε₀ ε_r) K₀(d/λ) less the cut-off's measured loss (0.16 % at d = λ, 0.61 %
    at 2λ), within 2e-4 on a grid of λ/2; refining to λ/4 changes it by less than 1e-5."""
    loss = {1.0: 1.58e-3, 2.0: 6.10e-3}[d]
    per_length = []
    for h in (0.5 * LAM, 0.25 * LAM):
        u = [model(two_strands(d * LAM, n * LAM, h)[1]).energy(
            two_strands(d * LAM, n * LAM, h)[0]) for n in (30, 50)]
        per_length.append((u[1] - u[0]) / (20 * LAM))
    assert per_length[0] == pytest.approx(LINE * k0(d) * (1 - loss), rel=2e-4)
    assert per_length[1] == pytest.approx(per_length[0], rel=1e-5)
    assert LINE * k0(d) - per_length[1] < tail_bound(NU, LAM, 6.0)


def test_the_debye_length_of_a_salt():
    """λ = √(ε₀ ε_r k_B T/(2 N_A e² 1000 c)): 0.1 mol/L of NaCl in water at 25 °C is
    0.96 nm (0.304/√c nm, the textbook figure), and λ goes as c^(−1/2)."""
    lam = debye_length(0.1, 298.15)
    assert lam == pytest.approx(0.304e-9 / math.sqrt(0.1), rel=5e-3)
    assert debye_length(0.4, 298.15) == pytest.approx(lam / 2, rel=1e-12)
    with pytest.raises(ValueError, match="salt_concentration"):
        debye_length(0.0, 298.15)


# ------------------------------------------------------------------ the quadrature

def _pair(d, angle, offset, h=1.0):
    """A rod of 3 segments whose first and last (h long) are a pair at distance d, the
    second turned by ``angle`` about the line between them and shifted by ``offset``."""
    e = np.array([math.cos(angle), math.sin(angle), 0.0])
    c = np.array([offset, 0.0, d])
    r = np.array([[-h / 2, 0, 0], [h / 2, 0, 0], c - e * h / 2, c + e * h / 2])
    return r, np.array([0.0, h, 2 * h, 3 * h])


@pytest.mark.parametrize("d, lam, bound", [(1.0, 0.5, 2e-7), (1.0, 0.25, 1e-6),
                                           (0.5, 0.5, 5e-5), (1 / 3, 0.5, 5e-4)])
def test_the_quadrature_is_within_its_stated_error(d, lam, bound):
    """Six Gauss–Legendre points per segment against 64 on single pairs (parallel, at
    45°, crossed; side by side, offset by h/2 and h), worst case within the module's
    stated error for d ≥ the given share of h and λ ≥ the given share of h; eight points
    are better still (the error falls with the points)."""
    worst6 = worst8 = 0.0
    for angle in (0.0, math.pi / 4, math.pi / 2):
        for offset in (0.0, 0.5, 1.0):
            r, s = _pair(d, angle, offset)
            es = ScreenedElectrostatics(s, 1.0, lam, cutoff=1e3, exclusion=1.0)
            assert es.pairs(r).tolist() == [[0, 2]]
            worst6 = max(worst6, quadrature_error(es, r, reference_points=64))
            worst8 = max(worst8, quadrature_error(es.with_points(8), r, 64))
    assert 0.0 < worst6 < bound
    assert worst8 < 0.2 * worst6


# ------------------------------------------------------------------ derivatives

def _coil(seed=1):
    """A perturbed helix (radius 2λ, pitch 3λ, 4 turns, 60 segments): pairs across the
    turns at every distance up to and through the cut-off's switch."""
    t = np.linspace(0.0, 8 * math.pi, 61)
    r = np.stack([2 * LAM * np.cos(t), 2 * LAM * np.sin(t), 3 * LAM * t / (2 * math.pi)], 1)
    r += 0.1 * LAM * np.random.default_rng(seed).standard_normal(r.shape)
    s = np.linspace(0.0, 1.0, 61) * np.linalg.norm(np.diff(r, axis=0), axis=1).sum()
    return r, s


def test_forces_are_the_gradient_and_the_jacobian_is_exact():
    """The nodal forces w_i L_i against central differences of the energy, and ∂L/∂r
    against central differences of the loads, on a coil with pairs inside and across the
    switch: 1e-6 of the largest entry (measured 3e-9 and 6e-10); w ∂L/∂r is symmetric
    (a Hessian)."""
    r, s = _coil()
    es = ScreenedElectrostatics(s, NU, LAM, cutoff=4.0, exclusion=5 * LAM)
    ev = es.evaluate(r)
    assert len(ev.pairs) > 100
    rho = [np.linalg.norm(r[a] - r[b]) for a, b in ev.pairs]
    assert min(rho) < 3 * LAM and max(rho) > 3.5 * LAM           # in and past the switch
    eps = 1e-6 * LAM
    grad = np.empty_like(r)
    jac = np.empty((r.size, r.size))
    for i in range(len(r)):
        for a in range(3):
            rp, rm = r.copy(), r.copy()
            rp[i, a] += eps
            rm[i, a] -= eps
            ep, em = es.evaluate(rp, False), es.evaluate(rm, False)
            grad[i, a] = (ep.energy - em.energy) / (2 * eps)
            jac[:, 3 * i + a] = ((ep.loads - em.loads) / (2 * eps)).ravel()
    force = ev.loads * es.weights[:, None]
    assert np.abs(force + grad).max() < 1e-6 * np.abs(grad).max()
    J = ev.jacobian.toarray()
    assert np.abs(J - jac).max() < 1e-6 * np.abs(J).max()
    H = J * np.repeat(es.weights, 3)[:, None]
    assert np.abs(H - H.T).max() < 1e-12 * np.abs(H).max()
    assert np.abs(force.sum(axis=0)).max() < 1e-12 * np.abs(force).max()   # momentum


# ------------------------------------------------------------------ cut-off and exclusion

def test_no_force_beyond_the_cutoff():
    """Two strands a little beyond the cut-off (6 λ) feel nothing (an exclusion of 20 λ
    leaves out the pairs around the turn, closer in space than along the rod); just
    inside the switch they do."""
    r, s = two_strands(6.05 * LAM, 30 * LAM, 0.5 * LAM)
    ev = model(s, exclusion=20 * LAM).evaluate(r)
    assert ev.energy == 0.0 and not ev.loads.any() and not ev.jacobian.count_nonzero()
    r, s = two_strands(5.5 * LAM, 30 * LAM, 0.5 * LAM)
    assert model(s, exclusion=20 * LAM).evaluate(r, False).energy > 0.0


def test_excluded_neighbours_give_nothing():
    """A straight rod stores nothing with the default exclusion (the cut-off); a pair
    nearer in arclength than the exclusion gives nothing even where it is close in space
    (a hairpin with an exclusion longer than its arms' arclength apart), and adjacent
    segments never pair."""
    s = np.linspace(0.0, 50 * LAM, 101)
    r = np.stack([s, 0 * s, 0 * s], 1)
    es = ScreenedElectrostatics(s, NU, LAM)
    assert es.exclusion == 6 * LAM
    ev = es.evaluate(r)
    assert ev.energy == 0.0 and not ev.loads.any()
    r, s = two_strands(LAM, 10 * LAM, 0.5 * LAM)
    assert model(s, exclusion=25 * LAM).evaluate(r, False).energy == 0.0
    pairs = model(s, exclusion=5 * LAM).pairs(r)
    assert len(pairs) and np.all(s[pairs[:, 1]] - s[pairs[:, 0] + 1] >= 5 * LAM - 1e-15)
    tiny = model(s, exclusion=1e-3 * LAM).pairs(r)
    assert np.all(tiny[:, 1] - tiny[:, 0] >= 2)                    # never adjacent


# ------------------------------------------------------------------ the case language

def es_spec(electrostatics, formulation="centreline", n=20) -> dict:
    """A 1-m rod on the given formulation with the given electrostatics block."""
    D = 0.02
    spec = {"schema_version": 1, "name": "charged",
            "rod": {"length": 1.0, "youngs_modulus": 1e-5 / (math.pi * D**4 / 64),
                    "shear_modulus": 0.8e-5 / (math.pi * D**4 / 32), "density": 1500.0,
                    "diameter": D},
            "electrostatics": electrostatics,
            "boundary": {"start": clamped_end(), "end": free_end()},
            "numerics": {"n_segments": n, "dt": 0.01, "t_end": 0.1,
                         "formulation": formulation}}
    if formulation is None:
        del spec["numerics"]["formulation"]
    return spec



@pytest.mark.parametrize("block, loc, text", [
    ({"charge_per_length": 0.0, "debye_length": 0.01}, "charge_per_length", "greater than 0"),
    ({"charge_per_length": 1e-5, "debye_length": -0.01}, "debye_length", "greater than 0"),
    ({"charge_per_length": 1e-5}, "debye_length", "salt_concentration and temperature"),
    ({"charge_per_length": 1e-5, "salt_concentration": 0.1}, "temperature", "needs both"),
    ({"charge_per_length": 1e-5, "temperature": 298.0}, "salt_concentration", "needs both"),
    ({"charge_per_length": 1e-5, "debye_length": 0.01, "temperature": 298.0},
     "temperature", "not both"),
    ({"charge_per_length": 1e-5, "debye_length": 0.01, "cutoff": 1.5}, "cutoff",
     "greater than or equal to 2"),
    ({"charge_per_length": 1e-5, "debye_length": 0.01, "exclusion": 0.0}, "exclusion",
     "greater than 0"),
    ({"charge_per_length": 1e-5, "debye_length": 0.01, "quadrature_points": 0},
     "quadrature_points", "greater than or equal to 1"),
    ({"charge_per_length": 1e-5, "debye_length": 0.01, "colour": 1}, "colour",
     "Extra inputs"),
])
def test_bad_input_names_the_field(block, loc, text):
    refused(es_spec(block), ("electrostatics", loc), text)


def test_the_goyal_scheme_refuses_electrostatics_at_the_field():
    refused(es_spec({"charge_per_length": 1e-5, "debye_length": 0.01}, formulation=None),
             ("electrostatics",), "numerics.formulation: centreline")


def test_salt_gives_the_debye_length_and_an_absent_block_keeps_the_canonical_json():
    """A salt and temperature give the model its λ; a case without the block writes no
    ``electrostatics`` key (its spec_hash unchanged), one with it round-trips."""
    case = Case.model_validate(es_spec({"charge_per_length": 1e-5,
                                        "salt_concentration": 0.1, "temperature": 298.15}))
    prob = statics.static_problem(case, 0.0)
    assert prob.electrostatics.debye == pytest.approx(debye_length(0.1, 298.15), rel=1e-15)
    assert not statics.band_ready(prob)
    plain = es_spec(None)
    del plain["electrostatics"]
    assert "electrostatics" not in Case.model_validate(plain).canonical_json()
    again = Case.model_validate_json(case.canonical_json())
    assert again.spec_hash() == case.spec_hash()


# ------------------------------------------------------------------ on the solver

Q = 1.0                       # the load pressing the arms together, N/m
LAM_H = 0.01                  # the hairpin's Debye length, m
D_TARGET = 2 * LAM_H          # where Q balances the repulsion (with the cut-off's excess)
NU_H = math.sqrt(Q * LAM_H / k1(D_TARGET / LAM_H) * 2 * math.pi * VACUUM_PERMITTIVITY
                 * WATER_PERMITTIVITY)


def charged_hairpin(n=100) -> Case:
    """A 1-m rod (B = 1e-5 N m², D = 2 cm) folded into a hairpin whose arms start 3 cm
    apart, clamped at s = 0 and free at s = L, its arms pressed together by Q = 1 N/m
    away from the bend; charged so that two parallel lines repel with Q at d = 2λ,
    λ = 1 cm; no contact, vacuum, on the centreline scheme."""
    radius = 0.015
    pts = hairpin(radius, n=4001)
    leg = 0.5 * (1.0 - math.pi * radius)
    spec = es_spec({"charge_per_length": NU_H, "debye_length": LAM_H}, n=n)
    spec.update({
        "distributed_forces": [{"value": [Q, 0.0, 0.0], "s_range": [0.0, leg - 0.05]},
                               {"value": [-Q, 0.0, 0.0], "s_range": [1.0 - leg + 0.05, 1.0]}],
        "initial": {"centreline": {"points": pts.tolist()}, "normal": [0.0, 1.0, 0.0]}})
    return Case.model_validate(spec)


def _equilibrium(rod):
    return statics.solve(rod.problem(0.0), rod.rest_state().Y, tol=1e-10, max_iterations=40)


def test_a_pressed_hairpin_settles_where_the_load_balances_the_k1_repulsion():
    """The statics' equilibrium: along the middle of the arms (s = 0.15 to 0.25, straight
    and parallel there) the gap d solves Q = ν²/(2π ε₀ ε_r λ) K₁(d/λ) (1 + the cut-off's
    excess at 2λ, 2.9e-4) to 3e-4 of d at each node and 1.5e-4 on average (measured
    −0.8e-4 on average, the arms' bending boundary layers from the bend and the ends
    leaving a ripple of 2e-4 d there, on 100 and 200 segments alike); a wrong factor 2 in
    the force would move d by ln 2 · λ ≈ 0.35 d, a wrong sign would close the arms."""
    n = 100
    rod = CentrelineRod.from_case(charged_hairpin(n))
    r = _equilibrium(rod).Y[:, 0:3]
    gaps = np.array([r[n - k, 0] - r[k, 0] for k in (15, 20, 25)])
    excess = 2.93e-4                                # the force's, at 2λ (module doc)
    line = NU_H**2 / (2 * math.pi * VACUUM_PERMITTIVITY * WATER_PERMITTIVITY * LAM_H)
    d = brentq(lambda x: line * k1(x / LAM_H) * (1 + excess) - Q, LAM_H, 5 * LAM_H)
    assert np.abs(gaps / d - 1).max() < 3e-4
    assert abs(gaps.mean() / d - 1) < 1.5e-4
    assert abs(np.linalg.norm(r[n - 20] - r[20]) / d - 1) < 3e-4   # across, not along


def test_the_equilibrium_is_a_rest_of_the_centreline_scheme():
    """The statics' equilibrium handed to the centreline scheme starts a run that stays
    there to rounding: the same rows, the electrostatics' loads in the step's residual
    and its Jacobian in the step's matrix."""
    rod = CentrelineRod.from_case(charged_hairpin(n=60))
    sol = _equilibrium(rod)
    state = rod.start(sol.Y)
    assert np.abs(state.Xd).max() < 1e-6
    for _ in range(10):
        state, its, _ = rod.step(state, 0.01)
    assert np.abs(state.Y[:, 0:3] - sol.Y[:, 0:3]).max() < 1e-10
    assert its <= 3


def test_the_step_jacobian_with_electrostatics_is_exact():
    """The centreline step's Jacobian (the band plus the pairs' ∂L/∂r on the force rows
    and position columns) against central differences of the step's residual, off the
    equilibrium and moving: 1e-7 of the largest entry."""
    rod = CentrelineRod.from_case(charged_hairpin(n=40))
    Y = _equilibrium(rod).Y
    Y[:, 0:3] += 1e-4 * np.random.default_rng(5).standard_normal((rod.n, 3))
    state = rod.rest_state(Y=Y)
    state.X[:, 0] = np.where(rod.props.s < 0.5, 0.02, -0.02)
    h = 0.01
    co, prob = rod.coefficients(state, h), rod.problem(h)
    Y = rod.predict(state, h)
    dL = rod.pair_load_jacobian(Y, state, co, prob)
    assert dL is not None and dL.nnz > 0
    J = (band_to_sparse(rod.jacobian(Y, state, co, prob)[KL:])
         + statics._load_rows(prob) @ dL @ statics._position_columns(prob)).toarray()
    Jfd = step_jacobian_fd(rod, Y, state, co, prob)
    assert np.abs(J - Jfd).max() < 1e-7 * np.abs(J).max()
    # and the statics' sparse Jacobian holds the same pairs
    Js = statics.jacobian(Y, prob).toarray()
    assert np.abs(Js - statics.jacobian(Y, replace(prob, electrostatics=None)).toarray()
                  ).max() > 0
