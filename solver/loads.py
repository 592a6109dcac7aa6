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

Orientation-dependent loads are evaluated with the orientation at the new time level
inside Newton; their derivative with respect to ω^{n+1} is ``(Δt_ω)[B]×`` where
``R^{n+1} = R̂ exp(Δt_ω (ω^n + ω^{n+1}))`` (first order in the rotation increment).
"""
from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["LoadModel"]


class LoadModel:
    """The case's distributed loads on the grid.

    Parameters
    ----------
    case : solver.case.Case
    props : solver.properties.RodProperties
    extra : callable(t, owner) -> (N+1, 3) array or None, optional
        A further global-frame distributed force (N/m) written as code (in-process runs:
        ``simulate(..., extra_force=...)``), evaluated like the case's forces at every
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
