"""Training the any-camera estimator (:mod:`ccjax.estimators.conditioned`) on labelled folders of
several cameras, and the folders a leave-one-camera-out fold keeps out.

Each folder's images are read in its own camera (never mapped into a target: the model has none),
each image's map into the reference space comes from its camera's curves, and camera
augmentation (:mod:`ccjax.runs.augmented`) adds copies of every image seen through other cameras,
drawn from the database and sampled, none of them a camera kept out or its twin.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np

from ccjax.evaluation.options import ReadOptions, TrainingOptions
from ccjax.evaluation.scored_folder import FolderData

__all__ = ["ANY_CAMERA", "kept_out", "train_any_camera"]

ANY_CAMERA = "any-camera"
"""The label of the camera-conditioned estimator."""


def kept_out(target: str, cameras: Sequence[str | None]) -> list[int]:
    """The folders whose camera is ``target`` or a twin of it (the same model from another source,
    or a fingerprint within :data:`ccjax.estimators.conditioned.TWIN_DEGREES`).

    Arguments:
        target: the scored folder's camera.
        cameras: every folder's camera (None: none given).

    Returns:
        The indices of the folders whose camera is ``target``'s twin (``target``'s own included).
    """
    from ccjax.camera import Camera
    from ccjax.estimators.conditioned import twins

    named = {name: Camera.from_name(name) for name in dict.fromkeys(c for c in cameras if c)}
    close = set(twins(named.get(target) or Camera.from_name(target), named))
    return [index for index, camera in enumerate(cameras) if camera in close]


def train_any_camera(
    training: Sequence[FolderData],
    read: ReadOptions,
    options: TrainingOptions,
    *,
    exclude: Sequence[str] = (),
    copies: int = 2,
    progress: bool = False,
    log: Callable[[str], None] | None = None,
):
    """Train one any-camera model on the labelled folders of several cameras.

    Arguments:
        training: the folders, each with its camera (its curves, or a named stand-in's).
        read: how images are read and prepared.
        options: the seed (of the augmentation's draws and the maps' worlds).
        exclude: cameras kept out of the augmentation with their twins (a fold's target).
        copies: augmented copies of each image (0: none).
        progress: progress bars.
        log: a line before the training.

    Returns:
        ``(unbound AnyCamera, record)``: the record (JSON-ready) names the cameras seen, each
        folder with its camera and images, the augmentation, the seconds and the seed.

    Raises:
        ValueError: no folder, a folder without a camera, or images of different sizes.
    """
    from ccjax import training as learning
    from ccjax.estimators import conditioned
    from ccjax.preprocessing import resolve
    from ccjax.runs.augmented import Augmentation, augment, augmentation_cameras

    if not training:
        raise ValueError("folders: expected at least one labelled folder to train any-camera on")
    missing = [folder.label for folder in training if not folder.camera]
    if missing:
        raise ValueError(f"folders: no camera for {', '.join(missing)}; any-camera needs every folder's curves")
    start = time.perf_counter()
    rule = resolve(conditioned.init_any_camera(), read.preprocessing)
    images, masks, lights, sources = [], [], [], []
    for folder in training:
        examples, _ = learning.source_examples(
            folder.source,
            folder.truth,
            folder.path_names,
            "image",
            rule,
            items=folder.source.usable(),
            dark=read.dark,
            progress=progress,
        )
        images.append(np.asarray(examples.x))
        masks.append(np.asarray(examples.mask))
        lights.append(np.asarray(examples.illuminant))
        sources.extend([str(folder.camera)] * len(examples))
    sizes = {image.shape[1:3] for image in images}
    if len(sizes) > 1:
        raise ValueError(f"folders: any-camera trains on images of one size, got {sorted(sizes)}")
    x, mask, light = np.concatenate(images), np.concatenate(masks), np.concatenate(lights)
    augmentation = Augmentation(copies=copies, seed=options.seed)
    bank = augmentation_cameras(list(exclude), augmentation) if copies else []
    entries = augment(light, sources, bank, augmentation, world_seed=options.seed)
    if log is not None:
        log(
            f"training any-camera on {len(x)} images of {len(set(sources))} cameras "
            f"and {len(entries.index) - len(x)} copies"
        )
    model, record = conditioned.train(x, mask, light, entries.matrices, index=entries.index)
    facts = {
        "camera": None,
        "conditioned": True,
        "cameras_seen": sorted(set(sources)),
        "folders": {
            folder.label: {
                "directory": str(folder.directory),
                "camera": folder.camera,
                "images": len(folder.source.usable()),
            }
            for folder in training
        },
        "augmentation": {
            "copies": copies,
            "cameras": [camera.name for camera in bank],
            "kept_out": list(exclude),
        },
        "images": int(len(x)),
        "entries": int(len(entries.index)),
        "seconds": round(time.perf_counter() - start, 1),
        "seed": options.seed,
    }
    return model, record, facts
