"""Lights known without estimation: a light measured elsewhere (a grey card read with a meter, or
in another frame), or the mean of a white or grey region of the image itself.

Both are estimators in the library's sense (a pure ``model(x, mask) -> Estimate``), so correcting
with a known light runs through the same image loop, outputs and records as correcting with an
estimated one. Neither is fitted to a world, so neither is in the registry of labels.
"""

from __future__ import annotations

import typing
from collections.abc import Sequence
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from ccjax.estimators.base import (
    AbstractImageEstimator,
    AbstractSurfaceEstimator,
    AbstractUnblockedEstimator,
    Estimate,
    with_fallback,
)

__all__ = ["KnownLight", "WhiteRegion", "check_region", "known_light", "white_region"]


@typing.final
class KnownLight(AbstractSurfaceEstimator, AbstractUnblockedEstimator):
    """The same given light for every scene, whatever its pixels (a measured light).

    Attributes:
        light: ``(3,)`` camera RGB of white under the light (any positive scale).
    """

    light: Float[Array, "3"]
    estimates_brightness: ClassVar[bool] = False
    world_based: ClassVar[bool] = False
    default_preprocessing: ClassVar[str] = "pixels"
    # The pixels are not looked at: one pooled datum is the cheapest input the pipeline makes.
    pools_pixels: ClassVar[bool] = True

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        """The given light, ``ok``.

        Arguments:
            rgb: ``(P, 3)`` the scene (not used).
            mask: ``(P,)`` (not used).

        Returns:
            The :class:`~ccjax.estimators.base.Estimate` of :attr:`light`.
        """
        return Estimate(self.light.astype(rgb.dtype), ok=jnp.asarray(True))


@typing.final
class WhiteRegion(AbstractImageEstimator, AbstractUnblockedEstimator):
    """The mean of the usable pixels of a rectangle of the image that shows a white or grey
    surface (a grey card): under one light such a surface's camera RGB is the light's colour
    (Barnard 1999 §2.5's white ``w``), up to its brightness.

    Attributes:
        x, y: the rectangle's top-left pixel (column, row) in the image as read (upright).
        width, height: its size in pixels.
        fallback: ``(3,)`` the answer (``ok=False``) when no pixel of the rectangle is usable
            (all clipped, dark or masked).
    """

    fallback: Float[Array, "3"]
    x: int = eqx.field(static=True)
    y: int = eqx.field(static=True)
    width: int = eqx.field(static=True)
    height: int = eqx.field(static=True)
    estimates_brightness: ClassVar[bool] = False
    world_based: ClassVar[bool] = False
    default_preprocessing: ClassVar[str] = "pixels"
    pools_pixels: ClassVar[bool] = False

    def __call__(self, image: Float[Array, "H W 3"], mask: Bool[Array, "H W"]) -> Estimate:
        """The mean RGB of the rectangle's usable pixels.

        Arguments:
            image: ``(H, W, 3)`` linear camera RGB; the rectangle must lie inside it.
            mask: ``(H, W)`` True where a pixel is usable.

        Returns:
            The :class:`~ccjax.estimators.base.Estimate`; ``ok=False`` without a usable pixel in the
            rectangle or with a channel whose mean is zero.
        """
        rows, columns = slice(self.y, self.y + self.height), slice(self.x, self.x + self.width)
        pixels, usable = image[rows, columns], mask[rows, columns]
        count = jnp.sum(usable.astype(image.dtype))
        mean = jnp.sum(jnp.where(usable[..., None], pixels, 0.0), axis=(0, 1)) / jnp.maximum(count, 1.0)
        return with_fallback(mean, (count > 0) & jnp.all(mean > 0), self.fallback.astype(image.dtype))


def known_light(light: ArrayLike | Sequence[float]) -> KnownLight:
    """A :class:`KnownLight`, checked.

    Arguments:
        light: three finite, non-negative numbers with a positive largest one (camera RGB of white).

    Returns:
        The model.

    Raises:
        ValueError: not three such numbers.
    """
    import numpy as np

    values = np.asarray(light, np.float64)
    if values.shape != (3,) or not np.all(np.isfinite(values)) or np.any(values < 0) or not values.max() > 0:
        raise ValueError(f"light: expected three finite, non-negative numbers, not all zero (R,G,B), got {light!r}")
    return KnownLight(light=jnp.asarray(values / values.max(), jnp.float32))


def white_region(region: tuple[int, int, int, int], fallback: ArrayLike) -> WhiteRegion:
    """A :class:`WhiteRegion`, checked.

    Arguments:
        region: ``(x, y, width, height)`` in pixels: non-negative corner, positive size.
        fallback: ``(3,)`` the answer when the region has no usable pixel (e.g. the world's
            :attr:`~ccjax.world.World.canonical_white`).

    Returns:
        The model (the image must contain the rectangle: :func:`check_region`).

    Raises:
        ValueError: a region that is not four such integers.
    """
    if len(region) != 4 or any(isinstance(v, bool) or not isinstance(v, int) for v in region):
        raise ValueError(f"region: expected four integers X,Y,WIDTH,HEIGHT, got {region!r}")
    x, y, width, height = region
    if x < 0 or y < 0 or width < 1 or height < 1:
        raise ValueError(f"region: expected X,Y >= 0 and WIDTH,HEIGHT >= 1, got {region!r}")
    return WhiteRegion(fallback=jnp.asarray(fallback, jnp.float32), x=x, y=y, width=width, height=height)


def check_region(model: WhiteRegion, height: int, width: int, name: str) -> None:
    """Refuse an image the rectangle does not fit inside (slicing would silently shorten it).

    Arguments:
        model: the :class:`WhiteRegion`.
        height, width: the image's size in pixels (upright, as read).
        name: the image, for the message.

    Returns:
        None.

    Raises:
        ValueError: naming the image, its size and the rectangle.
    """
    if model.x + model.width > width or model.y + model.height > height:
        raise ValueError(
            f"--white-region: {model.x},{model.y},{model.width},{model.height} does not fit inside {name} "
            f"({width} x {height} pixels as read)"
        )
