"""The 3-D constraint set (CRULE, ECRULE and their ND gamut): ray extents ``T(u)`` and violations on
the engine's grid of illuminant directions (Barnard 1999 §2.3.4, §4.5.3, §6.1).

Parametrisation (Barnard 1999 §4.5.3, §6.2, as an integral over illuminant directions): an illuminant
direction is its chromaticity
``u = (r, g, 1 - r - g)``; its diagonal maps are ``t * m(u)``, ``m(u) = w_C / u``. Writing
``q_j = p_j * w_C`` and ``v = 1 / u``, facet ``k`` constrains observation ``j`` along the ray by
``(n_k * q_j) . v``, so

* ``1 / T(u) = max over j and top facets k of (n_k * q_j / c_k) . v`` (a maximum of linear forms);
* surface feasibility is decided by the origin facets (``c_k = 0``) alone; their normalised
  violation ``V_S(u) = max over j, origin facets k of (n_k * q_j) . v / (|n_k| |q_j * v|)`` is the
  sine of how far the worst mapped colour lies outside the canonical chromaticity cone, and ``u``
  is feasible at relaxation level ``eps`` iff ``V_S(u) <= eps`` (a relaxation instead of an empty set);
* ECRULE's illumination constraint is ``V_I(u) = max_l n_l . u / |u| <= eps`` (cone of the
  training illuminants) and its convex approximation ``V_C(u) = max_l g_l . m / |m| <= eps``
  (cone of their map directions, used by ECRULE-AVE).

Stages, all with fixed shapes so the kernel jits and vmaps:

1. *locate* (:func:`~ccjax.estimators.gamut.engine.locate`) on the region violation, from the
   model's domain of directions;
2. *fine*: ``T`` and the violations on a ``fine_points x fine_points`` grid over that box.

Scenes with many observations are first reduced to the observations that can matter: those
extreme in chromaticity for locating (only chromaticities decide feasibility), and for the fine
stage those that are the support point of the observed set in the direction ``n_k * v`` of some
facet ``k`` at sample directions across the box (every constraint is a support function).
Selectors (``selectors.py``) are reductions over the fine grid.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ccjax.estimators.gamut.engine import OUTSIDE, GridOptions, cone_violation, directions, dot, locate, square_grid

# Coefficients of a masked observation: origin pairs give -sum(v)/|v| <= -1 (below any real
# violation), top pairs give -1e20 sum(v) (never the largest constraint).
OFF_ORIGIN = -1.0
OFF_TOP = -1e20


class Observations(eqx.Module):
    """A scene's observations as constraint coefficients along rays.

    Masked observations carry coefficients that never bind (``_OFF_*``), so the per-direction
    loops are plain fused multiply-add-and-max with no masking.

    Attributes:
        origin: ``(P, K0, 3)`` ``n_k * q_j`` for the origin facets (unit ``n_k``).
        scale: ``(P, 3)`` ``q_j`` (1 for masked ones), normalising origin violations.
        top: ``(P, K1, 3)`` ``n_k * q_j / c_k`` for the other facets.
    """

    origin: Float[Array, "P K0 3"]
    scale: Float[Array, "P 3"]
    top: Float[Array, "P K1 3"]

    def take(self, index) -> Observations:
        return Observations(origin=self.origin[index], scale=self.scale[index], top=self.top[index])


class Grid(eqx.Module):
    """Per-direction quantities on the fine grid of one scene (Barnard 1999 §4.5.3).

    Attributes:
        rg: ``(G, 2)`` direction chromaticities.
        valid: ``(G,)`` inside the chromaticity triangle.
        inverse_extent: ``(G,)`` ``1 / T(u)``.
        surface, illuminant, cone: ``(G,)`` ``V_S``, ``V_I``, ``V_C``.
        observations: the (reduced) observations, for refining MV between grid points.
        step: ``(2,)`` the fine grid's (r,g) step.
        exact: the observation reduction kept every observation it selected.
        usable: the scene has at least one usable observation.
    """

    rg: Float[Array, "G 2"]
    valid: Bool[Array, " G"]
    inverse_extent: Float[Array, " G"]
    surface: Float[Array, " G"]
    illuminant: Float[Array, " G"]
    cone: Float[Array, " G"]
    observations: Observations
    step: Float[Array, "2"]
    exact: Bool[Array, ""]
    usable: Bool[Array, ""]


# ---------------------------------------------------------------------------------------------
# per-direction quantities


def surface_violation(v: Float[Array, "G 3"], obs: Observations) -> Float[Array, " G"]:
    """``V_S``: the largest normalised origin-facet violation (<= -1 when nothing constrains)."""
    n_obs, k0, _ = obs.origin.shape
    scale = jnp.repeat(obs.scale, k0, axis=0)
    norm2 = dot(v * v, scale * scale)
    return jnp.max(dot(v, obs.origin.reshape(n_obs * k0, 3)) * jax.lax.rsqrt(norm2), axis=1)


def inverse_extent(v: Float[Array, "G 3"], obs: Observations) -> Float[Array, " G"]:
    """``1/T``: the largest top-facet constraint along each ray (negative when none binds)."""
    n_obs, k1, _ = obs.top.shape
    return jnp.max(dot(v, obs.top.reshape(n_obs * k1, 3)), axis=1)


def violations(model, v, valid, obs: Observations) -> tuple[Array, Array, Array, Array]:
    """``(R, V_S, V_I, V_C)``; ``R`` is the violation of the region any selector may use (CRULE:
    ``V_S``; ECRULE: ``max(V_S, min(V_I, V_C))``), ``OUTSIDE`` outside the triangle."""
    surface = surface_violation(v, obs)
    illuminant = cone_violation(1.0 / v, model.illuminant_planes.astype(v.dtype))
    cone = cone_violation(v * model.white.astype(v.dtype), model.map_planes.astype(v.dtype))
    region = jnp.maximum(surface, jnp.minimum(illuminant, cone)) if model.constraint == "ECRULE" else surface
    return jnp.where(valid, region, OUTSIDE), surface, illuminant, cone


# ---------------------------------------------------------------------------------------------
# observations


def observations(model, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> tuple[Observations, Array, Array]:
    """Constraint coefficients of a scene's observations; also ``q = p * w_C`` and usability."""
    dtype = rgb.dtype
    usable = mask & (jnp.sum(rgb, axis=-1) > 1e-12)
    q = jnp.where(usable[:, None], rgb * model.white.astype(dtype), 0.0)
    origin = model.origin_normals.astype(dtype)
    origin = origin / jnp.linalg.norm(origin, axis=-1, keepdims=True)
    top = (model.top_normals / model.top_offsets[:, None]).astype(dtype)
    on = usable[:, None, None]
    return (
        Observations(
            origin=jnp.where(on, q[:, None, :] * origin[None], OFF_ORIGIN),
            scale=jnp.where(usable[:, None], q, 1.0),
            top=jnp.where(on, q[:, None, :] * top[None], OFF_TOP),
        ),
        q,
        usable,
    )


def _chromaticity_extremes(obs: Observations, q, usable, count: int) -> Observations:
    """The observations extreme in (r,g) chromaticity in ``count`` directions (with repeats).

    Feasibility depends on observations only through their chromaticities, so observations
    inside the chromaticity hull of the others never matter for it; a hull vertex missed by the
    directions only enlarges the located region, which the later stages tighten.
    """
    chroma = q[:, :2] / jnp.maximum(jnp.sum(q, axis=-1, keepdims=True), 1e-30)
    angles = jnp.arange(count, dtype=q.dtype) * (2 * jnp.pi / count)
    axes = jnp.stack([jnp.cos(angles), jnp.sin(angles)], axis=1).astype(q.dtype)
    return obs.take(jnp.argmax(jnp.where(usable[:, None], chroma @ axes.T, -jnp.inf), axis=0))


def _support_observations(model, obs: Observations, q, usable, lo, hi, options: GridOptions):
    """The observations that are a support point of the observed set, in a facet's direction
    ``n_k * v`` (origin facets: after normalising by ``|q * v|``), at sample directions over the
    box; compacted to ``fine_observations`` (the flag says whether all fitted)."""
    rg, _ = square_grid(lo, hi, options.reduction_samples)
    _, v, valid = directions(rg)
    v = jnp.where(valid[:, None], v, 3.0)
    origin_scores = (
        jnp.einsum("pkc,sc->skp", obs.origin, v) / jnp.linalg.norm(q[None] * v[:, None], axis=-1)[:, None, :]
    )
    top_scores = jnp.einsum("pkc,sc->skp", obs.top, v)
    off = ~usable[None, None, :]
    winners = jnp.concatenate(
        [
            jnp.argmax(jnp.where(off, -jnp.inf, origin_scores), axis=-1).ravel(),
            jnp.argmax(jnp.where(off, -jnp.inf, top_scores), axis=-1).ravel(),
        ]
    )
    chosen = jnp.zeros(q.shape[0], bool).at[winners].set(True) & usable
    count = options.fine_observations if q.shape[0] <= options.large_scene else options.large_fine_observations
    index = jnp.argsort(~chosen, stable=True)[:count]
    keep = chosen[index]
    kept = obs.take(index)
    kept = Observations(
        origin=jnp.where(keep[:, None, None], kept.origin, OFF_ORIGIN),
        scale=jnp.where(keep[:, None], kept.scale, 1.0),
        top=jnp.where(keep[:, None, None], kept.top, OFF_TOP),
    )
    return kept, jnp.sum(chosen) <= count


# ---------------------------------------------------------------------------------------------
# stages


def locate_box(model, obs: Observations, q, usable, options: GridOptions) -> tuple[Array, Array]:
    """Stage 1: the engine's locating stage on the region violation, from the model's domain;
    scenes with many observations locate with the ones extreme in chromaticity."""
    few = (
        obs
        if q.shape[0] <= options.locate_observations
        else _chromaticity_extremes(obs, q, usable, options.locate_observations)
    )

    def region(rg):
        _, v, valid = directions(rg)
        return violations(model, v, valid, few)[0]

    return locate(region, model.domain.astype(q.dtype), options)


def evaluate(model, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Grid:
    """Both stages for one scene: the fine grid every selector reads.

    Arguments:
        model: a fitted :class:`~ccjax.estimators.gamut.GamutModel`.
        rgb: ``(P, 3)`` observed camera RGBs; ``mask``: ``(P,)`` valid ones.
    """
    options: GridOptions = model.options
    rgb = jnp.asarray(rgb)
    if not jnp.issubdtype(rgb.dtype, jnp.floating):
        rgb = rgb.astype(jnp.float32)
    obs, q, usable = observations(model, rgb, mask)
    lo, hi = locate_box(model, obs, q, usable, options)
    if q.shape[0] > options.fine_observations:
        obs, exact = _support_observations(model, obs, q, usable, lo, hi, options)
    else:
        exact = jnp.asarray(True)
    rg, step = square_grid(lo, hi, options.fine_points)
    _, v, valid = directions(rg)
    _, surface, illuminant, cone = violations(model, v, valid, obs)
    return Grid(
        rg=rg,
        valid=valid,
        inverse_extent=inverse_extent(v, obs),
        surface=surface,
        illuminant=illuminant,
        cone=cone,
        observations=obs,
        step=step,
        exact=exact,
        usable=jnp.any(usable),
    )
