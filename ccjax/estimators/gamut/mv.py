"""MV: the feasible direction of maximum map volume ``T^3 / (r g b)`` (the product ``d_r d_g d_b``
of the map at the ray's far end; Barnard 1999 §4.5.3), ``e = u / T``.

Hard: the best grid direction refined below the grid step by the engine's pattern search. Soft:
a softmax over directions with inverse temperature ``beta`` on the log-volume.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ccjax.estimators.gamut.constraints_3d import Grid, inverse_extent, violations
from ccjax.estimators.gamut.engine import directions, pattern_search
from ccjax.estimators.gamut.weights import log_volume, normalised


def hard(model, grid: Grid, mask_violation, level, feasible: Bool[Array, " G"], log_t) -> Float[Array, "3"]:
    """The refined MV illuminant.

    Arguments:
        model: the fitted model; grid: the scene's fine grid.
        mask_violation: ``(surface, illuminant, cone) -> violation`` of the selector's mask.
        level: the relaxation level; feasible: ``(G,)`` the mask on the grid; log_t: ``(G,)``.
    """
    u, _, _ = directions(grid.rg)
    start = grid.rg[jnp.argmax(jnp.where(feasible, log_volume(log_t, u), -jnp.inf))]

    def objective(rg):
        u, v, valid = directions(rg)
        inverse = inverse_extent(v, grid.observations, grid.count)
        _, surface, illuminant, cone = violations(model, v, valid, grid.observations, grid.count)
        inside = valid & (mask_violation(surface, illuminant, cone) <= level) & (inverse > 0)
        value = log_volume(-jnp.log(jnp.where(inside, inverse, 1.0)), u)
        return jnp.where(inside, value, -jnp.inf)

    centre = pattern_search(objective, start, grid.step / 2, model.options.refine_steps)
    u, v, _ = directions(centre[None])
    return u[0] * inverse_extent(v, grid.observations, grid.count)[0]


def soft(u: Float[Array, "G 3"], log_t, inverse, log_mask, beta: float) -> Float[Array, "3"]:
    """The soft MV illuminant: ``sum_g w_g u_g / T_g`` with ``w = softmax(beta log-volume + log_mask)``."""
    weight = normalised(beta * log_volume(log_t, u), log_mask)
    return jnp.sum((weight * inverse)[:, None] * u, axis=0)
