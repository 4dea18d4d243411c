"""Deprecated: the 3-D kernel now lives in :mod:`ccjax.estimators.gamut.constraints_3d` and the
shared direction engine in :mod:`ccjax.estimators.gamut.engine` (kept for one release)."""

from ccjax.estimators.gamut.constraints_3d import Grid as Grid
from ccjax.estimators.gamut.constraints_3d import Observations as Observations
from ccjax.estimators.gamut.constraints_3d import evaluate as evaluate
from ccjax.estimators.gamut.constraints_3d import inverse_extent as inverse_extent
from ccjax.estimators.gamut.constraints_3d import observations as observations
from ccjax.estimators.gamut.constraints_3d import surface_violation as surface_violation
from ccjax.estimators.gamut.constraints_3d import violations as violations
from ccjax.estimators.gamut.engine import GridOptions as GridOptions
from ccjax.estimators.gamut.engine import cone_violation as cone_violation
from ccjax.estimators.gamut.engine import directions as directions
from ccjax.estimators.gamut.relaxation import relaxation_level as relaxation_level
