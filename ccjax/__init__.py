"""ccjax: JAX-accelerated, differentiable computational colour constancy.

Faithful implementations of the methods of K. Barnard, *Practical Colour Constancy* (1999), plus
modern estimators, as pure ``jit``/``vmap`` kernels. Start with :class:`World`,
:func:`ccjax.scenes.sample`, :func:`estimate` and :func:`ccjax.experiments.sweep`.

The names below are imported on first use (PEP 562 module ``__getattr__``), so ``import ccjax``
itself loads no JAX: the ``ccjax`` command starts its Ctrl-C handling before the slow import of
JAX, and ``ccjax --help`` answers at once. ``import ccjax; ccjax.estimate(...)``, ``from ccjax
import World`` and ``ccjax.<subpackage>`` work as with eager imports.
"""

from __future__ import annotations

import importlib
import importlib.util
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the same names, eagerly, for type checkers and editors
    from ccjax import metrics
    from ccjax._estimate import estimate
    from ccjax.camera import Camera, cameras
    from ccjax.estimators import (
        AbstractEstimator,
        AbstractImageEstimator,
        AbstractSurfaceEstimator,
        Estimate,
        Status,
        estimate_batch,
    )
    from ccjax.runs.store import fit, load_model
    from ccjax.scenes import Scenes, ShotNoise, Specular, sample
    from ccjax.spectra import WAVELENGTHS
    from ccjax.world import World

from ccjax._version import __version__ as __version__

_SOURCES = {
    "WAVELENGTHS": "ccjax.spectra",
    "AbstractEstimator": "ccjax.estimators",
    "AbstractImageEstimator": "ccjax.estimators",
    "AbstractSurfaceEstimator": "ccjax.estimators",
    "Camera": "ccjax.camera",
    "Estimate": "ccjax.estimators",
    "Scenes": "ccjax.scenes",
    "ShotNoise": "ccjax.scenes",
    "Specular": "ccjax.scenes",
    "Status": "ccjax.estimators",
    "World": "ccjax.world",
    "cameras": "ccjax.camera",
    "estimate": "ccjax._estimate",
    "estimate_batch": "ccjax.estimators",
    "fit": "ccjax.runs.store",
    "load_model": "ccjax.runs.store",
    "sample": "ccjax.scenes",
}
"""The module each top-level name comes from."""


def __getattr__(name: str) -> object:
    """A top-level name or a subpackage, imported on first use and then kept in the module."""
    if name in _SOURCES:
        value = getattr(importlib.import_module(_SOURCES[name]), name)
    elif not name.startswith("__") and importlib.util.find_spec(f"{__name__}.{name}") is not None:
        value = importlib.import_module(f"{__name__}.{name}")  # ``import ccjax; ccjax.experiments``
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


__all__ = [
    "WAVELENGTHS",
    "AbstractEstimator",
    "AbstractImageEstimator",
    "AbstractSurfaceEstimator",
    "Camera",
    "Estimate",
    "Scenes",
    "ShotNoise",
    "Specular",
    "Status",
    "World",
    "cameras",
    "estimate",
    "estimate_batch",
    "fit",
    "load_model",
    "metrics",
    "sample",
]
