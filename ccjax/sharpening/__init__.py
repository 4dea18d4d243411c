"""Sensor sharpening for colour constancy (Barnard 1999 ch. 5).

A sharpening transform ``T`` (3x3) replaces responses ``x`` (rows) by ``x @ T``; a diagonal-model
algorithm runs there and its map ``d#`` acts back in camera space as ``T diag(d#) T^-1``.

* :mod:`ccjax.sharpening.transforms`: the error measures of §5.4/§5.7 (best linear map, best
  diagonal map for a given ``T``, RMS RGB mapping error over the whole reflectance set, the
  camera's sharpness) and database sharpening (§5.1/§5.2: "opt" and "ave");
* :mod:`ccjax.sharpening.new_method`: the thesis' new method (§5.3, "gd-identity");
* :mod:`ccjax.sharpening.wrapper`: :func:`sharpened`, any estimator run in sharpened space with
  the revert policy (§5.2, §5.4);
* :mod:`ccjax.sharpening.learned`: ``T`` learned end to end through a differentiable estimator
  (beyond the thesis).

The chapter-5 experiments (Table 5.1, the transform summaries and plots of ``ccjax sharpen``,
camera ranking) are in :mod:`ccjax.experiments.chapter5`.
"""

from ccjax.sharpening.learned import LearnedSharpening as LearnedSharpening
from ccjax.sharpening.learned import learned_sharpening as learned_sharpening
from ccjax.sharpening.learned import scene_losses as scene_losses
from ccjax.sharpening.new_method import NEGATIVE_TOLERANCE as NEGATIVE_TOLERANCE
from ccjax.sharpening.new_method import POSITIVITY_OFFSET as POSITIVITY_OFFSET
from ccjax.sharpening.new_method import DatabaseStatistics as DatabaseStatistics
from ccjax.sharpening.new_method import NewSharpening as NewSharpening
from ccjax.sharpening.new_method import ObjectiveTerms as ObjectiveTerms
from ccjax.sharpening.new_method import new_sharpening as new_sharpening
from ccjax.sharpening.new_method import objective as objective
from ccjax.sharpening.new_method import objective_terms as objective_terms
from ccjax.sharpening.new_method import on_sphere as on_sphere
from ccjax.sharpening.transforms import THESIS_SCALE as THESIS_SCALE
from ccjax.sharpening.transforms import actual_error as actual_error
from ccjax.sharpening.transforms import average_sharpening as average_sharpening
from ccjax.sharpening.transforms import best_diagonal_map as best_diagonal_map
from ccjax.sharpening.transforms import best_linear_error as best_linear_error
from ccjax.sharpening.transforms import best_linear_map as best_linear_map
from ccjax.sharpening.transforms import database_responses as database_responses
from ccjax.sharpening.transforms import database_sharpening as database_sharpening
from ccjax.sharpening.transforms import diagonal_error as diagonal_error
from ccjax.sharpening.transforms import mapping_error as mapping_error
from ccjax.sharpening.transforms import normalise_transform as normalise_transform
from ccjax.sharpening.transforms import optimal_sharpening as optimal_sharpening
from ccjax.sharpening.transforms import sharpness as sharpness
from ccjax.sharpening.wrapper import EstimatorFit as EstimatorFit
from ccjax.sharpening.wrapper import Sharpened as Sharpened
from ccjax.sharpening.wrapper import estimator_fit as estimator_fit
from ccjax.sharpening.wrapper import sharpened as sharpened
from ccjax.sharpening.wrapper import sharpened_world as sharpened_world
