"""One folder of photographs evaluated with keyword options (``evaluate_folder``): a convenience
over :func:`ccjax.evaluation.evaluate_data`, which takes the protocol, the read options and the
training options as values (:mod:`ccjax.evaluation`)."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence

from ccjax.evaluation import (
    FittedToWorld,
    FolderEvaluation,
    KFolds,
    ReadOptions,
    TrainedInFolds,
    TrainingOptions,
    evaluate_data,
    read_folder,
)
from ccjax.evaluation.folders import CSV_FIELDS, TRAINED_SUFFIX
from ccjax.evaluation.protocols import (
    MIN_TRAINING_IMAGES,
    AbstractProtocol,
    check_fold_options,
    train_in_folds,
    trainable_starts,
)
from ccjax.io.reading import MAX_PIXELS
from ccjax.preprocessing import DEFAULT_DARK, Preprocessing
from ccjax.world import World

__all__ = [
    "CSV_FIELDS",
    "MIN_TRAINING_IMAGES",
    "TRAINED_SUFFIX",
    "FolderEvaluation",
    "check_fold_options",
    "evaluate_folder",
    "protocol_for",
    "train_in_folds",
    "trainable_starts",
]


def protocol_for(folds: int | None, train: Sequence[str] | None) -> AbstractProtocol:
    """The protocol the keyword options name: trained in folds, K folds, or fitted to the world.

    Arguments:
        folds: K, or None.
        train: labels trained within the folds (needs ``folds``).

    Returns:
        :class:`~ccjax.evaluation.TrainedInFolds`, :class:`~ccjax.evaluation.KFolds` or
        :class:`~ccjax.evaluation.FittedToWorld`.
    """
    if train:
        assert folds is not None  # check_fold_options refused train without folds
        return TrainedInFolds(folds, tuple(train))
    return FittedToWorld() if folds is None else KFolds(folds)


def evaluate_folder(
    directory: str | os.PathLike,
    ground_truth: str | os.PathLike,
    methods: Sequence[str],
    *,
    world: World | None = None,
    folds: int | None = None,
    train: Sequence[str] | None = None,
    epochs: int | None = None,
    seed: int = 0,
    preprocessing: str | Preprocessing | None = None,
    dark: float = DEFAULT_DARK,
    read_options: dict | None = None,
    masks: str | os.PathLike | None = None,
    check_camera: bool = False,
    allow_missing: bool = False,
    progress: bool = False,
    log: Callable[[str], None] | None = None,
    max_pixels: int | None = MAX_PIXELS,
    pretraining=None,
) -> FolderEvaluation:
    """Run methods on every image a ground-truth CSV lists and score them (angular error).

    Without ``folds`` each method is fitted to ``world``. With ``folds`` K alone, each fold's
    models are fitted to a fold world whose training lights are those nearest the other folds'
    ground truths (:func:`ccjax.evaluation.fold_worlds`; folds from the CSV's fold column when it
    has one, else image i in fold i mod K, in path order). With ``train``, each listed label is
    started from its fit to ``world`` and trained within the folds (folds from the fold column,
    else seeded by ``seed`` in ground-truth order) and reported as ``"<label> trained"`` beside
    ``methods``, which are then fitted to ``world``.

    Arguments:
        directory: the image folder.
        ground_truth: CSV ``image,r,g,b[,fold]`` (:func:`ccjax.io.read_ground_truth_file`).
        methods: registry labels.
        world: the world (default :func:`ccjax.runs.store.world`); world-based methods need the
            camera that took the images.
        folds: K-fold cross-validation (K >= 2), or None.
        train: labels to train within the folds (needs ``folds``).
        epochs: training epochs at most (default: each family's schedule's).
        seed: seed of the training folds' assignment and of the training.
        preprocessing: one preprocessing for every method (None: each method's default).
        dark: the surface lists' dark rule.
        read_options: keyword arguments of :func:`ccjax.io.read_image`.
        masks: a folder of masks named by the images' stems, or None.
        check_camera: compare the ground truth with the world's camera even when no method is
            world-based.
        allow_missing: score the listed images when some image files of the folder have no
            ground-truth row (named in :attr:`FolderEvaluation.unlisted`) instead of refusing.
        progress: progress bars on stderr.
        log: called with a line for each warning and training step.
        max_pixels: the pixel budget (default 100 MP; None: no limit).
        pretraining: with ``train``, pretrain each start from spectra before its training.

    Returns:
        :class:`~ccjax.evaluation.FolderEvaluation`.

    Raises:
        ValueError: bad options (naming ``folds``, ``train``, ``epochs``, ``masks``), a bad ground
            truth, image files without a ground-truth row, or no usable image.
    """
    from ccjax.runs import store

    check_fold_options(folds, train, epochs)
    protocol = protocol_for(folds, train)
    options = TrainingOptions(seed=seed, epochs=epochs, pretraining=pretraining)
    read = ReadOptions(
        image=dict(read_options or {}),
        masks=masks,
        max_pixels=max_pixels,
        allow_missing=allow_missing,
        preprocessing=preprocessing,
        dark=dark,
    )
    data = read_folder(directory, ground_truth, read, with_folds=protocol.reads_fold_column())
    world = world if world is not None else store.world()
    return evaluate_data(
        data,
        [data],
        methods,
        protocol,
        world,
        read=read,
        options=options,
        check_camera=check_camera,
        progress=progress,
        log=log,
    )
