"""Distributed loads per unit length in the body frame (the B of seed eq. 4), each
assembled only when the case has it.

* Morison drag in still fluid (numerics-notes §2.3, WHOI Cable conventions):
  ``B_d = -½ ρ_f D C_dn |v_n| v_n - ½ ρ_f π D C_dt |v_t| v_t`` with v_t = (v·a3) a3 and
  v_n = v - v_t (body frame, a3 = (0, 0, 1)). The added mass is not a load here: it is
  part of the translational mass matrix (see :mod:`solver.properties`).
* Gravity with buoyancy: ``B_g = (ρ - ρ_f) A Rᵀ g`` (ρ_f = 0 without fluid).
* Time-windowed distributed forces given in the global frame: ``B = Rᵀ F(t)`` on
  ``start <= t < end`` and, optionally, on an arclength window ``s0 <= s <= s1``; F(t)
  is ``value`` times the force's ``factor`` table at t (piecewise linear; 1 without one).
* Point loads (``point_loads``): a force P at a node s_k is a jump of the internal
  force, f(s_k⁺) − f(s_k⁻) = −P (integrate f' + κ×f + B = 0, seed eq. 4, across a
  B = P δ(s − s_k)). The unknown f_k is the limit on the side of s = 0 (at s = L: the
  end's condition, the load beyond the rod), and the cell on the other side of the node
  takes the other limit, f_k − P (or f_N + P in the last cell for a load at s = L):
  each cell's box rule then integrates a smooth stretch, so the load is exact, not
  smeared over a cell, and the scheme stays second order in Δs. A load between nodes
  is split over the two nodes of its cell by the lever rule (its resultant and moment
  kept to O(Δs²)). P = Rᵀ P_global for a dead load (orientation at the new level, with
  the derivative below), P as given for a follower (``body: true``).

Orientation-dependent loads are evaluated with the orientation at the new time level
inside Newton; their derivative with respect to ω^{n+1} is ``(Δt_ω)[B]×`` where
``R^{n+1} = R̂ exp(Δt_ω (ω^n + ω^{n+1}))`` (first order in the rotation increment).
"""
from __future__ import annotations

import math

import numba
import numpy as np

from .kinematics import _right_jacobian_into

__all__ = ["LoadModel", "PointLoads", "point_loads_into", "end_reactions"]

#: a point load within this share of Δs of a node acts at that node
NODE_SNAP = 1e-9


def end_reactions(Y, q, stiffness, kappa0=None) -> dict:
    """The loads the surroundings apply to the rod at its ends, global frame (the output
    group ``reactions``): force −R f and moment −R q at s = 0, R f and R q at s = L
    (q = B (κ − κ⁰); the sign convention of :mod:`solver.boundary`), each (3,) N or N m,
    from the unknowns Y (N+1, 12), the frames' quaternions q (N+1, 4), the stiffness
    (N+1, 3) and the intrinsic curvature κ⁰ (N+1, 3) 1/m (None: zero). A point load at
    an end is not part of its reaction (f at s = L is the force beyond the load, at
    s = 0 the one before it: module docstring)."""
    from .kinematics import quat_to_matrix

    R = quat_to_matrix(np.asarray(q, float)[[0, -1]])
    f = np.asarray(Y, float)[[0, -1], 6:9]
    kappa = np.asarray(Y, float)[[0, -1], 9:12]
    if kappa0 is not None:
        kappa = kappa - np.asarray(kappa0, float)[[0, -1]]
    m = np.asarray(stiffness, float)[[0, -1]] * kappa
    return {"reaction_force_start": -(R[0] @ f[0]), "reaction_force_end": R[1] @ f[1],
            "reaction_moment_start": -(R[0] @ m[0]), "reaction_moment_end": R[1] @ m[1]}


class _EndForce:
    """A global dead force on an end free to turn, as a point-load entry: ``at(t)`` the
    global vector (3,) N, sign × the three conditions' values in the phase in force at t
    (``EndCondition.active``'s rule), 0 in a phase that holds the end instead."""

    body = False

    def __init__(self, phases, sign):
        from .case import UNTIL_RTOL

        self.phases = [(None if p[0].until is None else p[0].until * (1.0 + UNTIL_RTOL), p)
                       for p in phases]
        self.sign = sign
        self.value = [1.0, 1.0, 1.0]       # non-zero: the entry is kept

    def at(self, t):
        for until, phase in self.phases:
            if until is None or t <= until:
                break
        if phase[0].kind != "force":
            return np.zeros(3)
        return self.sign * np.array([c.value_at(t) for c in phase])


def _has_end_force(case):
    return any(getattr(ec, "frame", "body") == "global" and ec.rotation_mode == "free"
               and any(c.kind == "force" for c in ec.translation[0])
               for ec in (case.boundary.start, case.boundary.end))


class PointLoads:
    """The case's ``point_loads`` placed on the grid (module docstring, "Point loads").

    Parameters
    ----------
    case : solver.case.Case
    s : (N+1,) float, the grid's arclengths, m

    Attributes
    ----------
    nodes : (m,) intp, the node k each entry acts at (m ≥ the number of loads: a load
        between nodes gives two entries)
    cells : (m,) intp, the cell (0 … N−1) that takes the other limit of f at that node:
        k for k < N, N − 1 for k = N
    side : (m,) float, +1 where the node is the cell's first node (the cell uses
        f_k − P), −1 where it is its last (s = L: the cell uses f_N + P)
    weight : (m,) float, the lever-rule share (1 at a node)
    dead : (m,) bool, the value is global (True) or in the body frame (False)
    any_dead : bool
    """

    def __init__(self, case, s):
        s = np.asarray(s, float)
        n_last = s.size - 1
        ds = float(s[1] - s[0])
        nodes, weights, loads = [], [], []
        # a dead force on an end that is free to turn (frame: global, moment 0): a point
        # load at the end, the internal force's value there (so −F at s = 0: the load
        # applied to the end s = 0 is −f(0), boundary.py)
        for name, node, sign in (("start", 0, -1.0), ("end", n_last, 1.0)):
            ec = getattr(case.boundary, name)
            if (getattr(ec, "frame", "body") == "global" and ec.rotation_mode == "free"
                    and any(c.kind == "force" for c in ec.translation[0])):
                nodes.append(node)
                weights.append(1.0)
                loads.append(_EndForce(list(zip(*ec.translation)), sign))
        for load in case.point_loads:
            if not np.any(np.asarray(load.value, float) != 0):
                continue
            x = min(max(float(load.s) / ds, 0.0), float(n_last))
            k = int(round(x))
            if abs(x - k) <= NODE_SNAP * max(1.0, x):
                parts = ((k, 1.0),)
            else:
                k0 = min(int(math.floor(x)), n_last - 1)
                xi = x - k0
                parts = ((k0, 1.0 - xi), (k0 + 1, xi))
            for node, w in parts:
                nodes.append(node)
                weights.append(w)
                loads.append(load)
        self.loads = loads
        self.nodes = np.array(nodes, dtype=np.intp)
        self.cells = np.where(self.nodes < n_last, self.nodes, n_last - 1).astype(np.intp)
        self.side = np.where(self.nodes < n_last, 1.0, -1.0)
        self.weight = np.array(weights, dtype=float)
        self.base = np.array([np.asarray(ld.value, float) for ld in loads],
                             dtype=float).reshape(-1, 3)
        self.dead = np.array([not ld.body for ld in loads], dtype=np.bool_)
        self.any_dead = bool(self.dead.any())

    def __len__(self):
        return int(self.nodes.size)

    def values(self, t: float, left: bool = False) -> np.ndarray:
        """The entries' forces (m, 3) N at time t (global for dead entries, body frame
        for followers): weight × factor(t) × value on ``start <= t < end`` (``left``:
        ``start < t <= end``, the left limit at a breakpoint), else 0."""
        out = np.zeros((len(self), 3))
        for j, load in enumerate(self.loads):
            if isinstance(load, _EndForce):
                out[j] = load.at(t)
                continue
            end = math.inf if load.end is None else load.end
            if (load.start < t <= end) if left else (load.start <= t < end):
                out[j] = (self.weight[j] * load.scale_at(t)) * self.base[j]
        return out

    def body_values(self, values, q=None, R=None) -> np.ndarray:
        """Body-frame forces (m, 3) N of ``values`` (m, 3) (:meth:`values`): dead entries
        rotated by Rᵀ with the frames R (N+1, 3, 3) of the nodes, or from quaternions q
        (N+1, 4); followers as they are."""
        out = np.array(values, dtype=float)
        if self.any_dead:
            if R is None:
                from .kinematics import quat_to_matrix
                R = quat_to_matrix(np.asarray(q, float)[self.nodes])
            else:
                R = np.asarray(R, float)[self.nodes]
            rot = np.einsum("mji,mj->mi", R, out)
            out[self.dead] = rot[self.dead]
        return out

    def old_level(self, Y_old, body_old, ds: float, af: float) -> np.ndarray:
        """The old level's share (m, 12) of the cell rows, af × [E3: P/Δs − ½σ κ_k×P;
        E4: −½σ a3×P] per entry (σ its ``side``), from the old unknowns Y_old (N+1, 12)
        and the old body-frame forces body_old (m, 3) (:meth:`body_values`); the new
        level's share is :func:`point_loads_into`."""
        out = np.zeros((len(self), 12))
        if af == 0.0:
            return out
        kap = np.asarray(Y_old, float)[self.nodes, 9:12]
        P = np.asarray(body_old, float)
        sg = self.side[:, None]
        out[:, 6:9] = af * (P / ds - 0.5 * sg * np.cross(kap, P))
        a3xP = np.stack([-P[:, 1], P[:, 0], np.zeros(len(self))], axis=1)
        out[:, 9:12] = af * (-0.5 * sg * a3xP)
        return out


@numba.njit(cache=True)
def point_loads_into(Y, Rm, theta, half_dt, ds, af, want_jac, nodes, cells, side, vals, dead,
                     old, rows, blocks, Jr):
    """The point loads' share of the step's cell rows, added into rows (N, 12) and, with
    ``want_jac``, its derivative into the cell blocks (N, 12, 24) (module docstring,
    "Point loads"): per entry j at node k in cell c with side σ,
    E3 += (1 − αf)(P/Δs − ½σ κ_k×P), E4 += −½σ(1 − αf) a3×P, plus the old level's
    share old[j] (12,) (:meth:`PointLoads.old_level`). P = R_kᵀ vals[j] for a dead entry
    (R_k = Rm[k] the new-level frame), vals[j] for a follower. Derivatives: ∂/∂κ_k of
    E3 is ½σ(1 − αf)[P]×; for a dead entry ∂P/∂ω_k = ½Δt [P]× J_r(θ_k) =: L (as the
    distributed loads', :func:`solver.scheme.node_terms_into`), so ∂E3/∂ω_k =
    (1 − αf)(L/Δs − ½σ [κ_k]× L) and ∂E4/∂ω_k = −½σ(1 − αf) [a3]× L.
    Jr: scratch (N+1, 3, 3)."""
    g = 1.0 - af
    for j in range(nodes.shape[0]):
        k = nodes[j]
        c = cells[j]
        sg = side[j]
        if dead[j]:
            p0 = Rm[k, 0, 0] * vals[j, 0] + Rm[k, 1, 0] * vals[j, 1] + Rm[k, 2, 0] * vals[j, 2]
            p1 = Rm[k, 0, 1] * vals[j, 0] + Rm[k, 1, 1] * vals[j, 1] + Rm[k, 2, 1] * vals[j, 2]
            p2 = Rm[k, 0, 2] * vals[j, 0] + Rm[k, 1, 2] * vals[j, 1] + Rm[k, 2, 2] * vals[j, 2]
        else:
            p0, p1, p2 = vals[j, 0], vals[j, 1], vals[j, 2]
        k0, k1, k2 = Y[k, 9], Y[k, 10], Y[k, 11]
        x0 = k1 * p2 - k2 * p1
        x1 = k2 * p0 - k0 * p2
        x2 = k0 * p1 - k1 * p0
        h = 0.5 * sg * g
        rows[c, 6] += g * p0 / ds - h * x0 + old[j, 6]
        rows[c, 7] += g * p1 / ds - h * x1 + old[j, 7]
        rows[c, 8] += g * p2 / ds - h * x2 + old[j, 8]
        rows[c, 9] += h * p1 + old[j, 9]
        rows[c, 10] += -h * p0 + old[j, 10]
        rows[c, 11] += old[j, 11]
        if not want_jac:
            continue
        o = 0 if sg > 0 else 12
        # E3 / κ_k: ½σ(1 − αf)[P]×
        blocks[c, 6, o + 10] += -h * p2
        blocks[c, 6, o + 11] += h * p1
        blocks[c, 7, o + 9] += h * p2
        blocks[c, 7, o + 11] += -h * p0
        blocks[c, 8, o + 9] += -h * p1
        blocks[c, 8, o + 10] += h * p0
        if dead[j]:
            _right_jacobian_into(theta[k, 0], theta[k, 1], theta[k, 2], Jr, k)
            for col in range(3):
                l0 = half_dt * (-p2 * Jr[k, 1, col] + p1 * Jr[k, 2, col])
                l1 = half_dt * (p2 * Jr[k, 0, col] - p0 * Jr[k, 2, col])
                l2 = half_dt * (-p1 * Jr[k, 0, col] + p0 * Jr[k, 1, col])
                blocks[c, 6, o + 3 + col] += g * l0 / ds - h * (k1 * l2 - k2 * l1)
                blocks[c, 7, o + 3 + col] += g * l1 / ds - h * (k2 * l0 - k0 * l2)
                blocks[c, 8, o + 3 + col] += g * l2 / ds - h * (k0 * l1 - k1 * l0)
                blocks[c, 9, o + 3 + col] += h * l1
                blocks[c, 10, o + 3 + col] += -h * l0


class LoadModel:
    """The case's distributed loads on the grid.

    Parameters
    ----------
    case : solver.case.Case
    props : solver.properties.RodProperties
    extra : callable(t, owner) -> (N+1, 3) array or None, optional
        A further global-frame distributed force (N/m) written as code (in-process runs:
        ``integrate(..., extra_force=...)``), evaluated like the case's forces at every
        Newton iterate's time level; ``owner`` (the :class:`~solver.simulation.RodRun`) is
        handed to it so that it may read the last accepted state. None: the case's loads
        only.
    """

    def __init__(self, case, props, extra=None, owner=None):
        self.props = props
        self.extra = extra
        self.owner = owner
        fl = case.fluid
        self.has_drag = fl is not None and (fl.drag_coefficient_normal > 0
                                            or fl.drag_coefficient_tangential > 0)
        if fl is not None:
            self.cdn = 0.5 * fl.density * props.diameter * fl.drag_coefficient_normal
            self.cdt = 0.5 * fl.density * np.pi * props.diameter * fl.drag_coefficient_tangential
            rho_f = fl.density
        else:
            rho_f = 0.0
        # net weight per length (N/m per m/s^2), global-frame forces and windows
        self.gravity = None
        if case.gravity is not None and np.any(np.asarray(case.gravity, float) != 0):
            rho = np.asarray(case.rod.evaluate("density", props.s), float)
            net = (rho - rho_f) * props.area
            self.gravity = net[:, None] * np.asarray(case.gravity, float)[None, :]
        self.forces = []
        for df in case.distributed_forces:
            val = np.asarray(df.value, float)
            if not np.any(val != 0):
                continue
            mask = np.ones_like(props.s, dtype=bool)
            s_range = getattr(df, "s_range", None)
            if s_range is not None:
                s0, s1 = s_range
                mask = (props.s >= s0 - 1e-12) & (props.s <= s1 + 1e-12)
            end = df.end if df.end is not None else np.inf
            self.forces.append((float(df.start), float(end), mask.astype(float), val, df))
        self.has_global = self.gravity is not None or bool(self.forces) or extra is not None
        #: the point loads on the grid, or None without any
        self.points = (PointLoads(case, props.s)
                       if case.point_loads or _has_end_force(case) else None)
        if self.points is not None and len(self.points) == 0:
            self.points = None

    def with_points(self, body, t: float, R=None, left: bool = False):
        """The body-frame distributed load body (N+1, 3) N/m (or None) with the point
        loads at time t added as loads per node length, P/w_k at node k (w the nodal
        quadrature weights, so that Σ w_k B_k·Δx_k is each load's work P·Δx_k): the loads'
        work and power in ``work_in``/``power_in``. R (N+1, 3, 3): the frames that turn
        dead loads into the body frame (None: followers only). Returns body itself
        without point loads."""
        pts = self.points
        if pts is None:
            return body
        out = np.zeros((self.props.s.size, 3)) if body is None else np.array(body, dtype=float)
        if R is None and pts.any_dead:
            return out
        P = pts.body_values(pts.values(t, left=left), R=R) if pts.any_dead else pts.values(t, left=left)
        np.add.at(out, pts.nodes, P / self.props.quad_weights[pts.nodes, None])
        return out

    def global_force(self, t: float, left: bool = False):
        """Global-frame distributed force (N+1, 3) N/m at time t, or None if zero.

        left: the left limit at t (a window counts as ``start < t <= end``), for the step
        that ends on a breakpoint (:mod:`solver.stepping`). Raises ValueError when the
        ``extra`` force returns another shape than (N+1, 3)."""
        out = None
        if self.gravity is not None:
            out = self.gravity.copy()
        for start, end, mask, val, df in self.forces:
            if (start < t <= end) if left else (start <= t < end):
                contrib = (df.scale_at(t) * mask)[:, None] * val[None, :]
                out = contrib if out is None else out + contrib
        if self.extra is not None:
            contrib = self.extra(t, self.owner)
            if contrib is not None:
                contrib = np.asarray(contrib, dtype=float)
                if contrib.shape != self.props.s.shape + (3,):
                    raise ValueError(f"extra_force returned shape {contrib.shape}, expected "
                                     f"{self.props.s.shape + (3,)} (N/m per grid point)")
                out = contrib.copy() if out is None else out + contrib
        return out


@numba.njit(cache=True)
def _drag_kernel(v, cdn, cdt, b, jac, want_jacobian):
    """The Morison drag of the module docstring, as the compiled residual evaluates it
    (:func:`solver.scheme.node_terms_into`, when the case has a fluid with drag):
    B_d = −c_n |v_n| v_n − c_t |v_t| v_t (c_n = ½ρ_f D C_dn, c_t = ½ρ_f πD C_dt per
    node) for body-frame velocities v (N+1, 3) m/s into b (N+1, 3) N/m, and with
    ``want_jacobian`` its derivative into jac (N+1, 3, 3): −c_n (v_n v_nᵀ/|v_n| + |v_n| I)
    on the normal block (0 at v_n = 0), −2 c_t |v_t| on a3; the other entries are left
    as they are (the caller zeroes jac)."""
    for k in range(v.shape[0]):
        v0, v1, vt = v[k, 0], v[k, 1], v[k, 2]
        speed = math.sqrt(v0 * v0 + v1 * v1)
        cs = cdn[k] * speed
        b[k, 0] = -cs * v0
        b[k, 1] = -cs * v1
        b[k, 2] = -cdt[k] * abs(vt) * vt
        if want_jacobian:
            inv = 1.0 / speed if speed > 0 else 0.0
            jac[k, 0, 0] = -cdn[k] * (v0 * v0 * inv + speed)
            jac[k, 0, 1] = -cdn[k] * (v0 * v1 * inv)
            jac[k, 1, 0] = -cdn[k] * (v1 * v0 * inv)
            jac[k, 1, 1] = -cdn[k] * (v1 * v1 * inv + speed)
            jac[k, 2, 2] = -2.0 * cdt[k] * abs(vt)
