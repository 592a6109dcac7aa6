"""Plausibility warnings at validation (solver.plausibility): ten mistaken cases, each a
shipped case with one input in the wrong unit, are named by their warning; the shipped
cases have none; a failed run names the inputs it suspects; the CLI prints the warnings
with their place in the file, and a case's errors with theirs."""
from __future__ import annotations

import copy
from pathlib import Path

import pytest
import yaml

from hockle.cli import main
from solver.case import Case, _YamlLoader
from solver.plausibility import lowest_bending_period, plausibility_warnings, suspects

CASES = Path(__file__).resolve().parents[2] / "cases"


def shipped(name: str) -> dict:
    return yaml.load((CASES / f"{name}.yaml").read_text(), Loader=_YamlLoader)  # noqa: S506


def _set(doc: dict, path: str, value) -> dict:
    doc = copy.deepcopy(doc)
    *parents, last = path.split(".")
    node = doc
    for part in parents:
        node = node[int(part)] if part.isdigit() else node[part]
    node[int(last) if last.isdigit() else last] = value
    return doc


def _seed_in_mm() -> dict:
    """The seed's cable without contact, its lengths in mm: 1000 long, 20 thick."""
    doc = shipped("goyal-writhing")
    doc.pop("contact")
    doc["rod"]["length"] = 1000.0
    doc["rod"]["diameter"] = 20.0
    return doc


#: (what went wrong, the case, the warning that names it: (loc, type))
MISTAKES = [
    ("Young's modulus in MPa (1e6)", _set(shipped("goyal-writhing"), "rod.youngs_modulus", 12.5),
     ("rod.youngs_modulus", "implausible_modulus")),
    ("shear modulus in MPa (1e6)", _set(shipped("goyal-writhing"), "rod.shear_modulus", 5.0),
     ("rod.shear_modulus", "implausible_moduli_ratio")),
    ("Young's modulus in GPa (1e9)", _set(shipped("euler-column"), "rod.youngs_modulus", 0.2),
     ("rod.youngs_modulus", "implausible_modulus")),
    ("density in g/cm³ (1e3)", _set(shipped("goyal-writhing"), "rod.density", 1.5),
     ("rod.density", "implausible_density")),
    ("length in mm (1e3), the diameter profile in m",
     _set(shipped("goyal-writhing"), "rod.length", 1000.0), ("rod.diameter.s", "length_units")),
    ("all lengths in mm (1e3)", _seed_in_mm(), ("rod.diameter", "implausible_diameter")),
    ("diameter in cm (1e2)", _set(shipped("euler-column"), "rod.diameter", 0.5),
     ("rod.length", "not_slender")),
    ("Δt of 10 s on the seed rod", _set(shipped("goyal-writhing"), "numerics.dt", 10.0),
     ("numerics.dt", "dt_unresolved")),
    ("gravity in mm/s² (1e3)", _set(shipped("seabed-hockle"), "gravity", [0.0, 0.0, -9810.0]),
     ("gravity", "implausible_gravity")),
    ("compression in mN (1e3)",
     _set(shipped("euler-column"), "boundary.end.translation.2.force", -100.0),
     ("boundary.end.translation[2][0].force", "above_buckling_load")),
    ("tension in mN (1e3)",
     _set(shipped("goyal-writhing-tension"), "boundary.end.translation.2.0.force", 9100.0),
     ("boundary.end.translation[2][0].force", "strains_rod")),
    ("fluid density in g/m³ (1e3)", _set(shipped("goyal-writhing"), "fluid.density", 1e6),
     ("fluid.density", "implausible_density")),
]


@pytest.mark.parametrize("case_file", sorted(CASES.glob("*.yaml")), ids=lambda p: p.name)
def test_no_warning_on_the_shipped_cases(case_file):
    assert plausibility_warnings(Case.from_file(case_file)) == []


@pytest.mark.parametrize("what, doc, named", MISTAKES, ids=[m[0] for m in MISTAKES])
def test_a_mistaken_unit_is_named_by_its_warning(what, doc, named):
    """Each case validates (a warning is not an error) and is named by the warning for
    its mistake: the field, its number and the reason."""
    found = plausibility_warnings(Case.model_validate(doc))
    assert named in [(w["loc"], w["type"]) for w in found], found
    warning = next(w for w in found if (w["loc"], w["type"]) == named)
    assert any(ch.isdigit() for ch in warning["msg"])           # the number, compared
    assert suspects(Case.model_validate(doc)).startswith("inputs that look wrong")


def test_the_messages_give_the_number_and_the_unit_to_use():
    """12.5 Pa meant as MPa says so, with the value in Pa; a step of 10 s on the seed's
    rod names its slowest bending period, 1.62 s (pinned ends, water's added mass)."""
    e = plausibility_warnings(Case.model_validate(MISTAKES[0][1]))[0]["msg"]
    assert "12.5 Pa" in e and "given in MPa? 12.5 MPa is 1.25e+07 in SI" in e
    seed = Case.model_validate(shipped("goyal-writhing"))
    assert lowest_bending_period(seed) == pytest.approx(1.621, abs=1e-3)
    dt = plausibility_warnings(Case.model_validate(MISTAKES[7][1]))[0]["msg"]
    assert "a step of 10 s is 6.17 times the period of the rod's lowest bending mode (1.62 s" \
        in dt
    assert suspects(seed) is None


def test_a_failed_run_names_the_inputs_it_suspects():
    """The seed with rod.length 1000 (mm read as m; its diameter profile still over the
    first metre) ends in a failed Newton at 34.6 s: the message, and the partial result's
    hockle_message, end with the inputs that look wrong, the profile's stations and the
    segments 50 diameters long, where it said only "Newton did not converge"."""
    from solver.simulation import SolverDivergence, integrate

    case = Case.model_validate(MISTAKES[4][1])
    with pytest.raises(SolverDivergence) as info:
        integrate(case)
    message = str(info.value)
    assert "Newton did not converge" in message
    assert "inputs that look wrong and may be why: rod.diameter.s: " in message
    assert "numerics.ds: segments of 1 m are 50 diameters long" in message
    partial = info.value.partial
    assert partial.attrs["hockle_message"] == message
    assert partial.attrs["hockle_input_warnings"].startswith("rod.diameter.s: ")


# --------------------------------------------------------------------------- the CLI


def _write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_validate_prints_each_warning_at_its_place_and_succeeds(tmp_path, capsys):
    text = (CASES / "goyal-writhing.yaml").read_text().replace(
        "youngs_modulus: 1.25e7 ", "youngs_modulus: 12.5   ")
    path = _write(tmp_path, "mpa.yaml", text)
    assert main(["validate", str(path)]) == 0
    err = capsys.readouterr().err.splitlines()
    k = err.index(next(line for line in err if line.startswith(
        "hockle: warning: rod.youngs_modulus: a Young's modulus of 12.5 Pa")))
    assert err[k + 1].startswith(f"  at {path}:8:19: youngs_modulus: 12.5 ")
