"""Fit-time helpers of the Colour by Correlation family: the on-disk cache of slow fits, option
checks and defaults."""

from __future__ import annotations

import jax
import numpy as np
from jaxtyping import Array, Float

from ccjax._cache import cached_arrays, content_key
from ccjax._colour import rg_numpy
from ccjax.scenes import Specular
from ccjax.world import World

_CACHE_VERSION = 2  # bump when a cached computation changes
DEFAULT_SOFTNESS = 0.1
"""Soft binning scale in bins: weights move from one bin to the next over about +-0.3 bins."""
DEFAULT_TEMPERATURE = 0.05
"""Soft MAP: softmax of the log-posterior divided by this (-> MAP as it -> 0)."""


def cached(kind: str, world: World, options: dict, compute) -> dict[str, np.ndarray]:
    """Load ``compute()``'s arrays for (``kind``, world, options) from the one ccjax cache
    (:func:`ccjax._cache.cached_arrays`, keyed by :func:`ccjax._cache.content_key` of the world and
    the options), else compute and store them.

    Arguments:
        kind: what is cached (``"rgb-matrix"``, ``"mlm-width"``, ...).
        world: the world the arrays are fitted to.
        options: JSON-able fit options.
        compute: builds the arrays on a miss.

    Returns:
        The arrays by name.
    """
    kind = f"correlation-{kind}"
    key = content_key(kind, _CACHE_VERSION, world, options)
    return cached_arrays(kind, key, compute, {"world": world.name, "options": options})


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
