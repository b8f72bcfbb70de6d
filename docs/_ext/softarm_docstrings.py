"""Sphinx extension: render the Markdown parts of the project's docstrings in the API reference.

The env classes' docstrings follow Gymnasium's env-card layout, written as Markdown
(``## Action Space`` headings, ``| a | b |`` tables) so that they read well in ``help()``
and on the generated environment pages; autodoc reads docstrings as reStructuredText.
This turns each ``## Heading`` into a rubric and each pipe table into a ``list-table``.
"""

from __future__ import annotations

import importlib
import pkgutil
import re

from docutils import nodes
from docutils.statemachine import StringList
from sphinx.util.docutils import SphinxDirective

_HEADING = re.compile(r"^(\s*)#{2,4}\s+(.*\S)\s*$")
_ROW = re.compile(r"^\s*\|.*\|\s*$")
_RULE = re.compile(r"^\s*\|(\s*:?-+:?\s*\|)+\s*$")


def _cells(line: str) -> list[str]:
    return [_escape(c.strip()) for c in line.strip().strip("|").split("|")]


_LITERAL = re.compile(r"(``.+?``)")


def _escape(text: str) -> str:
    """``|x|`` (a norm, not a reST substitution) and ``name_`` (not a reference) outside
    inline literals, escaped."""
    parts = _LITERAL.split(text)
    for k in range(0, len(parts), 2):
        parts[k] = re.sub(r"(\w)_(?=\s|$|[.,;:)])", r"\1\\_", parts[k].replace("|", "\\|"))
    return "".join(parts)


def markdown_to_rst(lines: list[str]) -> list[str]:
    """Docstring lines with Markdown headings and pipe tables rewritten as reST, and the
    ``|`` of norms escaped outside literal blocks and inline literals."""
    out: list[str] = []
    i = 0
    literal_indent = None  # indentation of the "::" line whose literal block we are in
    while i < len(lines):
        line = lines[i]
        indent = len(line) - len(line.lstrip())
        if literal_indent is not None and line.strip() and indent <= literal_indent:
            literal_indent = None
        if literal_indent is not None:
            out.append(line)
            i += 1
            continue
        if line.rstrip().endswith("::"):
            literal_indent = indent
            out.append(_escape(line))
            i += 1
            continue
        heading = _HEADING.match(line)
        if heading:
            out += ["", f"{heading.group(1)}.. rubric:: {heading.group(2)}", ""]
            i += 1
            continue
        if _ROW.match(line) and i + 1 < len(lines) and _RULE.match(lines[i + 1]):
            indent = line[: len(line) - len(line.lstrip())]
            rows = [_cells(line)]
            i += 2
            while i < len(lines) and _ROW.match(lines[i]):
                rows.append(_cells(lines[i]))
                i += 1
            out += ["", f"{indent}.. list-table::", f"{indent}   :header-rows: 1", ""]
            for row in rows:
                out.append(f"{indent}   * - {row[0] or '..'}")
                out += [f"{indent}     - {cell or '..'}" for cell in row[1:]]
            out.append("")
            continue
        out.append(_escape(line))
        i += 1
    return out


def _process(app, what, name, obj, options, lines):
    lines[:] = markdown_to_rst(lines)


def public_modules(package: str) -> list[str]:
    """``package`` and every module under it whose dotted name has no part starting with ``_``,
    sorted: what the API reference documents (modules move; the list follows them)."""
    root = importlib.import_module(package)
    names = [package]
    for info in pkgutil.walk_packages(root.__path__, prefix=f"{package}."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            names.append(info.name)
    return sorted(names)


class ApiDirective(SphinxDirective):
    """``{softarm-api} PACKAGE`` (in a MyST page): an ``automodule`` section for each public
    module of PACKAGE."""

    required_arguments = 1

    def run(self):
        lines = []
        for name in public_modules(self.arguments[0]):
            lines += [f"## `{name}`", "", "```{eval-rst}", f".. automodule:: {name}", "```", ""]
        container = nodes.section()
        self.state.nested_parse(StringList(lines, source="softarm-api"), self.content_offset, container,
                                match_titles=True)
        return container.children


def setup(app):
    app.connect("autodoc-process-docstring", _process, priority=400)
    app.add_directive("softarm-api", ApiDirective)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
