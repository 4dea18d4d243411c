"""Camera experiments: the camera list, the curve check, the thesis camera against SFU-321, and the
sharpness study.

The computations behind ``ccjax cameras`` (and ``--check``: do a data set's ground-truth lights
lie along the Planckian/daylight locus of a camera's curves?), ``ccjax world --world barnard1999``
(the camera check) and ``ccjax sharpen --rank-cameras``; the command line only formats what these return.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import jax
import numpy as np

from ccjax.evaluation.camera_check import CURVE_THRESHOLD as CURVE_THRESHOLD
from ccjax.evaluation.camera_check import CurveCheck, locus_whites
from ccjax.evaluation.camera_check import curve_check as curve_check
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


def plot_curve_check(check: CurveCheck, world: World, truth, path) -> None:
    """The ground truth and the camera's Planckian/daylight locus in (r,g), with the verdict.

    Arguments:
        check: the :func:`curve_check` result.
        world: the world it was computed with.
        truth: ``(N, 3)`` the ground truth it was computed from.
        path: the PNG to write (a file name or a binary file object).

    Returns:
        None.
    """
    from ccjax._colour import rg_numpy
    from ccjax.io.files import new_figure, write_figure

    bodies, days = (rg_numpy(whites) for whites in locus_whites(world.camera))
    points = rg_numpy(np.asarray(truth, np.float64))
    fig = new_figure(figsize=(6, 5))
    ax = fig.subplots()
    ax.plot(bodies[:, 0], bodies[:, 1], lw=1.5, label=f"{check.camera}: blackbodies")
    ax.plot(days[:, 0], days[:, 1], lw=1.5, ls="--", label=f"{check.camera}: CIE daylights")
    ax.scatter(points[:, 0], points[:, 1], s=6, alpha=0.6, c="red", label="ground truth")
    ax.set_xlabel("r")
    ax.set_ylabel("g")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    verdict = "passes" if check.passed else "fails"
    ax.set_title(
        f"{100 * check.quantile:g} % quantile of the distance to the locus {check.distance:.4f} "
        f"(threshold {check.threshold:.3f}): {verdict}",
        fontsize=9,
    )
    fig.tight_layout()
    write_figure(fig, path, dpi=110)  # atomic for paths; file objects pass through (PNG)


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
