"""The fixed wavelength grid and resampling onto it.

Every spectrum in ccjax lives on 380–780 nm in 4 nm steps (101 samples), the sampling of the
PR-650 spectroradiometer used throughout the thesis (Barnard 1999 §2.2).
Loaders resample once, at load time:

* sensor curves are **zero** outside their measured range (a sensor that was not measured there
  is taken to have no sensitivity there);
* reflectances and illuminants **hold their edge values** (a spectrum is a physical quantity that
  does not drop to zero just because the instrument stopped).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

WAVELENGTHS: np.ndarray = np.arange(380.0, 780.0 + 1e-9, 4.0)
"""The ccjax wavelength grid in nm: 380, 384, ..., 780 (101 samples)."""

N_WAVELENGTHS: int = WAVELENGTHS.size


def resample(
    wavelengths: np.ndarray,
    values: np.ndarray,
    *,
    kind: Literal["sensor", "spectrum"],
) -> np.ndarray:
    """Resample spectra onto :data:`WAVELENGTHS` by linear interpolation.

    Arguments:
        wavelengths: strictly increasing sample positions in nm, shape ``(L,)``.
        values: samples, shape ``(L,)`` or ``(L, C)`` (wavelength first, channels after), or
            ``(N, L)`` when ``values.shape[-1] == L`` and ``values.shape[0] != L``.
        kind: ``"sensor"`` (zero outside the measured range) or ``"spectrum"`` (edge-held).

    Returns:
        Array on the grid: ``(101,)``, ``(101, C)`` or ``(N, 101)`` following the input layout.
    """
    wavelengths = np.asarray(wavelengths, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    if wavelengths.ndim != 1 or wavelengths.size < 2:
        raise ValueError(f"wavelengths: expected a 1-D array of at least 2 samples, got shape {wavelengths.shape}")
    if np.any(np.diff(wavelengths) <= 0):
        raise ValueError("wavelengths: must be strictly increasing")
    if not np.all(np.isfinite(values)):
        raise ValueError("values: contains NaN or infinite samples")
    if kind not in ("sensor", "spectrum"):
        raise ValueError(f"kind: expected 'sensor' or 'spectrum', got {kind!r}")
    length = wavelengths.size
    if values.ndim == 1:
        if values.size != length:
            raise ValueError(f"values: {values.size} samples for {length} wavelengths")
        columns = values[:, None]
        layout = "vector"
    elif values.shape[0] == length:
        columns = values
        layout = "columns"
    elif values.shape[-1] == length:
        columns = values.T
        layout = "rows"
    else:
        raise ValueError(f"values: shape {values.shape} does not match {length} wavelengths")
    outside = 0.0 if kind == "sensor" else None
    out = np.stack(
        [np.interp(WAVELENGTHS, wavelengths, column, left=outside, right=outside) for column in columns.T],
        axis=1,
    )
    if layout == "vector":
        return out[:, 0]
    return out if layout == "columns" else out.T


def chromaticity(rgb: np.ndarray) -> np.ndarray:
    """(r, g) chromaticity ``(R, G) / (R + G + B)`` of NumPy RGBs, shape ``(..., 3) -> (..., 2)``.

    A NumPy helper for loaders and plots, kept for its callers. New code uses
    :func:`ccjax._colour.rg_numpy` (or the jit-able :func:`ccjax.metrics.rg`), which agrees wherever
    ``R+G+B > 1e-12``; here a black RGB gives ``(0, 0)`` rather than the achromatic ``(1/3, 1/3)``,
    which is why this is not an alias of it (the numbers printed from it must not move).
    """
    rgb = np.asarray(rgb, dtype=np.float64)
    total = rgb.sum(axis=-1, keepdims=True)
    return rgb[..., :2] / np.where(total > 0, total, 1.0)
