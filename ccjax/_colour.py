"""(r,g) chromaticity (absolute and scale-free), which pixels have one, its inverse and (r,g)
binning: the one implementation of each.

``r = R / (R+G+B)``, ``g = G / (R+G+B)`` (Barnard 1999 §1.2); a pixel whose sum is not positive
has no chromaticity and maps to the achromatic point (1/3, 1/3), never to NaN.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

TINY = 1e-12
"""Sums at or below this have no chromaticity."""


def rg(rgb: Float[ArrayLike, "... 3"]) -> Float[Array, "... 2"]:
    """(r,g) chromaticity of RGB (traceable; ``(1/3, 1/3)`` where ``R+G+B <= TINY``).

    Arguments:
        rgb: ``(..., 3)`` non-negative RGB.

    Returns:
        ``(..., 2)`` chromaticities.
    """
    rgb = jnp.asarray(rgb)
    total = jnp.sum(rgb, axis=-1, keepdims=True)
    valid = total > TINY
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


def chromaticity(rgb: Float[Array, "... 3"]) -> Float[Array, "... 2"]:
    """Scale-free (r,g) of each pixel: :func:`rg` of the pixel divided by its largest
    channel, so that a dark but valid pixel (a scene scaled by 1e-12) is not taken for black by
    ``rg``'s absolute threshold. Black pixels give the achromatic point, as ``rg``."""
    peak = jnp.max(rgb, axis=-1, keepdims=True)
    return rg(rgb / jnp.where(peak > 0, peak, 1.0))


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
    """:func:`rg` in NumPy at the input's precision (for fit-time code that runs outside JAX).

    Arguments:
        rgb: ``(..., 3)`` non-negative RGB.

    Returns:
        ``(..., 2)`` chromaticities, ``(1/3, 1/3)`` where the sum is not positive.
    """
    rgb = np.asarray(rgb)
    total = rgb.sum(axis=-1, keepdims=True)
    valid = total > TINY
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
