"""Which training procedure a model gets: a family with its own solver (FFCC: L-BFGS on
histograms computed once, Barron & Tsai 2017 §3) is trained by it; the others by the Adam loop
(:func:`ccjax.training._loop.fit_to_examples`), with their family's default schedule
(:func:`default_schedule`)."""

from __future__ import annotations

import dataclasses
import time

from ccjax.estimators.base import AbstractEstimator
from ccjax.estimators.ffcc import FFCC, Hyperparameters, choose
from ccjax.estimators.ffcc import train as train_ffcc
from ccjax.estimators.neural import LogChromaNet
from ccjax.training._data import Examples
from ccjax.training._loop import Schedule, TrainingLog, fit_to_examples

__all__ = ["LOG_CHROMA_SCHEDULE", "default_schedule", "procedure_record", "train_model", "uses_schedule"]

LOG_CHROMA_SCHEDULE = Schedule(learning_rate=0.005, epochs=200, patience=20, stop_on="mean")
"""The log-chroma MLP's schedule. A net of some 70,000 weights on the ~170 training images of
one NUS-8 camera's fold overfits within a few Adam steps at the matrices' rate: it is trained at a
tenth of it, for up to 200 epochs, and the epoch kept is the one with the lowest held-out *mean*
angular error, which the worst images dominate (a median criterion keeps epochs whose median is
low but whose tail is long), with a patience of 20 epochs. The held-out split is taken from the
training images only (``validation_fraction``), so nothing is chosen on a scored fold."""


def _fit_ffcc(
    model: FFCC, examples: Examples, schedule: Schedule, validation: Examples | None, progress: bool, fine_tune: bool
) -> tuple[AbstractEstimator, TrainingLog]:
    """FFCC's L-BFGS fit on every training example, with the hyperparameters chosen by two-fold
    validation within them (:func:`ccjax.estimators.ffcc.choose`, seeded by the schedule's seed);
    its regularisers, not early stopping, keep it from overfitting, so nothing else is held out
    and the schedule's epochs and steps do not apply. A fine-tune centres the regulariser on
    ``model`` (:func:`ccjax.estimators.ffcc.train`'s prior) with the default hyperparameters: it is
    meant for training sets too small to split for a choice."""
    start, cpu_start = time.perf_counter(), time.process_time()
    if examples.x.ndim != 4:
        raise ValueError(f"examples: FFCC trains on images (N, H, W, 3), got shape {tuple(examples.x.shape)}")
    prior, settings = (model, Hyperparameters()) if fine_tune else (None, None)
    if settings is None:
        settings, _ = choose(
            model, examples.x, examples.mask, examples.illuminant, seed=schedule.seed, progress=progress
        )
    trained, record = train_ffcc(model, examples.x, examples.mask, examples.illuminant, settings, prior=prior)
    log = TrainingLog(train_loss=record.losses, n_train=len(examples), n_heldout=0)
    log.seconds, log.cpu_seconds = time.perf_counter() - start, time.process_time() - cpu_start
    return trained, log


_PROCEDURES = {FFCC: _fit_ffcc}

_SCHEDULES = {LogChromaNet: LOG_CHROMA_SCHEDULE}


def uses_schedule(model: AbstractEstimator) -> bool:
    """Whether ``model``'s family is trained by the Adam loop, whose :class:`Schedule` (epochs,
    batch size, learning rate, patience) applies; False for a family with its own solver (FFCC).

    Arguments:
        model: the fitted start.

    Returns:
        True for the Adam loop.
    """
    return not any(isinstance(model, kind) for kind in _PROCEDURES)


def procedure_record(model: AbstractEstimator, schedule: Schedule, *, fine_tune: bool = False) -> dict:
    """What a model file records of how it was trained: the Adam loop's schedule, or FFCC's own
    solver with the seed of its choice of settings (no schedule: none of it applies).

    Arguments:
        model: the fitted start.
        schedule: the schedule :func:`train_model` was given.
        fine_tune: the start was pretrained (FFCC then keeps its default settings).

    Returns:
        A JSON-able dict: ``procedure`` and its settings.
    """
    if uses_schedule(model):
        return {"procedure": "Adam", "schedule": dataclasses.asdict(schedule)}
    settings = "the defaults (a fine-tune)" if fine_tune else "chosen by two-fold validation within the training images"
    return {"procedure": "FFCC: L-BFGS on every training image", "settings": settings, "seed": schedule.seed}


def default_schedule(model: AbstractEstimator, **changes) -> Schedule:
    """The Adam loop's schedule for ``model``'s family (:data:`LOG_CHROMA_SCHEDULE` for the
    log-chroma MLP, the :class:`~ccjax.training.Schedule` defaults otherwise), with ``changes``.

    Arguments:
        model: the fitted start.
        changes: fields of the schedule to set (e.g. ``seed``, ``epochs``).

    Returns:
        The schedule.
    """
    for kind, schedule in _SCHEDULES.items():
        if isinstance(model, kind):
            return dataclasses.replace(schedule, **changes)
    return Schedule(**changes)


def train_model(
    model: AbstractEstimator,
    examples: Examples,
    schedule: Schedule | None = None,
    *,
    validation: Examples | None = None,
    progress: bool = True,
    fine_tune: bool = False,
) -> tuple[AbstractEstimator, TrainingLog]:
    """Train ``model`` on ``examples`` with its family's procedure.

    Arguments:
        model: a fitted, trainable estimator (the start).
        examples: training examples.
        schedule: the Adam loop's :class:`~ccjax.training._loop.Schedule` (default: the family's,
            :func:`default_schedule`; families with their own solver ignore it).
        validation: held-out examples for the Adam loop's early stopping.
        progress: progress bars.
        fine_tune: ``model`` was pretrained (:func:`ccjax.training.pretrain`) and the fit refines
            it: FFCC's regulariser is centred on it; the Adam loop starts from ``model`` either way.

    Returns:
        ``(trained model, TrainingLog)``.
    """
    schedule = schedule or default_schedule(model)
    for kind, procedure in _PROCEDURES.items():
        if isinstance(model, kind):
            return procedure(model, examples, schedule, validation, progress, fine_tune)
    return fit_to_examples(model, examples, schedule, validation=validation, progress=progress)
