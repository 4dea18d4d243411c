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

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray

from ccjax._colour import TINY
from ccjax.scenes import MondrianImages, Scenes, SceneTables, ShotNoise, Specular, render_mondrian


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
        :class:`ccjax.scenes.Scenes` under the new lights, with their whites as ground truth and the
        canonical RGB for mapping errors.
    """
    lights = jax.random.randint(key, surfaces.shape[:1], 0, tables.surface_rgb.shape[0])
    rgb = tables.surface_rgb[lights[:, None], surfaces]
    rgb = jnp.where(mask[..., None], rgb, jnp.zeros_like(rgb))
    return Scenes(rgb=rgb, mask=mask, illuminant=tables.whites[lights], canonical_rgb=tables.canonical_rgb[surfaces])


def relight_mondrians(
    key: PRNGKeyArray,
    tables: SceneTables,
    images: MondrianImages,
    *,
    shading: tuple[float, float] = (0.3, 1.0),
    specular: Specular | None = None,
    noise: ShotNoise | None = None,
) -> MondrianImages:
    """The same Mondrians (layout and reflectances) rendered again under a light drawn uniformly
    for each image from the tables' illuminants (with fresh shading, highlights and noise from
    ``key``; :func:`ccjax.scenes.render_mondrian`).

    Arguments:
        key: PRNG key.
        tables: the lights and the reflectances' responses (``SceneTables.from_world``).
        images: a batch from :func:`ccjax.scenes.sample_mondrians`.
        shading, specular, noise: as in :func:`ccjax.scenes.sample_mondrians`.

    Returns:
        :class:`ccjax.scenes.MondrianImages` with the new lights' whites as ground truth.
    """

    def one(key, labels, surfaces):
        key_light, key_render = jax.random.split(key)
        light = jax.random.randint(key_light, (), 0, tables.surface_rgb.shape[0])
        image, white = render_mondrian(
            key_render,
            labels,
            tables.surface_rgb[light, surfaces],
            tables.whites[light],
            shading=shading,
            specular=specular,
            noise=noise,
        )
        return MondrianImages(image=image, illuminant=white, labels=labels, surfaces=surfaces)

    keys = jax.random.split(key, images.labels.shape[0])
    return jax.vmap(one)(keys, images.labels, images.surfaces)


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
    choice = jax.random.randint(key, illuminant.shape[:1], 0, targets.shape[0])
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
