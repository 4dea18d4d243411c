"""Photo evaluation in one call with keyword options: :func:`evaluate_folder` (one folder) and
:func:`evaluate_folder_sets` (each of several folders with its camera, ``ccjax evaluate DIR DIR
...``). They build the values that :func:`ccjax.evaluation.evaluate_data` and
:func:`ccjax.evaluation.evaluate` take (the protocol, :func:`protocol_for`; the read and training
options) and call those."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence

from ccjax.evaluation.options import ReadOptions, TrainingOptions
from ccjax.evaluation.photo_protocols import check_fold_options, protocol_for
from ccjax.evaluation.scored_folder import FolderEvaluation, read_folder
from ccjax.evaluation.sets import FolderSet, SetsEvaluation, evaluate, evaluate_data
from ccjax.io.reading import MAX_PIXELS
from ccjax.preprocessing import DEFAULT_DARK, Preprocessing
from ccjax.world import World

__all__ = ["evaluate_folder", "evaluate_folder_sets"]


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

    protocol, read, options = _values(
        folds, train, epochs, seed, pretraining, read_options, masks, max_pixels, allow_missing, preprocessing, dark
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
    with each folder's camera (:func:`ccjax.evaluation.evaluate` with the protocol the options
    name, :func:`protocol_for`).

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
            :func:`evaluate_folder`, for every folder.
        log: called with a line per folder, warning and training step.

    Returns:
        :class:`~ccjax.evaluation.SetsEvaluation`.

    Raises:
        ValueError: no folder, two folders with one name, or what a folder's evaluation refuses
            (prefixed with the folder).
    """
    protocol, read, options = _values(
        folds, train, epochs, seed, None, read_options, None, max_pixels, allow_missing, preprocessing, dark
    )
    return evaluate(
        folders,
        methods,
        protocol,
        read=read,
        options=options,
        world_kind=world_kind,
        data_dir=data_dir,
        progress=progress,
        log=log,
    )


def _values(
    folds, train, epochs, seed, pretraining, read_options, masks, max_pixels, allow_missing, preprocessing, dark
):
    """The protocol, read options and training options that the keyword options name, after
    :func:`~ccjax.evaluation.photo_protocols.check_fold_options` (arguments as
    :func:`evaluate_folder`'s)."""
    check_fold_options(folds, list(train) if train else None, epochs)
    read = ReadOptions(
        image=dict(read_options or {}),
        masks=masks,
        max_pixels=max_pixels,
        allow_missing=allow_missing,
        preprocessing=preprocessing,
        dark=dark,
    )
    return protocol_for(folds, train), read, TrainingOptions(seed=seed, epochs=epochs, pretraining=pretraining)
