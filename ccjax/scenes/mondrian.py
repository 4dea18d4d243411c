"""Synthetic images: Mondrians rendered from a world's spectra (flat rectangular patches of
reflectances; Barnard 1999 §4.7 scenes laid out in space, for the image pipeline and spatial
methods).

Like the surface-list scenes, every image is a pure function of its key (image ``i`` uses
``fold_in(key, i)``), so batches are reproducible whatever their chunking.
"""

from __future__ import annotations

from functools import partial
from typing import SupportsIndex

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int, PRNGKeyArray

from ccjax.scenes.surfaces import (
    SceneKeys,
    SceneTables,
    ShotNoise,
    Specular,
    draw_without_replacement,
    require_count,
    resolve_options,
    scene_keys,
)
from ccjax.world import World


class MondrianImages(eqx.Module):
    """A batch of synthetic Mondrian images (flat rectangular patches of world reflectances).

    Attributes:
        image: ``(B, H, W, 3)`` linear camera RGB (non-negative; see :func:`render_mondrian`).
        illuminant: ``(B, 3)`` camera RGB of a perfect white under the image's light, on the
            image's scale (ground truth).
        labels: ``(B, H, W)`` patch index of every pixel.
        surfaces: ``(B, P)`` reflectance index of every patch.
    """

    image: Float[Array, "*batch H W 3"]
    illuminant: Float[Array, "*batch 3"]
    labels: Int[Array, "*batch H W"]
    surfaces: Int[Array, "*batch P"]


def _row_patch_counts(n_patches: int) -> list[int]:
    n_rows = max(1, int(round(n_patches**0.5)))
    return [n_patches // n_rows + (1 if row < n_patches % n_rows else 0) for row in range(n_rows)]


def _proportions(key: PRNGKeyArray, count: int) -> Float[Array, " N"]:
    # Shares 0.25 + U(0, 1), normalised: every patch visible, sizes differ by up to a factor 5
    # (a Dirichlet draw would do too, but its gamma sampler is slow to compile).
    shares = 0.25 + jax.random.uniform(key, (count,))
    return shares / jnp.sum(shares)


def mondrian_layout(key: PRNGKeyArray, height: int, width: int, n_patches: int) -> Int[Array, "H W"]:
    """A guillotine Mondrian: ``round(sqrt(P))`` horizontal bands of random heights, each cut
    into columns of random widths, ``n_patches`` rectangles in all (every one visible).

    Returns:
        ``(H, W)`` patch index per pixel, in ``0 .. n_patches - 1``.
    """
    counts = _row_patch_counts(n_patches)
    key_rows, *key_cols = jax.random.split(key, len(counts) + 1)
    y = (jnp.arange(height, dtype=float) + 0.5) / height
    x = (jnp.arange(width, dtype=float) + 0.5) / width
    row_edges = jnp.cumsum(_proportions(key_rows, len(counts)))[:-1]
    row = jnp.sum(y[:, None] >= row_edges[None, :], axis=1)  # (H,)
    labels = jnp.zeros((height, width), jnp.int32)
    offset = 0
    for index, count in enumerate(counts):  # a few bands: a static loop, not over pixels
        col_edges = jnp.cumsum(_proportions(key_cols[index], count))[:-1]
        col = jnp.sum(x[:, None] >= col_edges[None, :], axis=1)  # (W,)
        labels = jnp.where((row == index)[:, None], offset + col[None, :], labels)
        offset += count
    return labels


def render_mondrian(
    key: PRNGKeyArray,
    labels: Int[Array, "H W"],
    patch_rgb: Float[Array, "P 3"],
    white: Float[Array, "3"],
    *,
    shading: tuple[float, float] = (0.3, 1.0),
    specular: Specular | None = None,
    noise: ShotNoise | None = None,
    clip: float | None = None,
    normalise: bool = True,
) -> tuple[Float[Array, "H W 3"], Float[Array, "3"]]:
    """Render one Mondrian image from per-patch RGBs.

    Each patch ``i`` is ``s_i * rho_i`` with shading ``s_i ~ U(shading)``; with ``specular``, a
    patch is specular with ``specular.probability`` and gains a highlight, a Gaussian blob centred
    in the patch (width a quarter of the patch) of peak ``U(0, specular.max_amount) * s_i`` times
    the white (the dielectric model of §4.7, spread in space). With ``normalise`` the noise-free
    image is scaled so its brightest channel value is 1; ``noise`` adds Gaussian noise of variance
    ``a * rho + b`` (clamped at 0), after which the image is rescaled so its brightest value is
    exactly 1 again. ``clip`` saturates values above the level (a camera's full well).

    Returns:
        ``(image (H, W, 3), white (3,))``, the white on the image's scale.
    """
    height, width = labels.shape
    n_patches = patch_rgb.shape[0]
    key_shade, key_spec, key_amount, key_noise = jax.random.split(key, 4)
    shade = jax.random.uniform(key_shade, (n_patches,), minval=shading[0], maxval=shading[1])
    image = (shade[:, None] * patch_rgb)[labels]
    if specular is not None:
        is_specular = jax.random.uniform(key_spec, (n_patches,)) < specular.probability
        amount = jnp.where(is_specular, jax.random.uniform(key_amount, (n_patches,)) * specular.max_amount, 0.0) * shade
        yy, xx = jnp.meshgrid(
            jnp.arange(height, dtype=image.dtype), jnp.arange(width, dtype=image.dtype), indexing="ij"
        )
        one_hot = (labels[..., None] == jnp.arange(n_patches)).astype(image.dtype)  # (H, W, P); counts exact
        area = jnp.maximum(jnp.sum(one_hot, axis=(0, 1)), 1.0)
        centre_y = jnp.sum(one_hot * yy[..., None], axis=(0, 1)) / area
        centre_x = jnp.sum(one_hot * xx[..., None], axis=(0, 1)) / area
        spread = jnp.maximum(0.25 * jnp.sqrt(area.astype(image.dtype)), 1.0)
        blob = jnp.exp(-0.5 * ((yy - centre_y[labels]) ** 2 + (xx - centre_x[labels]) ** 2) / spread[labels] ** 2)
        image = image + (amount[labels] * blob)[..., None] * white
    if normalise:
        scale = 1.0 / jnp.maximum(jnp.max(image), 1e-12)
        image, white = image * scale, white * scale
    if noise is not None:
        sigma = jnp.sqrt(noise.a * image + noise.b)
        image = jnp.maximum(image + sigma * jax.random.normal(key_noise, image.shape, image.dtype), 0.0)
        if normalise:
            scale = 1.0 / jnp.maximum(jnp.max(image), 1e-12)
            image, white = image * scale, white * scale
    if clip is not None:
        image = jnp.minimum(image, clip)
    return image, white


@partial(jax.jit, static_argnames=("height", "width", "n_patches", "shading", "specular", "noise", "clip", "normalise"))
def mondrian_batch(
    keys: SceneKeys,
    tables: SceneTables,
    height: int,
    width: int,
    n_patches: int,
    shading: tuple[float, float] = (0.3, 1.0),
    specular: Specular | None = None,
    noise: ShotNoise | None = None,
    clip: float | None = None,
    normalise: bool = True,
) -> MondrianImages:
    """Mondrians for a batch of per-image keys ``(B,)``: a test illuminant and ``n_patches``
    reflectances (without replacement) per image, as :func:`sample_one` draws them."""

    def one(key):
        key_light, key_surf, key_layout, key_render = jax.random.split(key, 4)
        light = jax.random.randint(key_light, (), 0, tables.surface_rgb.shape[0])
        surfaces = draw_without_replacement(key_surf, tables.surface_rgb.shape[1], n_patches)
        labels = mondrian_layout(key_layout, height, width, n_patches)
        image, white = render_mondrian(
            key_render,
            labels,
            tables.surface_rgb[light, surfaces],
            tables.whites[light],
            shading=shading,
            specular=specular,
            noise=noise,
            clip=clip,
            normalise=normalise,
        )
        return MondrianImages(image=image, illuminant=white, labels=labels, surfaces=surfaces)

    return jax.vmap(one)(keys)


def sample_mondrians(
    key: PRNGKeyArray,
    world: World,
    n_images: SupportsIndex,
    *,
    height: SupportsIndex = 128,
    width: SupportsIndex = 128,
    n_patches: SupportsIndex = 16,
    shading: tuple[float, float] = (0.3, 1.0),
    specular: Specular | bool | None = None,
    noise: ShotNoise | bool | None = None,
    clip: float | None = None,
    normalise: bool = True,
) -> MondrianImages:
    """Draw synthetic Mondrian images rendered from the world's spectra.

    Arguments:
        key: a ``jax.random`` key (image ``i`` uses ``fold_in(key, i)``, as scenes do).
        world: reflectances, test illuminants and camera.
        n_images: number of images ``B``.
        height, width: image size in pixels.
        n_patches: patches per image (distinct reflectances).
        shading: range of the uniform per-patch shading factor.
        specular: ``True`` (thesis recipe: probability 0.25, up to 2 x white) or a :class:`Specular`.
        noise: ``True`` (chapter 3 model) or a :class:`ShotNoise` (variance ``a * rho + b`` on the
            image's scale, e.g. ``ShotNoise(a=1e-4, b=0)``).
        clip: saturation level on the image's scale (values above it are set to it).
        normalise: scale each image so its brightest value is 1.

    Returns:
        :class:`MondrianImages`.
    """
    n_reflectances = int(world.reflectances.shape[0])
    n_images = require_count(n_images, "n_images", 1)
    n_patches = require_count(n_patches, "n_patches", 1, n_reflectances)
    height = require_count(height, "height", 1)
    width = require_count(width, "width", 1)
    low, high = shading
    if not 0 <= low <= high:
        raise ValueError(f"shading: expected 0 <= low <= high, got {shading!r}")
    specular, noise = resolve_options(specular, noise, clip)
    tables = SceneTables.from_world(world)
    keys = scene_keys(key, 0, n_images)
    return mondrian_batch(
        keys, tables, height, width, n_patches, (float(low), float(high)), specular, noise, clip, normalise
    )
