"""Colour by Correlation: the 2-D (r,g) method (Barnard 1999 §4.5.4, after Finlayson, Hubel & Hordley
1997) and the 3-D (r, g, L) method of chapter 10, with soft (differentiable) variants.

A correlation matrix holds, per training illuminant, the log-probability of observing a colour cell
(spec ch02-04 §6.5, ch08-12 §4). It is computed once by a ``*_matrix`` function of the world (NumPy)
and stored in the fitted model as a plain array, so a matrix learned by gradient descent can be
dropped in with ``eqx.tree_at``. ccjax stores the thesis' matrix transposed, one column per training
illuminant, ``log_probability (cells, I)``: a scene's cells then gather contiguous rows.

2-D cells are the 50 x 50 (r,g) bins of width 0.02, ``cell = 50 * floor(50 r) + floor(50 g)``. 3-D
cells are ``rg_cell * l_total + floor(l_bins * L / b)``: ``rg_cell`` numbers the 1275 (r,g) bins
with ``i + j <= 49`` (the other half is impossible, r + g <= 1), ``L = R+G+B`` is divided by the
hypothesised illuminant brightness ``b`` (R+G+B of white) and ``l_bins`` bins cover matte
reflection ``[0, 1)``; ``l_total`` bins reach further for specular training. The last row of a 3-D
matrix is the "outside" cell (impossible chromaticity or brighter than modelled) at the floor.

Labels: ``C-by-C-01``, ``C-by-C-MAP``, ``C-by-C-MMSE``, ``C-by-C-MLM``; ``RGB-C-by-C-MAP`` and
``RGB-C-by-C-MMSE`` (discretisation remedy 2, presence minus ``n_occ log(b / B0)``, the default;
suffix ``-counts`` selects remedy 1, duplicate counts, as Table 10.1 used; ``-presence`` is explicit);
prefixes ``SPEC-`` (specular training world) and ``STD-`` (matte, Table 10.2's name); ``soft-``
variants of MAP and MMSE with kernel binning and softmax posteriors.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import tempfile
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int
from scipy.ndimage import gaussian_filter
from scipy.spatial import ConvexHull, QhullError

from ccjax.estimators.base import TINY, Estimate, Estimator, with_fallback
from ccjax.estimators.registry import register
from ccjax.estimators.simple import average_illuminant
from ccjax.scenes import Specular
from ccjax.world import World

RG_BINS = 50
"""(r,g) divisions: bins of width 0.02, as the thesis' C-by-C and neural net (§4.5.4)."""
N_RG_CELLS = RG_BINS * (RG_BINS + 1) // 2  # bins (i, j) with i + j <= 49
_CACHE_VERSION = 2
BRIGHTNESS_SIGMA = (0.75, 0.5)
"""Smoothing of the 3-D matrix in bins, (r,g) and L. The thesis gives none (spec ch08-12 A13); these
values reproduce Tables 10.1 and 10.2 best on World.barnard1999 (8 surfaces, 1000 scenes, rg RMS):
remedy 1 MAP/MMSE 0.0319/0.0264 (thesis 0.030/0.025), remedy 2 0.0252/0.0215 (0.029/0.024). With
(1, 1) they are 0.0404/0.0334 and 0.0316/0.0279; with (0.5, 0.5) 0.0304/0.0246 and 0.0254/0.0202."""
DEFAULT_SOFTNESS = 0.1
"""Soft binning scale in bins: weights move from one bin to the next over about +-0.3 bins."""
DEFAULT_TEMPERATURE = 0.05
"""Soft MAP: softmax of the log-posterior divided by this (-> MAP as it -> 0)."""


# ---------------------------------------------------------------------------------------------
# Binning (shared by the matrices and the estimators)


def _valid_pixels(rgb: Float[Array, "P 3"], mask: Bool[Array, "P"]) -> Bool[Array, "P"]:
    # A black pixel has no chromaticity: it carries no evidence about the light.
    return mask & (jnp.sum(rgb, axis=-1) > TINY)


def rg_bins(rgb: Float[Array, "... 3"]) -> Int[Array, "... 2"]:
    """(r,g) bin coordinates ``floor(50 r), floor(50 g)`` clipped to ``0..49`` (§4.5.4)."""
    total = jnp.sum(rgb, axis=-1, keepdims=True)
    rg = rgb[..., :2] / jnp.where(total > TINY, total, 1.0)
    return jnp.clip(jnp.floor(rg * RG_BINS), 0, RG_BINS - 1).astype(jnp.int32)


def _rg_bins_np(rgb: np.ndarray) -> np.ndarray:
    total = rgb.sum(axis=-1, keepdims=True)
    rg = rgb[..., :2] / np.where(total > 0, total, 1.0)
    return np.clip(np.floor(rg * RG_BINS), 0, RG_BINS - 1).astype(np.int64)


def compact_rg_cells() -> np.ndarray:
    """``(2500,)`` compact index of each (r,g) bin ``50 i + j``: ``0..1274`` where ``i + j <= 49``
    (row-major over the possible half), ``-1`` for impossible bins (spec ch08-12 §4.3 item 3)."""
    i, j = np.divmod(np.arange(RG_BINS * RG_BINS), RG_BINS)
    possible = i + j <= RG_BINS - 1
    cells = np.full(RG_BINS * RG_BINS, -1, np.int64)
    cells[possible] = np.arange(int(possible.sum()))
    return cells


# ---------------------------------------------------------------------------------------------
# Correlation matrices (fit time, NumPy)


def training_responses(world: World, specular: Specular | None = None, steps: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera RGB of every reflectance under every training illuminant, with frequency weights.

    Uniform statistics over surfaces and illuminants (§4.5.4, §10.2). With ``specular``, each
    surface also appears with ``s`` times the perfect white added, ``s`` at the midpoints of 8
    equal steps of ``[0, max_amount]``; the matte copy has weight ``1 - probability`` and each
    specular copy ``probability / 8`` (spec ch08-12 A18: a coarse model of the test generator).

    Returns:
        ``(rgb (I, K, 3), weights (K,), whites (I, 3))`` in float64.
    """
    sensors = np.asarray(world.camera.sensors, np.float64)
    lights = np.asarray(world.train_illuminants, np.float64)
    reflectances = np.asarray(world.reflectances, np.float64)
    whites = lights @ sensors
    lit = (lights[:, :, None] * sensors[None]).transpose(1, 0, 2).reshape(lights.shape[1], -1)  # (101, I*3)
    rgb = (reflectances @ lit).reshape(len(reflectances), len(lights), 3).transpose(1, 0, 2)  # one BLAS call
    weights = np.ones(rgb.shape[1])
    if specular is not None:
        amounts = (np.arange(steps) + 0.5) / steps * specular.max_amount
        shiny = rgb[:, :, None, :] + amounts[None, None, :, None] * whites[:, None, None, :]
        rgb = np.concatenate([rgb, shiny.reshape(rgb.shape[0], -1, 3)], axis=1)
        weights = np.concatenate(
            [np.full(weights.size, 1.0 - specular.probability), np.full(weights.size * steps, specular.probability / steps)]
        )
    return rgb, weights, whites


def _log_of_smoothed(counts: np.ndarray, sigma: tuple[float, ...], floor: float) -> np.ndarray:
    """Per illuminant (axis 0): Gaussian smoothing (``sigma`` in bins per remaining axis), normalise
    to probabilities, floor at ``floor`` x the illuminant's largest probability, log (§4.5.4)."""
    counts = np.asarray(counts, np.float32)  # float32: the 3-D matrices are tens of millions of cells
    if any(s > 0 for s in sigma):
        counts = gaussian_filter(counts, sigma=(0.0, *sigma), mode="constant", truncate=4.0, output=np.float32)
    flat = counts.reshape(counts.shape[0], -1)
    probability = flat / flat.sum(axis=1, keepdims=True, dtype=np.float64).astype(np.float32)
    lowest = floor * probability.max(axis=1, keepdims=True)
    return np.log(np.maximum(probability, lowest))


def chromaticity_matrix(world: World, *, sigma: float = 1.0, floor: float = 1e-6, specular: Specular | None = None) -> np.ndarray:
    """The probabilistic 2-D correlation matrix (§4.5.4): per training illuminant, the frequency of
    the reflectances' (r,g) bins, smoothed with a Gaussian of ``sigma`` bins, as log-probabilities.

    Arguments:
        world: supplies reflectances, training illuminants and camera.
        sigma: Gaussian smoothing in bins (the thesis does not give it; spec ch02-04 §10 item 20).
        floor: probabilities below ``floor`` x the illuminant's maximum are raised to it before the
            log, so no observation rules an illuminant out completely.
        specular: train on specular surfaces too (see :func:`training_responses`).

    Returns:
        ``(2500, I)`` float32 log-probabilities, row ``50 i + j`` for bin ``(i, j)``.
    """
    rgb, weights, _ = training_responses(world, specular)
    bins = _rg_bins_np(rgb)
    n_lights = rgb.shape[0]
    flat = (np.arange(n_lights)[:, None] * RG_BINS + bins[..., 0]) * RG_BINS + bins[..., 1]
    counts = np.bincount(flat.ravel(), np.broadcast_to(weights, flat.shape).ravel(), n_lights * RG_BINS * RG_BINS)
    log_p = _log_of_smoothed(counts.reshape(n_lights, RG_BINS, RG_BINS), (sigma, sigma), floor)
    return log_p.T.astype(np.float32)


def hull_matrix(world: World) -> np.ndarray:
    """The 0/1 matrix of C-by-C-01 (§4.5.4): bin ``b`` is compatible with illuminant ``I`` when it
    lies in the convex hull of the reflectances' (r,g) under ``I`` — its centre is inside the hull
    or it holds one of those chromaticities (so the hull's own corners count).

    Returns:
        ``(2500, I)`` float32 of 0 and 1.
    """
    rgb, _, _ = training_responses(world)
    i, j = np.divmod(np.arange(RG_BINS * RG_BINS), RG_BINS)
    centres = (np.stack([i, j], axis=1) + 0.5) / RG_BINS
    total = rgb.sum(axis=-1, keepdims=True)
    chromaticities = rgb[..., :2] / np.where(total > 0, total, 1.0)
    bins = _rg_bins_np(rgb)
    compatible = np.zeros((RG_BINS * RG_BINS, rgb.shape[0]), np.float32)
    for light, points in enumerate(chromaticities):
        try:
            equations = ConvexHull(points).equations  # a . x + c <= 0 inside
            inside = np.all(centres @ equations[:, :2].T + equations[:, 2] <= 1e-12, axis=1)
        except QhullError:  # degenerate (collinear) chromaticities: only their own bins
            inside = np.zeros(len(centres), bool)
        inside[bins[light, :, 0] * RG_BINS + bins[light, :, 1]] = True
        compatible[inside, light] = 1.0
    return compatible


def brightness_matrix(
    world: World,
    *,
    l_bins: int = 50,
    sigma: float = BRIGHTNESS_SIGMA[0],
    sigma_l: float = BRIGHTNESS_SIGMA[1],
    floor: float = 1e-6,
    specular: Specular | None = None,
    specular_steps: int = 8,
) -> tuple[np.ndarray, int]:
    """The 3-D correlation matrix of chapter 10 (§10.2; spec ch08-12 §4.3).

    For each training illuminant the reflectances' (r, g, L / L_white) are counted in cells
    (``l_bins`` linear bins per unit of ``L / L_white``; matte surfaces fill ``[0, 1)``, specular
    training extends the axis to ``1 + max_amount``), smoothed by a Gaussian (``sigma`` bins in r
    and g, ``sigma_l`` in L; spec ch08-12 A13), normalised, floored and logged.

    Returns:
        ``(log_probability (1275 * l_total + 1, I) float32, l_total)``; the last row is the
        outside cell, at each illuminant's floor.
    """
    rgb, weights, whites = training_responses(world, specular, specular_steps)
    n_lights = rgb.shape[0]
    relative = rgb.sum(axis=-1) / whites.sum(axis=-1)[:, None]
    reach = 1.0 + (specular.max_amount if specular is not None else 0.0)
    l_total = int(np.ceil(max(reach, relative.max() * 1.0001) * l_bins))
    bins = _rg_bins_np(rgb)
    level = np.floor(relative * l_bins).astype(np.int64)
    flat = ((np.arange(n_lights)[:, None] * RG_BINS + bins[..., 0]) * RG_BINS + bins[..., 1]) * l_total + level
    counts = np.bincount(
        flat.ravel(), np.broadcast_to(weights, flat.shape).ravel(), n_lights * RG_BINS * RG_BINS * l_total
    ).reshape(n_lights, RG_BINS * RG_BINS, l_total)
    log_p = _log_of_smoothed(counts.reshape(n_lights, RG_BINS, RG_BINS, l_total), (sigma, sigma, sigma_l), floor)
    log_p = log_p.reshape(n_lights, RG_BINS * RG_BINS, l_total)
    possible = compact_rg_cells() >= 0
    compact = log_p[:, possible, :].reshape(n_lights, -1)
    outside = log_p.min(axis=(1, 2))[:, None]  # the floor
    return np.concatenate([compact, outside], axis=1).T.astype(np.float32), l_total


# ---------------------------------------------------------------------------------------------
# Scoring kernels (one scene; jit/vmap-able)


def _unique_first(keys: Int[Array, "K"], valid: Bool[Array, "K"]) -> tuple[Int[Array, "K"], Bool[Array, "K"]]:
    """Sort ``keys`` (invalid entries last) and flag the first entry of each distinct valid key."""
    big = jnp.iinfo(keys.dtype).max
    ordered = jnp.sort(jnp.where(valid, keys, big))
    first = (ordered != jnp.concatenate([jnp.full((1,), -1, keys.dtype), ordered[:-1]])) & (ordered != big)
    return ordered, first


def presence_scores(log_probability: Float[Array, "C I"], rgb: Float[Array, "P 3"], valid: Bool[Array, "P"]) -> Float[Array, "I"]:
    """``M x`` of §4.5.4: the sum of the matrix rows of the (r,g) bins present in the scene (each
    bin once, whatever the number of pixels in it)."""
    bins = rg_bins(rgb)
    cells, first = _unique_first(bins[:, 0] * RG_BINS + bins[:, 1], valid)
    rows = log_probability.at[jnp.where(first, cells, 0)].get(mode="promise_in_bounds")
    return jnp.sum(jnp.where(first[:, None], rows, 0.0), axis=0)


def _soft_axis(x: Float[Array, "..."], softness: float) -> tuple[Int[Array, "... 2"], Float[Array, "... 2"]]:
    """Soft binning along one axis (``x`` in bin units, bin ``k`` covers ``[k, k+1)``): the two bins
    either side of the nearest bin edge ``m``, with weights ``1 - s, s``, ``s = sigmoid((x - m) /
    softness)``. As ``softness -> 0`` it is ``floor``; the weights are smooth in ``x`` except for a
    jump of about ``exp(-0.5 / softness)`` at bin centres, where the pair changes."""
    edge = jnp.round(x)
    upper = jax.nn.sigmoid((x - edge) / softness)
    index = edge.astype(jnp.int32)
    return jnp.stack([index - 1, index], axis=-1), jnp.stack([1.0 - upper, upper], axis=-1)


def _soft_presence_score(
    log_probability: Float[Array, "C I"], cells: Int[Array, "K"], weights: Float[Array, "K"], merge: Bool[Array, "K"]
) -> tuple[Float[Array, "I"], Float[Array, ""]]:
    """Soft presence: a cell reached by entries with weights ``w_k`` is present with probability
    ``1 - prod(1 - w_k)`` (1 when some pixel sits squarely in it). Entries with ``merge`` False are
    never pooled (the 3-D outside cell stands for many distinct cells).

    Returns:
        ``(sum over cells of presence x row, number of occupied cells)``.
    """
    size = cells.shape[0]
    key = jnp.where(merge, cells, -1 - jnp.arange(size))  # unmergeable entries get unique keys
    order = jnp.argsort(key)
    key, cells, weights = key[order], cells[order], weights[order]
    start = key != jnp.concatenate([key[:1] - 1, key[:-1]])
    run = jnp.cumsum(start) - 1
    eps = jnp.finfo(weights.dtype).eps
    absent = jax.ops.segment_sum(jnp.log1p(-jnp.clip(weights, 0.0, 1.0 - 4 * eps)), run, num_segments=size)
    present = -jnp.expm1(absent)[run] * start
    rows = log_probability.at[cells].get(mode="promise_in_bounds")
    return jnp.sum(present[:, None] * rows, axis=0), jnp.sum(present)


def soft_presence_scores(
    log_probability: Float[Array, "C I"], rgb: Float[Array, "P 3"], valid: Bool[Array, "P"], softness: float
) -> Float[Array, "I"]:
    """Differentiable :func:`presence_scores`: each pixel spreads over the 2 x 2 bins around it
    (:func:`_soft_axis`), bins are present with probability ``1 - prod(1 - w)``."""
    total = jnp.sum(rgb, axis=-1, keepdims=True)
    rg = rgb[..., :2] / jnp.where(total > TINY, total, 1.0) * RG_BINS
    (ri, rw), (gi, gw) = _soft_axis(rg[:, 0], softness), _soft_axis(rg[:, 1], softness)
    ri, gi = jnp.clip(ri, 0, RG_BINS - 1), jnp.clip(gi, 0, RG_BINS - 1)
    cells = (ri[:, :, None] * RG_BINS + gi[:, None, :]).reshape(-1)
    weights = (rw[:, :, None] * gw[:, None, :] * valid[:, None, None]).reshape(-1)
    score, _ = _soft_presence_score(log_probability, cells, weights, jnp.ones_like(cells, bool))
    return score


# ---------------------------------------------------------------------------------------------
# 2-D estimators


def _chromaticity_estimate(rg: Float[Array, "2"]) -> Float[Array, "3"]:
    return jnp.concatenate([rg, 1.0 - jnp.sum(rg, keepdims=True)])


class ColourByCorrelation(Estimator):
    """2-D Colour by Correlation with a probabilistic matrix (§4.5.4, eqs. 4.2–4.5).

    The scene's bins select matrix rows whose sum is the log-likelihood of each training illuminant;
    with uniform priors it is the log-posterior. ``MAP``: the most probable illuminant; ``MMSE``:
    the posterior mean (r,g); ``MLM``: the maximum of the posterior convolved with a Gaussian over
    the illuminants' (r,g) (``mlm_mask``). With ``softness`` set, bins are soft (gradients reach
    the input RGB) and MAP is the softmax-weighted mean at ``temperature``.

    Attributes:
        log_probability: ``(2500, I)`` log P(bin | illuminant) (the transposed correlation matrix).
        illuminant_rg: ``(I, 2)`` the training illuminants' chromaticities.
        fallback: estimate for a scene without valid pixels (``ok=False``).
        mlm_mask: ``(I, I)`` Gaussian weights between illuminants (MLM only).
    """

    log_probability: Float[Array, "C I"]
    illuminant_rg: Float[Array, "I 2"]
    fallback: Float[Array, "3"]
    mlm_mask: Float[Array, "I I"] | None = None
    selector: str = eqx.field(static=True, default="MMSE")
    mlm_width: float | None = eqx.field(static=True, default=None)
    softness: float | None = eqx.field(static=True, default=None)
    temperature: float = eqx.field(static=True, default=1.0)

    def log_posterior(self, rgb: Float[Array, "P 3"], mask: Bool[Array, "P"]) -> Float[Array, "I"]:
        """Normalised log-posterior over the training illuminants (uniform prior)."""
        valid = _valid_pixels(rgb, mask)
        if self.softness is None:
            scores = presence_scores(self.log_probability, rgb, valid)
        else:
            scores = soft_presence_scores(self.log_probability, rgb, valid, self.softness)
        return jax.nn.log_softmax(scores)

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, "P"]) -> Estimate:
        log_posterior = self.log_posterior(rgb, mask)
        posterior = jnp.exp(log_posterior)
        if self.selector == "MMSE":
            rg = posterior @ self.illuminant_rg
        elif self.softness is not None:  # soft MAP: softmax of the log-posterior at a temperature
            rg = jax.nn.softmax(log_posterior / self.temperature) @ self.illuminant_rg
        elif self.selector == "MAP":
            rg = self.illuminant_rg[jnp.argmax(posterior)]
        else:  # MLM
            rg = self.illuminant_rg[jnp.argmax(self.mlm_mask @ posterior)]
        return with_fallback(_chromaticity_estimate(rg), jnp.any(_valid_pixels(rgb, mask)), self.fallback)


class ColourByCorrelation01(Estimator):
    """C-by-C-01 (§4.5.4): a 0/1 matrix from the convex hulls of the reflectances' (r,g); an
    illuminant's score is the number of scene bins consistent with it; the estimate is the mean
    (r,g) of the illuminants whose score is within ``tolerance`` of the maximum (DESIGN.md §10)."""

    compatible: Float[Array, "C I"]
    illuminant_rg: Float[Array, "I 2"]
    fallback: Float[Array, "3"]
    tolerance: float = eqx.field(static=True, default=1.0)

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, "P"]) -> Estimate:
        valid = _valid_pixels(rgb, mask)
        counts = presence_scores(self.compatible, rgb, valid)
        chosen = counts >= jnp.max(counts) - self.tolerance
        rg = jnp.sum(jnp.where(chosen[:, None], self.illuminant_rg, 0.0), axis=0) / jnp.sum(chosen)
        return with_fallback(_chromaticity_estimate(rg), jnp.any(valid), self.fallback)


def mlm_mask(illuminant_rg, width: float) -> Float[Array, "I I"]:
    """Gaussian weights ``exp(-|rg_i - rg_j|^2 / (2 (0.02 width)^2))`` between illuminants."""
    rg = jnp.asarray(illuminant_rg)
    distance2 = jnp.sum((rg[:, None, :] - rg[None, :, :]) ** 2, axis=-1)
    return jnp.exp(-0.5 * distance2 / (width / RG_BINS) ** 2)


# ---------------------------------------------------------------------------------------------
# 3-D estimator


class ColourByCorrelation3D(Estimator):
    """Colour by Correlation in (r, g, L) (chapter 10, §10.1–10.2; spec ch08-12 §4).

    Every (training illuminant ``i``, brightness ``b_q``) pair is a hypothesis. ``B0 = 4.3 x
    mean(R+G+B)`` of the scene; ``b_q`` runs log-uniformly over ``[B0 / 3, 3 B0]`` (101 levels).
    For each level the input is rescaled, ``L / b_q``, and binned; the score of ``(i, q)`` is
    ``v . log P_i`` where ``v`` is (``method="counts"``, remedy 1) the number of colours per cell,
    exact duplicate colours removed first, or (``"presence"``, remedy 2, the default) the
    occupied cells, minus ``n_occ log(b_q / B0)``. The posterior ``~ exp(score)`` (uniform priors
    over illuminants and log-brightness) gives MAP (best pair) or MMSE (posterior mean (r,g) and
    brightness). The estimate's magnitude is the brightness: ``b (r, g, 1 - r - g)``.

    Memory is bounded: levels are visited by a ``scan`` that keeps a running (online) softmax.
    """

    log_probability: Float[Array, "C I"]
    rg_cells: Int[Array, "2500"]
    illuminant_rg: Float[Array, "I 2"]
    fallback: Float[Array, "3"]
    l_bins: int = eqx.field(static=True, default=50)
    l_total: int = eqx.field(static=True, default=50)
    selector: str = eqx.field(static=True, default="MMSE")
    method: str = eqx.field(static=True, default="presence")
    brightness_factor: float = eqx.field(static=True, default=4.3)
    brightness_range: float = eqx.field(static=True, default=3.0)
    n_levels: int = eqx.field(static=True, default=101)
    softness: float | None = eqx.field(static=True, default=None)
    temperature: float = eqx.field(static=True, default=1.0)
    estimates_brightness = True

    def _prepare(self, rgb, mask):
        valid = _valid_pixels(rgb, mask)
        brightness = jnp.sum(rgb, axis=-1)
        count = jnp.sum(valid)
        initial = self.brightness_factor * jnp.sum(jnp.where(valid, brightness, 0.0)) / jnp.maximum(count, 1)
        initial = jnp.where(count > 0, initial, 1.0)
        # Relative levels b_q / B0 = range^(2q/(n-1) - 1), q = 0..n-1.
        relative = self.brightness_range ** jnp.linspace(-1.0, 1.0, self.n_levels, dtype=rgb.dtype)
        return valid, brightness, initial, relative

    def _hard_level_scores(self, rgb, valid, brightness, initial, relative):
        """The function ``ratio -> (I,)`` scores of the level ``b = initial * ratio``."""
        outside = self.log_probability.shape[0] - 1
        bins = rg_bins(rgb)
        rg_cell = self.rg_cells[bins[:, 0] * RG_BINS + bins[:, 1]]
        # Sort pixels by (cell, L, R, G), invalid last: at every level, pixels sharing a 3-D cell
        # are then adjacent (same rg cell, L-bins non-decreasing), and so are exact duplicates.
        key = jnp.where(valid, rg_cell, jnp.iinfo(jnp.int32).max)
        key, brightness, red, green, blue, valid = jax.lax.sort(
            (key, brightness, rgb[:, 0], rgb[:, 1], rgb[:, 2], valid), num_keys=4
        )
        rg_cell = jnp.where(valid, key, -1)
        same_as_previous = lambda x: x == jnp.concatenate([x[:1] * 0 - 1, x[:-1]])  # noqa: E731
        duplicate = same_as_previous(red) & same_as_previous(green) & same_as_previous(blue) & same_as_previous(key)
        distinct = valid & ~duplicate

        def step(ratio):
            level = jnp.floor(brightness / (initial * ratio) * self.l_bins).astype(jnp.int32)
            inside = (rg_cell >= 0) & (level < self.l_total)
            cell = jnp.where(inside, rg_cell * self.l_total + level, outside)
            if self.method == "counts":
                use = distinct
            else:
                use = valid & ~(same_as_previous(cell) & inside)
            rows = self.log_probability.at[cell].get(mode="promise_in_bounds")
            score = jnp.sum(jnp.where(use[:, None], rows, 0.0), axis=0)
            if self.method == "presence":
                score = score - jnp.sum(use) * jnp.log(ratio)
            return score

        return step

    def _soft_level_scores(self, rgb, valid, brightness, initial):
        outside = self.log_probability.shape[0] - 1
        total = jnp.where(brightness > TINY, brightness, 1.0)
        rg = rgb[:, :2] / total[:, None] * RG_BINS
        (ri, rw), (gi, gw) = _soft_axis(rg[:, 0], self.softness), _soft_axis(rg[:, 1], self.softness)
        ri, gi = jnp.clip(ri, 0, RG_BINS - 1), jnp.clip(gi, 0, RG_BINS - 1)
        rg_cell = self.rg_cells[ri[:, :, None] * RG_BINS + gi[:, None, :]]  # (P, 2, 2)
        rg_weight = rw[:, :, None] * gw[:, None, :] * valid[:, None, None]

        def step(ratio):
            li, lw = _soft_axis(brightness / (initial * ratio) * self.l_bins, self.softness)
            li = jnp.maximum(li, 0)
            inside = (rg_cell[..., None] >= 0) & (li[:, None, None, :] < self.l_total)
            cell = jnp.where(inside, rg_cell[..., None] * self.l_total + li[:, None, None, :], outside).reshape(-1)
            weight = (rg_weight[..., None] * lw[:, None, None, :]).reshape(-1)
            if self.method == "counts":
                rows = self.log_probability.at[cell].get(mode="promise_in_bounds")
                return weight @ rows
            score, occupied = _soft_presence_score(self.log_probability, cell, weight, inside.reshape(-1))
            return score - occupied * jnp.log(ratio)

        return step

    def _scorer(self, rgb, mask):
        valid, brightness, initial, relative = self._prepare(rgb, mask)
        if self.softness is None:
            level_scores = self._hard_level_scores(rgb, valid, brightness, initial, relative)
        else:
            level_scores = self._soft_level_scores(rgb, valid, brightness, initial)
        return valid, initial, relative, level_scores

    def brightness_levels(self, rgb: Float[Array, "P 3"], mask: Bool[Array, "P"]) -> Float[Array, "Q"]:
        """The hypothesised illuminant brightnesses ``b_q`` (R+G+B of white) for this scene."""
        _, _, initial, relative = self._prepare(rgb, mask)
        return initial * relative

    def log_posterior(self, rgb: Float[Array, "P 3"], mask: Bool[Array, "P"]) -> Float[Array, "Q I"]:
        """Normalised log-posterior over (brightness level, training illuminant), materialised
        (``__call__`` never holds it); uniform priors over illuminants and log-brightness."""
        _, _, relative, level_scores = self._scorer(rgb, mask)
        scores = jax.lax.map(level_scores, relative)
        return jax.nn.log_softmax(scores.reshape(-1)).reshape(scores.shape)

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, "P"]) -> Estimate:
        valid, initial, relative, level_scores = self._scorer(rgb, mask)
        hard_map = self.selector == "MAP" and self.softness is None
        inverse_t = 1.0 if self.selector == "MMSE" else 1.0 / self.temperature

        def step(carry, ratio):
            score = level_scores(ratio)
            if hard_map:
                best, best_rg, best_b = carry
                top = jnp.argmax(score)
                better = score[top] > best
                carry = (
                    jnp.where(better, score[top], best),
                    jnp.where(better, self.illuminant_rg[top], best_rg),
                    jnp.where(better, ratio, best_b),
                )
                return carry, None
            # Online softmax over (illuminant, level): running max, normaliser and weighted sums.
            peak, norm, mean_rg, mean_b = carry
            score = score * inverse_t
            new_peak = jnp.maximum(peak, jnp.max(score))
            decay = jnp.exp(peak - new_peak)
            weight = jnp.exp(score - new_peak)
            total = jnp.sum(weight)
            carry = (new_peak, norm * decay + total, mean_rg * decay + weight @ self.illuminant_rg, mean_b * decay + total * ratio)
            return carry, None

        dtype = self.illuminant_rg.dtype
        if hard_map:
            init = (jnp.array(-jnp.inf, dtype), jnp.zeros(2, dtype), jnp.array(1.0, dtype))
            (_, rg, ratio), _ = jax.lax.scan(step, init, relative)
        else:
            init = (jnp.array(-jnp.inf, dtype), jnp.array(0.0, dtype), jnp.zeros(2, dtype), jnp.array(0.0, dtype))
            (_, norm, sum_rg, sum_b), _ = jax.lax.scan(step, init, relative)
            rg, ratio = sum_rg / norm, sum_b / norm
        illuminant = initial * ratio * _chromaticity_estimate(rg)
        return with_fallback(illuminant, jnp.any(valid), self.fallback)


# ---------------------------------------------------------------------------------------------
# Fitting, with a disk cache for the slow parts (DESIGN.md §2)


def _cache_dir() -> Path:
    root = os.environ.get("CCJAX_CACHE")
    if root:
        return Path(root)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "ccjax"


def _world_digest(world: World) -> str:
    digest = hashlib.sha256()
    for array in (world.reflectances, world.train_illuminants, world.test_illuminants, world.canonical, world.camera.sensors):
        values = np.ascontiguousarray(np.asarray(array, np.float32))
        digest.update(str(values.shape).encode())
        digest.update(values.tobytes())
    return digest.hexdigest()


def cached(kind: str, world: World, options: dict, compute) -> dict[str, np.ndarray]:
    """Load ``compute()``'s arrays for (``kind``, world, options) from the cache, else compute and
    store them (``$CCJAX_CACHE``, else ``$XDG_CACHE_HOME/ccjax`` or ``~/.cache/ccjax``)."""
    text = json.dumps({"kind": kind, "version": _CACHE_VERSION, "options": options}, sort_keys=True, default=str)
    key = hashlib.sha256((text + _world_digest(world)).encode()).hexdigest()[:20]
    path = _cache_dir() / f"correlation-{kind}-{key}.npz"
    if path.exists():
        try:
            with np.load(path) as stored:
                return {name: stored[name] for name in stored.files}
        except (OSError, ValueError):
            pass  # a damaged entry is recomputed and replaced
    arrays = compute()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, suffix=".npz", delete=False) as handle:
            np.savez(handle, **arrays)
        os.replace(handle.name, path)
    except OSError:
        pass  # an unwritable cache only costs time
    return arrays


def _illuminant_rg(world: World) -> Float[Array, "I 2"]:
    whites = np.asarray(world.train_illuminants, np.float64) @ np.asarray(world.camera.sensors, np.float64)
    return jnp.asarray(whites[:, :2] / whites.sum(axis=1, keepdims=True), jnp.float32)


def _resolve_specular(specular) -> Specular | None:
    if specular is True:
        return Specular()
    if specular in (None, False):
        return None
    if not isinstance(specular, Specular):
        raise ValueError(f"specular: expected True, False, None or a Specular, got {specular!r}")
    return specular


def _check_positive(name: str, value, *, allow_zero: bool = False) -> float:
    if not isinstance(value, (int, float)) or not (value >= 0 if allow_zero else value > 0):
        raise ValueError(f"{name}: expected a {'non-negative' if allow_zero else 'positive'} number, got {value!r}")
    return float(value)


def fit_chromaticity(
    world: World,
    selector: str = "MMSE",
    *,
    sigma: float = 1.0,
    floor: float = 1e-6,
    specular=None,
    mlm_width: float | None = None,
    softness: float | None = None,
    temperature: float = DEFAULT_TEMPERATURE,
) -> ColourByCorrelation:
    """Fit 2-D C-by-C-MAP / -MMSE / -MLM (§4.5.4).

    Arguments:
        world: the world.
        selector: ``"MAP"``, ``"MMSE"`` or ``"MLM"``.
        sigma: matrix smoothing in bins; floor: probability floor (see :func:`chromaticity_matrix`).
        specular: train on specular surfaces as well (``SPEC-`` labels).
        mlm_width: MLM mask width in bins; ``None`` chooses it as the thesis did (:func:`tune_mlm_width`).
        softness: soft binning (bins); ``None`` is the thesis' hard binning.
        temperature: soft MAP's softmax temperature on the log-posterior.
    """
    if selector not in ("MAP", "MMSE", "MLM"):
        raise ValueError(f"selector: expected MAP, MMSE or MLM, got {selector!r}")
    sigma = _check_positive("sigma", sigma, allow_zero=True)
    floor = _check_positive("floor", floor)
    specular = _resolve_specular(specular)
    if softness is not None:
        softness = _check_positive("softness", softness)
        if selector == "MLM":
            raise ValueError("softness: the MLM selector has no soft variant")
    temperature = _check_positive("temperature", temperature)
    matrix = chromaticity_matrix(world, sigma=sigma, floor=floor, specular=specular)
    model = ColourByCorrelation(
        log_probability=jnp.asarray(matrix),
        illuminant_rg=_illuminant_rg(world),
        fallback=average_illuminant(world),
        selector=selector,
        softness=softness,
        temperature=temperature,
    )
    if selector == "MLM":
        if mlm_width is None:
            mlm_width = float(mlm_width_search(world, sigma=sigma, floor=floor, specular=specular)["best"])
        mlm_width = _check_positive("mlm_width", mlm_width)
        model = dataclasses.replace(model, mlm_mask=mlm_mask(model.illuminant_rg, mlm_width), mlm_width=mlm_width)
    return model


def mlm_width_search(world: World, *, sigma: float = 1.0, floor: float = 1e-6, specular=None) -> dict[str, np.ndarray]:
    """The MLM mask-width search of :func:`tune_mlm_width` for the MMSE/MAP matrix with these
    options, cached on disk; ``["best"]`` is the width C-by-C-MLM uses."""
    specular = _resolve_specular(specular)
    options = {"sigma": sigma, "floor": floor, "specular": repr(specular)}

    def compute():
        model = fit_chromaticity(world, "MMSE", sigma=sigma, floor=floor, specular=specular)
        return tune_mlm_width(world, model, specular=specular)

    return cached("mlm-width", world, options, compute)


MLM_WIDTHS = (0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0, 6.0)


def tune_mlm_width(
    world: World, model: ColourByCorrelation, *, widths=MLM_WIDTHS, n_scenes: int = 1000, n_surfaces: int = 8, seed: int = 1999, specular=None
) -> dict[str, np.ndarray]:
    """Choose the MLM mask width as the thesis did (§4.5.4): the one with the least mean absolute
    (r,g) error on a synthetic validation set (the §4.7 protocol: a test illuminant and
    ``n_surfaces`` distinct reflectances per scene, drawn with NumPy from ``seed``, so independent
    of the sweeps' scenes).

    Returns:
        ``{"widths", "mean_error" (per width), "mmse_mean_error", "best"}``.
    """
    rng = np.random.default_rng(seed)
    sensors = np.asarray(world.camera.sensors, np.float64)
    lights = np.asarray(world.test_illuminants, np.float64)[rng.integers(0, world.test_illuminants.shape[0], n_scenes)]
    surfaces = np.argsort(rng.random((n_scenes, world.reflectances.shape[0])), axis=1)[:, :n_surfaces]
    reflectances = np.asarray(world.reflectances, np.float64)[surfaces]  # (B, P, 101)
    rgb = np.einsum("bpl,bl,lc->bpc", reflectances, lights, sensors)
    whites = lights @ sensors
    if specular is not None:
        shiny = rng.random(rgb.shape[:2]) < specular.probability
        rgb = rgb + (shiny * rng.uniform(0.0, specular.max_amount, rgb.shape[:2]))[..., None] * whites[:, None, :]
    rgb = jnp.asarray(rgb, jnp.float32)
    posterior = jnp.exp(jax.jit(jax.vmap(model.log_posterior))(rgb, jnp.ones(rgb.shape[:2], bool)))
    truth = jnp.asarray(whites[:, :2] / whites.sum(axis=1, keepdims=True), jnp.float32)
    mean_error = []
    for width in widths:
        choice = jnp.argmax(posterior @ mlm_mask(model.illuminant_rg, width).T, axis=1)
        mean_error.append(float(jnp.mean(jnp.linalg.norm(model.illuminant_rg[choice] - truth, axis=1))))
    mmse = float(jnp.mean(jnp.linalg.norm(posterior @ model.illuminant_rg - truth, axis=1)))
    return {
        "widths": np.asarray(widths, np.float64),
        "mean_error": np.asarray(mean_error),
        "mmse_mean_error": np.asarray(mmse),
        "best": np.asarray(widths[int(np.argmin(mean_error))], np.float64),
    }


def fit_hull(world: World, *, tolerance: float = 1.0) -> ColourByCorrelation01:
    """Fit C-by-C-01 (§4.5.4); ``tolerance``: scores within it of the maximum are averaged."""
    tolerance = _check_positive("tolerance", tolerance, allow_zero=True)
    return ColourByCorrelation01(
        compatible=jnp.asarray(hull_matrix(world)),
        illuminant_rg=_illuminant_rg(world),
        fallback=average_illuminant(world),
        tolerance=tolerance,
    )


def fit_brightness(
    world: World,
    selector: str = "MMSE",
    *,
    method: str = "presence",
    specular=None,
    l_bins: int = 50,
    sigma: float = BRIGHTNESS_SIGMA[0],
    sigma_l: float = BRIGHTNESS_SIGMA[1],
    floor: float = 1e-6,
    brightness_factor: float = 4.3,
    brightness_range: float = 3.0,
    n_levels: int = 101,
    softness: float | None = None,
    temperature: float = DEFAULT_TEMPERATURE,
    specular_steps: int = 8,
) -> ColourByCorrelation3D:
    """Fit 3-D Colour by Correlation (chapter 10), ``RGB-C-by-C-MAP`` / ``-MMSE``.

    Arguments:
        world: the world.
        selector: ``"MAP"`` or ``"MMSE"``.
        method: discretisation remedy, ``"presence"`` (2, default) or ``"counts"`` (1).
        specular: specular training world (``SPEC-`` labels; True for the thesis' recipe).
        l_bins: L bins per unit of ``L / L_white`` (50 for synthetic data, 25 for images, §10.2).
        sigma, sigma_l: matrix smoothing in bins (r,g and L); floor: probability floor.
        brightness_factor: ``B0 = factor x mean(R+G+B)`` (4.3, §10.1).
        brightness_range: hypotheses within ``[B0 / k, k B0]`` (k = 3).
        n_levels: log-spaced brightness levels (101).
        softness, temperature: soft binning (bins) and soft-MAP temperature; ``None`` is hard.
    """
    if selector not in ("MAP", "MMSE"):
        raise ValueError(f"selector: expected MAP or MMSE, got {selector!r}")
    if method not in ("presence", "counts"):
        raise ValueError(f"method: expected 'presence' or 'counts', got {method!r}")
    if not isinstance(l_bins, int) or l_bins < 1:
        raise ValueError(f"l_bins: expected a positive integer, got {l_bins!r}")
    if not isinstance(n_levels, int) or n_levels < 1:
        raise ValueError(f"n_levels: expected a positive integer, got {n_levels!r}")
    if not isinstance(brightness_range, (int, float)) or brightness_range < 1:
        raise ValueError(f"brightness_range: expected a number >= 1, got {brightness_range!r}")
    specular = _resolve_specular(specular)
    options = {
        "l_bins": l_bins,
        "sigma": _check_positive("sigma", sigma, allow_zero=True),
        "sigma_l": _check_positive("sigma_l", sigma_l, allow_zero=True),
        "floor": _check_positive("floor", floor),
        "specular": repr(specular),
        "specular_steps": specular_steps,
    }
    if softness is not None:
        softness = _check_positive("softness", softness)

    def compute():
        matrix, l_total = brightness_matrix(
            world, l_bins=l_bins, sigma=options["sigma"], sigma_l=options["sigma_l"], floor=options["floor"], specular=specular,
            specular_steps=specular_steps,
        )
        return {"log_probability": matrix, "l_total": np.asarray(l_total)}

    stored = cached("rgb-matrix", world, options, compute)
    return ColourByCorrelation3D(
        log_probability=jnp.asarray(stored["log_probability"]),
        rg_cells=jnp.asarray(compact_rg_cells(), jnp.int32),
        illuminant_rg=_illuminant_rg(world),
        fallback=average_illuminant(world),
        l_bins=l_bins,
        l_total=int(stored["l_total"]),
        selector=selector,
        method=method,
        brightness_factor=_check_positive("brightness_factor", brightness_factor),
        brightness_range=float(brightness_range),
        n_levels=n_levels,
        softness=softness,
        temperature=_check_positive("temperature", temperature),
    )


# ---------------------------------------------------------------------------------------------
# labels


@register(r"(?P<spec>SPEC-)?C-by-C-(?P<selector>MAP|MMSE|MLM)", "C-by-C-MMSE", "Colour by Correlation in (r,g): MAP, MMSE, MLM (§4.5.4)")
def _build_chromaticity(world, match, **options):
    if match["spec"]:
        options.setdefault("specular", True)
    return fit_chromaticity(world, match["selector"], **options)


@register(r"C-by-C-01", "C-by-C-01", "Colour by Correlation with the 0/1 hull matrix (§4.5.4)")
def _build_hull(world, match, **options):
    return fit_hull(world, **options)


@register(
    r"(?P<prefix>STD-|SPEC-)?RGB-C-by-C-(?P<selector>MAP|MMSE)(-(?P<method>counts|presence))?",
    "RGB-C-by-C-MMSE",
    "3-D Colour by Correlation in (r,g,L), brightness too (ch. 10); -counts: remedy 1",
)
def _build_brightness(world, match, **options):
    if match["prefix"] == "SPEC-":
        options.setdefault("specular", True)
    return fit_brightness(world, match["selector"], method=match["method"] or "presence", **options)


@register(
    r"soft-(?P<spec>SPEC-)?C-by-C-(?P<selector>MAP|MMSE)",
    "soft-C-by-C-MMSE",
    "differentiable 2-D Colour by Correlation (soft bins, softmax posterior)",
)
def _build_soft_chromaticity(world, match, **options):
    if match["spec"]:
        options.setdefault("specular", True)
    options.setdefault("softness", DEFAULT_SOFTNESS)
    return fit_chromaticity(world, match["selector"], **options)


@register(
    r"soft-(?P<prefix>STD-|SPEC-)?RGB-C-by-C-(?P<selector>MAP|MMSE)(-(?P<method>counts|presence))?",
    "soft-RGB-C-by-C-MMSE",
    "differentiable 3-D Colour by Correlation (soft bins, softmax posterior)",
)
def _build_soft_brightness(world, match, **options):
    if match["prefix"] == "SPEC-":
        options.setdefault("specular", True)
    options.setdefault("softness", DEFAULT_SOFTNESS)
    return fit_brightness(world, match["selector"], method=match["method"] or "presence", **options)

