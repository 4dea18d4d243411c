"""Correcting an image to the canonical light (Barnard 1999 §2.5).

A diagonal map ``diag(w_C / e)`` takes the estimated light ``e`` to the canonical white ``w_C``;
with a sharpening transform ``T`` (rows: sharpened sensors as combinations of R, G, B) the map is
the sharpened diagonal ``T^-1 diag(T w_C / T e) T``. Both are scaled to keep the brightness
R+G+B of a grey, because chromaticity methods leave the magnitude of ``e`` arbitrary.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ccjax.precision import einsum, matmul


@jax.jit
def correction_map(
    illuminant: Float[Array, "3"], canonical_white: Float[Array, "3"], sharpening: Float[Array, "3 3"] | None = None
) -> Float[Array, "3 3"]:
    """The 3x3 map taking the estimated light to the canonical one (§2.5).

    Arguments:
        illuminant: ``e``, camera RGB of white under the estimated light.
        canonical_white: ``w_C``, camera RGB of white under the canonical light.
        sharpening: optional ``T``; None for the plain diagonal map.

    Returns:
        ``M`` with ``corrected = M @ rgb``, scaled so that a grey keeps its R+G+B.
    """
    transform = jnp.eye(3, dtype=illuminant.dtype) if sharpening is None else jnp.asarray(sharpening, illuminant.dtype)
    target, source = matmul(transform, canonical_white), matmul(transform, illuminant)
    diagonal = target / jnp.where(jnp.abs(source) > 1e-12, source, 1e-12)
    matrix = jnp.linalg.solve(transform, diagonal[:, None] * transform)
    grey = illuminant / jnp.maximum(jnp.sum(illuminant), 1e-12)
    return matrix / jnp.maximum(jnp.sum(matmul(matrix, grey)), 1e-12)


@jax.jit
def diagonal_gains(illuminant: Float[Array, "3"], canonical_white: Float[Array, "3"]) -> Float[Array, "3"]:
    """The diagonal of :func:`correction_map` without sharpening (per-channel gains ``w_C / e``,
    scaled so that a grey keeps its R+G+B).

    Arguments:
        illuminant: ``(3,)`` the estimated illuminant ``e``.
        canonical_white: ``(3,)`` the canonical light's white ``w_C``.

    Returns:
        ``(3,)`` the per-channel gains.
    """
    gains = canonical_white / jnp.where(illuminant > 1e-12, illuminant, 1e-12)
    grey = illuminant / jnp.maximum(jnp.sum(illuminant), 1e-12)
    return gains / jnp.maximum(jnp.sum(gains * grey), 1e-12)


@jax.jit
def apply_map(rgb: Float[Array, "... 3"], matrix: Float[Array, "3 3"]) -> Float[Array, "... 3"]:
    """Apply a 3x3 colour map to every pixel (``matrix @ pixel``).

    Arguments:
        rgb: ``(..., 3)`` pixels.
        matrix: ``(3, 3)`` the map.

    Returns:
        ``(..., 3)`` the mapped pixels.
    """
    return einsum("...c,kc->...k", rgb, matrix)


def correct(
    rgb: ArrayLike,
    illuminant: ArrayLike,
    canonical_white: ArrayLike,
    sharpening: ArrayLike | None = None,
    saturation: float | None = None,
    clipped: ArrayLike | None = None,
) -> Float[Array, "... 3"]:
    """Map an image from the estimated light to the canonical light (jit-able).

    Clip to white: with ``saturation``, a pixel with a channel at or above it (or, given, a pixel
    marked in ``clipped``: the rule estimation used, :attr:`ccjax.io.LinearImage.clipped`) comes out
    as the canonical white with its brightest channel at ``saturation``. Its true colour is unknown (the
    sensor recorded its clipped channels at the ceiling, not their values), and mapped like the
    other pixels a clipped white takes the colour of the gains (a magenta highlight where the green
    gain is the largest); the brightest white the output can show is what a highlight looks like.

    Arguments:
        rgb: ``(..., 3)`` linear camera RGB.
        illuminant, canonical_white, sharpening: see :func:`correction_map`.
        saturation: the sensor's clip level on ``rgb``'s scale (1.0 for a :class:`ccjax.io.LinearImage`),
            or None to map clipped pixels like the others.
        clipped: optional booleans ``rgb.shape[:-1]``, True where a pixel is clipped; given, they
            decide which pixels come out white (``saturation`` then only sets the white's
            brightness, default 1.0), so that correction whitens what estimation left out.

    Returns:
        The corrected pixels; a diagonal map is applied as per-channel gains, a sharpened one as a
        3x3 matrix.
    """
    rgb, illuminant, canonical_white = jnp.asarray(rgb), jnp.asarray(illuminant), jnp.asarray(canonical_white)
    if sharpening is None:
        corrected = rgb * diagonal_gains(illuminant, canonical_white)
    else:
        corrected = apply_map(rgb, correction_map(illuminant, canonical_white, sharpening))
    if clipped is not None:
        level = 1.0 if saturation is None else saturation
        whitened = jnp.asarray(clipped, bool)[..., None]
    elif saturation is not None:
        level, whitened = saturation, jnp.any(rgb >= saturation, axis=-1, keepdims=True)
    else:
        return corrected
    white = (level * canonical_white / jnp.max(canonical_white)).astype(corrected.dtype)
    return jnp.where(whitened, white, corrected)
