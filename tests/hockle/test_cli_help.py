"""The command line explains itself: every command has a description, no help text carries
reStructuredText markup, options with a time say their unit, and an unknown case field is
answered with the fields allowed there (as the API answers it)."""
from __future__ import annotations

import argparse
from pathlib import Path

import pytest
import yaml

from hockle.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[2]


def _subparsers():
    parser, _ = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return parser, action.choices


def test_every_command_described_without_markup():
    parser, commands = _subparsers()
    assert "``" not in parser.format_help()
    for name, sub in commands.items():
        text = sub.format_help()
        assert "``" not in text, name
        assert sub.description, f"hockle {name} has no description"


@pytest.mark.parametrize("command", ["submit", "sweep"])
def test_timeout_and_poll_say_their_unit(command):
    _, commands = _subparsers()
    text = " ".join(commands[command].format_help().split())
    assert "--timeout S" in text and "--poll S" in text
    assert "give up after S seconds" in text and "seconds between status polls (default 1)" in text


def test_metavars_agree():
    _, commands = _subparsers()
    for name in ("validate", "run", "submit"):
        assert "CASE" in commands[name].format_usage(), name
    for name in ("run", "submit"):
        assert "OUT.nc" in commands[name].format_usage(), name
    for name in ("submit", "sweep"):
        assert "--api-key KEY" in commands[name].format_usage(), name


def test_unknown_field_lists_the_allowed_ones(tmp_path, capsys):
    doc = yaml.safe_load((ROOT / "cases" / "goyal-writhing.yaml").read_text())
    doc["rod"]["colour"] = "red"
    path = tmp_path / "case.yaml"
    path.write_text(yaml.safe_dump(doc))
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    line = next(line for line in err.splitlines() if line.startswith("rod.colour:"))
    assert "unknown field" in line and "allowed here:" in line
    assert "youngs_modulus" in line and "diameter" in line
