"""Which pixels of a photograph an estimator may use (Barnard 1999 §2.7, §4.6): not clipped, no
zero channel, inside the optional user mask, and (surface lists only) not overly dark."""

from __future__ import annotations

import numpy as np

DEFAULT_PREPROCESSING = "ave5"
"""The thesis' preprocessing (§4.6): the default of world-based surface-list methods."""
PIXELS = "pixels"
"""Every usable pixel, no dark rule: the default of the statistics methods (the field's protocol)."""
DEFAULT_DARK = 0.02
"""Dark rule: drop pixels whose R+G+B is below this fraction of the reference brightness."""
DEFAULT_PERCENTILE = 99.0
"""Dark rule: the reference brightness is this percentile of the usable pixels' R+G+B."""


def _check_mask(mask: np.ndarray | None, shape: tuple[int, ...], what: str = "mask") -> np.ndarray | None:
    if mask is None:
        return None
    mask = np.asarray(mask)
    if mask.dtype != bool:
        raise ValueError(f"{what}: expected a boolean (H, W) array, got dtype {mask.dtype}")
    if mask.shape != tuple(shape):
        raise ValueError(f"{what}: expected shape {tuple(shape)} (the image's height and width), got {mask.shape}")
    return mask


def usable_pixels(
    rgb: np.ndarray,
    clipped: np.ndarray,
    dark: float = DEFAULT_DARK,
    *,
    percentile: float = DEFAULT_PERCENTILE,
    mask: np.ndarray | None = None,
) -> np.ndarray:
    """Pixels an estimator may use (§4.6: clipped and "overly dark" pixels are discarded).

    A pixel is usable when

    1. it is not clipped (``clipped``: a channel at or above the saturation level, or transparent;
       :func:`ccjax.io.read_image`), and
    2. no channel is zero or negative: a channel at the black level says nothing about the light
       in that channel (under-exposed, or noise clamped at black), and the field's protocol drops
       such pixels, and
    3. it lies inside ``mask`` (optional user mask, e.g. excluding a colour checker), and
    4. (the dark rule, ``dark > 0``) its R+G+B is at least ``dark`` times the ``percentile``-th
       percentile of the R+G+B of the pixels passing 1-3.

    The thesis discards "overly dark" pixels without saying relative to what (§4.6, §2.7). The
    reference is a high percentile, not the single brightest pixel: one specular highlight then
    raised the threshold so far that it discarded most of a photograph (one image kept 460 of
    4,096 pixels). ``percentile=100`` is that old rule (the brightest usable pixel). Percentiles
    interpolate linearly between order statistics (``numpy.percentile``'s default).

    Arguments:
        rgb: ``(H, W, 3)`` linear image (not modified, not copied).
        clipped: ``(H, W)`` True where a pixel is not usable (saturated or transparent).
        dark: fraction in ``[0, 1)``; 0 disables the dark rule (rules 1-3 only).
        percentile: the reference percentile in ``(0, 100]``.
        mask: optional ``(H, W)`` bool, True where the user allows a pixel.

    Returns:
        ``(H, W)`` bool.
    """
    if not 0 <= dark < 1:
        raise ValueError(f"dark: expected a fraction in [0, 1), got {dark!r}")
    if not 0 < percentile <= 100:
        raise ValueError(f"percentile: expected a number in (0, 100], got {percentile!r}")
    mask = _check_mask(mask, rgb.shape[:2])
    # Channel by channel: (H, W) booleans, never an (H, W, 3) temporary (48-MP images).
    usable = ~clipped & (rgb[..., 0] > 0)
    usable &= rgb[..., 1] > 0
    usable &= rgb[..., 2] > 0
    if mask is not None:
        usable &= mask
    if dark == 0 or not usable.any():
        return usable
    brightness = rgb.sum(axis=-1)
    candidates = brightness[usable]
    # overwrite_input: the percentile may reorder this copy in place instead of making another.
    reference = float(np.percentile(candidates, percentile, overwrite_input=True))
    del candidates
    usable &= brightness >= dark * reference
    return usable
