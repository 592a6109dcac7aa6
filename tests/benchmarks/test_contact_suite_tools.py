"""The contact suite's decomposition of the contact cost (benchmarks/contact_suite.py):
steps per simulated second, Newton iterations per step and wall per iteration, on
attempts with known answers, and the table cell that prints them. The suite's runs are
not repeated here."""
from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks import contact_suite as cs


def test_phase_factors_split_the_attempts_at_first_contact_and_multiply_to_the_wall():
    """Before contact (0-1 s) two accepted one-iteration steps of 10 ms; in contact
    (1-1.2 s) two accepted steps and one refused attempt: 7 iterations over 2 steps,
    0.2 s of attempts. The three ratios multiply to the ratio of the attempts' wall per
    simulated second (1 s/s against 0.02 s/s)."""
    attempts = [(0.0, True, 1, 0.01), (0.5, True, 1, 0.01), (1.0, True, 3, 0.09),
                (1.05, False, 2, 0.05), (1.1, True, 2, 0.06)]
    ph = cs.phase_factors(attempts, 1.0, 1.2)
    assert ph["before"] == pytest.approx({"steps_per_s": 2.0, "its_per_step": 1.0,
                                          "wall_per_it_ms": 10.0})
    assert ph["contact"]["steps_per_s"] == pytest.approx(10.0)
    assert ph["contact"]["its_per_step"] == pytest.approx(3.5)
    assert ph["contact"]["wall_per_it_ms"] == pytest.approx(200.0 / 7.0)
    steps, its, wall = ph["ratios"]
    assert steps * its * wall == pytest.approx((0.2 / 0.2) / (0.02 / 1.0))
    cell = cs._factors({"phases": ph})
    assert cell.startswith("5.0 × 3.5 (1.0 → 3.5) × 2.9 (10.00 → 28.57 ms)")


def test_phase_factors_without_steps_in_a_phase_give_nan_not_an_error():
    """A restart is no step: a phase of restarts alone has no iterations per step."""
    ph = cs.phase_factors([(0.0, False, 1, 0.01), (1.0, True, 2, 0.02)], 0.5, 1.5)
    assert math.isnan(ph["before"]["its_per_step"])
    assert math.isnan(ph["ratios"][1])
    assert cs._factors({}) == "–"


def test_window_injection_sums_the_errors_of_each_window_over_its_largest_energy():
    """Steps every 0.1 s; ε of +1 J in the steps ending at 0.3 and 0.4 s and −0.5 J at
    0.5 s, the energy 10 J but 15 J at 0.4 s: over windows of 0.2 s the largest net
    injection is the window (0.2, 0.4] s, 2 J over 15 J; over windows of 0.1 s the step
    at 0.3 s, 1 J over 10 J."""
    t = np.arange(1, 8) * 0.1
    eps = np.array([0.0, 0.0, 1.0, 1.0, -0.5, 0.0, 0.0])
    energy = np.array([10.0, 10.0, 10.0, 15.0, 10.0, 10.0, 10.0])
    share, at = cs.window_injection(t, eps, energy, 0.2 + 1e-9)
    assert share == pytest.approx(2.0 / 15.0) and at == pytest.approx(0.4)
    share, at = cs.window_injection(t, eps, energy, 0.1 - 1e-9)
    assert share == pytest.approx(0.1) and at == pytest.approx(0.3)
    assert np.isnan(cs.window_injection([], [], [], 0.2)[0])


def test_backward_euler_retries_carry_pyelasticas_plectoneme_through_its_tolerance_spread():
    """PyElastica's plectoneme (ρ∞ = 0.8, N = 25, Δt = 0.1 s, to 12 s) with Newton's
    tolerance ×1.1: with numerics.backward_euler_retry false the cut steps after refusals
    put energy in until the run fails (on a development host at 11.46 s, its energy
    40 J); with the default (true) the run completes with the energy of the runs that
    complete either way (18.6-19.4 J) and well under their 32-35 Newton iterations per
    nominal step (docs/contact.md § 3, "The step after a refusal")."""
    r = cs.run_case("pyelastica-0.8", cs.ENERGY_TOLERANCE, tolerance_scale=1.1)
    assert r["status"] == "completed", r["reason"]
    assert 18.5 < r["energy_final"] < 19.5
    assert r["energy_window"][0] < 0.04
    assert r["newton_per_step"] < 25.0
