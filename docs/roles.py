"""Griffe extension of the documentation build: the Sphinx roles of ccjax's docstrings as links.

The docstrings cite other objects the Sphinx way (``:func:`estimate```, ``:class:`~ccjax.io.LinearImage```),
which Python's own tools and editors show well; mkdocstrings renders Markdown, where a role would
print literally. Each role becomes a mkdocs-autorefs cross-reference to the object it names,
resolved in the docstring's scope as Python resolves the name there (its module's imports and
members), and marked optional: an object that no page renders (a private helper) shows as code
with its full path as the tooltip instead of failing the strict build.
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
