"""Worlds and fitted models: one memory-plus-disk cache, used by the command line and the Python API.

In memory, per cache directory: the last :data:`MEMO_SIZE` fitted models and worlds of this process
(a repeated request returns the same object). On disk, under :func:`ccjax._cache.cache_directory`:
``fits/<key>.json|.npz`` and ``world/<key>.json|.npz``, keyed by
:func:`ccjax._cache.content_key` of everything the value depends on (for a fit: the label, the
world's content, the options, the float width, :func:`ccjax._cache.code_fingerprint`), so a second
process fits nothing and an edit of ccjax's code refits.

The files are data only (:mod:`ccjax.runs._serial`): arrays without pickle and a JSON record with a
schema version and a content digest; a model is rebuilt only from the classes of
:func:`ccjax.estimators.registry.model_classes`, looked up by name. An entry that does not verify
is fitted (or built) again and replaced, with one :class:`CacheEntryRejected` warning. Models that
cannot be written as data (a function inside) stay in memory only.

Trained-model files (:func:`save_trained`, :func:`load_model`) are the house format of
:func:`ccjax._cache.save_model`: a model's leaves and a JSON record of the label and world its
skeleton is fitted to.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import enum
import json
import os
from collections.abc import Callable, Hashable, Mapping
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import numpy as np

from ccjax._cache import FORMAT_VERSION, cache_directory, code_fingerprint, content_key, read_model_metadata, save_model
from ccjax._cache import load_model as load_leaves
from ccjax._entries import CacheEntryRejected, reject
from ccjax.estimators import registry
from ccjax.estimators.base import AbstractEstimator
from ccjax.runs import _serial
from ccjax.world import World

MEMO_SIZE = 64
"""Fitted models (and, separately, worlds) kept in memory; the least recently used go first."""


_MODELS: collections.OrderedDict[Hashable, AbstractEstimator] = collections.OrderedDict()
_WORLDS: collections.OrderedDict[Hashable, World] = collections.OrderedDict()


def world(
    kind: str = "default", camera: str | None = None, *, seed: int = 0, data_dir: str | os.PathLike | None = None
) -> World:
    """``World.default(camera)`` or ``World.barnard1999()``, built once and then read from the cache.

    Arguments:
        kind: ``"default"`` (embedded data) or ``"barnard1999"`` (the thesis world, external data).
        camera: camera of the default world (default: the Canon EOS 5D Mark II).
        seed: seed of the illuminant mixtures.
        data_dir: where the external data lives (``barnard1999``).

    Returns:
        The world (the same object for repeated calls in a process); its arrays are stored in the
        cache (``world/``).
    """
    if kind == "barnard1999":
        from ccjax.data import find_data_file

        source = find_data_file("sfu_barnard/sony_dxc930_380-780-4nm.csv", data_dir)
        parts, build = (kind, str(source), seed), lambda: World.barnard1999(data_dir, seed=seed)
    elif kind == "default":
        name = camera or "Canon EOS 5D Mark II"
        parts, build = (kind, name, seed), lambda: World.default(name, seed=seed)
    else:
        raise ValueError(f"world: expected 'default' or 'barnard1999', got {kind!r}")
    # float32, or float64 under x64: a world is built (and stored) in JAX's float of the moment.
    parts = (*parts, jax.dtypes.canonicalize_dtype(np.float64).name)
    folder = cache_directory()
    memo = (str(folder), *parts)
    if memo in _WORLDS:
        _WORLDS.move_to_end(memo)
        return _WORLDS[memo]
    key = content_key("world", code_fingerprint(), *parts)
    built = _world_on_disk(folder / "world" / f"{key}.json", key, build, {"world": list(parts)})
    _remember(_WORLDS, memo, built)
    return built


def _world_on_disk(path: Path, key: str, build: Callable[[], World], facts: Mapping[str, Any]) -> World:
    try:
        entry = _serial.read_entry(path, "world", key)
        if entry is not None:
            return _serial.world_from_parts(*entry)
    except _serial.Rejected as why:
        _reject(path, why, "building the world again")
    fresh = build()
    try:
        names, arrays = _serial.world_parts(fresh)
    except _serial.Unserialisable:
        return fresh
    # What a later run reads (the same arrays), so that every run computes with the same world.
    stored = _serial.world_from_parts(names, arrays)
    with contextlib.suppress(OSError):  # an unwritable cache only costs time
        _serial.write_entry(path, "world", key, names, arrays, facts)
    return stored


def fit_with_source(label: str, world: World, **options) -> tuple[AbstractEstimator, bool]:
    """Fit ``label`` to ``world`` through the cache.

    Arguments:
        label: a registry label.
        world: the world.
        **options: the family's fit options (JSON-like values, arrays and Modules are part of the
            key; with any other value the model is fitted every time).

    Returns:
        ``(model, from_cache)``: ``from_cache`` is True when the model came from memory or disk.
    """
    entry, _ = registry.lookup(label)  # unknown labels fail before anything is hashed
    if not _keyable(options):
        return registry.fit(label, world, **options), False
    folder = cache_directory()
    width = jax.dtypes.canonicalize_dtype(np.float64).name  # float32, or float64 under x64
    key = content_key("fit", label, world, options, width, code_fingerprint())
    memo = (str(folder), key)
    if memo in _MODELS:
        _MODELS.move_to_end(memo)
        return _MODELS[memo], True
    if entry.stored:
        facts = {"label": label, "world": world.name, "options": options}
        path = folder / "fits" / f"{key}.json"
        model, hit = _fit_on_disk(path, key, lambda: registry.fit(label, world, **options), facts)
    else:
        model, hit = registry.fit(label, world, **options), False
    _remember(_MODELS, memo, model)
    return model, hit


def fit(label: str, world: World, **options) -> AbstractEstimator:
    """Fit ``label`` to ``world`` through the cache (:func:`fit_with_source` without the source).

    Arguments:
        label: a registry label.
        world: the world.
        **options: the family's fit options.

    Returns:
        The fitted model (the same object for equal arguments within a process).
    """
    return fit_with_source(label, world, **options)[0]


def save_trained(
    path: str | os.PathLike,
    model: AbstractEstimator,
    *,
    label: str,
    camera: str | None,
    world_seed: int = 0,
    record: Mapping[str, Any] | None = None,
    overwrite: bool = True,
) -> Path:
    """Write a trained model: its leaves and a JSON record (format version, label, the camera and
    world seed its start was fitted to, and ``record``).

    Arguments:
        path: the model file (``.eqx``; the record goes beside it as ``.json``).
        model: the trained estimator.
        label: its registry label (the skeleton :func:`load_model` fits).
        camera: the camera whose default world the start was fitted to, or None when no camera's
            curves were used (a family that learns from the photographs alone; the skeleton then
            comes from :meth:`World.default`'s camera, whose numbers the file's leaves replace).
        world_seed: that world's seed.
        record: more JSON fields (``ccjax.training`` records its procedure and training log).
        overwrite: replace existing files (else ``FileExistsError``).

    Returns:
        The model file's path.

    Raises:
        ValueError: ``record`` holds a value strict JSON cannot (NaN, infinity, an object).
    """
    metadata = {
        **(record or {}),
        "kind": "trained-estimator",
        "label": label,
        "camera": camera,
        "world_seed": int(world_seed),
    }
    try:  # the record is strict JSON: NaN or Infinity would make it unreadable to other parsers
        json.dumps(metadata, allow_nan=False)
    except (TypeError, ValueError) as error:
        raise ValueError(f"record: the model record of {path} is not strict JSON: {error}") from None
    return save_model(Path(path), model, metadata, replace=overwrite)


def trained_record(path: str | os.PathLike) -> dict[str, Any]:
    """The JSON record of a model file written by :func:`save_trained` (label, camera, world seed,
    training procedure and log), checked to be one.

    Arguments:
        path: the model file (its record is beside it, ``.json``).

    Returns:
        The record.

    Raises:
        ValueError: not a trained-model record, another format version, or a field of the wrong type.
    """
    path = Path(path)
    metadata = read_model_metadata(path)
    if metadata.get("kind") != "trained-estimator" or "label" not in metadata:
        raise ValueError(f"model: {path} is not a trained-estimator file (format {FORMAT_VERSION})")
    fields = (
        ("label", str, None, "a str"),
        ("camera", (str, type(None)), None, "a str or null"),
        ("world_seed", int, 0, "an int"),
    )
    for field_name, kind, default, expected in fields:
        value = metadata.get(field_name, default)
        # A record names its camera, or says it used none (null): a missing field is neither.
        missing = field_name == "camera" and field_name not in metadata
        if missing or not isinstance(value, kind) or isinstance(value, bool):
            raise ValueError(f"model: the record of {path} gives {field_name} {value!r}; expected {expected}")
    return metadata


def load_model(path: str | os.PathLike, camera: str | None = None) -> AbstractEstimator:
    """Read a model written by :func:`save_trained` (format :data:`ccjax._cache.FORMAT_VERSION`):
    its skeleton is the label fitted to the recorded camera's default world, its leaves the file's.

    A camera-conditioned model (record ``conditioned: true``, ``ccjax train --method any-camera``)
    is bound to ``camera`` at load: its map into the model's space from the camera's curves
    (:meth:`ccjax.estimators.conditioned.AnyCamera.bind`).

    Arguments:
        path: the model file (as written by :func:`save_trained`, e.g. by ``ccjax train --out``).
        camera: the camera of the images a conditioned model will be given (required for one,
            not used by the others: their record names their camera).

    Returns:
        The trained estimator: the recorded method label fitted to ``World.default(camera,
        seed=world_seed)`` from the file's record (``World.default``'s camera when the record names
        none), with every array leaf replaced by the file's; a conditioned one bound to ``camera``.

    Raises:
        ValueError: not a trained-model file, another format version, leaves that do not fit, or a
            conditioned model without ``camera``.
    """
    path = Path(path)
    metadata = trained_record(path)
    if metadata.get("conditioned") is True and camera is None:
        raise ValueError(
            f"camera: the model {path} is camera-conditioned (any-camera): name the camera of the images (--camera)"
        )
    skeleton = fit(metadata["label"], world("default", metadata.get("camera"), seed=metadata.get("world_seed", 0)))
    model = load_leaves(path, skeleton)
    if metadata.get("conditioned") is True:
        from ccjax.camera import Camera
        from ccjax.estimators.conditioned import AnyCamera

        if not isinstance(model, AnyCamera):
            raise ValueError(f"model: {path} records conditioned: true but holds a {type(model).__name__}")
        return model.bind(Camera.from_name(str(camera)))
    return model


def clear_memory() -> None:
    """Forget the models and worlds kept in memory (the disk cache stays)."""
    _MODELS.clear()
    _WORLDS.clear()


def _fit_on_disk(
    path: Path, key: str, compute: Callable[[], AbstractEstimator], facts: Mapping[str, Any]
) -> tuple[AbstractEstimator, bool]:
    allowed = registry.model_classes()
    try:
        entry = _serial.read_entry(path, "fit", key)
        if entry is not None:
            return _decode(*entry, allowed), True
    except _serial.Rejected as why:
        _reject(path, why, "refitting")
    model = compute()
    try:
        arrays: dict[str, np.ndarray] = {}
        skeleton = _serial.encode(model, allowed, arrays)
        stored = _decode(skeleton, arrays, allowed)
    except (_serial.Unserialisable, _serial.Rejected):
        return model, False
    if not _serial.same_tree(stored, model):
        return model, False
    with contextlib.suppress(OSError):  # an unwritable cache only costs time
        _serial.write_entry(path, "fit", key, skeleton, arrays, facts)
    # Hand back what a later run reads (the same leaves, types and weak types), so both runs trace
    # the same programs and share XLA's compilation cache.
    return stored, False


def _decode(skeleton: Any, arrays: Mapping[str, np.ndarray], allowed: Mapping[str, type]) -> Any:
    try:
        return _serial.decode(skeleton, arrays, allowed)
    except (TypeError, ValueError, RecursionError) as error:
        raise _serial.Rejected(f"{type(error).__name__}: {error}") from None


def _reject(path: Path, why: Exception, action: str) -> None:
    reject(path, why, action, stacklevel=5)


def _remember(memo: collections.OrderedDict, key: Hashable, value: Any) -> None:
    memo[key] = value
    while len(memo) > MEMO_SIZE:
        memo.popitem(last=False)


def _keyable(value: Any) -> bool:
    """Whether :func:`ccjax._cache.content_key` captures ``value`` whole (it writes other objects
    as their ``str``, which may abbreviate)."""
    if value is None or isinstance(value, (bool, int, float, str, enum.Enum, np.ndarray, np.generic, jax.Array)):
        return True
    if isinstance(value, eqx.Module):
        return True
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return all(
            isinstance(getattr(value, f.name), (type(None), bool, int, float, str, enum.Enum))
            for f in dataclasses.fields(value)
        )
    if isinstance(value, (list, tuple)):
        return all(_keyable(item) for item in value)
    if isinstance(value, Mapping):
        return all(isinstance(name, str) and _keyable(item) for name, item in value.items())
    return False


__all__ = ["MEMO_SIZE", "CacheEntryRejected", "clear_memory", "fit", "fit_with_source", "world"]
