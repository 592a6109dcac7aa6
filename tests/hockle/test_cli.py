"""Tests for the ``hockle`` command: validate, run, plot (docs/interfaces.md, "Command line")."""
from __future__ import annotations

import copy
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from rodcases import tiny_spec
from hockle.cli import main
from hockle.io import open_result, write_netcdf
from solver.case import Case
from solver.results import build_dataset

REPO = Path(__file__).resolve().parents[2]

# The tiny case of the brief: a straight rod twisted at its start end.
TINY = tiny_spec(output={"fields": ["v", "omega", "f", "kappa", "position", "orientation",
                                     "energies", "topology"]})


def write_case(path: Path, spec: dict) -> Path:
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


@pytest.fixture()
def tiny(tmp_path) -> Path:
    return write_case(tmp_path / "tiny.yaml", TINY)


# --------------------------------------------------------------------------- validate


def test_validate_good_case(tiny, capsys):
    assert main(["validate", str(tiny)]) == 0
    out = capsys.readouterr().out
    digest = Case.from_file(tiny).spec_hash()
    assert "tiny" in out and "9 grid points" in out and "5 steps" in out
    assert digest[:12] in out
    assert len(out.strip().splitlines()) == 1


def test_validate_bad_case_names_fields(tmp_path, capsys):
    spec = copy.deepcopy(TINY)
    spec["rod"]["diameter"] = -0.02
    spec["numerics"]["colour"] = "blue"
    bad = write_case(tmp_path / "bad.yaml", spec)
    assert main(["validate", str(bad)]) == 2
    captured = capsys.readouterr()
    err = captured.err
    lines = err.strip().splitlines()
    assert any(line.startswith("rod.diameter: ") for line in lines), err
    assert any(line.startswith("numerics.colour: ") for line in lines), err
    assert "Traceback" not in err + captured.out


def test_validate_says_how_far_a_curved_start_lies_and_advises_a_finer_grid(tmp_path, capsys):
    """A twisted curved start (a 1-m arc of radius 0.5 m, τ0 = 20 rad/m) on 40 segments
    lies 37 mm (1.9 diameters) off its centreline: validate prints the offset on stdout,
    and on stderr the advice naming numerics.n_segments; the exit status stays 0 (advice,
    not an error)."""
    from hockle.api import circular_arc

    spec = copy.deepcopy(TINY)
    spec["numerics"] = {"n_segments": 40, "dt": 0.01, "t_end": 0.05}
    spec["initial"] = {"centreline": circular_arc(spec["rod"]["length"], 0.5),
                       "twist_rate": 20.0}
    path = write_case(tmp_path / "curved.yaml", spec)
    assert main(["validate", str(path)]) == 0
    captured = capsys.readouterr()
    assert "start pose: within" in captured.out and "of initial.centreline" in captured.out
    assert captured.err.startswith("hockle: advice: initial.centreline: on 40 segments")
    assert "numerics.n_segments of about" in captured.err


def test_validate_missing_file(tmp_path, capsys):
    assert main(["validate", str(tmp_path / "nope.yaml")]) == 2
    assert "nope.yaml" in capsys.readouterr().err


# --------------------------------------------------------------------------- plot


def synthetic_result(tmp_path: Path, fields=("position", "energies", "topology")) -> Path:
    """A helix that winds up over time, written as a result file."""
    case = Case.model_validate(TINY)
    n_t, n = 12, 41
    s = np.linspace(0.0, 1.0, n)
    times = np.linspace(0.0, 1.1, n_t)
    data = {}
    if "position" in fields:
        pos = np.zeros((n_t, n, 3))
        for k, t in enumerate(times):
            amp = 0.1 * t
            pos[k, :, 0] = amp * np.cos(2 * np.pi * s)
            pos[k, :, 1] = amp * np.sin(2 * np.pi * s)
            pos[k, :, 2] = s * (1 - 0.2 * t)
        data["position"] = pos
    if "energies" in fields:
        data.update(
            energy_bending=times**2,
            energy_torsion=np.exp(-times),
            energy_kinetic=0.1 * times,
            energy_total=times**2 + np.exp(-times) + 0.1 * times,
        )
    if "topology" in fields:
        data.update(
            twist=4 - times,
            writhe=times,
            linking_number=np.full(n_t, 4.0),
            topology_error=np.full(n_t, 1e-9),
        )
    ds = build_dataset(case, s, times, data, {}, "completed")
    return write_netcdf(ds, tmp_path / "synthetic.nc")


def assert_png(path: Path) -> None:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    assert len(data) > 5000, path


def test_plot_writes_the_three_figures_next_to_the_file(tmp_path, capsys):
    nc = synthetic_result(tmp_path)
    assert main(["plot", str(nc)]) == 0
    out_dir = tmp_path / "synthetic_plots"
    names = sorted(p.name for p in out_dir.iterdir())
    assert names == [
        "synthetic_energies.png",
        "synthetic_snapshots.png",
        "synthetic_topology.png",
    ]
    for p in out_dir.iterdir():
        assert_png(p)
    printed = capsys.readouterr().out.split()
    assert sorted(Path(p).name for p in printed) == names


def test_plot_chosen_times_into_a_directory(tmp_path, capsys):
    nc = synthetic_result(tmp_path)
    out_dir = tmp_path / "figs"
    assert main(["plot", str(nc), "-o", str(out_dir), "--times", "0.2", "0.9", "50"]) == 0
    assert_png(out_dir / "synthetic_snapshots.png")
    assert "t = 50 s is outside" in capsys.readouterr().err


def test_snapshot_times_choice(tmp_path):
    from hockle.plots import snapshot_times

    ds = open_result(synthetic_result(tmp_path))
    stored = ds["time"].values
    # by default the events: the helix leaves its axis by a diameter (0.02 m) at 0.1 s,
    # its writhe reaches 1 at 1.0 s, the run ends at 1.1 s (tests/hockle/test_plots.py has more)
    default = snapshot_times(ds)
    assert default == [pytest.approx(0.1), pytest.approx(1.0), pytest.approx(1.1)]
    assert default[-1] == stored[-1]
    assert snapshot_times(ds, [0.31, 0.29]) == [pytest.approx(0.3)]


def test_plot_skips_figures_without_their_variables(tmp_path, capsys):
    nc = synthetic_result(tmp_path, fields=("energies",))
    assert main(["plot", str(nc)]) == 0
    err = capsys.readouterr().err
    assert "snapshots (Fig. 6) skipped" in err and "topology (Fig. 8) skipped" in err
    assert [p.name for p in (tmp_path / "synthetic_plots").iterdir()] == [
        "synthetic_energies.png"
    ]


def test_plot_nothing_to_draw_and_unreadable_file(tmp_path, capsys):
    nc = synthetic_result(tmp_path, fields=())
    assert main(["plot", str(nc)]) == 1
    assert "nothing to plot" in capsys.readouterr().err
    junk = tmp_path / "junk.nc"
    junk.write_text("not a netcdf file")
    assert main(["plot", str(junk)]) == 2
    assert "cannot read" in capsys.readouterr().err


# --------------------------------------------------------------------------- run


def test_run_tiny_case_end_to_end(tiny, tmp_path, capsys):
    out = tmp_path / "results" / "tiny.nc"
    assert main(["run", str(tiny), "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert str(out) in captured.out and "wall time" in captured.out
    # not a terminal: plain progress lines instead of a bar, the last one at 100 %
    progress = [line for line in captured.err.splitlines() if line.startswith("t ")]
    # each number says what it counts: nominal steps of the case's Δt, Newton iterations
    assert progress and ("t 0.05/0.05 s (100 %), nominal step 5/5 of Δt 0.01 s, "
                         in progress[-1]), progress
    assert "Newton iterations" in progress[-1] and "ETA" in progress[-1]
    # the run's events, in the order they happened (this rod stays straight: none did)
    assert "events: none happened; did not happen: buckling onset" in captured.out
    ds = open_result(out)
    assert ds.attrs["hockle_status"] == "completed"
    assert ds.attrs["case_hash"] == Case.from_file(tiny).spec_hash()
    assert float(ds["time"].values[-1]) == pytest.approx(0.05)
    assert ds.sizes["s"] == 9
    requested = {
        "v", "omega", "f", "kappa", "position", "orientation",
        "energy_bending", "energy_torsion", "energy_kinetic", "energy_total",
        "twist", "writhe", "linking_number",
    }
    assert requested <= set(ds.data_vars)
    assert "moment" not in ds.data_vars  # not requested
    # the prescribed twist shows: the start end turned 1 rad/s for 0.05 s against the
    # fixed far end of a rod that stays straight (Wr = 0), so Tw = -0.05 rad / 2 pi
    assert float(ds["twist"].values[-1]) == pytest.approx(-0.05 / (2 * np.pi), rel=1e-6)
    assert np.all(np.abs(ds["writhe"].values) < 1e-9)
    assert [p.name for p in out.parent.iterdir()] == ["tiny.nc"]  # no temp file left


def test_run_default_output_name_and_plot_of_it(tiny, tmp_path, monkeypatch, capsys):
    workdir = tmp_path / "work"
    workdir.mkdir()
    monkeypatch.chdir(workdir)
    assert main(["run", str(tiny), "--quiet"]) == 0
    assert (workdir / "tiny.nc").exists()
    assert main(["plot", "tiny.nc"]) == 0
    for name in ("tiny_snapshots.png", "tiny_energies.png", "tiny_topology.png"):
        assert_png(workdir / "tiny_plots" / name)


def test_run_invalid_case(tmp_path, capsys):
    spec = copy.deepcopy(TINY)
    spec["numerics"]["dt"] = -1.0
    bad = write_case(tmp_path / "bad.yaml", spec)
    assert main(["run", str(bad), "-o", str(tmp_path / "bad.nc")]) == 2
    assert any(line.startswith("numerics.dt: ") for line in capsys.readouterr().err.splitlines())
    assert not (tmp_path / "bad.nc").exists()


def test_run_names_the_field_the_centreline_scheme_refuses(tmp_path, capsys):
    """A field the centreline scheme refuses when the run is built (a point load off the
    grid's nodes) is an invalid case: exit 2, the field and the reason on stderr, no
    traceback and no file."""
    spec = copy.deepcopy(TINY)
    spec["numerics"]["formulation"] = "centreline"
    spec["numerics"].pop("tolerance", None)
    length = spec["rod"]["length"]
    spec["point_loads"] = [{"s": 0.37 * length, "value": [0.0, 1e-3, 0.0]}]
    case = write_case(tmp_path / "off.yaml", spec)
    assert main(["run", str(case), "-o", str(tmp_path / "off.nc"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "point_loads.0.s" in err and "not a grid node" in err and "Traceback" not in err
    assert not (tmp_path / "off.nc").exists()


def test_run_out_of_wall_clock_budget_writes_partial_file(tmp_path, capsys):
    spec = copy.deepcopy(TINY)
    spec["numerics"]["wall_clock_budget"] = 1e-6  # s: spent before the first step ends
    case = write_case(tmp_path / "budget.yaml", spec)
    out = tmp_path / "budget.nc"
    assert main(["run", str(case), "-o", str(out), "--quiet"]) == 4
    assert "partial results" in capsys.readouterr().err
    ds = open_result(out)
    assert ds.attrs["hockle_status"] == "stopped"
    assert ds.attrs["hockle_stop_reason"] == "timeout"
    assert float(ds["time"].values[-1]) < 0.05


def test_run_divergence_writes_partial_file(tmp_path, capsys):
    # An absurd case: a free cantilever under 1 MN/m, Δt = 0.5 s with one cut allowed
    # and four Newton iterations per attempt; the first step cannot converge.
    spec = copy.deepcopy(TINY)
    spec["name"] = "absurd"
    spec["distributed_forces"] = [{"value": [1.0e6, 0.0, 0.0], "start": 0.0, "end": 1.0}]
    spec["boundary"]["end"] = {
        "translation": [{"force": 0}] * 3,
        "rotation": [{"moment": 0}] * 3,
    }
    spec["numerics"] = {
        "n_segments": 8,
        "dt": 0.5,
        "t_end": 2.0,
        "max_dt_cuts": 1,
        "newton": {"max_iterations": 4},
    }
    spec["output"] = {"fields": ["position", "energies"]}
    case = write_case(tmp_path / "absurd.yaml", spec)
    out = tmp_path / "absurd.nc"
    assert main(["run", str(case), "-o", str(out), "--quiet"]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "solver failed" in err[0] and str(out) in err[0]
    ds = open_result(out)
    assert ds.attrs["hockle_status"] == "failed"
    assert "position" in ds.data_vars and ds.sizes["time"] >= 1


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def test_ctrl_c_stops_cleanly_and_writes_partial_file(tmp_path):
    spec = copy.deepcopy(TINY)
    spec["numerics"]["t_end"] = 1000.0  # 100 000 steps: far longer than the test waits
    spec["output"] = {"every": 50, "fields": ["position", "energies"]}
    case = write_case(tmp_path / "long.yaml", spec)
    out = tmp_path / "long.nc"
    ckpt = tmp_path / "long.ckpt"
    proc = subprocess.Popen(
        [sys.executable, "-m", "hockle", "run", str(case), "-o", str(out),
         "--checkpoint", str(ckpt), "--checkpoint-every", "0.1"],
        cwd=tmp_path,
        env=_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        first = proc.stderr.readline()  # printed once the interrupt handler is in place
        assert "running" in first, first
        # Interrupt only once steps are being taken: on a fresh clone the first step
        # compiles the kernels (a minute or more), and an interrupt then stops at t = 0.
        # The first checkpoint is written after the first accepted step past 0.1 s wall.
        deadline = time.monotonic() + 600.0
        while not ckpt.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)
        assert ckpt.exists(), "no step was accepted before the deadline"
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr
    ds = open_result(out)
    assert ds.attrs["hockle_status"] == "stopped"
    assert ds.attrs["hockle_stop_reason"] == "cancelled_by_user"
    assert 0 < float(ds["time"].values[-1]) < 1000.0


# --------------------------------------------------------------------------- entry points


def test_python_dash_m_hockle(tiny):
    proc = subprocess.run(
        [sys.executable, "-m", "hockle", "validate", str(tiny)],
        cwd=tiny.parent,
        env=_env(),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("ok: tiny")


def test_help_lists_all_commands(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    for command in ("run", "validate", "plot", "serve", "worker", "submit"):
        assert f"    {command}" in out


def test_service_commands_fail_soft_when_their_module_cannot_load(tiny, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "hockle.service_commands", None)  # import fails
    assert main(["serve"]) == 1
    assert "hockle serve is unavailable" in capsys.readouterr().err
    assert main(["validate", str(tiny)]) == 0


def test_run_checkpoint_and_resume(tiny, tmp_path, capsys):
    """A run stopped by its wall-clock budget leaves a checkpoint; --resume with the case
    without the budget finishes it, identical to the uninterrupted run."""
    full = tmp_path / "full.nc"
    assert main(["run", str(tiny), "-o", str(full), "--quiet"]) == 0
    spec = copy.deepcopy(TINY)
    spec["numerics"]["wall_clock_budget"] = 1e-6
    stopped = write_case(tmp_path / "budget.yaml", spec)
    ck = tmp_path / "run.ckpt"
    part = tmp_path / "part.nc"
    assert main(["run", str(stopped), "-o", str(part), "--quiet", "--checkpoint", str(ck)]) == 4
    assert ck.exists() and not (tmp_path / "run.ckpt.tmp").exists()
    resumed = tmp_path / "resumed.nc"
    assert main(["run", str(tiny), "-o", str(resumed), "--quiet", "--resume", str(ck)]) == 0
    a, b = open_result(full), open_result(resumed)
    for name in a.data_vars:
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)
    # another case, or not a checkpoint: refused with the reason, exit 2
    other = copy.deepcopy(TINY)
    other["numerics"]["t_end"] = 0.06
    assert main(["run", str(write_case(tmp_path / "o.yaml", other)), "--quiet",
                 "--resume", str(ck)]) == 2
    assert "another case" in capsys.readouterr().err
    assert main(["run", str(tiny), "--quiet", "--resume", str(full)]) == 2
    assert "not a hockle checkpoint" in capsys.readouterr().err


def test_progress_line_says_what_each_number_counts():
    """A nominal step cut into sub-steps (the seabed case's 4 s: nominal step 80 of 200 at
    Δt 0.05 s, its last sub-step 0.00202 s, 136 Newton iterations over its sub-steps)
    says so; an uncut step does not name a sub-step; with numerics.tolerance the steps
    are error-controlled and have no count."""
    from types import SimpleNamespace

    from hockle.cli import _progress_line

    case = Case.model_validate(TINY | {"numerics": {"n_segments": 8, "dt": 0.05,
                                                     "t_end": 10.0}})
    info = SimpleNamespace(t=4.0, t_end=10.0, step=80, dt=0.00202, newton_iterations=136,
                           wall_time=105.0, fraction=0.4, eta_seconds=104.0)
    assert _progress_line(info, case) == (
        "t 4/10 s (40 %), nominal step 80/200 of Δt 0.05 s (last sub-step 0.00202 s), "
        "136 Newton iterations, wall 105 s, ETA 104 s")
    whole = SimpleNamespace(**{**vars(info), "dt": 0.05, "newton_iterations": 2})
    assert "nominal step 80/200 of Δt 0.05 s, 2 Newton iterations" in _progress_line(whole,
                                                                                     case)
    adaptive = Case.model_validate(TINY | {"numerics": {
        "n_segments": 8, "dt": 0.05, "t_end": 10.0, "tolerance": {"relative": 1e-3},
        "backward_euler_retry": False}})
    assert "step 80 (error-controlled, last Δt 0.00202 s), 136 Newton iterations" in \
        _progress_line(info, adaptive)
