"""Labels -> estimators. Accepts the thesis' labels (``GW``, ``DB-GW``, ``RETINEX``, ...; the grammar of
Barnard 1999 Table 4.1 and §6) and modern names (``shades-of-grey-p6``, ``grey-edge-1-6-2``).

Each family module declares its labels with the :func:`register` decorator on a build function
``build(world, match, **options) -> model``; the entry records the label grammar, the input kind
(surface list or image), whether the fit is traceable (pure JAX, so ``jax.jit`` / ``jax.grad`` of
``fit`` with respect to the world work) and whether the model is differentiable with respect to
its input. :func:`fit` builds a model for a world; :func:`fit_cached` memoises it in-process.
"""

from __future__ import annotations

import collections
import importlib
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from ccjax._cache import content_key
from ccjax.estimators.base import KINDS, AbstractEstimator
from ccjax.world import World


@dataclass(frozen=True)
class Entry:
    """One registered family of labels.

    Attributes:
        pattern: full-match regular expression of the labels (case-sensitive, as the thesis writes them).
        build: ``build(world, match, **options) -> model``.
        example: a label the pattern accepts (shown in listings and error messages).
        description: one line, citing the thesis section where there is one.
        grammar: the label grammar for people, e.g. ``"shades-of-grey-p<P>"``.
        input_kind: ``"surfaces"`` (``(P, 3)`` lists) or ``"image"`` (``(H, W, 3)``).
        traceable_fit: the fit is pure JAX (``jax.jit`` of ``fit`` over the world works).
        differentiable: the model has useful gradients with respect to its input RGB.
    """

    pattern: re.Pattern
    build: Callable[..., AbstractEstimator]
    example: str
    description: str
    grammar: str
    input_kind: str = "surfaces"
    traceable_fit: bool = False
    differentiable: bool = False

    def __iter__(self) -> Iterator[str]:
        """Deprecated (one release): unpack as the ``(example, description)`` pair that
        :func:`available` used to return."""
        return iter((self.example, self.description))


_ENTRIES: list[Entry] = []

# Family modules register their labels when imported; they are imported on first look-up so that
# importing ccjax stays cheap and a family's module is the one place its labels are declared.
FAMILIES = (
    "ccjax.estimators.simple",
    "ccjax.estimators.gamut",
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


def register(
    pattern: str,
    example: str | None = None,
    description: str | None = None,
    *,
    grammar: str | None = None,
    input_kind: str | None = None,
    traceable_fit: bool = False,
    differentiable: bool = False,
):
    """Decorator: register ``build(world, match, **options)`` for the labels matching ``pattern``.

    Arguments:
        pattern: full-match regular expression (case-sensitive).
        example: a label the pattern accepts.
        description: one line for listings.
        grammar: the label grammar for people (default: ``example``).
        input_kind: ``"surfaces"`` or ``"image"``; ``None`` (the older positional form) means
            surfaces. :func:`fit` checks that the built model agrees.
        traceable_fit: the build is pure JAX in the world's arrays.
        differentiable: the model has useful input gradients.

    Returns:
        The decorator (it returns ``build`` unchanged).
    """
    if example is None or description is None:
        raise ValueError(f"register {pattern!r}: give example and description")
    kind = "surfaces" if input_kind is None else input_kind
    if kind not in KINDS:
        raise ValueError(f"input_kind: expected one of {KINDS}, got {input_kind!r}")
    compiled = re.compile(pattern)
    if not compiled.fullmatch(example):
        raise ValueError(f"register {pattern!r}: the example {example!r} does not match the pattern")

    def decorator(build):
        entry = Entry(
            compiled, build, example, description, grammar or example, kind, bool(traceable_fit), bool(differentiable)
        )
        _ENTRIES.append(entry)
        return build

    return decorator


def lookup(label: str) -> tuple[Entry, re.Match]:
    """The entry whose pattern matches ``label`` and the match; ``ValueError`` listing the known
    labels when none does."""
    _load_families()
    for entry in _ENTRIES:
        match = entry.pattern.fullmatch(label)
        if match:
            return entry, match
    known = ", ".join(entry.grammar for entry in _ENTRIES)
    raise ValueError(f"method: unknown label {label!r}; known: {known}")


def fit(label: str, world: World, **options) -> AbstractEstimator:
    """Fit the estimator named ``label`` to ``world``.

    Arguments:
        label: a registry label, e.g. ``"GW"`` or ``"shades-of-grey-p6"``.
        world: the world supplying canonical light, training illuminants and reflectances.
        **options: passed to the family's fit function.

    Returns:
        The fitted model (an :class:`~ccjax.estimators.base.AbstractEstimator` of the entry's input kind).
    """
    entry, match = lookup(label)
    model = entry.build(world, match, **options)
    if not isinstance(model, AbstractEstimator):
        raise TypeError(f"{label}: the family built a {type(model).__name__}, not an AbstractEstimator")
    if model.input_kind != entry.input_kind:
        raise TypeError(
            f"{label}: registered with input_kind {entry.input_kind!r} but built a {type(model).__name__}, "
            f"an {model.input_kind!r} estimator"
        )
    return model


_MEMO: collections.OrderedDict[str, AbstractEstimator] = collections.OrderedDict()
MEMO_SIZE = 64
"""Fitted models :func:`fit_cached` keeps (least recently used dropped first)."""


def fit_cached(label: str, world: World, **options) -> AbstractEstimator:
    """:func:`fit`, memoised in this process by the content of ``label``, ``world`` and ``options``
    (:func:`ccjax._cache.content_key`), for pipelines that fit the same label repeatedly.

    Arguments:
        label: a registry label.
        world: the world.
        **options: passed to the family's fit function.

    Returns:
        The fitted model (the same object for equal arguments).
    """
    lookup(label)  # unknown labels fail before anything is hashed
    key = content_key("fit", label, world, options)
    if key in _MEMO:
        _MEMO.move_to_end(key)
        return _MEMO[key]
    model = fit(label, world, **options)
    _MEMO[key] = model
    if len(_MEMO) > MEMO_SIZE:
        _MEMO.popitem(last=False)
    return model


def available() -> list[Entry]:
    """Every registered family's :class:`Entry` (``grammar``, ``example``, ``description``,
    ``input_kind``, ``traceable_fit``, ``differentiable``), in registration order.

    Returns:
        The entries.
    """
    _load_families()
    return list(_ENTRIES)
