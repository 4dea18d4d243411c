"""Deprecated: Colour in Perspective now lives in :mod:`ccjax.estimators.gamut.cip` (its
constraint set in :mod:`ccjax.estimators.gamut.constraints_cip`); kept for one release."""

from ccjax.estimators.gamut.cip import CIP as CIP
from ccjax.estimators.gamut.cip import CONES as CONES
from ccjax.estimators.gamut.cip import DEFAULT_ILLUMINATION as DEFAULT_ILLUMINATION
from ccjax.estimators.gamut.cip import ILLUMINATION as ILLUMINATION
from ccjax.estimators.gamut.cip import SELECTORS as SELECTORS
from ccjax.estimators.gamut.cip import fit as fit
