"""The ground truth of a set of photographs against a camera's curves: do its lights lie where the
camera sees plausible lights? (``ccjax cameras --check``; run by photo evaluation whenever a
world-based method needs the camera's curves.)"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ccjax.world import World

__all__ = ["CURVE_THRESHOLD", "CurveCheck", "curve_check", "world_whites"]

CURVE_THRESHOLD = 0.008
"""Median (r,g) distance above which :func:`curve_check` says the ground truth was not taken
with the camera's curves.

Calibrated on the 52 embedded cameras (rawtoaces-data): truths rendered by each camera's own
curves, checked against every camera's whites under its default world's lights (training and
test sets of ``World.default(camera)``, seed 0). Truths of independent lights: the test set of
the seed-7 world (other random mixtures) and 100 daylight and blackbody lights at random
temperatures (4000-12000 K, 2500-7000 K). The same camera gives a median of at most 0.0032 and
0.0040 over all lights, and at most 0.0053 and 0.0060 over any of 50 random 20-image subsets
per camera; Nikon D5100 truths against the D5300's whites 0.0167 (mixtures; 0.0057 for the
daylight family, whose locus the two cameras nearly share), D5300 against D5100 0.0173 and
0.0363. 0.008 lies above every same-camera case and flags 37-38 % of the 2,652 pairs of
different cameras (those below it have curves close to the right ones). The median of a small
set varies: the D5100-against-D5300 median of 20 mixture lights ranged 0.0056-0.03 over random
subsets, so a set of a few dozen images can pass with a wrong camera; a failed check is the
strong statement."""


@dataclass(frozen=True)
class CurveCheck:
    """Ground-truth lights against a camera's whites (:func:`curve_check`).

    Attributes:
        camera: the camera's name.
        distance: median over images of the (r,g) distance from each ground truth to the
            nearest white of the camera under the world's lights (training and test sets).
        threshold: the distance above which the check fails (:data:`CURVE_THRESHOLD`).
        distances: ``(N,)`` each image's distance.
    """

    camera: str
    distance: float
    threshold: float
    distances: np.ndarray

    @property
    def passed(self) -> bool:
        """Whether the ground truth is consistent with the camera's curves."""
        return self.distance <= self.threshold

    def message(self) -> str:
        """One line: the measured distance, the threshold and the verdict."""
        verdict = (
            "consistent with its curves"
            if self.passed
            else "probably not taken with these curves (another model's?): world-based methods will be badly off"
        )
        return (
            f"camera check: ground truth of {len(self.distances)} images lies a median (r,g) distance "
            f"{self.distance:.4f} from the nearest white of {self.camera} (threshold {self.threshold:.3f}): {verdict}"
        )


def world_whites(world: World) -> np.ndarray:
    """``(I + J, 3)`` the camera's whites under the world's training and test lights."""
    return np.concatenate([np.asarray(world.train_whites), np.asarray(world.test_whites)]).astype(np.float64)


def curve_check(truth, world: World, *, threshold: float = CURVE_THRESHOLD) -> CurveCheck:
    """Compare ground-truth lights with the whites a world's camera gives under the world's lights.

    A world-based method knows the lights only as its camera sees them; when the images were taken
    with another camera (curves of a proxy model), the true lights' chromaticities lie off the set
    of whites it can answer with. The statistic is the median over images of the (r,g) distance
    from each ground truth to the nearest white under the world's training or test lights (both:
    the test set's 0.01 cells are twice as dense as the training set's 0.02, so a light of the
    right camera is never far from one): the median, so a few odd lights (or bad ground-truth
    rows) do not fail a data set. See :data:`CURVE_THRESHOLD` for its calibration.

    Arguments:
        truth: ``(N, 3)`` ground-truth camera RGB of the lights, any scale.
        world: the world (its camera and illuminant sets), e.g. ``World.default(camera)``.
        threshold: the largest median distance that passes.

    Returns:
        A :class:`CurveCheck`.

    Raises:
        ValueError: ``truth`` is not ``(N, 3)`` with a positive sum in every row, or is empty.
    """
    from ccjax._colour import rg_numpy

    truth = np.asarray(truth, np.float64)
    if truth.ndim != 2 or truth.shape[1] != 3 or len(truth) == 0:
        raise ValueError(f"truth: expected (N, 3) camera RGB with N >= 1, got shape {truth.shape}")
    if not np.all(np.isfinite(truth)) or np.any(truth.sum(axis=1) <= 0):
        raise ValueError("truth: every row must be finite with a positive sum")
    if not threshold > 0:
        raise ValueError(f"threshold: expected a positive distance, got {threshold!r}")
    whites = rg_numpy(np.asarray(world_whites(world), np.float64))
    points = rg_numpy(np.asarray(truth, np.float64))
    # (N, I) distances: N images by a few hundred whites at most.
    distances = np.sqrt(((points[:, None, :] - whites[None, :, :]) ** 2).sum(axis=-1)).min(axis=1)
    return CurveCheck(world.camera.name, float(np.median(distances)), float(threshold), distances)
