"""Labels -> estimators. Accepts the thesis' labels (``GW``, ``DB-GW``, ``RETINEX``, ...; grammar in
spec ch08-12 §0) and modern names (``shades-of-grey-p6``). Each family module registers its own
labels with :func:`register`; :func:`fit` builds the model for a world."""

from __future__ import annotations

import importlib
import re
from collections.abc import Callable
from dataclasses import dataclass

from ccjax.estimators.base import Estimator
from ccjax.world import World


@dataclass(frozen=True)
class Entry:
    pattern: re.Pattern
    build: Callable[..., Estimator]  # build(world, match, **options)
    example: str
    description: str


_ENTRIES: list[Entry] = []

# Family modules register their labels when imported; they are imported on first look-up so that
# importing ccjax stays cheap and a family's module is the one place its labels are declared.
FAMILIES = (
    "ccjax.estimators.simple",
    "ccjax.estimators.gamut",
    "ccjax.estimators.cip",
    "ccjax.estimators.correlation",
    "ccjax.estimators.neural",
    "ccjax.estimators.spatial",
)
_loaded = False


def _load_families() -> None:
    global _loaded
    if _loaded:
        return
    _loaded = True
    for name in FAMILIES:
        try:
            importlib.import_module(name)
        except ModuleNotFoundError as error:
            if error.name != name:  # a family that exists but fails to import is a real error
                raise


def register(pattern: str, example: str, description: str):
    """Decorator: register ``build(world, match, **options) -> Estimator`` for labels matching
    ``pattern`` (a full-match regular expression, case-sensitive as the thesis writes labels)."""

    def decorator(build):
        _ENTRIES.append(Entry(re.compile(pattern), build, example, description))
        return build

    return decorator


def lookup(label: str) -> tuple[Entry, re.Match]:
    _load_families()
    for entry in _ENTRIES:
        match = entry.pattern.fullmatch(label)
        if match:
            return entry, match
    known = ", ".join(entry.example for entry in _ENTRIES)
    raise ValueError(f"method: unknown label {label!r}; known: {known}")


def fit(label: str, world: World, **options) -> Estimator:
    """Fit the estimator named ``label`` to ``world``.

    Arguments:
        label: a registry label, e.g. ``"GW"`` or ``"shades-of-grey-p6"``.
        world: the world supplying canonical light, training illuminants and reflectances.
        **options: passed to the family's fit function.
    """
    entry, match = lookup(label)
    return entry.build(world, match, **options)


def available() -> list[tuple[str, str]]:
    """``(example label, description)`` for every registered family."""
    _load_families()
    return [(entry.example, entry.description) for entry in _ENTRIES]
