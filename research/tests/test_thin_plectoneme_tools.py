"""The thin-rod plectoneme benchmark's set-up and comparison (research/thin_plectoneme.py):
the case is PyElastica's plectoneme with D = 1 cm and a 2D contact tolerance, built without
changing the comparison module's own constants; the writhe error is the largest difference
after a time, relative to the reference's largest |Wr| there. The benchmark's solver runs
are not repeated here."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks import pyelastica_compare as pc
from research import thin_plectoneme as tp


def test_thin_case_is_the_plectoneme_with_a_one_centimetre_rod():
    diameter, contact = pc.DIAMETER, dict(pc.CONTACT)
    case = tp.thin_case(200, 0.02, 1.0)
    assert case.rod.diameter == pytest.approx(0.01)
    assert case.contact.tolerance == pytest.approx(0.02)
    assert case.numerics.n_segments == 200 and case.numerics.dt == pytest.approx(0.02)
    # the same material and loads as the 5-cm case
    wide = pc.hockle_plectoneme_case(200, 0.02, 1.0)
    assert case.rod.density == pytest.approx(wide.rod.density)
    assert case.contact.k1 == pytest.approx(wide.contact.k1)
    assert wide.rod.diameter == pytest.approx(0.05)
    # the comparison module's constants are left as they were
    assert pc.DIAMETER == diameter and pc.CONTACT == contact


def test_writhe_error_is_relative_to_the_reference_after_the_given_time():
    t = np.linspace(0.0, 10.0, 101)
    ref = {"t": t, "writhe": np.where(t >= 5.0, 2.0, 0.0)}
    run = {"t": t, "writhe": ref["writhe"] + np.where(t >= 8.0, 0.1, 0.0)
           + np.where(t < 5.0, 1.0, 0.0)}           # before 5 s: ignored
    assert tp.writhe_error(run, ref, 5.0) == pytest.approx(0.05)
    assert tp.writhe_error(ref, ref, 5.0) == 0.0
