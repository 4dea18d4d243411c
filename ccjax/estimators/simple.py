"""Baselines and statistical estimators: NOTHING, AVE-ILLUM, GW, DB-GW, RETINEX, shades of grey.

Definitions follow Barnard 1999 §4.5 (§4.5.1 grey world, §4.5.2 RETINEX). Every estimator respects the mask,
is jit/vmap-able and falls back (``ok=False``) to the world's average training illuminant when a
scene has no usable data.
"""

from __future__ import annotations

import typing
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ccjax._colour import TINY
from ccjax.estimators.base import (
    AbstractStatisticsSurfaceEstimator,
    AbstractSurfaceEstimator,
    AbstractUnblockedEstimator,
    AbstractWorldSurfaceEstimator,
    Estimate,
    pairwise_reduce,
    with_fallback,
)
from ccjax.estimators.minkowski import check_norm, minkowski_norm, minkowski_parts
from ccjax.estimators.registry import register
from ccjax.world import World


def average_illuminant(world: World) -> Float[Array, "3"]:
    """Mean white response over the (normalised) training illuminants: AVE-ILLUM's answer."""
    return jnp.mean(world.train_whites, axis=0)


@typing.final
class Constant(AbstractWorldSurfaceEstimator):
    """A scene-independent estimate: NOTHING (the canonical white) or AVE-ILLUM (§4.5)."""

    illuminant: Float[Array, "3"]
    estimates_brightness: ClassVar[bool] = False

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        # The answer ignores the scene, but a scene without one lit valid surface (all masked, all
        # black) is degenerate: report it (Status.NO_DATA) as every other estimator does.
        lit = jnp.any(mask & (jnp.max(rgb, axis=-1) > 0))
        return Estimate(illuminant=self.illuminant, ok=lit)


@typing.final
class GreyWorld(AbstractSurfaceEstimator, AbstractUnblockedEstimator):
    """Grey world, ``w = mean(rho) * (w_C / g_C)`` (§4.5.1, eq. 5.5).

    ``scale = w_C / g_C``: 2 for GW (grey = 50 % reflectance), the canonical white over the
    reflectance database's mean canonical RGB for DB-GW.

    Attributes:
        scale: ``(3,)`` ``w_C / g_C``.
        fallback: ``(3,)`` estimate for scenes without usable data.
        database: True for DB-GW, whose grey is the world's reflectance database: a world-based
            method, prepared from photographs as the thesis did (5x5 block averages); plain GW
            gets every usable pixel (:attr:`default_preprocessing`). Static: it is configuration.
    """

    scale: Float[Array, "3"]
    fallback: Float[Array, "3"]
    database: bool = eqx.field(static=True, default=False)
    estimates_brightness: ClassVar[bool] = True
    pools_pixels: ClassVar[bool] = True

    @property
    def world_based(self) -> bool:  # pyright: ignore[reportIncompatibleVariableOverride]
        """DB-GW's grey is the world's reflectance database; GW's is a 50 % grey."""
        return self.database

    @property
    def default_preprocessing(self) -> str:  # pyright: ignore[reportIncompatibleVariableOverride]
        """``"ave5"`` for DB-GW (world-based, §4.6), ``"pixels"`` for GW (every usable pixel)."""
        return "ave5" if self.database else "pixels"

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        weights = mask.astype(rgb.dtype)
        count = jnp.sum(weights)
        mean = pairwise_reduce(rgb * weights[:, None], jnp.add) / jnp.maximum(count, 1.0)
        # A channel whose mean is zero holds no light to estimate (it would divide by zero in
        # any correction): fall back, as without usable pixels.
        return with_fallback(mean * self.scale, (count > 0) & jnp.all(mean > 0), self.fallback)


@typing.final
class ShadesOfGrey(AbstractStatisticsSurfaceEstimator):
    """Shades of grey (Finlayson & Trezzi 2004): ``w = 2 * (mean(rho^p))^(1/p)`` per channel.

    The factor 2 is grey world's, so ``p = 1`` is exactly GW; as ``p -> inf`` the chromaticity
    tends to RETINEX's. The magnitude is only meaningful for ``p = 1``.

    Attributes:
        p: the Minkowski norm ``>= 1`` (an array, as grey edge's: it can be learned, and one
            compiled program serves every ``p``).
        fallback: ``(3,)`` estimate for scenes without usable data.
    """

    p: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    fallback: Float[Array, "3"]
    # A statistics method, evaluated on every usable pixel as the field does.
    estimates_brightness: ClassVar[bool] = False

    def __check_init__(self):
        check_norm(self.p)  # also run on a model read from a file: its p is the file's

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        # The surfaces as one column of positions per channel plane: grey edge's Minkowski mean.
        parts = minkowski_parts(rgb.T[:, :, None], mask[:, None], self.p)
        maximum, count = parts[0], parts[3]
        usable = (count > 0) & (jnp.max(maximum) > jnp.finfo(maximum.dtype).tiny)
        # The normalised mean lies in (0, 1], so the estimate is finite wherever ``usable``: no
        # need for with_fallback's finiteness checks, which make XLA re-evaluate the p-th root in
        # each of their fusions (measured 2x slower at 8 surfaces).
        illuminant = jnp.where(usable, 2.0 * minkowski_norm(parts, self.p), self.fallback)
        return Estimate(illuminant=illuminant, ok=usable)


@typing.final
class MaxRGB(AbstractStatisticsSurfaceEstimator):
    """RETINEX in its limiting form, per-channel maximum ``w_k = max_i rho_ik`` (§4.5.2).

    With ``temperature`` set, a soft maximum ``s t * logsumexp(rho / (s t))`` over valid pixels
    gives gradients to every pixel, where ``s`` is the scene's brightest valid value (so the
    temperature is relative and the answer scale-invariant); it tends to the hard maximum as ``t -> 0``.
    """

    fallback: Float[Array, "3"]
    temperature: Float[Array, ""] | None = None
    # A statistics method, evaluated on every usable pixel as the field does.
    estimates_brightness: ClassVar[bool] = True

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        count = jnp.sum(mask)
        if self.temperature is None:
            maximum = pairwise_reduce(jnp.where(mask[:, None], rgb, 0.0), jnp.maximum)
            return with_fallback(maximum, count > 0, self.fallback)
        # The temperature is relative to the scene's brightest value, so scaling a scene scales the
        # estimate and keeps its chromaticity: s * t * logsumexp(rho / (s * t)).
        brightest = jnp.max(jnp.where(mask[:, None], rgb, 0.0))
        # The soft maximum of an all-black scene is t log(P) > 0: demand a lit pixel, as the hard one does.
        lit = (count > 0) & (brightest > jnp.finfo(brightest.dtype).tiny)
        t = self.temperature * jnp.where(lit, brightest, 1.0)
        scaled = jnp.where(mask[:, None], rgb / t, 0.0)
        top = jax.lax.stop_gradient(jnp.max(scaled, axis=0))
        total = jnp.sum(jnp.where(mask[:, None], jnp.exp(scaled - top), 0.0), axis=0)
        maximum = t * (top + jnp.log(jnp.maximum(total, TINY)))
        return with_fallback(maximum, lit, self.fallback)


# ---------------------------------------------------------------------------------------------
# fit functions (label -> model), used by the registry


def fit_nothing(world: World) -> Constant:
    return Constant(illuminant=world.canonical_white)


def fit_ave_illum(world: World) -> Constant:
    return Constant(illuminant=average_illuminant(world))


def fit_gw(world: World) -> GreyWorld:
    fallback = average_illuminant(world)
    # The world's dtype, strong-typed: jnp.full(3, 2.0) alone is a weak-typed array, whose type
    # changes at a training step's first update (a second trace of the step).
    return GreyWorld(scale=jnp.full(3, 2.0, fallback.dtype), fallback=fallback)


def fit_db_gw(world: World) -> GreyWorld:
    database_grey = jnp.mean(world.canonical_rgb, axis=0)
    return GreyWorld(scale=world.canonical_white / database_grey, fallback=average_illuminant(world), database=True)


def fit_retinex(world: World, temperature: float | None = None) -> MaxRGB:
    if temperature is not None and not temperature > 0:
        raise ValueError(f"temperature: expected a positive number or None, got {temperature!r}")
    fallback = average_illuminant(world)
    # An array, not a Python float: the temperature is a (learnable) number, not configuration.
    t = None if temperature is None else jnp.asarray(temperature, fallback.dtype)
    return MaxRGB(fallback=fallback, temperature=t)


def fit_shades_of_grey(world: World, p: float = 6.0) -> ShadesOfGrey:
    if not p >= 1:
        raise ValueError(f"p: expected a Minkowski norm >= 1, got {p!r}")
    fallback = average_illuminant(world)
    # An array, not a Python float: the norm is a (learnable) number, not configuration.
    return ShadesOfGrey(p=jnp.asarray(p, fallback.dtype), fallback=fallback)


# ---------------------------------------------------------------------------------------------
# labels


# Labels without parameters: (pattern, grammar, description, fit, differentiable). Every fit here
# is pure JAX in the world's arrays.
_FIXED_LABELS = (
    ("NOTHING", "NOTHING", "assume the canonical light (§4.5)", fit_nothing, False),
    ("AVE-ILLUM", "AVE-ILLUM", "mean of the training illuminants (§4.5)", fit_ave_illum, False),
    ("GW|gw", "GW | gw", "grey world, 2 x mean RGB (§4.5.1)", fit_gw, True),
    ("DB-GW", "DB-GW", "grey world with the database mean as grey (§4.5.1)", fit_db_gw, True),
    ("RETINEX|MAX-RGB|max-rgb", "RETINEX | MAX-RGB | max-rgb", "per-channel maximum (§4.5.2)", fit_retinex, False),
)
for _pattern, _grammar, _description, _fit, _differentiable in _FIXED_LABELS:
    register(
        _pattern,
        grammar=_grammar,
        example=_grammar.split(" ")[0],
        description=_description,
        traceable_fit=True,
        differentiable=_differentiable,
    )(lambda world, match, fit=_fit, **options: fit(world, **options))


@register(
    r"soft-RETINEX-t(?P<t>\d+(\.\d+)?(e-?\d+)?)",
    grammar="soft-RETINEX-t<T>",
    example="soft-RETINEX-t0.01",
    description="soft maximum with temperature T (differentiable)",
    traceable_fit=True,
    differentiable=True,
)
def _build_soft_retinex(world, match, **options):
    return fit_retinex(world, temperature=float(match["t"]), **options)


@register(
    r"shades-of-grey-p(?P<p>\d+(\.\d+)?)",
    grammar="shades-of-grey-p<P>",
    example="shades-of-grey-p6",
    description="Minkowski p-norm grey world (Finlayson & Trezzi)",
    traceable_fit=True,
    differentiable=True,
)
def _build_shades_of_grey(world, match, **options):
    return fit_shades_of_grey(world, p=float(match["p"]), **options)
