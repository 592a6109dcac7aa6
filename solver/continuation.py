"""Pseudo-arclength continuation of static equilibria in one scalar parameter.

The branch is followed in the scaled unknowns z = (Y/(c √(N+1)), λ̂), c the typical sizes
of :meth:`solver.statics.StaticProblem.scales` and λ̂ = (λ − λ0)/(λ1 − λ0), so that the
arclength does not depend on units or on N (Keller, "Numerical solution of bifurcation
and nonlinear eigenvalue problems", 1977; Allgower & Georg, *Introduction to Numerical
Continuation Methods*, 2003, ch. 2 and 8). One step: the predictor z + Δs t, then the
corrector on the bordered system

    [ G_z  G_λ̂ ] dz = [ G(z)            ]
    [ tᵀ       ]      [ tᵀ(z − z_pred)  ]

with the exact G_z of :func:`solver.statics.jacobian` and G_λ̂ by a central difference in λ
(exact for the many parameters G is affine in): Newton's first iteration, Broyden's
updates of its factorisation after it, and one Newton step with the matrix factored at
the converged point (:func:`_corrector`). Without self-contact and seabed G_z is a band and
the bordered matrix is solved by block elimination on LAPACK's band LU
(:mod:`solver.static_band`), else by scipy's sparse LU. The new tangent solves the
matrix at the point against (0, 1), which keeps its orientation (t_oldᵀ t_new = 1). Step
control: Δs grows by 1.5 after a step of at most :data:`GROW_ITERATIONS` corrector
iterations, shrinks by 0.7 after more than :data:`SHRINK_ITERATIONS` and halves on a refusal
(no convergence in ``newton_max`` iterations, or a tangent turning by more than
``max_turn`` rad); the last step lands on λ̂ = 1 exactly (a natural-parameter solve).

Test functions along the branch (Allgower & Georg ch. 8; Seydel, *Practical Bifurcation
and Stability Analysis*, 2010, §5.3):

* fold: the λ̂ component of the tangent changes sign;
* simple branch point: the sign of det of the bordered matrix changes (from the LU:
  :func:`solver.statics.lu_det_sign`); the sign does not change at a fold;
* a branch point of even multiplicity (a symmetric pair, e.g. the helical modes of an
  isotropic rod): the number of unstable modes changes with neither of the above.

Each event is located by bisection in the arclength of its step (a corrector solve per
halving, to 1e-9 of the step). At a simple branch point the null vector φ of the bordered
matrix (inverse iteration) is the bifurcating direction: ``switch=True`` leaves the
primary branch there along φ (Keller's branch switching by the tangent of the null
vector) and follows the new branch. At a pair that the rod's rotation about its axis turns
into itself (a round rod) it leaves along one mode of the pair with a phase condition that
fixes the rotation (:func:`_corrector`, :meth:`_Tracer._switch_pair`).

A continuation keeps what it computed: an unexpected exception mid-branch leaves with the
branch so far on it (``exc.partial_branch``), and ``checkpoint`` hands out the state after
every accepted point (the points so far and the step state: z, t, det sign, Δs), from which
``resume=`` continues bit for bit (:class:`solver.checkpoint.BranchCheckpoint` turns it into
bytes).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np
import scipy.sparse as sp

from .simulation import _blas_controller
from .static_band import BandSingular, BorderedBandLU
from .statics import (NV, PIVOT_RTOL, StaticProblem, StaticsError, _count, _qmul, band_jacobian,
                      band_ready, factor, factor_jacobian, jacobian, lu_det_sign, mass_matrix,
                      nearest_eigenvalues, residual, solve, unstable_modes)

__all__ = ["Branch", "Bifurcation", "continuation", "ContinuationError", "range_unrepresentable"]


def range_unrepresentable(p0: StaticProblem, p1: StaticProblem) -> Optional[str]:
    """Why the range from the problem ``p0`` (the parameter's start value) to ``p1`` (its
    target) cannot be followed in double precision, or None.

    The bordered system of every corrector step carries the parameter's column
    G_λ̂ = (∂G/∂λ)·(λ1 − λ0) (:meth:`_Scaled.g_lam`): the change of the problem's loads over
    the whole range, beside the rod's own entries, whose sizes are the rod's units (forces
    EJ/L², distributed loads EJ/L³, positions L, rotations 1, stiffness EJ, curvatures
    1/L). Where that change is more than 1/PIVOT_RTOL = 1e14 of those units, every pivot of the rod's rows is below
    PIVOT_RTOL of the column's and the LU is singular to rounding
    (:func:`solver.statics._check_pivots`), from the first step; a `to` of ±1e308 N made the
    change infinite as well. Only the data the parameter moves are compared (end forces and
    positions, distributed loads, end twist, stiffness, intrinsic curvature)."""
    b = float(np.max(p0.stiffness[:, :2]))
    length = float(p0.length)
    units = {"force": b / length**2, "load": b / length**3, "position": length,
             "twist": 1.0, "stiffness": b, "curvature": 1.0 / length}
    changes = {
        "the end forces": (np.concatenate([p1.start.force - p0.start.force,
                                           p1.end.force - p0.end.force]), "force", "N"),
        "the end positions": (np.concatenate([p1.start.position - p0.start.position,
                                              p1.end.position - p0.end.position]),
                              "position", "m"),
        "the distributed load": (p1.load - p0.load, "load", "N/m"),
        "the end twist": (np.array([p1.start.twist - p0.start.twist,
                                    p1.end.twist - p0.end.twist]), "twist", "rad"),
        "the stiffness": (p1.stiffness - p0.stiffness, "stiffness", "N m²"),
        "the intrinsic curvature": (p1.kappa0 - p0.kappa0, "curvature", "1/m"),
    }
    limit = 1.0 / PIVOT_RTOL
    for name, (delta, unit, si) in changes.items():
        with np.errstate(over="ignore", invalid="ignore"):
            size = float(np.max(np.abs(delta))) if np.size(delta) else 0.0
            scaled = size / units[unit]
        if not scaled <= limit:           # also inf and NaN
            times = f"{scaled:.3g}" if np.isfinite(scaled) else "more than 1.8e308"
            return (f"the range changes {name} by {size:.3g} {si}, {times} times the "
                    f"rod's own scale ({units[unit]:.3g} {si}: EJ = {b:.3g} N m², L = "
                    f"{length:.6g} m); a continuation holds at most {limit:.0e} of it in double "
                    "precision (beyond, the rod's pivots fall below the rounding of the "
                    "parameter's column)")
    return None


#: step control: Δs grows by 1.5 after a step of at most GROW_ITERATIONS corrector
#: iterations and shrinks by 0.7 after more than SHRINK_ITERATIONS (Broyden's iterations
#: from one factorisation, :func:`_corrector`: about 1.5 times Newton's 3 and 5 for the
#: same predictor error, so that a branch gets about as many points as with Newton)
GROW_ITERATIONS = 5
SHRINK_ITERATIONS = 7
#: the corrector refactors at an iterate whose update is not below CONTRACTION times the
#: one before (:func:`_corrector`)
CONTRACTION = 0.5


class ContinuationError(StaticsError):
    """Bad continuation input (a range that does not move, a singular start)."""


@dataclass
class Bifurcation:
    """A located fold or branch point: ``kind`` ("fold" / "branch_point"), the parameter,
    the state Y (N+1, 13), the index of the branch point after which it lies, and for a
    simple branch point the critical direction ``null`` (N+1, 13) in Y units (unit scaled
    norm)."""

    kind: str
    parameter: float
    Y: np.ndarray
    after: int
    null: Optional[np.ndarray] = None
    simple: bool = True


@dataclass
class Branch:
    """The points of a branch, in order: ``parameter`` (λ), ``Y`` (N+1, 13) each,
    ``unstable`` (count of unstable modes, -1 where not computed), ``mu`` (eigenvalue
    nearest zero, 1/s²), ``iterations`` (Newton), the ``bifurcations`` found, the
    ``problems`` of each point, ``switched_at`` (the index after which the branch left a
    branch point, or None) and why it ``stopped``."""

    parameter: list = field(default_factory=list)
    Y: list = field(default_factory=list)
    unstable: list = field(default_factory=list)
    mu: list = field(default_factory=list)
    iterations: list = field(default_factory=list)
    problems: list = field(default_factory=list)
    bifurcations: list = field(default_factory=list)
    switched_at: Optional[int] = None
    stopped: str = ""


class _Scaled:
    """z <-> (Y, λ) and the bordered system of one problem family."""

    def __init__(self, problem_at, lam0, lam1, template: StaticProblem):
        self.problem_at = problem_at
        self.lam0, self.span = float(lam0), float(lam1) - float(lam0)
        self.shape = (template.n_segments + 1, NV)
        self.c = np.tile(template.scales(), self.shape[0]) * np.sqrt(self.shape[0])
        self.n = self.c.size
        self._cache: dict = {}

    def lam(self, z) -> float:
        return self.lam0 + self.span * float(z[-1])

    def prob(self, lam: float) -> StaticProblem:
        p = self._cache.get(lam)
        if p is None:
            if len(self._cache) > 8:
                self._cache.clear()
            p = self.problem_at(lam)
            self._cache[lam] = p
        return p

    def Y(self, z) -> np.ndarray:
        return (z[:-1] * self.c).reshape(self.shape)

    def z(self, Y, lam) -> np.ndarray:
        return np.concatenate([np.ravel(Y) / self.c, [(lam - self.lam0) / self.span]])

    def G(self, z) -> np.ndarray:
        return residual(self.Y(z), self.prob(self.lam(z)))

    def g_lam(self, z) -> np.ndarray:
        """G_λ̂ (13(N+1),) at z, by a central difference in λ."""
        lam, Y = self.lam(z), self.Y(z)
        d = 1e-6 * abs(self.span)
        g = (residual(Y, self.prob(lam + d)) - residual(Y, self.prob(lam - d))) / (2 * d)
        return g * self.span

    def blocks(self, z):
        """(G_z sparse, G_λ̂ dense) at z."""
        lam, Y = self.lam(z), self.Y(z)
        return jacobian(Y, self.prob(lam)) @ sp.diags(self.c), self.g_lam(z)

    def bordered(self, z, row, phase=None):
        """LU of the bordered matrix at z, [[G_z, G_λ̂], [row]] (row (n + 1,)); with
        ``phase`` (a branch of a symmetric pair), of [[G_z, G_λ̂, w], [row, 0], [a, 0, 0]]
        (:func:`_corrector`). Without self-contact and seabed G_z is a band and the LU is
        :class:`solver.static_band.BorderedBandLU` (block elimination on LAPACK's band LU);
        otherwise, or where the band LU meets a zero pivot, scipy's sparse LU of the whole
        matrix. Either has ``solve``; :func:`solver.statics.lu_det_sign` reads either.
        Raises StaticsError where the bordered matrix is singular."""
        prob = self.prob(self.lam(z))
        if band_ready(prob):
            try:
                return self._bordered_band(z, row, phase, prob)
            except BandSingular:
                pass
        J, g = self.blocks(z)
        if phase is None:
            A = sp.vstack([sp.hstack([J, sp.csc_matrix(g[:, None])]),
                           sp.csr_matrix(row[None, :])], format="csc")
        else:
            A = sp.vstack([sp.hstack([J, sp.csc_matrix(g[:, None]),
                                      sp.csc_matrix(phase["w"][:, None])]),
                           sp.csr_matrix(np.append(row, 0.0)[None, :]),
                           sp.csr_matrix(np.append(phase["a"], (0.0, 0.0))[None, :])],
                          format="csc")
        return factor(A)

    def _bordered_band(self, z, row, phase, prob):
        n = self.n
        ab = band_jacobian(self.Y(z), prob)
        ab *= self.c[None, :]
        g = self.g_lam(z)
        if phase is None:
            return BorderedBandLU(ab, g[:, None], row[:n, None], [[row[n]]])
        W = np.column_stack([g, phase["w"]])
        C = np.column_stack([row[:n], phase["a"]])
        return BorderedBandLU(ab, W, C, [[row[n], 0.0], [0.0, 0.0]])


def _corrector(S: _Scaled, z_pred, row, target, newton_max, tol, phase=None):
    """Solve [G(z); row·z − target] = 0 from z_pred. Returns (z, iterations, lu of the
    bordered matrix at z) or None when it does not converge.

    Quasi-Newton on one factorisation: the first iteration is Newton's, with the bordered
    LU at z_pred, the later ones solve with Broyden's good update of it, applied as its
    Sherman-Morrison product over the steps taken (Kelley, *Iterative Methods for
    Linear and Nonlinear Equations*, SIAM 1995, § 7.3, algorithm brsol; Broyden's method
    as the corrector of a continuation: Allgower & Georg, *Introduction to Numerical
    Continuation Methods*, 2003, § 7.2). An iteration whose update is not at most half
    the one before refactors at its iterate and starts the updates afresh. Converged
    (an update below ``tol``) after Broyden steps, the bordered matrix is factored at
    the point and one Newton step taken with it (the residual at rounding, as Newton's
    quadratic last step leaves it). The returned lu is factored at the last iterate
    before the final update, as Newton's, so its determinant sign and the tangent it
    gives belong to the new point.

    With ``phase`` (a branch of a pair that a rotation symmetry makes a circle of
    equilibria): the same on [G(z) + ε w; row·z − target; a·(z − z_ref)] = 0 in (z, ε), the
    phase condition a·(z − z_ref) = 0 (a the symmetry's generator at the last point)
    picking one equilibrium of the circle and the unfolding ε w (w off the range of G_z)
    keeping the system square; ε = 0 at a solution (phase condition and unfolding parameter
    of continuation with a continuous symmetry: Dellnitz & Werner, J. Comput. Appl. Math.
    26, 1989; Champneys & Sandstede in Krauskopf et al., *Numerical Continuation Methods
    for Dynamical Systems*, 2007). A converged ε above 1e-8 is refused."""
    u = z_pred.copy() if phase is None else np.append(z_pred, 0.0)   # (z, ε)
    lu, steps, last = None, [], np.inf
    for it in range(1, newton_max + 1):
        if lu is None:
            try:
                lu = S.bordered(u[:S.n + 1], row, phase)
            except StaticsError:
                return None
            steps = []
        d = -_solve(lu, _corrector_rows(S, u, row, target, phase), refine=False)
        for j in range(len(steps) - 1):
            d += steps[j + 1] * ((steps[j] @ d) / (steps[j] @ steps[j]))
        if steps:
            d /= 1.0 - (steps[-1] @ d) / (steps[-1] @ steps[-1])
        if not np.all(np.isfinite(d)):
            return None
        u = u + d
        steps.append(d)
        size = float(np.max(np.abs(d)))
        if size < tol:
            if len(steps) > 1:            # a last Newton step, with the LU at the point
                try:
                    lu = S.bordered(u[:S.n + 1], row, phase)
                except StaticsError:
                    return None
                u = u - lu.solve(_corrector_rows(S, u, row, target, phase))
            if phase is not None and abs(u[-1]) > 1e-8:
                return None
            return u[:S.n + 1], it, lu
        if size > CONTRACTION * last:
            lu = None                     # no contraction: refactor at this iterate
        last = size
    return None


def _corrector_rows(S: _Scaled, u, row, target, phase):
    """The corrector's equations at u = z, or (z, ε) with ``phase`` (:func:`_corrector`)."""
    z = u[:S.n + 1]
    F = np.concatenate([S.G(z), [row @ z - target]])
    if phase is None:
        return F
    F[:-1] += u[-1] * phase["w"]
    return np.append(F, phase["a"] @ (z[:-1] - phase["zref"][:-1]))


def _solve(lu, b, refine=True):
    """lu.solve(b); with ``refine=False`` a band LU's block elimination without its
    refinement step (:meth:`solver.static_band.BorderedBandLU.solve`): the corrector's
    own iterations refine."""
    return lu.solve(b, refine=refine) if isinstance(lu, BorderedBandLU) else lu.solve(b)


def _tangent(lu, n, phase=None):
    e = np.zeros(n + 1 + (phase is not None))
    e[n] = 1.0
    t = lu.solve(e)[:n + 1]
    return t / np.linalg.norm(t)


def _generator(Y, axis, origin) -> np.ndarray:
    """(N+1, 13) the infinitesimal rotation about the line ``origin`` + R ``axis`` of the
    equilibrium Y (positions, internal forces and moments turned about the axis; the frames
    turned about it and back about their own d3: p -> ½(â ⊗ p − p ⊗ ê3)). For an isotropic
    section (B1 = B2) with ends on the axis whose tangents lie along it, G(Y) = 0 is
    invariant under this rotation: the helical modes of a round rod come in pairs, and the
    branch they start is a circle of equilibria per parameter value."""
    d = np.zeros_like(Y)
    q = Y[:, 3:7]
    d[:, 0:3] = np.cross(axis, Y[:, 0:3] - origin)
    d[:, 3:7] = 0.5 * (_qmul(np.broadcast_to(np.append(0.0, axis), q.shape), q)
                       - _qmul(q, np.broadcast_to(np.array([0.0, 0.0, 0.0, 1.0]), q.shape)))
    d[:, 7:10] = np.cross(axis, Y[:, 7:10])
    d[:, 10:13] = np.cross(axis, Y[:, 10:13])
    return d


def _unstable_on_orbit(Y, prob, aY, k):
    """Unstable modes of an equilibrium of a symmetric circle (:func:`_generator` ``aY``
    (N+1, 13) its direction along the circle, a neutral mode): the pencil J z = μ B z on
    aYᵀ z = 0, bordered [[J, B aY], [aYᵀ, 0]] (a Lagrange multiplier); otherwise as
    :func:`solver.statics.unstable_modes`. Returns (count, μ sorted by |μ|)."""
    import scipy.sparse.linalg as spla

    a = np.ravel(aY)
    J, Bm = jacobian(Y, prob), mass_matrix(Y, prob)
    n = J.shape[0]
    lu = factor(sp.vstack([sp.hstack([J, sp.csc_matrix((Bm @ a)[:, None])]),
                           sp.csr_matrix(np.append(a, 0.0)[None, :])], format="csc"))
    Be = sp.block_diag([Bm, sp.csc_matrix((1, 1))], format="csc")
    op = spla.LinearOperator((n + 1, n + 1), matvec=lambda x: lu.solve(Be @ x), dtype=float)
    nu = nearest_eigenvalues(op, n + 1, min(k, n - 2))
    if nu.size == 0:
        return -1, np.array([], complex)
    return _count(nu)


def continuation(problem_at: Callable[[float], StaticProblem], lam0: float, lam1: float,
                 Y0: Optional[np.ndarray] = None, *, ds: float = 0.02, ds_max: float = 0.05,
                 ds_min: float = 1e-7, max_points: int = 500, tol: float = 1e-9,
                 newton_max: int = 10, max_turn: float = 0.3, stability: bool = True,
                 modes: int = 8, locate: bool = True, switch: bool = False,
                 start_tangent: Optional[np.ndarray] = None,
                 on_point: Optional[Callable[[int, float], None]] = None,
                 should_stop: Optional[Callable[[], object]] = None,
                 checkpoint: Optional[Callable[[dict], None]] = None,
                 resume: Optional[dict] = None) -> Branch:
    """Follow the equilibria of ``problem_at(λ)`` from λ = ``lam0`` towards ``lam1``.

    Parameters
    ----------
    problem_at : λ -> :class:`solver.statics.StaticProblem` (one grid for all λ)
    lam0, lam1 : the start and target values of the parameter (its unit)
    Y0 : (N+1, 13) start guess (default: the straight rod, loads ramped if needed)
    ds, ds_max, ds_min : first, largest and smallest step in scaled arclength, as fractions
        of the arclength of the start tangent per unit λ̂ (ds_max = 0.05: at least 20
        points to cross the range on a branch that does not bend)
    max_points : stop after this many points
    stability : count the unstable modes at every point (:func:`unstable_modes`)
    locate : locate folds and branch points by bisection
    switch : at the first branch point (simple, or a pair of the rod's rotation symmetry),
        follow the bifurcating branch instead
    start_tangent : (N+1, 13) a direction in Y units to leave the start point along
        (branch switching from a known branch point); default: along increasing λ
    on_point : called with (index, λ) after every accepted point
    should_stop : called before every step; a true answer (a reason, e.g. "timeout") ends
        the continuation there with the points so far, ``stopped`` = "stopped: <reason>"
    checkpoint : called with the continuation's state (a dict of arrays and lists: the
        points so far, z, t, the det sign, Δs; no problem objects) after every accepted point
        and once more when ``should_stop`` ends the branch
    resume : such a state (from ``checkpoint``, same problem family and options): continue
        from it instead of solving the start point; the branch returned is the one an
        uninterrupted continuation returns, to the last bit

    Returns
    -------
    Branch

    Raises
    ------
    ContinuationError
        for lam1 == lam0, no equilibrium at lam0, or a singular Jacobian at lam0 (a fold
        or branch point at the start), or a ``resume`` state of another grid.
    Exception
        any other exception raised after the start point carries the points computed so
        far as ``exc.partial_branch`` (a :class:`Branch`, ``stopped`` naming the exception).
    """
    lam0, lam1 = float(lam0), float(lam1)
    if not (np.isfinite(lam0) and np.isfinite(lam1)) or lam1 == lam0:
        raise ContinuationError(f"the range {lam0!r} -> {lam1!r} does not move the parameter")
    p0 = problem_at(lam0)
    opt = dict(ds=ds, ds_max=ds_max, ds_min=ds_min, tol=tol, newton_max=newton_max,
               max_turn=max_turn, stability=stability, modes=modes, locate=locate,
               switch=switch, on_point=on_point)
    S = _Scaled(problem_at, lam0, lam1, p0)
    # band LUs, small dense blocks and ARPACK: BLAS threads only oversubscribe shared cores,
    # as for solver.simulation.integrate (the 200-point branch of
    # research/continuation_speed.py before this limit, one run each at load 2.6 on 2
    # cores: 4.1 s under OPENBLAS_NUM_THREADS=1, 18.5 s under 2)
    with _blas_controller().limit(limits=1, user_api="blas"):
        if resume is not None:
            tr = _Tracer.restore(S, opt, resume)
        else:
            tr = _Tracer(S, _start_point(p0, lam0, Y0), opt, start_tangent)
        return _trace(tr, max_points, should_stop, checkpoint)


def _start_point(p0: StaticProblem, lam0: float, Y0: Optional[np.ndarray]):
    """The equilibrium at the start value, with a regular Jacobian
    (:func:`continuation`'s ContinuationError otherwise)."""
    try:
        sol = solve(p0, Y0)
    except StaticsError as exc:
        raise ContinuationError(f"no equilibrium at the start value {lam0!r}: {exc}") \
            from exc
    try:
        factor_jacobian(sol.Y, p0)
    except StaticsError as exc:
        raise ContinuationError(f"singular start at {lam0!r} (a fold or branch point): "
                                "start the continuation away from it") from exc
    return sol


def _trace(tr: "_Tracer", max_points: int, should_stop, checkpoint) -> Branch:
    """Step ``tr`` until the range, a stop or ``max_points`` (:func:`continuation`)."""
    try:
        while len(tr.br.parameter) < max_points:
            reason = should_stop() if should_stop is not None else False
            if reason:
                tr.br.stopped = f"stopped: {reason}"
                if checkpoint is not None:
                    checkpoint(tr.state())
                return tr.br
            if tr.step():
                return tr.br
            if checkpoint is not None:
                checkpoint(tr.state())
    except Exception as exc:
        # keep what was computed: the caller stores the branch so far and reports exc
        tr.br.stopped = f"failed: {type(exc).__name__}: {exc}"
        try:
            exc.partial_branch = tr.br
        except AttributeError:          # an exception type without a __dict__
            pass
        raise
    tr.br.stopped = "max_points"
    return tr.br


#: the Branch lists a checkpoint holds (``problems`` is rebuilt from the parameter)
_BRANCH_LISTS = ("parameter", "Y", "unstable", "mu", "iterations", "bifurcations")


class _Tracer:
    """The state of one continuation: the branch so far, the last point z, its tangent t,
    the sign of its bordered determinant, the step size (scaled arclength)."""

    def __init__(self, S: _Scaled, sol, opt: dict, start_tangent):
        self.S, self.o, self.br = S, opt, Branch()
        self.z = S.z(sol.Y, S.lam0)
        self.e_lam = np.zeros(S.n + 1)
        self.e_lam[-1] = 1.0
        t_raw = S.bordered(self.z, self.e_lam).solve(self.e_lam)     # dz/dλ̂ on the branch
        rho = float(np.linalg.norm(t_raw))
        self.t = t_raw / rho
        if start_tangent is not None:
            phi = np.concatenate([np.ravel(start_tangent) / S.c, [0.0]])
            self.t = phi / np.linalg.norm(phi)
        self.ds, self.ds_max, self.ds_min = (opt["ds"] * rho, opt["ds_max"] * rho,
                                             opt["ds_min"] * rho)
        self.switched = False
        self.phase = None            # the phase condition on a branch of a symmetric pair
        # the start point's determinant sign, with its own tangent as the border
        self.det = self.record(self.z, sol.iterations, S.bordered(self.z, self.t))

    def state(self) -> dict:
        """What :meth:`restore` needs to go on exactly as this tracer would (copies)."""
        br = self.br
        out = {k: list(getattr(br, k)) for k in _BRANCH_LISTS}
        out.update(switched_at=br.switched_at, z=self.z.copy(), t=self.t.copy(),
                   det=int(self.det), ds=self.ds, ds_max=self.ds_max, ds_min=self.ds_min,
                   switched=self.switched, shape=self.S.shape,
                   phase=None if self.phase is None else
                   {k: np.array(v) for k, v in self.phase.items()})
        return out

    @classmethod
    def restore(cls, S: _Scaled, opt: dict, state: dict) -> "_Tracer":
        """The tracer of :meth:`state` on the problem family of ``S``."""
        if tuple(state.get("shape", ())) != S.shape:
            raise ContinuationError(f"the resume state is of a grid {state.get('shape')} "
                                    f"that is not this problem's {S.shape}")
        tr = cls.__new__(cls)
        tr.S, tr.o, tr.br = S, opt, Branch()
        for k in _BRANCH_LISTS:
            setattr(tr.br, k, list(state[k]))
        tr.br.switched_at = state["switched_at"]
        tr.br.problems = [S.problem_at(lam) for lam in tr.br.parameter]
        tr.e_lam = np.zeros(S.n + 1)
        tr.e_lam[-1] = 1.0
        tr.z, tr.t, tr.det = np.array(state["z"]), np.array(state["t"]), int(state["det"])
        tr.ds, tr.ds_max, tr.ds_min = state["ds"], state["ds_max"], state["ds_min"]
        tr.switched = bool(state["switched"])
        phase = state.get("phase")
        tr.phase = None if phase is None else {k: np.array(v) for k, v in phase.items()}
        return tr

    def record(self, z, its, lu_border) -> int:
        """Append the point z (its unstable modes counted) and return its det sign."""
        S, br = self.S, self.br
        lam = S.lam(z)
        Y = S.Y(z)
        prob = S.prob(lam)
        count, mu0 = -1, np.nan
        if self.o["stability"] and self.phase is not None:
            count, mu = _unstable_on_orbit(Y, prob, _generator(Y, self.phase["axis"],
                                                               self.phase["origin"]),
                                           self.o["modes"])
            mu0 = float(mu[0].real) if mu.size else np.nan
        elif self.o["stability"]:
            count, mu = unstable_modes(Y, prob, k=self.o["modes"])
            mu0 = float(mu[0].real) if mu.size else np.nan
        br.parameter.append(lam)
        br.Y.append(Y)
        br.unstable.append(count)
        br.mu.append(mu0)
        br.iterations.append(its)
        br.problems.append(prob)
        if self.o["on_point"] is not None:
            self.o["on_point"](len(br.parameter) - 1, lam)
        return lu_det_sign(lu_border)

    def _refuse(self, why: str) -> bool:
        self.ds *= 0.5
        if self.ds < self.ds_min:
            self.br.stopped = f"step below ds_min ({why})"
            return True
        return False

    def step(self) -> bool:
        """Try one step; True when the continuation is over (``br.stopped`` says why)."""
        S, o, z, t, ph = self.S, self.o, self.z, self.t, self.phase
        landing = t[-1] > 0 and z[-1] + self.ds * t[-1] >= 1.0 - 1e-12
        if landing:
            res = _corrector(S, z + (1.0 - z[-1]) / t[-1] * t, self.e_lam, 1.0,
                             o["newton_max"], o["tol"], ph)
        else:
            z_pred = z + self.ds * t
            res = _corrector(S, z_pred, t, t @ z_pred, o["newton_max"], o["tol"], ph)
        if res is None:
            return self._refuse("no convergence")
        z_new, its, lu_new = res
        if landing:
            lu_new = S.bordered(z_new, t, ph)
        t_new = _tangent(lu_new, S.n, ph)
        if t_new @ t < np.cos(o["max_turn"]) and not landing:
            return self._refuse("tangent turning")
        det_new = self.record(z_new, its, lu_new)
        z_new, t_new, det_new = self._events(z_new, t_new, det_new)
        if z_new is None:
            return True
        self.z, self.t, self.det = z_new, t_new, det_new
        self._phase_at(z_new)
        if landing:
            self.br.stopped = "reached the target value"
            return True
        if not -1.0 <= z_new[-1] <= 2.0:
            self.br.stopped = "left the range"
            return True
        if its <= GROW_ITERATIONS:
            self.ds = min(1.5 * self.ds, self.ds_max)
        elif its > SHRINK_ITERATIONS:
            self.ds = max(0.7 * self.ds, self.ds_min)
        return False

    def _events(self, z_new, t_new, det_new):
        """Detect, locate and record the events of the step z -> z_new; switch branches
        when asked. Returns the point to go on from (None: stop)."""
        S, o, br, z, t = self.S, self.o, self.br, self.z, self.t
        k_prev = len(br.parameter) - 2
        events = []
        if np.sign(t_new[-1]) != np.sign(t[-1]) and t[-1] != 0:
            events.append("fold")
        if det_new != self.det:
            events.append("branch_point")
        elif (o["stability"] and "fold" not in events and min(br.unstable[-2:]) >= 0
              and br.unstable[-1] != br.unstable[-2]):
            events.append("even_branch_point")
        for kind in events:
            bif = (_locate(S, z, t, z_new, kind, o["newton_max"], o["tol"], self.det,
                           br.unstable[-2], o["modes"], self.phase)
                   if o["locate"] else None)
            if bif is None:
                bif = Bifurcation("branch_point" if "branch" in kind else kind,
                                  0.5 * (S.lam(z) + S.lam(z_new)), S.Y(z_new), k_prev,
                                  simple=kind != "even_branch_point")
            bif.after = k_prev
            br.bifurcations.append(bif)
            if o["switch"] and not self.switched and kind == "branch_point" \
                    and bif.null is not None:
                return self._switch(bif)
            if o["switch"] and not self.switched and kind == "even_branch_point":
                out = self._switch_pair(bif)
                if out is not None:
                    return out
        return z_new, t_new, det_new

    def _phase_at(self, z):
        """On a branch of a symmetric pair: the phase condition's reference is the point z
        and its row the symmetry's generator there (unit scaled norm)."""
        if self.phase is None:
            return
        S = self.S
        a = np.ravel(_generator(S.Y(z), self.phase["axis"], self.phase["origin"])) / S.c
        self.phase["a"] = a / np.linalg.norm(a)
        self.phase["zref"] = z.copy()

    def _switch_pair(self, bif: Bifurcation):
        """Leave a branch point of a symmetric pair (a double zero eigenvalue of G_y, the
        rod's rotation about its axis turning one mode of the pair into the other) along
        one mode φ of the pair, with the phase condition that fixes the rotation
        (:func:`_corrector`). Returns None (the primary branch goes on) when the kernel is
        not such a pair: not two-dimensional, or not turned into itself by the rotation
        about the line through the rod's ends."""
        S, o = self.S, self.o
        zb = S.z(bif.Y, bif.parameter)
        J, _ = S.blocks(zb)
        try:
            lu = factor(J.tocsc())
        except StaticsError:
            return None
        rng = np.random.default_rng(0)
        X, W = rng.standard_normal((S.n, 2)), rng.standard_normal((S.n, 2))
        for _ in range(4):                      # block inverse iteration: the 2-D kernels
            X = np.linalg.qr(np.column_stack([lu.solve(x) for x in X.T]))[0]
            W = np.linalg.qr(np.column_stack([lu.solve(x, trans="T") for x in W.T]))[0]
        ends = bif.Y[-1, 0:3] - bif.Y[0, 0:3]
        if not np.linalg.norm(ends) > 0:
            return None
        axis, origin = ends / np.linalg.norm(ends), bif.Y[0, 0:3].copy()
        phi = X[:, 0]
        if phi[int(np.argmax(np.abs(phi)))] < 0:
            phi = -phi
        a = np.ravel(_generator((phi * S.c).reshape(S.shape), axis, origin)) / S.c
        na = np.linalg.norm(a)
        r = rng.standard_normal(S.n)
        gain = np.linalg.norm(J @ r) / np.linalg.norm(r)     # |G_z x| of a typical unit x
        two_dimensional = np.all(np.linalg.norm(J @ X, axis=0) < 1e-6 * gain)
        turned_into_itself = na > 1e-6 and np.linalg.norm(a - X @ (X.T @ a)) < 1e-6 * na
        if not (two_dimensional and turned_into_itself):
            return None
        self.switched = True
        self.br.switched_at = len(self.br.parameter) - 1
        w = W @ rng.standard_normal(2)
        self.phase = {"axis": axis, "origin": origin, "w": w / np.linalg.norm(w),
                      "a": a / na, "zref": zb.copy()}
        phi_z = np.append(phi, 0.0)
        step = 0.1 * self.ds_max
        res = _corrector(S, zb + step * phi_z, phi_z, phi_z @ zb + step, o["newton_max"],
                         o["tol"], self.phase)
        if res is None:
            self.br.stopped = "branch switching did not converge"
            return None, None, None
        z_new, its, lu_new = res
        t_new = _tangent(lu_new, S.n, self.phase)
        self._phase_at(z_new)
        # the determinant's sign with the rows the next step borders with (its tangent and
        # the phase row there), as at the start point
        det = self.record(z_new, its, S.bordered(z_new, t_new, self.phase))
        return z_new, t_new, det

    def _switch(self, bif: Bifurcation):
        """Leave the branch point ``bif`` along its null vector (Keller's switching)."""
        S, o = self.S, self.o
        self.switched = True
        self.br.switched_at = len(self.br.parameter) - 1
        zb = S.z(bif.Y, bif.parameter)
        phi = np.concatenate([np.ravel(bif.null) / S.c, [0.0]])
        phi /= np.linalg.norm(phi)
        if phi[int(np.argmax(np.abs(phi[:-1])))] < 0:
            phi = -phi
        step = 0.1 * self.ds_max
        res = _corrector(S, zb + step * phi, phi, phi @ zb + step, o["newton_max"], o["tol"])
        if res is None:
            self.br.stopped = "branch switching did not converge"
            return None, None, None
        z_new, its, lu_new = res
        t_new = _tangent(lu_new, S.n)
        return z_new, t_new, self.record(z_new, its, lu_new)


def _locate(S: _Scaled, z0, t0, z1, kind, newton_max, tol, det0, count0, modes, phase=None):
    """Bisection on the arclength σ of the step z0 -> z1 (border t0) for the event
    ``kind``: the sign of t_λ̂ (fold), of det (branch_point), or the unstable count."""
    sig_hi = float(t0 @ (z1 - z0))
    lo, hi = 0.0, sig_hi
    z_lo, z_hi = z0, z1
    lu_at = None
    for _ in range(40):
        if hi - lo <= 1e-9 * sig_hi:
            break
        mid = 0.5 * (lo + hi)
        w = (mid - lo) / (hi - lo)
        guess = (1 - w) * z_lo + w * z_hi
        res = _corrector(S, guess, t0, t0 @ z0 + mid, newton_max, tol, phase)
        if res is None:
            return None
        zm, _, lu = res
        if kind == "fold":
            same = np.sign(_tangent(lu, S.n, phase)[-1]) == np.sign(t0[-1])
        elif kind == "branch_point":
            same = lu_det_sign(lu) == det0
        elif phase is not None:
            aY = _generator(S.Y(zm), phase["axis"], phase["origin"])
            same = _unstable_on_orbit(S.Y(zm), S.prob(S.lam(zm)), aY, modes)[0] == count0
        else:
            same = unstable_modes(S.Y(zm), S.prob(S.lam(zm)), k=modes)[0] == count0
        if same:
            lo, z_lo = mid, zm
        else:
            hi, z_hi = mid, zm
            lu_at = lu
    zb = 0.5 * (z_lo + z_hi)
    null = None
    if kind == "branch_point" and lu_at is not None:
        x = np.random.default_rng(0).standard_normal(S.n + 1 + (phase is not None))
        for _ in range(3):
            x = lu_at.solve(x)
            x /= np.linalg.norm(x)
        null = (x[:S.n] * S.c).reshape(S.shape)
    name = "fold" if kind == "fold" else "branch_point"
    return Bifurcation(name, S.lam(zb), S.Y(zb), -1, null=null,
                       simple=kind != "even_branch_point")


# --------------------------------------------------------------------------- the dataset

def _point_quantities(br: Branch, shapes_every: int):
    """Per point: end loads and positions (point, 3), scalars (point,), shapes
    (point, N+1, 3) on every ``shapes_every``-th point and the last (NaN elsewhere)."""
    from .statics import contact_gap, fields
    from .topology import linking_number, twist, writhe

    n_pts = len(br.parameter)
    s = br.problems[0].s
    n1 = s.size
    keep = np.zeros(n_pts, bool)
    keep[::max(1, int(shapes_every))] = True
    keep[-1] = True
    pos = np.full((n_pts, n1, 3), np.nan)
    kap = np.full((n_pts, n1, 3), np.nan)
    per = {k: np.zeros((n_pts, 3)) for k in ("start_force", "end_force", "start_moment",
                                               "end_moment", "start_position", "end_position")}
    scal = {k: np.zeros(n_pts) for k in ("start_rotation", "end_rotation", "end_to_end", "twist",
                                         "writhe", "link", "elastic_energy", "load_potential",
                                         "contact_gap")}
    for i, (Y, prob) in enumerate(zip(br.Y, br.problems)):
        f = fields(Y, prob)
        per["start_force"][i] = -Y[0, 7:10]
        per["end_force"][i] = Y[-1, 7:10]
        per["start_moment"][i] = -Y[0, 10:13]
        per["end_moment"][i] = Y[-1, 10:13]
        per["start_position"][i] = Y[0, 0:3]
        per["end_position"][i] = Y[-1, 0:3]
        scal["start_rotation"][i] = prob.start.twist
        scal["end_rotation"][i] = prob.end.twist
        scal["end_to_end"][i] = float(np.linalg.norm(Y[-1, 0:3] - Y[0, 0:3]))
        scal["twist"][i] = twist(f["kappa"][:, 2], s)
        scal["writhe"][i] = writhe(f["position"])
        scal["link"][i] = linking_number(prob.start.twist, prob.end.twist)
        scal["elastic_energy"][i] = f["elastic_energy"]
        scal["load_potential"][i] = f["load_potential"]
        scal["contact_gap"][i] = contact_gap(Y, prob)
        if keep[i]:
            pos[i], kap[i] = f["position"], f["kappa"]
    return per, scal, pos, kap


def branch_dataset(br: Branch, parameter: str = "parameter", *, shapes_every: int = 1,
                   attrs: Optional[dict] = None):
    """The branch as an ``xarray.Dataset`` along dimension ``point`` (one per equilibrium)
    and ``bifurcation`` (one per located fold or branch point).

    Per point: ``parameter`` (λ; its attribute ``path`` names it), ``unstable_modes``,
    ``stable`` (unstable_modes == 0), ``mu_nearest_zero`` (1/s²), ``newton_iterations``,
    ``start_force``/``end_force`` (N) and ``start_moment``/``end_moment`` (N m) that the
    supports apply to the rod (global xyz), ``start_position``/``end_position`` (m),
    ``start_rotation``/``end_rotation`` (rad about the end tangents, from the reference),
    ``end_to_end`` (m), ``twist``/``writhe``/``link`` (Tw, Wr, Lk, turns:
    :mod:`solver.topology`; Lk from the end rotations, meaningful when the end tangents
    stay on one axis), ``elastic_energy``, ``load_potential``, ``total_energy`` (J),
    ``contact_gap`` (m: the smallest segment-to-segment surface gap beyond the exclusion,
    :func:`solver.statics.contact_gap`; inf without self-contact); on
    every ``shapes_every``-th point (the last always) ``position`` and ``kappa`` on the
    nodes (NaN on the others). Per bifurcation: ``bifurcation_parameter``,
    ``bifurcation_kind`` ("fold" / "branch_point"), ``bifurcation_after`` (the point index
    it follows), ``bifurcation_simple``; ``branch`` per point: 0 on the start branch, 1
    after a switch at a branch point.
    """
    import xarray as xr

    n_pts = len(br.parameter)
    prob0 = br.problems[0]
    s = prob0.s
    per, scal, pos, kap = _point_quantities(br, shapes_every)
    unstable = np.asarray(br.unstable, int)
    units = {"start_force": "N", "end_force": "N", "start_moment": "N m", "end_moment": "N m",
             "start_position": "m", "end_position": "m", "start_rotation": "rad",
             "end_rotation": "rad", "end_to_end": "m", "twist": "turns", "writhe": "turns",
             "link": "turns", "elastic_energy": "J", "load_potential": "J",
             "contact_gap": "m"}
    data = {
        "parameter": ("point", np.asarray(br.parameter, float), {"path": parameter}),
        "unstable_modes": ("point", unstable, {"long_name": "number of unstable modes "
                           "(-1: not computed)"}),
        "stable": ("point", (unstable == 0).astype(np.int8), {"long_name": "1: stable"}),
        "mu_nearest_zero": ("point", np.asarray(br.mu, float),
                            {"units": "1/s^2", "long_name": "eigenvalue -omega^2 nearest zero"}),
        "newton_iterations": ("point", np.asarray(br.iterations, int)),
        "branch": ("point", (np.arange(n_pts) > (n_pts if br.switched_at is None
                                                 else br.switched_at)).astype(np.int8),
                   {"long_name": "0: the start branch, 1: the branch switched onto"}),
        "position": (("point", "node", "xyz"), pos, {"units": "m"}),
        "kappa": (("point", "node", "xyz"), kap, {"units": "1/m", "long_name": "body-frame curvature"}),
    }
    for k, v in per.items():
        data[k] = (("point", "xyz"), v, {"units": units[k]})
    for k, v in scal.items():
        data[k] = ("point", v, {"units": units[k]})
    data["total_energy"] = ("point", scal["elastic_energy"] + scal["load_potential"], {"units": "J"})
    bifs = br.bifurcations
    data["bifurcation_parameter"] = ("bifurcation", np.asarray([b.parameter for b in bifs], float))
    data["bifurcation_kind"] = ("bifurcation", np.asarray([b.kind for b in bifs], dtype="U12"))
    data["bifurcation_after"] = ("bifurcation", np.asarray([b.after for b in bifs], int))
    data["bifurcation_simple"] = ("bifurcation", np.asarray([int(b.simple) for b in bifs], np.int8))
    ds = xr.Dataset(data, coords={"point": np.arange(n_pts), "s": ("node", s),
                                  "xyz": ["x", "y", "z"]})
    ds.attrs.update({"hockle_kind": "branch", "parameter_path": parameter,
                     "n_segments": int(prob0.n_segments), "stopped": br.stopped,
                     "switched_at": -1 if br.switched_at is None else int(br.switched_at)})
    if attrs:
        ds.attrs.update(attrs)
    return ds
