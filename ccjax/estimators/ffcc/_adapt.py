"""FFCC's light prior moved to a camera without labels: the bias map re-weighted from the
training lights' distribution to the target's, estimated from the target's *unlabelled*
histograms by expectation-maximisation and blended with a prior from physics (the target's
Planckian and daylight loci through its curves).

FFCC's softmax is a discriminative posterior ``P(light | image)`` under the training lights'
prior ``p_train``. Under a change of the lights' distribution alone ("label shift"), the
posterior under a new prior ``q`` is ``P(light | image) q / p_train`` renormalised, and ``q`` is
found by EM on unlabelled images: ``q <- mean_i P_q(light | image_i)`` (Saerens, Latinne &
Decaestecker, "Adjusting the outputs of a classifier to new a priori probabilities", Neural
Computation 2002). On FFCC's torus of log-chroma bins the bias map is an additive log-prior
(FFCC §3), so the adapted model adds ``log(q / p_train)`` to it; nothing else changes, and its
inference costs what FFCC's does.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ccjax.estimators.ffcc._model import FFCC, convolve

__all__ = ["AdaptOptions", "adapt_bias", "light_density"]


class AdaptOptions(eqx.Module):
    """The adaptation's settings (fixed beforehand, never chosen on a scored folder's labels).

    Attributes:
        rounds: EM rounds on the unlabelled histograms (0: the physics prior alone, blended
            with the training prior).
        physics: the share of the physics prior (the target's loci) in the new prior, in [0, 1].
        smoothing: the Gaussian blur of each light density, in log-chroma units.
        floor: the share of a uniform density mixed into every density (no bin is impossible).
    """

    rounds: int = eqx.field(static=True, default=2)
    physics: float = eqx.field(static=True, default=0.25)
    smoothing: float = eqx.field(static=True, default=0.05)
    floor: float = eqx.field(static=True, default=0.02)

    def __check_init__(self) -> None:
        if isinstance(self.rounds, bool) or not isinstance(self.rounds, int) or self.rounds < 0:
            raise ValueError(f"rounds: expected a non-negative integer, got {self.rounds!r}")
        for name in ("physics", "floor"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name}: expected a share in [0, 1], got {value}")
        if not self.smoothing > 0:
            raise ValueError(f"smoothing: expected a positive log-chroma width, got {self.smoothing}")


def _blur(pmf: Float[Array, "n n"], sigma_bins: float) -> Float[Array, "n n"]:
    """A periodic Gaussian blur (the torus of FFCC's histogram), as a product in the Fourier domain."""
    n = pmf.shape[0]
    frequency = jnp.fft.fftfreq(n)
    kernel = jnp.exp(-2.0 * (jnp.pi * sigma_bins) ** 2 * (frequency[:, None] ** 2 + frequency[None, :] ** 2))
    spectrum = jnp.fft.fft2(pmf)
    return jnp.real(jnp.fft.ifft2(spectrum * kernel.astype(spectrum.dtype))).astype(pmf.dtype)


def _normalised(pmf: Float[Array, "n n"], floor: float) -> Float[Array, "n n"]:
    pmf = jnp.maximum(pmf, 0.0)
    pmf = pmf / jnp.sum(pmf)
    return (1.0 - floor) * pmf + floor / pmf.size


def light_density(model: FFCC, uv: Float[Array | np.ndarray, "L 2"], options: AdaptOptions) -> Float[Array, "n n"]:
    """Lights as a smoothed density on ``model``'s log-chroma torus: each light's bilinear weights
    on the four bins around it, blurred by ``options.smoothing``, mixed with ``options.floor`` of
    a uniform density.

    Arguments:
        model: the FFCC whose grid (origin, bin size, bins) is used.
        uv: ``(L, 2)`` the lights' log-chroma ``(log(G/R), log(G/B))``.
        options: the smoothing and the floor.

    Returns:
        ``(n, n)`` a density summing to 1.
    """
    uv = jnp.asarray(uv, model.bias.dtype)
    if uv.ndim != 2 or uv.shape[1] != 2 or uv.shape[0] == 0 or not bool(jnp.all(jnp.isfinite(uv))):
        raise ValueError(f"uv: expected (L, 2) finite log-chromas with L >= 1, got shape {uv.shape}")
    n = model.bins
    position = (uv - model.origin) / model.bin_size
    low = jnp.floor(position)
    weight = position - low
    pmf = jnp.zeros((n, n), model.bias.dtype)
    for di in (0, 1):
        for dj in (0, 1):
            share = (weight[:, 0] if di else 1 - weight[:, 0]) * (weight[:, 1] if dj else 1 - weight[:, 1])
            i = jnp.mod(low[:, 0].astype(jnp.int32) + di, n)
            j = jnp.mod(low[:, 1].astype(jnp.int32) + dj, n)
            pmf = pmf.at[i, j].add(share)
    return _normalised(_blur(pmf, options.smoothing / float(model.bin_size)), options.floor)


@eqx.filter_jit
def _scores(model: FFCC, histograms: Float[Array, "N 2 n n"]) -> Float[Array, "N n n"]:
    return jax.vmap(lambda h: convolve(h, model.filters, model.bias))(histograms)


def adapt_bias(
    model: FFCC,
    histograms: Float[Array | np.ndarray, "N 2 n n"],
    training_uv: Float[Array | np.ndarray, "S 2"],
    physics_uv: Float[Array | np.ndarray, "L 2"],
    options: AdaptOptions | None = None,
) -> tuple[FFCC, Float[Array, "n n"]]:
    """``model`` with its bias map moved from the training lights' prior to the target's (module
    docstring): ``q`` starts as ``(1 - physics) p_train + physics p_loci``; each EM round sets
    ``q <- (1 - physics) blur(mean_i softmax(scores_i + log(q / p_train))) + physics p_loci``.
    Only the unlabelled histograms are read.

    Arguments:
        model: a trained FFCC.
        histograms: ``(N, 2, n, n)`` the target's unlabelled images' histograms on ``model``'s grid
            (:func:`ccjax.estimators.ffcc._fitting.histograms`).
        training_uv: ``(S, 2)`` the log-chroma of the lights ``model`` was trained on.
        physics_uv: ``(L, 2)`` the log-chroma of the target's plausible lights (its loci through
            its curves).
        options: :class:`AdaptOptions` (None: its defaults).

    Returns:
        ``(adapted FFCC, q (n, n))``.
    """
    options = options or AdaptOptions()
    histograms = jnp.asarray(histograms, model.bias.dtype)
    if histograms.ndim != 4 or histograms.shape[1:] != (2, model.bins, model.bins) or histograms.shape[0] == 0:
        raise ValueError(f"histograms: expected (N, 2, {model.bins}, {model.bins}) with N >= 1, got {histograms.shape}")
    p_train = light_density(model, training_uv, options)
    p_loci = light_density(model, physics_uv, options)
    q = (1.0 - options.physics) * p_train + options.physics * p_loci
    scores = _scores(model, histograms)
    sigma = options.smoothing / float(model.bin_size)
    for _ in range(options.rounds):
        shift = jnp.log(q) - jnp.log(p_train)
        logits = (scores + shift).reshape(scores.shape[0], -1)
        expected = jnp.mean(jax.nn.softmax(logits, axis=-1), axis=0).reshape(q.shape)
        q = (1.0 - options.physics) * _normalised(_blur(expected, sigma), options.floor) + options.physics * p_loci
    shift = jnp.log(q) - jnp.log(p_train)
    return eqx.tree_at(lambda m: m.bias, model, model.bias + (shift - jnp.mean(shift))), q
