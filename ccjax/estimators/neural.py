"""The neural-net estimator: an MLP on the binarised (r,g) histogram (Barnard 1999 §4.5.5).

The thesis' net (Cardei, Funt & Barnard [63-67]; spec ch02-04 §6.6, ch08-12 §1.6): a multi-layer
perceptron ``2500 -> 400 -> 30 -> 2``. Input ``b`` of the 2500 is 1 when at least one scene
chromaticity falls in the (r,g) bin ``b`` of a 50 x 50 grid of 0.02-wide cells; the two outputs are
the illuminant's (r,g). It is trained on synthetic scenes of the world's reflectances under its
TRAINING illuminants, with the true illuminant chromaticity as target and small Gaussian noise on
the training data. NEURAL-NET is trained on matte scenes, SP-NEURAL-NET on scenes with
specularities generated with statistics different from the test protocol's (§4.5.5, [64]).

What the thesis leaves open is fixed here (spec ch02-04 §10 items 22-23, DESIGN.md §10) and
recorded in :class:`Recipe` and :class:`Schedule`:

* sigmoid hidden units, linear outputs, mean squared (r,g) error;
* Adam (optax) in place of back-propagation without momentum (DESIGN.md §10 allows it): 3000
  steps of 256 fresh scenes, learning rate 1e-2 with cosine decay, reach the thesis' Table 4.2
  accuracy in a few CPU minutes (plain SGD was not tried);
* a fully connected first layer instead of the thesis' rewiring of dormant links, which was a
  speed device (§4.5.5); it is evaluated sparsely (:func:`occupied_bins`), which is exact;
* the number of surfaces of a training scene is log-uniform on 1..64 (the test protocol's 8 is
  inside, and the net sees both sparse and rich histograms);
* noise: each training RGB is multiplied per channel by ``1 + 0.01 N(0, 1)`` ("small amount of
  normally distributed noise", 1 % of the signal);
* SP-NEURAL-NET's training specularities: each surface specular with probability 0.5 and
  ``U(0, 1)`` times the perfect white added (the test protocol uses 0.25 and ``U(0, 2)``), a
  different recipe as the thesis reports (§4.5.5, Table 4.3 discussion).

Trained weights live in the cache (DESIGN.md §2): ``$CCJAX_CACHE`` else the platform cache
directory, under ``neural/``, keyed by a hash of the world arrays the training reads (reflectances,
training illuminants, camera sensors) and of the :class:`Recipe`. The optimisation budget
(:class:`Schedule`) is recorded in a JSON file beside the weights; training again replaces them.
``ccjax train-net`` trains and saves; building NEURAL-NET for a world without weights raises
:class:`MissingWeightsError` saying how to train them (nothing is trained silently).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, Bool, Float, PRNGKeyArray
from tqdm.auto import tqdm

from ccjax.estimators.base import TINY, Estimate, Estimator
from ccjax.estimators.registry import register
from ccjax.estimators.simple import average_illuminant
from ccjax.scenes import SceneTables, Specular, sample_batch, scene_keys
from ccjax.world import World

BINS = 50
"""(r,g) bins per axis; cells are ``1 / BINS = 0.02`` wide (§4.5.5)."""
N_INPUTS = BINS * BINS
CACHE_FORMAT = 1
"""Bumped when the saved layout or the meaning of a recipe changes (old files are then ignored)."""

# Keeps the predicted illuminant strictly inside the chromaticity triangle, so every channel of the
# RGB estimate is positive and the diagonal map to canonical exists.
_SIMPLEX_MARGIN = 1e-4


# ---------------------------------------------------------------------------------------------
# input encoding


def histogram_bins(rgb: Float[Array, "P 3"]) -> jax.Array:
    """Flat (r,g) bin index ``floor(r * 50) * 50 + floor(g * 50)`` of each pixel (bins clamped to 0..49)."""
    total = jnp.sum(rgb, axis=-1)
    safe = jnp.where(total > TINY, total, 1.0)
    cells = jnp.clip(jnp.floor(rgb[..., :2] / safe[..., None] * BINS), 0, BINS - 1).astype(jnp.int32)
    return cells[..., 0] * BINS + cells[..., 1]


def binarised_histogram(rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Float[Array, "2500"]:
    """The net's input: 1 for every (r,g) bin holding at least one valid chromaticity (§4.5.5).

    Arguments:
        rgb: ``(P, 3)`` camera RGB.
        mask: ``(P,)`` True for valid pixels; black pixels (no chromaticity) are ignored too.

    Returns:
        ``(2500,)`` zeros and ones, bin ``(i, j)`` (r in ``[0.02 i, 0.02 (i+1))``) at ``50 i + j``.
    """
    valid = mask & (jnp.sum(rgb, axis=-1) > TINY)
    return jnp.zeros(N_INPUTS, rgb.dtype).at[histogram_bins(rgb)].max(valid.astype(rgb.dtype))


def occupied_bins(rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> tuple[jax.Array, jax.Array]:
    """The binarised histogram as a list: distinct occupied bins and a 0/1 weight per slot.

    ``sum_k weight_k * onehot(bin_k) == binarised_histogram(rgb, mask)``. The first layer then costs
    ``P x 400`` instead of ``2500 x 400`` (the thesis' rewiring was a speed device too, §4.5.5).

    Returns:
        ``bins (P,)`` int32 (sorted; unused slots hold a valid index with weight 0) and
        ``weight (P,)`` (1 for the first slot of each occupied bin, else 0).
    """
    valid = mask & (jnp.sum(rgb, axis=-1) > TINY)
    bins = jnp.sort(jnp.where(valid, histogram_bins(rgb), N_INPUTS))
    first = jnp.concatenate([jnp.ones((1,), bool), bins[1:] != bins[:-1]])
    weight = (first & (bins < N_INPUTS)).astype(rgb.dtype)
    return jnp.minimum(bins, N_INPUTS - 1), weight


# ---------------------------------------------------------------------------------------------
# the network


class Mlp(eqx.Module):
    """Multi-layer perceptron with sigmoid hidden units and linear outputs (§4.5.5).

    Attributes:
        layers: the affine layers, ``2500 -> 400 -> 30 -> 2`` for the thesis' net.
    """

    layers: tuple[eqx.nn.Linear, ...]

    def __init__(self, key: PRNGKeyArray, sizes: tuple[int, ...] = (N_INPUTS, 400, 30, 2)):
        keys = jax.random.split(key, len(sizes) - 1)
        self.layers = tuple(eqx.nn.Linear(a, b, key=k) for a, b, k in zip(sizes[:-1], sizes[1:], keys))

    def __call__(self, x: Float[Array, " n_in"]) -> Float[Array, " n_out"]:
        """The net on a dense input vector (e.g. :func:`binarised_histogram`)."""
        return self._hidden_to_output(self.layers[0](x))

    def from_bins(self, bins: jax.Array, weight: Float[Array, " P"]) -> Float[Array, " n_out"]:
        """The net on a sparse 0/1 input given by :func:`occupied_bins` (same value as ``__call__``)."""
        first = self.layers[0]
        return self._hidden_to_output(first.weight[:, bins] @ weight.astype(first.weight.dtype) + first.bias)

    def _hidden_to_output(self, x):
        for layer in self.layers[1:]:
            x = layer(jax.nn.sigmoid(x))
        return x


def _project_to_simplex(rg: Float[Array, "2"]) -> tuple[Float[Array, "2"], jax.Array]:
    """Nearest point of the chromaticity triangle (shrunk by a margin) and whether ``rg`` was in it."""
    low, high = _SIMPLEX_MARGIN, 1.0 - _SIMPLEX_MARGIN
    inside = jnp.all(rg >= low) & (jnp.sum(rg) <= high)
    clipped = jnp.maximum(rg, low)
    excess = jnp.maximum(jnp.sum(clipped) - high, 0.0)
    # Euclidean projection onto r + g = high moves both coordinates equally, then re-clip.
    moved = jnp.maximum(clipped - excess / 2.0, low)
    moved = jnp.where(jnp.sum(moved) > high, moved * high / jnp.sum(moved), moved)
    return moved, inside


class NeuralNet(Estimator):
    """The NEURAL-NET / SP-NEURAL-NET estimator: ``rg_to_rgb(net(histogram))`` (§4.5.5).

    A chromaticity method: the estimate is ``(r, g, 1 - r - g)``. A prediction outside the
    chromaticity triangle is projected into it (``ok=False``); a scene with no valid pixel gets the
    average training illuminant (``ok=False``).

    Attributes:
        net: the trained :class:`Mlp`.
        fallback: ``(3,)`` estimate for scenes without data.
    """

    net: Mlp
    fallback: Float[Array, "3"]
    estimates_brightness = False

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        has_data = jnp.any(mask & (jnp.sum(rgb, axis=-1) > TINY))
        predicted = self.net.from_bins(*occupied_bins(rgb, mask))
        rg, inside = _project_to_simplex(jnp.nan_to_num(predicted, nan=1.0 / 3.0))
        illuminant = jnp.concatenate([rg, 1.0 - jnp.sum(rg, keepdims=True)])
        illuminant = jnp.where(has_data, illuminant, self.fallback.astype(illuminant.dtype))
        return Estimate(illuminant=illuminant, ok=has_data & inside & jnp.all(jnp.isfinite(predicted)))


# ---------------------------------------------------------------------------------------------
# training


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
    # Statistics deliberately different from the test protocol's 0.25 / U(0, 2) (spec item 23).
    "SP-NEURAL-NET": Recipe(specular=Specular(probability=0.5, max_amount=1.0)),
}


def training_world(world: World) -> World:
    """``world`` with its training illuminants in the slot the scene sampler draws from."""
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
    """
    key_scenes, key_count, key_noise = jax.random.split(key, 3)
    scenes = sample_batch(scene_keys(key_scenes, 0, batch_size), tables, recipe.max_surfaces, recipe.specular)
    low, high = math.log(recipe.min_surfaces), math.log(recipe.max_surfaces + 1)
    count = jnp.floor(jnp.exp(jax.random.uniform(key_count, (batch_size, 1), minval=low, maxval=high)))
    mask = jnp.arange(recipe.max_surfaces)[None, :] < count
    rgb = scenes.rgb * (1.0 + recipe.noise * jax.random.normal(key_noise, scenes.rgb.shape))
    rgb = jnp.maximum(rgb, 0.0)
    histograms = jax.vmap(occupied_bins)(rgb, mask)
    total = jnp.sum(scenes.illuminant, axis=-1, keepdims=True)
    return histograms, scenes.illuminant[:, :2] / total


def _loss(net: Mlp, histograms, targets) -> jax.Array:
    predicted = jax.vmap(net.from_bins)(*histograms)
    return jnp.mean(jnp.sum((predicted - targets) ** 2, axis=-1))


# One optimiser object for every training run: its learning rate is a traced hyper-parameter set at
# each step, so runs that differ only in their schedule share one compilation.
_OPTIMISER = optax.inject_hyperparams(optax.adam)(learning_rate=0.0)


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
        loss, grads = eqx.filter_value_and_grad(_loss)(net, histograms, targets)
        rate = _cosine_rate(index, peak_rate, total_steps)
        opt_state.hyperparams["learning_rate"] = rate.astype(opt_state.hyperparams["learning_rate"].dtype)
        updates, opt_state = _OPTIMISER.update(grads, opt_state, net)
        return (eqx.apply_updates(net, updates), opt_state), loss

    (net, opt_state), losses = jax.lax.scan(step, (net, opt_state), (keys, steps))
    return net, opt_state, losses


@dataclass
class TrainingLog:
    """Per-chunk mean training loss (mean squared (r,g) error) and wall time."""

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
    opt_state = _OPTIMISER.init(eqx.filter(net, eqx.is_array))
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


# ---------------------------------------------------------------------------------------------
# cache


class MissingWeightsError(FileNotFoundError):
    """No trained weights are cached for this net and world."""


def cache_dir() -> Path:
    """``$CCJAX_CACHE``, else the platform's user cache directory + ``ccjax`` (DESIGN.md §2)."""
    if os.environ.get("CCJAX_CACHE"):
        return Path(os.environ["CCJAX_CACHE"]).expanduser()
    if sys.platform == "win32":
        return Path(os.environ.get("LOCALAPPDATA", Path.home() / "AppData" / "Local")) / "ccjax" / "Cache"
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Caches" / "ccjax"
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "ccjax"


def cache_key(world: World, recipe: Recipe) -> str:
    """Hash of the world arrays training reads and of the recipe (hex, 16 characters)."""
    digest = hashlib.sha256(f"neural v{CACHE_FORMAT}".encode())
    for array in (world.reflectances, world.train_illuminants, world.camera.sensors):
        values = np.ascontiguousarray(np.asarray(array, dtype=np.float32))
        digest.update(repr(values.shape).encode())
        digest.update(values.tobytes())
    digest.update(json.dumps(dataclasses.asdict(recipe), sort_keys=True, default=str).encode())
    return digest.hexdigest()[:16]


def weights_path(world: World, label: str, recipe: Recipe | None = None) -> Path:
    """Where the weights of net ``label`` (or of ``recipe``) for ``world`` are cached."""
    recipe = recipe or _recipe(label)
    return cache_dir() / "neural" / f"{label}-{cache_key(world, recipe)}.eqx"


def has_weights(world: World, label: str) -> bool:
    """True when trained weights of net ``label`` for ``world`` are cached."""
    return weights_path(world, label).is_file()


def is_net_label(label: str) -> bool:
    """True for the labels whose estimator needs trained weights (NEURAL-NET, SP-NEURAL-NET)."""
    return label in RECIPES


def save(net: Mlp, world: World, label: str, recipe: Recipe, schedule: Schedule, log: TrainingLog) -> Path:
    """Write the weights (``eqx.tree_serialise_leaves``) and a JSON record beside them, atomically."""
    path = weights_path(world, label, recipe)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(f".tmp{os.getpid()}")
    eqx.tree_serialise_leaves(partial, net)
    os.replace(partial, path)
    record = {
        "label": label,
        "world": world.name,
        "recipe": dataclasses.asdict(recipe),
        "schedule": dataclasses.asdict(schedule),
        "training_seconds": log.seconds,
        "final_rms_rg": math.sqrt(log.losses[-1]) if log.losses else None,
    }
    path.with_suffix(".json").write_text(json.dumps(record, indent=1, default=str))
    return path


def load(world: World, label: str, recipe: Recipe | None = None) -> Mlp:
    """Load the cached net ``label`` for ``world``; :class:`MissingWeightsError` if there is none."""
    recipe = recipe or _recipe(label)
    path = weights_path(world, label, recipe)
    if not path.is_file():
        raise MissingWeightsError(
            f"{label}: no trained weights for world {world.name!r} (looked for {path}); "
            f"train them with `{train_command(world, label)}` (a few minutes on a CPU)"
        )
    return eqx.tree_deserialise_leaves(path, Mlp(jax.random.key(0), recipe.sizes()))


def train_command(world: World, label: str) -> str:
    """The command line that trains ``label`` for ``world`` (for error messages)."""
    specular = " --specular" if RECIPES.get(label, Recipe()).specular is not None else ""
    if world.name == "barnard1999":
        return f"ccjax train-net --world barnard1999{specular}"
    if world.name.startswith("default (") and world.name.endswith(")"):
        return f'ccjax train-net --world default --camera "{world.name[9:-1]}"{specular}'
    return f"ccjax.estimators.neural.train_and_save(world, {label!r})"


def train_and_save(
    world: World, label: str = "NEURAL-NET", schedule: Schedule = Schedule(), *, progress: bool = False
) -> tuple[Path, TrainingLog]:
    """Train net ``label`` (a key of :data:`RECIPES`) for ``world`` and cache its weights.

    Returns:
        The weights' path and the :class:`TrainingLog`.
    """
    recipe = _recipe(label)
    net, log = train(world, recipe, schedule, progress=progress)
    return save(net, world, label, recipe, schedule, log), log


def _recipe(label: str) -> Recipe:
    if label not in RECIPES:
        raise ValueError(f"label: expected one of {sorted(RECIPES)}, got {label!r}")
    return RECIPES[label]


# ---------------------------------------------------------------------------------------------
# fit and labels


def fit_neural(world: World, label: str = "NEURAL-NET") -> NeuralNet:
    """The estimator with the cached weights of net ``label`` for ``world`` (never trains).

    Raises:
        MissingWeightsError: no weights cached; the message gives the command that trains them.
    """
    return NeuralNet(net=load(world, label), fallback=average_illuminant(world))


register(r"NEURAL-NET", "NEURAL-NET", "MLP on the binarised (r,g) histogram, matte training (§4.5.5; ccjax train-net)")(
    lambda w, m, **o: fit_neural(w, "NEURAL-NET", **o)
)
register(r"SP-NEURAL-NET", "SP-NEURAL-NET", "the MLP trained with specularities (§4.5.5; ccjax train-net --specular)")(
    lambda w, m, **o: fit_neural(w, "SP-NEURAL-NET", **o)
)
