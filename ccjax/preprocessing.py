"""From an image to an estimator's input (Barnard 1999 §4.6, Table 4.6).

Surface-list estimators get ``(rgb (N, 3), mask (N,))``: clipped pixels are dropped (the thesis
discards them, §2.7) and too-dark ones (R+G+B below ``dark`` times the brightest usable pixel's;
2 %), then one of the preprocessing methods of Table 4.6 (:data:`TABLE_4_6`) reduces the image to
a list of surfaces: block averaging (default 5x5, "roughly optimal", §4.6), block averaging + RGB
clustering, block averaging + convex-hull reduction, or region-growing segmentation. Image-only
estimators (``input_kind == "image"``, e.g. grey edge) get the image and its unclipped-pixel mask.
"""

from __future__ import annotations

import re
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import cast

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ccjax.estimators.base import AbstractEstimator, Estimate
from ccjax.io.reading import LinearImage

DEFAULT_PREPROCESSING = "ave5"
DEFAULT_DARK = 0.02


def usable_pixels(rgb: np.ndarray, clipped: np.ndarray, dark: float = DEFAULT_DARK) -> np.ndarray:
    """Pixels the thesis keeps (§4.6): not clipped, and not "overly dark".

    Arguments:
        rgb: ``(H, W, 3)`` linear image.
        clipped: ``(H, W)`` True where a channel saturated.
        dark: keep pixels whose R+G+B is at least this fraction of the brightest unclipped pixel's.

    Returns:
        ``(H, W)`` bool.
    """
    if not 0 <= dark < 1:
        raise ValueError(f"dark: expected a fraction in [0, 1), got {dark!r}")
    brightness = rgb.sum(axis=-1)
    peak = brightness[~clipped].max(initial=0.0)
    return ~clipped & (brightness >= dark * peak) & (brightness > 0)


def block_average(rgb: np.ndarray, usable: np.ndarray, block: int, max_rg_spread: float | None = None) -> np.ndarray:
    """Means of non-overlapping ``block x block`` tiles whose pixels are all usable (§4.6, the
    thesis' ``ave<b>``); edge rows/columns that do not fill a tile are dropped.

    Arguments:
        rgb: ``(H, W, 3)`` linear image.
        usable: ``(H, W)`` from :func:`usable_pixels`.
        block: tile side in pixels.
        max_rg_spread: an extension, not in the thesis: also drop tiles whose pixels' (r,g)
            bounding box has a diagonal above it, i.e. tiles straddling a boundary between surfaces,
            whose mean is a mixture no surface produces (harmless for gamut mapping, which is
            convex, but it fills histogram cells for Colour by Correlation).

    Returns:
        ``(n, 3)`` float32 tile means, in scan order.
    """
    height, width = (rgb.shape[0] // block) * block, (rgb.shape[1] // block) * block
    tiles = rgb[:height, :width].reshape(height // block, block, width // block, block, 3)
    ok = usable[:height, :width].reshape(height // block, block, width // block, block).all(axis=(1, 3))
    if max_rg_spread is not None:
        total = tiles.sum(axis=-1, keepdims=True, dtype=np.float64)
        chroma = tiles[..., :2] / np.where(total > 0, total, 1.0)
        spread = chroma.max(axis=(1, 3)) - chroma.min(axis=(1, 3))
        ok &= np.sqrt((spread**2).sum(axis=-1)) <= max_rg_spread
    return tiles.mean(axis=(1, 3), dtype=np.float64)[ok].astype(np.float32)


def cluster_rgb(rgb: np.ndarray, divisions: int = 100) -> np.ndarray:
    """RGB clustering (§4.6): bin in RGB (``divisions`` per channel over ``[0, max]``) and replace
    each occupied bin by the mean of its members (removes near-duplicates).

    Returns:
        ``(m, 3)`` float32, one row per occupied bin.
    """
    if len(rgb) == 0:
        return rgb
    top = max(float(rgb.max()), 1e-12)
    cells = np.minimum((rgb / top * divisions).astype(np.int64), divisions - 1)
    keys = (cells[:, 0] * divisions + cells[:, 1]) * divisions + cells[:, 2]
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    sums = np.zeros((len(counts), 3))
    np.add.at(sums, inverse.ravel(), rgb)
    return (sums / counts[:, None]).astype(np.float32)


def hull_reduce(rgb: np.ndarray) -> np.ndarray:
    """Keep only the vertices of the RGB convex hull (§4.6), in their original order; degenerate
    sets (fewer than 5 points, or flat) are kept whole."""
    from scipy.spatial import ConvexHull, QhullError

    if len(rgb) < 5:
        return rgb
    try:
        return rgb[np.sort(ConvexHull(rgb.astype(np.float64)).vertices)]
    except QhullError:
        return rgb


def segment(
    rgb: np.ndarray, usable: np.ndarray, min_size: int, rg_tolerance: float, brightness_tolerance: float
) -> np.ndarray:
    """Region growing (§4.6) and the mean RGB of each region.

    Seeds are taken in scan order; a region grows over 4-connected usable pixels while the
    diagonal of its (r,g) bounding box stays within ``rg_tolerance`` and ``(max - min) / min`` of
    its R+G+B within ``brightness_tolerance``; regions smaller than ``min_size`` are dropped.
    Plain Python region growing: a few seconds per megapixel (a preprocessing option, not the
    default).

    Returns:
        ``(regions, 3)`` float32 region means, in seed order.
    """
    height, width, _ = rgb.shape
    total = rgb.sum(axis=-1, dtype=np.float64)
    safe = np.where(total > 0, total, 1.0)
    r, g = (rgb[..., 0] / safe).tolist(), (rgb[..., 1] / safe).tolist()
    brightness = total.tolist()
    free = usable.copy()
    means = []
    rg_limit = rg_tolerance**2
    for y0, x0 in zip(*np.nonzero(usable)):
        if not free[y0, x0]:
            continue
        free[y0, x0] = False
        members = [(y0, x0)]
        r_lo = r_hi = r[y0][x0]
        g_lo = g_hi = g[y0][x0]
        b_lo = b_hi = brightness[y0][x0]
        queue = deque(members)
        while queue:
            y, x = queue.popleft()
            for ny, nx in ((y - 1, x), (y + 1, x), (y, x - 1), (y, x + 1)):
                if 0 <= ny < height and 0 <= nx < width and free[ny, nx]:
                    rr, gg, bb = r[ny][nx], g[ny][nx], brightness[ny][nx]
                    nr_lo, nr_hi, ng_lo, ng_hi = min(r_lo, rr), max(r_hi, rr), min(g_lo, gg), max(g_hi, gg)
                    nb_lo, nb_hi = min(b_lo, bb), max(b_hi, bb)
                    if (nr_hi - nr_lo) ** 2 + (
                        ng_hi - ng_lo
                    ) ** 2 <= rg_limit and nb_hi - nb_lo <= brightness_tolerance * nb_lo:
                        r_lo, r_hi, g_lo, g_hi, b_lo, b_hi = nr_lo, nr_hi, ng_lo, ng_hi, nb_lo, nb_hi
                        free[ny, nx] = False
                        members.append((ny, nx))
                        queue.append((ny, nx))
        if len(members) >= min_size:
            ys, xs = np.array(members).T
            means.append(rgb[ys, xs].mean(axis=0, dtype=np.float64))
    return np.array(means, np.float32).reshape(-1, 3)


@dataclass(frozen=True)
class Preprocessing:
    """One of the thesis' preprocessing methods (Table 4.6), parsed from a name.

    ``ave<b>`` (block averaging, ``ave1`` = single pixels), ``ave<b>-cluster`` (+ RGB clustering,
    100 divisions), ``ave<b>-hull`` (+ convex-hull reduction), ``seg-<min size>-<rg tol>-<rel
    R+G+B tol>`` (segmentation, e.g. ``seg-5-0.005-0.2``), ``seg-...-hull``, and ``generic``
    (Table 4.5's segmentation, ``seg-5-0.05-0.1``). Extension: ``ave<b>-u<spread>`` keeps only
    blocks whose (r,g) spread is at most ``<spread>`` (e.g. ``ave5-u0.04``; :func:`block_average`),
    combinable with ``-cluster``/``-hull``.
    """

    name: str
    block: int = 5
    segmentation: tuple[int, float, float] | None = None
    reduction: str | None = None  # None, "cluster" or "hull"
    max_rg_spread: float | None = None

    @classmethod
    def parse(cls, name: str) -> Preprocessing:
        """The method called ``name`` (class docstring); ``ValueError`` for unknown names."""
        text = "seg-5-0.05-0.1" if name == "generic" else name
        number = r"(\d+(?:\.\d*)?|\.\d+)"
        match = re.fullmatch(rf"ave(\d+)(?:-u{number})?(?:-(cluster|hull))?", text)
        if match and int(match[1]) >= 1:
            spread = None if match[2] is None else float(match[2])
            return cls(name=name, block=int(match[1]), reduction=match[3], max_rg_spread=spread)
        match = re.fullmatch(rf"seg-(\d+)-{number}-{number}(?:-(hull))?", text)
        if match:
            return cls(
                name=name, block=1, segmentation=(int(match[1]), float(match[2]), float(match[3])), reduction=match[4]
            )
        raise ValueError(
            f"preprocessing: unknown method {name!r}; expected ave<b>[-u<spread>][-cluster|-hull], "
            "seg-<min>-<rg>-<rel>[-hull] or generic"
        )

    def apply(self, rgb: np.ndarray, usable: np.ndarray) -> np.ndarray:
        """The surface list ``(n, 3)`` for one image (``usable`` from :func:`usable_pixels`)."""
        if self.segmentation is not None:
            data = segment(rgb, usable, *self.segmentation)
        else:
            data = block_average(rgb, usable, self.block, self.max_rg_spread)
        if self.reduction == "cluster":
            data = cluster_rgb(data)
        elif self.reduction == "hull":
            data = hull_reduce(data)
        return data


TABLE_4_6 = (
    [f"seg-{m}-{t}-{b}" for t in (0.0025, 0.005, 0.01, 0.02) for b in (0.1, 0.2, 0.3, 0.4) for m in (5, 10, 20)]
    + [f"ave{b}" for b in (1, 2, 3, 5, 7)]
    + [f"ave{b}-cluster" for b in (1, 2, 3, 5, 7)]
    + [f"ave{b}-hull" for b in (1, 2, 3, 5, 7)]
)
"""The 63 well-defined preprocessing methods of Table 4.6 (48 segmentations, 5 block sizes, 5 with
RGB clustering, 5 with hull reduction). The thesis' remaining two ("two selected segmentations +
hull reduction") do not say which segmentations; any ``seg-...-hull`` name runs such a variant."""


def padded_size(count: int | np.integer) -> int:
    """The length surface lists of ``count`` rows are padded to: a power of two, at least 64, so
    jit compiles once per size class, not once per image."""
    return max(64, 1 << int(np.ceil(np.log2(max(count, 1)))))


def surfaces(
    image: LinearImage,
    preprocessing: str | Preprocessing = DEFAULT_PREPROCESSING,
    *,
    dark: float = DEFAULT_DARK,
    pad: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Estimator input of a surface-list method.

    Arguments:
        image: a :class:`ccjax.io.LinearImage`.
        preprocessing: a :class:`Preprocessing` or its name (default ``ave5``).
        dark: dark-pixel fraction (:func:`usable_pixels`).
        pad: pad to :func:`padded_size` with masked zero rows, so batches share compiled code.

    Returns:
        ``(rgb (N, 3) float32, mask (N,) bool)``.
    """
    method = preprocessing if isinstance(preprocessing, Preprocessing) else Preprocessing.parse(preprocessing)
    data = method.apply(image.rgb, usable_pixels(image.rgb, image.clipped, dark))
    size = padded_size(len(data)) if pad else len(data)
    rgb = np.zeros((size, 3), np.float32)
    rgb[: len(data)] = data
    mask = np.arange(size) < len(data)
    return rgb, mask


def model_input(
    model: AbstractEstimator,
    image: LinearImage,
    preprocessing: str | Preprocessing = DEFAULT_PREPROCESSING,
    *,
    dark: float = DEFAULT_DARK,
) -> tuple[np.ndarray, np.ndarray]:
    """What ``model`` is called with: the image and its unclipped mask for image-only methods,
    the preprocessed surface list (:func:`surfaces`) otherwise."""
    if model.input_kind == "image":
        return image.rgb, ~image.clipped
    return surfaces(image, preprocessing, dark=dark)


def _concrete(model: AbstractEstimator) -> Callable[[Array, Array], Estimate]:
    # The abstract base declares no __call__ (its surface and image subtypes do, with different
    # shapes), so the type checker is told here what every fitted model is.
    return cast(Callable[[Array, Array], Estimate], model)


@eqx.filter_jit
def run_model(model: AbstractEstimator, rgb: Array, mask: Array) -> Estimate:
    """``model(rgb, mask)``, jit-compiled once per model structure and input shape."""
    return _concrete(model)(rgb, mask)


def estimate_image(
    model: AbstractEstimator,
    image: LinearImage,
    preprocessing: str | Preprocessing = DEFAULT_PREPROCESSING,
    *,
    dark: float = DEFAULT_DARK,
) -> Estimate:
    """Estimate the light of one image with a fitted model (jit-compiled per input size).

    Arguments:
        model: a fitted estimator.
        image: the image.
        preprocessing, dark: see :func:`surfaces` (ignored by image-only methods).

    Returns:
        The model's :class:`ccjax.estimators.base.Estimate`.
    """
    rgb, mask = model_input(model, image, preprocessing, dark=dark)
    return run_model(model, jnp.asarray(rgb), jnp.asarray(mask))


def masked_mean(rgb: Float[Array, "H W 3"], mask: Bool[Array, "H W"]) -> Float[Array, "3"]:
    """Mean RGB of the masked pixels (0 if none). Summed as a matrix-vector product over rows of
    ``W * 3`` values: XLA's CPU reductions over a minor axis of 3 are several times slower."""
    height, width, _ = rgb.shape
    rows = jnp.where(mask[..., None], rgb, 0.0).reshape(height, width * 3)
    total = (jnp.ones((height,), rgb.dtype) @ rows).reshape(width, 3).sum(axis=0)
    return total / jnp.maximum(jnp.sum(mask, dtype=rgb.dtype), 1.0)  # exact counts up to 2**24 pixels


def estimate_pixels(model: AbstractEstimator, rgb: Float[Array, "H W 3"], mask: Bool[Array, "H W"]) -> Estimate:
    """Run a model on every masked pixel of an image (no block averaging), jit-able.

    Image-only models get the image; grey-world models (linear in the pixels) get the masked mean
    as a single datum, which gives the same estimate with one fast reduction; others get the
    pixel list.
    """
    from ccjax.estimators.simple import GreyWorld

    if model.input_kind == "image":
        return _concrete(model)(rgb, mask)
    if isinstance(model, GreyWorld):
        return model(masked_mean(rgb, mask)[None], jnp.any(mask)[None])
    return _concrete(model)(rgb.reshape(-1, 3), mask.reshape(-1))
