"""Photo evaluation: methods scored on folders of photographs with ground truth, under a protocol.

A protocol is a value (:mod:`ccjax.evaluation.photo_protocols`), read and training options are values
(:class:`ReadOptions`, :class:`TrainingOptions`), and :func:`evaluate` runs them over
:class:`FolderSet` s::

    from ccjax import evaluation

    folders = [evaluation.FolderSet(Path("cube"), Path("cube/groundtruth.csv"), "Canon EOS 600D"), ...]
    result = evaluation.evaluate(folders, ["shades-of-grey-p6"], evaluation.LeaveOneCameraOut(("FFCC",)))
    print(result.table())

* :class:`AbstractProtocol` -- a protocol's hooks: its rounds (:class:`Round`) and each scored
  folder's models from the round's :class:`RoundInputs`;
* :class:`FittedToWorld`, :class:`KFolds`, :class:`TrainedInFolds` -- each folder on its own;
* :class:`LeaveOneCameraOut`, :class:`TrainOn` -- trained on other cameras' folders mapped into
  the scored folder's camera (:mod:`ccjax.evaluation.cross_camera`);
* :class:`ImageResults` -- per-image estimates and the field's statistics; :func:`fold_worlds`;
  :func:`curve_check` -- the ground truth against a camera's Planckian/daylight locus
  (:func:`locus_whites`);
* :func:`evaluate_folder`, :func:`evaluate_folder_sets` -- the same in one call with keyword
  options (the protocol named by ``folds`` and ``train``, :func:`protocol_for`).
"""

from ccjax.evaluation.camera_check import (
    CURVE_QUANTILE,
    CURVE_THRESHOLD,
    CurveCheck,
    curve_check,
    locus_distance,
    locus_whites,
    polyline_distance,
)
from ccjax.evaluation.cross_camera import (
    CAMERA_MAPS,
    LeaveOneCameraOut,
    TrainOn,
    pooled_source,
    train_for_camera,
    train_pooled,
)
from ccjax.evaluation.image_results import ImageResults, fold_worlds, run_images
from ccjax.evaluation.keyword_calls import evaluate_folder, evaluate_folder_sets
from ccjax.evaluation.options import ReadOptions, TrainingOptions
from ccjax.evaluation.photo_protocols import (
    AbstractProtocol,
    FittedToWorld,
    KFolds,
    Round,
    RoundInputs,
    TrainedInFolds,
    protocol_for,
)
from ccjax.evaluation.scored_folder import FolderData, FolderEvaluation, FolderModels, read_folder
from ccjax.evaluation.sets import (
    PROTOCOL_STATISTICS,
    FolderSet,
    SetResult,
    SetsEvaluation,
    evaluate,
    evaluate_data,
    geometric_mean,
    geometric_means,
    save_fold_models,
)

__all__ = [
    "CAMERA_MAPS",
    "CURVE_QUANTILE",
    "CURVE_THRESHOLD",
    "PROTOCOL_STATISTICS",
    "AbstractProtocol",
    "CurveCheck",
    "FittedToWorld",
    "FolderData",
    "FolderEvaluation",
    "FolderModels",
    "FolderSet",
    "ImageResults",
    "KFolds",
    "LeaveOneCameraOut",
    "ReadOptions",
    "Round",
    "RoundInputs",
    "SetResult",
    "SetsEvaluation",
    "TrainOn",
    "TrainedInFolds",
    "TrainingOptions",
    "curve_check",
    "evaluate",
    "evaluate_data",
    "evaluate_folder",
    "evaluate_folder_sets",
    "fold_worlds",
    "geometric_mean",
    "geometric_means",
    "locus_distance",
    "locus_whites",
    "polyline_distance",
    "pooled_source",
    "protocol_for",
    "read_folder",
    "run_images",
    "save_fold_models",
    "train_for_camera",
    "train_pooled",
]
