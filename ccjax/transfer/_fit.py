"""Fitting camera-to-camera maps by least squares on a world's spectra (Barnard 1999 §3–§4).

Both cameras see the SAME spectra: the world's reflectances under its lights, each product
integrated against each camera's curves. (A :class:`~ccjax.world.World` scales its lights for its
own camera; the scale is common to both sides of every pair here, so the map stays linear in the
signal and the fit does not depend on it.) The fit runs once, on the host, in float64 NumPy;
the maps it returns are float32 JAX PyTrees.
"""

from __future__ import annotations

import difflib
from typing import Literal

import jax
import numpy as np
from jaxtyping import ArrayLike, Bool, Float, Int

from ccjax._colour import rg_numpy
from ccjax.camera import Camera, cameras
from ccjax.spectra import N_WAVELENGTHS
from ccjax.transfer._maps import AbstractCameraMap, GlobalMap, PerLightMap
from ccjax.world import World, normalise_illuminants

# The condition number of a 3x3 normal matrix above which the surfaces do not span RGB (float64).
_SINGULAR = 1e12

SurfaceSelection = Bool[ArrayLike, " S"] | Int[ArrayLike, " N"] | None
"""Which of the world's reflectances to use: a boolean mask over them, integer indices, or
``None`` for all."""


def resolve_camera(argument: str, camera: Camera | str) -> Camera:
    """A :class:`~ccjax.camera.Camera` from a camera or a name ccjax can build.

    Arguments:
        argument: the caller's argument name (for the error).
        camera: a camera, or a name listed by :func:`ccjax.cameras`.

    Returns:
        The camera.

    Raises:
        ValueError: an unknown name (close names suggested) or neither a name nor a camera.
    """
    if isinstance(camera, Camera):
        return camera
    if not isinstance(camera, str):
        raise ValueError(f"{argument}: expected a Camera or a camera name, got {type(camera).__name__}")
    known = cameras()
    if camera not in known:
        close = difflib.get_close_matches(camera, list(known), n=3, cutoff=0.6)
        hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
        raise ValueError(
            f"{argument}: unknown camera {camera!r}{hint} ccjax.cameras() lists the {len(known)} names "
            "('Sony DXC-930' and 'Jiang: <model>' need the external data)"
        )
    return Camera.from_name(camera)


def held_back_surfaces(world: World, every: int = 5) -> np.ndarray:
    """The reflectances held back from a fit to measure it: every ``every``-th one (indices
    ``every - 1``, ``2 every - 1``, ...), so the held-back set samples the whole database.

    Arguments:
        world: the world whose reflectances are split.
        every: one in ``every`` is held back (at least 2).

    Returns:
        ``(S,)`` boolean mask, True where held back; fit on ``~mask``.
    """
    if every < 2:
        raise ValueError(f"every: expected at least 2 (one in `every` reflectances held back), got {every}")
    count = int(world.reflectances.shape[0])
    return np.arange(count) % every == every - 1


def surface_indices(surfaces: SurfaceSelection, count: int) -> np.ndarray:
    """Integer indices of the chosen reflectances (validated).

    Arguments:
        surfaces: a ``(count,)`` boolean mask, integer indices in ``[0, count)``, or ``None`` (all).
        count: how many reflectances the world has.

    Returns:
        ``(N,)`` sorted unique indices, at least 3 of them (a 3x3 fit needs three).
    """
    if surfaces is None:
        return np.arange(count)
    chosen = np.asarray(surfaces)
    if chosen.dtype == bool:
        if chosen.shape != (count,):
            raise ValueError(
                f"surfaces: a boolean mask must have shape ({count},) (one per reflectance), got {chosen.shape}"
            )
        indices = np.flatnonzero(chosen)
    elif np.issubdtype(chosen.dtype, np.integer) and chosen.ndim == 1:
        if chosen.size and (chosen.min() < 0 or chosen.max() >= count):
            raise ValueError(f"surfaces: indices must lie in [0, {count}), got {chosen.min()}..{chosen.max()}")
        indices = np.unique(chosen)
        if indices.size != chosen.size:
            raise ValueError("surfaces: repeated indices (each reflectance counts once)")
    else:
        raise ValueError(
            f"surfaces: expected a boolean mask or 1-D integer indices, got {chosen.dtype} of shape {chosen.shape}"
        )
    if indices.size < 3:
        raise ValueError(f"surfaces: a 3x3 fit needs at least 3 reflectances, got {indices.size}")
    return indices


def paired_responses(
    source: Camera, target: Camera, reflectances: np.ndarray, lights: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Both cameras' responses to the same colour signals, in float64 NumPy.

    Arguments:
        source, target: the cameras.
        reflectances: ``(S, 101)`` surfaces.
        lights: ``(L, 101)`` light spectra (one scale for both cameras).

    Returns:
        ``(L, S, 3)`` source and target responses (``rho_k = sum E S R_k``, Barnard 1999 eq. 4.1).
    """
    reflectances = np.asarray(reflectances, np.float64)
    lights = np.asarray(lights, np.float64)

    def render(camera: Camera) -> np.ndarray:
        lit_sensors = lights[:, :, None] * np.asarray(camera.sensors, np.float64)[None]  # (L, 101, 3)
        # One BLAS product (S, 101) x (101, 3L); einsum's loop took 0.2-1 s a camera.
        flat = reflectances @ np.moveaxis(lit_sensors, 1, 0).reshape(lit_sensors.shape[1], -1)
        return np.moveaxis(flat.reshape(reflectances.shape[0], lights.shape[0], 3), 1, 0)

    return render(source), render(target)


def _normal_equations(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``A^T A`` and ``A^T B`` over the last two axes (``(..., 3, 3)`` each)."""
    transposed = np.swapaxes(source, -1, -2)
    return transposed @ source, transposed @ target


def _solve(gram: np.ndarray, cross: np.ndarray) -> np.ndarray:
    """Row-convention least squares ``B ~ A X`` from the normal equations; returns ``X``."""
    condition = np.linalg.cond(gram)
    if np.any(~np.isfinite(condition) | (condition > _SINGULAR)):
        raise ValueError("surfaces: the chosen reflectances do not span the three channels (a singular fit)")
    return np.linalg.solve(gram, cross)


def _white_preserving(
    gram: np.ndarray, rows: np.ndarray, white_source: np.ndarray, white_target: np.ndarray
) -> np.ndarray:
    """The least-squares ``X`` subject to ``w_A X = w_B`` (the light's own white mapped exactly,
    as in white-point-preserving colour correction, Finlayson & Drew 1996): the Lagrange
    solution ``X = X0 - v lambda^T``, ``v = G^-1 w_A``, ``lambda = (w_A X0 - w_B) / (w_A . v)``,
    batched over lights."""
    v = np.linalg.solve(gram, white_source[..., None])[..., 0]  # (L, 3)
    residual = np.einsum("li,lij->lj", white_source, rows) - white_target  # (L, 3)
    scale = np.einsum("li,li->l", white_source, v)[:, None]
    return rows - v[:, :, None] * (residual / scale)[:, None, :]


def _fitting_lights(lights: World | ArrayLike, source: Camera) -> np.ndarray:
    """The fitting lights: a world's training lights, or given spectra validated and scaled for
    the source camera (white's largest channel 1, as a world scales its lights)."""
    if isinstance(lights, World):
        return np.asarray(lights.train_illuminants, np.float64)
    spectra = np.asarray(lights, np.float64)
    if spectra.ndim != 2 or spectra.shape[1] != N_WAVELENGTHS or spectra.shape[0] == 0:
        raise ValueError(f"lights: expected shape (L, {N_WAVELENGTHS}) with L >= 1, got {spectra.shape}")
    if not np.all(np.isfinite(spectra)) or np.any(spectra < 0):
        raise ValueError("lights: expected finite, non-negative spectra")
    return normalise_illuminants(spectra, np.asarray(source.sensors, np.float64))


def fit_camera_map(
    source: Camera | str,
    target: Camera | str,
    *,
    kind: Literal["global", "per-light"] = "per-light",
    world: World | None = None,
    surfaces: SurfaceSelection = None,
    neighbours: int = 6,
    white_preserving: bool = True,
    lights: Float[ArrayLike, "L 101"] | None = None,
) -> AbstractCameraMap:
    """Fit a map from ``source``'s raw RGB to ``target``'s on the spectra of a world.

    The data: the world's reflectances (``surfaces`` of them) under its training lights
    (``world.train_illuminants``: one light per 0.02 cell of (r,g), measured lights first, the
    set the thesis fits every estimator on), rendered through both cameras from the same spectra.
    The world's denser test lights (0.01 cells, other mixtures) stay out of the fit, so that
    :func:`ccjax.transfer.map_accuracy` measures the per-light interpolation on lights it was not
    fitted on.

    * ``"global"``: one least-squares 3x3 over every light and surface (:class:`GlobalMap`).
    * ``"per-light"``: one 3x3 per training light (:class:`PerLightMap`), each fitted on that
      light's surfaces; with ``white_preserving`` each maps its own light's white exactly (a
      constrained least squares), since a ground truth is mapped as a white is. Measured on
      held-back surfaces and test lights (``benchmarks/camera_maps.py``), it lowers the whites'
      error of the global map by 20–50 % and the surfaces' by 10–30 %.

    Arguments:
        source: the camera whose RGB is mapped (a :class:`~ccjax.camera.Camera` or a name from
            :func:`ccjax.cameras`).
        target: the camera it is mapped to.
        kind: ``"global"`` or ``"per-light"``.
        world: the spectra (reflectances and lights; its camera is not used); default
            ``World.default(camera=source)``, whose lights are placed in source (r,g) cells.
        surfaces: the reflectances to fit on (boolean mask or indices; default all). Hold some
            back to measure the map (:func:`held_back_surfaces`).
        neighbours: for ``"per-light"``, how many world lights each scene's map blends.
        white_preserving: for ``"per-light"``, map each light's own white exactly.
        lights: ``(L, 101)`` light spectra to fit on instead of the world's training lights, e.g.
            :func:`ccjax.transfer.locus_lights` (each is scaled, as a world's lights are, so the
            source camera's white has largest channel 1: the weight of each light in a global fit).

    Returns:
        The map (a :class:`GlobalMap` or a :class:`PerLightMap`), float32.
    """
    source_camera = resolve_camera("source", source)
    target_camera = resolve_camera("target", target)
    if kind not in ("global", "per-light"):
        raise ValueError(f"kind: expected 'global' or 'per-light', got {kind!r}")
    if world is None:
        world = World.default(camera=source_camera)
    reflectances = np.asarray(world.reflectances, np.float64)
    chosen = surface_indices(surfaces, reflectances.shape[0])
    lights = _fitting_lights(world if lights is None else lights, source_camera)
    rendered_source, rendered_target = paired_responses(source_camera, target_camera, reflectances[chosen], lights)
    gram, cross = _normal_equations(rendered_source, rendered_target)
    names = {"source": source_camera.name, "target": target_camera.name}
    as32 = lambda x: jax.device_put(np.asarray(x, np.float32))
    if kind == "global":
        rows = _solve(gram.sum(axis=0), cross.sum(axis=0))
        return GlobalMap(matrix=as32(rows.T), **names)
    if not 1 <= neighbours < lights.shape[0]:
        raise ValueError(
            f"neighbours: expected 1 <= neighbours < {lights.shape[0]} (the fitting lights), got {neighbours}"
        )
    rows = _solve(gram, cross)
    white_source, white_target = paired_responses(source_camera, target_camera, np.ones((1, lights.shape[1])), lights)
    if white_preserving:
        rows = _white_preserving(gram, rows, white_source[:, 0], white_target[:, 0])
    return PerLightMap(
        matrices=as32(np.swapaxes(rows, 1, 2)),
        light_chromaticities=as32(rg_numpy(white_source[:, 0])),
        neighbours=neighbours,
        **names,
    )
