"""Correlation matrices as functions of the world (fit time, NumPy): the probabilistic 2-D matrix
and the 0/1 hull matrix of §4.5.4, and the 3-D (r, g, L) matrix of chapter 10."""

from __future__ import annotations

import numpy as np

from ccjax.estimators.correlation._binning import RG_BINS, compact_rg_cells, rg_bins_np
from ccjax.scenes import Specular
from ccjax.world import World

BRIGHTNESS_SIGMA = (0.75, 0.5)
"""Smoothing of the 3-D matrix in bins, (r,g) and L. The thesis gives none (§10.2); these
values reproduce Tables 10.1 and 10.2 best on World.barnard1999 (8 surfaces, 1000 scenes, rg RMS):
remedy 1 MAP/MMSE 0.0319/0.0264 (thesis 0.030/0.025), remedy 2 0.0252/0.0215 (0.029/0.024). With
(1, 1) they are 0.0404/0.0334 and 0.0316/0.0279; with (0.5, 0.5) 0.0304/0.0246 and 0.0254/0.0202."""


def training_responses(
    world: World, specular: Specular | None = None, steps: int = 8, fluorescent: float | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera RGB of every reflectance under every training illuminant, with frequency weights.

    Uniform statistics over surfaces and illuminants (§4.5.4, §10.2). With ``fluorescent`` (a
    fraction in (0, 1)), the characterised fluorescent surfaces
    (:func:`ccjax.estimators.gamut.characterised_fluorescents`) join the reflectances,
    weighted so that they are that fraction of all occurrences (FL training, §7.2, §10.2: "about
    15 %"). With ``specular``, each surface also appears with ``s`` times the perfect white
    added, ``s`` at the midpoints of 8 equal steps of ``[0, max_amount]``; the matte copy has
    weight ``1 - probability`` and each specular copy ``probability / 8`` of the surface's weight
    (a coarse model of the test generator, §10.2).

    Returns:
        ``(rgb (I, K, 3), weights (K,), whites (I, 3))`` in float64.

    Arguments:
        world: the world.
        specular: optional specular training recipe.
        steps: specular copies per surface.
        fluorescent: optional fraction of fluorescent occurrences.
    """
    sensors = np.asarray(world.camera.sensors, np.float64)
    lights = np.asarray(world.train_illuminants, np.float64)
    reflectances = np.asarray(world.reflectances, np.float64)
    whites = lights @ sensors
    lit = (lights[:, :, None] * sensors[None]).transpose(1, 0, 2).reshape(lights.shape[1], -1)  # (101, I*3)
    rgb = (reflectances @ lit).reshape(len(reflectances), len(lights), 3).transpose(1, 0, 2)  # one BLAS call
    weights = np.ones(rgb.shape[1])
    if fluorescent is not None:
        from ccjax import materials
        from ccjax.estimators.gamut import characterised_fluorescents

        radiance = np.asarray(characterised_fluorescents(world).radiance(lights), np.float64)  # (I, F, 101)
        share = materials.fluorescent_weights(len(reflectances), radiance.shape[1], fraction=fluorescent)
        rgb = np.concatenate([rgb, radiance @ sensors], axis=1)
        weights = np.concatenate([weights, np.full(radiance.shape[1], share.fluorescent)])
    if specular is not None:
        amounts = (np.arange(steps) + 0.5) / steps * specular.max_amount
        shiny = rgb[:, :, None, :] + amounts[None, None, :, None] * whites[:, None, None, :]
        rgb = np.concatenate([rgb, shiny.reshape(rgb.shape[0], -1, 3)], axis=1)
        weights = np.concatenate(
            [weights * (1.0 - specular.probability), np.repeat(weights, steps) * (specular.probability / steps)]
        )
    return rgb, weights, whites


def _log_of_smoothed(counts: np.ndarray, sigma: tuple[float, ...], floor: float) -> np.ndarray:
    """Per illuminant (axis 0): Gaussian smoothing (``sigma`` in bins per remaining axis), normalise
    to probabilities, floor at ``floor`` x the illuminant's largest probability, log (§4.5.4)."""
    from scipy.ndimage import gaussian_filter  # imported on use: slow to import

    counts = np.asarray(counts, np.float32)  # float32: the 3-D matrices are tens of millions of cells
    if any(s > 0 for s in sigma):
        counts = gaussian_filter(counts, sigma=(0.0, *sigma), mode="constant", truncate=4.0, output=np.float32)
    flat = counts.reshape(counts.shape[0], -1)
    probability = flat / flat.sum(axis=1, keepdims=True, dtype=np.float64).astype(np.float32)
    lowest = floor * probability.max(axis=1, keepdims=True)
    return np.log(np.maximum(probability, lowest))


def chromaticity_matrix(
    world: World,
    *,
    sigma: float = 1.0,
    floor: float = 1e-6,
    specular: Specular | None = None,
    fluorescent: float | None = None,
) -> np.ndarray:
    """The probabilistic 2-D correlation matrix (§4.5.4): per training illuminant, the frequency of
    the reflectances' (r,g) bins, smoothed with a Gaussian of ``sigma`` bins, as log-probabilities.

    Arguments:
        world: supplies reflectances, training illuminants and camera.
        sigma: Gaussian smoothing in bins (the thesis does not give it, §4.5.4).
        floor: probabilities below ``floor`` x the illuminant's maximum are raised to it before the
            log, so no observation rules an illuminant out completely.
        specular: train on specular surfaces too (see :func:`training_responses`).
        fluorescent: fraction of fluorescent occurrences in training (FL-, §7.2), or ``None``.

    Returns:
        ``(2500, I)`` float32 log-probabilities, row ``50 i + j`` for bin ``(i, j)``.
    """
    rgb, weights, _ = training_responses(world, specular, fluorescent=fluorescent)
    bins = rg_bins_np(rgb)
    n_lights = rgb.shape[0]
    flat = (np.arange(n_lights)[:, None] * RG_BINS + bins[..., 0]) * RG_BINS + bins[..., 1]
    counts = np.bincount(flat.ravel(), np.broadcast_to(weights, flat.shape).ravel(), n_lights * RG_BINS * RG_BINS)
    log_p = _log_of_smoothed(counts.reshape(n_lights, RG_BINS, RG_BINS), (sigma, sigma), floor)
    return log_p.T.astype(np.float32)


def hull_matrix(world: World) -> np.ndarray:
    """The 0/1 matrix of C-by-C-01 (§4.5.4): bin ``b`` is compatible with illuminant ``I`` when it
    lies in the convex hull of the reflectances' (r,g) under ``I`` — its centre is inside the hull
    or it holds one of those chromaticities (so the hull's own corners count).

    Returns:
        ``(2500, I)`` float32 of 0 and 1.

    Arguments:
        world: the world (reflectances, training illuminants, camera).
    """
    from scipy.spatial import ConvexHull, QhullError  # imported on use: slow to import

    rgb, _, _ = training_responses(world)
    i, j = np.divmod(np.arange(RG_BINS * RG_BINS), RG_BINS)
    centres = (np.stack([i, j], axis=1) + 0.5) / RG_BINS
    total = rgb.sum(axis=-1, keepdims=True)
    chromaticities = rgb[..., :2] / np.where(total > 0, total, 1.0)
    bins = rg_bins_np(rgb)
    compatible = np.zeros((RG_BINS * RG_BINS, rgb.shape[0]), np.float32)
    for light, points in enumerate(chromaticities):
        try:
            equations = ConvexHull(points).equations  # a . x + c <= 0 inside
            inside = np.all(centres @ equations[:, :2].T + equations[:, 2] <= 1e-12, axis=1)
        except QhullError:  # degenerate (collinear) chromaticities: only their own bins
            inside = np.zeros(len(centres), bool)
        inside[bins[light, :, 0] * RG_BINS + bins[light, :, 1]] = True
        compatible[inside, light] = 1.0
    return compatible


def brightness_matrix(
    world: World,
    *,
    l_bins: int = 50,
    sigma: float = BRIGHTNESS_SIGMA[0],
    sigma_l: float = BRIGHTNESS_SIGMA[1],
    floor: float = 1e-6,
    specular: Specular | None = None,
    specular_steps: int = 8,
    fluorescent: float | None = None,
) -> tuple[np.ndarray, int]:
    """The 3-D correlation matrix of chapter 10 (§10.2).

    For each training illuminant the reflectances' (r, g, L / L_white) are counted in cells
    (``l_bins`` linear bins per unit of ``L / L_white``; matte surfaces fill ``[0, 1)``, specular
    training extends the axis to ``1 + max_amount``; ``fluorescent``: the fraction of fluorescent
    occurrences of FL training, :func:`training_responses`), smoothed by a Gaussian (``sigma`` bins in r
    and g, ``sigma_l`` in L; :data:`BRIGHTNESS_SIGMA`), normalised, floored and logged.

    Returns:
        ``(log_probability (1275 * l_total + 1, I) float32, l_total)``; the last row is the
        outside cell, at each illuminant's floor.

    Arguments:
        world: the world.
        l_bins: L bins per unit of ``L / L_white``.
        sigma: Gaussian smoothing in (r,g) bins.
        sigma_l: Gaussian smoothing in L bins.
        floor: probability floor.
        specular: specular training (see :func:`training_responses`).
        specular_steps: specular copies per surface.
        fluorescent: FL training's fraction of fluorescent occurrences.
    """
    rgb, weights, whites = training_responses(world, specular, specular_steps, fluorescent)
    n_lights = rgb.shape[0]
    relative = rgb.sum(axis=-1) / whites.sum(axis=-1)[:, None]
    reach = 1.0 + (specular.max_amount if specular is not None else 0.0)
    l_total = int(np.ceil(max(reach, relative.max() * 1.0001) * l_bins))
    bins = rg_bins_np(rgb)
    level = np.floor(relative * l_bins).astype(np.int64)
    flat = ((np.arange(n_lights)[:, None] * RG_BINS + bins[..., 0]) * RG_BINS + bins[..., 1]) * l_total + level
    counts = np.bincount(
        flat.ravel(), np.broadcast_to(weights, flat.shape).ravel(), n_lights * RG_BINS * RG_BINS * l_total
    ).reshape(n_lights, RG_BINS * RG_BINS, l_total)
    log_p = _log_of_smoothed(counts.reshape(n_lights, RG_BINS, RG_BINS, l_total), (sigma, sigma, sigma_l), floor)
    log_p = log_p.reshape(n_lights, RG_BINS * RG_BINS, l_total)
    possible = compact_rg_cells() >= 0
    compact = log_p[:, possible, :].reshape(n_lights, -1)
    outside = log_p.min(axis=(1, 2))[:, None]  # the floor
    return np.concatenate([compact, outside], axis=1).T.astype(np.float32), l_total
