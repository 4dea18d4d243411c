"""The any-camera estimator's second opinion: shades of grey as a Gaussian observation of the
light's log-chroma, combined with FFCC's posterior by the product of the two Gaussians.

FFCC's filters learn the training cameras' scenes; on a camera whose scenes are unlike them (Cube+
against the NUS-8 pool: indoor lights pulled towards daylight) its posterior is confident and
wrong, where a statistic of the image's own pixels is not fooled. Shades of grey (Finlayson &
Trezzi 2004, ``p = 6``) of the image mapped into the reference space is read as an observation
``o = u + b + e``, ``e ~ N(0, S)``, of the light's log-chroma ``u``; ``b`` and ``S`` are the mean
and covariance of its residual over the training entries (in the reference space, so no camera's
own labels are needed at inference). With FFCC's posterior ``N(m, k C)`` the light's log-chroma is
the mean of their product (Bishop 2006, §2.3.3):

    u = (P + Q)^-1 (P m + Q (o - b)),   P = (k C)^-1,  Q = S^-1.

``Q = 0`` gives FFCC's mean unchanged. ``k`` scales FFCC's covariance; 0.5 was chosen among
0.25, 0.5, 0.75 and 1 on four leave-one-camera-out folds of the development photo sets (Cube+, NUS
1Ds Mark III, 600D, Fuji) and confirmed on two others (NUS Panasonic, Sony): the only setting
chosen on scored folds (docs/camera-without-labels.md).
"""

from __future__ import annotations

import typing

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ccjax.estimators.neural import log_chroma
from ccjax.estimators.simple import ShadesOfGrey
from ccjax.precision import matmul

__all__ = ["GreyObservation", "fit_grey_observation", "no_grey_observation"]

# Shades of grey's norm: Finlayson & Trezzi's best on their sets and the field's usual baseline.
NORM = 6
# FFCC's covariance is multiplied by this before the product (module docstring).
POSTERIOR_SCALE = 0.5
_CHUNK = 512


@typing.final
class GreyObservation(eqx.Module):
    """Shades of grey's estimate read as a Gaussian observation of the light's log-chroma
    (module docstring).

    Attributes:
        bias: ``(2,)`` the mean residual ``o - u`` over the training entries, log-chroma units.
        precision: ``(2, 2)`` the inverse of the residual's covariance (zeros: no observation, the
            estimate is FFCC's alone).
        posterior_scale: ``k``, the factor on FFCC's covariance (static).
        norm: shades of grey's ``p`` (static).
    """

    bias: Float[Array, "2"]
    precision: Float[Array, "2 2"]
    posterior_scale: float = eqx.field(static=True, default=POSTERIOR_SCALE)
    norm: int = eqx.field(static=True, default=NORM)

    def observe(
        self, image: Float[Array, "H W 3"], mask: Bool[Array, "H W"]
    ) -> tuple[Float[Array, "2"], Bool[Array, ""]]:
        """Shades of grey's log-chroma of the usable pixels, less the training bias.

        Arguments:
            image: ``(H, W, 3)`` linear RGB in the reference space.
            mask: ``(H, W)`` usable pixels.

        Returns:
            ``(o - b, ok)``: the observation, and whether every channel of the estimate is positive.
        """
        estimator = ShadesOfGrey(p=float(self.norm), fallback=jnp.ones(3, image.dtype))
        estimate = estimator(image.reshape(-1, 3), mask.reshape(-1))
        ok = estimate.ok & jnp.all(estimate.illuminant > 0)
        return log_chroma(estimate.illuminant[None])[0] - self.bias, ok

    def combine(
        self, mean: Float[Array, "2"], covariance: Float[Array, "2 2"], observed: Float[Array, "2"], ok: Bool[Array, ""]
    ) -> Float[Array, "2"]:
        """The mean of the product of FFCC's posterior and the observation (module docstring).

        Arguments:
            mean: ``(2,)`` FFCC's posterior mean.
            covariance: ``(2, 2)`` its covariance (positive definite: FFCC adds a floor).
            observed: ``(2,)`` the observation less its bias (:meth:`observe`).
            ok: False: the observation is left out (FFCC's mean returned).

        Returns:
            ``(2,)`` the combined log-chroma.
        """
        observation = jnp.where(ok, self.precision, 0.0)
        posterior = jnp.linalg.inv(self.posterior_scale * covariance)
        weighted = matmul(posterior, mean[:, None]) + matmul(observation, observed[:, None])
        return jnp.linalg.solve(posterior + observation, weighted)[:, 0]


def no_grey_observation(dtype=jnp.float32) -> GreyObservation:
    """An observation that changes nothing (zero precision): FFCC alone.

    Arguments:
        dtype: the leaves' dtype.

    Returns:
        The :class:`GreyObservation`.
    """
    return GreyObservation(bias=jnp.zeros(2, dtype), precision=jnp.zeros((2, 2), dtype))


@eqx.filter_jit
def _residuals(observation: GreyObservation, images, masks, lights):
    observed, ok = jax.vmap(observation.observe)(images, masks)
    return observed - log_chroma(lights), ok


def fit_grey_observation(
    images: Float[np.ndarray, "N H W 3"],
    masks: Bool[np.ndarray, "N H W"],
    lights: Float[np.ndarray, "N 3"],
    posterior_scale: float = POSTERIOR_SCALE,
) -> GreyObservation:
    """The observation's bias and precision from the training entries' residuals (module docstring).

    Arguments:
        images: ``(N, H, W, 3)`` the training entries in the reference space.
        masks: ``(N, H, W)`` their usable pixels.
        lights: ``(N, 3)`` their lights in the reference space (every channel positive).
        posterior_scale: ``k``, the factor on FFCC's covariance.

    Returns:
        The fitted :class:`GreyObservation` (zero precision when fewer than 3 entries have an
        estimate: no covariance to invert).
    """
    plain = no_grey_observation()
    parts = [
        _residuals(plain, *(jnp.asarray(a[start : start + _CHUNK]) for a in (images, masks, lights)))
        for start in range(0, len(images), _CHUNK)
    ]
    residual = np.concatenate([np.asarray(part[0], np.float64) for part in parts])
    ok = np.concatenate([np.asarray(part[1]) for part in parts])
    residual = residual[ok]
    if len(residual) < 3:
        return GreyObservation(bias=plain.bias, precision=plain.precision, posterior_scale=posterior_scale)
    covariance = np.cov(residual.T)
    return GreyObservation(
        bias=jnp.asarray(residual.mean(axis=0), jnp.float32),
        precision=jnp.asarray(np.linalg.inv(covariance), jnp.float32),
        posterior_scale=posterior_scale,
    )
