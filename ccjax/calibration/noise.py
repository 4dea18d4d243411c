"""The camera noise model of chapter 3: variance = a * mean + floor (Barnard 1999 §3.4, Fig. 3.1).

The thesis measured 100 repeated frames of the channel averages of 24 windows under uniform
stimuli at several intensities, and found the variance roughly proportional to the mean (photon
shot noise) plus an intensity-independent part. :func:`fit_noise_model` recovers ``a`` and the
floor from such repeated measurements; :func:`synthetic_repeats` generates them.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float


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
        """Modelled variance at the given mean responses."""
        return self.gain * jnp.asarray(mean) + self.floor


def _fit_line(mean, variance, repeats, iterations: int = 4):
    """Non-negative weighted least squares of ``variance ~ a mean + b`` for one channel.

    A sample variance of R draws has standard deviation ``sqrt(2 / (R - 1))`` times its expectation,
    so rows are weighted by ``1 / model variance``, iterated from unit weights.
    """
    design = jnp.stack([mean, jnp.ones_like(mean)], axis=1)

    def solve(weight):
        A = design * weight[:, None]
        y = variance * weight
        full = jnp.linalg.lstsq(A, y)[0]
        # The non-negative optimum lies on a face when the free one does not: try both single
        # coefficients and keep the best feasible candidate.
        only_a = jnp.array([jnp.maximum(A[:, 0] @ y / jnp.maximum(A[:, 0] @ A[:, 0], 1e-30), 0.0), 0.0])
        only_b = jnp.array([0.0, jnp.maximum(A[:, 1] @ y / jnp.maximum(A[:, 1] @ A[:, 1], 1e-30), 0.0)])
        candidates = jnp.stack([full, only_a, only_b])
        feasible = jnp.all(candidates >= 0, axis=1)
        cost = jnp.where(feasible, jnp.sum((candidates @ A.T - y) ** 2, axis=1), jnp.inf)
        return candidates[jnp.argmin(cost)]

    coef = solve(jnp.ones_like(mean))
    for _ in range(iterations):
        model = jnp.maximum(design @ coef, 1e-3 * jnp.max(variance) + 1e-30)
        coef = solve(1.0 / model)
    del repeats  # equal repeat counts: the factor sqrt(2 / (R - 1)) is common to every row
    return coef


def fit_noise_model(samples: Float[np.ndarray, "R N C"]) -> NoiseModel:
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
    dtype = jnp.zeros(0).dtype
    mean = jnp.asarray(samples.mean(axis=0), dtype)
    variance = jnp.asarray(samples.var(axis=0, ddof=1), dtype)
    coef = jax.vmap(lambda m, v: _fit_line(m, v, samples.shape[0]), in_axes=(1, 1))(mean, variance)
    return NoiseModel(gain=coef[:, 0], floor=coef[:, 1], mean=mean, variance=variance)


def synthetic_repeats(
    levels: Float[np.ndarray, " N"],
    *,
    repeats: int = 100,
    gain: float,
    floor: float,
    seed: int = 0,
) -> np.ndarray:
    """Repeated noisy measurements of stimuli at ``levels`` (``(repeats, N)``), Gaussian with
    variance ``gain * level + floor`` — the thesis' Fig. 3.1 experiment for a known model."""
    levels = np.asarray(levels, dtype=np.float64)
    if levels.ndim != 1 or np.any(levels < 0) or not np.all(np.isfinite(levels)):
        raise ValueError("levels: expected a 1-D array of finite values >= 0")
    rng = np.random.default_rng(seed)
    return levels[None, :] + rng.standard_normal((repeats, levels.size)) * np.sqrt(gain * levels + floor)[None, :]
