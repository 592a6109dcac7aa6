"""The first run after an installation says that it compiles the kernels, and how long it
took, instead of showing a progress bar that stands still at step 0."""
from __future__ import annotations

from pathlib import Path

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


def test_the_compilation_shows_how_far_it_got(monkeypatch, capsys):
    """Off a terminal, a line every LINE_EVERY_S with the count of function signatures
    numba compiled so far (its compile events, counted as they end), and the total at
    the end; quiet: nothing."""
    import numba

    def fake_warm_up():
        # two fresh functions, one calling the other: two compilations
        @numba.njit
        def inner(x):
            return x + 1.0

        @numba.njit
        def outer(x):
            return inner(x) * 2.0

        assert outer(1.0) == 4.0

    monkeypatch.setattr(cli, "_kernels_cached", lambda: False)
    monkeypatch.setattr("solver.compiled.warm_up", fake_warm_up)
    monkeypatch.setattr(cli._CompileProgress, "LINE_EVERY_S", 0.0)
    cli._compile_kernels_first(quiet=False)
    lines = capsys.readouterr().err.splitlines()
    assert [line.rsplit(",", 1)[0] for line in lines[1:3]] == [
        f"hockle: compiling the solver's kernels: {k} function signatures" for k in (1, 2)]
    assert all(line.endswith(" s ...") for line in lines[1:3])
    assert "kernels compiled in" in lines[-1] and "(2 function signatures)" in lines[-1]
    cli._compile_kernels_first(quiet=True)
    assert capsys.readouterr().err == ""


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
    __pycache__ holds kernels; the solver's kernels there, in the folder numba names after
    the source folder (solver_<sha1 of its path>), mean cached, another package's do not."""
    from numba.core.caching import UserProvidedCacheLocator

    import solver
    from solver.compiled import warm_up

    warm_up()                                     # the package's __pycache__ holds kernels
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert not cli._kernels_cached()
    other = tmp_path / "other_0123456789abcdef"
    other.mkdir()
    (other / "kernel-1.py311.nbi").write_bytes(b"")
    assert not cli._kernels_cached()
    ours = tmp_path / UserProvidedCacheLocator.get_suitable_cache_subpath(
        str(Path(solver.__file__).resolve().parent / "newton.py"))
    ours.mkdir()
    (ours / "newton._newton_kernel-1.py311.nbi").write_bytes(b"")
    assert cli._kernels_cached()


def test_the_purge_reaches_the_packages_folders_under_numba_cache_dir(monkeypatch, tmp_path):
    """purge_stale deletes the files of every folder _cache_dirs lists: under
    NUMBA_CACHE_DIR those are numba's folders for the package's sources (solver_<sha1>,
    contact_<sha1>, ...), not another package's folder of the same name."""
    from solver import _kernel_cache

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    ours = _kernel_cache._user_cache_dirs()
    assert {d.name.rsplit("_", 1)[0] for d in ours} >= {"solver", "contact", "stepping"}
    for d in ours:
        d.mkdir()
    other = tmp_path / "contact_0123456789abcdef"      # a folder of another package
    other.mkdir()
    listed = set(_kernel_cache._cache_dirs())
    assert set(ours) <= listed and other not in listed


def test_a_worker_says_when_it_compiles_the_kernels(monkeypatch, capsys):
    """A worker loads the kernels before its pool forks; the first start after an
    installation compiles them and says so, with how long it took; later starts say
    nothing."""
    from worker import cli as worker_cli

    calls = []
    monkeypatch.setattr("solver._kernel_cache.kernels_cached", lambda: False)
    monkeypatch.setattr("solver.warm_up", lambda: calls.append("warm_up"))
    worker_cli.load_kernels()
    err = capsys.readouterr().err
    assert calls == ["warm_up"]
    assert "hockle worker: compiling the solver's kernels" in err
    assert "hockle worker: kernels compiled in" in err
    monkeypatch.setattr("solver._kernel_cache.kernels_cached", lambda: True)
    worker_cli.load_kernels()
    assert calls == ["warm_up", "warm_up"] and capsys.readouterr().err == ""
