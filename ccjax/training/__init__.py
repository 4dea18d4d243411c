"""Training estimators on image sets (optax): the learnable parameters of each differentiable
family (:mod:`._parameters`), training examples read from a folder (:mod:`._data`), the Adam loop
with relighting augmentation, held-out error and early stopping (:mod:`._loop`), K-fold
cross-validation (:mod:`._folds`), pretraining on images rendered from a camera's spectra
(:mod:`._pretraining`); model files: :func:`ccjax.runs.store.save_trained` and
:func:`ccjax.load_model`.

Typical use::

    model, log, folds = ccjax.training.train_on_images(
        "images/", "images/groundtruth.csv", "RGB-C-by-C-MMSE", camera="Canon EOS 5D Mark II", folds=3
    )
"""

from ccjax.training._data import Examples, load_examples, read_examples, source_examples
from ccjax.training._folds import (
    CrossValidation,
    FoldResult,
    assign_folds,
    cross_validate,
    read_folds,
    train_on_images,
)
from ccjax.training._loop import Schedule, TrainingLog, angular_errors, fit_to_examples, predict, subsample
from ccjax.training._parameters import constrain, learnable, learnable_types
from ccjax.training._pretraining import (
    Pretraining,
    fine_tune,
    planckian_lights,
    planckian_locus,
    pretrain,
    render_examples,
    render_images,
)
from ccjax.training._procedures import (
    LOG_CHROMA_SCHEDULE,
    default_schedule,
    procedure_record,
    train_model,
    uses_schedule,
)

__all__ = [
    "LOG_CHROMA_SCHEDULE",
    "CrossValidation",
    "Examples",
    "FoldResult",
    "Pretraining",
    "Schedule",
    "TrainingLog",
    "angular_errors",
    "assign_folds",
    "constrain",
    "cross_validate",
    "default_schedule",
    "fine_tune",
    "fit_to_examples",
    "learnable",
    "learnable_types",
    "load_examples",
    "planckian_lights",
    "planckian_locus",
    "predict",
    "pretrain",
    "procedure_record",
    "read_examples",
    "read_folds",
    "render_examples",
    "render_images",
    "source_examples",
    "subsample",
    "train_model",
    "train_on_images",
    "uses_schedule",
]
