"""The one Adam loop of every learner (optax): the nets (:mod:`ccjax.estimators.neural._training`),
``ccjax train`` (:mod:`ccjax.training._loop`) and learned sharpening (:mod:`ccjax.sharpening._learned`)
each iterate :func:`adam_step` over their own batches (:func:`optax_step` where the caller
brings its own optax optimiser).

One optimiser object serves every run: its learning rate is a hyper-parameter held in the state
(``optax.inject_hyperparams``) and set at each step, so a schedule (the nets' cosine decay) is a
value, not a new optimiser, and runs that differ only in their rates share one compilation.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import ArrayLike

if TYPE_CHECKING:
    import optax


@functools.cache
def optimiser() -> optax.GradientTransformationExtraArgs:
    """Adam with its learning rate in the state (Kingma & Ba 2015; optax's defaults otherwise).
    Built on first use: optax is imported by the commands that train, not by every command that
    loads the estimators."""
    import optax

    return optax.inject_hyperparams(optax.adam)(learning_rate=0.0)


def adam_init(params: Any) -> optax.OptState:
    """The Adam state of ``params`` (its array leaves; zero moments, step 0).

    Arguments:
        params: a PyTree (a model, or a model's learnable part); only its arrays are optimised.

    Returns:
        The optimiser state.
    """
    return optimiser().init(eqx.filter(params, eqx.is_array))


def adam_step(
    loss: Callable[..., jax.Array],
    params: Any,
    state: optax.OptState,
    *args: Any,
    learning_rate: float | ArrayLike,
) -> tuple[Any, optax.OptState, jax.Array]:
    """One Adam step on ``loss(params, *args)``: its value and gradient with respect to the array
    leaves of ``params``, then the update at ``learning_rate``.

    Arguments:
        loss: a scalar function of ``params`` and ``args``.
        params: the PyTree being optimised.
        state: its optimiser state (:func:`adam_init`, or the previous step's).
        args: the loss's other arguments (the batch).
        learning_rate: this step's rate (a number, or a traced scalar for a schedule).

    Returns:
        ``(updated params, new state, loss value before the update)``.
    """
    value, grads = eqx.filter_value_and_grad(loss)(params, *args)
    rate = state.hyperparams["learning_rate"]  # pyright: ignore[reportAttributeAccessIssue]
    state.hyperparams["learning_rate"] = jnp.asarray(learning_rate).astype(rate.dtype)  # pyright: ignore[reportAttributeAccessIssue]
    # optax's bias correction raises a float32 decay to the int32 step count; strict dtype
    # promotion (the test suite's) would refuse it, so optax runs under JAX's standard rules.
    with jax.numpy_dtype_promotion("standard"):
        updates, state = optimiser().update(grads, state)
    return eqx.apply_updates(params, updates), state, value


def optax_step(
    loss: Callable[..., jax.Array],
    params: Any,
    state: optax.OptState,
    *args: Any,
    optimizer: optax.GradientTransformation,
) -> tuple[Any, optax.OptState, jax.Array]:
    """One step of a caller's optax ``optimizer`` on ``loss(params, *args)`` (its own rate or
    schedule): :func:`adam_step` for any optimiser. Its state is ``optimizer.init`` of the array
    leaves of ``params``.

    Arguments:
        loss: a scalar function of ``params`` and ``args``.
        params: the PyTree being optimised.
        state: the optimiser's state.
        args: the loss's other arguments.
        optimizer: the optax gradient transformation.

    Returns:
        ``(updated params, new state, loss value before the update)``.
    """
    value, grads = eqx.filter_value_and_grad(loss)(params, *args)
    with jax.numpy_dtype_promotion("standard"):  # as in adam_step
        updates, state = optimizer.update(grads, state, eqx.filter(params, eqx.is_array))
    return eqx.apply_updates(params, updates), state, value
