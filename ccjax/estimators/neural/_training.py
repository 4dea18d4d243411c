"""Training the NEURAL-NET / SP-NEURAL-NET nets on synthetic scenes (Barnard 1999 §4.5.5): the
recipes (what a net is), the schedule (how long it is optimised) and the Adam loop."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray
from tqdm.auto import tqdm

from ccjax._adam import adam_init, adam_step
from ccjax.estimators.neural._model import N_INPUTS, Mlp, occupied_bins
from ccjax.scenes import SceneTables, Specular, sample_batch, scene_keys
from ccjax.world import World


@dataclass(frozen=True)
class Recipe:
    """What a trained net is: its training scenes and architecture (part of the cache key).

    Attributes:
        specular: specularities of the training scenes (``None``: matte).
        noise: relative Gaussian noise on every training RGB channel (``0.01`` = 1 %).
        min_surfaces, max_surfaces: surfaces per training scene, log-uniform on this range.
        hidden: hidden layer widths.
    """

    specular: Specular | None = None
    noise: float = 0.01
    min_surfaces: int = 1
    max_surfaces: int = 64
    hidden: tuple[int, ...] = (400, 30)

    def sizes(self) -> tuple[int, ...]:
        return (N_INPUTS, *self.hidden, 2)


@dataclass(frozen=True)
class Schedule:
    """How long and how a net is optimised (recorded beside the weights, not in the cache key).

    Attributes:
        steps: Adam steps.
        batch_size: training scenes per step (each one fresh: scenes are generated on the fly).
        learning_rate: peak learning rate; cosine decay to 1 % of it over ``steps``.
        seed: PRNG seed of initialisation and training scenes.
    """

    steps: int = 3000
    batch_size: int = 256
    learning_rate: float = 1e-2
    seed: int = 0


RECIPES: dict[str, Recipe] = {
    "NEURAL-NET": Recipe(),
    # Statistics deliberately different from the test protocol's 0.25 / U(0, 2) (§4.5.5, [64]).
    "SP-NEURAL-NET": Recipe(specular=Specular(probability=0.5, max_amount=1.0)),
}
"""The training recipe of each registered label: ``NEURAL-NET`` on matte scenes, ``SP-NEURAL-NET`` on
scenes with specularities (probability 0.5, amount up to 1)."""


def training_world(world: World) -> World:
    """``world`` with its training illuminants in the slot the scene sampler draws from.

    Arguments:
        world: the world.

    Returns:
        The world used for training scenes.
    """
    return eqx.tree_at(lambda w: w.test_illuminants, world, world.train_illuminants)


def training_batch(
    key: PRNGKeyArray, tables: SceneTables, recipe: Recipe, batch_size: int
) -> tuple[tuple[jax.Array, jax.Array], Float[Array, "B 2"]]:
    """Fresh training scenes: sparse histograms (:func:`occupied_bins`) and target illuminant (r,g).

    ``max_surfaces`` surfaces are drawn per scene (without replacement) and the first ``n`` kept,
    ``n`` log-uniform on ``[min_surfaces, max_surfaces]``: a uniform ``n``-subset.

    Arguments:
        key: PRNG key.
        tables: :class:`SceneTables` of :func:`training_world` (training illuminants).
        recipe: the training scene recipe.
        batch_size: number of scenes.

    Returns:
        ``((bins (B, P), weights (B, P)), targets (B, 2))``.
    """
    key_scenes, key_count, key_noise = jax.random.split(key, 3)
    scenes = sample_batch(scene_keys(key_scenes, 0, batch_size), tables, recipe.max_surfaces, recipe.specular)
    low, high = math.log(recipe.min_surfaces), math.log(recipe.max_surfaces + 1)
    count = jnp.floor(jnp.exp(jax.random.uniform(key_count, (batch_size, 1), minval=low, maxval=high)))
    mask = jnp.arange(recipe.max_surfaces, dtype=count.dtype)[None, :] < count
    rgb = scenes.rgb * (1.0 + recipe.noise * jax.random.normal(key_noise, scenes.rgb.shape))
    rgb = jnp.maximum(rgb, 0.0)
    histograms = jax.vmap(occupied_bins)(rgb, mask)
    # Not ccjax._colour.rg: its guard for black pixels (never the case for a light) lets XLA fuse the
    # division differently and moves the trained weights by float32 rounding; keep the nets as trained.
    total = jnp.sum(scenes.illuminant, axis=-1, keepdims=True)
    return histograms, scenes.illuminant[:, :2] / total


def training_loss(net: Mlp, histograms, targets) -> jax.Array:
    """Mean squared (r,g) error of ``net`` on a :func:`training_batch`.

    Arguments:
        net: the net.
        histograms: the sparse histograms of :func:`training_batch`.
        targets: ``(B, 2)`` target (r,g).

    Returns:
        The scalar loss.
    """
    predicted = jax.vmap(net.from_bins)(*histograms)
    return jnp.mean(jnp.sum((predicted - targets) ** 2, axis=-1))


def _cosine_rate(step, peak, total):
    """Cosine decay from ``peak`` to ``0.01 * peak`` over ``total`` steps (as ``optax.cosine_decay_schedule``)."""
    progress = jnp.minimum(step / total, 1.0)
    return peak * (0.01 + 0.99 * 0.5 * (1.0 + jnp.cos(jnp.pi * progress)))


@eqx.filter_jit
def _train_chunk(net, opt_state, keys, steps, tables, recipe, batch_size, peak_rate, total_steps):
    def step(carry, inputs):
        net, opt_state = carry
        key, index = inputs
        histograms, targets = training_batch(key, tables, recipe, batch_size)
        rate = _cosine_rate(index, peak_rate, total_steps)
        net, opt_state, loss = adam_step(training_loss, net, opt_state, histograms, targets, learning_rate=rate)
        return (net, opt_state), loss

    (net, opt_state), losses = jax.lax.scan(step, (net, opt_state), (keys, steps))
    return net, opt_state, losses


@dataclass
class TrainingLog:
    """Per-chunk mean training loss (mean squared (r,g) error) and wall time.

    Attributes:
        losses: mean training loss per chunk of steps.
        seconds: wall time of the training.
    """

    losses: list[float]
    seconds: float


def train(
    world: World,
    recipe: Recipe = Recipe(),
    schedule: Schedule = Schedule(),
    *,
    progress: bool = False,
    chunk: int = 50,
) -> tuple[Mlp, TrainingLog]:
    """Train the net on synthetic scenes of ``world``'s training illuminants (§4.5.5).

    Arguments:
        world: the world (reflectances, training illuminants, camera).
        recipe: training scenes and architecture (:data:`RECIPES` holds the two thesis nets).
        schedule: optimisation budget.
        progress: show a progress bar.
        chunk: steps per compiled call (one progress update each).

    Returns:
        The trained :class:`Mlp` and a :class:`TrainingLog`.
    """
    _check_recipe(recipe, world)
    if not isinstance(schedule.steps, int) or schedule.steps < 1:
        raise ValueError(f"steps: expected a positive integer, got {schedule.steps!r}")
    if not isinstance(schedule.batch_size, int) or schedule.batch_size < 1:
        raise ValueError(f"batch_size: expected a positive integer, got {schedule.batch_size!r}")
    start = time.perf_counter()
    key_init, key_train = jax.random.split(jax.random.key(schedule.seed))
    net = Mlp(key_init, recipe.sizes())
    tables = SceneTables.from_world(training_world(world))
    opt_state = adam_init(net)
    peak_rate = jnp.asarray(schedule.learning_rate, jnp.float32)
    total_steps = jnp.asarray(schedule.steps, jnp.float32)
    losses = []
    bar = tqdm(total=schedule.steps, desc="train-net", unit="step", disable=not progress)
    done = 0
    while done < schedule.steps:
        size = min(chunk, schedule.steps - done)
        steps = jnp.arange(done, done + size, dtype=jnp.uint32)
        keys = jax.vmap(lambda i: jax.random.fold_in(key_train, i))(steps)
        net, opt_state, chunk_losses = _train_chunk(
            net, opt_state, keys, steps.astype(jnp.float32), tables, recipe, schedule.batch_size, peak_rate, total_steps
        )
        losses.append(float(jnp.mean(chunk_losses)))
        done += size
        bar.update(size)
        bar.set_postfix(rms_rg=f"{math.sqrt(losses[-1]):.4f}")
    bar.close()
    return net, TrainingLog(losses=losses, seconds=time.perf_counter() - start)


def _check_recipe(recipe: Recipe, world: World) -> None:
    n_reflectances = int(world.reflectances.shape[0])
    if not 1 <= recipe.min_surfaces <= recipe.max_surfaces <= n_reflectances:
        raise ValueError(
            f"recipe: need 1 <= min_surfaces <= max_surfaces <= {n_reflectances}, "
            f"got {recipe.min_surfaces}..{recipe.max_surfaces}"
        )
    if not recipe.noise >= 0:
        raise ValueError(f"recipe: noise must be >= 0, got {recipe.noise!r}")
