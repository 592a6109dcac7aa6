"""The first run after an installation says that it compiles the kernels, and how long it
took, instead of showing a progress bar that stands still at step 0."""
from __future__ import annotations

from hockle import cli


def test_compilation_is_announced_and_timed(monkeypatch, capsys):
    calls = []
    monkeypatch.setattr(cli, "_kernels_cached", lambda: False)
    monkeypatch.setattr("solver.compiled.warm_up", lambda: calls.append("warm_up"))
    cli._compile_kernels_first(quiet=False)
    err = capsys.readouterr().err
    assert calls == ["warm_up"]
    assert "compiling the solver's kernels" in err and "kernels compiled in" in err
    cli._compile_kernels_first(quiet=True)        # quiet: compiled, nothing said
    assert calls == ["warm_up", "warm_up"] and capsys.readouterr().err == ""


def test_nothing_said_when_the_kernels_are_cached(monkeypatch, capsys):
    from solver.compiled import warm_up

    warm_up()                                     # compiles once if the cache is empty
    assert cli._kernels_cached()
    monkeypatch.setattr("solver.compiled.warm_up", lambda: (_ for _ in ()).throw(AssertionError))
    cli._compile_kernels_first(quiet=False)
    assert capsys.readouterr().err == ""


def test_an_empty_numba_cache_dir_means_not_compiled(monkeypatch, tmp_path):
    """With NUMBA_CACHE_DIR set numba keeps its cache there only: an empty folder means
    the kernels will be compiled (and the run says so) even where the package's own
    __pycache__ holds kernels; the solver's kernels there mean cached, another package's
    do not."""
    from solver.compiled import warm_up

    warm_up()                                     # the package's __pycache__ holds kernels
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert not cli._kernels_cached()
    other = tmp_path / "site" / "other_package"
    other.mkdir(parents=True)
    (other / "kernel-1.py311.nbi").write_bytes(b"")
    assert not cli._kernels_cached()
    ours = tmp_path / "work" / "solver"
    ours.mkdir(parents=True)
    (ours / "newton._newton_kernel-1.py311.nbi").write_bytes(b"")
    assert cli._kernels_cached()
