"""Running any estimator in sharpened space with the thesis' revert policy (Barnard 1999 §5.2,
§5.4, §5.6).

The input is sharpened (``x @ T``), an estimator fitted to the sharpened world estimates the
sharpened white ``e#``, and the answer is ``e# @ T^-1``. Where negative sharpened values make that
invalid for an algorithm that needs positive data (gamut mapping), the scene reverts to the
unsharpened answer: no clipping, offsetting or dropping (§5.2).
"""

from __future__ import annotations

import re
import typing
from collections.abc import Callable
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ccjax.estimators.base import AbstractEstimator, AbstractSurfaceEstimator, Estimate, Padding
from ccjax.precision import matmul
from ccjax.world import World

EstimatorFit = Callable[[World], AbstractEstimator]
"""``fit(world) -> estimator``: how :func:`sharpened` builds the inner and the plain models."""

_NEEDS_POSITIVE = re.compile(r"(^|-)(CRULE|ECRULE|CIP)(-|$)")


def sharpened_world(world: World, transform: Float[Array, "3 3"]) -> World:
    """The world seen through sensors ``Q @ T`` (Barnard 1999 §5.4).

    Every response (canonical gamut, training whites, database means) becomes ``x @ T``, which is
    how §5.4 runs an algorithm "entirely in sharpened space". Illuminants keep their
    (unsharpened) normalisation.

    Arguments:
        world: the unsharpened world.
        transform: ``(3, 3)`` sharpening ``T``.

    Returns:
        The world with sharpened sensors.
    """
    sensors = matmul(world.camera.sensors, jnp.asarray(transform, world.camera.sensors.dtype))
    return eqx.tree_at(lambda w: w.camera.sensors, world, sensors)


@typing.final
class Sharpened(AbstractSurfaceEstimator):
    """An estimator run in the space sharpened by ``transform`` (Barnard 1999 §5.4).

    The input is sharpened (``x @ T``), ``inner`` (fitted in the sharpened world) estimates the
    sharpened white ``e#``, and the answer is ``e# @ T^-1``. Where negative values make the
    sharpened run invalid — a non-positive sharpened training white, canonical white or canonical
    reflectance response (``calibration_ok`` False; every scene), a non-positive sharpened input
    (that scene), or the inner estimator failing (``ok`` False: no feasible map) — and
    ``requires_positive`` is set (gamut mapping), the scene reverts to ``plain``'s unsharpened
    answer (§5.2). :meth:`estimate_and_revert` also says whether a scene reverted.

    Attributes:
        inner: the estimator fitted to :func:`sharpened_world`.
        plain: the estimator fitted to the unsharpened world (the revert answer).
        transform: ``(3, 3)`` ``T``; ``inverse`` its inverse.
        calibration_ok: False where sharpened calibration data is non-positive.
        requires_positive: whether negative sharpened data forces a revert (static).
    """

    inner: AbstractSurfaceEstimator
    plain: AbstractSurfaceEstimator
    transform: Float[Array, "3 3"]
    inverse: Float[Array, "3 3"]
    calibration_ok: Bool[Array, ""]
    requires_positive: bool = eqx.field(static=True, default=False)

    world_based: ClassVar[bool] = True  # T is fitted to the world's camera
    pools_pixels: ClassVar[bool] = False

    @property
    def estimates_brightness(self) -> bool:  # pyright: ignore[reportIncompatibleVariableOverride]
        """What the wrapped method measures: a 3-D method's magnitude survives ``T ... T^-1``."""
        return self.plain.estimates_brightness

    @property
    def default_preprocessing(self) -> str:  # pyright: ignore[reportIncompatibleVariableOverride]
        """The wrapped method's input."""
        return self.plain.default_preprocessing

    @property
    def padding(self) -> Padding:  # pyright: ignore[reportIncompatibleVariableOverride]
        """Both runs' size branches (each scene runs ``inner`` and ``plain``)."""
        return Padding.combine([self.inner.padding, self.plain.padding])

    def block_size(self, backend: str) -> int | None:
        """One ``vmap`` over the whole batch on every backend.

        Arguments:
            backend: ``"cpu"``, ``"gpu"`` or ``"tpu"`` (not used).

        Returns:
            ``None``.
        """
        return None

    def estimate_and_revert(
        self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]
    ) -> tuple[Estimate, Bool[Array, ""]]:
        """Estimate one scene and say whether it reverted to the unsharpened answer (§5.2).

        Arguments:
            rgb: ``(P, 3)`` linear camera RGB (unsharpened).
            mask: ``(P,)`` True where a surface is valid.

        Returns:
            ``(estimate, reverted)``: the :class:`Estimate` in camera space (status and relaxation
            of the run that answered) and True where the scene reverted.
        """
        sharp = matmul(rgb, self.transform)
        inner = self.inner(sharp, mask)
        plain = self.plain(rgb, mask)
        estimate = matmul(inner.illuminant, self.inverse)
        if self.requires_positive:
            inputs_ok = jnp.all(jnp.where(mask[:, None], sharp > 0, True))
            valid = self.calibration_ok & inputs_ok & inner.ok
        else:
            valid = jnp.all(jnp.isfinite(estimate))
        result = Estimate(
            illuminant=jnp.where(valid, estimate, plain.illuminant),
            status=jnp.where(valid, inner.status, plain.status),
            relaxation=jnp.where(valid, inner.relaxation, plain.relaxation),
        )
        return result, ~valid

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        """Estimate the light of one scene in sharpened space (see the class docstring).

        Arguments:
            rgb: ``(P, 3)`` linear camera RGB (unsharpened).
            mask: ``(P,)`` True where a surface is valid.

        Returns:
            The :class:`Estimate` in camera space.
        """
        return self.estimate_and_revert(rgb, mask)[0]


def _surface_estimator(model: AbstractEstimator) -> AbstractSurfaceEstimator:
    # The input kind, not the class, decides: estimators written before the abstract surface type
    # declare input_kind "surfaces" without deriving from it.
    if model.input_kind != "surfaces":
        raise ValueError(f"estimator: sharpening runs surface-list estimators, got {type(model).__name__}")
    return typing.cast(AbstractSurfaceEstimator, model)


def estimator_fit(estimator: str | EstimatorFit) -> EstimatorFit:
    """``fit(world)`` for a registry label, or the given callable itself.

    Arguments:
        estimator: a registry label (``"DB-GW"``) or ``fit(world) -> estimator``.

    Returns:
        ``fit(world) -> estimator``.
    """
    if isinstance(estimator, str):
        from ccjax.estimators import registry

        return lambda w: registry.fit(estimator, w)
    if callable(estimator):
        return estimator
    raise ValueError(f"estimator: expected a label or a fit(world) callable, got {estimator!r}")


def sharpened(
    estimator: str | EstimatorFit,
    transform,
    world: World,
    *,
    requires_positive: bool | None = None,
    plain: AbstractEstimator | None = None,
) -> Sharpened:
    """Run any estimator in the space sharpened by ``transform`` with the revert policy
    (Barnard 1999 §5.2, §5.4).

    Arguments:
        estimator: a registry label (``"DB-GW"``, ``"ECRULE-ICA"``) or ``fit(world) -> estimator``;
            it is fitted twice: to the sharpened world (sensors ``Q @ T``) and to ``world``.
        transform: ``(3, 3)`` invertible ``T``.
        world: the (unsharpened) world.
        requires_positive: revert on negative sharpened data; default True for gamut-mapping
            labels (CRULE/ECRULE/CIP), the only algorithms the thesis saw revert (§5.2).
        plain: the unsharpened model if already fitted.

    Raises:
        ValueError: ``transform`` is not an invertible 3x3 matrix, or the estimator is not a
            surface-list estimator.

    Returns:
        A :class:`Sharpened` estimator. It works under ``jit``/``vmap``, and ``grad`` with respect
        to ``transform`` when the estimator's fit is traceable.
    """
    t = jnp.asarray(transform, dtype=world.canonical_rgb.dtype)
    if t.shape != (3, 3):
        raise ValueError(f"transform: expected shape (3, 3), got {t.shape}")
    try:  # concrete T: check at the boundary (traced T: the caller's job)
        concrete = np.asarray(t, np.float64)
    except jax.errors.TracerArrayConversionError:
        concrete = None
    if concrete is not None:
        condition = np.linalg.cond(concrete)
        if not np.isfinite(condition) or condition > 1e6:
            raise ValueError(f"transform: singular or badly conditioned (condition number {condition:.3g})")
    fit = estimator_fit(estimator)
    if requires_positive is None:
        requires_positive = isinstance(estimator, str) and bool(_NEEDS_POSITIVE.search(estimator))
    sharp = sharpened_world(world, t)
    # Calibration data that must be positive (§5.2): the sharpened whites (illumination
    # constraint, w_c# / e#) and the sharpened canonical gamut, whose hull must keep the origin as
    # its vertex in the positive octant (with negative points the feasible maps become unbounded
    # and gamut estimates collapse to near-black lights).
    calibration_ok = (
        jnp.all(sharp.train_whites > 0) & jnp.all(sharp.canonical_white > 0) & jnp.all(sharp.canonical_rgb > 0)
    )
    plain = _surface_estimator(fit(world) if plain is None else plain)
    try:
        inner = _surface_estimator(fit(sharp))
    except ValueError:
        # A fit that refuses negative sharpened calibration data (e.g. a gamut hull) cannot run in
        # this space at all: every scene reverts (§5.2; the thesis' DCS-200 "ave" rows).
        if not requires_positive:
            raise
        inner, calibration_ok = plain, jnp.asarray(False)
    return Sharpened(
        inner=inner,
        plain=plain,
        transform=t,
        inverse=jnp.linalg.inv(t),
        calibration_ok=calibration_ok,
        requires_positive=bool(requires_positive),
    )
