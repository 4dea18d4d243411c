"""Error measures and summary statistics (Barnard 1999 §4.2).

Every error function works on single items and broadcasts over leading axes, so it is usable on
batches directly and inside ``jit``/``vmap``/``grad``. Gradients are safe at zero error (no
``sqrt(0)`` or ``arccos(1)`` singularities), so the angular error can be a training loss.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

# (r,g) chromaticity and its inverse have one implementation, in ccjax._colour; re-exported here,
# where they have always been public.
from ccjax._colour import TINY as _TINY
from ccjax._colour import rg as rg
from ccjax._colour import rg_to_rgb as rg_to_rgb
from ccjax.precision import scale_down


def _safe_norm(x: Float[Array, "... n"]) -> Float[Array, "..."]:
    squared = jnp.sum(x * x, axis=-1)
    positive = squared > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, squared, 1.0)), 0.0)


def _unit_scale(x: Float[Array, "... n"]) -> Float[Array, "... n"]:
    """``x`` divided by its largest ``|component|`` (zero vectors stay zero), so that products of
    components neither underflow nor overflow whatever the scale the caller uses. The scale is
    held out of the gradient: every measure it serves depends on direction only."""
    return scale_down(x, jnp.max(jnp.abs(x), axis=-1, keepdims=True))


def angular_error(estimate: Float[ArrayLike, "... 3"], truth: Float[ArrayLike, "... 3"]) -> Float[Array, "..."]:
    """Angle in degrees between two illuminant RGBs (thesis measure 1, Barnard 1999 §4.2).

    Computed as ``atan2(|a x b|, a . b)`` on each vector divided by its largest ``|component|``
    first, so any scale gives the same angle (a float32 product of two components under- or
    overflows beyond about 1e±19): accurate for small angles, with a finite gradient at zero
    error. A zero vector gives 90 degrees against a non-zero one (no direction agrees with it),
    and 0 against another zero vector.

    Arguments:
        estimate: ``(..., 3)`` estimated illuminant RGB, any scale.
        truth: ``(..., 3)`` true illuminant RGB, any scale.

    Returns:
        ``(...)`` angles in degrees, in ``[0, 180]``.
    """
    estimate, truth = _unit_scale(jnp.asarray(estimate)), _unit_scale(jnp.asarray(truth))
    zero_estimate, zero_truth = ~jnp.any(estimate != 0, axis=-1), ~jnp.any(truth != 0, axis=-1)
    cross = jnp.cross(estimate, truth)
    # atan2(0, 0) has no gradient: a zero vector's angle comes from the where below instead.
    dot = jnp.where(zero_estimate | zero_truth, 1.0, jnp.sum(estimate * truth, axis=-1))
    angle = jnp.degrees(jnp.arctan2(_safe_norm(cross), dot))
    return jnp.where(zero_estimate != zero_truth, jnp.asarray(90.0, angle.dtype), angle)


def rg_error(estimate: Float[ArrayLike, "... 3"], truth: Float[ArrayLike, "... 3"]) -> Float[Array, "..."]:
    """Euclidean distance of (r, g) chromaticities (thesis measure 2), computed on each light divided
    by its largest channel, so any scale gives the same distance.

    Arguments:
        estimate: ``(..., 3)`` estimated illuminant RGBs.
        truth: ``(..., 3)`` true illuminant RGBs.

    Returns:
        ``(...)`` the distances (the same at any scale of either light).
    """
    # Each light divided by its largest channel first: a chromaticity is scale-free, but its float32
    # division by R+G+B is not (the sum's reciprocal is subnormal above about 8.5e37 and flushed
    # to zero, which gave an error of 0 between [9e37, 0, 0] and [0, 9e37, 0]).
    estimate, truth = _unit_scale(jnp.asarray(estimate)), _unit_scale(jnp.asarray(truth))
    return _safe_norm(rg(estimate) - rg(truth))


def rgb_error(estimate: Float[ArrayLike, "... 3"], truth: Float[ArrayLike, "... 3"]) -> Float[Array, "..."]:
    """Euclidean RGB distance (thesis measure 3; meaningful for 3-D estimators).

    Arguments:
        estimate: ``(..., 3)`` estimated illuminant RGBs.
        truth: ``(..., 3)`` true illuminant RGBs.

    Returns:
        ``(...)`` the distances, in the units of the RGBs.
    """
    estimate, truth = jnp.asarray(estimate), jnp.asarray(truth)
    return _safe_norm(estimate - truth)


def brightness_error(estimate: Float[ArrayLike, "... 3"], truth: Float[ArrayLike, "... 3"]) -> Float[Array, "..."]:
    """Signed ``(R+G+B)`` of the estimate minus that of the truth (thesis measure 4; reported as RMS).

    Arguments:
        estimate: ``(..., 3)`` estimated illuminant RGBs.
        truth: ``(..., 3)`` true illuminant RGBs.

    Returns:
        ``(...)`` the signed differences.
    """
    estimate, truth = jnp.asarray(estimate), jnp.asarray(truth)
    return jnp.sum(estimate, axis=-1) - jnp.sum(truth, axis=-1)


def diagonal_map(estimate: Float[ArrayLike, "... 3"], canonical_white: Float[ArrayLike, "3"]) -> Float[Array, "... 3"]:
    """The diagonal map ``w_C / estimate`` taking the scene light to the canonical one (thesis §2.5).

    Arguments:
        estimate: ``(..., 3)`` estimated illuminant RGBs.
        canonical_white: ``(3,)`` the canonical light's white ``w_C``.

    Returns:
        ``(..., 3)`` the map's diagonal.
    """
    estimate, canonical_white = jnp.asarray(estimate), jnp.asarray(canonical_white)
    positive = estimate > _TINY
    return jnp.where(positive, canonical_white / jnp.where(positive, estimate, 1.0), 0.0)


def _masked_rms(values: Float[Array, "... P"], mask: Bool[Array, "... P"]) -> Float[Array, "..."]:
    total = jnp.sum(jnp.where(mask, values, 0.0), axis=-1)
    mean_square = total / jnp.maximum(jnp.sum(mask, axis=-1), 1).astype(total.dtype)
    positive = mean_square > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, mean_square, 1.0)), 0.0)


def mapping_errors(
    estimate: Float[ArrayLike, "... 3"],
    rgb: Float[ArrayLike, "... P 3"],
    mask: Bool[ArrayLike, "... P"],
    canonical_rgb: Float[ArrayLike, "... P 3"],
    canonical_white: Float[ArrayLike, "3"],
) -> tuple[Float[Array, "..."], Float[Array, "..."]]:
    """Scene mapping RMS errors, (r,g) and RGB (thesis measures 5 and 6).

    The scene's surfaces are mapped to the canonical light by ``diag(w_C / estimate)`` and compared
    with the same surfaces under the canonical light; per scene the root mean square over its valid
    surfaces of the (r,g) and of the RGB distances (Barnard 1999 §4.2).

    Arguments:
        estimate: ``(..., 3)`` estimated illuminant RGBs.
        rgb: ``(..., P, 3)`` the scenes' surfaces under the scene light.
        mask: ``(..., P)`` the valid surfaces.
        canonical_rgb: ``(..., P, 3)`` the same surfaces under the canonical light.
        canonical_white: ``(3,)`` the canonical light's white ``w_C``.

    Returns:
        ``(rg_rms, rgb_rms)``, each with the batch shape; 0 for a scene with no valid surface.
    """
    rgb, mask, canonical_rgb = jnp.asarray(rgb), jnp.asarray(mask), jnp.asarray(canonical_rgb)
    mapped = rgb * diagonal_map(estimate, canonical_white)[..., None, :]
    rg_sq = jnp.sum((rg(mapped) - rg(canonical_rgb)) ** 2, axis=-1)
    rgb_sq = jnp.sum((mapped - canonical_rgb) ** 2, axis=-1)
    return _masked_rms(rg_sq, mask), _masked_rms(rgb_sq, mask)


def reproduction_angular_error(
    estimate: Float[ArrayLike, "... 3"], truth: Float[ArrayLike, "... 3"]
) -> Float[Array, "..."]:
    """Reproduction angular error (Finlayson & Zakizadeh 2014): the angle between the white
    corrected by the estimate, ``truth / estimate``, and the achromatic ``(1, 1, 1)``.

    Arguments:
        estimate: ``(..., 3)`` estimated illuminant RGBs.
        truth: ``(..., 3)`` true illuminant RGBs.

    Returns:
        ``(...)`` the errors in degrees.
    """
    corrected = jnp.asarray(truth) * diagonal_map(estimate, jnp.ones(3))
    return angular_error(corrected, jnp.ones_like(corrected))


# ---------------------------------------------------------------------------------------------
# Summaries (NumPy: they run on collected per-scene errors, outside jit)

SUMMARIES = ("rms", "mean", "median", "trimean", "best25", "worst25", "p95", "max")


def summarise(errors, summary: str = "rms") -> float:
    """Summarise per-scene errors.

    Arguments:
        errors: 1-D array of per-scene errors (non-empty, finite).
        summary: ``rms`` (the thesis' aggregate, §4.2), ``mean``, ``median``, ``trimean``
            (``(Q1 + 2 Q2 + Q3) / 4``), ``best25`` / ``worst25`` (means of the lowest / highest
            quarter), ``p95`` (the 95th percentile, linear interpolation), ``max``.

    Returns:
        The summary, a Python float.
    """
    errors = np.asarray(errors, dtype=np.float64).ravel()
    if errors.size == 0:
        raise ValueError("errors: empty")
    if not np.all(np.isfinite(errors)):
        raise ValueError("errors: contains NaN or infinite values")
    if summary == "rms":
        return float(np.sqrt(np.mean(errors**2)))
    if summary == "mean":
        return float(np.mean(errors))
    if summary == "median":
        return float(np.median(errors))
    if summary == "p95":
        return float(np.percentile(errors, 95))
    if summary == "trimean":
        q1, q2, q3 = np.percentile(errors, [25, 50, 75])
        return float((q1 + 2 * q2 + q3) / 4)
    ordered = np.sort(errors)
    quarter = max(1, int(round(errors.size / 4)))
    if summary == "best25":
        return float(ordered[:quarter].mean())
    if summary == "worst25":
        return float(ordered[-quarter:].mean())
    if summary == "max":
        return float(ordered[-1])
    raise ValueError(f"summary: expected one of {SUMMARIES}, got {summary!r}")


FIELD_STATISTICS = ("mean", "median", "trimean", "best25", "worst25", "p95", "max")
"""The statistics colour-constancy papers report for an image set (the thesis' RMS aside)."""

_BOOTSTRAPPED = {"mean": np.mean, "median": np.median}


def bootstrap_interval(
    errors, summary: str = "mean", *, level: float = 0.95, resamples: int = 2000, seed: int = 0
) -> tuple[float, float]:
    """Bootstrap confidence interval of the mean or median of per-image errors.

    The bias-corrected and accelerated (BCa) percentile interval (Efron 1987; Efron & Tibshirani,
    *An Introduction to the Bootstrap*, 1993, §14.3), computed by ``scipy.stats.bootstrap``: the
    plain percentile interval undercovers for skewed data such as angular errors, BCa corrects
    its median bias and its skewness (the jackknife acceleration). The resampling is seeded, so a
    report is reproducible.

    Arguments:
        errors: 1-D per-image errors (non-empty, finite).
        summary: ``"mean"`` or ``"median"``.
        level: the coverage, in (0, 1).
        resamples: bootstrap resamples (at least 100).
        seed: seed of the resampling.

    Returns:
        ``(low, high)``; ``(x, x)`` for a single error or identical errors.
    """
    from scipy import stats

    if summary not in _BOOTSTRAPPED:
        raise ValueError(f"summary: expected one of {tuple(_BOOTSTRAPPED)}, got {summary!r}")
    if not 0 < level < 1:
        raise ValueError(f"level: expected a coverage in (0, 1), got {level!r}")
    if int(resamples) != resamples or resamples < 100:
        raise ValueError(f"resamples: expected an integer of at least 100, got {resamples!r}")
    errors = np.asarray(errors, dtype=np.float64).ravel()
    observed = summarise(errors, summary)  # validates: non-empty, finite
    if np.all(errors == errors[0]):
        return observed, observed
    result = stats.bootstrap(
        (errors,),
        _BOOTSTRAPPED[summary],
        n_resamples=int(resamples),
        # Resamples (and jackknife samples) in batches of at most ~4 million values: bounded
        # memory on large image sets.
        batch=max(1, 4_000_000 // errors.size),
        vectorized=True,
        confidence_level=level,
        method="BCa",
        rng=np.random.default_rng(seed),
    ).confidence_interval
    low, high = float(result.low), float(result.high)
    if not (np.isfinite(low) and np.isfinite(high)):
        # SciPy gives NaN where the bootstrap distribution is degenerate (two distinct errors,
        # every resample on one side): the observed value is then the honest interval.
        return observed, observed
    return low, high


def error_statistics(errors, *, level: float = 0.95, resamples: int = 2000, seed: int = 0) -> dict[str, float]:
    """The field's summary of per-image errors, with bootstrap intervals for mean and median.

    Arguments:
        errors: 1-D per-image errors (non-empty, finite).
        level, resamples, seed: see :func:`bootstrap_interval`.

    Returns:
        ``{"mean", "median", "trimean", "best25", "worst25", "p95", "max"}`` (:func:`summarise`)
        and ``"mean_low"``, ``"mean_high"``, ``"median_low"``, ``"median_high"`` (the intervals).
    """
    row = {name: summarise(errors, name) for name in FIELD_STATISTICS}
    for summary in _BOOTSTRAPPED:
        low, high = bootstrap_interval(errors, summary, level=level, resamples=resamples, seed=seed)
        row[f"{summary}_low"], row[f"{summary}_high"] = low, high
    return row
