"""Differentiable gamut mapping (soft feasibility and soft selectors, so gradients reach the RGB and the gamut facets).

The hard selectors have zero or undefined gradients: ``T(u)`` is a minimum over constraints and
feasibility is an indicator. Here every non-smooth step gets a temperature:

* ``1/T`` is a soft maximum of the top-facet constraint values ``d``: their ``1/tau``-norm
  ``(sum max(d, 0)^(1/tau))^tau`` (a relative temperature);
* the surface violation is a soft maximum with width ``kappa`` (sine units) and feasibility is
  ``sigmoid((eps - V)/kappa)`` (ECRULE multiplies the illumination constraint's sigmoid);
* the selectors are the modules' soft forms: MV a softmax over directions with inverse
  temperature ``beta`` on ``log(T^3/(rgb))`` (:func:`~ccjax.estimators.gamut._mv.soft`); AVE, ICA and
  SCWIA are weighted averages that take the soft mask as their log-mask.

Gradients reach the input RGB and the model's arrays (canonical gamut facets, white). The grid
box comes from the hard locating stage under ``stop_gradient`` (it is piecewise constant in the
input), widened by ``margin`` so the soft mask has decayed at its edges.
"""

from __future__ import annotations

import typing

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ccjax.estimators.base import Estimate
from ccjax.estimators.gamut import _average, _mv, _scwia
from ccjax.estimators.gamut._constraints_3d import locate_box, observations, usable_observations
from ccjax.estimators.gamut._engine import OUTSIDE, cone_violation, directions, dot, square_grid
from ccjax.estimators.gamut._model import AbstractGamutMapEstimator, GamutModel
from ccjax.estimators.gamut._relaxation import relaxation_level
from ccjax.estimators.gamut._selectors import SELECTORS, finish, mask_violation


def _soft_max(values: Float[Array, "G M"], temperature) -> Float[Array, " G"]:
    top = jax.lax.stop_gradient(jnp.max(values, axis=1, keepdims=True))
    return top[:, 0] + temperature * jnp.log(jnp.sum(jnp.exp((values - top) / temperature), axis=1))


@typing.final
class SoftGamutMapping(AbstractGamutMapEstimator):
    """A gamut-mapping selector with soft feasibility and soft selection.

    Attributes:
        model: the fitted model (its arrays receive gradients).
        selector: ``"MV"``, ``"AVE"``, ``"ICA"`` or ``"SCWIA"``; ``power``: SCWIA's N.
        tau: relative temperature of the soft minimum giving ``T``.
        kappa: width (sine units) of the soft feasibility and of the soft maximum of violations.
        beta: inverse temperature of soft MV on log-volume.
        margin: (r,g) widening of the hard box the grid covers.
    """

    model: GamutModel
    selector: str = eqx.field(static=True)
    power: float = eqx.field(static=True, default=12.0)
    tau: float = eqx.field(static=True, default=0.01)
    kappa: float = eqx.field(static=True, default=0.002)
    beta: float = eqx.field(static=True, default=200.0)
    margin: float = eqx.field(static=True, default=0.02)

    def block_size(self, backend: str) -> int | None:
        """One ``vmap`` over the whole batch on every backend.

        Arguments:
            backend: ``"cpu"``, ``"gpu"`` or ``"tpu"`` (not used).

        Returns:
            ``None``.
        """
        return None

    def __check_init__(self):
        if self.selector not in SELECTORS:
            raise ValueError(f"selector: expected one of {SELECTORS}, got {self.selector!r}")
        if self.selector == "ICA" and self.model.constraint != "ECRULE":
            raise ValueError("selector: ICA needs constraint='ECRULE'")
        for name in ("tau", "kappa", "beta"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: expected a positive temperature parameter, got {getattr(self, name)!r}")

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        model, options = self.model, self.model.options
        rgb = jnp.asarray(rgb)
        # Scale-free: the estimate is homogeneous in the scene, so work on it divided by its scale.
        _, scene_scale = usable_observations(rgb, mask)
        scene_scale = jnp.where(scene_scale > 0, scene_scale, 1.0)
        rgb = rgb / scene_scale
        obs, q, usable = observations(model, rgb, mask)
        lo, hi = jax.lax.stop_gradient(locate_box(model, obs, q, usable, options))
        rg, _ = square_grid(lo - self.margin, hi + self.margin, options.fine_points)
        u, v, valid = directions(rg)
        dtype = rgb.dtype

        n_obs, k0, _ = obs.origin.shape
        scale = jnp.repeat(obs.scale, k0, axis=0)
        ratio = dot(v, obs.origin.reshape(n_obs * k0, 3)) * jax.lax.rsqrt(dot(v * v, scale * scale))
        surface = _soft_max(ratio, self.kappa)
        # 1/T as a p-norm (p = 1/tau) of the positive constraint values: a soft maximum with a
        # relative temperature; the hard maximum only rescales it (homogeneity), so stopping its
        # gradient changes nothing.
        top = dot(v, obs.top.reshape(-1, 3))
        hard = jax.lax.stop_gradient(jnp.maximum(jnp.max(top, axis=1, keepdims=True), 1e-30))
        ratio_top = jnp.maximum(top, 0.0) / hard
        inverse = hard[:, 0] * jnp.sum(ratio_top ** (1.0 / self.tau), axis=1) ** self.tau
        illuminant = cone_violation(u, model.illuminant_planes.astype(dtype))
        cone = cone_violation(v * model.white.astype(dtype), model.map_planes.astype(dtype))
        violation = mask_violation(model.constraint, self.selector, surface, illuminant, cone)

        bounded = valid & (inverse > 0)
        violation = jnp.where(bounded, violation, OUTSIDE)
        level, failed = relaxation_level(jax.lax.stop_gradient(jnp.min(violation)), options.first_level, options.levels)
        log_mask = jax.nn.log_sigmoid((level - violation) / self.kappa)
        log_mask = jnp.where(bounded, log_mask, -jnp.inf)
        log_t = -jnp.log(jnp.where(bounded, inverse, 1.0))
        white = model.white.astype(dtype)

        inverse = jnp.where(bounded, inverse, 0.0)
        if self.selector == "MV":
            estimate = _mv.soft(u, log_t, inverse, log_mask, self.beta)
        elif self.selector in ("AVE", "ICA"):
            estimate = _average.estimate(u, v, log_t, white, log_mask)
        else:
            estimate = _scwia.estimate(u, log_t, inverse, white, self.power, log_mask)
        return finish(estimate, jnp.any(usable), ~failed, level, model.fallback.astype(dtype), scene_scale)
