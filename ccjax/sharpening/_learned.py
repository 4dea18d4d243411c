"""Learned end-to-end sharpening (beyond Barnard 1999 ch. 5): ``T`` trained by gradient descent
through a differentiable estimator on synthetic scenes.

GW's chromaticity estimate does not depend on ``T`` (it is linear), so learning through GW needs
the chapter-5 mapping error of §5.4, not the angular error; non-linear estimators (soft RETINEX,
shades of grey) learn from either.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray

from ccjax._adam import adam_init, adam_step, optax_step
from ccjax.estimators.base import AbstractEstimator
from ccjax.metrics import angular_error as angular_errors  # gradient-safe at zero error
from ccjax.precision import matmul
from ccjax.scenes import draw_scenes, sweep_keys
from ccjax.sharpening._new_method import on_sphere
from ccjax.sharpening._transforms import THESIS_SCALE, database_responses, mapping_error
from ccjax.sharpening._wrapper import sharpened
from ccjax.world import World

if TYPE_CHECKING:
    import optax

LOSSES = ("mapping", "angular")
DEFAULT_LEARNING_RATE = 3e-3
"""Adam's rate when :func:`learned_sharpening` is given no optimiser."""


@dataclass
class LearnedSharpening:
    """``T`` learned through an estimator.

    Attributes:
        transform: ``(3, 3)`` NumPy ``T`` with unit columns (the gauge of Barnard 1999 §5.2).
        estimator: the registry label trained through.
        loss: ``"mapping"`` or ``"angular"``.
        rms_errors: per step, the root of the objective (the batch's mean square error): the
            RMS over the batch of the mapping error (thesis units) or of the angle (degrees).
            Not a mean error (:func:`ccjax.losses.angular_loss` is one).
        seconds: training time.
    """

    transform: np.ndarray
    estimator: str
    loss: str
    rms_errors: list
    seconds: float

    @property
    def losses(self) -> list:
        """Deprecated alias of :attr:`rms_errors` (it warns, for one release): ccjax's other
        ``losses`` are the minimised objective or a mean, and this is neither.

        Returns:
            :attr:`rms_errors`.
        """
        warnings.warn(
            "LearnedSharpening.losses is deprecated: use rms_errors (per step, the RMS over the batch; "
            "the objective is its square)",
            DeprecationWarning,
            stacklevel=2,
        )
        return self.rms_errors


def scene_losses(
    parameters: Float[Array, "3 3"],
    label: str,
    loss: str,
    world: World,
    train: Float[Array, "I S 3"],
    whites: Float[Array, "I 3"],
    lights: Int[Array, " B"],
    surfaces: Int[Array, "B P"],
    plain: AbstractEstimator,
) -> Float[Array, " B"]:
    """Per-scene training losses of ``T = on_sphere(parameters)`` through ``sharpened(label, T)``.

    Arguments:
        parameters: ``(3, 3)`` unconstrained parameters (``T`` on ``|T|_F^2 = 3``, §5.3).
        label: registry label of an estimator whose fit is plain JAX.
        loss: ``"mapping"`` (the §5.4 mapping error over the whole database, thesis units) or
            ``"angular"`` (degrees).
        world: the world (canonical light and responses).
        train: ``(I, S, 3)`` database under the training lights.
        whites: ``(I, 3)`` camera RGB of white under each training light.
        lights: ``(B,)`` light index of each scene.
        surfaces: ``(B, P)`` each scene's reflectance indices.
        plain: the unsharpened model of ``label`` (fitted once).

    Returns:
        ``(B,)`` losses.
    """
    transform = on_sphere(parameters)
    model = sharpened(label, transform, world, plain=plain)
    canonical, canonical_white = world.canonical_rgb, world.canonical_white

    def one(light, chosen):
        rgb = train[light, chosen]
        mask: Bool[Array, " P"] = jnp.ones(chosen.shape, bool)
        estimate = model(rgb, mask).illuminant
        if loss == "angular":
            return angular_errors(estimate, whites[light])  # safe gradients (ccjax.losses)
        sharp_map = matmul(canonical_white, transform) / matmul(estimate, transform)
        return mapping_error(train[light], canonical, transform, sharp_map) * THESIS_SCALE

    return jax.vmap(one)(lights, surfaces)


class _Problem(eqx.Module):
    """What a training step learns from: its static fields (and the arrays' shapes) key the
    compiled step, its arrays are arguments (so a second call with the same shapes reuses it)."""

    estimator: str = eqx.field(static=True)
    loss: str = eqx.field(static=True)
    batch_size: int = eqx.field(static=True)
    n_surfaces: int = eqx.field(static=True)
    world: World
    train: Float[Array, "I S 3"]
    whites: Float[Array, "I 3"]
    plain: AbstractEstimator


@eqx.filter_jit
def _sharpening_step(parameters, state, key, index, learning_rate, problem: _Problem, optimizer):
    """One training step (module level: compiled once per problem shape, optimiser and loss; the
    step index and learning rate are traced values)."""
    n_lights, n_reflectances = problem.train.shape[:2]
    step_key = jax.random.fold_in(key, index)
    draws = draw_scenes(
        sweep_keys(step_key, problem.n_surfaces, 0, problem.batch_size), n_lights, n_reflectances, problem.n_surfaces
    )

    def batch_loss(p):
        errors = scene_losses(
            p,
            problem.estimator,
            problem.loss,
            problem.world,
            problem.train,
            problem.whites,
            draws.light,
            draws.surfaces,
            problem.plain,
        )
        return jnp.mean(errors**2)

    if optimizer is None:
        return adam_step(batch_loss, parameters, state, learning_rate=learning_rate)
    return optax_step(batch_loss, parameters, state, optimizer=optimizer)


def learned_sharpening(
    world: World,
    estimator: str = "GW",
    loss: str = "mapping",
    *,
    steps: int = 300,
    batch_size: int = 128,
    n_surfaces: int = 8,
    learning_rate: float | None = None,
    optimizer: optax.GradientTransformation | None = None,
    key: PRNGKeyArray | None = None,
) -> LearnedSharpening:
    """Learn ``T`` by gradient descent through a differentiable estimator (beyond Barnard 1999 ch. 5).

    Training scenes (``n_surfaces`` random reflectances under a random *training* illuminant, fresh
    every step, drawn by :func:`ccjax.scenes.draw_scenes`) are run through
    ``sharpened(estimator, T)``; the loss is the mean square of the §5.4 mapping error
    (``loss="mapping"``, the one to use for GW, whose chromaticity does not depend on ``T``) or of
    the angular error (``loss="angular"``, for non-linear estimators such as
    ``soft-RETINEX-t0.01`` or ``shades-of-grey-p6``). ``T`` starts at the identity and stays on
    ``|T|_F^2 = 3`` (the new method's norm constraint, §5.3); Adam (optax) at ``learning_rate``,
    or the caller's optax ``optimizer`` (a schedule goes inside it).

    The training step is compiled once per estimator, loss, batch shape, world shape and optimiser
    object: the step count and the learning rate are values, so a second call with the same shapes
    (any ``steps``, any ``learning_rate``, the same ``optimizer`` object) compiles nothing.

    Example::

        import optax
        from ccjax import World, sharpening

        world = World.default()
        schedule = optax.cosine_decay_schedule(1e-2, decay_steps=20)
        learned = sharpening.learned_sharpening(
            world, "GW", steps=20, batch_size=16, optimizer=optax.adam(schedule)
        )
        print(learned.transform.shape, len(learned.rms_errors))  # (3, 3) 20

    Arguments:
        world: training illuminants, reflectances, canonical light.
        estimator: a registry label whose fit is plain JAX (GW, DB-GW, shades of grey, soft RETINEX).
        loss: ``"mapping"`` or ``"angular"``.
        steps, batch_size, n_surfaces: the schedule (steps, scenes per step, surfaces per scene).
        learning_rate: Adam's rate (default ``3e-3``) when no ``optimizer`` is given; give one
            or the other.
        optimizer: an optax gradient transformation (e.g. ``optax.adam(schedule)``) used instead
            of Adam at ``learning_rate``; it is part of the compiled step's key, so reuse the same
            object across calls to reuse the compilation.
        key: PRNG key (default ``jax.random.key(1)``).

    Returns:
        :class:`LearnedSharpening`.
    """
    from ccjax.estimators import registry

    if loss not in LOSSES:
        raise ValueError(f"loss: expected 'mapping' or 'angular', got {loss!r}")
    for name, value in (("steps", steps), ("batch_size", batch_size), ("n_surfaces", n_surfaces)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{name}: expected a positive integer, got {value!r}")
    if optimizer is not None and learning_rate is not None:
        raise ValueError("learning_rate: the optimizer sets its own rate (or schedule); give one or the other")
    if optimizer is not None and not (
        callable(getattr(optimizer, "init", None)) and callable(getattr(optimizer, "update", None))
    ):
        raise TypeError(f"optimizer: expected an optax GradientTransformation, got {type(optimizer).__name__}")
    rate = DEFAULT_LEARNING_RATE if learning_rate is None else learning_rate
    if not (isinstance(rate, (int, float)) and not isinstance(rate, bool) and rate > 0):
        raise ValueError(f"learning_rate: expected a positive number, got {learning_rate!r}")
    key = jax.random.key(1) if key is None else key
    train = database_responses(world, world.train_illuminants)
    problem = _Problem(
        estimator, loss, batch_size, n_surfaces, world, train, world.train_whites, registry.fit(estimator, world)
    )
    parameters = jnp.eye(3, dtype=train.dtype)
    state = adam_init(parameters) if optimizer is None else optimizer.init(parameters)
    # A traced value of the parameters' dtype: every rate shares the one compilation.
    rate = jnp.asarray(rate, train.dtype)
    values = []
    start = time.perf_counter()
    for index in range(steps):  # dispatched asynchronously: no host round trip per step
        parameters, state, value = _sharpening_step(parameters, state, key, jnp.uint32(index), rate, problem, optimizer)
        values.append(value)
    rms_errors = np.sqrt(np.asarray(jnp.stack(values))).tolist()
    t = np.asarray(on_sphere(jnp.asarray(parameters)), dtype=np.float64)
    return LearnedSharpening(
        transform=t / np.linalg.norm(t, axis=0, keepdims=True),
        estimator=estimator,
        loss=loss,
        rms_errors=rms_errors,
        seconds=time.perf_counter() - start,
    )
