"""Differentiable losses for training loops: the error measures of :mod:`ccjax.metrics`
(Barnard 1999 §4.2) as scalar losses with finite gradients everywhere.

Each loss wraps the one implementation in :mod:`ccjax.metrics` and adds only what a loss needs:

* a band of :data:`ZERO_ERROR_EPS` machine epsilons below which an error counts as zero (its
  value is kept, its gradient is 0), since rounding rarely makes an error of parallel vectors
  exactly 0;
* a reduction over the batch (mean of the per-item errors, weighted by an optional ``weight``, so
  a padded batch can carry empty slots with weight 0);
* safe gradients at the points where an error measure is not differentiable. An angle (or a
  distance) is a cone at zero error: it has no derivative there, and **its gradient at zero error
  is defined as 0** (the subgradient of least norm; central differences agree). A zero estimate has
  no direction: its angle is 90 degrees (as in :func:`ccjax.metrics.angular_error`) with gradient
  0, so a model that outputs black is not pushed anywhere by the loss, and no NaN ever appears;
* masked pixels in the mapping losses are replaced by zeros before anything is computed, so
  whatever a masked slot holds (even NaN or infinity) neither the loss nor its gradient sees it.

All losses are pure ``jnp`` functions: usable under ``jit``, ``vmap`` and ``grad``.
"""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from ccjax import metrics
from ccjax._colour import TINY

LOSSES = ("angular", "reproduction", "rg", "mapping_rg", "mapping_rgb")
"""Names accepted by :func:`illuminant_loss` and :func:`scene_loss`."""


def _has_direction(x: Float[Array, "... 3"]) -> Bool[Array, "..."]:
    # Only an exactly zero vector has no direction: any other one has a defined angle.
    return jnp.sum(x * x, axis=-1) > 0


def _directed(x: Float[Array, "... 3"]) -> tuple[Float[Array, "... 3"], Bool[Array, "..."]]:
    """``x`` with directionless (zero) vectors replaced by ``(1, 1, 1)`` and the mask of the real
    ones: the double-``where`` that keeps NaN out of the backward pass of ``atan2(0, 0)``."""
    ok = _has_direction(x)
    return jnp.where(ok[..., None], x, jnp.ones_like(x)), ok


ZERO_ERROR_EPS = 100
"""Errors below this many machine epsilons (radians for angles; the measure's units otherwise) are
zero error, where the gradient is 0. Rounding leaves ``|a x b|`` of parallel vectors at about one
epsilon, not exactly 0; without the band the gradient there would be the cone's slope from
whichever side rounding fell on, and finite differences (which see the symmetric cone) give 0."""


def _zero_error_band(errors: Float[Array, "..."], unit: float = 1.0) -> Float[Array, "..."]:
    """``errors`` unchanged, with gradient 0 where they are below :data:`ZERO_ERROR_EPS` epsilons."""
    tolerance = ZERO_ERROR_EPS * float(jnp.finfo(errors.dtype).eps) * unit
    return jnp.where(errors < tolerance, jax.lax.stop_gradient(errors), errors)


def _reduce(errors: Float[Array, "..."], weight: Float[ArrayLike, "..."] | None) -> Float[Array, ""]:
    if weight is None:
        return jnp.mean(errors)
    weight = jnp.broadcast_to(jnp.asarray(weight, errors.dtype), errors.shape)
    total = jnp.sum(weight)
    return jnp.sum(weight * errors) / jnp.where(total > 0, total, jnp.ones_like(total))


def _check_rgb(name: str, x) -> Array:
    x = jnp.asarray(x)
    if x.ndim < 1 or x.shape[-1] != 3:
        raise ValueError(f"{name}: expected an array of shape (..., 3), got shape {x.shape}")
    if not jnp.issubdtype(x.dtype, jnp.floating):
        raise ValueError(f"{name}: expected floating-point values, got dtype {x.dtype}")
    return x


def _angular_errors(estimate: Float[ArrayLike, "... 3"], truth: Float[ArrayLike, "... 3"]) -> Float[Array, "..."]:
    """Per-item angles of :func:`angular_loss`: :func:`ccjax.metrics.angular_error` with the loss's
    zero-error band, and 90 degrees with gradient 0 where either vector is zero."""
    estimate, truth = _check_rgb("estimate", estimate), _check_rgb("truth", truth)
    estimate, estimate_ok = _directed(estimate)
    truth, truth_ok = _directed(truth)
    angle = _zero_error_band(metrics.angular_error(estimate, truth), unit=180.0 / jnp.pi)
    return jnp.where(estimate_ok & truth_ok, angle, jnp.full_like(angle, 90.0))


def angular_errors(estimate: Float[ArrayLike, "... 3"], truth: Float[ArrayLike, "... 3"]) -> Float[Array, "..."]:
    """Deprecated alias of :func:`ccjax.metrics.angular_error` (the one per-item angular error);
    it warns and will be removed in the next release.

    It returns what it always did: the angles of :func:`ccjax.metrics.angular_error` (also
    gradient-safe at zero error), except 90 degrees where both vectors are zero.

    Arguments:
        estimate: ``(..., 3)`` estimated illuminant RGB.
        truth: ``(..., 3)`` true illuminant RGB.

    Returns:
        ``(...)`` angles in degrees.
    """
    warnings.warn(
        "ccjax.losses.angular_errors is deprecated: use ccjax.metrics.angular_error (per item) or "
        "ccjax.losses.angular_loss (the mean)",
        DeprecationWarning,
        stacklevel=2,
    )
    return _angular_errors(estimate, truth)


def angular_loss(
    estimate: Float[ArrayLike, "... 3"],
    truth: Float[ArrayLike, "... 3"],
    weight: Float[ArrayLike, "..."] | None = None,
) -> Float[Array, ""]:
    """Mean recovery angular error in degrees (thesis measure 1, §4.2) as a loss.

    Arguments:
        estimate: ``(..., 3)`` estimated illuminant RGB.
        truth: ``(..., 3)`` true illuminant RGB.
        weight: optional per-item weights (0 drops an item, e.g. a padded slot).

    Returns:
        The (weighted) mean angle; its gradient is finite everywhere and 0 at zero error.
    """
    return _reduce(_angular_errors(estimate, truth), weight)


def reproduction_errors(estimate: Float[ArrayLike, "... 3"], truth: Float[ArrayLike, "... 3"]) -> Float[Array, "..."]:
    """Per-item reproduction angular error in degrees (:func:`ccjax.metrics.reproduction_angular_error`)
    with safe gradients: the corrected white ``truth / estimate`` (0 in channels where the estimate
    is not positive, as the metric's diagonal map has it) is compared with ``(1, 1, 1)``; where the
    corrected white is zero the error is 90 degrees with gradient 0.

    Arguments:
        estimate: ``(..., 3)`` estimated illuminant RGBs.
        truth: ``(..., 3)`` true illuminant RGBs.

    Returns:
        ``(...)`` the errors in degrees.
    """
    estimate, truth = _check_rgb("estimate", estimate), _check_rgb("truth", truth)
    usable = jnp.any((estimate > TINY) & (truth != 0), axis=-1)
    safe_estimate = jnp.where(usable[..., None], estimate, jnp.ones_like(estimate))
    safe_truth = jnp.where(usable[..., None], truth, jnp.ones_like(truth))
    error = _zero_error_band(metrics.reproduction_angular_error(safe_estimate, safe_truth), unit=180.0 / jnp.pi)
    return jnp.where(usable, error, jnp.full_like(error, 90.0))


def reproduction_loss(
    estimate: Float[ArrayLike, "... 3"],
    truth: Float[ArrayLike, "... 3"],
    weight: Float[ArrayLike, "..."] | None = None,
) -> Float[Array, ""]:
    """Mean reproduction angular error (Finlayson & Zakizadeh 2014) in degrees as a loss.

    Arguments:
        estimate, truth: ``(..., 3)`` illuminant RGBs.
        weight: optional per-item weights.

    Returns:
        The (weighted) mean; gradient finite everywhere, 0 at zero error.
    """
    return _reduce(reproduction_errors(estimate, truth), weight)


def rg_loss(
    estimate: Float[ArrayLike, "... 3"],
    truth: Float[ArrayLike, "... 3"],
    weight: Float[ArrayLike, "..."] | None = None,
) -> Float[Array, ""]:
    """Mean (r,g) chromaticity distance (thesis measure 2, :func:`ccjax.metrics.rg_error`) as a loss.

    The distance's gradient is 0 at zero error (metrics' safe norm); a zero vector has the
    achromatic chromaticity (1/3, 1/3) (:func:`ccjax.metrics.rg`), so its gradient is 0 too.

    Arguments:
        estimate, truth: ``(..., 3)`` illuminant RGBs.
        weight: optional per-item weights.

    Returns:
        The (weighted) mean distance.
    """
    estimate, truth = _check_rgb("estimate", estimate), _check_rgb("truth", truth)
    return _reduce(_zero_error_band(metrics.rg_error(estimate, truth)), weight)


def mapping_loss(
    estimate: Float[ArrayLike, "... 3"],
    rgb: Float[ArrayLike, "... P 3"],
    mask: Bool[ArrayLike, "... P"],
    canonical_rgb: Float[ArrayLike, "... P 3"],
    canonical_white: Float[ArrayLike, "3"],
    *,
    space: str = "rgb",
    weight: Float[ArrayLike, "..."] | None = None,
) -> Float[Array, ""]:
    """Mean of the per-scene RMS mapping errors (thesis measures 5 and 6,
    :func:`ccjax.metrics.mapping_errors`) as a loss.

    Masked pixels are zeroed before the error is computed, so their content never reaches the loss
    or its gradient; a scene without valid pixels contributes 0. (Needed for sharpening through GW,
    whose chromaticity does not depend on the transform.)

    Arguments:
        estimate: ``(..., 3)`` estimated illuminants.
        rgb: ``(..., P, 3)`` the scene's surfaces under its light.
        mask: ``(..., P)`` True for valid surfaces.
        canonical_rgb: ``(..., P, 3)`` the same surfaces under the canonical light.
        canonical_white: ``(3,)`` RGB of white under the canonical light.
        space: ``"rgb"`` (RGB RMS, measure 6) or ``"rg"`` ((r,g) RMS, measure 5).
        weight: optional per-scene weights.

    Returns:
        The (weighted) mean RMS error.
    """
    if space not in ("rgb", "rg"):
        raise ValueError(f"space: expected 'rgb' or 'rg', got {space!r}")
    estimate = _check_rgb("estimate", estimate)
    rgb, canonical_rgb = _check_rgb("rgb", rgb), _check_rgb("canonical_rgb", canonical_rgb)
    mask = jnp.asarray(mask)
    if mask.shape != rgb.shape[:-1]:
        raise ValueError(f"mask: expected shape {rgb.shape[:-1]} (rgb without its last axis), got {mask.shape}")
    rgb = jnp.where(mask[..., None], rgb, jnp.zeros_like(rgb))
    canonical_rgb = jnp.where(mask[..., None], canonical_rgb, jnp.zeros_like(canonical_rgb))
    rg_rms, rgb_rms = metrics.mapping_errors(estimate, rgb, mask, canonical_rgb, canonical_white)
    return _reduce(_zero_error_band(rgb_rms if space == "rgb" else rg_rms), weight)


def illuminant_loss(
    name: str,
    estimate: Float[ArrayLike, "... 3"],
    truth: Float[ArrayLike, "... 3"],
    weight: Float[ArrayLike, "..."] | None = None,
) -> Float[Array, ""]:
    """The illuminant loss called ``name`` (``"angular"``, ``"reproduction"`` or ``"rg"``).

    Arguments:
        name: the loss.
        estimate, truth: ``(..., 3)`` illuminant RGBs.
        weight: optional per-item weights.

    Returns:
        The scalar loss.
    """
    losses = {"angular": angular_loss, "reproduction": reproduction_loss, "rg": rg_loss}
    if name not in losses:
        raise ValueError(f"loss: expected one of {tuple(losses)}, got {name!r}")
    return losses[name](estimate, truth, weight)


def scene_loss(
    model,
    scenes,
    name: str = "angular",
    *,
    canonical_white: Float[ArrayLike, "3"] | None = None,
    weight: Float[ArrayLike, " B"] | None = None,
) -> Float[Array, ""]:
    """Loss of a surface estimator over a scene batch: ``vmap(model)`` on ``scenes.rgb`` /
    ``scenes.mask``, then the loss ``name`` against ``scenes.illuminant`` (or, for the mapping
    losses, against ``scenes.canonical_rgb``).

    Arguments:
        model: a fitted surface estimator (any PyTree; differentiate with ``eqx.filter_grad``).
        scenes: a :class:`ccjax.scenes.Scenes` batch.
        name: one of :data:`LOSSES`.
        canonical_white: RGB of white under the canonical light (mapping losses only).
        weight: optional per-scene weights.

    Returns:
        The scalar loss.
    """
    if name not in LOSSES:
        raise ValueError(f"loss: expected one of {LOSSES}, got {name!r}")
    estimate = jax.vmap(model)(scenes.rgb, scenes.mask).illuminant
    if name.startswith("mapping"):
        if canonical_white is None:
            raise ValueError(f"canonical_white: required by the {name!r} loss")
        space = name.removeprefix("mapping_")
        return mapping_loss(
            estimate, scenes.rgb, scenes.mask, scenes.canonical_rgb, canonical_white, space=space, weight=weight
        )
    return illuminant_loss(name, estimate, scenes.illuminant, weight)
