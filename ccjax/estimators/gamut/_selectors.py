"""Solution selection from the fine direction grid: the masks, and dispatch to the selector modules
(:mod:`~ccjax.estimators.gamut._mv`, :mod:`~ccjax.estimators.gamut._average`,
:mod:`~ccjax.estimators.gamut._scwia`) (Barnard 1999 §4.5.3, §6.2).

Every selector reads the same per-direction quantities (``T(u)`` and the violations) and
differs only in the mask and the weights:

* MV: the feasible ``u`` maximising ``T^3 / (r g b)`` (the product ``d_r d_g d_b`` of the map on
  the ray's far end), refined by a pattern search below the grid step; ``e = u / T``.
* AVE / ICA: the centroid of the feasible set in map space, volume weights ``T^3 / (rgb)^2`` and
  centroid weights ``(3/4) m(u) T^4 / (rgb)^2``; ``e = w_C / centroid``.
* SCWIA-N: the average of feasible ``(r, g)`` with weights
  ``(T^3 prod(w_C) / (rgb))^(N/3) dOmega``, ``dOmega = dr dg / |u|^3``, in the log domain.
  Brightness (not reported by the thesis) is the same average of ``1/T`` (our default).

Masks: CRULE uses surface feasibility ``V_S <= eps``; ECRULE's MV, ICA and SCWIA add the exact
illumination constraint ``V_I <= eps``; ECRULE-AVE adds its convex approximation ``V_C <= eps``.
``eps`` is the first relaxation level at which the mask is non-empty.
"""

from __future__ import annotations

import functools

import jax.numpy as jnp
from jaxtyping import Array

from ccjax._colour import TINY
from ccjax.estimators.base import Estimate
from ccjax.estimators.gamut import _average, _mv, _scwia
from ccjax.estimators.gamut._constraints_3d import Grid
from ccjax.estimators.gamut._engine import OUTSIDE, directions
from ccjax.estimators.gamut._relaxation import relaxation_level, status_of
from ccjax.estimators.gamut._weights import hard_mask

SELECTORS = ("MV", "AVE", "ICA", "SCWIA")


def mask_violation(constraint: str, selector: str, surface, illuminant, cone):
    """The violation whose sub-level set is the selector's feasible set (see module docstring)."""
    if constraint == "CRULE":
        return surface
    if selector == "AVE":
        return jnp.maximum(surface, cone)
    return jnp.maximum(surface, illuminant)


def select(model, grid: Grid, selector: str, power: float = 12.0) -> Estimate:
    """Apply one selector to a scene's fine grid.

    Arguments:
        model: the fitted :class:`~ccjax.estimators.gamut.GamutModel`.
        grid: from :func:`~ccjax.estimators.gamut._constraints_3d.evaluate`.
        selector: ``"MV"``, ``"AVE"``, ``"ICA"`` (ECRULE) or ``"SCWIA"``.
        power: SCWIA's ``N``.

    Returns:
        The estimate with its status (``RELAXED`` with ``relaxation = eps`` when the constraints
        were relaxed; ``NO_DATA`` / ``EMPTY_SET`` with the average training illuminant when there
        were no usable observations / no level had a solution).
    """
    white = model.white.astype(grid.rg.dtype)
    bounded = grid.valid & (grid.inverse_extent > 0)
    violation = jnp.where(
        bounded, mask_violation(model.constraint, selector, grid.surface, grid.illuminant, grid.cone), OUTSIDE
    )
    level, failed = relaxation_level(jnp.min(violation), model.options.first_level, model.options.levels)
    feasible = violation <= level
    u, v, _ = directions(grid.rg)
    log_t = -jnp.log(jnp.where(bounded, grid.inverse_extent, 1.0))

    log_mask = hard_mask(feasible)
    if selector == "MV":
        illuminant = _mv.hard(
            model, grid, functools.partial(mask_violation, model.constraint, selector), level, feasible, log_t
        )
    elif selector in ("AVE", "ICA"):
        illuminant = _average.estimate(u, v, log_t, white, log_mask)
    elif selector == "SCWIA":
        illuminant = _scwia.estimate(u, log_t, jnp.where(bounded, grid.inverse_extent, 0.0), white, power, log_mask)
    else:
        raise ValueError(f"selector: expected one of {SELECTORS}, got {selector!r}")

    return finish(
        illuminant, grid.usable, ~failed & jnp.any(feasible), level, model.fallback.astype(grid.rg.dtype), grid.scale
    )


def finish(illuminant, usable, found, level, fallback, scale: Array | float = 1.0) -> Estimate:
    """The :class:`Estimate` of a selector's answer: ``fallback`` unless the scene had usable
    observations, a level with feasible directions and a finite, positive answer.

    Arguments:
        illuminant: the selector's answer in the units of observations divided by ``scale``
            (so the positivity test is relative to the scene, not an absolute threshold).
        scale: the scene's scale (:func:`~ccjax.estimators.gamut._constraints_3d.evaluate`).
    """
    found = found & usable & jnp.all(jnp.isfinite(illuminant)) & (jnp.sum(illuminant) > TINY)
    return Estimate(
        illuminant=jnp.where(found, jnp.nan_to_num(illuminant) * scale, fallback),
        status=status_of(usable, found, level),
        relaxation=jnp.where(found, level, 0.0).astype(fallback.dtype),
    )
