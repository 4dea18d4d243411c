"""The field's protocol over several folders of photographs with keyword options
(``evaluate_folder_sets``): a convenience over :func:`ccjax.evaluation.evaluate`, which takes the
protocol, the read options and the training options as values (:mod:`ccjax.evaluation`)."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence

from ccjax.evaluation import ReadOptions, TrainingOptions, evaluate
from ccjax.evaluation.sets import (
    PROTOCOL_STATISTICS,
    FolderSet,
    SetResult,
    SetsEvaluation,
    fold_model_file,
    geometric_mean,
    geometric_means,
    save_fold_models,
)
from ccjax.experiments.folders import check_fold_options, protocol_for
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
    """Evaluate ``methods`` (and ``train``, trained within the folds) on each folder on its own,
    with each folder's camera (:func:`ccjax.evaluation.evaluate` with the protocol the options name).

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
            :func:`ccjax.experiments.folders.evaluate_folder`, for every folder.
        log: called with a line per folder, warning and training step.

    Returns:
        :class:`~ccjax.evaluation.SetsEvaluation`.

    Raises:
        ValueError: no folder, two folders with one name, or what a folder's evaluation refuses
            (prefixed with the folder).
    """
    check_fold_options(folds, list(train) if train else None, epochs)
    read = ReadOptions(
        image=dict(read_options or {}),
        max_pixels=max_pixels,
        allow_missing=allow_missing,
        preprocessing=preprocessing,
        dark=dark,
    )
    return evaluate(
        folders,
        methods,
        protocol_for(folds, train),
        read=read,
        options=TrainingOptions(seed=seed, epochs=epochs),
        world_kind=world_kind,
        data_dir=data_dir,
        progress=progress,
        log=log,
    )
