"""Step control in one place: where steps must land, how a step restarts after a jump,
the local error of a step, the PI controller of Δt and the growth guard.

:class:`solver.simulation.RodRun` drives the steps; the rules it follows are here.

* **Breakpoints** (:func:`breakpoints`): the times at which the case changes (a
  distributed force switched on or off, a boundary condition's ``until``, the knots of
  a boundary table). Steps land on them exactly; the step that ends on one sees the
  loads' left limit, and the next step starts with a *consistent restart*.
* **Consistent restart** (:data:`RESTART_FRACTION`): at t = 0 and after every
  breakpoint one backward-Euler step of ε = RESTART_FRACTION·Δt. A BE step satisfies the
  equations at its new level, so it leaves the internal force f (an algebraic variable
  of the DAE) and Ẏ consistent with the loads and conditions now in force; its local
  error is O(ε²). Without it the generalized-α scheme starts from an inconsistent f and
  Ẏ and loses an order (Arnold & Brüls, Multibody Syst. Dyn. 18 (2007) 185-202, §3;
  measured in docs/numerics.md § 7).
* **Local error** (:class:`ErrorControl`): Milne's device. A polynomial predictor
  through the last accepted levels (three values, or two and the restart's Ẏ) has error
  Y'''·Π/6 (Π the product of the distances to its nodes); the generalized-α corrector
  has error C(ρ∞)·h³·Y''' (C = 1/12 at ρ∞ = 1, :func:`error_constant`). Their difference
  therefore gives the corrector's local error as (Y_c − Y_p)·C h³/(C h³ + Π/6)
  (Hairer, Nørsett & Wanner, *Solving ODEs I*, § III.7; the Newmark analogue is
  Zienkiewicz & Xie, Earthquake Eng. Struct. Dyn. 20 (1991) 871-887).
* **PI controller**: h_{n+1} = h_n·0.9·(1/e_n)^{0.3/k}·(e_{n−1}/e_n)^{0.4/k}, k = 3
  (Gustafsson, ACM TOMS 17 (1991) 533-554; Söderlind, ACM TOMS 29 (2003) 1-26).
* **Growth guard** (:func:`growth_rate`): the largest real part σ of the linearised
  dynamics' eigenvalues near the step's scale, by shift-invert Arnoldi on the converged
  step's Jacobian; a step with σΔt above ``numerics.growth_guard`` would suppress a
  growing mode (generalized-α with ρ∞ < 1 damps σΔt ≳ 2 to an amplification near 1) and
  is refused.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["breakpoints", "RESTART_FRACTION", "ErrorControl", "error_constant",
           "growth_rate"]

#: size of the backward-Euler restart step, as a fraction of the nominal Δt
RESTART_FRACTION = 1e-4


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


def breakpoints(case) -> np.ndarray:
    """Times (s) in (0, t_end) at which the case's loads or boundary conditions change.

    Collected: ``start`` and ``end`` of every distributed force with a non-zero value;
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
        times.append(float(df.start))
        if df.end is not None:
            times.append(float(df.end))
    for end in (case.boundary.start, case.boundary.end):
        for group in (end.translation, end.rotation):
            for conditions in group:
                for cond in conditions:
                    if cond.until is not None:
                        times.append(float(cond.until))
                    value = cond.value
                    if hasattr(value, "t"):
                        times.extend(_table_kinks(value.t, value.value))
    times = sorted(t for t in times if 0.0 < t < t_end * (1.0 - 1e-12))
    out = []
    for t in times:
        if not out or t > out[-1] * (1.0 + 1e-12) + 1e-300:
            out.append(t)
    return np.asarray(out, float)
