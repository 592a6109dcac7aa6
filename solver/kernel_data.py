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

__all__ = ["BandFactor", "NewtonParams", "LinearSolve", "ExactProduct", "Operator", "GmresWork",
           "NewtonWork", "NewtonCounters", "SeabedData", "RodData", "StepData",
           "ResidualBuffers", "CandidateArrays", "ContactData", "EvaluationArrays"]


# ------------------------------------------------------------------------- the residual
class SeabedData(NamedTuple):
    """``seabed``: the sea floor on the grid as the kernels of :mod:`solver.seabed` take
    it (:attr:`solver.seabed.SeabedContact.data`; :data:`solver.seabed.NO_SEABED` without
    a seabed: kind 0)."""

    #: (10,): kind (0 none, 1 flat, 2 grid), elevation m (flat), normal stiffness k Pa,
    #: normal damping c Pa s, axial and lateral friction coefficients μa, μl, static to
    #: kinetic ratio, slip velocity m/s, top m (the highest bottom point), slope factor
    #: max √(1 + hx² + hy²)
    scalars: np.ndarray
    #: the rod's radius at the nodes (N+1,), m
    radius: np.ndarray
    #: the bathymetry grid's x (nx,), m
    grid_x: np.ndarray
    #: the bathymetry grid's y (ny,), m
    grid_y: np.ndarray
    #: the bathymetry's elevation z (nx, ny), m
    grid_z: np.ndarray
    #: the old level's share of the cell rows (N, 12), frozen at the step's start
    old_rows: np.ndarray
    #: the damper's branch held per cell (N,) (−1 the law's, 0, 1, 2)
    modes: np.ndarray
    #: the control of the held branches (8,)
    #: (:meth:`solver.seabed.SeabedContact.freeze_control`)
    hold: np.ndarray


class RodData(NamedTuple):
    """``rod``: the run's constant data as :func:`solver.scheme.residual_into` takes it
    (:attr:`solver.scheme.RodSystem.rod_data`)."""

    #: translational mass per unit length (N+1, 3) (ρA with the fluid's added mass
    #: across the axis, ρA along it), kg/m
    mass_t: np.ndarray
    #: the bending and torsion stiffnesses EJ1, EJ2, GJ3 (N+1, 3), N m²
    stiffness: np.ndarray
    #: rotary inertia per unit length ρJ1, ρJ2, ρJ3 (N+1, 3), kg m
    inertia: np.ndarray
    #: the Morison drag's normal coefficient per node (N+1,) (zeros without drag)
    cdn: np.ndarray
    #: the Morison drag's tangential coefficient per node (N+1,) (zeros without drag)
    cdt: np.ndarray
    #: the column scale's floors (12,): the characteristic size of each kind of unknown
    floor: np.ndarray
    #: the segment length Δs, m
    ds: float
    #: whether the Morison drag acts (a fluid)
    has_drag: bool
    #: whether the pose is the space route (self-contact configured)
    space: bool
    #: the sea floor (:class:`SeabedData`)
    seabed: SeabedData


class StepData(NamedTuple):
    """``step``: one time step's data as :func:`solver.scheme.residual_into` takes it,
    made by :meth:`solver.scheme.RodSystem.begin_step` (``RodSystem.step.data``)."""

    #: the old level Y^n (N+1, 12)
    Y_old: np.ndarray
    #: the old level's part of the cell rows ½(M·cY + αf F^n) (N+1, 12)
    zconst: np.ndarray
    #: αf K Y^n (N+1, 12)
    flux_const: np.ndarray
    #: the global-frame load at t_new (N+1, 3), N/m ((0, 3) without one)
    glob: np.ndarray
    #: the old orientations q^n (N+1, 4) (zeros without an old pose)
    q_old: np.ndarray
    #: the old positions r^n (N+1, 3), m (zeros without an old pose)
    r_old: np.ndarray
    #: the old global velocities ṙ^n (N+1, 3), m/s (zeros without an old pose)
    vg_old: np.ndarray
    #: the boundary rows (12,) int
    bc_rows: np.ndarray
    #: the boundary rows' unknowns (12,) int (node · 12 + column)
    bc_cols: np.ndarray
    #: the boundary rows' coefficients (12,)
    bc_coef: np.ndarray
    #: the boundary rows' values at t_new (12,)
    bc_vals: np.ndarray
    #: the step Δt, s
    dt: float
    #: the generalized-α coefficient cm = (1 − αm)/(γΔt), 1/s
    cm: float
    #: the generalized-α weight αf of the old level
    af: float
    #: whether a global-frame load acts (``glob``)
    has_glob: bool
    #: whether the old pose r^n, ṙ^n is given
    has_r_old: bool
    #: whether the run needs the new-level pose (RodSystem.needs_pose)
    needs_pose: bool
    #: whether the end at s = 0 is towed in the global frame with its rotation free
    turning_start: bool
    #: whether the end at s = L is towed in the global frame with its rotation free
    turning_end: bool
    #: the point loads' nodes (m,) int (:func:`solver.loads.point_loads_into`)
    pl_nodes: np.ndarray
    #: the point loads' cells (m,) int
    pl_cells: np.ndarray
    #: the point loads' side of their cell (m,)
    pl_side: np.ndarray
    #: the point loads' values at t_new (m, 3), N
    pl_vals: np.ndarray
    #: whether each point load is dead (global frame) (m,) bool
    pl_dead: np.ndarray
    #: the point loads' old-level share of the cell rows (m, 12)
    pl_old: np.ndarray


class ResidualBuffers(NamedTuple):
    """``buf``: the output and scratch buffers of :func:`solver.scheme.residual_into`
    (:meth:`solver.scheme.RodSystem.buffers`), written at every evaluation."""

    #: the residual (n,)
    R: np.ndarray
    #: the residual's cell rows, a view of ``R`` (N, 12)
    cells: np.ndarray
    #: the node terms F (N+1, 12)
    Fn: np.ndarray
    #: their Jacobian ∂F/∂Y (N+1, 12, 12)
    dF: np.ndarray
    #: the Jacobian's cell blocks (N, 12, 24) on [node c | node c + 1]
    blocks: np.ndarray
    #: the new-level pose: quaternions (N+1, 4)
    q: np.ndarray
    #: the new-level frames (N+1, 3, 3)
    Rm: np.ndarray
    #: the new-level positions (N+1, 3), m
    r: np.ndarray
    #: the rotation increments θ (N+1, 3)
    theta: np.ndarray
    #: the global velocities ṙ = R v (N+1, 3), m/s
    vg: np.ndarray
    #: the global load G (N+1, 3), N/m (contact forces and global-frame loads)
    G: np.ndarray
    #: the node-local contact block (N+1, 3, 6) on (v, ω)
    diag: np.ndarray
    #: the rotated load's block on ω, ½Δt [B]× J_r(θ) (N+1, 3, 3)
    loadrot: np.ndarray
    #: the body-frame load B = Rᵀ G (N+1, 3), N/m
    brot: np.ndarray
    #: the exact product's C (N, 3, 3) (:class:`ExactProduct`)
    C: np.ndarray
    #: the exact product's D (N, 3, 3)
    D: np.ndarray
    #: the mid-cell tangents (N, 3)
    tmid: np.ndarray
    #: ṙ for the exact product (N+1, 3), m/s
    rdot: np.ndarray
    #: node 0's rotation per unit δω_0 (3, 3)
    A0: np.ndarray
    #: the node-local load block the band holds (N+1, 3, 6)
    L: np.ndarray
    #: scratch: the drag (N+1, 3)
    drag_b: np.ndarray
    #: scratch: the drag's Jacobian (N+1, 3, 3)
    drag_j: np.ndarray
    #: scratch: right Jacobians J_r(θ) (N+1, 3, 3)
    Jr: np.ndarray
    #: the seabed's touching cells (N,) int (:func:`solver.seabed.seabed_into`'s ``lin``)
    seabed_cells: np.ndarray
    #: how many cells touch the seabed (1,) int
    seabed_count: np.ndarray
    #: the seabed law's partials per touching cell (N, 6, 12)
    seabed_partials: np.ndarray
    #: the seabed's cell loads (F, M) (N, 6), N/m and N m/m
    seabed_loads: np.ndarray
    #: each node's global angular velocity R ω (N+1, 3), rad/s
    Romega: np.ndarray
    #: the band's frame change per unit ω^{n+1}, ½Δt R J_r(θ) (N+1, 3, 3), s
    Aphi: np.ndarray
    #: the towed ends' blocks ∂(v − RᵀV)/∂ω^{n+1} (2, 3, 3)
    bc_jac: np.ndarray
    #: (4,) int: [0 ok, 1 non-finite positions, 2 coincident contact points; the active
    #: contacts P; the pose computed; the exact product's data computed]
    flags: np.ndarray


# ------------------------------------------------------------------------------ Newton
class BandFactor(NamedTuple):
    """``lu``: the storage of the band LU of :mod:`solver.banded`
    (:func:`~solver.banded.block_storage`, factorised by
    :func:`~solver.banded.block_factor`, applied by :func:`~solver.banded.block_solve`)."""

    #: the windows' first 12 columns after elimination (N, 18, 12): U's upper triangle in
    #: rows 0-11, the multipliers below
    LW: np.ndarray
    #: U's entries on node k + 1 (N, 12, 12)
    UR: np.ndarray
    #: the row interchanges of each window (N, 12) int
    piv: np.ndarray
    #: the last window's LU (12, 12)
    LF: np.ndarray
    #: the last window's row interchanges (12,) int
    pivf: np.ndarray
    #: work array: a window (18, 24)
    W: np.ndarray
    #: work array: a window's right-hand side (18,)
    w: np.ndarray


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

    #: the band LU's storage (:class:`BandFactor`), factorised in place
    lu: BandFactor
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


# ------------------------------------------------------------------------ self-contact
class CandidateArrays(NamedTuple):
    """``cand``: a step's contact candidates as the kernels take them
    (:attr:`solver.contact.ContactCandidates.arrays`; empty arrays without candidates):
    M owner-node / partner-segment combinations in R runs."""

    #: the owner node of each combination (M,) int
    owner: np.ndarray
    #: the partner segment k (nodes k, k + 1) of each combination (M,) int
    segment: np.ndarray
    #: where each run begins in owner / segment (R,) int
    run_start: np.ndarray
    #: whether each run's first outer vertex is a rod end (R,) bool
    first_is_end: np.ndarray
    #: whether each run's last outer vertex is a rod end (R,) bool
    last_is_end: np.ndarray


class ContactData(NamedTuple):
    """``cdata``: the self-contact model's constant data
    (:attr:`solver.contact.SelfContact.kernel_data`; zero-length arrays without
    self-contact)."""

    #: every segment's four curve nodes (N, 4) int
    seg_nodes: np.ndarray
    #: every segment's curve matrix (N, 4, 4)
    seg_mats: np.ndarray
    #: the diameter at the nodes (N+1,), m
    diameter: np.ndarray
    #: mass per unit length ρA at the nodes (N+1,), kg/m
    rho_a: np.ndarray
    #: the nodal weights Δs_i (N+1,), m
    weights: np.ndarray
    #: the contact law's parameter vector (9,) (:attr:`solver.contact.laws._Law.params`)
    law: np.ndarray


class EvaluationArrays(NamedTuple):
    """``ev``: the work arrays of :func:`solver.contact.model.evaluate_into` with room for
    R_cap runs (:func:`solver.contact.model.evaluation_arrays`): one contact at most per
    run, the first P entries of the per-contact arrays valid after an evaluation."""

    #: each run's selected combination (R_cap,) int
    selection: np.ndarray
    #: per contact: the owner node i (R_cap,) int
    owner: np.ndarray
    #: per contact: the partner segment j (R_cap,) int
    segment: np.ndarray
    #: per contact: the partner point's parameter t on its segment (R_cap,)
    t: np.ndarray
    #: per contact: its five nodes (owner, the partner curve's four) (R_cap, 5) int
    nodes: np.ndarray
    #: per contact: the load weights of its nodes (R_cap, 5)
    weights: np.ndarray
    #: per contact: the coefficients c_a of x = Σ c_a r_a (R_cap, 5)
    coef: np.ndarray
    #: per contact: the force F on the owner (R_cap, 3), N/m
    force: np.ndarray
    #: per contact: ∂F/∂r_a (R_cap, 5, 3, 3)
    dF_dr: np.ndarray
    #: per contact: ∂F/∂v_a (R_cap, 5, 3, 3)
    dF_dv: np.ndarray
    #: per contact: ∂t/∂r_a (R_cap, 5, 3)
    dt_dr: np.ndarray
    #: per contact: ∂w_a/∂t (R_cap, 5)
    dw_dt: np.ndarray
    #: per contact: the surface gap (R_cap,), m
    gap: np.ndarray
    #: per contact: the centreline distance d (R_cap,), m
    distance: np.ndarray
    #: per run: the surface gap of its closest point (R_cap,), m (inf at an interior run
    #: edge)
    run_gap: np.ndarray
