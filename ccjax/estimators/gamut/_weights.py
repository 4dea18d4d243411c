"""Weights shared by the 3-D selectors (Barnard 1999 §4.5.3, §6.2)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float


def log_volume(log_t: Float[Array, " G"], u: Float[Array, "G 3"]) -> Float[Array, " G"]:
    """``log(T^3 / (r g b))``: log of the coordinate product of the map ``T m(u)`` over prod(w_C)."""
    return 3.0 * log_t - jnp.sum(jnp.log(u), axis=-1)


def hard_mask(feasible: Bool[Array, " G"]) -> Float[Array, " G"]:
    """The log-mask of a feasible set: 0 inside, ``-inf`` outside (the soft selectors use a
    log-sigmoid instead)."""
    return jnp.where(feasible, 0.0, -jnp.inf)


def normalised(log_weight: Float[Array, " G"], log_mask: Float[Array, " G"]) -> Float[Array, " G"]:
    """``exp(log_weight + log_mask)`` normalised to sum 1, computed in the log domain; all zeros
    (not NaN) when the mask excludes every direction."""
    total = log_weight + log_mask
    top = jnp.max(total)
    top = jax.lax.stop_gradient(jnp.where(jnp.isfinite(top), top, 0.0))
    weight = jnp.where(log_mask > -jnp.inf, jnp.exp(total - top), 0.0)
    return weight / jnp.maximum(jnp.sum(weight), 1e-30)
