"""Choosing FFCC's hyperparameters inside the training images (Barron & Tsai 2017, §5: the paper's
weights were tuned per dataset by cross-validation; here the choice is nested, so the images a
model is scored on never inform it).

The candidates are the settings the reference code (google/ffcc) tuned for the NUS-8 thumbnails
of two cameras (``ChengCanon600DThumbHyperparams``, ``ChengCanon1DsMkIIIThumbHyperparams``): the
first regularises strongly and barely uses the convex pass, the second regularises less, gives
the cross-entropy pass weight and widens the von Mises fit. :func:`choose` trains each on one
half of the training images, scores it on the other half and the other way round, and keeps the
one with the lower mean of the mean and median angular errors.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ccjax.estimators.base import estimate_batch
from ccjax.estimators.ffcc._fitting import Hyperparameters, train
from ccjax.estimators.ffcc._model import FFCC
from ccjax.metrics import angular_error

__all__ = ["CANDIDATES", "MIN_IMAGES", "choose"]

MIN_IMAGES = 8
"""Fewer training images than this: the first candidate, unscored (halves that small say nothing)."""

CANDIDATES = (
    Hyperparameters(),
    Hyperparameters(
        crossent=2**-5.25,
        vonmises=2**2.5,
        filter_tv=(2**-23.5, 2**-22.5),
        filter_l2=(2**-40.25, 2**-38.0),
        bias_tv=2**-16.0,
        bias_l2=2**-37.75,
        diagonal=2**0.5,
    ),
)
"""The reference code's settings for the Canon 600D and the Canon 1Ds Mark III thumbnails of NUS-8."""


def choose(
    model: FFCC,
    images: Float[Array | np.ndarray, "N H W 3"],
    masks: Bool[Array | np.ndarray, "N H W"],
    illuminants: Float[Array | np.ndarray, "N 3"],
    candidates: tuple[Hyperparameters, ...] = CANDIDATES,
    seed: int = 0,
) -> tuple[Hyperparameters, list[float]]:
    """The candidate with the lowest two-fold error within the given (training) images.

    Arguments:
        model: the start (as :func:`ccjax.estimators.ffcc.train`).
        images, masks, illuminants: the training images, as :func:`ccjax.estimators.ffcc.train`.
        candidates: the settings to choose from.
        seed: seed of the split into two halves.

    Returns:
        ``(the chosen settings, each candidate's score)``; the score is the mean of the mean and
        the median angular error (degrees) over both held-out halves. With fewer than
        :data:`MIN_IMAGES` images, the first candidate and no score.

    Raises:
        ValueError: no candidate.
    """
    if not candidates:
        raise ValueError("candidates: expected at least one setting")
    count = len(illuminants)
    if count < MIN_IMAGES:
        return candidates[0], []
    images, masks, illuminants = np.asarray(images), np.asarray(masks), np.asarray(illuminants)
    half = np.random.default_rng(seed).permutation(count) < count // 2
    scores = []
    for settings in candidates:
        errors = []
        for fit_on in (half, ~half):
            trained, _ = train(model, images[fit_on], masks[fit_on], illuminants[fit_on], settings)
            held = ~fit_on
            estimate = estimate_batch(trained, jnp.asarray(images[held]), jnp.asarray(masks[held]))
            errors.append(np.asarray(angular_error(estimate.illuminant, jnp.asarray(illuminants[held]))))
        pooled = np.concatenate(errors)
        scores.append(0.5 * float(np.mean(pooled) + np.median(pooled)))
    return candidates[int(np.argmin(scores))], scores
