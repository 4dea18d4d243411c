"""``ccjax.estimate``: one call from a label (or a fitted model) and a scene to an :class:`Estimate`."""

from __future__ import annotations

import functools
import math

import numpy as np

from ccjax._cache import enable_compilation_cache
from ccjax.estimators import AbstractEstimator, Estimate, estimate_batch, registry, validate_input
from ccjax.estimators.inputs import validate_image
from ccjax.io.reading import CLIP_FRACTION, LinearImage
from ccjax.preprocessing import estimate_image, estimate_pixels, resolve, usable_pixels
from ccjax.runs import store
from ccjax.world import World


def estimate(method, x, mask=None, *, world: World | None = None, saturation: float | None = CLIP_FRACTION) -> Estimate:
    """Estimate the light of one scene: a surface list, an image, or a batch of images.

    What ``x`` is goes by its shape, the same for every family:

    * ``(P, 3)``: one surface list, for surface estimators (grey world, gamut mapping, ...),
      used as given (an image estimator refuses it: a list has no neighbours).
    * ``(H, W, 3)``: one image. Its usable pixels are those the command line uses
      (:func:`ccjax.preprocessing.usable_pixels`): no channel at or above ``saturation``, no
      zero channel, inside ``mask``; each model then gets its default input
      (:func:`ccjax.preprocessing.prepare`: the pixels for the statistics methods and grey edge,
      the 5x5 block averages for the world-based methods). A clipped pixel holds the sensor's
      limit, not the light's colour (Barnard 1999 §2.7), so it is dropped by default.
    * ``(B, H, W, 3)``: a batch of images, by the same rule, for image estimators and models
      whose default input is the pixels (a block-averaged list has a length that depends on the
      image: give those one image at a time).

    A batch of surface lists ``(B, P, 3)`` goes to :func:`ccjax.estimate_batch`.

    A label is fitted through :mod:`ccjax.runs.store` (in memory and on disk, so a later process
    reads the fit), and the compiled programs go to JAX's persistent compilation cache in the ccjax
    cache (``<cache>/xla``; unless the program configured its own), so a later process compiles
    nothing either.

    Arguments:
        method: a registry label (``"GW"``, ``"shades-of-grey-p6"``, ``"grey-edge-1-6-2"``, ...) or a
            fitted estimator.
        x: linear camera RGB, non-negative and finite.
        mask: optional booleans ``x.shape[:-1]``, True where a surface or pixel may be used.
        world: the world a label is fitted to (default :meth:`World.default`).
        saturation: images only: a pixel with any channel at or above this value is clipped and
            not used, in ``x``'s own units (default 0.98, the command line's clip level for images
            on the unit scale, saturation = 1); None uses every pixel. Surface lists ignore it.

    ``estimate`` fits and inspects its input on the host, so it is called outside ``jax.jit``; inside
    a jitted function (a training loop), fit the model outside it and call the model::

        model = ccjax.fit("GW", ccjax.World.default())   # outside jit, once
        step = jax.jit(lambda rgb, mask: model(rgb, mask).illuminant)

    (``ccjax.estimate_batch(model, rgb, mask)`` for a batch of surface lists.)

    Returns:
        An :class:`Estimate` (``illuminant`` RGB of white, ``ok``, ``status``), batched like an image
        batch ``x``.

    Raises:
        TypeError: ``x`` or ``mask`` is a traced value (a call inside ``jax.jit``, ``vmap`` or
            ``grad``).
    """
    _refuse_traced(x, mask)
    enable_compilation_cache()
    if isinstance(method, str):
        registry.refuse_untrained(method)
        # The same object for repeated calls, so they also reuse its compiled code.
        model = store.fit(method, world if world is not None else store.world())
    elif isinstance(method, AbstractEstimator):
        model = method
    else:
        raise ValueError(f"method: expected a label or a fitted estimator, got {type(method).__name__}")
    if np.ndim(x) not in (3, 4):
        x, mask = validate_input(model, x, mask)
        return _run(model, x, mask)
    _check_saturation(saturation, x)
    images, mask = validate_image(x, mask)
    clipped = np.zeros(images.shape[:-1], bool) if saturation is None else np.any(images >= saturation, axis=-1)
    _refuse_all_clipped(clipped, saturation)
    if images.ndim == 3:
        return estimate_image(model, LinearImage(rgb=images, clipped=clipped), mask=mask)
    if model.input_kind == "surfaces" and not resolve(model).pixels:
        raise ValueError(
            f"image: {type(model).__name__} takes {resolve(model).name} surface lists of an image, whose length "
            f"depends on the image; give one image (H, W, 3) at a time, not a batch of shape {images.shape}"
        )
    # The pixel rule is per pixel: the batch's rows as one tall image give every image's mask at once.
    batch, height, width, _ = images.shape
    usable = usable_pixels(
        images.reshape(batch * height, width, 3),
        clipped.reshape(batch * height, width),
        0.0,
        mask=mask.reshape(batch * height, width),
    ).reshape(batch, height, width)
    return _run(model, images, usable)


def _refuse_traced(x, mask) -> None:
    from jax.core import Tracer

    for name, value in (("x", x), ("mask", mask)):
        if isinstance(value, Tracer):
            raise TypeError(
                f"{name}: ccjax.estimate was called on a traced value (inside jax.jit, vmap or grad); it fits "
                "the model and reads the pixels on the host. Fit the model outside the transformation and call it "
                "inside: model = ccjax.fit(label, world); model(rgb, mask) (or ccjax.estimate_batch(model, rgb, mask))"
            )


def _check_saturation(saturation: float | None, x) -> None:
    if saturation is None:
        return
    if isinstance(saturation, bool) or not isinstance(saturation, (int, float)) or not math.isfinite(saturation):
        raise ValueError(f"saturation: expected a positive number or None, got {saturation!r}")
    if saturation <= 0:
        raise ValueError(f"saturation: expected a positive number or None, got {saturation!r}")
    dtype = getattr(x, "dtype", None)
    if dtype is not None and np.dtype(dtype).kind in "ui" and saturation <= 1:
        raise ValueError(
            f"saturation: {saturation!r} is on the unit scale but the image holds integers ({np.dtype(dtype)}); "
            "divide it by its saturation level (e.g. 65535) or give saturation in its units"
        )


def _refuse_all_clipped(clipped: np.ndarray, saturation: float | None) -> None:
    """The command line's rule for an image every pixel of which is clipped (an error, not the
    fallback light): most often an image on its file's scale (0..65535) given with the unit
    scale's clip level."""
    whole = clipped.reshape(-1, *clipped.shape[-2:]).all(axis=(1, 2))
    if np.any(whole):
        which = "the image" if clipped.ndim == 2 else f"image {int(np.argmax(whole))} of the batch"
        raise ValueError(
            f"image: every pixel of {which} is clipped (a channel at or above the clip level saturation="
            f"{saturation:g}); an image on its file's scale (0..65535) must be divided by its saturation level, "
            "or given with saturation in its units"
        )


@functools.cache
def _compiled_runner():
    import equinox as eqx
    import jax

    @eqx.filter_jit
    def run(model, x, mask):
        if x.ndim == 4 and model.input_kind == "surfaces":
            return jax.vmap(lambda image, usable: estimate_pixels(model, image, usable))(x, mask)
        return estimate_batch(model, x, mask) if x.ndim == 4 else model(x, mask)

    return run


def _run(model, x, mask):
    return _compiled_runner()(model, x, mask)
