"""Training examples from a folder of images with ground truth: the estimator's input, read and
prepared by the execution layer's image source exactly as ``ccjax evaluate`` prepares it (surface
lists, or whole images with their usable pixels), stacked into fixed-shape arrays so a training
step is one compiled function."""

from __future__ import annotations

import os

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float
from tqdm.auto import tqdm

from ccjax.estimators.base import AbstractEstimator
from ccjax.io.ground_truth import match_ground_truth, read_ground_truth
from ccjax.preprocessing import DEFAULT_DARK, DEFAULT_PREPROCESSING, Preprocessing, input_rule, resolve
from ccjax.runs.pooled import ImageSource
from ccjax.runs.sources import image_folder


class Examples(eqx.Module):
    """A set of training examples with ground truth.

    Attributes:
        x: ``(N, P, 3)`` padded surface lists or ``(N, H, W, 3)`` images.
        mask: ``(N, P)`` / ``(N, H, W)`` valid entries.
        illuminant: ``(N, 3)`` the true lights (camera RGB of white).
        names: the image names (ground-truth rows), in order.
    """

    x: Float[Array, "N *item 3"]
    mask: Bool[Array, "N ..."]
    illuminant: Float[Array, "N 3"]
    names: tuple[str, ...] = eqx.field(static=True, default=())

    def __len__(self) -> int:
        return int(self.x.shape[0])

    def take(self, indices) -> Examples:
        """A subset of the examples.

        Arguments:
            indices: a 1-D integer array.

        Returns:
            The :class:`Examples` at ``indices``.
        """
        indices = np.asarray(indices, np.int64)
        names = tuple(self.names[i] for i in indices) if self.names else ()
        return Examples(self.x[indices], self.mask[indices], self.illuminant[indices], names)


def stack_inputs(inputs, masks, input_kind: str) -> tuple[np.ndarray, np.ndarray]:
    """Stack per-image inputs into fixed-shape arrays: images must share one size; surface lists
    are padded (invalid slots) to the longest one (a surface model given whole images, the
    ``pixels`` rule, gets each image's pixels as a list, as :func:`ccjax.preprocessing.run_model`
    gives it them).

    Arguments:
        inputs: per image, ``(H, W, 3)`` or ``(P, 3)`` what :func:`ccjax.preprocessing.prepare_input` gave.
        masks: per image, its mask.
        input_kind: the estimator's input kind (``"surfaces"`` or ``"image"``).

    Returns:
        ``(x, mask)``: ``(N, H, W, 3)`` / ``(N, H, W)`` images or ``(N, P, 3)`` / ``(N, P)`` padded lists.
    """
    if input_kind == "image":
        shapes = {x.shape for x in inputs}
        if len(shapes) > 1:
            raise ValueError(f"images: training an image estimator needs images of one size, got {sorted(shapes)}")
        return np.stack(inputs), np.stack(masks)
    inputs = [rgb.reshape(-1, 3) for rgb in inputs]
    masks = [valid.reshape(-1) for valid in masks]
    size = max(len(m) for m in masks)
    x = np.zeros((len(inputs), size, 3), np.float32)
    mask = np.zeros((len(inputs), size), bool)
    for index, (rgb, valid) in enumerate(zip(inputs, masks)):
        x[index, : len(rgb)], mask[index, : len(valid)] = rgb, valid
    return x, mask


def source_examples(
    source: ImageSource,
    illuminants,
    names,
    input_kind: str,
    rule: Preprocessing,
    *,
    items=None,
    dark: float = DEFAULT_DARK,
    progress: bool = False,
    keep_going: bool = True,
) -> tuple[Examples, dict[str, str]]:
    """Training examples from an image source: each image read and prepared by the source
    (:meth:`ccjax.runs.sources.ImageFolder.prepared`), exactly as ``ccjax evaluate`` prepares it.

    Arguments:
        source: the images (:func:`ccjax.runs.sources.image_folder`, or several cameras' folders
            pooled, :class:`ccjax.runs.pooled.PooledImages`).
        illuminants: ``(N, 3)`` the ground-truth light of each of the source's files.
        names: the name (ground-truth row) of each of the source's files.
        input_kind: the estimator's input kind (``"surfaces"`` or ``"image"``).
        rule: the resolved input rule (:func:`ccjax.preprocessing.resolve` / ``input_rule``).
        items: the source's files to use (default: every one), in order.
        dark: the surface lists' dark rule.
        progress: show a progress bar.
        keep_going: leave out (and report) files that cannot be used; otherwise raise.

    Returns:
        ``(Examples of the images that could be used, {path: reason} for those that could not)``.

    Raises:
        ValueError: no image could be used, or image inputs of different sizes.
    """
    names = list(names)
    illuminants = np.asarray(illuminants, np.float32)
    if not (len(source) == len(names) == len(illuminants)):
        raise ValueError(
            f"paths, names, illuminants: expected one each, got {len(source)}, {len(names)}, {len(illuminants)}"
        )
    chosen = list(range(len(source))) if items is None else [int(i) for i in items]
    inputs, valid, kept, failures = [], [], [], {}
    prepared = source.prepared({rule.name: rule}, chosen, dark=dark)
    for item in tqdm(prepared, total=len(chosen), desc="reading", unit="image", disable=not progress, leave=False):
        if item.failure is not None:
            if not keep_going and item.error is not None:
                raise item.error
            failures[str(item.path)] = item.failure
            continue
        rgb, usable = item.inputs[rule.name]
        inputs.append(np.asarray(rgb, np.float32))
        valid.append(np.asarray(usable, bool))
        kept.append(item.index)
    if not kept:
        raise ValueError(f"images: none of the {len(chosen)} images could be used for training")
    x, mask = stack_inputs(inputs, valid, input_kind)
    light = jnp.asarray(illuminants[kept])
    return Examples(jnp.asarray(x), jnp.asarray(mask), light, tuple(names[i] for i in kept)), failures


def read_examples(
    paths,
    illuminants,
    names,
    model: AbstractEstimator,
    *,
    preprocessing: str | Preprocessing | None = None,
    dark: float = DEFAULT_DARK,
    read_options: dict | None = None,
    masks=None,
    progress: bool = False,
) -> tuple[Examples, dict[str, str]]:
    """Training examples of ``model`` from image files: each image is read and given exactly the
    input ``ccjax evaluate`` gives the model (:func:`ccjax.preprocessing.prepare`, through the
    image source of :mod:`ccjax.runs.sources`), so a model is trained on what it is scored on.

    Arguments:
        paths: the image files.
        illuminants: ``(N, 3)`` their ground-truth lights (camera RGB, any scale).
        names: their names (ground-truth rows), kept in :attr:`Examples.names`.
        model: the estimator to be trained (its input kind and default preprocessing).
        preprocessing: a preprocessing for the model (None: its default).
        dark: the surface lists' dark rule.
        read_options: keyword arguments of :func:`ccjax.io.read_image`.
        masks: optional mask file per image (``None`` entries: no mask).
        progress: show a progress bar.

    Returns:
        ``(Examples of the images that could be used, {path: reason} for those that could not)``.

    Raises:
        ValueError: no image could be used, or image inputs of different sizes.
    """
    paths, names = list(paths), list(names)
    if not (len(paths) == len(names) == len(illuminants)):
        raise ValueError(
            f"paths, names, illuminants: expected one each, got {len(paths)}, {len(names)}, {len(illuminants)}"
        )
    if masks is not None and len(masks) != len(paths):
        raise ValueError(f"masks: expected one entry per image ({len(paths)}), got {len(masks)}")
    if not paths:
        raise ValueError("images: none of the 0 images could be used for training")
    source = image_folder(paths, masks=masks, read_options=read_options)
    rule = resolve(model, preprocessing)
    return source_examples(source, illuminants, names, model.input_kind, rule, dark=dark, progress=progress)


def load_examples(
    directory: str | os.PathLike,
    ground_truth: str | os.PathLike,
    input_kind: str = "surfaces",
    *,
    preprocessing: str | Preprocessing = DEFAULT_PREPROCESSING,
    dark: float = DEFAULT_DARK,
    progress: bool = False,
) -> Examples:
    """Read every image of ``ground_truth`` from ``directory`` once and build the estimator input,
    with the usable-pixel rules ``ccjax evaluate`` applies (:func:`ccjax.preprocessing.prepare`).

    Arguments:
        directory: the image folder.
        ground_truth: CSV ``image,r,g,b[,...]`` (:func:`ccjax.io.read_ground_truth`).
        input_kind: ``"surfaces"`` (preprocessed surface lists, padded to the longest one) or
            ``"image"`` (the images themselves, which must share one size; mask = the usable
            pixels: not clipped, no zero channel).
        preprocessing, dark: the surface-list preprocessing (:func:`ccjax.preprocessing.surfaces`).
        progress: show a progress bar.

    Returns:
        :class:`Examples` in ground-truth order.

    Raises:
        ValueError: an image that cannot be used (its failure record).
    """
    if input_kind not in ("surfaces", "image"):
        raise ValueError(f"input_kind: expected 'surfaces' or 'image', got {input_kind!r}")
    truth = read_ground_truth(ground_truth)
    pairs = match_ground_truth(truth, directory)
    source = image_folder([path for path, _ in pairs], keep_going=False)
    illuminant = np.stack([light for _, light in pairs]).astype(np.float32)
    rule = input_rule(input_kind, preprocessing)
    examples, _ = source_examples(
        source, illuminant, list(truth), input_kind, rule, dark=dark, progress=progress, keep_going=False
    )
    return examples
