"""benchmarks/compare_results.py: the bit-for-bit verdict and, with ``--largest``, how far
one result lies from another over a window of output times."""
from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from benchmarks.compare_results import differences, largest_differences, main


def _result(path, shift=0.0, df=0.0):
    t = np.array([0.0, 0.5, 1.0, 1.5])
    pos = np.zeros((4, 3, 3))
    pos[:, :, 0] = np.arange(3)                    # three nodes on the x axis
    pos[2:, 1] += [shift * 0.6, shift * 0.8, 0.0]   # node 1 moved by |shift| from t = 1 s
    f = np.ones((4, 3, 3)) * 2.0
    f[3, 0, 2] += df
    xr.Dataset({"position": (("time", "s", "component"), pos),
                "f": (("time", "s", "component"), f),
                "writhe": ("time", [0.0, 0.1, 0.2, 0.4])},
               coords={"time": t}).to_netcdf(path)
    return path


def test_the_largest_difference_is_a_distance_within_the_window(tmp_path):
    """Node 1 moved 5 mm (3 along x, 4 along y) from t = 1 s: over 0-0.5 s nothing
    differs, over 0-1.5 s the position's largest difference is the 5-mm distance, over
    the largest |position| (2 m); f differs by 0.1 N in one component of a vector of
    magnitude √12 N at t = 1.5 s only."""
    a = _result(tmp_path / "a.nc")
    b = _result(tmp_path / "b.nc", shift=0.005, df=0.1)
    early = largest_differences(a, b, 0.0, 0.5, ["position", "f", "writhe"])
    assert early["position"] == (0.0, 0.0) and early["f"] == (0.0, 0.0)
    whole = largest_differences(a, b, 0.0, 1.5, ["position", "f"])
    assert whole["position"][0] == pytest.approx(0.005)
    assert whole["position"][1] == pytest.approx(0.005 / 2.0)
    assert whole["f"][0] == pytest.approx(0.1)
    assert whole["f"][1] == pytest.approx(0.1 / np.sqrt(12.0))
    assert differences(a, b) and not differences(a, a)


def test_the_command_prints_each_window(tmp_path, capsys):
    a = _result(tmp_path / "a.nc")
    b = _result(tmp_path / "b.nc", shift=0.005)
    assert main([str(a), str(b), "--largest", "0:0.5,1:1.5", "--fields", "position"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("0-0.5 s: position 0 ")
    assert lines[1].startswith("1-1.5 s: position 0.005 (2.50e-03 of its largest)")
