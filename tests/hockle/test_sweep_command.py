"""hockle sweep: a --set with one value is a fixed override of every member, not an axis."""
from __future__ import annotations

import copy
import json

import pytest

from rodcases import tiny_spec
from hockle.sweep_command import split_fixed

BASE = tiny_spec("sweep-base", n_segments=6, dt=0.1, t_end=0.2)
FORCE = "boundary.end.translation.2.force"


def test_split_fixed():
    varied, fixed = split_fixed({FORCE: [0, 1, 2], "numerics.n_segments": [100]})
    assert varied == {FORCE: [0, 1, 2]} and fixed == {"numerics.n_segments": 100}
    # nothing varied: the one-valued paths stay (a sweep of one member)
    assert split_fixed({"numerics.n_segments": [100]}) == ({"numerics.n_segments": [100]}, {})


def test_one_valued_set_is_not_an_axis(tmp_path, capsys):
    """The README's sweep: three end forces at a given resolution; the combined file has
    one axis (the force), and every member ran at the fixed number of segments."""
    from hockle.cli import main
    from hockle.io import open_result

    path = tmp_path / "base.json"
    path.write_text(json.dumps(copy.deepcopy(BASE)))
    out = tmp_path / "sweep.nc"
    code = main(["sweep", str(path), "--set", f"{FORCE}=0,0.5", "--set",
                 "numerics.n_segments=8", "--workers", "1", "-o", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured
    assert "numerics.n_segments = 8" in captured.err
    ds = open_result(out)
    assert FORCE in ds.dims and "numerics.n_segments" not in ds.dims
    assert [d for d in ds["energy_total"].dims if d != "time"] == [FORCE]
    assert json.loads(ds.attrs["hockle_first_member_case"])["numerics"]["n_segments"] == 8
    code = main(["sweep", str(path), "--set", f"{FORCE}=0,1", "--set",
                 "boundary.nowhere.3=1", "--workers", "1", "-q", "-o", str(tmp_path / "x.nc")])
    assert code == 2 and "parameters.boundary.nowhere.3" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["--timeout", "S"], ["--poll", "S"]])
def test_sweep_help_names_units(argv, capsys):
    from hockle.cli import main

    with pytest.raises(SystemExit):
        main(["sweep", "--help"])
    text = capsys.readouterr().out
    assert " ".join(argv) in text and "seconds" in text
