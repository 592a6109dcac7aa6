"""The seed-accuracy benchmark's comparison (benchmarks/seed_accuracy.py): event times by
interpolation between outputs and the writhe difference against a reference, on records
with known answers, and the ``--newton`` option it shares with contact_suite.py. The
solver runs of the benchmark are not repeated here."""
from __future__ import annotations

import pytest

from benchmarks import seed_accuracy as sa


def _records(ts, wrs, first_contact):
    return [{"t": t, "writhe": w, "contacts": int(t >= first_contact), "topology_error": 0.0,
             "min_surface_gap": 1e-3} for t, w in zip(ts, wrs)]


def test_events_interpolate_the_writhe_crossings_between_outputs():
    recs = _records([18.0, 18.1, 18.2, 18.3], [0.0, 0.4, 0.8, 1.2], 18.1)
    ev = sa.events(recs)
    assert ev["first_contact"] == 18.1
    assert ev["writhe_0_5"] == pytest.approx(18.125)      # 0.4 → 0.8 crosses 0.5 at ¼
    assert ev["writhe_1_0"] == pytest.approx(18.25)


def test_compare_gives_the_largest_writhe_difference_and_the_event_shifts():
    ts = [18.0, 18.1, 18.2, 18.3]
    ref = _records(ts, [0.0, 0.4, 0.8, 1.2], 18.1)
    run = _records(ts, [0.0, 0.4, 0.86, 1.2], 18.1)
    out = sa.compare(run, ref)
    assert out["writhe_max_abs_diff"] == pytest.approx(0.06)
    assert out["writhe_rel_diff"] == pytest.approx(0.06 / 1.2)
    # the run crosses 1.0 between 18.2 (0.86) and 18.3 (1.2), at 0.14/0.34 of that output step
    assert out["event_time_diffs_s"]["writhe_1_0"] == pytest.approx(
        18.2 + 0.1 * 0.14 / 0.34 - 18.25)
    assert out["event_time_diffs_s"]["first_contact"] == 0.0
    # an event the run never reaches compares as None
    late = sa.compare(_records(ts, [0.0, 0.1, 0.2, 0.3], 18.1), ref)
    assert late["event_time_diffs_s"]["writhe_0_5"] is None


def test_events_include_the_later_writhe_levels_and_none_where_not_reached():
    recs = _records([25.0, 25.1, 25.2, 25.3], [1.2, 1.4, 1.8, 1.9], 18.1)
    ev = sa.events(recs)
    assert ev["writhe_1_5"] == pytest.approx(25.125)      # 1.4 → 1.8 crosses 1.5 at ¼
    assert ev["writhe_2_0"] is None
    assert ev["writhe_1_0"] is None                       # already above 1 at the start


def test_compare_by_window_takes_each_windows_own_scale():
    ts = [18.0, 18.1, 18.2, 18.3]
    ref = _records(ts, [0.5, 1.0, 2.0, 2.0], 18.0)
    run = _records(ts, [0.51, 1.0, 2.0, 1.9], 18.0)
    out = sa.compare(run, ref, windows=[(18.0, 18.1), (18.2, 18.3), (19.0, 20.0)])
    assert out["by_window"]["18-18.1"] == pytest.approx(0.01 / 1.0)
    assert out["by_window"]["18.2-18.3"] == pytest.approx(0.1 / 2.0)
    assert out["by_window"]["19-20"] is None
    assert "by_window" not in sa.compare(run, ref)


def test_newton_option_sets_the_named_class_attributes_and_refuses_unknown_ones():
    """``--newton ATTR=VALUE`` (seed_accuracy.py, contact_suite.py) sets Newton's class
    attributes with their own types, and names an attribute Newton does not have."""
    from benchmarks.tuning import set_newton
    from solver.newton import NewtonSolver
    saved = NewtonSolver.CONTACT_RESIDUAL_FACTOR, NewtonSolver.GMRES_MAX
    try:
        got = set_newton("CONTACT_RESIDUAL_FACTOR=2,GMRES_MAX=7")
        assert got == {"CONTACT_RESIDUAL_FACTOR": 2.0, "GMRES_MAX": 7}
        assert NewtonSolver.CONTACT_RESIDUAL_FACTOR == 2.0
        assert NewtonSolver.GMRES_MAX == 7 and isinstance(NewtonSolver.GMRES_MAX, int)
        with pytest.raises(ValueError, match="NO_SUCH"):
            set_newton("NO_SUCH=1")
    finally:
        NewtonSolver.CONTACT_RESIDUAL_FACTOR, NewtonSolver.GMRES_MAX = saved


def test_variants_set_the_candidate_search_skin_on_its_own_class():
    """``VERLET_SKIN`` in a variant or ``--newton`` is the candidate search's attribute
    (benchmarks.tuning.OWNERS), set there and not on Newton."""
    from benchmarks.tuning import set_newton
    from solver.contact.search import CandidateSearch
    from solver.newton import NewtonSolver
    saved = CandidateSearch.VERLET_SKIN
    try:
        assert set_newton("VERLET_SKIN=0.5") == {"VERLET_SKIN": 0.5}
        assert CandidateSearch.VERLET_SKIN == 0.5 and not hasattr(NewtonSolver, "VERLET_SKIN")
    finally:
        CandidateSearch.VERLET_SKIN = saved


def test_candidate_search_reset_forgets_the_kept_candidates_and_the_skin():
    """After :meth:`CandidateSearch.reset` the skin follows the present VERLET_SKIN and
    nothing is covered until the next search (a replayed snapshot searches anew)."""
    import numpy as np
    from types import SimpleNamespace
    from solver.contact.search import CandidateSearch
    search = CandidateSearch(SimpleNamespace(tolerance=0.04), np.full(5, 0.02))
    r = np.zeros((5, 3))
    search.verlet = (None, r)
    assert search.skin() == pytest.approx(CandidateSearch.VERLET_SKIN * 0.02)
    assert search.covers(r)
    saved = CandidateSearch.VERLET_SKIN
    try:
        CandidateSearch.VERLET_SKIN = 2 * saved
        assert search.skin() == pytest.approx(saved * 0.02)  # kept until reset
        search.reset()
        assert search.verlet is None and not search.covers(r)
        assert search.skin() == pytest.approx(2 * saved * 0.02)
    finally:
        CandidateSearch.VERLET_SKIN = saved
