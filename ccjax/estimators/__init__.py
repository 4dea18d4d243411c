"""Estimator families; see :mod:`ccjax.estimators.registry` for labels."""

from ccjax.estimators.base import Estimate, Estimator, estimate_batch
from ccjax.estimators.registry import available, fit

__all__ = ["Estimate", "Estimator", "available", "estimate_batch", "fit"]
