"""ccjax: JAX-accelerated, differentiable computational colour constancy.

Faithful implementations of the methods of K. Barnard, *Practical Colour Constancy* (1999), plus
modern estimators, as pure ``jit``/``vmap`` kernels. Start with :class:`World`,
:func:`ccjax.scenes.sample`, :func:`estimate` and :func:`ccjax.experiments.sweep`.
"""

from __future__ import annotations

import functools

from ccjax import metrics
from ccjax.camera import Camera, cameras
from ccjax.estimators import Estimate, Estimator, estimate_batch, fit
from ccjax.scenes import Scenes, ShotNoise, Specular, sample
from ccjax.spectra import WAVELENGTHS
from ccjax.world import World

__version__ = "0.1.0"


@functools.cache
def _default_world() -> World:
    return World.default()


def estimate(method, rgb, mask=None, *, world: World | None = None) -> Estimate:
    """Estimate the illuminant of one scene ``(P, 3)`` or a batch ``(B, P, 3)``.

    Arguments:
        method: a registry label (``"GW"``, ``"shades-of-grey-p6"``, ...) or a fitted
            :class:`Estimator`.
        rgb: linear camera RGB, non-negative and finite.
        mask: optional booleans ``rgb.shape[:-1]``, True where a pixel is valid.
        world: the world a label is fitted to (default :meth:`World.default`).

    Returns:
        An :class:`Estimate` (``illuminant`` RGB of white, ``ok``), batched like ``rgb``.
    """
    from ccjax.estimators.base import validate_scene

    rgb, mask = validate_scene(rgb, mask)
    if isinstance(method, str):
        model = fit(method, world if world is not None else _default_world())
    elif isinstance(method, Estimator):
        model = method
    else:
        raise ValueError(f"method: expected a label or an Estimator, got {type(method).__name__}")
    return _run(model, rgb, mask)


@functools.cache
def _compiled_runner():
    import equinox as eqx

    @eqx.filter_jit
    def run(model, rgb, mask):
        return estimate_batch(model, rgb, mask) if rgb.ndim == 3 else model(rgb, mask)

    return run


def _run(model, rgb, mask):
    return _compiled_runner()(model, rgb, mask)


__all__ = [
    "WAVELENGTHS",
    "Camera",
    "Estimate",
    "Estimator",
    "Scenes",
    "ShotNoise",
    "Specular",
    "World",
    "cameras",
    "estimate",
    "estimate_batch",
    "fit",
    "metrics",
    "sample",
]
