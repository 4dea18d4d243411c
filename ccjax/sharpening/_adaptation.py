"""The standard chromatic adaptation transforms (Bradford, CAT02, CAT16) as sharpening transforms,
for comparison with the sharpening methods of Barnard 1999 ch. 5.

A chromatic adaptation transform (CAT) is a von Kries model in a sharpened space of XYZ: ``M``
maps XYZ (columns) to cone-like responses, where the white pair gives a diagonal map. A camera
sees RGB, not XYZ, so the transform needs the camera -> XYZ map ``C`` (``xyz = rgb @ C``, rows);
then ``T = C @ M^T`` is a sharpening transform like any other: ``rgb @ T`` are the CAT's
responses and ``T diag(d#) T^-1`` its adaptation in camera space. The matrices ``M`` are
colour-science's (``colour.adaptation.CHROMATIC_ADAPTATION_TRANSFORMS``).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ccjax.precision import matmul
from ccjax.sharpening._transforms import best_linear_map
from ccjax.world import World

ADAPTATION_TRANSFORMS = ("Bradford", "CAT02", "CAT16")
"""The standard adaptation transforms compared with the sharpening methods (``ccjax sharpen
--method``); :func:`adaptation_sharpening` takes any name of colour-science's
``CHROMATIC_ADAPTATION_TRANSFORMS`` (``"Sharp"``, ``"Von Kries"``, ...)."""


def _observer(dtype) -> Array:
    """The CIE 1931 2° colour matching functions on the ccjax grid, ``(101, 3)``."""
    import colour  # imported here: colour-science is slow to import

    from ccjax.spectra import resample

    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    return jnp.asarray(resample(np.asarray(cmfs.wavelengths), np.asarray(cmfs.values), kind="sensor"), dtype)


def camera_to_xyz(world: World) -> Float[Array, "3 3"]:
    """The camera -> CIE XYZ map ``C`` (``xyz ~ rgb @ C``), fitted on the world's surfaces.

    The fit is least squares over every reflectance of ``world`` under its canonical light and each
    training light: camera responses (:meth:`World.responses`) against the CIE 1931 2° XYZ of the
    same colour signals (reflectance times light), with the canonical white's ``Y`` at 1. The
    products go through :func:`ccjax.precision.matmul` (``precision=HIGHEST``: the same numbers on
    CPU and GPU), in the world's dtype.

    Arguments:
        world: the world (reflectances, canonical and training lights, camera).

    Returns:
        ``(3, 3)`` ``C``: row ``k`` is how camera channel ``k`` contributes to X, Y and Z.
    """
    dtype = world.canonical_rgb.dtype
    observer = _observer(dtype)
    lights = jnp.concatenate([world.canonical[None], world.train_illuminants]).astype(dtype)
    signals = world.reflectances[None] * lights[:, None, :]
    camera = world.responses(lights).reshape(-1, 3)
    xyz = matmul(signals, observer).reshape(-1, 3) / matmul(world.canonical.astype(dtype), observer)[1]
    return best_linear_map(camera, xyz)


def cat_matrix(name: str) -> np.ndarray:
    """The XYZ -> cone-response matrix ``M`` of a chromatic adaptation transform (colour-science's).

    Arguments:
        name: a name of ``colour.adaptation.CHROMATIC_ADAPTATION_TRANSFORMS``, e.g. ``"CAT02"``
            (:data:`ADAPTATION_TRANSFORMS`: the standard three).

    Returns:
        ``(3, 3)`` NumPy float64 ``M`` (``lms = M @ xyz``, columns).

    Raises:
        ValueError: an unknown name (the known ones are listed).
    """
    import colour  # imported here: colour-science is slow to import

    known = colour.adaptation.CHROMATIC_ADAPTATION_TRANSFORMS
    if name not in known:
        raise ValueError(f"name: unknown adaptation transform {name!r}; expected one of {sorted(known)}")
    return np.asarray(known[name], np.float64)


def adaptation_sharpening(world: World, name: str = "CAT02") -> Float[np.ndarray, "3 3"]:
    """A chromatic adaptation transform as a sharpening transform of the world's camera:
    ``T = C @ M^T`` with ``C`` = :func:`camera_to_xyz` (fitted on the world's surfaces) and ``M``
    the transform's matrix (:func:`cat_matrix`).

    ``rgb @ T`` are the CAT's responses of the camera's (fitted) XYZ, so a diagonal map there is
    von Kries adaptation with that CAT. ``T`` is usable wherever a sharpening transform is:
    :func:`sharpened`, :func:`mapping_error`, ``ccjax sharpen --method cat02``.

    Arguments:
        world: the world whose camera is mapped to XYZ.
        name: ``"Bradford"``, ``"CAT02"``, ``"CAT16"`` (:data:`ADAPTATION_TRANSFORMS`), or another
            name of colour-science's ``CHROMATIC_ADAPTATION_TRANSFORMS``.

    Returns:
        ``(3, 3)`` ``T``, NumPy float64 (as every sharpening method's transform:
        :func:`database_sharpening`, :func:`optimal_sharpening`, :func:`new_sharpening`,
        :func:`learned_sharpening`).

    Examples:
        >>> from ccjax import World, sharpening
        >>> world = World.default()
        >>> transform = sharpening.adaptation_sharpening(world, "Bradford")
        >>> model = sharpening.sharpened("GW", transform, world)  # grey world in Bradford space
        >>> transform.shape, transform.dtype
        ((3, 3), dtype('float64'))
    """
    return np.asarray(camera_to_xyz(world), np.float64) @ cat_matrix(name).T
