"""Sphinx configuration of hockle's documentation site.

Build (offline, warnings as errors; what ``tests/test_docs.py`` runs)::

    python3 -m sphinx -W -b html docs docs/_build/html

Pages are Markdown (myst-parser); the API reference, the public modules only
(``PUBLIC_MODULES``), is generated from the docstrings (autodoc, numpydoc sections through
napoleon); the gallery runs the
scripts of ``examples/`` in their ``--quick`` mode (sphinx-gallery); the REST reference
renders the service's OpenAPI document, written here from ``service.app`` without a
server (sphinxcontrib-openapi); the CLI reference is the ``--help`` text of every command.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import sys
import tempfile
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
GENERATED = DOCS / "_generated"
sys.path.insert(0, str(ROOT))

from solver import __version__  # noqa: E402  (the installed distribution's version)

project = "hockle"
author = "the hockle developers"
copyright = "2026, the hockle developers"
release = version = __version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "sphinx_gallery.gen_gallery",
    "sphinxcontrib.openapi",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "**/*.ipynb", "_generated/cli-help.md",
                    "auto_examples/*.md5", "auto_examples/*.py", "auto_examples/*.zip"]
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3
suppress_warnings = ["myst.header", "myst.xref_missing", "config.cache",
                     "ref.python"]   # solver.contact re-exports its classes: two targets

html_theme = "pydata_sphinx_theme"
html_title = f"hockle {release}"
html_theme_options = {"navigation_with_keys": False, "show_toc_level": 2,
                      "header_links_before_dropdown": 4}
html_static_path: list[str] = []

# --------------------------------------------------------------------------- API reference
autosummary_generate = True
# no default "members": a default of True would override each page's explicit member list
autodoc_default_options = {"show-inheritance": False}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_typehints_description_target = "documented_params"   # no bare type lists
autodoc_mock_imports: list[str] = []
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_ivar = True   # Attributes sections as fields, not second descriptions
nitpicky = False

# --------------------------------------------------------------------------- gallery
# Each example runs once per build in its --quick mode (small grids, seconds), and draws
# its figure (--plot); tests/test_examples.py runs the same scripts without --plot.


def _gallery_argv(script_name: str, gallery_conf) -> list[str]:
    return ["--quick", "--plot"]


sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"\.py$",          # run every example (all are quick)
    "reset_argv": _gallery_argv,
    "download_all_examples": False,
    "remove_config_comments": True,
    "plot_gallery": "True",
    "abort_on_example_error": True,
    "within_subsection_order": "FileNameSortKey",
}


# --------------------------------------------------------------------------- generated pages


def _write_openapi() -> None:
    """The service's OpenAPI document, from the app itself (no server, no network)."""
    with tempfile.TemporaryDirectory() as data:
        os.environ["HOCKLE_DATA_DIR"] = data
        os.environ.pop("HOCKLE_API_KEYS", None)
        from service.app import create_app

        schema = create_app().openapi()
    GENERATED.mkdir(exist_ok=True)
    (GENERATED / "openapi.json").write_text(json.dumps(schema, indent=1, sort_keys=True))


def _write_cli_help() -> None:
    """Every ``hockle`` command's ``--help`` text, as the parser prints it."""
    from hockle.cli import build_parser

    parser, _ = build_parser()
    os.environ.setdefault("COLUMNS", "90")
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    lines = ["# Command reference", "",
             "Generated from the parser of `hockle` (`hockle COMMAND --help` prints the same).",
             "", "## hockle", "", "```text", parser.format_help().rstrip(), "```", ""]
    for name, sp in sub.choices.items():
        lines += [f"## hockle {name}", "", "```text", sp.format_help().rstrip(), "```", ""]
    GENERATED.mkdir(exist_ok=True)
    (GENERATED / "cli-help.md").write_text("\n".join(lines))


#: The public API, the modules a user imports, with what each is for. Only these are
#: documented: the rest of the four packages is the implementation (docs/developer.md walks
#: through it), and its docstrings are read in the sources.
PUBLIC_MODULES = [
    ("hockle.api", "The Python API: run a case in-process with callbacks and loads "
                   "written in Python, build cases and ends, sweep on all cores, find "
                   "equilibria and follow their branches."),
    ("hockle.io", "Result files: write and open them, read a start state from one."),
    ("solver", "The solver's public names: the validated case, the time loop, its "
               "progress record and failure, the kernels' warm-up."),
    ("solver.case", "The case spec (the input contract): the sections of a case."),
    ("solver.results", "The result dataset (the output contract): its builder, "
                       "metadata and events."),
    ("solver.topology", "Twist, writhe and linking number of a centreline."),
    ("solver.checkpoint", "Checkpoints of a run or a branch, and resuming from them."),
    ("service.client", "The REST service's Python client."),
]


def _public_names() -> dict[str, list[str]]:
    """The names each public module exports (``__all__``), each object documented once:
    at the first module of ``PUBLIC_MODULES`` that exports it (``solver.Case`` on the
    ``solver`` page, not again on ``solver.case``'s)."""
    import importlib

    seen, out = set(), {}
    for name, _ in PUBLIC_MODULES:
        module = importlib.import_module(name)
        out[name] = []
        for attr in getattr(module, "__all__", []):
            if attr.startswith("_"):
                continue
            obj = getattr(module, attr)
            key = id(obj) if callable(obj) or isinstance(obj, type) else (name, attr)
            if key in seen:
                continue
            seen.add(key)
            out[name].append(attr)
    return out


def _write_api_reference() -> None:
    """The API reference: an index page and one page per public module, written from
    ``PUBLIC_MODULES`` (numpydoc docstrings rendered by napoleon)."""
    import importlib
    import shutil

    pages = GENERATED / "api"
    shutil.rmtree(pages, ignore_errors=True)
    pages.mkdir(parents=True)
    lines = ["# API reference", "",
             "The public API, generated from the docstrings (numpydoc sections: parameters "
             "with their shapes and units, returns, errors raised). The command line is in "
             "{doc}`../cli`, the REST API in {doc}`../rest-api`; the contracts behind them "
             "(the case spec, the result dataset) in {doc}`../case-spec` and "
             "{doc}`../interfaces`.", "",
             "## Entry points", "", "```{eval-rst}", ".. autosummary::", "",
             "   hockle.api.simulate", "   solver.Case", "   solver.SolverDivergence",
             "   service.client.HockleClient", "```", "",
             "## Modules", "", "| module | what it is for |", "| --- | --- |"]
    for name, what in PUBLIC_MODULES:
        lines.append(f"| {{doc}}`{name} <api/{name}>` | {what} |")
    lines += ["", "```{toctree}", ":hidden:", "",
              *[f"api/{name}" for name, _ in PUBLIC_MODULES], "```", ""]
    (GENERATED / "api.md").write_text("\n".join(lines))
    public = _public_names()
    for name, what in PUBLIC_MODULES:
        module = importlib.import_module(name)
        names = public[name]
        body = [name, "=" * len(name), "", what, "", f".. automodule:: {name}"]
        if name == "solver":
            # its names are resolved lazily (solver/__init__.py): one directive each
            body += ["   :no-members:", ""]
            for attr in names:
                kind = "autoclass" if isinstance(getattr(module, attr), type) else "autofunction"
                body += [f".. {kind}:: solver.{attr}"]
                body += ["   :members:", ""] if kind == "autoclass" else [""]
        elif names:
            body += [f"   :members: {', '.join(names)}", ""]
        else:
            body += ["   :no-members:", ""]
        (pages / f"{name}.rst").write_text("\n".join(body))


_write_openapi()
_write_cli_help()
_write_api_reference()


DEVELOPER_MARK = ":caption: Developers\n"


def _toctree_extras(app, docname, source):
    """Pages that the index does not list yet join its toctree: the developer guide
    (docs/developer.md) under Developers, any other top-level page (a new guide from
    another change) under More, so that no page is left outside the site."""
    if docname != "index":
        return
    text = source[0]
    listed = set(re.findall(r"^([\w./-]+)$", text, re.M))
    extra = sorted(p.stem for p in DOCS.glob("*.md")
                   if p.stem not in listed and p.stem not in ("index", "developer"))
    if (DOCS / "developer.md").exists() and "developer" not in listed:
        text = text.replace(DEVELOPER_MARK, DEVELOPER_MARK + "\ndeveloper\n", 1)
    if extra:
        text += "\n```{toctree}\n:caption: More\n:maxdepth: 1\n\n" + "\n".join(extra) + "\n```\n"
    source[0] = text


# The docstrings are written to be read as plain text first (|x| for a norm, aligned
# tables, indented examples): `|` is escaped, and a docstring that plain docutils still
# cannot parse cleanly is shown as preformatted text rather than failing the build.
_IGNORED_RST_MESSAGES = ("Unknown interpreted text role", "Unknown directive type",
                         "No role entry", "No directive entry", "Unknown target name")


def _rst_problems(text: str) -> bool:
    import io

    from docutils import nodes
    from docutils.core import publish_doctree

    # Sphinx's roles and directives need its environment: test the text without them
    text = re.sub(r":[\w:.+-]+:`", "`", text)
    text = re.sub(r"^(\s*)\.\. ([\w:.+-]+)::", r"\1.. \2 (directive)", text, flags=re.M)
    doctree = publish_doctree(text, settings_overrides={
        "report_level": 5, "halt_level": 5, "warning_stream": io.StringIO()})
    return any(m["level"] >= 2 and not any(s in m.astext() for s in _IGNORED_RST_MESSAGES)
               for m in doctree.findall(nodes.system_message))


def _plain_text_docstrings(app, what, name, obj, options, lines):
    escaped = [line.replace("|", "\\|") for line in lines]
    if _rst_problems("\n".join(escaped)):
        escaped = ["::", ""] + ["    " + line for line in lines] + [""]
    lines[:] = escaped


def _skip_sqlalchemy_internals(app, what, name, obj, skip, options):
    """The declarative base's ``metadata`` and ``registry`` are SQLAlchemy's, and their
    docstrings cross-reference SQLAlchemy's own documentation: not hockle's API."""
    if name in ("metadata", "registry") and type(obj).__module__.startswith("sqlalchemy"):
        return True
    return None


def setup(app):
    app.connect("source-read", _toctree_extras)
    app.connect("autodoc-skip-member", _skip_sqlalchemy_internals)
    app.connect("autodoc-process-docstring", _plain_text_docstrings, priority=600)
