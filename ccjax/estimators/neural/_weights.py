"""Trained NEURAL-NET weights in the ccjax cache: a verified entry (:mod:`ccjax._entries`) of kind
``neural`` under ``<label>-<key>``, keyed by the world arrays training reads and the recipe, read
back only when its digest (bound to the key), its arrays' names, shapes and finite values all
check (a truncated or edited entry is removed with one warning, then reported missing).
Building a net estimator never trains: missing weights raise :class:`MissingWeightsError` with the
command that trains them."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ccjax._cache import cache_directory, content_key
from ccjax._entries import Expect, normal_facts, read_arrays, write_entry
from ccjax.estimators.neural._model import Mlp
from ccjax.estimators.neural._training import RECIPES, Recipe, Schedule, TrainingLog, train
from ccjax.world import World

KIND = "neural"
"""The cache's sub-folder and entry kind of the nets' weights."""


class MissingWeightsError(FileNotFoundError):
    """No trained weights are cached for this net and world."""


def cache_key(world: World, recipe: Recipe) -> str:
    """:func:`ccjax._cache.content_key` of the world arrays training reads (reflectances, training
    illuminants, camera sensors; not the test illuminants) and of the recipe.

    Arguments:
        world: the world.
        recipe: the training recipe.

    Returns:
        The hex key.
    """
    fields = {field.name: getattr(recipe, field.name) for field in dataclasses.fields(recipe)}
    return content_key("neural", world.reflectances, world.train_illuminants, world.camera.sensors, fields)


def weights_path(world: World, label: str, recipe: Recipe | None = None) -> Path:
    """Where the weights of net ``label`` (or of ``recipe``) for ``world`` are cached.

    Arguments:
        world: the world.
        label: the net's label.
        recipe: the training recipe (default: the label's).

    Returns:
        The path (which may not exist yet).
    """
    recipe = recipe or _recipe(label)
    return cache_directory() / KIND / f"{_entry_key(world, label, recipe)}.json"


def _entry_key(world: World, label: str, recipe: Recipe) -> str:
    return f"{label}-{cache_key(world, recipe)}"


def _facts(world: World, label: str, recipe: Recipe) -> dict:
    """What the entry must say it holds (checked when read)."""
    return {"label": label, "world": world.name, "recipe": dataclasses.asdict(recipe)}


def _leaves(net: Mlp) -> list:
    return jax.tree_util.tree_leaves(eqx.filter(net, eqx.is_array))


def has_weights(world: World, label: str) -> bool:
    """True when trained weights of net ``label`` for ``world`` are cached.

    Arguments:
        world: the world.
        label: the net's label.

    Returns:
        Whether the weights are cached.
    """
    return weights_path(world, label).is_file()


def is_net_label(label: str) -> bool:
    """True for the labels whose estimator needs trained weights (NEURAL-NET, SP-NEURAL-NET).

    Arguments:
        label: an estimator label.

    Returns:
        Whether it is a net's label.
    """
    return label in RECIPES


def save(net: Mlp, world: World, label: str, recipe: Recipe, schedule: Schedule, log: TrainingLog) -> Path:
    """Write the weights as a verified cache entry (:func:`ccjax._entries.write_entry`, atomic).

    Arguments:
        net: the trained net.
        world: the world it was trained for.
        label: the net's label.
        recipe: the training recipe.
        schedule: the optimisation schedule (not stored).
        log: the training log (its seconds and final RMS rg error go in the entry's record, for people).

    Returns:
        The entry's record path.
    """
    arrays = {f"leaf{index:03d}": np.asarray(leaf) for index, leaf in enumerate(_leaves(net))}
    path, key, facts = (
        weights_path(world, label, recipe),
        _entry_key(world, label, recipe),
        _facts(world, label, recipe),
    )
    # Not write_arrays, which ignores an unwritable cache: minutes of training must not vanish unsaid.
    record = {
        **facts,
        "training_seconds": log.seconds,
        "final_rms_rg": math.sqrt(log.losses[-1]) if log.losses else None,
    }
    write_entry(path, KIND, key, normal_facts(facts), arrays, record)
    return path


def load(world: World, label: str, recipe: Recipe | None = None) -> Mlp:
    """Load the cached net ``label`` for ``world``; :class:`MissingWeightsError` if there is none.

    Arguments:
        world: the world.
        label: the net's label.
        recipe: the training recipe (default: the label's).

    Returns:
        The trained :class:`Mlp`.
    """
    recipe = recipe or _recipe(label)
    path = weights_path(world, label, recipe)
    like = Mlp(jax.random.key(0), recipe.sizes())
    leaves = _leaves(like)
    expect = {f"leaf{index:03d}": Expect(tuple(leaf.shape), "f") for index, leaf in enumerate(leaves)}
    arrays = read_arrays(KIND, _entry_key(world, label, recipe), expect, _facts(world, label, recipe))
    if arrays is None:
        raise MissingWeightsError(
            f"{label}: no trained weights for world {world.name!r} (looked for {path}); "
            f"train them with `{train_command(world, label)}` (a few minutes on a CPU)"
        )
    params, static = eqx.partition(like, eqx.is_array)
    trained = [jnp.asarray(arrays[f"leaf{index:03d}"], leaf.dtype) for index, leaf in enumerate(leaves)]
    return eqx.combine(jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(params), trained), static)


def train_command(world: World, label: str) -> str:
    """The command line that trains ``label`` for ``world`` (for error messages).

    Arguments:
        world: the world.
        label: the net's label.

    Returns:
        The shell command.
    """
    specular = " --specular" if RECIPES.get(label, Recipe()).specular is not None else ""
    if world.name == "barnard1999":
        return f"ccjax train-net --world barnard1999{specular}"
    if world.name.startswith("default (") and world.name.endswith(")"):
        return f'ccjax train-net --world default --camera "{world.name[9:-1]}"{specular}'
    return f"ccjax.estimators.neural.train_and_save(world, {label!r})"


def train_and_save(
    world: World, label: str = "NEURAL-NET", schedule: Schedule | None = None, *, progress: bool = False
) -> tuple[Path, TrainingLog]:
    """Train net ``label`` (a key of :data:`RECIPES`) for ``world`` and cache its weights.

    Returns:
        The weights' path and the :class:`TrainingLog`.

    Arguments:
        world: the world.
        label: the net's label.
        schedule: the optimisation schedule (default: ``Schedule()``).
        progress: show a progress bar.
    """
    recipe = _recipe(label)
    schedule = schedule or Schedule()
    net, log = train(world, recipe, schedule, progress=progress)
    return save(net, world, label, recipe, schedule, log), log


def _recipe(label: str) -> Recipe:
    if label not in RECIPES:
        raise ValueError(f"label: expected one of {sorted(RECIPES)}, got {label!r}")
    return RECIPES[label]
