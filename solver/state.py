"""The state of a run between steps: what a step starts from and what it leaves.

:class:`RunState` holds the rod's unknowns at the current time level and the levels before
it, the carried poses, the end rotations and the energy accounts. The step
(:meth:`solver.run.RodRun.try_step`) reads it and, when a step is accepted, rebinds its
arrays (never writes into them), so a shallow copy is a snapshot of it
(:meth:`solver.run.RodRun._state`, the dense output of :mod:`solver.recording`). It knows
nothing of the step logic; a checkpoint (:mod:`solver.checkpoint`) pickles it with the run.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, Optional

import numpy as np


__all__ = ["RunState"]


@dataclass
class RunState:
    """One time level of a run and what the next step needs of the levels before it.

    Shapes: N+1 grid points; Y rows are (v, ω, f, κ) in the body frame (12 columns: m/s,
    rad/s, N, rad/m; the scheme of :mod:`solver.scheme`).

    Attributes
    ----------
    t : float
        Simulated time, s.
    Y, Ydot : (N+1, 12)
        The unknowns and their rates of the generalized-α scheme (Ydot per s).
    F_old : (N+1, 12)
        The node terms at this level (:meth:`solver.scheme.RodSystem.node_terms`).
    Y_prev, h_prev, Y_prev2, h_prev2 : (N+1, 12) or None, float or None
        The two levels before this one and the steps (s) from them, for the predictors
        (None after a restart).
    q, r : (N+1, 4), (N+1, 3)
        Space-route pose: unit quaternions (w, x, y, z) and centreline, m.
    q_time, r_time : (N+1, 4), (N+1, 3)
        Time-route pose (every node advanced in time on its own; a diagnostic, and the
        end's reference for :meth:`solver.step_problem.ProblemAssembly.end_correction`).
    v_global, v_global_time : (N+1, 3)
        Global-frame node velocities of the two routes, m/s.
    bc : solver.boundary.BoundaryRows or None
        The boundary rows in force at this level.
    bc_offset : (12,) or None
        The end correction of the step that reached this level.
    phi : (2,)
        End rotations about a3, rad (the linking number).
    work_in, power : float
        Work put in by the end and distributed loads, J, and its rate, W.
    end_load : (2, 6)
        End loads of this level (:func:`solver.energies.end_loads`).
    xdot_end : (2, 6)
        End displacement rates of the α-relation, m/s and rad/s ([:, 5] is φ̇).
    xdot_nodes : (N+1, 3)
        Node displacement rates, m/s (advanced only where distributed loads do work).
    body_force : (N+1, 3) or None
        Distributed global-frame load in the body frame, N/m, at this level.
    seabed_work, seabed_power : float
        Work done on the rod by the seabed (normal reaction, friction and its moment), J,
        and its rate at this level, W (0 without a seabed; :meth:`solver.run.RodRun.
        _advance_seabed_work`).
    quat_norm_error : float
        Largest drift of the time route's quaternions from unit norm so far.
    balance : dict or None
        What the energy check carries from this level to the next (the level's energy,
        each work account's old data; :mod:`solver.balance`), None without
        ``numerics.energy_tolerance`` and after a step the check does not measure.
    """

    t: float
    Y: np.ndarray
    Ydot: np.ndarray
    q: np.ndarray
    r: np.ndarray
    q_time: np.ndarray
    r_time: np.ndarray
    v_global: np.ndarray
    v_global_time: np.ndarray
    phi: np.ndarray
    xdot_end: np.ndarray
    xdot_nodes: np.ndarray
    F_old: Optional[np.ndarray] = None
    Y_prev: Optional[np.ndarray] = None
    h_prev: Optional[float] = None
    Y_prev2: Optional[np.ndarray] = None
    h_prev2: Optional[float] = None
    bc: Any = None
    bc_offset: Optional[np.ndarray] = None
    work_in: float = 0.0
    power: float = 0.0
    end_load: Optional[np.ndarray] = None
    body_force: Optional[np.ndarray] = None
    quat_norm_error: float = 0.0
    seabed_work: float = 0.0
    seabed_power: float = 0.0
    balance: Optional[dict] = None

    @classmethod
    def names(cls) -> tuple:
        """The names of the state's quantities (the run exposes each as an attribute)."""
        return tuple(f.name for f in fields(cls))

    @classmethod
    def at_rest(cls, case, s: np.ndarray, start=None) -> "RunState":
        """The rod at rest at t = 0 in the case's initial configuration
        (:func:`solver.initial.initial_state`: straight along the initial tangent and
        normal, or along ``initial.centreline`` with ``initial.twist_rate``), or the
        :class:`solver.initial.StartState` ``start`` (``initial.from_result``); s (N+1,)
        the arclength, m. F_old, the loads' accounts and ``bc`` are filled by the run
        (they need its system)."""
        from .initial import apply_start, initial_state

        n1 = s.size
        q, r, Y, t0 = initial_state(case, s, start)
        state = cls(t=t0, Y=Y, Ydot=np.zeros((n1, 12)), q=q, r=r,
                    q_time=q.copy(), r_time=r.copy(), v_global=np.zeros((n1, 3)),
                    v_global_time=np.zeros((n1, 3)), phi=np.zeros(2),
                    xdot_end=np.zeros((2, 6)), xdot_nodes=np.zeros((n1, 3)))
        if start is not None:
            apply_start(state, start)
        elif case.initial.twist_rate != 0.0 or case.initial.centreline is not None:
            state.phi = initial_end_rotations(r, Y[:, 11], s)
        return state


def initial_end_rotations(r: np.ndarray, kappa3: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(2,) rad: the end rotations φ of a start that is already twisted or curved
    (``initial.twist_rate``, ``initial.centreline``), so that its linking number
    Lk = (φ_end − φ_start)/2π is Tw + Wr of the start shape (Călugăreanu–White; the
    linking number counts from the untwisted straight rod, docs/topology.md). r (N+1, 3)
    m, kappa3 (N+1,) rad/m, s (N+1,) m."""
    from .topology import twist, writhe

    return np.array([0.0, 2.0 * np.pi * (float(twist(kappa3, s)) + float(writhe(r)))])

