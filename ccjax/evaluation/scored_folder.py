"""One folder of photographs with ground truth, scored: read once (:func:`read_folder`), given its
models by a protocol (:mod:`ccjax.evaluation.photo_protocols`: fitted to a world, K folds, trained in
folds, trained on other cameras' folders), run through the execution layer's image loop
(:func:`ccjax.runs.images.run_models`) and summarised as a :class:`FolderEvaluation`: the
statistics, per fold and pooled, the training record, the camera check, the JSON / CSV reports.
"""

from __future__ import annotations

import csv
import io as text_io
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ccjax.estimators.base import AbstractEstimator
from ccjax.evaluation._fold_tables import fold_table, training_table
from ccjax.evaluation.camera_check import CurveCheck, curve_check
from ccjax.evaluation.image_results import ImageResults
from ccjax.evaluation.options import ReadOptions
from ccjax.io.files import csv_text_cell
from ccjax.runs.sources import ImageFolder
from ccjax.world import World

TRAINED_SUFFIX = " trained"
"""Suffix of a method trained within folds (``train=``) in the tables and reports."""

CSV_FIELDS = ("path", "method", "preprocessing", "R", "G", "B", "r", "g", "ok", "status", "angular")
"""Columns of :meth:`FolderEvaluation.csv`: one row per image and method."""


@dataclass
class FolderEvaluation:
    """What :func:`evaluate_folder` found.

    Attributes:
        results: the per-image estimates and statistics of every method (trained ones as
            ``"<label> trained"``).
        world: the name of the world the methods were fitted to.
        folds: the number of folds (None: no cross-validation).
        fold_source: where the folds came from: ``"the ground truth's fold column"``,
            ``"seed <n>"`` or ``"image i in fold i mod K"`` (None without folds).
        trained: the labels trained within the folds.
        fold_of: ``(N,)`` the fold of each of ``results.paths`` (None without folds).
        validations: ``{label: CrossValidation}`` of each trained label.
        trained_models: ``{"<label> trained": [the model of fold 0, ...]}`` (to save them).
        check: the ground truth against the world's camera (:func:`ccjax.evaluation.curve_check`),
            when it was asked for or a method is world-based.
        failures: one failure record per image that could not be used, in path order.
        total: how many images the ground truth lists.
        unlisted: the image files of the folder without a ground-truth row (not scored; only with
            ``allow_missing``).
        training_notes: one line per method trained outside this folder (on which folders and
            cameras, through which maps).
    """

    results: ImageResults
    world: str
    folds: int | None = None
    fold_source: str | None = None
    trained: list[str] = field(default_factory=list)
    fold_of: np.ndarray | None = None
    validations: dict = field(default_factory=dict)
    trained_models: dict = field(default_factory=dict)
    check: CurveCheck | None = None
    failures: list[str] = field(default_factory=list)
    total: int = 0
    unlisted: list[str] = field(default_factory=list)
    training_notes: list[str] = field(default_factory=list)

    def tables(self) -> str:
        """The statistics table (:meth:`ImageResults.table`), then per fold and pooled, then the
        training record.

        Returns:
            The text.
        """
        parts = [self.results.table()]
        if self.fold_of is not None and len(self.results.paths):
            parts.append("\n" + fold_table(self.results, self.fold_of))
        if self.validations:
            parts.append("\n" + training_table(self.validations))
        parts += self.training_notes
        return "\n".join(parts)

    def report(self) -> dict:
        """The JSON report: ``summary`` per method, ``images`` (one record per image and method),
        ``failures``, and ``camera_check`` and ``folds`` (fold of each image, each fold's training)
        when there are.

        Returns:
            A JSON-ready dict.
        """
        results = self.results
        report: dict = {
            "summary": {label: results.summary(label) for label in results.estimates},
            "images": results.records(),
            "failures": list(self.failures),
            "unlisted": list(self.unlisted),
        }
        check = self.check
        if check is not None:
            report["camera_check"] = {"camera": check.camera, "distance": check.distance, "threshold": check.threshold}
        if self.training_notes:
            report["training"] = list(self.training_notes)
        if self.fold_of is not None:
            report["folds"] = {
                "fold_of": dict(zip(results.paths, self.fold_of.tolist(), strict=True)),
                "training": {
                    label + TRAINED_SUFFIX: [
                        {
                            **result.summary(),
                            "heldout_median_per_epoch": result.log.heldout_median,
                            "train_images": result.train_names,
                            "test_images": result.test_names,
                        }
                        for result in validation.folds
                    ]
                    for label, validation in self.validations.items()
                },
            }
        return report

    def csv(self) -> str:
        """One CSV row per image and method (:data:`CSV_FIELDS`).

        Returns:
            The CSV text.
        """
        buffer = text_io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(CSV_FIELDS)
        for r in self.results.records():
            writer.writerow(
                [
                    csv_text_cell(r["path"]),
                    csv_text_cell(r["method"]),
                    self.results.preprocessing.get(r["method"], ""),
                    *(f"{v:.9g}" for v in r["illuminant"] + r["rg"]),
                    str(r["ok"]),
                    r.get("status", ""),
                    f"{r['angular']:.9g}",
                ]
            )
        return buffer.getvalue()


MODEL_SUFFIX = ".eqx"
"""A method given as a trained model file (``ccjax train --out``) rather than a registry label."""


def method_model(method: str, world: World) -> AbstractEstimator:
    """A method of an evaluation: a registry label fitted to ``world`` (through the store), or a
    trained model file (``.eqx``, :func:`ccjax.load_model`) as it was trained.

    Arguments:
        method: a label or a model file's path.
        world: the scored folder's world.

    Returns:
        The model.
    """
    from ccjax.runs import store

    if not method.endswith(MODEL_SUFFIX):
        return store.fit(method, world)
    conditioned = store.trained_record(method).get("conditioned") is True
    return store.load_model(method, camera=world.camera.name if conditioned else None)


@dataclass
class FolderData:
    """One labelled folder, its ground truth read and matched to its files once.

    Attributes:
        directory: the image folder.
        ground_truth: its CSV.
        camera: the camera that took it (None: none given).
        label: its name in tables and reports.
        names: the ground-truth names in the CSV's order (fold assignments follow it).
        given_folds: the CSV's fold column (None: none, or not read).
        paths: the listed image files, in path order.
        truth: ``(N, 3)`` the ground truth of ``paths``.
        path_names: the ground-truth name of each of ``paths``.
        unlisted: image files of the folder without a row (allowed by ``allow_missing``).
        source: the images (:func:`ccjax.runs.sources.image_folder`), headers probed.
    """

    directory: str | os.PathLike
    ground_truth: str | os.PathLike
    camera: str | None
    label: str
    names: list[str]
    given_folds: dict | None
    paths: list
    truth: np.ndarray
    path_names: list[str]
    unlisted: list[str]
    source: ImageFolder


def read_folder(
    directory: str | os.PathLike,
    ground_truth: str | os.PathLike,
    read: ReadOptions,
    *,
    camera: str | None = None,
    label: str = "",
    with_folds: bool = False,
) -> FolderData:
    """Read a folder's ground truth, match it to the image files and probe every header once.

    Arguments:
        directory: the image folder.
        ground_truth: CSV ``image,r,g,b[,fold]`` (:func:`ccjax.io.read_ground_truth_file`).
        read: how the images are read (``allow_missing``, masks, the pixel budget).
        camera: the camera that took them.
        label: the folder's name in tables (default: the directory's name).
        with_folds: read the CSV's fold column.

    Returns:
        :class:`FolderData`.

    Raises:
        ValueError: a bad ground truth, image files without a row (each named; unless
            ``read.allow_missing``), or no usable image (every file's failure record).
    """
    from ccjax import io
    from ccjax.runs.sources import image_folder, raise_failures

    table = io.read_ground_truth_file(ground_truth, with_folds=with_folds)
    pairs = io.match_ground_truth(table.lights, directory)
    unlisted = [str(file) for file in io.unlisted_images(pairs, directory)]
    if unlisted and not read.allow_missing:
        # A silently smaller set is a different benchmark: the caller decides.
        raise ValueError(
            f"ground_truth: {len(unlisted)} image(s) in {directory} have no row in {ground_truth}: "
            f"{', '.join(unlisted)}; add their rows, or score the listed images only (allow_missing=True; "
            "--allow-missing on the command line)"
        )
    names = list(table.lights)
    order = sorted(range(len(pairs)), key=lambda index: str(pairs[index][0]))
    paths = [pairs[i][0] for i in order]
    truth = np.stack([pairs[i][1] for i in order])
    source = image_folder(paths, masks=read.masks, read_options=read.image, max_pixels=read.max_pixels)
    if not source.usable():
        raise_failures(list(source.failures.values()), len(paths))
    return FolderData(
        directory=directory,
        ground_truth=ground_truth,
        camera=camera,
        label=label or os.path.basename(os.path.normpath(directory)),
        names=names,
        given_folds=table.folds,
        paths=paths,
        truth=truth,
        path_names=[names[i] for i in order],
        unlisted=unlisted,
        source=source,
    )


@dataclass
class FolderModels:
    """What a protocol gives one scored folder (:meth:`ccjax.evaluation.AbstractProtocol.models`).

    Attributes:
        models: ``{label: [model of fold 0, ...]}`` (one model when there are no folds).
        fold_of: ``(N,)`` the fold of each of the folder's files (None: no folds).
        folds: the number of folds (None: none).
        fold_source: where the folds came from (None without folds).
        trained: the labels trained within the folds.
        validations: ``{label: CrossValidation}`` of each label trained within the folds.
        trained_models: ``{"<label> trained": [model of each fold]}`` (to save them).
        training_notes: a line per method trained elsewhere (other cameras' folders).
    """

    models: dict[str, list[AbstractEstimator]]
    fold_of: np.ndarray | None = None
    folds: int | None = None
    fold_source: str | None = None
    trained: list[str] = field(default_factory=list)
    validations: dict = field(default_factory=dict)
    trained_models: dict = field(default_factory=dict)
    training_notes: list[str] = field(default_factory=list)


def camera_check(
    data: FolderData, world: World, labels: Sequence[str], *, asked: bool, log: Callable[[str], None] | None
) -> CurveCheck | None:
    """The folder's ground truth against the world's camera (:func:`curve_check`), when it was
    asked for or a method needs the camera's curves (a world-based one); a failed check is logged.

    Arguments:
        data: the folder.
        world: the world its methods are fitted to.
        labels: every label run on it.
        asked: check even when no method is world-based.
        log: where the warning goes.

    Returns:
        The check, or None when it was not needed.
    """
    if not asked and not any(method_model(label, world).world_based for label in labels):
        return None
    check = curve_check(data.truth, world)
    if not check.passed and log is not None:
        log(f"warning: {check.message()}; try `ccjax cameras --check {data.ground_truth} --camera NAME`")
    return check


def score_folder(
    data: FolderData,
    given: FolderModels,
    world: World,
    read: ReadOptions,
    *,
    check: CurveCheck | None = None,
    progress: bool = False,
) -> FolderEvaluation:
    """Run the models a protocol gave a folder on its images and score them (angular error).

    Arguments:
        data: the folder.
        given: its models (per fold), folds and training record.
        world: the world the methods were fitted to (its name goes in the report).
        read: the preparation (preprocessing, dark rule).
        check: the folder's camera check.
        progress: progress bars on stderr.

    Returns:
        :class:`FolderEvaluation`.
    """
    from ccjax.runs.images import run_models

    source, keep = data.source, data.source.usable()
    run = run_models(
        source,
        given.models,
        items=keep,
        fold_of=given.fold_of,
        preprocessing=read.preprocessing,
        dark=read.dark,
        progress=progress,
    )
    results = ImageResults.from_run(run, data.truth[keep])
    merged = source.failures | run.failures
    failures = [merged[str(path)] for path in data.paths if str(path) in merged]
    scored = None if given.fold_of is None else given.fold_of[np.asarray(run.items)[run.done]]
    return FolderEvaluation(
        results=results,
        world=world.name,
        folds=given.folds,
        fold_source=given.fold_source,
        trained=list(given.trained),
        fold_of=scored,
        validations=given.validations,
        trained_models=given.trained_models,
        check=check,
        failures=failures,
        total=len(data.paths),
        unlisted=data.unlisted,
        training_notes=list(given.training_notes),
    )
