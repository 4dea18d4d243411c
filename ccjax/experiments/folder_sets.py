"""The field's protocol over several folders of photographs: each folder (one camera's set, e.g.
one of the eight NUS-8 cameras, Cheng, Prasad & Brown 2014) K-fold cross-validated on its own,
the learned methods trained within its folds, then the geometric mean of each statistic over
the folders, as the field reports NUS-8 (e.g. Barron & Tsai 2017, Table 1), with each method's
training seconds per fold and inference milliseconds per image.

:func:`evaluate_folder_sets` runs :func:`ccjax.experiments.folders.evaluate_folder` on every
:class:`FolderSet` (each with its own camera: the sets were taken by different cameras, and
only some of them have curves) and returns a :class:`SetsEvaluation` (its table, its JSON report,
its fold models written by :func:`save_fold_models`).
"""

from __future__ import annotations

import math
import os
import pathlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ccjax.experiments.folders import TRAINED_SUFFIX, FolderEvaluation
from ccjax.io.reading import MAX_PIXELS
from ccjax.preprocessing import DEFAULT_DARK, Preprocessing

__all__ = [
    "PROTOCOL_STATISTICS",
    "FolderSet",
    "SetResult",
    "SetsEvaluation",
    "evaluate_folder_sets",
    "fold_model_file",
    "geometric_mean",
    "geometric_means",
    "save_fold_models",
]

PROTOCOL_STATISTICS = ("mean", "median", "trimean", "best25", "worst25")
"""The statistics the field reports per set and as geometric means over a data set's cameras
(angular error, degrees)."""


@dataclass(frozen=True)
class FolderSet:
    """One folder of photographs with ground truth, and the camera that took them.

    Attributes:
        directory: the image folder.
        ground_truth: its CSV (``image,r,g,b[,fold]``).
        camera: the camera whose curves fit the folder's world-based methods; ``None``: ccjax has
            no curves for it, so world-based methods are left out of this folder.
        name: the folder's name in tables and reports (default: the directory's name).
    """

    directory: pathlib.Path
    ground_truth: pathlib.Path
    camera: str | None = None
    name: str = ""

    @property
    def label(self) -> str:
        return self.name or pathlib.Path(self.directory).name


@dataclass
class SetResult:
    """One folder's evaluation and its protocol rows.

    Attributes:
        folder: the :class:`FolderSet`.
        evaluation: its :class:`~ccjax.experiments.folders.FolderEvaluation`.
        rows: ``{method: {statistic: degrees, "ms_per_image": ..., "train_seconds": ...}}``
            (training seconds: the mean over the folds, trained methods only).
        left_out: the world-based methods not run here (the folder has no camera).
        world_camera: the camera of the world the methods were fitted to (the default world's
            when the folder has none).
    """

    folder: FolderSet
    evaluation: FolderEvaluation
    rows: dict[str, dict[str, float]]
    left_out: list[str] = field(default_factory=list)
    world_camera: str = ""

    @property
    def images(self) -> int:
        return len(self.evaluation.results.paths)


def geometric_mean(values: Sequence[float]) -> float:
    """``(prod values) ** (1 / n)``, computed as ``exp(mean(log values))`` (no overflow); 0 when a
    value is 0.

    Arguments:
        values: non-negative finite numbers (at least one).

    Returns:
        Their geometric mean.

    Raises:
        ValueError: no value, or a negative or non-finite one.
    """
    array = np.asarray(values, np.float64)
    if array.size == 0:
        raise ValueError("values: the geometric mean needs at least one value")
    if not np.all(np.isfinite(array)) or np.any(array < 0):
        raise ValueError(f"values: expected finite non-negative numbers, got {array.tolist()}")
    if np.any(array == 0):
        return 0.0
    return float(np.exp(np.mean(np.log(array))))


def geometric_means(rows: Sequence[dict[str, dict[str, float]]]) -> dict[str, dict[str, float]]:
    """The geometric mean over folders of each :data:`PROTOCOL_STATISTICS` statistic, for each
    method scored in every folder.

    Arguments:
        rows: per folder, ``{method: {statistic: value}}`` (:attr:`SetResult.rows`).

    Returns:
        ``{method: {statistic: geometric mean}}``, methods in the first folder's order.
    """
    if not rows:
        return {}
    shared = [label for label in rows[0] if all(label in folder for folder in rows)]
    return {
        label: {name: geometric_mean([folder[label][name] for folder in rows]) for name in PROTOCOL_STATISTICS}
        for label in shared
    }


def _rows(evaluation: FolderEvaluation) -> dict[str, dict[str, float]]:
    """Each method's protocol statistics, inference ms per image and training s per fold."""
    results, rows = evaluation.results, {}
    for label in results.estimates:
        summary = results.summary(label)
        row = {name: float(summary[name]) for name in PROTOCOL_STATISTICS}
        row["ms_per_image"] = 1e3 * results.seconds.get(label, math.nan) / max(1, len(results.paths))
        rows[label] = row
    for label, validation in evaluation.validations.items():
        seconds = [fold.log.seconds for fold in validation.folds]
        rows[label + TRAINED_SUFFIX]["train_seconds"] = float(np.mean(seconds))
    return rows


@dataclass
class SetsEvaluation:
    """What :func:`evaluate_folder_sets` found.

    Attributes:
        sets: one :class:`SetResult` per folder, in the order given.
        folds: the number of folds of every folder.
    """

    sets: list[SetResult]
    folds: int | None = None

    def geometric_means(self) -> dict[str, dict[str, float]]:
        """:func:`geometric_means` of the folders' rows.

        Returns:
            ``{method: {statistic: geometric mean over the folders}}``.
        """
        return geometric_means([s.rows for s in self.sets])

    def table(self) -> str:
        """One row per folder and method (statistics in degrees, training seconds per fold,
        inference ms per image), then the geometric mean over the folders of each method scored
        in every folder.

        Returns:
            The table's text.
        """
        width = max([24, *(len(label) + 2 for s in self.sets for label in s.rows)])
        title = f"geometric mean ({len(self.sets)})"
        place = max([len(title) + 2, *(len(f"{s.folder.label} ({s.images})") + 2 for s in self.sets)])
        heads = ("mean", "median", "trimean", "best 25%", "worst 25%", "train s/fold", "ms/image")
        lines = [
            "angular error (degrees) per folder, then the geometric mean over the folders",
            f"{'folder (images)':<{place}}{'method':<{width}}" + "".join(f"{head:>13}" for head in heads),
        ]

        def cells(row: dict) -> str:
            text = "".join(f"{row[name]:>13.3f}" for name in PROTOCOL_STATISTICS)
            train, speed = row.get("train_seconds"), row.get("ms_per_image")
            text += f"{train:>13.1f}" if train is not None else f"{'':>13}"
            return text + (f"{speed:>13.3f}" if speed is not None and math.isfinite(speed) else f"{'':>13}")

        for result in self.sets:
            where = f"{result.folder.label} ({result.images})"
            lines += [f"{where:<{place}}{label:<{width}}{cells(row)}" for label, row in result.rows.items()]
        lines += [f"{title:<{place}}{label:<{width}}{cells(row)}" for label, row in self.geometric_means().items()]
        for result in self.sets:
            if result.left_out:
                lines.append(
                    f"{result.folder.label}: no camera given, world-based {', '.join(result.left_out)} left out"
                )
        return "\n".join(lines)

    def save_models(
        self, directory: str | os.PathLike, *, seed: int = 0, overwrite: bool = False
    ) -> list[pathlib.Path]:
        """Write every folder's fold models under ``directory/<folder name>/`` (:func:`save_fold_models`).

        Arguments:
            directory: the folder to write into.
            seed: the worlds' seed (as given to :func:`evaluate_folder_sets`).
            overwrite: replace existing files (else ``FileExistsError``).

        Returns:
            The model files written.
        """
        return [
            path
            for s in self.sets
            for path in save_fold_models(
                s.evaluation,
                pathlib.Path(directory) / s.folder.label,
                s.world_camera,
                world_seed=seed,
                overwrite=overwrite,
            )
        ]

    def report(self) -> dict:
        """The JSON report: per folder its camera, images and rows, and its full evaluation
        report (:meth:`FolderEvaluation.report`); the geometric means.

        Returns:
            A JSON-ready dict.
        """
        return {
            "folds": self.folds,
            "sets": {
                s.folder.label: {
                    "directory": str(s.folder.directory),
                    "camera": s.folder.camera,
                    "images": s.images,
                    "methods": s.rows,
                    "left_out": s.left_out,
                    "evaluation": s.evaluation.report(),
                }
                for s in self.sets
            },
            "geometric_mean": {"folders": len(self.sets), "methods": self.geometric_means()},
        }


def fold_model_file(directory: str | os.PathLike, label: str, fold: int) -> pathlib.Path:
    """Where :func:`save_fold_models` writes ``label``'s model of ``fold``: ``directory/<label>-fold<k>.eqx``
    (its JSON record beside it, ``.json``).

    Arguments:
        directory: the models' folder.
        label: the trained method's label.
        fold: the fold index.

    Returns:
        The model file's path.
    """
    return pathlib.Path(directory) / f"{label}-fold{fold}.eqx"


def save_fold_models(
    evaluation: FolderEvaluation,
    directory: str | os.PathLike,
    camera: str,
    *,
    world_seed: int = 0,
    overwrite: bool = False,
) -> list[pathlib.Path]:
    """Write each trained method's fold models: ``directory/<label>-fold<k>.eqx`` with its record
    (:func:`ccjax.runs.store.save_trained`; :func:`ccjax.load_model` reads them).

    Arguments:
        evaluation: an evaluation with methods trained within folds.
        directory: the folder to write into (made when missing).
        camera: the camera of the default world the starts were fitted to.
        world_seed: that world's seed.
        overwrite: replace existing files (else ``FileExistsError``).

    Returns:
        The model files written, by method and fold.
    """
    from ccjax.runs import store

    folder = pathlib.Path(directory)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for label, validation in evaluation.validations.items():
        for fold, model in enumerate(evaluation.trained_models[label + TRAINED_SUFFIX]):
            record = {
                "fold": fold,
                "train_images": validation.folds[fold].train_names,
                "test_images": validation.folds[fold].test_names,
            }
            written.append(
                store.save_trained(
                    fold_model_file(folder, label, fold),
                    model,
                    label=label,
                    camera=camera,
                    world_seed=world_seed,
                    record=record,
                    overwrite=overwrite,
                )
            )
    return written


def evaluate_folder_sets(
    folders: Sequence[FolderSet],
    methods: Sequence[str],
    *,
    folds: int | None = None,
    train: Sequence[str] | None = None,
    epochs: int | None = None,
    seed: int = 0,
    world_kind: str = "default",
    data_dir: str | os.PathLike | None = None,
    preprocessing: str | Preprocessing | None = None,
    dark: float = DEFAULT_DARK,
    read_options: dict | None = None,
    allow_missing: bool = False,
    progress: bool = False,
    log: Callable[[str], None] | None = None,
    max_pixels: int | None = MAX_PIXELS,
) -> SetsEvaluation:
    """Evaluate ``methods`` (and ``train``, trained within the folds) on each folder on its own
    (:func:`ccjax.experiments.folders.evaluate_folder`), with each folder's camera.

    Arguments:
        folders: the :class:`FolderSet` s (distinct names).
        methods: registry labels fitted to each folder's world.
        folds: K-fold cross-validation within each folder (K >= 2), or None.
        train: labels trained within each folder's folds (needs ``folds``).
        epochs: training epochs at most (default: the training schedule's).
        seed: seed of the worlds, the fold assignment and the training.
        world_kind: ``"default"`` (each folder's camera) or ``"barnard1999"``.
        data_dir: the external data directory (``barnard1999``).
        preprocessing, dark, read_options, allow_missing, progress, max_pixels: as
            :func:`~ccjax.experiments.folders.evaluate_folder`, for every folder.
        log: called with a line per folder, warning and training step.

    Returns:
        :class:`SetsEvaluation`.

    Raises:
        ValueError: no folder, two folders with one name, or what
            :func:`~ccjax.experiments.folders.evaluate_folder` refuses (prefixed with the folder).
    """
    from ccjax.experiments.folders import check_fold_options, evaluate_folder
    from ccjax.runs import store

    check_fold_options(folds, list(train) if train else None, epochs)
    if not folders:
        raise ValueError("folders: expected at least one folder")
    names = [folder.label for folder in folders]
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise ValueError(f"folders: each folder needs its own name, got {', '.join(repeated)} more than once")
    results = []
    for folder in folders:
        world = store.world(world_kind, folder.camera, seed=seed, data_dir=data_dir)
        curves = world_kind != "default" or folder.camera is not None
        # World-based methods need the camera's own curves: without them they are left out here.
        left_out = (
            [] if curves else [label for label in [*methods, *(train or [])] if store.fit(label, world).world_based]
        )
        if log is not None:
            log(f"{folder.label}: {folder.directory} (camera: {folder.camera or 'none given'})")
        try:
            evaluation = evaluate_folder(
                folder.directory,
                folder.ground_truth,
                [label for label in methods if label not in left_out],
                world=world,
                folds=folds,
                train=[label for label in train or [] if label not in left_out],
                epochs=epochs,
                seed=seed,
                preprocessing=preprocessing,
                dark=dark,
                read_options=read_options,
                check_camera=curves,
                allow_missing=allow_missing,
                progress=progress,
                log=log,
                max_pixels=max_pixels,
            )
        except ValueError as error:
            raise ValueError(f"{error} (folder {folder.label})") from None
        results.append(SetResult(folder, evaluation, _rows(evaluation), left_out, world.camera.name))
    return SetsEvaluation(results, folds)
