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

1. *locate* (:func:`~ccjax.estimators.gamut._engine.locate`) on the region violation, from the
   model's domain of directions;
2. *fine*: ``T`` and the violations on a ``fine_points x fine_points`` grid over that box. ``1/T``
   reads, in each block of ``certificate_tile`` directions, only the forms a bound over the block
   cannot exclude (:func:`certified_inverse_extent`), with the same maximum at every valid
   direction. How many it excludes depends on the scene (median kept, thesis world, CRULE: 4 of
   3,744 forms in reduced 1,024-surface scenes, 807 of 2,496 at 64 surfaces, nearly all at 8; ND
   gamut, default world: 7,418 of 7,872 at 32 surfaces). Measured against reading every form
   (``certificate_tile=0``, the same estimates bitwise): CRULE-AVE 1.44x faster at 1,024
   surfaces and 1.1x at 64, ND-ECRULE-MV about 0.9x at 8 and 32 surfaces.

Scenes with many observations are first reduced to the observations that can matter: those
extreme in chromaticity for locating (only chromaticities decide feasibility), and for the fine
stage those that are the support point of the observed set in the direction ``n_k * v`` of some
facet ``k`` at sample directions across the box (every constraint is a support function). Both
reductions are a running maximum over the observations (:func:`forms_argmax`), so memory does not
grow with the number of observations (camera-sized images).
Observations are divided by the scene's scale first (constraints are scale-invariant, ``T``
scales with the scene), so no threshold is absolute. Selectors (``selectors.py``) are
reductions over the fine grid.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ccjax.estimators.gamut._engine import (
    OUTSIDE,
    GridOptions,
    binding_forms,
    cone_violation,
    directions,
    form,
    forms_argmax,
    locate,
    max_of_forms,
    square_grid,
    tile_boxes,
)

# Coefficients of a masked observation: origin pairs give -sum(v)/|v| <= -1 (below any real
# violation), top pairs give -1e20 sum(v) (never the largest constraint).
OFF_ORIGIN = -1.0
OFF_TOP = -1e20
# Small scenes of at least this many slots read only their usable observations (a sweep pads 4
# to 32 surfaces: ND-ECRULE-MV about 3.6x faster); with fewer, the counted loops' fixed cost
# outweighs what they skip (measured at 8 surfaces: ECRULE-MV and ECRULE-SCWIA-12 5-15 % slower
# counted).
COUNTED_SLOTS = 16
# Observations dimmer than this fraction of the scene's brightest do not constrain (relative, so
# the scene's scale does not matter).
RELATIVE_DARK = 1e-12


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
        count: MV's refinement reads only the first ``count`` of them (the others are masked),
            or all of them when ``None``.
        step: ``(2,)`` the fine grid's (r,g) step.
        exact: the fine stage ran on every observation, or the reduction of a large scene kept
            every support point it selected.
        usable: the scene has at least one usable observation.
        scale: the scene's scale the observations were divided by (``T`` and the selectors'
            illuminants are in those units).
    """

    rg: Float[Array, "G 2"]
    valid: Bool[Array, " G"]
    inverse_extent: Float[Array, " G"]
    surface: Float[Array, " G"]
    illuminant: Float[Array, " G"]
    cone: Float[Array, " G"]
    observations: Observations
    count: Int[Array, ""] | None
    step: Float[Array, "2"]
    exact: Bool[Array, ""]
    usable: Bool[Array, ""]
    scale: Float[Array, ""]


# ---------------------------------------------------------------------------------------------
# per-direction quantities


def surface_violation(
    v: Float[Array, "G 3"], obs: Observations, count: Int[Array, ""] | None = None
) -> Float[Array, " G"]:
    """``V_S``: the largest normalised origin-facet violation (<= -1 when nothing constrains).

    The normalisation ``|q_j * v|`` depends on the observation only, so each observation's
    maximum over its origin facets is scaled once (a positive factor commutes with the maximum,
    exactly so in floating point: rounding is monotone). With ``count``, only the first ``count``
    observations (at least one) are read: the others are masked and never bind."""
    xt = v.T
    squares = xt * xt

    def term(origin, scale):
        # The few origin facets unrolled (max_of_forms would pad 10 to 16 forms).
        worst = form(origin[0], xt)
        for k in range(1, origin.shape[0]):
            worst = jnp.maximum(worst, form(origin[k], xt))
        return worst * jax.lax.rsqrt(form(scale * scale, squares))

    start = jnp.full(xt.shape[1:], -jnp.inf, v.dtype)
    if count is None:
        best, _ = jax.lax.scan(lambda best, xs: (jnp.maximum(best, term(*xs)), None), start, (obs.origin, obs.scale))
        return best
    needed = jnp.clip(count, 1, obs.origin.shape[0]).astype(jnp.int32)

    def body(carry):
        index, best = carry
        origin = jax.lax.dynamic_index_in_dim(obs.origin, index, keepdims=False)
        scale = jax.lax.dynamic_index_in_dim(obs.scale, index, keepdims=False)
        return index + 1, jnp.maximum(best, term(origin, scale))

    _, best = jax.lax.while_loop(lambda carry: carry[0] < needed, body, (jnp.zeros((), jnp.int32), start))
    return best


def inverse_extent(
    v: Float[Array, "G 3"], obs: Observations, count: Int[Array, ""] | None = None
) -> Float[Array, " G"]:
    """``1/T``: the largest top-facet constraint along each ray (negative when none binds). With
    ``count``, only the first ``count`` observations' constraints are read (masked ones never
    bind)."""
    n_obs, k1, _ = obs.top.shape
    return max_of_forms(v, obs.top.reshape(n_obs * k1, 3), None if count is None else count * k1)


def certified_inverse_extent(
    v: Float[Array, "G 3"],
    valid: Bool[Array, " G"],
    obs: Observations,
    count: Int[Array, ""] | None,
    options: GridOptions,
) -> Float[Array, " G"]:
    """:func:`inverse_extent` on the fine grid, reading only the top-facet forms that can bind in
    some block of ``options.certificate_tile`` directions (:func:`~ccjax.estimators.gamut._engine.binding_forms`).

    At every valid direction the same form reaches the maximum, so the value is the same,
    bitwise; at invalid directions (which no selector reads) it may be smaller."""
    n, tile = options.fine_points, options.certificate_tile
    if tile <= 0 or n % tile:
        return inverse_extent(v, obs, count)
    n_obs, k1, _ = obs.top.shape
    coef = obs.top.reshape(n_obs * k1, 3)
    centre, half, occupied = tile_boxes(v, valid, n, tile)
    order, kept = binding_forms(coef, None if count is None else count * k1, centre, half, occupied)
    return max_of_forms(v, coef[order], kept)


def violations(
    model, v, valid, obs: Observations, count: Int[Array, ""] | None = None
) -> tuple[Array, Array, Array, Array]:
    """``(R, V_S, V_I, V_C)``; ``R`` is the violation of the region any selector may use (CRULE:
    ``V_S``; ECRULE: ``max(V_S, min(V_I, V_C))``), ``OUTSIDE`` outside the triangle. With
    ``count``, only the first ``count`` observations are read (the others are masked)."""
    surface = surface_violation(v, obs, count)
    illuminant = cone_violation(1.0 / v, model.illuminant_planes.astype(v.dtype))
    cone = cone_violation(v * model.white.astype(v.dtype), model.map_planes.astype(v.dtype))
    region = jnp.maximum(surface, jnp.minimum(illuminant, cone)) if model.constraint == "ECRULE" else surface
    return jnp.where(valid, region, OUTSIDE), surface, illuminant, cone


# ---------------------------------------------------------------------------------------------
# observations


def usable_observations(rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> tuple[Array, Array]:
    """The observations that constrain, and the scene's scale (the largest usable R+G+B).

    An observation is usable when masked in, finite, and its R+G+B is positive and above
    ``RELATIVE_DARK`` times the scene's largest: a threshold relative to the scene, so a scene
    scaled by any factor keeps the same observations (every constraint is scale-invariant).
    """
    total = jnp.sum(rgb, axis=-1)
    candidate = mask & jnp.isfinite(total) & jnp.all(jnp.isfinite(rgb), axis=-1) & (total > 0)
    scale = jnp.max(jnp.where(candidate, total, 0.0))
    return candidate & (total > RELATIVE_DARK * scale), scale


def coefficients(model, q: Float[Array, "P 3"], usable: Bool[Array, " P"]) -> Observations:
    """Constraint coefficients of observations ``q = p * w_C`` (masked ones never bind)."""
    dtype = q.dtype
    origin = model.origin_normals.astype(dtype)
    origin = origin / jnp.linalg.norm(origin, axis=-1, keepdims=True)
    top = (model.top_normals / model.top_offsets[:, None]).astype(dtype)
    on = usable[:, None, None]
    return Observations(
        origin=jnp.where(on, q[:, None, :] * origin[None], OFF_ORIGIN),
        scale=jnp.where(usable[:, None], q, 1.0),
        top=jnp.where(on, q[:, None, :] * top[None], OFF_TOP),
    )


def observations(model, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> tuple[Observations, Array, Array]:
    """Constraint coefficients of a scene's observations; also ``q = p * w_C`` and usability."""
    usable, _ = usable_observations(rgb, mask)
    q = jnp.where(usable[:, None], rgb * model.white.astype(rgb.dtype), 0.0)
    return coefficients(model, q, usable), q, usable


def _first_distinct(indices: Int[Array, " W"], usable: Bool[Array, " P"], slots: int) -> tuple[Array, Array, Array]:
    """The distinct usable observations among ``indices``, in index order, in ``slots`` slots.

    Returns:
        ``(index, keep, fitted)``: ``(slots,)`` indices (0 in unused slots), which slots hold one,
        and whether every distinct one found a slot.
    """
    ordered = jnp.sort(indices)
    first = jnp.concatenate([jnp.ones((1,), bool), ordered[1:] != ordered[:-1]]) & usable[ordered]
    slot = jnp.where(first, jnp.cumsum(first) - 1, slots)
    index = jnp.zeros((slots,), jnp.int32).at[slot].set(ordered, mode="drop")
    chosen = jnp.sum(first)
    return index, jnp.arange(slots) < chosen, chosen <= slots


def _chromaticity_extremes(q, usable, count: int) -> Int[Array, " M"]:
    """The observations extreme in (r,g) chromaticity in ``count`` directions (with repeats).

    Feasibility depends on observations only through their chromaticities, so observations
    inside the chromaticity hull of the others never matter for it; a hull vertex missed by the
    directions only enlarges the located region, which the later stages tighten.
    """
    angles = jnp.arange(count, dtype=q.dtype) * (2 * jnp.pi / count)
    axes = jnp.stack([jnp.cos(angles), jnp.sin(angles), jnp.zeros_like(angles)], axis=1).astype(q.dtype)
    chroma = q / jnp.maximum(jnp.sum(q, axis=-1, keepdims=True), 1e-30)
    none = jnp.zeros((0, 3), q.dtype)
    return forms_argmax(chroma, usable, none, none, axes)


def _support_index(model, q, usable, lo, hi, options: GridOptions) -> tuple[Array, Array, Array]:
    """The observations that are a support point of the observed set, in a facet's direction
    ``n_k * v`` (origin facets: after normalising by ``|q * v|``), at sample directions over the
    box (a running maximum over the observations); the first ``fine_observations`` of them in
    index order.

    Returns:
        ``(index, keep, exact)``: indices, which of them are support points, and whether all fitted.
    """
    rg, _ = square_grid(lo, hi, options.reduction_samples)
    _, v, valid = directions(rg)
    v = jnp.where(valid[:, None], v, 3.0)
    origin = model.origin_normals.astype(q.dtype)
    origin = origin / jnp.linalg.norm(origin, axis=-1, keepdims=True)
    top = (model.top_normals / model.top_offsets[:, None]).astype(q.dtype)

    # Every score is a length-3 form in the observation, q . (v_s * n_k) (origin facets divided by
    # |q * v_s|, whose square is (q * q) . (v_s * v_s)).
    origin_forms = (v[:, None, :] * origin[None]).reshape(-1, 3)  # (S * K0, 3)
    origin_squares = v * v  # (S, 3): one norm per sample direction
    top_forms = (v[:, None, :] * top[None]).reshape(-1, 3)  # (S * K1, 3)
    winners = forms_argmax(q, usable, origin_forms, origin_squares, top_forms)
    count = options.fine_observations if q.shape[0] <= options.large_scene else options.large_fine_observations
    return _first_distinct(winners, usable, count)


# ---------------------------------------------------------------------------------------------
# stages


def locate_box(
    model, obs: Observations | None, q, usable, options: GridOptions, count: Int[Array, ""] | None = None
) -> tuple[Array, Array]:
    """Stage 1: the engine's locating stage on the region violation, from the model's domain;
    scenes with many observations locate with the distinct ones extreme in chromaticity (``obs``
    is only read for scenes of at most ``locate_observations``).

    The extremes in ``locate_observations`` directions repeat (at most 13 distinct were measured
    in scenes of up to 1,024 surfaces), and the violation is a maximum over observations, so
    locating on the ``locate_distinct`` distinct ones gives the same box at a third of the cost."""
    if q.shape[0] <= options.locate_observations and obs is not None:
        few = obs
    else:
        count = None
        extremes = _chromaticity_extremes(q, usable, options.locate_observations)
        index, keep, _ = _first_distinct(extremes, usable, options.locate_distinct)
        few = coefficients(model, q[index], usable[index] & keep)

    def region(rg):
        _, v, valid = directions(rg)
        return violations(model, v, valid, few, count)[0]

    return locate(region, model.domain.astype(q.dtype), options)


def evaluate(model, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Grid:
    """Both stages for one scene: the fine grid every selector reads.

    The observations are divided by the scene's scale first (every constraint is
    scale-invariant and ``T`` scales with it; the selectors multiply it back), so a scene and the
    same scene times ``1e-12`` give the same answer up to that factor. Scenes of at most
    ``max(fine_observations, exact_scene)`` observations run the fine stage on all of them;
    larger ones on the support-point reduction, a running maximum over the observations (memory
    independent of their number). MV refines on at most ``fine_observations`` support points
    (``Grid.observations``). In small scenes of at least :data:`COUNTED_SLOTS` slots the usable
    observations are moved to the leading slots first and every stage reads only those, so
    masked slots (a sweep's padding) cost almost nothing.

    Arguments:
        model: a fitted :class:`~ccjax.estimators.gamut.GamutModel`.
        rgb: ``(P, 3)`` observed camera RGBs.
        mask: ``(P,)`` the valid ones.

    Returns:
        A :class:`Grid`: the fine grid of illuminant directions with each direction's constraint
        violation and its ``1/T`` terms, the observations MV refines on, the scene's scale, and the
        ``exact`` flag of the observation reduction — what every selector (``selectors.select``)
        turns into an estimate.
    """
    options: GridOptions = model.options
    rgb = jnp.asarray(rgb)
    if not jnp.issubdtype(rgb.dtype, jnp.floating):
        rgb = rgb.astype(jnp.float32)
    usable, scale = usable_observations(rgb, mask)
    scale = jnp.where(scale > 0, scale, 1.0)
    q = jnp.where(usable[:, None], (rgb / scale) * model.white.astype(rgb.dtype), 0.0)
    size = q.shape[0]
    exact_all = size <= max(options.fine_observations, options.exact_scene)
    small = exact_all or size <= options.locate_observations
    used = None
    if exact_all and size >= COUNTED_SLOTS:
        # The usable observations first, in their order: every loop below then reads only the
        # first `used` (the masked ones never bind: the same maxima, bitwise), so a scene padded
        # with masked-out surfaces costs about what it costs unpadded.
        first = jnp.argsort(~usable, stable=True)
        q, usable = q[first], usable[first]
        used = jnp.sum(usable, dtype=jnp.int32)
    everything = coefficients(model, q, usable) if small else None
    lo, hi = locate_box(model, everything, q, usable, options, used)
    # The reduction puts the support points in the leading slots, so the fine stage reads only
    # those (masked slots never bind: the same maxima, bitwise). On a reduced scene MV's
    # refinement keeps the full scan: for its 25 directions per step the loop's overhead
    # outweighs the few slots it would skip (measured 1.3x slower at 256 and 1,024 surfaces); on
    # a small one it reads the usable ones only (a scene padded from 4 to 32 slots: ND-ECRULE-MV
    # about 3.6x faster).
    kept = None
    if size > options.fine_observations:
        index, keep, exact = _support_index(model, q, usable, lo, hi, options)
        reduced = coefficients(model, q[index], usable[index] & keep)
        kept = jnp.sum(keep)
    else:
        exact, reduced = jnp.asarray(True), everything
    fine = everything if exact_all else reduced
    active = used if exact_all else kept
    assert fine is not None and reduced is not None
    exact = exact | exact_all
    rg, step = square_grid(lo, hi, options.fine_points)
    _, v, valid = directions(rg)
    inverse = certified_inverse_extent(v, valid, fine, active, options)
    surface = surface_violation(v, fine, active)
    illuminant = cone_violation(1.0 / v, model.illuminant_planes.astype(v.dtype))
    cone = cone_violation(v * model.white.astype(v.dtype), model.map_planes.astype(v.dtype))
    return Grid(
        rg=rg,
        valid=valid,
        inverse_extent=inverse,
        surface=surface,
        illuminant=illuminant,
        cone=cone,
        observations=reduced,
        count=used if reduced is everything else None,  # a reduced scene's MV keeps the full scan
        step=step,
        exact=exact,
        usable=jnp.any(usable),
        scale=scale,
    )
