"""``ccjax.estimate``: one call from a label (or a fitted model) and a scene to an :class:`Estimate`."""

from __future__ import annotations

import functools

from ccjax._cache import enable_compilation_cache
from ccjax.estimators import AbstractEstimator, Estimate, estimate_batch, validate_input
from ccjax.runs import store
from ccjax.world import World


def estimate(method, x, mask=None, *, world: World | None = None) -> Estimate:
    """Estimate the illuminant of one scene (or a batch of images), with a label or a fitted model.

    The model's input kind decides what ``x`` is: surface estimators take one surface list
    ``(P, 3)``; image estimators (grey edge) an image ``(H, W, 3)`` or a batch ``(B, H, W, 3)``.
    Anything else raises a ``ValueError`` saying what to pass. A 3-D array given to a surface
    estimator is refused, since an image ``(H, W, 3)`` would pass for a batch of ``H`` surface
    lists: images reach surface estimators through the image pipeline
    (:func:`ccjax.preprocessing.estimate_image`), batches of surface lists through
    :func:`ccjax.estimate_batch`.

    A label is fitted through :mod:`ccjax.runs.store` (in memory and on disk, so a later process
    reads the fit), and the compiled programs go to JAX's persistent compilation cache in the ccjax
    cache (``<cache>/xla``; unless the program configured its own), so a later process compiles
    nothing either.

    Arguments:
        method: a registry label (``"GW"``, ``"shades-of-grey-p6"``, ``"grey-edge-1-6-2"``, ...) or a
            fitted estimator.
        x: linear camera RGB, non-negative and finite.
        mask: optional booleans ``x.shape[:-1]``, True where a surface or pixel is valid.
        world: the world a label is fitted to (default :meth:`World.default`).

    Returns:
        An :class:`Estimate` (``illuminant`` RGB of white, ``ok``, ``status``), batched like an image
        batch ``x``.
    """
    enable_compilation_cache()
    if isinstance(method, str):
        # The same object for repeated calls, so they also reuse its compiled code.
        model = store.fit(method, world if world is not None else store.world())
    elif isinstance(method, AbstractEstimator):
        model = method
    else:
        raise ValueError(f"method: expected a label or a fitted estimator, got {type(method).__name__}")
    x, mask = validate_input(model, x, mask)
    return _run(model, x, mask)


@functools.cache
def _compiled_runner():
    import equinox as eqx

    @eqx.filter_jit
    def run(model, x, mask):
        return estimate_batch(model, x, mask) if x.ndim == 4 else model(x, mask)

    return run


def _run(model, x, mask):
    return _compiled_runner()(model, x, mask)
