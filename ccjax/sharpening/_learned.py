"""Learned end-to-end sharpening (beyond Barnard 1999 ch. 5): ``T`` trained by gradient descent
through a differentiable estimator on synthetic scenes.

GW's chromaticity estimate does not depend on ``T`` (it is linear), so learning through GW needs
the chapter-5 mapping error of §5.4, not the angular error; non-linear estimators (soft RETINEX,
shades of grey) learn from either.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray

from ccjax._adam import adam_init, adam_step
from ccjax.estimators.base import AbstractEstimator
from ccjax.metrics import angular_error as angular_errors  # gradient-safe at zero error
from ccjax.precision import matmul
from ccjax.scenes import draw_scenes, sweep_keys
from ccjax.sharpening._new_method import on_sphere
from ccjax.sharpening._transforms import THESIS_SCALE, database_responses, mapping_error
from ccjax.sharpening._wrapper import sharpened
from ccjax.world import World

LOSSES = ("mapping", "angular")


@dataclass
class LearnedSharpening:
    """``T`` learned through an estimator.

    Attributes:
        transform: ``(3, 3)`` NumPy ``T`` with unit columns (the gauge of Barnard 1999 §5.2).
        estimator: the registry label trained through.
        loss: ``"mapping"`` or ``"angular"``.
        losses: training loss per step, RMS over the batch (thesis units for the mapping loss,
            degrees for the angle).
        seconds: training time.
    """

    transform: np.ndarray
    estimator: str
    loss: str
    losses: list
    seconds: float


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


def learned_sharpening(
    world: World,
    estimator: str = "GW",
    loss: str = "mapping",
    *,
    steps: int = 300,
    batch_size: int = 128,
    n_surfaces: int = 8,
    learning_rate: float = 3e-3,
    key: PRNGKeyArray | None = None,
) -> LearnedSharpening:
    """Learn ``T`` by gradient descent through a differentiable estimator (beyond Barnard 1999 ch. 5).

    Training scenes (``n_surfaces`` random reflectances under a random *training* illuminant, fresh
    every step, drawn by :func:`ccjax.scenes.draw_scenes`) are run through
    ``sharpened(estimator, T)``; the loss is the mean square of the §5.4 mapping error
    (``loss="mapping"``, the one to use for GW, whose chromaticity does not depend on ``T``) or of
    the angular error (``loss="angular"``, for non-linear estimators such as
    ``soft-RETINEX-t0.01`` or ``shades-of-grey-p6``). ``T`` starts at the identity and stays on
    ``|T|_F^2 = 3`` (the new method's norm constraint, §5.3); Adam (optax).

    Arguments:
        world: training illuminants, reflectances, canonical light.
        estimator: a registry label whose fit is plain JAX (GW, DB-GW, shades of grey, soft RETINEX).
        loss: ``"mapping"`` or ``"angular"``.
        steps, batch_size, n_surfaces, learning_rate: the schedule.
        key: PRNG key (default ``jax.random.key(1)``).

    Returns:
        :class:`LearnedSharpening`.
    """
    from ccjax.estimators import registry

    if loss not in LOSSES:
        raise ValueError(f"loss: expected 'mapping' or 'angular', got {loss!r}")
    if not isinstance(steps, int) or steps < 1:
        raise ValueError(f"steps: expected a positive integer, got {steps!r}")
    key = jax.random.key(1) if key is None else key
    train = database_responses(world, world.train_illuminants)
    whites = world.train_whites
    plain = registry.fit(estimator, world)
    n_lights, n_reflectances = train.shape[:2]

    @eqx.filter_jit
    def step(parameters, state, step_key):
        draws = draw_scenes(sweep_keys(step_key, n_surfaces, 0, batch_size), n_lights, n_reflectances, n_surfaces)

        def batch_loss(p):
            errors = scene_losses(p, estimator, loss, world, train, whites, draws.light, draws.surfaces, plain)
            return jnp.mean(errors**2)

        return adam_step(batch_loss, parameters, state, learning_rate=learning_rate)

    parameters = jnp.eye(3, dtype=train.dtype)
    state = adam_init(parameters)
    losses = []
    start = time.perf_counter()
    for index in range(steps):
        parameters, state, value = step(parameters, state, jax.random.fold_in(key, index))
        losses.append(float(jnp.sqrt(value)))
    t = np.asarray(on_sphere(jnp.asarray(parameters)), dtype=np.float64)
    return LearnedSharpening(
        transform=t / np.linalg.norm(t, axis=0, keepdims=True),
        estimator=estimator,
        loss=loss,
        losses=losses,
        seconds=time.perf_counter() - start,
    )
