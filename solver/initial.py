"""The initial configuration of a run: a straight rod, or a given centreline with an
initial twist rate (docs/case-spec.md, "Initial").

A centreline given as points is made a smooth curve by a cubic spline through them in
their chord length (scipy's ``CubicSpline``, not-a-knot ends; two points give a
segment), measured by Gauss-Legendre quadrature of its speed, and resampled at the
grid's arclengths (the curve's parameter scaled so that its length is the rod's). Its
frames are the rotation-minimising (Bishop) frame, transported from the start's
``normal`` by the double-reflection method (Wang, Jüttler, Zheng & Liu, ACM Trans.
Graph. 27 (2008) 2) on 16 substeps per cell, turned about the tangent by the twist
rate τ0 (rad/m) times s. The curvature is the Darboux vector in those frames,
κ = (−c·a2, c·a1, τ0) with c = da3/ds the curve's curvature vector (R' = R[κ]×, so
a3' = κ2 a1 − κ1 a2). A node takes its bending components as the rotation of the
rotation-minimising frame across the node's dual cell (half a cell either side,
:func:`_dual_cell_curvatures`) over that length, turned into the node's twisted frame:
κ's mean there, so that a curvature jump inside a cell does not turn the rest of the
rod. The pose the run starts from is the space route of those κ
(:func:`solver.kinematics.space_route`, the one the scheme carries), anchored at the
first point and the first frame: it lies within O(Δs²) of the given curve.

Velocities and forces start at zero; the run's first step is a consistent restart
(:mod:`solver.stepping`), which sets f to what the loads and conditions then require.
A curved start is an equilibrium only where it is one (a catenary under its own weight
with its ends held where the curve puts them; a stress-free rod whose rest shape it is
is not modelled: the rod is straight when unstressed), so a curved rod set free moves.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Curve", "StartState", "StartOffset", "initial_pose", "node_frames", "initial_state",
           "start_offset", "LENGTH_RTOL", "START_OFFSET_ADVICE"]

#: relative tolerance with which a centreline's length must match rod.length
LENGTH_RTOL = 1e-3
#: Gauss-Legendre nodes and weights on [0, 1] for the curve's length
_GL_X, _GL_W = np.polynomial.legendre.leggauss(6)
_GL_X = 0.5 * (_GL_X + 1.0)
_GL_W = 0.5 * _GL_W
#: substeps per cell of the frame transport, and per spline piece of the length table
_SUB = 16


class Curve:
    """A smooth curve through points (M, 3) m, M >= 2 distinct consecutive points.

    Attributes: ``length`` (m, by quadrature), ``u`` the chord-length knots (M,).
    Raises ValueError for fewer than 2 points or a zero-length segment.
    """

    def __init__(self, points):
        from scipy.interpolate import CubicSpline

        P = np.asarray(points, dtype=float)
        if P.ndim != 2 or P.shape[1] != 3 or P.shape[0] < 2:
            raise ValueError("a centreline needs at least 2 points of 3 coordinates")
        chord = np.linalg.norm(np.diff(P, axis=0), axis=1)
        if not np.all(chord > 0):
            k = int(np.argmin(chord > 0)) + 1
            raise ValueError(f"points {k - 1} and {k} coincide (a zero-length segment)")
        self.u = np.concatenate([[0.0], np.cumsum(chord)])
        if P.shape[0] == 2:
            self.spline = CubicSpline(self.u, P, bc_type=((1, (P[1] - P[0]) / chord[0]),
                                                          (1, (P[1] - P[0]) / chord[0])))
        else:
            self.spline = CubicSpline(self.u, P, bc_type="not-a-knot")
        self.d1 = self.spline.derivative(1)
        # length table on a fine subdivision of every piece
        fine = np.concatenate([np.linspace(a, b, _SUB, endpoint=False)
                               for a, b in zip(self.u[:-1], self.u[1:])] + [[self.u[-1]]])
        self.fine = fine
        h = np.diff(fine)
        x = fine[:-1, None] + h[:, None] * _GL_X[None, :]
        speed = np.linalg.norm(self.d1(x.ravel()), axis=1).reshape(x.shape)
        self.table = np.concatenate([[0.0], np.cumsum(h * (speed @ _GL_W))])
        self.length = float(self.table[-1])

    def _arc(self, u):
        """Arclength (m) from the start to parameters u (array)."""
        j = np.clip(np.searchsorted(self.fine, u, side="right") - 1, 0, self.fine.size - 2)
        a = self.fine[j]
        h = u - a
        x = a[:, None] + h[:, None] * _GL_X[None, :]
        speed = np.linalg.norm(self.d1(x.ravel()), axis=1).reshape(x.shape)
        return self.table[j] + h * (speed @ _GL_W)

    def parameter_at(self, s):
        """The curve's parameter at arclengths s (m, within [0, length]): interpolated
        in the length table, then three Newton steps on the quadrature (to round-off)."""
        s = np.asarray(s, dtype=float)
        u = np.interp(s, self.table, self.fine)
        for _ in range(3):
            speed = np.linalg.norm(self.d1(u), axis=1)
            u = np.clip(u - (self._arc(u) - s) / speed, 0.0, self.u[-1])
        return u

    def start_tangent(self):
        """Unit tangent (3,) at the first point."""
        t = self.d1(0.0)
        return t / np.linalg.norm(t)


def _frames(curve, s, normal, twist_rate):
    """Frames R (n, 3, 3) [a1 a2 a3] and curvatures κ (n, 3) 1/m at arclengths s (n,)
    (uniform, from 0) of the curve scaled to length s[-1] (module docstring)."""
    n = s.size
    scale = curve.length / s[-1]
    sub = np.linspace(0.0, s[-1], (n - 1) * _SUB + 1)
    u = curve.parameter_at(sub * scale)
    r = curve.spline(u)
    d1 = curve.d1(u)
    t = d1 / np.linalg.norm(d1, axis=1)[:, None]
    a1 = np.empty_like(t)
    a1[0] = normal - np.dot(normal, t[0]) * t[0]
    a1[0] /= np.linalg.norm(a1[0])
    for j in range(sub.size - 1):
        # double reflection: reflect across the chord's bisector, then across the one of
        # the tangents' difference (Wang et al. 2008, Algorithm 1)
        v1 = r[j + 1] - r[j]
        c1 = v1 @ v1
        aL = a1[j] - (2.0 / c1) * (v1 @ a1[j]) * v1
        tL = t[j] - (2.0 / c1) * (v1 @ t[j]) * v1
        v2 = t[j + 1] - tL
        c2 = v2 @ v2
        a = aL - (2.0 / c2) * (v2 @ aL) * v2 if c2 > 0 else aL
        a -= (a @ t[j + 1]) * t[j + 1]
        a1[j + 1] = a / np.linalg.norm(a)
    bishop = np.stack([a1, np.cross(t, a1), t], axis=2)
    idx = np.arange(n) * _SUB
    A1, A2, T = bishop[idx, :, 0], bishop[idx, :, 1], bishop[idx, :, 2]
    phi = twist_rate * s
    c, sn = np.cos(phi)[:, None], np.sin(phi)[:, None]
    B1, B2 = c * A1 + sn * A2, -sn * A1 + c * A2
    # bending curvatures over the nodes' dual cells in the rotation-minimising frames,
    # whose components do not turn with the twist, then in the twisted node frames
    theta = _dual_cell_curvatures(bishop, n, float(s[1] - s[0]))
    kappa = np.empty((n, 3))
    kappa[:, 0] = c[:, 0] * theta[:, 0] + sn[:, 0] * theta[:, 1]
    kappa[:, 1] = -sn[:, 0] * theta[:, 0] + c[:, 0] * theta[:, 1]
    kappa[:, 2] = float(twist_rate)
    R = np.stack([B1, B2, T], axis=2)
    return R, kappa, r[0]


def _dual_cell_curvatures(frames, n, ds):
    """Body-frame curvatures κ (n, 3) 1/m at the nodes from the frames (M, 3, 3) [a1 a2 a3]
    on _SUB substeps per cell (M = (n − 1)·_SUB + 1; ds the cell length, m): for each
    node, the rotation from the frame half a cell before it to the one half a cell after
    (within [0, L]), as a rotation vector in the node's frame, over that arclength. For
    a constant κ that is κ; in general it is κ's mean over the node's dual cell to
    O(Δs²). Components that turn within the cell come out shorter by sinc(½ωΔs), ω their
    rate of turn: :func:`_frames` therefore passes the rotation-minimising frames, in
    which a plane curve's bending does not turn (a twisted frame's would: 2 % shorter for
    `cases/seabed-hockle.yaml`'s 9.4 rad/m over 5-cm cells), and a helix's turns with its
    torsion (3e-5 shorter for the one of ``tests/solver/test_initial_shapes.py``).

    Why not the curvature at the node: the space route turns each cell by the mean of
    its two nodes' κ (:func:`solver.kinematics.space_route`), so with dual-cell means the
    rotation accumulated to a node is the integral of κ up to half a cell before it plus
    half a cell's mean: second order also where the curvature jumps (a straight leg
    meeting an arc). With the curvature at the nodes, a jump inside a cell turned
    everything after it by up to Δs·Δκ/2: a 1-m hairpin with a 5-cm half circle ended
    61, 18 and 3.5 mm off its last point at 100, 200 and 400 segments, against 1.1, 0.25
    and 0.05 mm with the dual cells (``tests/solver/test_initial_shapes.py``)."""
    from scipy.spatial.transform import Rotation

    half = _SUB // 2
    m = (n - 1) * _SUB
    k = np.arange(n) * _SUB
    a, b = np.maximum(k - half, 0), np.minimum(k + half, m)
    Fa, Fb, Fk = frames[a], frames[b], frames[k]
    # R_aᵀ R_b = exp([θ]×) with θ in frame a's components; θ is the rotation's axis, so
    # frame b's components are the same; in the node's frame: R_kᵀ R_a θ
    rel = np.einsum("nji,njk->nik", Fa, Fb)
    theta = Rotation.from_matrix(rel).as_rotvec()
    theta = np.einsum("nji,njk,nk->ni", Fk, Fa, theta)
    return theta / ((b - a) * (ds / _SUB))[:, None]


def initial_pose(case, s):
    """The pose and curvatures a run starts from.

    Parameters
    ----------
    case : solver.case.Case (validated)
    s : (N+1,) grid arclengths, m

    Returns
    -------
    q : (N+1, 4) unit quaternions of the frames [a1 a2 a3]
    r : (N+1, 3) positions, m
    kappa : (N+1, 3) body-frame curvatures, 1/m (zero for a straight untwisted rod)

    A straight rod without twist starts as it always has (the same arrays, bit for bit):
    every node's frame (``normal``, ``tangent × normal``, ``tangent``), r = s·tangent.
    A closed rod starts from its circle (:func:`ring_pose`).
    """
    from .kinematics import quat_from_matrix, space_route

    if getattr(case.rod, "closed", False):
        return ring_pose(case, s)
    ini = case.initial
    s = np.asarray(s, dtype=float)
    n1 = s.size
    tangent = np.asarray(ini.tangent, float)
    tangent = tangent / np.linalg.norm(tangent)
    normal = np.asarray(ini.normal, float)
    normal = normal - np.dot(normal, tangent) * tangent
    normal = normal / np.linalg.norm(normal)
    centreline = getattr(ini, "centreline", None)
    twist = float(getattr(ini, "twist_rate", 0.0) or 0.0)
    if centreline is None:
        R0 = np.column_stack([normal, np.cross(tangent, normal), tangent])
        q0 = quat_from_matrix(R0)
        if twist == 0.0:
            return np.tile(q0, (n1, 1)), s[:, None] * tangent[None, :], np.zeros((n1, 3))
        kappa = np.zeros((n1, 3))
        kappa[:, 2] = twist
        q, r = space_route(q0, np.zeros(3), kappa, float(s[1] - s[0]))
        return q, r, kappa
    curve = Curve(centreline.points)
    R, kappa, r0 = _frames(curve, s - s[0], normal, twist)
    q0 = quat_from_matrix(R[0])
    q, r = space_route(q0, np.asarray(r0, float), kappa, float(s[1] - s[0]))
    return q, r, kappa


def ring_pose(case, s):
    """A closed rod's start (q (N+1, 4), r (N+1, 3) m, κ (N+1, 3) 1/m, as
    :func:`initial_pose`): the circle of circumference L through the origin, tangent
    ``initial.tangent`` there and bending towards ``initial.normal`` (its centre at
    R·normal, R = L/2π), its frame turned about the tangent by ``initial.linking_number``
    turns uniformly (φ = 2π Lk s/L): a1 = cos φ u + sin φ b, u the unit vector to the
    centre, b = tangent × normal, so κ = (sin φ/R, cos φ/R, 2π Lk/L). A plane circle has
    no writhe, so Lk = Tw. Node N is node 0 again (the same position and frame, the
    quaternion's sign aside)."""
    from .kinematics import quat_from_matrix

    ini = case.initial
    s = np.asarray(s, dtype=float)
    length = float(case.rod.length)
    t0 = np.asarray(ini.tangent, float)
    t0 = t0 / np.linalg.norm(t0)
    n0 = np.asarray(ini.normal, float)
    n0 = n0 - np.dot(n0, t0) * t0
    n0 = n0 / np.linalg.norm(n0)
    b = np.cross(t0, n0)
    radius = length / (2.0 * np.pi)
    theta = s / radius
    link = int(ini.linking_number or 0)
    phi = 2.0 * np.pi * link * s / length
    c, sn = np.cos(theta)[:, None], np.sin(theta)[:, None]
    r = radius * (sn * t0 + (1.0 - c) * n0)
    a3 = c * t0 + sn * n0
    u = c * n0 - sn * t0
    a1 = np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * b
    a2 = np.cross(a3, a1)
    q = np.array([quat_from_matrix(np.column_stack([x, y, z])) for x, y, z in zip(a1, a2, a3)])
    # one sign along s (q and −q are one frame; the box rule's rows need neighbours close)
    flip = np.cumsum(np.r_[0, np.einsum("ki,ki->k", q[1:], q[:-1]) < 0.0]) % 2 == 1
    q[flip] *= -1.0
    kappa = np.stack([np.sin(phi) / radius, np.cos(phi) / radius,
                      np.full(s.size, 2.0 * np.pi * link / length)], axis=1)
    r[-1] = r[0]
    return q, r, kappa


def node_frames(case, s):
    """The frames (N+1, 4) (unit quaternions of [a1 a2 a3]) of the case's initial shape at
    each node's own arclength s (N+1,) m: for an ``initial.centreline``, the curve's unit
    tangent and its twisted rotation-minimising normal there (:func:`_frames`), each
    node's own; otherwise :func:`initial_pose`'s (exact: a straight rod's frames turn
    about one axis). :func:`initial_pose` instead integrates κ along s from the first
    frame (the seed scheme's space route), which turns a twisted curve's tangents out of
    its plane at O(Δs²): the centreline scheme builds its centreline from these
    (:func:`solver.centreline.box_centreline`), so a plane curve stays in its plane."""
    from .kinematics import quat_from_matrix

    ini = case.initial
    s = np.asarray(s, dtype=float)
    if getattr(ini, "centreline", None) is None:
        return initial_pose(case, s)[0]
    tangent = np.asarray(ini.tangent, float)
    tangent = tangent / np.linalg.norm(tangent)
    normal = np.asarray(ini.normal, float)
    normal = normal - np.dot(normal, tangent) * tangent
    normal = normal / np.linalg.norm(normal)
    R, _, _ = _frames(Curve(ini.centreline.points), s - s[0], normal,
                      float(getattr(ini, "twist_rate", 0.0) or 0.0))
    q = np.array([quat_from_matrix(Rk) for Rk in R])
    # one sign along s (q and −q are one frame; the box rule's rows need neighbours close)
    flip = np.cumsum(np.r_[0, np.einsum("ki,ki->k", q[1:], q[:-1]) < 0.0]) % 2 == 1
    q[flip] *= -1.0
    return q


@dataclass(frozen=True)
class StartOffset:
    """How far the pose a run starts from lies from the centreline its case gives
    (:func:`start_offset`).

    distance: the largest distance of a node from the centreline's point at the node's
    arclength, m; s: that node's arclength, m; share: distance over the rod's diameter
    there; segments: the grid's cells; twist_step: Δs·|τ0| (rad), the twist of one cell.
    """

    distance: float
    s: float
    share: float
    segments: int
    twist_step: float

    def advice(self, limit: float | None = None) -> str | None:
        """A sentence naming the fields to change when ``share`` is above ``limit``
        (default :data:`START_OFFSET_ADVICE`), else None. The segments it proposes follow
        from the offset's O(Δs²) fall (the pose's error; module docstring): N·√(share/limit),
        rounded up to a multiple of 10 (an estimate: on grids too coarse for the O(Δs²)
        regime, a twisted arc's 10 segments propose 160 where its 40 propose 180)."""
        limit = START_OFFSET_ADVICE if limit is None else float(limit)
        if not self.share > limit:
            return None
        need = int(np.ceil(self.segments * np.sqrt(self.share / limit) / 10.0)) * 10
        twist = (f" (Δs·τ0 = {self.twist_step:.2f} rad: a twisted start needs cells "
                 "well under a radian of twist)" if self.twist_step > 0.0 else "")
        return (f"initial.centreline: on {self.segments} segments the start pose lies "
                f"{self.distance * 1e3:.3g} mm ({self.share:.2g} diameters) from the "
                f"given centreline at s = {self.s:.4g} m{twist}; the offset falls as Δs²: "
                f"numerics.n_segments of about {need} would bring it within "
                f"{limit:g} diameters")


#: the share of the rod's diameter by which the start pose may lie off the given
#: centreline before :meth:`StartOffset.advice` speaks. Evidence (docs/case-spec.md,
#: "Initial"): ``cases/seabed-hockle.yaml`` (τ0 = 9.42 rad/m) starts 1.12 / 0.29 / 0.073
#: diameters off at 40 / 80 / 160 segments, and stops within 0.07 s / at 3.67 s /
#: completes (``python -m research.hockle_resolution``)
START_OFFSET_ADVICE = 0.1


def start_offset(case, s=None, diameter=None, r=None) -> StartOffset | None:
    """How far the start pose of ``case`` on the grid s lies from its given centreline.

    Parameters
    ----------
    case : solver.case.Case (validated)
    s : (N+1,) grid arclengths, m (uniform; default the case's grid)
    diameter : (N+1,) the rod's diameter at s, m (default the case's ``rod.diameter``)
    r : (N+1, 3) the start pose's positions, m, where the caller has them (a run at its
        start); default :func:`initial_pose`'s

    Returns
    -------
    StartOffset, or None where the case gives no centreline (a straight start, with or
    without twist, is exact: its space route is the straight line) or starts from a
    result. Raises nothing for a validated case.

    The start pose is the space route of the resampled curvatures (module docstring),
    which lies within O(Δs²) of the curve; the constant grows with the twist rate τ0,
    because the route turns each cell by the mean of its two nodes' κ, whose bending
    components differ in direction by Δs·τ0 in the twisted frames (a chord of the
    bending's circle, shorter by cos(½Δs·τ0)).
    """
    ini = case.initial
    if getattr(ini, "centreline", None) is None:      # also a start from a result
        return None
    if s is None:
        s = np.linspace(0.0, case.rod.length, case.numerics.n_segments + 1)
    s = np.asarray(s, dtype=float)
    if diameter is None:
        diameter = case.rod.evaluate("diameter", s)
    if r is None:
        r = initial_pose(case, s)[1]
    curve = Curve(ini.centreline.points)
    target = curve.spline(curve.parameter_at((s - s[0]) * (curve.length / (s[-1] - s[0]))))
    d = np.linalg.norm(np.asarray(r, float) - target, axis=1)
    k = int(np.argmax(d))
    share = float(d[k] / np.asarray(diameter, float)[k])
    return StartOffset(distance=float(d[k]), s=float(s[k]), share=share, segments=s.size - 1,
                       twist_step=float(abs(float(ini.twist_rate or 0.0)) * (s[1] - s[0])))


@dataclass
class StartState:
    """The state a run starts from instead of its case's initial configuration
    (``initial.from_result``), read by the caller from an earlier result
    (:func:`solver.results.start_state_from`): time ``t`` (s) and per node v, ω, f, κ
    (N+1, 3) body frame (m/s, rad/s, N, rad/m), ``q`` (N+1, 4) unit quaternions, ``r``
    (N+1, 3) m; ``phi`` (2,) the end rotations about a3 (rad) of the linking number and
    ``work_in`` (J), or None where the result did not store them."""

    t: float
    v: np.ndarray
    omega: np.ndarray
    f: np.ndarray
    kappa: np.ndarray
    q: np.ndarray
    r: np.ndarray
    phi: object = None
    work_in: object = None


def initial_state(case, s, start=None):
    """(q (N+1, 4), r (N+1, 3), Y (N+1, 12), t0 (s)): the pose, unknowns and time a run
    starts from: :func:`initial_pose` with v = ω = f = 0 at t = 0, or the
    :class:`StartState` ``start`` as it is. Raises ValueError when the start's arrays do
    not match the grid."""
    n1 = np.asarray(s).size
    Y = np.zeros((n1, 12))
    if start is None:
        q, r, kappa = initial_pose(case, s)
        Y[:, 9:12] = kappa
        return q, r, Y, 0.0
    for name in ("v", "omega", "f", "kappa", "r"):
        if np.shape(getattr(start, name)) != (n1, 3):
            raise ValueError(f"start state: {name} has shape {np.shape(getattr(start, name))}, "
                             f"expected ({n1}, 3)")
    if np.shape(start.q) != (n1, 4):
        raise ValueError(f"start state: q has shape {np.shape(start.q)}, expected ({n1}, 4)")
    Y[:, 0:3], Y[:, 3:6], Y[:, 6:9], Y[:, 9:12] = start.v, start.omega, start.f, start.kappa
    return (np.array(start.q, dtype=float), np.array(start.r, dtype=float), Y,
            float(start.t))


def apply_start(state, start) -> None:
    """Set the rest of a run's state (:class:`solver.state.RunState`) from a
    :class:`StartState` (after :func:`initial_state` set the pose, the unknowns and the
    time): the time route of every node is the start's pose, the global velocities R v,
    and the end rotations and the work put in where the start has them."""
    from .kinematics import rotate_rows

    state.q_time, state.r_time = state.q.copy(), state.r.copy()
    state.v_global = np.empty_like(state.r)
    rotate_rows(np.ascontiguousarray(state.q), np.ascontiguousarray(state.Y[:, 0:3]),
                state.v_global)
    state.v_global_time = state.v_global.copy()
    if start.phi is not None:
        state.phi = np.array(start.phi, dtype=float)
    if start.work_in is not None:
        state.work_in = float(start.work_in)


def start_step(case, start) -> int:
    """The first fixed step of a run: 1, or after a start at t (a multiple of
    numerics.dt, :class:`solver.case.FromResult`) the step that follows it."""
    if start is None:
        return 1
    return int(round(start.t / case.numerics.dt)) + 1

