"""The ground truth of a set of photographs against a camera's curves: do its lights lie along the
camera's Planckian/daylight locus, where photographs' lights lie? (``ccjax cameras --check``; run by
photo evaluation whenever a world-based method needs the camera's curves.)"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from jaxtyping import Float

from ccjax._colour import rg_numpy
from ccjax.camera import Camera
from ccjax.spectra import blackbody, cie_daylight
from ccjax.world import World

__all__ = [
    "CURVE_QUANTILE",
    "CURVE_THRESHOLD",
    "LOCUS_BLACKBODY_KELVIN",
    "LOCUS_DAYLIGHT_KELVIN",
    "LOCUS_MIRED_STEP",
    "CurveCheck",
    "curve_check",
    "locus_distance",
    "locus_whites",
    "polyline_distance",
]

CURVE_QUANTILE = 0.25
"""Share of the images whose distance to the locus :func:`curve_check` reads: the lower quartile
(:data:`CURVE_THRESHOLD` says why)."""

CURVE_THRESHOLD = 0.008
"""Lower-quartile (r,g) distance from the camera's locus above which :func:`curve_check` says
the ground truth was not taken with the camera's curves.

The statistic: the distance of each ground truth to the camera's Planckian/daylight locus
(:func:`locus_whites`), and over the images its lower quartile (:data:`CURVE_QUANTILE`). Real
scenes' lights lie on both sides of the locus (fluorescents, LEDs, mixed light), but a data set
always holds many near it (daylight, shade, tungsten, flash), and another camera moves the whole
locus away from them; the lower quartile asks that a quarter of the images be near the locus, so
a data set with many off-locus lights still passes with its own camera.

Calibrated on the 52 embedded cameras (rawtoaces-data) with ``benchmarks/camera_check.py``:
truths rendered by each camera's own curves, checked against every camera's locus. Truths: the
default world's lights (training and test sets of ``World.default(camera)``, seed 0: daylight,
blackbody, CIE and LED lamps, fluorescents and random mixtures filling (r,g) cells; 15-29 % of
them lie within 0.001 of the locus), the test set of the seed-7 world (other random mixtures) and
100 daylight and blackbody lights at random temperatures (4000-12000 K, 2500-7000 K). The same
camera gives a lower quartile of at most 0.0063, 0.0073 and 0.0000 (the test sets of seeds 1, 2,
3 and 11: at most 0.0072); 0.008 lies above every same-camera case (0 failures) and flags 66.3 %,
65.0 % and 69.9 % of the 2,652 ordered pairs of different cameras. The check before this one
(the median distance to the nearest white of the world's lights, same threshold) flagged 37.8 %,
37.1 % and 36.7 %: a wrong camera's truths fell inside the cloud of mixtures. The pairs left are
cameras with nearly the same locus (many Canons among themselves).

Photographs (ground truth of the development sets) against their camera's locus: NUS-8 Canon
EOS 600D 0.0023, Canon EOS-1Ds Mark III 0.0011, Cube+ (Canon 550D) against the 600D's 0.0058, and
no random 20-image subset of them fails (1000 draws each, largest 0.0078); the NUS 600D's against
the Nikon D5300's 0.0107, Cube+'s 0.0134. Limits: a set whose lights are mostly off the locus can
fail with the right camera (random 20-image subsets of the world's lights fail in 21 % of draws,
50-image subsets in 11 %), and a set can pass with a camera whose locus nearly coincides with the
right one's: a failed check on a set with daylight or tungsten images is the strong statement."""

LOCUS_BLACKBODY_KELVIN = (1500.0, 20000.0)
"""Colour temperatures of the locus' blackbodies (candle flame to blue sky)."""

LOCUS_DAYLIGHT_KELVIN = (4000.0, 25000.0)
"""Correlated colour temperatures of the locus' CIE daylights (the D series' range)."""

LOCUS_MIRED_STEP = 5.0
"""Spacing of the locus' samples in mired (10^6 / K): uniform in mired, where equal steps are
roughly equal changes of chromaticity; the chords of 5-mired steps lie within 3e-5 (r,g) of the curves
(the 52 embedded cameras)."""


@dataclass(frozen=True)
class CurveCheck:
    """Ground-truth lights against a camera's Planckian/daylight locus (:func:`curve_check`).

    Attributes:
        camera: the camera's name.
        distance: the ``quantile`` over images of the (r,g) distance from each ground truth to
            the camera's locus (:func:`locus_whites`).
        threshold: the distance above which the check fails (:data:`CURVE_THRESHOLD`).
        distances: ``(N,)`` each image's distance.
        quantile: the share of images ``distance`` reads (:data:`CURVE_QUANTILE`).
    """

    camera: str
    distance: float
    threshold: float
    distances: np.ndarray
    quantile: float = CURVE_QUANTILE

    @property
    def passed(self) -> bool:
        """Whether the ground truth is consistent with the camera's curves."""
        return self.distance <= self.threshold

    def message(self) -> str:
        """The check in one line.

        Returns:
            The measured distance, the threshold and the verdict.
        """
        verdict = (
            "consistent with its curves"
            if self.passed
            else "probably not taken with these curves (another model's?): world-based methods will be badly off"
        )
        share = "lower-quartile" if self.quantile == 0.25 else f"{100 * self.quantile:g} % quantile"
        return (
            f"camera check: ground truth of {len(self.distances)} images lies a {share} (r,g) distance "
            f"{self.distance:.4f} from the Planckian/daylight locus of {self.camera} "
            f"(threshold {self.threshold:.3f}): {verdict}"
        )


def _mired_samples(low: float, high: float) -> np.ndarray:
    """Temperatures from ``high`` down to ``low`` K, uniform in mired at most
    :data:`LOCUS_MIRED_STEP` apart (ends included)."""
    count = int(np.ceil((1e6 / low - 1e6 / high) / LOCUS_MIRED_STEP)) + 1
    return 1e6 / np.linspace(1e6 / high, 1e6 / low, count)


@functools.cache
def _locus_lights() -> tuple[np.ndarray, np.ndarray]:
    """The locus' blackbody and daylight spectra (read-only; computed once: colour-science is slow)."""
    lights = (blackbody(_mired_samples(*LOCUS_BLACKBODY_KELVIN)), cie_daylight(_mired_samples(*LOCUS_DAYLIGHT_KELVIN)))
    for spectra in lights:
        spectra.flags.writeable = False
    return lights


def locus_whites(camera: Camera) -> tuple[Float[np.ndarray, "B 3"], Float[np.ndarray, "D 3"]]:
    """A camera's Planckian and daylight locus: its responses to blackbodies and CIE daylights.

    The lights a photograph is most often taken under (CIE 015:2018 §3.1 for both families):
    blackbodies over :data:`LOCUS_BLACKBODY_KELVIN` and CIE daylights over
    :data:`LOCUS_DAYLIGHT_KELVIN`, uniform in mired (:data:`LOCUS_MIRED_STEP`), seen through the
    camera's curves.

    Arguments:
        camera: the camera.

    Returns:
        ``(blackbodies, daylights)``: ``(B, 3)`` and ``(D, 3)`` camera RGB, hottest first, any scale.
    """
    sensors = np.asarray(camera.sensors, np.float64)
    bodies, days = _locus_lights()
    return bodies @ sensors, days @ sensors


def polyline_distance(points: Float[np.ndarray, "N 2"], vertices: Float[np.ndarray, "K 2"]) -> Float[np.ndarray, " N"]:
    """Euclidean distance from each point to a polyline (the nearest point of its segments).

    Arguments:
        points: ``(N, 2)`` points.
        vertices: ``(K, 2)`` the polyline's vertices in order, ``K >= 2``.

    Returns:
        ``(N,)`` distances.

    Raises:
        ValueError: ``vertices`` is not ``(K, 2)`` with ``K >= 2``, or two neighbours coincide.
    """
    points = np.asarray(points, np.float64)
    vertices = np.asarray(vertices, np.float64)
    if vertices.ndim != 2 or vertices.shape[1] != 2 or len(vertices) < 2:
        raise ValueError(f"vertices: expected (K, 2) with K >= 2, got shape {vertices.shape}")
    start, step = vertices[:-1], np.diff(vertices, axis=0)
    length2 = (step**2).sum(axis=-1)
    if np.any(length2 == 0):
        raise ValueError("vertices: two neighbouring vertices coincide (a segment of zero length)")
    # (N, K-1): the nearest point of each segment is its end or the foot of the perpendicular.
    along = np.clip(((points[:, None, :] - start[None]) * step[None]).sum(axis=-1) / length2, 0.0, 1.0)
    nearest = start[None] + along[..., None] * step[None]
    return np.sqrt(((points[:, None, :] - nearest) ** 2).sum(axis=-1)).min(axis=1)


def locus_distance(truth: Float[np.ndarray, "N 3"], camera: Camera) -> Float[np.ndarray, " N"]:
    """(r,g) distance from each ground truth to the camera's locus (:func:`locus_whites`): the
    nearer of its blackbody and daylight polylines.

    Arguments:
        truth: ``(N, 3)`` camera RGB with positive sums, any scale.
        camera: the camera.

    Returns:
        ``(N,)`` distances.
    """
    points = rg_numpy(np.asarray(truth, np.float64))
    lines = [rg_numpy(whites) for whites in locus_whites(camera)]
    return np.min([polyline_distance(points, line) for line in lines], axis=0)


def curve_check(
    truth, world: World, *, threshold: float = CURVE_THRESHOLD, quantile: float = CURVE_QUANTILE
) -> CurveCheck:
    """Compare ground-truth lights with the Planckian/daylight locus of a world's camera.

    A world-based method knows the lights only as its camera sees them; when the images were taken
    with another camera (curves of a proxy model), the lights the photographs were taken under
    (daylight, tungsten) lie off the camera's locus. The statistic is a low quantile over images
    of the (r,g) distance from each ground truth to the locus (:func:`locus_distance`): low, so
    the many lights of a data set off the locus (fluorescents, LEDs, mixtures, on either side) do
    not fail it as long as enough lie near it. See :data:`CURVE_THRESHOLD` for its calibration.

    Arguments:
        truth: ``(N, 3)`` ground-truth camera RGB of the lights, any scale.
        world: the world whose camera is checked, e.g. ``World.default(camera)`` (only its camera is used).
        threshold: the largest distance that passes.
        quantile: the share of images the statistic reads, in (0, 1] (1: the largest distance).

    Returns:
        A :class:`CurveCheck`.

    Raises:
        ValueError: ``truth`` is not ``(N, 3)`` with a positive sum in every row, or is empty;
            ``threshold`` is not positive; ``quantile`` is not in (0, 1].
    """
    truth = np.asarray(truth, np.float64)
    if truth.ndim != 2 or truth.shape[1] != 3 or len(truth) == 0:
        raise ValueError(f"truth: expected (N, 3) camera RGB with N >= 1, got shape {truth.shape}")
    if not np.all(np.isfinite(truth)) or np.any(truth.sum(axis=1) <= 0):
        raise ValueError("truth: every row must be finite with a positive sum")
    if not threshold > 0:
        raise ValueError(f"threshold: expected a positive distance, got {threshold!r}")
    if not 0 < quantile <= 1:
        raise ValueError(f"quantile: expected a share in (0, 1], got {quantile!r}")
    distances = locus_distance(truth, world.camera)
    statistic = float(np.quantile(distances, quantile))
    return CurveCheck(world.camera.name, statistic, float(threshold), distances, float(quantile))
