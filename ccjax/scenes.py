"""Synthetic scenes: surface lists drawn from a world (Barnard 1999 §4.7, spec ch02-04 §5.4).

A scene is ``P`` surfaces drawn without replacement from the world's reflectances under one
illuminant drawn from the **test** set; each surface gives one RGB. Options reproduce the thesis'
experiments: specularities (each surface specular with probability 0.25, adding ``U(0, 2)`` times a
perfect white, §4.7 and ch. 8), clipping (pixels with any channel above the level are discarded,
i.e. masked out) and shot noise (the chapter 3 noise model, variance ``a * rho + b``).

Everything after the per-world tables is a pure function of a PRNG key, so scenes are reproducible
and batches are generated with ``jax.vmap`` over per-scene keys: a sweep gives the same scenes
whatever its chunking or sharding.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray

from ccjax.world import World

# Floyd's algorithm costs O(P^2) per scene, Gumbel top-k O(S log P); switch where they cross.
_FLOYD_MAX_SURFACES = 64


class Scenes(eqx.Module):
    """A batch of synthetic scenes (DESIGN.md §2).

    Attributes:
        rgb: ``(B, P, 3)`` camera RGB of each surface under the scene light.
        mask: ``(B, P)`` True where the surface is valid (False: clipped or padding).
        illuminant: ``(B, 3)`` camera RGB of a perfect white under the scene light (ground truth).
        canonical_rgb: ``(B, P, 3)`` the same surfaces under the canonical light (mapping errors).
    """

    rgb: Float[Array, "B P 3"]
    mask: Bool[Array, "B P"]
    illuminant: Float[Array, "B 3"]
    canonical_rgb: Float[Array, "B P 3"]


@dataclass(frozen=True)
class Specular:
    """Dielectric specularities (Barnard 1999 §4.7, ch. 8): each surface is specular with
    ``probability`` and then gains ``U(0, max_amount)`` times a perfect white reflectance."""

    probability: float = 0.25
    max_amount: float = 2.0


@dataclass(frozen=True)
class ShotNoise:
    """Chapter 3 noise model on the unit scale: ``rho + sqrt(a * rho + b) * N(0, 1)``, clamped at
    zero (a sensor cannot report a negative count). Defaults: ``a = 2e-6``, ``b = (0.05/255)^2``."""

    a: float = 2e-6
    b: float = (0.05 / 255.0) ** 2


class SceneTables(eqx.Module):
    """Per-world response tables from which scenes are gathered (computed once per world)."""

    surface_rgb: Float[Array, "J S 3"]  # every reflectance under every test illuminant
    whites: Float[Array, "J 3"]
    canonical_rgb: Float[Array, "S 3"]
    canonical_white: Float[Array, "3"]

    @classmethod
    def from_world(cls, world: World) -> SceneTables:
        sensors = world.camera.sensors
        lit_sensors = world.test_illuminants[:, :, None] * sensors[None]  # (J, 101, 3)
        surface_rgb = jnp.einsum("sl,jlc->jsc", world.reflectances, lit_sensors)
        return cls(
            surface_rgb=surface_rgb,
            whites=world.test_whites,
            canonical_rgb=world.canonical_rgb,
            canonical_white=world.canonical_white,
        )


def _draw_without_replacement(key: PRNGKeyArray, n_population: int, n_draws: int) -> Int[Array, " P"]:
    if n_draws <= _FLOYD_MAX_SURFACES:
        # Floyd's algorithm: step i draws t in [0, n - P + i]; a repeat is replaced by n - P + i.
        ceilings = n_population - n_draws + jnp.arange(n_draws)
        draws = jnp.floor(jax.random.uniform(key, (n_draws,)) * (ceilings + 1)).astype(jnp.int32)
        draws = jnp.minimum(draws, ceilings)

        def step(i, chosen):
            taken = jnp.any((chosen == draws[i]) & (jnp.arange(n_draws) < i))
            return chosen.at[i].set(jnp.where(taken, ceilings[i], draws[i]))

        return jax.lax.fori_loop(0, n_draws, step, jnp.full((n_draws,), -1, jnp.int32))
    # Gumbel top-k: the P largest of S iid uniforms form a uniform P-subset.
    return jax.lax.top_k(jax.random.uniform(key, (n_population,)), n_draws)[1].astype(jnp.int32)


def sample_one(
    key: PRNGKeyArray,
    tables: SceneTables,
    n_surfaces: int,
    specular: Specular | None = None,
    noise: ShotNoise | None = None,
    clip: float | None = None,
) -> Scenes:
    """One scene from a per-scene key (fields without the batch axis); vmap it for batches."""
    n_lights, n_reflectances, _ = tables.surface_rgb.shape
    key_light, key_surf, key_spec, key_amount, key_noise = jax.random.split(key, 5)
    light = jax.random.randint(key_light, (), 0, n_lights)
    surfaces = _draw_without_replacement(key_surf, n_reflectances, n_surfaces)
    white = tables.whites[light]
    rgb = tables.surface_rgb[light, surfaces]
    canonical = tables.canonical_rgb[surfaces]
    if specular is not None:
        is_specular = jax.random.uniform(key_spec, (n_surfaces,)) < specular.probability
        amount = jnp.where(is_specular, jax.random.uniform(key_amount, (n_surfaces,)) * specular.max_amount, 0.0)
        rgb = rgb + amount[:, None] * white
        canonical = canonical + amount[:, None] * tables.canonical_white
    if noise is not None:
        sigma = jnp.sqrt(noise.a * rgb + noise.b)
        rgb = jnp.maximum(rgb + sigma * jax.random.normal(key_noise, rgb.shape), 0.0)
    mask = jnp.ones((n_surfaces,), bool)
    if clip is not None:
        mask = jnp.all(rgb <= clip, axis=-1)
    return Scenes(rgb=rgb, mask=mask, illuminant=white, canonical_rgb=canonical)


@partial(jax.jit, static_argnames=("n_surfaces", "specular", "noise", "clip"))
def sample_batch(
    keys: PRNGKeyArray,
    tables: SceneTables,
    n_surfaces: int,
    specular: Specular | None = None,
    noise: ShotNoise | None = None,
    clip: float | None = None,
) -> Scenes:
    """Scenes for a batch of per-scene keys ``(B,)`` (the sweep engine's entry point)."""
    return jax.vmap(lambda k: sample_one(k, tables, n_surfaces, specular, noise, clip))(keys)


def scene_keys(key: PRNGKeyArray, start: int, count: int) -> PRNGKeyArray:
    """Keys of scenes ``start .. start+count-1`` of a stream: independent of how it is chunked."""
    return jax.vmap(lambda i: jax.random.fold_in(key, i))(jnp.arange(start, start + count, dtype=jnp.uint32))


def sample(
    key: PRNGKeyArray,
    world: World,
    n_scenes: int,
    n_surfaces: int,
    *,
    specular: Specular | bool | None = None,
    noise: ShotNoise | bool | None = None,
    clip: float | None = None,
) -> Scenes:
    """Draw a batch of synthetic scenes (Barnard 1999 §4.7).

    Arguments:
        key: a ``jax.random`` key.
        world: the world (test illuminants, reflectances, camera).
        n_scenes: number of scenes ``B``.
        n_surfaces: surfaces per scene ``P`` (drawn without replacement, at most the number of
            reflectances).
        specular: ``True`` for the thesis recipe (:class:`Specular` defaults) or a :class:`Specular`.
        noise: ``True`` for the chapter 3 model with defaults, or a :class:`ShotNoise`.
        clip: clip level on the unit scale (thesis levels 250, 300, 400 are ``250/255`` ...);
            surfaces with any channel above it are masked out.

    Returns:
        :class:`Scenes` with batch size ``n_scenes``.
    """
    n_reflectances = int(world.reflectances.shape[0])
    if not isinstance(n_scenes, int) or n_scenes < 1:
        raise ValueError(f"n_scenes: expected a positive integer, got {n_scenes!r}")
    if not isinstance(n_surfaces, int) or not 1 <= n_surfaces <= n_reflectances:
        raise ValueError(f"n_surfaces: expected an integer in [1, {n_reflectances}], got {n_surfaces!r}")
    specular, noise = resolve_options(specular, noise, clip)
    tables = SceneTables.from_world(world)
    return sample_batch(scene_keys(key, 0, n_scenes), tables, n_surfaces, specular, noise, clip)


def resolve_options(specular, noise, clip) -> tuple[Specular | None, ShotNoise | None]:
    """Validate and normalise the scene options (``True`` -> the default recipe)."""
    specular = Specular() if specular is True else (specular or None)
    noise = ShotNoise() if noise is True else (noise or None)
    if specular is not None:
        if not isinstance(specular, Specular):
            raise ValueError(f"specular: expected True, None or a Specular, got {specular!r}")
        if not 0 <= specular.probability <= 1 or specular.max_amount < 0:
            raise ValueError(f"specular: probability must be in [0, 1] and max_amount >= 0, got {specular}")
    if noise is not None:
        if not isinstance(noise, ShotNoise):
            raise ValueError(f"noise: expected True, None or a ShotNoise, got {noise!r}")
        if noise.a < 0 or noise.b < 0:
            raise ValueError(f"noise: a and b must be non-negative, got {noise}")
    if clip is not None and not (isinstance(clip, (int, float)) and clip > 0):
        raise ValueError(f"clip: expected a positive level on the unit scale, got {clip!r}")
    return specular, noise


# ---------------------------------------------------------------------------------------------
# Synthetic images: Mondrians rendered from spectra (for the image pipeline and spatial methods)


class MondrianImages(eqx.Module):
    """A batch of synthetic Mondrian images (flat rectangular patches of world reflectances).

    Attributes:
        image: ``(B, H, W, 3)`` linear camera RGB (non-negative; see :func:`render_mondrian`).
        illuminant: ``(B, 3)`` camera RGB of a perfect white under the image's light, on the
            image's scale (ground truth).
        labels: ``(B, H, W)`` patch index of every pixel.
        surfaces: ``(B, P)`` reflectance index of every patch.
    """

    image: Float[Array, "B H W 3"]
    illuminant: Float[Array, "B 3"]
    labels: Int[Array, "B H W"]
    surfaces: Int[Array, "B P"]


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
    y = (jnp.arange(height) + 0.5) / height
    x = (jnp.arange(width) + 0.5) / width
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
        one_hot = labels[..., None] == jnp.arange(n_patches)  # (H, W, P)
        area = jnp.maximum(jnp.sum(one_hot, axis=(0, 1)), 1)
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
    keys: PRNGKeyArray,
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
        surfaces = _draw_without_replacement(key_surf, tables.surface_rgb.shape[1], n_patches)
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
    n_images: int,
    *,
    height: int = 128,
    width: int = 128,
    n_patches: int = 16,
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
    if not isinstance(n_images, int) or n_images < 1:
        raise ValueError(f"n_images: expected a positive integer, got {n_images!r}")
    if not isinstance(n_patches, int) or not 1 <= n_patches <= n_reflectances:
        raise ValueError(f"n_patches: expected an integer in [1, {n_reflectances}], got {n_patches!r}")
    if not (isinstance(height, int) and isinstance(width, int) and height >= 1 and width >= 1):
        raise ValueError(f"height, width: expected positive integers, got {height!r}, {width!r}")
    low, high = shading
    if not 0 <= low <= high:
        raise ValueError(f"shading: expected 0 <= low <= high, got {shading!r}")
    specular, noise = resolve_options(specular, noise, clip)
    tables = SceneTables.from_world(world)
    keys = scene_keys(key, 0, n_images)
    return mondrian_batch(
        keys, tables, height, width, n_patches, (float(low), float(high)), specular, noise, clip, normalise
    )
