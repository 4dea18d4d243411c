"""Choosing FFCC's hyperparameters inside the training images (Barron & Tsai 2017, §5: the paper's
weights were tuned per dataset by cross-validation; here the choice is nested, so the images a
model is scored on never inform it).

The candidates are the settings the reference code (google/ffcc) tuned for the NUS-8 thumbnails
of seven of its eight cameras (``Cheng<camera>ThumbHyperparams``): they span strong and weak
filter and bias regularisation and a weighted or an idle convex pass. :func:`choose` trains each
on one half of (at most :data:`CHOICE_IMAGES` of) the training images, scores it on the other half
and the other way round, and keeps the one with the lower mean of the mean and median angular
errors.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ccjax.estimators.base import estimate_batch
from ccjax.estimators.ffcc._fitting import Hyperparameters, train
from ccjax.estimators.ffcc._model import FFCC
from ccjax.metrics import angular_error

__all__ = ["CANDIDATES", "CHOICE_IMAGES", "MIN_IMAGES", "choose"]

MIN_IMAGES = 8
"""Fewer training images than this: the first candidate, unscored (halves that small say nothing)."""

CHOICE_IMAGES = 512
"""At most this many training images (a seeded random subset) inform the choice: seven candidates
fitted twice each on halves of a 1,140-image Cube+ fold would take most of the two minutes a fold
may take (with this cap a Cube+ fold trains in about 40 s and scores 1.51 / 0.85 mean / median
degrees, against 1.56 / 0.87 for the former two-setting choice on every training image)."""

CANDIDATES = (
    Hyperparameters(),  # Canon 600D
    Hyperparameters(  # Canon 1Ds Mark III
        crossent=2**-5.25,
        vonmises=2**2.5,
        filter_tv=(2**-23.5, 2**-22.5),
        filter_l2=(2**-40.25, 2**-38.0),
        bias_tv=2**-16.0,
        bias_l2=2**-37.75,
        diagonal=2**0.5,
    ),
    Hyperparameters(  # Nikon D5200
        crossent=2**-12.25,
        vonmises=2**-2.25,
        filter_tv=(2**-23.0, 2**-29.5),
        filter_l2=(2**-59.25, 2**-35.5),
        bias_tv=2**-26.0,
        bias_l2=2**-51.5,
    ),
    Hyperparameters(  # Olympus E-PL6
        crossent=2**-14.25,
        vonmises=2**-0.75,
        filter_tv=(2**-24.75, 2**-26.25),
        filter_l2=(2**-38.0, 2**-38.0),
        bias_tv=2**-20.75,
        bias_l2=2**-49.25,
    ),
    Hyperparameters(  # Panasonic GX1
        crossent=2**-3.25,
        vonmises=2**-2.25,
        filter_tv=(2**-21.75, 2**-26.5),
        filter_l2=(2**-43.5, 2**-36.0),
        bias_tv=2**-26.25,
        bias_l2=2**-46.75,
    ),
    Hyperparameters(  # Samsung NX2000
        crossent=2**-7.0,
        vonmises=2**-2.0,
        filter_tv=(2**-25.25, 2**-25.0),
        filter_l2=(2**-36.75, 2**-32.0),
        bias_tv=2**-22.5,
        bias_l2=2**-37.5,
    ),
    Hyperparameters(  # Sony A57
        crossent=2**-13.0,
        vonmises=2**-3.0,
        filter_tv=(2**-27.75, 2**-28.0),
        filter_l2=(2**-41.75, 2**-42.25),
        bias_tv=2**-23.5,
        bias_l2=2**-39.75,
    ),
)
"""The reference code's thumbnail settings for seven NUS-8 cameras, the Canon 600D's first (the
default). Its Fujifilm X-M1 setting is left out: a pixel-filter L2 weight of 2^-73.5 stretches the
preconditioner over 2^30 and float32 L-BFGS then crawls (7x the time of the others on Cube+)."""


def choose(
    model: FFCC,
    images: Float[Array | np.ndarray, "N H W 3"],
    masks: Bool[Array | np.ndarray, "N H W"],
    illuminants: Float[Array | np.ndarray, "N 3"],
    candidates: tuple[Hyperparameters, ...] = CANDIDATES,
    seed: int = 0,
    progress: bool = False,
) -> tuple[Hyperparameters, list[float]]:
    """The candidate with the lowest two-fold error within the given (training) images.

    Arguments:
        model: the start (as :func:`ccjax.estimators.ffcc.train`).
        images, masks, illuminants: the training images, as :func:`ccjax.estimators.ffcc.train`.
        candidates: the settings to choose from.
        seed: seed of the subset and of its split into two halves.
        progress: a progress bar over the candidates (each is two L-BFGS fits).

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
    rng = np.random.default_rng(seed)
    used = np.sort(rng.permutation(count)[:CHOICE_IMAGES])
    images, masks, illuminants = (np.asarray(a)[used] for a in (images, masks, illuminants))
    count = len(used)
    half = rng.permutation(count) < count // 2
    from tqdm.auto import tqdm

    scores = []
    for settings in tqdm(candidates, desc="FFCC settings", unit="candidate", disable=not progress, leave=False):
        errors = []
        for fit_on in (half, ~half):
            trained, _ = train(model, images[fit_on], masks[fit_on], illuminants[fit_on], settings)
            held = ~fit_on
            estimate = estimate_batch(trained, jnp.asarray(images[held]), jnp.asarray(masks[held]))
            errors.append(np.asarray(angular_error(estimate.illuminant, jnp.asarray(illuminants[held]))))
        pooled = np.concatenate(errors)
        scores.append(0.5 * float(np.mean(pooled) + np.median(pooled)))
    return candidates[int(np.argmin(scores))], scores
