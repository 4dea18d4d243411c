"""Synthetic images: Mondrians rendered from a world's spectra (flat rectangular patches of
reflectances; Barnard 1999 §4.7 scenes laid out in space, for the image pipeline and spatial
methods).

Like the surface-list scenes, every image is a pure function of its key (image ``i`` uses
``fold_in(key, i)``), so batches are reproducible whatever their chunking. The material options of
:mod:`ccjax.scenes._surfaces` apply here too: fluorescent patches (:class:`Fluorescent`, §7.3) and
metallic highlights (:class:`Metallic`, §8.3: a highlight blob coloured by the metal), their draws
folded off the image key so that images without them are unchanged.
"""

from __future__ import annotations

from functools import partial
from typing import SupportsIndex

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, Int, PRNGKeyArray

from ccjax.scenes import _draws as draws_
from ccjax.scenes._options import (
    Fluorescent,
    Metallic,
    SceneOptions,
    ShotNoise,
    Specular,
    require_count,
    resolve_materials,
    resolve_options,
)
from ccjax.scenes._surfaces import (
    FLUORESCENT_STREAM,
    METAL_STREAM,
    SceneKeys,
    draw_without_replacement,
    scene_keys,
)
from ccjax.scenes._tables import RadianceModel, SceneTables, default_fluorescent, require_tables
from ccjax.world import World


class MondrianImages(eqx.Module):
    """A batch of synthetic Mondrian images (flat rectangular patches of world reflectances).

    Attributes:
        image: ``(B, H, W, 3)`` linear camera RGB (non-negative; see :func:`render_mondrian`).
        illuminant: ``(B, 3)`` camera RGB of a perfect white under the image's light, on the
            image's scale (ground truth).
        labels: ``(B, H, W)`` patch index of every pixel.
        surfaces: ``(B, P)`` reflectance index of every patch (drawn even where the patch is
            fluorescent).
        fluorescent: ``(B, P)`` index into the fluorescent surfaces, -1 for an ordinary patch
            (``None`` without the fluorescent option).
        light: ``(B,)`` int32 index of each image's light among the tables' lights (the world's
            test illuminants, or its training ones with ``lights="train"``); ``None`` where unknown.
        shading: the range of the per-patch shading the images were rendered with (static).
        options: the :class:`SceneOptions` they were rendered with: highlights, noise, clipping,
            metallic highlights, fluorescent surfaces (static), which
            :func:`ccjax.augment.relight_mondrians` renders again unless told otherwise.
        normalise: whether each image was scaled so its brightest value is 1 (static).
    """

    image: Float[Array, "*batch H W 3"]
    illuminant: Float[Array, "*batch 3"]
    labels: Int[Array, "*batch H W"]
    surfaces: Int[Array, "*batch P"]
    fluorescent: Int[Array, "*batch P"] | None = None
    light: Int[Array, "*batch"] | None = None
    shading: tuple[float, float] = eqx.field(static=True, default=(0.3, 1.0))
    options: SceneOptions = eqx.field(static=True, default=SceneOptions())
    normalise: bool = eqx.field(static=True, default=True)


def _row_patch_counts(n_patches: int) -> list[int]:
    n_rows = max(1, int(round(n_patches**0.5)))
    return [n_patches // n_rows + (1 if row < n_patches % n_rows else 0) for row in range(n_rows)]


def _proportions(key: PRNGKeyArray, count: int) -> Float[Array, " N"]:
    # Shares 0.25 + U(0, 1), normalised: every patch visible, sizes differ by up to a factor 5
    # (a Dirichlet draw would do too, but its gamma sampler is slow to compile).
    shares = 0.25 + draws_.uniform(key, (count,))
    return shares / jnp.sum(shares)


def mondrian_layout(key: PRNGKeyArray, height: int, width: int, n_patches: int) -> Int[Array, "H W"]:
    """A guillotine Mondrian: ``round(sqrt(P))`` horizontal bands of random heights, each cut
    into columns of random widths, ``n_patches`` rectangles in all (every one visible).

    Arguments:
        key: PRNG key of the layout.
        height, width: image size in pixels.
        n_patches: number of rectangles.

    Returns:
        ``(H, W)`` patch index per pixel, in ``0 .. n_patches - 1``.
    """
    counts = _row_patch_counts(n_patches)
    key_rows, *key_cols = jax.random.split(key, len(counts) + 1)
    # float32 under x64 too: the same layout whatever the precision.
    y = (jnp.arange(height, dtype=jnp.float32) + 0.5) / height
    x = (jnp.arange(width, dtype=jnp.float32) + 0.5) / width
    row_edges = jnp.cumsum(_proportions(key_rows, len(counts)))[:-1]
    row = jnp.sum(y[:, None] >= row_edges[None, :], axis=1)  # (H,)
    labels = jnp.zeros((height, width), jnp.int32)
    offset = 0
    for index, count in enumerate(counts):  # a few bands: a static loop, not over pixels
        col_edges = jnp.cumsum(_proportions(key_cols[index], count))[:-1]
        col = jnp.sum(x[:, None] >= col_edges[None, :], axis=1, dtype=jnp.int32)  # (W,)
        labels = jnp.where((row == index)[:, None], offset + col[None, :], labels)
        offset += count
    return labels


def _highlight_blobs(labels: Int[Array, "H W"], n_patches: int, dtype) -> Float[Array, "H W"]:
    """Per pixel, a Gaussian blob centred in its patch (width a quarter of the patch's size), peak 1."""
    height, width = labels.shape
    yy, xx = jnp.meshgrid(jnp.arange(height, dtype=dtype), jnp.arange(width, dtype=dtype), indexing="ij")
    one_hot = (labels[..., None] == jnp.arange(n_patches, dtype=labels.dtype)).astype(dtype)  # (H, W, P); counts exact
    area = jnp.maximum(jnp.sum(one_hot, axis=(0, 1)), 1.0)
    centre_y = jnp.sum(one_hot * yy[..., None], axis=(0, 1)) / area
    centre_x = jnp.sum(one_hot * xx[..., None], axis=(0, 1)) / area
    spread = jnp.maximum(0.25 * jnp.sqrt(area.astype(dtype)), 1.0)
    return jnp.exp(-0.5 * ((yy - centre_y[labels]) ** 2 + (xx - centre_x[labels]) ** 2) / spread[labels] ** 2)


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
    metallic: Metallic | None = None,
    metal_rgb: Float[Array, "M 3"] | None = None,
) -> tuple[Float[Array, "H W 3"], Float[Array, "3"]]:
    """Render one Mondrian image from per-patch RGBs.

    Each patch ``i`` is ``s_i * rho_i`` with shading ``s_i ~ U(shading)``; with ``specular``, a
    patch is specular with ``specular.probability`` and gains a highlight, a Gaussian blob centred
    in the patch (width a quarter of the patch) of peak ``U(0, specular.max_amount) * s_i`` times
    the white (the dielectric model of §4.7, spread in space). With ``normalise`` the noise-free
    image is scaled so its brightest channel value is 1; ``noise`` adds Gaussian noise of variance
    ``a * rho + b`` (clamped at 0), after which the image is rescaled so its brightest value is
    exactly 1 again. ``clip`` saturates values above the level (a camera's full well). With
    ``metallic`` (and ``metal_rgb``, the metals' RGBs under the image's light), a patch gets, with
    ``metallic.probability``, a blob of the same shape of peak ``U(0, metallic.max_amount) * s_i``
    times a metal's RGB, the metal uniform over ``metal_rgb`` (§8.3).

    Arguments:
        key: PRNG key of the shading, highlights and noise.
        labels: ``(H, W)`` patch index per pixel (:func:`mondrian_layout`).
        patch_rgb: ``(P, 3)`` RGB of each patch under the image's light.
        white: ``(3,)`` RGB of a perfect white under that light.
        shading: range of the per-patch shading factor.
        specular, noise, clip, metallic: the scene options (:mod:`ccjax.scenes._options`).
        normalise: scale the noise-free image so its brightest channel value is 1.
        metal_rgb: ``(M, 3)`` the metals' RGBs under the image's light (with ``metallic``).

    Returns:
        ``(image (H, W, 3), white (3,))``, the white on the image's scale.
    """
    n_patches = patch_rgb.shape[0]
    key_shade, key_spec, key_amount, key_noise = jax.random.split(key, 4)
    # Drawn in float32 and cast to the patches' dtype (ccjax.scenes._draws).
    shade = draws_.uniform(key_shade, (n_patches,), patch_rgb.dtype, shading[0], shading[1])
    image = (shade[:, None] * patch_rgb)[labels]
    if specular is not None:
        is_specular = draws_.uniform(key_spec, (n_patches,)) < specular.probability
        draw = draws_.uniform(key_amount, (n_patches,), patch_rgb.dtype)
        amount = jnp.where(is_specular, draw * specular.max_amount, 0.0) * shade
        blob = _highlight_blobs(labels, n_patches, image.dtype)
        image = image + (amount[labels] * blob)[..., None] * white
    if metallic is not None:
        if metal_rgb is None:
            raise ValueError("metal_rgb: needed with metallic (the metals' RGBs under the image's light)")
        key_which, key_metal, key_strength = jax.random.split(jax.random.fold_in(key, METAL_STREAM), 3)
        is_metal = draws_.uniform(key_which, (n_patches,)) < metallic.probability
        metal = draws_.randint(key_metal, (n_patches,), metal_rgb.shape[0])
        strength = draws_.uniform(key_strength, (n_patches,), patch_rgb.dtype) * metallic.max_amount
        strength = jnp.where(is_metal, strength, 0.0) * shade
        blob = _highlight_blobs(labels, n_patches, image.dtype)
        image = image + (strength[labels] * blob)[..., None] * metal_rgb[metal][labels]
    if normalise:
        scale = 1.0 / jnp.maximum(jnp.max(image), 1e-12)
        image, white = image * scale, white * scale
    if noise is not None:
        sigma = jnp.sqrt(noise.a * image + noise.b)
        image = jnp.maximum(image + sigma * draws_.normal(key_noise, image.shape, image.dtype), 0.0)
        if normalise:
            scale = 1.0 / jnp.maximum(jnp.max(image), 1e-12)
            image, white = image * scale, white * scale
    if clip is not None:
        image = jnp.minimum(image, clip)
    return image, white


@partial(
    jax.jit,
    static_argnames=(
        "height",
        "width",
        "n_patches",
        "shading",
        "specular",
        "noise",
        "clip",
        "normalise",
        "metallic",
        "fluorescent",
    ),
)
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
    metallic: Metallic | None = None,
    fluorescent: Fluorescent | None = None,
) -> MondrianImages:
    """Mondrians for a batch of per-image keys ``(B,)``: a test illuminant and ``n_patches``
    reflectances (without replacement) per image, as :func:`sample_one` draws them; with
    ``fluorescent``, each patch is one of the tables' fluorescent surfaces with its probability.

    Arguments:
        keys: ``(B,)`` per-image keys (:func:`scene_keys`).
        tables: the world's :class:`SceneTables`.
        height, width: image size in pixels.
        n_patches: patches (reflectances) per image.
        shading, specular, noise, clip, normalise, metallic: as for :func:`render_mondrian`.
        fluorescent: fluorescent surfaces (:class:`Fluorescent`), or ``None``.

    Returns:
        The :class:`MondrianImages` of the batch.
    """
    require_tables(tables, metallic, fluorescent)

    def one(key):
        key_light, key_surf, key_layout, key_render = jax.random.split(key, 4)
        light = draws_.randint(key_light, (), tables.surface_rgb.shape[0])
        surfaces = draw_without_replacement(key_surf, tables.surface_rgb.shape[1], n_patches)
        labels = mondrian_layout(key_layout, height, width, n_patches)
        patch_rgb = tables.surface_rgb[light, surfaces]
        identity = None
        if fluorescent is not None:
            assert tables.fluorescent_rgb is not None
            key_which, key_identity = jax.random.split(jax.random.fold_in(key, FLUORESCENT_STREAM))
            is_fluorescent = draws_.uniform(key_which, (n_patches,)) < fluorescent.probability
            drawn = draws_.randint(key_identity, (n_patches,), tables.fluorescent_rgb.shape[1])
            patch_rgb = jnp.where(is_fluorescent[:, None], tables.fluorescent_rgb[light, drawn], patch_rgb)
            identity = jnp.where(is_fluorescent, drawn, -1)
        image, white = render_mondrian(
            key_render,
            labels,
            patch_rgb,
            tables.whites[light],
            shading=shading,
            specular=specular,
            noise=noise,
            clip=clip,
            normalise=normalise,
            metallic=metallic,
            metal_rgb=None if tables.metal_rgb is None else tables.metal_rgb[light],
        )
        return MondrianImages(
            image=image,
            illuminant=white,
            labels=labels,
            surfaces=surfaces,
            fluorescent=identity,
            light=light,
            shading=shading,
            options=SceneOptions(specular, noise, clip, metallic, fluorescent),
            normalise=normalise,
        )

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
    metallic: Metallic | bool | None = None,
    fluorescent: Fluorescent | bool | None = None,
    metals: Float[ArrayLike, "M 101"] | None = None,
    fluorescent_surfaces: RadianceModel | None = None,
    lights: str = "test",
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
        metallic: ``True`` (§8.3: probability 0.25, up to 4 x a metal's reflectance) or a
            :class:`Metallic`: metal-coloured highlight blobs.
        fluorescent: ``True`` (§7.3: each patch fluorescent with probability 0.3) or a
            :class:`Fluorescent`.
        metals: metal spectra ``(M, 101)`` (default: the six metals' reflectances,
            :func:`ccjax.materials.scene_metal_spectra`).
        fluorescent_surfaces: the fluorescent :class:`RadianceModel` (default: the nine synthetic
            surfaces' physical model).
        lights: ``"test"`` (the world's test illuminants) or ``"train"`` (its training ones).

    Returns:
        :class:`MondrianImages`, carrying the options they were drawn with.

    Example:
        Highlighted images under the training lights; a relight keeps the highlights:

        >>> import jax, ccjax
        >>> from ccjax.scenes import SceneTables, sample_mondrians
        >>> from ccjax.augment import relight_mondrians
        >>> world = ccjax.World.default()
        >>> images = sample_mondrians(jax.random.key(0), world, 2, height=32, width=32, specular=True, lights="train")
        >>> images.options.specular
        Specular(probability=0.25, max_amount=2.0)
        >>> relit = relight_mondrians(jax.random.key(1), SceneTables.from_world(world, lights="train"), images)
        >>> relit.options == images.options
        True
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
    metallic, fluorescent = resolve_materials(metallic, fluorescent)
    tables = SceneTables.from_world(
        world,
        metals=(True if metals is None else metals) if metallic is not None else None,
        fluorescent=default_fluorescent(fluorescent_surfaces) if fluorescent is not None else None,
        lights=lights,
    )
    keys = scene_keys(key, 0, n_images)
    return mondrian_batch(
        keys,
        tables,
        height,
        width,
        n_patches,
        (float(low), float(high)),
        specular,
        noise,
        clip,
        normalise,
        metallic,
        fluorescent,
    )
