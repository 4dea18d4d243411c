"""The relaxation ladder of gamut mapping and the status it gives an estimate (Barnard 1999 §4.3.2).

A direction is feasible at level ``eps`` when its normalised violation (a sine) is ``<= eps``. The
ladder is ``0``, then ``FIRST_LEVEL`` doubling for ``LEVELS`` steps; its last level (2.048) exceeds
1, the largest sine, so a scene with any bounded direction inside the chromaticity triangle always
finds a level. Scaling the canonical gamut or shifting its origin facets is not a relaxation: the
first scales the feasible set with it, the second makes every direction feasible at once.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ccjax.estimators.base import Status

FIRST_LEVEL = 1e-3
LEVELS = 12


def relaxation_level(
    violation: Float[Array, "..."], first: float = FIRST_LEVEL, levels: int = LEVELS
) -> tuple[Float[Array, "..."], Bool[Array, "..."]]:
    """The first ladder level not below ``violation``, and whether the ladder has none.

    Arguments:
        violation: the smallest violation over the directions considered.
        first, levels: the ladder ``0, first * 2^i`` for ``i < levels``.

    Returns:
        ``(level, failed)``; ``failed`` is True when ``violation`` exceeds the last level.
    """
    steps = jnp.ceil(jnp.log2(jnp.maximum(violation, first) / first))
    level = jnp.where(violation <= 0, 0.0, first * 2.0**steps)
    return level.astype(violation.dtype), (violation > 0) & (steps >= levels)


def status_of(usable: Bool[Array, ""], found: Bool[Array, ""], level: Float[Array, ""]) -> Int[Array, ""]:
    """The :class:`~ccjax.estimators.base.Status` of a gamut-mapping estimate.

    Arguments:
        usable: the scene has at least one usable observation.
        found: some level of the ladder had feasible directions and the selector's answer is finite.
        level: that level.

    Returns:
        ``NO_DATA`` without usable observations, ``EMPTY_SET`` when no level had a solution,
        ``RELAXED`` when the level is above 0, else ``ESTIMATED``.
    """
    return jnp.where(
        ~usable,
        Status.NO_DATA,
        jnp.where(~found, Status.EMPTY_SET, jnp.where(level > 0, Status.RELAXED, Status.ESTIMATED)),
    ).astype(jnp.int32)
