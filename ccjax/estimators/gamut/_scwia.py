"""SCWIA-N: the average of feasible chromaticities weighted by the N/3-th power of the map volume
and the solid angle of each direction (Barnard 1999 §6.2): weights
``(T^3 prod(w_C) / (rgb))^(N/3) dOmega``, ``dOmega = dr dg / |u|^3``, in the log domain. The
brightness (not reported by the thesis) is the same average of ``1/T``. One function for the hard
(indicator mask) and soft (sigmoid mask) forms."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from ccjax.estimators.gamut._weights import log_volume, normalised


def estimate(
    u: Float[Array, "G 3"],
    log_t: Float[Array, " G"],
    inverse: Float[Array, " G"],
    white: Float[Array, "3"],
    power: float,
    log_mask: Float[Array, " G"],
) -> Float[Array, "3"]:
    """The SCWIA-N illuminant.

    Arguments:
        u: ``(G, 3)`` directions; log_t: ``(G,)`` ``log T``; inverse: ``(G,)`` ``1/T`` (0 where
            unbounded); white: ``(3,)``; power: ``N``; log_mask: ``(G,)`` log-membership.
    """
    log_solid_angle = -1.5 * jnp.log(jnp.sum(u * u, axis=-1))
    weight = normalised(power / 3.0 * (log_volume(log_t, u) + jnp.sum(jnp.log(white))) + log_solid_angle, log_mask)
    return jnp.sum(weight[:, None] * u, axis=0) * jnp.sum(weight * inverse)
