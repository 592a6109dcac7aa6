"""The peer comparison's own machinery (benchmarks/peer_compare.py), without PyElastica:
the Morison drag written for PyElastica against hockle's drag kernel, the writhe-history
error, the step that keeps outputs on the common grid, and the counting rule of a setting
and its refinement. The runs themselves are the benchmark's (its ``--quick`` mode is the
smoke test)."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks import peer_compare as peer
from solver.loads import _drag_kernel


def test_pyelastica_morison_matches_hockle_drag_kernel_on_a_bent_rod():
    # nodes on a helix; hockle's kernel works in the body frame with a3 the tangent, so
    # rotate each node's velocity into a frame whose third axis is the same tangent
    n = 12
    s = np.linspace(0.0, 1.0, n + 1)
    x = np.stack([0.1 * np.cos(3 * s), 0.1 * np.sin(3 * s), s])            # (3, n+1)
    rng = np.random.default_rng(4)
    v = rng.normal(size=(3, n + 1))
    w = peer.nodal_lengths(n)
    cn, ct = 0.7, 0.3
    out = np.zeros((3, n + 1))
    peer._morison_into(x, v, w, cn, ct, np.zeros(3), out)
    for i in range(n + 1):
        a, b = max(i - 1, 0), min(i + 1, n)
        t = (x[:, b] - x[:, a]) / np.linalg.norm(x[:, b] - x[:, a])
        e1 = np.cross(t, [1.0, 0.0, 0.0])
        e1 /= np.linalg.norm(e1)
        R = np.stack([e1, np.cross(t, e1), t], axis=1)        # body -> global
        vb = (R.T @ v[:, i])[None, :]
        bb = np.zeros((1, 3))
        _drag_kernel(vb, np.array([cn]), np.array([ct]), bb, np.zeros((1, 3, 3)), False)
        np.testing.assert_allclose(out[:, i], w[i] * (R @ bb[0]), rtol=1e-12, atol=1e-15)


def test_pyelastica_morison_adds_the_constant_force_times_nodal_length():
    n = 4
    x = np.stack([np.zeros(n + 1), np.zeros(n + 1), np.linspace(0, 1, n + 1)])
    out = np.ones((3, n + 1))
    peer._morison_into(x, np.zeros((3, n + 1)), peer.nodal_lengths(n), 1.0, 1.0,
                       np.array([2.0, 0.0, -1.0]), out)
    assert out[0].tolist() == pytest.approx([1.25, 1.5, 1.5, 1.5, 1.25])
    assert out[2].tolist() == pytest.approx([0.875, 0.75, 0.75, 0.75, 0.875])


def test_writhe_error_is_the_relative_l1_norm_and_catches_a_time_shift():
    t = np.arange(0.0, 10.0 + 1e-9, 0.02)
    ref = np.where(t < 5.0, 0.0, 1.0)
    assert peer.wr_error(t, ref, t, ref) == 0.0
    # a step 0.1 s late: error area 0.1 over ∫|ref| = 5
    late = np.where(t < 5.1 - 1e-9, 0.0, 1.0)
    assert peer.wr_error(t, late, t, ref) == pytest.approx(0.1 / 5.0, rel=0.02)
    # coarser outputs are interpolated onto the reference's times
    tc = t[::5]
    assert peer.wr_error(tc, 2.0 * np.ones_like(tc), t, np.ones_like(t)) == pytest.approx(1.0)
    # a run that stopped early or went non-finite has no error to give
    assert np.isnan(peer.wr_error(t[:100], ref[:100], t, ref))
    bad = ref.copy()
    bad[3] = np.nan
    assert np.isnan(peer.wr_error(t, bad, t, ref))


@pytest.mark.parametrize("n, ratio", [(25, 0.011), (50, 0.015), (100, 0.0055), (200, 0.011)])
def test_pyelastica_step_divides_the_output_interval_and_is_not_above_nominal(n, ratio):
    dt = peer.pyelastica_step(n, ratio)
    assert dt <= ratio * peer.pc.LENGTH / n * (1 + 1e-12)
    assert dt > 0.9 * ratio * peer.pc.LENGTH / n
    k = peer.OUT_DT / dt
    assert k == pytest.approx(round(k), abs=1e-9)


def test_a_setting_counts_only_if_its_refinement_is_within_the_level_too():
    def run(code, a, b, e):
        return {"code": code, "a": a, "b": b, "err_self": e, "wall": a * 1.0 / b,
                "walls": [a * 1.0 / b]}
    data = {peer._key("hockle", 25, 0.05): run("hockle", 25, 0.05, 0.004),
            peer._key("hockle", 50, 0.025): run("hockle", 50, 0.025, 0.02),   # not monotone
            peer._key("hockle", 100, 0.0125): run("hockle", 100, 0.0125, 0.0),
            peer._key("PyElastica", 25, 0.011): run("PyElastica", 25, 0.011, 0.005),
            peer._key("PyElastica", 50, 0.011): run("PyElastica", 50, 0.011, 0.0)}
    assert not peer.counts(data, "hockle:25:0.05", 0.01, "err_self")      # 50 fails
    assert not peer.counts(data, "hockle:50:0.025", 0.01, "err_self")
    assert peer.counts(data, "PyElastica:25:0.011", 0.01, "err_self")
    assert not peer.counts(data, "PyElastica:25:0.011", 0.001, "err_self")
    refs = {"hockle": "hockle:100:0.0125", "PyElastica": "PyElastica:50:0.011"}
    r = peer.matched_ratios({k: {**d, "err_vs_hockle": d["err_self"],
                                 "err_vs_PyElastica": d["err_self"]}
                             for k, d in data.items()}, refs)
    assert r["err_self@0.01"]["hockle"] is None          # only the reference is within
    assert r["err_self@0.01"]["PyElastica"] == "PyElastica:25:0.011"
    assert r["err_self@0.01"]["ratio"] is None


def test_moordyn_case_matches_the_hockle_case_and_its_step_divides_the_outputs():
    from benchmarks import moordyn_compare as md
    text = md.moordyn_input(40, 0.002)
    line = next(x for x in text.splitlines() if x.startswith("cable "))
    d, m, ea, ba, ei, cd, ca, cdax, caax = map(float, line.split()[1:])
    case = md.hockle_case(40, 0.01, 1.0)
    assert d == case.rod.diameter and ei == pytest.approx(
        case.rod.youngs_modulus * np.pi * d**4 / 64, rel=1e-12)
    assert m == pytest.approx(case.rod.density * np.pi * d**2 / 4, rel=1e-12)
    assert (cd, ca, cdax, caax) == (case.fluid.drag_coefficient_normal,
                                    case.fluid.added_mass_coefficient,
                                    case.fluid.drag_coefficient_tangential, 0.0)
    dtm = float(next(x for x in text.splitlines() if x.endswith(" dtM")).split()[0])
    assert dtm == md.moordyn_step(40, 0.002) and dtm <= 0.002 * md.LENGTH / 40
    assert (md.OUT_DT / dtm) == pytest.approx(round(md.OUT_DT / dtm), abs=1e-9)


def test_moordyn_tip_error_is_the_mean_distance_over_the_length():
    from benchmarks import moordyn_compare as md
    t = np.arange(0.0, 1.0 + 1e-9, 0.02)
    ref = {"t": t, "tip": np.stack([np.cos(t), 0 * t, -np.sin(t)], 1)}
    run = {"t": t, "tip": ref["tip"] + [0.0, 0.003, 0.004]}
    assert md.tip_error(run, ref) == pytest.approx(0.005)
    assert np.isnan(md.tip_error({"t": t[:10], "tip": ref["tip"][:10]}, ref))
