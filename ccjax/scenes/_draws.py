"""The scenes' random draws, the same under ``jax_enable_x64`` as without it.

JAX draws a float64 uniform (or an int64 integer) from 64 random bits where a float32 one takes
32, so the default dtypes would make the same key give other scenes once x64 is on. Every draw of
the scene samplers goes through here instead: integers as int32, reals as float32, then cast to
the dtype the scene is computed in. Under x64 the draws are therefore the float32 ones exactly and
only the arithmetic after them is wider: a float64 re-check sees the same scenes, to float32
rounding. Without x64 these are JAX's default draws, bit for bit.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int, PRNGKeyArray


def uniform(
    key: PRNGKeyArray,
    shape: Sequence[int],
    dtype=jnp.float32,
    minval: float = 0.0,
    maxval: float = 1.0,
) -> Float[Array, "..."]:
    """``U(minval, maxval)`` drawn in float32, cast to ``dtype``.

    Arguments:
        key: PRNG key.
        shape: shape of the draw.
        dtype: dtype of the result (the scene's).
        minval, maxval: the range.

    Returns:
        The draw, ``shape``, in ``dtype``.
    """
    return jax.random.uniform(key, tuple(shape), jnp.float32, minval, maxval).astype(dtype)


def normal(key: PRNGKeyArray, shape: Sequence[int], dtype=jnp.float32) -> Float[Array, "..."]:
    """Standard normal draws in float32, cast to ``dtype``.

    Arguments:
        key: PRNG key.
        shape: shape of the draw.
        dtype: dtype of the result.

    Returns:
        The draw, ``shape``, in ``dtype``.
    """
    return jax.random.normal(key, tuple(shape), jnp.float32).astype(dtype)


def randint(key: PRNGKeyArray, shape: Sequence[int], high) -> Int[Array, "..."]:
    """Integers uniform in ``0 .. high - 1``, drawn as int32.

    Arguments:
        key: PRNG key.
        shape: shape of the draw.
        high: the exclusive upper bound.

    Returns:
        int32 draws of ``shape``.
    """
    return jax.random.randint(key, tuple(shape), 0, high, jnp.int32)
