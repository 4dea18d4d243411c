"""NumPy reference for the field's per-pixel protocol: grey world and shades of grey on
every usable pixel of a 16-bit linear file, written from the definitions, not from ccjax.

The protocol: a pixel is usable when no channel is 0 and no channel is at or above 0.98 of the
file maximum (65535). Grey world: ``2 * mean(rho)`` over usable pixels (Barnard 1999 §4.5.1);
shades of grey: ``2 * (mean(rho^p))^(1/p)`` per channel (Finlayson & Trezzi 2004). Values are on
the unit scale ``rho = code / 65535``; everything is float64.
"""

from __future__ import annotations

import math

import numpy as np

FULL_SCALE = 65535.0
SATURATION_FRACTION = 0.98


def protocol_mask(codes: np.ndarray) -> np.ndarray:
    """``(H, W)`` True where no channel of the ``(H, W, 3)`` uint16 codes is 0 and none is at or
    above 0.98 of 65535."""
    values = codes.astype(np.int64)
    return (values.min(axis=-1) > 0) & (values.max(axis=-1) < SATURATION_FRACTION * FULL_SCALE)


def usable_values(codes: np.ndarray) -> np.ndarray:
    """``(n, 3)`` float64 unit-scale values of the usable pixels, in scan order."""
    return codes[protocol_mask(codes)].astype(np.float64) / FULL_SCALE


def grey_world(codes: np.ndarray) -> np.ndarray:
    """``(3,)`` twice the mean of the usable pixels."""
    values = usable_values(codes)
    return np.array([2.0 * math.fsum(values[:, c]) / len(values) for c in range(3)])


def shades_of_grey(codes: np.ndarray, p: float = 6.0) -> np.ndarray:
    """``(3,)`` twice the Minkowski ``p``-mean of the usable pixels, per channel."""
    values = usable_values(codes)
    return np.array([2.0 * (math.fsum(values[:, c] ** p) / len(values)) ** (1.0 / p) for c in range(3)])


def angle_degrees(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two RGB vectors in degrees, accurate near 0 (atan2 of |a x b| and a . b)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return math.degrees(math.atan2(float(np.linalg.norm(np.cross(a, b))), float(np.dot(a, b))))
