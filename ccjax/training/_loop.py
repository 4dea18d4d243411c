"""Training a fitted estimator's learnable parameters on examples with ground truth: Adam (optax)
on a :mod:`ccjax.losses` loss, von Kries relighting augmentation (:mod:`ccjax.augment`), held-out
error per epoch and early stopping."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, PRNGKeyArray
from tqdm.auto import tqdm

from ccjax import augment, losses, metrics
from ccjax._adam import adam_init, adam_step
from ccjax.estimators.base import AbstractEstimator
from ccjax.runs import hosts
from ccjax.training._data import Examples
from ccjax.training._parameters import constrain, learnable


@dataclass(frozen=True)
class Schedule:
    """How a model is trained (recorded in the model file).

    Attributes:
        epochs: at most this many passes over the training examples.
        batch_size: examples per Adam step.
        learning_rate: Adam's step size (the matrix entries are log-probabilities, so 0.05 moves a
            cell by a factor e in 20 steps).
        patience: stop after this many epochs without a better held-out error (``stop_on``).
        validation_fraction: share of the training examples held out for the per-epoch error
            (when no validation set is given).
        surfaces: surfaces per training scene, a random subset of its valid ones, redrawn every
            step (``None``: all; it bounds the step's cost and is an augmentation too).
        relight: share of every batch von Kries relit to another training example's light.
        stop_on: the held-out statistic early stopping follows, ``"median"`` or ``"mean"``
            angular error.
        loss: a :data:`ccjax.losses.LOSSES` illuminant loss (``"angular"``, ``"reproduction"``, ``"rg"``).
        seed: PRNG seed (split, batches, subsets, relighting).
    """

    epochs: int = 30
    batch_size: int = 32
    learning_rate: float = 0.05
    patience: int = 4
    validation_fraction: float = 0.15
    surfaces: int | None = 256
    relight: float = 0.5
    stop_on: str = "median"
    loss: str = "angular"
    seed: int = 0

    def __post_init__(self):
        for name in ("epochs", "batch_size", "patience"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}: expected a positive integer, got {value!r}")
        if not (isinstance(self.learning_rate, (int, float)) and self.learning_rate > 0):
            raise ValueError(f"learning_rate: expected a positive number, got {self.learning_rate!r}")
        if not 0 < self.validation_fraction < 1:
            raise ValueError(f"validation_fraction: expected a number in (0, 1), got {self.validation_fraction!r}")
        if self.surfaces is not None and (not isinstance(self.surfaces, int) or self.surfaces < 1):
            raise ValueError(f"surfaces: expected a positive integer or None, got {self.surfaces!r}")
        if not 0 <= self.relight <= 1:
            raise ValueError(f"relight: expected a share in [0, 1], got {self.relight!r}")
        if self.stop_on not in ("median", "mean"):
            raise ValueError(f"stop_on: expected 'median' or 'mean', got {self.stop_on!r}")
        if self.loss not in ("angular", "reproduction", "rg"):
            raise ValueError(f"loss: expected 'angular', 'reproduction' or 'rg', got {self.loss!r}")


@dataclass
class TrainingLog:
    """What happened: per-epoch mean training loss and held-out angular error (degrees); wall and
    CPU (process) seconds of the whole fit.

    Attributes:
        train_loss: mean training loss per epoch.
        heldout_median, heldout_mean: held-out angular error per epoch (degrees).
        initial_median: held-out median before training.
        best_epoch: the epoch whose parameters were kept.
        stopped_early: early stopping ended the fit.
        seconds, cpu_seconds: wall and process CPU time of the fit.
        n_train, n_heldout: number of training and held-out examples.
    """

    train_loss: list[float] = field(default_factory=list)
    heldout_median: list[float] = field(default_factory=list)
    heldout_mean: list[float] = field(default_factory=list)
    initial_median: float = math.nan
    best_epoch: int = 0
    stopped_early: bool = False
    seconds: float = 0.0
    cpu_seconds: float = 0.0
    n_train: int = 0
    n_heldout: int = 0

    def as_dict(self) -> dict:
        """The log as strict JSON values: only what the fit measured (a fit with nothing held out,
        FFCC's, has no held-out errors, best epoch or early stopping to report).

        Returns:
            A dict of numbers, lists of numbers and booleans, none of them NaN.
        """
        record = dict(self.__dict__)
        if self.n_heldout == 0:
            for name in (
                "heldout_median",
                "heldout_mean",
                "initial_median",
                "best_epoch",
                "stopped_early",
                "n_heldout",
            ):
                del record[name]
        return record


def subsample(
    key: PRNGKeyArray, x: Float[Array, "B P 3"], mask: Bool[Array, "B P"], count: int
) -> tuple[Float[Array, "B S 3"], Bool[Array, "B S"]]:
    """``count`` slots of each surface list, its valid surfaces first in a random order (a uniform
    subset of them when there are more than ``count``).

    Arguments:
        key: PRNG key.
        x: ``(B, P, 3)`` surface lists.
        mask: ``(B, P)`` valid surfaces.
        count: slots kept per list.

    Returns:
        ``(x (B, count, 3), mask (B, count))``.
    """
    noise = jax.random.uniform(key, mask.shape)
    order = jnp.argsort(jnp.where(mask, noise, noise + 2.0), axis=-1)[:, :count]
    return jnp.take_along_axis(x, order[..., None], axis=1), jnp.take_along_axis(mask, order, axis=1)


@eqx.filter_jit
def _batch_estimates(model, x, mask):
    estimate = jax.vmap(model)(x, mask)
    return estimate.illuminant, estimate.ok


def predict(model: AbstractEstimator, examples: Examples, chunk: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """The model's estimates for every example, in fixed-size chunks (one compilation).

    Arguments:
        model: the estimator.
        examples: the examples.
        chunk: examples per compiled call.

    Returns:
        ``(illuminants (N, 3), ok (N,))`` as NumPy arrays.
    """
    n = len(examples)
    size = min(chunk, n)
    estimates, oks = [], []
    for start in range(0, n, size):
        index = np.minimum(np.arange(start, start + size), n - 1)  # the last chunk repeats its last example
        illuminant, ok = _batch_estimates(model, examples.x[index], examples.mask[index])
        keep = min(size, n - start)
        estimates.append(np.asarray(illuminant)[:keep])
        oks.append(np.asarray(ok)[:keep])
    return np.concatenate(estimates), np.concatenate(oks)


def angular_errors(model: AbstractEstimator, examples: Examples) -> np.ndarray:
    """Per-example recovery angular error (degrees) of ``model``.

    Arguments:
        model: the estimator.
        examples: the examples, with their true lights.

    Returns:
        ``(N,)`` angular errors in degrees.
    """
    estimates, _ = predict(model, examples)
    return np.asarray(metrics.angular_error(jnp.asarray(estimates), examples.illuminant))


def _split(n: int, fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    order = np.random.default_rng(seed).permutation(n)
    held = max(1, int(round(fraction * n)))
    return np.sort(order[held:]), np.sort(order[:held])


@dataclass(frozen=True)
class _StepRule:
    """The part of a :class:`Schedule` that shapes the step's program (its compilation key); the
    rate is a traced argument, and epochs, patience, seed, ... belong to the Python loop, so fits
    that differ only in those share one compilation."""

    surfaces: int | None
    relighting: bool
    loss: str


@eqx.filter_jit
def _step(params, static, opt_state, x, mask, illuminant, targets, key, rule: _StepRule, rate, relight):
    key_subset, key_light, key_which = jax.random.split(key, 3)
    if rule.surfaces is not None and x.ndim == 3 and x.shape[1] > rule.surfaces:
        x, mask = subsample(key_subset, x, mask, rule.surfaces)
    if rule.relighting:
        relit, new = augment.von_kries_relight(key_light, x, illuminant, targets, mask)
        chosen = jax.random.uniform(key_which, illuminant.shape[:1]) < relight
        x = jnp.where(chosen.reshape((-1,) + (1,) * (x.ndim - 1)), relit, x)
        illuminant = jnp.where(chosen[:, None], new, illuminant)

    def loss_of(params):
        model = eqx.combine(params, static)
        estimate = jax.vmap(model)(x, mask).illuminant
        return losses.illuminant_loss(rule.loss, estimate, illuminant)

    params, opt_state, loss = adam_step(loss_of, params, opt_state, learning_rate=rate)
    model = constrain(eqx.combine(params, static))
    params, _ = eqx.partition(model, learnable(model))
    return params, opt_state, loss


def fit_to_examples(
    model: AbstractEstimator,
    examples: Examples,
    schedule: Schedule = Schedule(),
    *,
    validation: Examples | None = None,
    progress: bool = True,
    mesh: jax.sharding.Mesh | None = None,
) -> tuple[AbstractEstimator, TrainingLog]:
    """Train ``model``'s learnable parameters (:func:`ccjax.training.learnable`) on ``examples``.

    Every epoch shuffles the examples into batches; every step draws a subset of each scene's
    surfaces and relights part of the batch (von Kries) to other training examples' lights, then
    takes an Adam step on the loss. After each epoch the held-out angular error is measured
    (``validation``, else a ``schedule.validation_fraction`` split of ``examples``); the model with
    the best held-out ``schedule.stop_on`` statistic so far is kept, and training stops after
    ``schedule.patience`` epochs without improvement.

    Arguments:
        model: a fitted, trainable estimator (the start: e.g. the spectral fit to the camera).
        examples: training examples.
        schedule: the :class:`Schedule`.
        validation: held-out examples (default: split off ``examples``).
        progress: show a progress bar (one step per tick, the held-out error per epoch).
        mesh: optional one-axis mesh (:func:`ccjax.runs.hosts.item_mesh`): every batch is split
            over its devices and the parameters replicated, so each step's gradient is the
            pooled one (data parallel). Across processes (``jax.distributed``) every process
            passes the same examples and schedule and puts its block of each batch onto the mesh;
            ``schedule.batch_size`` must be a multiple of the mesh's device count.

    Returns:
        ``(best model, TrainingLog)``.
    """
    start, cpu_start = time.perf_counter(), time.process_time()
    spec = learnable(model)
    if validation is None:
        if len(examples) < 4:
            raise ValueError(f"examples: need at least 4 to hold some out, got {len(examples)}")
        train_index, held_index = _split(len(examples), schedule.validation_fraction, schedule.seed)
        validation, examples = examples.take(held_index), examples.take(train_index)
    batch = min(schedule.batch_size, len(examples))
    params, static = eqx.partition(model, spec)
    opt_state = adam_init(params)
    targets = examples.illuminant
    rule = _StepRule(schedule.surfaces, schedule.relight > 0, schedule.loss)
    # Traced values (not part of the compilation key), in the dtypes the step used as constants.
    rate, relight = jnp.asarray(schedule.learning_rate, jnp.float32), jnp.asarray(schedule.relight, jnp.float32)
    if mesh is not None:
        devices = mesh.devices.size
        if batch % devices:
            raise ValueError(
                f"schedule.batch_size: {batch} examples per step do not split over the mesh's {devices} devices"
            )
        params, opt_state, targets, rate, relight = hosts.replicate((params, opt_state, targets, rate, relight), mesh)
        rows = hosts.process_share(batch)  # this process's block of every batch
    key = jax.random.key(schedule.seed)
    rng = np.random.default_rng(schedule.seed)
    log = TrainingLog(n_train=len(examples), n_heldout=len(validation))
    best = model
    stop_statistic = np.median if schedule.stop_on == "median" else np.mean
    start_errors = angular_errors(model, validation)
    log.initial_median = float(np.median(start_errors))
    best_value = float(stop_statistic(start_errors))
    steps_per_epoch = len(examples) // batch
    # The bar counts epochs (what the schedule, early stopping and the held-out column are in).
    bar = tqdm(total=schedule.epochs, desc="train", unit="epoch", disable=not progress)
    bar.set_postfix(heldout_median=f"{log.initial_median:.3f}")
    stale = 0
    for epoch in range(schedule.epochs):
        order = rng.permutation(len(examples))
        epoch_losses = []
        for step in range(steps_per_epoch):
            index = order[step * batch : (step + 1) * batch]
            key, key_step = jax.random.split(key)
            x, mask, illuminant = examples.x[index], examples.mask[index], examples.illuminant[index]
            if mesh is not None:
                x, mask, illuminant = hosts.shard_items((x[rows], mask[rows], illuminant[rows]), mesh)
                key_step = hosts.replicate(key_step, mesh)
            params, opt_state, loss = _step(
                params, static, opt_state, x, mask, illuminant, targets, key_step, rule, rate, relight
            )
            epoch_losses.append(float(loss))
        # Trained on a mesh, the parameters come back as this process's copy (a model to use anywhere).
        current = eqx.combine(params if mesh is None else jax.tree.map(jnp.asarray, hosts.global_value(params)), static)
        errors = angular_errors(current, validation)
        median = float(np.median(errors))
        log.train_loss.append(float(np.mean(epoch_losses)))
        log.heldout_median.append(median)
        log.heldout_mean.append(float(np.mean(errors)))
        bar.set_postfix(loss=f"{log.train_loss[-1]:.3f}", heldout_median=f"{median:.3f}", refresh=False)
        bar.update()
        value = float(stop_statistic(errors))
        if value < best_value:
            best, best_value, log.best_epoch, stale = current, value, epoch + 1, 0
        else:
            stale += 1
            if stale >= schedule.patience:
                log.stopped_early = True
                bar.set_postfix_str(f"stopped early (best epoch {log.best_epoch})", refresh=False)
                break
    bar.close()
    log.seconds = time.perf_counter() - start
    log.cpu_seconds = time.process_time() - cpu_start
    return best, log
