"""MV: the feasible direction of maximum map volume ``T^3 / (r g b)`` (the product ``d_r d_g d_b``
of the map at the ray's far end; Barnard 1999 §4.5.3), ``e = u / T``.

Hard: the best grid direction refined below the grid step by the engine's pattern search. Soft:
a softmax over directions with inverse temperature ``beta`` on the log-volume.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ccjax.estimators.gamut._constraints_3d import Grid, Observations, violations
from ccjax.estimators.gamut._engine import (
    CERTIFICATE_SLACK,
    EDGE,
    directions,
    leading,
    max_of_forms,
    pattern_search_carrying,
)
from ccjax.estimators.gamut._weights import log_volume, normalised
from ccjax.precision import matmul

# The pattern search evaluates its candidates in a box of this many fine-grid steps around its
# start with only the top-facet forms that can be the largest there (:func:`box_forms`), and
# any candidate outside it with all of them. Measured (ND-ECRULE-MV, 8 to 64 surfaces, 900
# scenes): the search ends at most 2.75 steps from its start, 99 % within 2.3.
BOX_STEPS = 4.0


def hard(model, grid: Grid, mask_violation, level, feasible: Bool[Array, " G"], log_t) -> Float[Array, "3"]:
    """The refined MV illuminant.

    Arguments:
        model: the fitted model; grid: the scene's fine grid.
        mask_violation: ``(surface, illuminant, cone) -> violation`` of the selector's mask.
        level: the relaxation level; feasible: ``(G,)`` the mask on the grid; log_t: ``(G,)``.
    """
    u, _, _ = directions(grid.rg)
    volumes = jnp.where(feasible, log_volume(log_t, u), -jnp.inf)
    best = jnp.argmax(volumes)
    start = grid.rg[best]
    lo, hi = start - BOX_STEPS * grid.step, start + BOX_STEPS * grid.step
    n_obs, k1, _ = grid.observations.top.shape
    every = grid.observations.top.reshape(n_obs * k1, 3)
    every_count = (n_obs if grid.count is None else grid.count) * k1
    order, kept = box_forms(grid.observations, grid.count, lo, hi)
    near = every[order]

    def objective(rg):
        u, v, valid = directions(rg)
        # Inside the box the kept forms give the same maximum (the same form reaches it: bitwise),
        # so a batch wholly inside reads only those, any other every form: one loop either way
        # (one copy of it in the program).
        inside = jnp.all(jnp.all((rg >= lo) & (rg <= hi), axis=-1))
        inverse = max_of_forms(v, jnp.where(inside, near, every), jnp.where(inside, kept, every_count))
        _, surface, illuminant, cone = violations(model, v, valid, grid.observations, grid.count)
        inside = valid & (mask_violation(surface, illuminant, cone) <= level) & (inverse > 0)
        value = log_volume(-jnp.log(jnp.where(inside, inverse, 1.0)), u)
        return jnp.where(inside, value, -jnp.inf), inverse

    # The start's objective and 1/T are its grid values (the same forms and violations; the
    # grid's 1/T is the same at valid directions), and the search carries the best point's 1/T:
    # the objective is traced once, inside the search's loop, and no other form loop is needed.
    options = model.options
    at_start = (volumes[best], grid.inverse_extent[best])
    centre, inverse = pattern_search_carrying(
        objective, start, grid.step / 2, options.refine_steps, options.refine_scales, *at_start
    )
    return directions(centre[None])[0][0] * inverse


def box_forms(
    obs: Observations, count: Int[Array, ""] | None, lo: Float[Array, "2"], hi: Float[Array, "2"]
) -> tuple[Int[Array, " M"], Int[Array, ""]]:
    """The top-facet forms (``obs.top`` flattened) that can be the largest, ``1/T``, at a valid
    direction in the (r,g) box ``[lo, hi]``, in their leading slots (Barnard 1999 §4.5.3: MV's
    ``T`` near its start).

    Over the box, ``v = 1/u`` lies in the componentwise box ``c +- h`` (each ``u_i`` is affine in
    (r,g), so its extremes are at the corners; valid directions have ``u_i > EDGE``), and a form
    ``f`` is dropped when it is certainly below another there: below the largest lower bound
    ``max_g (g . c - |g| . h)`` even at its own upper bound ``f . c + |f| . h``, or, among its
    observation's forms, below the one largest at ``c`` by ``(f - f*) . c + |f - f*| . h < 0``
    (each with :data:`~ccjax.estimators.gamut._engine.CERTIFICATE_SLACK` for rounding). The form
    reaching the maximum anywhere in the box passes both tests.

    Returns:
        ``(order, kept)``: form indices with the kept ones in the first ``kept`` slots.
    """
    n_obs, k1, _ = obs.top.shape
    dtype = obs.top.dtype
    corners = jnp.stack([lo, jnp.stack([lo[0], hi[1]]), jnp.stack([hi[0], lo[1]]), hi])
    u = jnp.maximum(jnp.concatenate([corners, 1.0 - jnp.sum(corners, axis=-1, keepdims=True)], axis=-1), EDGE)
    v_low, v_high = 1.0 / jnp.max(u, axis=0), 1.0 / jnp.min(u, axis=0)
    centre, half = (0.5 * (v_low + v_high)).astype(dtype), (0.5 * (v_high - v_low)).astype(dtype)
    reach = centre + half
    top = obs.top
    live = (jnp.arange(n_obs, dtype=jnp.int32) < (n_obs if count is None else count))[:, None]
    at_centre = matmul(top, centre)  # (P, K1)
    spread = matmul(jnp.abs(top), half)
    size = matmul(jnp.abs(top), reach)
    # Against the largest lower bound over the box.
    lower = jnp.where(live, at_centre - spread, -jnp.inf)
    best = jnp.unravel_index(jnp.argmax(lower), lower.shape)
    floor = lower[best]
    above_floor = at_centre + spread >= floor - CERTIFICATE_SLACK * (size + size[best])
    # Against the observation's own form largest at the centre.
    star = jnp.argmax(at_centre, axis=1)
    star_form = jnp.take_along_axis(top, star[:, None, None], axis=1)  # (P, 1, 3)
    gap = top - star_form
    star_size = jnp.take_along_axis(size, star[:, None], axis=1)
    above_own = matmul(gap, centre) + matmul(jnp.abs(gap), half) > -CERTIFICATE_SLACK * (size + star_size)
    return leading((live & above_floor & above_own).reshape(n_obs * k1))


def soft(u: Float[Array, "G 3"], log_t, inverse, log_mask, beta: float) -> Float[Array, "3"]:
    """The soft MV illuminant: ``sum_g w_g u_g / T_g`` with ``w = softmax(beta log-volume + log_mask)``."""
    weight = normalised(beta * log_volume(log_t, u), log_mask)
    return jnp.sum((weight * inverse)[:, None] * u, axis=0)
