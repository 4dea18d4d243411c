"""The bivariate von Mises fit of FFCC (Barron & Tsai 2017, §4): a distribution on the histogram's
torus from its first and second moments, giving the estimate (the mean) and its covariance (the
per-image uncertainty), and its negative log-likelihood, FFCC's training loss."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ccjax.precision import matmul

__all__ = ["fit_von_mises", "gaussian_nll"]


def fit_von_mises(
    probability: Float[Array, "n n"], diagonal: float = 1.0
) -> tuple[Float[Array, "2"], Float[Array, "2 2"]]:
    """Fit a bivariate von Mises distribution to a PMF on the ``n x n`` torus (FFCC §4, eq. 17-18).

    The mean of each axis is the circular mean of its marginal (``atan2`` of the first
    trigonometric moments); the covariance is the second moment of the bin offsets from the
    rounded mean, wrapped to the nearest copy on the torus, plus ``diagonal`` bins^2 on the
    diagonal (the reference code's ``VON_MISES_DIAGONAL_EPS``, which keeps it positive definite).

    Arguments:
        probability: ``(n, n)`` non-negative, summing to 1 (``n`` even).
        diagonal: variance added to each axis, in bins^2.

    Returns:
        ``(mean (2,), covariance (2, 2))`` in bin units, the mean in ``[0, n)``.
    """
    n = probability.shape[0]
    angles = 2 * jnp.pi * jnp.arange(n, dtype=probability.dtype) / n
    marginals = jnp.stack([jnp.sum(probability, axis=1), jnp.sum(probability, axis=0)])
    sines, cosines = matmul(marginals, jnp.sin(angles)), matmul(marginals, jnp.cos(angles))
    mean = jnp.mod(jnp.arctan2(sines, cosines), 2 * jnp.pi) * (n / (2 * jnp.pi))
    # Offsets from the nearest bin to the mean, wrapped to (-n/2, n/2]; the rounding has no
    # gradient, as in the reference code's derivatives.
    centre = jax.lax.stop_gradient(jnp.round(mean))
    bins = jnp.arange(n, dtype=probability.dtype)
    offsets = jnp.mod(bins[None, :] - centre[:, None] + n / 2 - 1, n) + 1 - n / 2
    first = jnp.sum(marginals * offsets, axis=1)
    second = jnp.sum(marginals * offsets**2, axis=1) - first**2
    cross = matmul(matmul(offsets[0], probability), offsets[1]) - first[0] * first[1]
    covariance = jnp.array([[second[0], cross], [cross, second[1]]]) + diagonal * jnp.eye(2, dtype=probability.dtype)
    return mean, covariance


def gaussian_nll(
    truth: Float[Array, "2"], mean: Float[Array, "2"], covariance: Float[Array, "2 2"]
) -> Float[Array, ""]:
    """Negative log-likelihood of ``truth`` under the normal with ``mean`` and ``covariance`` (FFCC
    §4 treats the fitted von Mises as a normal on the unwrapped plane).

    Arguments:
        truth, mean: ``(2,)`` points.
        covariance: ``(2, 2)`` positive definite.

    Returns:
        ``0.5 d^T C^-1 d + 0.5 log det(2 pi C)``.
    """
    delta = truth - mean
    det = covariance[0, 0] * covariance[1, 1] - covariance[0, 1] * covariance[1, 0]
    inverse = jnp.array([[covariance[1, 1], -covariance[0, 1]], [-covariance[1, 0], covariance[0, 0]]]) / det
    return 0.5 * matmul(matmul(delta, inverse), delta) + 0.5 * jnp.log((2 * jnp.pi) ** 2 * det)
