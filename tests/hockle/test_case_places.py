"""Where a case file's errors are: the CLI prints each error's line and column in the file
(solver.case_source, the dashboard's way of finding a field), a syntax error's own place,
and a number written with its unit is refused echoing the text (docs/case-spec.md,
"Errors")."""
from __future__ import annotations

from pathlib import Path

from hockle.cli import main
from solver.case_source import field_position, where

CASES = Path(__file__).resolve().parents[2] / "cases"


def _write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_field_positions_in_yaml_and_json():
    """A scalar's own line and column; a mapping's key where the path ends at it or goes
    on past what the file writes; a condition written without its list is item 0."""
    text = (CASES / "goyal-writhing.yaml").read_text()
    assert field_position(text, "rod.youngs_modulus") == (8, 19)
    assert field_position(text, "rod.diameter.value[2]") == (13, 25)
    assert field_position(text, "rod.diameter") == (11, 3)
    assert field_position(text, "numerics.colour") == (46, 1)            # not written
    assert field_position(text, "boundary.end.translation[2][0].until") == (32, 58)
    assert field_position(text, "boundary.start.translation[0][0].velocity") == (26, 30)
    assert field_position(text, "") is None and field_position(text, "nope") is None
    json_text = '{\n  "rod": {\n    "density": "1500 kg/m3"\n  }\n}'
    assert where("c.json", json_text, "rod.density") == 'c.json:3:16: "density": "1500 kg/m3"'


def test_errors_carry_their_line_and_column_and_a_text_value_is_echoed(tmp_path, capsys):
    """The CLI's errors say where in the file, as the dashboard's do: the value's line
    and column under each error; a number written with its unit is refused echoing the
    text, saying values are SI numbers and what to write."""
    text = (CASES / "goyal-writhing.yaml").read_text().replace(
        "density: 1500.0 ", 'density: "1500 kg/m3"')
    path = _write(tmp_path, "unit.yaml", text)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[1] == ("rod.density: Input should be a number or a table/profile mapping, not "
                      "the text '1500 kg/m3': case values are plain numbers in SI units (m, s, "
                      "kg, N, Pa, rad), written without a unit: write 1500")
    assert err[2] == f'  at {path}:10:12: density: "1500 kg/m3"                  # Table 1'
    mpa = _write(tmp_path, "mpa.json", '{"schema_version": 1, "name": "x", "rod": {\n'
                 '  "length": 1, "youngs_modulus": "12.5 MPa"}}')
    assert main(["validate", str(mpa)]) == 2
    err = capsys.readouterr().err.splitlines()
    line = next(k for k, e in enumerate(err) if e.startswith("rod.youngs_modulus: "))
    assert err[line].endswith("12.5 MPa is 1.25e+07 in SI, so write 1.25e+07")
    assert err[line + 1].startswith(f"  at {mpa}:2:34: ")
    # a syntax error, at its line and column
    broken = _write(tmp_path, "broken.yaml", "schema_version: 1\nname: x\nrod: {length: 1\n")
    assert main(["validate", str(broken)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith(f"hockle: invalid case {broken}: YAML syntax error at line 4, "
                             "column 1: expected ',' or '}'")
    assert err[1] == f"  at {broken}:4:1: "
