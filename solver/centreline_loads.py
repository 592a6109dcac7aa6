"""The centreline scheme's per-node terms, compiled: the inertia and fluid loads with
their exact 6 × 7 Jacobian block, the nodes' kinematics with the derivative of the
angular velocity and the tangent by the frame, and the residual's rounding level.

These are the formulas of :meth:`solver.centreline.CentrelineRod.nodal_loads` and
:meth:`~solver.centreline.CentrelineRod.kinematics` (docs/numerics.md § 9; the seed's
eqs. 4-5 for the inertia and Morison's loads, resistive-force theory's Stokes drag of
:mod:`solver.resistive_force`), evaluated node by node in one kernel instead of as
NumPy expressions over stacked arrays, whose overhead dominated a step. The derivatives
are the complex step (Squire & Trapp 1998; Martins, Sturdza & Alonso 2003), exact to
rounding: every formula below is written with + − × ÷ and the principal square root,
analytic where the complex step is taken. Pure: no I/O, no state.
"""
from __future__ import annotations

import numba
import numpy as np

from .static_band import _rotation

#: the complex step's size (the derivative is its imaginary part / EPS; no cancellation)
EPS = 1e-30


@numba.njit(cache=True)
def _increment(y, yo, D):
    """The increment Δ = (Δr, Δθ) (m, rad) of a node from its old level yo (7,) (r, p) to
    y (7,) into D (6,) (complex-safe): Δr = r − r_old and Δθ = 2 vec(d)/w(d),
    d = p̄_old ⊗ p, the Cayley map's inverse (:func:`solver.centreline.cayley_vector`)."""
    for e in range(3):
        D[e] = y[e] - yo[e]
    aw, ax, ay, az = yo[3], -yo[4], -yo[5], -yo[6]
    bw, bx, by, bz = y[3], y[4], y[5], y[6]
    dw = aw * bw - ax * bx - ay * by - az * bz
    D[3] = 2.0 * (aw * bx + ax * bw + ay * bz - az * by) / dw
    D[4] = 2.0 * (aw * by - ax * bz + ay * bw + az * bx) / dw
    D[5] = 2.0 * (aw * bz + ax * by - ay * bx + az * bw) / dw


@numba.njit(cache=True)
def _node_load(y, yo, cXd, dXd, cX, dX, mass, added, inertia, zeta, drag, out, work):
    """One node's load per length ``out`` (6,) complex, global: the force f_fluid − M r̈
    (N/m) and the moment −R(I Ẇ + W × I W) − ζ_r W3 a3 (N m/m) of y (7,) complex, the
    node's r (m) and quaternion p at the new level; yo (7,) the old level's; the step's
    affine maps Ẋ = cXd Δ + dXd, X = cX Δ + dX (dXd, dX (6,)) of the increment Δ = (Δr,
    Δθ), Δθ = 2 vec(d)/w(d), d = p̄_old ⊗ p (the Cayley map's inverse); mass, added (kg/m),
    inertia (3,) kg m; zeta (3,) the Stokes drag's ζ_n, ζ_t (N s/m²), ζ_r (N s) and drag
    (2,) Morison's ½ρ_f D C_dn, ½ρ_f πD C_dt (kg/m²), zeros where the case has none;
    work (4, 9) complex scratch."""
    D = work[0]
    _increment(y, yo, D)
    Xd = work[1]
    X = work[2]
    for e in range(6):
        Xd[e] = cXd * D[e] + dXd[e]
        X[e] = cX * D[e] + dX[e]
    R = work[3].reshape((3, 3))
    _rotation(y[3:7], R)
    acc_t = R[0, 2] * Xd[0] + R[1, 2] * Xd[1] + R[2, 2] * Xd[2]
    rdot_t = R[0, 2] * X[0] + R[1, 2] * X[1] + R[2, 2] * X[2]
    for e in range(3):
        f = -mass * Xd[e]
        # the added mass on the normal acceleration, r̈ − (a3·r̈) a3
        f -= added * (Xd[e] - acc_t * R[e, 2])
        # Stokes: −ζ_n ṙ − (ζ_t − ζ_n)(a3·ṙ) a3
        f -= zeta[0] * X[e] + (zeta[1] - zeta[0]) * rdot_t * R[e, 2]
        out[e] = f
    if drag[0] != 0.0 or drag[1] != 0.0:
        # Morison on the body velocity v = Rᵀ ṙ: −cdn |v_n| v_n − cdt |v_t| v_t e3
        v0 = R[0, 0] * X[0] + R[1, 0] * X[1] + R[2, 0] * X[2]
        v1 = R[0, 1] * X[0] + R[1, 1] * X[1] + R[2, 1] * X[2]
        speed = np.sqrt(v0 * v0 + v1 * v1)
        b0 = -drag[0] * speed * v0
        b1 = -drag[0] * speed * v1
        b2 = -drag[1] * np.sqrt(rdot_t * rdot_t) * rdot_t
        for e in range(3):
            out[e] += R[e, 0] * b0 + R[e, 1] * b1 + R[e, 2] * b2
    W0, W1, W2 = X[3], X[4], X[5]
    I0, I1, I2 = inertia[0], inertia[1], inertia[2]
    # I Ẇ + W × I W
    g0 = I0 * Xd[3] + (W1 * I2 * W2 - W2 * I1 * W1)
    g1 = I1 * Xd[4] + (W2 * I0 * W0 - W0 * I2 * W2)
    g2 = I2 * Xd[5] + (W0 * I1 * W1 - W1 * I0 * W0)
    for e in range(3):
        out[3 + e] = -(R[e, 0] * g0 + R[e, 1] * g1 + R[e, 2] * g2) - zeta[2] * W2 * R[e, 2]


@numba.njit(cache=True)
def nodal_loads_kernel(Y, Yold, cXd, dXd, cX, dX, mass, added, inertia, zeta, drag,
                       want, L, dL):
    """Every node's inertia and fluid load (:func:`_node_load`) into L (N+1, 6) and, with
    ``want``, its derivative by the node's (r, p) into dL (N+1, 6, 7), exact by the
    complex step. Y, Yold (N+1, 13) the new iterate and the old level; dXd, dX (N+1, 6);
    mass, added (N+1,); inertia (N+1, 3); zeta (N+1, 3) ζ_n, ζ_t, ζ_r; drag (N+1, 2)."""
    n1 = Y.shape[0]
    y = np.empty(7, np.complex128)
    yo = np.empty(7, np.complex128)
    out = np.empty(6, np.complex128)
    work = np.empty((4, 9), np.complex128)
    for k in range(n1):
        for j in range(7):
            y[j] = Y[k, j]
            yo[j] = Yold[k, j]
        _node_load(y, yo, cXd, dXd[k], cX, dX[k], mass[k], added[k], inertia[k],
                   zeta[k], drag[k], out, work)
        for e in range(6):
            L[k, e] = out[e].real
        if not want:
            continue
        for b in range(7):
            y[b] = Y[k, b] + 1j * EPS
            _node_load(y, yo, cXd, dXd[k], cX, dX[k], mass[k], added[k], inertia[k],
                       zeta[k], drag[k], out, work)
            for e in range(6):
                dL[k, e, b] = out[e].imag / EPS
            y[b] = Y[k, b]


@numba.njit(cache=True)
def rounding_level(ab, kl, ku, y, weights):
    """ε max_i w_i Σ_j |J_ij| |y_j| (float) for J in LAPACK band storage ``ab``
    (2 kl + ku + 1, n), J[i, j] at ab[kl + ku + i − j, j]; y, weights (n,): the bound on a
    backward-stable evaluation of J y in the rows' weights (Higham, *Accuracy and
    Stability of Numerical Algorithms*, 2002, § 3.5)."""
    n = y.size
    acc = np.zeros(n)
    d = kl + ku
    for j in range(n):
        yj = abs(y[j])
        if yj == 0.0:
            continue
        for i in range(max(0, j - ku), min(n, j + kl + 1)):
            acc[i] += abs(ab[d + i - j, j]) * yj
    top = 0.0
    for i in range(n):
        top = max(top, weights[i] * acc[i])
    return np.finfo(np.float64).eps * top


@numba.njit(cache=True)
def _node_motion(y, yo, cX, dX, out, R, D):
    """One node's velocity ṙ (m/s), global angular velocity Ω = R W (rad/s) and tangent
    a3 = R e3 into out (9,) complex, of y (7,) complex (r, p at the new level), yo (7,)
    the old level's, X = cX Δ + dX (dX (6,)) as in :func:`_node_load`; R (3, 3) complex
    scratch; D (6,) complex scratch."""
    _increment(y, yo, D)
    for e in range(3):
        out[e] = cX * D[e] + dX[e]
    W0 = cX * D[3] + dX[3]
    W1 = cX * D[4] + dX[4]
    W2 = cX * D[5] + dX[5]
    _rotation(y[3:7], R)
    for e in range(3):
        out[3 + e] = R[e, 0] * W0 + R[e, 1] * W1 + R[e, 2] * W2
        out[6 + e] = R[e, 2]


@numba.njit(cache=True)
def node_motion_kernel(Y, Yold, cX, dX, want, u, Om, t, dOm, dt):
    """Every node's ṙ, Ω and a3 (:func:`_node_motion`) into u, Om, t (N+1, 3) and, with
    ``want``, the derivatives of Ω and a3 by the node's quaternion p into dOm, dt
    (N+1, 3, 4), exact by the complex step. Y, Yold (N+1, 13); dX (N+1, 6)."""
    n1 = Y.shape[0]
    y = np.empty(7, np.complex128)
    yo = np.empty(7, np.complex128)
    out = np.empty(9, np.complex128)
    R = np.empty((3, 3), np.complex128)
    D = np.empty(6, np.complex128)
    for k in range(n1):
        for j in range(7):
            y[j] = Y[k, j]
            yo[j] = Yold[k, j]
        _node_motion(y, yo, cX, dX[k], out, R, D)
        for e in range(3):
            u[k, e] = out[e].real
            Om[k, e] = out[3 + e].real
            t[k, e] = out[6 + e].real
        if not want:
            continue
        for b in range(4):
            y[3 + b] = Y[k, 3 + b] + 1j * EPS
            _node_motion(y, yo, cX, dX[k], out, R, D)
            for e in range(3):
                dOm[k, e, b] = out[3 + e].imag / EPS
                dt[k, e, b] = out[6 + e].imag / EPS
            y[3 + b] = Y[k, 3 + b]
