"""From an image to an estimator's input (Barnard 1999 §4.6, Table 4.6).

:func:`prepare` gives what a model is called with, per model by default
(``model.default_preprocessing``, overridable per call):

* ``pixels`` (statistics methods: grey world, shades of grey, max-RGB, grey edge): the image and
  its usable mask, every pixel that is not clipped, has no zero channel and lies inside the
  optional user mask (the field's protocol); :func:`run_model` gives surface models the pixel
  list (grey world: the masked mean, the same estimate from one reduction).
* ``ave5`` and the other Table 4.6 methods (:data:`TABLE_4_6`; world-based methods: gamut
  mapping, Colour by Correlation, nets, DB-GW): the thesis' surface list. Clipped pixels are
  dropped (§2.7), and too-dark ones (R+G+B below ``dark`` = 2 % of the 99th percentile of the
  usable pixels' R+G+B, :func:`usable_pixels`), then block averaging (default 5x5, "roughly
  optimal", §4.6), block averaging + RGB clustering, block averaging + convex-hull reduction, or
  region-growing segmentation reduce the image to a list of surfaces, padded to a power of two
  (:func:`padded_size`) so jit compiles once per size class.
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
"""The thesis' preprocessing (§4.6): the default of world-based surface-list methods."""
PIXELS = "pixels"
"""Every usable pixel, no dark rule: the default of the statistics methods (the field's protocol)."""
DEFAULT_DARK = 0.02
"""Dark rule: drop pixels whose R+G+B is below this fraction of the reference brightness."""
DEFAULT_PERCENTILE = 99.0
"""Dark rule: the reference brightness is this percentile of the usable pixels' R+G+B."""

_CHUNK_PIXELS = 1 << 20  # pixels per chunk of block averaging (bounded working memory)


def _check_mask(mask: np.ndarray | None, shape: tuple[int, ...], what: str = "mask") -> np.ndarray | None:
    if mask is None:
        return None
    mask = np.asarray(mask)
    if mask.dtype != bool:
        raise ValueError(f"{what}: expected a boolean (H, W) array, got dtype {mask.dtype}")
    if mask.shape != tuple(shape):
        raise ValueError(f"{what}: expected shape {tuple(shape)} (the image's height and width), got {mask.shape}")
    return mask


def usable_pixels(
    rgb: np.ndarray,
    clipped: np.ndarray,
    dark: float = DEFAULT_DARK,
    *,
    percentile: float = DEFAULT_PERCENTILE,
    mask: np.ndarray | None = None,
) -> np.ndarray:
    """Pixels an estimator may use (§4.6: clipped and "overly dark" pixels are discarded).

    A pixel is usable when

    1. it is not clipped (``clipped``: a channel at or above the saturation level, or transparent;
       :func:`ccjax.io.read_image`), and
    2. no channel is zero or negative: a channel at the black level says nothing about the light
       in that channel (under-exposed, or noise clamped at black), and the field's protocol drops
       such pixels, and
    3. it lies inside ``mask`` (optional user mask, e.g. excluding a colour checker), and
    4. (the dark rule, ``dark > 0``) its R+G+B is at least ``dark`` times the ``percentile``-th
       percentile of the R+G+B of the pixels passing 1-3.

    The thesis discards "overly dark" pixels without saying relative to what (§4.6, §2.7). The
    reference is a high percentile, not the single brightest pixel: one specular highlight then
    raised the threshold so far that it discarded most of a photograph (one image kept 460 of
    4,096 pixels). ``percentile=100`` is that old rule (the brightest usable pixel). Percentiles
    interpolate linearly between order statistics (``numpy.percentile``'s default).

    Arguments:
        rgb: ``(H, W, 3)`` linear image (not modified, not copied).
        clipped: ``(H, W)`` True where a pixel is not usable (saturated or transparent).
        dark: fraction in ``[0, 1)``; 0 disables the dark rule (rules 1-3 only).
        percentile: the reference percentile in ``(0, 100]``.
        mask: optional ``(H, W)`` bool, True where the user allows a pixel.

    Returns:
        ``(H, W)`` bool.
    """
    if not 0 <= dark < 1:
        raise ValueError(f"dark: expected a fraction in [0, 1), got {dark!r}")
    if not 0 < percentile <= 100:
        raise ValueError(f"percentile: expected a number in (0, 100], got {percentile!r}")
    mask = _check_mask(mask, rgb.shape[:2])
    # Channel by channel: (H, W) booleans, never an (H, W, 3) temporary (48-MP images).
    usable = ~clipped & (rgb[..., 0] > 0)
    usable &= rgb[..., 1] > 0
    usable &= rgb[..., 2] > 0
    if mask is not None:
        usable &= mask
    if dark == 0 or not usable.any():
        return usable
    brightness = rgb.sum(axis=-1)
    candidates = brightness[usable]
    # overwrite_input: the percentile may reorder this copy in place instead of making another.
    reference = float(np.percentile(candidates, percentile, overwrite_input=True))
    del candidates
    usable &= brightness >= dark * reference
    return usable


def _tile_starts(length: int, block: int) -> np.ndarray:
    return np.arange(0, length, block)


def _tile_sizes(length: int, block: int) -> np.ndarray:
    return np.diff(np.append(_tile_starts(length, block), length))


def block_average(
    rgb: np.ndarray,
    usable: np.ndarray,
    block: int,
    max_rg_spread: float | None = None,
    *,
    edges: bool = False,
) -> np.ndarray:
    """Means of non-overlapping ``block x block`` tiles whose pixels are all usable (§4.6, the
    thesis' ``ave<b>``).

    Arguments:
        rgb: ``(H, W, 3)`` linear image.
        usable: ``(H, W)`` from :func:`usable_pixels`.
        block: tile side in pixels.
        max_rg_spread: an extension, not in the thesis: also drop tiles whose pixels' (r,g)
            bounding box has a diagonal above it, i.e. tiles straddling a boundary between surfaces,
            whose mean is a mixture no surface produces (harmless for gamut mapping, which is
            convex, but it fills histogram cells for Colour by Correlation).
        edges: an extension (``ave<b>-edges``): also keep the partial tiles of the right and bottom
            edges (fewer than ``block`` rows or columns), under the same rule (all their pixels
            usable). Without it those edge rows and columns are dropped, as in the thesis.

    Returns:
        ``(n, 3)`` float32 tile means (summed in float64), in scan order.

    The image is processed in bands of whole tile rows, so the working memory stays small (a few
    megabytes) whatever the image size: no copy of the image is made.
    """
    if block < 1:
        raise ValueError(f"block: expected a tile side >= 1, got {block!r}")
    height, width = rgb.shape[:2]
    if not edges:
        height, width = (height // block) * block, (width // block) * block
    if height == 0 or width == 0:
        return np.zeros((0, 3), np.float32)
    columns = _tile_starts(width, block)
    column_sizes = _tile_sizes(width, block)
    band = block * max(1, _CHUNK_PIXELS // (block * width))
    means = []
    for top in range(0, height, band):
        bottom = min(top + band, height)
        rows = _tile_starts(bottom - top, block)
        part = rgb[top:bottom, :width]
        sums = np.add.reduceat(np.add.reduceat(part, rows, axis=0, dtype=np.float64), columns, axis=1)
        counts = np.add.reduceat(
            np.add.reduceat(usable[top:bottom, :width], rows, axis=0, dtype=np.int32), columns, axis=1
        )
        sizes = _tile_sizes(bottom - top, block)[:, None] * column_sizes[None, :]
        ok = counts == sizes
        if max_rg_spread is not None:
            total = part.sum(axis=-1, keepdims=True, dtype=np.float64)
            chroma = part[..., :2] / np.where(total > 0, total, 1.0)
            high = np.maximum.reduceat(np.maximum.reduceat(chroma, rows, axis=0), columns, axis=1)
            low = np.minimum.reduceat(np.minimum.reduceat(chroma, rows, axis=0), columns, axis=1)
            ok &= np.sqrt(((high - low) ** 2).sum(axis=-1)) <= max_rg_spread
        means.append((sums / sizes[..., None])[ok])
    return np.concatenate(means).astype(np.float32)


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
    """One of the thesis' preprocessing methods (Table 4.6), parsed from a name, or ``pixels``.

    ``ave<b>`` (block averaging, ``ave1`` = single pixels), ``ave<b>-cluster`` (+ RGB clustering,
    100 divisions), ``ave<b>-hull`` (+ convex-hull reduction), ``seg-<min size>-<rg tol>-<rel
    R+G+B tol>`` (segmentation, e.g. ``seg-5-0.005-0.2``), ``seg-...-hull``, and ``generic``
    (Table 4.5's segmentation, ``seg-5-0.05-0.1``). These use the dark rule of
    :func:`usable_pixels`.

    Extensions: ``pixels``, every usable pixel with no dark rule (the image and its mask, as the
    field evaluates statistics methods: :func:`prepare`); ``ave<b>-edges`` also keeps the partial
    tiles of the right and bottom edges (:func:`block_average`); ``ave<b>-u<spread>`` keeps only
    blocks whose (r,g) spread is at most ``<spread>`` (e.g. ``ave5-u0.04``). They combine in the
    order ``ave<b>[-edges][-u<spread>][-cluster|-hull]``, e.g. ``ave5-edges-hull``.
    """

    name: str
    block: int = 5
    segmentation: tuple[int, float, float] | None = None
    reduction: str | None = None  # None, "cluster" or "hull"
    max_rg_spread: float | None = None
    edges: bool = False
    pixels: bool = False

    @classmethod
    def parse(cls, name: str) -> Preprocessing:
        """The method called ``name`` (class docstring); ``ValueError`` for unknown names."""
        if name == PIXELS:
            return cls(name=name, block=1, pixels=True)
        text = "seg-5-0.05-0.1" if name == "generic" else name
        number = r"(\d+(?:\.\d*)?|\.\d+)"
        match = re.fullmatch(rf"ave(\d+)(-edges)?(?:-u{number})?(?:-(cluster|hull))?", text)
        if match and int(match[1]) >= 1:
            spread = None if match[3] is None else float(match[3])
            return cls(
                name=name,
                block=int(match[1]),
                reduction=match[4],
                max_rg_spread=spread,
                edges=match[2] is not None,
            )
        match = re.fullmatch(rf"seg-(\d+)-{number}-{number}(?:-(hull))?", text)
        if match:
            return cls(
                name=name, block=1, segmentation=(int(match[1]), float(match[2]), float(match[3])), reduction=match[4]
            )
        raise ValueError(
            f"preprocessing: unknown method {name!r}; expected pixels, ave<b>[-edges][-u<spread>][-cluster|-hull], "
            "seg-<min>-<rg>-<rel>[-hull] or generic"
        )

    def apply(self, rgb: np.ndarray, usable: np.ndarray) -> np.ndarray:
        """The surface list ``(n, 3)`` for one image (``usable`` from :func:`usable_pixels`;
        ``pixels``: the usable pixels themselves, in scan order)."""
        if self.pixels:
            return rgb[usable]
        if self.segmentation is not None:
            data = segment(rgb, usable, *self.segmentation)
        else:
            data = block_average(rgb, usable, self.block, self.max_rg_spread, edges=self.edges)
        if self.reduction == "cluster":
            data = cluster_rgb(data)
        elif self.reduction == "hull":
            data = hull_reduce(data)
        return data

    def max_count(self, height: int, width: int) -> int:
        """The most surfaces :meth:`apply` can return for an ``height x width`` image."""
        if self.pixels:
            return height * width
        if self.segmentation is not None:
            return (height * width) // max(self.segmentation[0], 1)
        if self.edges:
            return -(-height // self.block) * -(-width // self.block)
        return (height // self.block) * (width // self.block)


def as_preprocessing(preprocessing: str | Preprocessing) -> Preprocessing:
    """``preprocessing`` as a :class:`Preprocessing` (names are parsed; ``ValueError`` if unknown)."""
    return preprocessing if isinstance(preprocessing, Preprocessing) else Preprocessing.parse(preprocessing)


def resolve(model: AbstractEstimator, preprocessing: str | Preprocessing | None = None) -> Preprocessing:
    """The preprocessing ``model`` gets: ``preprocessing``, or the model's own default
    (``model.default_preprocessing``: ``pixels`` for the statistics methods, ``ave5`` for the
    world-based ones) when it is None. Image estimators always get the image (``pixels``): they
    need the pixels' neighbours, so a surface-list preprocessing cannot apply to them."""
    if model.input_kind == "image":
        return Preprocessing.parse(PIXELS)
    return as_preprocessing(model.default_preprocessing if preprocessing is None else preprocessing)


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
    mask: np.ndarray | None = None,
    percentile: float = DEFAULT_PERCENTILE,
) -> tuple[np.ndarray, np.ndarray]:
    """Estimator input of a surface-list method.

    Arguments:
        image: a :class:`ccjax.io.LinearImage`.
        preprocessing: a :class:`Preprocessing` or its name (default ``ave5``). ``pixels`` gives
            the list of usable pixels (no dark rule); :func:`prepare` gives the image instead,
            which is smaller and faster.
        dark, percentile, mask: the usable-pixel rules (:func:`usable_pixels`).
        pad: pad to :func:`padded_size` with masked zero rows, so batches share compiled code.

    Returns:
        ``(rgb (N, 3) float32, mask (N,) bool)``.
    """
    method = as_preprocessing(preprocessing)
    usable = usable_pixels(image.rgb, image.clipped, 0.0 if method.pixels else dark, percentile=percentile, mask=mask)
    data = method.apply(image.rgb, usable)
    size = padded_size(len(data)) if pad else len(data)
    rgb = np.zeros((size, 3), np.float32)
    rgb[: len(data)] = data
    valid = np.arange(size) < len(data)
    return rgb, valid


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
    method = resolve(model, preprocessing)
    if method.pixels:
        return image.rgb, usable_pixels(image.rgb, image.clipped, 0.0, mask=mask)
    return surfaces(image, method, dark=dark, mask=mask, percentile=percentile)


def input_key(model: AbstractEstimator, preprocessing: str | Preprocessing | None = None) -> str:
    """A key equal for models that :func:`prepare` gives the same input (with the same image,
    dark rule and mask): the resolved method's name, so a caller prepares each input once."""
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


def model_input(
    model: AbstractEstimator,
    image: LinearImage,
    preprocessing: str | Preprocessing | None = None,
    *,
    dark: float = DEFAULT_DARK,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`prepare` (kept for callers of the earlier name)."""
    return prepare(model, image, preprocessing, dark=dark)


def _concrete(model: AbstractEstimator) -> Callable[[Array, Array], Estimate]:
    # The abstract base declares no __call__ (its surface and image subtypes do, with different
    # shapes), so the type checker is told here what every fitted model is.
    return cast(Callable[[Array, Array], Estimate], model)


@eqx.filter_jit
def run_model(model: AbstractEstimator, rgb: Array, mask: Array) -> Estimate:
    """Run ``model`` on what :func:`prepare` gave, jit-compiled once per model structure and
    input shape: an image ``(H, W, 3)`` goes through :func:`estimate_pixels` (so surface models
    see every usable pixel), a surface list ``(N, 3)`` to the model directly."""
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
    ``W * 3`` values: XLA's CPU reductions over a minor axis of 3 are several times slower."""
    height, width, _ = rgb.shape
    rows = jnp.where(mask[..., None], rgb, 0.0).reshape(height, width * 3)
    total = (jnp.ones((height,), rgb.dtype) @ rows).reshape(width, 3).sum(axis=0)
    return total / jnp.maximum(jnp.sum(mask, dtype=rgb.dtype), 1.0)  # exact counts up to 2**24 pixels


def estimate_pixels(model: AbstractEstimator, rgb: Float[Array, "H W 3"], mask: Bool[Array, "H W"]) -> Estimate:
    """Run a model on every masked pixel of an image (no block averaging), jit-able.

    Image-only models get the image; models linear in the pixels (``model.pools_pixels``: grey
    world) get the masked mean as a single datum, which gives the same estimate with one fast
    reduction; others get the pixel list.
    """
    if model.input_kind == "image":
        return _concrete(model)(rgb, mask)
    if model.pools_pixels:
        return model(masked_mean(rgb, mask)[None], jnp.any(mask)[None])
    return _concrete(model)(rgb.reshape(-1, 3), mask.reshape(-1))
