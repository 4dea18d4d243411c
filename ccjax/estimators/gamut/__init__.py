"""3-D gamut mapping: CRULE / ECRULE with MV, AVE, ICA and SCWIA-N (Barnard 1999 §2.3.4, §4.5.3,
ch. 6) on the matte canonical gamut or its extensions (ND §6.1, FL ch. 7, SP and MET §8.2, combined
as in ch. 9), computed by illuminant-direction integration.

Registered labels: ``[ND-](CRULE|ECRULE)-(MV|AVE|SCWIA-N)``, ``[ND-]ECRULE-ICA``, and the
differentiable ``soft-`` versions of each (options ``tau``, ``kappa``, ``beta``, ``margin``);
``(SP|MET)[k]-[ND-|FL-]BASE-SELECTOR`` and ``FL-BASE-SELECTOR`` (``k``: the specular multiplier,
8 by default; :mod:`._extensions`).
"""

from ccjax.estimators.gamut._constraints_3d import Grid, evaluate
from ccjax.estimators.gamut._engine import GridOptions
from ccjax.estimators.gamut._extensions import (
    MEASUREMENT_LIGHTS,
    Extension,
    characterised_fluorescents,
    default_fluorescent,
)
from ccjax.estimators.gamut._geometry import Facets, cone_planes, gamut_facets, nd_points
from ccjax.estimators.gamut._model import GamutMapping, GamutModel, estimate_all, fit
from ccjax.estimators.gamut._selectors import select
from ccjax.estimators.gamut._soft import SoftGamutMapping

__all__ = [
    "MEASUREMENT_LIGHTS",
    "Extension",
    "Facets",
    "GamutMapping",
    "GamutModel",
    "Grid",
    "GridOptions",
    "SoftGamutMapping",
    "characterised_fluorescents",
    "cip",
    "cone_planes",
    "default_fluorescent",
    "estimate_all",
    "evaluate",
    "fit",
    "gamut_facets",
    "nd_points",
    "select",
]


# ---------------------------------------------------------------------------------------------
# labels (Table 4.1, Table 6.1; the thesis' label grammar)

from ccjax.estimators.registry import register as _register

_SOFT_OPTIONS = ("tau", "kappa", "beta", "margin")


def _build(world, match, **options):
    groups = match.groupdict()
    extension = Extension.parse(
        tuple(groups[name].rstrip("-") for name in ("specular", "diagonal", "nd") if groups.get(name) is not None)
    )
    selector, power = match["selector"], 12.0
    if selector.startswith("SCWIA"):
        selector, power = "SCWIA", float(match["power"])
    if selector == "ICA" and match["base"] != "ECRULE":
        raise ValueError("method: ICA is the illumination-constrained average; CRULE has none (use CRULE-AVE)")
    soft_options = {name: options.pop(name) for name in _SOFT_OPTIONS if name in options}
    model = fit(world, constraint=match["base"], extension=extension, **options)
    if match.groupdict().get("soft"):
        return SoftGamutMapping(model, selector, power, **soft_options)
    if soft_options:
        raise ValueError(f"options: {sorted(soft_options)} apply to the soft- variants only")
    return GamutMapping(model, selector, power)


_BASE = r"(?P<base>CRULE|ECRULE)-(?P<selector>MV|AVE|ICA|SCWIA-(?P<power>\d+))"
_LABEL = r"(?P<nd>ND-)?" + _BASE

_register(
    _LABEL,
    "ND-ECRULE-SCWIA-12",
    "3-D gamut mapping [ND-](CRULE|ECRULE)-(MV|AVE|ICA|SCWIA-N) by direction integration (§4.5.3, ch. 6)",
    grammar="[ND-](CRULE|ECRULE)-(MV|AVE|ICA|SCWIA-N)",
    input_kind="surfaces",
)(_build)
_register(
    r"(?P<soft>soft-)" + _LABEL,
    "soft-ECRULE-SCWIA-12",
    "differentiable 3-D gamut mapping soft-[ND-](CRULE|ECRULE)-(MV|AVE|ICA|SCWIA-N) (options tau, kappa, beta, margin)",
    grammar="soft-[ND-](CRULE|ECRULE)-(MV|AVE|ICA|SCWIA-N)",
    input_kind="surfaces",
    differentiable=True,
)(_build)

_register(
    r"(?P<specular>(SP|MET)\d*-)(?P<diagonal>ND-|FL-)?" + _BASE,
    "SP-ND-ECRULE-SCWIA-6",
    "3-D gamut mapping with specular (SP) or metallic (MET) canonical-gamut extensions, "
    "optionally with ND or FL (§8.2, ch. 9)",
    grammar="(SP|MET)[k]-[ND-|FL-](CRULE|ECRULE)-(MV|AVE|ICA|SCWIA-N)",
    input_kind="surfaces",
)(_build)
_register(
    r"(?P<diagonal>FL-)" + _BASE,
    "FL-ECRULE-SCWIA-12",
    "3-D gamut mapping with the fluorescent (FL) canonical gamut: ND with fluorescent surfaces (ch. 7)",
    grammar="FL-(CRULE|ECRULE)-(MV|AVE|ICA|SCWIA-N)",
    input_kind="surfaces",
)(_build)

# The 2-D family (its labels register on import) after the 3-D ones, so the registry lists them in
# the thesis' order.
from ccjax.estimators.gamut import cip  # noqa: E402
