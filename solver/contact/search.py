"""The contact candidate search of a run: a Verlet list over the blocked k-d tree.

Candidates (node pairs that may touch) are searched within tolerance + skin of the old
positions and kept over the following steps while no node has moved more than half the
skin from where they were searched (a Verlet list: Verlet, Phys. Rev. 159 (1967) 98-103);
every pair within the tolerance is then among them, so neither a new search nor the
coverage check after Newton is needed (docs/contact.md § 2). The search itself (the O(N)
pre-test, the blocked k-d tree, the runs) is :meth:`solver.contact.SelfContact.search`.
"""
from __future__ import annotations

import numpy as np

from .geometry import max_distance

__all__ = ["CandidateSearch"]


class CandidateSearch:
    """The kept candidates of a run's self-contact and the rule that keeps them.

    Parameters
    ----------
    contact : solver.contact.SelfContact
    diameter : (N+1,) array, m
        The rod's diameters (the skin is a share of tolerance − D_max).
    """

    #: the search's skin, a share of ``tolerance − D_max`` (m). Half: the seed example
    #: spends 4.2 % of its run searching against 6.4 % with a quarter and runs 1.08×
    #: faster (3810 against 3894 Newton iterations, the same events; its writhe 0.838 %
    #: off the converged reference against 0.852 %), PyElastica's plectoneme at N = 100
    #: 1.06× faster, at N = 20 (all pairs searched at once) 0.97× (docs/contact.md § 2,
    #: "Candidates")
    VERLET_SKIN = 0.5

    def __init__(self, contact, diameter):
        self.contact = contact
        self.diameter = diameter
        #: (candidates or None, the positions (N+1, 3) they were searched at) or None
        self.verlet = None
        self._skin_m = None

    def reset(self) -> None:
        """Forget the kept candidates and the skin, so that the next step searches anew
        with the present :attr:`VERLET_SKIN` (a run restored from a snapshot whose skin
        was another). Raises nothing."""
        self.verlet = None
        self._skin_m = None

    def search(self, positions, R, reach):
        """Contact candidates near the given positions (N+1, 3) and rotations (N+1, 3, 3)
        within tolerance + reach (m), or None when none is possible (the O(N) pre-test
        skips the k-d tree) or none is found (:meth:`SelfContact.search`)."""
        return self.contact.search(positions, R[:, :, 2], reach)

    def skin(self) -> float:
        """The search skin (m): VERLET_SKIN × (tolerance − D_max)."""
        skin = self._skin_m
        if skin is None:
            skin = self._skin_m = self.VERLET_SKIN * (
                self.contact.tolerance - float(np.max(self.diameter)))
        return skin

    def covers(self, positions) -> bool:
        """Whether the kept candidates (:attr:`verlet`) hold every pair within the
        tolerance at these positions (N+1, 3): no node more than half the skin from where
        they were searched."""
        if self.verlet is None:
            return False
        return max_distance(positions, self.verlet[1]) <= 0.5 * self.skin()

    def candidates(self, r_old, R_old, r_new, R_new):
        """Candidates for a step from the old positions r_old (N+1, 3) with rotations
        R_old (N+1, 3, 3) to those the Newton start predicts (r_new, R_new): the kept ones
        while they cover both, else node pairs within tolerance + skin of the old
        positions (and of the predicted ones, when those lie more than half the skin
        away). Pairs that come within the tolerance beyond that are added by the coverage
        check after Newton (:meth:`solver.step_problem.StepProblem.solve`), and the step
        is solved again. ``R_old`` may be a callable returning the rotations (they are
        needed only for a new search)."""
        finite = bool(np.all(np.isfinite(r_new)))
        if self.covers(r_old) and (not finite or self.covers(r_new)):
            return self.verlet[0]
        skin = self.skin()
        cand = self.search(r_old, R_old() if callable(R_old) else R_old, skin)
        self.verlet = (cand, r_old)
        if finite and not self.covers(r_new):
            new = self.search(r_new, R_new, skin)
            if new is not None:
                cand = new if cand is None else self.contact.merge(cand, new)
        return cand
