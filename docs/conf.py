"""Sphinx configuration of hockle's documentation site.

Build (offline, warnings as errors; what ``tests/test_docs.py`` runs)::

    python3 -m sphinx -W -b html docs docs/_build/html

Pages are Markdown (myst-parser); the API reference is generated from the docstrings
(autodoc + autosummary, numpydoc-style sections through napoleon); the gallery runs the
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
templates_path = ["_templates"]

# --------------------------------------------------------------------------- API reference
autosummary_generate = True
autodoc_default_options = {"members": True, "show-inheritance": False}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
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


SKIP_MODULES = ("migrations", "__main__")


def _write_api_reference() -> None:
    """The API reference page: every module of the four packages, walked from the
    tree (so a module added or moved is documented without editing this file)."""
    import importlib
    import pkgutil

    lines = ["# API reference", "",
             "Generated from the docstrings (array shapes, units, errors raised, sources).",
             "", "## Entry points", "", "```{eval-rst}", ".. autosummary::", "",
             "   hockle.api.simulate", "   solver.Case", "   solver.SolverDivergence",
             "   service.client.HockleClient", "```", ""]
    for package in ("solver", "hockle", "service", "worker"):
        mod = importlib.import_module(package)
        names = [package] + sorted(
            m.name for m in pkgutil.walk_packages(mod.__path__, prefix=package + ".")
            if not any(part in SKIP_MODULES for part in m.name.split(".")))
        lines += [f"## {package}", "", "```{eval-rst}", ".. autosummary::",
                  "   :toctree: api", "", *[f"   {n}" for n in names], "```", ""]
    GENERATED.mkdir(exist_ok=True)
    (GENERATED / "api.md").write_text("\n".join(lines))


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
