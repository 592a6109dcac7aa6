"""The growth guard of a run: when to estimate the fastest growth rate, and the cap on Δt.

The estimate itself is :func:`solver.stepping.growth_rate` (shift-invert Arnoldi on the
converged step's Jacobian). What the guard has learnt (its last σ, the Δt and the Arnoldi
vector of that check) is not part of the state a refused or probe step rolls back
(:meth:`solver.run.RodRun._restore`): a check made in a probe step of step doubling serves
the steps that replace it (rolled back with the state, it was lost at every doubled step
and every refused one: Greenhill at tolerance 1e-2, 16 of 21 checks, each a band LU and an
Arnoldi run).
"""
from __future__ import annotations

import math

import numpy as np

from ..banded import BlockLU
from . import growth_rate

__all__ = ["GrowthGuard", "pencil_growth_rate"]


class GrowthGuard:
    """The growth guard's knowledge and rule (``numerics.growth_guard``).

    Parameters
    ----------
    limit : float or None
        The largest σΔt allowed (``numerics.growth_guard``, g); None: no guard.

    Attributes
    ----------
    sigma : float
        Last estimate of the fastest growth rate σ, 1/s (NaN: not yet checked).
    h, h_max : float
        The Δt of the last check and the largest Δt checked, s.
    since : int
        Accepted steps since the last check.
    v0 : ndarray or None
        The Arnoldi start vector (the last check's eigenvector).
    """

    #: accepted steps between growth-guard checks at an unchanged Δt
    GUARD_EVERY = 10

    def __init__(self, limit):
        self.limit = limit
        self.sigma = math.nan
        self.h = 0.0
        self.h_max = 0.0
        self.since = 0
        self.v0 = None
        self.layout = None

    def cap(self) -> float:
        """Largest Δt (s) the growth guard allows now (inf when no growth is known)."""
        if self.limit is None or not self.sigma > 0.0:
            return math.inf
        return self.limit / self.sigma

    def ok(self, system, h, Y) -> bool:
        """The growth guard for a converged step of h (s) to Y (N+1, 12) of ``system``
        (:class:`solver.scheme.RodSystem`, set up for the step): :meth:`check` with
        σ estimated by :func:`solver.stepping.growth_rate` on the step's Jacobian and
        the bending time scale ``system.tc``."""
        def estimate(shift, v0):
            if self.layout is None:
                self.layout = BlockLU(system.n_cells)
            return growth_rate(system, Y, shift, self.layout, v0)

        return self.check(h, system.tc, estimate)

    def check(self, h, tc, estimate, look_far: bool = False) -> bool:
        """The growth guard for a converged step of h (s): False when the fastest
        growth rate σ of the linearised dynamics has σh > ``limit`` (such a step would
        damp the growing mode instead of following it). ``estimate(shift, v0)`` returns
        (σ (1/s), −inf where none is found near the shift, and the eigenvector for the
        next start), or None where it cannot be estimated (the last σ then stands); tc
        is the bending time scale L²√(ρA/EJ) (s). σ is estimated
        (shift 2g/h, which finds every σ up to 4g/h;
        and 16g/h as well when h is more than twice the largest step checked so far)
        every GUARD_EVERY accepted steps (every 4 GUARD_EVERY while the last check found
        σh < g/4), at every step longer than a tenth of tc
        (a run of a few long steps would otherwise see one check: the
        stability map's twisted rod at Δt = 0.3 s buckles after its fifth step), and
        whenever h exceeds twice the step of the last
        check (below that the last check's disc covers σ = g/h); in between the last
        estimate is used. With ``look_far``, 16g/h is looked at too whenever the near
        disc holds no growth (an estimate that sees no growth below the critical load
        cannot warn of one that starts within a step: the stability map's rod twisted
        at 10 rad/s at Δt = 0.3 s on the centreline scheme went from none at 0.85 of
        Greenhill's twist to σ ≈ 20 1/s, beyond 4g/h, one step later)."""
        g = self.limit
        # far from the limit (σh < g/4 at the last check) a check every 4·GUARD_EVERY
        every = self.GUARD_EVERY * (4 if self.sigma * self.h < 0.25 * g else 1)
        if (math.isnan(self.sigma) or self.since >= every
                or h > 2.0 * self.h or h > 0.1 * tc):
            near = estimate(2.0 * g / h, self.v0)
            if near is None:
                self.since = 0
                return not self.sigma * h > g * (1.0 + 1e-9)
            sigma, vec = near
            # further out (16g/h) at new largest steps, and when a growth known from the
            # last check is not in the near disc any more: under a rising load σ grows
            # past 4g/h rather than vanishing (the stability map's twisted rod at Δt =
            # 0.3 s: σ = 2.2 s⁻¹, then none in (0, 14), then 21 s⁻¹ one step later)
            if (h > 2.0 * self.h_max or (not sigma > 0.0 and self.sigma > 0.0)
                    or (look_far and not sigma > 0.0)):
                far, _ = estimate(16.0 * g / h, None)
                sigma = max(sigma, far)
                self.h_max = max(self.h_max, h)
            self.sigma = max(sigma, 0.0)
            self.v0 = vec
            self.h = h
            self.since = 0
        return self.sigma * h <= g * (1.0 + 1e-9)


def pencil_growth_rate(solve, M, C, shift: float, v0=None):
    """Largest real part σ (1/s) among the eigenvalues λ of the quadratic pencil
    Q(λ) = λ²M + λC + K nearest the shift s, with its eigenvector (for a warm start), or
    (−inf, None) when no eigenvalue lies in the right half-plane disc |λ − s| < s.

    The linearised dynamics of a second-order scheme, M ÿ + C ẏ + K y = 0 (M singular
    where unknowns carry no inertia: the internal force and moment, the quaternion's
    norm), has the modes y e^{λt} with Q(λ) y = 0. Its companion linearisation
    A w = λ B w, A = [[0, I], [−K, −C]], B = diag(I, M), w = (y, λy) (Tisseur &
    Meerbergen, SIAM Rev. 43, 2001, § 3.4) is shifted and inverted with one
    factorisation of Q(s): (A − sB)⁻¹B w = θ w with θ = 1/(λ − s), and
    (A − sB)⁻¹B (x1, x2) = (u1, x1 + s u1), u1 = −Q(s)⁻¹(M x2 + (C + sM) x1). The λ
    in the disc are those with |θ| > 1/s; undamped oscillations (λ = ±iω) and damped
    modes lie outside it, the constraints' infinite eigenvalues have θ = 0, so a few
    Arnoldi iterations on the largest |θ| (scipy's ARPACK ``eigs``, as
    :func:`growth_rate`) find a growing mode. The second half of w is taken in units of
    s (x2 = λy/s) so that both halves are of one size.

    Parameters
    ----------
    solve : callable, b (n,) -> Q(s)⁻¹ b (n,)
    M, C : (n, n) sparse matrices (or anything with ``@``), in the columns' scales of
        ``solve``
    shift : float, 1/s (> 0)
    v0 : (2n,) start vector or None (a fixed one)

    Returns
    -------
    (sigma, vector): σ in 1/s (−inf when none is found), the eigenvector (2n,).
    """
    from scipy.sparse.linalg import ArpackNoConvergence, LinearOperator, eigs

    n = M.shape[0]
    s = float(shift)

    def apply(z):
        z = np.real(z)
        x1, x2 = z[:n], s * z[n:]
        u1 = -solve(M @ x2 + C @ x1 + s * (M @ x1))
        return np.concatenate([u1, (x1 + s * u1) / s])

    op = LinearOperator((2 * n, 2 * n), matvec=apply, dtype=float)
    if v0 is None:
        v0 = np.random.default_rng(0).standard_normal(2 * n)
    try:
        mu, vec = eigs(op, k=3, which="LM", ncv=min(12, 2 * n - 1), tol=1e-2, maxiter=5,
                       v0=v0)
    except ArpackNoConvergence as exc:
        mu, vec = exc.eigenvalues, exc.eigenvectors
    if mu is None or len(mu) == 0:
        return -math.inf, None
    mu = np.asarray(mu)
    big = np.abs(mu) > (1.0 + 1e-6) / s
    if not np.any(big):
        return -math.inf, np.real(vec[:, 0])
    lam = s + 1.0 / mu[big]
    j = int(np.argmax(lam.real))
    return float(lam.real[j]), np.real(vec[:, np.flatnonzero(big)[j]])
