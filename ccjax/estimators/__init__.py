"""Estimator families; see :mod:`ccjax.estimators.registry` for labels and
:mod:`ccjax.estimators.base` for the contract every model follows."""

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
from ccjax.estimators.registry import Entry, available, fit, model_classes

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
    "fit",
    "model_classes",
    "require_kind",
    "validate_input",
]
