"""The camera noise model of chapter 3: variance = a * mean + floor (Barnard 1999 §3.4, Fig. 3.1).

The thesis measured 100 repeated frames of the channel averages of 24 windows under uniform
stimuli at several intensities, and found the variance roughly proportional to the mean (photon
shot noise) plus an intensity-independent part. :func:`fit_noise_model` recovers ``a`` and the
floor from such repeated measurements; :func:`synthetic_repeats` generates them.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float


class NoiseModel(eqx.Module):
    """Per-channel ``variance = gain * mean + floor`` (units of the measurements).

    Attributes:
        gain: ``(C,)`` shot-noise coefficient ``a``.
        floor: ``(C,)`` intensity-independent variance.
        mean, variance: ``(N, C)`` the per-stimulus sample means and variances that were fitted.
    """

    gain: Float[Array, " C"]
    floor: Float[Array, " C"]
    mean: Float[Array, "N C"]
    variance: Float[Array, "N C"]

    def predict(self, mean: Float[Array, "... C"]) -> Float[Array, "... C"]:
        """Modelled variance at the given mean responses.

        Arguments:
            mean: mean responses, the channels last.

        Returns:
            The variance, the shape of ``mean``.
        """
        return self.gain * jnp.asarray(mean) + self.floor


def _fit_line(mean: np.ndarray, variance: np.ndarray, iterations: int = 4) -> np.ndarray:
    """Non-negative weighted least squares of ``variance ~ a mean + b`` for one channel (NumPy).

    A sample variance of R draws has standard deviation ``sqrt(2 / (R - 1))`` times its expectation,
    so rows are weighted by ``1 / model variance`` (the common factor drops out), iterated from unit
    weights.
    """
    design = np.stack([mean, np.ones_like(mean)], axis=1)

    def solve(weight):
        A = design * weight[:, None]
        y = variance * weight
        full = np.linalg.lstsq(A, y, rcond=None)[0]
        # The non-negative optimum lies on a face when the free one does not: try both single
        # coefficients and keep the best feasible candidate.
        only_a = np.array([max(A[:, 0] @ y / max(A[:, 0] @ A[:, 0], 1e-300), 0.0), 0.0])
        only_b = np.array([0.0, max(A[:, 1] @ y / max(A[:, 1] @ A[:, 1], 1e-300), 0.0)])
        candidates = [c for c in (full, only_a, only_b) if np.all(c >= 0)]
        return min(candidates, key=lambda c: float(np.sum((A @ c - y) ** 2)))

    coef = solve(np.ones_like(mean))
    for _ in range(iterations):
        model = np.maximum(design @ coef, 1e-3 * variance.max() + 1e-300)
        coef = solve(1.0 / model)
    return coef


def fit_noise_model(samples: Float[ArrayLike, "R N *C"]) -> NoiseModel:
    """Fit ``variance = a * mean + floor`` from repeated measurements (§3.4, Fig. 3.1).

    Arguments:
        samples: ``(R, N)`` or ``(R, N, C)``: R repeats of N stimuli (intensity levels / windows)
            for C channels; linear responses (the thesis linearised them first).

    Returns:
        A :class:`NoiseModel` with non-negative ``gain`` and ``floor`` per channel.
    """
    samples = np.asarray(samples, dtype=np.float64)
    if samples.ndim == 2:
        samples = samples[:, :, None]
    if samples.ndim != 3 or samples.shape[0] < 3 or samples.shape[1] < 2:
        raise ValueError(f"samples: expected (repeats >= 3, stimuli >= 2[, channels]), got shape {samples.shape}")
    if not np.all(np.isfinite(samples)):
        raise ValueError("samples: contains NaN or infinite values")
    mean = samples.mean(axis=0)
    variance = samples.var(axis=0, ddof=1)
    coef = np.stack([_fit_line(mean[:, k], variance[:, k]) for k in range(samples.shape[2])])
    dtype = jnp.zeros(0).dtype
    return NoiseModel(
        gain=jnp.asarray(coef[:, 0], dtype),
        floor=jnp.asarray(coef[:, 1], dtype),
        mean=jnp.asarray(mean, dtype),
        variance=jnp.asarray(variance, dtype),
    )


def synthetic_repeats(
    levels: Float[np.ndarray, " N"],
    *,
    repeats: int = 100,
    gain: float,
    floor: float,
    seed: int = 0,
) -> np.ndarray:
    """Repeated noisy measurements of stimuli at ``levels`` (``(repeats, N)``), Gaussian with
    variance ``gain * level + floor`` — the thesis' Fig. 3.1 experiment for a known model.

    Arguments:
        levels: ``(N,)`` noise-free stimulus levels.
        repeats: measurements per level.
        gain: the variance's gain (per unit level).
        floor: the variance's floor.
        seed: NumPy seed.

    Returns:
        ``(repeats, N)`` noisy measurements.
    """
    levels = np.asarray(levels, dtype=np.float64)
    if levels.ndim != 1 or np.any(levels < 0) or not np.all(np.isfinite(levels)):
        raise ValueError("levels: expected a 1-D array of finite values >= 0")
    rng = np.random.default_rng(seed)
    return levels[None, :] + rng.standard_normal((repeats, levels.size)) * np.sqrt(gain * levels + floor)[None, :]
