"""Colour in Perspective: 2-D gamut mapping with the illumination constraint.

CIP-MV, CIP-AVE (also ``CIP-HA``) and CIP-ICA of Barnard 1999 §4.5.3, Table 4.1 (Finlayson 1996
[40]; Barnard 1995 [8]; Finlayson & Hordley 1998 [61]); spec ch02-04 §6.4, ch08-12 §1.6, §1.8.

Everything happens in perspective chromaticity ``(R/B, G/B)``: the canonical gamut is the convex
polygon of the reflectances' canonical perspective chromaticities, a 2-D diagonal map
``D = (D1, D2)`` is feasible when ``D * p`` lies in that polygon for every observed ``p``, and the
illumination constraint keeps the maps whose illuminant ``c / D`` lies in the hull of the training
illuminants' perspective chromaticities (``c`` = canonical white's).

Parametrisation (DESIGN.md §4, binding). A candidate illuminant direction is its chromaticity
``u = (r, g, 1-r-g)``; its 3-D map direction is ``m(u) = w_C / u`` and its 2-D map is
``D(u) = (m1/m3, m2/m3) = (k1 b / r, k2 b / g)`` with ``k = (w1/w3, w2/w3)``. A perspective
constraint is a cone through the origin in RGB, so "``D * p`` in the polygon" is
``n_k . (m(u) * p) <= 0`` for the normals ``n_k`` of the planes through the origin and the
polygon's edges — a mask on ``u``, with no brightness bound. The illumination constraint is a
mask on ``u`` too: ``u`` in the cone of the training illuminants (exact, non-convex in map space)
or ``m(u)`` in the cone spanned by the training maps ``w_C / e_j`` (its convex hull, [8]).

Selectors on an ``(r, g)`` grid, weights derived by the change of variables from ``(r, g)``:

* **MV** maximises the 2-D map area ``D1 D2 = k1 k2 b^2 / (r g)``.
* **AVE** is the area centroid of the feasible set in 2-D map space; the Jacobian of
  ``(r, g) -> D`` is ``|dD/d(r,g)| = k1 k2 b / (r^2 g^2)``.
* **ICA** averages the feasible 3-D map directions uniformly in solid angle (the cones of 3-D maps
  that the 2-D constraints define, truncated by the unit ball; spec ch02-04 §10 item 16). The
  solid angle of map directions is ``dOmega_m = w1 w2 w3 / (|m|^3 (r g b)^2) dr dg`` (three times
  the volume ``dV = w1 w2 w3 t^2 / (r g b)^2 dt dr dg`` of the cone inside the unit ball) and the
  centroid direction is ``integral (m/|m|) dOmega_m / integral dOmega_m``. Option ``cone="plane"``
  truncates by ``d_r + d_g + d_b <= 1`` instead.

Grid (DESIGN.md §4): a coarse pass over the bounding box of the allowed illuminants locates the
feasible set, a fine grid over its bounding box integrates, and MV is refined locally below the
fine step. When no direction is feasible the constraints are relaxed by a growing angle
(normalised violation, DESIGN.md §4) and the estimate is flagged ``ok=False``.
"""

from __future__ import annotations

import typing

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float
from scipy.spatial import ConvexHull

from ccjax.estimators.base import TINY, AbstractSurfaceEstimator, Estimate
from ccjax.estimators.gamut.relaxation import relaxation_level
from ccjax.estimators.gamut.selectors import finish
from ccjax.estimators.registry import register
from ccjax.world import World

SELECTORS = ("MV", "AVE", "ICA")
ILLUMINATION = ("exact", "hull")
CONES = ("ball", "plane")
DEFAULT_ILLUMINATION = {"MV": "exact", "AVE": "hull", "ICA": "exact"}

# A direction outside the chromaticity triangle gets a violation above every ladder level.
_OUTSIDE = 4.0
# Margin (in r and g) around the allowed illuminant region, so relaxed sets can widen past it.
_DOMAIN_MARGIN = 0.005
# MV refinement: a pattern search with (n x n) patches around the best direction, starting at one
# fine-grid step; it moves along thin spikes of the feasible set and shrinks four-fold otherwise.
_MV_PATCH = 9
_MV_ROUNDS = 6
# Safety factor on the first-order cell bound of the locating pass.
_LOCATE_SAFETY = 1.5


# ---------------------------------------------------------------------------------------------
# geometry computed once per world (NumPy / Qhull)


def cone_facets(rays: np.ndarray) -> np.ndarray:
    """Unit normals of the convex cone spanned by positive rays, ``n_k . x <= 0`` inside.

    The cone's faces are planes through the origin and two adjacent extreme rays; the extreme rays
    are the hull vertices of the rays' central projection onto ``R + G + B = 1`` (any central
    projection gives the same cone, spec ch08-12 §1.7.3).

    Arguments:
        rays: ``(N, 3)`` vectors with positive component sums.

    Returns:
        ``(K, 3)`` unit normals, one per face.
    """
    rays = np.asarray(rays, dtype=np.float64)
    projected = rays / rays.sum(axis=1, keepdims=True)
    hull = ConvexHull(projected[:, :2])
    extreme = projected[hull.vertices]
    normals = np.cross(extreme, np.roll(extreme, -1, axis=0))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    inside = extreme.mean(axis=0)
    return normals * -np.sign(normals @ inside)[:, None]


def _rg(rgb: np.ndarray) -> np.ndarray:
    return rgb[..., :2] / rgb.sum(axis=-1, keepdims=True)


def _map_cone_rg(white: np.ndarray, train_whites: np.ndarray, samples: int = 257) -> np.ndarray:
    """Chromaticities of illuminants on the boundary of the convex cone of training maps."""
    maps = white / train_whites
    projected = maps / maps.sum(axis=1, keepdims=True)
    extreme = projected[ConvexHull(projected[:, :2]).vertices]
    t = np.linspace(0.0, 1.0, samples)[:, None, None]
    boundary = (1 - t) * extreme[None] + t * np.roll(extreme, -1, axis=0)[None]
    return _rg(white / boundary.reshape(-1, 3))


def _box(rg: np.ndarray) -> np.ndarray:
    low, high = rg.min(axis=0) - _DOMAIN_MARGIN, rg.max(axis=0) + _DOMAIN_MARGIN
    low = np.maximum(low, 1e-3)
    return np.array([low[0], high[0], low[1], high[1]])


# ---------------------------------------------------------------------------------------------
# the per-scene kernel


def _grid(box: Float[Array, "4"], n: int) -> Float[Array, "3 G"]:
    """Cell centres of an ``n x n`` grid over ``box = (r0, r1, g0, g1)`` as directions ``u``.

    Directions are stored component-major, ``(3, G)``: every per-direction quantity below is then
    an elementwise expression on contiguous rows, which XLA fuses into vectorised CPU loops.
    """
    t = (jnp.arange(n, dtype=box.dtype) + 0.5) / n
    r, g = jnp.meshgrid(box[0] + t * (box[1] - box[0]), box[2] + t * (box[3] - box[2]), indexing="ij")
    r, g = r.ravel(), g.ravel()
    return jnp.stack([r, g, 1.0 - r - g])


def _max_of_dots(x: Float[Array, "3 G"], vectors: Float[Array, "K 3"]) -> Float[Array, " G"]:
    """``max_k x_g . vectors_k`` for every ``g``, as unrolled multiply-adds and maxima.

    Inner products of length 3 are far faster as fused elementwise loops than as (batched) matrix
    products on CPU.
    """
    best = None
    for k in range(vectors.shape[0]):
        dot = x[0] * vectors[k, 0] + x[1] * vectors[k, 1] + x[2] * vectors[k, 2]
        best = dot if best is None else jnp.maximum(best, dot)
    return best


def _argmax(x: Float[Array, " G"]) -> Array:
    """First index of the maximum; a max and a min reduction vectorise on CPU, where XLA's
    variadic (value, index) reduction of ``jnp.argmax`` does not."""
    index = jnp.arange(x.shape[0])
    return jnp.min(jnp.where(x == jnp.max(x), index, x.shape[0] - 1))


def _cell_lower_bound(v: Float[Array, " G"], n: int) -> Float[Array, " G"]:
    """A first-order lower bound of the violation anywhere in each cell of an ``n x n`` grid.

    Thin feasible slivers can pass between grid centres; a cell may hold feasible directions when
    its centre's violation minus half the largest change to a neighbour along each axis (times a
    safety factor for curvature) is not positive.
    """
    grid = v.reshape(n, n)

    def change(axis):
        step = jnp.abs(jnp.diff(grid, axis=axis))
        pad = [(0, 0), (0, 0)]
        pad[axis] = (1, 0)
        before = jnp.pad(step, pad, mode="edge")
        pad[axis] = (0, 1)
        after = jnp.pad(step, pad, mode="edge")
        return jnp.maximum(before, after)

    return (grid - _LOCATE_SAFETY * 0.5 * (change(0) + change(1))).ravel()


def _coverage(v: Float[Array, " G"], n: int) -> Float[Array, " G"]:
    """Fraction of each cell of an ``n x n`` grid where the violation is ``<= 0``.

    The violation is taken as linear across the cell with the central-difference slopes
    ``a, b`` (per cell width) of the grid, ``v0 + a s + b t`` with ``s, t`` uniform in
    ``[-1/2, 1/2]``; the covered fraction is the CDF at ``-v0`` of that trapezoidal distribution.
    This makes the boundary error of the integrals second order instead of first (a cell counts
    with the part of it that is feasible, not all or nothing).
    """
    grid = v.reshape(n, n)

    def slope(axis):
        padded = jnp.pad(grid, [(1, 1) if a == axis else (0, 0) for a in range(2)], mode="reflect", reflect_type="odd")
        centre = jax.lax.slice_in_dim(padded, 1, n + 1, axis=axis)
        ahead = jax.lax.slice_in_dim(padded, 2, n + 2, axis=axis) - centre
        behind = centre - jax.lax.slice_in_dim(padded, 0, n, axis=axis)
        return jnp.maximum(jnp.abs(ahead), jnp.abs(behind)).ravel()

    a, b = slope(0), slope(1)
    a, b = jnp.maximum(a, b), jnp.minimum(a, b)
    x = -v
    half = 0.5 * (a + b)
    knee = 0.5 * (a - b)
    flat = b <= 1e-6 * a  # one slope only: uniform distribution of width a
    a_safe = jnp.maximum(a, TINY)
    b_safe = jnp.where(flat, 1.0, jnp.maximum(b, TINY))
    ramp = jnp.where(
        x <= -knee,
        jnp.square(jnp.maximum(x + half, 0.0)) / (2.0 * a_safe * b_safe),
        jnp.where(
            x <= knee,
            b / (2.0 * a_safe) + (x + knee) / a_safe,
            1.0 - jnp.square(jnp.maximum(half - x, 0.0)) / (2.0 * a_safe * b_safe),
        ),
    )
    uniform = (x + 0.5 * a) / a_safe
    fraction = jnp.where(flat, uniform, ramp)
    # No slope at all (a constant violation): all or nothing.
    fraction = jnp.where(a <= TINY, (v <= 0).astype(v.dtype), fraction)
    # The violation is a maximum of smooth functions: beyond the tip of a feasible spike it has a
    # valley of small positive values that a linear model would read as a boundary crossing. An
    # infeasible centre only counts when a 4-neighbour is feasible (the boundary is really there).
    feasible = jnp.pad(grid <= 0, 1)
    near = feasible[:-2, 1:-1] | feasible[2:, 1:-1] | feasible[1:-1, :-2] | feasible[1:-1, 2:]
    fraction = jnp.where((v <= 0) | near.ravel(), fraction, 0.0)
    return jnp.clip(fraction, 0.0, 1.0)


@typing.final
class CIP(AbstractSurfaceEstimator):
    """Colour in Perspective with the illumination constraint, one scene per call.

    Attributes:
        white: ``(3,)`` canonical white ``w_C``.
        surface_facets: ``(K, 3)`` unit normals of the cone over the canonical perspective polygon.
        illuminant_facets: ``(L, 3)`` unit normals of the illumination constraint's cone: of the
            training illuminant directions (``illumination="exact"``, tested on ``u``) or of the
            training maps ``w_C / e_j`` (``"hull"``, tested on ``m(u)``).
        domain: ``(4,)`` rg box ``(r0, r1, g0, g1)`` holding every allowed direction (+ margin).
        fallback: ``(3,)`` answer for scenes without data (average training illuminant).
        selector: ``"MV"``, ``"AVE"`` or ``"ICA"``.
        illumination: ``"exact"`` or ``"hull"``.
        cone: ICA truncation, ``"ball"`` (uniform in solid angle) or ``"plane"``.
        coarse, fine: grid sizes per axis of the locating and the integrating pass.
    """

    white: Float[Array, "3"]
    surface_facets: Float[Array, "K 3"]
    illuminant_facets: Float[Array, "L 3"]
    domain: Float[Array, "4"]
    fallback: Float[Array, "3"]
    selector: str = eqx.field(static=True, default="ICA")
    illumination: str = eqx.field(static=True, default="exact")
    cone: str = eqx.field(static=True, default="ball")
    coarse: int = eqx.field(static=True, default=24)
    fine: int = eqx.field(static=True, default=48)

    def violation(
        self, u: Float[Array, "3 G"], rgb: Float[Array, "P 3"], valid: Bool[Array, " P"]
    ) -> Float[Array, " G"]:
        """Largest normalised violation (a sine) of the perspective and illumination constraints.

        ``<= 0`` exactly when ``u`` is feasible; a relaxation level ``eps`` accepts ``<= eps``.
        Surface part (DESIGN.md §4): ``max_{j,k} n_k . (p_j * m) / |p_j * m|``; illumination part:
        ``max_l h_l . x / |x|`` with ``x = u`` (exact) or ``m(u)`` (hull).

        Arguments:
            u: ``(3, G)`` directions (component-major).
            rgb: ``(P, 3)`` observed RGB; valid: ``(P,)`` pixels that constrain.

        Returns:
            ``(G,)`` violations; directions outside the chromaticity triangle get a value above
            every relaxation level.
        """
        inside = jnp.all(u > 1e-6, axis=0)
        u = jnp.where(inside[None, :], u, 1.0 / 3.0)
        m = self.white[:, None] / u

        scaled = self.surface_facets[None, :, :] * rgb[:, None, :]  # (P, K, 3): n_k * p_j

        # One pixel at a time: memory stays O(G) per scene whatever the number of pixels, and each
        # step is one fused elementwise loop over the directions (measured as fast as evaluating
        # all pixels at once, already for 8 pixels).
        def pixel(j, worst):
            along = _max_of_dots(m, scaled[j])  # max_k (n_k * p_j) . m
            length = jnp.sqrt(sum((m[c] * rgb[j, c]) ** 2 for c in range(3)))  # |p_j * m|
            return jnp.where(valid[j], jnp.maximum(worst, along / jnp.maximum(length, TINY)), worst)

        surface = jax.lax.fori_loop(0, rgb.shape[0], pixel, jnp.full(u.shape[1:], -1.0, u.dtype))
        x = u if self.illumination == "exact" else m
        x = x / jnp.sqrt(jnp.sum(x * x, axis=0))
        illuminant = _max_of_dots(x, self.illuminant_facets)
        return jnp.where(inside, jnp.maximum(surface, illuminant), _OUTSIDE)

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        # The perspective constraints ignore each pixel's brightness. Pixels are not normalised
        # here (measured ~25 % slower on CPU); float32 squares of ``m * p`` stay finite for pixel
        # values between about 1e-15 and 1e15.
        valid = mask & (jnp.sum(rgb, axis=-1) > 0)
        has_data = jnp.any(valid)

        def level_of(v):
            # First ladder level at which some direction is accepted.
            return relaxation_level(jnp.min(v))

        # Locate: coarse grid over the allowed region, bounding box of the accepted directions
        # widened by one coarse step (the set's edge lies within a step of an accepted centre).
        domain = self.domain.astype(rgb.dtype)
        lower, upper = domain[jnp.array([0, 2])], domain[jnp.array([1, 3])]
        u_coarse = _grid(domain, self.coarse)
        bound = _cell_lower_bound(self.violation(u_coarse, rgb, valid), self.coarse)
        accepted = (bound <= level_of(bound)[0])[None, :]
        step = (upper - lower) / self.coarse
        low = jnp.maximum(jnp.min(jnp.where(accepted, u_coarse[:2], jnp.inf), axis=1) - step, lower)
        high = jnp.minimum(jnp.max(jnp.where(accepted, u_coarse[:2], -jnp.inf), axis=1) + step, upper)

        # Integrate: fine grid over the located box.
        u = _grid(jnp.stack([low[0], high[0], low[1], high[1]]), self.fine)
        v = self.violation(u, rgb, valid)
        level, failed = level_of(v)
        feasible = v <= level
        if self.selector == "MV":
            direction = self._max_area(u, feasible, (high - low) / self.fine, level, rgb, valid)
        else:
            direction = self._average(u, _coverage(v - level, self.fine))
        return finish(direction, has_data, ~failed & jnp.any(feasible), level, self.fallback.astype(rgb.dtype))

    @staticmethod
    def _log_area(u: Float[Array, "3 G"]) -> Float[Array, " G"]:
        # log(D1 D2) up to the constant log(k1 k2): 2 log b - log r - log g.
        safe = jnp.maximum(u, TINY)
        return 2.0 * jnp.log(safe[2]) - jnp.log(safe[0]) - jnp.log(safe[1])

    def _max_area(self, u, feasible, step, level, rgb, valid) -> Float[Array, "3"]:
        """MV: the feasible direction of largest 2-D map area, refined by a pattern search.

        Each round evaluates a patch of half-width ``step`` around the best direction so far; when
        the best lies on the patch's edge the patch moves with the same size (the maximum is often
        at the tip of a thin spike of the feasible set), otherwise it shrinks four-fold.
        """
        best = u[:, _argmax(jnp.where(feasible, self._log_area(u), -jnp.inf))]
        offsets = jnp.linspace(-1.0, 1.0, _MV_PATCH, dtype=u.dtype)
        dr, dg = jnp.meshgrid(offsets, offsets, indexing="ij")
        patch = jnp.stack([dr.ravel(), dg.ravel()])
        on_edge = jnp.max(jnp.abs(patch), axis=0) == 1.0

        def round_(_, state):
            best, step = state
            rg = best[:2, None] + patch * step[:, None]
            candidates = jnp.concatenate([rg, 1.0 - rg.sum(axis=0, keepdims=True)])
            ok = self.violation(candidates, rgb, valid) <= level
            # The patch centre is the current best, so a round never loses feasibility.
            index = _argmax(jnp.where(ok, self._log_area(candidates), -jnp.inf))
            return candidates[:, index], jnp.where(on_edge[index], step, step / 4.0)

        # A loop (not unrolled) so the violation kernel is compiled once for all rounds.
        return jax.lax.fori_loop(0, _MV_ROUNDS, round_, (best, step))[0]

    def _average(self, u, coverage) -> Float[Array, "3"]:
        """AVE (2-D map-space centroid) or ICA (solid-angle centroid of 3-D map directions).

        ``coverage`` is each cell's feasible fraction (:func:`_coverage`).
        """
        r, g, b = jnp.maximum(u, TINY)
        m = self.white[:, None] / jnp.maximum(u, TINY)
        if self.selector == "AVE":
            # D = (m1/m3, m2/m3); area element k1 k2 b / (r g)^2 dr dg.
            value = m[:2] / m[2:]
            log_weight = jnp.log(b) - 2.0 * jnp.log(r * g)
        else:
            # Map direction m / |m| (ball) or m / sum(m) (plane); solid-angle (or truncated-cone)
            # element w1 w2 w3 / (|m|^3 (r g b)^2) dr dg.
            size = jnp.sqrt(jnp.sum(m * m, axis=0)) if self.cone == "ball" else jnp.sum(m, axis=0)
            value = m / size
            log_weight = -3.0 * jnp.log(size) - 2.0 * jnp.log(r * g * b)
        covered = coverage > 0
        log_weight = jnp.where(covered, log_weight, -jnp.inf)
        weight = jnp.where(covered, coverage * jnp.exp(log_weight - jnp.max(log_weight)), 0.0)
        mean = jnp.sum(weight * value, axis=1) / jnp.maximum(jnp.sum(weight), TINY)
        if self.selector == "AVE":
            mean = jnp.concatenate([mean, jnp.ones(1, mean.dtype)])
        # Illuminant of a map: e = w_C / d (spec ch08-12 §0).
        return jnp.where(mean > TINY, self.white / jnp.maximum(mean, TINY), 0.0)


# ---------------------------------------------------------------------------------------------
# fit


def fit(
    world: World,
    selector: str = "ICA",
    *,
    illumination: str | None = None,
    cone: str = "ball",
    coarse: int = 24,
    fine: int = 48,
) -> CIP:
    """Fit a Colour-in-Perspective estimator to a world (Barnard 1999 §4.5.3, Table 4.1).

    Arguments:
        world: supplies the reflectances under the canonical light (canonical gamut), the training
            illuminants (illumination constraint, spec ch02-04 §10 item 6) and the canonical white.
        selector: ``"MV"`` (max 2-D map area, [40]), ``"AVE"`` (centroid, [8]) or ``"ICA"``
            (3-D average over map directions, [61]).
        illumination: ``"exact"`` (the non-convex constraint) or ``"hull"`` (its convex hull in
            map space, [8]); default exact for MV and ICA, hull for AVE (Table 4.1).
        cone: ICA only: ``"ball"`` (uniform in solid angle, spec ch02-04 §10 item 16) or
            ``"plane"`` (cones truncated by ``d_r + d_g + d_b = 1``).
        coarse, fine: grid points per axis of the locating and the integrating pass.

    Returns:
        A :class:`CIP` estimator.
    """
    if selector not in SELECTORS:
        raise ValueError(f"selector: expected one of {SELECTORS}, got {selector!r}")
    illumination = DEFAULT_ILLUMINATION[selector] if illumination is None else illumination
    if illumination not in ILLUMINATION:
        raise ValueError(f"illumination: expected one of {ILLUMINATION}, got {illumination!r}")
    if cone not in CONES:
        raise ValueError(f"cone: expected one of {CONES}, got {cone!r}")
    for name, value in (("coarse", coarse), ("fine", fine)):
        if not isinstance(value, int) or value < 4:
            raise ValueError(f"{name}: expected an integer >= 4, got {value!r}")
    white = np.asarray(world.canonical_white, dtype=np.float64)
    canonical = np.asarray(world.canonical_rgb, dtype=np.float64)
    train = np.asarray(world.train_whites, dtype=np.float64)
    # Perspective chromaticity needs B > 0; a surface black in B has no perspective chromaticity.
    canonical = canonical[canonical[:, 2] > 0]
    if canonical.shape[0] < 3 or train.shape[0] < 3:
        raise ValueError("world: needs at least 3 reflectances with B > 0 and 3 training illuminants")
    if illumination == "exact":
        illuminant_facets = cone_facets(train)
        allowed = _rg(train)
    else:
        illuminant_facets = cone_facets(white / train)
        allowed = _map_cone_rg(white, train)
    as32 = lambda x: jnp.asarray(x, dtype=jnp.float32)
    return CIP(
        white=as32(white),
        surface_facets=as32(cone_facets(canonical)),
        illuminant_facets=as32(illuminant_facets),
        domain=as32(_box(allowed)),
        fallback=as32(train.mean(axis=0)),
        selector=selector,
        illumination=illumination,
        cone=cone,
        coarse=coarse,
        fine=fine,
    )


# ---------------------------------------------------------------------------------------------
# labels (Table 4.1; "HA" = AVE, spec ch02-04 §10 item 17)

_SELECTOR_OF_LABEL = {"MV": "MV", "AVE": "AVE", "HA": "AVE", "ICA": "ICA"}

register(
    r"CIP-(?P<selector>MV|AVE|HA|ICA)",
    "CIP-ICA",
    "Colour in Perspective, 2-D gamut mapping with the illumination constraint (§4.5.3)",
)(lambda world, match, **options: fit(world, _SELECTOR_OF_LABEL[match["selector"]], **options))
