"""The Minkowski mean ``(mean of x^p)^(1/p)`` per channel, shared by shades of grey (on pixels or
surfaces) and grey edge (on derivative responses, in row tiles): one implementation, with ``p`` an
array so that it can be traced and learned.

The values are divided by each channel's own maximum before the power, so ``x^p`` neither
overflows nor underflows for large ``p`` (one maximum over all channels let a dim channel's
``x^p`` underflow to 0 at ``p = 1000``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ccjax.precision import scale_down


def check_norm(p: Float[ArrayLike, ""]) -> None:
    """Refuse a Minkowski norm below 1 (NaN too) where it is known; a traced one (a norm learned
    inside ``jit``) is not checked here.

    Arguments:
        p: the norm.

    Returns:
        None.

    Raises:
        ValueError: ``p`` is below 1 or NaN.
    """
    try:
        below = not bool(jnp.asarray(p) >= 1)
    except jax.errors.ConcretizationTypeError:
        return
    if below:
        raise ValueError(f"p: expected a Minkowski norm >= 1 or inf, got {float(jnp.asarray(p))!r}")


WHOLE_POWERS = 8
"""Whole norms ``p = 1 ... WHOLE_POWERS`` are raised to by repeated multiplication
(``lax.integer_pow``), chosen at run time: ``exp(p log x)`` costs about 1.5x the whole estimate."""


@jax.custom_jvp
def unit_power(x: Float[Array, "..."], p: Float[Array, ""]) -> Float[Array, "..."]:
    """``x^p`` for positive ``x``: by multiplication where ``p`` is a whole number up to
    :data:`WHOLE_POWERS` (a run-time branch, so one compiled program serves every ``p`` and a
    traced or learned ``p`` keeps the fast path), else ``exp(p log x)``.

    Arguments:
        x: positive values.
        p: the exponent, a scalar.

    Returns:
        ``x^p``; its derivative in ``p`` is ``x^p log x`` on every branch.
    """
    whole = (p == jnp.round(p)) & (p >= 1) & (p <= WHOLE_POWERS)
    index = jnp.where(whole, p, 0).astype(jnp.int32)
    branches = [lambda x, p: x**p] + [lambda x, p, n=n: x**n for n in range(1, WHOLE_POWERS + 1)]
    return jax.lax.switch(index, branches, x, p)


@unit_power.defjvp
def _unit_power_jvp(primals, tangents):
    # The whole-number branches do not depend on p, so the derivative is given, not traced.
    x, p = primals
    dx, dp = tangents
    y = unit_power(x, p)
    return y, p * unit_power(x, p - 1) * dx + y * jnp.log(x) * dp


def minkowski_parts(
    values: Float[Array, "3 H W"], valid: Bool[Array, "H W"], p: Float[ArrayLike, ""]
) -> tuple[Float[Array, "3"], Float[Array, "3"], Float[Array, "3"], Int[Array, ""]]:
    """What :func:`minkowski_norm` needs of one set of positions (a whole image, a tile of one, a
    list of surfaces as ``(3, P, 1)``): sums that can be combined across tiles.

    Arguments:
        values: ``(3, H, W)`` non-negative values, one plane per channel.
        valid: ``(H, W)`` the positions that count.
        p: the Minkowski norm, ``>= 1`` or ``inf``.

    Returns:
        ``(maximum, scale, total, count)``: the per-channel maxima of the valid values, the scale
        each channel's powers were taken at (its maximum, or 1 where that is not a normal float),
        the per-channel sums of ``(values / scale)^p`` and the number of valid positions.
    """
    p = jnp.asarray(p, values.dtype)
    weights = valid[None]
    maximum = jnp.max(jnp.where(weights, values, 0.0), axis=(1, 2))
    finite_p = jnp.where(jnp.isinf(p), 1.0, p)  # the finite branch must stay finite (and its gradient)
    # Scale-free: any normal float is a usable peak (its reciprocal is finite), so values scaled by
    # 1e-12 are still estimated. The scale is held out of the gradient: x / s * s is x.
    peak = jax.lax.stop_gradient(maximum)
    scale = jnp.where(peak > jnp.finfo(peak.dtype).tiny, peak, 1.0)
    # scale_down, not a product with 1 / scale: that reciprocal is subnormal above ~8.5e37 and
    # devices flush it to zero.
    scaled = jnp.where(weights, scale_down(values, scale[:, None, None]), 0.0)
    positive = weights & (scaled > 0)
    powered = jnp.where(positive, unit_power(jnp.where(positive, scaled, 1.0), finite_p), 0.0)
    return maximum, scale, jnp.sum(powered, axis=(1, 2)), jnp.sum(valid, dtype=jnp.int32)


def minkowski_norm(parts: tuple[Array, Array, Array, Array], p: Float[ArrayLike, ""]) -> Float[Array, "3"]:
    """``(total / count)^(1/p) * scale`` per channel (the maximum for ``p = inf``), from
    :func:`minkowski_parts`' sums.

    Arguments:
        parts: ``(maximum, scale, total, count)`` as :func:`minkowski_parts` gives them: the
            per-channel maxima, the scale each channel's sums were taken at, the sums of
            ``(values / scale)^p`` and the number of valid positions.
        p: the Minkowski norm.

    Returns:
        ``(3,)`` the norms (0 in a channel without a positive value).
    """
    maximum, scale, total, count = parts
    p = jnp.asarray(p, total.dtype)
    infinite = jnp.isinf(p)
    finite_p = jnp.where(infinite, 1.0, p)
    mean = total / jnp.maximum(count, 1).astype(total.dtype)
    positive = mean > 0
    # The mean lies in (0, 1] where positive, so the root and its product with the scale are finite.
    norm = scale * jnp.where(positive, jnp.where(positive, mean, 1.0) ** (1.0 / finite_p), 0.0)
    return jnp.where(infinite, maximum, norm)


def minkowski_mean(
    values: Float[Array, "3 H W"], valid: Bool[Array, "H W"], p: Float[ArrayLike, ""]
) -> Float[Array, "3"]:
    """``(mean over valid of values^p)^(1/p)`` per channel plane (non-negative values; ``p = inf``:
    the maximum). ``p`` is an array, so it can be traced and learned.

    Arguments:
        values: ``(3, H, W)`` non-negative values.
        valid: ``(H, W)`` positions that count.
        p: the Minkowski norm, ``>= 1`` or ``inf``.

    Returns:
        ``(3,)`` the norms.
    """
    return minkowski_norm(minkowski_parts(values, valid, p), p)
