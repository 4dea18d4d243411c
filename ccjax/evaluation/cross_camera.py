"""Protocols that train on other cameras' labelled photographs: each training folder's images and
ground truth mapped into the scored folder's camera through the two cameras' curves
(:mod:`ccjax.transfer`, thesis §3–§4: a response is the integral of light x reflectance x
sensor), pooled (:class:`ccjax.runs.pooled.PooledImages`), optionally with images rendered
through the scored camera's curves, and the learned methods trained on the pool.

* :class:`LeaveOneCameraOut` -- each folder with a camera scored by models trained only on the
  *other* folders (the cross-dataset protocol of C5, Afifi et al. ICCV 2021, and SIIE, Afifi &
  Brown BMVC 2019, with the camera's curves as the bridge);
* :class:`TrainOn` -- train on the named folders, score every other folder with a camera.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import replace

import equinox as eqx
import jax.numpy as jnp

from ccjax.evaluation.any_camera import ANY_CAMERA, kept_out, train_any_camera
from ccjax.evaluation.options import ReadOptions, TrainingOptions
from ccjax.evaluation.photo_protocols import AbstractProtocol, Round, RoundInputs
from ccjax.evaluation.scored_folder import TRAINED_SUFFIX, FolderData, FolderModels
from ccjax.evaluation.sets import FolderSet
from ccjax.world import World

__all__ = [
    "ADAPTED_SUFFIX",
    "CAMERA_MAPS",
    "LeaveOneCameraOut",
    "TrainOn",
    "pooled_source",
    "train_for_camera",
    "train_on_pool",
    "train_pooled",
]

ADAPTED_SUFFIX = " adapted"
"""The label suffix of a trained model adapted to the scored folder's unlabelled images."""

CAMERA_MAPS = ("global", "per-light")
"""The camera-to-camera maps a pooled training can use (:func:`ccjax.transfer.fit_camera_map`)."""


def _check(train: tuple[str, ...], camera_map: str, rendered: int) -> None:
    if not train:
        raise ValueError("train: expected at least one label to train on the other cameras' folders")
    if len(set(train)) != len(train):
        raise ValueError(f"train: a label is given twice ({', '.join(train)})")
    if camera_map not in CAMERA_MAPS:
        raise ValueError(f"camera_map: expected one of {', '.join(CAMERA_MAPS)}, got {camera_map!r}")
    if isinstance(rendered, bool) or not isinstance(rendered, int) or rendered < 0:
        raise ValueError(f"rendered: expected a non-negative number of rendered images, got {rendered!r}")


def _with_cameras(cameras: Sequence[str | None], log: Callable[[str], None] | None) -> list[int]:
    """The folders that have a camera; the others named as left out."""
    without = [index for index, camera in enumerate(cameras) if not camera]
    if without and log is not None:
        log(
            f"left out: {len(without)} folder(s) without a camera (folder index {', '.join(map(str, without))}): "
            "their images cannot be mapped into another camera, nor another camera's into theirs"
        )
    return [index for index, camera in enumerate(cameras) if camera]


class LeaveOneCameraOut(AbstractProtocol):
    """Each folder with a camera scored by models trained only on the other folders, mapped into its
    camera; folders without a camera are named and left out.

    Attributes:
        train: the labels trained on the pool (e.g. ``("FFCC",)``).
        camera_map: ``"per-light"`` (the map of each image's own light) or ``"global"`` (one 3x3).
        rendered: images rendered through the scored camera's curves pooled in (0: none).
        adapt: also score each trained FFCC with its light prior adapted to the scored folder's
            *unlabelled* images (label ``"<label> adapted"``, :func:`adapt_to_images`; its ground
            truth is never read).
        twins_out: also keep out of each fold the folders whose camera is the scored folder's
            camera or its twin (:func:`ccjax.evaluation.any_camera.kept_out`).
        copies: the any-camera estimator's augmented copies of each training image.
    """

    train: tuple[str, ...] = eqx.field(static=True)
    camera_map: str = eqx.field(static=True, default="per-light")
    rendered: int = eqx.field(static=True, default=0)
    adapt: bool = eqx.field(static=True, default=False)
    twins_out: bool = eqx.field(static=True, default=False)
    copies: int = eqx.field(static=True, default=2)

    def __check_init__(self) -> None:
        _check(self.train, self.camera_map, self.rendered)
        if ANY_CAMERA in self.train and self.rendered:
            raise ValueError("rendered: images rendered through the scored camera are refused for any-camera")
        if isinstance(self.copies, bool) or not isinstance(self.copies, int) or self.copies < 0:
            raise ValueError(f"copies: expected a non-negative integer, got {self.copies!r}")

    def trained_labels(self) -> tuple[str, ...]:
        return self.train

    def reads_fold_column(self) -> bool:
        return False

    def rounds(self, cameras, log) -> list[Round]:
        chosen = _with_cameras(cameras, log)
        if len(chosen) < 2:
            raise ValueError(
                f"folders: leave-one-camera-out needs at least two folders with a camera, got {len(chosen)}"
            )
        rounds = []
        for index in chosen:
            out = set(kept_out(str(cameras[index]), cameras)) if self.twins_out else set()
            training = tuple(other for other in chosen if other != index and other not in out)
            if not training:
                raise ValueError(f"twins_out: folder index {index} has no folder left to train on")
            rounds.append(Round(index, training))
        return rounds

    def models(self, inputs, *, progress, log) -> FolderModels:
        pooled = [label for label in inputs.trained if label != ANY_CAMERA]
        if not pooled:
            from ccjax.runs import store

            fitted = {label: [store.fit(label, inputs.world)] for label in inputs.methods}
            models = FolderModels(fitted, training_notes=[])
        else:  # the any-camera estimator is not trained on the pool: it is trained below
            pooled_inputs = replace(inputs, trained=pooled)
            models = train_on_pool(pooled_inputs, self.camera_map, self.rendered, progress, log, adapt=self.adapt)
        if ANY_CAMERA not in inputs.trained:
            return models
        target, training = str(inputs.data.camera), inputs.training
        model, _, facts = train_any_camera(
            training, inputs.read, inputs.options, exclude=(target,), copies=self.copies, progress=progress, log=log
        )
        models.models[ANY_CAMERA + TRAINED_SUFFIX] = [model.bind(inputs.world.camera)]
        notes = list(models.training_notes or [])
        notes.append(
            f"{ANY_CAMERA} trained on {facts['images']} images of {', '.join(f.label for f in training)} "
            f"({', '.join(facts['cameras_seen'])}) and {facts['entries'] - facts['images']} copies through "
            f"{len(facts['augmentation']['cameras'])} other cameras, bound to {target}'s curves, "
            f"in {facts['seconds']:.1f} s"
        )
        return FolderModels(models.models, training_notes=notes)


class TrainOn(AbstractProtocol):
    """Train on the named folders (mapped into each scored folder's camera), score every other
    folder with a camera.

    Attributes:
        training: the indices of the training folders (in the order the folders are given).
        train: the labels trained.
        camera_map: as :class:`LeaveOneCameraOut`.
        rendered: as :class:`LeaveOneCameraOut`.
    """

    training: tuple[int, ...] = eqx.field(static=True)
    train: tuple[str, ...] = eqx.field(static=True)
    camera_map: str = eqx.field(static=True, default="per-light")
    rendered: int = eqx.field(static=True, default=0)

    def __check_init__(self) -> None:
        _check(self.train, self.camera_map, self.rendered)
        if not self.training:
            raise ValueError("training: expected at least one training folder")

    def trained_labels(self) -> tuple[str, ...]:
        return self.train

    def reads_fold_column(self) -> bool:
        return False

    def rounds(self, cameras, log) -> list[Round]:
        chosen = _with_cameras(cameras, log)
        missing = [index for index in self.training if index not in chosen]
        if missing:
            raise ValueError(f"training: folder(s) {missing} have no camera (or do not exist): cannot be mapped")
        scored = [index for index in chosen if index not in self.training]
        if not scored:
            raise ValueError("training: every folder with a camera is a training folder; none is left to score")
        return [Round(index, self.training) for index in scored]

    def models(self, inputs, *, progress, log) -> FolderModels:
        return train_on_pool(inputs, self.camera_map, self.rendered, progress, log)


def pooled_source(training: Sequence[FolderData], target: str, camera_map: str, *, seed: int = 0):
    """The training folders mapped into ``target``'s raw space as one image source.

    Arguments:
        training: the labelled folders, each with its camera.
        target: the target camera.
        camera_map: ``"global"`` or ``"per-light"`` (:func:`ccjax.transfer.fit_camera_map`),
            fitted on each source camera's default world.
        seed: the worlds' seed.

    Returns:
        :class:`ccjax.runs.pooled.PooledImages`.
    """
    from ccjax.runs import store
    from ccjax.runs.pooled import MappedFolder, PooledImages
    from ccjax.transfer import fit_camera_map

    parts = []
    for folder in training:
        if folder.camera is None:
            raise ValueError(f"training: folder {folder.label} has no camera; its images cannot be mapped")
        fitted = None
        if folder.camera != target:
            fitted = fit_camera_map(
                folder.camera,
                target,
                kind="global" if camera_map == "global" else "per-light",
                world=store.world("default", folder.camera, seed=seed),
            )
        parts.append(MappedFolder(folder.source, folder.truth, folder.path_names, folder.camera, fitted, folder.label))
    return PooledImages(parts, target)


def train_on_pool(
    inputs: RoundInputs,
    camera_map: str,
    rendered: int,
    progress: bool,
    log: Callable[[str], None] | None,
    *,
    adapt: bool = False,
) -> FolderModels:
    """The scored folder's models: ``inputs.methods`` fitted to its world, ``inputs.trained``
    trained on the training folders mapped into its camera (and ``rendered`` images of its camera).

    Arguments:
        inputs: the round (:class:`~ccjax.evaluation.photo_protocols.RoundInputs`); the scored
            folder's camera is the target.
        camera_map: the map's kind.
        rendered: images rendered through the target's curves pooled in.
        progress: progress bars.
        log: a line per training.
        adapt: adapt each trained FFCC to the scored folder's images, never its ground truth
            (:func:`adapt_to_images`).

    Returns:
        :class:`~ccjax.evaluation.scored_folder.FolderModels` (no folds; a training note per label).
    """
    from ccjax.runs import store

    data, training, world, read, options = inputs.data, inputs.training, inputs.world, inputs.read, inputs.options
    target = data.camera
    if target is None:
        raise ValueError(f"folders: {data.label} has no camera; a model mapped into it needs its curves")
    pool = pooled_source(training, target, camera_map, seed=options.seed)
    models = {label: [store.fit(label, world)] for label in inputs.methods}
    notes = []
    parts = ", ".join(
        f"{folder.label} ({folder.camera}{'' if folder.camera == target else ', mapped ' + camera_map})"
        for folder in training
    )
    for label in inputs.trained:
        model, record, images = train_pooled(label, pool, world, read, options, rendered, progress=progress, log=log)
        models[label + TRAINED_SUFFIX] = [model]
        if adapt and label == "FFCC":  # scored beside the model it adapts: the zero-adaptation figure in the same run
            lights = pool.lights()[pool.usable()]
            models[label + ADAPTED_SUFFIX] = [
                adapt_to_images(model, data.source, target, lights, read, seed=options.seed, progress=progress)
            ]
        extra = f" and {rendered} rendered through {target}'s curves" if rendered else ""
        if adapt:
            extra += f"; light prior adapted to {len(data.source.usable())} unlabelled images of {data.label}"
        notes.append(f"{label} trained on {images} images of {parts}{extra} in {record.seconds:.1f} s")
    return FolderModels(models, training_notes=notes)


def adapt_to_images(
    model,
    images,
    target: str,
    training_lights,
    read: ReadOptions,
    *,
    seed: int = 0,
    options=None,
    progress: bool = False,
):
    """``model`` (a trained FFCC) with its light prior adapted to the target camera: the target's
    *unlabelled* images estimated by the model, the prior re-weighted toward their lights by EM
    and blended with the target's Planckian and daylight loci rendered through its curves
    (:func:`ccjax.estimators.ffcc.adapt_bias`). Only the images are read, never a ground truth.

    Arguments:
        model: the trained model (an :class:`~ccjax.estimators.ffcc.FFCC`; other models refused).
        images: the target's images (:func:`ccjax.runs.sources.image_folder`), any labels unread.
        target: the target camera (its curves give the loci).
        training_lights: ``(S, 3)`` the lights the model was trained on, in the target's raw space.
        read: the inputs' preparation (as the training's).
        seed: the target world's seed.
        options: :class:`~ccjax.estimators.ffcc.AdaptOptions` (default: its defaults).
        progress: a progress bar while reading.

    Returns:
        The adapted model.

    Raises:
        ValueError: a model other than FFCC, or no usable image.
    """
    import numpy as np

    from ccjax import training as learning
    from ccjax.estimators import ffcc
    from ccjax.estimators.neural import log_chroma
    from ccjax.preprocessing import resolve
    from ccjax.runs import store
    from ccjax.transfer import locus_lights

    if not isinstance(model, ffcc.FFCC):
        raise ValueError(f"adapt: adapts FFCC's light prior only, got {type(model).__name__}")
    rule = resolve(model, read.preprocessing)
    items = images.usable()
    # The labels are never read: every image is given the same placeholder light.
    placeholder = np.ones((len(images), 3), np.float32)
    names = [str(path) for path in images.paths]
    examples, _ = learning.source_examples(
        images, placeholder, names, model.input_kind, rule, items=items, dark=read.dark, progress=progress
    )
    histograms = ffcc.histograms(model, examples.x, examples.mask)
    camera = store.world("default", target, seed=seed).camera
    loci = np.asarray(locus_lights(), np.float64) @ np.asarray(camera.sensors, np.float64)
    adapted, _ = ffcc.adapt_bias(
        model,
        histograms,
        log_chroma(jnp.asarray(training_lights, jnp.float32)),
        log_chroma(jnp.asarray(loci, jnp.float32)),
        options or ffcc.AdaptOptions(),
    )
    return adapted


def train_pooled(
    label: str,
    pool,
    world: World,
    read: ReadOptions,
    options: TrainingOptions,
    rendered: int = 0,
    *,
    progress: bool = False,
    log: Callable[[str], None] | None = None,
):
    """Train ``label`` for the pool's target camera on the pooled images (and ``rendered`` images
    rendered through the target's curves), started from its fit to the target's world (or
    pretrained from spectra when ``options.pretraining`` says so).

    Arguments:
        label: a trainable registry label (e.g. ``"FFCC"``).
        pool: the mapped folders (:func:`pooled_source`).
        world: the target camera's world.
        read: the inputs' preparation.
        options: seed, epochs, pretraining.
        rendered: images rendered through the target's curves pooled in.
        progress: progress bars.
        log: a line before the training.

    Returns:
        ``(trained model, ccjax.training.TrainingLog, training images)``.
    """
    from ccjax import training as learning
    from ccjax.evaluation.photo_protocols import trainable_starts
    from ccjax.preprocessing import resolve

    start = trainable_starts([label], world)[label]
    rule = resolve(start, read.preprocessing)
    examples, _ = learning.source_examples(
        pool, pool.lights(), pool.names, start.input_kind, rule, items=pool.usable(), dark=read.dark, progress=progress
    )
    if rendered:
        pretraining = learning.Pretraining(camera=pool.target, images=rendered, seed=options.seed)
        synthetic = learning.render_examples(pretraining, rule, start.input_kind, dark=read.dark, progress=progress)
        examples = learning.Examples(
            jnp.concatenate([examples.x, synthetic.x]),
            jnp.concatenate([examples.mask, synthetic.mask]),
            jnp.concatenate([examples.illuminant, synthetic.illuminant]),
            examples.names + synthetic.names,
        )
    schedule = learning.default_schedule(start, **options.schedule_changes())
    fine_tune = options.pretraining is not None
    if fine_tune:
        start, _ = learning.pretrain(start, options.pretraining, rule, schedule, progress=progress)
    if log is not None:
        cameras = ", ".join(f"{folder} {count}" for folder, count in pool.counts().items())
        log(f"training {label} for the {pool.target} on {len(examples)} images ({cameras}; rendered {rendered})")
    model, record = learning.train_model(start, examples, schedule, progress=progress, fine_tune=fine_tune)
    return model, record, len(examples)


def train_for_camera(
    folders: Sequence[FolderSet],
    label: str,
    target: str,
    *,
    camera_map: str = "per-light",
    rendered: int = 0,
    read: ReadOptions | None = None,
    options: TrainingOptions | None = None,
    adapt_on: str | os.PathLike | None = None,
    progress: bool = False,
    log: Callable[[str], None] | None = None,
):
    """A model of ``label`` for ``target``, a camera none of the folders need have been taken with:
    every folder's images and ground truth mapped into the target's raw space through the cameras'
    curves (:func:`pooled_source`), pooled, and the model trained on them (:func:`train_pooled`).

    Arguments:
        folders: the labelled folders, each with its camera (its curves, or a named stand-in's).
        label: a trainable registry label (e.g. ``"FFCC"``).
        target: the camera the model is for (an embedded or external camera's name).
        camera_map: ``"per-light"`` or ``"global"`` (:func:`ccjax.transfer.fit_camera_map`).
        rendered: images rendered through the target's curves pooled in.
        read: how images are read and prepared (default :class:`ReadOptions`).
        options: seed, epochs, pretraining (default :class:`TrainingOptions`).
        adapt_on: a folder of the target camera's *unlabelled* images: FFCC's light prior adapted
            to them (:func:`adapt_to_images`; a ground-truth file there is never read).
        progress: progress bars.
        log: a line per folder and before the training.

    Returns:
        ``(model, ccjax.training.TrainingLog, record)``: the record (JSON-ready) names the target,
        the map, each folder with its camera and images, the rendered images and the seed.

    Raises:
        ValueError: no folder, a folder without a camera, or what reading a folder refuses.
    """
    from ccjax.evaluation.scored_folder import read_folder
    from ccjax.runs import store

    read, options = read or ReadOptions(), options or TrainingOptions()
    _check((label,), camera_map, rendered)
    if not folders:
        raise ValueError("folders: expected at least one labelled folder")
    missing = [folder.label for folder in folders if not folder.camera]
    if missing:
        raise ValueError(f"folders: no camera for {', '.join(missing)}; their images cannot be mapped into {target}")
    data = []
    for folder in folders:
        try:
            data.append(
                read_folder(folder.directory, folder.ground_truth, read, camera=folder.camera, label=folder.label)
            )
        except ValueError as error:
            raise ValueError(f"{error} (folder {folder.label})") from None
    world = store.world("default", target, seed=options.seed)
    pool = pooled_source(data, target, camera_map, seed=options.seed)
    model, record, images = train_pooled(label, pool, world, read, options, rendered, progress=progress, log=log)
    adapted = None
    if adapt_on is not None:
        from ccjax.runs.sources import image_folder, raise_failures

        unlabelled = image_folder(adapt_on, masks=read.masks, read_options=read.image, max_pixels=read.max_pixels)
        if not unlabelled.usable():
            raise_failures(list(unlabelled.failures.values()), len(unlabelled))
        lights = pool.lights()[pool.usable()]
        model = adapt_to_images(model, unlabelled, target, lights, read, seed=options.seed, progress=progress)
        adapted = {"directory": str(adapt_on), "images": len(unlabelled.usable())}
    facts = {
        "target_camera": target,
        "camera_map": camera_map,
        "source_folders": {
            item.label: {"directory": str(item.directory), "camera": item.camera, "images": len(item.paths)}
            for item in data
        },
        "source_images": {item.label: len(item.source.usable()) for item in data},
        "rendered": rendered,
        "images": images,
        "seed": options.seed,
        "adapted_on": adapted,
    }
    return model, record, facts
