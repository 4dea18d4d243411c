"""2-D Colour by Correlation (Barnard 1999 §4.5.4): C-by-C-MAP, -MMSE, -MLM and C-by-C-01."""

from __future__ import annotations

import dataclasses
import typing
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ccjax._colour import rg_numpy, rg_to_rgb, valid_pixels
from ccjax.estimators.base import AbstractWorldSurfaceEstimator, Estimate, with_fallback
from ccjax.estimators.correlation._binning import RG_BINS, presence_scores, soft_presence_scores
from ccjax.estimators.correlation._fitting import (
    DEFAULT_TEMPERATURE,
    check_positive,
    illuminant_rg_of,
    resolve_fluorescent,
    resolve_specular,
)
from ccjax.estimators.correlation._matrices import chromaticity_matrix, hull_matrix
from ccjax.estimators.simple import average_illuminant
from ccjax.precision import device_array, matmul
from ccjax.world import World


@typing.final
class ColourByCorrelation(AbstractWorldSurfaceEstimator):
    """2-D Colour by Correlation with a probabilistic matrix (§4.5.4, eqs. 4.2–4.5).

    The scene's bins select matrix rows whose sum is the log-likelihood of each training illuminant;
    with uniform priors it is the log-posterior. ``MAP``: the most probable illuminant; ``MMSE``:
    the posterior mean (r,g); ``MLM``: the maximum of the posterior convolved with a Gaussian over
    the illuminants' (r,g) (``mlm_mask``). With ``softness`` set, bins are soft (gradients reach
    the input RGB) and MAP is the softmax-weighted mean at ``temperature``.

    Attributes:
        log_probability: ``(2500, I)`` log P(bin | illuminant) (the transposed correlation matrix).
        illuminant_rg: ``(I, 2)`` the training illuminants' chromaticities.
        fallback: estimate for a scene without valid pixels (``ok=False``).
        mlm_mask: ``(I, I)`` Gaussian weights between illuminants (MLM only).
    """

    log_probability: Float[Array, "C I"]
    illuminant_rg: Float[Array, "I 2"]
    fallback: Float[Array, "3"]
    mlm_mask: Float[Array, "I I"] | None = None
    selector: str = eqx.field(static=True, default="MMSE")
    mlm_width: float | None = eqx.field(static=True, default=None)
    softness: float | None = eqx.field(static=True, default=None)
    temperature: float = eqx.field(static=True, default=1.0)
    estimates_brightness: ClassVar[bool] = False

    def log_posterior(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Float[Array, " I"]:
        """Normalised log-posterior over the training illuminants (uniform prior).

        Arguments:
            rgb: ``(P, 3)`` the scene's surfaces.
            mask: ``(P,)`` the valid ones.

        Returns:
            ``(I,)`` the log-posterior.
        """
        valid = valid_pixels(rgb, mask)
        if self.softness is None:
            scores = presence_scores(self.log_probability, rgb, valid)
        else:
            scores = soft_presence_scores(self.log_probability, rgb, valid, self.softness)
        return jax.nn.log_softmax(scores)

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        log_posterior = self.log_posterior(rgb, mask)
        posterior = jnp.exp(log_posterior)
        if self.selector == "MMSE":
            rg = matmul(posterior, self.illuminant_rg)
        elif self.softness is not None:  # soft MAP: softmax of the log-posterior at a temperature
            rg = matmul(jax.nn.softmax(log_posterior / self.temperature), self.illuminant_rg)
        elif self.selector == "MAP":
            rg = self.illuminant_rg[jnp.argmax(posterior)]
        else:  # MLM
            assert self.mlm_mask is not None, "fit_chromaticity sets the MLM mask"
            rg = self.illuminant_rg[jnp.argmax(matmul(self.mlm_mask, posterior))]
        return with_fallback(rg_to_rgb(rg), jnp.any(valid_pixels(rgb, mask)), self.fallback)


@typing.final
class ColourByCorrelation01(AbstractWorldSurfaceEstimator):
    """C-by-C-01 (§4.5.4): a 0/1 matrix from the convex hulls of the reflectances' (r,g); an
    illuminant's score is the number of scene bins consistent with it; the estimate is the mean
    (r,g) of the illuminants whose score is within ``tolerance`` of the maximum (by default those
    within 1 of it).

    Attributes:
        compatible: ``(C, I)`` 0/1 matrix, bin ``C`` compatible with illuminant ``I``.
        illuminant_rg: ``(I, 2)`` the training illuminants' (r,g).
        fallback: ``(3,)`` the light answered for a scene without data.
        tolerance: scores within it of the maximum are averaged.
    """

    compatible: Float[Array, "C I"]
    illuminant_rg: Float[Array, "I 2"]
    fallback: Float[Array, "3"]
    tolerance: float = eqx.field(static=True, default=1.0)
    estimates_brightness: ClassVar[bool] = False

    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        valid = valid_pixels(rgb, mask)
        counts = presence_scores(self.compatible, rgb, valid)
        chosen = counts >= jnp.max(counts) - self.tolerance
        total = jnp.sum(jnp.where(chosen[:, None], self.illuminant_rg, 0.0), axis=0)
        rg = total / jnp.sum(chosen).astype(total.dtype)
        return with_fallback(rg_to_rgb(rg), jnp.any(valid), self.fallback)


def mlm_mask(illuminant_rg, width: float) -> Float[Array, "I I"]:
    """Gaussian weights ``exp(-|rg_i - rg_j|^2 / (2 (0.02 width)^2))`` between illuminants.

    Arguments:
        illuminant_rg: ``(I, 2)`` the illuminants' (r,g).
        width: the mask's width in (r,g) bins of 0.02.

    Returns:
        ``(I, I)`` weights.
    """
    rg = jnp.asarray(illuminant_rg)
    distance2 = jnp.sum((rg[:, None, :] - rg[None, :, :]) ** 2, axis=-1)
    return jnp.exp(-0.5 * distance2 / (width / RG_BINS) ** 2)


def fit_chromaticity(
    world: World,
    selector: str = "MMSE",
    *,
    sigma: float = 1.0,
    floor: float = 1e-6,
    specular=None,
    fluorescent=None,
    mlm_width: float | None = None,
    softness: float | None = None,
    temperature: float = DEFAULT_TEMPERATURE,
) -> ColourByCorrelation:
    """Fit 2-D C-by-C-MAP / -MMSE / -MLM (§4.5.4).

    Arguments:
        world: the world.
        selector: ``"MAP"``, ``"MMSE"`` or ``"MLM"``.
        sigma: matrix smoothing in bins (see :func:`chromaticity_matrix`).
        floor: probability floor (see :func:`chromaticity_matrix`).
        specular: train on specular surfaces as well (``SPEC-`` labels).
        fluorescent: FL training (``FL-`` labels, §7.2): ``True`` for fluorescent surfaces at
            about 15 % of the training occurrences, or that fraction.
        mlm_width: MLM mask width in bins; ``None`` chooses it as the thesis did (:func:`tune_mlm_width`).
        softness: soft binning (bins); ``None`` is the thesis' hard binning.
        temperature: soft MAP's softmax temperature on the log-posterior.

    Returns:
        The fitted :class:`ColourByCorrelation`.
    """
    if selector not in ("MAP", "MMSE", "MLM"):
        raise ValueError(f"selector: expected MAP, MMSE or MLM, got {selector!r}")
    sigma = check_positive("sigma", sigma, allow_zero=True)
    floor = check_positive("floor", floor)
    specular = resolve_specular(specular)
    fluorescent = resolve_fluorescent(fluorescent)
    if softness is not None:
        softness = check_positive("softness", softness)
        if selector == "MLM":
            raise ValueError("softness: the MLM selector has no soft variant")
    temperature = check_positive("temperature", temperature)
    matrix = chromaticity_matrix(world, sigma=sigma, floor=floor, specular=specular, fluorescent=fluorescent)
    model = ColourByCorrelation(
        log_probability=device_array(matrix),
        illuminant_rg=illuminant_rg_of(world),
        fallback=average_illuminant(world),
        selector=selector,
        softness=softness,
        temperature=temperature,
    )
    if selector == "MLM":
        if mlm_width is None:
            search = mlm_width_search(world, sigma=sigma, floor=floor, specular=specular, fluorescent=fluorescent)
            mlm_width = float(search["best"])
        mlm_width = check_positive("mlm_width", mlm_width)
        model = dataclasses.replace(model, mlm_mask=mlm_mask(model.illuminant_rg, mlm_width), mlm_width=mlm_width)
    return model


def mlm_width_search(
    world: World, *, sigma: float = 1.0, floor: float = 1e-6, specular=None, fluorescent=None
) -> dict[str, np.ndarray]:
    """The MLM mask-width search of :func:`tune_mlm_width` for the MMSE/MAP matrix with these
    options; ``["best"]`` is the width C-by-C-MLM uses (the validation scenes have no fluorescent
    surfaces, so FL-C-by-C-MLM's width is tuned for the matte world). It runs in the fit of
    C-by-C-MLM, whose fitted model :mod:`ccjax.runs.store` caches whole.

    Arguments:
        world: the world.
        sigma: matrix smoothing in bins.
        floor: probability floor.
        specular: specular training.
        fluorescent: FL training.

    Returns:
        The search of :func:`tune_mlm_width` (``widths``, ``mean_error``, ``mmse_mean_error``, ``best``).
    """
    specular = resolve_specular(specular)
    fluorescent = resolve_fluorescent(fluorescent)
    model = fit_chromaticity(world, "MMSE", sigma=sigma, floor=floor, specular=specular, fluorescent=fluorescent)
    return tune_mlm_width(world, model, specular=specular)


MLM_WIDTHS = (0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0, 6.0)
"""The candidate widths (in bins) :func:`tune_mlm_width` chooses the MLM blur from."""


def tune_mlm_width(
    world: World,
    model: ColourByCorrelation,
    *,
    widths=MLM_WIDTHS,
    n_scenes: int = 1000,
    n_surfaces: int = 8,
    seed: int = 1999,
    specular=None,
) -> dict[str, np.ndarray]:
    """Choose the MLM mask width as the thesis did (§4.5.4): the one with the least mean absolute
    (r,g) error on a synthetic validation set (the §4.7 protocol: a test illuminant and
    ``n_surfaces`` distinct reflectances per scene, drawn with NumPy from ``seed``, so independent
    of the sweeps' scenes).

    Returns:
        ``{"widths", "mean_error" (per width), "mmse_mean_error", "best"}``.

    Arguments:
        world: the world.
        model: the fitted MMSE/MAP estimator whose matrix the mask is applied to.
        widths: the candidate widths in bins.
        n_scenes: validation scenes.
        n_surfaces: surfaces per validation scene.
        seed: NumPy seed of the validation scenes.
        specular: specular validation scenes.
    """
    rng = np.random.default_rng(seed)
    sensors = np.asarray(world.camera.sensors, np.float64)
    lights = np.asarray(world.test_illuminants, np.float64)[rng.integers(0, world.test_illuminants.shape[0], n_scenes)]
    surfaces = np.argsort(rng.random((n_scenes, world.reflectances.shape[0])), axis=1)[:, :n_surfaces]
    reflectances = np.asarray(world.reflectances, np.float64)[surfaces]  # (B, P, 101)
    rgb = np.einsum("bpl,bl,lc->bpc", reflectances, lights, sensors)
    whites = lights @ sensors
    if specular is not None:
        shiny = rng.random(rgb.shape[:2]) < specular.probability
        rgb = rgb + (shiny * rng.uniform(0.0, specular.max_amount, rgb.shape[:2]))[..., None] * whites[:, None, :]
    rgb = jnp.asarray(rgb, jnp.float32)
    posterior = jnp.exp(jax.jit(jax.vmap(model.log_posterior))(rgb, jnp.ones(rgb.shape[:2], bool)))
    truth = jnp.asarray(rg_numpy(whites), jnp.float32)
    mean_error = []
    for width in widths:
        choice = jnp.argmax(matmul(posterior, mlm_mask(model.illuminant_rg, width).T), axis=1)
        mean_error.append(float(jnp.mean(jnp.linalg.norm(model.illuminant_rg[choice] - truth, axis=1))))
    mmse = float(jnp.mean(jnp.linalg.norm(matmul(posterior, model.illuminant_rg) - truth, axis=1)))
    return {
        "widths": np.asarray(widths, np.float64),
        "mean_error": np.asarray(mean_error),
        "mmse_mean_error": np.asarray(mmse),
        "best": np.asarray(widths[int(np.argmin(mean_error))], np.float64),
    }


def fit_hull(world: World, *, tolerance: float = 1.0) -> ColourByCorrelation01:
    """Fit C-by-C-01 (§4.5.4); ``tolerance``: scores within it of the maximum are averaged.

    Arguments:
        world: the world.
        tolerance: scores within it of the maximum are averaged.

    Returns:
        The fitted :class:`ColourByCorrelation01`.
    """
    tolerance = check_positive("tolerance", tolerance, allow_zero=True)
    return ColourByCorrelation01(
        compatible=jnp.asarray(hull_matrix(world)),
        illuminant_rg=illuminant_rg_of(world),
        fallback=average_illuminant(world),
        tolerance=tolerance,
    )
