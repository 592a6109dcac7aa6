"""Every command given a file of the wrong kind (issue 80): a branch where a run is expected,
a run or a sweep where a branch or a case is, a case file or any other file where a result
is: one line on stderr saying what the file is, a non-zero exit, no traceback.

The files are real: a tiny run, a tiny continuation and a tiny sweep written by the
commands themselves. Every command of the parser is classified below (what its first
argument is), so a new command must be added here to pass."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import xarray as xr
import yaml

from rodcases import tiny_spec

ROOT = Path(__file__).resolve().parents[2]

#: the first argument of each command, and the files it takes
TAKES_RESULT = {"plot": ("run", "branch", "sweep"), "animate": ("run",),
                "export": ("run", "branch")}
TAKES_CASE = ("validate", "run", "continue", "sweep", "submit")
TAKES_NO_FILE = ("serve", "worker", "db")
#: what each command needs besides its file (to get past the parser to the file)
EXTRA = {"continue": ["--parameter", "boundary.end.translation.2.force", "--to", "-1"],
         "sweep": ["--set", "numerics.dt=0.01,0.02", "--workers", "1"],
         "submit": ["--url", "http://127.0.0.1:9"]}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """One file of every kind: a run, a branch, a sweep, a case, a NetCDF file that is not
    hockle's, a text file."""
    from hockle.cli import main

    d = tmp_path_factory.mktemp("kinds")
    case = tiny_spec("kinds", n_segments=8, dt=0.01, t_end=0.02)
    case["boundary"]["end"]["translation"][2] = {"force": -0.5}
    (d / "case.yaml").write_text(yaml.safe_dump(case))
    out = {"case": d / "case.yaml", "run": d / "run.nc", "branch": d / "branch.nc",
           "sweep": d / "sweep.nc", "foreign": d / "foreign.nc", "text": d / "notes.txt"}
    assert main(["run", str(out["case"]), "-o", str(out["run"]), "-q"]) == 0
    assert main(["continue", str(out["case"]), "--parameter", "boundary.end.translation.2.force",
                 "--to", "-1", "--max-points", "4", "-o", str(out["branch"]), "-q"]) == 0
    assert main(["sweep", str(out["case"]), "--set", "numerics.dt=0.01,0.02", "--workers", "1",
                 "-o", str(out["sweep"]), "-q"]) == 0
    xr.Dataset({"temperature": ("x", [1.0, 2.0])}).to_netcdf(out["foreign"])
    out["text"].write_text("not a result\n")
    return out


def _wrong_kinds(command: str) -> list[str]:
    if command in TAKES_RESULT:
        return [k for k in ("run", "branch", "sweep", "case", "foreign", "text")
                if k not in TAKES_RESULT[command]]
    return ["run", "branch", "sweep"]


def test_every_command_is_classified():
    from hockle.cli import build_parser

    parser, _ = build_parser()
    commands = set(parser._subparsers._group_actions[0].choices)      # noqa: SLF001
    assert commands == set(TAKES_RESULT) | set(TAKES_CASE) | set(TAKES_NO_FILE)


@pytest.mark.parametrize("command", [*TAKES_RESULT, *TAKES_CASE])
def test_a_file_of_the_wrong_kind_ends_in_one_line(command, files, tmp_path, capsys,
                                                   monkeypatch):
    from hockle.cli import main

    monkeypatch.chdir(tmp_path)                     # default outputs land here
    for kind in _wrong_kinds(command):
        path = files[kind]
        argv = [command, str(path), *EXTRA.get(command, [])]
        code = main(argv)
        captured = capsys.readouterr()
        err = captured.err.strip()
        assert code not in (0, None), (argv, captured)
        assert "Traceback" not in captured.err + captured.out, argv
        assert len(err.splitlines()) == 1, (argv, captured.err)
        assert err.startswith(f"hockle {command}: ") or err.startswith("hockle: "), err
        assert str(path) in err, (argv, err)
        if kind in ("run", "branch", "sweep") and command in TAKES_CASE:
            assert "is a result file" in err, err
        if kind == "branch":
            assert "branch" in err, err
        if kind == "sweep" and command in TAKES_RESULT:
            assert "sweep" in err, err


def test_a_start_from_a_branch_or_a_sweep_is_refused_naming_the_field(files, tmp_path, capsys):
    from hockle.cli import main

    for kind in ("branch", "sweep", "text"):
        case = yaml.safe_load(files["case"].read_text())
        case["initial"] = {"from_result": {"file": str(files[kind]), "time": 0.0}}
        path = tmp_path / f"from_{kind}.yaml"
        path.write_text(yaml.safe_dump(case))
        assert main(["run", str(path), "-o", str(tmp_path / "x.nc"), "-q"]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "initial.from_result.file" in err, err
        if kind != "text":
            assert kind in err and ("not a run" in err or "not a single run" in err), err


def test_from_a_shell_no_traceback(files):
    """The installed entry point (python -m hockle), as a user types it."""
    for argv in (["animate", str(files["branch"])], ["export", str(files["sweep"])],
                 ["plot", str(files["case"])], ["validate", str(files["branch"])]):
        done = subprocess.run([sys.executable, "-m", "hockle", *argv], capture_output=True,
                              text=True, cwd=ROOT, timeout=300)
        assert done.returncode == 2, (argv, done.stderr)
        assert "Traceback" not in done.stderr and len(done.stderr.strip().splitlines()) == 1, \
            (argv, done.stderr)
