"""The execution layer: the one place where fitted models meet data.

* :mod:`ccjax.runs.store`: worlds and fitted models, one memory-plus-disk cache.
* :mod:`ccjax.runs.engine`: chunks of one shape, compile-ahead, the item axis placed on one
  device or sharded over a mesh, per-item errors and statuses (:func:`~ccjax.runs.engine.scene_errors`).
* :mod:`ccjax.runs.synthetic`: synthetic scene sources (a key, surface counts and one
  :class:`~ccjax.scenes.SceneOptions`), padding from the models' rules, the disk cache of cells.
"""

from ccjax.runs import engine, store, synthetic

__all__ = ["engine", "store", "synthetic"]
