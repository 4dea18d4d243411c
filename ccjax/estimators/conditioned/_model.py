"""The any-camera estimator: one histogram model in the reference camera's space, bound to a
camera by its curves' map (:func:`ccjax.estimators.conditioned.reference_matrix`).

An image of camera C is mapped into the reference camera (``M_C x`` per pixel; a pixel whose mapped
colour leaves the positive octant is not counted), the FFCC model trained there
(:class:`~ccjax.estimators.ffcc.FFCC`: log-chroma histograms of pixels and edges, learned filters
and bias, von Mises fit) gives a posterior over the light in the reference space, shades of grey of
the mapped image is combined with it as a second, Gaussian observation
(:mod:`ccjax.estimators.conditioned._grey`), and ``M_C^-1`` takes the light back into C's raw
space. The model's weights do not depend on the camera: binding is a 3x3 from the
curves, no retraining.
"""

from __future__ import annotations

import typing
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ccjax.backends import block_scenes
from ccjax.camera import Camera
from ccjax.estimators.base import NO_PADDING_BRANCH, AbstractImageEstimator, Estimate, Padding
from ccjax.estimators.conditioned._grey import GreyObservation
from ccjax.estimators.conditioned._space import reference_matrix
from ccjax.estimators.ffcc import FFCC, uv_to_rgb
from ccjax.precision import matmul

__all__ = ["AnyCamera"]


@typing.final
class AnyCamera(AbstractImageEstimator):
    """One trained model for every camera (module docstring); :meth:`bind` gives it a camera.

    Attributes:
        core: the FFCC model of the reference camera's space.
        grey: shades of grey's observation of the light, combined with ``core``'s posterior
            (:class:`~ccjax.estimators.conditioned.GreyObservation`; zero precision: FFCC alone).
        matrix: ``(3, 3)`` the bound camera's map into the reference space (identity: unbound).
        camera: the bound camera's name (None: unbound; estimating then takes images as the
            reference camera's).
    """

    core: FFCC
    grey: GreyObservation
    matrix: Float[Array, "3 3"]
    camera: str | None = eqx.field(static=True, default=None)
    estimates_brightness: ClassVar[bool] = False
    world_based: ClassVar[bool] = False
    default_preprocessing: ClassVar[str] = "pixels"
    pools_pixels: ClassVar[bool] = False
    padding: ClassVar[Padding] = NO_PADDING_BRANCH

    def block_size(self, backend: str) -> int | None:
        """The backend's block (:func:`ccjax.backends.block_scenes`), as FFCC's.

        Arguments:
            backend: ``"cpu"``, ``"gpu"`` or ``"tpu"``.

        Returns:
            Images per vmapped block.
        """
        return block_scenes(backend)

    def bind(self, camera: Camera) -> AnyCamera:
        """This model for ``camera``: its map into the reference space from its curves.

        Arguments:
            camera: the camera whose images the model will be given.

        Returns:
            The bound model (same weights).
        """
        matrix = jnp.asarray(np.asarray(reference_matrix(camera), np.float32))
        return AnyCamera(core=self.core, grey=self.grey, matrix=matrix, camera=camera.name)

    def unbound(self) -> AnyCamera:
        """The model without a camera (the identity map): what a model file holds.

        Returns:
            The unbound model.
        """
        return AnyCamera(core=self.core, grey=self.grey, matrix=jnp.eye(3, dtype=self.matrix.dtype), camera=None)

    def __call__(self, image: Float[Array, "H W 3"], mask: Bool[Array, "H W"]) -> Estimate:
        mapped = matmul(image, self.matrix.T)
        usable = mask & jnp.all(mapped > 0, axis=-1)
        mapped = jnp.where(usable[..., None], mapped, 0.0)
        posterior = self.core.posterior(mapped, usable)
        observed, seen = self.grey.observe(mapped, usable)
        uv = self.grey.combine(posterior.mean, posterior.covariance, observed, seen & posterior.ok)
        light = jnp.linalg.solve(self.matrix, uv_to_rgb(uv))
        light = light / jnp.sum(light)
        return Estimate(illuminant=light, ok=posterior.ok & jnp.all(light > 0))
