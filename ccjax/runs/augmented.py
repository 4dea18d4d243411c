"""Camera augmentation from the curves: each labelled image of camera A also seen through other
cameras D, drawn from ccjax's database and sampled anew, for the any-camera estimator
(:mod:`ccjax.estimators.conditioned`).

A copy of an image in camera D is the image mapped by the per-light map A -> D of its own ground
truth ``e`` (:func:`ccjax.transfer.fit_camera_map`, fitted on A's default world), then into the
reference space by D's map ``R_D``: one 3x3 ``R_D M_AD(e)`` per copy, applied to the image and its
light alike. The original is ``R_A`` alone. So a copy costs a matrix, not an image: the
augmented set is ``(image index, matrix)`` pairs over the source images (:class:`Augmented`), and
the trainer maps each pair once (:func:`ccjax.estimators.conditioned.to_reference`). The copies
differ from the original by the maps' errors between cameras, which teaches the model what
binding an unseen camera by its curves costs.

Sampled cameras are convex blends of two or three database cameras' curves (each channel scaled
to unit area first), Dirichlet weights. Under leave-one-camera-out the target camera and its twins
(:func:`ccjax.estimators.conditioned.twins`) are kept out of the database draws and of every
sampled camera's blend, and a sampled camera whose fingerprint lies within
:data:`~ccjax.estimators.conditioned.TWIN_DEGREES` of the target is drawn again.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ccjax.camera import Camera, cameras
from ccjax.estimators.conditioned import TWIN_DEGREES, fingerprint_distance, reference_matrix, twins
from ccjax.transfer import AbstractCameraMap

__all__ = ["Augmentation", "Augmented", "augment", "augmentation_cameras"]


@dataclass(frozen=True)
class Augmentation:
    """How many copies and from which cameras.

    Attributes:
        copies: copies of each image (0: none), each in a camera drawn from the bank.
        database: database cameras in the bank (drawn from :func:`ccjax.cameras`).
        sampled: sampled new cameras in the bank.
        seed: the draws' seed.
    """

    copies: int = 2
    database: int = 12
    sampled: int = 6
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("copies", "database", "sampled", "seed"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name}: expected a non-negative integer, got {value!r}")
        if self.copies and not (self.database or self.sampled):
            raise ValueError("database, sampled: copies need at least one camera to be drawn")


@dataclass
class Augmented:
    """A training set of images with their maps into the reference space.

    Attributes:
        index: ``(K,)`` the source image of each entry.
        matrices: ``(K, 3, 3)`` each entry's map of the source image (and its light) into the
            reference space.
        cameras: each entry's camera name (the source's, or the copy's).
    """

    index: np.ndarray
    matrices: np.ndarray
    cameras: list[str]


def augmentation_cameras(
    exclude: Sequence[str], augmentation: Augmentation, *, names: Sequence[str] | None = None
) -> list[Camera]:
    """The bank of a fold: database cameras and sampled ones, none of them an excluded camera or
    a twin of one (module docstring).

    Arguments:
        exclude: the cameras kept out (the target of a leave-one-camera-out fold).
        augmentation: the bank's sizes and seed.
        names: the database (default: :func:`ccjax.cameras`).

    Returns:
        The cameras (database draws first).
    """
    names = list(cameras() if names is None else names)
    database = {name: Camera.from_name(name) for name in names}
    out: set[str] = set()
    for name in exclude:
        target = database.get(name) or Camera.from_name(name)
        out.update(twins(target, database))
    allowed = [name for name in names if name not in out]
    if not allowed:
        raise ValueError("exclude: every database camera is excluded; nothing to augment with")
    rng = np.random.default_rng(augmentation.seed)
    drawn = rng.choice(len(allowed), size=min(augmentation.database, len(allowed)), replace=False)
    bank = [database[allowed[i]] for i in sorted(drawn)]
    excluded = [database.get(name) or Camera.from_name(name) for name in exclude]
    while len(bank) < min(augmentation.database, len(allowed)) + augmentation.sampled:
        parts = rng.choice(len(allowed), size=int(rng.integers(2, 4)), replace=False)
        weights = rng.dirichlet(np.ones(len(parts)))
        curves = [np.asarray(database[allowed[i]].sensors, np.float64) for i in parts]
        blend = sum(w * c / c.sum(axis=0, keepdims=True) for w, c in zip(weights, curves, strict=True))
        sampled = Camera.from_array(np.asarray(blend, np.float32), name=f"sampled camera {len(bank)}")
        if all(fingerprint_distance(sampled, other) >= TWIN_DEGREES for other in excluded):
            bank.append(sampled)
    return bank


@eqx.filter_jit
def _matrices_for(camera_map, lights):
    return jax.vmap(camera_map.matrix_for)(lights)


def _per_light_matrices(camera_map: AbstractCameraMap, lights: np.ndarray) -> np.ndarray:
    """Each light's map (``camera_map.matrix_for``) as one compiled program per power-of-two
    count of lights: every (source, camera) pair's map has the same shapes, so a fold compiles a
    handful of programs, not one per pair (op by op under ``vmap``, 90 pairs cost 100 s of
    compiling).

    Arguments:
        camera_map: a camera map (:class:`~ccjax.transfer.PerLightMap` here).
        lights: ``(N, 3)`` the lights in the map's source camera, ``N >= 1``.

    Returns:
        ``(N, 3, 3)`` float64.
    """
    count = len(lights)
    size = 1 << max(0, (count - 1).bit_length())
    # Padded with copies of the first light: a valid light, its rows dropped below.
    padded = np.concatenate([lights, np.repeat(lights[:1], size - count, axis=0)])
    return np.asarray(_matrices_for(camera_map, jnp.asarray(padded)), np.float64)[:count]


def augment(
    lights: np.ndarray,
    sources: Sequence[str],
    bank: Sequence[Camera],
    augmentation: Augmentation,
    *,
    world_seed: int = 0,
) -> Augmented:
    """Every image with its own camera's map, and ``augmentation.copies`` copies of it into
    cameras of ``bank`` (module docstring).

    Arguments:
        lights: ``(N, 3)`` each image's ground truth in its own camera.
        sources: each image's camera name.
        bank: the cameras to copy into (:func:`augmentation_cameras`).
        augmentation: the copies and the seed.
        world_seed: the seed of the source cameras' default worlds (the maps' fitting lights).

    Returns:
        The :class:`Augmented` entries: the originals first, then the copies.
    """
    from ccjax.runs import store
    from ccjax.transfer import fit_camera_map

    lights = np.asarray(lights, np.float32)
    if len(sources) != len(lights):
        raise ValueError(f"sources: expected one camera per image ({len(lights)}), got {len(sources)}")
    own = {name: reference_matrix(Camera.from_name(name)) for name in dict.fromkeys(sources)}
    index = [np.arange(len(lights))]
    matrices = [np.stack([own[name] for name in sources])]
    names = list(sources)
    if augmentation.copies and bank:
        rng = np.random.default_rng(augmentation.seed + 1)
        chosen = rng.integers(0, len(bank), size=(augmentation.copies, len(lights)))
        into = [reference_matrix(camera) for camera in bank]
        source_array = np.asarray(sources)
        for source in own:
            world = store.world("default", source, seed=world_seed)
            for k, camera in enumerate(bank):
                _, image = np.nonzero((chosen == k) & (source_array == source)[None, :])
                if not len(image):
                    continue
                camera_map = fit_camera_map(source, camera, world=world)
                per_light = _per_light_matrices(camera_map, lights[image])
                index.append(image)
                matrices.append(into[k] @ per_light)
                names.extend([camera.name] * len(image))
    return Augmented(np.concatenate(index), np.concatenate(matrices).astype(np.float32), names)
