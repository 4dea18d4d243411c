"""Fit-time helpers of the Colour by Correlation family: option checks and defaults (fitted models
are cached whole by :mod:`ccjax.runs.store`)."""

from __future__ import annotations

import jax
import numpy as np
from jaxtyping import Array, Float

from ccjax._colour import rg_numpy
from ccjax.scenes import Specular
from ccjax.world import World

DEFAULT_SOFTNESS = 0.1
"""Soft binning scale in bins: weights move from one bin to the next over about +-0.3 bins."""
DEFAULT_TEMPERATURE = 0.05
"""Soft MAP: softmax of the log-posterior divided by this (-> MAP as it -> 0)."""


def illuminant_rg_of(world: World) -> Float[Array, "I 2"]:
    """``(I, 2)`` (r,g) of the training illuminants' whites (float64 products, float32 result)."""
    whites = np.asarray(world.train_illuminants, np.float64) @ np.asarray(world.camera.sensors, np.float64)
    return jax.device_put(np.asarray(rg_numpy(whites), np.float32))


def resolve_specular(specular) -> Specular | None:
    if specular is True:
        return Specular()
    if specular in (None, False):
        return None
    if not isinstance(specular, Specular):
        raise ValueError(f"specular: expected True, False, None or a Specular, got {specular!r}")
    return specular


FLUORESCENT_FRACTION = 0.15
"""FL training (§7.2, §10.2): fluorescent surfaces are about 15 % of the training occurrences (the
thesis' 50x per surface gives 18 % with 1995 reflectances; A16/A20)."""


def resolve_fluorescent(fluorescent) -> float | None:
    """``None``/``False`` -> no FL training; ``True`` -> :data:`FLUORESCENT_FRACTION`; a number
    in (0, 1) -> that fraction of fluorescent occurrences."""
    if fluorescent is True:
        return FLUORESCENT_FRACTION
    if fluorescent in (None, False):
        return None
    if isinstance(fluorescent, bool) or not isinstance(fluorescent, (int, float)) or not 0 < fluorescent < 1:
        raise ValueError(f"fluorescent: expected True, False, None or a fraction in (0, 1), got {fluorescent!r}")
    return float(fluorescent)


def check_positive(name: str, value, *, allow_zero: bool = False) -> float:
    if not isinstance(value, (int, float)) or not (value >= 0 if allow_zero else value > 0):
        raise ValueError(f"{name}: expected a {'non-negative' if allow_zero else 'positive'} number, got {value!r}")
    return float(value)
