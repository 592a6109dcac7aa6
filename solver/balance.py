"""The energy balance of one step: is a converged step right, or did it inject energy?

Generalized-α is unconditionally stable for *linear* systems, where its algorithmic
dissipation is non-negative (Chung & Hulbert 1993, § 4; ρ∞ = 1 conserves the energy of
a linear system exactly). The rod is not linear, and a large step of a strongly
nonlinear motion can converge to a state with more energy than the loads put in: the
steel cantilever of docs/numerics.md § 8 at Δt = 0.1 s gains up to 135 J in a step of a
185-J motion and never settles. This module measures each converged step's imbalance

    ε = E(Y^{n+1}) − E(Y^n) − Σ_a W_a            (J)

with E the rod's energy (:func:`solver.energies.energies`: bending, torsion, kinetic
with the added mass) and W_a the work put in over the step by each force of the list
:attr:`EnergyBalance.accounts` (:class:`WorkAccount`). The scheme's own dissipation
(ρ∞ < 1) and the fluid's drag only make ε negative, so the check is one-sided: a step
with ε > ``numerics.energy_tolerance`` × the energy scale is refused with the reason
``"energy"`` (:meth:`solver.run.RodRun._refusal`), and the step control cuts Δt.

The accounts (each one more term; a new force joins the balance by one more
:class:`WorkAccount` in :meth:`EnergyBalance.for_run`):

* :class:`EndWork`: the end loads (force and moment at s = 0 and s = L, body frame),
  Σ ½(F^n + F^{n+1})·Δx with the end sections' displacement increments by the scheme's
  generalized-α relation (:func:`solver.energies.end_work_into`); where the global loads
  are measured on a pose (next item), only the end moments, the end forces being
  measured on that same pose;
* :class:`GlobalLoadWork`: distributed global-frame forces (gravity with buoyancy,
  ``distributed_forces``, an ``extra_force``) and point loads (dead or follower), in the
  **global** frame, Σ_k w_k ½(G_k^n + G_k^{n+1})·Δr_k with Δr_k the change of the
  centreline integrated from κ, and the end forces turned to the global frame on the
  same centreline's end displacements. One pose for all forces: where an end is held in
  position, its reaction does work on the κ-integrated end, which drifts from the hold
  (the soft hanging cable of research/loads_verification.py: gravity's work alone on
  the κ-shape read ε = 200 T in a step and refused every Δt down to 5e-5 s at t = 3 ms).
  Where the s = L end is held in position the shape is turned rigidly about node 0 so
  that its chord points at the end's prescribed position (:meth:`GlobalLoadWork.turned`):
  integrated from κ its end still jumps off the hold as the shape turns about node 0
  (the cable at Δt = 0.1 s read ε = 8.4 T in its first measured step and ended 1.3 %
  off at tolerance 0.5; turned, it is never refused and its answer is the unchecked
  one).
  With a seabed (and no self-contact) the pose is each node's time route, the one the
  seabed acts on, so that gravity and the spring holding the rod up are measured on one
  pose (mixing the two, Newton's noise in a cable resting on the bottom read up to
  0.2 T). The body-frame account of ``work_in``
  (:func:`solver.energies.distributed_work_into` on body-frame loads and velocities) is
  not usable here: at large steps the frames turn within the step and its sum drifts
  (the cantilever at Δt = 0.1 s: 1012 J of work against 179 J of energy at rest, where
  the global account gives 178 J);
* :class:`DragWork`: the Morison drag (body frame, on the body-frame velocities);
* :class:`SeabedWork`: the sea floor's normal spring, minus the change of its stored
  energy ½kp² on the pose the seabed acts on (each node's time route; the space route
  with self-contact). The damper and the friction only dissipate and are left out, as
  the scheme's own dissipation is;
* :class:`ContactWork`: the self-contact law's repulsion, minus the change of its
  stored energy U_c (:meth:`solver.contact.model.SelfContact.potential`) with the
  step's candidates on the space route; the law's damping only dissipates and is left
  out.

The consistent restart's backward-Euler steps are not checked (their dissipation is
first order).

The check is on by default at ``numerics.energy_tolerance`` = 0.5, the lowest tolerance
that leaves the right cantilever at Δt = 0.02 s unrefused while every Δt up to 0.2 s
settles within 0.1 % of the elastica; measured on the right runs it leaves their answers
as they are, at a cost where a settling motion is resolved by a few steps per period
(the hanging cable at Δt = 0.2 s: 6.3× the Newton iterations; docs/numerics.md § 8,
``research/energy_check.py``).

Everything a step carries to the next (the energy of the level, each account's old
forces and displacement rates) is kept in the run's state
(:attr:`solver.state.RunState.balance`, a dict rebound at every accepted step), so a
refused or rolled-back step leaves it as it was. Restarts are not measured; the step
after one starts the accounts afresh from its old level (:meth:`EnergyBalance.start`;
the displacement rates of the drag's account then start at the velocities).
"""
from __future__ import annotations

import math
from typing import NamedTuple, Optional

import numba
import numpy as np

from .banded import true_at_run_time
from .energies import distributed_work_into, end_work_into, total_and_kinetic
from .kinematics import (_matrix_into, normalize_quaternions, quat_exp, quat_multiply,
                         quat_to_matrix, rotate_rows, space_route)
from .scheme import pose_into
from .loads import _drag_kernel

__all__ = ["EnergyBalance", "WorkAccount", "EndWork", "GlobalLoadWork", "DragWork",
           "SeabedWork", "ContactWork", "StepBalance", "CentrelineBalance"]


class StepBalance(NamedTuple):
    """One converged step's balance: error ε (J, > 0: energy injected), the energy scale
    it is measured against (J), the energy of the new level (J), the work of each
    account (J, by name) and what each account carries to the next level (by name)."""

    error: float
    scale: float
    energy: float
    work: dict
    carry: dict

    @property
    def relative(self) -> float:
        """ε / scale (dimensionless)."""
        return self.error / self.scale


class WorkAccount:
    """One force's work over a step. Subclasses set ``name`` and implement
    :meth:`start` (what the level at the run's start carries) and :meth:`step` (the
    step's work, J, and what the new level carries). ``run`` is the
    :class:`solver.run.RodRun` before the step (its state is the old level), ``prob``
    the step's :class:`solver.step_problem.StepProblem`, ``sol`` its converged
    :class:`solver.step_problem.Solution`, ``old`` what the old level carries."""

    name = "work"

    def start(self, run):
        raise NotImplementedError

    def step(self, run, prob, sol, old):
        raise NotImplementedError

    def stored(self, carried) -> float:
        """The energy (J) the force stores at a level, from what the level carries (0: a
        force with no potential outside E); it joins E in the energy scale's floor."""
        return 0.0


def _rates(params):
    g, am, af = params.gamma, params.alpha_m, params.alpha_f
    return float(g), float(am), float(af)


@numba.njit(cache=True)
def _end_work(Y, Y_old, h, gamma, am, af, xdot_old, load_old, stiffness, moments_only,
              xdot, loads):
    """:func:`solver.energies.end_work_into`'s work Σ ½(F^n + F^{n+1})·Δx (J) of the end
    loads, less the end forces' part Σ ½(f^n + f^{n+1})·Δx_{0:3} with ``moments_only``
    (their work then measured on the shape, :class:`GlobalLoadWork`); the end loads and
    displacement rates (2, 6) into ``loads`` and ``xdot``. Y, Y_old (N+1, 12)."""
    work = end_work_into(Y, Y_old, h, gamma, am, af, xdot_old, load_old, stiffness, xdot,
                         loads)[0]
    if moments_only:
        for e in range(2):
            for i in range(3):
                dx = h * ((1.0 - gamma) * xdot_old[e, i] + gamma * xdot[e, i])
                work -= 0.5 * (load_old[e, i] + loads[e, i]) * dx
    return work


@numba.njit(cache=True)
def _end_forces_into(Y, q, out):
    """The end forces on the rod (2, 3) N in the global frame into ``out``: −f at s = 0,
    +f at s = L (:func:`solver.energies.end_loads`), f turned by the frames of the
    quaternions q[0] and q[N] (q (N+1, 4); Y (N+1, 12))."""
    R = np.empty((1, 3, 3))
    for e in range(2):
        k = 0 if e == 0 else Y.shape[0] - 1
        sign = -1.0 if e == 0 else 1.0
        _matrix_into(q[k, 0], q[k, 1], q[k, 2], q[k, 3], R, 0)
        for i in range(3):
            out[e, i] = sign * (R[0, i, 0] * Y[k, 6] + R[0, i, 1] * Y[k, 7]
                                + R[0, i, 2] * Y[k, 8])


@numba.njit(cache=True)
def _shape_work(weights, G_old, G, r, r_old, F_old, Y, q, F):
    """:meth:`GlobalLoadWork.step`'s work (J): Σ_k w_k ½(G_k^n + G_k^{n+1})·(r_k − r_k^n)
    plus Σ_ends ½(F^n + F^{n+1})·Δr_end, with the new level's end forces F (2, 3) N
    (:func:`_end_forces_into` on Y (N+1, 12) and q (N+1, 4)) written into ``F``.
    weights (N+1,) m; G_old, G (N+1, 3) N/m; r, r_old (N+1, 3) m; F_old (2, 3) N."""
    work = 0.0
    for k in range(r.shape[0]):
        acc = 0.0
        for i in range(3):
            acc += (G_old[k, i] + G[k, i]) * (r[k, i] - r_old[k, i])
        work += weights[k] * acc
    _end_forces_into(Y, q, F)
    last = r.shape[0] - 1
    for i in range(3):
        work += (F_old[0, i] + F[0, i]) * (r[0, i] - r_old[0, i])
        work += (F_old[1, i] + F[1, i]) * (r[last, i] - r_old[last, i])
    return 0.5 * work


class EndWork(WorkAccount):
    """Work of the end loads (:func:`solver.energies.end_work_into`); carries the end
    loads (2, 6) and the end sections' displacement rates (2, 6)."""

    name = "ends"

    def __init__(self, moments_only: bool = False):
        #: the end forces' work is measured on the shape (:class:`GlobalLoadWork`)
        self.moments_only = bool(moments_only)

    def start(self, run):
        st = run.state
        return (np.array(st.end_load, dtype=float), np.array(st.xdot_end, dtype=float))

    def step(self, run, prob, sol, old):
        load_old, xdot_old = old
        loads, xdot = np.empty((2, 6)), np.empty((2, 6))
        g, am, af = _rates(prob.params)
        work = _end_work(sol.Y, run.state.Y, float(prob.h), g, am, af, xdot_old, load_old,
                         run.props.stiffness, self.moments_only, xdot, loads)
        return work, (loads, xdot)


class GlobalLoadWork(WorkAccount):
    """Work of the global-frame distributed forces, the point loads and the end forces
    in the global frame, on the centreline (module docstring): Σ_k w_k ½(G_k^n +
    G_k^{n+1})·(r_k^{n+1} − r_k^n) + Σ_ends ½(F^n + F^{n+1})·Δr_end, r the shape
    integrated along s from κ (the space route, :func:`solver.kinematics.space_route`,
    anchored at node 0's new pose, and turned about node 0 onto the s = L end's
    prescribed position where that end is held in position: :meth:`held_end`,
    :meth:`turned`), or with ``time_route`` each node's time route (the seabed's pose).
    The shape,
    not the velocities: the elastic energy is a function of κ, and a dead load's
    potential −P·r is one of the shape; at large steps of a strongly nonlinear motion
    the velocities no longer integrate to the shape's change (the gap is the output
    ``position_route_difference``), and a balance on the velocities stays closed while
    the shape gains energy (the cantilever at Δt = 0.1 s: ε ≤ 0.4 % of the energy per
    step on the velocities, up to 70 % on the shape). Carries the level's global force
    per length G (N+1, 3) N/m, its centreline (N+1, 3) m and its end forces (2, 3) N."""

    name = "loads"

    def force(self, run, t, q, left, glob):
        """The global force per length (N+1, 3) N/m at time t with the node frames of
        the quaternions q (N+1, 4): ``glob`` (the distributed loads, or None) plus each
        point load P as P/w_k at its node k (w the nodal quadrature weights; followers
        turned to the global frame)."""
        props = run.props
        out = np.zeros((props.s.size, 3)) if glob is None else np.array(glob, dtype=float)
        pts = run.loads.points
        if pts is not None:
            P = pts.values(t, left=left)
            if not pts.dead.all():
                turned = np.einsum("mij,mj->mi", quat_to_matrix(q[pts.nodes]), P)
                P[~pts.dead] = turned[~pts.dead]
            np.add.at(out, pts.nodes, P / props.quad_weights[pts.nodes, None])
        return out

    @staticmethod
    def end_forces(Y, q):
        """The end forces on the rod (2, 3) N in the global frame: −f at s = 0, +f at
        s = L (:func:`solver.energies.end_loads`), f turned by the node frames of q."""
        out = np.empty((2, 3))
        _end_forces_into(np.ascontiguousarray(Y), np.ascontiguousarray(q), out)
        return out

    def __init__(self, time_route: bool = False):
        #: measure on each node's time route (where the seabed acts on it) instead of
        #: the shape integrated from κ
        self.time_route = bool(time_route)

    @staticmethod
    def held_end(run, bc) -> bool:
        """Whether the shape is turned onto the s = L end's prescribed position: the end's
        three translations kinematic in the rows ``bc`` (a :class:`solver.boundary.
        BoundaryRows`), and the pose the shape integrated from κ (no self-contact, not
        the time route)."""
        return run.contact is None and bool(bc.kinematic[6:9].all())

    @staticmethod
    def turned(q, r, target):
        """The shape (q (N+1, 4), r (N+1, 3) m) turned rigidly about node 0 by the
        smallest rotation that points its chord r_N − r_0 at ``target`` − r_0 (target
        (3,) m: the held end's prescribed position). The rotation is the axis-angle
        vector (a × b)/|a × b| · atan2(|a × b|, a·b) of the chord a onto b = target − r_0
        (Rodrigues), applied to every position about r_0 and to every frame by
        left-multiplying its quaternion. Returns new arrays (q (N+1, 4), r (N+1, 3) m);
        the inputs themselves where the chord already points there (or is zero).
        Raises nothing."""
        a, b = r[-1] - r[0], np.asarray(target, dtype=float) - r[0]
        axis = np.cross(a, b)
        sin = float(np.linalg.norm(axis))
        if sin == 0.0:
            return q, r
        dq = quat_exp(axis / sin * math.atan2(sin, float(np.dot(a, b))))
        R = quat_to_matrix(dq[None])[0]
        return quat_multiply(dq[None], q), r[0] + (r - r[0]) @ R.T

    def start(self, run):
        glob = run.loads.global_force(run.state.t) if run.loads.has_global else None
        if self.time_route:
            q, r = np.array(run.state.q_time), np.array(run.state.r_time)
        else:
            q, r = space_route(run.state.q_time[0], run.state.r_time[0], run.state.Y[:, 9:12],
                               float(run.props.ds))
            if self.held_end(run, run.state.bc):
                q, r = self.turned(q, r, run.state.r_time[-1])
        return (self.force(run, run.state.t, q, False, glob), r,
                self.end_forces(run.state.Y, q))

    def step(self, run, prob, sol, old):
        G_old, r_old, F_old = old
        q, r = self.new_pose(run, prob, sol)
        G = self.force(run, prob.t_new, q, prob.left_limit, run.system.step.glob_force)
        F = np.empty((2, 3))
        c = np.ascontiguousarray
        r = c(r)
        work = _shape_work(run.props.quad_weights, G_old, G, r, r_old, F_old, c(sol.Y),
                           c(q), F)
        return float(work), (G, r, F)

    def new_pose(self, run, prob, sol):
        """The pose of the step's new level that the work is measured on (class
        docstring): orientations (N+1, 4) and positions (N+1, 3) m. The space route of
        the solution with self-contact, else each node's time route (``time_route``) or
        the shape integrated from κ, anchored at node 0's time route (turned onto node
        N's time route where the s = L end is held in position). Raises nothing."""
        if run.contact is not None:
            return sol.pose[0], sol.pose[2]     # the space route already
        elif self.time_route:
            st = run.state
            q, _, _, r = run.assembly._time_step(st, prob.h, sol.Y, st.q_time, st.r_time,
                                                 st.v_global_time,
                                                 offsets=((st.bc_offset, st.bc.cols),
                                                          (prob.offset, prob.bc.cols)))
            normalize_quaternions(q)
        else:
            # nodes 0 and N one step along their time routes (without self-contact no end
            # correction offsets the boundary values), the shape integrated from node 0
            # (as the run's space route, ProblemAssembly.update_space_route), turned onto node N
            # where that end is held in position
            ends = [0, -1]
            q0, r0 = np.empty((2, 4)), np.empty((2, 3))
            c = np.ascontiguousarray
            pose_into(c(sol.Y[ends]), c(run.state.Y[ends]), float(prob.h), False,
                      c(run.state.q_time[ends]), c(run.state.r_time[ends]),
                      c(run.state.v_global_time[ends]),
                      True, 0.0, q0, np.empty((2, 3, 3)), r0, np.empty((2, 3)),
                      np.empty((2, 3)))
            q0[0] /= np.linalg.norm(q0[0])
            q, r = space_route(q0[0], r0[0], sol.Y[:, 9:12], float(run.props.ds))
            if self.held_end(run, prob.bc):
                q, r = self.turned(q, r, r0[1])
        return q, r


class DragWork(WorkAccount):
    """Work of the Morison drag (:func:`solver.loads._drag_kernel`) on the body-frame
    velocities (never positive but for the α relation's lag). Carries the drag per
    length (N+1, 3) N/m and the displacement rates (N+1, 3)."""

    name = "drag"

    def start(self, run):
        b = np.empty((run.state.Y.shape[0], 3))
        rod = run.system.rod_data
        # a column view of the (N+1, 12) unknowns, as the compiled callers pass it (one
        # signature of the kernel)
        _drag_kernel(np.ascontiguousarray(run.state.Y, dtype=float)[:, 0:3], rod.cdn, rod.cdt, b,
                     np.empty((0, 3, 3)), False)
        return b, np.array(run.state.Y[:, 0:3], dtype=float)

    def step(self, run, prob, sol, old):
        b_old, rate_old = old
        n1 = sol.Y.shape[0]
        b, rate = np.empty((n1, 3)), np.empty((n1, 3))
        g, am, af = _rates(prob.params)
        rod = run.system.rod_data
        work = _drag_work(np.ascontiguousarray(sol.Y), run.state.Y, float(prob.h), g, am, af,
                          rate_old, b_old, rod.cdn, rod.cdt, run.props.quad_weights, b, rate)
        return work, (b, rate)


@numba.njit(cache=True)
def _drag_work(Y, Y_old, h, gamma, am, af, rate_old, b_old, cdn, cdt, weights, b, rate):
    """:class:`DragWork`'s work (J): the new level's Morison drag (N+1, 3) N/m on the
    body-frame velocities of Y (N+1, 12) into ``b`` (:func:`solver.loads._drag_kernel`,
    c_n, c_t (N+1,) its coefficients) and its trapezoid work on the nodes' displacement
    rates into ``rate`` (:func:`solver.energies.distributed_work_into`)."""
    yes = true_at_run_time(Y)
    _drag_kernel(Y[:, 0:3], cdn, cdt, b, np.empty((0, 3, 3)), not yes)
    return distributed_work_into(Y, Y_old, h, gamma, am, af, rate_old, b_old, yes, b, yes,
                                 weights, rate)[0]


class SeabedWork(WorkAccount):
    """Work of the sea floor's normal spring (:mod:`solver.seabed`, the linear
    spring-damper per unit length of MoorDyn): minus the change of its stored energy
    U = Σ_c Δs ½ k max(p_c, 0)² (J; k the normal stiffness, Pa, p_c the surface
    penetration at cell c's midpoint, m, where the seabed's law acts), exact for a flat
    bottom and for each grid cell's tangent plane. U is not part of E, so the spring enters
    the balance as a work term, on the shape like gravity. The damper (clamped to the sign of −n·ṙ)
    and the Coulomb friction with its moment only take energy out at every instant
    (module :mod:`solver.seabed`), so they are left out like the scheme's own
    dissipation: they only make ε negative. Their trapezoid on the two levels' power
    (the run's ``seabed_work``) is no account of them where the bottom stops a node
    within a step (its damper's time m/c, microseconds, far below any Δt): it over-counts
    the energy taken and reads the landing as injected energy (docs/numerics.md § 8).
    The new level's penetration is the one the seabed acted on in the step: on each
    node's time route (:meth:`solver.step_problem.ProblemAssembly._time_step`, as the accepted step
    advances it), or with self-contact the space route of the solution. Carries U (J)."""

    name = "seabed"

    @staticmethod
    def spring_energy(run, r) -> float:
        """The spring's stored energy U (J) at the node positions r (N+1, 3) m
        (:meth:`solver.seabed.SeabedContact.stored_energy`: per cell, at its midpoint)."""
        return run.system.seabed.stored_energy(r, float(run.props.ds))

    def stored(self, carried) -> float:
        return float(carried)

    def start(self, run):
        return self.spring_energy(run, run._seabed_pose()[1])

    def step(self, run, prob, sol, old):
        if run.contact is not None:
            q = sol.pose[0].copy()
            normalize_quaternions(q)
            r = sol.pose[2]
            v = np.empty_like(r)
            rotate_rows(q, sol.Y[:, 0:3], v)
        else:
            st = run.state
            q, _, v, r = run.assembly._time_step(st, prob.h, sol.Y, st.q_time, st.r_time,
                                                 st.v_global_time,
                                                 offsets=((st.bc_offset, st.bc.cols),
                                                          (prob.offset, prob.bc.cols)))
            normalize_quaternions(q)
        energy = self.spring_energy(run, r)
        return old - energy, energy


class ContactWork(WorkAccount):
    """Work of the self-contact law's repulsion: minus the change of its stored energy
    U_c = Σ_i ½ Δs_i ρĀ Ψ(d_i) (J; :meth:`solver.contact.model.SelfContact.potential`,
    Ψ the law's potential :func:`solver.contact.laws.law_potential`, d_i node i's
    distance to its closest point on the partner curve, Δs_i its quadrature weight).
    Node i's force ½ f n Δs_i with its reaction spread over the partner curve's nodes is
    −∇U_c (the closest point is stationary along the curve), so −ΔU_c is the repulsion's
    exact work, as ½kp² is the seabed spring's. Both levels are evaluated with the
    step's candidates (``sol.candidates``) on the pose the contact acts on (the space
    route: the old level's ``run.state.r``, the solution's ``sol.pose``, read off the fresh
    evaluation the step's contact summary made there, :meth:`solver.scheme.RodSystem.
    summary_potential`); a step without
    candidates has U_c = 0 at both (no pair within the search distance, beyond every
    law's cut-off). The law's damper only takes energy out and is left out, as the
    scheme's own dissipation is. Carries (U_c (J), the candidates and the positions
    (N+1, 3) it was evaluated with) of the new level: where the next step keeps the same
    candidates (:meth:`solver.contact.search.CandidateSearch.candidates` returns the kept
    object) from the very positions the level carries, its old level's U_c is the
    carried one, bit for bit (PyElastica's plectoneme at N = 100, 12 s: 461 evaluations
    of ~80 µs each); None at the start, where no step has made candidates yet (a bare
    float from a checkpoint written before the positions were carried)."""

    name = "contact"

    def stored(self, carried) -> float:
        if carried is None:
            return 0.0
        return float(carried[0] if isinstance(carried, tuple) else carried)

    def start(self, run):
        return None

    def step(self, run, prob, sol, old):
        cand = sol.candidates
        if cand is None or not cand.runs:
            return 0.0, 0.0
        if isinstance(old, tuple) and old[1] is cand and old[2] is run.state.r:
            u_old = old[0]
        else:
            u_old = run.contact.potential(cand, run.state.r)
        # the step's contact summary evaluated the contacts afresh at these positions:
        # the same value without finding the closest points again
        r_new = sol.pose[2]
        u_new = run.system.summary_potential(r_new)
        if u_new is None:
            u_new = run.contact.potential(cand, r_new)
        return u_old - u_new, (u_new, cand, r_new)


class EnergyBalance:
    """The per-step energy check of a run (module docstring).

    Parameters
    ----------
    tolerance : float
        The largest ε allowed per step as a share of the energy scale
        (``numerics.energy_tolerance``).
    accounts : list of WorkAccount
    floor : float
        The smallest energy scale, J (:meth:`for_run`).
    """

    #: the energy scale's floor as a share of the stored energies (the rod's energy E
    #: and each account's potential, :meth:`WorkAccount.stored`: the seabed's spring):
    #: Newton's tolerance and the work's trapezoid leave an ε of that order in a step
    #: that turns over almost nothing (the soft hanging cable settling at Δt = 0.2 s:
    #: ε of 3.5e-9 to 2.4e-8 J against E = 1.04e-4 J; docs/numerics.md § 8)
    ENERGY_SHARE = 1e-5

    def __init__(self, tolerance: float, accounts: list, floor: float):
        self.tolerance = float(tolerance)
        self.accounts = list(accounts)
        self.floor = float(floor)
        #: steps with contact candidates are measured (the accounts hold the contact
        #: law's, :class:`ContactWork`; a balance without it leaves them unmeasured)
        self.contact_steps = any(isinstance(a, ContactWork) for a in self.accounts)

    @classmethod
    def for_run(cls, run) -> Optional["EnergyBalance"]:
        """The balance of ``run``'s case, or None without ``numerics.energy_tolerance``.
        Accounts: the end loads always, the global-frame loads where the case has
        distributed global forces or point loads, the drag with a fluid's drag, the sea
        floor's work with a ``seabed``, the contact law's with ``contact``. The
        floor of the energy scale: 1e-9 EJ/L (J; EJ the largest bending stiffness)."""
        tol = run.case.numerics.energy_tolerance
        if tol is None:
            return None
        shape = run.loads.has_global or run.loads.points is not None
        accounts = [EndWork(moments_only=shape)]
        if shape:
            # with a seabed (and no self-contact) on the pose the seabed acts on
            accounts.append(GlobalLoadWork(time_route=run.system.seabed is not None
                                           and run.contact is None))
        if run.loads.has_drag:
            accounts.append(DragWork())
        if run.system.seabed is not None:
            accounts.append(SeabedWork())
        if run.contact is not None:
            accounts.append(ContactWork())
        props = run.props
        length = float(props.s[-1] - props.s[0])
        floor = 1e-9 * float(np.max(props.stiffness[:, :2])) / length
        return cls(tol, accounts, floor)

    def start(self, run) -> dict:
        """What the run's first level carries: its energy and kinetic energy (J) and
        each account's old data."""
        out = {a.name: a.start(run) for a in self.accounts}
        out["energy"], out["kinetic"] = total_and_kinetic(run.state.Y, run.props)
        return out

    def measure(self, run, prob, sol) -> StepBalance:
        """The balance of the converged step ``sol`` of ``prob`` from the run's state.

        The scale is the kinetic energy (with the added mass's), max(T^n, T^{n+1}),
        floored at ENERGY_SHARE × (E + the accounts' stored energies) and at the run's
        floor: not E, whose strain part can
        dwarf the motion, nor the step's work, whose trapezoid sum is itself ~1 % off in
        a good step of a ramped load. Measured on the cantilever (docs/numerics.md § 8):
        against E, or the larger of T and 0.3|Σ W|, steps that each injected less than
        the tolerance kept the rod oscillating (tip 0.4-6 % off at 8 s); against T at
        the default 0.5 every Δt from 0.02 to 0.2 s settles within 0.1 % of the
        elastica."""
        old = run.state.balance
        work, carry = {}, {}
        for a in self.accounts:
            work[a.name], carry[a.name] = a.step(run, prob, sol, old[a.name])
        energy, kinetic = total_and_kinetic(sol.Y, run.props)
        total = sum(work.values())
        error = energy - old["energy"] - total
        stored_old = old["energy"] + sum(a.stored(old[a.name]) for a in self.accounts)
        stored = energy + sum(a.stored(carry[a.name]) for a in self.accounts)
        scale = max(old["kinetic"], kinetic, self.ENERGY_SHARE * max(stored, stored_old),
                    self.floor)
        carry["energy"] = energy
        carry["kinetic"] = kinetic
        return StepBalance(float(error), float(scale), float(energy), work, carry)

    def refuses(self, bal: StepBalance) -> bool:
        """The step injected more than the tolerance (a NaN error refuses too)."""
        return not bal.error <= self.tolerance * bal.scale


class CentrelineBalance:
    """The per-step energy check of the centreline scheme
    (:class:`solver.centreline_run.CentrelineRun`): the module's ε on one centreline,

        ε = E^{n+1} − E^n − W − (U_s^n − U_s^{n+1}) − (U_c^n − U_c^{n+1}) + W_c     (J)

    E the rod's energy (:func:`solver.energies.total_and_kinetic` of the body fields the
    outputs read), W the scheme's discrete work of the ends, the dead loads and the
    thermal impulses (:meth:`solver.centreline_run.CentrelineRun._work`), U_s the sea
    floor's spring energy at the nodes where its law acts (:meth:`solver.seabed.
    SeabedContact.nodal_stored_energy`), U_c the contact law's (:meth:`solver.contact.
    model.SelfContact.potential`, both levels with the candidates searched at the new
    one), W_c the internal force's work on the box rule's chords (:meth:`chord_work`).
    Dissipative forces are left out, as in :class:`EnergyBalance` (Morison's and the
    viscous drag in still water, the seabed's damper and friction, the contact law's
    damping): the check is one-sided. Refused, with :class:`EnergyBalance`'s tolerance
    and rule, where

        ε > tolerance × max(T^n, T^{n+1}, 1e-5 (E + U_s + U_c), |W_c|,
                            |ΔU_el| (h|κ − κ⁰|)²_max, 1e-9 EJ/L).

    Two terms are the box rule's, whose discrete energy is not the trapezoid's
    E at O((hκ)²):

    * *The chords* (W_c, and |W_c| in the scale): the position rows make a cell's chord
      |r_{i+1} − r_i| = h cos(φ/2), φ the angle between its tangents, so the chords
      shorten as cells bend and the tension works on that. On the soft hanging cable of
      tests/solver/test_global_ends.py (ρ∞ 0, settling) ε without W_c is about −W, the
      gravity work of the sway's rise, ten to a hundred times the sway's kinetic energy,
      and the check refused 765 steps at Δt = 0.1 s (454 and 527 at 0.05 and 0.2 s) for
      the same sag; W_c takes out 80-100 % of it (the first step: ε −1.902e-5 J, W_c
      +1.902e-5 J) and with it the cable has none (largest ε/scale 0.28).
    * *The frames' turn* (|ΔU_el| (hκ)² in the scale): a cell's frames turn by the
      Cayley map of its mean κ, 2 atan(hκ/2) rather than hκ, so the end moment's work
      along them and the trapezoid's U_el = ½∫(κ − κ⁰)·K(κ − κ⁰) ds part at O((hκ)²) of
      what a step stores: on a straight rod twisted past Greenhill's threshold by its
      end (40 segments, hκ up to 0.15) ε = 1.2e-3 of the step's ΔU_el, 0.06 (hκ)² ΔU_el,
      and every step was refused down to the smallest against the other terms, whose
      1e-5 E is 1.2e-5 of ΔU_el there (research/notes/centreline.md).

    What it refuses (tests/solver/test_centreline_energy.py): the first fall of
    cases/catenary-touchdown.yaml onto the bottom's spring at Δt = 0.05 s, where the
    damper, taken at generalized-α's velocity of a mode far beyond the step (upward
    while the node went 26 µm down), pumped 6e-4 J into the spring (T 9.3e-4 J at
    0.05 s against 3.7e-6 J at Δt/4); a column's buckling starting within a step at
    ρ∞ 0 without the growth guard. Not measured: the restart at a breakpoint (its
    Taylor steps re-solve n and m at the level's positions, and the nodal κ's split
    across each cell, which the frames leave free, moves E by up to 0.3 % there on the
    sin² pulse of tests/solver/test_verification.py), cases with electrostatics (its
    potential is no account yet) or thermal noise (the noise's work is a fluctuation the
    drag takes out again; a check would chase it).

    Parameters
    ----------
    tolerance : float (``numerics.energy_tolerance``)
    floor : float, J (1e-9 EJ/L)
    """

    ENERGY_SHARE = EnergyBalance.ENERGY_SHARE

    def __init__(self, tolerance: float, floor: float):
        self.tolerance = float(tolerance)
        self.floor = float(floor)
        #: (the level last measured, its figures without U_c): an accepted step's new
        #: level is the next step's old one, measured once
        self._kept = None

    @classmethod
    def for_run(cls, run) -> Optional["CentrelineBalance"]:
        """The check of a centreline run, or None without ``numerics.energy_tolerance``
        and with electrostatics or thermal noise (class docstring)."""
        tol = run.case.numerics.energy_tolerance
        if tol is None or run.case.electrostatics is not None or run.rod.thermal is not None:
            return None
        props = run.props
        length = float(props.s[-1] - props.s[0])
        return cls(tol, 1e-9 * float(np.max(props.stiffness[:, :2])) / length)

    def _level(self, run, state, cand):
        """(E, T, U_s + U_c, the largest h|κ − κ⁰| over the nodes) of a level (J, J, J,
        dimensionless), the contact's energy over the candidates ``cand``."""
        if self._kept is not None and self._kept[0] is state:
            energy, kinetic, stored, strain = self._kept[1]
        else:
            fl = run.rod.body_fields(state)
            Y = np.concatenate([fl["v"], fl["omega"], fl["f"], fl["kappa"]], axis=1)
            energy, kinetic = total_and_kinetic(Y, run.props)
            # h|κ − κ⁰| = h|K⁻¹ Rᵀ m| (the law m = R K (κ − κ⁰))
            body_m = np.einsum("kji,kj->ki", quat_to_matrix(state.Y[:, 3:7]),
                               state.Y[:, 10:13])
            strain = float(np.max(run.rod.h * np.linalg.norm(body_m / run.props.stiffness,
                                                              axis=1)))
            stored = 0.0
            if run.rod.seabed is not None:
                stored = run.rod.seabed.nodal_stored_energy(run._seabed_split(state)[3],
                                                            run.props.quad_weights)
            self._kept = (state, (energy, kinetic, stored, strain))
        if cand is not None:
            stored += run.contact.potential(cand, state.Y[:, 0:3])
        return energy, kinetic, stored, strain

    def measure(self, run, old, new, work: float) -> StepBalance:
        """The balance (:class:`StepBalance`; its work: the scheme's ``work`` and the
        chords' W_c, J) of the converged step from the level ``old`` to ``new``
        (:class:`solver.centreline.CentrelineState`) with the scheme's work ``work`` (J).
        Raises nothing; non-finite levels give a NaN error, which :meth:`refuses`."""
        cand = None
        if run.contact is not None:
            r = np.ascontiguousarray(new.Y[:, 0:3], dtype=float)
            a3 = np.ascontiguousarray(quat_to_matrix(new.Y[:, 3:7])[:, :, 2])
            cand = run.contact.search(r, a3)
        e0, t0, u0, k0 = self._level(run, old, cand)
        e1, t1, u1, k1 = self._level(run, new, cand)
        chord = self.chord_work(old.Y, new.Y)
        error = e1 - e0 - work - (u0 - u1) + chord
        box = abs((e1 - t1) - (e0 - t0)) * max(k0, k1) ** 2
        scale = max(t0, t1, self.ENERGY_SHARE * max(e0 + u0, e1 + u1), box, abs(chord),
                    self.floor)
        return StepBalance(float(error), float(scale), float(e1),
                           {"work": work, "chords": chord}, {"stored": u1})

    @staticmethod
    def chord_work(Y0, Y1) -> float:
        """The internal force's work on the box rule's chords over a step (J): Σ_i
        n̄_i·ĉ_i (|c_i^{n+1}| − |c_i^n|), c_i = r_{i+1} − r_i the cell's chord, ĉ_i the unit
        of c_i^n + c_i^{n+1}, n̄_i the mean of the cell's two nodes at both levels; Y0, Y1
        (N+1, 13) the levels' unknowns. The position rows make |c_i| = h cos(φ_i/2), φ_i
        the angle between the cell's two tangents: the discrete centreline's chords
        shorten as a cell bends, by O((hκ)²), and the tension does work on that, which
        the inextensible continuum has not."""
        c0, c1 = np.diff(Y0[:, 0:3], axis=0), np.diff(Y1[:, 0:3], axis=0)
        u = c0 + c1
        u /= np.linalg.norm(u, axis=1)[:, None]
        n = Y0[:, 7:10] + Y1[:, 7:10]
        nbar = 0.25 * np.sum((n[1:] + n[:-1]) * u, axis=1)
        return float(nbar @ (np.linalg.norm(c1, axis=1) - np.linalg.norm(c0, axis=1)))

    def refuses(self, bal: StepBalance) -> bool:
        """The step injected more than the tolerance (a NaN error refuses too)."""
        return not bal.error <= self.tolerance * bal.scale
