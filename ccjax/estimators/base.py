"""The estimator contract (DESIGN.md §2): a fitted model is an ``eqx.Module`` whose ``__call__``
estimates ONE scene, ``model(rgb (P, 3), mask (P,)) -> Estimate``; batching is ``jax.vmap``."""

from __future__ import annotations

import abc
import enum
import typing
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

TINY = 1e-12


class Status(enum.IntEnum):
    """Why an :class:`Estimate` is what it is (``Estimate.status``).

    ``ESTIMATED`` is the only status with ``ok=True``. ``RELAXED``: gamut mapping found no feasible
    illuminant and answered from the first relaxed constraint level that had one (thesis §4.3.2);
    ``NO_DATA``: no usable pixel (all masked, all zero), the answer is the model's fallback light;
    ``EMPTY_SET``: the method's feasible set stayed empty (every relaxation level), fallback light.
    """

    ESTIMATED = 0
    RELAXED = 1
    NO_DATA = 2
    EMPTY_SET = 3


@typing.final
class Estimate(eqx.Module):
    """An illuminant estimate; every estimator returns this one type.

    Attributes:
        illuminant: ``(..., 3)`` camera RGB of a perfect white under the estimated light. Its
            magnitude is meaningful for 3-D methods and arbitrary for chromaticity methods.
        ok: ``(...)`` True exactly where ``status == Status.ESTIMATED``.
        status: ``(...)`` int32 :class:`Status` code saying why.
        relaxation: ``(...)`` how far the method relaxed its constraints to find an answer (the
            gamut methods' level ``eps``; 0 for methods without relaxation).
    """

    illuminant: Float[Array, "... 3"]
    ok: Bool[Array, "..."]
    status: Int[Array, "..."]
    relaxation: Float[Array, "..."]

    def __init__(self, illuminant, ok=None, status=None, relaxation=None):
        """Build from ``status`` (``ok`` follows from it) or, for methods that only know whether
        they had data, from ``ok`` (``False`` means ``Status.NO_DATA``)."""
        self.illuminant = illuminant
        if status is None:
            if ok is None:
                raise ValueError("Estimate: give status or ok")
            status = jnp.where(ok, Status.ESTIMATED, Status.NO_DATA)
        self.status = jnp.asarray(status, jnp.int32)
        self.ok = self.status == Status.ESTIMATED
        if relaxation is None:
            relaxation = jnp.zeros(self.status.shape, jnp.result_type(illuminant))
        self.relaxation = jnp.asarray(relaxation)


class AbstractEstimator(eqx.Module):
    """A fitted estimator (DESIGN.md §2): configuration that changes the trace is static, what can
    be learned is an array, so every model is a valid ``jax.jit`` / ``jax.vmap`` / ``jax.grad``
    argument. Concrete estimators derive from :class:`AbstractSurfaceEstimator` or
    :class:`AbstractImageEstimator` and are final.

    Class attributes:
        input_kind: ``"surfaces"`` (a list of RGBs with a mask) or ``"image"`` (``(H, W, 3)``).
        estimates_brightness: True for 3-D methods whose estimate magnitude is meaningful (the
            RGB and R+G+B errors and the RGB mapping error apply to them).
        block_size: scenes per vmapped block in :func:`estimate_batch` (``None``: one ``vmap``
            over the whole batch). Kernels with a large per-scene working set set it so a
            block's intermediates stay in cache.
    """

    input_kind: ClassVar[str] = "surfaces"
    estimates_brightness: ClassVar[bool] = False
    block_size: ClassVar[int | None] = None


class AbstractSurfaceEstimator(AbstractEstimator):
    """An estimator of ONE scene given as a list of surface RGBs: ``model(rgb (P, 3), mask (P,))``."""

    input_kind: ClassVar[str] = "surfaces"

    @abc.abstractmethod
    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        """Estimate the light of one scene.

        Arguments:
            rgb: ``(P, 3)`` linear camera RGB, non-negative.
            mask: ``(P,)`` True where a surface is valid.

        Returns:
            The :class:`Estimate`.
        """


class AbstractImageEstimator(AbstractEstimator):
    """An estimator of ONE image: ``model(image (H, W, 3), mask (H, W))`` (spatial methods such as
    grey edge, which need the pixels' neighbours)."""

    input_kind: ClassVar[str] = "image"

    @abc.abstractmethod
    def __call__(self, image: Float[Array, "H W 3"], mask: Bool[Array, "H W"]) -> Estimate:
        """Estimate the light of one image.

        Arguments:
            image: ``(H, W, 3)`` linear camera RGB, non-negative.
            mask: ``(H, W)`` True where a pixel is usable.

        Returns:
            The :class:`Estimate`.
        """


Estimator = AbstractEstimator
"""Deprecated alias of :class:`AbstractEstimator` (kept for one release)."""


def estimate_batch(model: Estimator, rgb: Float[Array, "B P 3"], mask: Bool[Array, "B P"]) -> Estimate:
    """Estimate every scene of a batch: ``jax.vmap(model)(rgb, mask)``, computed in blocks.

    With ``model.block_size`` set, blocks of that many scenes are vmapped and the blocks mapped
    one after another (``jax.lax.map``), so each block's intermediates stay in cache: the gamut
    kernel's fine grid is ~2,000 directions per scene, and one vmap over 4,096 scenes streams
    every stage through memory (measured 1.2-1.4x slower at 8 and 64 surfaces). The results
    are those of the plain vmap.
    """
    size = getattr(type(model), "block_size", None)
    if size is None or rgb.shape[0] <= size:
        return jax.vmap(model)(rgb, mask)
    return jax.lax.map(lambda scene: model(*scene), (rgb, mask), batch_size=size)


def pairwise_reduce(values: Float[Array, "P ..."], op) -> Float[Array, "..."]:
    """Reduce over the leading axis by repeated halving, ``op(first half, second half)``.

    Equivalent to ``jnp.sum`` / ``jnp.max`` over axis 0 for ``op = jnp.add`` / ``jnp.maximum`` on
    non-negative data (odd lengths are padded with zeros), but each step is an element-wise op on
    contiguous blocks, which XLA vectorises well; a direct reduction over the surface axis with a
    trailing RGB axis of 3 does not (2–3x slower on CPU, measured in ``benchmarks/simple.py``).
    """
    while values.shape[0] > 1:
        if values.shape[0] % 2:
            values = jnp.concatenate([values, jnp.zeros((1, *values.shape[1:]), values.dtype)])
        half = values.shape[0] // 2
        values = op(values[:half], values[half:])
    return values[0]


def with_fallback(illuminant: Float[Array, "3"], usable, fallback: Float[Array, "3"]) -> Estimate:
    """Return ``illuminant`` where ``usable``, else ``fallback`` with ``ok=False`` (never NaN)."""
    usable = usable & jnp.all(jnp.isfinite(illuminant)) & (jnp.sum(illuminant) > TINY)
    safe = jnp.where(usable, jnp.nan_to_num(illuminant), fallback)
    return Estimate(illuminant=safe, ok=usable)


def validate_scene(rgb, mask, *, name: str = "rgb") -> tuple[np.ndarray, np.ndarray]:
    """Check estimator input at the Python boundary; raise ``ValueError`` naming the argument.

    Arguments:
        rgb: ``(P, 3)`` or ``(B, P, 3)`` non-negative finite floats.
        mask: ``None`` (all valid) or booleans of shape ``rgb.shape[:-1]``.

    Returns:
        ``(rgb, mask)`` as NumPy float32 / bool arrays.
    """
    array = np.asarray(rgb)
    if array.dtype == object or not (np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer)):
        raise ValueError(f"{name}: expected a real numeric array, got dtype {array.dtype}")
    if array.ndim not in (2, 3) or array.shape[-1] != 3:
        raise ValueError(f"{name}: expected shape (P, 3) or (B, P, 3), got {array.shape}")
    if array.shape[-2] == 0:
        raise ValueError(f"{name}: has no pixels (P = 0); pass a mask to mark missing data instead")
    array = array.astype(np.float32)
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    if np.any(array < 0):
        raise ValueError(f"{name}: contains negative values (linear camera RGB is non-negative)")
    if mask is None:
        mask_array = np.ones(array.shape[:-1], bool)
    else:
        mask_array = np.asarray(mask)
        if mask_array.dtype != bool:
            raise ValueError(f"mask: expected a boolean array, got dtype {mask_array.dtype}")
        if mask_array.shape != array.shape[:-1]:
            raise ValueError(f"mask: expected shape {array.shape[:-1]}, got {mask_array.shape}")
    return array, mask_array
