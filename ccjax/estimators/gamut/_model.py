"""Fitting gamut-mapping models and the Estimator that runs them (Barnard 1999 §4.5.3, ch. 6-9).

``fit(world, constraint=..., extension=...)`` computes, once, with Qhull: the canonical gamut (or
its extension: ND, FL, SP, MET and their combinations, :mod:`._extensions`) as fixed-size facet
arrays, the cone of the training illuminants (ECRULE's illumination constraint) and the cone of
their map directions (its convex approximation), and the domain of illuminant directions the
locating stage starts from. The per-scene work is
:func:`~ccjax.estimators.gamut._constraints_3d.evaluate` followed by a selector.
"""

from __future__ import annotations

import typing
from typing import ClassVar

import equinox as eqx
import jax
import numpy as np
from jaxtyping import Array, Bool, Float

from ccjax._colour import rg_numpy
from ccjax.backends import block_scenes
from ccjax.estimators.base import AbstractSurfaceEstimator, Estimate, Padding
from ccjax.estimators.gamut import _extensions, _geometry
from ccjax.estimators.gamut._constraints_3d import COUNTED_SLOTS, evaluate
from ccjax.estimators.gamut._engine import GridOptions
from ccjax.estimators.gamut._selectors import SELECTORS, select
from ccjax.world import World

CONSTRAINTS = ("CRULE", "ECRULE")
# ECRULE's domain of directions extends this far beyond its illumination constraints, so relaxed
# (widened) constraints still find directions.
_ECRULE_MARGIN = 0.06


class GamutModel(eqx.Module):
    """A fitted 3-D gamut-mapping model (all arrays are PyTree leaves, so gradients reach them).

    Attributes:
        white: ``(3,)`` canonical white ``w_C``.
        origin_normals: ``(K0, 3)`` outward normals of the canonical gamut's facets through the origin.
        top_normals, top_offsets: ``(K1, 3)``, ``(K1,)`` the other facets, ``n . x <= c``.
        illuminant_planes: ``(L, 3)`` unit face normals of the training-illuminant cone.
        map_planes: ``(Lc, 3)`` unit face normals of the cone of their map directions ``w_C / e``.
        domain: ``(2, 2)`` lower and upper (r,g) corners of the box the locating stage starts
            from (CRULE: the whole chromaticity triangle; ECRULE: the illumination constraints'
            box with a margin).
        fallback: ``(3,)`` returned (with ``ok=False``) when no solution exists at any level.
        constraint, extension, options: static configuration; ``extension`` is the label prefix
            of the canonical gamut's extensions (``None``, ``"ND"``, ``"SP-FL"``, ...).
    """

    white: Float[Array, "3"]
    origin_normals: Float[Array, "K0 3"]
    top_normals: Float[Array, "K1 3"]
    top_offsets: Float[Array, " K1"]
    illuminant_planes: Float[Array, "L 3"]
    map_planes: Float[Array, "Lc 3"]
    domain: Float[Array, "2 2"]
    fallback: Float[Array, "3"]
    constraint: str = eqx.field(static=True)
    extension: str | None = eqx.field(static=True)
    options: GridOptions = eqx.field(static=True)


def canonical_points(
    world: World,
    extension: _extensions.Extension | str | tuple | None,
    *,
    metals: np.ndarray | None = None,
    fluorescent: _extensions.FluorescentResponses | None = None,
) -> np.ndarray:
    """The points whose hull (with the origin) is the canonical gamut: the database under the
    canonical light, for ND/FL also every training illuminant's white-balanced database (§6.1),
    plus the FL/SP/MET points (:func:`ccjax.estimators.gamut._extensions.points`)."""
    extension = _extensions.Extension.parse(extension)
    if extension.specular == "MET" and metals is None:
        metals = _extensions.default_metals()
    if extension.diagonal == "FL" and fluorescent is None:
        fluorescent = _extensions.default_fluorescent(world)
    return _extensions.points(world, extension, metals=metals, fluorescent=fluorescent)


def fit(
    world: World,
    *,
    constraint: str = "ECRULE",
    extension: _extensions.Extension | str | tuple | None = None,
    options: GridOptions | None = None,
    metals: np.ndarray | None = None,
    fluorescent: _extensions.FluorescentResponses | None = None,
) -> GamutModel:
    """Fit a gamut-mapping model to a world.

    Arguments:
        world: supplies the reflectances, canonical light, training illuminants and camera.
        constraint: ``"CRULE"`` (surface constraints only, Forsyth) or ``"ECRULE"`` (plus the
            training-illuminant constraint, Finlayson).
        extension: the canonical gamut's extensions: ``None``; ``"ND"`` (diagonal-model failure,
            §6.1); ``"FL"`` (ND with fluorescent surfaces, ch. 7); ``"SP"`` (specular white
            points, §8.2), ``"MET"`` (SP plus coloured-metal specular points); combinations such
            as ``"SP-ND"``, ``("MET", "FL")``; ``"SP4"`` for a multiplier other than 8
            (:class:`~ccjax.estimators.gamut._extensions.Extension`).
        options: grid sizes and budgets (:class:`GridOptions`).
        metals: ``(M, 101)`` metal specular reflectances for MET (default: brass, copper, gold
            from :mod:`ccjax.materials`, unit mean).
        fluorescent: the fluorescent surfaces' responses for FL (default: the characterised
            surfaces of :mod:`ccjax.materials`).

    Returns:
        A :class:`GamutModel` (float32 arrays).
    """
    if constraint not in CONSTRAINTS:
        raise ValueError(f"constraint: expected one of {CONSTRAINTS}, got {constraint!r}")
    extension = _extensions.Extension.parse(extension)
    options = options or GridOptions()
    if not isinstance(options, GridOptions):
        raise ValueError(f"options: expected a GridOptions, got {type(options).__name__}")
    facets = _geometry.gamut_facets(canonical_points(world, extension, metals=metals, fluorescent=fluorescent))
    white = np.asarray(world.canonical_white, np.float64)
    whites = np.asarray(world.train_whites, np.float64)
    illuminant_planes = _geometry.cone_planes(whites)
    map_planes = _geometry.cone_planes(white / whites)
    if constraint == "ECRULE":
        chroma = rg_numpy(whites)
        pr0, pr1, pg0, pg1 = _geometry.preimage_box(map_planes, white)
        lo = np.minimum(chroma.min(axis=0), [pr0, pg0]) - _ECRULE_MARGIN
        hi = np.maximum(chroma.max(axis=0), [pr1, pg1]) + _ECRULE_MARGIN
        domain = np.stack([np.maximum(lo, 0.0), np.minimum(hi, 1.0)])
    else:
        domain = np.array([[0.0, 0.0], [1.0, 1.0]])
    # Cast on the host and device_put: jnp.asarray compiles a small program per shape (start-up time).
    f32 = lambda x: jax.device_put(np.asarray(x, np.float32))
    return GamutModel(
        white=f32(white),
        origin_normals=f32(facets.origin_normals),
        top_normals=f32(facets.top_normals),
        top_offsets=f32(facets.top_offsets),
        illuminant_planes=f32(illuminant_planes),
        map_planes=f32(map_planes),
        domain=f32(domain),
        fallback=f32(whites.mean(axis=0)),
        constraint=constraint,
        extension=extension.label,
        options=options,
    )


class AbstractGamutMapEstimator(AbstractSurfaceEstimator):
    """A selector over the feasible maps of a fitted :class:`GamutModel` (hard or soft): world-based,
    given the thesis' 5x5 block averages of a photograph (§4.6), and padded to the model's grid
    budgets; below the smallest budget the kernel reads only the usable observations. Final
    subclasses hold ``model`` and state ``block_size``."""

    if typing.TYPE_CHECKING:
        # A field of every final subclass (a dataclass field cannot be declared abstract here).
        model: GamutModel
    estimates_brightness: ClassVar[bool] = True
    world_based: ClassVar[bool] = True
    default_preprocessing: ClassVar[str] = "ave5"
    pools_pixels: ClassVar[bool] = False

    @property
    def padding(self) -> Padding:  # pyright: ignore[reportIncompatibleVariableOverride]
        """The model's grid observation budgets, counted over the counted slots."""
        return Padding(self.model.options.budgets(), COUNTED_SLOTS)


@typing.final
class GamutMapping(AbstractGamutMapEstimator):
    """A gamut-mapping estimator: one model and one selector (Table 4.1, §6.2).

    ``GamutMapping(model, "SCWIA", 12)`` is ECRULE-SCWIA-12 when ``model`` is an ECRULE model.
    Call it on one scene, ``(rgb (P, 3), mask (P,)) -> Estimate``; vmap for batches.

    Attributes:
        model: the fitted :class:`GamutModel` (CRULE or ECRULE, with its canonical-gamut
            extension), from :func:`fit`.
        selector: how one light is chosen from the feasible set (§4.5.3, §6.2): ``"MV"`` (maximum
            volume), ``"AVE"`` (centroid of the feasible maps), ``"ICA"`` (illumination-constrained
            average; ECRULE only) or ``"SCWIA"`` (surface-constrained chromaticity-weighted
            illumination average).
        power: SCWIA's ``N``, the exponent of its weights (must be positive; 12 as in
            ECRULE-SCWIA-12); ignored by the other selectors.
    """

    model: GamutModel
    selector: str = eqx.field(static=True)
    power: float = eqx.field(static=True, default=12.0)

    def block_size(self, backend: str) -> int | None:
        """The backend's block (:func:`ccjax.backends.block_scenes`: cache-sized on CPU, as large
        as the device's memory allows on an accelerator).

        Arguments:
            backend: ``"cpu"``, ``"gpu"`` or ``"tpu"``.

        Returns:
            Scenes per vmapped block.
        """
        return block_scenes(backend)

    def __check_init__(self):
        if self.selector not in SELECTORS:
            raise ValueError(f"selector: expected one of {SELECTORS}, got {self.selector!r}")
        if self.selector == "ICA" and self.model.constraint != "ECRULE":
            raise ValueError("selector: ICA is the illumination-constrained average; it needs constraint='ECRULE'")
        if self.selector == "SCWIA" and not self.power > 0:
            raise ValueError(f"power: SCWIA's N must be positive, got {self.power!r}")

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        return select(self.model, evaluate(self.model, rgb, mask), self.selector, self.power)

    def reduction_exact(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Bool[Array, ""]:
        """Diagnostic: whether the observation reduction of a large scene kept every observation
        it selected as a support point (False means the fine stage ran on a budgeted subset, so
        the estimate may differ from the unreduced one). One scene; vmap for batches.

        Arguments:
            rgb: ``(P, 3)`` the scene's observations.
            mask: ``(P,)`` the valid ones.

        Returns:
            A boolean scalar.
        """
        return evaluate(self.model, rgb, mask).exact


def estimate_all(
    model: GamutModel, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"], powers=(3, 6, 9, 12, 18, 24)
) -> dict[str, Estimate]:
    """Every selector of a model from ONE evaluation of the direction grid.

    Arguments:
        model: the fitted :class:`GamutModel`.
        rgb: ``(P, 3)`` one scene's camera RGB.
        mask: ``(P,)`` True where a pixel may be used.
        powers: the SCWIA exponents ``N`` to report, one ``"SCWIA-N"`` entry each.

    Returns:
        ``{"MV": ..., "AVE": ..., "ICA": ... (ECRULE only), "SCWIA-N": ...}``.
    """
    grid = evaluate(model, rgb, mask)
    selectors = ["MV", "AVE"] + (["ICA"] if model.constraint == "ECRULE" else [])
    out = {name: select(model, grid, name) for name in selectors}
    for n in powers:
        out[f"SCWIA-{n}"] = select(model, grid, "SCWIA", float(n))
    return out
