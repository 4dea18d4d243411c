"""Colour by Correlation: the 2-D (r,g) method (Barnard 1999 §4.5.4, after Finlayson, Hubel & Hordley
1997) and the 3-D (r, g, L) method of chapter 10, with soft (differentiable) variants.

A correlation matrix holds, per training illuminant, the log-probability of observing a colour cell
(§4.5.4, §10.2). It is computed once by a ``*_matrix`` function of the world (NumPy,
:mod:`._matrices`) and stored in the fitted model as a plain array, so a matrix learned by gradient
descent can be dropped in (``dataclasses.replace(model, log_probability=learned)``). ccjax stores the
thesis' matrix transposed, one column per training illuminant, ``log_probability (cells, I)``: a
scene's cells then gather contiguous rows.

2-D cells are the 50 x 50 (r,g) bins of width 0.02, ``cell = 50 * floor(50 r) + floor(50 g)``. 3-D
cells are ``rg_cell * l_total + floor(l_bins * L / b)``: ``rg_cell`` numbers the 1275 (r,g) bins
with ``i + j <= 49`` row-major (the other half is impossible, r + g <= 1), ``L = R+G+B`` is divided
by the hypothesised illuminant brightness ``b`` (R+G+B of white) and ``l_bins`` bins cover matte
reflection ``[0, 1)``; ``l_total`` bins reach further for specular training. The last row of a 3-D
matrix is the "outside" cell (impossible chromaticity or brighter than modelled) at the floor.

Labels: ``C-by-C-01``, ``C-by-C-MAP``, ``C-by-C-MMSE``, ``C-by-C-MLM``; ``RGB-C-by-C-MAP`` and
``RGB-C-by-C-MMSE`` (discretisation remedy 2, presence minus ``n_occ log(b / B0)``, the default;
suffix ``-counts`` selects remedy 1, duplicate counts, as Table 10.1 used; ``-presence`` is explicit);
prefixes ``SPEC-`` (specular training world), ``STD-`` (matte, Table 10.2's name) and ``FL-``
(fluorescent surfaces in the training world at about 15 % of occurrences, §7.2, Table 10.1; before
``SPEC-``/``STD-``); ``soft-`` variants of MAP and MMSE with kernel binning and softmax posteriors.
"""

from __future__ import annotations

from ccjax.estimators.correlation._binning import (
    N_RG_CELLS,
    RG_BINS,
    compact_rg_cells,
    presence_scores,
    rg_bins,
    soft_presence_scores,
)
from ccjax.estimators.correlation._brightness import ColourByCorrelation3D, fit_brightness
from ccjax.estimators.correlation._chromaticity import (
    MLM_WIDTHS,
    ColourByCorrelation,
    ColourByCorrelation01,
    fit_chromaticity,
    fit_hull,
    mlm_mask,
    mlm_width_search,
    tune_mlm_width,
)
from ccjax.estimators.correlation._fitting import (
    DEFAULT_SOFTNESS,
    DEFAULT_TEMPERATURE,
    FLUORESCENT_FRACTION,
)
from ccjax.estimators.correlation._matrices import (
    BRIGHTNESS_SIGMA,
    brightness_matrix,
    chromaticity_matrix,
    hull_matrix,
    training_responses,
)
from ccjax.estimators.registry import register


def _training_world(match, options: dict) -> None:
    """The training-world prefixes: ``FL-`` (fluorescent surfaces) and ``SPEC-`` (specularities)."""
    if match.groupdict().get("fl"):
        options.setdefault("fluorescent", True)
    if match.groupdict().get("spec") or match.groupdict().get("prefix") == "SPEC-":
        options.setdefault("specular", True)


@register(
    r"(?P<fl>FL-)?(?P<spec>SPEC-)?C-by-C-(?P<selector>MAP|MMSE|MLM)",
    grammar="[FL-][SPEC-]C-by-C-(MAP|MMSE|MLM)",
    example="C-by-C-MMSE",
    description="Colour by Correlation in (r,g): MAP, MMSE, MLM (§4.5.4); FL-: fluorescent training (§7.2)",
    input_kind="surfaces",
)
def _build_chromaticity(world, match, **options):
    _training_world(match, options)
    return fit_chromaticity(world, match["selector"], **options)


@register(
    r"C-by-C-01",
    example="C-by-C-01",
    description="Colour by Correlation with the 0/1 hull matrix (§4.5.4)",
    input_kind="surfaces",
)
def _build_hull(world, match, **options):
    return fit_hull(world, **options)


@register(
    r"(?P<fl>FL-)?(?P<prefix>STD-|SPEC-)?RGB-C-by-C-(?P<selector>MAP|MMSE)(-(?P<method>counts|presence))?",
    grammar="[FL-][STD-|SPEC-]RGB-C-by-C-(MAP|MMSE)[-counts|-presence]",
    example="RGB-C-by-C-MMSE",
    description="3-D Colour by Correlation in (r,g,L), brightness too (ch. 10); -counts: remedy 1; FL-: fluorescent",
    input_kind="surfaces",
)
def _build_brightness(world, match, **options):
    _training_world(match, options)
    return fit_brightness(world, match["selector"], method=match["method"] or "presence", **options)


@register(
    r"soft-(?P<fl>FL-)?(?P<spec>SPEC-)?C-by-C-(?P<selector>MAP|MMSE)",
    grammar="soft-[FL-][SPEC-]C-by-C-(MAP|MMSE)",
    example="soft-C-by-C-MMSE",
    description="differentiable 2-D Colour by Correlation (soft bins, softmax posterior)",
    input_kind="surfaces",
    differentiable=True,
)
def _build_soft_chromaticity(world, match, **options):
    _training_world(match, options)
    options.setdefault("softness", DEFAULT_SOFTNESS)
    return fit_chromaticity(world, match["selector"], **options)


@register(
    r"soft-(?P<fl>FL-)?(?P<prefix>STD-|SPEC-)?RGB-C-by-C-(?P<selector>MAP|MMSE)(-(?P<method>counts|presence))?",
    grammar="soft-[FL-][STD-|SPEC-]RGB-C-by-C-(MAP|MMSE)[-counts|-presence]",
    example="soft-RGB-C-by-C-MMSE",
    description="differentiable 3-D Colour by Correlation (soft bins, softmax posterior)",
    input_kind="surfaces",
    differentiable=True,
)
def _build_soft_brightness(world, match, **options):
    _training_world(match, options)
    options.setdefault("softness", DEFAULT_SOFTNESS)
    return fit_brightness(world, match["selector"], method=match["method"] or "presence", **options)


__all__ = [
    "BRIGHTNESS_SIGMA",
    "DEFAULT_SOFTNESS",
    "DEFAULT_TEMPERATURE",
    "FLUORESCENT_FRACTION",
    "MLM_WIDTHS",
    "N_RG_CELLS",
    "RG_BINS",
    "ColourByCorrelation",
    "ColourByCorrelation01",
    "ColourByCorrelation3D",
    "brightness_matrix",
    "chromaticity_matrix",
    "compact_rg_cells",
    "fit_brightness",
    "fit_chromaticity",
    "fit_hull",
    "hull_matrix",
    "mlm_mask",
    "mlm_width_search",
    "presence_scores",
    "rg_bins",
    "soft_presence_scores",
    "training_responses",
    "tune_mlm_width",
]
