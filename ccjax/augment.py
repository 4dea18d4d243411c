"""Relighting augmentation: new training examples with their ground truth, as pure functions of a
PRNG key (usable inside a jitted training step).

* Spectral relighting (:func:`relight_surfaces`, :func:`relight_mondrians`): the same surfaces
  under another light of the world, rendered from the spectra (exact, Barnard 1999 §4.7's image
  formation ``rho = integral R E S``), with that light's white as the new ground truth.
* Von Kries relighting (:func:`von_kries_relight`), for RGB data without spectra (photographs):
  every channel is scaled by the ratio of a new white to the old one. It is exact where the
  diagonal model holds (Barnard 1999 §2.5) and only an approximation otherwise: the point of the
  spectral form is that it is not.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray

from ccjax._colour import TINY
from ccjax.scenes import (
    Fluorescent,
    Metallic,
    MondrianImages,
    SceneOptions,
    Scenes,
    SceneTables,
    ShotNoise,
    Specular,
    render_mondrian,
    require_tables,
)


def relight_surfaces(
    key: PRNGKeyArray,
    tables: SceneTables,
    surfaces: Int[Array, "B P"],
    mask: Bool[Array, "B P"],
) -> Scenes:
    """The scenes' surfaces (reflectance indices) under a light drawn uniformly for each scene from
    the tables' illuminants.

    Arguments:
        key: PRNG key.
        tables: :class:`ccjax.scenes.SceneTables` (the lights relit under are its illuminants,
            ``SceneTables.from_world`` takes the world's test illuminants).
        surfaces: ``(B, P)`` reflectance indices into the world's reflectances.
        mask: ``(B, P)`` valid surfaces.

    Returns:
        :class:`ccjax.scenes.Scenes` under the new lights, with their whites as ground truth, their
        indices in ``light`` and the canonical RGB for mapping errors.
    """
    lights = jax.random.randint(key, surfaces.shape[:1], 0, tables.surface_rgb.shape[0], jnp.int32)
    rgb = tables.surface_rgb[lights[:, None], surfaces]
    rgb = jnp.where(mask[..., None], rgb, jnp.zeros_like(rgb))
    canonical = tables.canonical_rgb[surfaces]
    return Scenes(rgb=rgb, mask=mask, illuminant=tables.whites[lights], canonical_rgb=canonical, light=lights)


def relight_mondrians(
    key: PRNGKeyArray,
    tables: SceneTables,
    images: MondrianImages,
    *,
    shading: tuple[float, float] | None = None,
    specular: Specular | bool | None = None,
    noise: ShotNoise | bool | None = None,
    clip: float | bool | None = None,
    normalise: bool | None = None,
    metallic: Metallic | bool | None = None,
    fluorescent: Fluorescent | bool | None = None,
) -> MondrianImages:
    """The same Mondrians (layout, reflectances and fluorescent patches) rendered again under a
    light drawn uniformly for each image from the tables' illuminants, with fresh shading,
    highlights and noise from ``key`` (:func:`ccjax.scenes.render_mondrian`).

    By default every option is the one the images were drawn with (``images.shading``,
    ``images.options``, ``images.normalise``): highlights, metallic highlights, fluorescent
    patches, noise, clipping and normalisation are all rendered again. A keyword replaces one:
    ``True`` or a value as in :func:`ccjax.scenes.sample_mondrians`, ``False`` turns it off
    (``None``, the default, keeps it). ``fluorescent=True`` (or a :class:`Fluorescent`) draws
    which patches fluoresce afresh; kept, the images' fluorescent patches stay the same surfaces.

    Arguments:
        key: PRNG key.
        tables: the lights and the reflectances' responses (``SceneTables.from_world``; with the
            metals or fluorescent surfaces the options need, e.g.
            ``SceneTables.from_world(world, metals=True)`` for metallic highlights).
        images: a batch from :func:`ccjax.scenes.sample_mondrians`.
        shading: range of the per-patch shading (``None``: the images').
        specular, noise, metallic, fluorescent: the options (``None``: the images'; ``False``: off).
        clip: saturation level (``None``: the images'; ``False``: no clipping).
        normalise: scale each image so its brightest value is 1 (``None``: as the images were).

    Returns:
        :class:`ccjax.scenes.MondrianImages` with the new lights' whites as ground truth, their
        indices in ``light`` and the options rendered with.

    Example:
        >>> import jax, ccjax
        >>> from ccjax.scenes import SceneTables, sample_mondrians
        >>> world = ccjax.World.default()
        >>> images = sample_mondrians(jax.random.key(0), world, 2, height=32, width=32, specular=True)
        >>> tables = SceneTables.from_world(world)
        >>> relight_mondrians(jax.random.key(1), tables, images).options.specular is not None
        True
        >>> relight_mondrians(jax.random.key(1), tables, images, specular=False).options.specular is None
        True
    """
    drawn = images.options
    shading = images.shading if shading is None else shading
    low, high = (float(value) for value in shading)
    if not 0 <= low <= high:
        raise ValueError(f"shading: expected 0 <= low <= high, got {shading!r}")
    if clip is True:
        raise ValueError("clip: expected a level, None (the images') or False (no clipping), got True")
    options = SceneOptions.resolve(
        drawn.specular if specular is None else specular,
        drawn.noise if noise is None else noise,
        drawn.clip if clip is None else (clip or None),
        drawn.metallic if metallic is None else metallic,
        drawn.fluorescent if fluorescent is None else fluorescent,
    )
    normalise = images.normalise if normalise is None else bool(normalise)
    keep_patches = fluorescent is None and images.fluorescent is not None
    return _relight(key, tables, images, (low, high), options, normalise, keep_patches)


@partial(jax.jit, static_argnames=("shading", "options", "normalise", "keep_patches"))
def _relight(
    key: PRNGKeyArray,
    tables: SceneTables,
    images: MondrianImages,
    shading: tuple[float, float],
    options: SceneOptions,
    normalise: bool,
    keep_patches: bool,
) -> MondrianImages:
    require_tables(tables, options.metallic, options.fluorescent)
    n_lights = tables.surface_rgb.shape[0]
    identities = images.fluorescent if keep_patches else jnp.full_like(images.surfaces, -1)

    def one(key, labels, surfaces, kept):
        key_light, key_render, key_which, key_identity = jax.random.split(key, 4)
        light = jax.random.randint(key_light, (), 0, n_lights, jnp.int32)
        patch_rgb = tables.surface_rgb[light, surfaces]
        identity = None
        if options.fluorescent is not None:
            assert tables.fluorescent_rgb is not None
            if keep_patches:
                identity = kept
            else:
                count = surfaces.shape[0]
                chosen = jax.random.uniform(key_which, (count,), jnp.float32) < options.fluorescent.probability
                drawn = jax.random.randint(key_identity, (count,), 0, tables.fluorescent_rgb.shape[1], jnp.int32)
                identity = jnp.where(chosen, drawn, -1)
            glowing = tables.fluorescent_rgb[light, jnp.maximum(identity, 0)]
            patch_rgb = jnp.where((identity >= 0)[:, None], glowing, patch_rgb)
        image, white = render_mondrian(
            key_render,
            labels,
            patch_rgb,
            tables.whites[light],
            shading=shading,
            specular=options.specular,
            noise=options.noise,
            clip=options.clip,
            normalise=normalise,
            metallic=options.metallic,
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
            options=options,
            normalise=normalise,
        )

    keys = jax.random.split(key, images.labels.shape[0])
    return jax.vmap(one)(keys, images.labels, images.surfaces, identities)


def von_kries_gains(
    key: PRNGKeyArray,
    illuminant: Float[Array, "B 3"],
    targets: Float[Array, "J 3"],
) -> tuple[Float[Array, "B 3"], Float[Array, "B 3"]]:
    """Diagonal gains taking each scene's light to one drawn uniformly from ``targets``.

    The new white keeps the old one's brightest channel (so the data's range is unchanged): gains
    ``g = (t / max t) * max(e) / e``.

    Arguments:
        key: PRNG key.
        illuminant: ``(B, 3)`` the scenes' true whites (positive channels).
        targets: ``(J, 3)`` whites to relight to (e.g. other images' ground truths).

    Returns:
        ``(gains (B, 3), new_illuminant (B, 3))``.
    """
    choice = jax.random.randint(key, illuminant.shape[:1], 0, targets.shape[0], jnp.int32)
    target = targets[choice]
    new = target / jnp.maximum(jnp.max(target, axis=-1, keepdims=True), TINY)
    new = new * jnp.max(illuminant, axis=-1, keepdims=True)
    gains = new / jnp.maximum(illuminant, TINY)
    return gains, new


def von_kries_relight(
    key: PRNGKeyArray,
    rgb: Float[Array, "B *pixels 3"],
    illuminant: Float[Array, "B 3"],
    targets: Float[Array, "J 3"],
    mask: Bool[Array, "..."] | None = None,
) -> tuple[Float[Array, "B *pixels 3"], Float[Array, "B 3"]]:
    """Von Kries relighting of RGB data with ground truth: each scene's pixels times the diagonal
    gains (:func:`von_kries_gains`) that take its light to one of ``targets``.

    Arguments:
        key: PRNG key.
        rgb: ``(B, ..., 3)`` surface lists ``(B, P, 3)`` or images ``(B, H, W, 3)``.
        illuminant: ``(B, 3)`` their true whites.
        targets: ``(J, 3)`` whites to draw the new lights from.
        mask: optional ``(B, ...)``; masked pixels are left unchanged.

    Returns:
        ``(relit rgb, new illuminant (B, 3))``.
    """
    if rgb.ndim < 2 or rgb.shape[-1] != 3:
        raise ValueError(f"rgb: expected shape (B, ..., 3), got {rgb.shape}")
    if illuminant.shape != (rgb.shape[0], 3):
        raise ValueError(f"illuminant: expected shape ({rgb.shape[0]}, 3), got {illuminant.shape}")
    if targets.ndim != 2 or targets.shape[-1] != 3 or targets.shape[0] < 1:
        raise ValueError(f"targets: expected shape (J, 3) with J >= 1, got {targets.shape}")
    gains, new = von_kries_gains(key, illuminant, targets)
    gains = gains.reshape(gains.shape[:1] + (1,) * (rgb.ndim - 2) + (3,))
    relit = rgb * gains
    if mask is not None:
        relit = jnp.where(mask[..., None], relit, rgb)
    return relit, new
