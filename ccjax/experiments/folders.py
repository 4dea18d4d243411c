"""Deprecated: one folder of photographs evaluated with keyword options; photo evaluation lives in
:mod:`ccjax.evaluation` (:func:`ccjax.evaluation.evaluate_folder`). It warns on import and on each
use of a name, naming the replacement, and will be removed in the next release."""

from ccjax._deprecation import moved_names, warn_moved_module

warn_moved_module("ccjax.experiments.folders", "ccjax.evaluation")
__getattr__, __dir__ = moved_names(
    "ccjax.experiments.folders",
    {
        "CSV_FIELDS": "ccjax.evaluation.scored_folder.CSV_FIELDS",
        "MIN_TRAINING_IMAGES": "ccjax.evaluation.photo_protocols.MIN_TRAINING_IMAGES",
        "TRAINED_SUFFIX": "ccjax.evaluation.scored_folder.TRAINED_SUFFIX",
        "FolderEvaluation": "ccjax.evaluation.FolderEvaluation",
        "check_fold_options": "ccjax.evaluation.photo_protocols.check_fold_options",
        "evaluate_folder": "ccjax.evaluation.evaluate_folder",
        "protocol_for": "ccjax.evaluation.protocol_for",
        "train_in_folds": "ccjax.evaluation.photo_protocols.train_in_folds",
        "trainable_starts": "ccjax.evaluation.photo_protocols.trainable_starts",
    },
)
