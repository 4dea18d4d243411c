"""Deprecated: the image pipeline moved; this module re-exports it for one release.

New homes: :mod:`ccjax.io` (reading, writing, ground truth, sRGB preview),
:mod:`ccjax.preprocessing` (usable pixels, Table 4.6 preprocessing, estimator input),
:mod:`ccjax.correction` (correction maps and gains), :mod:`ccjax.experiments.evaluation`
(the evaluation runner, fold worlds), :mod:`ccjax.runs.store` (cached worlds and fitted models)
and :mod:`ccjax._cache` (cache directory, compilation cache).
"""

from ccjax._cache import cache_directory as cache_directory
from ccjax._cache import enable_compilation_cache as enable_compilation_cache
from ccjax.correction import apply_map as apply_map
from ccjax.correction import correct as correct
from ccjax.correction import correction_map as correction_map
from ccjax.correction import diagonal_gains as diagonal_gains
from ccjax.experiments.evaluation import ImageResults as ImageResults
from ccjax.experiments.evaluation import fold_worlds as fold_worlds
from ccjax.experiments.evaluation import run_images as run_images
from ccjax.io.ground_truth import match_ground_truth as match_ground_truth
from ccjax.io.ground_truth import read_ground_truth as read_ground_truth
from ccjax.io.ground_truth import write_ground_truth as write_ground_truth
from ccjax.io.png import PNG_SIGNATURE as PNG_SIGNATURE
from ccjax.io.png import read_png as read_png
from ccjax.io.png import write_png as write_png
from ccjax.io.preview import preview_matrix as preview_matrix
from ccjax.io.preview import preview_matrix_cached as preview_matrix_cached
from ccjax.io.preview import srgb_preview as srgb_preview
from ccjax.io.preview import write_preview as write_preview
from ccjax.io.reading import IMAGE_SUFFIXES as IMAGE_SUFFIXES
from ccjax.io.reading import RAW_SUFFIXES as RAW_SUFFIXES
from ccjax.io.reading import LinearImage as LinearImage
from ccjax.io.reading import list_images as list_images
from ccjax.io.reading import read_image as read_image
from ccjax.io.writing import quantise as quantise
from ccjax.io.writing import write_dataset as write_dataset
from ccjax.io.writing import write_linear as write_linear
from ccjax.preprocessing import DEFAULT_DARK as DEFAULT_DARK
from ccjax.preprocessing import DEFAULT_PREPROCESSING as DEFAULT_PREPROCESSING
from ccjax.preprocessing import TABLE_4_6 as TABLE_4_6
from ccjax.preprocessing import Preprocessing as Preprocessing
from ccjax.preprocessing import block_average as block_average
from ccjax.preprocessing import cluster_rgb as cluster_rgb
from ccjax.preprocessing import estimate_image as estimate_image
from ccjax.preprocessing import estimate_pixels as estimate_pixels
from ccjax.preprocessing import hull_reduce as hull_reduce
from ccjax.preprocessing import masked_mean as masked_mean
from ccjax.preprocessing import model_input as model_input
from ccjax.preprocessing import segment as segment
from ccjax.preprocessing import surfaces as surfaces
from ccjax.preprocessing import usable_pixels as usable_pixels
from ccjax.runs.store import fit as cached_fit  # noqa: F401  (re-exported under its old name)
from ccjax.runs.store import world as cached_world  # noqa: F401  (re-exported under its old name)
