"""Labels -> estimators. Accepts the thesis' labels (``GW``, ``DB-GW``, ``RETINEX``, ...; the grammar of
Barnard 1999 Table 4.1 and §6) and modern names (``shades-of-grey-p6``, ``grey-edge-1-6-2``).

Each family module declares its labels with the :func:`register` decorator on a build function
``build(world, match, **options) -> model``; the entry records the label grammar, the input kind
(surface list or image), whether the fit is traceable (pure JAX, so ``jax.jit`` / ``jax.grad`` of
``fit`` with respect to the world work) and whether the model is differentiable with respect to
its input. :func:`fit` builds a model for a world (uncached: :mod:`ccjax.runs.store` keeps fitted
models); :func:`model_classes` is the allow-list of classes the store rebuilds cached models from.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import importlib
import inspect
import re
import sys
import types
import typing
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import equinox as eqx

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
        stored: the store may keep fitted models on disk (False where the fit reads files that
            change, such as trained weights, so that a stored model could go stale).
        untrained: the fit is only training's starting point (FFCC's zero filters, an MLP's random
            weights): its answers mean nothing until the model is trained on labelled photographs,
            so estimating by this label is refused (:func:`refuse_untrained`).
    """

    pattern: re.Pattern
    build: Callable[..., AbstractEstimator]
    example: str
    description: str
    grammar: str
    input_kind: str = "surfaces"
    traceable_fit: bool = False
    differentiable: bool = False
    stored: bool = True
    untrained: bool = False


_ENTRIES: list[Entry] = []

# Family modules register their labels when imported; they are imported on first look-up so that
# importing ccjax stays cheap and a family's module is the one place its labels are declared.
FAMILIES = (
    "ccjax.estimators.simple",
    "ccjax.estimators.gamut",
    "ccjax.estimators.correlation",
    "ccjax.estimators.neural",
    "ccjax.estimators.spatial",
    "ccjax.estimators.ffcc",
    "ccjax.estimators.conditioned",
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
    stored: bool = True,
    untrained: bool = False,
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
        stored: the store may keep fitted models on disk (see :class:`Entry`).
        untrained: the fit is only training's starting point (see :class:`Entry`).

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
            compiled,
            build,
            example,
            description,
            grammar or example,
            kind,
            bool(traceable_fit),
            bool(differentiable),
            bool(stored),
            bool(untrained),
        )
        _ENTRIES.append(entry)
        return build

    return decorator


def lookup(label: str) -> tuple[Entry, re.Match]:
    """The entry whose pattern matches ``label``.

    Arguments:
        label: a registry label.

    Returns:
        ``(entry, match)``: the :class:`Entry` and its pattern's match.

    Raises:
        ValueError: no pattern matches (the message lists the known labels).
    """
    _load_families()
    for entry in _ENTRIES:
        match = entry.pattern.fullmatch(label)
        if match:
            return entry, match
    close = _close_labels(label)
    hint = f"did you mean {' or '.join(close)}? " if close else ""
    raise ValueError(
        f"method: unknown label {label!r}; {hint}`ccjax methods` (ccjax.estimators.registry.available()) lists "
        "every family's label grammar"
    )


def refuse_untrained(labels, option: str = "method") -> None:
    """Refuse estimating by the label of a method whose fit is only training's starting point
    (:attr:`Entry.untrained`): an untrained FFCC or MLP answers with its initial parameters, a
    light that has nothing to do with the image, marked as estimated. Fitting such a label stays
    allowed (it is where training starts).

    Arguments:
        labels: registry labels (a single label may be given as a string).
        option: the argument's name for the message (``"method"``, ``"--methods"``).

    Returns:
        None.

    Raises:
        ValueError: naming the first untrained label, how to train it and how to pass the model.
    """
    for label in [labels] if isinstance(labels, str) else labels:
        if lookup(label)[0].untrained:
            raise ValueError(
                f"{option}: {label} is learned from labelled photographs and ccjax ships no trained parameters for "
                f"it; untrained it would answer with its initial parameters. Train it (ccjax train --method {label} "
                f"FOLDER --out MODEL.eqx; or evaluate --train {label}) and estimate with the "
                "model (--model MODEL.eqx; ccjax.load_model(path) in Python)"
            )


def _spelling(name: str) -> str:
    # Case, hyphens and spaces are how labels are most often mistyped ("Grey World", "greyworld").
    return re.sub(r"[^0-9a-z]", "", name.lower())


def _close_labels(label: str) -> list[str]:
    """Up to three known labels spelled like ``label``: the families' fixed spellings and examples,
    also found by their names in words ("grey world" gives GW); a parameterised family's
    suggestion shows its grammar."""
    import difflib

    suggestions: dict[str, str] = {}
    for entry in _ENTRIES:
        words = re.split(r"[,(]", entry.description)[0].strip()
        names = [*entry.grammar.split(" | "), entry.example, *([words] if len(words.split()) <= 3 else [])]
        fixed = all(entry.pattern.fullmatch(name) for name in entry.grammar.split(" | "))
        for name in names:
            shown = repr(name if entry.pattern.fullmatch(name) else entry.example)
            suggestions.setdefault(_spelling(name), shown if fixed else f"{shown} ({entry.grammar})")
    close = difflib.get_close_matches(_spelling(label), list(suggestions), n=3, cutoff=0.75)
    return list(dict.fromkeys(suggestions[name] for name in close))


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


def available() -> list[Entry]:
    """Every registered family's :class:`Entry` (``grammar``, ``example``, ``description``,
    ``input_kind``, ``traceable_fit``, ``differentiable``), in registration order.

    Returns:
        The entries.
    """
    _load_families()
    return list(_ENTRIES)


# Layers above the estimators: never part of a fitted model (and the top package, whose lazily
# imported attributes would otherwise reach them).
_NOT_MODEL_MODULES = ("ccjax.runs", "ccjax.experiments", "ccjax.training", "ccjax.cli")


def model_classes() -> dict[str, type]:
    """The classes a cached fitted model may be rebuilt from, by ``"module:qualname"``: the
    allow-list of :mod:`ccjax.runs.store` (a name read from a cache file is looked up here, never
    imported).

    They are the concrete equinox Modules, enums and frozen dataclasses defined in the ccjax modules
    that the registered families import (directly or through other ccjax modules), and the classes
    the fields of those classes are declared to hold (e.g. ``equinox.nn.Linear`` inside a net).

    Returns:
        A new dict ``{qualified name: class}``.
    """
    _load_families()
    starts = tuple(dict.fromkeys([*FAMILIES, *(entry.build.__module__ for entry in _ENTRIES)]))
    return dict(_model_classes(starts))


def qualified_name(cls: type) -> str:
    """``"module:qualname"`` of ``cls``, the name :func:`model_classes` lists it under.

    Arguments:
        cls: a class.

    Returns:
        The name.
    """
    return f"{cls.__module__}:{cls.__qualname__}"


@functools.cache
def _model_classes(starts: tuple[str, ...]) -> tuple[tuple[str, type], ...]:
    found: dict[str, type] = {}
    for module in _imported_modules(starts):
        for value in vars(module).values():
            if isinstance(value, type) and value.__module__ == module.__name__ and _rebuildable(value):
                found[qualified_name(value)] = value
    pending = list(found.values())
    while pending:
        for cls in _declared_classes(pending.pop()):
            name = qualified_name(cls)
            if name not in found and _rebuildable(cls):
                found[name] = cls
                pending.append(cls)
    return tuple(sorted(found.items()))


def _is_model_module(name: str) -> bool:
    return name.startswith("ccjax.") and not name.startswith(_NOT_MODEL_MODULES)


def _imported_modules(starts: tuple[str, ...]) -> list[types.ModuleType]:
    """``starts`` (the families' modules) and the ccjax modules they reach through their globals
    (modules, classes and functions they import), transitively."""
    seen: dict[str, types.ModuleType] = {}
    pending = [name for name in starts if name in sys.modules]
    while pending:
        name = pending.pop()
        if name in seen or not (_is_model_module(name) or name in starts):
            continue
        seen[name] = module = sys.modules[name]
        for value in vars(module).values():
            if isinstance(value, types.ModuleType):
                pending.append(value.__name__)
            elif isinstance(value, (type, types.FunctionType)) and isinstance(value.__module__, str):
                pending.append(value.__module__)
        pending = [other for other in pending if other in sys.modules]
    return list(seen.values())


def _rebuildable(cls: type) -> bool:
    if inspect.isabstract(cls) or "<locals>" in cls.__qualname__:
        return False
    if issubclass(cls, (enum.Enum, eqx.Module)):
        return True
    return dataclasses.is_dataclass(cls) and cls.__dataclass_params__.frozen  # pyright: ignore[reportAttributeAccessIssue]


def _declared_classes(cls: type) -> Iterator[type]:
    """The classes named in the annotations of ``cls``'s dataclass fields."""
    if not dataclasses.is_dataclass(cls):
        return
    try:
        hints = typing.get_type_hints(cls)
    except (NameError, TypeError, AttributeError):  # an annotation only a type checker can read
        return
    for field in dataclasses.fields(cls):
        yield from _classes_in(hints.get(field.name))


def _classes_in(hint) -> Iterator[type]:
    if isinstance(hint, type) and not typing.get_args(hint):
        yield hint
    for argument in typing.get_args(hint):
        yield from _classes_in(argument)
