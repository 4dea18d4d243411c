"""The execution layer: the one place where fitted models meet data.

* :mod:`ccjax.runs.store`: worlds and fitted models, one memory-plus-disk cache.
* :mod:`ccjax.runs.hosts`: scale-out primitives: processes under ``jax.distributed``, the item
  axis split over processes and sharded over a device mesh, results pooled.
"""

from ccjax.runs import hosts, store

__all__ = ["hosts", "store"]
