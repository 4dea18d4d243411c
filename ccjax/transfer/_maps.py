"""Camera-to-camera maps: the abstract map and its two final forms (a global 3x3, a 3x3 per light).

Image formation (Barnard 1999 §2.2, §4.2): camera ``X`` sees surface ``S`` under light ``E`` as
``rho^X_k = sum_lambda E(lambda) S(lambda) R^X_k(lambda)``. Two cameras seeing the same scene
are related through their curves; over a world of reflectances and lights that relation is
close to linear, ``rho^B ~ M rho^A`` with ``M`` a 3x3 matrix, and closer still when ``M`` may
depend on the light (:class:`PerLightMap`). The maps are fitted in :mod:`ccjax.transfer._fit`.

Convention: a matrix ``M`` maps a column vector, ``rho^B = M rho^A``; on rows of RGB (images,
lists of surfaces) that is ``rgb @ M.T``.
"""

from __future__ import annotations

import abc
import typing

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ccjax._colour import rg
from ccjax.precision import einsum, matmul

# Below this (r,g) distance a light is a world light (float32 chromaticities agree to ~1e-7).
_SAME_LIGHT = 1e-6


def _as_float(values: ArrayLike, like: Array) -> Array:
    """``values`` as a JAX array in a floating dtype: floats keep theirs, integers (raw images)
    become ``like``'s dtype (the matrices' float32)."""
    values = jnp.asarray(values)
    return values if jnp.issubdtype(values.dtype, jnp.floating) else values.astype(like.dtype)


def _checked_light(light: ArrayLike, like: Array) -> Array:
    light = _as_float(light, like)
    if light.shape != (3,):
        raise ValueError(f"light: expected the source camera's RGB of a white, shape (3,), got {light.shape}")
    return light


class AbstractCameraMap(eqx.Module):
    """A map from camera ``source``'s raw RGB to camera ``target``'s, fitted from spectra.

    A labelled image and its ground truth are mapped alike: :meth:`map_rgb` applies to the
    image the matrix of the image's own light (:meth:`matrix_for` of its ground truth) and
    :meth:`map_light` applies the same matrix to the ground truth. Both are pure JAX
    (``jit``/``vmap``-able; the shapes are checked when traced).

    Mapped values can be negative (a 3x3 map of a saturated colour can leave the positive
    octant; measured on held-back surfaces in :func:`ccjax.transfer.map_accuracy`): they are
    returned as they are, never clipped, and a caller that needs positive responses masks them.

    Attributes:
        source: the source camera's name (for records and errors).
        target: the target camera's name.
    """

    source: str = eqx.field(static=True)
    target: str = eqx.field(static=True)

    @abc.abstractmethod
    def matrix_for(self, light: Float[ArrayLike, "3"]) -> Float[Array, "3 3"]:
        """The 3x3 map for a scene whose light is ``light``.

        Arguments:
            light: ``(3,)`` the source camera's RGB of a white under the scene's light, any
                scale (only its chromaticity is used).

        Returns:
            ``(3, 3)`` ``M``, mapping a source RGB column ``x`` to the target's ``M x``.
        """

    def map_rgb(self, rgb: Float[ArrayLike, "*shape 3"], light: Float[ArrayLike, "3"]) -> Float[Array, "*shape 3"]:
        """Source-camera RGB (an image, a list of surfaces) of a scene under ``light`` in the
        target camera's raw space: ``rgb @ matrix_for(light).T``.

        Linear in ``rgb`` (exposure and black level carry over; nothing is clipped: negative
        outputs are possible and left to the caller to mask).

        Arguments:
            rgb: ``(..., 3)`` linear source-camera RGB; integer images are taken as float32.
            light: ``(3,)`` the source camera's RGB of the scene's white (its ground truth).

        Returns:
            ``(..., 3)`` target-camera RGB, in ``rgb``'s float dtype.
        """
        matrix = self.matrix_for(light)
        rgb = _as_float(rgb, matrix)
        if rgb.ndim < 1 or rgb.shape[-1] != 3:
            raise ValueError(f"rgb: expected shape (..., 3) (RGB last), got {rgb.shape}")
        return matmul(rgb, matrix.T.astype(rgb.dtype))

    def map_light(self, light: Float[ArrayLike, "3"]) -> Float[Array, "3"]:
        """The ground truth in the target camera: ``matrix_for(light) @ light``, scaled so its
        largest channel is 1 (the scale ccjax's worlds give a white).

        The same matrix :meth:`map_rgb` applies to the image, so a white surface of the image is
        mapped to this white. A mapped white whose largest channel is not positive (no real
        light gives one) is divided by its largest ``|channel|`` instead; zero stays zero.

        Arguments:
            light: ``(3,)`` the source camera's RGB of a white under the scene's light.

        Returns:
            ``(3,)`` the target camera's RGB of that white, largest channel 1.
        """
        matrix = self.matrix_for(light)
        light = _checked_light(light, matrix)
        mapped = matmul(matrix.astype(light.dtype), light)
        peak = jnp.max(mapped)
        scale = jnp.where(peak > 0, peak, jnp.max(jnp.abs(mapped)))
        return mapped / jnp.where(scale > 0, scale, 1.0)


@typing.final
class GlobalMap(AbstractCameraMap):
    """One 3x3 map for every light: least squares over the world's reflectances under all its
    fitting lights.

    Attributes:
        source, target: the cameras' names.
        matrix: ``(3, 3)`` ``M`` (``target = M source``).
    """

    matrix: Float[Array, "3 3"]

    def __check_init__(self):
        if np.shape(self.matrix) != (3, 3):
            raise ValueError(f"matrix: expected shape (3, 3), got {np.shape(self.matrix)}")

    def matrix_for(self, light: Float[ArrayLike, "3"]) -> Float[Array, "3 3"]:
        """The one matrix.

        Arguments:
            light: ``(3,)`` the scene's light (checked, not used).

        Returns:
            ``(3, 3)`` the map.
        """
        _checked_light(light, self.matrix)
        return self.matrix


@typing.final
class PerLightMap(AbstractCameraMap):
    """One 3x3 map per world light, interpolated in the source camera's (r,g) chromaticity.

    For a scene light ``e`` with chromaticity ``c``, the ``k = neighbours`` world lights nearest
    to ``c`` (distances ``d_1 <= ... <= d_k``) are blended with the modified Shepard weights
    ``w_i = ((R - d_i)_+ / (R d_i))^2`` (Franke & Nielson 1980), where ``R`` is the distance to
    the ``(k+1)``-th nearest light. The weights are:

    * exact at a world light (``d_1 = 0``: that light's own matrix);
    * continuous in ``c`` (a light leaving the ``k`` nearest has weight 0 as it leaves), so two
      nearly equal ground truths get nearly equal maps;
    * convex: the blend never extrapolates, and outside the cloud of world lights it is a blend
      of the lights at the cloud's edge nearest ``c``, weighted towards the nearest.

    Attributes:
        source, target: the cameras' names.
        matrices: ``(L, 3, 3)`` one ``M`` per world light.
        light_chromaticities: ``(L, 2)`` each light's (r,g) in the source camera.
        neighbours: ``k``, how many world lights are blended (static; ``1 <= k < L``).
    """

    matrices: Float[Array, "L 3 3"]
    light_chromaticities: Float[Array, "L 2"]
    neighbours: int = eqx.field(static=True, default=6)

    def __check_init__(self):
        shape, chromaticities = np.shape(self.matrices), np.shape(self.light_chromaticities)
        if len(shape) != 3 or shape[1:] != (3, 3):
            raise ValueError(f"matrices: expected shape (L, 3, 3), got {shape}")
        if chromaticities != (shape[0], 2):
            raise ValueError(
                f"light_chromaticities: expected shape ({shape[0]}, 2) (one per matrix), got {chromaticities}"
            )
        if shape[0] < 2:
            raise ValueError(f"matrices: a per-light map needs at least 2 lights, got {shape[0]} (use GlobalMap)")
        if not 1 <= self.neighbours < shape[0]:
            raise ValueError(
                f"neighbours: expected 1 <= neighbours < {shape[0]} (the number of lights), got {self.neighbours}"
            )

    def weights(self, light: Float[ArrayLike, "3"]) -> Float[Array, " L"]:
        """Each world light's weight in :meth:`matrix_for` (non-negative, sum 1, at most
        ``neighbours`` of them non-zero).

        Arguments:
            light: ``(3,)`` the source camera's RGB of a white under the scene's light.

        Returns:
            ``(L,)`` weights.
        """
        light = _checked_light(light, self.matrices)
        offset = self.light_chromaticities - rg(light).astype(self.light_chromaticities.dtype)
        distance = jnp.sqrt(jnp.sum(offset * offset, axis=-1))
        negated, nearest = jax.lax.top_k(-distance, self.neighbours + 1)
        near, radius = -negated[:-1], -negated[-1]
        at_light = near[0] <= _SAME_LIGHT
        # Guarded divisions: d_i = 0 is the exact case below; R = 0 only when every light sits at c.
        safe_near = jnp.where(near > _SAME_LIGHT, near, 1.0)
        safe_radius = jnp.where(radius > 0, radius, 1.0)
        shepard = (jnp.maximum(radius - near, 0.0) / (safe_radius * safe_near)) ** 2
        total = jnp.sum(shepard)
        first = jnp.zeros_like(near).at[0].set(1.0)
        # Ties at R (every neighbour as far as the next light) leave no weight: the nearest decides.
        blend = jnp.where(at_light | (total <= 0), first, shepard / jnp.where(total > 0, total, 1.0))
        return jnp.zeros(self.matrices.shape[0], blend.dtype).at[nearest[:-1]].set(blend)

    def matrix_for(self, light: Float[ArrayLike, "3"]) -> Float[Array, "3 3"]:
        """The map for one light.

        Arguments:
            light: ``(3,)`` the scene's light in the source camera.

        Returns:
            ``(3, 3)`` the blend of the nearest world lights' matrices (weights: :meth:`weights`).
        """
        return einsum("l,lij->ij", self.weights(light), self.matrices)
