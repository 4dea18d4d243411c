"""How well a camera map reproduces the target camera: angular errors on held-back surfaces and on
whites, against the same spectra rendered through the target directly."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from ccjax.camera import Camera
from ccjax.metrics import angular_error
from ccjax.transfer._fit import SurfaceSelection, paired_responses, resolve_camera, surface_indices
from ccjax.transfer._maps import AbstractCameraMap
from ccjax.world import World


@dataclass(frozen=True)
class AngularStatistics:
    """Angular errors in degrees (Barnard 1999 §4.2, measure 1) summarised.

    Attributes:
        mean, median, max: of the errors, in degrees.
        count: how many errors.
    """

    mean: float
    median: float
    max: float
    count: int

    @classmethod
    def of(cls, errors: np.ndarray) -> AngularStatistics:
        errors = np.asarray(errors, np.float64).ravel()
        return cls(float(errors.mean()), float(np.median(errors)), float(errors.max()), int(errors.size))


@dataclass(frozen=True)
class MapAccuracy:
    """A camera map's accuracy on spectra it was not fitted on.

    Attributes:
        surfaces: errors of the mapped surfaces against the target's own rendering, one per
            (light, held-back surface) pair.
        whites: errors of the mapped white (:meth:`AbstractCameraMap.map_light`) against the
            target's white, one per light.
        negative: the share of mapped surfaces with a negative channel (kept by the map, masked
            by a caller that needs positive responses).
    """

    surfaces: AngularStatistics
    whites: AngularStatistics
    negative: float


class MapErrors(NamedTuple):
    """A camera map's errors item by item (degrees), for tables that split them (by light, say).

    Attributes:
        surfaces: ``(J, N)`` the error of each of ``N`` surfaces under each of ``J`` lights.
        whites: ``(J,)`` the error of each light's mapped white.
        negative: ``(J, N)`` True where the mapped surface has a negative channel.
    """

    surfaces: np.ndarray
    whites: np.ndarray
    negative: np.ndarray


def map_errors(
    camera_map: AbstractCameraMap,
    source: Camera | str,
    target: Camera | str,
    world: World,
    surfaces: SurfaceSelection,
    *,
    lights: Float[ArrayLike, "J 101"] | None = None,
) -> MapErrors:
    """Angular errors of ``camera_map`` on held-back surfaces and on whites, item by item.

    Each surface of ``surfaces`` under each light is rendered through both cameras (the same
    spectra); the source rendering is mapped with the matrix of its light
    (``camera_map.map_rgb(rgb, white)``, the white being the source camera's response to a
    perfect white under that light, as a ground truth is) and compared with the target's
    (:func:`ccjax.metrics.angular_error`). The whites: ``camera_map.map_light(white)`` against
    the target's white.

    Arguments:
        camera_map: the map, fitted for ``source`` -> ``target``.
        source, target: the cameras (or names), as the map was fitted for.
        world: the spectra (reflectances; lights unless ``lights`` is given).
        surfaces: the reflectances to measure on (boolean mask or indices), normally those held
            back from the fit (:func:`ccjax.transfer.held_back_surfaces`).
        lights: ``(J, 101)`` light spectra (default ``world.test_illuminants``: the denser set,
            not the training lights the maps are fitted on).

    Returns:
        The errors (degrees).
    """
    source_camera = resolve_camera("source", source)
    target_camera = resolve_camera("target", target)
    if (camera_map.source, camera_map.target) != (source_camera.name, target_camera.name):
        raise ValueError(
            f"camera_map: fitted for {camera_map.source!r} -> {camera_map.target!r}, "
            f"not {source_camera.name!r} -> {target_camera.name!r}"
        )
    reflectances = np.asarray(world.reflectances, np.float64)
    chosen = surface_indices(surfaces, reflectances.shape[0])
    spectra = np.asarray(world.test_illuminants if lights is None else lights, np.float64)
    if spectra.ndim != 2 or spectra.shape[1] != reflectances.shape[1] or spectra.shape[0] == 0:
        raise ValueError(f"lights: expected shape (J, {reflectances.shape[1]}) with J >= 1, got {spectra.shape}")
    rendered_source, rendered_target = paired_responses(source_camera, target_camera, reflectances[chosen], spectra)
    white_source, white_target = paired_responses(source_camera, target_camera, np.ones((1, spectra.shape[1])), spectra)
    as32 = lambda x: jax.device_put(np.asarray(x, np.float32))
    errors = _errors(
        camera_map, as32(rendered_source), as32(white_source[:, 0]), as32(rendered_target), as32(white_target[:, 0])
    )
    return MapErrors(*(np.asarray(x) for x in errors))


def map_accuracy(
    camera_map: AbstractCameraMap,
    source: Camera | str,
    target: Camera | str,
    world: World,
    surfaces: SurfaceSelection,
    *,
    lights: Float[ArrayLike, "J 101"] | None = None,
) -> MapAccuracy:
    """Angular-error statistics of ``camera_map`` on held-back surfaces and on whites: the
    summary of :func:`map_errors`.

    Arguments:
        camera_map: the map, fitted for ``source`` -> ``target``.
        source, target: the cameras (or names), as the map was fitted for.
        world: the spectra (reflectances; lights unless ``lights`` is given).
        surfaces: the reflectances to measure on, normally those held back from the fit.
        lights: ``(J, 101)`` light spectra (default ``world.test_illuminants``).

    Returns:
        The statistics (degrees) and the share of mapped surfaces with a negative channel.
    """
    errors = map_errors(camera_map, source, target, world, surfaces, lights=lights)
    return MapAccuracy(
        surfaces=AngularStatistics.of(errors.surfaces),
        whites=AngularStatistics.of(errors.whites),
        negative=float(np.mean(errors.negative)),
    )


@eqx.filter_jit  # one compilation instead of one per operation
def _errors(
    camera_map: AbstractCameraMap,
    rendered_source: Float[Array, "J N 3"],
    whites: Float[Array, "J 3"],
    rendered_target: Float[Array, "J N 3"],
    white_target: Float[Array, "J 3"],
) -> tuple[Float[Array, "J N"], Float[Array, " J"], Bool[Array, "J N"]]:
    mapped = jax.vmap(camera_map.map_rgb)(rendered_source, whites)
    mapped_whites = jax.vmap(camera_map.map_light)(whites)
    return (
        angular_error(mapped, rendered_target),
        angular_error(mapped_whites, white_target),
        jnp.any(mapped < 0, axis=-1),
    )
