"""Colour in Perspective: 2-D gamut mapping with the illumination constraint, on the shared
illuminant-direction engine.

CIP-MV, CIP-AVE (also ``CIP-HA``) and CIP-ICA of Barnard 1999 §4.5.3, Table 4.1 (Finlayson 1996;
Barnard 1995; Finlayson & Hordley 1998).

A candidate illuminant direction is its chromaticity ``u = (r, g, 1-r-g)``; its 3-D map direction
is ``m(u) = w_C / u`` and its 2-D map ``D(u) = (m1/m3, m2/m3) = (k1 b / r, k2 b / g)`` with
``k = (w1/w3, w2/w3)``. The constraints are masks on ``u``
(:mod:`~ccjax.estimators.gamut._constraints_cip`); the selectors, weights derived by the change of
variables from ``(r, g)``:

* **MV** maximises the 2-D map area ``D1 D2 = k1 k2 b^2 / (r g)``, refined below the grid step by
  the engine's pattern search.
* **AVE** is the area centroid of the feasible set in 2-D map space; the Jacobian of
  ``(r, g) -> D`` is ``|dD/d(r,g)| = k1 k2 b / (r^2 g^2)``.
* **ICA** averages the feasible 3-D map directions uniformly in solid angle (the cones of 3-D maps
  that the 2-D constraints define, truncated by the unit ball, a choice the thesis leaves open). The
  solid angle of map directions is ``dOmega_m = w1 w2 w3 / (|m|^3 (r g b)^2) dr dg`` and the
  centroid direction is ``integral (m/|m|) dOmega_m / integral dOmega_m``. Option ``cone="plane"``
  truncates by ``d_r + d_g + d_b <= 1`` instead.

The averages weight each fine cell by its feasible fraction (a linear model of the violation
across the cell), so the boundary error is second order in the grid step.
"""

from __future__ import annotations

import typing
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ccjax._colour import TINY, rg_numpy
from ccjax.estimators.base import AbstractSurfaceEstimator, Estimate, Padding
from ccjax.estimators.gamut import _constraints_cip, _geometry
from ccjax.estimators.gamut._engine import GridOptions, directions, locate, pattern_search, square_grid
from ccjax.estimators.gamut._relaxation import relaxation_level
from ccjax.estimators.gamut._selectors import finish
from ccjax.estimators.registry import register
from ccjax.world import World

SELECTORS = ("MV", "AVE", "ICA")
ILLUMINATION = ("exact", "hull")
CONES = ("ball", "plane")
DEFAULT_ILLUMINATION = {"MV": "exact", "AVE": "hull", "ICA": "exact"}

# Margin (in r and g) around the allowed illuminant region, so relaxed sets can widen past it.
_DOMAIN_MARGIN = 0.005
# One coarse locating pass whose cells count by a first-order bound of their violation (thin
# feasible slivers pass between the centres), with this safety factor for curvature.
_LOCATE_SAFETY = 1.5


@typing.final
class CIP(AbstractSurfaceEstimator):
    """Colour in Perspective with the illumination constraint, one scene per call.

    Attributes:
        white: ``(3,)`` canonical white ``w_C``.
        surface_facets: ``(K, 3)`` unit normals of the cone over the canonical perspective polygon.
        illuminant_facets: ``(L, 3)`` unit normals of the illumination constraint's cone: of the
            training illuminant directions (``illumination="exact"``, tested on ``u``) or of the
            training maps ``w_C / e_j`` (``"hull"``, tested on ``m(u)``).
        domain: ``(2, 2)`` lower and upper (r,g) corners holding every allowed direction (+ margin).
        fallback: ``(3,)`` answer for scenes without data (average training illuminant).
        selector: ``"MV"``, ``"AVE"`` or ``"ICA"``.
        illumination: ``"exact"`` or ``"hull"``.
        cone: ICA truncation, ``"ball"`` (uniform in solid angle) or ``"plane"``.
        options: the engine's grid sizes (one locating pass of ``coarse^2`` cells, a fine grid of
            ``fine^2`` directions).
    """

    white: Float[Array, "3"]
    surface_facets: Float[Array, "K 3"]
    illuminant_facets: Float[Array, "L 3"]
    domain: Float[Array, "2 2"]
    fallback: Float[Array, "3"]
    selector: str = eqx.field(static=True, default="ICA")
    illumination: str = eqx.field(static=True, default="exact")
    cone: str = eqx.field(static=True, default="ball")
    options: GridOptions = eqx.field(static=True, default=GridOptions())
    estimates_brightness: ClassVar[bool] = False
    world_based: ClassVar[bool] = True
    default_preprocessing: ClassVar[str] = "ave5"
    pools_pixels: ClassVar[bool] = False

    @property
    def padding(self) -> Padding:  # pyright: ignore[reportIncompatibleVariableOverride]
        """The grid's observation budgets; CIP reads every slot of a scene."""
        return Padding(self.options.budgets(), None)

    def block_size(self, backend: str) -> int | None:
        """One ``vmap`` over the whole batch on every backend.

        Arguments:
            backend: ``"cpu"``, ``"gpu"`` or ``"tpu"`` (not used).

        Returns:
            ``None``.
        """
        return None

    def violation(
        self, rg: Float[Array, "G 2"], rgb: Float[Array, "P 3"], valid: Bool[Array, " P"]
    ) -> Float[Array, " G"]:
        """The constraint set's per-direction violation; see
        :func:`~ccjax.estimators.gamut._constraints_cip.violation`.

        Arguments:
            rg: ``(G, 2)`` candidate illuminant chromaticities.
            rgb: ``(P, 3)`` the scene's observations.
            valid: ``(P,)`` the valid ones.

        Returns:
            ``(G,)`` the violation of each candidate (``<= 0`` where feasible).
        """
        dtype = rgb.dtype
        return _constraints_cip.violation(
            self.white.astype(dtype),
            self.surface_facets.astype(dtype),
            self.illuminant_facets.astype(dtype),
            self.illumination,
            rg.astype(dtype),
            rgb,
            valid,
        )

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        # The perspective constraints ignore each pixel's brightness. Pixels are not normalised
        # here (measured ~25 % slower on CPU); float32 squares of ``m * p`` stay finite for pixel
        # values between about 1e-15 and 1e15.
        valid = mask & (jnp.sum(rgb, axis=-1) > 0)

        def region(rg):
            return self.violation(rg, rgb, valid)

        options = self.options
        lo, hi = locate(region, self.domain.astype(rgb.dtype), options)
        rg, step = square_grid(lo, hi, options.fine_points)
        v = region(rg)
        level, failed = relaxation_level(jnp.min(v), options.first_level, options.levels)
        feasible = v <= level
        u, _, _ = directions(rg)
        if self.selector == "MV":

            def objective(candidates):
                inside = region(candidates) <= level
                return jnp.where(inside, _log_area(directions(candidates)[0]), -jnp.inf)

            areas = jnp.where(feasible, _log_area(u), -jnp.inf)
            index = jnp.argmax(areas)
            # The start's objective is its grid value: the objective is traced once, in the loop.
            centre = pattern_search(objective, rg[index], step / 2, options.refine_steps, value=areas[index])
            direction = directions(centre[None])[0][0]
        else:
            direction = self._average(u.T, _constraints_cip.coverage(v - level, options.fine_points))
        return finish(direction, jnp.any(valid), ~failed & jnp.any(feasible), level, self.fallback.astype(rgb.dtype))

    def _average(self, u, coverage) -> Float[Array, "3"]:
        """AVE (2-D map-space centroid) or ICA (solid-angle centroid of 3-D map directions) over
        the cells, each weighted by its feasible fraction ``coverage``."""
        r, g, b = jnp.maximum(u, TINY)
        white = self.white.astype(u.dtype)
        m = white[:, None] / jnp.maximum(u, TINY)
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
        # Illuminant of a map: e = w_C / d (Barnard 1999 §4.5.3).
        return jnp.where(mean > TINY, white / jnp.maximum(mean, TINY), 0.0)


def _log_area(u: Float[Array, "G 3"]) -> Float[Array, " G"]:
    # log(D1 D2) up to the constant log(k1 k2): 2 log b - log r - log g.
    safe = jnp.maximum(u, TINY)
    return 2.0 * jnp.log(safe[:, 2]) - jnp.log(safe[:, 0]) - jnp.log(safe[:, 1])


# ---------------------------------------------------------------------------------------------
# fit


def _domain(rg: np.ndarray) -> np.ndarray:
    low, high = rg.min(axis=0) - _DOMAIN_MARGIN, rg.max(axis=0) + _DOMAIN_MARGIN
    return np.stack([np.maximum(low, 1e-3), high])


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
            illuminants (the illumination constraint) and the canonical white.
        selector: ``"MV"`` (max 2-D map area, Finlayson 1996), ``"AVE"`` (centroid, Barnard 1995)
            or ``"ICA"`` (3-D average over map directions, Finlayson & Hordley 1998).
        illumination: ``"exact"`` (the non-convex constraint) or ``"hull"`` (its convex hull in
            map space, Barnard 1995); default exact for MV and ICA, hull for AVE (Table 4.1).
        cone: ICA only: ``"ball"`` (uniform in solid angle) or
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
        illuminant_facets = _geometry.cone_planes(train)
        domain = _domain(rg_numpy(train))
    else:
        illuminant_facets = _geometry.cone_planes(white / train)
        domain = _domain(_geometry.map_cone_chromaticities(white, train))
    options = GridOptions(
        locate_points=coarse,
        locate_iterations=1,
        locate_safety=_LOCATE_SAFETY,
        clip_to_domain=True,
        fine_points=fine,
        refine_steps=48,
        refine_scales=(1.0,),
    )
    as32 = lambda x: jnp.asarray(x, dtype=jnp.float32)
    return CIP(
        white=as32(white),
        surface_facets=as32(_geometry.cone_planes(canonical)),
        illuminant_facets=as32(illuminant_facets),
        domain=as32(domain),
        fallback=as32(train.mean(axis=0)),
        selector=selector,
        illumination=illumination,
        cone=cone,
        options=options,
    )


# ---------------------------------------------------------------------------------------------
# labels (Table 4.1; "HA", hull average, = AVE)

_SELECTOR_OF_LABEL = {"MV": "MV", "AVE": "AVE", "HA": "AVE", "ICA": "ICA"}

register(
    r"CIP-(?P<selector>MV|AVE|HA|ICA)",
    "CIP-ICA",
    "Colour in Perspective, 2-D gamut mapping with the illumination constraint (§4.5.3)",
    grammar="CIP-(MV|AVE|HA|ICA)",
    input_kind="surfaces",
)(lambda world, match, **options: fit(world, _SELECTOR_OF_LABEL[match["selector"]], **options))
