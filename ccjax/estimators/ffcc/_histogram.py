"""FFCC's input: two log-chroma histograms of an image on a torus (Barron & Tsai 2017, §2 and §3;
Barron 2015, §2), one of the usable pixels and one of their local absolute deviation (an edge
image, §4: "pixels and edges").

Log-chroma is ``u = log(G / R)``, ``v = log(G / B)`` (:func:`ccjax.estimators.neural.log_chroma`);
bin ``(i, j)`` is centred on ``origin + bin_size * (i, j)`` and the histogram wraps: a value lands
in the nearest bin modulo ``bins`` (FFCC §3, "aliasing"), so the convolutions of the model are the
periodic ones the FFT computes.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ccjax.estimators.neural import log_chroma

__all__ = ["MINIMUM_INTENSITY", "featurize", "local_absolute_deviation", "wrapped_histogram"]

MINIMUM_INTENSITY = 1.0 / 256.0
"""Channels below this, in units of the sensor's saturation level (1.0 on ccjax's linear scale), are
not trusted (the reference code's ``HISTOGRAM.MINIMUM_INTENSITY``)."""


def local_absolute_deviation(image: Float[Array, "H W 3"], mask: Bool[Array, "H W"]) -> Float[Array, "H W 3"]:
    """Mean absolute difference between each usable pixel and its usable 3x3 neighbours, per
    channel (FFCC §4's edge channel; borders replicate the edge pixels).

    Arguments:
        image: ``(H, W, 3)`` linear RGB.
        mask: ``(H, W)`` usable pixels.

    Returns:
        ``(H, W, 3)`` the deviation; 0 where a pixel is unusable or has no usable neighbour.
    """
    height, width = mask.shape
    padded = jnp.pad(image, ((1, 1), (1, 1), (0, 0)), mode="edge")
    padded_mask = jnp.pad(mask, 1, mode="edge")
    numerator = jnp.zeros_like(image)
    count = jnp.zeros(mask.shape, image.dtype)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di == 0 and dj == 0:
                continue
            shifted = padded[1 + di : 1 + di + height, 1 + dj : 1 + dj + width]
            both = (mask & padded_mask[1 + di : 1 + di + height, 1 + dj : 1 + dj + width]).astype(image.dtype)
            numerator = numerator + both[..., None] * jnp.abs(shifted - image)
            count = count + both
    return numerator / jnp.maximum(count, 1.0)[..., None]


def wrapped_histogram(
    rgb: Float[Array, "P 3"],
    valid: Bool[Array, " P"],
    origin: Float[Array, "2"],
    bins: int,
    bin_size: Float[Array, ""] | float,
) -> Float[Array, "bins bins"]:
    """Normalised histogram of the valid colours' log-chroma on the ``bins x bins`` torus.

    Arguments:
        rgb: ``(P, 3)`` colours (a channel at or below 0 must be marked invalid).
        valid: ``(P,)`` the colours counted.
        origin: ``(2,)`` log-chroma ``(u, v)`` of bin ``(0, 0)``'s centre.
        bins: bins per axis.
        bin_size: log-chroma width of a bin.

    Returns:
        ``(bins, bins)`` counts divided by their sum (all zeros when nothing is valid); axis 0 is
        ``u``, axis 1 ``v``.
    """
    cells = jnp.floor((log_chroma(rgb) - origin) / bin_size + 0.5).astype(jnp.int32) % bins
    weight = valid.astype(rgb.dtype)
    counts = jnp.zeros(bins * bins, rgb.dtype).at[cells[:, 0] * bins + cells[:, 1]].add(weight)
    return (counts / jnp.maximum(jnp.sum(weight), 1.0)).reshape(bins, bins)


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
    edges = local_absolute_deviation(image, mask)
    channels = []
    for values in (image, edges):
        rgb = values.reshape(-1, 3)
        valid = mask.reshape(-1) & jnp.all(rgb >= minimum, axis=-1) & jnp.all(rgb > 0, axis=-1)
        channels.append(wrapped_histogram(rgb, valid, origin, bins, bin_size))
    return jnp.stack(channels)
