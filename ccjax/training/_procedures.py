"""Which training procedure a model gets: a family with its own solver (FFCC: L-BFGS on
histograms computed once, Barron & Tsai 2017 §3) is trained by it; the others by the Adam loop
(:func:`ccjax.training._loop.fit_to_examples`)."""

from __future__ import annotations

import time

from ccjax.estimators.base import AbstractEstimator
from ccjax.estimators.ffcc import FFCC
from ccjax.estimators.ffcc import train as train_ffcc
from ccjax.training._data import Examples
from ccjax.training._loop import Schedule, TrainingLog, fit_to_examples

__all__ = ["train_model"]


def _fit_ffcc(
    model: FFCC, examples: Examples, schedule: Schedule, validation: Examples | None, progress: bool
) -> tuple[AbstractEstimator, TrainingLog]:
    """FFCC's L-BFGS fit on every training example (its regularisers, not early stopping, keep it
    from overfitting, so nothing is held out; the schedule's epochs and steps do not apply)."""
    cpu_start = time.process_time()
    if examples.x.ndim != 4:
        raise ValueError(f"examples: FFCC trains on images (N, H, W, 3), got shape {tuple(examples.x.shape)}")
    trained, record = train_ffcc(model, examples.x, examples.mask, examples.illuminant)
    log = TrainingLog(train_loss=record.losses, n_train=len(examples), n_heldout=0)
    log.seconds, log.cpu_seconds = record.seconds, time.process_time() - cpu_start
    return trained, log


_PROCEDURES = {FFCC: _fit_ffcc}


def train_model(
    model: AbstractEstimator,
    examples: Examples,
    schedule: Schedule | None = None,
    *,
    validation: Examples | None = None,
    progress: bool = True,
) -> tuple[AbstractEstimator, TrainingLog]:
    """Train ``model`` on ``examples`` with its family's procedure.

    Arguments:
        model: a fitted, trainable estimator (the start).
        examples: training examples.
        schedule: the Adam loop's :class:`~ccjax.training._loop.Schedule` (default: its
            defaults; families with their own solver ignore it).
        validation: held-out examples for the Adam loop's early stopping.
        progress: progress bars.

    Returns:
        ``(trained model, TrainingLog)``.
    """
    schedule = schedule or Schedule()
    for kind, procedure in _PROCEDURES.items():
        if isinstance(model, kind):
            return procedure(model, examples, schedule, validation, progress)
    return fit_to_examples(model, examples, schedule, validation=validation, progress=progress)
