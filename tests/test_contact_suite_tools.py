"""The contact suite's decomposition of the contact cost (benchmarks/contact_suite.py):
steps per simulated second, Newton iterations per step and wall per iteration, on
attempts with known answers, and the table cell that prints them. The suite's runs are
not repeated here."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import contact_suite as cs  # noqa: E402


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
