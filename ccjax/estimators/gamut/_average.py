"""AVE and ICA: the centroid of the feasible set in map space (Barnard 1999 §4.5.3),
on the direction grid with volume weights ``T^3 / (rgb)^2`` and centroid weights
``(3/4) m(u) T^4 / (rgb)^2``; ``e = w_C / centroid``. ICA differs from AVE only by its mask (the
exact illumination constraint; AVE uses its convex approximation), so one function serves both,
hard (indicator mask) and soft (sigmoid mask)."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from ccjax.estimators.gamut._weights import normalised


def estimate(
    u: Float[Array, "G 3"],
    v: Float[Array, "G 3"],
    log_t: Float[Array, " G"],
    white: Float[Array, "3"],
    log_mask: Float[Array, " G"],
) -> Float[Array, "3"]:
    """The illuminant of the map-space centroid.

    Arguments:
        u, v: ``(G, 3)`` directions and ``1/u``; log_t: ``(G,)`` ``log T(u)``.
        white: ``(3,)`` canonical white; log_mask: ``(G,)`` log of each direction's membership.
    """
    weight = normalised(3.0 * log_t - 2.0 * jnp.sum(jnp.log(u), axis=-1), log_mask)
    centroid = 0.75 * jnp.sum((weight * jnp.exp(log_t))[:, None] * (white * v), axis=0)
    return white / jnp.maximum(centroid, 1e-30)
