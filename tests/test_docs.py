"""The documentation site builds offline with warnings as errors, the version is written
once, and the README's commands are the ones the code accepts."""
from __future__ import annotations

import importlib.metadata
import importlib.util
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
DOCS_EXTENSIONS = ("sphinx", "myst_parser", "pydata_sphinx_theme", "sphinx_gallery",
                   "sphinxcontrib.openapi")


def _shell_blocks(text: str) -> list[str]:
    return re.findall(r"```sh\n(.*?)```", text, re.S)


def _commands(block: str) -> list[str]:
    """Shell lines of a block, continuations joined, comments dropped."""
    joined = block.replace("\\\n", " ")
    out = []
    for line in joined.splitlines():
        line = re.sub(r"\s+#.*$", "", line).strip()
        if line and not line.startswith("#"):
            out.append(line)
    return out


# --------------------------------------------------------------------------- the site


def test_docs_build_offline_with_warnings_as_errors(tmp_path):
    """`python3 -m sphinx -W -b html docs docs/_build/html`, into a temporary folder: the
    pages, the API reference from the docstrings, the CLI and REST references and the
    gallery running examples/ in --quick mode (about a minute on 2 cores)."""
    missing = [m for m in DOCS_EXTENSIONS if importlib.util.find_spec(m) is None]
    if missing:
        pytest.skip(f"the docs extra is not installed ({', '.join(missing)}): "
                    "pip install -e '.[docs]'")
    out = tmp_path / "html"
    done = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "-q", "-b", "html", "-d",
         str(tmp_path / "doctrees"), "docs", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-5000:] + done.stderr[-5000:]
    api = (out / "_generated" / "api.html").read_text()
    for name in ("hockle.api.simulate", "solver.Case", "HockleClient"):
        assert name in api, name
    gallery = {p.stem for p in (out / "auto_examples").glob("*.html")}
    assert {p.stem for p in (ROOT / "examples").glob("*.py")} <= gallery
    assert "/v1/jobs/{job_id}" in (out / "rest-api.html").read_text()
    assert "hockle export" in (out / "cli.html").read_text()


# --------------------------------------------------------------------------- reference, not a diary

# A page of the site describes the software as it is: dates, the hosts a figure was measured
# on and the commits it was measured at belong to the changelog, the generated benchmark
# report (which names its machine and date) and the research notebook (research/notes/).
DOCS_DATED = {"docs/changelog.md", "docs/benchmarks.md"}
ISO_DATE = re.compile(r"\b(?:19|20)\d\d-(?:0[1-9]|1[0-2])-(?:0[1-9]|[12]\d|3[01])\b")
# a commit hash: 7 to 40 hexadecimal digits with at least one letter and one digit
COMMIT = re.compile(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*\d)[0-9a-f]{7,40}\b")
HOST = re.compile(r"\b(?:EPYC|Xeon|Ryzen|Opteron|Threadripper|Graviton)\b"
                  r"|\b\d+(?:\.\d+)?[ -]?GHz\b", re.I)


def _site_sources() -> list[Path]:
    """What the site is built from: the pages and configuration under docs/ (not its
    build, its generated pages or the gallery's copies) and the gallery's examples."""
    skip = ("docs/_build/", "docs/_generated/", "docs/auto_examples/", "docs/figures/")
    out = []
    for path in sorted([*(ROOT / "docs").rglob("*"), *(ROOT / "examples").glob("*.py")]):
        rel = path.relative_to(ROOT).as_posix()
        if (path.is_file() and path.suffix in {".md", ".rst", ".py", ".txt"}
                and not rel.startswith(skip) and rel not in DOCS_DATED):
            out.append(path)
    return out


def test_patterns_catch_what_they_are_for():
    assert ISO_DATE.search("measured 2026-11-27 on") and not ISO_DATE.search("Δt 1e-4 … 1 s")
    assert COMMIT.search("at commit `894957f`") and COMMIT.search("a86c358")
    assert not COMMIT.search("1000 segments, 0.00113 s, deadbeef, 1234567")
    assert HOST.search("a 2-core AMD EPYC") and HOST.search("a 2.1-GHz Intel Xeon")
    assert HOST.search("at 2.6 GHz") and not HOST.search("2 shared cores")


def test_docs_carry_no_dates_hosts_or_commits():
    """docs/ (and the gallery's examples) name no date, CPU model or commit hash outside
    the changelog and the generated benchmark report (issue 78): such figures go to the
    research notebook, and a page links to the report for the last measured one."""
    found = []
    for path in _site_sources():
        rel = path.relative_to(ROOT).as_posix()
        for n, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            for kind, pattern in (("date", ISO_DATE), ("commit", COMMIT), ("host", HOST)):
                match = pattern.search(line)
                if match:
                    found.append(f"{rel}:{n}: {kind} {match.group(0)!r}: {line.strip()[:80]}")
    assert not found, "\n".join(found)


def _markdown_files() -> list[Path]:
    return sorted([ROOT / "README.md", ROOT / "CHANGELOG.md", *(ROOT / "docs").glob("*.md"),
                   *(ROOT / "research").rglob("*.md")])


def test_relative_links_and_doc_references_resolve():
    """Every relative Markdown link of the README, the changelog, docs/ and research/
    names a file that exists, every {doc} reference a page, and every research/notes/
    path a page cites exists: moving a page out of the site leaves no dangling link."""
    pages = {p.stem for p in (ROOT / "docs").glob("*.md")} | {"auto_examples/index",
                                                             "_generated/api"}
    bad = []
    for path in _markdown_files():
        rel = path.relative_to(ROOT).as_posix()
        text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if re.match(r"[a-z]+:|#", target):
                continue
            file = target.split("#")[0]
            if not (path.parent / file).exists():
                bad.append(f"{rel}: link to {target}")
        for target in re.findall(r"\{doc\}`(?:[^`<]*<)?([^`>]+)>?`", text):
            if target.lstrip("./") not in pages:
                bad.append(f"{rel}: {{doc}} {target}")
        for cited in re.findall(r"research/notes/[\w.-]+\.md", text):
            if not (ROOT / cited).exists():
                bad.append(f"{rel}: cites {cited}")
    assert not bad, "\n".join(bad)


# --------------------------------------------------------------------------- one version


def test_one_version_everywhere(capsys):
    import hockle
    import solver
    from hockle.cli import main

    installed = importlib.metadata.version("hockle")
    assert solver.__version__ == hockle.__version__ == installed
    with pytest.raises(SystemExit):
        main(["--version"])
    assert capsys.readouterr().out.strip() == f"hockle {installed}"
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert re.search(rf'^version = "{re.escape(installed)}"', pyproject, re.M)
    # written nowhere else in the sources
    for path in [*ROOT.glob("solver/**/*.py"), *ROOT.glob("hockle/**/*.py"),
                 *ROOT.glob("service/**/*.py"), *ROOT.glob("worker/**/*.py")]:
        assert not re.search(r'__version__\s*=\s*["\']\d+\.\d', path.read_text()), path


def test_health_reports_the_version(tmp_path, monkeypatch):
    pytest.importorskip("fastapi")
    from fastapi.testclient import TestClient

    monkeypatch.setenv("HOCKLE_DATA_DIR", str(tmp_path))
    monkeypatch.delenv("HOCKLE_API_KEYS", raising=False)
    from service.app import create_app
    from service.settings import get_settings

    getattr(get_settings, "cache_clear", lambda: None)()
    app = create_app()
    body = TestClient(app).get("/v1/health").json()
    assert body["solver_version"] == importlib.metadata.version("hockle")
    assert app.version == importlib.metadata.version("hockle")


# --------------------------------------------------------------------------- the README


# what `grep -rniE "<this pattern>" --include='*.md' --include='*.py' .` looks for; spelled
# in pieces so that this file does not match it itself
DIARY = re.compile("sess" "ion [0-9]+|sit" "ting", re.I)


def test_readme_is_short():
    assert len(README.splitlines()) <= 150


def test_no_diary_outside_the_changelog():
    """The repository describes the software as it is: what changed and when goes to
    CHANGELOG.md (and the dated notes of research/notes/), not into prose."""
    found = []
    for path in sorted([*ROOT.rglob("*.md"), *ROOT.rglob("*.py")]):
        rel = path.relative_to(ROOT).as_posix()
        if (rel == "CHANGELOG.md"
                or rel.split("/")[0] in {".venv", "build", "dist", ".git"}
                or "/_build/" in rel or rel.startswith(("docs/_generated/", "docs/auto_examples/"))):
            continue
        for n, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            if DIARY.search(line):
                found.append(f"{rel}:{n}: {line.strip()[:80]}")
    assert not found, "\n".join(found)


def test_readme_test_command_is_what_ci_runs():
    ci = (ROOT / ".ci" / "run").read_text()
    ci_test = [line for line in ci.splitlines() if line.strip() and not line.startswith("#")][-1]
    quick = [c for b in _shell_blocks(README) for c in _commands(b) if "pytest" in c]
    assert quick and quick[0].endswith("&& " + ci_test.strip()), (quick, ci_test)
    extras = re.search(r"pip install -q -e '\.\[([\w,]+)\]'", ci).group(1).split(",")
    assert "docs" in extras and "test" in extras


def test_readme_hockle_commands_parse(tmp_path, monkeypatch):
    """Every `hockle ...` command of the README's shell blocks is accepted by the parser
    (the seed run itself takes a minute: tests/hockle/test_cli.py runs `hockle run` on small
    cases), every case file it names exists and validates."""
    from hockle.cli import build_parser, main

    parser, _ = build_parser()
    seen = set()
    for block in _shell_blocks(README):
        for command in _commands(block):
            for part in command.split("&&"):
                words = shlex.split(part.strip().rstrip("&").strip())
                if not words or words[0] != "hockle":
                    continue
                args = parser.parse_args(words[1:])
                seen.add(words[1])
                case = getattr(args, "case", None) or getattr(args, "base", None)
                if case:
                    assert (ROOT / case).is_file(), case
                    assert main(["validate", str(ROOT / case)]) == 0
    assert {"validate", "run", "plot", "animate", "export", "sweep", "serve",
            "submit"} <= seen


def test_readme_python_blocks_import_what_exists():
    """The README's Python blocks parse, and every name they import exists."""
    import ast

    blocks = re.findall(r"```python\n(.*?)```", README, re.S)
    assert blocks
    for block in blocks:
        for node in ast.walk(ast.parse(block)):
            if isinstance(node, ast.ImportFrom):
                module = importlib.import_module(node.module)
                for alias in node.names:
                    assert hasattr(module, alias.name), f"{node.module}.{alias.name}"
    from service.client import HockleClient

    for method in ("submit", "wait", "dataset"):
        assert callable(getattr(HockleClient, method))


def test_readme_compose_and_kubernetes_secrets():
    """The compose lines create every variable docker-compose.yml requires (`${VAR:?}`),
    and the kubectl lines every secret the manifests read."""
    compose = "\n".join(line for line in (ROOT / "docker-compose.yml").read_text().splitlines()
                        if not line.lstrip().startswith("#"))
    required = set(re.findall(r"\$\{(\w+):\?", compose))
    lines = [c for b in _shell_blocks(README) for c in _commands(b)]
    written = next(c for c in lines if c.startswith("for var in"))
    assert required <= set(written.split(";")[0].split()[3:]), (required, written)
    secrets = set()
    for manifest in (ROOT / "deploy" / "k8s").glob("*.yaml"):
        for doc in yaml.safe_load_all(manifest.read_text()):
            secrets |= set(re.findall(r"secretKeyRef: \{'name': '([\w-]+)'",
                                      str(doc).replace('"', "'")))
    secrets |= set(re.findall(r"secretKeyRef:\s*\{name:\s*([\w-]+)",
                              "".join(p.read_text() for p in (ROOT / "deploy" / "k8s")
                                      .glob("*.yaml"))))
    created = {c.split()[4] for c in lines if c.startswith("kubectl create secret generic")}
    assert secrets and secrets <= created, (secrets, created)
