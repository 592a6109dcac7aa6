"""Static equilibria of the Kirchhoff rod: the box rule in s on the static equations.

The static problem drops the inertia and fluid velocity terms of the dynamic scheme
(``solver/scheme.py``, v = ω = 0) and writes the equilibrium of an inextensible,
unshearable Kirchhoff rod with global-frame unknowns per node k = 0..N (13 per node)::

    r_k (3)   centreline position, m (global)
    p_k (4)   unit quaternion (w, x, y, z) of the frame [a1 a2 a3] (R(p) e3 = a3 = r')
    n_k (3)   internal force, N (global): the force of the part s+ on the part s-
    m_k (3)   internal moment, N m (global)

with the constitutive law m = R K (κ − κ⁰), K = diag(EJ1, EJ2, GJ3) (seed eq. 1; κ⁰ the
intrinsic curvature and twist, ``rod.intrinsic_curvature``, zero for a rod straight and
untwisted when unloaded; the linear law about a curved rest shape, Antman, *Nonlinear
Problems of Elasticity*, 2nd ed., ch. 8), so κ_k = K⁻¹ R(p_k)ᵀ m_k + κ⁰_k. Kirchhoff's static equations (Antman, *Nonlinear
Problems of Elasticity*, ch. 8; the form of van der Heijden & Thompson, Nonlinear Dyn. 21,
2000) ::

    r' = a3,   p' = ½ p ⊗ (0, κ),   n' + f = 0,   m' + r' × n + l = 0

are discretised by the box rule (trapezoid/midpoint, second order in Δs = h) on each cell
[s_i, s_i+1], i = 0..N-1::

    r_i+1 − r_i − h/2 (a3_i + a3_i+1)                         = 0   (3)
    p_i+1 − p_i − h/4 (p_i + p_i+1) ⊗ (0, κ̄),  κ̄ = (κ_i + κ_i+1)/2 = 0   (4)
    n_i+1 − n_i + h/2 (f_i + f_i+1)                           = 0   (3)
    m_i+1 − m_i + h/2 (a3_i × n_i + a3_i+1 × n_i+1) + h/2 (l_i + l_i+1) = 0   (3)

The quaternion rows are the Cayley (midpoint) map: p_i+1 = (I − hΩ/4)⁻¹(I + hΩ/4) p_i with
Ω skew, so |p| is carried exactly from s = 0 and the frames stay orthonormal without a
projection. Dead loads f (N/m: gravity with buoyancy, distributed forces) are given at the
nodes; a point load P at an interior node k is the nodal load P/h (the trapezoid puts P/2
on each neighbouring cell); at an end it adds to the end force.

End conditions, 13 rows (7 at s = 0, 6 at s = L), in the end's axes E (3×3, columns e_j):
translation component j is held (e_j·(r − r_target) = 0) or loaded (e_j·(n_L − F) = 0 at
s = L, e_j·(n_0 + F) = 0 at s = 0, F the applied force); the rotation is held (p_0 = q_0,
4 rows; vec(q_Lᵀ ⊗ p_N) = 0, 3 rows) or free under a zero moment (m = 0, 3 rows, with
|p_0|² = 1 at s = 0). A held rotation is given with its total angle about the end's
tangent (``twist``, rad), which the quaternion keeps only modulo 2π: the Newton start and
the linking number use it.

The Jacobian is exact to rounding: each column group of the bidiagonal block pattern is
differentiated by the complex step (Squire & Trapp, SIAM Rev. 40, 1998; Martins et al.,
ACM TOMS 29, 2003): ∂G/∂y_j = Im G(y + iε e_j)/ε with ε = 1e-30, no subtraction, so no
truncation or cancellation error; 26 residual evaluations colour the whole matrix (nodes
of one parity share no row).

Self-contact, the seabed and screened electrostatics (optional, ``StaticProblem.contact``/
``seabed``/``electrostatics``) add nodal load densities L_k (N/m) to the force rows,
h/2 (L_i + L_i+1) per cell: the dynamic contact model at rest (its law without damping,
:func:`contact_loads`), the bottom's normal spring without damping or friction
(:func:`seabed_loads`) and the Debye–Hückel repulsion between non-adjacent segments
(:func:`electrostatic_loads`, :mod:`solver.electrostatics`), with their exact
derivatives with respect to the positions. All three are conservative; the energies of
:func:`fields` leave their potentials out.

Stability: the linearised dynamics about an equilibrium are M z̈ + K z = 0 with the
dynamic box rule; in the static rows this reads J z = μ B z, μ = −ω², where B puts the
mass per length ρA and the rotational inertia on the force and moment rows. For a
conservative problem (dead loads, held ends) the number of ω² < 0 (μ > 0) is the number of
negative eigenvalues of the second variation of the energy on the constraint manifold
(Sylvester's law of inertia: M positive definite does not change the count), i.e. the
number of unstable modes. :func:`unstable_modes` finds the eigenvalues μ nearest zero by
shift-invert Arnoldi (scipy ARPACK on J⁻¹B).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Optional

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .static_band import (KL, KU, BandSingular, BorderedBandLU, band_storage, cell_band,
                          cell_residual)

__all__ = ["EndSpec", "applied_sign", "StaticProblem", "StaticSolution", "StaticsError", "residual",
           "jacobian", "solve", "straight_guess", "unstable_modes", "lu_det_sign",
           "static_problem", "quat_axis_angle", "contact_loads", "seabed_loads",
           "electrostatic_loads", "without_pair_loads",
           "contact_gap", "NV", "N_START", "band_jacobian", "band_ready", "factor_jacobian",
           "problem_at", "join_coupling",
           "nearest_eigenvalues"]

NV = 13          # unknowns per node
N_START = 7      # boundary rows at s = 0
N_END = 6        # boundary rows at s = L
_EPS = 1e-30     # complex step


class StaticsError(ValueError):
    """Bad static input or no equilibrium: the message names the field or the cause."""


# --------------------------------------------------------------------------- quaternions
# written with + - * only, so that complex arguments (the complex step) pass through

def _qmul(p, q):
    """Hamilton product p ⊗ q, (..., 4) x (..., 4) -> (..., 4)."""
    pw, px, py, pz = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([pw * qw - px * qx - py * qy - pz * qz,
                     pw * qx + px * qw + py * qz - pz * qy,
                     pw * qy - px * qz + py * qw + pz * qx,
                     pw * qz + px * qy - py * qx + pz * qw], axis=-1)


def _qconj(p):
    return p * np.array([1.0, -1.0, -1.0, -1.0])


def _rot(p):
    """R(p) (..., 3, 3) of a unit quaternion (columns a1, a2, a3 in global components)."""
    w, x, y, z = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    return np.stack([
        np.stack([w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z], -1),
    ], axis=-2)


def _a3(p):
    """The tangent a3 = R(p) e3 (..., 3) of a unit quaternion (..., 4): the third column
    of :func:`_rot`, the same arithmetic, without the other two."""
    w, x, y, z = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    return np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), w * w - x * x - y * y + z * z],
                    axis=-1)


def quat_axis_angle(axis, angle) -> np.ndarray:
    """Unit quaternion (4,) of a rotation by ``angle`` (rad) about ``axis`` (3,)."""
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * a])


# --------------------------------------------------------------------------- the problem

@dataclass(frozen=True)
class EndSpec:
    """Conditions at one rod end (all global components, SI).

    axes : (3, 3) columns e_j, the directions of the three translation conditions
    held : (3,) bool, translation component j held at ``position`` (else loaded by ``force``)
    position : (3,) m, the held position (components along unheld axes ignored)
    force : (3,) N, the applied dead force (components along held axes ignored)
    rotation_held : True: the frame is ``quaternion``; False: free under a zero moment
    quaternion : (4,) unit quaternion of the held frame
    twist : rad, total rotation of the held frame about the end tangent from the reference
            frame (for the Newton start and Lk; the quaternion alone knows it modulo 2π)
    """

    axes: np.ndarray
    held: np.ndarray
    position: np.ndarray
    force: np.ndarray
    rotation_held: bool
    quaternion: np.ndarray
    twist: float = 0.0


def clamp(position, quaternion, twist: float = 0.0, *, axes=None, held=(True, True, True),
          force=(0.0, 0.0, 0.0)) -> EndSpec:
    """An end held in rotation at ``quaternion``; translation components held or loaded."""
    return EndSpec(axes=np.eye(3) if axes is None else np.asarray(axes, float),
                   held=np.asarray(held, bool), position=np.asarray(position, float),
                   force=np.asarray(force, float), rotation_held=True,
                   quaternion=np.asarray(quaternion, float), twist=float(twist))


def free_end(force=(0.0, 0.0, 0.0)) -> EndSpec:
    """An end free in rotation (zero moment) under a dead ``force`` (N, global)."""
    return EndSpec(axes=np.eye(3), held=np.zeros(3, bool), position=np.zeros(3),
                   force=np.asarray(force, float), rotation_held=False,
                   quaternion=np.array([1.0, 0, 0, 0]), twist=0.0)


@dataclass(frozen=True)
class StaticProblem:
    """One static problem on the grid s_k = k L/N.

    length : L, m;  n_segments : N
    stiffness : (N+1, 3) EJ1, EJ2, GJ3 at the nodes, N m²
    load : (N+1, 3) dead force per length at the nodes (point loads included as P/h), N/m
    start, end : :class:`EndSpec`
    mass : (N+1,) ρA, kg/m; inertia : (N+1,) rotational inertia per length, kg m
           (only the stability pencil reads them; any positive values give the same count)
    reference : (4,) frame of the straight reference rod (tangent a3 along the rod)
    contact : :class:`solver.contact.SelfContact` or None: self-contact by its law's
              repulsion, without damping (:func:`contact_loads`)
    seabed : :class:`solver.seabed.SeabedContact` or None: the bottom's normal spring, without
             damping and friction (:func:`seabed_loads`)
    intrinsic_curvature : (N+1, 3) κ⁰ (1/m) in the body frame, or None (zero): the
             curvatures and twist of the unloaded rod, m = R K (κ − κ⁰)
    closed : a closed rod (``rod.closed``): node N is node 0 again, joined by
             :func:`_closed_rows` instead of the ends' rows (the centreline scheme's
             rows; a static solve refuses it, :func:`static_problem`)
    electrostatics : :class:`solver.electrostatics.ScreenedElectrostatics` or None: the
             Debye–Hückel repulsion between non-adjacent segments (:func:`electrostatic_loads`)
    """

    length: float
    n_segments: int
    stiffness: np.ndarray
    load: np.ndarray
    start: EndSpec
    end: EndSpec
    mass: Optional[np.ndarray] = None
    inertia: Optional[np.ndarray] = None
    reference: np.ndarray = field(default_factory=lambda: np.array([1.0, 0, 0, 0]))
    contact: Optional[object] = None
    seabed: Optional[object] = None
    electrostatics: Optional[object] = None
    intrinsic_curvature: Optional[np.ndarray] = None
    closed: bool = False

    @property
    def kappa0(self) -> np.ndarray:
        """(N+1, 3) the intrinsic curvature κ⁰, 1/m (zeros where none is given)."""
        if self.intrinsic_curvature is None:
            return np.zeros((self.n_segments + 1, 3))
        return self.intrinsic_curvature

    @property
    def h(self) -> float:
        return self.length / self.n_segments

    @property
    def s(self) -> np.ndarray:
        return np.linspace(0.0, self.length, self.n_segments + 1)

    def scales(self) -> np.ndarray:
        """(13,) typical sizes of r (L), p (1), n (B/L²), m (B/L) for norms."""
        b = float(np.max(self.stiffness[:, :2]))
        L = self.length
        return np.array([L] * 3 + [1.0] * 4 + [b / L**2] * 3 + [b / L] * 3)


def uniform(length: float, n_segments: int, stiffness, start: EndSpec, end: EndSpec,
            load=(0.0, 0.0, 0.0), **kw) -> StaticProblem:
    """A uniform rod: ``stiffness`` (3,) EJ1, EJ2, GJ3 (N m²), ``load`` (3,) N/m."""
    n1 = n_segments + 1
    return StaticProblem(length=float(length), n_segments=int(n_segments),
                         stiffness=np.tile(np.asarray(stiffness, float), (n1, 1)),
                         load=np.tile(np.asarray(load, float), (n1, 1)),
                         start=start, end=end, **kw)


# --------------------------------------------------------------------------- residual

def residual(Y, prob: StaticProblem) -> np.ndarray:
    """The 13(N+1) static rows (7 start, 13 per cell, 6 end) of the node unknowns.

    Y : (N+1, 13) real or complex (complex step). Returns (13(N+1),) of Y's dtype.
    Row units: m (positions), 1 (quaternions), N (forces), N m (moments).
    """
    out = np.empty(NV * (prob.n_segments + 1), dtype=Y.dtype)
    if Y.dtype == np.float64 and Y.ndim == 2:        # the compiled cells
        cell_residual(np.ascontiguousarray(Y), prob.stiffness, prob.kappa0, prob.load, prob.h,
                      out[N_START:-N_END].reshape(prob.n_segments, NV))
    else:                                             # complex (the complex step)
        out[N_START:-N_END] = _cell_rows(Y, prob).ravel()
    out[:N_START], out[-N_END:] = _end_rows(Y, prob)
    if not band_ready(prob):
        extra = contact_loads(Y, prob) + seabed_loads(Y, prob) + electrostatic_loads(Y, prob)
        cells = out[N_START:-N_END].reshape(prob.n_segments, NV)
        cells[:, 7:10] += 0.5 * prob.h * (extra[:-1] + extra[1:])
    return out


def _cell_rows(Y, prob: StaticProblem) -> np.ndarray:
    """The box rule on every cell: Y (..., N+1, 13) -> (..., N, 13) (leading axes: a
    batch of states, the complex step's column groups)."""
    h = prob.h
    r, p, n, m = Y[..., 0:3], Y[..., 3:7], Y[..., 7:10], Y[..., 10:13]
    R = _rot(p)
    a3 = R[..., :, 2]
    kappa = np.einsum("...kji,...kj->...ki", R, m) / prob.stiffness + prob.kappa0
    kbar = 0.5 * (kappa[..., :-1, :] + kappa[..., 1:, :])
    zero = np.zeros(kbar.shape[:-1] + (1,), dtype=kbar.dtype)
    omega = np.concatenate([zero, kbar], axis=-1)
    cell = np.empty(Y.shape[:-2] + (prob.n_segments, NV), dtype=Y.dtype)
    cell[..., 0:3] = r[..., 1:, :] - r[..., :-1, :] - 0.5 * h * (a3[..., :-1, :] + a3[..., 1:, :])
    cell[..., 3:7] = (p[..., 1:, :] - p[..., :-1, :]
                      - 0.25 * h * _qmul(p[..., :-1, :] + p[..., 1:, :], omega))
    cell[..., 7:10] = n[..., 1:, :] - n[..., :-1, :] + 0.5 * h * (prob.load[:-1] + prob.load[1:])
    an = np.cross(a3, n)
    cell[..., 10:13] = m[..., 1:, :] - m[..., :-1, :] + 0.5 * h * (an[..., :-1, :] + an[..., 1:, :])
    return cell


def _end_rows(Y, prob: StaticProblem):
    """The 7 rows at s = 0 and the 6 at s = L of Y (N+1, 13) (of a closed rod:
    :func:`_closed_rows`)."""
    if prob.closed:
        return _closed_rows(Y, prob)
    st, en = prob.start, prob.end
    r0, p0, n0, m0 = Y[0, 0:3], Y[0, 3:7], Y[0, 7:10], Y[0, 10:13]
    rN, pN, nN, mN = Y[-1, 0:3], Y[-1, 3:7], Y[-1, 7:10], Y[-1, 10:13]
    start = np.empty(N_START, dtype=Y.dtype)
    E = st.axes
    start[0:3] = np.where(st.held, E.T @ (r0 - st.position), E.T @ (n0 + st.force))
    if st.rotation_held:
        start[3:7] = p0 - st.quaternion
    else:
        start[3:6] = m0
        start[6] = p0 @ p0 - 1.0
    end = np.empty(N_END, dtype=Y.dtype)
    E = en.axes
    end[0:3] = np.where(en.held, E.T @ (rN - en.position), E.T @ (nN - en.force))
    end[3:6] = _qmul(_qconj(en.quaternion), pN)[1:] if en.rotation_held else mN
    return start, end


def _closed_rows(Y, prob: StaticProblem):
    """The 13 rows that join node N to node 0 of a closed rod, in place of the ends'
    (7, 6): at s = 0 the internal loads continue across the join, n_N − n_0 = 0,
    m_N − m_0 = 0, and |p_0|² = 1; at s = L the centreline and the frame close,
    r_N − r_0 = 0 and vec(p̄_0 ⊗ p_N) = 0 (p_N = ±p_0, one frame; the Cayley rows carry
    |p| exactly, so the fourth component is not a condition, and the frame's turns
    around the ring, its linking number, are kept by continuity). With inertia these
    rows and the cells' are regular. Without (a static ring) they are singular along
    the ring's rigid motions and, for an isotropic rod, the spin of every section about
    the tangent; fixing node 0's position and frame instead of the n, m continuity
    leaves a null space still, which is why the statics refuse closed rods."""
    n0, m0, p0 = Y[0, 7:10], Y[0, 10:13], Y[0, 3:7]
    start = np.concatenate([Y[-1, 7:10] - n0, Y[-1, 10:13] - m0, [p0 @ p0 - 1.0]])
    end = np.concatenate([Y[-1, 0:3] - Y[0, 0:3], _qmul(_qconj(p0), Y[-1, 3:7])[1:]])
    return start, end


_PATTERNS: dict = {}


def _pattern(n_segments: int, closed: bool = False):
    """The CSC structure of the Jacobian (indices, indptr) and, per colour, the positions
    of its entries in the CSC data and their rows (cached per N and ``closed``). Nodes of
    one parity share no row, so they share a colour (26 colours); a closed rod's join
    rows read nodes 0 and N both, so node N takes colours of its own (39)."""
    key = (n_segments, bool(closed))
    if key in _PATTERNS:
        return _PATTERNS[key]
    N = n_segments
    k = np.arange(N + 1)
    comp = np.arange(NV)
    # rows touched by node k: its cells' 13 rows each, the start/end rows at the ends
    blocks = []
    for lo, hi, base in ((1, N + 1, lambda k: N_START + NV * (k - 1)),
                         (0, N, lambda k: N_START + NV * k)):
        kk = k[lo:hi]
        r = (base(kk)[:, None] + comp[None, :])                    # (n, 13)
        blocks.append((np.repeat(kk, NV), r.ravel()))
    start_rows = np.arange(N_START)
    end_rows = NV * (N + 1) - N_END + np.arange(N_END)
    blocks.append((np.zeros(N_START, int), start_rows))
    blocks.append((np.full(N_END, N), end_rows))
    if closed:
        blocks.append((np.full(N_START, N), start_rows))
        blocks.append((np.zeros(N_END, int), end_rows))
    node = np.concatenate([b[0] for b in blocks])
    row = np.concatenate([b[1] for b in blocks])
    rows = np.repeat(row, NV)
    cols = (NV * node[:, None] + comp[None, :]).ravel()
    group = node % 2
    if closed:
        group = np.where(node == N, 2, group)
    colour = (group[:, None] * NV + comp[None, :]).ravel()
    order = np.lexsort((rows, cols))
    rows, cols, colour = rows[order], cols[order], colour[order]
    n = NV * (N + 1)
    indptr = np.concatenate([[0], np.cumsum(np.bincount(cols, minlength=n))])
    groups = []
    for c in range((3 if closed else 2) * NV):
        pos = np.flatnonzero(colour == c)
        groups.append((pos, rows[pos]))
    pat = (rows, indptr, groups)
    _PATTERNS[key] = pat
    return pat


def jacobian(Y: np.ndarray, prob: StaticProblem) -> sp.csc_matrix:
    """∂G/∂Y, exact to rounding (complex step by column groups, all 26 groups in one
    batched evaluation of the cell rows; 39 for a closed rod), sparse (13(N+1))²."""
    closed = prob.closed
    indices, indptr, groups = _pattern(prob.n_segments, closed)
    ng = len(groups)
    Yc = np.empty((ng,) + Y.shape, dtype=complex)
    Yc[:] = Y
    N = prob.n_segments
    for c in range(ng):
        par, comp = divmod(c, NV)
        if par == 2:
            Yc[c, N, comp] += 1j * _EPS
        elif closed:
            Yc[c, par:N:2, comp] += 1j * _EPS            # node N: colours of its own
        else:
            Yc[c, par::2, comp] += 1j * _EPS
    G = np.empty((ng, Y.size))
    G[:, N_START:-N_END] = _cell_rows(Yc, prob).reshape(ng, -1).imag
    vals = np.empty(indices.size)
    for c, (pos, rows) in enumerate(groups):
        start, end = _end_rows(Yc[c], prob)
        G[c, :N_START], G[c, -N_END:] = start.imag, end.imag
        vals[pos] = G[c, rows]
    vals /= _EPS
    n = NV * (prob.n_segments + 1)
    J = sp.csc_matrix((vals, indices, indptr), shape=(n, n))
    if band_ready(prob):
        return J
    dL = (_contact_load_jacobian(Y, prob) + _seabed_load_jacobian(Y, prob)
          + _electrostatic_load_jacobian(Y, prob))
    return (J + _load_rows(prob) @ dL @ _position_columns(prob)).tocsc()


def band_ready(prob: StaticProblem) -> bool:
    """True where the Jacobian is a band (:mod:`solver.static_band`): no self-contact
    and no electrostatics (their pairs couple distant nodes), no seabed (its load
    Jacobian goes the sparse way, with the contact's) and an open rod (a closed one's
    join couples nodes 0 and N)."""
    return (prob.contact is None and prob.seabed is None and prob.electrostatics is None
            and not prob.closed)


def without_pair_loads(prob: StaticProblem) -> StaticProblem:
    """``prob`` without its electrostatics: the rows a band holds, for a caller that adds
    the pairs' load Jacobian itself (:class:`solver.centreline.CentrelineRod`)."""
    return prob if prob.electrostatics is None else replace(prob, electrostatics=None)


def band_jacobian(Y: np.ndarray, prob: StaticProblem) -> np.ndarray:
    """∂G/∂Y in LAPACK band storage (2 KL + KU + 1, 13(N+1)) (:mod:`solver.static_band`),
    exact to rounding: the cells by the compiled per-cell complex step, the 13 end rows
    exactly (:func:`_end_jacobian`; they are linear but for |p_0|² − 1). The same
    matrix as :func:`jacobian`; of a closed rod, the part inside the band (the join's
    rows on the columns of nodes 0 and N lie outside it: :func:`join_coupling`). Raises
    :class:`StaticsError` where the problem has self-contact, a seabed or
    electrostatics (:func:`band_ready`)."""
    if not (prob.contact is None and prob.seabed is None and prob.electrostatics is None):
        raise StaticsError("the Jacobian with self-contact, a seabed or electrostatics "
                           "is not a band")
    N = prob.n_segments
    n = NV * (N + 1)
    ab = band_storage(n)
    cell_band(np.ascontiguousarray(Y, dtype=float), prob.stiffness, prob.kappa0, prob.load,
              prob.h, ab)
    diag = KL + KU
    start_rows = np.arange(N_START)
    end_rows = n - N_END + np.arange(N_END)
    if prob.closed:
        J = _join_jacobian(Y, prob)
        for c in range(NV):
            ab[diag + start_rows - c, c] = J[:N_START, c]
            col = NV * N + c
            ab[diag + end_rows - col, col] = J[N_START:, NV + c]
        return ab
    start, end = _end_jacobian(Y, prob)
    for c in range(NV):
        ab[diag + start_rows - c, c] = start[:, c]
        col = NV * N + c
        ab[diag + end_rows - col, col] = end[:, c]
    return ab


def _end_jacobian(Y: np.ndarray, prob: StaticProblem):
    """∂(the 7 start rows)/∂(node 0's 13 unknowns) (7, 13) and ∂(the 6 end rows)/∂(node
    N's) (6, 13) of :func:`_end_rows` for an open rod, exact: a translation row is
    e_jᵀ on r (held) or on n (loaded); a held frame's rows are p_0 − q (the identity on
    p_0) at s = 0 and vec(q̄ ⊗ p_N) at s = L (the rows 1-3 of q̄'s left product matrix,
    the Hamilton product being linear in p_N); a free frame's are m (the identity on
    m) and |p_0|² − 1 (2 p_0ᵀ). Y (N+1, 13) real."""
    st, en = prob.start, prob.end
    start = np.zeros((N_START, NV))
    _translation_jacobian(st, start)
    if st.rotation_held:
        start[3:7, 3:7] = np.eye(4)
    else:
        start[3:6, 10:13] = np.eye(3)
        start[6, 3:7] = 2.0 * Y[0, 3:7]
    end = np.zeros((N_END, NV))
    _translation_jacobian(en, end)
    if en.rotation_held:
        end[3:6, 3:7] = _qmul(_qconj(en.quaternion)[None, :], np.eye(4))[:, 1:].T
    else:
        end[3:6, 10:13] = np.eye(3)
    return start, end


def _translation_jacobian(spec: EndSpec, out: np.ndarray) -> None:
    """Writes the derivative of an end's 3 translation rows (:func:`_end_rows`: e_jᵀ(r −
    position) where component j is held, e_jᵀ(n ± force) where loaded) by its node's 13
    unknowns into out[0:3] (out (≥ 3, 13), zeros there): e_jᵀ on the r or the n columns."""
    rows = np.arange(3)
    E = spec.axes.T
    out[rows[spec.held][:, None], np.arange(0, 3)] = E[spec.held]
    out[rows[~spec.held][:, None], np.arange(7, 10)] = E[~spec.held]


def _join_jacobian(Y: np.ndarray, prob: StaticProblem) -> np.ndarray:
    """(13, 26) ∂(the 13 join rows of a closed rod, :func:`_closed_rows`)/∂(node 0's
    unknowns, node N's), by 26 complex steps (exact to rounding)."""
    ends = np.empty((2, NV), dtype=complex)
    J = np.empty((N_START + N_END, 2 * NV))
    for node in range(2):
        for c in range(NV):
            ends[0], ends[1] = Y[0], Y[-1]
            ends[node, c] += 1j * _EPS
            start, end = _closed_rows(ends, prob)
            J[:N_START, NV * node + c] = start.imag / _EPS
            J[N_START:, NV * node + c] = end.imag / _EPS
    return J


def join_coupling(Y: np.ndarray, prob: StaticProblem) -> sp.csc_matrix:
    """(13(N+1))² sparse: a closed rod's join rows on the columns outside the band, the
    s = 0 rows on node N's unknowns and the s = L rows on node 0's (exact, as
    :func:`band_jacobian`, which holds the rest); an empty matrix for an open rod. Raises
    nothing."""
    N = prob.n_segments
    n = NV * (N + 1)
    if not prob.closed:
        return sp.csc_matrix((n, n))
    J = _join_jacobian(Y, prob)
    comp = np.arange(NV)
    rows = np.concatenate([np.repeat(np.arange(N_START), NV),
                           np.repeat(n - N_END + np.arange(N_END), NV)])
    cols = np.concatenate([np.tile(NV * N + comp, N_START), np.tile(comp, N_END)])
    vals = np.concatenate([J[:N_START, NV:].ravel(), J[N_START:, :NV].ravel()])
    return sp.csc_matrix((vals, (rows, cols)), shape=(n, n))


# --------------------------------------------------------------------------- contact, seabed

def _load_rows(prob: StaticProblem) -> sp.csr_matrix:
    """(13(N+1), 3(N+1)): how a nodal load density L_k (N/m) enters the force rows of the
    box rule, h/2 in the cells k − 1 and k."""
    N, h = prob.n_segments, prob.h
    k = np.repeat(np.arange(N + 1), 3)
    c = np.tile(np.arange(3), N + 1)
    rows, cols = [], []
    for cell in (k - 1, k):
        ok = (cell >= 0) & (cell < N)
        rows.append(N_START + NV * cell[ok] + 7 + c[ok])
        cols.append(3 * k[ok] + c[ok])
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    return sp.csr_matrix((np.full(rows.size, 0.5 * h), (rows, cols)),
                         shape=(NV * (N + 1), 3 * (N + 1)))


def _position_columns(prob: StaticProblem) -> sp.csr_matrix:
    """(3(N+1), 13(N+1)): the position unknowns r_k among the node unknowns."""
    n1 = prob.n_segments + 1
    k = np.repeat(np.arange(n1), 3)
    c = np.tile(np.arange(3), n1)
    return sp.csr_matrix((np.ones(3 * n1), (3 * k + c, NV * k + c)), shape=(3 * n1, NV * n1))


def _contact_evaluation(Y, prob):
    """The dynamic contact model's evaluation (:meth:`solver.contact.SelfContact.evaluate`)
    at the positions of Y and zero velocities, or None without contact or candidates: the
    candidates searched afresh at every call (within the tolerance, no reach), so that
    the residual is a function of Y alone."""
    c = prob.contact
    if c is None:
        return None
    r = np.ascontiguousarray(np.real(Y[:, 0:3]), dtype=float)
    if not np.all(np.isfinite(r)):
        raise StaticsError("contact: non-finite positions")
    a3 = np.ascontiguousarray(_a3(np.real(Y[:, 3:7])), dtype=float)
    cand = c.search(r, a3)
    if cand is None:
        return None
    try:
        return c.evaluate(cand, r, np.zeros_like(r))
    except ValueError as exc:
        raise StaticsError(f"contact: {exc}") from exc


def contact_loads(Y: np.ndarray, prob: StaticProblem) -> np.ndarray:
    """Self-contact load density (N+1, 3) N/m (global) at the state Y (N+1, 13), zeros
    without ``prob.contact``.

    The dynamic model of :mod:`solver.contact.model` at rest: every node i finds the
    closest point of each run of nearby partner nodes on the partner curve (Catmull-Rom
    through the nodes), d its centreline distance, n the unit direction; node i receives
    ½ f(d) n and the curve's nodes the reaction weighted by the curve's basis (and the
    ratio of nodal weights), :func:`solver.contact.assemble_nodal`; f the law of
    :mod:`solver.contact.laws` at zero approach rate ḋ = 0, i.e. the repulsion alone
    (ρĀ P(g) for the barrier, ρĀ φ(d) P(g) for the seed law): no damping in statics.
    The closest point t minimises d, so the loads are the gradient of the potential
    Σ_i ½ Δs_i Π(d_i), Π' = −f (for a uniform diameter; the dynamic model interpolates
    D̄ and ρĀ along the partner segment, which the derivative leaves out).
    """
    n1 = prob.n_segments + 1
    ev = _contact_evaluation(Y, prob)
    if ev is None or ev.count == 0:
        return np.zeros((n1, 3))
    from .contact import assemble_nodal
    return assemble_nodal(ev, n1)


def _contact_load_jacobian(Y, prob) -> sp.csr_matrix:
    """∂L/∂r (3(N+1), 3(N+1)) of :func:`contact_loads` from the dynamic model's exact
    pair derivatives (:func:`solver.contact.assemble_nodal_jacobian`)."""
    from .contact import assemble_nodal_jacobian

    n1 = prob.n_segments + 1
    ev = _contact_evaluation(Y, prob)
    if ev is None or ev.count == 0:
        return sp.csr_matrix((3 * n1, 3 * n1))
    return assemble_nodal_jacobian(ev, n1)


def _electrostatic_evaluation(Y, prob, want_jacobian):
    """:meth:`solver.electrostatics.ScreenedElectrostatics.evaluate` at the positions of Y
    (N+1, 13), or None without ``prob.electrostatics``. Raises :class:`StaticsError` for
    non-finite positions or kept segments that meet."""
    es = prob.electrostatics
    if es is None:
        return None
    r = np.ascontiguousarray(np.real(Y[:, 0:3]), dtype=float)
    try:
        return es.evaluate(r, want_jacobian=want_jacobian)
    except ValueError as exc:
        raise StaticsError(f"electrostatics: {exc}") from exc


def electrostatic_loads(Y: np.ndarray, prob: StaticProblem) -> np.ndarray:
    """Screened electrostatics' load density (N+1, 3) N/m (global) at the state Y
    (N+1, 13), zeros without ``prob.electrostatics``: the nodal forces −∂U/∂r_i of the
    Debye–Hückel energy between non-adjacent segments over the nodes' shares of the grid
    (:mod:`solver.electrostatics`). Raises :class:`StaticsError` as
    :func:`_electrostatic_evaluation`."""
    ev = _electrostatic_evaluation(Y, prob, False)
    return np.zeros((prob.n_segments + 1, 3)) if ev is None else ev.loads


def _electrostatic_load_jacobian(Y, prob) -> sp.csr_matrix:
    """∂L/∂r (3(N+1), 3(N+1)) of :func:`electrostatic_loads`, exact (the kernel's second
    derivatives under the quadrature)."""
    ev = _electrostatic_evaluation(Y, prob, True)
    if ev is None:
        n3 = 3 * (prob.n_segments + 1)
        return sp.csr_matrix((n3, n3))
    return ev.jacobian


def contact_gap(Y: np.ndarray, prob: StaticProblem) -> float:
    """Smallest surface gap (m) between segments of the centreline polyline further apart
    in arclength than the exclusion (:func:`solver.contact.geometry.min_surface_gap`,
    segment to segment, the measure the dynamic run reports); inf without contact or
    with no pair within the tolerance."""
    from .contact.geometry import min_surface_gap

    c = prob.contact
    if c is None:
        return float("inf")
    r = np.ascontiguousarray(np.real(Y[:, 0:3]), dtype=float)
    return min_surface_gap(r, c.diameter, prob.s, c.separation_cut, c.tolerance + prob.h)


def _static_seabed_data(sb):
    """The seabed's kernel data with its damping and friction set to zero: in statics the
    bottom is the normal spring alone (no velocity, no slip history)."""
    scal = np.array(sb.data.scalars, float)
    scal[3] = scal[4] = scal[5] = 0.0
    return sb.data._replace(scalars=scal)


def seabed_loads(Y: np.ndarray, prob: StaticProblem) -> np.ndarray:
    """The seabed's normal reaction per unit length (N+1, 3) N/m (global) at the state Y,
    zeros without ``prob.seabed``: the seabed's law at each node
    (:func:`solver.seabed._node`) at rest with its damping and friction off, N = k p n
    (p the node's surface penetration, n the bottom's normal; a per-node spring, where a
    dynamic step takes the law at each cell's midpoint).
    Frictionless: Coulomb friction is a force of the slip history, which a static problem
    does not have."""
    from .seabed import _node

    n1 = prob.n_segments + 1
    sb = prob.seabed
    Fn = np.zeros((n1, 3))
    if sb is None:
        return Fn
    data = _static_seabed_data(sb)
    r = np.real(Y[:, 0:3])
    R = _rot(np.real(Y[:, 3:7]))
    z36 = np.zeros((3, 6))
    wk = np.zeros((9, 3, 6))
    ff, mm, zero3 = np.zeros(3), np.zeros(3), np.zeros(3)
    for k in range(n1):
        _node(np.array(r[k], float), zero3, zero3, np.array(R[k, :, 2], float),
              float(sb.radius[k]), data, False, z36, z36, z36, z36, Fn[k], ff, mm,
              z36.copy(), z36.copy(), wk)
    return Fn


def _seabed_load_jacobian(Y, prob) -> sp.csr_matrix:
    """∂L/∂r (3(N+1), 3(N+1)) of :func:`seabed_loads`: node-local 3×3 blocks, exact, from
    the derivative propagation of :func:`solver.seabed._node` (velocity, rotation and
    tangent seeds zero) at the nodes in contact."""
    from .seabed import _node

    n1 = prob.n_segments + 1
    sb = prob.seabed
    if sb is None:
        return sp.csr_matrix((3 * n1, 3 * n1))
    data = _static_seabed_data(sb)
    r = np.real(Y[:, 0:3])
    R = _rot(np.real(Y[:, 3:7]))
    Dr = np.zeros((3, 6))
    Dr[:, :3] = np.eye(3)
    z36 = np.zeros((3, 6))
    wk = np.zeros((9, 3, 6))
    a, b, cc = np.zeros(3), np.zeros(3), np.zeros(3)
    DF, DM = np.zeros((3, 6)), np.zeros((3, 6))
    rows, cols, vals = [], [], []
    zero3 = np.zeros(3)
    for k in range(n1):
        pen = _node(np.array(r[k], float), zero3, zero3, np.array(R[k, :, 2], float),
                    float(sb.radius[k]), data, True, Dr, z36, z36, z36, a, b, cc, DF, DM, wk)
        if pen <= 0:
            continue
        for i in range(3):
            for j in range(3):
                rows.append(3 * k + i)
                cols.append(3 * k + j)
                vals.append(DF[i, j])
    return sp.csr_matrix((vals, (rows, cols)), shape=(3 * n1, 3 * n1))


# --------------------------------------------------------------------------- Newton

def straight_guess(prob: StaticProblem) -> np.ndarray:
    """(N+1, 13): the straight rod from the start end along its tangent, twisted
    uniformly from the start's to the end's ``twist``, no internal loads."""
    N = prob.n_segments
    s = prob.s
    q0 = prob.start.quaternion if prob.start.rotation_held else prob.reference
    a3 = _rot(q0)[:, 2]
    r0 = prob.start.position if np.all(prob.start.held) else np.zeros(3)
    Y = np.zeros((N + 1, NV))
    Y[:, 0:3] = r0 + s[:, None] * a3
    dtw = (prob.end.twist - prob.start.twist) if prob.end.rotation_held else 0.0
    for k in range(N + 1):
        Y[k, 3:7] = _qmul(q0, quat_axis_angle([0, 0, 1], dtw * s[k] / prob.length))
    return Y


def lu_det_sign(lu) -> int:
    """Sign of det A from a scipy ``splu`` factor (Pr A Pc = L U, L unit lower), or the
    ``det_sign`` of a :class:`solver.static_band.BorderedBandLU`."""
    if hasattr(lu, "det_sign"):
        return int(lu.det_sign)
    d = lu.U.diagonal()
    sign = int(np.prod(np.sign(d)))
    for perm in (lu.perm_r, lu.perm_c):
        sign *= _perm_parity(perm)
    return sign


def _perm_parity(perm: np.ndarray) -> int:
    n = perm.size
    seen = np.zeros(n, bool)
    cycles = 0
    for i in range(n):
        if not seen[i]:
            cycles += 1
            j = i
            while not seen[j]:
                seen[j] = True
                j = perm[j]
    return -1 if (n - cycles) % 2 else 1


class EquilibratedLU:
    """The LU of a square matrix A through its equilibrated Dr A Dc: Dc the given column
    scales (the unknowns' sizes; default 1), Dr one over each row's largest entry of
    A Dc (Bunch, Math. Comp. 25, 1971; Golub & Van Loan, *Matrix Computations*, 4th ed.,
    § 3.5.2). A rod's rows mix metres, newtons and newton-metres: DNA in SI units puts
    1e27 between a moment row's entries and a quaternion row's, so the pivots of A itself
    say nothing about singularity (:func:`_check_pivots` compares them with the largest),
    those of Dr A Dc do. ``solve(b, trans="N"|"T", refine=...)`` solves A x = b or
    Aᵀ x = b (b (n,) or (n, k)); ``det_sign`` is the sign of det A (Dr, Dc > 0); ``lu``
    the factor of Dr A Dc (``splu``'s, or :class:`solver.static_band.BorderedBandLU`'s)."""

    def __init__(self, lu, r, c):
        self.lu, self.r, self.c = lu, r, c
        self.det_sign = lu_det_sign(lu)

    def solve(self, b, trans: str = "N", refine: bool = True):
        b = np.asarray(b, float)
        r = self.r if b.ndim == 1 else self.r[:, None]
        c = self.c if b.ndim == 1 else self.c[:, None]
        if trans == "T":
            return r * self.lu.solve(c * b, trans="T")
        if isinstance(self.lu, BorderedBandLU):
            return c * self.lu.solve(r * b, refine=refine)
        return c * self.lu.solve(r * b)


def _row_equilibration(A) -> np.ndarray:
    """(n,) one over each row's largest |entry| of the sparse A (1 for an empty row)."""
    big = np.asarray(abs(sp.csr_matrix(A)).max(axis=1).todense()).ravel()
    return 1.0 / np.where(big > 0.0, big, 1.0)


def factor(A, col_scale=None):
    """The sparse LU (scipy's ``splu``) of a square matrix A through its equilibrated
    Dr A Dc (:class:`EquilibratedLU`; ``col_scale`` (n,) Dc, default 1); raises
    :class:`StaticsError` when singular (a pivot of Dr A Dc below PIVOT_RTOL of the
    largest)."""
    A = sp.csc_matrix(A)
    c = np.ones(A.shape[1]) if col_scale is None else np.asarray(col_scale, float)
    Ac = A @ sp.diags(c)
    r = _row_equilibration(Ac)
    try:
        lu = spla.splu(sp.csc_matrix(sp.diags(r) @ Ac))
    except RuntimeError as exc:
        raise StaticsError(f"singular Jacobian ({exc})") from exc
    _check_pivots(lu.U.diagonal())
    return EquilibratedLU(lu, r, c)


#: a pivot below this fraction of the largest in size is zero to rounding (:func:`_check_pivots`)
PIVOT_RTOL = 1e-14


def _check_pivots(d):
    """Raise :class:`StaticsError` where a pivot of U's diagonal ``d`` is not finite or is
    below PIVOT_RTOL (1e-14) of the largest in size (a matrix singular to rounding)."""
    d = np.abs(d)
    if not np.all(np.isfinite(d)) or d.min() <= PIVOT_RTOL * d.max():
        raise StaticsError("singular Jacobian (a pivot is zero to rounding)")


def factor_jacobian(Y: np.ndarray, prob: StaticProblem):
    """The LU of ∂G/∂Y at Y (N+1, 13), a 13(N+1)-square matrix, through its equilibrated
    Dr J Dc (Dc the unknowns' scales, :meth:`StaticProblem.scales`; Dr one over each
    row's largest entry; :class:`EquilibratedLU`): LAPACK's band LU
    (:class:`solver.static_band.BorderedBandLU` with no border) where the Jacobian is a
    band (:func:`band_ready`), else scipy's sparse LU (:func:`factor`); it has
    ``solve`` and ``det_sign``. Raises :class:`StaticsError` when the Jacobian is
    singular (a pivot of Dr J Dc zero, or below 1e-14 of the largest)."""
    c = np.tile(prob.scales(), prob.n_segments + 1)
    if band_ready(prob):
        ab = band_jacobian(Y, prob)
        r = _equilibrate_band(ab, c)
        try:
            lu = BorderedBandLU(ab)
        except BandSingular as exc:
            raise StaticsError(f"singular Jacobian ({exc})") from exc
        _check_pivots(lu.lu[KL + KU])
        return EquilibratedLU(lu, r, c)
    return factor(jacobian(Y, prob), c)


def _equilibrate_band(ab, c) -> np.ndarray:
    """Scale the band ``ab`` (LAPACK storage, A[i, j] at ab[KL + KU + i − j, j]) in place
    to Dr A Dc with Dc = diag(c) and Dr one over each row's largest |entry| of A Dc
    (:class:`EquilibratedLU`); returns Dr's diagonal (n,)."""
    n = ab.shape[1]
    band = ab[KL:]                        # band[k, j] = A[j + k − KU, j]
    band *= c[None, :]
    big = np.zeros(n)
    for k in range(KL + KU + 1):          # diagonal by diagonal: rows i = j + k − KU
        off = k - KU
        lo, hi = max(0, -off), min(n, n - off)
        np.maximum(big[lo + off:hi + off], np.abs(band[k, lo:hi]), out=big[lo + off:hi + off])
    r = 1.0 / np.where(big > 0.0, big, 1.0)
    for k in range(KL + KU + 1):
        off = k - KU
        lo, hi = max(0, -off), min(n, n - off)
        band[k, lo:hi] *= r[lo + off:hi + off]
    return r


@dataclass
class StaticSolution:
    """A converged equilibrium: ``Y`` (N+1, 13), Newton ``iterations``, scaled ``residual``."""

    Y: np.ndarray
    iterations: int
    residual: float
    problem: StaticProblem


def solve(prob: StaticProblem, Y0: Optional[np.ndarray] = None, *, tol: float = 1e-10,
          max_iterations: int = 30, ramp: bool = True) -> StaticSolution:
    """Newton with the exact Jacobian from ``Y0`` (default :func:`straight_guess`).

    Converged when the scaled update (by :meth:`StaticProblem.scales`) is below ``tol``.
    Without convergence from the start and with ``ramp``, the dead loads (distributed
    and end forces) and the intrinsic curvature are raised from 0 in steps (halved on a failure, at most 64 solves),
    each solve starting from the last. Raises :class:`StaticsError` on a singular
    Jacobian or no convergence.
    """
    try:
        return _newton(prob, Y0, tol, max_iterations)
    except StaticsError:
        if not ramp:
            raise
    Y, a, da, solves = Y0, 0.0, 0.25, 0
    while a < 1.0:
        b = min(1.0, a + da)
        try:
            sol = _newton(scaled_loads(prob, b), Y, tol, max_iterations)
        except StaticsError:
            da *= 0.5
            solves += 1
            if solves > 64 or da < 1e-4:
                raise
            continue
        Y, a, solves = sol.Y, b, solves + 1
        da = min(2 * da, 0.5)
    return StaticSolution(sol.Y, sol.iterations, sol.residual, prob)


def scaled_loads(prob: StaticProblem, a: float) -> StaticProblem:
    """``prob`` with every dead load (distributed, end forces) and the intrinsic curvature
    κ⁰ times ``a`` (the ramp of :func:`solve`: κ⁰ loads the straight start as a moment
    −K κ⁰ would)."""
    k0 = None if prob.intrinsic_curvature is None else a * prob.intrinsic_curvature
    return replace(prob, load=a * prob.load, start=replace(prob.start, force=a * prob.start.force),
                   end=replace(prob.end, force=a * prob.end.force), intrinsic_curvature=k0)


def _row_scales(prob: StaticProblem) -> np.ndarray:
    """(13(N+1),) typical sizes of the residual rows: the cell rows as the unknowns
    (:meth:`StaticProblem.scales`), the boundary rows 1."""
    return np.concatenate([np.ones(N_START), np.tile(prob.scales(), prob.n_segments),
                           np.ones(N_END)])


def _damped(prob, Y, G, dY):
    """Y − λ dY with the first λ of 1, ½, ¼ ... (down to 2⁻¹⁰) whose residual is smaller
    in the scaled max norm than G's (backtracking: a stiff contact barrier or a seabed
    spring makes the full Newton step overshoot far from the solution; Deuflhard,
    *Newton Methods for Nonlinear Problems*, 2004, §3.1 for the monotonicity test)."""
    w = 1.0 / _row_scales(prob)
    g0 = float(np.max(np.abs(G) * w))
    lam = 1.0
    while True:
        Yt = Y - lam * dY
        try:
            gt = float(np.max(np.abs(residual(Yt, prob)) * w))
        except StaticsError:
            gt = np.inf
        if gt < g0 or lam < 2.0 ** -10:
            return Yt
        lam *= 0.5


def _newton(prob, Y0, tol, max_iterations):
    Y = straight_guess(prob) if Y0 is None else np.array(Y0, float)
    scale = prob.scales()
    damp = not band_ready(prob)
    for it in range(1, max_iterations + 1):
        G = residual(Y, prob)
        lu = factor_jacobian(Y, prob)
        dY = lu.solve(G).reshape(Y.shape)
        if not np.all(np.isfinite(dY)):
            raise StaticsError("Newton: non-finite update")
        Y = _damped(prob, Y, G, dY) if damp else Y - dY
        err = float(np.max(np.abs(dY) / scale))
        if err < tol:
            return StaticSolution(Y, it, err, prob)
    raise StaticsError(f"Newton did not converge in {max_iterations} iterations "
                       f"(scaled update {err:.3g})")


# --------------------------------------------------------------------------- stability

def mass_matrix(Y: np.ndarray, prob: StaticProblem) -> sp.csc_matrix:
    """B of the pencil J z = μ B z (see the module docstring): ρA h/2 on the force rows
    against δr of the cell's nodes, I h/2 on the moment rows against δθ = 2 vec(δp ⊗ p̄)."""
    N, h = prob.n_segments, prob.h
    mass = np.ones(N + 1) if prob.mass is None else np.asarray(prob.mass, float)
    inert = (np.full(N + 1, 1e-2 * prob.length**2) * mass if prob.inertia is None
             else np.asarray(prob.inertia, float))
    cells = np.arange(N)
    base = N_START + NV * cells
    rows, cols, vals = [], [], []
    for k in (cells, cells + 1):                 # each cell's two nodes
        rows.append(np.repeat(base + 7, 3) + np.tile(np.arange(3), N))
        cols.append((NV * k[:, None] + np.arange(3)).ravel())
        vals.append(np.repeat(0.5 * h * mass[k], 3))
        w, v = Y[k, 3], Y[k, 4:7]
        D = np.zeros((N, 3, 4))
        D[:, :, 0] = -2 * v
        D[:, :, 1:] = 2 * w[:, None, None] * np.eye(3)
        D[:, 0, 2], D[:, 0, 3] = -2 * v[:, 2], 2 * v[:, 1]
        D[:, 1, 1], D[:, 1, 3] = 2 * v[:, 2], -2 * v[:, 0]
        D[:, 2, 1], D[:, 2, 2] = -2 * v[:, 1], 2 * v[:, 0]
        rows.append(np.broadcast_to((base + 10)[:, None, None] + np.arange(3)[None, :, None],
                                    D.shape).ravel())
        cols.append(np.broadcast_to((NV * k + 3)[:, None, None] + np.arange(4), D.shape).ravel())
        vals.append((0.5 * h * inert[k][:, None, None] * D).ravel())
    n = NV * (N + 1)
    return sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n, n))


def nearest_eigenvalues(op, n: int, k: int, tol: float = 1e-8) -> np.ndarray:
    """The k eigenvalues ν of largest |ν| of ``op`` (a real LinearOperator n × n, here
    J⁻¹B: μ = 1/ν nearest zero), each as often as its multiplicity.

    ARPACK's implicitly restarted Arnoldi (scipy ``eigs``) works in the Krylov space of
    one start vector, which holds one vector of each eigenspace: a double eigenvalue (a
    round rod's pairs) is found twice only where rounding breaks the symmetry. So the
    search is repeated, where an eigenvalue found is real and positive (an unstable mode,
    whose copies the count needs), on the deflated operator P op P, P = I − QQᵀ with Q an
    orthonormal basis of the eigenvectors found: were Q exactly invariant, P op P would have the
    remaining eigenvalues, a second copy included, and zeros on Q (Saad, *Numerical
    Methods for Large Eigenvalue Problems*, 2nd ed., SIAM 2011, § 4.2). ARPACK's
    eigenvectors are accurate to ``tol`` only, and the deflated operator of a non-normal
    op then has spurious eigenvalues (seen on Greenhill's rod: μ = +5821 and −1318 where
    the spectrum has neither). So every eigenvalue λ of the deflated search is checked on
    op itself: its vector w is completed to x = w + Q z, (R − λ) z = −Qᵀ op w by least
    squares (R = Qᵀ op Q), and λ is kept only where |op x − λ x| ≤ 1e-6 |λ| |x|. One
    deflated search, from a fixed pseudo-random start (a symmetric one like the first
    search's ones would miss the copy again): a double eigenvalue is found twice, a
    triple one (which no symmetry of a rod makes) possibly twice only.

    Returns (m,) complex, m ≤ k, sorted by |ν| descending (fewer where ARPACK did not
    converge, empty where it converged on none).
    """
    def search(vectors):
        try:
            out = spla.eigs(op, k=k, which="LM", tol=tol, v0=np.ones(n),
                            return_eigenvectors=vectors)
        except spla.ArpackNoConvergence as exc:   # the converged ones, or none
            out = (np.asarray(exc.eigenvalues), np.asarray(exc.eigenvectors))
            return out if vectors else out[0]
        return out

    found = search(False)
    found = found[np.abs(found) > 0]
    # the count (μ = 1/ν > 0) misses a copy only of a positive ν: search where one is,
    # for as many as there are positive ones (a copy is as large as its original)
    positive = int(np.sum((np.abs(found.imag) <= 1e-6 * np.abs(found)) & (found.real > 0)))
    if positive:
        found, X = search(True)                   # the same search, with its vectors
        keep = np.abs(found) > 0
        found, X = found[keep], X[:, keep]
        found = np.concatenate([found, _copies(op, n, found, X, positive, k, tol)])
    return found[np.argsort(-np.abs(found))][:k]


def _copies(op, n, found, X, positive, k, tol):
    """The second copies of the eigenvalues ``found`` (vectors X, n × m) of ``op``, by
    one search on the deflated operator, each checked on op (:func:`nearest_eigenvalues`).
    Returns (c,) complex."""
    cols = [X.real] + [X.imag[:, [j]] for j in range(X.shape[1])
                       if np.linalg.norm(X.imag[:, j]) > 1e-10 * np.linalg.norm(X[:, j])]
    Q = np.linalg.qr(np.column_stack(cols))[0]
    kk = min(positive + 1, k, n - 2 - Q.shape[1])
    if kk < 1:
        return np.zeros(0, complex)
    AQ = _apply(op, Q)
    R = Q.T @ AQ

    def deflated(x):
        y = op.matvec(x - Q @ (Q.T @ x))
        return y - Q @ (Q.T @ y)

    try:
        nu, vec = spla.eigs(spla.LinearOperator((n, n), matvec=deflated, dtype=float), k=kk,
                            which="LM", tol=tol, v0=np.random.default_rng(0).standard_normal(n))
    except spla.ArpackNoConvergence as exc:
        nu, vec = np.asarray(exc.eigenvalues), np.asarray(exc.eigenvectors)
    bound = np.sort(np.abs(found))[::-1][min(k, found.size) - 1]
    added = []
    for lam, w in zip(nu, vec.T):
        if not abs(lam) >= bound * (1 - 1e-6):
            continue
        Aw = _apply(op, w[:, None])[:, 0]
        z = np.linalg.lstsq(R - lam * np.eye(R.shape[0]), -(Q.T @ Aw), rcond=None)[0]
        x = w + Q @ z
        if np.linalg.norm(Aw + AQ @ z - lam * x) <= 1e-6 * abs(lam) * np.linalg.norm(x):
            added.append(lam)
    return np.asarray(added, complex)


def _apply(op, X):
    """op (real) applied to each column of X (n, m), real or complex."""
    out = np.empty(X.shape, dtype=X.dtype)
    for j in range(X.shape[1]):
        out[:, j] = op.matvec(X[:, j].real)
        if np.iscomplexobj(X):
            out[:, j] += 1j * op.matvec(X[:, j].imag)
    return out


def _count(nu):
    """(number of μ = 1/ν real and > 0, μ sorted by |μ|) of the eigenvalues ν of J⁻¹B."""
    mu = 1.0 / nu
    mu = mu[np.argsort(np.abs(mu))]
    real = np.abs(mu.imag) <= 1e-6 * np.abs(mu)
    return int(np.sum(real & (mu.real > 0))), mu


def unstable_modes(Y: np.ndarray, prob: StaticProblem, k: int = 8, lu=None):
    """Number of unstable modes of the equilibrium ``Y`` and the eigenvalues μ = −ω²
    (1/s², per the mass and inertia of ``prob``) nearest zero, by shift-invert Arnoldi on
    J⁻¹ B (μ > 0: ω² < 0, unstable), each eigenvalue as often as its multiplicity
    (:func:`nearest_eigenvalues`). ``lu``: a factorisation of J with ``solve`` (default
    :func:`factor_jacobian`). Returns (count, μ sorted by |μ|); count -1 when ARPACK
    converged on no eigenvalue.
    """
    lu = factor_jacobian(Y, prob) if lu is None else lu
    B = mass_matrix(Y, prob)
    n = B.shape[0]
    op = spla.LinearOperator((n, n), matvec=lambda x: lu.solve(B @ x), dtype=float)
    nu = nearest_eigenvalues(op, n, min(k, n - 2))
    if nu.size == 0:
        return -1, np.array([], complex)
    return _count(nu)


def critical_mode(Y: np.ndarray, prob: StaticProblem) -> np.ndarray:
    """(N+1, 13) the eigenvector of the pencil with μ nearest zero (real part), scaled
    to a largest position component of 1 m."""
    lu = factor(jacobian(Y, prob), np.tile(prob.scales(), prob.n_segments + 1))
    B = mass_matrix(Y, prob)
    n = B.shape[0]
    op = spla.LinearOperator((n, n), matvec=lambda x: lu.solve(B @ x), dtype=float)
    nu, vec = spla.eigs(op, k=min(6, n - 2), which="LM", tol=1e-10, v0=np.ones(n))
    z = vec[:, int(np.argmax(np.abs(nu)))].real.reshape(-1, NV)
    return z / np.max(np.abs(z[:, 0:3]))


# --------------------------------------------------------------------------- derived fields

def fields(Y: np.ndarray, prob: StaticProblem) -> dict:
    """Positions (N+1, 3) m, κ (N+1, 3) 1/m, quaternions (N+1, 4), internal force and
    moment (N+1, 3) N, N m, the elastic energy ½∫(κ − κ⁰)·K(κ − κ⁰) ds (J, trapezoid) and
    the potential of the dead loads −∫f·r ds − Σ F·r over the ends' loaded components
    (J)."""
    R = _rot(Y[:, 3:7])
    strain = np.einsum("kji,kj->ki", R, Y[:, 10:13]) / prob.stiffness     # κ − κ⁰
    kappa = strain + prob.kappa0
    w = np.full(prob.n_segments + 1, prob.h)
    w[0] = w[-1] = 0.5 * prob.h
    elastic = 0.5 * float(np.sum(w * np.sum(prob.stiffness * strain**2, axis=1)))
    potential = -float(np.sum(w * np.sum(prob.load * Y[:, 0:3], axis=1)))
    for end, r in ((prob.start, Y[0, 0:3]), (prob.end, Y[-1, 0:3])):
        loaded = ~end.held
        fa = end.axes.T @ end.force
        ra = end.axes.T @ r
        potential -= float(np.sum(fa[loaded] * ra[loaded]))
    return {"position": Y[:, 0:3], "kappa": kappa, "quaternion": Y[:, 3:7],
            "force": Y[:, 7:10], "moment": Y[:, 10:13], "elastic_energy": elastic,
            "load_potential": potential}


# --------------------------------------------------------------------------- from a case

def _integral(cond, t0: float, t1: float) -> float:
    """∫ value dt of a Condition over [t0, t1] (piecewise-linear table held at its ends)."""
    from .case import Table

    v = cond.value
    if not isinstance(v, Table):
        return float(v) * (t1 - t0)
    tt = np.unique(np.concatenate([[t0, t1], [x for x in v.t if t0 < x < t1]]))
    vals = np.array([v.value_at(x) for x in tt])
    return float(np.trapezoid(vals, tt)) if hasattr(np, "trapezoid") else float(np.trapz(vals, tt))


def _dof(conditions, t: float, where: str, anchors=None):
    """(kind of the condition in force at t, its value at t, its integral over [0, t]);
    raises StaticsError if a kinematic condition at t follows a load before t, unless
    ``anchors`` holds where the end was when that load phase ended: {(where, t_a):
    r_a (3,) m}, t_a the last load phase's ``until``. The kind is then "anchored" and
    the third item (r_a, the integral over [t_a, t]) instead (the dynamic centreline
    scheme records r_a when its run reaches t_a: :class:`solver.centreline.
    CentrelineRod`)."""
    t0 = 0.0
    total = since = 0.0
    t_load = None                               # the last load phase's until
    for cond in conditions:
        t1 = t if cond.until is None else min(t, cond.until)
        if cond.kinematic and cond.kind != "position" and t1 > t0:
            part = _integral(cond, t0, t1)
            total += part
            since += part
        if cond.until is None or t <= cond.until:
            if cond.kind == "position":                 # absolute: needs no anchor
                return "position", cond.value_at(t), None
            if t_load is not None and cond.kinematic:
                key = (where, t_load)
                if anchors is None or key not in anchors:
                    raise StaticsError(f"{where}: held at t = {t} s after a load phase: "
                                       "the static problem does not know where the end "
                                       "stopped")
                return "anchored", cond.value_at(t), (np.asarray(anchors[key], float), since)
            return cond.kind, cond.value_at(t), total
        if not cond.kinematic:
            t_load, since = cond.until, 0.0
        t0 = cond.until
    raise AssertionError("validated conditions cover every time")


def load_to_held_switches(case) -> list:
    """The ends' translation items held after a load phase: [(end name "start"/"end",
    the item's ``where`` as :func:`_dof` keys it, t_a)] for each load phase's ``until``
    t_a followed by a kinematic condition (the times at which the dynamic centreline
    scheme records where the end is, :func:`_dof`'s ``anchors``)."""
    out = []
    for name in ("start", "end"):
        ec = getattr(case.boundary, name)
        if ec is None:
            continue
        for i, conditions in enumerate(ec.translation):
            for a, b in zip(conditions[:-1], conditions[1:]):
                if not a.kinematic and b.kinematic:
                    out.append((name, f"boundary.{name}.translation.{i}", float(a.until)))
    return out


def _dead_loads(case, props, t: float):
    """(N+1, 3) dead force per length (N/m) at the nodes at time t: gravity with buoyancy,
    the active distributed forces, interior point loads as P/Δs; and the point loads at
    the ends {"start": (3,), "end": (3,)} (N). Raises StaticsError for a follower point
    load or one between nodes."""
    s = props.s
    N = s.size - 1
    load = np.zeros((N + 1, 3))
    if case.gravity is not None:
        rho_f = case.fluid.density if case.fluid is not None else 0.0
        rho = np.asarray(case.rod.evaluate("density", s), float)
        load += ((rho - rho_f) * props.area)[:, None] * np.asarray(case.gravity, float)
    for i, dfc in enumerate(case.distributed_forces):
        if not dfc.is_active(t):              # start <= t < end, the case's window
            continue
        fac = 1.0 if dfc.factor is None else dfc.factor.value_at(t)
        mask = np.ones(N + 1, bool)
        if dfc.s_range is not None:
            mask = (s >= dfc.s_range[0] - 1e-12) & (s <= dfc.s_range[1] + 1e-12)
        load[mask] += fac * np.asarray(dfc.value, float)
    extra_force = {"start": np.zeros(3), "end": np.zeros(3)}
    for i, pl in enumerate(case.point_loads):
        if not pl.is_active(t):               # start <= t < end, the case's window
            continue
        if pl.body:
            raise StaticsError(f"point_loads.{i}.body: a follower load is not conservative; "
                               "the static problem takes dead loads (body: false)")
        k = int(round(pl.s / props.ds))
        if abs(k * props.ds - pl.s) > 1e-9 * case.rod.length:
            raise StaticsError(f"point_loads.{i}.s: {pl.s} m is not a grid node")
        fac = 1.0 if pl.factor is None else pl.factor.value_at(t)
        P = fac * np.asarray(pl.value, float)
        if k == 0:
            extra_force["start"] += P
        elif k == N:
            extra_force["end"] += P
        else:
            load[k] += P / props.ds
    return load, extra_force


def applied_sign(end: str) -> float:
    """The sign that turns an end's ``force`` item into the load applied there
    (:attr:`EndSpec.force`): a force item gives the internal force n, the part beyond s
    on the part before it (docs/case-spec.md, "Frames and signs"), so the load applied
    to the end s = L (``end = "end"``) is +n and to the end s = 0 (``"start"``) −n.
    Raises ValueError for another name."""
    if end not in ("start", "end"):
        raise ValueError(f"applied_sign: the end is 'start' or 'end', got {end!r}")
    return -1.0 if end == "start" else 1.0


def _end_spec(ec, where: str, qk, rk, t: float, extra, anchors=None) -> EndSpec:
    """The :class:`EndSpec` of the case's end conditions ``ec`` at time t, the end's
    initial frame qk (4,) and position rk (3,) m, plus point loads ``extra`` (3,) N at the
    end; ``anchors`` as :func:`_dof`'s. Raises StaticsError naming ``where`` for what a
    static problem cannot take."""
    rot = [_dof(ec.rotation[i], t, f"{where}.rotation.{i}") for i in range(3)]
    kinds = {kd for kd, _, _ in rot}
    if kinds == {"angular_velocity"}:
        angles = [a for _, _, a in rot]
        if ec.frame == "global" or (angles[0] == 0 and angles[1] == 0):
            twist = 0.0 if ec.frame == "global" else angles[2]
        else:
            raise StaticsError(f"{where}.rotation: the static problem turns a held end "
                               "about its tangent a3 only (items 0 and 1 integrate to 0)")
        quat = _qmul(qk, quat_axis_angle([0, 0, 1], twist))
        held_rot = True
    elif kinds == {"moment"}:
        if any(v != 0 for _, v, _ in rot):
            raise StaticsError(f"{where}.rotation: an end moment in the body frame is a "
                               "follower moment; the static problem takes moment 0 "
                               "(free) or a held rotation")
        quat, twist, held_rot = qk, 0.0, False
    else:
        raise StaticsError(f"{where}.rotation: mixed angular_velocity and moment items "
                           "are not a static end condition; hold all or free all")
    axes = np.eye(3) if ec.frame == "global" else _rot(quat)
    held = np.zeros(3, bool)
    pos = np.array(rk, float)
    force = np.zeros(3)
    sign = applied_sign(where.rsplit(".", 1)[-1])
    for i in range(3):
        kind, value, integral = _dof(ec.translation[i], t, f"{where}.translation.{i}",
                                     anchors)
        if kind == "position":
            held[i] = True
            pos = pos + (value - axes[:, i] @ pos) * axes[:, i]
        elif kind == "anchored":
            # where the end was when the load phase ended, moved along since
            held[i] = True
            r_a, since = integral
            if ec.frame != "global" and i < 2 and twist != 0:
                raise StaticsError(f"{where}.translation.{i}: a body-frame velocity "
                                   "across a turning end depends on the path")
            pos = pos + (axes[:, i] @ r_a + since - axes[:, i] @ pos) * axes[:, i]
        elif kind == "velocity":
            held[i] = True
            if ec.frame != "global" and i < 2 and integral != 0 and twist != 0:
                raise StaticsError(f"{where}.translation.{i}: a body-frame velocity "
                                   "across a turning end depends on the path")
            pos = pos + integral * axes[:, i]
        else:
            if not held_rot and ec.frame != "global" and value != 0:
                raise StaticsError(f"{where}.translation.{i}: a body-frame force on an "
                                   "end free to turn is a follower load")
            force = force + sign * value * axes[:, i]
    force = force + extra
    return EndSpec(axes=axes, held=held, position=pos, force=force,
                   rotation_held=held_rot, quaternion=quat, twist=twist)


def static_problem(case, time: Optional[float] = None) -> StaticProblem:
    """The static problem of a validated :class:`solver.case.Case` at ``time`` (s;
    default ``numerics.t_end``): the end conditions in force then, velocities and angular
    velocities integrated from 0 to ``time`` into positions and rotation angles from the
    initial configuration, the dead loads active then.

    Supported (else :class:`StaticsError` naming the field): a rotation held (every item
    angular_velocity) turning about the end's tangent a3 only, or free under zero moments;
    body-frame velocities of a turning end along a3 only; end forces on an end whose
    rotation is held (dead in its fixed frame) or with ``frame: global``; point loads with
    ``body: false`` at grid nodes. Self-contact (``contact``) enters by its law's
    repulsion without damping (:func:`contact_loads`), the seabed by its normal spring
    without damping and friction (:func:`seabed_loads`), ``electrostatics`` by its
    Debye–Hückel repulsion (:func:`electrostatic_loads`); fluid drag does not enter. A
    closed rod (``rod.closed``) is refused: its static rows are singular
    (:func:`_closed_rows`), a dynamic run takes it.
    """
    from .initial import initial_pose
    from .properties import RodProperties

    if getattr(case.rod, "closed", False):
        raise StaticsError("rod.closed: the statics do not take a closed rod yet (its "
                           "equilibria are not isolated: the ring's rigid motions and an "
                           "isotropic rod's spin about its centreline leave the rows "
                           "singular); a dynamic run (numerics.formulation: centreline) "
                           "takes it")
    t = float(case.numerics.t_end if time is None else time)
    if not np.isfinite(t) or t < 0:
        raise StaticsError(f"time: {t} is not a time >= 0")
    props = RodProperties.from_case(case)
    q, r, _ = initial_pose(case, props.s)  # the ends' initial frames and positions
    return problem_at(case, t, props, q, r)


def problem_at(case, t: float, props, q, r, skip=(), anchors=None) -> StaticProblem:
    """The static problem of ``case`` at time t (s) on its evaluated properties ``props``
    (:class:`solver.properties.RodProperties`), from initial frames q (N+1, 4) and
    positions r (N+1, 3) m (only the ends' are read): :func:`static_problem` without
    recomputing them, the rows the centreline scheme (:mod:`solver.centreline`) steps
    on. The ends named in ``skip`` ("start", "end") are left free under their point
    loads for the caller to replace; ``anchors``: where an end held after a load phase
    was when that phase ended (:func:`_dof`). Raises :class:`StaticsError` as
    :func:`static_problem`."""
    N = case.numerics.n_segments
    load, extra_force = _dead_loads(case, props, t)
    if getattr(case.rod, "closed", False):
        return _closed_problem(case, props, q, r, load, extra_force)
    ends = {}
    for name, k in (("start", 0), ("end", N)):
        if name in skip:
            ends[name] = free_end(extra_force[name])
            continue
        ends[name] = _end_spec(getattr(case.boundary, name), f"boundary.{name}", q[k], r[k],
                               t, extra_force[name], anchors)
    inertia = np.asarray(props.inertia[:, 0], float)
    contact, electrostatics = _pair_models(case, props)
    seabed = None
    if case.seabed is not None:
        from .seabed import SeabedContact
        seabed = SeabedContact(case.seabed, props.diameter)
    return StaticProblem(length=float(case.rod.length), n_segments=N,
                         stiffness=np.asarray(props.stiffness, float), load=load,
                         start=ends["start"], end=ends["end"], mass=props.rho_a,
                         inertia=inertia, reference=np.asarray(q[0], float),
                         contact=contact, seabed=seabed, electrostatics=electrostatics,
                         intrinsic_curvature=props.intrinsic_curvature)


def _pair_models(case, props):
    """(self-contact, screened electrostatics) of ``case`` on its evaluated properties
    (:class:`solver.contact.SelfContact`, :class:`solver.electrostatics.
    ScreenedElectrostatics`), each None where the case has none; of a closed rod
    (``rod.closed``) both periodic: the arclength exclusion measured round the ring,
    node N's loads node 0's."""
    closed = bool(getattr(case.rod, "closed", False))
    contact = electrostatics = None
    if case.electrostatics is not None:
        from .electrostatics import ScreenedElectrostatics
        es = case.electrostatics
        electrostatics = ScreenedElectrostatics(
            props.s, es.charge_per_length, es.screening_length(), es.relative_permittivity,
            es.cutoff, es.exclusion, es.quadrature_points, closed=closed)
    if case.contact is not None:
        from .contact import SelfContact
        contact = SelfContact(case.contact, props.s, props.diameter, props.rho_a,
                              closed=closed)
    return contact, electrostatics


def _closed_problem(case, props, q, r, load, extra_force) -> StaticProblem:
    """The rows of a closed rod (``rod.closed``): the cells' and the join's
    (:func:`_closed_rows`) with the dead loads, a point load at s = 0 or s = L (one
    point, the join) as P/h at node 0 and at node N, so that the cells either side carry
    P/2 each, as at an interior node; self-contact and electrostatics periodic
    (:func:`_pair_models`). The centreline scheme's rows (it adds the sea floor's loads
    and self-contact's dynamic law itself); a static solve refuses a closed rod
    (:func:`static_problem`). Raises nothing beyond :func:`problem_at`."""
    N = case.numerics.n_segments
    h = float(case.rod.length) / N
    load = load.copy()
    joint = (extra_force["start"] + extra_force["end"]) / h
    load[0] += joint
    load[-1] += joint
    contact, electrostatics = _pair_models(case, props)
    return StaticProblem(length=float(case.rod.length), n_segments=N,
                         stiffness=np.asarray(props.stiffness, float), load=load,
                         start=clamp(r[0], q[0]), end=free_end(), mass=props.rho_a,
                         inertia=np.asarray(props.inertia[:, 0], float),
                         reference=np.asarray(q[0], float),
                         intrinsic_curvature=props.intrinsic_curvature, closed=True,
                         contact=contact, electrostatics=electrostatics)


def with_load(prob: StaticProblem, **changes) -> StaticProblem:
    """A copy of ``prob`` with fields replaced (dataclasses.replace)."""
    return replace(prob, **changes)


# --------------------------------------------------------------------------- a dynamic start

def start_state(Y: np.ndarray, prob: StaticProblem, mode: Optional[np.ndarray] = None,
                amplitude: float = 0.0, t: float = 0.0):
    """A :class:`solver.initial.StartState` at rest (v = ω = 0) in the equilibrium ``Y``
    (N+1, 13), plus ``amplitude`` (m) times ``mode`` ((N+1, 13), e.g. :func:`critical_mode`,
    largest position component 1 m) when given: f = Rᵀn, κ = K⁻¹Rᵀm + κ⁰ (body frame, the
    dynamic scheme's unknowns), q renormalised, r as they are, the end rotations about a3
    (the linking number's φ) from the ends' ``twist``. Time ``t`` (s)."""
    from .initial import StartState

    Z = np.array(Y, float)
    if mode is not None and amplitude != 0.0:
        Z = Z + float(amplitude) * np.asarray(mode, float)
    q = Z[:, 3:7] / np.linalg.norm(Z[:, 3:7], axis=1)[:, None]
    R = _rot(q)
    f = np.einsum("kji,kj->ki", R, Z[:, 7:10])
    kappa = np.einsum("kji,kj->ki", R, Z[:, 10:13]) / prob.stiffness + prob.kappa0
    zeros = np.zeros_like(f)
    return StartState(t=float(t), v=zeros, omega=zeros.copy(), f=f, kappa=kappa, q=q,
                      r=np.ascontiguousarray(Z[:, 0:3]),
                      phi=np.array([prob.start.twist, prob.end.twist], float))
