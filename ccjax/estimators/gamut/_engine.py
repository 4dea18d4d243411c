"""The illuminant-direction engine shared by every gamut-mapping family (Barnard 1999 §2.3.4,
§4.5.3).

An illuminant direction is its chromaticity ``u = (r, g, 1 - r - g)``, its diagonal maps are
``t * m(u)`` with ``m(u) = w_C / u``. A family is a *constraint set*: a function giving, for a
list of directions, the normalised violation (a sine, ``<= 0`` where feasible) of the region its
selectors use; 3-D families (CRULE, ECRULE, ND) also bound each ray by ``T(u)``. The engine owns
what every family shares:

* the direction grids (:func:`directions`, :func:`square_grid`) and their edge threshold;
* the locating stage (:func:`locate`): a few square grids, each over the box the previous one
  found, around the feasible region at the first relaxation level that has feasible directions;
* the cones through the origin (:func:`cone_violation`), for illumination constraints;
* the pattern search that refines MV below the grid step (:func:`pattern_search`).

The relaxation ladder is :mod:`ccjax.estimators.gamut._relaxation`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ccjax.estimators.gamut import _relaxation
from ccjax.estimators.gamut._relaxation import relaxation_level

# Directions closer than this to the edge of the chromaticity triangle are never evaluated.
EDGE = 1e-4
# Violation value of directions outside the chromaticity triangle (a sine is <= 1); above every
# relaxation level.
OUTSIDE = 4.0

Violation = Callable[[Float[Array, "G 2"]], Float[Array, " G"]]


@dataclass(frozen=True)
class GridOptions:
    """Static sizes of the direction grids (hashable; part of the jit cache key).

    Attributes:
        locate_points, locate_iterations: the locating stage evaluates ``locate_points^2``
            directions per iteration, each over the box the previous one found.
        locate_safety: 0, or the factor on the first-order bound of the violation inside a
            locating cell (a cell counts as feasible when its bound is; catches thin feasible
            slivers that pass between the cell centres of a single coarse pass).
        clip_to_domain: keep the located box inside the domain (for domains that bound the
            feasible set, such as CIP's illumination-constraint box; CRULE's domain is the
            whole triangle, whose edges the direction validity already handles).
        fine_points: per-axis points of the fine grid (``fine_points^2`` directions).
        refine_steps: iterations of the MV pattern search (it starts at half a fine step).
        refine_scales: the stencil spacings each iteration tries at once, relative to the
            current one (:func:`pattern_search`). Measured against the classic search (24 steps
            of one spacing) on 200 CRULE scenes at 4, 8 and 64 surfaces: the median shortfall of
            the map volume from the exact optimum fell from 6.5e-5 / 4.9e-5 / 2.8e-5 to
            1.5e-5 / 1.1e-5 / 0.9e-5 with half the sequential steps and 4 % fewer evaluations.
        locate_observations: scenes with more observations locate with the extreme
            chromaticities in this many directions (with repeats).
        locate_distinct: slots for those extremes once repeats are removed (the 48 directions
            find at most 13 distinct extremes in measured scenes of up to 1,024 surfaces; more
            are dropped in index order, which can only widen the located box).
        fine_observations: observations kept for the fine stage when a scene has more (at most
            about 25 are support points at 64 surfaces);
        large_scene, large_fine_observations: the budget for scenes of more than ``large_scene``
            observations (at most about 43 at 1024 surfaces with the ND gamut).
        reduction_samples: per-axis sample directions used to pick those observations.
        certificate_tile: the fine stage's ``1/T`` reads, in each ``certificate_tile`` square
            block of the fine grid, only the top-facet forms a bound cannot exclude there
            (:func:`binding_forms`; the same maxima at every valid direction, bitwise); 0, or a
            size that does not divide ``fine_points``: every form at every direction.
        exact_scene: scenes of at most this many observations run the fine stage on all of them
            (the unreduced engine, exact at every relaxation level; 0: only those of at most
            ``fine_observations``).
        first_level, levels: relaxation levels ``first_level * 2^i``, ``i < levels``.
    """

    locate_points: int = 16
    locate_iterations: int = 4
    locate_safety: float = 0.0
    clip_to_domain: bool = False
    fine_points: int = 45
    refine_steps: int = 12
    refine_scales: tuple[float, ...] = (0.5, 2.0)
    locate_observations: int = 48
    locate_distinct: int = 16
    fine_observations: int = 32
    large_scene: int = 128
    large_fine_observations: int = 48
    reduction_samples: int = 5
    certificate_tile: int = 9
    exact_scene: int = 0
    first_level: float = _relaxation.FIRST_LEVEL
    levels: int = _relaxation.LEVELS

    def budgets(self) -> tuple[int, ...]:
        """The observation counts at which the engine takes another Python branch: padding a scene
        across one of them changes its path.

        Returns:
            The counts, sorted, the unset ones left out.
        """
        limits = (self.fine_observations, self.locate_observations, self.large_scene, self.exact_scene)
        return tuple(sorted({limit for limit in limits if limit > 0}))


# ---------------------------------------------------------------------------------------------
# direction grids


def directions(rg: Float[Array, "G 2"]) -> tuple[Float[Array, "G 3"], Float[Array, "G 3"], Bool[Array, " G"]]:
    """``u`` (with out-of-triangle directions replaced by the centre), ``v = 1/u`` and validity."""
    u = jnp.concatenate([rg, 1.0 - jnp.sum(rg, axis=-1, keepdims=True)], axis=-1)
    valid = jnp.all(u > EDGE, axis=-1)
    u = jnp.where(valid[..., None], u, 1.0 / 3.0)
    return u, 1.0 / u, valid


def square_grid(lo: Float[Array, "2"], hi: Float[Array, "2"], n: int) -> tuple[Float[Array, "G 2"], Float[Array, "2"]]:
    """Cell centres of an ``n x n`` grid over the (r,g) box ``[lo, hi]`` (r-major), and its step."""
    step = (hi - lo) / n
    offsets = jnp.arange(n, dtype=lo.dtype) + 0.5
    rr, gg = jnp.meshgrid(lo[0] + offsets * step[0], lo[1] + offsets * step[1], indexing="ij")
    return jnp.stack([rr.ravel(), gg.ravel()], axis=1), step


def box_of(points: Float[Array, "G 2"], steps, selected: Bool[Array, " G"]) -> tuple[Array, Array]:
    """The box of the selected points, widened by ``steps``."""
    lo = jnp.min(jnp.where(selected[:, None], points - steps, jnp.inf), axis=0)
    hi = jnp.max(jnp.where(selected[:, None], points + steps, -jnp.inf), axis=0)
    return lo, hi


# ---------------------------------------------------------------------------------------------
# length-3 inner products as fused multiply-adds


def dot(v: Float[Array, "G 3"], coef: Float[Array, "M 3"]) -> Float[Array, "G M"]:
    """``v_g . coef_m`` for every pair, written out so XLA fuses it into the reduction that
    follows (a K=3 matmul would materialise ``(G, M)``; a ``(G, P, K)`` layout compiles to slow
    loops)."""
    return v[:, None, 0] * coef[None, :, 0] + v[:, None, 1] * coef[None, :, 1] + v[:, None, 2] * coef[None, :, 2]


def form(coef: Float[Array, "3"], xt: Float[Array, "3 G"]) -> Float[Array, " G"]:
    """``coef . x_g`` for every column of ``xt`` (directions as the minor, vectorised axis), as
    three fused multiply-adds."""
    return coef[0] * xt[0] + coef[1] * xt[1] + coef[2] * xt[2]


# Linear forms per step of :func:`max_of_forms` (8 and 16 measured alike; 8 compiles faster).
FORMS_PER_STEP = 8


def max_of_forms(
    v: Float[Array, "G 3"], coef: Float[Array, "M 3"], count: Int[Array, ""] | None = None
) -> Float[Array, " G"]:
    """``max_m v_g . coef_m`` for every direction, as a running maximum over steps of
    :data:`FORMS_PER_STEP` forms with the directions as the minor (vectorised) axis.

    The same maximum as ``jnp.max(dot(v, coef), axis=1)`` (up to the fused multiply-adds' rounding)
    at about 4x its speed: XLA CPU reduces the ``(G, M)`` layout along its minor axis with slow
    horizontal steps, and materialises blocks of it; here each step is 16 plain FMA-and-max vector
    passes over ``G`` kept in registers. ``coef`` is padded with copies of its last row, which
    change no maximum.

    With ``count``, only the first ``count`` forms (at least one step) are read, in a loop whose
    trip count follows it (under ``vmap``, the largest of the batch): for form lists whose
    leading rows are the only ones that can bind."""
    total = coef.shape[0]
    steps = -(-total // FORMS_PER_STEP)
    coef = jnp.concatenate([coef, jnp.broadcast_to(coef[-1:], (steps * FORMS_PER_STEP - total, 3))])
    blocks = coef.reshape(steps, FORMS_PER_STEP, 3)
    xt = v.T

    def accumulate(best: Array, block: Array) -> Array:
        for row in range(FORMS_PER_STEP):
            best = jnp.maximum(best, form(block[row], xt))
        return best

    def step(best: Array, block: Array) -> tuple[Array, None]:
        return accumulate(best, block), None

    start = jnp.full(xt.shape[1:], -jnp.inf, v.dtype)
    if count is None:
        best, _ = jax.lax.scan(step, start, blocks)
        return best
    needed = jnp.clip(-(-count // FORMS_PER_STEP), 1, steps).astype(jnp.int32)

    def body(carry):
        index, best = carry
        return index + 1, accumulate(best, jax.lax.dynamic_index_in_dim(blocks, index, keepdims=False))

    _, best = jax.lax.while_loop(lambda carry: carry[0] < needed, body, (jnp.zeros((), jnp.int32), start))
    return best


# Observations per step of `forms_argmax`'s loop (unrolled in its body; 8 measured 1.2x faster
# than 4 at 1,024 surfaces, 16 only 1.05x more for a longer compile).
OBSERVATIONS_PER_STEP = 8


def forms_argmax(
    q: Float[Array, "P 3"],
    usable: Bool[Array, " P"],
    origin_forms: Float[Array, "W0 3"],
    origin_squares: Float[Array, "S 3"],
    top_forms: Float[Array, "W1 3"],
    count: Int[Array, ""] | None = None,
) -> Int[Array, " W"]:
    """For every form, the first usable observation maximising it: ``argmax_j`` of
    ``(q_j . f) / sqrt((q_j * q_j) . s)`` for the origin forms ``f`` and of ``q_j . f`` for the
    top forms, concatenated. The origin forms come in ``S`` equal groups, group ``i`` normalised
    by ``origin_squares[i]`` (one norm per group and observation, not per form).

    A running maximum over the observations with the forms as the minor (vectorised) axis: each
    step is a few fused multiply-adds and selects per form, with no ``(observations, forms)``
    array (memory O(forms) whatever the number of observations) and no separate pass for the
    index (a strict ``>`` in index order keeps the first maximum, as ``argmax`` does). With
    ``count``, only the first ``count`` observations are read (the others must be unusable), in a
    loop whose trip count follows it (under ``vmap``, the largest of the batch)."""
    total = q.shape[0]
    steps = -(-total // OBSERVATIONS_PER_STEP)
    pad = steps * OBSERVATIONS_PER_STEP - total
    qs = jnp.pad(q, ((0, pad), (0, 0))).reshape(steps, OBSERVATIONS_PER_STEP, 3)
    us = jnp.pad(usable, (0, pad)).reshape(steps, OBSERVATIONS_PER_STEP)
    n_origin, n_top, groups = origin_forms.shape[0], top_forms.shape[0], origin_squares.shape[0]
    if groups and n_origin % groups:
        raise ValueError(f"origin_forms: {n_origin} forms do not split into {groups} groups")
    origin_t, squares_t, top_t = origin_forms.T, origin_squares.T, top_forms.T

    def step(carry, xs):
        origin_best, origin_index, top_best, top_index = carry
        first, qb, ub = xs
        for row in range(OBSERVATIONS_PER_STEP):
            qj, index = qb[row], first + row
            if n_origin:
                norms = jax.lax.rsqrt(form(qj * qj, squares_t))
                origin_score = (form(qj, origin_t).reshape(groups, -1) * norms[:, None]).reshape(-1)
                better = ub[row] & (origin_score > origin_best)
                origin_best = jnp.where(better, origin_score, origin_best)
                origin_index = jnp.where(better, index, origin_index)
            top_score = form(qj, top_t)
            better = ub[row] & (top_score > top_best)
            top_best = jnp.where(better, top_score, top_best)
            top_index = jnp.where(better, index, top_index)
        return (origin_best, origin_index, top_best, top_index), None

    start = (
        jnp.full((n_origin,), -jnp.inf, q.dtype),
        jnp.zeros((n_origin,), jnp.int32),
        jnp.full((n_top,), -jnp.inf, q.dtype),
        jnp.zeros((n_top,), jnp.int32),
    )
    firsts = jnp.arange(steps, dtype=jnp.int32) * OBSERVATIONS_PER_STEP
    if count is None:
        (_, origin_index, _, top_index), _ = jax.lax.scan(step, start, (firsts, qs, us))
        return jnp.concatenate([origin_index, top_index])
    needed = jnp.clip(-(-count // OBSERVATIONS_PER_STEP), 1, steps).astype(jnp.int32)

    def body(carry):
        index, state = carry
        xs = (firsts[index], qs[index], us[index])
        return index + 1, step(state, xs)[0]

    _, (_, origin_index, _, top_index) = jax.lax.while_loop(
        lambda carry: carry[0] < needed, body, (jnp.zeros((), jnp.int32), start)
    )
    return jnp.concatenate([origin_index, top_index])


# Relative slack of the tile certificate: a form is dropped from a tile only when its bound
# there is below the tile's winner by more than this fraction of the two forms' magnitudes
# (float32 rounding of a 3-term form is ~2e-7 of it, so rounding cannot flip a dropped form
# above the maximum).
CERTIFICATE_SLACK = 2e-6


def tile_boxes(
    v: Float[Array, "G 3"], valid: Bool[Array, " G"], n: int, tile: int
) -> tuple[Float[Array, "T 3"], Float[Array, "T 3"], Bool[Array, " T"]]:
    """The componentwise box of the valid directions in each ``tile x tile`` block of an
    ``n x n`` r-major grid: ``(centre, half width, has a valid direction)``."""
    blocks = n // tile
    shaped = v.reshape(blocks, tile, blocks, tile, 3).transpose(0, 2, 1, 3, 4).reshape(blocks * blocks, tile * tile, 3)
    inside = valid.reshape(blocks, tile, blocks, tile).transpose(0, 2, 1, 3).reshape(blocks * blocks, tile * tile, 1)
    low = jnp.min(jnp.where(inside, shaped, jnp.inf), axis=1)
    high = jnp.max(jnp.where(inside, shaped, -jnp.inf), axis=1)
    occupied = jnp.any(inside[..., 0], axis=1)
    low, high = jnp.where(occupied[:, None], low, 1.0), jnp.where(occupied[:, None], high, 1.0)
    return 0.5 * (low + high), 0.5 * (high - low), occupied


def binding_forms(
    coef: Float[Array, "M 3"],
    count: Int[Array, ""] | None,
    centre: Float[Array, "T 3"],
    half: Float[Array, "T 3"],
    occupied: Bool[Array, " T"],
) -> tuple[Int[Array, " M"], Int[Array, ""]]:
    """The forms that can be the maximum somewhere in a box, in their leading slots.

    In each box the form largest at its centre, ``f*``, is kept; another form ``f`` is dropped
    when ``(f - f*) . x < 0`` everywhere in the box, certified by the bound
    ``(f - f*) . c + |f - f*| . h`` (centre ``c``, half widths ``h``) being below
    ``-CERTIFICATE_SLACK`` times their magnitudes. A form kept in any box is kept. So at every
    direction in a box the maximum over the kept forms is the maximum over all of them (the same
    form reaches it, so the same value, bitwise). With ``count``, only the first ``count`` forms
    are candidates (the others never bind).

    Returns:
        ``(order, kept)``: form indices with the kept ones in the first ``kept`` slots.
    """
    total = coef.shape[0]
    rows = jnp.arange(total, dtype=jnp.int32)
    live = rows < (total if count is None else count)
    none = jnp.zeros((0, 3), coef.dtype)
    # The winners at the box centres: a running maximum over the forms (the boxes are the
    # vectorised axis), the first maximum as argmax.
    star = coef[forms_argmax(coef, live, none, none, centre, count)]  # (T, 3)
    # (T, M) with the forms as the minor axis, written per component (a length-3 axis would be
    # reduced with slow strided steps); the any() over boxes reduces along the major axis.
    bound = jnp.zeros((centre.shape[0], total), coef.dtype)
    for i in range(3):
        gap = coef[None, :, i] - star[:, i, None]
        scale = centre[:, i, None] + half[:, i, None]
        bound = bound + gap * centre[:, i, None] + jnp.abs(gap) * half[:, i, None]
        bound = bound + CERTIFICATE_SLACK * (jnp.abs(coef[None, :, i]) + jnp.abs(star[:, i, None])) * scale
    return leading(live & jnp.any(occupied[:, None] & (bound > 0), axis=0))


def leading(keep: Bool[Array, " M"]) -> tuple[Int[Array, " M"], Int[Array, ""]]:
    """Indices with the kept ones first, in order, and how many are kept (a stable partition,
    without a sort)."""
    total = keep.shape[0]
    rows = jnp.arange(total, dtype=jnp.int32)
    order = jnp.zeros((total,), jnp.int32).at[jnp.where(keep, jnp.cumsum(keep) - 1, total)].set(rows, mode="drop")
    return order, jnp.sum(keep, dtype=jnp.int32)


def dot_minor(xt: Float[Array, "3 G"], coef: Float[Array, "M 3"]) -> Float[Array, "M G"]:
    """The same with the directions as the minor (vectorised) axis, for short plane lists."""
    return coef[:, 0, None] * xt[None, 0] + coef[:, 1, None] * xt[None, 1] + coef[:, 2, None] * xt[None, 2]


def cone_violation(x: Float[Array, "G 3"], planes: Float[Array, "L 3"]) -> Float[Array, " G"]:
    """``max_l n_l . x / |x|`` for a cone through the origin given by unit face normals ``n_l``
    (:func:`~ccjax.estimators.gamut._geometry.cone_planes`): ``<= 0`` inside, else the sine of the
    angle outside it."""
    # Directions minor (L, G): a (G, 3) layout strides over the RGB axis for only L ~ 12 planes
    # (2.8x slower in isolation; about equal inside the full kernel), and a K=3 matmul is slower.
    xt = x.T
    return jnp.max(dot_minor(xt, planes), axis=0) * jax.lax.rsqrt(jnp.sum(xt * xt, axis=0))


# ---------------------------------------------------------------------------------------------
# locating stage


def cell_lower_bound(values: Float[Array, " G"], n: int, safety: float) -> Float[Array, " G"]:
    """A first-order lower bound of the violation anywhere in each cell of an ``n x n`` grid:
    the centre's value minus ``safety`` times half the largest change to a neighbour along each
    axis (the factor allows for curvature)."""
    grid = values.reshape(n, n)

    def change(axis):
        step = jnp.abs(jnp.diff(grid, axis=axis))
        pad = [(0, 0), (0, 0)]
        pad[axis] = (1, 0)
        before = jnp.pad(step, pad, mode="edge")
        pad[axis] = (0, 1)
        after = jnp.pad(step, pad, mode="edge")
        return jnp.maximum(before, after)

    return (grid - safety * 0.5 * (change(0) + change(1))).ravel()


def locate(violation: Violation, domain: Float[Array, "2 2"], options: GridOptions) -> tuple[Array, Array]:
    """The locating stage: a box around the feasible region at the scene's relaxation level.

    Each iteration evaluates a square grid over the current box (the first: ``domain``) and keeps
    the points at the first relaxation level reached so far, padded by one step (and kept inside
    the domain when ``options.clip_to_domain``); when none of its own points is at that level it
    zooms to one step around its best point. One compiled body serves every iteration.

    Arguments:
        violation: ``rg (G, 2) -> (G,)`` the constraint set's violation (``OUTSIDE`` outside
            the chromaticity triangle).
        domain: ``(2, 2)`` lower and upper (r,g) corners of the first grid.
        options: the grid sizes.

    Returns:
        ``(lo, hi)`` corners of the box.
    """
    n = options.locate_points

    def iteration(carry, _):
        lo, hi, best = carry
        points, step = square_grid(lo, hi, n)
        values = violation(points)
        if options.locate_safety > 0:
            values = cell_lower_bound(values, n, options.locate_safety)
        nearest = jnp.argmin(values)
        best = jnp.minimum(best, values[nearest])
        level, _ = relaxation_level(best, options.first_level, options.levels)
        chosen = values <= level
        chosen = jnp.where(jnp.any(chosen), chosen, jnp.arange(values.shape[0]) == nearest)
        lo, hi = box_of(points, step[None, :], chosen)
        if options.clip_to_domain:
            lo, hi = jnp.maximum(lo, domain[0]), jnp.minimum(hi, domain[1])
        return (lo, hi, best), None

    start = (domain[0], domain[1], jnp.asarray(OUTSIDE, domain.dtype))
    (lo, hi, _), _ = jax.lax.scan(iteration, start, None, length=options.locate_iterations)
    return lo, hi


# ---------------------------------------------------------------------------------------------
# MV refinement


def pattern_search(
    objective: Callable[[Float[Array, "N 2"]], Float[Array, " N"]],
    start: Float[Array, "2"],
    half_step: Float[Array, "2"],
    steps: int,
    scales: tuple[float, ...] = (1.0,),
    value: Float[Array, ""] | None = None,
) -> Float[Array, "2"]:
    """Maximise ``objective`` (``-inf`` where infeasible) from a feasible (r,g) start.

    A 5x5 stencil around the current point at each spacing ``half * s`` for ``s`` in ``scales``,
    all evaluated as one batch: move to the best point and set the spacing to twice the one that
    found it when it improves, else shrink it by ``min(scales) / 2``. MV's maximum is often a
    vertex of the feasible set (a kink of ``T(u)``, or the tip of a thin spike of a 2-D set) where
    the objective falls off along ridges; moving with an expanding step follows such ridges where
    a fixed shrinking search stalls. With one scale this is the classic expanding pattern search
    (one stencil of 25 per sequential step); with several, each sequential step tries the
    spacings that several classic steps would reach, so fewer steps of wider batches cover the
    same range of spacings (on a GPU the number of sequential steps, not the batch width, sets
    the time).

    Arguments:
        objective: ``rg (N, 2) -> (N,)``.
        start: the best grid direction; ``half_step``: the initial stencil spacing.
        steps: iterations (static).
        scales: the stencil spacings of one iteration, relative to the current one (static).
        value: the objective at ``start`` when the caller has it (its grid value): then
            ``objective`` is traced once, in the loop (half the search's program).

    Returns:
        The best (r,g) found.
    """
    if value is None:
        value = objective(start[None])[0]

    def both(rg):
        values = objective(rg)
        return values, values

    return pattern_search_carrying(both, start, half_step, steps, scales, value, value)[0]


def pattern_search_carrying(
    objective: Callable[[Float[Array, "N 2"]], tuple[Float[Array, " N"], Float[Array, " N"]]],
    start: Float[Array, "2"],
    half_step: Float[Array, "2"],
    steps: int,
    scales: tuple[float, ...],
    value: Float[Array, ""],
    extra: Float[Array, ""],
) -> tuple[Float[Array, "2"], Float[Array, ""]]:
    """:func:`pattern_search` of an objective ``rg -> (values, extras)`` from its ``value`` and
    ``extra`` at ``start``, carrying the best point's extra (MV's ``1/T``: no other form loop
    evaluates it at the answer). Returns ``(best (r,g), its extra)``."""
    unit = np.arange(-2.0, 3.0)
    offsets = np.stack(np.meshgrid(unit, unit, indexing="ij"), axis=-1).reshape(-1, 2)
    offsets = offsets[np.any(offsets != 0, axis=1)]  # the centre is the carried value
    factor = np.repeat(np.asarray(scales), offsets.shape[0])
    stencil = jnp.asarray(np.tile(offsets, (len(scales), 1)) * factor[:, None], start.dtype)
    factor = jnp.asarray(factor, start.dtype)
    shrink = 0.5 * min(scales)

    def step(carry, _):
        centre, value, half, kept = carry
        candidates = centre + stencil * half
        values, extras = objective(candidates)
        best = jnp.argmax(values)
        better = values[best] > value
        centre = jnp.where(better, candidates[best], centre)
        kept = jnp.where(better, extras[best], kept)
        half = jnp.where(better, 2.0 * factor[best] * half, shrink * half)
        return (centre, jnp.maximum(values[best], value), half, kept), None

    (centre, _, _, kept), _ = jax.lax.scan(step, (start, value, half_step, extra), None, length=steps)
    return centre, kept
