"""Step control in one place: where steps must land, how a step restarts after a jump,
the local error of a step, the PI controller of Δt and the growth guard.

:class:`solver.stepping.control.StepControl` drives the steps by these rules (sizes,
levels, landing on stops, restarts, refusals), :class:`solver.stepping.guard.GrowthGuard`
keeps what the growth guard has learnt; a step itself is tried by
:meth:`solver.run.RodRun.try_step`.

* **Breakpoints** (:func:`breakpoints`): the times at which the case changes (a
  distributed force switched on or off, a boundary condition's ``until``, the knots of
  a boundary table). Steps land on them exactly; the step that ends on one sees the
  loads' left limit, and the next step starts with a *consistent restart*.
* **Consistent restart** (:data:`RESTART_FRACTION`, :data:`RESTART_STEPS`): at t = 0
  and after every breakpoint two backward-Euler steps of ε = RESTART_FRACTION·Δt. A BE
  step satisfies the equations at its new level, so it leaves the internal force f (an
  algebraic variable of the DAE) and Ẏ consistent with the loads and conditions now in
  force; its local error is O(ε²). Without it the generalized-α scheme starts from an
  inconsistent f and Ẏ and loses an order (Arnold & Brüls, Multibody Syst. Dyn. 18
  (2007) 185-202, §3; measured in docs/numerics.md § 7). Where the velocities jump (a
  sliding end held, a prescribed velocity different from the present one) the first
  BE step takes the jump: its f carries the impulse, ~ρA L Δv/ε, and its Ẏ = Δv/ε; the
  next generalized-α step weights both into its old level, and the end force rang at
  ±ρA L Δv/ε, undamped at ρ∞ = 1 (a rod stopped at 0.21 m/s: ±2e4 N against its static
  0.5 N; the seed case's held end at 30 s: ±143 N). The second BE step starts after the
  jump and leaves f and Ẏ those of the new state.
* **Local error** (:class:`ErrorControl`): Milne's device. A polynomial predictor
  through the last three accepted levels (two: linear, conservative) has error
  Y'''·Π/6 (Π the product of the distances to its nodes); the generalized-α corrector
  has error C(ρ∞)·h³·Y''' (C = 1/12 at ρ∞ = 1, :func:`error_constant`). Their difference
  therefore gives the corrector's local error as (Y_c − Y_p)·C h³/(C h³ + Π/6), after
  the stiff filter J⁻¹(c M_b ·) (:meth:`solver.newton.NewtonSolver.filtered`) has removed the
  components that the scheme damps and need not be resolved
  (Hairer, Nørsett & Wanner, *Solving ODEs I*, § III.7; the Newmark analogue is
  Zienkiewicz & Xie, Earthquake Eng. Struct. Dyn. 20 (1991) 871-887). The first step
  after a restart has no predictor: it is measured by step doubling (one step h against
  two of h/2, :meth:`ErrorControl.doubling_error`; the same book, § II.4). The norm
  takes the lateral (a1, a2) and axial (a3) parts of v, ω and κ as separate groups and
  weights each wavelength along the rod by the displacement it carries
  (:class:`DisplacementWeight`), so that the grid's shortest waves, excited by every
  sudden load, are not followed at tight tolerances.
* **Local error of the centreline scheme** (:class:`DisplacementErrorControl`): its
  positions and frames are unknowns, so the estimate is the displacements' own,
  C(ρ∞)·h²·(a_{n+1} − a_n) from generalized-α's algebraic accelerations (the Newmark
  estimator of Zienkiewicz & Xie with generalized-α's constant), no predictor and no
  step doubling; the displacement weight on the frames' turns only.
* **PI controller**: h_{n+1} = h_n·0.9·(1/e_n)^{0.3/k}·(e_{n−1}/e_n)^{0.4/k}, k = 3
  (Gustafsson, ACM TOMS 17 (1991) 533-554; Söderlind, ACM TOMS 29 (2003) 1-26), with
  the elementary controller h_n·(θ/e_n)^{1/k} (θ its steady ratio 0.9¹⁰) while the
  error stays far below the target (:meth:`ErrorControl.accepted`).
* **Growth guard** (:func:`growth_rate`): the largest real part σ of the linearised
  dynamics' eigenvalues near the step's scale, by shift-invert Arnoldi on the converged
  step's Jacobian; a step with σΔt above ``numerics.growth_guard`` would suppress a
  growing mode (generalized-α with ρ∞ < 1 damps σΔt ≳ 2 to an amplification near 1) and
  is refused.
"""
from __future__ import annotations

import functools
import math

import numba
import numpy as np

from ..banded import NV, block_solve
from ..scheme import _apply_M_kernel

__all__ = ["breakpoints", "RESTART_FRACTION", "RESTART_STEPS", "extrapolate",
           "kappa_distance", "ErrorControl", "PIController", "DisplacementWeight",
           "error_constant", "growth_rate", "hermite", "DisplacementErrorControl",
           "landing_step", "floored_step"]

#: size of the backward-Euler restart step, as a fraction of the nominal Δt
RESTART_FRACTION = 1e-4

#: backward-Euler steps of ε in a restart: the first absorbs a jump of the velocities
#: (a sliding end held, a prescribed velocity that differs from the current one), whose
#: impulse it leaves in its f and its Ẏ = Δv/ε; the second starts from the state after
#: the jump and leaves f and Ẏ consistent with it (module docstring)
RESTART_STEPS = 2


#: a table knot is a breakpoint when its slope changes by more than this fraction of
#: the table's steepest slope
KINK_FRACTION = 0.05


def _table_kinks(t, value) -> list:
    """Knots of a piecewise-linear table, held constant outside, at which the slope
    changes by more than KINK_FRACTION of the steepest slope."""
    t = np.asarray(t, float)
    v = np.asarray(value, float)
    slopes = np.concatenate([[0.0], np.diff(v) / np.diff(t), [0.0]])
    steepest = float(np.max(np.abs(slopes)))
    if steepest == 0.0:
        return []
    change = np.abs(np.diff(slopes))
    return [float(x) for x in t[change > KINK_FRACTION * steepest]]


def breakpoints(case, kinks: bool = True) -> np.ndarray:
    """Times (s) in (0, t_end) at which the case's loads or boundary conditions change;
    ``kinks=False``: only where they jump (no table's kinks).

    Collected: ``start`` and ``end`` of every distributed force and point load with a
    non-zero value (unless its ``factor`` table is 0 there: no jump) and the kinks of
    that table;
    ``until`` of every boundary condition; the kinks of every boundary table (held
    constant outside its knots) whose slope change exceeds KINK_FRACTION of the table's
    steepest slope: the corners of a ramp are breakpoints, the knots of a finely sampled
    smooth curve are not (a kink not landed on costs O(Δslope·Δt²) once, which keeps
    second order; a jump costs O(Δt)). Returns a sorted array of unique times in
    (0, t_end) (1e-12 relative).
    """
    t_end = float(case.numerics.t_end)
    times = []
    for df in case.distributed_forces:
        if not np.any(np.asarray(df.value, float) != 0):
            continue
        # a switch (start/end) is a jump unless the factor is 0 on that side of it
        if df.scale_at(df.start) != 0.0:
            times.append(float(df.start))
        if df.end is not None and df.scale_at(df.end) != 0.0:
            times.append(float(df.end))
        if df.factor is not None and kinks:
            times.extend(_table_kinks(df.factor.t, df.factor.value))
    for load in case.point_loads:
        if not np.any(np.asarray(load.value, float) != 0):
            continue
        if load.scale_at(load.start) != 0.0:
            times.append(float(load.start))
        if load.end is not None and load.scale_at(load.end) != 0.0:
            times.append(float(load.end))
        if load.factor is not None and kinks:
            times.extend(_table_kinks(load.factor.t, load.factor.value))
    for end in (case.boundary.start, case.boundary.end):
        for group in (end.translation, end.rotation):
            for conditions in group:
                for cond in conditions:
                    if cond.until is not None:
                        times.append(float(cond.until))
                    value = cond.value
                    if hasattr(value, "t") and kinks:
                        times.extend(_table_kinks(value.t, value.value))
    times = sorted(t for t in times if 0.0 < t < t_end * (1.0 - 1e-12))
    out = []
    for t in times:
        if not out or t > out[-1] * (1.0 + 1e-12) + 1e-300:
            out.append(t)
    return np.asarray(out, float)


def extrapolate(times, values, t_new: float):
    """The polynomial through two or three levels evaluated at t_new (s): the line
    through (times[0], values[0]) and (times[1], values[1]), or the parabola through
    three (Newton's divided differences, unequal spacing). times: 2 or 3 distinct floats
    (s); values: as many arrays of one shape; returns an array of that shape. The
    predictor of the error estimate (:meth:`ErrorControl.predict`) and the Newton start
    (``ProblemAssembly._predictions``). Raises ValueError for another number of levels."""
    if len(times) not in (2, 3):
        raise ValueError(f"extrapolate: 2 or 3 levels, got {len(times)}")
    if _flat_floats(values):
        # one compiled pass, the same operations in the same order as below (a Newton
        # start of every step: ~10 array expressions of small arrays cost more in calls
        # than in arithmetic)
        out = np.empty_like(values[0])
        if len(times) == 2:
            _line_into(values[0].reshape(-1), values[1].reshape(-1), float(times[0]),
                       float(times[1]), float(t_new), out.reshape(-1))
        else:
            _parabola_into(values[0].reshape(-1), values[1].reshape(-1),
                           values[2].reshape(-1), float(times[0]), float(times[1]),
                           float(times[2]), float(t_new), out.reshape(-1))
        return out
    if len(times) == 2:
        (t0, t1), (y0, y1) = times, values
        return y1 + ((t_new - t1) / (t1 - t0)) * (y1 - y0)
    (z0, z1, z2), (y0, y1, y2) = times, values
    d01 = (y1 - y0) / (z1 - z0)
    d12 = (y2 - y1) / (z2 - z1)
    second = (d12 - d01) / (z2 - z0)
    w0, w1 = t_new - z0, t_new - z1
    return y0 + d01 * w0 + second * w0 * w1


@numba.njit(cache=True)
def kappa_distance(Y, G) -> float:
    """Σ_k |κ_k(Y) − κ_k(G)|² (1/m², summed over the nodes) between two states Y, G
    (N+1, 12) (κ their columns 9-11): how near a Newton start G put the curvature of the
    accepted level Y (``ProblemAssembly._better_predictor``). One compiled pass. Raises
    nothing: G must have Y's shape (not checked; the caller's levels share it)."""
    acc = 0.0
    for k in range(Y.shape[0]):
        for i in range(9, 12):
            d = Y[k, i] - G[k, i]
            acc += d * d
    return acc


def _flat_floats(values) -> bool:
    """Whether the levels are C-contiguous float64 arrays of one shape."""
    shape = values[0].shape if type(values[0]) is np.ndarray else None
    for y in values:
        if (type(y) is not np.ndarray or y.dtype != np.float64 or y.shape != shape
                or not y.flags.c_contiguous):
            return False
    return True


@numba.njit(cache=True)
def _line_into(y0, y1, t0, t1, t_new, out):
    """:func:`extrapolate` through two levels, flat float arrays, into out."""
    c = (t_new - t1) / (t1 - t0)
    for i in range(out.size):
        out[i] = y1[i] + c * (y1[i] - y0[i])


@numba.njit(cache=True)
def _parabola_into(y0, y1, y2, z0, z1, z2, t_new, out):
    """:func:`extrapolate` through three levels, flat float arrays, into out."""
    w0, w1 = t_new - z0, t_new - z1
    for i in range(out.size):
        d01 = (y1[i] - y0[i]) / (z1 - z0)
        d12 = (y2[i] - y1[i]) / (z2 - z1)
        second = (d12 - d01) / (z2 - z0)
        out[i] = y0[i] + d01 * w0 + second * w0 * w1


# --------------------------------------------------------------------------- dense output
def hermite(s: float, h: float, a, da, b, db):
    """Cubic Hermite interpolant at the fraction s ∈ [0, 1] of a step of h (s) between
    values a, b with time derivatives da, db (arrays of one shape, or floats): the dense
    output of an error-controlled step (Hairer, Nørsett & Wanner I, § II.6). The scheme's
    Ẏ approximates Y' only to first order at its level when ρ∞ < 1 (the α-levels shift
    it by about (αm − αf)h; second order at ρ∞ = 1), so with it the interpolant's error is
    O(h²), the order of the global error the tolerance controls. Measured on the swung
    cantilever (ρ∞ = 0.5): the interpolated positions lie within 1-3× the tolerance of a
    fine run; a quadratic through the last three accepted levels instead (no Ẏ) gave the
    same errors to 10 % (tried, not kept)."""
    s2, s3 = s * s, s * s * s
    return ((2.0 * s3 - 3.0 * s2 + 1.0) * a + (s3 - 2.0 * s2 + s) * h * da
            + (3.0 * s2 - 2.0 * s3) * b + (s3 - s2) * h * db)


# --------------------------------------------------------------------------- growth guard
def growth_rate(system, Y, shift: float, layout, v0=None):
    """Largest real part σ (1/s) among the eigenvalues of the step's linearised dynamics
    nearest the shift, with its eigenvector (for a warm start), or (−inf, None) when no
    eigenvalue lies in the right half-plane disc |σ − shift| < shift.

    The linearised semi-discrete dynamics of the box scheme, M_b Ẏ + A_b Y = 0 (M_b the
    cell-averaged inertia, A_b the flux differences and ⟨∂F/∂Y⟩), has growth modes
    A_b y = −σ M_b y. The converged step's Jacobian is J(c) = c M_b + (1 − αf) A_b with
    c = (1 − αm)/(γΔt); at c_s = (1 − αf)·shift it is singular exactly when σ = shift. The
    eigenvalues μ of T = J(c_s)⁻¹ M_b give σ = shift − 1/((1 − αf) μ); those nearest the
    shift have the largest |μ|, found by ARPACK's implicitly restarted Arnoldi
    (scipy.sparse.linalg.eigs; Lehoucq, Sorensen & Yang 1998) on T in the scaled
    coordinates of the Jacobian's LU (one factorisation, a few tens of solves). Every
    eigenvalue with Re σ > 0 and |σ − shift| < shift has |μ|(1 − αf) > 1/shift, larger
    than that of any oscillatory or damped mode.

    Parameters
    ----------
    system : solver.scheme.RodSystem with the step set up (``begin_step``)
    Y : (N+1, 12) the converged new level
    shift : float, 1/s (> 0)
    layout : solver.banded.BlockLU used as the workspace (not Newton's)
    v0 : (12(N+1),) start vector or None

    Returns
    -------
    (sigma, vector): σ in 1/s (−inf when none is found), the scaled eigenvector.

    Orientation-dependent loads enter A_b through the step's rotation increment (their
    ½Δt factor is kept), so a gravity-driven growth (an inverted pendulum) is estimated
    only roughly.
    """
    from scipy.sparse.linalg import ArpackNoConvergence, eigs

    from ..banded import BandFactorError
    from ..newton import equilibrate, scale_blocks

    af = system.step.params.alpha_f
    _, _, blocks, _ = system.residual(Y, want_jacobian=True)
    blocks = blocks.copy()
    system.add_inertia(blocks, (1.0 - af) * shift - system.step.cm)
    rs, s12 = equilibrate(system, Y, blocks)
    scaled, bc_scaled = scale_blocks(system, blocks, rs, s12)
    bc_rows, bc_cols, _ = system.step.bc.jacobian_entries()
    try:
        layout.factor(scaled, bc_rows, bc_cols, bc_scaled)
    except BandFactorError:
        return -math.inf, None
    n = system.n
    op = _shift_invert_operator(system, rs, np.tile(s12, system.n_nodes), layout)
    if v0 is None:
        # a fixed start: the same run gives the same steps
        v0 = np.random.default_rng(0).standard_normal(n)
    try:
        # a pair of modes (circular sections buckle in two planes) and one more, to 1e-2:
        # the guard needs σ's size, not its digits. A mode with σ in (g/h, 3g/h) has |μ|
        # at least twice that of every slow mode (they cluster near 1/shift) and converges
        # in a few restarts; when nothing converges in 5, nothing stands out of the cluster
        # (more restarts cost 150 ms per check at N = 1000, Δt = 3 ms, and found nothing)
        mu, vec = eigs(op, k=3, which="LM", ncv=12, tol=1e-2, maxiter=5, v0=v0)
    except ArpackNoConvergence as exc:
        mu, vec = exc.eigenvalues, exc.eigenvectors
    if mu is None or len(mu) == 0:
        return -math.inf, None
    mu = np.asarray(mu)
    big = np.abs(mu) * (1.0 - af) > 1.0 / shift * (1.0 + 1e-6)
    if not np.any(big):
        return -math.inf, np.real(vec[:, 0])
    sigma = shift - 1.0 / ((1.0 - af) * mu[big])
    j = int(np.argmax(sigma.real))
    return float(sigma.real[j]), np.real(vec[:, np.flatnonzero(big)[j]])


def _shift_invert_operator(system, rs, cs, layout):
    """The operator T z = J(c_s)⁻¹ rs ⟨M (z·cs)⟩ of :func:`growth_rate` (rs, cs (n,) the
    row and column scales; layout the factored :class:`solver.banded.BlockLU`), a
    LinearOperator for ARPACK."""
    from scipy.sparse.linalg import LinearOperator

    n, p = system.n, system.p
    e, Me = np.empty((system.n_nodes, NV)), np.empty((system.n_nodes, NV))

    def apply(z):
        # RodSystem.cell_inertia and BlockLU.solve in one compiled pass (the same
        # operations; ARPACK calls it tens of times)
        x = np.empty(n)
        _shift_invert_apply(np.ascontiguousarray(np.real(z), dtype=float), cs, rs,
                            p.mass_t, p.inertia, layout.lu, e, Me, x)
        return x

    op = LinearOperator((n, n), matvec=apply, dtype=float)
    # ARPACK's reverse communication calls op.matvec with (n,) float vectors only: the
    # function itself, without LinearOperator's shape checks around every call
    op.matvec = apply
    return op


@numba.njit(cache=True)
def _shift_invert_apply(z, cs, rs, mass_t, inertia, lu, e, Me, x):
    """x = J(c_s)⁻¹ rs ⟨M (z·cs)⟩ of :func:`growth_rate`: z, cs, rs, x (n,); e, Me
    (N+1, 12) scratch; lu a :class:`solver.banded.BlockLU`'s factor. The operations of
    ``layout.solve(rs * system.cell_inertia((z * cs).reshape(N+1, 12)))``, in order."""
    n1, nv = e.shape
    for k in range(n1):
        for j in range(nv):
            e[k, j] = z[nv * k + j] * cs[nv * k + j]
    _apply_M_kernel(e, mass_t, inertia, Me)
    for i in range(6):
        x[i] = rs[i] * 0.0
    for k in range(n1 - 1):
        for j in range(nv):
            i = 6 + nv * k + j
            x[i] = rs[i] * (0.5 * (Me[k, j] + Me[k + 1, j]))
    for i in range(6 + nv * (n1 - 1), x.size):
        x[i] = rs[i] * 0.0
    block_solve(lu, x)


# --------------------------------------------------------------------------- local error
def error_constant(rho_inf: float) -> float:
    """Error constant C of the generalized-α scheme (first-order form, weights on the old
    level): the principal root of its amplification for y' = λy is exp(z + C z³ + O(z⁴)),
    z = λΔt, so the local error of a step is C Δt³ Y''' (C > 0).

    C(ρ∞) = 1/12 + ¼((1 − ρ∞)/(1 + ρ∞))²: 1/12 for the trapezoidal rule (ρ∞ = 1), 1/9 at
    ρ∞ = 0.5, 1/3 at ρ∞ = 0 (fitted to the principal root computed from the scheme's
    amplification matrix at z = 0.01 and 0.02 for ρ∞ = 0, ¼, ½, ¾, 1: agreement to 0.3 %).
    """
    r = (1.0 - rho_inf) / (1.0 + rho_inf)
    return 1.0 / 12.0 + 0.25 * r * r


class DisplacementWeight:
    """The spatial weighting of the error norm: the Helmholtz smoother
    u = (1 − ℓ²∂²ₛ)⁻¹ e on the nodes, zero-flux ends, ℓ = L/π.

    Why: the estimate measures the velocity-level fields v, ω, κ. A Fourier component
    of wavenumber k along the rod is a bending wave of frequency ω_k ∝ k², so the same
    velocity (or curvature) error in it moves the centreline by ∝ 1/k². A norm of the
    raw fields therefore weights the shortest waves of the grid most, and those are
    exactly the ones a sudden load excites and an undamped scheme (ρ∞ = 1) keeps: the
    Greenhill benchmark took 2,698 steps at tolerance 1e-3 following them, and every
    problem ran away below 1e-3 (9,766 steps at 1e-4 on the vibration, stopped). The
    smoother passes components longer than the rod (k ≲ π/L: rigid motion, the first
    modes) nearly unchanged and divides shorter ones by 1 + (kℓ)² ≈ (kL/π)², the
    displacement weighting of bending waves (the Newmark estimators of Zienkiewicz &
    Xie, Earthquake Eng. Struct. Dyn. 20 (1991) 871-887, measure displacements for the
    same reason; positions are not unknowns here). Both the error and the field sizes it
    is measured against are smoothed, so an error of the motion's own wavelength counts
    as before. Measured in docs/numerics.md § 7.

    Discretisation: finite volumes on the nodes s (N+1,) (control lengths w_j, half
    cells at the ends): w_j u_j − ℓ²[(u_{j+1} − u_j)/h_j − (u_j − u_{j−1})/h_{j−1}] =
    w_j e_j, a symmetric positive definite tridiagonal system, factorised once (LAPACK
    ``dpttrf``, L D Lᵀ) and solved per call (``dpttrs``); constants pass exactly.
    Calling the object on e (N+1, m) returns u (N+1, m). Parameters: s (N+1,) node
    arclengths, m, increasing; length_factor: ℓ in units of L/π. Raises ArithmeticError
    if the factorisation fails (it cannot for increasing s: the matrix is diagonally
    dominant).
    """

    def __init__(self, s, length_factor: float = 1.0):
        from scipy.linalg import lapack

        s = np.asarray(s, float)
        h = np.diff(s)
        self.w = np.zeros(s.size)
        self.w[:-1] += 0.5 * h
        self.w[1:] += 0.5 * h
        ell = length_factor * (s[-1] - s[0]) / math.pi
        k = ell**2 / h
        diag = self.w.copy()
        diag[:-1] += k
        diag[1:] += k
        self.d, self.e, info = lapack.dpttrf(diag, -k)
        if info != 0:  # pragma: no cover - the matrix is diagonally dominant
            raise ArithmeticError(f"dpttrf failed (info {info})")

    def __call__(self, e: np.ndarray) -> np.ndarray:
        from scipy.linalg import lapack

        u, info = lapack.dpttrs(self.d, self.e, self.w[:, None] * e)
        if info != 0:  # pragma: no cover
            raise ValueError(f"dpttrs argument {-info} invalid")
        return u


@functools.cache
def _group_bounds(groups: tuple, n_cols: int) -> tuple:
    """``reduceat`` indices over the (start, stop) column ranges ``groups`` (increasing,
    disjoint) of an array with n_cols columns, and which of the sums are the groups' (the
    gaps between groups are summed too and dropped). Computed once per groups."""
    bounds, keep = [], []
    for a, b in groups:
        if not bounds or bounds[-1] != a:
            bounds.append(a)
        keep.append(len(bounds) - 1)
        bounds.append(b)
    if bounds[-1] >= n_cols:
        bounds.pop()
    return np.array(bounds), np.array(keep)


def _group_sq(X: np.ndarray, groups: tuple) -> np.ndarray:
    """Squared Euclidean norm of each group's columns at every node: (N+1, len(groups)).
    groups: (start, stop) column ranges, increasing and disjoint (a tuple); one
    ``reduceat`` over their bounds (:func:`_group_bounds`)."""
    bounds, keep = _group_bounds(groups, X.shape[1])
    return np.add.reduceat(X * X, bounds, axis=1)[:, keep]


class PIController:
    """The step-size controller of error-controlled steps: Δt from the ratio of a step's
    local error estimate to its tolerance (accept when ≤ 1).

    Used by :class:`ErrorControl` (``numerics.tolerance``) and, with fixed steps, by the
    steps where strands may meet, whose error ratio is the route rule's
    (docs/contact.md § 3). Holds only the controller's memory (the last ratio, whether
    the last two were low); the constants are class attributes. Sources: Gustafsson,
    ACM TOMS 17 (1991) 533-554; Söderlind, ACM TOMS 29 (2003) 1-26.
    """

    ORDER = 3                            # the local error is O(h³)
    SAFETY = 0.9
    MAX_GROWTH = 5.0
    MAX_SHRINK = 0.2
    #: below this observed order a refused step is cut by MAX_SHRINK (:meth:`rejected`)
    MIN_ORDER = 1.0
    #: steady error ratio of the PI controller: 0.9¹⁰, that of the classic
    #: SAFETY·e^(−0.7/k)·e_prev^(0.4/k) form (SAFETY^(k/0.3), k = 3)
    TARGET = SAFETY ** 10
    #: below this fraction of TARGET at two accepted steps in a row, the elementary
    #: controller grows the step (at most ×FAST_MAX per step)
    FAST_BELOW = 0.5
    FAST_MAX = 2.0

    def __init__(self):
        self.err_prev = None
        #: whether the last accepted step's ratio was below FAST_BELOW·TARGET
        self.low_prev = False

    def forget(self) -> None:
        """Drop the controller's memory (a restart, or the start of a run of steps)."""
        self.err_prev = None
        self.low_prev = False

    def accepted(self, h: float, err: float) -> float:
        """Next step size after an accepted step of h (s) with error ratio err.

        Near the target (the usual case): Gustafsson's PI controller
        h·(θ/e)^(0.7/k)·(e_prev/θ)^(0.4/k), k = 3, θ = TARGET = 0.9¹⁰ (identical to the
        form h·0.9·e^(−0.7/k)·e_prev^(0.4/k), whose steady error ratio is θ; Gustafsson,
        ACM TOMS 17 (1991) 533-554). Its integral gain is small: at a steady error ratio
        e ≪ θ it grows the step by only (θ/e)^(0.1) per step (×1.13 at e = 0.1), so after
        a start from rest or a restart the Greenhill benchmark spent ~30 steps growing at
        e ≈ 0.1. When the error ratio has been below FAST_BELOW·θ at two accepted steps
        in a row (and on the first estimate after a restart) the elementary controller
        h·(θ/e)^(1/k) is used instead, at most ×FAST_MAX, and the history is set to θ so
        that the PI step after it does not read the jump as a rising error. Two in a row,
        not one: the estimate fluctuates by ×3-10 from step to step in the seed's
        pre-buckling phase, and acting on single low values doubled the refused steps.
        Limited to ×[MAX_SHRINK, MAX_GROWTH]; NaN (no estimate) keeps the step."""
        if math.isnan(err):
            return h          # no estimate: keep the step
        k = self.ORDER
        e = max(err, 1e-10)
        th = self.TARGET
        low = e < self.FAST_BELOW * th
        was_low, self.low_prev = self.low_prev, low
        if self.err_prev is None or (low and was_low):
            fac = min((th / e) ** (1.0 / k), self.FAST_MAX)
            self.err_prev = th
        else:
            fac = (th / e) ** (0.7 / k) * (max(self.err_prev, 1e-10) / th) ** (0.4 / k)
            self.err_prev = e
        return h * min(self.MAX_GROWTH, max(self.MAX_SHRINK, fac))

    def rejected(self, h: float, err: float, previous=None) -> float:
        """Step size to retry with after a step of h (s) rejected with error ratio err > 1:
        h·max(MAX_SHRINK, 0.9·err^(−1/p)), p = k = 3, the order of the local error.

        ``previous``: (h, err) of the attempt refused before this one from the same
        state, or None. Then p is the order the two attempts show,
        log(err_prev/err)/log(h_prev/h), at most k, and below MIN_ORDER the step is cut
        by MAX_SHRINK outright. Why: right after a start from rest a relative error does
        not fall as h³ (the fields grow like a power of the elapsed time t, so the error
        relative to them depends on h/t, not h, until h reaches t), and the seed case's
        first step was refused 27 times at ×0.86 each, from 0.1 s down to 1.7e-4 s (81
        Newton solves), with the error ratio at 1.1-2.8 throughout; with the observed
        order 5 times (measured)."""
        p = float(self.ORDER)
        if previous is not None:
            h_prev, err_prev = previous
            if h_prev > h and err_prev > 0.0 and err > 0.0:
                observed = math.log(err_prev / err) / math.log(h_prev / h)
                if observed < self.MIN_ORDER:
                    return h * self.MAX_SHRINK
                p = min(p, observed)
        return h * max(self.MAX_SHRINK, self.SAFETY * err ** (-1.0 / p))


class ErrorControl(PIController):
    """Local error estimate and PI step-size controller for ``numerics.tolerance``.

    Parameters
    ----------
    relative, absolute : float
        Tolerances: a step is accepted when, for each group of the differential fields v,
        ω, κ (:attr:`GROUPS`), the root mean square over nodes of |W e_k| ≤ absolute·u +
        relative·max over nodes of |W Y_k| (|·| the Euclidean norm of the node's vector,
        e its local error estimate, W the displacement weight along the rod, the larger
        of both levels' maxima and of the peak taken), u the field's characteristic size
        (``RodSystem.floor``: L/t_c, 1/t_c, 1/L). The RMS (as in Hairer & Wanner's codes)
        rather than the maximum: a wave front one node wide (an impact's torsional front
        runs at 58 m/s across 1-mm segments of the seed case) would otherwise hold every
        step of the rod to the front's transit time of one segment.
    floor : (12,) characteristic sizes of the unknowns
    rho_inf : float, the scheme's ρ∞ (error constant, :func:`error_constant`)
    s : (N+1,) node arclengths, m, for the displacement weight W
        (:class:`DisplacementWeight`, ℓ = SMOOTHING·L/π); None: no weight (W = 1)

    The predictor, the estimate and the controller are described in the module
    docstring; the error ratio e/tolerance is returned, accept when ≤ 1.
    """

    #: the variables with a time derivative, each of v, ω, κ split into its lateral
    #: (a1, a2: bending and sway) and axial (a3: twist and axial motion) parts, which
    #: differ by orders of magnitude before buckling (the seed example's bending energy
    #: is 1e-12 of its torsional energy for 15 s): measured against the field's whole
    #: size, the lateral error went unseen and a buckling time ran 1-2 % off at every
    #: tolerance (docs/numerics.md § 7)
    GROUPS = ((0, 2), (2, 3), (3, 5), (5, 6), (9, 11), (11, 12))

    #: length ℓ of the displacement weighting in units of L/π (None: no weighting, the
    #: raw fields; kept for measurements)
    SMOOTHING = 1.0

    def __init__(self, relative: float, absolute: float, floor, rho_inf: float, s=None):
        self.smooth = (DisplacementWeight(s, self.SMOOTHING)
                       if s is not None and self.SMOOTHING is not None else None)
        self.rtol = float(relative)
        self.atol = float(absolute)
        self.floor = np.asarray(floor, float)
        self.C = error_constant(rho_inf)
        self.times: list = []
        self.values: list = []
        super().__init__()
        #: the largest norm each group has reached on the rod at an accepted level
        self.peak = np.zeros(len(self.GROUPS))
        self._sized = None

    def reset(self, t: float, Y: np.ndarray) -> None:
        """Forget the history (not the peaks): a (consistent) restart at t with state Y."""
        self.times, self.values = [t], [Y]
        self.forget()
        self.peak = np.maximum(self.peak, self._group_sizes(Y))

    def _group_sizes(self, Y: np.ndarray) -> np.ndarray:
        """Largest norm on the rod of each group of :attr:`GROUPS` in Y (N+1, 12), after
        the displacement weight; the last result is kept for :meth:`push` (the level a
        step has just measured is the one it accepts)."""
        if self._sized is not None and self._sized[0] is Y:
            return self._sized[1]
        W = Y if self.smooth is None else self.smooth(Y)
        sizes = np.sqrt(np.max(_group_sq(W, self.GROUPS), axis=0))
        self._sized = (Y, sizes)
        return sizes

    def push(self, t: float, Y: np.ndarray) -> None:
        """Record an accepted level (the last three are kept)."""
        self.times.append(t)
        self.values.append(Y)
        self.peak = np.maximum(self.peak, self._group_sizes(Y))
        if len(self.times) > 3:
            self.times.pop(0)
            self.values.pop(0)

    def predict(self, t_new: float):
        """Polynomial predictor at t_new through the history: (Y_p (N+1, 12), Π), Π the
        product of t_new's distances to the interpolation nodes, or None with only one
        level (the first step after a restart is not estimated). Three levels: quadratic
        (Lagrange); two: linear, with Π = 6h³ by convention (an O(h²) estimate read as
        the O(h³) one of equal steps: conservative). The restart's Ẏ is not used: the
        short backward-Euler step leaves the grid's stiff modes in it, and an estimate
        built on it asked the vibration benchmark for 1e-5 s first steps."""
        ts, ys = self.times, self.values
        if len(ts) == 1:
            return None
        if len(ts) == 2:
            return extrapolate(ts, ys, t_new), 6.0 * (t_new - ts[1])**3
        z = tuple(ts[-3:])
        return extrapolate(z, ys[-3:], t_new), (t_new - z[0]) * (t_new - z[1]) * (t_new - z[2])

    def ratio(self, t_new: float, Y_new: np.ndarray, Y_old: np.ndarray,
              filter=None) -> float:
        """Error ratio (estimate / tolerance) of the step ending at t_new with Y_new;
        NaN when there is no estimate (the first step after a restart).

        filter: callable (N+1, 12) -> (N+1, 12) applied to the predictor-corrector
        difference before it is measured (:meth:`solver.newton.NewtonSolver.filtered`), or None.
        """
        h = t_new - self.times[-1]
        prediction = self.predict(t_new)
        if prediction is None:
            return math.nan
        Yp, pi = prediction
        ch3 = self.C * h**3
        return self.measure((ch3 / (ch3 + pi / 6.0)) * (Y_new - Yp), Y_new, Y_old, filter)

    def measure(self, error: np.ndarray, Y_new: np.ndarray, Y_old: np.ndarray,
                filter=None) -> float:
        """Error ratio of a local error estimate ``error`` (N+1, 12) of the step from
        Y_old to Y_new (N+1, 12): the largest over :attr:`GROUPS` of the root mean square
        over nodes of the group's error vector against absolute·u + relative·(the group's
        largest norm on the rod at the new level or at any accepted level before, Y_old
        among them (it must have been passed to :meth:`reset` or :meth:`push`): a field
        that falls quiet, the twist rate once the twisting stops, keeps the scale it had,
        so that its residual waves are not chased at the absolute tolerance);
        both after the displacement weight; ``filter`` as in :meth:`ratio`. The arrays
        are not modified, and must not be modified in place afterwards (the sizes of
        Y_new are kept for :meth:`push`)."""
        if filter is not None:
            error = filter(error)
        if self.smooth is not None:
            error = self.smooth(error)
        # the old level is an accepted one, so its sizes are in the peak already
        sizes = np.maximum(self._group_sizes(Y_new), self.peak)
        rms = np.sqrt(np.mean(_group_sq(error, self.GROUPS), axis=0))
        lows = np.array([a for a, _ in self.GROUPS])
        return float(np.max(rms / (self.atol * self.floor[lows] + self.rtol * sizes)))

    @staticmethod
    def doubling_error(Y_full: np.ndarray, Y_halves: np.ndarray) -> np.ndarray:
        """Local error (N+1, 12) of each of two half steps from the difference between
        one step h and the two steps h/2 over the same interval (step doubling; Hairer,
        Nørsett & Wanner I, § II.4): with local errors C·h³·Y‴ and C·(h/2)³·Y‴ each,
        Y_full − Y_halves = ¾·C·h³·Y‴, so one half step's error is (Y_full − Y_halves)/6."""
        return (Y_full - Y_halves) / 6.0

    @property
    def can_estimate(self) -> bool:
        """Whether the next step has a predictor (False right after a restart)."""
        return len(self.times) > 1

    def state(self):
        """The history and the last error ratio, for :meth:`restore`."""
        return (list(self.times), list(self.values), self.err_prev, self.peak.copy(),
                self.low_prev)

    def restore(self, state) -> None:
        """Return to a :meth:`state` (steps taken only to be measured are forgotten)."""
        self.times, self.values, self.err_prev = list(state[0]), list(state[1]), state[2]
        self.peak = state[3].copy()
        self.low_prev = state[4]



def landing_step(h: float, remaining: float) -> tuple[float, bool]:
    """The step to try (s) of a controller's size h (s) with ``remaining`` (s) to the
    next stop, and whether it lands there: the remainder when h reaches it, half of it
    when h would leave less than itself, else h."""
    last = h >= remaining * (1.0 - 1e-9)
    return (remaining if last else (0.5 * remaining if 2.0 * h > remaining else h)), last


def floored_step(h: float, h_try: float, h_min: float):
    """The retry size (s) after a refused attempt of h_try (s) whose next size would be
    h (s), with the floor h_min (s): h where it is not below the floor; h_min where it is
    but the refused attempt was above the floor, so that the smallest step is tried
    before the run is given up; None where the refused attempt was itself at (or,
    landing on a stop, below) the floor. Without the floor's own try a run could end "no
    step down to the smallest is trusted" with the smallest never tried (PyElastica's
    plectoneme, ρ∞ = 0.8, N = 25, Δt = 0.1 s, with Newton's tolerance ×1.1: an energy
    refusal at 80 µs, the next cut 20 µs below the floor of 24 µs, after a step of 40 µs
    had passed; docs/contact.md § 3)."""
    if h >= h_min * (1.0 - 1e-9):
        return h
    if h_try > h_min * (1.0 + 1e-9):
        return h_min
    return None


class DisplacementErrorControl(PIController):
    """Local error estimate and PI step-size controller of ``numerics.tolerance`` on the
    centreline scheme (``numerics.formulation: centreline``), whose positions r and
    frames are unknowns.

    Estimate: generalized-α's displacement update Δ = h X_n + h²((½ − β) a_n + β a_n+1),
    with the algebraic acceleration a tracking Ẍ(t + (α_m − α_f) h) (Chung & Hulbert
    1993), has the local error (β + (α_m − α_f)/2 − 1/6) h³ X⃛ = C(ρ∞) h³ X⃛, the first-order
    form's constant (:func:`error_constant`: 1/12 at ρ∞ = 1, 1/9 at ½, 1/3 at 0), and
    a_n+1 − a_n = h X⃛ + O(h²), so

        e = C(ρ∞) h² (a_n+1 − a_n)                      (N+1, 6): m (global), rad (body)

    (the Newmark estimator of Zienkiewicz & Xie, Earthquake Eng. Struct. Dyn. 20 (1991)
    871-887, with generalized-α's constant). It needs no history: the first step after a
    start or a restart is measured like any other (the restart's a is consistent with
    what is in force after the jump).

    Norm: three groups, the positions (m), the frame's turn about a1, a2 (bending, rad)
    and about a3 (twist, rad); for each the root mean square over nodes of the node's
    error vector against absolute·u + relative·S, u = (L, 1 rad, 1 rad) and S the
    group's largest value at any accepted level so far of the node's displacement
    |r − r(0)| and, for the turns, the larger of the parts of the node's turn from the
    start's frame (the rotation vector of p̄(0) ⊗ p, at most π) and of the bending and
    twist the rod holds, ∫|κ₁,₂| ds and ∫|κ₃| ds: a lateral motion that has not yet
    grown (before a buckling) is measured against its own small size, not against the
    twist, and a twist error against the twist the rod carries (a cable laid with six
    turns holds 38 rad, while its frames turn by tenths of a radian as it lifts off).
    The turns' errors and sizes pass through the displacement weight along the rod
    (:class:`DisplacementWeight`, ℓ = L/π) first: a rod's rotational inertia is small,
    so the frames' algebraic accelerations carry the grid's short torsional and
    bending-rotation waves, which every contact and friction change excites, at sizes
    that move no position (measured on cases/seabed-hockle.yaml's lift-off,
    docs/numerics.md § 9); the positions, which the turns' long waves move, are
    measured as they are. Accept when the largest ratio is ≤ 1.

    Parameters: relative, absolute (dimensionless), length L (m), rho_inf, s (N+1,)
    the node arclengths (m) of the weight. Raises ArithmeticError where the weight's
    factorisation fails (it cannot for increasing s).
    """

    #: (start, stop) columns of the groups in the estimate and the displacements
    GROUPS = ((0, 3), (3, 5), (5, 6))

    def __init__(self, relative: float, absolute: float, length: float, rho_inf: float,
                 s):
        super().__init__()
        self.smooth = DisplacementWeight(s)
        self.rtol = float(relative)
        self.atol = float(absolute)
        self.units = np.array([float(length), 1.0, 1.0])
        self.C = error_constant(rho_inf)
        #: the largest displacement of each group at an accepted level
        self.peak = np.zeros(len(self.GROUPS))
        #: the next step's size (s) and the start's (r (N+1, 3), p (N+1, 4)) the sizes
        #: count from: the run's (:meth:`solver.centreline_run.CentrelineRun.
        #: step_adaptive`)
        self.h_next = math.nan
        self.origin = None

    def estimate(self, h: float, a_old: np.ndarray, a_new: np.ndarray) -> np.ndarray:
        """The local error (N+1, 6) of a step of h (s) whose algebraic accelerations at
        its two levels are a_old and a_new (N+1, 6): C h² (a_new − a_old)."""
        return self.C * h * h * (a_new - a_old)

    def sizes(self, moved: np.ndarray, held) -> np.ndarray:
        """The groups' sizes (3,) at a level: the largest norms on the rod of ``moved``
        (N+1, 6), each node's displacement from the start (m, global) and turn from the
        start's frame (rad, body), the turns through the displacement weight; the turns'
        at least ``held`` (2,), the bending and twist the rod holds, ∫|κ₁,₂| ds and
        ∫|κ₃| ds (rad)."""
        out = np.sqrt(np.max(_group_sq(self._weighted(moved), self.GROUPS), axis=0))
        out[1:] = np.maximum(out[1:], held)
        return out

    def _weighted(self, x: np.ndarray) -> np.ndarray:
        """x (N+1, 6) with its turns (columns 3-5) through the displacement weight."""
        out = x.copy()
        out[:, 3:6] = self.smooth(x[:, 3:6])
        return out

    def ratio(self, error: np.ndarray, sizes: np.ndarray) -> float:
        """The error ratio (estimate / tolerance) of a step's local error ``error``
        (N+1, 6), :meth:`estimate`, with the new level's ``sizes`` (3,) (:meth:`sizes`)."""
        scale = self.atol * self.units + self.rtol * np.maximum(self.peak, sizes)
        rms = np.sqrt(np.mean(_group_sq(self._weighted(error), self.GROUPS), axis=0))
        return float(np.max(rms / scale))

    def push(self, sizes: np.ndarray) -> None:
        """Record an accepted level's ``sizes`` (3,) (:meth:`sizes`) in the peaks."""
        self.peak = np.maximum(self.peak, sizes)
