"""The data the compiled kernels take, as named tuples: one class per tuple, one field
per array or scalar, each field's shape, units and meaning in its docstring.

numba takes a :class:`typing.NamedTuple` as a kernel argument (a heterogeneous named
tuple type), reads its fields by name (``prm.tolerance``, ``ws.frozen``) at no cost
against a plain tuple, and caches kernels compiled for them (``cache=True``: the classes
live here, at module level, so that numba and pickle find them). The tuples are made in
Python (:class:`solver.newton.NewtonSolver`, :class:`solver.scheme.RodSystem`,
:class:`solver.seabed.SeabedContact`) and handed to the kernels whole; the arrays in them
are the kernels' persistent state or scratch and are written in place, so a tuple is
made once (per run, per step or per reallocation) and never rebuilt in a kernel.

Notation: N the number of cells (N + 1 nodes), n = 12(N + 1) the number of unknowns,
R the number of candidate runs (contact), P the number of active contact pairs; the
unknowns of a node are (v, ω, f, κ) in columns 0-2, 3-5, 6-8, 9-11 (:mod:`solver.scheme`).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["NewtonParams", "LinearSolve", "ExactProduct", "Operator", "GmresWork",
           "NewtonWork", "NewtonCounters"]


# ------------------------------------------------------------------------------ Newton
class NewtonParams(NamedTuple):
    """``prm``: the controls of one Newton solve (:func:`solver.newton._newton_kernel`),
    made by :meth:`solver.newton.NewtonSolver._params` from the solver's attributes."""

    #: convergence: the scaled residual max_i |R_i| r_i at most this (dimensionless)
    tolerance: float
    #: the most Newton iterations of a step
    max_iterations: int
    #: iterations taken even when the start passes the test
    min_iterations: int
    #: contact steps: from this iterate on the closest-point selection is frozen
    freeze_after: int
    #: a correction may close no candidate gap to less than this fraction of itself
    gap_keep: float
    #: contact steps: refactor when the last GMRES solve took more iterations than this
    gmres_refactor: int
    #: GMRES's relative residual at which a solve stops
    gmres_rtol: float
    #: GMRES's iteration limit (the Krylov basis' size)
    gmres_max: int
    #: the share of the node-local contact blocks the preconditioning band LU holds
    contact_band_weight: float
    #: contact steps: the position test's bound on an iterate's position error, m
    #: (0: no position test)
    position_bound: float
    #: contact steps: the scaled residual below which the position test may stop Newton
    position_residual: float


class LinearSolve(NamedTuple):
    """``lin``: the last factorisation of a Newton object and its scales
    (:func:`solver.newton._factor`)."""

    #: the band LU's storage (:func:`solver.banded.block_storage`), factorised in place
    lu: tuple
    #: row scale (n,) of the equilibration (:func:`solver.newton.equilibrate`)
    row_scale: np.ndarray
    #: column scale (12,) per node: the characteristic size of each kind of unknown
    s12: np.ndarray
    #: column scale (n,): s12 repeated on every node
    col_scale: np.ndarray


class ExactProduct(NamedTuple):
    """``ex``: the data of the exact load product at the linearisation point
    (:func:`solver.scheme.exact_loads_product`): the space-route pose's frames, the first
    P contacts and the seabed's linearisation, copied from the residual's buffers by
    :func:`solver.newton._set_operator`. Rows of contact arrays beyond P are stale."""

    #: node frames R (N+1, 3, 3) (body to global)
    R: np.ndarray
    #: per cell the change of δφ across it per unit mid-cell δκ (N, 3, 3)
    C: np.ndarray
    #: per cell the change of the mid-cell rotation δψ per unit δκ (N, 3, 3)
    D: np.ndarray
    #: mid-cell tangents (N, 3)
    tmid: np.ndarray
    #: global node velocities ṙ = R v (N+1, 3), m/s
    rdot: np.ndarray
    #: node 0's rotation per unit δω_0, ½Δt R_0 J_r(θ_0) (3, 3)
    A0: np.ndarray
    #: the global load G (N+1, 3), N/m (contact forces and global-frame loads)
    G: np.ndarray
    #: the node-local load block the band holds, (N+1, 3, 6) on (v, ω)
    L: np.ndarray
    #: the contacts' five nodes (cap, 5) int
    nodes: np.ndarray
    #: the contacts' node weights (cap, 5)
    weights: np.ndarray
    #: the contact forces (cap, 3), N/m
    force: np.ndarray
    #: ∂F/∂r of each contact at its five nodes (cap, 5, 3, 3)
    dF_dr: np.ndarray
    #: ∂F/∂ṙ of each contact at its five nodes (cap, 5, 3, 3)
    dF_dv: np.ndarray
    #: ∂t/∂r of each contact's segment parameter at its five nodes (cap, 5, 3)
    dt_dr: np.ndarray
    #: ∂w/∂t of each contact's node weights (cap, 5)
    dw_dt: np.ndarray
    #: (Δt s, Δs m, αf): the step's size, the grid's, the generalized-α weight (3,)
    scalars: np.ndarray
    #: scratch: δφ (N+1, 3)
    dphi: np.ndarray
    #: scratch: δr (N+1, 3)
    dr: np.ndarray
    #: scratch: δG (N+1, 3)
    dG: np.ndarray
    #: the seabed's touching cells (N,) int, the first ``seabed_count[0]`` valid
    seabed_cells: np.ndarray
    #: how many cells touch the seabed (1,) int
    seabed_count: np.ndarray
    #: the seabed law's partials ∂(F, M)/∂(x, u, Ω, t) per cell (N, 6, 12)
    seabed_partials: np.ndarray
    #: the seabed's cell loads (F, M) (N, 6), N/m and N m/m
    seabed_loads: np.ndarray
    #: each node's global angular velocity R ω (N+1, 3), rad/s
    Romega: np.ndarray
    #: the band's frame change per unit ω^{n+1}, ½Δt R J_r(θ) (N+1, 3, 3), s
    Aphi: np.ndarray


#: ExactProduct's fields sized by the contact capacity (reallocated for more runs)
EXACT_PAIR_FIELDS = ("nodes", "weights", "force", "dF_dr", "dF_dv", "dt_dr", "dw_dt")


class Operator(NamedTuple):
    """``op``: GMRES's operator, the scaled Jacobian at the last residual evaluation
    (:func:`solver.newton._set_operator`, :func:`solver.newton._matvec`)."""

    #: scaled band blocks (N, 12, 24) (rows 6 + 12c + i on nodes c, c + 1)
    blocks: np.ndarray
    #: scaled boundary values (30,): the 12 boundary rows', then per towed end turning
    #: freely the 9 of its translation rows on its ω columns
    bc_scaled: np.ndarray
    #: the load rows' weight ½(1 − αf) r_i (N, 3) of the cell E3 rows
    load_row_weight: np.ndarray
    #: the exact load product's data (:class:`ExactProduct`)
    exact: ExactProduct
    #: (1,) int: 1 where the operator has exact load terms (GMRES solves with it)
    coupled: np.ndarray
    #: (1,) int: the active contacts P in ``exact``
    pairs: np.ndarray


class GmresWork(NamedTuple):
    """``gm``: GMRES's work arrays (:func:`solver.newton._gmres`), m = GMRES_MAX."""

    #: the Krylov basis (m+1, n)
    V: np.ndarray
    #: the preconditioned basis (m, n)
    Z: np.ndarray
    #: the Hessenberg matrix (m+1, m), rotated
    H: np.ndarray
    #: Givens cosines (m,)
    cs: np.ndarray
    #: Givens sines (m,)
    sn: np.ndarray
    #: the rotated right-hand side (m+1,)
    g: np.ndarray
    #: scratch (n,): the new basis vector
    w: np.ndarray
    #: scratch (n,): the preconditioned start
    x0: np.ndarray
    #: scratch (n,): the start's residual
    r: np.ndarray
    #: scratch: the unscaled change of the unknowns (N+1, 12)
    dY: np.ndarray
    #: scratch: the body-frame load change (N+1, 3)
    dB: np.ndarray
    #: scratch: the seabed's cell row change (N, 6)
    dS: np.ndarray


class NewtonWork(NamedTuple):
    """``ws``: a Newton object's work arrays (:func:`solver.newton._newton_kernel`),
    R_cap the candidate runs they have room for."""

    #: the iterate (N+1, 12); the solution when a solve returns
    Y: np.ndarray
    #: the trial iterate (N+1, 12)
    Y_trial: np.ndarray
    #: the correction (n,) (viewed as (N+1, 12))
    delta: np.ndarray
    #: the scaled right-hand side (n,)
    rhs: np.ndarray
    #: the row scale (n,) in which contact stalls are judged
    stall_scale: np.ndarray
    #: the scaled residual per contact iteration (max_it + 2,)
    history: np.ndarray
    #: candidate gaps at the current iterate (R_cap,), m
    gaps0: np.ndarray
    #: candidate gaps at a trial (R_cap,), m
    gaps1: np.ndarray
    #: each run's frozen closest-point combination (R_cap,) int
    frozen: np.ndarray
    #: pose scratch: quaternions (N+1, 4)
    q: np.ndarray
    #: pose scratch: frames (N+1, 3, 3)
    Rm: np.ndarray
    #: pose scratch: positions (N+1, 3), m
    r: np.ndarray
    #: pose scratch: rotation vectors θ (N+1, 3)
    theta: np.ndarray
    #: per iteration (max_it + 2, 4): the scaled residual, the feasibility fraction, the
    #: line-search fraction, GMRES's iterations
    trace: np.ndarray
    #: pose scratch: global velocities ṙ (N+1, 3), m/s
    vg: np.ndarray
    #: the last iterate's positions (N+1, 3), m, for the position test
    r_prev: np.ndarray
    #: how far the last correction moved the positions (1,), m (< 0: unknown)
    moved: np.ndarray


class NewtonCounters(NamedTuple):
    """``ctr``: a Newton object's counters over the run, each a (1,) int64 array that
    the kernels count up in place."""

    #: band LU factorisations
    factorizations: np.ndarray
    #: GMRES iterations
    gmres_iterations: np.ndarray
    #: GMRES solves that did not reach their tolerance
    gmres_failures: np.ndarray
    #: 1 while the last factorisation may be reused, else 0
    factor_valid: np.ndarray

    @classmethod
    def zeros(cls) -> "NewtonCounters":
        return cls(*(np.zeros(1, np.int64) for _ in cls._fields))
