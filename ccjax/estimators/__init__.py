"""Estimator families; see :mod:`ccjax.estimators.registry` for labels."""

from ccjax.estimators.base import Estimate, Estimator
from ccjax.estimators.registry import available, fit

__all__ = ["Estimate", "Estimator", "available", "fit"]
