"""The network of NEURAL-NET (Barnard 1999 §4.5.5): the binarised (r,g) histogram input, the
multi-layer perceptron and the estimator that wraps a trained net."""

from __future__ import annotations

import typing
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray

from ccjax._colour import rg, rg_bin, rg_to_rgb, valid_pixels
from ccjax.estimators.base import AbstractWorldSurfaceEstimator, Estimate, Status
from ccjax.precision import linear, matmul

BINS = 50
"""(r,g) bins per axis; cells are ``1 / BINS = 0.02`` wide (§4.5.5)."""
N_INPUTS = BINS * BINS
"""The net's inputs: one per (r,g) bin, ``BINS * BINS = 2500`` (§4.5.5)."""
SIMPLEX_MARGIN = 1e-4
"""Keeps the predicted illuminant strictly inside the chromaticity triangle, so every channel of the
RGB estimate is positive and the diagonal map to canonical exists."""


# ---------------------------------------------------------------------------------------------
# input encoding


def histogram_bins(rgb: Float[Array, "P 3"]) -> Int[Array, " P"]:
    """Flat (r,g) bin index ``floor(r * 50) * 50 + floor(g * 50)`` of each pixel (bins clamped to
    0..49; scale-free, :func:`ccjax._colour.rg`; black pixels land in the achromatic bin
    and are masked by the callers).

    Arguments:
        rgb: ``(P, 3)`` pixels or surfaces.

    Returns:
        ``(P,)`` int32 bin indices in ``0 .. 2499``.
    """
    cells = rg_bin(rg(rgb), BINS)  # scale-free, as Colour by Correlation's bins
    return cells[..., 0] * BINS + cells[..., 1]


def binarised_histogram(rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Float[Array, "2500"]:
    """The net's input: 1 for every (r,g) bin holding at least one valid chromaticity (§4.5.5).

    Arguments:
        rgb: ``(P, 3)`` camera RGB.
        mask: ``(P,)`` True for valid pixels; black pixels (no chromaticity; black relative to the
            brightest masked pixel, :func:`ccjax._colour.valid_pixels`) are ignored too.

    Returns:
        ``(2500,)`` zeros and ones, bin ``(i, j)`` (r in ``[0.02 i, 0.02 (i+1))``) at ``50 i + j``.
    """
    valid = valid_pixels(rgb, mask)
    return jnp.zeros(N_INPUTS, rgb.dtype).at[histogram_bins(rgb)].max(valid.astype(rgb.dtype))


def occupied_bins(rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> tuple[jax.Array, jax.Array]:
    """The binarised histogram as a list: distinct occupied bins and a 0/1 weight per slot.

    ``sum_k weight_k * onehot(bin_k) == binarised_histogram(rgb, mask)``. The first layer then costs
    ``P x 400`` instead of ``2500 x 400`` (the thesis' rewiring was a speed device too, §4.5.5).

    Returns:
        ``bins (P,)`` int32 (sorted; unused slots hold a valid index with weight 0) and
        ``weight (P,)`` (1 for the first slot of each occupied bin, else 0).

    Arguments:
        rgb: ``(P, 3)`` surfaces.
        mask: ``(P,)`` True where a surface is valid.
    """
    valid = valid_pixels(rgb, mask)
    bins = jnp.sort(jnp.where(valid, histogram_bins(rgb), N_INPUTS))
    first = jnp.concatenate([jnp.ones((1,), bool), bins[1:] != bins[:-1]])
    weight = (first & (bins < N_INPUTS)).astype(rgb.dtype)
    return jnp.minimum(bins, N_INPUTS - 1), weight


class Mlp(eqx.Module):
    """Multi-layer perceptron with sigmoid hidden units and linear outputs (§4.5.5).

    Attributes:
        layers: the affine layers, ``2500 -> 400 -> 30 -> 2`` for the thesis' net.
    """

    layers: tuple[eqx.nn.Linear, ...]

    def __init__(self, key: PRNGKeyArray, sizes: tuple[int, ...] = (N_INPUTS, 400, 30, 2)):
        keys = jax.random.split(key, len(sizes) - 1)
        self.layers = tuple(eqx.nn.Linear(a, b, key=k) for a, b, k in zip(sizes[:-1], sizes[1:], keys))

    def __call__(self, x: Float[Array, " n_in"]) -> Float[Array, " n_out"]:
        """The net on a dense input vector (e.g. :func:`binarised_histogram`)."""
        return self._hidden_to_output(linear(self.layers[0], x))

    def from_bins(self, bins: jax.Array, weight: Float[Array, " P"]) -> Float[Array, " n_out"]:
        """The net on a sparse 0/1 input given by :func:`occupied_bins` (same value as ``__call__``).

        Arguments:
            bins: the occupied bins' indices (:func:`occupied_bins`).
            weight: ``(P,)`` each index's weight (0 for padding).

        Returns:
            ``(n_out,)`` the net's output.
        """
        first = self.layers[0]
        hidden = matmul(first.weight[:, bins], weight.astype(first.weight.dtype))
        return self._hidden_to_output(hidden if first.bias is None else hidden + first.bias)

    def _hidden_to_output(self, x):
        for layer in self.layers[1:]:
            x = linear(layer, jax.nn.sigmoid(x))
        return x


def _project_to_simplex(point: Float[Array, "2"]) -> tuple[Float[Array, "2"], jax.Array]:
    """Nearest point of the chromaticity triangle (shrunk by a margin) and whether ``point`` was in it."""
    low, high = SIMPLEX_MARGIN, 1.0 - SIMPLEX_MARGIN
    inside = jnp.all(point >= low) & (jnp.sum(point) <= high)
    clipped = jnp.maximum(point, low)
    excess = jnp.maximum(jnp.sum(clipped) - high, 0.0)
    # Euclidean projection onto r + g = high moves both coordinates equally, then re-clip.
    moved = jnp.maximum(clipped - excess / 2.0, low)
    moved = jnp.where(jnp.sum(moved) > high, moved * high / jnp.sum(moved), moved)
    return moved, inside


@typing.final
class NeuralNet(AbstractWorldSurfaceEstimator):
    """The NEURAL-NET / SP-NEURAL-NET estimator: ``rg_to_rgb(net(histogram))`` (§4.5.5).

    A chromaticity method: the estimate is ``(r, g, 1 - r - g)``. A prediction outside the
    chromaticity triangle is projected into it (``Status.RELAXED``); a scene with no valid pixel
    gets the average training illuminant (``Status.NO_DATA``).

    Attributes:
        net: the trained :class:`Mlp`.
        fallback: ``(3,)`` estimate for scenes without data.
    """

    net: Mlp
    fallback: Float[Array, "3"]
    estimates_brightness: ClassVar[bool] = False

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        has_data = jnp.any(valid_pixels(rgb, mask))
        predicted = self.net.from_bins(*occupied_bins(rgb, mask))
        projected, inside = _project_to_simplex(jnp.nan_to_num(predicted, nan=1.0 / 3.0))
        illuminant = jnp.where(has_data, rg_to_rgb(projected), self.fallback.astype(projected.dtype))
        admissible = inside & jnp.all(jnp.isfinite(predicted))
        status = jnp.where(has_data, jnp.where(admissible, Status.ESTIMATED, Status.RELAXED), Status.NO_DATA)
        return Estimate(illuminant=illuminant, status=status)
