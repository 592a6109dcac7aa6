"""The tests' case factory: small case builders shared by the tests (real `Case` objects
and case documents, no fakes)."""
from __future__ import annotations

import copy

import numpy as np

from solver.case import Case

E, G, RHO, RHO_F = 1.25e7, 5.0e6, 1500.0, 1000.0

#: the cases the time loop ran on the centreline scheme under HOCKLE_TEST_FORMULATION
#: (tests/conftest.py), by id (the case kept, so that its id is not reused)
CENTRELINE_RUNS: dict[int, Case] = {}


def ran_on_centreline(case) -> bool:
    """Whether ``case``'s run took the centreline scheme (its own numerics.formulation, or
    the suite's HOCKLE_TEST_FORMULATION=centreline)."""
    return case.numerics.formulation == "centreline" or id(case) in CENTRELINE_RUNS


def kin(value=0.0, key="velocity"):
    return {key: value}


def clamped_end():
    return {"translation": [kin(), kin(), kin()],
            "rotation": [kin(key="angular_velocity")] * 3}


def free_end():
    return {"translation": [{"force": 0.0}] * 3, "rotation": [{"moment": 0.0}] * 3}


def smooth_pulse_table(amplitude, duration, n=401):
    """sin² pulse of the given peak value and duration, sampled as a table."""
    t = np.linspace(0.0, duration, n)
    return {"t": t.tolist(), "value": (amplitude * np.sin(np.pi * t / duration) ** 2).tolist()}


def make_case(*, n_segments=20, dt=0.01, t_end=0.1, rho_inf=0.5, diameter=0.02,
              length=1.0, start=None, end=None, fluid=None, gravity=None, forces=(),
              fields=("v", "omega", "f", "kappa", "position", "energies"), every=1,
              tolerance=1e-10, contact=None, max_dt_cuts=6):
    spec = {
        "schema_version": 1,
        "name": "test",
        "rod": {"length": length, "youngs_modulus": E, "shear_modulus": G,
                "density": RHO, "diameter": diameter},
        "boundary": {"start": start or clamped_end(), "end": end or clamped_end()},
        "distributed_forces": list(forces),
        "numerics": {"n_segments": n_segments, "dt": dt, "t_end": t_end,
                     "rho_inf": rho_inf, "max_dt_cuts": max_dt_cuts,
                     "newton": {"tolerance": tolerance, "max_iterations": 30}},
        "output": {"every": every, "fields": list(fields)},
    }
    if fluid is not None:
        spec["fluid"] = fluid
    if gravity is not None:
        spec["gravity"] = list(gravity)
    if contact is not None:
        spec["contact"] = contact
    return Case.model_validate(spec)



def tiny_spec(name: str = "tiny", *, n_segments: int = 8, dt: float = 0.01,
              t_end: float = 0.05, diameter=0.02, **sections) -> dict:
    """The tiny case as a case document (a dict, as a service request, a case file or a
    sweep's base carries it): the seed's cable (1 m, E = 12.5 MPa, G = 5 MPa,
    1500 kg/m³, D = 2 cm or the ``diameter`` given, a profile too) clamped at s = 0 and
    turned there at 1 rad/s, held sideways and in rotation at s = L and free along the
    axis (zero force); ``n_segments``, ``dt`` (s), ``t_end`` (s) its numerics. Further
    top-level sections (``output``, ``fluid``, ``contact``, ...) are set as given. A new
    dict on every call."""
    spec = {
        "schema_version": 1,
        "name": name,
        "rod": {"length": 1.0, "youngs_modulus": 1.25e7, "shear_modulus": 5.0e6,
                "density": 1500.0, "diameter": diameter},
        "boundary": {
            "start": {"translation": [{"velocity": 0}, {"velocity": 0}, {"velocity": 0}],
                      "rotation": [{"angular_velocity": 0}, {"angular_velocity": 0},
                                   {"angular_velocity": 1.0}]},
            "end": {"translation": [{"velocity": 0}, {"velocity": 0}, {"force": 0}],
                    "rotation": [{"angular_velocity": 0}, {"angular_velocity": 0},
                                 {"angular_velocity": 0}]},
        },
        "numerics": {"n_segments": n_segments, "dt": dt, "t_end": t_end},
    }
    spec.update(copy.deepcopy(sections))
    return spec

def jacobian_fd_error(run, seed: int, t_new: float = 0.43, dt: float = 0.01) -> np.ndarray:
    """Per row, the largest difference between the step's assembled Jacobian (cell blocks
    and boundary rows) and central finite differences of its residual, each entry weighted
    by its unknown's scale and divided by the size of the row's terms; (n,) array. The
    state is random (``seed``): old and new levels, a unit quaternion per node, old
    positions and global velocities, so that every pose-dependent load is exercised."""
    from solver.boundary import BoundaryRows
    from solver.scheme import alpha_parameters

    sysm, props = run.system, run.props
    rng = np.random.default_rng(seed)
    n1 = props.s.size
    scale = np.repeat([0.3, 1.0, 0.5, 2.0], 3)       # v, ω, f, κ
    Y_old = rng.standard_normal((n1, 12)) * scale
    Ydot_old = rng.standard_normal((n1, 12)) * scale * 10
    Y = rng.standard_normal((n1, 12)) * scale
    q_old = rng.standard_normal((n1, 4))
    q_old /= np.linalg.norm(q_old, axis=1)[:, None]
    r_old, v_old = rng.standard_normal((n1, 3)), rng.standard_normal((n1, 3))
    bc = BoundaryRows(run.case, props, t_new, sysm.n)
    F_old, _ = sysm.node_terms(Y_old, False, None, None)
    sysm.begin_step(dt, alpha_parameters(0.5), t_new, Y_old, Ydot_old, F_old, bc,
                    q_old=q_old, r_old=r_old, v_old_global=v_old)
    _, _, blocks, _ = sysm.residual(Y, want_jacobian=True)
    n = sysm.n
    J = np.zeros((n, n))
    for k in range(n1 - 1):                      # row order: 6 BC, 12 per cell, 6 BC
        J[6 + 12 * k:18 + 12 * k, 12 * k:12 * k + 24] = blocks[k]
    rows, cols, vals = bc.jacobian_entries()
    J[rows, cols] += vals
    J_fd = np.zeros_like(J)
    y = Y.ravel()
    col_scale = np.tile(scale, n1)
    for j in range(n):
        h = 1e-6 * max(abs(y[j]), col_scale[j])
        yp, ym = y.copy(), y.copy()
        yp[j] += h
        ym[j] -= h
        J_fd[:, j] = (sysm.residual(yp.reshape(Y.shape))[0]
                      - sysm.residual(ym.reshape(Y.shape))[0]) / (2 * h)
    # compare each entry's contribution J_ij y_j with the size of its row's terms
    row_size = (np.abs(J) * col_scale).sum(axis=1)
    return (np.abs(J - J_fd) * col_scale).max(axis=1) / row_size


def hairpin(radius, n=4001, length=1.0):
    """Points (n, 3) of a hairpin of the given length (m): a straight leg up z from the
    origin, a half circle of the given radius (m) bending towards +x, a straight leg back
    down, 2·radius from the first. Its curvature jumps from 0 to 1/radius and back."""
    leg = 0.5 * (length - np.pi * radius)
    pts = np.empty((n, 3))
    for i, x in enumerate(np.linspace(0.0, length, n)):
        if x <= leg:
            pts[i] = (0.0, 0.0, x)
        elif x <= leg + np.pi * radius:
            a = (x - leg) / radius
            pts[i] = (radius * (1.0 - np.cos(a)), 0.0, leg + radius * np.sin(a))
        else:
            pts[i] = (2.0 * radius, 0.0, length - x)
    return pts


def plectoneme_case(n_segments, dt, t_end=9.0):
    """PyElastica's plectoneme example as benchmarks/pyelastica_compare.py sets it up: a
    1-m rod, clamped at s = 0, its s = L end held laterally, free to slide axially and
    turned at 1.257 rad/s; Morison drag, a 1e-4 N/m imperfection, the seed's contact law.
    It buckles at 6.7 s and collapses into a plectoneme at 7.2 s."""
    zero, still = {"velocity": 0.0}, {"angular_velocity": 0.0}
    omega = 2.0 * np.pi * 10 / 50.0
    radius = 0.025
    area = np.pi * radius**2
    spec = {
        "schema_version": 1, "name": "plectoneme",
        "rod": {"length": 1.0, "youngs_modulus": 1e6, "shear_modulus": 1e6 / 1.5,
                "density": 1.0 / area, "diameter": 2 * radius},
        "distributed_forces": [{"value": [1e-4, 0.0, 0.0]}],
        "fluid": {"density": 1000.0, "added_mass_coefficient": 0.0,
                  "drag_coefficient_normal": 0.04,
                  "drag_coefficient_tangential": 0.04 / np.pi},
        "contact": {"aperture": 90.0, "tolerance": 0.1, "k1": 1e-7, "k2": 3.0, "k3": 5.0,
                    "k4": 0.0},
        "boundary": {
            "start": {"translation": [zero] * 3, "rotation": [still] * 3},
            "end": {"translation": [zero, zero, {"force": 0.0}],
                    "rotation": [still, still, {"angular_velocity": {
                        "t": [0.0, 0.5], "value": [0.0, omega]}}]}},
        "numerics": {"n_segments": n_segments, "dt": dt, "t_end": t_end, "rho_inf": 0.5},
        "output": {"every": 1, "fields": ["position", "topology", "contact"]},
    }
    return Case.model_validate(spec)


def thin_plectoneme_case(dt, t_end):
    """The contact suite's thin-rod plectoneme (benchmarks/contact_suite.py): PyElastica's
    plectoneme of :func:`plectoneme_case` with a 1-cm rod (L/D = 100) on 200 segments,
    the search margin twice the diameter; resolved at Δt = 0.02 s."""
    spec = plectoneme_case(200, dt, t_end).model_dump(mode="json")
    spec["rod"]["diameter"] = 0.01
    spec["contact"]["tolerance"] = 0.02
    return Case.model_validate(spec)


def step_jacobian_fd(rod, Y, old, co, prob, eps: float = 1e-7) -> np.ndarray:
    """Central differences (13(N+1), 13(N+1)) of a centreline step's residual
    (:meth:`solver.centreline.CentrelineRod.residual`) at Y (N+1, 13), column by column:
    the oracle of the step's exact Jacobian."""
    fd = np.empty((Y.size, Y.size))
    for j in range(Y.size):
        d = np.zeros(Y.size)
        d[j] = eps
        d = d.reshape(Y.shape)
        fd[:, j] = (rod.residual(Y + d, old, co, prob) - rod.residual(Y - d, old, co, prob)) / (2 * eps)
    return fd


def refused(spec, loc, text):
    """Assert that validating the case mapping ``spec`` fails with an error at ``loc``
    (a tuple, as pydantic's ``loc``) whose message contains ``text``."""
    import pytest
    from pydantic import ValidationError

    with pytest.raises(ValidationError) as info:
        Case.model_validate(spec)
    errors = [e for e in info.value.errors() if e["loc"] == loc]
    assert errors, info.value.errors()
    assert text in errors[0]["msg"], errors[0]["msg"]
