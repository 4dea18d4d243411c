"""Sensor sharpening for colour constancy (Barnard 1999 ch. 5).

A sharpening transform ``T`` (3x3) replaces responses ``x`` (rows) by ``x @ T``; a diagonal-model
algorithm runs there and its map ``d#`` acts back in camera space as ``T diag(d#) T^-1``.

* :mod:`ccjax.sharpening._transforms`: the error measures of §5.4/§5.7 (best linear map, best
  diagonal map for a given ``T``, RMS RGB mapping error over the whole reflectance set, the
  camera's sharpness) and database sharpening (§5.1/§5.2: "opt" and "ave");
* :mod:`ccjax.sharpening._new_method`: the thesis' new method (§5.3, "gd-identity");
* :mod:`ccjax.sharpening._wrapper`: :func:`sharpened`, any estimator run in sharpened space with
  the revert policy (§5.2, §5.4);
* :mod:`ccjax.sharpening._adaptation`: the standard chromatic adaptation transforms (Bradford,
  CAT02, CAT16) as sharpening transforms of a camera, for comparison;
* :mod:`ccjax.sharpening._learned`: ``T`` learned end to end through a differentiable estimator
  (beyond the thesis).

The chapter-5 experiments (Table 5.1, the transform summaries and plots of ``ccjax sharpen``,
camera ranking) are in :mod:`ccjax.experiments.chapter5`.
"""

from ccjax.sharpening._adaptation import ADAPTATION_TRANSFORMS, adaptation_sharpening, camera_to_xyz, cat_matrix
from ccjax.sharpening._learned import LearnedSharpening, learned_sharpening, scene_losses
from ccjax.sharpening._new_method import (
    NEGATIVE_TOLERANCE,
    POSITIVITY_OFFSET,
    DatabaseStatistics,
    NewSharpening,
    ObjectiveTerms,
    new_sharpening,
    objective,
    objective_terms,
    on_sphere,
)
from ccjax.sharpening._transforms import (
    THESIS_SCALE,
    actual_error,
    average_sharpening,
    best_diagonal_map,
    best_linear_error,
    best_linear_map,
    database_responses,
    database_sharpening,
    diagonal_error,
    mapping_error,
    normalise_transform,
    optimal_sharpening,
    sharpness,
)
from ccjax.sharpening._wrapper import EstimatorFit, Sharpened, estimator_fit, sharpened, sharpened_world

__all__ = [
    "ADAPTATION_TRANSFORMS",
    "NEGATIVE_TOLERANCE",
    "POSITIVITY_OFFSET",
    "THESIS_SCALE",
    "DatabaseStatistics",
    "EstimatorFit",
    "LearnedSharpening",
    "NewSharpening",
    "ObjectiveTerms",
    "Sharpened",
    "actual_error",
    "adaptation_sharpening",
    "average_sharpening",
    "best_diagonal_map",
    "best_linear_error",
    "best_linear_map",
    "camera_to_xyz",
    "cat_matrix",
    "database_responses",
    "database_sharpening",
    "diagonal_error",
    "estimator_fit",
    "learned_sharpening",
    "mapping_error",
    "new_sharpening",
    "normalise_transform",
    "objective",
    "objective_terms",
    "on_sphere",
    "optimal_sharpening",
    "scene_losses",
    "sharpened",
    "sharpened_world",
    "sharpness",
]
