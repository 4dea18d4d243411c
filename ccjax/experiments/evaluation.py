"""The per-image results of photo evaluation, kept under their earlier import path: they live in
:mod:`ccjax.evaluation.results` (:class:`ImageResults`, :func:`run_images`, :func:`fold_worlds`)."""

from ccjax.evaluation.results import ImageResults, fold_worlds, run_images

__all__ = ["ImageResults", "fold_worlds", "run_images"]
