"""FFCC's input: two log-chroma histograms of an image on a torus (Barron & Tsai 2017, §2 and §3;
Barron 2015, §2), one of the usable pixels and one of their local absolute deviation (an edge
image, §4: "pixels and edges").

Log-chroma is ``u = log(G / R)``, ``v = log(G / B)`` (:func:`ccjax.estimators.neural.log_chroma`);
bin ``(i, j)`` is centred on ``origin + bin_size * (i, j)`` and the histogram wraps: a value lands
in the nearest bin modulo ``bins`` (FFCC §3, "aliasing"), so the convolutions of the model are the
periodic ones the FFT computes.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ccjax.estimators.neural import log_chroma

__all__ = ["MINIMUM_INTENSITY", "block_means", "featurize", "local_absolute_deviation", "wrapped_histogram"]

MINIMUM_INTENSITY = 1.0 / 256.0
"""Channels below this, in units of the sensor's saturation level (1.0 on ccjax's linear scale), are
not trusted (the reference code's ``HISTOGRAM.MINIMUM_INTENSITY``)."""

_HALF_NEIGHBOURHOOD = ((0, 1), (1, 0), (1, 1), (1, -1))
"""One of each pair of opposite 3x3 neighbour offsets: ``|a - b| = |b - a|``, so each difference
is computed once and credited to both pixels of the pair."""


def block_means(
    image: Float[Array, "H W 3"], mask: Bool[Array, "H W"], block: int
) -> tuple[Float[Array, "h w 3"], Bool[Array, "h w"]]:
    """The image reduced to the means of its usable pixels in ``block x block`` blocks (the
    reference code's masked downsampling of a camera image to its statistics image, e.g. the
    32 x 48 NUS-8 thumbnails): a block without a usable pixel is unusable. An image whose sides are
    not multiples of ``block`` is padded with unusable pixels, so every pixel counts.

    Arguments:
        image: ``(H, W, 3)`` linear RGB.
        mask: ``(H, W)`` usable pixels.
        block: the block's side in pixels (1: the image and mask unchanged).

    Returns:
        ``(means (ceil(H / block), ceil(W / block), 3), usable blocks)``.
    """
    if block == 1:
        return image, mask
    height, width = mask.shape
    rows, cols = -(-height // block), -(-width // block)
    pad = ((0, rows * block - height), (0, cols * block - width))
    weight = jnp.pad(mask, pad).astype(image.dtype)
    total = jnp.pad(image, (*pad, (0, 0))) * weight[..., None]
    sums = total.reshape(rows, block, cols, block, 3).sum(axis=(1, 3))
    counts = weight.reshape(rows, block, cols, block).sum(axis=(1, 3))
    return sums / jnp.maximum(counts, 1.0)[..., None], counts > 0


def local_absolute_deviation(image: Float[Array, "H W 3"], mask: Bool[Array, "H W"]) -> Float[Array, "H W 3"]:
    """Mean absolute difference between each usable pixel and its usable 3x3 neighbours, per
    channel (FFCC §4's edge channel; borders replicate the edge pixels, as the reference code's
    ``MaskedLocalAbsoluteDeviation``).

    Arguments:
        image: ``(H, W, 3)`` linear RGB.
        mask: ``(H, W)`` usable pixels.

    Returns:
        ``(H, W, 3)`` the deviation; 0 where a pixel is unusable or has no usable neighbour.
    """
    height, width = mask.shape
    # Channels first: the rows, not the 3 channels, are the innermost axis the CPU vectorises.
    padded = jnp.pad(jnp.moveaxis(image, -1, 0), ((0, 0), (1, 1), (1, 1)), mode="edge")
    padded_mask = jnp.pad(mask, 1, mode="edge").astype(image.dtype)
    numerator = jnp.zeros((3, height, width), image.dtype)
    count = jnp.zeros(mask.shape, image.dtype)
    for di, dj in _HALF_NEIGHBOURHOOD:
        # Pairs (q, q + d) of the padded grid, indexed by q from row 0 and column max(0, -dj).
        rows, cols = slice(0, height + 2 - di), slice(max(0, -dj), width + 2 - max(0, dj))
        shifted_rows, shifted_cols = slice(di, height + 2), slice(max(0, -dj) + dj, width + 2 - max(0, dj) + dj)
        both = padded_mask[rows, cols] * padded_mask[shifted_rows, shifted_cols]
        difference = both * jnp.abs(padded[:, shifted_rows, shifted_cols] - padded[:, rows, cols])
        # A pixel p (padded (1 + y, 1 + x)) is the first of the pair at q = p and the second at q = p - d.
        for oi, oj in ((0, 0), (-di, -dj)):
            top, left = 1 + oi, 1 + oj - max(0, -dj)
            numerator = numerator + difference[:, top : top + height, left : left + width]
            count = count + both[top : top + height, left : left + width]
    return jnp.moveaxis(numerator / jnp.maximum(count, 1.0), 0, -1)


def wrapped_histogram(
    rgb: Float[Array, "*C P 3"],
    valid: Bool[Array, "*C P"],
    origin: Float[Array, "2"],
    bins: int,
    bin_size: Float[Array, ""] | float,
) -> Float[Array, "*C bins bins"]:
    """Normalised histogram of the valid colours' log-chroma on the ``bins x bins`` torus, one per
    leading index (one scatter for all of them).

    Arguments:
        rgb: ``(..., P, 3)`` colours (a channel at or below 0 must be marked invalid).
        valid: ``(..., P)`` the colours counted.
        origin: ``(2,)`` log-chroma ``(u, v)`` of bin ``(0, 0)``'s centre.
        bins: bins per axis.
        bin_size: log-chroma width of a bin.

    Returns:
        ``(..., bins, bins)`` counts divided by their sum (all zeros when nothing is valid); axis
        -2 is ``u``, axis -1 ``v``.
    """
    leading, points = valid.shape[:-1], valid.shape[-1]
    cells = jnp.floor((log_chroma(rgb.reshape(-1, 3)) - origin) / bin_size + 0.5).astype(jnp.int32) % bins
    histograms = math.prod(leading)
    offset = jnp.repeat(jnp.arange(histograms, dtype=jnp.int32) * bins * bins, points)
    # Invalid colours go to an index past the end, which the scatter drops.
    index = jnp.where(valid.reshape(-1), offset + cells[:, 0] * bins + cells[:, 1], histograms * bins * bins)
    counts = jnp.zeros(histograms * bins * bins, rgb.dtype).at[index].add(1.0, mode="drop")
    counts = counts.reshape(*leading, bins, bins)
    return counts / jnp.maximum(jnp.sum(counts, axis=(-2, -1), keepdims=True), 1.0)


def featurize(
    image: Float[Array, "H W 3"],
    mask: Bool[Array, "H W"],
    *,
    origin: Float[Array, "2"],
    bins: int,
    bin_size: Float[Array, ""] | float,
    minimum: float = MINIMUM_INTENSITY,
) -> Float[Array, "2 bins bins"]:
    """FFCC's two-channel histogram of an image: its usable pixels, and their local absolute
    deviation (:func:`local_absolute_deviation`), each counted where every channel is at least
    ``minimum`` (reference code ``FeaturizeImage``).

    Arguments:
        image: ``(H, W, 3)`` linear RGB, 1.0 = saturation.
        mask: ``(H, W)`` usable pixels (not clipped).
        origin, bins, bin_size: the histogram grid (:func:`wrapped_histogram`).
        minimum: the smallest trusted channel value.

    Returns:
        ``(2, bins, bins)`` the pixel histogram and the edge histogram.
    """
    rgb = jnp.stack([image, local_absolute_deviation(image, mask)]).reshape(2, -1, 3)
    valid = mask.reshape(1, -1) & jnp.all(rgb >= minimum, axis=-1) & jnp.all(rgb > 0, axis=-1)
    return wrapped_histogram(rgb, valid, origin, bins, bin_size)
