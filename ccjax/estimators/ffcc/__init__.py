"""Fast Fourier Color Constancy (Barron & Tsai, CVPR 2017; Barron, "Convolutional Color
Constancy", ICCV 2015), trained on photographs: ``FFCC``.

The image's log-chroma histograms (pixels and local absolute deviation, :mod:`._histogram`) are
convolved with learned filters in the Fourier domain and a learned bias map is added
(:mod:`._model`); a softmax makes a distribution over the light's log-chroma on a torus, and the
fitted bivariate von Mises distribution (:mod:`._vonmises`) gives the estimate (its mean) and the
per-image uncertainty (its covariance, :meth:`FFCC.posterior`). Training (:mod:`._fitting`) is
L-BFGS in the paper's preconditioned Fourier parametrisation with its total-variation and L2
regularisers; ``ccjax train --method FFCC`` and ``ccjax evaluate --train FFCC`` run it.
"""

from ccjax.estimators.ffcc._adapt import AdaptOptions, adapt_bias, light_density
from ccjax.estimators.ffcc._fitting import Hyperparameters, TrainingRecord, histograms, train
from ccjax.estimators.ffcc._histogram import (
    MINIMUM_INTENSITY,
    block_means,
    featurize,
    local_absolute_deviation,
    wrapped_histogram,
)
from ccjax.estimators.ffcc._model import BIN_SIZE, BINS, FFCC, ORIGIN, Posterior, convolve, uv_to_rgb
from ccjax.estimators.ffcc._selection import CANDIDATES, choose
from ccjax.estimators.ffcc._vonmises import fit_von_mises, gaussian_nll
from ccjax.estimators.registry import register

__all__ = [
    "BINS",
    "BIN_SIZE",
    "CANDIDATES",
    "FFCC",
    "MINIMUM_INTENSITY",
    "ORIGIN",
    "AdaptOptions",
    "Hyperparameters",
    "Posterior",
    "TrainingRecord",
    "adapt_bias",
    "block_means",
    "choose",
    "convolve",
    "featurize",
    "fit_von_mises",
    "gaussian_nll",
    "histograms",
    "init_ffcc",
    "light_density",
    "local_absolute_deviation",
    "train",
    "uv_to_rgb",
    "wrapped_histogram",
]


def init_ffcc(bins: int = BINS, bin_size: float = BIN_SIZE, origin: float = ORIGIN, pool: int = 1) -> FFCC:
    """An untrained :class:`FFCC` (zero filters and bias: a uniform distribution), the start of
    training.

    Arguments:
        bins: histogram bins per axis (even).
        bin_size: log-chroma width of a bin (training may widen it, :func:`.fitting.fit_grid`).
        origin: log-chroma of bin ``(0, 0)``'s centre on both axes (training re-centres it on
            the training lights).
        pool: the side of the blocks whose means the histograms count (:attr:`FFCC.pool`; 1:
            every pixel).

    Returns:
        The :class:`FFCC`.
    """
    import jax.numpy as jnp

    if bins < 2 or bins % 2:
        raise ValueError(f"bins: expected an even number >= 2, got {bins}")
    if isinstance(pool, bool) or not isinstance(pool, int) or pool < 1:
        raise ValueError(f"pool: expected an integer >= 1, got {pool!r}")
    return FFCC(
        filters=jnp.zeros((2, bins, bins), jnp.float32),
        bias=jnp.zeros((bins, bins), jnp.float32),
        origin=jnp.full((2,), origin, jnp.float32),
        bin_size=jnp.asarray(bin_size, jnp.float32),
        pool=pool,
    )


@register(
    r"FFCC(?:-pool([1-9][0-9]?))?",
    example="FFCC",
    description="Fast Fourier Color Constancy (Barron & Tsai 2017; untrained until ccjax train / evaluate --train); "
    "FFCC-pool<k>: its histograms of k x k block means",
    grammar="FFCC[-pool<k>]",
    input_kind="image",
    untrained=True,
)
def _build_ffcc(world, match, **options):
    if match.group(1) is not None:
        options.setdefault("pool", int(match.group(1)))
    return init_ffcc(**options)
