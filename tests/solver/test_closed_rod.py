"""Closed rods (``rod.closed``) on the centreline scheme: node N is node 0 again, joined by
13 rows (n, m continuous, |p0| = 1, centreline and frame closed). Oracles: a linked ring
at rest stays the box rule's circle with Tw + Wr = Lk, Tw converging to Lk at second
order; a ring falling in vacuum keeps its shape and falls as g t²/2; the step's Jacobian
with the join's coupling is the residual's derivative; Michell's instability of a
twisted ring (Lk_c = √3 B/C) brackets within ±5 %; the spec's refusals name their
field; the canonical JSON of a closed case validates again."""
import math

import numpy as np
import pytest
from pydantic import ValidationError

from rodcases import step_jacobian_fd
from solver import statics
from solver.case import Case
from solver.centreline import CentrelineRod
from solver.simulation import integrate

E, RHO, D = 1.25e7, 1500.0, 0.02


def ring(link=1, n=40, t_end=0.5, dt=0.01, shear=5e6, fluid=True, **extra):
    spec = {"schema_version": 1, "name": "ring",
            "rod": {"length": 1.0, "youngs_modulus": E, "shear_modulus": shear,
                    "density": RHO, "diameter": D, "closed": True},
            "initial": {"linking_number": link},
            "numerics": {"n_segments": n, "dt": dt, "t_end": t_end,
                         "formulation": "centreline"},
            "output": {"fields": ["position", "kappa", "energies", "topology"]}}
    if fluid:
        spec["fluid"] = {"density": 1000.0}
    spec.update(extra)
    return spec


def test_a_linked_ring_at_rest_stays_its_circle_with_tw_plus_wr_equal_to_lk():
    """Lk = 1 on 20 and 40 segments: the ring closes to rounding, keeps one radius and
    does not move; Wr = 0 (a plane circle); Tw falls short of Lk by the box rule's O(Δs²)
    (the trapezoid of κ3 against the Cayley map's turns, 4 atan(Δs κ̄3/4) per cell)."""
    gaps = []
    for n in (20, 40):
        ds = integrate(Case.model_validate(ring(n=n)))
        assert ds.attrs["hockle_status"] == "completed"
        r = ds.position.values
        assert np.abs(r[:, -1] - r[:, 0]).max() < 1e-14
        radius = np.linalg.norm(r[:, :-1] - r[:, :-1].mean(axis=1, keepdims=True), axis=2)
        assert radius.max() - radius.min() < 1e-12
        assert abs(radius.mean() - 1.0 / (2 * math.pi)) < 2.0 / n**2
        assert np.abs(ds.writhe.values).max() < 1e-12
        assert np.all(ds.linking_number.values == 1.0)
        assert float(ds.energy_kinetic.max()) < 1e-20
        gaps.append(float(ds.topology_error.max()))
    assert gaps[1] < 1.5e-3 and 3.8 < gaps[0] / gaps[1] < 4.2, gaps


def test_a_ring_falls_in_vacuum_as_a_rigid_body():
    """Gravity on a free ring without fluid: every node falls g t²/2 (generalized-α is
    exact for a constant acceleration from a consistent start) and the shape keeps."""
    spec = ring(link=2, n=20, t_end=0.3, dt=0.01, fluid=False, gravity=[0.0, 0.0, -9.81])
    ds = integrate(Case.model_validate(spec))
    r = ds.position.values
    t = ds.time.values
    drop = r[:, :, 2] - r[0, :, 2]
    assert np.abs(drop + 0.5 * 9.81 * t[:, None] ** 2).max() < 1e-9
    assert np.abs(r[:, :, :2] - r[0, :, :2]).max() < 1e-9
    assert np.abs(ds.topology_error.values - ds.topology_error.values[0]).max() < 1e-12


def test_the_step_jacobian_with_the_join_is_the_residuals_derivative():
    """The band plus the join's coupling of nodes 0 and N (solver.statics.join_coupling)
    against central differences of the step's residual, on a twisted ring moved off its
    circle."""
    rod = CentrelineRod.from_case(Case.model_validate(ring(link=2, n=12)))
    old = rod.start()
    h = 0.01
    co = rod.coefficients(old, h)
    prob = rod.problem(h)
    rng = np.random.default_rng(3)
    Y = old.Y + 1e-3 * rng.standard_normal(old.Y.shape)
    from solver.centreline import _SparseLU
    A = _SparseLU(rod.jacobian(Y, old, co, prob), statics.join_coupling(Y, prob)).A.toarray()
    fd = step_jacobian_fd(rod, Y, old, co, prob, eps=1e-6)
    assert np.abs(A - fd).max() < 1e-6 * np.abs(A).max()
    # the join's rows reach outside the band: nodes 0 and N both
    assert np.abs(A[:statics.N_START, -statics.NV:]).max() > 0.5


def michell_out_of_plane(ratio, t_end=1.2):
    """The largest out-of-plane size (m, the rms distance from the ring's best plane)
    of an Lk = 2 ring in water whose GJ puts Lk at ``ratio`` × Michell's √3 EJ/GJ,
    nudged out of its plane by 1 mN for 0.2 s."""
    shear = ratio * math.sqrt(3) * E / (2 * 2)              # Lk_c = √3 EJ/GJ = √3 E/(2G)
    spec = ring(link=2, n=40, t_end=t_end, dt=0.05, shear=shear,
                point_loads=[{"s": 0.25, "value": [0.0, 1e-3, 0.0], "start": 0.0, "end": 0.2}])
    spec["numerics"]["rho_inf"] = 0.8
    spec["output"] = {"fields": ["position", "topology"], "every": 4}
    ds = integrate(Case.model_validate(spec))
    r = ds.position.values[:, :-1]
    size = [np.linalg.svd(x - x.mean(0), compute_uv=False)[-1] / math.sqrt(len(x)) for x in r]
    return max(size), ds


def test_michells_instability_of_a_twisted_ring():
    """Michell (1890; Goriely, J. Elasticity 84, 2006): a twisted ring of an isotropic rod
    is stable below Lk = √3 EJ/GJ. At 0.95 of it the nudged ring stays in its plane
    (measured 1e-5 m), at 1.05 it leaves it exponentially (0.2 mm, 1.1 mm, 7 mm at
    0.4, 0.6, 0.8 s on 40 segments) and Tw + Wr keeps Lk until strands cross."""
    below, ds = michell_out_of_plane(0.95)
    assert below < 1e-4 and ds.topology_error.max() < 2e-3
    above, ds = michell_out_of_plane(1.05, t_end=0.8)
    assert above > 5e-3, above
    assert ds.topology_error.max() < 2e-3


# ------------------------------------------------------------------ the case spec

def test_a_closed_rods_refusals_name_their_field():
    cases = [
        ({"boundary": {"start": {}, "end": {}}}, "boundary", "no ends"),
        ({"numerics": {"n_segments": 40, "dt": 0.01, "t_end": 0.5}}, "rod.closed",
         "centreline"),
        ({"initial": {"linking_number": 1, "twist_rate": 1.0}}, "initial.twist_rate",
         "circle"),
        ({"initial": {"linking_number": 30}}, "initial.linking_number", "not_resolved|half"),
    ]
    for change, field, words in cases:
        spec = ring()
        spec.update(change)
        with pytest.raises(ValidationError, match=rf"{field}[\s\S]*({words})"):
            Case.model_validate(spec)
    open_rod = ring()
    open_rod["rod"]["closed"] = False
    open_rod["boundary"] = {"start": {"translation": [{"velocity": 0.0}] * 3,
                                      "rotation": [{"angular_velocity": 0.0}] * 3},
                            "end": {"translation": [{"force": 0.0}] * 3,
                                    "rotation": [{"moment": 0.0}] * 3}}
    with pytest.raises(ValidationError, match="initial.linking_number"):
        Case.model_validate(open_rod)


def test_a_closed_case_round_trips_and_the_statics_refuse_it():
    case = Case.model_validate(ring(link=3))
    text = case.canonical_json()
    assert '"closed":true' in text and '"boundary"' not in text
    assert Case.model_validate_json(text).spec_hash() == case.spec_hash()
    plain = ring()
    del plain["rod"]["closed"]
    plain["initial"] = {}
    plain["boundary"] = {"start": {"translation": [{"velocity": 0.0}] * 3,
                                   "rotation": [{"angular_velocity": 0.0}] * 3},
                         "end": {"translation": [{"force": 0.0}] * 3,
                                 "rotation": [{"moment": 0.0}] * 3}}
    assert '"closed"' not in Case.model_validate(plain).canonical_json()
    with pytest.raises(statics.StaticsError, match="rod.closed"):
        statics.static_problem(case)
