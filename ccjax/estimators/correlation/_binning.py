"""(r,g) and (r, g, L) binning and the scene-scoring kernels of Colour by Correlation, hard (the
thesis') and soft (differentiable). One scene at a time; jit- and vmap-able."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ccjax._colour import rg, rg_bin, rg_numpy

RG_BINS = 50
"""(r,g) divisions: bins of width 0.02, as the thesis' C-by-C and neural net (§4.5.4)."""
N_RG_CELLS = RG_BINS * (RG_BINS + 1) // 2  # bins (i, j) with i + j <= 49
"""The (r,g) cells inside the chromaticity triangle: bins ``(i, j)`` with ``i + j <= 49`` (1275)."""


def rg_bins(rgb: Float[Array, "... 3"]) -> Int[Array, "... 2"]:
    """(r,g) bin coordinates ``floor(50 r), floor(50 g)`` clipped to ``0..49`` (§4.5.4), from the
    scale-free :func:`ccjax._colour.rg`; a black pixel lands in the achromatic bin (the kernels ignore
    black pixels).

    Arguments:
        rgb: ``(..., 3)`` non-negative camera RGB (any scale).

    Returns:
        ``(..., 2)`` integer bin indices ``(i, j)`` in ``0..49`` of ``r = R/(R+G+B)`` and
        ``g = G/(R+G+B)``; the flat bin (a correlation-matrix row) is ``50 i + j``.
    """
    return rg_bin(rg(rgb), RG_BINS)


def rg_bins_np(rgb: np.ndarray) -> np.ndarray:
    """:func:`rg_bins` in NumPy at the input's precision (fit time), as int64."""
    return np.clip(np.floor(rg_numpy(rgb) * RG_BINS), 0, RG_BINS - 1).astype(np.int64)


def compact_rg_cells() -> np.ndarray:
    """``(2500,)`` compact index of each (r,g) bin ``50 i + j``: ``0..1274`` where ``i + j <= 49``
    (row-major over the possible half), ``-1`` for impossible bins (r + g > 1, §10.2).

    Returns:
        ``(2500,)`` int64 array: entry ``50 i + j`` is the bin's index among the 1275 possible bins
        (``N_RG_CELLS``), or ``-1`` where ``i + j > 49``.
    """
    i, j = np.divmod(np.arange(RG_BINS * RG_BINS), RG_BINS)
    possible = i + j <= RG_BINS - 1
    cells = np.full(RG_BINS * RG_BINS, -1, np.int64)
    cells[possible] = np.arange(int(possible.sum()))
    return cells


def _unique_first(keys: Int[Array, " K"], valid: Bool[Array, " K"]) -> tuple[Int[Array, " K"], Bool[Array, " K"]]:
    """Sort ``keys`` (invalid entries last) and flag the first entry of each distinct valid key."""
    big = jnp.iinfo(keys.dtype).max
    ordered = jnp.sort(jnp.where(valid, keys, big))
    first = (ordered != jnp.concatenate([jnp.full((1,), -1, keys.dtype), ordered[:-1]])) & (ordered != big)
    return ordered, first


def presence_scores(
    log_probability: Float[Array, "C I"], rgb: Float[Array, "P 3"], valid: Bool[Array, " P"]
) -> Float[Array, " I"]:
    """``M x`` of §4.5.4: the sum of the matrix rows of the (r,g) bins present in the scene (each
    bin once, whatever the number of pixels in it).

    Arguments:
        log_probability: ``(2500, I)`` matrix, row ``50 i + j`` for (r,g) bin ``(i, j)``, one column
            per training illuminant: log P(bin | illuminant) for C-by-C, or the 0/1 compatibility
            matrix for C-by-C-01.
        rgb: ``(P, 3)`` the scene's camera RGB.
        valid: ``(P,)`` True for the pixels to count (:func:`valid_pixels`).

    Returns:
        ``(I,)`` per illuminant, the sum of the rows of the distinct bins of the valid pixels: the
        log-likelihood (unnormalised log-posterior under a uniform prior), or with a 0/1 matrix the
        number of scene bins compatible with it. All zeros when no pixel is valid.
    """
    bins = rg_bins(rgb)
    cells, first = _unique_first(bins[:, 0] * RG_BINS + bins[:, 1], valid)
    rows = log_probability.at[jnp.where(first, cells, 0)].get(mode="promise_in_bounds")
    return jnp.sum(jnp.where(first[:, None], rows, 0.0), axis=0)


def soft_axis(x: Float[Array, "..."], softness: float) -> tuple[Int[Array, "... 2"], Float[Array, "... 2"]]:
    """Soft binning along one axis (``x`` in bin units, bin ``k`` covers ``[k, k+1)``): the two bins
    either side of the nearest bin edge ``m``, with weights ``1 - s, s``, ``s = sigmoid((x - m) /
    softness)``. As ``softness -> 0`` it is ``floor``; the weights are smooth in ``x`` except for a
    jump of about ``exp(-0.5 / softness)`` at bin centres, where the pair changes."""
    edge = jnp.round(x)
    upper = jax.nn.sigmoid((x - edge) / softness)
    index = edge.astype(jnp.int32)
    return jnp.stack([index - 1, index], axis=-1), jnp.stack([1.0 - upper, upper], axis=-1)


def soft_presence_score(
    log_probability: Float[Array, "C I"], cells: Int[Array, " K"], weights: Float[Array, " K"], merge: Bool[Array, " K"]
) -> tuple[Float[Array, " I"], Float[Array, ""]]:
    """Soft presence: a cell reached by entries with weights ``w_k`` is present with probability
    ``1 - prod(1 - w_k)`` (1 when some pixel sits squarely in it). Entries with ``merge`` False are
    never pooled (the 3-D outside cell stands for many distinct cells).

    Returns:
        ``(sum over cells of presence x row, number of occupied cells)``.
    """
    size = cells.shape[0]
    key = jnp.where(merge, cells, -1 - jnp.arange(size, dtype=cells.dtype))  # unmergeable entries get unique keys
    order = jnp.argsort(key)
    key, cells, weights = key[order], cells[order], weights[order]
    start = key != jnp.concatenate([key[:1] - 1, key[:-1]])
    run = jnp.cumsum(start) - 1
    eps = jnp.finfo(weights.dtype).eps
    absent = jax.ops.segment_sum(jnp.log1p(-jnp.clip(weights, 0.0, 1.0 - 4 * eps)), run, num_segments=size)
    present = -jnp.expm1(absent)[run] * start.astype(absent.dtype)
    rows = log_probability.at[cells].get(mode="promise_in_bounds")
    return jnp.sum(present[:, None] * rows, axis=0), jnp.sum(present)


def soft_presence_scores(
    log_probability: Float[Array, "C I"], rgb: Float[Array, "P 3"], valid: Bool[Array, " P"], softness: float
) -> Float[Array, " I"]:
    """Differentiable :func:`presence_scores`: each pixel spreads over the 2 x 2 bins around it
    (:func:`soft_axis`), bins are present with probability ``1 - prod(1 - w)``.

    Arguments:
        log_probability: ``(2500, I)`` log P(bin | illuminant), row ``50 i + j`` for (r,g) bin
            ``(i, j)``, as for :func:`presence_scores`.
        rgb: ``(P, 3)`` the scene's camera RGB (gradients reach it through the bin weights).
        valid: ``(P,)`` True for the pixels to count; invalid pixels get zero weight.
        softness: soft binning scale in bins (``DEFAULT_SOFTNESS`` is 0.1); as it goes to 0 the
            result tends to :func:`presence_scores`.

    Returns:
        ``(I,)`` per illuminant, the sum over bins of presence probability times the bin's row.
    """
    # Black pixels sit at the achromatic point; their weights are zeroed by ``valid``.
    scaled = rg(rgb) * RG_BINS
    (ri, rw), (gi, gw) = soft_axis(scaled[:, 0], softness), soft_axis(scaled[:, 1], softness)
    ri, gi = jnp.clip(ri, 0, RG_BINS - 1), jnp.clip(gi, 0, RG_BINS - 1)
    cells = (ri[:, :, None] * RG_BINS + gi[:, None, :]).reshape(-1)
    weights = (rw[:, :, None] * gw[:, None, :] * valid[:, None, None].astype(rw.dtype)).reshape(-1)
    score, _ = soft_presence_score(log_probability, cells, weights, jnp.ones_like(cells, bool))
    return score
