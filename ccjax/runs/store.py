"""Worlds and fitted models, one memory-plus-disk cache used by the command line and the Python API."""

from __future__ import annotations

import os

from ccjax.estimators.base import AbstractEstimator
from ccjax.world import World


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
        The world.
    """
    from ccjax.experiments.evaluation import cached_world

    return cached_world(kind, camera, seed=seed, data_dir=data_dir)


def fit_with_source(label: str, world: World, **options) -> tuple[AbstractEstimator, bool]:
    """Fit ``label`` to ``world`` through the cache.

    Arguments:
        label: a registry label.
        world: the world.
        **options: the family's fit options.

    Returns:
        ``(model, from_cache)``.
    """
    from ccjax.experiments.sweeps import fit_label

    if options:
        from ccjax.estimators import registry

        return registry.fit_cached(label, world, **options), False
    return fit_label(label, world)


def fit(label: str, world: World, **options) -> AbstractEstimator:
    """Fit ``label`` to ``world`` through the cache (:func:`fit_with_source` without the source).

    Arguments:
        label: a registry label.
        world: the world.
        **options: the family's fit options.

    Returns:
        The fitted model.
    """
    return fit_with_source(label, world, **options)[0]
