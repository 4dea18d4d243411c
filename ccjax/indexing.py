"""Deprecated path: the colour-indexing experiment (Barnard 1999 ch. 11) moved to
:mod:`ccjax.experiments.indexing`; these re-exports go in the next release."""

from ccjax.experiments.indexing import BINS as BINS
from ccjax.experiments.indexing import IMAGE_NOISE as IMAGE_NOISE
from ccjax.experiments.indexing import IndexingResult as IndexingResult
from ccjax.experiments.indexing import ObjectImages as ObjectImages
from ccjax.experiments.indexing import correct_ranks as correct_ranks
from ccjax.experiments.indexing import intersection as intersection
from ccjax.experiments.indexing import rank_scores as rank_scores
from ccjax.experiments.indexing import render_objects as render_objects
from ccjax.experiments.indexing import rg_histogram as rg_histogram
from ccjax.experiments.indexing import run_indexing as run_indexing
