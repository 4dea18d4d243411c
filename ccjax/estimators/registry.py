"""Labels -> estimators. Accepts the thesis' labels (``GW``, ``DB-GW``, ``RETINEX``, ...; grammar in
spec ch08-12 §0) and modern names (``shades-of-grey-p6``). Each family module registers its own
labels with :func:`register`; :func:`fit` builds the model for a world."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Callable

from ccjax.estimators import simple
from ccjax.estimators.base import Estimator
from ccjax.world import World


@dataclass(frozen=True)
class Entry:
    pattern: re.Pattern
    build: Callable[..., Estimator]  # build(world, match, **options)
    example: str
    description: str


_ENTRIES: list[Entry] = []


def register(pattern: str, example: str, description: str):
    """Decorator: register ``build(world, match, **options) -> Estimator`` for labels matching
    ``pattern`` (a full-match regular expression, case-sensitive as the thesis writes labels)."""

    def decorator(build):
        _ENTRIES.append(Entry(re.compile(pattern), build, example, description))
        return build

    return decorator


def lookup(label: str) -> tuple[Entry, re.Match]:
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
    return [(entry.example, entry.description) for entry in _ENTRIES]


register(r"NOTHING", "NOTHING", "assume the canonical light (§4.5)")(lambda w, m, **o: simple.fit_nothing(w, **o))
register(r"AVE-ILLUM", "AVE-ILLUM", "mean of the training illuminants (§4.5)")(
    lambda w, m, **o: simple.fit_ave_illum(w, **o)
)
register(r"GW", "GW", "grey world, 2 x mean RGB (§4.5.1)")(lambda w, m, **o: simple.fit_gw(w, **o))
register(r"DB-GW", "DB-GW", "grey world with the database mean as grey (§4.5.1)")(
    lambda w, m, **o: simple.fit_db_gw(w, **o)
)
register(r"RETINEX|MAX-RGB|max-rgb", "RETINEX", "per-channel maximum (§4.5.2)")(
    lambda w, m, **o: simple.fit_retinex(w, **o)
)
register(
    r"soft-RETINEX-t(?P<t>\d+(\.\d+)?(e-?\d+)?)", "soft-RETINEX-t0.01", "soft maximum with temperature t (differentiable)"
)(lambda w, m, **o: simple.fit_retinex(w, temperature=float(m["t"]), **o))
register(r"shades-of-grey-p(?P<p>\d+(\.\d+)?)", "shades-of-grey-p6", "Minkowski p-norm grey world (Finlayson & Trezzi)")(
    lambda w, m, **o: simple.fit_shades_of_grey(w, p=float(m["p"]), **o)
)
