"""The magnetic-tweezers protocol (docs/tweezers.md): its recognition from the case in a
result (solver.results.tweezers_protocol), its curves (tweezers_series: turns from the
case's tables, extension along the force, torque at the pulled end) and hockle plot's two
figures, on synthetic datasets whose curves are known by construction and on a tiny run."""
from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from rodcases import tiny_spec
from hockle.cli import main
from hockle.io import write_netcdf
from hockle.plots import plot_all, plot_tweezers, tweezers_units
from solver.case import Case
from solver.results import build_dataset, tweezers_protocol, tweezers_series

FORCE = 0.01                                        # N
SPIN = {"t": [0.0, 1.0], "value": [0.0, 4 * np.pi]}  # rad/s: ramped up over 1 s


def tweezers_spec(**numerics) -> dict:
    """The seed's cable (1 m, G = 5 MPa, D = 2 cm) in the tweezers form: s = 0 held in
    position and frame, s = L pulled along the axis by 0.01 N, its tangent held and turned
    about it by ``SPIN`` (2 turns in the first 2 s: 1 during the ramp, 2 per second
    after)."""
    spec = tiny_spec("tweezers", **({"n_segments": 10, "dt": 0.1, "t_end": 3.0} | numerics),
                     output={"fields": ["position", "topology", "reactions"]})
    spec["boundary"]["start"]["rotation"][2] = {"angular_velocity": 0}
    spec["boundary"]["end"] = {
        "translation": [{"force": 0}, {"force": 0}, {"force": FORCE}],
        "rotation": [{"angular_velocity": 0}, {"angular_velocity": 0},
                     {"angular_velocity": copy.deepcopy(SPIN)}]}
    return spec


TIMES = np.round(np.arange(0.0, 3.01, 0.1), 10)
S = np.linspace(0.0, 1.0, 11)
TURNS = np.where(TIMES <= 1.0, TIMES**2, 1.0 + 2.0 * (TIMES - 1.0))   # ∫ SPIN dt / 2π


def synthetic(spec=None, fields=("position", "reactions")):
    """A tweezers dataset: straight up to 2 turns, then 0.1 m shorter per turn; the torque
    rising by 0.05 N m per turn up to 2 turns, then flat at 0.1 N m (global z is the axis)."""
    spec = spec or tweezers_spec()
    height = np.where(TURNS <= 2.0, 1.0, 1.0 - 0.1 * (TURNS - 2.0))
    data = {}
    if "position" in fields:
        pos = np.zeros((TIMES.size, S.size, 3))
        pos[:, :, 2] = height[:, None] * S[None, :]
        data["position"] = pos
    if "reactions" in fields:
        moment = np.zeros((TIMES.size, 3))
        moment[:, 2] = 0.05 * np.minimum(TURNS, 2.0)
        data.update(reaction_moment_end=moment, reaction_moment_start=-moment,
                    reaction_force_end=np.tile([0.0, 0.0, FORCE], (TIMES.size, 1)),
                    reaction_force_start=np.tile([0.0, 0.0, -FORCE], (TIMES.size, 1)))
    return build_dataset(Case.model_validate(spec), S, TIMES, data, {}, "completed")


def test_turns_extension_and_torque_of_a_synthetic_run():
    series = tweezers_series(synthetic())
    assert series["force_end"] == "end" and series["force"] == FORCE
    assert series["axis"] == pytest.approx([0.0, 0.0, 1.0])
    assert series["turns"] == pytest.approx(TURNS, abs=1e-12)       # the table, exactly
    assert series["extension"][TURNS <= 2.0] == pytest.approx(1.0)
    assert series["extension"][-1] == pytest.approx(1.0 - 0.1 * (TURNS[-1] - 2.0))
    assert series["torque"][-1] == pytest.approx(0.1)
    gj = 5.0e6 * np.pi * 0.02**4 / 32
    assert series["twist_torque"] == pytest.approx(2 * np.pi * gj * TURNS)


def test_the_pulled_end_at_s0_reads_the_same_curves():
    """The mirror form: s = L held, s = 0 pulled and turned. Turns are the rotation of
    s = L less that of s = 0 (the linking number's sign), so turning s = 0 by +n gives
    −n; extension and torque keep their signs (the rod overwound in its own sense gives a
    positive torque)."""
    spec = tweezers_spec()
    b = spec["boundary"]
    b["start"], b["end"] = b["end"], b["start"]
    b["start"]["translation"][2] = {"force": FORCE}     # f3 > 0 is tension at either end
    ds = synthetic(spec)
    # the same rod seen from its other end: s = 0 is now the pulled end, at the top
    ds["reaction_moment_start"].values[:, 2] *= -1.0
    ds["position"].values[:] = ds["position"].values[:, ::-1, :]
    series = tweezers_series(ds)
    assert series["force_end"] == "start"
    assert series["axis"] == pytest.approx([0.0, 0.0, -1.0])
    assert series["turns"] == pytest.approx(-TURNS, abs=1e-12)
    assert series["extension"][0] == pytest.approx(-1.0)    # s = 0 above s = L: along −z
    assert series["torque"][-1] == pytest.approx(-0.1)


@pytest.mark.parametrize("change, why", [
    (lambda b: b["end"]["translation"].__setitem__(2, {"force": 0}), "no tension"),
    (lambda b: b["end"]["translation"].__setitem__(
        2, [{"force": FORCE, "until": 1.0}, {"velocity": 0}]), "the force switches"),
    (lambda b: b["end"]["rotation"].__setitem__(0, {"moment": 0}), "the bead tilts freely"),
    (lambda b: b["start"]["translation"].__setitem__(0, {"force": 0}), "the surface slides"),
    (lambda b: b["start"].__setitem__("frame", "global"), "a global-frame end"),
])
def test_what_is_not_the_tweezers_form(change, why):
    spec = tweezers_spec()
    change(spec["boundary"])
    case = Case.model_validate(spec)
    assert tweezers_protocol(case.model_dump(mode="json")) is None, why


def test_the_default_tiny_case_and_a_curved_start_are_not_tweezers_runs():
    assert tweezers_protocol(Case.model_validate(tiny_spec()).model_dump(mode="json")) is None
    spec = tweezers_spec()
    spec["initial"] = {"centreline": {"points": [[0, 0, 0], [0.1, 0, 0.5], [0, 0, 0.98]]}}
    assert tweezers_protocol(spec) is None


def test_the_two_figures_are_drawn_in_the_molecular_units_or_si(tmp_path):
    paths = plot_tweezers(synthetic(), tmp_path, stem="run")
    assert [p.name for p in paths] == ["run_extension.png", "run_torque.png"]
    for p in paths:
        data = p.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000
    assert tweezers_units(1.0)["torque"] == ("N m", 1.0)
    assert tweezers_units(2e-7) == {"extension": ("nm", 1e9), "torque": ("pN nm", 1e21),
                                    "force": ("pN", 1e12)}


def test_figures_without_their_variables_are_skipped_and_say_so(tmp_path):
    said = []
    assert plot_tweezers(synthetic(fields=()), tmp_path, on_skip=said.append) == []
    assert len(said) == 2
    assert "no 'position'" in said[0] and "output.fields: reactions" in said[1]
    said.clear()
    only = plot_tweezers(synthetic(fields=("position",)), tmp_path, stem="p",
                         on_skip=said.append)
    assert [p.name for p in only] == ["p_extension.png"] and len(said) == 1


def test_a_run_that_is_not_tweezers_draws_nothing_and_says_nothing(tmp_path):
    spec = tweezers_spec()
    spec["boundary"]["end"]["translation"][2] = {"force": 0}
    said = []
    assert plot_tweezers(synthetic(spec), tmp_path, on_skip=said.append) == []
    assert said == []
    names = [p.name for p in plot_all(synthetic(spec), tmp_path, on_skip=said.append)]
    assert not any("extension" in n or "torque" in n for n in names)


def test_hockle_plot_adds_the_two_figures_for_a_tweezers_result(tmp_path, capsys):
    nc = write_netcdf(synthetic(), tmp_path / "tw.nc")
    assert main(["plot", str(nc)]) == 0
    names = sorted(p.name for p in (tmp_path / "tw_plots").iterdir())
    assert "tw_extension.png" in names and "tw_torque.png" in names


def test_a_tiny_run_in_the_tweezers_form():
    """The seed's cable under 1 N turned 0.625 turns in 3 s (π/2 rad/s reached over 1 s),
    below the twisted rod's buckling torque under tension 2√(B F) (1.3 turns; more on
    this short rod): the turns are its linking number (to the scheme's end angles, 1e-5),
    the rod stays straight and at constant rate its torque is the straight rod's
    2π G J3 n / L (to 1e-3)."""
    from solver.simulation import integrate

    spec = tweezers_spec(dt=0.01)
    spec["boundary"]["end"]["translation"][2] = {"force": 1.0}
    spec["boundary"]["end"]["rotation"][2] = {
        "angular_velocity": {"t": [0.0, 1.0], "value": [0.0, np.pi / 2]}}
    ds = integrate(Case.model_validate(spec))
    assert ds.attrs["hockle_status"] == "completed"
    series = tweezers_series(ds)
    assert series["force"] == 1.0
    assert np.abs(series["turns"] - ds["linking_number"].values).max() < 1e-5
    assert series["turns"][-1] == pytest.approx(0.625)
    assert np.abs(series["extension"] - 1.0).max() < 1e-6
    late = ds["time"].values >= 1.5
    assert series["torque"][late] == pytest.approx(series["twist_torque"][late], rel=1e-3)


DNA_CASE = Path(__file__).resolve().parents[2] / "cases" / "dna-tweezers.yaml"
KT = 4.11e-21                                      # J at 25 °C


def _dna(t_end=None):
    case = Case.from_file(DNA_CASE)
    if t_end is not None:
        case = Case.model_validate(case.model_dump(mode="json") | {
            "numerics": case.model_dump(mode="json")["numerics"] | {"t_end": t_end}})
    return case


def test_the_dna_case_states_the_protocol_in_si_with_the_moduli_of_its_stiffnesses():
    """B = 50 nm kT = E π d⁴/64 and C = 100 nm kT = G π d⁴/32 at d = 2 nm (to 1e-4); it
    is a tweezers run pulled at s = L by 1 pN along +z."""
    case = _dna()
    d = case.rod.diameter
    assert case.rod.youngs_modulus * np.pi * d**4 / 64 == pytest.approx(50e-9 * KT, rel=1e-4)
    assert case.rod.shear_modulus * np.pi * d**4 / 32 == pytest.approx(100e-9 * KT, rel=1e-4)
    protocol = tweezers_protocol(case.model_dump(mode="json"))
    assert protocol["force_end"] == "end" and protocol["force"] == pytest.approx(1e-12)


def test_the_dna_case_before_it_buckles():
    """The case's first 2 ms (1.9 turns, below Greenhill's 2√(B F) = 28.7 pN nm at 2.2
    turns): straight at 200 nm, its torque the straight rod's 2π C n / L (to 1 %; the
    spin's Stokes moment ζ_r ω L is 0.014 pN nm) once the ramp is past."""
    from solver.simulation import integrate

    series = tweezers_series(integrate(_dna(2.0e-3)))
    assert series["turns"][-1] == pytest.approx(1.9)
    assert np.abs(series["extension"] - 2e-7).max() < 1e-12
    late = series["turns"] > 0.5
    assert series["torque"][late] == pytest.approx(series["twist_torque"][late], rel=1e-2)


@pytest.mark.slow
def test_the_dna_case_forms_a_plectoneme():
    """The whole case (about 40 s): it buckles near 2√(B F) (29.7 pN nm measured at 2.3
    turns), the loop wraps into a plectoneme held apart by contact (no strand passage:
    Tw + Wr = Lk, no closure passage), past 2.5 turns the torque stays on a plateau of
    6.6-6.9 pN nm and the extension falls by about 31 nm per turn (docs/tweezers.md)."""
    from solver.simulation import integrate

    ds = integrate(_dna())
    series = tweezers_series(ds)
    n, tq, ext = series["turns"], series["torque"] * 1e21, series["extension"] * 1e9
    peak = int(np.argmax(tq))
    assert 2.2 < n[peak] < 2.4 and 28.0 < tq[peak] < 31.0
    past = n >= 2.5
    assert 6.0 < tq[past].min() and tq[past].max() < 7.5
    slope = np.polyfit(n[past], ext[past], 1)[0]
    assert -36.0 < slope < -26.0
    assert float(ds["writhe"][-1]) > 2.5 and int(ds["contact_count"][-1]) > 0
    assert float(ds["topology_error"].max()) < 0.01
    assert int(ds["writhe_closure_passages"].max()) == 0
    # beside the two-phase theory with R from the simulated ply (benchmarks/
    # tweezers_plateau.py prints it): the extension per turn within 5 % (measured
    # 0.994), the torque plateau 6 % above the theory's M_p (measured 1.060)
    from benchmarks.tweezers_plateau import compare

    c = compare(ds, _dna())
    assert abs(c["extension_per_turn"] / c["theory_extension_per_turn"] - 1.0) < 0.05, c
    assert 1.0 < c["torque_mean"] / c["theory_torque"] < 1.1, c
