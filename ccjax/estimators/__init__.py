"""Estimator families; see :mod:`ccjax.estimators.registry` for labels and
:mod:`ccjax.estimators.base` for the contract every model follows.

:func:`fit_uncached` fits a label afresh on every call; :func:`ccjax.fit` is the cached one (on
disk and in memory), which most programs want."""

import warnings

from ccjax.estimators.base import (
    AbstractEstimator,
    AbstractImageEstimator,
    AbstractStatisticsSurfaceEstimator,
    AbstractSurfaceEstimator,
    AbstractUnblockedEstimator,
    AbstractWorldSurfaceEstimator,
    Estimate,
    Status,
    estimate_batch,
)
from ccjax.estimators.inputs import require_kind, validate_input
from ccjax.estimators.registry import Entry, available, model_classes
from ccjax.estimators.registry import fit as fit_uncached
from ccjax.world import World

__all__ = [
    "AbstractEstimator",
    "AbstractImageEstimator",
    "AbstractStatisticsSurfaceEstimator",
    "AbstractSurfaceEstimator",
    "AbstractUnblockedEstimator",
    "AbstractWorldSurfaceEstimator",
    "Entry",
    "Estimate",
    "Status",
    "available",
    "estimate_batch",
    "fit_uncached",
    "model_classes",
    "require_kind",
    "validate_input",
]


def fit(label: str, world: World, **options) -> AbstractEstimator:
    """Deprecated alias of :func:`fit_uncached` (renamed so that it no longer shares a name with
    the cached :func:`ccjax.fit`); it warns and will be removed in the next release.

    Arguments:
        label: a registry label.
        world: the world.
        **options: the family's fit options.

    Returns:
        The fitted model, as :func:`fit_uncached` returns it.
    """
    warnings.warn(
        "ccjax.estimators.fit is deprecated: use ccjax.estimators.fit_uncached (or ccjax.fit, which caches)",
        DeprecationWarning,
        stacklevel=2,
    )
    return fit_uncached(label, world, **options)
