"""Training estimators on image sets (optax): the learnable parameters of each differentiable
family (:mod:`.parameters`), training examples read from a folder (:mod:`.data`), the Adam loop
with relighting augmentation, held-out error and early stopping (:mod:`.loop`), K-fold
cross-validation and the model files (:mod:`.folds`).

Typical use::

    model, log, folds = ccjax.training.train_on_images(
        "images/", "images/groundtruth.csv", "RGB-C-by-C-MMSE", camera="Canon EOS 5D Mark II", folds=3
    )
"""

from ccjax.training.data import Examples as Examples
from ccjax.training.data import load_examples as load_examples
from ccjax.training.data import read_examples as read_examples
from ccjax.training.data import source_examples as source_examples
from ccjax.training.folds import CrossValidation as CrossValidation
from ccjax.training.folds import FoldResult as FoldResult
from ccjax.training.folds import assign_folds as assign_folds
from ccjax.training.folds import cross_validate as cross_validate
from ccjax.training.folds import load_model as load_model
from ccjax.training.folds import read_folds as read_folds
from ccjax.training.folds import save_trained as save_trained
from ccjax.training.folds import train_on_images as train_on_images
from ccjax.training.loop import Schedule as Schedule
from ccjax.training.loop import TrainingLog as TrainingLog
from ccjax.training.loop import angular_errors as angular_errors
from ccjax.training.loop import fit_to_examples as fit_to_examples
from ccjax.training.loop import predict as predict
from ccjax.training.loop import subsample as subsample
from ccjax.training.parameters import constrain as constrain
from ccjax.training.parameters import learnable as learnable
from ccjax.training.parameters import learnable_types as learnable_types
