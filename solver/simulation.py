"""The time loop: ``simulate(case) -> xarray.Dataset`` (DESIGN.md, "Python API").

Each time step solves the box/generalized-α difference equations of
:mod:`solver.scheme` for all grid points at once by Newton. A step that does not converge
is retried from the restored state with Δt cut by ``numerics.dt_cut_factor``, up to
``numerics.max_dt_cuts`` times (WHOI Cable's adaptive pattern, numerics-notes §1.2); the
cut steps complete the nominal step, so outputs stay on the nominal time grid. When all
cuts fail, :class:`SolverDivergence` is raised carrying the partial dataset.

Start-up: for ρ∞ < 1 the first step (and any step at which a boundary condition switches
kind) is a backward-Euler step, which leaves a consistent Ẏ behind (docs/numerics.md;
numerics-notes §9 "Initial time derivative"). At ρ∞ = 1 the scheme does not depend on Ẏ^n.
"""
from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .boundary import BoundaryRows
from .energies import distributed_power, end_loads, end_power, energies
from .kinematics import quat_exp, quat_from_matrix, quat_multiply, quat_to_matrix, space_route
from .loads import LoadModel
from .properties import RodProperties
from .scheme import BACKWARD_EULER, RodSystem, alpha_parameters

__all__ = ["simulate", "SolverDivergence", "Progress", "RodRun"]


@dataclass(frozen=True)
class Progress:
    """What the progress callback receives after every accepted nominal step.

    t, t_end, dt: s; step: number of nominal steps done; newton_iterations: of the last
    step; residual_norm: scaled (dimensionless); wall_time: s since the start;
    fraction: t / t_end in [0, 1].
    """

    t: float
    t_end: float
    step: int
    dt: float
    newton_iterations: int
    residual_norm: float
    wall_time: float
    fraction: float
    contact_count: int = 0


class SolverDivergence(RuntimeError):
    """A time step could not be completed even after all Δt cuts.

    Attributes: t (s, the time reached), step (nominal steps completed), residual (the
    scaled residual of the last attempt), reason ("solver_diverged" or
    "nonfinite_state"), partial (the xarray.Dataset up to the last accepted step).
    """

    def __init__(self, message, t, step, residual, reason, partial=None):
        super().__init__(message)
        self.t = t
        self.step = step
        self.residual = residual
        self.reason = reason
        self.partial = partial


class RodRun:
    """The state of one run and the step logic; :func:`simulate` drives it.

    Exposed for tests and benchmarks that need the state between steps.

    Parameters
    ----------
    case : solver.case.Case (validated)
    """

    GROW_AFTER = 3   # accepted substeps at one Δt level before Δt is allowed to grow

    def __init__(self, case):
        self.case = case
        num = case.numerics
        self.props = props = RodProperties.from_case(case)
        self.loads = LoadModel(case, props)
        self.contact = None
        if case.contact is not None:
            from .contact import SelfContact

            self.contact = SelfContact(case.contact, props.s, props.diameter, props.rho_a)
        self.system = RodSystem(props, self.loads, num.newton.tolerance,
                                num.newton.max_iterations, contact=self.contact)
        self.params = alpha_parameters(num.rho_inf)
        self.rho_inf = num.rho_inf
        n1 = props.s.size
        self.t = 0.0
        self.Y = np.zeros((n1, 12))
        self.Ydot = np.zeros((n1, 12))
        self.Y_prev = None
        self.h_prev = None
        tangent = np.asarray(case.initial.tangent, float)
        tangent = tangent / np.linalg.norm(tangent)
        normal = np.asarray(case.initial.normal, float)
        normal = normal - np.dot(normal, tangent) * tangent
        normal = normal / np.linalg.norm(normal)
        R0 = np.column_stack([normal, np.cross(tangent, normal), tangent])
        q0 = quat_from_matrix(R0)
        self.q = np.tile(q0, (n1, 1))                     # space-route pose
        self.r = props.s[:, None] * tangent[None, :]
        self.q_time = self.q.copy()                       # time-route pose (diagnostic)
        self.r_time = self.r.copy()
        self.v_global = np.zeros((n1, 3))
        self.v_global_time = np.zeros((n1, 3))
        self.phi = np.zeros(2)                            # end rotations about a3, rad
        self.work_in = 0.0
        # end displacement rates (2, 6) of the α-relation, m/s and rad/s; [:, 5] is φ̇
        self.xdot_end = np.zeros((2, 6))
        self.xdot_nodes = np.zeros((n1, 3))               # node displacement rates, m/s
        # (advanced only where distributed loads do work: loads.has_global)
        self.quat_norm_error = 0.0
        glob = self.loads.global_force(0.0) if self.loads.has_global else None
        pose = ((quat_to_matrix(self.q), np.zeros((n1, 3)), 0.0)
                if self.system.needs_pose else None)
        self.F_old, _ = self.system.node_terms(self.Y, False, pose, glob)
        self.body_force = self._body_force(glob, pose)
        self.power = end_power(self.Y, props) + distributed_power(self.Y, self.body_force, props)
        self.end_load = end_loads(self.Y, props)
        self.bc = BoundaryRows(case, props, 0.0, self.system.n)
        self.first_step = True
        self.level_hint = 0
        self.last_iterations = 0
        self.last_residual = 0.0
        self.last_dt = num.dt
        self.contact_count = 0
        self.min_gap = math.inf

    @staticmethod
    def _body_force(glob, pose):
        if glob is None or pose is None:
            return None
        return np.einsum("nji,nj->ni", pose[0], glob)

    # -------------------------------------------------------------------------------
    def try_step(self, h: float):
        """Attempt one step of size h (s). On success the state advances and
        (True, iterations, residual, nonfinite=False) is returned; on failure the state is
        untouched."""
        sysm = self.system
        t_new = self.t + h
        bc = BoundaryRows(self.case, self.props, t_new, sysm.n)
        switched = bc.key != self.bc.key
        use_be = (self.rho_inf < 1.0 and self.first_step) or switched
        params = BACKWARD_EULER if use_be else self.params
        if self.Y_prev is not None and self.h_prev:
            guess = self.Y + (h / self.h_prev) * (self.Y - self.Y_prev)
        else:
            guess = self.Y
        pairs = None
        if self.contact is not None:
            # pairs from the predicted positions, held fixed during Newton
            pairs = self._find_pairs(self.r + h * self.v_global, quat_to_matrix(self.q))
        its_total = 0
        for _attempt in range(3):
            sysm.begin_step(h, params, t_new, self.Y, self.Ydot, self.F_old, bc,
                            q_old=self.q, r_old=self.r, v_old_global=self.v_global,
                            pairs=pairs)
            if sysm.pairs is not None and guess is not self.Y:
                # an extrapolated predictor must not close any gap by more than 70 %
                g_old, g_new = sysm.pair_gaps(self.Y), sysm.pair_gaps(guess)
                if not np.all(g_new >= 0.3 * np.maximum(g_old, 0.0)):
                    guess = self.Y
            Y, Fn, its, res, ok, pose = sysm.solve_step(guess)
            its_total += its
            if not ok:
                return False, its_total, res, not np.isfinite(res)
            if self.contact is None:
                break
            if pose is None:
                pose = sysm.pose_new(Y)
            # the pairs at the new positions must be among those the step used
            new_pairs = self._find_pairs(pose[2], pose[1])
            merged = self._merge_pairs(pairs, new_pairs)
            if merged is pairs:
                break
            pairs, guess = merged, Y
        its = its_total
        if self.contact is not None:
            ev = None
            if pairs is not None and len(pairs.i):
                vg = np.einsum("nij,nj->ni", pose[1], Y[:, 0:3])
                ev = self.contact.evaluate(pairs, pose[2], vg)
            if ev is not None and ev.min_gap < 0.0:
                # the surfaces interpenetrate: reject, the caller cuts Δt
                return False, its, res, False
            contact_count = 0 if ev is None else int(ev.count)
            min_gap = math.inf if ev is None else float(ev.min_gap)
        # accept ------------------------------------------------------------------
        g = params.gamma
        Ydot = (Y - self.Y) / (g * h) - ((1.0 - g) / g) * self.Ydot
        props = self.props
        # time route of every node (diagnostic) and the end rotations (linking number)
        theta = 0.5 * h * (self.Y[:, 3:6] + Y[:, 3:6])
        q_t = quat_multiply(self.q_time, quat_exp(theta))
        nrm = np.linalg.norm(q_t, axis=1)
        q_t /= nrm[:, None]
        R_t = quat_to_matrix(q_t)
        vg_t = np.einsum("nij,nj->ni", R_t, Y[:, 0:3])
        r_t = self.r_time + 0.5 * h * (self.v_global_time + vg_t)
        space = None
        if self.contact is not None:
            space = space_route(q_t[0], r_t[0], Y[:, 9:12], props.ds)
            if not self._contact_step_ok(space[1], pose[2]):
                return False, its, res, False
            self.contact_count, self.min_gap = contact_count, min_gap
        self.quat_norm_error = max(self.quat_norm_error, float(np.max(np.abs(nrm - 1.0))))
        self.r_time, self.q_time, self.v_global_time = r_t, q_t, vg_t
        # displacement increments of the end sections (v, ω components, body frame) with
        # the scheme's own generalized-α relation (the one κ obeys through E1). Their
        # a3 rotations are the end rotations φ of the linking number, so Lk and the
        # discrete twist advance consistently; with the end loads they give the work.
        am, af = params.alpha_m, params.alpha_f
        rate = (1.0 - af) * Y[[0, -1], 0:6] + af * self.Y[[0, -1], 0:6]
        xdot = (rate - am * self.xdot_end) / (1.0 - am)
        dx = h * ((1.0 - g) * self.xdot_end + g * xdot)
        self.phi = self.phi + dx[:, 5]
        # work put in: the mean load of the step times the increment of its conjugate
        # displacement. At ρ∞ = 1 this is the box scheme's discrete work, ½(Fⁿ + Fⁿ⁺¹)·
        # ½(ẋⁿ + ẋⁿ⁺¹)Δt, which the energy then equals; a trapezoid of the power (mean of
        # the products) differs from it by O(Δt²) (10 % at Δt = 1 s, docs/numerics.md § 6).
        glob = sysm._glob_force
        body = self._body_force(glob, None if pose is None else (pose[1],))
        loads = end_loads(Y, props)
        power = end_power(Y, props, loads) + distributed_power(Y, body, props)
        self.work_in += float(np.sum(0.5 * (self.end_load + loads) * dx))
        self.xdot_end, self.end_load = xdot, loads
        if self.loads.has_global:
            # distributed global-frame loads: the same per node, with the quadrature weights
            rate = (1.0 - af) * Y[:, 0:3] + af * self.Y[:, 0:3]
            vdot = (rate - am * self.xdot_nodes) / (1.0 - am)
            dx = h * ((1.0 - g) * self.xdot_nodes + g * vdot)
            loaded = [b for b in (self.body_force, body) if b is not None]
            if loaded:                                    # None: no load at that level
                b_mean = 0.5 * sum(loaded)
                self.work_in += float(np.dot(props.quad_weights,
                                             np.einsum("ni,ni->n", b_mean, dx)))
            self.xdot_nodes = vdot
        self.power, self.body_force = power, body
        self.Y_prev, self.h_prev = self.Y, h
        self.Y, self.Ydot, self.F_old = Y, Ydot, Fn
        self.t = t_new
        self.bc = bc
        self.first_step = False
        if space is not None:
            self.q, self.r = space
            self.v_global = np.einsum("nij,nj->ni", quat_to_matrix(self.q), self.Y[:, 0:3])
        elif sysm.needs_pose:
            self.update_space_route()
        self.last_iterations, self.last_residual = its, res
        return True, its, res, False

    def _contact_step_ok(self, r_space, r_newton) -> bool:
        """Step control where self-contact is possible (docs/contact.md).

        A step is refused (and Δt cut) when (a) two non-neighbouring nodes may have passed
        through each other within the step: with their relative position moving linearly
        from its old to its new value, the closest approach falls below half the sum of
        their radii (a swept test on the pairs a k-d tree finds within the largest
        relative motion); (b) the positions Newton used for the contact forces (time
        route) differ from the shape integrated from κ (space route) by more than
        δ/2, δ = ½(tolerance − max D); or (c) the surfaces of the space-route shape
        interpenetrate.
        """
        c = self.contact
        props = self.props
        tangents = np.diff(r_space, axis=0)
        tangents = np.vstack([tangents, tangents[-1:]])
        if not c.may_touch(r_space, tangents) and not c.may_touch(self.r, tangents):
            return True
        dmax = float(np.max(props.diameter))
        delta = 0.5 * (c.tolerance - dmax)
        if delta <= 0.0:
            delta = 0.25 * dmax
        if float(np.max(np.linalg.norm(r_space - r_newton, axis=1))) > 0.5 * delta:
            return False
        # (a) swept test
        disp = r_space - self.r
        reach = dmax + 2.0 * float(np.max(np.linalg.norm(disp, axis=1)))
        cand = cKDTree(r_space).query_pairs(r=reach, output_type="ndarray")
        if cand.size:
            a, b = cand[:, 0], cand[:, 1]
            far = np.abs(props.s[a] - props.s[b]) > c.separation_cut
            a, b = a[far], b[far]
            if a.size:
                x0 = self.r[a] - self.r[b]
                dx = disp[a] - disp[b]
                dd = np.einsum("ij,ij->i", dx, dx)
                tmin = np.clip(-np.einsum("ij,ij->i", x0, dx) / np.where(dd > 0, dd, 1.0),
                               0.0, 1.0)
                closest = np.linalg.norm(x0 + tmin[:, None] * dx, axis=1)
                radii = 0.5 * (props.diameter[a] + props.diameter[b])
                if np.any(closest < 0.5 * radii):
                    return False
        # (c) no interpenetration of the new shape
        pairs = c.find_pairs(r_space, tangents)
        if len(pairs.i):
            gaps = pairs.distance - 0.5 * (props.diameter[pairs.i] + props.diameter[pairs.j])
            if float(np.min(gaps)) < 0.0:
                return False
        return True

    def _find_pairs(self, positions, R):
        """Contact pairs at the given positions (N+1, 3) and rotations (N+1, 3, 3), or
        None when no pair is possible (the O(N) test skips the k-d tree)."""
        tangents = R[:, :, 2]
        if not self.contact.may_touch(positions, tangents):
            return None
        pairs = self.contact.find_pairs(positions, tangents)
        return pairs if len(pairs.i) else None

    @staticmethod
    def _merge_pairs(used, found):
        """``used`` itself if every pair of ``found`` is in it, else the union."""
        if found is None:
            return used
        if used is None:
            return found
        n = 1 + int(max(used.i.max(), used.j.max(), found.i.max(), found.j.max()))
        key_used = set((used.i * n + used.j).tolist())
        key_found = (found.i * n + found.j).tolist()
        if all(k in key_used for k in key_found):
            return used
        keep = np.array([k not in key_used for k in key_found])
        return _concat_pairs(used, found, keep)

    def update_space_route(self):
        """Recompute pose along the rod from κ, anchored at node 0's time-route pose."""
        self.q, self.r = space_route(self.q_time[0], self.r_time[0], self.Y[:, 9:12],
                                     self.props.ds)
        self.v_global = np.einsum("nij,nj->ni", quat_to_matrix(self.q), self.Y[:, 0:3])

    def advance(self, t_target: float):
        """Advance to t_target (s), cutting Δt on failure. Returns (iterations, residual)
        of the nominal step; raises SolverDivergence (without partial) when all cuts
        fail.

        Δt levels: h = (t_target − t)/factor^level. A nominal step starts one level below
        the level the previous one needed (so Δt grows back gradually after an event), and
        substeps at the current level until t_target is reached; after
        ``GROW_AFTER`` consecutive accepted substeps the level drops by one (Δt grows by
        the factor) within the nominal step as well, so one brief event does not leave
        the rest of the step at the smallest Δt.
        """
        num = self.case.numerics
        h_full = t_target - self.t
        level = max(0, self.level_hint - 1)
        total_its = 0
        failed = False
        accepted = 0
        while self.t < t_target - 1e-12 * max(1.0, abs(t_target)):
            if accepted >= self.GROW_AFTER and level > 0:
                level -= 1
                accepted = 0
            h = h_full / num.dt_cut_factor**level
            h_try = min(h, t_target - self.t)
            if t_target - self.t - h_try < 1e-9 * h:
                h_try = t_target - self.t
            ok, its, res, nonfinite = self.try_step(h_try)
            total_its += its
            if ok:
                self.last_dt = h_try
                accepted += 1
                continue
            accepted = 0
            failed = True
            if level >= num.max_dt_cuts:
                singular = self.system.last_failure == "singular"
                reason = "nonfinite_state" if (nonfinite and not singular) else "solver_diverged"
                why = ("singular Jacobian: the boundary conditions leave a force or moment "
                       "undetermined (e.g. a straight inextensible rod held axially at both "
                       "ends)" if singular else
                       "non-finite state" if nonfinite else "Newton did not converge")
                raise SolverDivergence(
                    f"time step from t = {self.t:.6g} s did not converge after {level} "
                    f"Δt cuts (Δt = {h_try:.3g} s, scaled residual {res:.3g}, {why})",
                    t=self.t, step=None, residual=res, reason=reason)
            level += 1
        self.level_hint = level if failed else max(0, level)
        return total_its, self.last_residual

    # -------------------------------------------------------------------------------
    def snapshot(self, fields: set) -> dict:
        """Output quantities of the current state for the requested field groups."""
        out = {}
        Y = self.Y
        if not self.system.needs_pose:
            self.update_space_route()
        if "v" in fields:
            out["v"] = Y[:, 0:3].copy()
        if "omega" in fields:
            out["omega"] = Y[:, 3:6].copy()
        if "f" in fields:
            out["f"] = Y[:, 6:9].copy()
        if "kappa" in fields:
            out["kappa"] = Y[:, 9:12].copy()
        if "moment" in fields:
            out["moment"] = self.props.stiffness * Y[:, 9:12]
        if "position" in fields:
            out["position"] = self.r.copy()
        if "orientation" in fields:
            out["orientation"] = self.q.copy()
        if "energies" in fields:
            out.update(energies(Y, self.props))
            out["work_in"] = self.work_in
            out["power_in"] = self.power
        if "topology" in fields:
            from .topology import linking_number, twist, writhe

            tw = twist(Y[:, 11], self.props.s)
            wr = writhe(self.r)
            lk = linking_number(self.phi[0], self.phi[1])
            out.update(twist=tw, writhe=wr, linking_number=lk,
                       topology_error=abs(tw + wr - lk))
        if "contact" in fields:
            out["contact_count"] = self.contact_count
            out["min_surface_gap"] = self.min_gap
        out["newton_iterations"] = self.last_iterations
        out["residual_norm"] = self.last_residual
        out["dt"] = self.last_dt
        out["position_route_difference"] = float(np.max(np.linalg.norm(self.r_time - self.r, axis=1)))
        out["quaternion_norm_error"] = self.quat_norm_error
        return out


def _concat_pairs(used, found, keep):
    """Union of two pair sets (same class), taking the pairs of ``found`` flagged keep."""
    import dataclasses

    fields = {}
    for fld in dataclasses.fields(used):
        a, b = getattr(used, fld.name), getattr(found, fld.name)
        if isinstance(a, np.ndarray) and a.shape[:1] == used.i.shape:
            fields[fld.name] = np.concatenate([a, b[keep]])
        else:
            fields[fld.name] = a
    return type(used)(**fields)


def simulate(case, progress=None, should_stop=None):
    """Run a case and return its result dataset (DESIGN.md "Result dataset").

    Parameters
    ----------
    case : solver.case.Case
    progress : callable(Progress) or None, called after every accepted nominal step
    should_stop : callable() -> bool | str, or None; checked before every step. A truthy
        value stops the run: the partial dataset is *returned* with
        ``attrs["hockle_status"] = "stopped"`` and ``attrs["hockle_stop_reason"]``.

    Returns
    -------
    xarray.Dataset with ``attrs["hockle_status"]`` in {"completed", "stopped"}.

    Raises
    ------
    SolverDivergence
        when a step cannot be completed after all Δt cuts; ``.partial`` holds the dataset
        up to the last accepted step (``hockle_status = "failed"``).
    """
    from threadpoolctl import threadpool_limits

    # the linear algebra is band LU and small dense blocks: BLAS threads only add
    # overhead and oversubscribe shared cores (measured 3.8x slower in contact phases)
    with threadpool_limits(limits=1, user_api="blas"):
        return _simulate(case, progress, should_stop)


def _simulate(case, progress, should_stop):
    from .results import build_dataset

    wall0 = _time.perf_counter()
    run = RodRun(case)
    num = case.numerics
    fields = set(case.output.fields)
    every = case.output.every
    n_steps = max(1, int(math.ceil(num.t_end / num.dt - 1e-9)))
    times, records = [], []
    diag = {"step_time": [], "step_dt": [], "step_newton_iterations": [],
            "step_residual_norm": []}

    def record():
        times.append(run.t)
        records.append(run.snapshot(fields))

    def finish(status, message="", reason=None):
        stacked = {}
        if records:
            for key in records[0]:
                stacked[key] = np.asarray([rec[key] for rec in records])
        ds = build_dataset(case, run.props.s, np.asarray(times), stacked,
                           {k: np.asarray(v) for k, v in diag.items()}, status, message)
        if reason is not None:
            ds.attrs["hockle_stop_reason"] = reason
        ds.attrs["wall_time_s"] = _time.perf_counter() - wall0
        ds.attrs["factorizations"] = run.system.factorizations
        return ds

    record()
    budget = num.wall_clock_budget
    for step in range(1, n_steps + 1):
        if should_stop is not None:
            flag = should_stop()
            if flag:
                reason = flag if isinstance(flag, str) else "stopped"
                return finish("stopped", f"stopped at t = {run.t:.6g} s: {reason}", reason)
        if budget is not None and _time.perf_counter() - wall0 > budget:
            return finish("stopped", f"wall-clock budget of {budget} s exceeded at "
                          f"t = {run.t:.6g} s", "timeout")
        t_target = min(step * num.dt, num.t_end)
        try:
            its, res = run.advance(t_target)
        except SolverDivergence as exc:
            exc.step = step - 1
            exc.partial = finish("failed", str(exc), exc.reason)
            raise
        diag["step_time"].append(run.t)
        diag["step_dt"].append(run.last_dt)
        diag["step_newton_iterations"].append(its)
        diag["step_residual_norm"].append(res)
        if step % every == 0 or step == n_steps:
            record()
        if progress is not None:
            progress(Progress(t=run.t, t_end=num.t_end, step=step, dt=run.last_dt,
                              newton_iterations=its, residual_norm=res,
                              wall_time=_time.perf_counter() - wall0,
                              fraction=min(1.0, run.t / num.t_end),
                              contact_count=run.contact_count))
    return finish("completed", f"completed {n_steps} steps to t = {run.t:.6g} s")
