"""Which numbers of a fitted model are learned: the learnable parameters of each differentiable
family, as an equinox filter (a PyTree of booleans shaped like the model)."""

from __future__ import annotations

import equinox as eqx
import jax

from ccjax.estimators.base import AbstractEstimator
from ccjax.estimators.correlation import ColourByCorrelation, ColourByCorrelation3D
from ccjax.estimators.ffcc import FFCC
from ccjax.estimators.neural import LogChromaNet, NeuralNet
from ccjax.estimators.simple import ShadesOfGrey
from ccjax.estimators.spatial import GreyEdge

# What each family learns: the Colour by Correlation matrix (Barnard 1999 §4.5.4, ch. 10; starts
# from the camera's spectral fit), grey edge's and shades of grey's Minkowski norm, the net's weights (§4.5.5), FFCC's
# filters and bias map (Barron & Tsai 2017 §3). (A
# sharpened model's inner estimator is fitted to the sharpened world, so its transform is learned
# through a traceable fit instead: ccjax.sharpening.learned_sharpening.)
_LEARNABLE = {
    ColourByCorrelation: lambda m: m.log_probability,
    ColourByCorrelation3D: lambda m: m.log_probability,
    GreyEdge: lambda m: m.p,
    ShadesOfGrey: lambda m: m.p,
    NeuralNet: lambda m: m.net,
    LogChromaNet: lambda m: m.net,
    FFCC: lambda m: (m.filters, m.bias),
}


def learnable_types() -> tuple[str, ...]:
    """Names of the model types :func:`learnable` knows.

    Returns:
        The class names.
    """
    return tuple(kind.__name__ for kind in _LEARNABLE)


def learnable(model: AbstractEstimator):
    """The filter of ``model``'s learnable parameters (``eqx.partition(model, learnable(model))``).

    Arguments:
        model: a fitted estimator of a trainable type (:func:`learnable_types`).

    Returns:
        A PyTree of booleans, True at the learned array leaves.

    Raises:
        ValueError: the model has nothing to learn.
    """
    for kind, select in _LEARNABLE.items():
        if isinstance(model, kind):
            spec = jax.tree_util.tree_map(lambda _: False, model)
            return eqx.tree_at(select, spec, replace=jax.tree_util.tree_map(eqx.is_inexact_array, select(model)))
    raise ValueError(
        f"model: a {type(model).__name__} has no learnable parameters; trainable: {', '.join(learnable_types())}"
    )


def constrain(model: AbstractEstimator) -> AbstractEstimator:
    """Re-establish what a learned model must satisfy after an update: grey edge's and shades of
    grey's Minkowski norm stays a norm (>= 1).

    Arguments:
        model: the updated model.

    Returns:
        The model with its constraints re-established.
    """
    import jax.numpy as jnp

    if isinstance(model, (GreyEdge, ShadesOfGrey)):
        return eqx.tree_at(lambda m: m.p, model, jnp.maximum(model.p, 1.0))
    return model
