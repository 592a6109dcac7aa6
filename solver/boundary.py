"""Boundary rows of the step's difference equations (docs/case-spec.md, "Boundary").

Each end has six conditions, one per degree of freedom, in body-frame components:
translation i = 1, 2, 3 prescribes the velocity v_i or the internal force f_i, rotation
i prescribes the angular velocity ω_i or the internal moment q_i = B_ii κ_i. They are
imposed at the new time level, unweighted, as in WHOI Cable (numerics-notes §1.2).

Sign convention: f(s) and q(s) are the force and moment that the part of the rod beyond
s (larger arclength) exerts on the part before it; so f3 > 0 is tension at either end,
the load applied *to* the end s = L is +f(L), and the load applied to the end s = 0 is
−f(0).
"""
from __future__ import annotations

import numpy as np

from .banded import NV

__all__ = ["BoundaryRows", "BoundarySchedule", "boundary_plan", "global_translation", "position_rate", "towed_free"]

_GROUPS = ("translation", "rotation")


def boundary_plan(case, props, n: int):
    """The 12 boundary rows of a case as (row, choices) pairs, each choice (until (s) or
    None, column, Jacobian entry, kinematic, value: a float or the table's (t, value)
    arrays, turning: a global velocity imposed through the end's new-level frame,
    :func:`towed_free`), in the case's order, so that :class:`BoundaryRows` finds the condition in
    force at t without going through the case's models (the first choice whose until is
    None or ≥ t, ``EndCondition.active``'s rule). Built once per (case, grid) and kept
    on the case object."""
    key = (id(props), n)
    memo = getattr(case, "_hockle_boundary_plan", None)
    if memo is not None and memo[0] == key:
        return memo[1]
    from .case import UNTIL_RTOL, Table

    n_last = props.s.size - 1
    plan = []
    frames = None
    for end, node, row0 in (("start", 0, 0), ("end", n_last, n - 6)):
        ec = getattr(case.boundary, end)
        glob = None
        if getattr(ec, "frame", "body") == "global":
            if frames is None:
                from .initial import initial_pose
                from .kinematics import quat_to_matrix
                frames = quat_to_matrix(initial_pose(case, props.s)[0][[0, -1]])
            R0 = frames[0 if end == "start" else 1]
            glob = [(None if phase[0].until is None else phase[0].until * (1.0 + UNTIL_RTOL),
                     global_translation(ec, R0, phase), towed_free(ec, phase))
                    for phase in zip(*ec.translation)]
        for g, group in enumerate(_GROUPS):
            for i in range(3):
                if glob is not None and group == "translation":
                    plan.append((row0 + i, [(until, NV * node + (0 if rows[i][0] else 6) + i,
                                             1.0, rows[i][0], rows[i][1], turning)
                                            for until, rows, turning in glob]))
                    continue
                choices = []
                for cond in getattr(ec, group)[i]:
                    kinematic = bool(cond.kinematic)
                    if group == "translation":
                        idx = (0 if kinematic else 6) + i
                        c = 1.0
                    else:
                        idx = (3 if kinematic else 9) + i
                        c = 1.0 if kinematic else float(props.stiffness[node, i])
                    value = cond.value
                    value = ((np.asarray(value.t, float), np.asarray(value.value, float))
                             if isinstance(value, Table) else float(value))
                    until = None if cond.until is None else cond.until * (1.0 + UNTIL_RTOL)
                    choices.append((until, NV * node + idx, c, kinematic, value, False))
                plan.append((row0 + 3 * g + i, choices))
    return plan


def position_rate(value, Table):
    """The velocity (m/s) of a position condition: 0 for a number (a point held); for a
    table, the slope of each of its pieces, as a table (t, value) that jumps just after
    each knot (1e-9 of the shortest piece later), so that a step landing on a knot (the
    knots are breakpoints, :func:`solver.stepping.breakpoints`) takes the slope of the
    piece it covers, and 0 outside the table (a position held constant)."""
    if not isinstance(value, Table):
        return 0.0
    t = np.asarray(value.t, float)
    p = np.asarray(value.value, float)
    slope = np.diff(p) / np.diff(t)
    delta = 1e-9 * float(np.min(np.diff(t)))
    times, rates = [t[0]], [0.0]
    for k in range(slope.size):
        times += [t[k] + delta, t[k + 1]]
        rates += [slope[k], slope[k]]
    times.append(t[-1] + delta)
    rates.append(0.0)
    return np.asarray(times), np.asarray(rates)


def towed_free(ec, phase=None) -> bool:
    """Whether an end with ``frame: global`` is moved (a velocity other than 0, or a
    position table) while its rotation is free (moment 0): its body-frame velocity is
    then v = R(t)ᵀ V(t) with R the end's frame at the new level, which the unknowns
    decide (:func:`solver.scheme.residual_into`). ``phase``: the three translation
    conditions in force together (None: the first)."""
    from .case import Table

    if ec.rotation_mode != "free":
        return False
    items = [c[0] for c in ec.translation] if phase is None else list(phase)
    if items[0].kind == "force":
        return False
    return any(isinstance(c.value, Table) or (c.kind == "velocity" and c.value != 0.0)
               for c in items)


def global_translation(ec, R0, phase=None):
    """The three translation rows of an end with ``frame: global`` (docs/case-spec.md,
    "Global-frame ends") as (kinematic, value) per body component i, a value a float or
    a (t, value) table; ``phase``: the three conditions in force together (one of the
    items' switching phases; None: the first). With the rotation held fixed in space the end's frame is its
    initial one, R0 (3, 3) [a1 a2 a3], so the body components of the global velocity V
    (a position table's :func:`position_rate`) or of the global internal force F are
    R0ᵀ V, R0ᵀ F, exact and linear; on the union of the tables' knots they are again
    piecewise linear. With the rotation free the end is held (v = 0), or moved
    (:func:`towed_free`: the values are then the global components of V, turned into
    the end's new-level frame by the residual), or its internal force is 0 here and the
    dead force is a point load at the end (:class:`solver.loads.PointLoads`)."""
    from .case import Table

    items = [c[0] for c in ec.translation] if phase is None else list(phase)
    kinematic = items[0].kind != "force"
    if ec.rotation_mode == "free":
        if not towed_free(ec, phase):
            return [(kinematic, 0.0)] * 3
        R0 = np.eye(3)
    series = []
    for c in items:
        if c.kind == "position":
            series.append(position_rate(c.value, Table))
        elif isinstance(c.value, Table):
            series.append((np.asarray(c.value.t, float), np.asarray(c.value.value, float)))
        else:
            series.append(float(c.value))
    tabled = [x for x in series if not isinstance(x, float)]
    if not tabled:
        g = np.array(series, float)
        return [(kinematic, float(R0[:, i] @ g)) for i in range(3)]
    times = np.unique(np.concatenate([x[0] for x in tabled]))
    G = np.stack([np.full(times.size, x) if isinstance(x, float) else np.interp(times, *x)
                  for x in series])
    return [(kinematic, (times, R0[:, i] @ G)) for i in range(3)]


class BoundaryRows:
    """The 12 boundary rows in force at time t.

    Parameters
    ----------
    case : solver.case.Case
    props : RodProperties
    t : float, s
    n : int, number of unknowns 12(N+1)
    plan : :func:`boundary_plan` of (case, props, n), or None to build it here

    Attributes
    ----------
    rows, cols : (12,) int, matrix positions (rows 0-5 for s = 0, n-6..n-1 for s = L)
    coef : (12,) float, the Jacobian entries (1, or the stiffness for a moment)
    values : (12,) float, prescribed values (m/s, rad/s, N, N m)
    kinematic : (12,) bool
    turning : (2,) bool, per end (s = 0, s = L): its three translation rows hold a global
        velocity V (values 0-2 or 6-8, m/s) imposed as v = R^{n+1}ᵀ V through the end's
        new-level frame (:func:`towed_free`; :func:`solver.scheme.residual_into`)
    key : hashable description of which kind of condition holds on each DOF
    """

    #: no towed end (the default of rows kept in a checkpoint written before towed ends)
    turning = np.zeros(2, dtype=bool)

    def __init__(self, case, props, t: float, n: int, plan=None, choice=None):
        plan = boundary_plan(case, props, n) if plan is None else plan
        rows, cols, coef, vals, kin, turn = [], [], [], [], [], []
        for k, (row, choices) in enumerate(plan):
            if choice is not None:
                until, col, c, kinematic, value, *towed = choices[choice[k]]
            else:
                for until, col, c, kinematic, value, *towed in choices:
                    if until is None or t <= until:
                        break
            # a plan kept in a checkpoint written before towed ends has 5-field choices
            turning = bool(towed and towed[0])
            turn.append(turning)
            rows.append(row)
            cols.append(col)
            coef.append(c)
            vals.append(value if isinstance(value, float)
                        else float(np.interp(float(t), value[0], value[1])))
            kin.append(kinematic)
        self.rows = np.array(rows, dtype=np.intp)
        self.cols = np.array(cols, dtype=np.intp)
        self.coef = np.array(coef, dtype=float)
        self.values = np.array(vals, dtype=float)
        self.kinematic = np.array(kin)
        self.turning = np.array([turn[0], turn[6]])
        self.key = tuple(cols) + (("turning", turn[0], turn[6]),) if self.turning.any() else tuple(cols)
        # what project and end_kinematic_dofs derive from the rows, made at their first
        # use (shared by the rows a BoundarySchedule makes from one template)
        self.derived = {}

    def end_drift_offsets(self, n_last: int, position_error, rotation_error, rate: float):
        """Offsets (12,) to the prescribed values that steer the s = L end back onto its
        prescribed motion: rate·(a_i·e) on each kinematic translation row i = 1, 2, 3 and
        rate·θ_i on each kinematic rotation row i = 1, 2 (the tilt of a3; a prescribed
        rate about a3 is left alone, so that the end rotation φ of the linking number
        stays the prescribed one), zero elsewhere.

        n_last: index N of the s = L node; position_error (3,) m and rotation_error (3,)
        rad: body-frame components of how far the end's prescribed position and frame lie
        from the end of the centreline (:meth:`solver.step_problem.ProblemAssembly.end_correction`);
        rate: 1/s. A velocity-level (Baumgarte) stabilisation of the end's position
        constraint: Baumgarte, Comput. Methods Appl. Mech. Eng. 1 (1972) 1-16."""
        off = np.zeros(self.rows.size)
        for j, idx in self.end_kinematic_dofs(n_last):
            if idx < 3:
                off[j] = rate * float(position_error[idx])
            elif idx < 5:
                off[j] = rate * float(rotation_error[idx - 3])
        return off

    def project(self, Y: np.ndarray) -> np.ndarray:
        """A copy of Y (N+1, 12) that satisfies these 12 rows: each prescribed unknown set
        to value/coef (a Newton start that meets the step's linear boundary rows; the
        translation rows of a :attr:`turning` end are left as they are). Raises
        nothing (coef is 1, or a bending/torsional stiffness > 0, by construction)."""
        out = np.array(Y, dtype=float)
        d = self.derived
        keep = d.get("keep")
        if keep is None:
            keep = np.ones(self.cols.size, bool)
            for e in np.flatnonzero(self.turning):
                keep[6 * e:6 * e + 3] = False     # v = RᵀV: R is the iterate's
            if keep.all():
                keep = slice(None)
            d["keep"] = keep = (keep, self.cols[keep], self.coef[keep])
        mask, cols, coef = keep
        out.reshape(-1)[cols] = self.values[mask] / coef
        return out

    def end_kinematic_dofs(self, n_last: int):
        """The kinematic conditions at s = L as (row j in 6..11 of these 12 rows, degree of
        freedom 0-5: v1, v2, v3, ω1, ω2, ω3) pairs, a list. n_last: index N of the s = L
        node."""
        d = self.derived
        dofs = d.get(("dofs", n_last))
        if dofs is None:
            dofs = d[("dofs", n_last)] = tuple(
                (j, int(self.cols[j]) - NV * n_last) for j in range(6, 12) if self.kinematic[j])
        return list(dofs)

    def residual(self, Y: np.ndarray, R: np.ndarray) -> None:
        """Write the 12 boundary residuals coef·Y − value into R (n,) in place."""
        R[self.rows] = self.coef * Y.reshape(-1)[self.cols] - self.values

    def jacobian_entries(self):
        """(rows, cols, values) of the boundary rows' Jacobian entries."""
        return self.rows, self.cols, self.coef


class BoundarySchedule:
    """The boundary rows of a run at any time (:meth:`at`), from its :func:`boundary_plan`.

    Which condition holds on each row changes only at its ``until`` times; the rows,
    columns, coefficients and kinds of each such combination are made once (a template
    :class:`BoundaryRows`), and a step's rows copy them and set the values at its time
    (a constant, or the interpolated table), so that a step does not rebuild them from
    the plan. The rows are those ``BoundaryRows(case, props, t, n, plan)`` makes.

    Parameters: as :class:`BoundaryRows` (plan None: :func:`boundary_plan` of case,
    props and n, kept as ``plan``).
    """

    def __init__(self, case, props, n: int, plan=None):
        plan = boundary_plan(case, props, n) if plan is None else plan
        self.case, self.props, self.n, self.plan = case, props, n, plan
        # rows whose condition switches: (row index, the untils of its choices)
        self.switching = tuple((k, tuple(ch[0] for ch in choices))
                               for k, (_, choices) in enumerate(plan)
                               if len(choices) > 1 or choices[0][0] is not None)
        self.templates = {}

    def at(self, t: float) -> BoundaryRows:
        """The rows in force at t (s), a new :class:`BoundaryRows` (its ``values`` its
        own; the other arrays shared with the rows of the same conditions, read only)."""
        choice = [0] * len(self.plan)
        for k, untils in self.switching:
            for i, until in enumerate(untils):
                if until is None or t <= until:
                    break
            choice[k] = i
        key = tuple(choice)
        entry = self.templates.get(key)
        if entry is None:
            template = BoundaryRows(self.case, self.props, t, self.n, self.plan, choice=key)
            tables = tuple((j, choices[key[j]][4]) for j, (_, choices) in enumerate(self.plan)
                           if not isinstance(choices[key[j]][4], float))
            entry = self.templates[key] = (template, tables)
        template, tables = entry
        out = BoundaryRows.__new__(BoundaryRows)
        out.__dict__.update(template.__dict__)
        values = template.values.copy()
        for j, (times, series) in tables:
            values[j] = float(np.interp(float(t), times, series))
        out.values = values
        return out
