"""Self-contact on the centreline scheme (solver/centreline.py, ``contact_terms``): the
contact model of solver/contact at the nodes of the one centreline, as the statics take
it. Its oracles: an exact Jacobian (band plus the pairs' off-band blocks), a static
equilibrium with strands pressed together as a dynamic rest, and PyElastica's plectoneme
collapsing as on the seed scheme, with Lk = Tw + Wr kept."""
from dataclasses import replace

import numpy as np
import pytest

from rodcases import clamped_end, free_end, hairpin, plectoneme_case, step_jacobian_fd
from solver import statics
from solver.case import Case
from solver.centreline import CentrelineRod
from solver.simulation import integrate
from solver.static_band import KL, band_to_sparse

D, G_HAT = 0.02, 0.004


def pressed_hairpin(n=60, q=1.0) -> Case:
    """A 1-m rod folded into a hairpin (arms 2.4 mm apart at the surface, the barrier law
    of reach 4 mm), clamped at s = 0, free at s = L, its arms pressed together by q (N/m)
    on each away from the bend; no gravity, vacuum; B = 1e-5 N m²."""
    radius = 0.5 * (D + 0.6 * G_HAT)
    pts = hairpin(radius, n=4001)
    leg = 0.5 * (1.0 - np.pi * radius)
    spec = {"schema_version": 1, "name": "pressed-hairpin",
            "rod": {"length": 1.0, "youngs_modulus": 1e-5 / (np.pi * D**4 / 64),
                    "shear_modulus": 0.8e-5 / (np.pi * D**4 / 32), "density": 1500.0,
                    "diameter": D},
            "distributed_forces": [
                {"value": [q, 0.0, 0.0], "s_range": [0.0, leg - 0.05]},
                {"value": [-q, 0.0, 0.0], "s_range": [1.0 - leg + 0.05, 1.0]}],
            "contact": {"aperture": 90.0, "tolerance": 0.04, "k1": 1e-7, "k2": 3.0,
                        "k3": 1e-3, "k4": 1.0, "law": "barrier", "barrier_gap": G_HAT,
                        "barrier_stiffness": 1e4},
            "initial": {"centreline": {"points": pts.tolist()}, "normal": [0.0, 1.0, 0.0]},
            "boundary": {"start": clamped_end(), "end": free_end()},
            "numerics": {"n_segments": n, "dt": 0.01, "t_end": 0.2, "rho_inf": 0.5,
                         "formulation": "centreline"}}
    return Case.model_validate(spec)


def pressed_equilibrium(rod) -> statics.StaticSolution:
    """The statics' equilibrium of :func:`pressed_hairpin` (contact at rest), from the
    case's hairpin."""
    return statics.solve(replace(rod.problem(0.0), contact=rod.contact), rod.rest_state().Y,
                         tol=1e-10, ramp=False, max_iterations=40)


def full_jacobian(rod, Y, state, co, prob):
    """The step's Jacobian (dense) as Newton factors it: the band and the contact's."""
    J = band_to_sparse(rod.jacobian(Y, state, co, prob)[KL:])
    dL = rod.contact_terms(Y, state, co, want=True)[2]
    if dL is not None:
        J = J + statics._load_rows(prob) @ dL @ statics._position_columns(prob)
    return J.toarray()


def test_the_jacobian_with_self_contact_is_exact():
    """The step's Jacobian with pairs in contact (the band plus the pairs' blocks between
    nodes far apart along the rod, the damper's ∂F/∂ṙ chained by c_X) against central
    differences of the residual, the strands pressed and moving towards each other: 1e-7
    of the largest entry."""
    rod = CentrelineRod.from_case(pressed_hairpin())
    Y = pressed_equilibrium(rod).Y
    # off the symmetric equilibrium, whose closest points sit exactly on the partner's
    # nodes, where the Catmull-Rom curve's curvature jumps and so does ∂t/∂r (central
    # differences there average the two sides)
    Y[:, 0:3] += 1e-4 * np.random.default_rng(5).standard_normal((rod.n, 3))
    state = rod.rest_state(Y=Y)
    state.X[:, 0] = np.where(rod.props.s < 0.5, 0.02, -0.02)     # arms approaching
    h = 0.01
    co, prob = rod.coefficients(state, h), rod.problem(h)
    Y = rod.predict(state, h)
    _, ev, dL = rod.contact_terms(Y, state, co, want=True)
    assert ev.count > 10 and dL.nnz > 0
    J = full_jacobian(rod, Y, state, co, prob)
    Jfd = step_jacobian_fd(rod, Y, state, co, prob)
    assert np.abs(J - Jfd).max() < 1e-7 * np.abs(J).max()


def test_a_static_equilibrium_in_contact_is_a_dynamic_rest():
    """The hairpin's arms pressed together: the statics' equilibrium (the contact law at
    rest, :func:`solver.statics.contact_loads`) handed over as it is starts a run that
    stays there, to rounding: the dynamic law at rest is the static one, on the same
    nodes and rows. The gap is the barrier law's for q (the statics' own test)."""
    rod = CentrelineRod.from_case(pressed_hairpin())
    sol = pressed_equilibrium(rod)
    state = rod.start(sol.Y)
    assert np.abs(state.Xd).max() < 1e-6
    for _ in range(20):
        state, _, _ = rod.step(state, 0.01)
    assert np.abs(state.Y[:, 0:3] - sol.Y[:, 0:3]).max() < 1e-10
    _, ev, _ = rod.contact_terms(state.Y, state, rod.coefficients(state, 0.01), False)
    assert ev.count > 10 and 0.0 < ev.min_gap < G_HAT


@pytest.mark.parametrize("n", [25, 50])
def test_the_plectoneme_collapses_as_on_the_seed_scheme(n):
    """PyElastica's plectoneme (tests/rodcases.py) at Δt 0.05 s: the rod buckles and
    collapses into a plectoneme with its strands held apart, as on the seed scheme (first
    contact at 7.2 s, writhe at 9 s 0.983 / 0.967 on 25 / 50 segments there; measured
    here 0.946 / 0.960); Tw + Wr = Lk to 0.01 (the seed scheme's 0.033 / 0.017;
    `python -m benchmarks.centreline_compare --only plectoneme`)."""
    spec = plectoneme_case(n, 0.05).model_dump(mode="json")
    spec["numerics"]["formulation"] = "centreline"
    ds = integrate(Case.model_validate(spec))
    assert ds.attrs["hockle_status"] == "completed"
    t = ds.time.values
    first = t[np.argmax(ds.contact_count.values > 0)]
    assert 7.0 <= first <= 7.3
    assert float(ds.writhe.values[-1]) == pytest.approx(0.97, abs=0.03)
    assert float(ds.topology_error.max()) < 0.01
    assert float(ds.min_surface_gap.min()) > 0.0
