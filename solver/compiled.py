"""The solver's compiled (numba) kernels, loaded ahead of a timed run.

The hot loops over nodes and pairs are numba kernels in the modules that own them: the
writhe's pair sum (:mod:`solver.topology`); the space route, the right Jacobian, the
quaternion exponential and rotation matrices (:mod:`solver.kinematics`); the node terms
of seed eqs. 2-5 with their Jacobian, the cell rows and blocks of the step's equations,
the contact loads with their band blocks and the exact contact load product with its
pose data (:mod:`solver.scheme`); the Morison drag (:mod:`solver.loads`); the scaling of the
Jacobian's blocks and GMRES's operator product (:mod:`solver.newton`); the candidate
search and the closest points (:mod:`solver.contact.geometry`) and the contact forces'
derivatives (:mod:`solver.contact.model`). They are compiled once per installation and
cached on disk (``cache=True``; about 15 s on the development machine, measured on a
fresh clone); a process still loads each from the cache at its first call, about 1 s in
all. :func:`warm_up` does that at once, for benchmarks that time single runs and for
processes that serve many short ones.
"""
from __future__ import annotations

import numpy as np

__all__ = ["warm_up"]


def warm_up() -> None:
    """Call every compiled kernel once on small arrays of the types the solver passes,
    so that later calls in this process run at once. Pure (no I/O of its own besides
    numba's cache). Raises nothing on a working installation."""
    from .contact.geometry import (candidate_pairs, point_curve, point_segment, run_closest,
                                   run_minima)
    from .contact.model import _force_derivatives, _relative_motion
    from .kinematics import quat_exp, quat_to_matrix, right_jacobian, space_route
    from .loads import _drag_kernel
    from .newton import _NO_LOAD_ROWS, _matvec_kernel, _scale_blocks_kernel
    from .scheme import (_NO_PAIRS, _add_inertia_kernel, _apply_M_kernel, _cell_blocks_kernel,
                         _cells_kernel, _contact_band_kernel, _contact_loads_kernel,
                         _exact_frames_kernel, _exact_loads_kernel, _flux_kernel,
                         _node_forces_kernel, _node_jacobian_kernel)
    from .topology import writhe

    n = 8
    rng = np.random.default_rng(0)
    kappa = rng.normal(size=(n, 3))
    q, r = space_route(quat_exp(np.array([0.1, 0.2, 0.3])), np.zeros(3), kappa, 0.1)
    writhe(r)
    quat_to_matrix(q)
    J = right_jacobian(kappa)
    j = np.arange(n - 1, dtype=np.intp)
    point_segment(r[:-1], r[:-1], r[1:])
    point_curve(r[:-1], r, j)
    run_minima(r, np.zeros(n - 1, dtype=np.intp), j, np.array([0, 3], dtype=np.intp))
    candidate_pairs(r, r, 1.0, np.arange(n, dtype=float), 0.5, 0.7)
    run_closest(r, np.zeros(n - 1, dtype=np.intp), j, np.array([0, 3], dtype=np.intp))
    run_closest(r, np.zeros(n - 1, dtype=np.intp), j, np.array([0, 3], dtype=np.intp),
                np.array([1, 4], dtype=np.intp))
    Y = rng.normal(size=(n, 12))
    ones = np.ones((n, 3))
    dF = np.empty((n, 12, 12))
    _node_jacobian_kernel(Y, ones, ones, ones, dF)
    Fn = np.empty((n, 12))
    _node_forces_kernel(Y, ones, ones, ones, Fn)
    _cells_kernel(Y, Fn, Fn, Fn, ones, ones, ones, 1.0, 0.5, 0.1, np.empty((n - 1, 12)))
    _apply_M_kernel(Y, ones, ones, np.empty((n, 12)))
    _flux_kernel(Y, ones, np.empty((n, 12)))
    blocks = np.empty((n - 1, 12, 24))
    _cell_blocks_kernel(dF, ones, ones, ones, 1.0, 0.5, 0.1, blocks)
    _add_inertia_kernel(blocks, 1.0, ones, ones)
    _scale_blocks_kernel(blocks, np.ones(12 * n), np.ones(12), np.empty_like(blocks))
    x = np.ones(12 * n)
    _matvec_kernel(blocks, x, np.ones((n - 1, 3)), np.ones((n, 3)), np.empty(12 * n))
    _matvec_kernel(blocks, x, _NO_LOAD_ROWS, _NO_LOAD_ROWS, np.empty(12 * n))
    _drag_kernel(Y[:, :3].copy(), np.ones(n), np.ones(n), np.empty((n, 3)),
                 np.empty((n, 3, 3)), True)
    R = np.ascontiguousarray(np.broadcast_to(np.eye(3), (n, 3, 3)))
    args = (Y, np.eye(3), J[1:].copy(), J[1:].copy(), R, r.copy(), r[1:].copy(), r.copy(),
            np.zeros((n, 3, 6)), 0.1, 0.1)
    _exact_loads_kernel(*args, *_NO_PAIRS)
    _exact_frames_kernel(R, Y, kappa, 0.1, 0.1, np.empty((n - 1, 3, 3)),
                         np.empty((n - 1, 3, 3)), np.empty((n - 1, 3)), np.empty((n, 3)),
                         np.empty((3, 3)))
    p = 2
    _exact_loads_kernel(*args, np.zeros((p, 5), np.intp), np.zeros((p, 3, 30)),
                        np.zeros((p, 15)), np.zeros((p, 3)), np.zeros((p, 5)),
                        np.zeros((p, 5)))
    # the contact's relative motion, force derivatives and node loads: two pairs, 5 nodes
    nodes = np.array([[0, 2, 3, 4, 5], [1, 3, 4, 5, 6]], dtype=np.intp)
    c5 = np.ones((p, 5))
    x3 = np.ones((p, 3))
    one = np.ones(p)
    n3, u3, ddot, ut = _relative_motion(x3, one, c5, c5, nodes, r)
    out = _force_derivatives(n3, u3, ddot, ut, one, one, one, one, c5, c5, x3, x3, one,
                             0.5 * one, np.ones(n), nodes)
    _contact_loads_kernel(nodes, out[4], out[0], np.zeros((n, 3)))
    _contact_band_kernel(nodes, out[4], out[1], out[2], R, Y, J, 0.1, np.zeros((n, 3, 6)))
