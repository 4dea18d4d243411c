"""Griffe extension of the documentation build: the Sphinx roles of ccjax's docstrings as links.

The docstrings cite other objects the Sphinx way (``:func:`estimate```, ``:class:`~ccjax.io.LinearImage```),
which Python's own tools and editors show well; mkdocstrings renders Markdown, where a role would
print literally. Each role becomes a mkdocs-autorefs cross-reference to the object it names,
resolved in the docstring's scope as Python resolves the name there (its module's imports and
members), and marked optional: an object that no page renders (a private helper) shows as code
with its full path as the tooltip instead of failing the strict build.

A second extension, :class:`SplitGroupedParameters`, gives a parameter documented with others
(``height, width: image size in pixels.``) a row of its own, so that each row shows its own name,
type and default (the Google parser would read ``height, width`` as one unknown, required name).
"""

from __future__ import annotations

import html
import re

import griffe

ROLE = re.compile(r":(?:class|func|meth|mod|data|attr|exc|obj):`(~?)([^`]+)`")
"""A Sphinx cross-reference role; ``~`` shows the last component only."""


def _target(obj: griffe.Object, name: str) -> str:
    """The full path ``name`` means in ``obj``'s scope (``name`` itself when it cannot be resolved)."""
    head, _, rest = name.partition(".")
    try:
        resolved = obj.resolve(head)
    except (griffe.NameResolutionError, AttributeError):
        return name
    return f"{resolved}.{rest}" if rest else resolved


def _link(obj: griffe.Object, match: re.Match) -> str:
    short, name = match.group(1) == "~", match.group(2).strip()
    shown = name.rsplit(".", 1)[-1] if short else name
    target = html.escape(_target(obj, name.removesuffix("()")), quote=True)
    return f'<autoref optional identifier="{target}"><code>{html.escape(shown)}</code></autoref>'


def _rewrite(obj: griffe.Object) -> None:
    if obj.docstring is not None and ":" in obj.docstring.value:
        obj.docstring.value = ROLE.sub(lambda match: _link(obj, match), obj.docstring.value)
    for member in obj.members.values():
        if not member.is_alias and isinstance(member, griffe.Object):
            _rewrite(member)


class SphinxRoles(griffe.Extension):
    """Rewrite every docstring of a loaded package once it is complete (so names resolve)."""

    def on_package(self, *, pkg: griffe.Module, **kwargs) -> None:
        del kwargs
        _rewrite(pkg)


PARAMETER_SECTION = re.compile(
    r"^\s*(?:args|arguments|params|parameters|keyword args|keyword arguments|other args|other arguments"
    r"|other params|other parameters):\s*$",
    re.IGNORECASE,
)
"""The header of a Google parameters section."""

GROUPED = re.compile(r"^(\s+)(\*{0,2}\w+(?:\s*,\s*\*{0,2}\w+)+)\s*:(.*)$")
"""An item documenting several parameters at once: ``a, b: description``."""


def split_grouped(text: str) -> str:
    """A docstring with each grouped parameter item (``a, b: text``) written as one item per name.

    Arguments:
        text: the docstring (cleaned, as griffe keeps it).

    Returns:
        The docstring with ``a: text`` and ``b: text`` (continuation lines repeated) in place of
        each grouped item of a parameters section; other lines unchanged.
    """
    lines = text.split("\n")
    out: list[str] = []
    index = 0
    while index < len(lines):
        line = lines[index]
        out.append(line)
        index += 1
        if not PARAMETER_SECTION.match(line):
            continue
        section_indent = len(line) - len(line.lstrip())
        item_indent = None
        while index < len(lines):
            line = lines[index]
            indent = len(line) - len(line.lstrip())
            if line.strip() and (indent <= section_indent or (item_indent is not None and indent < item_indent)):
                break  # the section ends
            if line.strip() and item_indent is None:
                item_indent = indent
            match = GROUPED.match(line) if line.strip() and indent == item_indent else None
            index += 1
            if match is None:
                out.append(line)
                continue
            continuation = []
            while index < len(lines) and (
                not lines[index].strip() or len(lines[index]) - len(lines[index].lstrip()) > indent
            ):
                continuation.append(lines[index])
                index += 1
            while continuation and not continuation[-1].strip():
                index -= 1  # blank lines after the item stay where they were
                continuation.pop()
            for name in match.group(2).split(","):
                out.append(f"{match.group(1)}{name.strip()}:{match.group(3)}")
                out.extend(continuation)
    return "\n".join(out)


def _split(obj: griffe.Object) -> None:
    if obj.docstring is not None and "," in obj.docstring.value:
        obj.docstring.value = split_grouped(obj.docstring.value)
    for member in obj.members.values():
        if not member.is_alias and isinstance(member, griffe.Object):
            _split(member)


class SplitGroupedParameters(griffe.Extension):
    """Give each parameter of a grouped item (``a, b: text``) its own row."""

    def on_package(self, *, pkg: griffe.Module, **kwargs) -> None:
        del kwargs
        _split(pkg)
