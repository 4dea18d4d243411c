"""Deprecated module paths: a module that moved (or whose names moved) keeps its old path for one
release, warning on import and on each use of a name, naming the replacement."""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable


def warn_moved_module(old: str, new: str) -> None:
    """Warn that module ``old`` is deprecated in favour of ``new`` (called when ``old`` is imported).

    Arguments:
        old: the deprecated module's dotted name.
        new: what to import instead.

    Returns:
        None.
    """
    warnings.warn(f"{old} is deprecated: use {new}", DeprecationWarning, stacklevel=3)


def moved_names(old: str, targets: str | dict[str, str]) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """The module ``__getattr__`` and ``__dir__`` of a deprecated module: each public name resolves
    to its replacement with a ``DeprecationWarning`` naming it.

    Arguments:
        old: the deprecated module's dotted name.
        targets: the module every public name moved to, or ``{name: "module.name"}`` per name.

    Returns:
        ``(__getattr__, __dir__)`` for the deprecated module.
    """

    def target_of(name: str) -> str | None:
        if isinstance(targets, dict):
            return targets.get(name)
        if name.startswith("_") or not hasattr(importlib.import_module(targets), name):
            return None
        return f"{targets}.{name}"

    def __getattr__(name: str) -> object:
        target = target_of(name)
        if target is None:
            raise AttributeError(f"module {old!r} has no attribute {name!r}")
        warnings.warn(f"{old}.{name} is deprecated: use {target}", DeprecationWarning, stacklevel=2)
        module, _, attribute = target.rpartition(".")
        return getattr(importlib.import_module(module), attribute)

    def __dir__() -> list[str]:
        if isinstance(targets, dict):
            return sorted(targets)
        return sorted(name for name in dir(importlib.import_module(targets)) if not name.startswith("_"))

    return __getattr__, __dir__
