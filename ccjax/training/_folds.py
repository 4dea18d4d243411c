"""Training estimators on image sets with K-fold cross-validation: reproducible fold assignment (or
a ``fold`` column of the ground-truth CSV, as in the Gehler–Shi three-fold split), training within
folds (never on the fold that is scored); the model files are :func:`ccjax.runs.store.save_trained`'s."""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field

import numpy as np

from ccjax.estimators.base import AbstractEstimator
from ccjax.io.ground_truth import match_ground_truth, read_ground_truth_file
from ccjax.io.reading import MAX_PIXELS
from ccjax.preprocessing import resolve
from ccjax.training._data import Examples, read_examples
from ccjax.training._loop import Schedule, TrainingLog, angular_errors
from ccjax.training._pretraining import Pretraining, pretrain
from ccjax.training._procedures import default_schedule, procedure_record, train_model


def read_folds(ground_truth: str | os.PathLike) -> dict[str, int] | None:
    """The ``fold`` column of a ground-truth CSV (header ``image,r,g,b,...,fold``), or ``None``
    when it has none (:func:`ccjax.io.read_ground_truth_file`, which reads the lights with it).

    Arguments:
        ground_truth: the CSV file.

    Returns:
        ``{image name: fold}`` with the file's fold labels (any integers).
    """
    return read_ground_truth_file(ground_truth).folds


def assign_folds(names, k: int, *, seed: int = 0, given: dict[str, int] | None = None) -> np.ndarray:
    """Fold of every example, ``0 .. k-1``.

    Arguments:
        names: the examples' image names, in order.
        k: number of folds (>= 2).
        seed: seed of the random assignment (a permutation cut into ``k`` near-equal parts).
        given: ``{name: fold label}`` (from :func:`read_folds`); its ``k`` distinct labels are
            numbered in sorted order.

    Returns:
        ``(N,)`` int fold indices.
    """
    names = list(names)
    if isinstance(k, bool) or not isinstance(k, int) or k < 2:
        raise ValueError(f"folds: expected an integer >= 2, got {k!r}")
    if len(names) < k:
        raise ValueError(f"folds: {k} folds need at least {k} images, got {len(names)}")
    if given is not None:
        missing = [name for name in names if name not in given]
        if missing:
            raise ValueError(f"fold column: no fold for {len(missing)} images, e.g. {missing[:3]}")
        labels = sorted({given[name] for name in names})
        if len(labels) != k:
            raise ValueError(f"fold column: has {len(labels)} distinct folds {labels}, but --folds is {k}")
        return np.array([labels.index(given[name]) for name in names])
    folds = np.empty(len(names), int)
    folds[np.random.default_rng(seed).permutation(len(names))] = np.arange(len(names)) % k
    return folds


@dataclass
class FoldResult:
    """One fold: its test examples' errors for the trained and the untrained (start) model.

    Attributes:
        fold: the fold index.
        test_names: the examples scored (this fold's).
        trained_errors, untrained_errors: their angular errors (degrees).
        log: the training log of this fold's model.
        train_names: the examples the model was trained on (the other folds', its early-stopping
            split included): disjoint from ``test_names``.
    """

    fold: int
    test_names: list[str]
    trained_errors: np.ndarray
    untrained_errors: np.ndarray
    log: TrainingLog
    train_names: list[str] = field(default_factory=list)

    def summary(self) -> dict:
        return {
            "fold": self.fold,
            "n_test": len(self.test_names),
            "trained_median": float(np.median(self.trained_errors)),
            "trained_mean": float(np.mean(self.trained_errors)),
            "untrained_median": float(np.median(self.untrained_errors)),
            "untrained_mean": float(np.mean(self.untrained_errors)),
            "n_train": len(self.train_names),
            "train_seconds": self.log.seconds,
            "train_cpu_seconds": self.log.cpu_seconds,
            "epochs": len(self.log.heldout_median),
            "best_epoch": self.log.best_epoch,
        }


@dataclass
class CrossValidation:
    """K-fold results and the pooled errors (every example scored once, by the model trained
    without its fold).

    Attributes:
        method: the method's label.
        folds: one :class:`FoldResult` per fold.
    """

    method: str
    folds: list[FoldResult] = field(default_factory=list)

    def pooled(self, which: str = "trained") -> np.ndarray:
        return np.concatenate([getattr(fold, f"{which}_errors") for fold in self.folds])

    def table(self) -> str:
        lines = [
            f"{self.method}: angular error (degrees), trained within folds vs the spectral fit",
            f"{'fold':>6}{'images':>8}{'trained median':>16}{'mean':>8}{'untrained median':>18}{'mean':>8}"
            f"{'train s':>9}{'epoch':>7}",
        ]
        for result in self.folds:
            row = result.summary()
            lines.append(
                f"{row['fold']:>6}{row['n_test']:>8}{row['trained_median']:>16.3f}{row['trained_mean']:>8.3f}"
                f"{row['untrained_median']:>18.3f}{row['untrained_mean']:>8.3f}{row['train_seconds']:>9.1f}"
                f"{row['best_epoch']:>7}"
            )
        trained, untrained = self.pooled("trained"), self.pooled("untrained")
        lines.append(
            f"{'pooled':>6}{len(trained):>8}{np.median(trained):>16.3f}{np.mean(trained):>8.3f}"
            f"{np.median(untrained):>18.3f}{np.mean(untrained):>8.3f}"
        )
        return "\n".join(lines)


def cross_validate(
    model: AbstractEstimator,
    examples: Examples,
    folds: np.ndarray,
    schedule: Schedule | None = None,
    *,
    method: str = "",
    progress: bool = True,
    fine_tune: bool = False,
) -> tuple[CrossValidation, list[AbstractEstimator]]:
    """Train ``model`` once per fold on the other folds' examples and score it on the fold.

    Arguments:
        model: the fitted start model (the same start for every fold).
        examples: all examples.
        folds: ``(N,)`` fold index of each example (:func:`assign_folds`).
        schedule: the training schedule (default: the family's, :func:`default_schedule`; its
            held-out split is taken from the training folds).
        method: the label, for the report.
        progress: progress bars.
        fine_tune: ``model`` was pretrained; each fold refines it (:func:`train_model`).

    Returns:
        ``(CrossValidation, the K trained models)``.
    """
    schedule = schedule or default_schedule(model)
    folds = np.asarray(folds)
    if folds.shape != (len(examples),):
        raise ValueError(f"folds: expected shape ({len(examples)},), got {folds.shape}")
    untrained = angular_errors(model, examples)
    result, models = CrossValidation(method=method), []
    names = list(examples.names) if examples.names else [str(i) for i in range(len(examples))]
    for fold in np.unique(folds):
        test = np.flatnonzero(folds == fold)
        train = np.flatnonzero(folds != fold)  # never the scored fold (early stopping splits these)
        trained, log = train_model(model, examples.take(train), schedule, progress=progress, fine_tune=fine_tune)
        errors = angular_errors(trained, examples.take(test))
        result.folds.append(
            FoldResult(int(fold), [names[i] for i in test], errors, untrained[test], log, [names[i] for i in train])
        )
        models.append(trained)
    return result, models


def train_on_images(
    directory: str | os.PathLike,
    ground_truth: str | os.PathLike,
    method: str,
    *,
    camera: str | None = None,
    world_seed: int = 0,
    folds: int | None = None,
    fold_seed: int = 0,
    schedule: Schedule | None = None,
    out: str | os.PathLike | None = None,
    progress: bool = True,
    max_pixels: int | None = MAX_PIXELS,
    overwrite: bool = True,
    pretraining: Pretraining | None = None,
    read_options: dict | None = None,
) -> tuple[AbstractEstimator, TrainingLog, CrossValidation | None]:
    """Train the estimator ``method`` on a folder of images with ground truth.

    The start is ``method`` fitted to ``World.default(camera)`` (the physics: e.g. the Colour by
    Correlation matrix from the camera's curves); each image gets the input ``ccjax evaluate`` gives
    the method (:func:`ccjax.training.read_examples`); its learnable parameters are trained
    (:func:`fit_to_examples`). With ``folds``, it is first cross-validated (folds from the CSV's
    ``fold`` column when present, else a seeded random assignment); the returned model is then
    trained on every image.

    Arguments:
        directory: the image folder.
        ground_truth: its CSV.
        method: a registry label of a trainable family.
        camera: camera of the default world the start is fitted to (None: ``World.default``'s).
            The model file records it when it is given or the family is world-based (its start
            is the camera's spectral fit), and records none otherwise (FFCC, the log-chroma MLP
            and grey edge learn from the photographs alone).
        world_seed: that world's seed.
        folds: number of cross-validation folds (``None``: none).
        fold_seed: seed of the random fold assignment.
        schedule: training schedule (default: the family's, :func:`default_schedule`).
        out: where to save the final model (``None``: not saved).
        progress: progress bars.
        max_pixels: the pixel budget of the image headers (default 100 MP; None: no limit).
        overwrite: replace an existing ``out`` (and its record).
        pretraining: pretrain the start on images rendered from spectra, then fine-tune it on the
            photographs (:func:`ccjax.training.pretrain`; None: no pretraining).
        read_options: how the files are read, keyword arguments of :func:`ccjax.io.read_image`
            (e.g. ``{"black_level": 2048, "saturation": 15000}``, as ``ccjax evaluate`` reads them;
            its ``max_pixels`` replaces the argument above).

    Returns:
        ``(trained model, its TrainingLog, CrossValidation or None)``.
    """
    from ccjax.runs import store

    world = store.world("default", camera, seed=world_seed)
    start = store.fit(method, world)
    recorded_camera = camera if camera is not None or not start.world_based else world.camera.name
    schedule = schedule or default_schedule(start)
    # The inputs ``ccjax evaluate`` gives the method (its default preprocessing), as ``evaluate --train``.
    table = read_ground_truth_file(ground_truth)
    pairs = match_ground_truth(table.lights, directory)
    lights = np.stack([light for _, light in pairs])
    examples, failures = read_examples(
        [path for path, _ in pairs],
        lights,
        list(table.lights),
        start,
        progress=progress,
        read_options={"max_pixels": max_pixels, **(read_options or {})},
    )
    if failures:
        raise ValueError(f"{len(failures)} images cannot be used for training:\n  " + "\n  ".join(failures.values()))
    tune = pretraining is not None
    if pretraining is not None:
        start, _ = pretrain(start, pretraining, resolve(start), schedule, progress=progress)
    validation = None
    if folds is not None:
        assignment = assign_folds(examples.names, folds, seed=fold_seed, given=table.folds)
        validation, _ = cross_validate(
            start, examples, assignment, schedule, method=method, progress=progress, fine_tune=tune
        )
    model, log = train_model(start, examples, schedule, progress=progress, fine_tune=tune)
    if out is not None:
        record = {**procedure_record(start, schedule, fine_tune=tune), "log": log.as_dict()}
        if pretraining is not None:
            record["pretraining"] = asdict(pretraining)
        store.save_trained(
            out, model, label=method, camera=recorded_camera, world_seed=world_seed, record=record, overwrite=overwrite
        )
    return model, log, validation
