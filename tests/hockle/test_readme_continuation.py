"""The README's continuation example, taken literally (issue 80): its `hockle continue` and
`hockle plot` lines, run in order in an empty folder (the repository's cases/ beside them),
give a branch that buckles: a branch point is found, the column leaves it laterally by far
more than round-off, and the plots are drawn with a panel for that excursion."""
from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def _readme_continuation_commands() -> list[list[str]]:
    """The README's `hockle continue ...` line and the `hockle plot` of its output, as argv
    lists (shell continuations joined, comments dropped)."""
    text = (ROOT / "README.md").read_text()
    commands = []
    for block in re.findall(r"```sh\n(.*?)```", text, re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = re.sub(r"\s+#.*$", "", line).strip()
            if line.startswith("hockle "):
                commands.append(shlex.split(line)[1:])
    start = next(i for i, c in enumerate(commands) if c[0] == "continue")
    out = commands[start][commands[start].index("-o") + 1]
    plot = next(c for c in commands[start + 1:] if c[:2] == ["plot", out])
    return [commands[start], plot]


def test_the_readme_continuation_shows_a_buckled_branch(tmp_path, monkeypatch, capsys):
    import xarray as xr

    from hockle.cli import main
    from service.branch_view import measures

    (tmp_path / "cases").symlink_to(ROOT / "cases")
    monkeypatch.chdir(tmp_path)
    continue_argv, plot_argv = _readme_continuation_commands()
    assert main(continue_argv) == 0
    assert main(plot_argv) == 0
    printed = capsys.readouterr().out
    out = Path(continue_argv[continue_argv.index("-o") + 1])
    with xr.open_dataset(out) as ds:
        kinds = [str(k) for k in ds["bifurcation_kind"].values]
        assert "branch_point" in kinds, kinds
        length = json.loads(ds.attrs["case"])["rod"]["length"]
        r = ds["position"].values
        lateral = np.hypot(r[..., 0], r[..., 1])
        # buckled: the column leaves its axis by a third of its length (round-off: 1e-17 m)
        assert np.nanmax(lateral) > 0.1 * length, np.nanmax(lateral)
        assert int(ds["branch"].values.max()) == 1       # the switched, buckled branch
        found = measures(ds)
    assert not found["excursion"]["constant"]
    # the plots: the bifurcation diagram and the shapes, where the plot said
    pngs = [Path(p) for p in printed.split() if p.endswith(".png")]
    assert {p.name for p in pngs} == {f"{out.stem}_bifurcation.png", f"{out.stem}_shapes.png"}
    assert all(p.is_file() and p.stat().st_size > 10_000 for p in pngs)
