"""A small learned baseline beyond the thesis: an MLP on the log-chroma histogram of the scene
(the input of the field's histogram methods, e.g. Barron's convolutional colour constancy), trained
on photographs with ``ccjax train --method log-chroma-mlp`` (nothing is fitted from spectra: the
world gives only the fallback light).

Each valid surface ``(R, G, B)`` has log-chroma ``u = log(G / R)``, ``v = log(G / B)``; the
histogram counts them on a ``bins x bins`` grid over ``[-extent, extent]^2`` (normalised, square
root), the MLP maps it to the light's log-chroma ``(u_L, v_L)`` and the estimate is
``(exp(-u_L), 1, exp(-v_L))``. The histogram is hard, so the model is differentiable in its
parameters (what training needs) but not in its input.
"""

from __future__ import annotations

import typing
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, PRNGKeyArray

from ccjax._colour import TINY
from ccjax.estimators.base import AbstractSurfaceEstimator, AbstractUnblockedEstimator, Estimate, with_fallback
from ccjax.precision import linear

LOG_CHROMA_BINS = 32
LOG_CHROMA_EXTENT = 2.0
"""log-chroma range covered by the histogram, ``[-2, 2]`` (a factor e^2 ~ 7.4 between channels)."""


def log_chroma(rgb: Float[Array, "P 3"]) -> Float[Array, "P 2"]:
    """``(log(G / R), log(G / B))`` of each surface (a channel at or below 0 counts as 1: finite,
    and such a surface is never valid, :func:`lit_surfaces`).

    Arguments:
        rgb: the surfaces' responses.

    Returns:
        Each surface's log-chroma ``(u, v)``.
    """
    safe = jnp.where(rgb > 0, rgb, 1.0)
    return jnp.stack([jnp.log(safe[:, 1] / safe[:, 0]), jnp.log(safe[:, 1] / safe[:, 2])], axis=-1)


def lit_surfaces(rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Bool[Array, " P"]:
    """The surfaces with a log-chroma: masked in, every channel above :data:`TINY` times the
    scene's brightest masked channel (relative, so a scene times any positive factor keeps the
    same surfaces, as :func:`ccjax._colour.valid_pixels` does for chromaticity)."""
    brightest = jnp.max(jnp.where(mask[:, None], rgb, 0.0))
    return mask & jnp.all(rgb > TINY * brightest, axis=-1) & (brightest > 0)


def log_chroma_histogram(
    rgb: Float[Array, "P 3"], mask: Bool[Array, " P"], bins: int = LOG_CHROMA_BINS, extent: float = LOG_CHROMA_EXTENT
) -> Float[Array, " n"]:
    """Square root of the normalised histogram of the valid surfaces' log-chroma, flattened
    (``bins * bins``; values outside the range land in the edge bins).

    Arguments:
        rgb: ``(P, 3)`` camera RGB of the surfaces; only :func:`lit_surfaces` are counted.
        mask: ``(P,)`` True where a surface may be used.
        bins: divisions per log-chroma axis.
        extent: half-width of the range covered on each axis, ``[-extent, extent]``.

    Returns:
        ``(bins * bins,)`` ``sqrt(count / number of valid surfaces)``, bin ``(i, j)`` (``i`` along
        ``log(G / R)``, ``j`` along ``log(G / B)``) at index ``bins * i + j``; all zeros when no
        surface is valid.
    """
    valid = lit_surfaces(rgb, mask)
    cells = jnp.clip(jnp.floor((log_chroma(rgb) + extent) / (2 * extent) * bins), 0, bins - 1).astype(jnp.int32)
    weight = valid.astype(rgb.dtype)
    counts = jnp.zeros(bins * bins, rgb.dtype).at[cells[:, 0] * bins + cells[:, 1]].add(weight)
    return jnp.sqrt(counts / jnp.maximum(jnp.sum(weight), 1.0))


@typing.final
class ReluMLP(eqx.Module):
    """A ReLU multilayer perceptron whose leaves are only its weights and biases (``eqx.nn.MLP``
    keeps its activation function as a leaf, which a fitted model must not have: every leaf is an
    array, so the model itself is a ``jax.jit`` / ``jax.grad`` argument).

    Attributes:
        layers: the linear layers; ReLU between them, none after the last.
    """

    layers: tuple[eqx.nn.Linear, ...]

    def __call__(self, x: Float[Array, " n"]) -> Float[Array, " m"]:
        for layer in self.layers[:-1]:
            x = jax.nn.relu(linear(layer, x))
        return linear(self.layers[-1], x)


@typing.final
class LogChromaNet(AbstractSurfaceEstimator, AbstractUnblockedEstimator):
    """MLP on the log-chroma histogram (module docstring). Everything it knows is learned from
    photographs, so it is not world-based (the world gives only its fallback light, as for the
    statistics methods) and, like them, it is given every usable pixel of a photograph: a
    histogram of a few thousand pixels is a smoother input than one of the thesis' 5x5 block
    averages.

    Attributes:
        net: ``bins^2 -> hidden -> hidden -> 2`` (ReLU).
        fallback: ``(3,)`` estimate for a scene without valid surfaces (``ok=False``).
        bins, extent: the histogram grid (static).
    """

    net: ReluMLP
    fallback: Float[Array, "3"]
    bins: int = eqx.field(static=True, default=LOG_CHROMA_BINS)
    extent: float = eqx.field(static=True, default=LOG_CHROMA_EXTENT)
    estimates_brightness: ClassVar[bool] = False
    world_based: ClassVar[bool] = False
    default_preprocessing: ClassVar[str] = "pixels"
    pools_pixels: ClassVar[bool] = False

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        histogram = log_chroma_histogram(rgb, mask, self.bins, self.extent)
        u, v = self.net(histogram)
        illuminant = jnp.stack([jnp.exp(-u), jnp.ones_like(u), jnp.exp(-v)])
        usable = jnp.any(lit_surfaces(rgb, mask))
        return with_fallback(illuminant / jnp.sum(illuminant), usable, self.fallback)


def init_log_chroma_net(
    key: PRNGKeyArray, fallback: Float[Array, "3"], *, hidden: int = 64, bins: int = LOG_CHROMA_BINS
) -> LogChromaNet:
    """An untrained :class:`LogChromaNet` (the start of training); its last layer is zeroed so the
    untrained estimate is the grey light ``(1, 1, 1) / 3``.

    Arguments:
        key: PRNG key for the MLP's initial weights.
        fallback: ``(3,)`` RGB light returned (with ``ok=False``) for a scene without valid
            surfaces, e.g. the average training illuminant.
        hidden: width of the MLP's two hidden layers.
        bins: divisions per axis of the input histogram (the MLP takes ``bins * bins`` inputs);
            the histogram's extent is the default :data:`LOG_CHROMA_EXTENT`.

    Returns:
        A :class:`LogChromaNet` with a ``bins^2 -> hidden -> hidden -> 2`` ReLU MLP whose last
        layer is zero.
    """
    first, second = jax.random.split(key)
    last = eqx.nn.Linear(hidden, 2, key=key)
    # Zero last layer: the untrained estimate is grey.
    last = eqx.tree_at(
        lambda n: (n.weight, n.bias), last, (jnp.zeros_like(last.weight), jnp.zeros(2, last.weight.dtype))
    )
    net = ReluMLP(
        layers=(eqx.nn.Linear(bins * bins, hidden, key=first), eqx.nn.Linear(hidden, hidden, key=second), last)
    )
    return LogChromaNet(net=net, fallback=jnp.asarray(fallback), bins=bins)
