"""Training the any-camera estimator: every training image (of any camera) and its ground truth
mapped into the reference camera's space by its own camera's map, and FFCC trained there once
(:func:`ccjax.estimators.ffcc.train`, the reference code's hyperparameters: a choice among the
settings by cross-validation costs seven fits on a pool of thousands of images), its histogram's
window set on the training lights and on every plausible light
(:func:`~ccjax.estimators.conditioned.window_lights`)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ccjax.estimators.conditioned._grey import POSTERIOR_SCALE, fit_grey_observation, no_grey_observation
from ccjax.estimators.conditioned._model import AnyCamera
from ccjax.estimators.conditioned._space import window_lights
from ccjax.estimators.ffcc import BINS, Hyperparameters, TrainingRecord, init_ffcc
from ccjax.estimators.ffcc import train as train_ffcc
from ccjax.precision import matmul

__all__ = ["to_reference", "train"]

_CHUNK = 512


@eqx.filter_jit
def _map(images, masks, lights, matrices):
    mapped = matmul(images, jnp.swapaxes(matrices, -1, -2)[:, None])
    usable = masks & jnp.all(mapped > 0, axis=-1)
    light = matmul(matrices, lights[..., None])[..., 0]
    return jnp.where(usable[..., None], mapped, 0.0), usable, light / jnp.max(light, axis=-1, keepdims=True)


def to_reference(
    images: Float[Array | np.ndarray, "N H W 3"],
    masks: Bool[Array | np.ndarray, "N H W"],
    lights: Float[Array | np.ndarray, "N 3"],
    matrices: Float[Array | np.ndarray, "K 3 3"],
    index: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Images and their lights in the reference camera's space: each pixel and light times its
    image's matrix; a pixel whose mapped colour leaves the positive octant leaves the mask (its
    value set to 0, not clipped into a wrong colour).

    Arguments:
        images: ``(N, H, W, 3)`` linear RGB of each image's own camera.
        masks: ``(N, H, W)`` usable pixels.
        lights: ``(N, 3)`` the ground truths (each image's camera RGB of white).
        matrices: ``(K, 3, 3)`` each entry's map into the reference space (:func:`reference_matrix`).
        index: ``(K,)`` the image of each entry (default: entry ``k`` is image ``k``): copies of an
            image under other maps cost a matrix, not an image.

    Returns:
        ``(images, masks, lights)`` of the ``K`` entries in the reference space (lights with
        largest channel 1), NumPy.
    """
    count = len(images)
    if not (len(masks) == len(lights) == count):
        raise ValueError(
            f"images, masks, lights: expected one of each per image, got {count}, {len(masks)}, {len(lights)}"
        )
    index = np.arange(count) if index is None else np.asarray(index)
    if len(index) != len(matrices) or (len(index) and (index.min() < 0 or index.max() >= count)):
        raise ValueError(f"index, matrices: expected one image index in [0, {count}) per matrix")
    images, masks, lights = np.asarray(images), np.asarray(masks), np.asarray(lights)
    parts = []
    for start in range(0, len(index), _CHUNK):
        chosen = index[start : start + _CHUNK]
        arrays = (images[chosen], masks[chosen], lights[chosen], matrices[start : start + _CHUNK])
        parts.append(_map(*(jnp.asarray(a) for a in arrays)))
    return tuple(np.concatenate([np.asarray(part[k]) for part in parts]) for k in range(3))  # type: ignore[return-value]


def train(
    images: Float[Array | np.ndarray, "N H W 3"],
    masks: Bool[Array | np.ndarray, "N H W"],
    lights: Float[Array | np.ndarray, "N 3"],
    matrices: Float[Array | np.ndarray, "K 3 3"],
    hyperparameters: Hyperparameters | None = None,
    *,
    bins: int = BINS,
    index: np.ndarray | None = None,
    window: Float[Array | np.ndarray, "M 3"] | None = None,
    posterior_scale: float | None = POSTERIOR_SCALE,
) -> tuple[AnyCamera, TrainingRecord]:
    """Train the any-camera estimator on images of several cameras (module docstring).

    Arguments:
        images: ``(N, H, W, 3)`` linear RGB of each image's own camera, 1.0 = saturation.
        masks: ``(N, H, W)`` usable pixels.
        lights: ``(N, 3)`` the ground truths, each in its image's camera (every channel positive).
        matrices: ``(K, 3, 3)`` each entry's map into the reference space
            (:func:`ccjax.estimators.conditioned.reference_matrix` of its camera).
        hyperparameters: FFCC's settings (default: :class:`~ccjax.estimators.ffcc.Hyperparameters`).
        bins: the histogram's bins per axis (even).
        index: ``(K,)`` the image of each entry (:func:`to_reference`; default: one per image).
        window: ``(M, 3)`` reference-space lights the histogram must hold besides the training
            lights (:func:`ccjax.estimators.ffcc.train`; None: :func:`window_lights`, every light
            of the bank and the discharge lamps, so that a camera whose lights lie beyond the
            training cameras' does not see them wrap).
        posterior_scale: the factor on FFCC's covariance where shades of grey's observation is
            combined with it (:class:`~ccjax.estimators.conditioned.GreyObservation`; the
            observation's bias and covariance are fitted on the training entries); None: no
            observation, FFCC alone.

    Returns:
        ``(unbound AnyCamera, TrainingRecord)``.

    Raises:
        ValueError: no image, a light with a channel at or below 0, or mismatched lengths.
    """
    if len(images) == 0:
        raise ValueError("images: the any-camera estimator needs at least one training image")
    if not bool(np.all(np.asarray(lights) > 0)):
        raise ValueError("lights: every channel of every training light must be positive")
    mapped, usable, reference_lights = to_reference(images, masks, lights, matrices, index)
    if not bool(np.all(reference_lights > 0)):
        raise ValueError("matrices: a training light leaves the positive octant in the reference space")
    settings = hyperparameters or Hyperparameters()
    held = window_lights() if window is None else window
    core, record = train_ffcc(init_ffcc(bins), mapped, usable, reference_lights, settings, window=held)
    if posterior_scale is None:
        grey = no_grey_observation(core.bias.dtype)
    else:
        grey = fit_grey_observation(mapped, usable, reference_lights, posterior_scale)
    del mapped
    model = AnyCamera(core=core, grey=grey, matrix=jnp.eye(3, dtype=core.bias.dtype))
    jax.block_until_ready(model)
    return model, record
