"""The sea floor: normal contact and Coulomb friction at the cable's surface.

A distributed load per unit length on the cells of the grid that touch the bottom, the
law taken at each cell's midpoint (docs/seabed.md):

* **Bottom.** A flat bottom z = e, or the bilinear interpolation h(x, y) of a regular
  grid with its gradient (hx, hy) and twist hxy (held constant outside the grid: the
  clamped direction's gradient is 0). Its unit normal n = (−hx, −hy, 1)/√(1 + hx² + hy²).
* **Normal contact** (MoorDyn v2 theory documentation, seabed: a linear spring-damper
  per unit length, kBot and cBot). The centreline's distance to the bottom's tangent
  plane under it d = (z − h)/√(1 + hx² + hy²) (exact for a plane); the surface
  penetration p = ρ − d with ρ the local radius (half the diameter profile). While
  p > 0 the reaction per unit length is F_n = N n with
  N = k p + clamp(−c n·ṙ, −k p, k p): k = ``normal_stiffness`` (Pa), c =
  ``normal_damping`` (Pa s); MoorDyn's k p − c n·ṙ wherever the damper's force is
  smaller than the spring's. The clamp keeps N between 0 and 2kp: the damper neither
  pulls a lifting cable down (no adhesion) nor jumps the force at first touch (MoorDyn's
  law jumps by c·|n·ṙ| at p = 0, which made Newton cycle; Hunt & Crossley (1975) scale
  the damping with the penetration for physical reasons, no jump at impact and no pull
  at separation; the clamp is not their law). MoorDyn's kBot (Pa/m) and cBot (Pa s/m)
  are per unit of contact width: k = kBot·D, c = cBot·D.
* **Friction** (Coulomb, axial and lateral separately as MoorDyn v2 does) acts at the
  contact point r − ρn, whose velocity is w = ṙ + Ω × (−ρn) (Ω the global angular
  velocity of the section, so a spinning cable's contact point slides unless it rolls).
  With â the cable tangent projected onto the bottom and normalised, l̂ = n × â, and the
  sliding speeds v_a = w·â, v_l = w·l̂:
  F_f = −N (φ_a(v_a) â + φ_l(v_l) l̂),
  φ(v) = sign(v) μ(|v|/v_s) with x = |v|/v_s: μ(x) = μ_s x(2 − x) for x ≤ 1
  (regularised: the static coefficient μ_s = ``static_to_kinetic`` · μ is reached at the
  slip velocity v_s = ``slip_velocity``, as MoorDyn's static coefficient applies below
  its slip threshold), then the smoothstep μ_s + (μ − μ_s)(3y² − 2y³), y = x − 1, to the
  kinetic μ at 2v_s, and μ beyond. MoorDyn's law is linear below the threshold and drops
  to μ at once; this one is continuously differentiable, so that Newton's linearisation
  does not jump between iterates (a piecewise-linear law stalled Newton where nodes
  crossed the threshold). The moment per unit length about the
  centreline is M = (−ρn) × F_f.

**Per cell.** The law acts at each cell's midpoint: the means of its two nodes'
position, velocity, global angular velocity, tangent and radius (for a flat bottom the
penetration is the mean of the nodes'). Its force F and moment M enter the cell's E3 and
E4 rows (:mod:`solver.scheme`) as the box rule's mean of its two nodes' body-frame loads,
½(R_aᵀ + R_bᵀ) F and ½(R_aᵀ + R_bᵀ) M, at the generalized-α level (1 − αf) new + αf old
(the old level from the old pose), in the same Newton as the rest, with the exact
derivative with respect to the two nodes' v and ω at the new level through the pose of
the time route (r = r^n + ½Δt(ṙ^n + R v), R = R^n exp(½Δt(ω^n + ω)), Ω = R ω, tangent
R a3): propagated forward through every step of the formulas above. The law at the
nodes let a lying cable rest on every other node (the box rule's averaging hides a
node-to-node alternation of the nodal loads: 2w, 0, 2w, ... has the cell means w).
With self-contact configured the pose is the space route (integrated along s from κ), so
each cell's loads depend on κ upstream of it and on node 0's motion too: this derivative
through the cell's two nodes is then the band's part (Newton's preconditioner), and the
rest is in the exact product that GMRES applies (:func:`solver.scheme.exact_loads_product`,
from the law's partials that :func:`seabed_into` keeps).

**The damper's branch in a step.** Where the step is long against c/k (at Δt = 0.01 s
with the default c/k = 0.1 s, c|n·ṙ| with ṙ ~ p/Δt is about ten times kp) N sits on the
clamp's bounds 0 or 2kp, which swap with the sign of n·ṙ from one Newton iterate to the
next (N is monotone in the penetration rate, with
slopes differing tenfold between its three branches: Newton's iterates cycled and the
step was refused). Newton therefore holds each cell's branch (0: N = 0, free: N = kp −
c n·ṙ unclamped, 2kp: N = 2kp) fixed within a step's solve, with the held branch's exact
derivative: taken from the law at the iterate after the first correction
(``FREEZE_AT``); each evaluation counts the touching cells whose held branch is not the
law's there, and an iterate with such cells re-decides the branches once its scaled
residual is below ``RECHECK_BELOW`` or the tolerance, so that a solve ends only where
every held branch is the law's (its residual is then the law's); a cell held
at one bound whose law gives the other goes to the free branch between them
(:func:`_next_mode`; the root lies between the two bounds' roots). After
``REDECISIONS`` re-decisions the law's clamp acts at every iterate as before. A cell held
on the free branch whose midpoint an iterate lifts clear of the bottom goes back to the
law's clamp for the rest of the solve: held free, its force jumps at p = 0 from 0 to
−c n·ṙ (the jump the clamp exists to remove), and Newton cycled across it (a cell
arriving at 1 cm/s: 27 N/m; docs/seabed.md, "What a refused step looks like"). The
solution is the law's; only the path of the iterates changes.
This is the primal-dual active-set strategy, a semismooth Newton method, applied to the
clamp's two bounds (M. Hintermüller, K. Ito, K. Kunisch (2002), "The primal-dual active
set strategy as a semismooth Newton method", SIAM J. Optim. 13(3), 865–888), with the
set held through the Newton iterations of the smooth remainder and re-decided near their
solution.

Cost: one pass over the cells, O(N), and one more on the old level; cells whose
midpoint is higher than the bottom's top plus its radius (times the steepest slope
factor) are skipped, and the whole kernel when every node is (:func:`far_from_bottom`).
"""
from __future__ import annotations

import math

import numba
import numpy as np

from .banded import true_at_run_time
from .kernel_data import SeabedData
from .kinematics import _right_jacobian_into

__all__ = ["SeabedContact", "seabed_into", "seabed_points", "seabed_old_into", "seabed_cells", "node_penetration", "to_nodes",
           "far_from_bottom", "contact_length", "hover_gap", "CONTACT_GAP", "touchdown",
           "NO_SEABED"]

#: the kernels' data of a run without a seabed (the scalars' kind 0)
NO_SEABED = SeabedData(scalars=np.zeros(10), radius=np.zeros(1), grid_x=np.zeros(1),
                       grid_y=np.zeros(1), grid_z=np.zeros((1, 1)),
                       old_rows=np.zeros((1, 12)), modes=np.zeros(1), hold=np.zeros(8))

# rows and columns of the node's unknowns (solver.scheme's V, W, E3, E4)
_V, _E3, _E4 = 0, 6, 9


class SeabedContact:
    """The case's ``seabed`` on the grid, as the compiled kernels take it.

    Parameters
    ----------
    spec : solver.case.Seabed
    diameter : (N+1,) m, the diameter profile on the grid

    Attributes
    ----------
    data : :class:`solver.kernel_data.SeabedData`, the kernels' data
    """

    def __init__(self, spec, diameter):
        fr = spec.friction
        radius = 0.5 * np.asarray(diameter, float)
        if spec.bathymetry is None:
            gx = gy = np.zeros(1)
            gz = np.zeros((1, 1))
            kind, elev, top, slope = 1.0, float(spec.elevation), float(spec.elevation), 1.0
        else:
            b = spec.bathymetry
            gx, gy = np.asarray(b.x, float), np.asarray(b.y, float)
            gz = np.ascontiguousarray(b.z, dtype=float)
            kind, elev, top = 2.0, 0.0, float(gz.max())
            hx = np.diff(gz, axis=0) / np.diff(gx)[:, None]
            hy = np.diff(gz, axis=1) / np.diff(gy)[None, :]
            slope = float(np.sqrt(1.0 + np.max(hx**2, initial=0.0) + np.max(hy**2, initial=0.0)))
        scal = np.array([kind, elev, spec.normal_stiffness, spec.normal_damping,
                         0.0 if fr is None else fr.axial, 0.0 if fr is None else fr.lateral,
                         1.0 if fr is None else fr.static_to_kinetic,
                         1.0 if fr is None else fr.slip_velocity, top, slope])
        #: the old level's share of the cell rows (N, 12), set by :meth:`begin_step`
        self.old_rows = np.zeros((radius.size - 1, 12))
        #: the damper's branch per cell held in a step's Newton iterations, and the
        #: control of that hold (:meth:`freeze`)
        self.modes = np.full(radius.size - 1, -1.0)
        self.control = self.freeze_control()
        self.data = SeabedData(scalars=scal, radius=radius, grid_x=gx, grid_y=gy, grid_z=gz,
                               old_rows=self.old_rows, modes=self.modes, hold=self.control)
        self.radius = radius

    def __setstate__(self, state):
        # a checkpoint from before the old level's rows were frozen per step
        self.__dict__.update(state)
        if "old_rows" not in state:
            self.old_rows = np.zeros((self.radius.size - 1, 12))
        if "modes" not in state:
            # ... and from before the damper's branch was held within a step
            self.modes = np.full(self.radius.size - 1, -1.0)
            self.control = self.freeze_control()
        if not isinstance(self.data, SeabedData):
            # ... and from before the data were named (a plain tuple, its first five
            # fields by position)
            self.data = SeabedData(*tuple(self.data)[:5], old_rows=self.old_rows,
                                   modes=self.modes, hold=self.control)

    #: hold the damper's branch within a step's Newton iterations (module docstring,
    #: :meth:`freeze_control`)
    FREEZE = True
    #: the Newton iterate at which the branches are taken from the law (0: the start;
    #: negative: the last solve's branches)
    FREEZE_AT = 1
    #: re-decisions of the branches in one Newton solve, after which the law's clamp
    #: acts at every iterate
    REDECISIONS = 4
    #: the scaled residual below which an iterate with touching cells off the law's
    #: branch re-decides them (a solve held on branches the law no longer takes is not
    #: finished to the tolerance)
    RECHECK_BELOW = 1e-4

    @classmethod
    def freeze_control(cls):
        """The kernels' control of the held branches (6,): state (0 the law's clamp at
        every evaluation, 1 take the branches from the law, 2 use the held ones, 3
        re-decide them, :func:`_next_mode`), on (1) or off (0), the iterate at which they
        are taken, the re-decisions allowed per solve, this solve's re-decisions, the
        run's, the residual below which iterates re-decide, the touching cells off the
        law's branch at the last held evaluation."""
        return np.array([0.0, 1.0 if cls.FREEZE else 0.0, float(cls.FREEZE_AT),
                         float(cls.REDECISIONS), 0.0, 0.0, float(cls.RECHECK_BELOW), 0.0])

    def begin_step(self, af, Y_old, q_old, r_old, v_old_global):
        """Freeze the old level's share αf ½(R_aᵀ + R_bᵀ)(F, M) of each cell's E3, E4 rows
        (:func:`seabed_old_into`) for a step with the generalized-α weight af = αf from
        the old level Y^n (N+1, 12), q^n (N+1, 4), r^n and ṙ^n (N+1, 3) (None: no old
        pose, the share 0)."""
        self.old_rows[:] = 0.0
        if af == 0.0 or r_old is None or q_old is None or v_old_global is None:
            return
        seabed_old_into(np.ascontiguousarray(Y_old, dtype=float),
                        np.ascontiguousarray(q_old, dtype=float),
                        np.ascontiguousarray(r_old, dtype=float),
                        np.ascontiguousarray(v_old_global, dtype=float), float(af), self.data,
                        self.old_rows)

    def cell_loads(self, r, v_global, R, omega):
        """(force (N, 6): normal reaction in [:, 0:3] and friction in [:, 3:6], moment
        (N, 3), penetration (N,) m) of each cell, per unit length, global frame, at its
        midpoint (:func:`seabed_cells`), for node positions r, velocities ṙ (N+1, 3),
        frames R (N+1, 3, 3) and body angular velocities ω (N+1, 3)."""
        nc = r.shape[0] - 1
        F, M, pen = np.zeros((nc, 6)), np.zeros((nc, 3)), np.zeros(nc)
        seabed_cells(np.ascontiguousarray(r, dtype=float),
                     np.ascontiguousarray(v_global, dtype=float),
                     np.ascontiguousarray(R, dtype=float), np.ascontiguousarray(omega, dtype=float),
                     self.data, F, M, pen)
        return F, M, pen

    def loads(self, r, v_global, R, omega):
        """(normal reaction, friction, moment) per unit length at the nodes, each
        (N+1, 3) N/m or N m/m, global frame (the mean of a node's two cells' loads,
        :func:`to_nodes`), and each node's surface penetration (N+1,) m (negative: the
        gap, :func:`node_penetration`), for positions r, velocities ṙ (N+1, 3), frames
        R (N+1, 3, 3) and body angular velocities ω (N+1, 3)."""
        F, M, _ = self.cell_loads(r, v_global, R, omega)
        pen = np.empty(r.shape[0])
        node_penetration(np.ascontiguousarray(r, dtype=float), self.data, pen)
        F, M = to_nodes(F), to_nodes(M)
        return F[:, 0:3], F[:, 3:6], M, pen

    def stored_energy(self, r, ds) -> float:
        """The spring's stored energy U = Σ_cells Δs ½ k max(p, 0)² (J) of the cells'
        midpoint penetrations p at node positions r (N+1, 3), cells of length ds (m)."""
        r = np.ascontiguousarray(r, dtype=float)
        n1 = r.shape[0]
        eye = np.broadcast_to(np.eye(3), (n1, 3, 3))
        _, _, pen = self.cell_loads(r, np.zeros((n1, 3)), eye, np.zeros((n1, 3)))
        return float(ds * np.sum(0.5 * self.data.scalars[2] * np.maximum(pen, 0.0) ** 2))

    def nodal_stored_energy(self, penetration, weights) -> float:
        """The spring's stored energy U = Σ_k w_k ½ k max(p_k, 0)² (J) of the law taken at
        the nodes (the centreline scheme's and the statics'): penetrations p (N+1,) m,
        quadrature weights w (N+1,) m. Its gradient is the nodal spring force w_k k p_k
        along the surface normal (flat bottom; each grid cell's tangent plane)."""
        pen = np.maximum(np.asarray(penetration, dtype=float), 0.0)
        return float(np.sum(np.asarray(weights, dtype=float) * 0.5
                            * self.data.scalars[2] * pen ** 2))


@numba.njit(cache=True, inline="always")
def _locate(g, x):
    """(cell i, share t in [0, 1], inside) of x on the increasing axis g (binary search);
    outside the axis the nearest end, t at it, inside False."""
    n = g.shape[0]
    if x <= g[0]:
        return 0, 0.0, False
    if x >= g[n - 1]:
        return n - 2, 1.0, False
    lo, hi = 0, n - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if g[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo, (x - g[lo]) / (g[lo + 1] - g[lo]), True


@numba.njit(cache=True)
def _bottom(x, y, data):
    """(h, hx, hy, hxy) of the bottom at global (x, y) m: the flat elevation, or the
    grid's bilinear interpolation with its derivatives (0 across a clamped axis)."""
    scal, gx, gy, gz = data.scalars, data.grid_x, data.grid_y, data.grid_z
    if scal[0] == 1.0:
        return scal[1], 0.0, 0.0, 0.0
    i, tx, inx = _locate(gx, x)
    j, ty, iny = _locate(gy, y)
    z00, z10, z01, z11 = gz[i, j], gz[i + 1, j], gz[i, j + 1], gz[i + 1, j + 1]
    ddx = gx[i + 1] - gx[i]
    ddy = gy[j + 1] - gy[j]
    h = ((1.0 - tx) * (1.0 - ty) * z00 + tx * (1.0 - ty) * z10 + (1.0 - tx) * ty * z01
         + tx * ty * z11)
    hx = ((1.0 - ty) * (z10 - z00) + ty * (z11 - z01)) / ddx if inx else 0.0
    hy = ((1.0 - tx) * (z01 - z00) + tx * (z11 - z10)) / ddy if iny else 0.0
    hxy = (z11 - z10 - z01 + z00) / (ddx * ddy) if (inx and iny) else 0.0
    return h, hx, hy, hxy


@numba.njit(cache=True, inline="always")
def _coef(v, mu, ratio, vs):
    """The friction coefficient law φ(v) (signed) and its derivative φ'(v) (s/m):
    module docstring (x = |v|/v_s: μ_s x(2 − x) up to x = 1, the smoothstep from μ_s
    to μ up to x = 2, μ beyond; continuously differentiable)."""
    x = abs(v) / vs
    sg = 1.0 if v >= 0.0 else -1.0
    mus = ratio * mu
    if x <= 1.0:
        return sg * mus * x * (2.0 - x), mus * (2.0 - 2.0 * x) / vs
    if x < 2.0:
        y = x - 1.0
        return (sg * (mus + (mu - mus) * y * y * (3.0 - 2.0 * y)),
                (mu - mus) * 6.0 * y * (1.0 - y) / vs)
    return sg * mu, 0.0


@numba.njit(cache=True, inline="always")
def _cross_cols(a, B, out, sign):
    """out (3, m) += sign · a × B[:, j] for every column j (a (3,), B (3, m))."""
    for j in range(B.shape[1]):
        out[0, j] += sign * (a[1] * B[2, j] - a[2] * B[1, j])
        out[1, j] += sign * (a[2] * B[0, j] - a[0] * B[2, j])
        out[2, j] += sign * (a[0] * B[1, j] - a[1] * B[0, j])


@numba.njit(cache=True, inline="always")
def _zero_derivatives(DF, DM):
    """DF, DM (3, m) := 0: a cell the bottom does not push on has no load derivatives."""
    for i in range(3):
        for j in range(DF.shape[1]):
            DF[i, j] = 0.0
            DM[i, j] = 0.0


@numba.njit(cache=True)
def _node(x, u, Om, t, rho, data, want, Dr, Du, DOm, Dt, Fn, Ff, M, DF, DM, wk):
    """The seabed's law at one point of the centreline (a cell's midpoint, module
    docstring): normal reaction Fn, friction Ff, moment M (3,) global, per unit length,
    from the centreline x, its velocity u, the global angular velocity Om, the tangent t
    (3,) and the radius rho (m). With ``want`` also DF = ∂(Fn + Ff)/∂X and DM = ∂M/∂X
    (3, m) for the derivatives of x, u, Om, t with respect to m unknowns X (Dr, Du, DOm,
    Dt (3, m)), by forward propagation through the formulas. wk: scratch (9, 3, m).
    Returns the penetration p (m, ≤ 0: no contact, every output 0)."""
    # mode −1 and rule off, typed as run-time values: the same compiled _law as
    # seabed_into's (solver.banded.true_at_run_time)
    yes = true_at_run_time(x)
    return _law(x, u, Om, t, rho, data, want, Dr, Du, DOm, Dt, Fn, Ff, M, DF, DM, wk,
                -1 if yes else 0, not yes)[0]


@numba.njit(cache=True)
def _law(x, u, Om, t, rho, data, want, Dr, Du, DOm, Dt, Fn, Ff, M, DF, DM, wk, mode, rule):
    """:func:`_node` with the damper's branch given: mode −1 the law's own (the clamp),
    0 the lower bound (N = 0), 1 free (N = k p − c n·ṙ, unclamped), 2 the upper bound
    (N = 2kp); with ``rule`` the branch is the one :func:`_next_mode` gives from mode and
    the law's. Returns (p, the branch used, the law's own). The branch is decided (and returned) where
    p ≤ 0 too: there the outputs are 0 whatever it is."""
    for i in range(3):
        Fn[i] = 0.0
        Ff[i] = 0.0
        M[i] = 0.0
    scal = data.scalars
    kst, cdp, mua, mul, ratio, vs = scal[2], scal[3], scal[4], scal[5], scal[6], scal[7]
    h, hx, hy, hxy = _bottom(x[0], x[1], data)
    sq = math.sqrt(1.0 + hx * hx + hy * hy)
    n0, n1, n2 = -hx / sq, -hy / sq, 1.0 / sq
    d = (x[2] - h) / sq
    p = rho - d
    sn = n0 * u[0] + n1 * u[1] + n2 * u[2]
    spring = kst * p
    damper = -cdp * sn
    if damper > spring:
        law = 2
    elif spring + damper <= 0.0:
        law = 0
    else:
        law = 1
    if rule:
        m = _next_mode(mode, law)
    elif mode < 0:
        m = law
    else:
        m = mode
    if p <= 0.0 or m == 0:
        if want:
            _zero_derivatives(DF, DM)
        return p, m, law
    capped = m == 2
    if capped:
        N = 2.0 * spring
    else:
        N = spring + damper
    if N == 0.0:
        if want:
            _zero_derivatives(DF, DM)
        return p, m, law
    n = wk[7, 0]
    n[0], n[1], n[2] = n0, n1, n2
    for i in range(3):
        Fn[i] = N * n[i]
    fric = mua > 0.0 or mul > 0.0
    # friction: contact-point velocity, directions, speeds
    w, a, ah, lh = wk[7, 1], wk[7, 2], wk[8, 0], wk[8, 1]
    w[0] = u[0] - rho * (Om[1] * n2 - Om[2] * n1)
    w[1] = u[1] - rho * (Om[2] * n0 - Om[0] * n2)
    w[2] = u[2] - rho * (Om[0] * n1 - Om[1] * n0)
    tn = t[0] * n0 + t[1] * n1 + t[2] * n2
    for i in range(3):
        a[i] = t[i] - tn * n[i]
    la = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    if la < 1e-12:
        fric = False        # the cable stands on the bottom: no axial direction
    pa = pl = dpa = dpl = va = vl = 0.0
    if fric:
        for i in range(3):
            ah[i] = a[i] / la
        lh[0] = n1 * ah[2] - n2 * ah[1]
        lh[1] = n2 * ah[0] - n0 * ah[2]
        lh[2] = n0 * ah[1] - n1 * ah[0]
        va = w[0] * ah[0] + w[1] * ah[1] + w[2] * ah[2]
        vl = w[0] * lh[0] + w[1] * lh[1] + w[2] * lh[2]
        pa, dpa = _coef(va, mua, ratio, vs)
        pl, dpl = _coef(vl, mul, ratio, vs)
        for i in range(3):
            Ff[i] = -N * (pa * ah[i] + pl * lh[i])
        M[0] = -rho * (n1 * Ff[2] - n2 * Ff[1])
        M[1] = -rho * (n2 * Ff[0] - n0 * Ff[2])
        M[2] = -rho * (n0 * Ff[1] - n1 * Ff[0])
    if not want:
        return p, m, law
    # ---- derivatives with respect to the unknowns X (3, m columns)
    Dn, Dw, Da, Dah, Dl, DFf = wk[0], wk[1], wk[2], wk[3], wk[4], wk[5]
    # ∂n/∂x and ∂d/∂x (bilinear: hxx = hyy = 0)
    dsx = hy * hxy / sq
    dsy = hx * hxy / sq
    G0, G1 = -hx, -hy
    dn = wk[6]          # (3, 3) in its first columns: ∂n/∂x
    dn[0, 0] = -G0 * dsx / (sq * sq)
    dn[1, 0] = -hxy / sq - G1 * dsx / (sq * sq)
    dn[2, 0] = -dsx / (sq * sq)
    dn[0, 1] = -hxy / sq - G0 * dsy / (sq * sq)
    dn[1, 1] = -G1 * dsy / (sq * sq)
    dn[2, 1] = -dsy / (sq * sq)
    dn[0, 2] = 0.0
    dn[1, 2] = 0.0
    dn[2, 2] = 0.0
    dd0 = n0 - d * dsx / sq
    dd1 = n1 - d * dsy / sq
    dd2 = n2
    DN = wk[8, 2]
    nc = Dr.shape[1]
    for j in range(nc):
        for i in range(3):
            Dn[i, j] = dn[i, 0] * Dr[0, j] + dn[i, 1] * Dr[1, j]
        Dd = dd0 * Dr[0, j] + dd1 * Dr[1, j] + dd2 * Dr[2, j]
        Dsn = (n0 * Du[0, j] + n1 * Du[1, j] + n2 * Du[2, j]
               + u[0] * Dn[0, j] + u[1] * Dn[1, j] + u[2] * Dn[2, j])
        DN[j] = -2.0 * kst * Dd if capped else -kst * Dd - cdp * Dsn
        for i in range(3):
            DF[i, j] = DN[j] * n[i] + N * Dn[i, j]
            DM[i, j] = 0.0
    if not fric:
        return p, m, law
    # Dw = Du − ρ(DOm × n + Om × Dn)
    for i in range(3):
        for j in range(nc):
            Dw[i, j] = Du[i, j]
    _cross_cols(n, DOm, Dw, rho)            # −ρ DOm × n = +ρ n × DOm
    _cross_cols(Om, Dn, Dw, -rho)
    # Da = Dt − n (nᵀDt + tᵀDn) − (t·n) Dn
    for j in range(nc):
        c = (n0 * Dt[0, j] + n1 * Dt[1, j] + n2 * Dt[2, j]
             + t[0] * Dn[0, j] + t[1] * Dn[1, j] + t[2] * Dn[2, j])
        for i in range(3):
            Da[i, j] = Dt[i, j] - n[i] * c - tn * Dn[i, j]
    # Dâ = (I − â âᵀ) Da / |a|
    for j in range(nc):
        c = ah[0] * Da[0, j] + ah[1] * Da[1, j] + ah[2] * Da[2, j]
        for i in range(3):
            Dah[i, j] = (Da[i, j] - ah[i] * c) / la
    # Dl = Dn × â + n × Dâ
    for i in range(3):
        for j in range(nc):
            Dl[i, j] = 0.0
    _cross_cols(ah, Dn, Dl, -1.0)
    _cross_cols(n, Dah, Dl, 1.0)
    for j in range(nc):
        Dva = 0.0
        Dvl = 0.0
        for i in range(3):
            Dva += ah[i] * Dw[i, j] + w[i] * Dah[i, j]
            Dvl += lh[i] * Dw[i, j] + w[i] * Dl[i, j]
        for i in range(3):
            DFf[i, j] = (-DN[j] * (pa * ah[i] + pl * lh[i])
                         - N * (dpa * Dva * ah[i] + pa * Dah[i, j]
                                + dpl * Dvl * lh[i] + pl * Dl[i, j]))
            DF[i, j] += DFf[i, j]
    # DM = −ρ (Dn × Ff + n × DFf)
    _cross_cols(Ff, Dn, DM, rho)
    _cross_cols(n, DFf, DM, -rho)
    return p, m, law


@numba.njit(cache=True, inline="always")
def _next_mode(frozen, law):
    """The damper's branch after a re-decision (:meth:`SeabedContact.freeze`): the law's, except
    that a cell held at one bound whose law gives the other goes to the free branch
    between them (N is monotone in the penetration rate, so the root lies between the
    two bounds' roots: held at one bound alone, the iterates would swap bounds)."""
    if frozen < 0 or frozen == law:
        return law
    if frozen + law == 2 and frozen != 1:
        return 1
    return law


@numba.njit(cache=True)
def far_from_bottom(r, data):
    """True when every node is above the bottom's top by more than its radius times the
    steepest slope factor (then no node touches: the kernel is skipped)."""
    scal, radius = data.scalars, data.radius
    lim = scal[8]
    f = scal[9]
    for k in range(r.shape[0]):
        if r[k, 2] - f * radius[k] <= lim:
            return False
    return True


@numba.njit(cache=True, inline="always")
def _seeds_into(Y, R, theta, k, hdt, col, Dr, Du, DOm, Dt, J, S, RS):
    """The derivatives of node k's new-level position, velocity, global angular velocity
    and tangent with respect to its (v, ω), halved (a cell's midpoint takes half of each
    node), into columns col..col+5 of Dr, Du, DOm, Dt (3, 12), and J_r(θ_k) into J
    (1, 3, 3): r = r^n + ½Δt(ṙ^n + R v), R = R^n exp(θ), θ = ½Δt(ω^n + ω), so
    ∂(R a)/∂ω = −½Δt R [a]× J_r and Du = [R | −½Δt R [v]× J_r], Dr = ½Δt Du."""
    _right_jacobian_into(theta[k, 0], theta[k, 1], theta[k, 2], J, 0)
    for vec in range(3):
        if vec == 0:
            a0, a1, a2 = Y[k, 0], Y[k, 1], Y[k, 2]
        elif vec == 1:
            a0, a1, a2 = Y[k, 3], Y[k, 4], Y[k, 5]
        else:
            a0, a1, a2 = 0.0, 0.0, 1.0
        # S = [a]× J_r, RS = −½Δt R S
        for j in range(3):
            S[0, j] = -a2 * J[0, 1, j] + a1 * J[0, 2, j]
            S[1, j] = a2 * J[0, 0, j] - a0 * J[0, 2, j]
            S[2, j] = -a1 * J[0, 0, j] + a0 * J[0, 1, j]
        for i in range(3):
            for j in range(3):
                RS[i, j] = -hdt * (R[i, 0] * S[0, j] + R[i, 1] * S[1, j] + R[i, 2] * S[2, j])
        for i in range(3):
            for j in range(3):
                if vec == 0:
                    Du[i, col + j] = 0.5 * R[i, j]
                    Du[i, col + 3 + j] = 0.5 * RS[i, j]
                    Dr[i, col + j] = 0.5 * hdt * R[i, j]
                    Dr[i, col + 3 + j] = 0.5 * hdt * RS[i, j]
                elif vec == 1:
                    DOm[i, col + j] = 0.0
                    DOm[i, col + 3 + j] = 0.5 * (R[i, j] + RS[i, j])
                else:
                    Dt[i, col + j] = 0.0
                    Dt[i, col + 3 + j] = 0.5 * RS[i, j]


@numba.njit(cache=True)
def _unit_seeds():
    """Unit seeds (4, 3, 12) for :func:`_law`: the derivatives of x, u, Ω and t with
    respect to (x, u, Ω, t) themselves, so that its DF, DM are the law's partials."""
    E = np.zeros((4, 3, 12))
    for a in range(4):
        for i in range(3):
            E[a, i, 3 * a + i] = 1.0
    return E


@numba.njit(cache=True, inline="always")
def _midpoint(r, vg, Rm, omega, radius, a, x, u, Om, t):
    """The midpoint of cell (a, a + 1): centreline x, velocity u, global angular velocity
    Om = ½(R_a ω_a + R_b ω_b), tangent t = ½(R_a a3 + R_b a3) (3,) into the arguments;
    returns the radius ½(ρ_a + ρ_b) (m)."""
    b = a + 1
    for i in range(3):
        x[i] = 0.5 * (r[a, i] + r[b, i])
        u[i] = 0.5 * (vg[a, i] + vg[b, i])
        Om[i] = 0.5 * (Rm[a, i, 0] * omega[a, 0] + Rm[a, i, 1] * omega[a, 1]
                       + Rm[a, i, 2] * omega[a, 2] + Rm[b, i, 0] * omega[b, 0]
                       + Rm[b, i, 1] * omega[b, 1] + Rm[b, i, 2] * omega[b, 2])
        t[i] = 0.5 * (Rm[a, i, 2] + Rm[b, i, 2])
    return 0.5 * (radius[a] + radius[b])


@numba.njit(cache=True)
def _old_frames(q_old, R_old, lo, hi):
    """The rotation matrices of the unit quaternions q_old[lo:hi] into R_old[lo:hi]."""
    for k in range(lo, hi):
        w, x, y, z = q_old[k, 0], q_old[k, 1], q_old[k, 2], q_old[k, 3]
        R_old[k, 0, 0] = 1 - 2 * (y * y + z * z)
        R_old[k, 0, 1] = 2 * (x * y - w * z)
        R_old[k, 0, 2] = 2 * (x * z + w * y)
        R_old[k, 1, 0] = 2 * (x * y + w * z)
        R_old[k, 1, 1] = 1 - 2 * (x * x + z * z)
        R_old[k, 1, 2] = 2 * (y * z - w * x)
        R_old[k, 2, 0] = 2 * (x * z - w * y)
        R_old[k, 2, 1] = 2 * (y * z + w * x)
        R_old[k, 2, 2] = 1 - 2 * (x * x + y * y)


@numba.njit(cache=True)
def _cell_touches(r, radius, a, lim, f):
    """Whether cell (a, a + 1)'s midpoint may touch: its height minus its radius times
    the steepest slope factor f not above the bottom's top lim (m)."""
    return 0.5 * (r[a, 2] + r[a + 1, 2]) - f * 0.5 * (radius[a] + radius[a + 1]) <= lim


@numba.njit(cache=True)
def seabed_into(Y, Rm, r, vg, theta, dt, af, data, want, cells, blocks, record, lin):
    """Add the seabed's loads to the cell rows (N, 12) of the residual and with ``want``
    their exact derivative to the cell blocks (N, 12, 24) on [node k | node k + 1]
    (module docstring): for each cell the law at its midpoint (position, velocity,
    angular velocity, tangent and radius the means of its two nodes'), its force F and
    moment M (N/m, N m/m, global) entering the E3 and E4 rows as the box rule's mean of
    the two nodes' body-frame loads, ½(R_aᵀ + R_bᵀ) F and ½(R_aᵀ + R_bᵀ) M, at the
    generalized-α level: (1 − αf) times the new level's plus αf times the old level's.
    Y (N+1, 12) the iterate with the new-level frames Rm (N+1, 3, 3), positions r and
    velocities ṙ = R v (N+1, 3), rotation increments θ (N+1, 3); dt (s); af = αf (the
    old level's share is data.old_rows, frozen at the step's start by
    :meth:`SeabedContact.begin_step`). The derivative is with respect to the cell's two nodes' v and ω
    at the new level. A cell whose midpoint is above the bottom's top plus its radius
    is skipped.

    With ``record`` (and ``want``: the pose is the space route, so the positions and
    frames depend on κ upstream too) the law's linearisation at each loaded cell is kept
    for the exact product (:func:`solver.scheme.exact_loads_product`) in
    lin = (cells (N,) int, their count (1,) int, ∂(F, M)/∂(x, u, Ω, t) (N, 6, 12) and
    (F, M) (N, 6) N/m, N m/m, global, at the new level), the partials by one more call of
    the law with unit seeds in the branch the cell was evaluated in."""
    scal, radius = data.scalars, data.radius
    if scal[0] == 0.0:
        return
    lim = scal[8]
    f = scal[9]
    hdt = 0.5 * dt
    gf = 1.0 - af
    n_cells = r.shape[0] - 1
    yes = true_at_run_time(r)       # the recorded law's flags (see its docstring)
    x = np.empty(3)
    u = np.empty(3)
    Om = np.empty(3)
    t = np.empty(3)
    Fnv = np.empty(3)
    Ffv = np.empty(3)
    Mv = np.empty(3)
    Dr = np.zeros((3, 12))
    Du = np.zeros((3, 12))
    DOm = np.zeros((3, 12))
    Dt = np.zeros((3, 12))
    DF = np.empty((3, 12))
    DM = np.empty((3, 12))
    wk = np.zeros((9, 3, 12))
    Ja = np.empty((1, 3, 3))
    Jb = np.empty((1, 3, 3))
    S = np.empty((3, 3))
    RS = np.empty((3, 3))
    b = np.empty(3)
    q = np.empty(3)
    sbc, sbn, sbj, sbl = lin
    sbn[0] = 0
    if record:
        E = _unit_seeds()
        PF = np.empty((3, 12))
        PM = np.empty((3, 12))
    modes, hold = data.modes, data.hold
    state = int(hold[0])
    if state == 1:
        for c in range(n_cells):
            modes[c] = -1.0
    if state >= 1:
        hold[7] = 0.0
    if not far_from_bottom(r, data):
        for c in range(n_cells):
            if not _cell_touches(r, radius, c, lim, f):
                if state == 2 and modes[c] == 1.0:
                    # held on the free branch and now clear of the bottom: the law's clamp
                    # from here on in this solve (held free, N jumps by c|n·ṙ| at p = 0)
                    modes[c] = -1.0
                continue
            rho = _midpoint(r, vg, Rm, Y[:, 3:6], radius, c, x, u, Om, t)
            if want:
                _seeds_into(Y, Rm[c], theta, c, hdt, 0, Dr, Du, DOm, Dt, Ja, S, RS)
                _seeds_into(Y, Rm[c + 1], theta, c + 1, hdt, 6, Dr, Du, DOm, Dt, Jb, S, RS)
            held = int(modes[c]) if state >= 2 else -1
            p, m, law = _law(x, u, Om, t, rho, data, want, Dr, Du, DOm, Dt, Fnv, Ffv, Mv, DF,
                             DM, wk, held, state == 3)
            if state == 2 and held == 1 and p <= 0.0:
                modes[c] = -1.0         # clear of the bottom (a slope's skip test passed it)
            if state >= 2 and p > 0.0 and m != law:
                hold[7] += 1.0          # a touching cell off the law's branch
            if state == 1 or state == 3:
                modes[c] = m
            if p <= 0.0 or m == 0:
                continue
            if record:
                _law(x, u, Om, t, rho, data, yes, E[0], E[1], E[2], E[3], Fnv, Ffv, Mv, PF,
                     PM, wk, m, not yes)
                j = sbn[0]
                sbc[j] = c
                sbn[0] = j + 1
                for i in range(3):
                    sbl[c, i] = Fnv[i] + Ffv[i]
                    sbl[c, 3 + i] = Mv[i]
                    for col in range(12):
                        sbj[c, i, col] = PF[i, col]
                        sbj[c, 3 + i, col] = PM[i, col]
            for e in range(2):
                k = c + e
                R = Rm[k]
                for i in range(3):
                    b[i] = 0.5 * gf * (R[0, i] * (Fnv[0] + Ffv[0]) + R[1, i] * (Fnv[1] + Ffv[1])
                                       + R[2, i] * (Fnv[2] + Ffv[2]))
                    q[i] = 0.5 * gf * (R[0, i] * Mv[0] + R[1, i] * Mv[1] + R[2, i] * Mv[2])
                    cells[c, _E3 + i] += b[i]
                    cells[c, _E4 + i] += q[i]
                if not want:
                    continue
                for i in range(3):
                    for j in range(12):
                        col = j if j < 6 else j + 6        # (v, ω) of node c, node c + 1
                        blocks[c, _E3 + i, col] += 0.5 * gf * (
                            R[0, i] * DF[0, j] + R[1, i] * DF[1, j] + R[2, i] * DF[2, j])
                        blocks[c, _E4 + i, col] += 0.5 * gf * (
                            R[0, i] * DM[0, j] + R[1, i] * DM[1, j] + R[2, i] * DM[2, j])
                # node k's body frame turns with its ω: ∂(Rᵀ F)/∂ω = ½Δt [Rᵀ F]× J_r
                J = Ja if e == 0 else Jb
                w0 = 3 + 12 * e
                for vec in range(2):
                    c0, c1, c2 = (b[0], b[1], b[2]) if vec == 0 else (q[0], q[1], q[2])
                    row = _E3 if vec == 0 else _E4
                    for j in range(3):
                        blocks[c, row, w0 + j] += hdt * (-c2 * J[0, 1, j] + c1 * J[0, 2, j])
                        blocks[c, row + 1, w0 + j] += hdt * (c2 * J[0, 0, j] - c0 * J[0, 2, j])
                        blocks[c, row + 2, w0 + j] += hdt * (-c1 * J[0, 0, j] + c0 * J[0, 1, j])
    if af != 0.0:
        old = data.old_rows
        for c in range(n_cells):
            for i in range(12):
                cells[c, i] += old[c, i]


@numba.njit(cache=True)
def seabed_old_into(Y_old, q_old, r_old, vg_old, af, data, out):
    """The old level's share of the seabed's cell rows, αf ½(R_aᵀ + R_bᵀ) F into the E3
    and αf ½(R_aᵀ + R_bᵀ) M into the E4 columns of out (N, 12) (zero elsewhere): the law
    at each cell's midpoint on the old pose Y^n (N+1, 12), q^n (N+1, 4), r^n and ṙ^n
    (N+1, 3) (:func:`seabed_into`; constant in a step, so computed once at its start)."""
    scal, radius = data.scalars, data.radius
    if scal[0] == 0.0 or far_from_bottom(r_old, data):
        return
    lim = scal[8]
    f = scal[9]
    x = np.empty(3)
    u = np.empty(3)
    Om = np.empty(3)
    t = np.empty(3)
    Fnv = np.empty(3)
    Ffv = np.empty(3)
    Mv = np.empty(3)
    wk = np.zeros((9, 3, 12))
    z = np.zeros((3, 12))
    R_old = np.empty((r_old.shape[0], 3, 3))
    _old_frames(q_old, R_old, 0, r_old.shape[0])
    for c in range(r_old.shape[0] - 1):
        if not _cell_touches(r_old, radius, c, lim, f):
            continue
        rho = _midpoint(r_old, vg_old, R_old, Y_old[:, 3:6], radius, c, x, u, Om, t)
        p = _node(x, u, Om, t, rho, data, not true_at_run_time(x), z, z, z, z, Fnv, Ffv,
                  Mv, z, z, wk)
        if p <= 0.0:
            continue
        for e in range(2):
            R = R_old[c + e]
            for i in range(3):
                out[c, _E3 + i] += 0.5 * af * (
                    R[0, i] * (Fnv[0] + Ffv[0]) + R[1, i] * (Fnv[1] + Ffv[1])
                    + R[2, i] * (Fnv[2] + Ffv[2]))
                out[c, _E4 + i] += 0.5 * af * (R[0, i] * Mv[0] + R[1, i] * Mv[1]
                                               + R[2, i] * Mv[2])


@numba.njit(cache=True)
def seabed_cells(r, vg, Rm, omega, data, F, M, pen):
    """The seabed's force F = normal reaction + friction and moment M per unit length on
    each cell (N, 3) (N/m, N m/m, global: the law at the cell's midpoint, module
    docstring) and the midpoint's surface penetration pen (N,) m (negative: the gap), for
    node positions r, velocities ṙ (N+1, 3), frames Rm (N+1, 3, 3) and body angular
    velocities omega (N+1, 3). Fills F[:, 0:3] with the normal reaction and F[:, 3:6]
    with the friction (F (N, 6))."""
    x = np.empty(3)
    u = np.empty(3)
    Om = np.empty(3)
    t = np.empty(3)
    a = np.empty(3)
    b = np.empty(3)
    c = np.empty(3)
    z = np.zeros((3, 12))
    wk = np.zeros((9, 3, 12))
    for k in range(r.shape[0] - 1):
        rho = _midpoint(r, vg, Rm, omega, data.radius, k, x, u, Om, t)
        pen[k] = _node(x, u, Om, t, rho, data, not true_at_run_time(x), z, z, z, z, a, b,
                       c, z, z, wk)
        for i in range(3):
            F[k, i] = a[i]
            F[k, 3 + i] = b[i]
            M[k, i] = c[i]


@numba.njit(cache=True)
def seabed_points(x, u, Om, t, radius, data, want, hold, modes, F, M, DF, DM, pen, laws):
    """The seabed's law (:func:`_node`, module docstring) at m points of the centreline:
    the normal reaction F[:, 0:3] and the friction F[:, 3:6] (F (m, 6), N/m) and the
    moment M (m, 3) N m/m per unit length, global, from the positions x, velocities u, global angular velocities Om and
    unit tangents t (m, 3) and the radii (m,) m; pen (m,) m the surface penetrations
    (negative: the gap). With ``want`` also the law's exact partials (m, 3, 12) DF =
    ∂(normal + friction)/∂(x, u, Om, t) and DM = ∂M/∂(x, u, Om, t), by the forward propagation of
    :func:`_law` (zero where a point does not touch). The damper's branch of point k is
    modes[k] (m,): −1 the law's clamp, 0, 1, 2 a branch held (N = 0, the free
    kp − c n·ṙ, 2kp; :func:`_law`); laws (m,) receives the law's own branch at each
    touching point (−1 where it does not touch). Points higher than the bottom's top
    plus their radius times the steepest slope factor are skipped (zero load). A point
    with hold[k] True that does not touch (p ≤ 0) takes the spring's line on,
    F = k p n (pulling, no damper or friction; DF = −k n nᵀ on x, the tangent
    plane's): the contact set a Newton solve holds
    (:meth:`solver.centreline.CentrelineRod.solve`)."""
    E = _unit_seeds()
    wk = np.zeros((9, 3, 12))
    fn = np.empty(3)
    ff = np.empty(3)
    mm = np.empty(3)
    dF = np.zeros((3, 12))
    dM = np.zeros((3, 12))
    scal = data.scalars
    lim, slope = scal[8], scal[9]
    # the rule off, typed as a run-time value (the branch held or the clamp: modes)
    yes = true_at_run_time(x)
    for k in range(x.shape[0]):
        for i in range(3):
            F[k, i] = 0.0
            F[k, 3 + i] = 0.0
            M[k, i] = 0.0
            for j in range(12):
                DF[k, i, j] = 0.0
                DM[k, i, j] = 0.0
        laws[k] = -1.0
        if x[k, 2] - slope * radius[k] > lim and not hold[k]:
            h, hx, hy, _ = _bottom(x[k, 0], x[k, 1], data)
            pen[k] = radius[k] - (x[k, 2] - h) / math.sqrt(1.0 + hx * hx + hy * hy)
            continue
        p, _, law = _law(x[k], u[k], Om[k], t[k], radius[k], data, want, E[0], E[1], E[2],
                         E[3], fn, ff, mm, dF, dM, wk, int(modes[k]), not yes)
        pen[k] = p
        if p > 0.0:
            laws[k] = law
        if pen[k] <= 0.0:
            if hold[k]:
                h, hx, hy, _ = _bottom(x[k, 0], x[k, 1], data)
                sq = math.sqrt(1.0 + hx * hx + hy * hy)
                nv = (-hx / sq, -hy / sq, 1.0 / sq)
                for i in range(3):
                    F[k, i] = scal[2] * pen[k] * nv[i]
                    if want:
                        for j in range(3):
                            DF[k, i, j] = -scal[2] * nv[i] * nv[j]
            continue
        for i in range(3):
            F[k, i] = fn[i]
            F[k, 3 + i] = ff[i]
            M[k, i] = mm[i]
            if want:
                for j in range(12):
                    DF[k, i, j] = dF[i, j]
                    DM[k, i, j] = dM[i, j]


@numba.njit(cache=True)
def node_penetration(r, data, pen):
    """The surface penetration ρ − d (m, negative: the gap) of each node's centreline r
    (N+1, 3) into pen (N+1,) (module docstring; d the distance to the bottom's tangent
    plane under the node)."""
    radius = data.radius
    for k in range(r.shape[0]):
        h, hx, hy, _ = _bottom(r[k, 0], r[k, 1], data)
        pen[k] = radius[k] - (r[k, 2] - h) / math.sqrt(1.0 + hx * hx + hy * hy)


def to_nodes(cell_values):
    """Per-cell values (N, ...) per unit length as node values (N+1, ...): the mean of
    a node's two cells, an end node's own cell's. With the trapezoid weights (Δs/2 at the
    ends, Δs inside) their integral is the cells' Σ Δs·value, and their power with the
    node velocities the cells' with the midpoint velocities (both exactly)."""
    c = np.asarray(cell_values, float)
    out = np.empty((c.shape[0] + 1,) + c.shape[1:])
    out[0], out[-1] = c[0], c[-1]
    out[1:-1] = 0.5 * (c[:-1] + c[1:])
    return out


#: the gap, as a fraction of the diameter, that a node between two touching nodes may
#: hover above the bottom and still count as lying on it: the box rule's odd-even mode
#: zig-zags the node heights of a cable lying on the bottom by up to ~0.15 mm while the
#: cells carry it (docs/seabed.md, "Per cell")
CONTACT_GAP = 0.025


def hover_gap(diameter):
    """The gap (N+1,) m a hovering node may bridge and still count as lying on the bottom
    (:func:`contact_length`): CONTACT_GAP times the diameter
    profile (N+1,) m."""
    return CONTACT_GAP * np.asarray(diameter, float)


def contact_length(pen, s, gap=0.0) -> float:
    """Length of rod on the bottom, m, from the surface penetration pen (N+1,) m, linear
    in each cell of the grid s (N+1,) m: the arclength where pen > 0, where each run of
    nodes hovering less than gap ((N+1,) or scalar m, :func:`hover_gap`) above the
    bottom between two touching nodes counts as touching. A contact's ends are the zeros
    of pen, so the touchdown (:func:`touchdown`) is where this length ends."""
    pen, s = np.asarray(pen, float), np.asarray(s, float)
    on = pen > 0
    near = pen > -np.broadcast_to(np.asarray(gap, float), pen.shape)
    # a node bridges when the nearest non-near node on each side lies beyond a touching one
    idx = np.arange(pen.size)
    last_on = np.maximum.accumulate(np.where(on, idx, -1))
    last_far = np.maximum.accumulate(np.where(~near, idx, -1))
    next_on = np.minimum.accumulate(np.where(on, idx, pen.size)[::-1])[::-1]
    next_far = np.minimum.accumulate(np.where(~near, idx, pen.size)[::-1])[::-1]
    bridged = near & ~on & (last_on > last_far) & (next_on < next_far)
    pen = np.where(bridged, 1.0, pen)
    a, b, ds = pen[:-1], pen[1:], np.diff(s)
    both = (a > 0) & (b > 0)
    one = (a > 0) != (b > 0)
    share = np.where(one, np.maximum(a, b) / np.where(one, np.abs(a - b), 1.0), 0.0)
    return float(np.sum(ds * both) + np.sum(ds * share))


def touchdown(pen, s) -> float:
    """The touchdown point's arclength, m: with i0, i1 the first and last node whose
    surface penetration pen (N+1,) m is positive, the zero of pen (linear in its cell)
    between the contact and the longer of the two free spans, after i1 or before i0
    (a lifted end node does not count as the suspended span); NaN when no node or every
    node touches."""
    pen, s = np.asarray(pen, float), np.asarray(s, float)
    on = np.flatnonzero(pen > 0)
    if on.size == 0 or on.size == pen.size:
        return math.nan
    i0, i1 = int(on[0]), int(on[-1])
    if pen.size - 1 - i1 >= i0:
        j = i1                                  # the cell (i1, i1 + 1)
    else:
        j = i0 - 1                              # the cell (i0 − 1, i0)
    a, b = pen[j], pen[j + 1]
    return float(s[j] + (s[j + 1] - s[j]) * a / (a - b))
