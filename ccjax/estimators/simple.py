"""Baselines and statistical estimators: NOTHING, AVE-ILLUM, GW, DB-GW, RETINEX, shades of grey.

Definitions follow Barnard 1999 §4.5 (spec ch02-04 §6.1–6.3). Every estimator respects the mask,
is jit/vmap-able and falls back (``ok=False``) to the world's average training illuminant when a
scene has no usable data (spec ch02-04 §10 item 27).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ccjax.estimators.base import TINY, Estimate, Estimator, pairwise_reduce, with_fallback
from ccjax.estimators.registry import register
from ccjax.world import World


def average_illuminant(world: World) -> Float[Array, "3"]:
    """Mean white response over the (normalised) training illuminants: AVE-ILLUM's answer."""
    return jnp.mean(world.train_whites, axis=0)


class Constant(Estimator):
    """A scene-independent estimate: NOTHING (the canonical white) or AVE-ILLUM (§4.5)."""

    illuminant: Float[Array, "3"]

    def __call__(self, rgb, mask) -> Estimate:
        return Estimate(illuminant=self.illuminant, ok=jnp.asarray(True))


class GreyWorld(Estimator):
    """Grey world, ``w = mean(rho) * (w_C / g_C)`` (§4.5.1, eq. 5.5).

    ``scale = w_C / g_C``: 2 for GW (grey = 50 % reflectance), the canonical white over the
    reflectance database's mean canonical RGB for DB-GW.
    """

    scale: Float[Array, "3"]
    fallback: Float[Array, "3"]
    estimates_brightness = True

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        weights = mask.astype(rgb.dtype)
        count = jnp.sum(weights)
        mean = pairwise_reduce(rgb * weights[:, None], jnp.add) / jnp.maximum(count, 1.0)
        return with_fallback(mean * self.scale, count > 0, self.fallback)


class ShadesOfGrey(Estimator):
    """Shades of grey (Finlayson & Trezzi 2004): ``w = 2 * (mean(rho^p))^(1/p)`` per channel.

    The factor 2 is grey world's, so ``p = 1`` is exactly GW; as ``p -> inf`` the chromaticity
    tends to RETINEX's. The magnitude is only meaningful for ``p = 1``.
    """

    p: float = eqx.field(static=True)  # static: an integer p compiles to multiplications
    fallback: Float[Array, "3"]

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        count = jnp.sum(mask)
        masked = jnp.where(mask[:, None], rgb, 0.0)
        # Normalise by the brightest value first so rho^p neither overflows nor underflows.
        peak = jnp.max(pairwise_reduce(masked, jnp.maximum))
        usable = (count > 0) & (peak > TINY)
        inverse_peak = 1.0 / jnp.where(usable, peak, 1.0)
        # An integer p becomes repeated multiplication (lax.integer_pow), not exp(p log x).
        exponent = int(self.p) if float(self.p).is_integer() else self.p
        mean = pairwise_reduce((masked * inverse_peak) ** exponent, jnp.add) / jnp.maximum(count, 1)
        positive = mean > 0
        root = jnp.where(positive, jnp.where(positive, mean, 1.0) ** (1.0 / self.p), 0.0)
        # The normalised mean lies in (0, 1], so the estimate is finite wherever ``usable``: no
        # need for with_fallback's finiteness checks, which make XLA re-evaluate the p-th root in
        # each of their fusions (measured 2x slower at 8 surfaces).
        illuminant = jnp.where(usable, 2.0 * root / inverse_peak, self.fallback)
        return Estimate(illuminant=illuminant, ok=usable)


class MaxRGB(Estimator):
    """RETINEX in its limiting form, per-channel maximum ``w_k = max_i rho_ik`` (§4.5.2).

    With ``temperature`` set, a soft maximum ``t * logsumexp(rho / t)`` over valid pixels gives
    gradients to every pixel (DESIGN.md §5); it tends to the hard maximum as ``t -> 0``.
    """

    fallback: Float[Array, "3"]
    temperature: float | None = None
    estimates_brightness = True

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        count = jnp.sum(mask)
        if self.temperature is None:
            maximum = pairwise_reduce(jnp.where(mask[:, None], rgb, 0.0), jnp.maximum)
        else:
            t = self.temperature
            scaled = jnp.where(mask[:, None], rgb / t, 0.0)
            top = jax.lax.stop_gradient(jnp.max(scaled, axis=0))
            total = jnp.sum(jnp.where(mask[:, None], jnp.exp(scaled - top), 0.0), axis=0)
            maximum = t * (top + jnp.log(jnp.maximum(total, TINY)))
        return with_fallback(maximum, count > 0, self.fallback)


# ---------------------------------------------------------------------------------------------
# fit functions (label -> model), used by the registry


def fit_nothing(world: World) -> Constant:
    return Constant(illuminant=world.canonical_white)


def fit_ave_illum(world: World) -> Constant:
    return Constant(illuminant=average_illuminant(world))


def fit_gw(world: World) -> GreyWorld:
    return GreyWorld(scale=jnp.full(3, 2.0), fallback=average_illuminant(world))


def fit_db_gw(world: World) -> GreyWorld:
    database_grey = jnp.mean(world.canonical_rgb, axis=0)
    return GreyWorld(scale=world.canonical_white / database_grey, fallback=average_illuminant(world))


def fit_retinex(world: World, temperature: float | None = None) -> MaxRGB:
    if temperature is not None and not temperature > 0:
        raise ValueError(f"temperature: expected a positive number or None, got {temperature!r}")
    return MaxRGB(fallback=average_illuminant(world), temperature=temperature)


def fit_shades_of_grey(world: World, p: float = 6.0) -> ShadesOfGrey:
    if not p >= 1:
        raise ValueError(f"p: expected a Minkowski norm >= 1, got {p!r}")
    return ShadesOfGrey(p=float(p), fallback=average_illuminant(world))


# ---------------------------------------------------------------------------------------------
# labels

register(r"NOTHING", "NOTHING", "assume the canonical light (§4.5)")(lambda w, m, **o: fit_nothing(w, **o))
register(r"AVE-ILLUM", "AVE-ILLUM", "mean of the training illuminants (§4.5)")(lambda w, m, **o: fit_ave_illum(w, **o))
register(r"GW", "GW", "grey world, 2 x mean RGB (§4.5.1)")(lambda w, m, **o: fit_gw(w, **o))
register(r"DB-GW", "DB-GW", "grey world with the database mean as grey (§4.5.1)")(lambda w, m, **o: fit_db_gw(w, **o))
register(r"RETINEX|MAX-RGB|max-rgb", "RETINEX", "per-channel maximum (§4.5.2)")(lambda w, m, **o: fit_retinex(w, **o))
register(
    r"soft-RETINEX-t(?P<t>\d+(\.\d+)?(e-?\d+)?)",
    "soft-RETINEX-t0.01",
    "soft maximum with temperature t (differentiable)",
)(lambda w, m, **o: fit_retinex(w, temperature=float(m["t"]), **o))
register(
    r"shades-of-grey-p(?P<p>\d+(\.\d+)?)", "shades-of-grey-p6", "Minkowski p-norm grey world (Finlayson & Trezzi)"
)(lambda w, m, **o: fit_shades_of_grey(w, p=float(m["p"]), **o))
