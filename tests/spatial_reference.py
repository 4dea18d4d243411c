"""NumPy/SciPy reference of the general grey-edge estimate (van de Weijer, Gevers & Gijsenij 2007),
written from the definition in ccjax/estimators/spatial.py's docstring as plain code:

    e_c = ( mean over valid positions of d_c^p )^(1/p)   (p = inf: max)

with d_c the smoothed channel (n = 0), the gradient magnitude (n = 1) or
sqrt(f_xx^2 + 4 f_xy^2 + f_yy^2) (n = 2) of Gaussian derivatives (scipy.ndimage.gaussian_filter,
mode="nearest") or, for sigma = 0, central differences on an edge-padded image; a position is
valid when the mask is True on the whole (2r+1)^2 square around it (edge-replicated).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage


def _central(channel: np.ndarray, order_y: int, order_x: int) -> np.ndarray:
    out = channel.astype(np.float64)
    for axis, order in ((0, order_y), (1, order_x)):
        for _ in range(order if order == 1 else 0):
            padded = np.pad(out, [(1, 1) if a == axis else (0, 0) for a in (0, 1)], mode="edge")
            lo = padded[:-2] if axis == 0 else padded[:, :-2]
            hi = padded[2:] if axis == 0 else padded[:, 2:]
            out = (hi - lo) / 2.0
        if order == 2:
            padded = np.pad(out, [(1, 1) if a == axis else (0, 0) for a in (0, 1)], mode="edge")
            lo = padded[:-2] if axis == 0 else padded[:, :-2]
            mid = padded[1:-1] if axis == 0 else padded[:, 1:-1]
            hi = padded[2:] if axis == 0 else padded[:, 2:]
            out = hi - 2.0 * mid + lo
    return out


def _derivative(channel: np.ndarray, sigma: float, order_y: int, order_x: int) -> np.ndarray:
    if sigma == 0:
        return _central(channel, order_y, order_x)
    return ndimage.gaussian_filter(channel.astype(np.float64), sigma, order=(order_y, order_x), mode="nearest")


def grey_edge_reference(image: np.ndarray, mask: np.ndarray, order: int, p: float, sigma: float) -> np.ndarray:
    estimate = np.zeros(3)
    if sigma == 0:
        radius = 0 if order == 0 else 1
    else:
        radius = int(math.ceil(2 * sigma))
    valid = ndimage.minimum_filter(mask.astype(np.uint8), size=2 * radius + 1, mode="nearest").astype(bool)
    for c in range(3):
        f = image[..., c]
        if order == 0:
            d = _derivative(f, sigma, 0, 0)
        elif order == 1:
            d = np.sqrt(_derivative(f, sigma, 0, 1) ** 2 + _derivative(f, sigma, 1, 0) ** 2)
        else:
            d = np.sqrt(
                _derivative(f, sigma, 0, 2) ** 2
                + 4 * _derivative(f, sigma, 1, 1) ** 2
                + _derivative(f, sigma, 2, 0) ** 2
            )
        values = d[valid]
        estimate[c] = values.max() if math.isinf(p) else np.mean(values**p) ** (1.0 / p)
    return estimate
