"""The execution layer: the one place where fitted models meet data.

* :mod:`ccjax.runs.store`: worlds and fitted models, one memory-plus-disk cache.
"""

from ccjax.runs import store

__all__ = ["store"]
