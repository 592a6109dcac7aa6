"""The solver's compiled (numba) kernels, loaded ahead of a timed run.

The hot loops over nodes and pairs are numba kernels in the modules that own them: the
writhe's pair sum (:mod:`solver.topology`); the space route, the right Jacobian, the
quaternion exponential and rotation matrices (:mod:`solver.kinematics`); the node terms
of seed eqs. 2-5 with their Jacobian, the cell rows and blocks of the step's equations,
the contact loads with their band blocks and the exact contact load product with its
pose data (:mod:`solver.scheme`); the Morison drag (:mod:`solver.loads`); the scaling of the
Jacobian's blocks and GMRES's operator product (:mod:`solver.newton`); the candidate
search and the closest points (:mod:`solver.contact.geometry`) and the contact forces'
derivatives (:mod:`solver.contact.model`); the static Jacobian's band, the static cell
rows and the band product (:mod:`solver.static_band`). They are compiled once per
installation and cached on disk (``cache=True``; 91 s on an idle 2-core AMD EPYC,
measured by ``python -m benchmarks.compile_time``, which also says where the time goes;
1.9 s once cached); ``hockle run`` and ``hockle worker`` say when they compile and how
long it took. A process still loads each kernel from the cache at its first call, about
1 s in all. :func:`warm_up` does that at once, for benchmarks that time single runs and for
processes that serve many short ones.
"""
from __future__ import annotations

import numpy as np

__all__ = ["warm_up"]


def warm_up() -> None:
    """Load every compiled kernel once, so that later runs in this process start at once.

    Runs the code paths a run takes: a few steps of a small rod with fluid, a distributed
    force and self-contact configured, a step of the same rod on the sea floor, and one
    contact-coupled Newton solve with candidates set by hand. The first call after an
    installation compiles the kernels into numba's cache (minutes); later ones load them
    (about a second). Pure (no I/O of its own besides numba's cache); raises nothing on a
    working installation."""
    from .case import Case
    from .contact import point_curve, point_segment, smoothstep_off
    from .contact.geometry import run_minima
    from .kinematics import quat_slerp, right_jacobian
    from .run import RodRun
    from .energies import energies
    from .topology import PARALLEL_SEGMENTS, twist, writhe

    run = RodRun(Case.model_validate(_warm_up_spec()))
    for k in range(1, 4):
        run.advance(0.01 * k)
    # the sea floor's kernels outside the residual (the old level's loads, the cells'
    # loads and penetrations of the outputs): the rod laid on a flat bottom
    bottom = _warm_up_spec()
    del bottom["contact"]
    bottom["seabed"] = {"elevation": -0.0101}
    bottom["initial"] = {"tangent": [1.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}
    RodRun(Case.model_validate(bottom)).advance(0.01)
    # a contact-coupled solve (candidates by hand: the contact kernels and GMRES)
    contact = run.contact
    cand = contact._runs(np.array([0, 0, 8], np.intp), np.array([3, 4, 4], np.intp))
    sysm = run.system
    st = run.state
    sysm.begin_step(0.01, run.assembly.params, st.t + 0.01, st.Y, st.Ydot, st.F_old, st.bc,
                    q_old=st.q, r_old=st.r, v_old_global=st.v_global, candidates=cand)
    run.newton.feasible_start(run.state.Y)
    pose = run.newton.solve(run.state.Y)[5]
    sysm.contact_summary(pose[2], run.state.v_global, False)
    sysm.summary_potential(pose[2])                      # the energy check's contact account
    sysm.residual(run.state.Y, want_jacobian=True)
    sysm.candidate_gaps(run.state.Y)
    contact.evaluate(cand, run.state.r, run.state.v_global)
    contact.closest(cand, run.state.r)
    contact.closest(cand, run.state.r, np.zeros(cand.runs, np.intp))
    writhe(run.state.r)
    twist(run.state.Y[:, 11], run.props.s)
    energies(run.state.Y, run.props)
    # the writhe of a long rod sums its pairs on all cores (solver.topology)
    writhe(np.column_stack([np.cos(np.arange(PARALLEL_SEGMENTS + 1.0)), np.sin(
        np.arange(PARALLEL_SEGMENTS + 1.0)), np.arange(PARALLEL_SEGMENTS + 1.0)]))
    _warm_up_search(contact, cand)
    # the error filter of error-controlled steps (the inertia's cell rows, the band LU)
    run.newton.filtered(run.state.Y)
    # the Python faces of the kernels that runs without contact or with dense output use
    run.update_space_route()
    quat_slerp(run.state.q[0], run.state.q[-1], 0.5)
    right_jacobian(np.ones((2, 3)))
    point_segment(run.state.r[:2], run.state.r[1:3], run.state.r[2:4])
    point_curve(run.state.r[:2], run.state.r, np.array([2, 3], np.intp))
    run_minima(run.state.r, cand.owner, cand.segment, cand.run_start)
    law = contact.law
    d = np.array([0.021, 0.03])
    law(d, np.zeros(2), np.full(2, 0.02), np.ones(2))
    law.repulsion(d - 0.02)
    law.cutoff(np.full(2, 0.02))
    law.potential(d, np.full(2, 0.02))                   # the energy check's contact account
    contact.potential(cand, run.state.r)
    smoothstep_off(d, np.full(2, 0.02), np.full(2, 0.04))
    # statics: the band Jacobian, the compiled residual and the band LU's product
    from . import statics
    from .static_band import BorderedBandLU
    prob = statics.uniform(1.0, 4, (1.0, 1.0, 0.8), statics.clamp([0, 0, 0], [1, 0, 0, 0]),
                           statics.free_end([0.1, 0.0, 0.0]))
    sol = statics.solve(prob)
    lu = BorderedBandLU(statics.band_jacobian(sol.Y, prob), np.ones(sol.Y.size),
                        np.ones(sol.Y.size))
    lu.solve(np.ones(sol.Y.size + 1))
    _warm_up_centreline(bottom)


def _warm_up_centreline(spec) -> None:
    """The centreline scheme's kernels (nodal loads, kinematics, rounding level) for
    :func:`warm_up`: a step of the rod of ``spec`` (a case's dict, on the bottom)."""
    from .case import Case
    from .centreline import CentrelineRod

    spec["numerics"]["formulation"] = "centreline"
    rod = CentrelineRod.from_case(Case.model_validate(spec))
    rod.step(rod.start(), 0.01)


def _warm_up_search(contact, cand) -> None:
    """The contact search's kernels for :func:`warm_up`: on a hairpin (the candidates,
    merge, coverage, the swept distances) and on a helix longer than ALL_PAIRS_NODES (the
    blocked k-d tree's pairs, and what the search and the tunnelling check do with
    them). contact: the warm-up run's SelfContact; cand: candidates of its grid."""
    from .contact import swept_min_distance
    from .contact.geometry import ALL_PAIRS_NODES, close_node_pairs
    from .contact.model import _search_kernel, _swept_any_within, _swept_reach

    # the search on a hairpin (a k-d tree's pairs, the cones, the runs, merge, coverage)
    s = np.linspace(0.0, 1.0, 9)
    hairpin = np.column_stack([np.where(s < 0.5, s, 1.0 - s), np.where(s < 0.5, 0.0, 0.03),
                               np.zeros(9)])
    tangents = np.gradient(hairpin, axis=0)
    found = contact.candidates(hairpin, tangents, 0.01)
    if contact.may_touch(hairpin, tangents) and found.runs:
        contact.covers(contact.merge(found, cand), found)
    contact.search(hairpin, tangents, 0.01)
    swept_min_distance(hairpin, hairpin, np.array([0], np.intp), np.array([8], np.intp))
    contact.passes_through(hairpin, hairpin * [1.0, -1.0, 1.0])   # one leg through the other
    # the blocked k-d tree search of a longer grid (a helix, blocks of 5 nodes)
    nh = ALL_PAIRS_NODES + 72
    sh = np.linspace(0.0, 1.0, nh)
    helix = np.column_stack([0.02 * np.cos(40.0 * sh), 0.02 * np.sin(40.0 * sh), 0.05 * sh])
    a, b = close_node_pairs(helix, 5.5 * (sh[1] - sh[0]), sh, 0.1)
    # what the search and the tunnelling check do with such a grid's pairs (on grids of at
    # most ALL_PAIRS_NODES nodes they are parts of one compiled call)
    _search_kernel(helix, np.gradient(helix, axis=0), a, b, sh, 0.1, 1.0, np.inf)
    moved, dh = helix + [0.0, 0.0, 0.001], np.full(nh, 0.02)
    _swept_reach(helix, moved, sh, dh, 0.1)
    _swept_any_within(helix, moved, a, b, dh, sh, 0.1, np.inf)


def _warm_up_spec() -> dict:
    """The small case :func:`warm_up` runs: 8 segments with fluid, a distributed force,
    a twisted start, a sliding end, self-contact and the growth guard."""
    return {
        "schema_version": 1, "name": "warm-up",
        "rod": {"length": 1.0, "youngs_modulus": 1.25e7, "shear_modulus": 5.0e6,
                "density": 1500.0, "diameter": 0.02},
        "fluid": {"density": 1000.0, "added_mass_coefficient": 1.0,
                  "drag_coefficient_normal": 1.2, "drag_coefficient_tangential": 0.02},
        "distributed_forces": [{"value": [1e-5, 0.0, 0.0], "start": 0.0, "end": 1.0}],
        "boundary": {
            "start": {"translation": [{"velocity": 0}] * 3,
                      "rotation": [{"angular_velocity": 0}, {"angular_velocity": 0},
                                   {"angular_velocity": 1.0}]},
            "end": {"translation": [{"velocity": 0}, {"velocity": 0}, {"force": 0}],
                    "rotation": [{"angular_velocity": 0}] * 3}},
        "contact": {"aperture": 180.0, "tolerance": 0.04, "k1": 1e-7, "k2": 3.0,
                    "k3": 1e-6, "k4": 1.0},
        "numerics": {"n_segments": 8, "dt": 0.01, "t_end": 0.03, "growth_guard": 0.5},
    }
