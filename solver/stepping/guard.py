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

from ..banded import BlockLU
from . import growth_rate

__all__ = ["GrowthGuard"]


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
        (:class:`solver.scheme.RodSystem`, set up for the step): False when the fastest
        growth rate σ of the linearised dynamics has σh > ``limit`` (such a step would
        damp the growing mode instead of following it). σ is estimated
        (:func:`solver.stepping.growth_rate`, shift 2g/h, which finds every σ up to 4g/h;
        and 16g/h as well when h is more than twice the largest step checked so far)
        every GUARD_EVERY accepted steps (every 4 GUARD_EVERY while the last check found
        σh < g/4), at every step longer than a tenth of the bending time scale
        L²√(ρA/EJ) (a run of a few long steps would otherwise see one check: the
        stability map's twisted rod at Δt = 0.3 s buckles after its fifth step), and
        whenever h exceeds twice the step of the last
        check (below that the last check's disc covers σ = g/h); in between the last
        estimate is used. Not run for steps with contact candidates (their Jacobian is not
        banded)."""
        g = self.limit
        # far from the limit (σh < g/4 at the last check) a check every 4·GUARD_EVERY
        every = self.GUARD_EVERY * (4 if self.sigma * self.h < 0.25 * g else 1)
        if (math.isnan(self.sigma) or self.since >= every
                or h > 2.0 * self.h or h > 0.1 * system.tc):
            if self.layout is None:
                self.layout = BlockLU(system.n_cells)
            sigma, vec = growth_rate(system, Y, 2.0 * g / h, self.layout, self.v0)
            # further out (16g/h) at new largest steps, and when a growth known from the
            # last check is not in the near disc any more: under a rising load σ grows
            # past 4g/h rather than vanishing (the stability map's twisted rod at Δt =
            # 0.3 s: σ = 2.2 s⁻¹, then none in (0, 14), then 21 s⁻¹ one step later)
            if h > 2.0 * self.h_max or (not sigma > 0.0 and self.sigma > 0.0):
                far, _ = growth_rate(system, Y, 16.0 * g / h, self.layout)
                sigma = max(sigma, far)
                self.h_max = max(self.h_max, h)
            self.sigma = max(sigma, 0.0)
            self.v0 = vec
            self.h = h
            self.since = 0
        return self.sigma * h <= g * (1.0 + 1e-9)
