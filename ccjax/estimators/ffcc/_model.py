"""The fitted FFCC model (Barron & Tsai, "Fast Fourier Color Constancy", CVPR 2017): the image's
two-channel log-chroma histogram convolved with learned filters in the Fourier domain, plus a
learned bias map, a softmax over the torus of illuminant chromas, and the bivariate von Mises fit
whose mean is the estimate and whose covariance is its uncertainty (:meth:`FFCC.posterior`)."""

from __future__ import annotations

import typing
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ccjax.backends import block_scenes
from ccjax.estimators.base import NO_PADDING_BRANCH, AbstractImageEstimator, Estimate, Padding
from ccjax.estimators.ffcc._histogram import MINIMUM_INTENSITY, block_means, featurize
from ccjax.estimators.ffcc._vonmises import fit_von_mises

__all__ = ["FFCC", "Posterior", "convolve", "uv_to_rgb"]

BINS = 64
"""Histogram bins per log-chroma axis (the reference code's ``NUM_BINS``)."""
BIN_SIZE = 1.0 / 32.0
"""The reference code's histogram for camera-specific models (``NUM_BINS``, ``BIN_SIZE``): 64 bins of
1/32 cover a log-chroma range of 2 (a factor e^2 between channels) on each axis."""

ORIGIN = -0.3125
"""Log-chroma of the first bin's centre when none is fitted (the reference code's ``STARTING_UV``:
the histogram's centre is the light of gains ``(2, 1, 2)``)."""


def convolve(
    histogram: Float[Array, "C n n"], filters: Float[Array, "C n n"], bias: Float[Array, "n n"]
) -> Float[Array, "n n"]:
    """``sum_c histogram_c (*) filters_c + bias`` with periodic convolution, computed as products
    in the Fourier domain (FFCC §3, eq. 7; one inverse FFT for all channels).

    Arguments:
        histogram: ``(C, n, n)`` the channels.
        filters: ``(C, n, n)`` one filter per channel.
        bias: ``(n, n)`` the bias map.

    Returns:
        ``(n, n)`` the scores.
    """
    # Real inputs: the half spectra (rfft2) hold everything, at half the cost.
    product = jnp.sum(jnp.fft.rfft2(histogram) * jnp.fft.rfft2(filters), axis=0)
    return jnp.fft.irfft2(product, s=bias.shape).astype(bias.dtype) + bias


def uv_to_rgb(uv: Float[Array, "2"]) -> Float[Array, "3"]:
    """The light of a log-chroma (FFCC §2: ``u = log(G / R)``, ``v = log(G / B)``).

    Arguments:
        uv: ``(2,)`` the log-chroma ``(u, v)``.

    Returns:
        ``(3,)`` ``(exp(-u), 1, exp(-v))`` normalised to sum 1.
    """
    rgb = jnp.stack([jnp.exp(-uv[0]), jnp.ones_like(uv[0]), jnp.exp(-uv[1])])
    return rgb / jnp.sum(rgb)


@typing.final
class Posterior(eqx.Module):
    """FFCC's answer for one image as a distribution over the light's log-chroma (FFCC §4).

    Attributes:
        mean: ``(2,)`` the estimate's ``(u, v) = (log(G / R), log(G / B))``.
        covariance: ``(2, 2)`` its covariance in log-chroma units^2: the per-image uncertainty.
        confidence: in ``(0, 1]``, ``exp(minimum entropy - entropy)`` of the fitted distribution
            (1: as concentrated as the model allows; the reference code's ``entropy_confidence``).
        ok: the image had usable pixels.
    """

    mean: Float[Array, "2"]
    covariance: Float[Array, "2 2"]
    confidence: Float[Array, ""]
    ok: Bool[Array, ""]


@typing.final
class FFCC(AbstractImageEstimator):
    """Fast Fourier Color Constancy on one image (module docstring); train it with
    ``ccjax train --method FFCC`` or ``ccjax evaluate --train FFCC`` (:mod:`ccjax.estimators.ffcc._fitting`).

    The estimate is the mean of the fitted distribution; :meth:`posterior` gives the whole
    distribution (the covariance and a confidence), the per-image uncertainty. An image without a
    usable pixel gets the bias map's answer (the learned prior) with status ``NO_DATA``.

    Attributes:
        filters: ``(2, n, n)`` the filters of the pixel and edge histograms.
        bias: ``(n, n)`` the bias map (a prior over the light's log-chroma).
        origin: ``(2,)`` log-chroma of bin ``(0, 0)``'s centre (fitted to the training lights).
        bin_size: ``()`` log-chroma width of a bin (fitted to the training lights' range).
        diagonal: variance added to the fitted covariance, in bins^2 (static).
        minimum: the smallest trusted channel value, 1.0 = saturation (static).
        pool: the image is reduced to the means of its usable pixels in ``pool x pool`` blocks
            before its histograms (:func:`ccjax.estimators.ffcc.block_means`; 1: every pixel as
            given; static). Thumbnails made by sampling rather than averaging the photograph keep
            its pixel noise, which scatters the histogram: on the NUS-8 development thumbnails
            2 lowers the mean error (docs/camera-without-labels.md).
    """

    filters: Float[Array, "2 n n"]
    bias: Float[Array, "n n"]
    origin: Float[Array, "2"]
    bin_size: Float[Array, ""]
    diagonal: float = eqx.field(static=True, default=1.0)
    minimum: float = eqx.field(static=True, default=MINIMUM_INTENSITY)
    pool: int = eqx.field(static=True, default=1)
    estimates_brightness: ClassVar[bool] = False
    world_based: ClassVar[bool] = False
    default_preprocessing: ClassVar[str] = "pixels"
    pools_pixels: ClassVar[bool] = False
    padding: ClassVar[Padding] = NO_PADDING_BRANCH

    def block_size(self, backend: str) -> int | None:
        """The backend's block (:func:`ccjax.backends.block_scenes`): one ``vmap`` over the whole
        batch streams each image's edge channel and histograms through memory (measured 1.8x
        slower than blocks of 128 on a CPU).

        Arguments:
            backend: ``"cpu"``, ``"gpu"`` or ``"tpu"``.

        Returns:
            Images per vmapped block.
        """
        return block_scenes(backend)

    @property
    def bins(self) -> int:
        """Histogram bins per axis."""
        return self.bias.shape[0]

    def histogram(self, image: Float[Array, "H W 3"], mask: Bool[Array, "H W"]) -> Float[Array, "2 n n"]:
        """The image's two-channel histogram on this model's grid
        (:func:`ccjax.estimators.ffcc._histogram.featurize`), of its block means when ``pool > 1``.

        Arguments:
            image: ``(H, W, 3)`` linear camera RGB.
            mask: ``(H, W)`` usable pixels.

        Returns:
            ``(2, n, n)``: the pixel and the edge histograms.
        """
        image, mask = block_means(image, mask, self.pool)
        return featurize(image, mask, origin=self.origin, bins=self.bins, bin_size=self.bin_size, minimum=self.minimum)

    def fit_histogram(self, histogram: Float[Array, "2 n n"]) -> tuple[Float[Array, "2"], Float[Array, "2 2"]]:
        """The von Mises fit to the softmax of the scores of ``histogram``.

        Arguments:
            histogram: ``(2, n, n)`` an image's histograms (:meth:`histogram`).

        Returns:
            ``(mean (2,), covariance (2, 2))`` in log-chroma units.
        """
        scores = convolve(histogram, self.filters, self.bias)
        probability = jax.nn.softmax(scores.reshape(-1)).reshape(scores.shape)
        mean, covariance = fit_von_mises(probability, self.diagonal)
        return self.origin + self.bin_size * mean, covariance * self.bin_size**2

    def posterior(self, image: Float[Array, "H W 3"], mask: Bool[Array, "H W"]) -> Posterior:
        """The fitted distribution of the light's log-chroma: the estimate with its uncertainty.

        Arguments:
            image: ``(H, W, 3)`` linear RGB, 1.0 = saturation.
            mask: ``(H, W)`` usable pixels.

        Returns:
            The :class:`Posterior`.
        """
        histogram = self.histogram(image, mask)
        mean, covariance = self.fit_histogram(histogram)
        floor = self.diagonal * self.bin_size**2
        det = covariance[0, 0] * covariance[1, 1] - covariance[0, 1] ** 2
        confidence = jnp.exp(0.5 * jnp.log(floor**2) - 0.5 * jnp.log(det))
        return Posterior(mean, covariance, confidence, jnp.sum(histogram[0]) > 0)

    def __call__(self, image: Float[Array, "H W 3"], mask: Bool[Array, "H W"]) -> Estimate:
        posterior = self.posterior(image, mask)
        return Estimate(illuminant=uv_to_rgb(posterior.mean), ok=posterior.ok)
