"""3-D Colour by Correlation in (r, g, L) (Barnard 1999 chapter 10): RGB-C-by-C-MAP and -MMSE."""

from __future__ import annotations

import typing
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ccjax._colour import rg, rg_to_rgb, valid_pixels
from ccjax.estimators.base import AbstractWorldSurfaceEstimator, Estimate, with_fallback
from ccjax.estimators.correlation._binning import (
    RG_BINS,
    compact_rg_cells,
    rg_bins,
    soft_axis,
    soft_presence_score,
)
from ccjax.estimators.correlation._fitting import (
    DEFAULT_TEMPERATURE,
    check_positive,
    illuminant_rg_of,
    resolve_fluorescent,
    resolve_specular,
)
from ccjax.estimators.correlation._matrices import BRIGHTNESS_SIGMA, brightness_matrix
from ccjax.estimators.simple import average_illuminant
from ccjax.precision import device_array, matmul
from ccjax.world import World

RG_CELLS = compact_rg_cells().astype(np.int32)
"""The compact (r,g) cell of each of the 2500 (r,g) bins (a constant of the binning, not fitted)."""


@typing.final
class ColourByCorrelation3D(AbstractWorldSurfaceEstimator):
    """Colour by Correlation in (r, g, L) (chapter 10, §10.1–10.2).

    Every (training illuminant ``i``, brightness ``b_q``) pair is a hypothesis. ``B0 = 4.3 x
    mean(R+G+B)`` of the scene; ``b_q`` runs log-uniformly over ``[B0 / 3, 3 B0]`` (101 levels).
    For each level the input is rescaled, ``L / b_q``, and binned; the score of ``(i, q)`` is
    ``v . log P_i`` where ``v`` is (``method="counts"``, remedy 1) the number of colours per cell,
    exact duplicate colours removed first, or (``"presence"``, remedy 2, the default) the
    occupied cells, minus ``n_occ log(b_q / B0)``. The posterior ``~ exp(score)`` (uniform priors
    over illuminants and log-brightness) gives MAP (best pair) or MMSE (posterior mean (r,g) and
    brightness). The estimate's magnitude is the brightness: ``b (r, g, 1 - r - g)``.

    Memory is bounded: levels are visited by a ``scan`` that keeps a running (online) softmax.

    Attributes:
        log_probability: ``(C, I)`` the log correlation matrix (last row: the outside cell).
        illuminant_rg: ``(I, 2)`` the training illuminants' (r,g).
        fallback: ``(3,)`` the light answered for a scene without data.
        l_bins: L bins per unit of ``L / L_white``.
        l_total: L bins of the matrix.
        selector: ``"MAP"`` or ``"MMSE"``.
        method: ``"presence"`` or ``"counts"``.
        brightness_factor: ``B0 = factor x mean(R+G+B)``.
        brightness_range: hypotheses within ``[B0 / k, k B0]``.
        n_levels: brightness levels.
        softness: soft binning width in bins (``None``: hard).
        temperature: soft-MAP temperature.
    """

    log_probability: Float[Array, "C I"]
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
    estimates_brightness: ClassVar[bool] = True

    def _prepare(self, rgb, mask):
        valid = valid_pixels(rgb, mask)
        brightness = jnp.sum(rgb, axis=-1)
        count = jnp.sum(valid)
        lit = jnp.sum(jnp.where(valid, brightness, 0.0))
        initial = self.brightness_factor * lit / jnp.maximum(count, 1).astype(lit.dtype)
        initial = jnp.where(count > 0, initial, 1.0)
        # Relative levels b_q / B0 = range^(2q/(n-1) - 1), q = 0..n-1.
        relative = self.brightness_range ** jnp.linspace(-1.0, 1.0, self.n_levels, dtype=rgb.dtype)
        return valid, brightness, initial, relative

    def _hard_level_scores(self, rgb, valid, brightness, initial):
        """The function ``ratio -> (I,)`` scores of the level ``b = initial * ratio``."""
        outside = self.log_probability.shape[0] - 1
        bins = rg_bins(rgb)
        rg_cell = jnp.asarray(RG_CELLS)[bins[:, 0] * RG_BINS + bins[:, 1]]
        # Sort pixels by (cell, L, R, G), invalid last: at every level, pixels sharing a 3-D cell
        # are then adjacent (same rg cell, L-bins non-decreasing), and so are exact duplicates.
        key = jnp.where(valid, rg_cell, jnp.iinfo(jnp.int32).max)
        key, brightness, red, green, blue, valid = jax.lax.sort(
            (key, brightness, rgb[:, 0], rgb[:, 1], rgb[:, 2], valid), num_keys=4
        )
        rg_cell = jnp.where(valid, key, -1)
        same_as_previous = lambda x: x == jnp.concatenate([x[:1] * 0 - 1, x[:-1]])
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
                score = score - jnp.sum(use).astype(score.dtype) * jnp.log(ratio)
            return score

        return step

    def _soft_level_scores(self, rgb, valid, brightness, initial):
        softness = self.softness
        assert softness is not None, "soft scores of a hard model"
        outside = self.log_probability.shape[0] - 1
        # The scale-free chromaticity, as the hard path's ``rg_bins``: a dark but valid scene (x1e-12)
        # must not read as black. Black pixels (achromatic point) get zero weight through ``valid``.
        scaled = rg(rgb) * RG_BINS
        (ri, rw), (gi, gw) = soft_axis(scaled[:, 0], softness), soft_axis(scaled[:, 1], softness)
        ri, gi = jnp.clip(ri, 0, RG_BINS - 1), jnp.clip(gi, 0, RG_BINS - 1)
        rg_cell = jnp.asarray(RG_CELLS)[ri[:, :, None] * RG_BINS + gi[:, None, :]]  # (P, 2, 2)
        rg_weight = rw[:, :, None] * gw[:, None, :] * valid[:, None, None].astype(rw.dtype)

        def step(ratio):
            li, lw = soft_axis(brightness / (initial * ratio) * self.l_bins, softness)
            li = jnp.maximum(li, 0)
            inside = (rg_cell[..., None] >= 0) & (li[:, None, None, :] < self.l_total)
            cell = jnp.where(inside, rg_cell[..., None] * self.l_total + li[:, None, None, :], outside).reshape(-1)
            weight = (rg_weight[..., None] * lw[:, None, None, :]).reshape(-1)
            if self.method == "counts":
                rows = self.log_probability.at[cell].get(mode="promise_in_bounds")
                return matmul(weight, rows)
            score, occupied = soft_presence_score(self.log_probability, cell, weight, inside.reshape(-1))
            return score - occupied * jnp.log(ratio)

        return step

    def _scorer(self, rgb, mask):
        valid, brightness, initial, relative = self._prepare(rgb, mask)
        if self.softness is None:
            level_scores = self._hard_level_scores(rgb, valid, brightness, initial)
        else:
            level_scores = self._soft_level_scores(rgb, valid, brightness, initial)
        return valid, initial, relative, level_scores

    def brightness_levels(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Float[Array, " Q"]:
        """The hypothesised illuminant brightnesses ``b_q`` (R+G+B of white) for this scene.

        Arguments:
            rgb: ``(P, 3)`` the scene's surfaces.
            mask: ``(P,)`` the valid ones.

        Returns:
            ``(Q,)`` the brightness levels.
        """
        _, _, initial, relative = self._prepare(rgb, mask)
        return initial * relative

    def log_posterior(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Float[Array, "Q I"]:
        """Normalised log-posterior over (brightness level, training illuminant), materialised
        (``__call__`` never holds it); uniform priors over illuminants and log-brightness.

        Arguments:
            rgb: ``(P, 3)`` the scene's surfaces.
            mask: ``(P,)`` the valid ones.

        Returns:
            ``(Q, I)`` the log-posterior.
        """
        _, _, relative, level_scores = self._scorer(rgb, mask)
        scores = jax.lax.map(level_scores, relative)
        return jax.nn.log_softmax(scores.reshape(-1)).reshape(scores.shape)

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        valid, initial, relative, level_scores = self._scorer(rgb, mask)
        hard_map = self.selector == "MAP" and self.softness is None
        inverse_t = 1.0 if self.selector == "MMSE" else 1.0 / self.temperature

        def hard_step(carry, ratio):
            best, best_rg, best_b = carry
            score = level_scores(ratio)
            top = jnp.argmax(score)
            better = score[top] > best
            carry = (
                jnp.where(better, score[top], best),
                jnp.where(better, self.illuminant_rg[top], best_rg),
                jnp.where(better, ratio, best_b),
            )
            return carry, None

        def soft_step(carry, ratio):
            # Online softmax over (illuminant, level): running max, normaliser and weighted sums.
            peak, norm, mean_rg, mean_b = carry
            score = level_scores(ratio) * inverse_t
            new_peak = jnp.maximum(peak, jnp.max(score))
            decay = jnp.exp(peak - new_peak)
            weight = jnp.exp(score - new_peak)
            total = jnp.sum(weight)
            carry = (
                new_peak,
                norm * decay + total,
                mean_rg * decay + matmul(weight, self.illuminant_rg),
                mean_b * decay + total * ratio,
            )
            return carry, None

        dtype = self.illuminant_rg.dtype
        if hard_map:
            init = (jnp.array(-jnp.inf, dtype), jnp.zeros(2, dtype), jnp.array(1.0, dtype))
            (_, rg, ratio), _ = jax.lax.scan(hard_step, init, relative)
        else:
            init = (jnp.array(-jnp.inf, dtype), jnp.array(0.0, dtype), jnp.zeros(2, dtype), jnp.array(0.0, dtype))
            (_, norm, sum_rg, sum_b), _ = jax.lax.scan(soft_step, init, relative)
            rg, ratio = sum_rg / norm, sum_b / norm
        illuminant = initial * ratio * rg_to_rgb(rg)
        return with_fallback(illuminant, jnp.any(valid), self.fallback)


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
    fluorescent=None,
) -> ColourByCorrelation3D:
    """Fit 3-D Colour by Correlation (chapter 10), ``RGB-C-by-C-MAP`` / ``-MMSE``.

    Arguments:
        world: the world.
        selector: ``"MAP"`` or ``"MMSE"``.
        method: discretisation remedy, ``"presence"`` (2, default) or ``"counts"`` (1).
        specular: specular training world (``SPEC-`` labels; True for the thesis' recipe).
        l_bins: L bins per unit of ``L / L_white`` (50 for synthetic data, 25 for images, §10.2).
        sigma, sigma_l: matrix smoothing in bins (r,g and L).
        floor: probability floor.
        brightness_factor: ``B0 = factor x mean(R+G+B)`` (4.3, §10.1).
        brightness_range: hypotheses within ``[B0 / k, k B0]`` (k = 3).
        n_levels: log-spaced brightness levels (101).
        softness, temperature: soft binning (bins) and soft-MAP temperature; ``None`` is hard.
        specular_steps: specular copies per surface in specular training.
        fluorescent: FL training (``FL-`` labels, ch. 10 Table 10.1): ``True`` for fluorescent
            surfaces at about 15 % of the training occurrences, or that fraction.

    Returns:
        The fitted :class:`ColourByCorrelation3D`.
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
    specular = resolve_specular(specular)
    sigma = check_positive("sigma", sigma, allow_zero=True)
    sigma_l = check_positive("sigma_l", sigma_l, allow_zero=True)
    floor = check_positive("floor", floor)
    fluorescent = resolve_fluorescent(fluorescent)
    if softness is not None:
        softness = check_positive("softness", softness)
    matrix, l_total = brightness_matrix(
        world,
        l_bins=l_bins,
        sigma=sigma,
        sigma_l=sigma_l,
        floor=floor,
        specular=specular,
        specular_steps=specular_steps,
        fluorescent=fluorescent,
    )
    return ColourByCorrelation3D(
        log_probability=device_array(matrix),
        illuminant_rg=illuminant_rg_of(world),
        fallback=average_illuminant(world),
        l_bins=l_bins,
        l_total=int(l_total),
        selector=selector,
        method=method,
        brightness_factor=check_positive("brightness_factor", brightness_factor),
        brightness_range=float(brightness_range),
        n_levels=n_levels,
        softness=softness,
        temperature=check_positive("temperature", temperature),
    )
