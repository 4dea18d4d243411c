"""Image-only estimators: the grey-edge family (van de Weijer, Gevers & Gijsenij 2007).

Not in the thesis (Barnard 1999 works on surface lists); these need the spatial layout, so they
take an image ``(H, W, 3)`` with a pixel mask ``(H, W)`` (``input_kind = "image"``).

Definition (the general grey-world / grey-edge hypothesis). For each channel ``c``:

* ``n = 0``: ``d_c = f_c * G_sigma`` (the image smoothed by a Gaussian; ``sigma = 0`` is no
  smoothing);
* ``n = 1``: ``d_c = sqrt(f_cx^2 + f_cy^2)``, the gradient magnitude of the smoothed image;
* ``n = 2``: ``d_c = sqrt(f_cxx^2 + 4 f_cxy^2 + f_cyy^2)`` (van de Weijer's reference code);

where derivatives are Gaussian derivatives of scale ``sigma`` (SciPy's kernels: the sampled
Gaussian normalised to unit sum on ``|x| <= round(4 sigma)``, times the derivative polynomial),
or, for ``sigma = 0`` and ``n >= 1``, central differences ``(f[x+1] - f[x-1]) / 2`` and
``f[x+1] - 2 f[x] + f[x-1]``. Borders replicate the edge pixel (``mode="nearest"``). The estimate
is the Minkowski mean ``e_c = (mean over valid positions of d_c^p)^(1/p)``, ``p = inf`` meaning
the maximum. A position is valid when every pixel within the filter's support radius (0 for
``n = sigma = 0``, 1 for central differences, ``ceil(2 sigma)`` for Gaussians) is valid, so clipped
pixels do not create false edges. Special cases: ``(0, 1, 0)`` is grey world, ``(0, inf, 0)``
max-RGB, ``(0, p, 0)`` shades of grey. The magnitude of the estimate is arbitrary.

Everything is a pure function of the image: ``jit``, ``vmap`` over image batches and ``grad``
with respect to the pixels work.
"""

from __future__ import annotations

import math
import typing
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from ccjax import limits
from ccjax.estimators.base import AbstractImageEstimator, AbstractUnblockedEstimator, Estimate, with_fallback
from ccjax.estimators.minkowski import check_norm, minkowski_norm, minkowski_parts
from ccjax.estimators.registry import register
from ccjax.estimators.simple import average_illuminant
from ccjax.estimators.tiles import map_row_tiles, tile_rows
from ccjax.world import World

# SciPy's gaussian_filter truncates its kernels at 4 sigma; using the same taps makes the filter
# bit-for-bit the textbook one that the reference implementation in tests/ uses.
_TRUNCATE = 4.0
# Relative size below which an edge response counts as zero (float32 rounding of a flat image).
_FLAT = 1e-5


def derivative_kernel(sigma: float, order: int) -> np.ndarray:
    """Taps ``k[x]`` (``x = -r .. r``) of a 1-D derivative filter, applied as ``sum_x k[x] f[i - x]``.

    Arguments:
        sigma: Gaussian scale in pixels; 0 selects central differences (identity for order 0).
        order: derivative order 0, 1 or 2.

    Returns:
        ``(2r + 1,)`` float64 taps.
    """
    if sigma == 0:
        return {0: np.array([1.0]), 1: np.array([-0.5, 0.0, 0.5])[::-1].copy(), 2: np.array([1.0, -2.0, 1.0])}[order]
    radius = int(_TRUNCATE * sigma + 0.5)
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    gauss = np.exp(-0.5 * (x / sigma) ** 2)
    gauss /= gauss.sum()
    polynomial = {0: np.ones_like(x), 1: -x / sigma**2, 2: x**2 / sigma**4 - 1.0 / sigma**2}[order]
    return polynomial * gauss


def support_radius(order: int, sigma: float) -> int:
    """Half-width of the neighbourhood that must be valid for a derivative value to count."""
    if sigma == 0:
        return 0 if order == 0 else 1
    return int(math.ceil(2.0 * sigma))


def _filter_axis(planes: Float[Array, "C H W"], taps: np.ndarray, axis: int) -> Float[Array, "C H W"]:
    """``out[i] = sum_x taps[x] planes[i - x]`` along ``axis`` with edge replication."""
    if taps.size == 1:
        return planes * float(taps[0])
    radius = taps.size // 2
    pad = [(0, 0)] * planes.ndim
    pad[axis] = (radius, radius)
    # Materialise the padded planes: with the edge padding fused into the tap sums, XLA's CPU
    # code clamps every index and runs 2-5x slower.
    padded = jax.lax.optimization_barrier(jnp.pad(planes, pad, mode="edge"))
    length = planes.shape[axis]

    def shifted(start):
        return jax.lax.slice_in_dim(padded, start, start + length, axis=axis)

    # A static loop over the taps (not the pixels), pairing the mirror taps of the symmetric
    # (even order) and antisymmetric (odd order) kernels: half the multiplications.
    reverse = taps[::-1]
    out = float(reverse[radius]) * shifted(radius)
    for k in range(1, radius + 1):
        left, right = float(reverse[radius - k]), float(reverse[radius + k])
        if left == right:
            out = out + left * (shifted(radius - k) + shifted(radius + k))
        elif left == -right:
            out = out + left * (shifted(radius - k) - shifted(radius + k))
        else:
            out = out + left * shifted(radius - k) + right * shifted(radius + k)
    return out


def _derivative(planes, sigma: float, order_y: int, order_x: int):
    # Channel-first planes, filtered along y (axis 1) first and x (axis 2) second: on XLA's CPU
    # backend this order and layout run several times faster than the others.
    smoothed = _filter_axis(planes, derivative_kernel(sigma, order_y), axis=1)
    # Materialise the first pass: fused into the second, XLA would recompute it for every tap.
    smoothed = jax.lax.optimization_barrier(smoothed)
    return _filter_axis(smoothed, derivative_kernel(sigma, order_x), axis=2)


def _safe_sqrt(x):
    positive = x > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, x, 1.0)), 0.0)


def _planar_response(
    image: Float[Array, "H W 3"], order: int, sigma: float
) -> tuple[Float[Array, "3 H W"], Float[Array, ""]]:
    """``d_c`` of the module docstring, channel first, divided by a power of two ``up``.

    A derivative's square overflows float32 above about 1.8e19 (an image scaled by 1e20 had
    infinite edges and fell back) and underflows below about 1e-19 (no edges at all). The filters
    are linear, so the image is divided by the power of two ``up`` that brings its largest value
    near 1 (exact; inside the padding pass, which reads the image anyway), and the caller
    multiplies its few results by ``up`` (multiplying the response itself cost 30% of the
    estimate: XLA then computed the root once for each of its consumers).

    Arguments:
        image: ``(H, W, 3)``.
        order, sigma: the derivative order and scale.

    Returns:
        ``(response / up, up)``; ``up`` is 1 for ``order = 0`` (no square).
    """
    if order == 0:
        return _derivative(jnp.moveaxis(image, -1, 0), sigma, 0, 0), jnp.ones((), image.dtype)
    down, up = _power_of_two_scale(jnp.max(jnp.abs(image)))
    planes = jnp.moveaxis(image * down, -1, 0)
    if order == 1:
        dx, dy = jax.lax.optimization_barrier((_derivative(planes, sigma, 0, 1), _derivative(planes, sigma, 1, 0)))
        return _safe_sqrt(dx**2 + dy**2), up
    xx, yy, xy = jax.lax.optimization_barrier(
        (_derivative(planes, sigma, 0, 2), _derivative(planes, sigma, 2, 0), _derivative(planes, sigma, 1, 1))
    )
    return _safe_sqrt(xx**2 + 4.0 * xy**2 + yy**2), up


def _power_of_two_scale(largest: Float[Array, ""]) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """``(2^-e, 2^e)`` with ``2^e`` the power of two at or just above ``largest`` (held out of the
    gradient), ``e`` kept within ``[-126, 126]`` so that both are normal floats (a subnormal
    factor is flushed to zero on devices): values up to float32's largest come out below 4."""
    _, exponent = jnp.frexp(jax.lax.stop_gradient(largest))
    exponent = jnp.clip(exponent, -126, 126)
    one = jnp.ones((), largest.dtype)
    return jnp.ldexp(one, -exponent), jnp.ldexp(one, exponent)


def edge_response(image: Float[Array, "H W 3"], order: int, sigma: float) -> Float[Array, "H W 3"]:
    """``d_c`` of the module docstring: smoothed image (n = 0) or derivative magnitude (n = 1, 2)."""
    response, up = _planar_response(image, order, sigma)
    return jnp.moveaxis(response * up, 0, -1)


def valid_positions(mask: Bool[Array, "H W"], radius: int) -> Bool[Array, "H W"]:
    """Erode the pixel mask by a ``(2 radius + 1)^2`` square (edge-replicated borders)."""
    if radius == 0:
        return mask
    # Separable: a square erosion is a row erosion followed by a column erosion.
    for axis in (0, 1):
        padded = jnp.pad(mask, [(radius, radius) if a == axis else (0, 0) for a in (0, 1)], mode="edge")
        length = mask.shape[axis]
        eroded = jax.lax.slice_in_dim(padded, 0, length, axis=axis)
        for start in range(1, 2 * radius + 1):
            eroded = eroded & jax.lax.slice_in_dim(padded, start, start + length, axis=axis)
        mask = eroded
    return mask


def _filter_radius(order: int, sigma: float) -> int:
    """Half-width of the derivative filters (rows a tile needs above and below its own)."""
    return max(derivative_kernel(sigma, n).size // 2 for n in range(order + 1))


def edge_norms(
    image: Float[Array, "H W 3"],
    mask: Bool[Array, "H W"],
    order: int,
    sigma: float,
    p: Float[ArrayLike, ""],
    *,
    rows: int | None = None,
) -> tuple[Float[Array, "3"], Bool[Array, ""], Float[Array, ""]]:
    """The grey-edge estimate of the module docstring, in row tiles of ``rows`` image rows
    (:func:`ccjax.estimators.tiles.map_row_tiles`; None: the whole image at once). A tile
    gathers the filters' support above and below its rows, so each position's response is the
    whole image's; the Minkowski sums of the tiles are combined at the largest tile scale, which
    changes the estimate by float rounding only.

    Arguments:
        image: ``(H, W, 3)``.
        mask: ``(H, W)`` usable pixels.
        order, sigma: the derivative order and scale.
        p: the Minkowski norm.
        rows: image rows per tile, or None.

    Returns:
        ``(estimate (3,), any valid position, largest |masked pixel value|)``.
    """
    p = jnp.asarray(p, image.dtype)
    radius = support_radius(order, sigma)
    halo = max(radius, _filter_radius(order, sigma))

    def parts(tile, usable, own, margin=halo):
        # The tile's own rows lie ``margin`` rows inside it; the rest is the filters' support.
        response, up = _planar_response(tile, order, sigma)
        response = response[:, margin : margin + own.size]
        valid = valid_positions(usable, radius)[margin : margin + own.size] & own[:, None]
        own_pixels = usable[margin : margin + own.size] & own[:, None]
        brightest = jnp.max(jnp.abs(jnp.where(own_pixels[..., None], tile[margin : margin + own.size], 0.0)))
        maximum, scale, total, count = minkowski_parts(response, valid, p)
        # The sums are of (response / scale)^p, the same for the response divided by up.
        return maximum * up, scale * up, total, count, brightest

    if rows is None:
        maximum, scale, total, count, brightest = parts(image, mask, jnp.ones(image.shape[0], bool), margin=0)
        return minkowski_norm((maximum, scale, total, count), p), count > 0, brightest
    maxima, scales, totals, counts, brightest = map_row_tiles(parts, image, mask, rows=rows, halo=halo)
    scale = jnp.max(scales, axis=0)
    finite_p = jnp.where(jnp.isinf(p), 1.0, p)
    # Each tile's sums were taken at its own per-channel scale: bring them to the largest (ratios <= 1).
    rescaled = jnp.where(totals > 0, totals * (scales / scale) ** finite_p, 0.0)
    count = counts.sum()
    estimate = minkowski_norm((jnp.max(maxima, axis=0), scale, rescaled.sum(axis=0), count), p)
    return estimate, count > 0, jnp.max(brightest)


@typing.final
class GreyEdge(AbstractImageEstimator, AbstractUnblockedEstimator):
    """Grey edge of order ``n``, Minkowski norm ``p`` and scale ``sigma`` (module docstring).

    Call it on one image: ``model(image (H, W, 3), mask (H, W)) -> Estimate``; ``jax.vmap`` it over
    ``(B, H, W, 3)`` batches. Falls back (``ok=False``) to the world's average training illuminant
    when no position is valid or every edge is zero (a flat image has no edges).

    Attributes:
        p: the Minkowski norm (an array: it can be learned; ``inf`` is the maximum).
        fallback: ``(3,)`` estimate for images without usable edges.
        order: derivative order 0, 1 or 2 (static: it selects the filters).
        sigma: Gaussian scale in pixels (static: it sets the filter taps).
    """

    p: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    fallback: Float[Array, "3"]
    order: int = eqx.field(static=True)
    sigma: float = eqx.field(static=True)
    # The image and its usable-pixel mask: an image estimator never gets blocks.
    estimates_brightness: ClassVar[bool] = False
    world_based: ClassVar[bool] = False
    default_preprocessing: ClassVar[str] = "pixels"
    pools_pixels: ClassVar[bool] = False

    def __check_init__(self):
        # Also run on a model read from a file (ccjax._cache.load_model): its p is the file's.
        check_norm(self.p)
        if not (0 <= self.sigma <= limits.SIGMA.value):
            raise ValueError(
                f"sigma: {self.sigma!r} is outside [0, {limits.SIGMA.value:g}] ({limits.describe(limits.SIGMA)})"
            )

    def __call__(self, image: Float[Array, "H W 3"], mask: Bool[Array, "H W"]) -> Estimate:
        if image.ndim != 3 or image.shape[-1] != 3 or mask.shape != image.shape[:2]:
            raise ValueError(
                f"image, mask: grey edge takes an image (H, W, 3) and its mask (H, W), got shapes "
                f"{tuple(image.shape)} and {tuple(mask.shape)} (a pixel list has no edges; "
                "ccjax.estimate gives it an image)"
            )
        # Camera-sized images in row tiles: the filters' intermediates are several image-sized
        # arrays otherwise (4 GB at 48 MP).
        rows = tile_rows(*mask.shape)
        estimate, any_valid, brightest = edge_norms(image, mask, self.order, self.sigma, self.p, rows=rows)
        # Edges of a flat image are rounding noise, not zero: demand edges above float precision,
        # relative to the image's brightest value (scale-free; a black image has floor 0 and no
        # positive edge).
        floor = _FLAT * jax.lax.stop_gradient(brightest)
        usable = any_valid & jnp.all(estimate > floor)
        return with_fallback(estimate, usable, self.fallback)


def fit_grey_edge(world: World, order: int = 1, p: float = 6.0, sigma: float = 2.0) -> GreyEdge:
    """Build a :class:`GreyEdge` (no training: the world only supplies the fallback).

    Arguments:
        world: the world whose average training illuminant is the fallback.
        order: derivative order 0, 1 or 2.
        p: Minkowski norm, ``>= 1`` or ``inf``.
        sigma: Gaussian scale in pixels, ``>= 0`` (0 with ``order >= 1``: central differences).
    """
    if order not in (0, 1, 2):
        raise ValueError(f"order: expected 0, 1 or 2, got {order!r}")
    if not (p >= 1):
        raise ValueError(f"p: expected a Minkowski norm >= 1 or inf, got {p!r}")
    if not (sigma >= 0 and math.isfinite(sigma)):
        raise ValueError(f"sigma: expected a finite scale >= 0, got {sigma!r}")
    if sigma > limits.SIGMA.value:
        raise ValueError(f"sigma: {sigma:g} is over {limits.describe(limits.SIGMA)}")
    fallback = average_illuminant(world)
    return GreyEdge(p=jnp.asarray(p, fallback.dtype), fallback=fallback, order=int(order), sigma=float(sigma))


def _number(text: str) -> float:
    return math.inf if text == "inf" else float(text)


@register(
    r"grey-edge-(?P<n>[012])-(?P<p>inf|\d+(\.\d+)?)-(?P<sigma>\d+(\.\d+)?)",
    grammar="grey-edge-<n>-<p>-<sigma> (n in 0, 1, 2; p a number or inf)",
    example="grey-edge-1-6-2",
    description="grey edge n-p-sigma (van de Weijer 2007; image input)",
    input_kind="image",
    traceable_fit=True,
    differentiable=True,
)
def _build_grey_edge(world, match, **options):
    return fit_grey_edge(world, order=int(match["n"]), p=_number(match["p"]), sigma=float(match["sigma"]), **options)
