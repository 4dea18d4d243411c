"""Evaluating methods on a folder of images with ground truth, optionally with K-fold cross-validation
and with methods trained within the folds (what ``ccjax evaluate`` runs).

:func:`evaluate_folder` reads the ground truth once (lights and the optional fold column), assigns
folds, builds the fold worlds or trains each listed method within the folds (never on the fold it
scores, on exactly the inputs the evaluation gives it), runs every method through the execution
layer's image loop (:func:`ccjax.runs.images.run_models`) and returns a
:class:`FolderEvaluation`: the statistics, per fold and pooled, the training record, the camera
check, and the JSON / CSV reports.
"""

from __future__ import annotations

import csv
import io as text_io
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ccjax.estimators.base import AbstractEstimator
from ccjax.experiments._cameras import CurveCheck, curve_check
from ccjax.experiments._fold_tables import fold_table, training_table
from ccjax.experiments.evaluation import ImageResults, fold_worlds
from ccjax.io.reading import MAX_PIXELS
from ccjax.preprocessing import DEFAULT_DARK, Preprocessing, resolve
from ccjax.world import World

TRAINED_SUFFIX = " trained"
"""Suffix of a method trained within folds (``train=``) in the tables and reports."""

CSV_FIELDS = ("path", "method", "preprocessing", "R", "G", "B", "r", "g", "ok", "status", "angular")
"""Columns of :meth:`FolderEvaluation.csv`: one row per image and method."""

MIN_TRAINING_IMAGES = 4
"""The fewest images a fold's training set may have (training holds some out for early stopping)."""


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
        check: the ground truth against the world's camera (:func:`ccjax.experiments._cameras.curve_check`),
            when it was asked for or a method is world-based.
        failures: one failure record per image that could not be used, in path order.
        total: how many images the ground truth lists.
        unlisted: the image files of the folder without a ground-truth row (not scored; only with
            ``allow_missing``).
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
                    r["path"],
                    r["method"],
                    self.results.preprocessing.get(r["method"], ""),
                    *(f"{v:.9g}" for v in r["illuminant"] + r["rg"]),
                    str(r["ok"]),
                    r.get("status", ""),
                    f"{r['angular']:.9g}",
                ]
            )
        return buffer.getvalue()


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
    ground truths (:func:`ccjax.experiments.evaluation.fold_worlds`; folds from the CSV's fold
    column when it has one, else image i in fold i mod K, in path order). With ``train``, each
    listed label is started from its fit to ``world`` and trained within the folds (folds from the
    fold column, else seeded by ``seed`` in ground-truth order) and reported as
    ``"<label> trained"`` beside ``methods``, which are then fitted to ``world``.

    Arguments:
        directory: the image folder.
        ground_truth: CSV ``image,r,g,b[,fold]`` (:func:`ccjax.io.read_ground_truth_file`).
        methods: registry labels.
        world: the world (default :func:`ccjax.runs.store.world`); world-based methods need the
            camera that took the images.
        folds: K-fold cross-validation (K >= 2), or None.
        train: labels to train within the folds (needs ``folds``).
        epochs: training epochs at most (default: each family's schedule's,
            :func:`ccjax.training.default_schedule`).
        seed: seed of the training folds' assignment and of the training.
        preprocessing: one preprocessing for every method (None: each method's default).
        dark: the surface lists' dark rule.
        read_options: keyword arguments of :func:`ccjax.io.read_image`.
        masks: a folder of masks named by the images' stems, or None.
        check_camera: compare the ground truth with the world's camera
            (:func:`ccjax.experiments._cameras.curve_check`) even when no method is world-based.
        allow_missing: score the listed images when some image files of the folder have no
            ground-truth row (named in :attr:`FolderEvaluation.unlisted`) instead of refusing.
        progress: progress bars on stderr.
        log: called with a line for each warning and training step (e.g. ``print`` to stderr).
        max_pixels: the pixel budget: a file whose header claims more pixels is refused (a
            failure record) before anything is allocated for it (default 100 MP; None: no limit).
        pretraining: with ``train``, pretrain each start from spectra before its training
            (:func:`train_in_folds`).

    Returns:
        :class:`FolderEvaluation`.

    Raises:
        ValueError: bad options (naming ``folds``, ``train``, ``epochs``, ``masks``), a bad ground
            truth, image files without a ground-truth row (each named; unless ``allow_missing``),
            or no usable image (every file's failure record).
    """
    from ccjax import io, training
    from ccjax.runs import store
    from ccjax.runs.images import run_models
    from ccjax.runs.sources import image_folder, raise_failures

    check_fold_options(folds, train, epochs)
    train = list(train or [])
    table = io.read_ground_truth_file(ground_truth, with_folds=folds is not None)
    pairs = io.match_ground_truth(table.lights, directory)
    unlisted = [str(file) for file in io.unlisted_images(pairs, directory)]
    if unlisted and not allow_missing:
        # A silently smaller set is a different benchmark: the caller decides.
        raise ValueError(
            f"ground_truth: {len(unlisted)} image(s) in {directory} have no row in {ground_truth}: "
            f"{', '.join(unlisted)}; add their rows, or score the listed images only (allow_missing=True; "
            "--allow-missing on the command line)"
        )
    names = list(table.lights)
    assigned, fold_source = None, None
    if folds is not None:
        try:
            if train:
                # Folds of training: the CSV's fold column, else seeded; assigned in ground-truth
                # order (as ``ccjax train --folds``), so the same file and seed give the same folds.
                assigned = dict(zip(names, training.assign_folds(names, folds, seed=seed, given=table.folds)))
            elif table.folds is not None:
                # Fold worlds follow a published split when the CSV has one (else image i in fold i mod K).
                assigned = dict(zip(names, training.assign_folds(names, folds, given=table.folds)))
        except ValueError as error:
            raise ValueError(f"folds: {error}") from None
        if train:
            fold_source = "the ground truth's fold column" if table.folds else f"seed {seed}"
        else:
            fold_source = "the ground truth's fold column" if assigned is not None else "image i in fold i mod K"
    order = sorted(range(len(pairs)), key=lambda index: str(pairs[index][0]))
    pairs, names = [pairs[i] for i in order], [names[i] for i in order]
    paths, truth = [p for p, _ in pairs], np.stack([t for _, t in pairs])
    source = image_folder(paths, masks=masks, read_options=read_options, max_pixels=max_pixels)
    if not source.usable():
        raise_failures(list(source.failures.values()), len(paths))
    world = world if world is not None else store.world()
    starts = trainable_starts(train, world) if train else {}
    fold_of = None
    if train:
        assert assigned is not None and folds is not None  # train needs folds (check_fold_options)
        fold_of = np.array([assigned[name] for name in names])
        models = {label: [store.fit(label, world)] * folds for label in methods}
    elif folds is not None:
        given_folds = None if assigned is None else np.array([assigned[name] for name in names])
        fold_of, worlds = fold_worlds(world, truth, folds, given_folds)
        models = {label: [store.fit(label, w) for w in worlds] for label in methods}
    else:
        models = {label: [store.fit(label, world)] for label in methods}
    check = None
    if check_camera or any(model.world_based for model in [*(m[0] for m in models.values()), *starts.values()]):
        check = curve_check(truth, world)
        if not check.passed and log is not None:
            log(f"warning: {check.message()}; try `ccjax cameras --check {ground_truth} --camera NAME`")
    keep = source.usable()
    if folds is not None and len(keep) < folds:
        raise ValueError(f"folds: {folds} folds need at least {folds} usable images, got {len(keep)}")
    validations: dict = {}
    trained: dict = {}
    if starts:
        assert fold_of is not None and folds is not None
        changes = {"seed": seed} if epochs is None else {"seed": seed, "epochs": epochs}
        schedules = {label: training.default_schedule(start, **changes) for label, start in starts.items()}
        trained, validations = train_in_folds(
            source,
            starts,
            truth,
            names,
            fold_of,
            folds,
            items=keep,
            schedules=schedules,
            preprocessing=preprocessing,
            dark=dark,
            progress=progress,
            log=log,
            pretraining=pretraining,
        )
        models.update(trained)
    run = run_models(
        source, models, items=keep, fold_of=fold_of, preprocessing=preprocessing, dark=dark, progress=progress
    )
    results = ImageResults.from_run(run, truth[keep])
    merged = source.failures | run.failures
    failures = [merged[str(path)] for path in paths if str(path) in merged]
    scored = None if fold_of is None else fold_of[np.asarray(run.items)[run.done]]
    return FolderEvaluation(
        results=results,
        world=world.name,
        folds=folds,
        fold_source=fold_source,
        trained=train,
        fold_of=scored,
        validations=validations,
        trained_models=trained,
        check=check,
        failures=failures,
        total=len(paths),
        unlisted=unlisted,
    )
