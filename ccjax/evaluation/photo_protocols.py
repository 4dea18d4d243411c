"""Protocols of photo evaluation: what each scored folder's methods are fitted or trained on.

A protocol is a value (an ``eqx.Module`` with static fields) with two hooks: :meth:`AbstractProtocol.rounds`
says which folder is scored with which folders' labelled images, and :meth:`AbstractProtocol.models`
gives a scored folder its models (per fold) and their training record from the round's
:class:`RoundInputs`. The runner
(:func:`ccjax.evaluation.evaluate`) calls the hooks and nothing else, so a new protocol is one new
value:

* :class:`FittedToWorld` -- every method fitted to the folder's world (Barnard 1999 §4.6);
* :class:`KFolds` -- K-fold cross-validation whose fold worlds learn the other folds' lights;
* :class:`TrainedInFolds` -- learned methods trained within K folds, never on the fold scored;
* :class:`LeaveOneCameraOut` and :class:`TrainOn` (:mod:`ccjax.evaluation.cross_camera`) --
  trained on other cameras' folders mapped into the scored folder's camera.
"""

from __future__ import annotations

import abc
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import equinox as eqx
import numpy as np

from ccjax.estimators.base import AbstractEstimator
from ccjax.evaluation.image_results import fold_worlds
from ccjax.evaluation.options import ReadOptions, TrainingOptions
from ccjax.evaluation.scored_folder import TRAINED_SUFFIX, FolderData, FolderModels, method_model
from ccjax.preprocessing import DEFAULT_DARK, Preprocessing, resolve
from ccjax.world import World

__all__ = [
    "MIN_TRAINING_IMAGES",
    "AbstractProtocol",
    "FittedToWorld",
    "KFolds",
    "Round",
    "RoundInputs",
    "TrainedInFolds",
    "check_fold_options",
    "protocol_for",
    "train_in_folds",
    "trainable_starts",
]

MIN_TRAINING_IMAGES = 4
"""The fewest images a fold's training set may have (training holds some out for early stopping)."""


@dataclass(frozen=True)
class Round:
    """One scored folder and the folders whose labelled images its learned methods train on.

    Attributes:
        scored: the index of the scored folder.
        training: the indices of the training folders (the scored one itself for the protocols
            that train within its folds; empty when nothing is trained).
    """

    scored: int
    training: tuple[int, ...] = ()


@dataclass(frozen=True)
class RoundInputs:
    """What a protocol's :meth:`AbstractProtocol.models` is given for one round.

    Attributes:
        data: the scored folder.
        training: the round's training folders (:attr:`Round.training`, read).
        methods: the labels fitted to ``world`` (not trained).
        trained: the labels to train (:meth:`AbstractProtocol.trained_labels`, less those the
            folder cannot run: world-based ones without a camera).
        world: the scored folder's world (its camera's curves).
        read: the preparation of every input.
        options: seed, epochs, pretraining.
    """

    data: FolderData
    training: Sequence[FolderData]
    methods: Sequence[str]
    trained: Sequence[str]
    world: World
    read: ReadOptions
    options: TrainingOptions


class AbstractProtocol(eqx.Module):
    """What each scored folder's methods are fitted or trained on (see the module's list)."""

    @abc.abstractmethod
    def trained_labels(self) -> tuple[str, ...]:
        """The labels this protocol trains (reported as ``"<label> trained"``).

        Returns:
            The registry labels.
        """

    @abc.abstractmethod
    def reads_fold_column(self) -> bool:
        """Whether the ground truth's fold column is read (and checked).

        Returns:
            True when the protocol uses the CSV's folds.
        """

    @abc.abstractmethod
    def rounds(self, cameras: Sequence[str | None], log: Callable[[str], None] | None) -> list[Round]:
        """The rounds of an evaluation of folders taken with ``cameras`` (None: no camera given).

        Arguments:
            cameras: each folder's camera.
            log: where to say which folders are left out and why.

        Returns:
            The :class:`Round` s, in order.
        """

    @abc.abstractmethod
    def models(self, inputs: RoundInputs, *, progress: bool, log: Callable[[str], None] | None) -> FolderModels:
        """The scored folder's models (per fold) and their training record.

        Arguments:
            inputs: the round's scored folder, training folders, labels, world and options.
            progress: progress bars.
            log: a line per training step.

        Returns:
            :class:`~ccjax.evaluation.scored_folder.FolderModels`.
        """


def _fitted(methods: Sequence[str], world: World, copies: int = 1) -> dict[str, list[AbstractEstimator]]:
    return {method: [method_model(method, world)] * copies for method in methods}


class FittedToWorld(AbstractProtocol):
    """Every method fitted to the folder's world; no folds, nothing trained."""

    def trained_labels(self) -> tuple[str, ...]:
        return ()

    def reads_fold_column(self) -> bool:
        return False

    def rounds(self, cameras, log) -> list[Round]:
        return [Round(index) for index in range(len(cameras))]

    def models(self, inputs, *, progress, log) -> FolderModels:
        return FolderModels(_fitted(inputs.methods, inputs.world))


class KFolds(AbstractProtocol):
    """K-fold cross-validation: each fold's models are fitted to a fold world whose training lights
    are those nearest the other folds' ground truth (:func:`ccjax.evaluation.fold_worlds`; folds
    from the CSV's fold column when it has one, else image i in fold i mod K, in path order).

    Attributes:
        folds: K (at least 2).
    """

    folds: int = eqx.field(static=True)

    def __check_init__(self) -> None:
        check_fold_options(self.folds, None, None)

    def trained_labels(self) -> tuple[str, ...]:
        return ()

    def reads_fold_column(self) -> bool:
        return True

    def rounds(self, cameras, log) -> list[Round]:
        return [Round(index) for index in range(len(cameras))]

    def models(self, inputs, *, progress, log) -> FolderModels:
        from ccjax import training as learning

        data = inputs.data
        given = None
        if data.given_folds is not None:
            try:
                assigned = dict(zip(data.names, learning.assign_folds(data.names, self.folds, given=data.given_folds)))
            except ValueError as error:
                raise ValueError(f"folds: {error}") from None
            given = np.array([assigned[name] for name in data.path_names])
        fold_of, worlds = fold_worlds(inputs.world, data.truth, self.folds, given)
        _enough_images(data, self.folds)
        source = "the ground truth's fold column" if given is not None else "image i in fold i mod K"
        models = {method: [method_model(method, w) for w in worlds] for method in inputs.methods}
        return FolderModels(models, fold_of=fold_of, folds=self.folds, fold_source=source)


class TrainedInFolds(AbstractProtocol):
    """Learned methods trained within K folds (never on the fold they score), started from their fit
    to the world (or pretrained from spectra), beside ``methods`` fitted to the world. Folds from
    the CSV's fold column, else seeded, assigned in ground-truth order (as ``ccjax train --folds``).

    Attributes:
        folds: K (at least 2).
        train: the labels trained.
    """

    folds: int = eqx.field(static=True)
    train: tuple[str, ...] = eqx.field(static=True)

    def __check_init__(self) -> None:
        if not self.train:
            raise ValueError("train: expected at least one label to train within the folds")
        check_fold_options(self.folds, self.train, None)

    def trained_labels(self) -> tuple[str, ...]:
        return self.train

    def reads_fold_column(self) -> bool:
        return True

    def rounds(self, cameras, log) -> list[Round]:
        return [Round(index, (index,)) for index in range(len(cameras))]

    def models(self, inputs, *, progress, log) -> FolderModels:
        from ccjax import training as learning

        data, read, options = inputs.data, inputs.read, inputs.options
        try:
            folds = learning.assign_folds(data.names, self.folds, seed=options.seed, given=data.given_folds)
        except ValueError as error:
            raise ValueError(f"folds: {error}") from None
        assigned = dict(zip(data.names, folds))
        fold_of = np.array([assigned[name] for name in data.path_names])
        labels = list(inputs.trained)
        starts = trainable_starts(labels, inputs.world)
        _enough_images(data, self.folds)
        schedules = {
            label: learning.default_schedule(start, **options.schedule_changes()) for label, start in starts.items()
        }
        trained, validations = train_in_folds(
            data.source,
            starts,
            data.truth,
            data.path_names,
            fold_of,
            self.folds,
            items=data.source.usable(),
            schedules=schedules,
            preprocessing=read.preprocessing,
            dark=read.dark,
            progress=progress,
            log=log,
            pretraining=options.pretraining,
        )
        source = "the ground truth's fold column" if data.given_folds else f"seed {options.seed}"
        models = _fitted(inputs.methods, inputs.world, self.folds) | trained
        return FolderModels(
            models,
            fold_of=fold_of,
            folds=self.folds,
            fold_source=source,
            trained=labels,
            validations=validations,
            trained_models=trained,
        )


def _enough_images(data: FolderData, folds: int) -> None:
    usable = len(data.source.usable())
    if usable < folds:
        raise ValueError(f"folds: {folds} folds need at least {folds} usable images, got {usable}")


def check_fold_options(folds: int | None, train: Sequence[str] | None, epochs: int | None) -> None:
    """Refuse ``folds`` below 2, ``train`` without ``folds``, a label trained twice, and ``epochs``
    without ``train``, before any work.

    Arguments:
        folds, train, epochs: as :func:`evaluate_folder`.

    Returns:
        None.

    Raises:
        ValueError: naming the argument.
    """
    if folds is not None and (isinstance(folds, bool) or not isinstance(folds, int) or folds < 2):
        raise ValueError(f"folds: expected an integer >= 2 (the number of folds), got {folds}")
    if train:
        if folds is None:
            raise ValueError("train: needs folds (each method is trained on the other folds' images)")
        if len(set(train)) != len(train):
            raise ValueError(f"train: a label is given twice ({', '.join(train)})")
    if epochs is not None:
        if not train:
            raise ValueError("epochs: applies to train only")
        if epochs < 1:
            raise ValueError(f"epochs: expected a positive integer, got {epochs}")


def protocol_for(folds: int | None, train: Sequence[str] | None) -> AbstractProtocol:
    """The protocol that keyword options name: trained in folds, K folds, or fitted to the world.

    Arguments:
        folds: K, or None.
        train: labels trained within the folds (needs ``folds``; :func:`check_fold_options`).

    Returns:
        :class:`TrainedInFolds`, :class:`KFolds` or :class:`FittedToWorld`.
    """
    if train:
        assert folds is not None  # check_fold_options refused train without folds
        return TrainedInFolds(folds, tuple(train))
    return FittedToWorld() if folds is None else KFolds(folds)


def trainable_starts(labels: Sequence[str], world: World) -> dict[str, AbstractEstimator]:
    """``{label: its fit to world}`` (through the store) for training within folds, refusing labels
    with nothing to learn.

    Arguments:
        labels: registry labels.
        world: the world they are fitted to.

    Returns:
        The fitted starts.

    Raises:
        ValueError: naming ``train``, the label and the trainable families.
    """
    from ccjax import training
    from ccjax.runs import store

    starts = {}
    for label in labels:
        model = store.fit(label, world)
        try:
            training.learnable(model)
        except ValueError:
            raise ValueError(
                f"train: {label} ({type(model).__name__}) has no learnable parameters; trainable families: "
                f"{', '.join(training.learnable_types())} (e.g. C-by-C-MMSE, RGB-C-by-C-MMSE, grey-edge-1-6-2)"
            ) from None
        starts[label] = model
    return starts


def train_in_folds(
    source,
    starts: dict[str, AbstractEstimator],
    truth: np.ndarray,
    names: Sequence[str],
    fold_of: np.ndarray,
    folds: int,
    *,
    items: Sequence[int] | None = None,
    schedules: dict | None = None,
    preprocessing: str | Preprocessing | None = None,
    dark: float = DEFAULT_DARK,
    progress: bool = False,
    log: Callable[[str], None] | None = None,
    pretraining=None,
) -> tuple[dict[str, list[AbstractEstimator]], dict]:
    """Each start trained within the folds (:func:`ccjax.training.cross_validate`, never on the fold
    it scores) on exactly the inputs the evaluation gives it (:func:`ccjax.training.source_examples`).

    Arguments:
        source: the images (:class:`ccjax.runs.sources.ImageFolder`).
        starts: ``{label: start model}``.
        truth: ``(N, 3)`` the ground truth of each of the source's files.
        names: their ground-truth names.
        fold_of: ``(N,)`` their folds.
        folds: the number of folds.
        items: the source's files to train on (default: every one).
        schedules: ``{label: its ccjax.training.Schedule}`` (default, and for labels not in it:
            the family's, :func:`ccjax.training.default_schedule`).
        preprocessing, dark: the inputs' preparation.
        progress: progress bars.
        log: called with a line before each label's training.
        pretraining: a :class:`ccjax.training.Pretraining`: each start is first
            pretrained on images rendered from spectra and then fine-tuned within the folds
            (None: trained from its fit to the world).

    Returns:
        ``({"<label> trained": [model of fold 0, ...]}, {label: CrossValidation})``.

    Raises:
        ValueError: a fold whose training set (the other folds) has too few usable images.
    """
    from ccjax import training

    assignment = dict(zip(names, np.asarray(fold_of).tolist(), strict=True))
    models, validations = {}, {}
    for label, start in starts.items():
        examples, _ = training.source_examples(  # failures: the evaluation pass reports them
            source,
            truth,
            names,
            start.input_kind,
            resolve(start, preprocessing),
            items=items,
            dark=dark,
            progress=progress,
        )
        scored = np.array([assignment[name] for name in examples.names])
        for fold in range(folds):
            trained_on = int(np.sum(scored != fold))
            if trained_on < MIN_TRAINING_IMAGES:
                raise ValueError(
                    f"folds: fold {fold}'s training set (the other folds) has {trained_on} usable images; training "
                    f"needs at least {MIN_TRAINING_IMAGES} (fewer folds or more images)"
                )
        schedule = (schedules or {}).get(label) or training.default_schedule(start)
        origin = "its fit to the world"
        if pretraining is not None:
            start, _ = training.pretrain(start, pretraining, resolve(start, preprocessing), schedule, progress=progress)
            origin = f"pretrained on {pretraining.images} images rendered with {pretraining.camera}'s curves"
        if log is not None:
            log(f"training {label} within {folds} folds on {len(examples)} images (start: {origin})")
        validation, fold_models = training.cross_validate(
            start, examples, scored, schedule, method=label, progress=progress, fine_tune=pretraining is not None
        )
        models[label + TRAINED_SUFFIX], validations[label] = fold_models, validation
    return models, validations
