"""Deprecated: the field's protocol over several folders of photographs; photo evaluation lives in
:mod:`ccjax.evaluation` (:func:`ccjax.evaluation.evaluate_folder_sets`). It warns on import and on
each use of a name, naming the replacement, and will be removed in the next release."""

from ccjax._deprecation import moved_names, warn_moved_module

warn_moved_module("ccjax.experiments.folder_sets", "ccjax.evaluation")
__getattr__, __dir__ = moved_names(
    "ccjax.experiments.folder_sets",
    {
        "PROTOCOL_STATISTICS": "ccjax.evaluation.PROTOCOL_STATISTICS",
        "FolderSet": "ccjax.evaluation.FolderSet",
        "SetResult": "ccjax.evaluation.SetResult",
        "SetsEvaluation": "ccjax.evaluation.SetsEvaluation",
        "evaluate_folder_sets": "ccjax.evaluation.evaluate_folder_sets",
        "geometric_mean": "ccjax.evaluation.geometric_mean",
        "geometric_means": "ccjax.evaluation.geometric_means",
        "save_fold_models": "ccjax.evaluation.save_fold_models",
        "fold_model_file": "ccjax.evaluation.sets.fold_model_file",
    },
)
