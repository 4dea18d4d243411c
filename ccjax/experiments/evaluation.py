"""Deprecated: the per-image results of photo evaluation; they live in :mod:`ccjax.evaluation`
(:class:`ccjax.evaluation.ImageResults`). It warns on import and on each use of a name, naming the
replacement, and will be removed in the next release."""

from ccjax._deprecation import moved_names, warn_moved_module

warn_moved_module("ccjax.experiments.evaluation", "ccjax.evaluation")
__getattr__, __dir__ = moved_names(
    "ccjax.experiments.evaluation",
    {
        "ImageResults": "ccjax.evaluation.ImageResults",
        "fold_worlds": "ccjax.evaluation.fold_worlds",
        "run_images": "ccjax.evaluation.run_images",
    },
)
