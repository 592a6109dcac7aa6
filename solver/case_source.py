"""Where a field of a case file is written: the line and column of a field path.

Validation names a field by its path (``rod.density``,
``boundary.end.translation[2][0].force``: :func:`solver.case.format_loc`); a person
editing the file wants the line. The dashboard finds it in its editor by walking the
path's keys down the text (``lineOf`` in ``service/dashboard/static/app.js``);
:func:`field_position` walks the same path down the document's YAML nodes, which carry
their exact line and column (JSON is read as the YAML it also is), and falls back to the
dashboard's walk over the lines where the text does not compose. A path that goes on past
what the file writes (a default left out, a whole item missing) stops at the deepest part
the file has: the place to add it.
"""
from __future__ import annotations

import re

import yaml

__all__ = ["field_position", "where"]

_PART = re.compile(r"([^.\[\]]+)|\[(\d+)\]")


def _parts(loc: str) -> list:
    """``boundary.end.translation[2][0].force`` -> ['boundary', 'end', 'translation', 2, 0,
    'force']."""
    out: list = []
    for m in _PART.finditer(loc or ""):
        out.append(m.group(1) if m.group(1) is not None else int(m.group(2)))
    return out


def _walk(node, parts):
    """The start mark of the deepest node of ``parts`` under ``node`` and how many parts
    were found: a scalar's own mark (the value to change), a mapping's or list's key (the
    line that opens it, where the path goes on or ends at it)."""
    mark, reached = node.start_mark, 0
    for part in parts:
        if isinstance(part, str) and isinstance(node, yaml.MappingNode):
            for key, value in node.value:
                if isinstance(key, yaml.ScalarNode) and key.value == part:
                    node = value
                    mark = value.start_mark if isinstance(value, yaml.ScalarNode) \
                        else key.start_mark
                    break
            else:
                break
        elif isinstance(part, int) and isinstance(node, yaml.SequenceNode):
            if part >= len(node.value):
                break
            node = node.value[part]
            mark = node.start_mark
        elif isinstance(part, int) and part == 0 and isinstance(node, yaml.MappingNode):
            pass                 # one condition written without its list: item 0 is itself
        else:
            break
        reached += 1
    return mark, reached


def _by_lines(text: str, parts) -> tuple[int, int] | None:
    """The dashboard's ``lineOf``: each key of the path searched for from the line of the
    one before; (line, column) of the deepest found, 1-based, or None."""
    lines = text.split("\n")
    found, start = None, 0
    for part in parts:
        if not isinstance(part, str):
            continue
        pat = re.compile(r"(^|[{,\s])\"?" + re.escape(part) + r"\"?\s*:")
        for i in range(start, len(lines)):
            m = pat.search(lines[i])
            if m:
                found, start = (i + 1, m.start() + len(m.group(1)) + 1), i
                break
        else:
            break
    return found


def field_position(text: str, loc: str) -> tuple[int, int] | None:
    """The 1-based (line, column) where the case text ``text`` (YAML or JSON) writes the
    value of the field path ``loc``, or, where the file does not write it, the deepest
    part of the path it does; None for the document as a whole (``loc`` empty) or when
    neither walk finds any part."""
    parts = _parts(loc)
    if not parts:
        return None
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except (yaml.YAMLError, RecursionError, ValueError):
        root = None
    if root is None:
        return _by_lines(text, parts)
    mark, reached = _walk(root, parts)
    if reached == 0:
        return None
    return mark.line + 1, mark.column + 1


def where(source: str, text: str, loc: str) -> str | None:
    """``source:line:column: <that line of the file>`` for the field path ``loc`` (as
    compilers print a place, so editors and terminals open it there), or None
    (:func:`field_position`)."""
    pos = field_position(text, loc)
    if pos is None:
        return None
    line, column = pos
    lines = text.splitlines()
    shown = lines[line - 1].strip() if 0 < line <= len(lines) else ""
    if len(shown) > 100:
        shown = shown[:97] + "..."
    return f"{source}:{line}:{column}: {shown}"
