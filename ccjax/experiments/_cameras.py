"""Camera experiments: the camera list, the curve check, the thesis camera against SFU-321, and the
sharpness study.

The computations behind ``ccjax cameras`` (and ``--check``: do a data set's ground-truth lights
fit a camera's curves?), ``ccjax world --world barnard1999`` (the camera check)
and ``ccjax sharpen --rank-cameras``; the command line only formats what these return.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import jax
import numpy as np

from ccjax.experiments.reports import Column, Report
from ccjax.experiments.sweeps import is_registered
from ccjax.world import World

if TYPE_CHECKING:
    from ccjax.sharpening import NewSharpening

STUDY_METHODS = ("GW", "DB-GW", "RETINEX", "ECRULE-ICA", "ECRULE-MV")
"""Estimators compared with and without the new sharpening in :func:`sharpening_study`."""


def camera_listing(data_dir=None) -> Report:
    """Every camera ccjax can build and where its curves come from.

    Arguments:
        data_dir: external data directory (its cameras are listed by name when it is found, as
            needing it otherwise).

    Returns:
        A :class:`Report` with rows ``{"camera", "source"}``.
    """
    from ccjax.camera import cameras

    listing = cameras(data_dir)
    rows = [{"camera": name, "source": source} for name, source in listing.items()]
    if "Sony DXC-930" not in listing:
        # Named all the same: a reader of the listing learns they exist and what they need.
        missing = "needs the external data, not found (--data-dir or $CCJAX_DATA)"
        rows.append({"camera": "Sony DXC-930", "source": f"external (sfu_barnard): {missing}"})
        rows.append({"camera": "Jiang: <model>", "source": f"external (Jiang et al. 2013): {missing}"})
    return Report(rows, [Column("camera"), Column("source", gap=2)])


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


def _world_whites(world: World) -> np.ndarray:
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
    whites = rg_numpy(np.asarray(_world_whites(world), np.float64))
    points = rg_numpy(np.asarray(truth, np.float64))
    # (N, I) distances: N images by a few hundred whites at most.
    distances = np.sqrt(((points[:, None, :] - whites[None, :, :]) ** 2).sum(axis=-1)).min(axis=1)
    return CurveCheck(world.camera.name, float(np.median(distances)), float(threshold), distances)


def plot_curve_check(check: CurveCheck, world: World, truth, path) -> None:
    """The ground truth and the camera's whites (training and test lights) in (r,g), with the verdict.

    Arguments:
        check: the :func:`curve_check` result.
        world: the world it was computed with.
        truth: ``(N, 3)`` the ground truth it was computed from.
        path: the PNG to write (a file name or a binary file object).

    Returns:
        None.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ccjax._colour import rg_numpy
    from ccjax.io.files import write_figure

    whites = rg_numpy(np.asarray(_world_whites(world), np.float64))
    points = rg_numpy(np.asarray(truth, np.float64))
    fig, ax = plt.subplots(figsize=(6, 5))
    ax.scatter(whites[:, 0], whites[:, 1], s=14, marker="s", label=f"{check.camera}: whites of the world's lights")
    ax.scatter(points[:, 0], points[:, 1], s=6, alpha=0.6, c="red", label="ground truth")
    ax.set_xlabel("r")
    ax.set_ylabel("g")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    verdict = "passes" if check.passed else "fails"
    ax.set_title(f"median distance {check.distance:.4f} (threshold {check.threshold:.3f}): {verdict}", fontsize=9)
    fig.tight_layout()
    write_figure(fig, path, dpi=110)  # atomic for paths; file objects pass through (PNG)
    plt.close(fig)


def sfu321_check(world: World, data_dir=None) -> Report:
    """The camera of ``world`` against the SFU-321 ground truth (Barnard 1999 §4.4).

    For each of the 11 lab lights: the angle between the camera's response to a perfect white
    under that light and the mean ground-truth RGB of the images taken under it.

    Arguments:
        world: a world with the Sony DXC-930 camera (:meth:`World.barnard1999`).
        data_dir: external data directory.

    Returns:
        A :class:`Report` with rows ``{"light", "angular", "images"}`` (degrees).
    """
    from ccjax import data
    from ccjax.metrics import angular_error

    truth = data.sfu321_groundtruth(data_dir)
    lights = data.sfu_illuminants(data_dir)
    rows = []
    for code, name in data.SFU_LAB_LIGHTS.items():
        images = [i for i, label in enumerate(truth.labels) if label == code]
        mean_truth = truth.rgb[images].mean(axis=0)
        white = np.asarray(world.camera.response(lights.values[lights.names.index(name)]))
        rows.append({"light": code, "angular": float(angular_error(white, mean_truth)), "images": len(images)})
    columns = [Column("light"), Column("angular", spec=".2f", align=">", gap=2), Column("images", align=">", gap=2)]
    return Report(rows, columns)


@dataclass
class SharpeningStudy:
    """Cameras ranked by sharpness and the new sharpening of the least sharp one.

    Attributes:
        ranking: ``[{"camera", "source", "ratio", "best_linear", "best_diagonal"}]``, least sharp first.
        camera: the least sharp camera.
        sharpening: its :class:`ccjax.sharpening.NewSharpening` result.
        n_scenes: test scenes per comparison.
        comparisons: one row per estimator: ``{"method", "none", "new"}`` with the
            ``ccjax.experiments.chapter5.evaluate_transforms`` results (``None`` for estimators not registered yet).
    """

    ranking: list[dict]
    camera: str
    sharpening: NewSharpening
    n_scenes: int
    comparisons: list[dict]


def sharpening_study(
    data_dir=None,
    *,
    seed: int = 0,
    lambda_p: float | None = None,
    n_scenes: int = 1000,
    methods: Sequence[str] = STUDY_METHODS,
) -> SharpeningStudy:
    """Rank every available camera by sharpness (Barnard 1999 §5.7), sharpen the least sharp one
    with the new method (§5.6) and compare estimators with and without it.

    Arguments:
        data_dir: external data directory (more cameras when it is found).
        seed: seed of the default world's illuminant sets and of the test scenes.
        lambda_p: positivity weight of the new method (default: its own search).
        n_scenes: test scenes of 8 surfaces under the test lights.
        methods: estimators compared.

    Returns:
        A :class:`SharpeningStudy`.
    """
    from ccjax import sharpening
    from ccjax.camera import Camera
    from ccjax.experiments import chapter5, chapter5_report

    ranking = chapter5_report.rank_cameras(data_dir)
    least = ranking[0]["camera"]
    world = World.default(Camera.from_name(least, data_dir), seed=seed)
    new = sharpening.new_sharpening(world, lambda_p=lambda_p)
    transforms = {"none": np.eye(3), "new": new.transform}
    comparisons = []
    for label in methods:
        if not is_registered(label):
            comparisons.append({"method": label, "none": None, "new": None})
            continue
        out = chapter5.evaluate_transforms(world, label, transforms, n_scenes, key=jax.random.key(seed))
        comparisons.append({"method": label, "none": out["none"], "new": out["new"]})
    return SharpeningStudy(ranking, least, new, n_scenes, comparisons)
