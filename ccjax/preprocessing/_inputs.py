"""From an image to what a model is called with: each model's input rule (:func:`resolve`), the
prepared input (:func:`prepare`), its shapes for compiling ahead, and running a model on it."""

from __future__ import annotations

from collections.abc import Callable
from typing import cast

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ccjax.estimators.base import AbstractEstimator, Estimate
from ccjax.estimators.tiles import map_row_tiles, tile_rows
from ccjax.io.reading import LinearImage
from ccjax.precision import matmul
from ccjax.preprocessing._methods import Preprocessing, as_preprocessing, padded_size, surfaces
from ccjax.preprocessing._rules import DEFAULT_DARK, DEFAULT_PERCENTILE, PIXELS, usable_pixels


def input_rule(input_kind: str, preprocessing: str | Preprocessing) -> Preprocessing:
    """The preprocessing an estimator of ``input_kind`` gets when ``preprocessing`` is asked for:
    image estimators always get the image (``pixels``): they need the pixels' neighbours, so a
    surface-list preprocessing cannot apply to them.

    Arguments:
        input_kind: ``"surfaces"`` or ``"image"`` (``model.input_kind``).
        preprocessing: a :class:`Preprocessing` or its name.

    Returns:
        The :class:`Preprocessing`.
    """
    if input_kind == "image":
        return Preprocessing.parse(PIXELS)
    return as_preprocessing(preprocessing)


def resolve(model: AbstractEstimator, preprocessing: str | Preprocessing | None = None) -> Preprocessing:
    """The preprocessing ``model`` gets: ``preprocessing``, or the model's own default
    (``model.default_preprocessing``: ``pixels`` for the statistics methods, ``ave5`` for the
    world-based ones) when it is None; image estimators always get ``pixels`` (:func:`input_rule`).

    Arguments:
        model: a fitted estimator.
        preprocessing: a :class:`Preprocessing` or its name, or None.

    Returns:
        The :class:`Preprocessing`.
    """
    return input_rule(model.input_kind, model.default_preprocessing if preprocessing is None else preprocessing)


def prepare_input(
    method: Preprocessing,
    image: LinearImage,
    *,
    dark: float = DEFAULT_DARK,
    mask: np.ndarray | None = None,
    percentile: float = DEFAULT_PERCENTILE,
) -> tuple[np.ndarray, np.ndarray]:
    """The input that ``method`` (a resolved rule, :func:`resolve`) makes of one photograph:
    :func:`prepare` for every model whose rule it is.

    Arguments:
        method: the :class:`Preprocessing`.
        image: a :class:`ccjax.io.LinearImage`.
        dark, percentile, mask: as for :func:`prepare`.

    Returns:
        As :func:`prepare`.
    """
    if method.pixels:
        return image.rgb, usable_pixels(image.rgb, image.clipped, 0.0, mask=mask)
    return surfaces(image, method, dark=dark, mask=mask, percentile=percentile)


def prepare(
    model: AbstractEstimator,
    image: LinearImage,
    preprocessing: str | Preprocessing | None = None,
    *,
    dark: float = DEFAULT_DARK,
    mask: np.ndarray | None = None,
    percentile: float = DEFAULT_PERCENTILE,
) -> tuple[np.ndarray, np.ndarray]:
    """What ``model`` is called with for one photograph; pass both to :func:`run_model`.

    Arguments:
        model: a fitted estimator.
        image: a :class:`ccjax.io.LinearImage`.
        preprocessing: a :class:`Preprocessing` or its name; None: the model's default
            (:func:`resolve`: ``pixels`` for grey world, shades of grey, max-RGB and grey edge,
            ``ave5`` for the world-based methods).
        dark, percentile: the dark rule of :func:`usable_pixels` (surface lists only; ``pixels``
            has none).
        mask: optional ``(H, W)`` bool, True where the user allows a pixel (e.g. from
            :func:`ccjax.io.read_mask`), combined with the image's own rules.

    Returns:
        ``pixels`` (and every image estimator): the image ``(H, W, 3)`` itself (not copied) and its
        usable mask ``(H, W)`` (not clipped, no zero channel, inside ``mask``); otherwise the
        surface list ``(N, 3)`` and its mask ``(N,)``, padded to :func:`padded_size`
        (:func:`surfaces`).

    Shapes, for compiling ahead of time: an image input has the image's shape; a surface list
    has one of the sizes :func:`input_shapes` lists (the count depends on the content, so a
    caller compiles each size class once, ahead of time or when it first appears).
    :func:`input_key` says which models share an input.
    """
    return prepare_input(resolve(model, preprocessing), image, dark=dark, mask=mask, percentile=percentile)


def input_key(model: AbstractEstimator, preprocessing: str | Preprocessing | None = None) -> str:
    """A key equal for models that :func:`prepare` gives the same input (with the same image,
    dark rule and mask): the resolved method's name, so a caller prepares each input once.

    Arguments:
        model: a fitted estimator.
        preprocessing: as for :func:`prepare`.

    Returns:
        The key.
    """
    return resolve(model, preprocessing).name


def input_shapes(
    model: AbstractEstimator, image_shape: tuple[int, int], preprocessing: str | Preprocessing | None = None
) -> list[tuple[tuple[int, ...], tuple[int, ...]]]:
    """Every ``(rgb shape, mask shape)`` :func:`prepare` can give ``model`` for images of
    ``image_shape``, so a caller can compile them all before timing anything (e.g. before a
    progress bar starts).

    Arguments:
        model: a fitted estimator.
        image_shape: ``(H, W)``.
        preprocessing: as for :func:`prepare`.

    Returns:
        ``[((H, W, 3), (H, W))]`` for image inputs; for surface lists ``[((n, 3), (n,)), ...]`` for
        each size class ``n`` from 64 to :func:`padded_size` of the most surfaces the method can
        return (a power of two each; a 48-MP image at ``ave5`` has 16 classes, most of which a
        data set never reaches: compile lazily there).
    """
    height, width = image_shape
    method = resolve(model, preprocessing)
    if method.pixels:
        return [((height, width, 3), (height, width))]
    top, size, shapes = padded_size(method.max_count(height, width)), padded_size(0), []
    while size <= top:
        shapes.append(((size, 3), (size,)))
        size *= 2
    return shapes


def _concrete(model: AbstractEstimator) -> Callable[[Array, Array], Estimate]:
    # The abstract base declares no __call__ (its surface and image subtypes do, with different
    # shapes), so the type checker is told here what every fitted model is.
    return cast(Callable[[Array, Array], Estimate], model)


@eqx.filter_jit
def run_model(model: AbstractEstimator, rgb: Array, mask: Array) -> Estimate:
    """Run ``model`` on what :func:`prepare` gave, jit-compiled once per model structure and
    input shape: an image ``(H, W, 3)`` goes through :func:`estimate_pixels` (so surface models
    see every usable pixel), a surface list ``(N, 3)`` to the model directly.

    Arguments:
        model: a fitted estimator.
        rgb: the prepared input, ``(H, W, 3)`` or ``(N, 3)``.
        mask: its mask, ``(H, W)`` or ``(N,)``.

    Returns:
        The model's :class:`~ccjax.estimators.base.Estimate`.
    """
    if rgb.ndim == 3:
        return estimate_pixels(model, rgb, mask)
    return _concrete(model)(rgb, mask)


def estimate_image(
    model: AbstractEstimator,
    image: LinearImage,
    preprocessing: str | Preprocessing | None = None,
    *,
    dark: float = DEFAULT_DARK,
    mask: np.ndarray | None = None,
    percentile: float = DEFAULT_PERCENTILE,
) -> Estimate:
    """Estimate the light of one image with a fitted model (jit-compiled per input size).

    Arguments:
        model: a fitted estimator.
        image: the image.
        preprocessing, dark, mask, percentile: see :func:`prepare` (None: the model's default).

    Returns:
        The model's :class:`ccjax.estimators.base.Estimate`.
    """
    rgb, valid = prepare(model, image, preprocessing, dark=dark, mask=mask, percentile=percentile)
    return run_model(model, jnp.asarray(rgb), jnp.asarray(valid))


def masked_mean(rgb: Float[Array, "H W 3"], mask: Bool[Array, "H W"]) -> Float[Array, "3"]:
    """Mean RGB of the masked pixels (0 if none). Summed as a matrix-vector product over rows of
    ``W * 3`` values: XLA's CPU reductions over a minor axis of 3 are several times slower. An
    image above :data:`ccjax.estimators.tiles.TILE_PIXELS` is summed in row tiles
    (:func:`ccjax.estimators.tiles.map_row_tiles`), so no image-sized copy is made.

    Arguments:
        rgb: ``(H, W, 3)`` image.
        mask: ``(H, W)`` pixels to average.

    Returns:
        ``(3,)`` the mean.
    """
    height, width, _ = rgb.shape

    def sums(image, usable, own):
        usable = usable & own[:, None] if own is not None else usable
        rows = jnp.where(usable[..., None], image, 0.0).reshape(image.shape[0], width * 3)
        total = matmul(jnp.ones((image.shape[0],), image.dtype), rows).reshape(width, 3).sum(axis=0)
        return total, jnp.sum(usable, dtype=jnp.int32)

    tile = tile_rows(height, width)
    if tile is None:
        total, count = sums(rgb, mask, None)
    else:
        totals, counts = map_row_tiles(sums, rgb, mask, rows=tile)
        total, count = totals.sum(axis=0), counts.sum()
    # Counted in int32: a float32 count is exact only up to 2**24 pixels (16.7 MP).
    return total / jnp.maximum(count, 1).astype(rgb.dtype)


def estimate_pixels(model: AbstractEstimator, rgb: Float[Array, "H W 3"], mask: Bool[Array, "H W"]) -> Estimate:
    """Run a model on every masked pixel of an image (no block averaging), jit-able.

    Image-only models get the image; models linear in the pixels (``model.pools_pixels``: grey
    world) get the masked mean as a single datum, which gives the same estimate with one fast
    reduction; others get the pixel list.

    Arguments:
        model: a fitted estimator.
        rgb: ``(H, W, 3)`` image.
        mask: ``(H, W)`` usable pixels.

    Returns:
        The model's :class:`~ccjax.estimators.base.Estimate`.
    """
    if model.input_kind == "image":
        return _concrete(model)(rgb, mask)
    if model.pools_pixels:
        return model(masked_mean(rgb, mask)[None], jnp.any(mask)[None])
    return _concrete(model)(rgb.reshape(-1, 3), mask.reshape(-1))
