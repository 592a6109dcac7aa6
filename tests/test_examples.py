"""The scripts in examples/ run as users run them (a fresh interpreter, from the repository
root) in their --quick mode, and print what their docstrings promise."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = {
    "seed_example.py": ["buckling onset: at t =", "first contact: at t =", "completed in"],
    "plectoneme.py": ["contacts", "completed at t = 10.0 s"],
    "sweep_threshold.py": ["tension (N)", "successful"],
    "custom_load_callback.py": ["finger + foundation: stopped", "writhe past half a turn"],
    "paraview_export.py": ["run.pvd:", "frame at t = 10 s: 41 points, point data"],
}


def test_every_example_is_tested():
    assert sorted(p.name for p in (ROOT / "examples").glob("*.py")) == sorted(EXAMPLES)


@pytest.mark.parametrize("script", sorted(EXAMPLES))
def test_example_runs_quick(script, tmp_path):
    done = subprocess.run([sys.executable, str(ROOT / "examples" / script), "--quick"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    for text in EXAMPLES[script]:
        assert text in done.stdout, done.stdout
