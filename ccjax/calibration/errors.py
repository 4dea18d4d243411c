"""The error measures of Table 3.1 (Barnard 1999 §3.6) and the comparisons of fitted sensor
curves with the truth (curve error, main-peak support)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from ccjax.spectra import WAVELENGTHS


class FitErrors(eqx.Module):
    """The error columns of Table 3.1, over measurements and channels.

    Attributes:
        rms_relative: RMS of ``(predicted - measured) / measured`` as a fraction (1.02 % = 0.0102).
        rms_absolute: RMS of ``predicted - measured`` in response units (thesis: 0–255 pixel units).
        rms_r, rms_g: RMS absolute error of the (r, g) chromaticity.
    """

    rms_relative: Float[Array, ""]
    rms_absolute: Float[Array, ""]
    rms_r: Float[Array, ""]
    rms_g: Float[Array, ""]

    def as_dict(self) -> dict[str, float]:
        return {name: float(getattr(self, name)) for name in ("rms_relative", "rms_absolute", "rms_r", "rms_g")}


def fit_errors(
    predicted: Float[ArrayLike, "M 3"], measured: Float[ArrayLike, "M 3"], mask: Bool[ArrayLike, " M"] | None = None
) -> FitErrors:
    """Table 3.1's errors of predicted against measured linear responses (jit-able).

    Relative errors use only entries with a positive measured response; chromaticity errors only
    rows with a positive sum. ``mask`` (True = use) selects measurements.

    Arguments:
        predicted: ``(M, 3)`` predicted linear responses.
        measured: ``(M, 3)`` measured linear responses.
        mask: optional ``(M,)`` selection (True = use).

    Returns:
        The :class:`FitErrors` (Table 3.1's columns).
    """
    predicted = jnp.asarray(predicted)
    measured = jnp.asarray(measured)
    mask = jnp.ones(measured.shape[0], bool) if mask is None else jnp.asarray(mask, bool)
    entries = mask[:, None] & jnp.ones(measured.shape, bool)
    positive = entries & (measured > 0)
    relative = jnp.where(positive, (predicted - measured) / jnp.where(positive, measured, 1.0), 0.0)
    absolute = jnp.where(entries, predicted - measured, 0.0)

    def rms(values, where):
        total = jnp.sum(jnp.where(where, values**2, 0.0))
        return jnp.sqrt(total / jnp.maximum(jnp.sum(where), 1).astype(total.dtype))

    sum_p = predicted.sum(-1, keepdims=True)
    sum_m = measured.sum(-1, keepdims=True)
    rows = mask & (sum_p[:, 0] > 0) & (sum_m[:, 0] > 0)
    rg_p = predicted[:, :2] / jnp.where(sum_p > 0, sum_p, 1.0)
    rg_m = measured[:, :2] / jnp.where(sum_m > 0, sum_m, 1.0)
    return FitErrors(
        rms_relative=rms(relative, positive),
        rms_absolute=rms(absolute, entries),
        rms_r=rms(rg_p[:, 0] - rg_m[:, 0], rows),
        rms_g=rms(rg_p[:, 1] - rg_m[:, 1], rows),
    )


def support_of(sensors: Float[ArrayLike, "101 3"], threshold: float = 0.01) -> np.ndarray:
    """The main-peak range of each curve: the contiguous wavelengths around the peak where the
    curve stays above ``threshold`` x its peak ("the obvious boundaries of the main peaks", §3.6).

    Returns:
        ``(3, 2)`` [min_nm, max_nm] per channel, for ``fit_sensors(support=...)``.

    Arguments:
        sensors: ``(101, 3)`` sensor curves.
        threshold: the fraction of the peak that bounds the main peak.
    """
    sensors = np.asarray(sensors, dtype=np.float64)
    out = np.zeros((3, 2))
    for k in range(3):
        curve = sensors[:, k]
        peak = int(np.argmax(curve))
        above = curve >= threshold * curve[peak]
        lo = peak
        while lo > 0 and above[lo - 1]:
            lo -= 1
        hi = peak
        while hi < len(curve) - 1 and above[hi + 1]:
            hi += 1
        out[k] = WAVELENGTHS[lo], WAVELENGTHS[hi]
    return out


def curve_error(fitted: Float[ArrayLike, "101 3"], truth: Float[ArrayLike, "101 3"]) -> np.ndarray:
    """RMS over wavelengths of ``fitted - truth`` as a fraction of each true curve's peak, ``(3,)``.

    Arguments:
        fitted: ``(101, 3)`` fitted sensor curves.
        truth: ``(101, 3)`` true curves.

    Returns:
        ``(3,)`` relative RMS errors.
    """
    fitted = np.asarray(fitted, dtype=np.float64)
    truth = np.asarray(truth, dtype=np.float64)
    return np.sqrt(np.mean((fitted - truth) ** 2, axis=0)) / truth.max(axis=0)
