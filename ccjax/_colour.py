"""(r,g) chromaticity (:func:`rg`, and :func:`rg_numpy` for fit-time NumPy code), which pixels
carry one, its inverse and (r,g) binning: the one implementation of each.

``r = R / (R+G+B)``, ``g = G / (R+G+B)`` (Barnard 1999 §1.2). One rule at black: a pixel whose sum
is not positive has no chromaticity and maps to the achromatic point (1/3, 1/3), never to NaN.
Any positive sum has one, however small, so the chromaticity does not depend on the scene's scale
(a scene times 1e-12 has the same chromaticities).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

TINY = 1e-12
"""The one small number: a floor for divisors and, relative to a scene's brightest pixel, the
level at or below which a pixel is black (:func:`valid_pixels`)."""


def rg(rgb: Float[ArrayLike, "... 3"]) -> Float[Array, "... 2"]:
    """(r,g) chromaticity of RGB (traceable and differentiable; ``(1/3, 1/3)`` where ``R+G+B`` is not
    positive).

    Arguments:
        rgb: ``(..., 3)`` non-negative RGB, on any scale.

    Returns:
        ``(..., 2)`` chromaticities.
    """
    rgb = jnp.asarray(rgb)
    total = jnp.sum(rgb, axis=-1, keepdims=True)
    valid = total > 0
    return jnp.where(valid, rgb[..., :2] / jnp.where(valid, total, 1.0), 1.0 / 3.0)


def valid_pixels(rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Bool[Array, " P"]:
    """The pixels that carry evidence about the light: masked in and not black.

    A black pixel has no chromaticity. "Black" is relative to the scene's brightest masked pixel
    (``R+G+B`` at most :data:`TINY` times its), not an absolute level, so that the test, like the
    chromaticities it guards, does not depend on the scene's scale: a scene multiplied by 1e-12
    keeps every pixel, and an all-zero scene keeps none.

    Arguments:
        rgb: ``(P, 3)`` non-negative camera RGB.
        mask: ``(P,)`` True where a pixel may be used.

    Returns:
        ``(P,)`` booleans.
    """
    total = jnp.sum(rgb, axis=-1)
    brightest = jnp.max(jnp.where(mask, total, 0.0))
    return mask & (total > TINY * brightest)


def rg_to_rgb(chromaticity: Float[ArrayLike, "... 2"]) -> Float[Array, "... 3"]:
    """The RGB of unit sum with chromaticity ``(r, g)``: ``(r, g, 1 - r - g)``.

    Arguments:
        chromaticity: ``(..., 2)``.

    Returns:
        ``(..., 3)``.
    """
    chromaticity = jnp.asarray(chromaticity)
    return jnp.concatenate([chromaticity, 1.0 - jnp.sum(chromaticity, axis=-1, keepdims=True)], axis=-1)


def rg_numpy(rgb: np.ndarray) -> np.ndarray:
    """:func:`rg` in NumPy at the input's precision (for fit-time code that runs outside JAX), the
    same arithmetic and the same rule at black.

    Arguments:
        rgb: ``(..., 3)`` non-negative RGB.

    Returns:
        ``(..., 2)`` chromaticities, ``(1/3, 1/3)`` where the sum is not positive.
    """
    rgb = np.asarray(rgb)
    total = rgb.sum(axis=-1, keepdims=True)
    valid = total > 0
    return np.where(valid, rgb[..., :2] / np.where(valid, total, 1.0), 1.0 / 3.0)


def rg_bin(chromaticity: Float[ArrayLike, "... 2"], n_bins: int) -> Int[Array, "... 2"]:
    """The (r,g) cell of each chromaticity on an ``n_bins`` x ``n_bins`` grid over ``[0, 1]^2``.

    Cell ``i`` covers ``[i / n_bins, (i + 1) / n_bins)``; 1.0 falls in the last cell.

    Arguments:
        chromaticity: ``(..., 2)``.
        n_bins: cells per axis.

    Returns:
        ``(..., 2)`` integer cell indices in ``[0, n_bins - 1]``.
    """
    return jnp.clip(jnp.floor(jnp.asarray(chromaticity) * n_bins).astype(jnp.int32), 0, n_bins - 1)


def unit_light(rgb: list[float]) -> list[float]:
    """``rgb`` scaled so that its largest channel is 1 (the scale of ccjax's lights): a relaxed
    gamut solution's raw magnitude (hundreds) says nothing about the light's brightness, and a
    photograph's exposure leaves that brightness unknown for every method.

    Arguments:
        rgb: an estimate's camera RGB, non-negative.

    Returns:
        The scaled RGB (as given when every channel is 0).
    """
    top = max(rgb)
    return [value / top for value in rgb] if top > 0 else list(rgb)
