"""Photo evaluation over folders of photographs, each taken by one camera: :func:`evaluate` runs a
protocol's rounds (:mod:`ccjax.evaluation.photo_protocols`: each folder on its own, K-fold, trained in
folds, or trained on the other cameras' folders), each scored folder with its own camera's world,
then the geometric mean of each statistic over the folders, as the field reports NUS-8 (Cheng,
Prasad & Brown 2014; e.g. Barron & Tsai 2017, Table 1), with each method's training seconds and
inference milliseconds per image. :class:`SetsEvaluation` holds the table, the JSON report and
the fold models (:func:`save_fold_models`).
"""

from __future__ import annotations

import math
import os
import pathlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ccjax.evaluation.methods import check_methods
from ccjax.evaluation.options import ReadOptions, TrainingOptions
from ccjax.evaluation.photo_protocols import AbstractProtocol, RoundInputs
from ccjax.evaluation.scored_folder import (
    TRAINED_SUFFIX,
    FolderData,
    FolderEvaluation,
    camera_check,
    method_model,
    read_folder,
    score_folder,
)
from ccjax.world import World

__all__ = [
    "PROTOCOL_STATISTICS",
    "FolderSet",
    "SetResult",
    "SetsEvaluation",
    "evaluate",
    "evaluate_data",
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
        evaluation: its :class:`~ccjax.evaluation.FolderEvaluation`.
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
        sets: one :class:`SetResult` per scored folder, in the order given.
        folds: the number of folds of every folder.
        notes: what the protocol left out, and why (e.g. folders without a camera).
    """

    sets: list[SetResult]
    folds: int | None = None
    notes: list[str] = field(default_factory=list)

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
            lines += [f"{result.folder.label}: {note}" for note in result.evaluation.training_notes]
        return "\n".join(lines + self.notes)

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
            "notes": list(self.notes),
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


def evaluate_data(
    data: FolderData,
    training: Sequence[FolderData],
    methods: Sequence[str],
    protocol: AbstractProtocol,
    world: World,
    *,
    trained: Sequence[str] | None = None,
    read: ReadOptions | None = None,
    options: TrainingOptions | None = None,
    check_camera: bool = False,
    progress: bool = False,
    log: Callable[[str], None] | None = None,
) -> FolderEvaluation:
    """Score one read folder: its models from the protocol, its camera check, its run.

    Arguments:
        data: the scored folder (:func:`~ccjax.evaluation.scored_folder.read_folder`).
        training: the round's training folders.
        methods: labels fitted to ``world``.
        protocol: the protocol.
        world: the scored folder's world.
        trained: the labels to train (default: the protocol's).
        read: how images are read and prepared (default :class:`ReadOptions`).
        options: seed, epochs, pretraining (default :class:`TrainingOptions`).
        check_camera: compare the ground truth with the world's camera even when no method is
            world-based.
        progress: progress bars on stderr.
        log: a line per warning and training step.

    Returns:
        :class:`~ccjax.evaluation.scored_folder.FolderEvaluation`.
    """
    read, options = read or ReadOptions(), options or TrainingOptions()
    trained = list(protocol.trained_labels() if trained is None else trained)
    check = camera_check(data, world, [*methods, *trained], asked=check_camera, log=log)
    inputs = RoundInputs(data, training, methods, trained, world, read, options)
    given = protocol.models(inputs, progress=progress, log=log)
    return score_folder(data, given, world, read, check=check, progress=progress)


def evaluate(
    folders: Sequence[FolderSet],
    methods: Sequence[str],
    protocol: AbstractProtocol,
    *,
    read: ReadOptions | None = None,
    options: TrainingOptions | None = None,
    world_kind: str = "default",
    data_dir: str | os.PathLike | None = None,
    progress: bool = False,
    log: Callable[[str], None] | None = None,
    refuse_without_camera: bool = False,
) -> SetsEvaluation:
    """Evaluate ``methods`` (and the protocol's trained labels) on folders of photographs, each
    scored folder with its own camera's world, in the protocol's rounds.

    Arguments:
        folders: the :class:`FolderSet` s (distinct names).
        methods: registry labels fitted to each scored folder's world.
        protocol: what the methods are fitted or trained on (:mod:`ccjax.evaluation.photo_protocols`).
        read: how images are read and prepared, every folder (default :class:`ReadOptions`).
        options: seed (worlds, folds, training), epochs, pretraining (default :class:`TrainingOptions`).
        world_kind: ``"default"`` (each folder's camera) or ``"barnard1999"``.
        data_dir: the external data directory (``barnard1999``).
        progress: progress bars on stderr.
        log: called with a line per folder, warning and training step.
        refuse_without_camera: refuse world-based methods on a folder without a camera (they
            would be fitted to curves the images were never matched to) instead of leaving them
            out of it, before any image is read.

    Returns:
        :class:`SetsEvaluation`: one row set per scored folder, the geometric means.

    Raises:
        ValueError: no folder, two folders with one name, a method :func:`check_methods` refuses, or
            a folder's evaluation's refusal (prefixed with it).
    """
    from ccjax.runs import store

    read, options = read or ReadOptions(), options or TrainingOptions()
    if not folders:
        raise ValueError("folders: expected at least one folder")
    names = [folder.label for folder in folders]
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise ValueError(f"folders: each folder needs its own name, got {', '.join(repeated)} more than once")
    check_methods(methods, folders)
    notes: list[str] = []

    def where(folder: FolderSet) -> str:  # one folder's errors need no name
        return f" (folder {folder.label})" if len(folders) > 1 else ""

    rounds = protocol.rounds([folder.camera for folder in folders], notes.append)
    read_once: dict[int, FolderData] = {}

    def data(index: int) -> FolderData:
        if index not in read_once:
            folder = folders[index]
            try:
                read_once[index] = read_folder(
                    folder.directory,
                    folder.ground_truth,
                    read,
                    camera=folder.camera,
                    label=folder.label,
                    with_folds=protocol.reads_fold_column(),
                )
            except ValueError as error:
                raise ValueError(f"{error}{where(folder)}") from None
        return read_once[index]

    results = []
    for step in rounds:
        folder = folders[step.scored]
        world = store.world(world_kind, folder.camera, seed=options.seed, data_dir=data_dir)
        curves = world_kind != "default" or folder.camera is not None
        # World-based methods need the camera's own curves: without them they are left out here.
        labels = [*methods, *protocol.trained_labels()]
        left_out = [] if curves else [label for label in labels if method_model(label, world).world_based]
        if left_out and refuse_without_camera:
            raise ValueError(
                f"camera: {', '.join(left_out)} {'is' if len(left_out) == 1 else 'are'} fitted to a world seen "
                "through a camera's curves; give the camera that took the images with --camera NAME (`ccjax "
                "cameras` lists the names, `ccjax cameras --check GT.csv --camera NAME` tests a guess against the "
                "ground truth) or use --world barnard1999"
            )
        if log is not None and len(folders) > 1:  # one folder: the header already says it all
            log(f"{folder.label}: {folder.directory} (camera: {folder.camera or 'none given'})")
        try:
            evaluation = evaluate_data(
                data(step.scored),
                [data(index) for index in step.training],
                [label for label in methods if label not in left_out],
                protocol,
                world,
                trained=[label for label in protocol.trained_labels() if label not in left_out],
                read=read,
                options=options,
                check_camera=curves,
                progress=progress,
                log=log,
            )
        except ValueError as error:
            raise ValueError(f"{error}{where(folder)}") from None
        results.append(SetResult(folder, evaluation, _rows(evaluation), left_out, world.camera.name))
    folds = results[0].evaluation.folds if results else None
    return SetsEvaluation(results, folds, notes)
