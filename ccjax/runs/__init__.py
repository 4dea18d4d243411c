"""The execution layer: the one place where fitted models meet data.

* :mod:`ccjax.runs.store`: worlds and fitted models, one memory-plus-disk cache.
* :mod:`ccjax.runs.engine`: chunks of one shape, compile-ahead, the item axis placed on one
  device or sharded over a mesh, per-item errors and statuses (:func:`~ccjax.runs.engine.scene_errors`).
* :mod:`ccjax.runs.synthetic`: synthetic scene sources (a key, surface counts and one
  :class:`~ccjax.scenes.SceneOptions`), padding from the models' rules, the disk cache of cells.
* :mod:`ccjax.runs.sources`: image folders (listed once, headers probed once, images read, masked
  and prepared per model, one failure record per bad file).
* :mod:`ccjax.runs.images`: the one image loop, a set of models (optionally one per fold) over a
  source, compilation timed apart.
* :mod:`ccjax.runs.folders`: the Python calls over a folder, :func:`estimate_folder` and
  :func:`correct_folder` (evaluation with folds and training:
  :func:`ccjax.evaluation.evaluate_folder`).
* :mod:`ccjax.runs.hosts`: scale-out primitives: processes under ``jax.distributed``, the item
  axis split over processes and sharded over a device mesh, results pooled.

:class:`CompileLog` counts the programs a run compiled and the seconds compiling took.
"""

from ccjax.runs import engine, folders, hosts, images, sources, store, synthetic
from ccjax.runs._compilation import CompileLog
from ccjax.runs.folders import correct_folder, estimate_folder
from ccjax.runs.images import ImageRun, run_models
from ccjax.runs.sources import ImageFolder, image_folder

__all__ = [
    "CompileLog",
    "ImageFolder",
    "ImageRun",
    "correct_folder",
    "engine",
    "estimate_folder",
    "folders",
    "hosts",
    "image_folder",
    "images",
    "run_models",
    "sources",
    "store",
    "synthetic",
]
