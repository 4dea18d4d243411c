"""Synthetic scenes: surface lists drawn from a world (Barnard 1999 §4.7).

A scene is ``P`` surfaces drawn without replacement from the world's reflectances under one
illuminant drawn from the **test** set; each surface gives one RGB. The rendering options
(:mod:`ccjax.scenes._options`, all held by one :class:`SceneOptions`) reproduce the thesis'
experiments: specularities (each surface specular with probability 0.25, adding ``U(0, 2)`` times
a perfect white, §4.7 and ch. 8), metallic highlights (:class:`Metallic`: probability 0.25, adding
``U(0, 4)`` times a metal's reflectance, §8.3), fluorescent surfaces (:class:`Fluorescent`: each
surface slot replaced by one of the fluorescent surfaces with probability 0.3, §7.3, A21),
clipping (pixels with any channel above the level are discarded, i.e. masked out) and shot noise
(the chapter 3 noise model, variance ``a * rho + b``).

Metal and fluorescent colours come from :class:`SceneTables` (:mod:`ccjax.scenes._tables`), built
with ``SceneTables.from_world(world, metals=..., fluorescent=...)``; the options only say how often
and how strongly they occur, so they stay static (hashable) arguments of the jitted samplers.
Their random draws come from keys folded off the scene key, so turning a material option on
leaves the light, the surfaces and the other options' draws of every scene as they are.

Everything after the per-world tables is a pure function of a PRNG key, so scenes are reproducible
and batches are generated with ``jax.vmap`` over per-scene keys: a sweep gives the same scenes
whatever its chunking or sharding.
"""

from __future__ import annotations

import operator
from functools import partial
from typing import SupportsIndex

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float, Int, Integer, Key, PRNGKeyArray, UInt32

from ccjax import limits
from ccjax.scenes import _draws as draws_
from ccjax.scenes._options import (
    Fluorescent,
    Metallic,
    SceneOptions,
    ShotNoise,
    Specular,
    require_count,
)
from ccjax.scenes._tables import RadianceModel, SceneTables, default_fluorescent, require_tables
from ccjax.world import World

SceneKeys = Key[Array, " B"] | UInt32[Array, "B 2"]
"""A batch of ``B`` PRNG keys, one per scene (typed keys or raw ``uint32`` pairs)."""

_FLOYD_MAX_SURFACES = 64
# Streams folded off a scene key for the material options (never split from it: a split's
# outputs depend on how many keys are asked for, so adding one would move every existing draw).
METAL_STREAM = 0x4D45  # "ME"
FLUORESCENT_STREAM = 0x464C  # "FL"


class Scenes(eqx.Module):
    """A batch of synthetic scenes (Barnard 1999 §4.7): fixed shapes with a mask, so batches ``vmap``
    (one scene, as :func:`sample_one` returns it, has no batch axis).

    Attributes:
        rgb: ``(B, P, 3)`` camera RGB of each surface under the scene light.
        mask: ``(B, P)`` True where the surface is valid (False: clipped or padding).
        illuminant: ``(B, 3)`` camera RGB of a perfect white under the scene light (ground truth).
        canonical_rgb: ``(B, P, 3)`` the same surfaces under the canonical light (mapping errors).
        light: ``(B,)`` int32 index of each scene's light among the lights it was drawn from
            (``tables.lights``: the world's test illuminants, or its training ones with
            ``lights="train"``), e.g. to apply per-light sharpening; ``None`` where unknown
            (scenes built by hand).

    Example:
        >>> import jax, ccjax, numpy as np
        >>> world = ccjax.World.default()
        >>> scenes = ccjax.sample(jax.random.key(0), world, 4, 8)
        >>> np.allclose(scenes.illuminant, world.test_whites[scenes.light])
        True
    """

    rgb: Float[Array, "*batch P 3"]
    mask: Bool[Array, "*batch P"]
    illuminant: Float[Array, "*batch 3"]
    canonical_rgb: Float[Array, "*batch P 3"]
    light: Int[Array, "*batch"] | None = None


def draw_without_replacement(
    key: PRNGKeyArray, n_population: int, n_draws: int | Int[Array, ""], slots: int | None = None
) -> Int[Array, " P"]:
    """``n_draws`` distinct indices into ``0 .. n_population - 1``, uniformly (Barnard 1999 §4.7:
    the surfaces of a scene are distinct).

    Arguments:
        key: a ``jax.random`` key.
        n_population: number of items to draw from.
        n_draws: number of distinct draws: static, or with ``slots`` a traced count (at most ``slots``).
        slots: static length of the result: its first ``n_draws`` entries are the draws, the
            others 0 (one compiled program for every count up to ``slots``). The draws are those
            of ``slots=None``, bitwise: JAX's partitionable threefry gives a longer shape's random
            bits as an extension of a shorter one's.

    Returns:
        ``(n_draws,)`` (or ``(slots,)``) int32 indices.
    """
    if slots is None:
        n = operator.index(n_draws)
        return _floyd(key, n_population, n, n) if n <= _FLOYD_MAX_SURFACES else _top_k(key, n_population, n)
    drawn = _floyd(key, n_population, n_draws, slots)
    if slots > _FLOYD_MAX_SURFACES:
        drawn = jnp.where(n_draws <= _FLOYD_MAX_SURFACES, drawn, _top_k(key, n_population, slots))
    return jnp.where(jnp.arange(slots, dtype=jnp.int32) < n_draws, drawn, 0)


def _floyd(key: PRNGKeyArray, n_population: int, n_draws, slots: int) -> Int[Array, " P"]:
    # Floyd's algorithm: step i draws t in [0, n - P + i]; a repeat is replaced by n - P + i.
    ceilings = n_population - n_draws + jnp.arange(slots, dtype=jnp.int32)
    uniform = draws_.uniform(key, (slots,))  # float32 under x64 too: the same surfaces
    draws = jnp.floor(uniform * (ceilings + 1).astype(uniform.dtype)).astype(jnp.int32)
    draws = jnp.minimum(draws, ceilings)

    def step(i, chosen):
        taken = jnp.any((chosen == draws[i]) & (jnp.arange(slots, dtype=i.dtype) < i))
        return chosen.at[i].set(jnp.where(taken, ceilings[i], draws[i]))

    return jax.lax.fori_loop(0, n_draws, step, jnp.full((slots,), -1, jnp.int32))


def _top_k(key: PRNGKeyArray, n_population: int, n_draws: int) -> Int[Array, " P"]:
    # Gumbel top-k: the P largest of S iid uniforms form a uniform P-subset (in decreasing order,
    # so the first P of a larger k are the same P).
    return jax.lax.top_k(draws_.uniform(key, (n_population,)), n_draws)[1].astype(jnp.int32)


class SceneDraw(eqx.Module):
    """Which light and which surfaces a scene uses (Barnard 1999 §4.7), as indices.

    Attributes:
        light: ``(...)`` index into the world's test illuminants (or whichever light set was drawn from).
        surfaces: ``(..., P)`` distinct indices into the world's reflectances.
    """

    light: Int[Array, "*batch"]
    surfaces: Int[Array, "*batch P"]


def _scene_subkeys(key: PRNGKeyArray) -> SceneKeys:
    # One split per scene key: light, surfaces, specular choice, specular amount, noise.
    return jax.random.split(key, 5)


def draw_scene(
    key: PRNGKeyArray, n_lights: int, n_reflectances: int, n_surfaces: int | Int[Array, ""], slots: int | None = None
) -> SceneDraw:
    """Draw the light and the surfaces of ONE scene from its per-scene key (Barnard 1999 §4.7).

    This is the one place scenes are drawn: :func:`sample_one` (hence :func:`sample`,
    :func:`sample_batch` and the sweeps) and the chapter-5 experiment both call it, so the same
    key gives the same light and surfaces everywhere.

    Arguments:
        key: the scene's key (e.g. one of :func:`scene_keys`).
        n_lights: number of lights to draw from.
        n_reflectances: number of reflectances to draw from.
        n_surfaces: surfaces per scene (static; traced with ``slots``), drawn without replacement.
        slots: static number of surface slots (:func:`draw_without_replacement`).

    Returns:
        :class:`SceneDraw` without a batch axis.
    """
    key_light, key_surf = _scene_subkeys(key)[:2]
    light = draws_.randint(key_light, (), n_lights)
    return SceneDraw(light=light, surfaces=draw_without_replacement(key_surf, n_reflectances, n_surfaces, slots))


def draw_scenes(keys: SceneKeys, n_lights: int, n_reflectances: int, n_surfaces: int) -> SceneDraw:
    """:func:`draw_scene` for a batch of per-scene keys ``(B,)``.

    Arguments:
        keys: ``(B,)`` per-scene keys.
        n_lights, n_reflectances, n_surfaces: as :func:`draw_scene`.

    Returns:
        :class:`SceneDraw` with batch axis ``B``.
    """
    return jax.vmap(lambda k: draw_scene(k, n_lights, n_reflectances, n_surfaces))(keys)


def sample_one(
    key: PRNGKeyArray,
    tables: SceneTables,
    n_surfaces: int | Int[Array, ""],
    specular: Specular | None = None,
    noise: ShotNoise | None = None,
    clip: float | None = None,
    metallic: Metallic | None = None,
    fluorescent: Fluorescent | None = None,
    slots: int | None = None,
) -> Scenes:
    """One scene from a per-scene key (fields without the batch axis); vmap it for batches.

    Order of the recipe: fluorescent surfaces replace drawn reflectances (both under the scene
    light and under the canonical one), then dielectric and metallic highlights are added, then
    noise, then clipping. ``metallic`` needs ``tables.metal_rgb``, ``fluorescent``
    ``tables.fluorescent_rgb`` (see :meth:`SceneTables.from_world`).

    With ``slots`` (static), the scene has ``slots`` surface slots of which the first
    ``n_surfaces`` (then possibly traced) are the scene's and the others zero and masked out:
    the same scene as without ``slots`` padded with masked-out zeros (every draw's random bits
    for a longer shape extend a shorter one's; see :func:`sample_batch_slots` for rounding),
    from one program for every count.

    Arguments:
        key: the scene's key.
        tables: the world's :class:`SceneTables`.
        n_surfaces: surfaces in the scene.
        specular, noise, clip, metallic, fluorescent: the scene options (:mod:`ccjax.scenes._options`).
        slots: surface slots (static; ``None``: ``n_surfaces``).

    Returns:
        The :class:`Scenes` of one scene (no batch axis).
    """
    require_tables(tables, metallic, fluorescent)
    n_lights, n_reflectances, _ = tables.surface_rgb.shape
    drawn = draw_scene(key, n_lights, n_reflectances, n_surfaces, slots)
    n_slots = operator.index(n_surfaces) if slots is None else slots
    light, surfaces = drawn.light, drawn.surfaces
    key_spec, key_amount, key_noise = _scene_subkeys(key)[2:]
    white = tables.whites[light]
    rgb = tables.surface_rgb[light, surfaces]
    canonical = tables.canonical_rgb[surfaces]
    if fluorescent is not None:
        assert tables.fluorescent_rgb is not None and tables.canonical_fluorescent_rgb is not None
        key_which, key_identity = jax.random.split(jax.random.fold_in(key, FLUORESCENT_STREAM))
        is_fluorescent = draws_.uniform(key_which, (n_slots,)) < fluorescent.probability
        identity = draws_.randint(key_identity, (n_slots,), tables.fluorescent_rgb.shape[1])
        rgb = jnp.where(is_fluorescent[:, None], tables.fluorescent_rgb[light, identity], rgb)
        canonical = jnp.where(is_fluorescent[:, None], tables.canonical_fluorescent_rgb[identity], canonical)
    if specular is not None:
        is_specular = draws_.uniform(key_spec, (n_slots,)) < specular.probability
        # Drawn in float32 and cast to the tables' dtype (ccjax.scenes._draws).
        draw = draws_.uniform(key_amount, (n_slots,), rgb.dtype)
        amount = jnp.where(is_specular, draw * specular.max_amount, 0.0)
        rgb = rgb + amount[:, None] * white
        canonical = canonical + amount[:, None] * tables.canonical_white
    if metallic is not None:
        # §8.3 / A11: S' = S + s M, s ~ U(0, max_amount), M uniform over the tables' metals.
        assert tables.metal_rgb is not None and tables.canonical_metal_rgb is not None
        key_which, key_metal, key_strength = jax.random.split(jax.random.fold_in(key, METAL_STREAM), 3)
        is_metal = draws_.uniform(key_which, (n_slots,)) < metallic.probability
        metal = draws_.randint(key_metal, (n_slots,), tables.metal_rgb.shape[1])
        draw = draws_.uniform(key_strength, (n_slots,), rgb.dtype)
        strength = jnp.where(is_metal, draw * metallic.max_amount, 0.0)
        rgb = rgb + strength[:, None] * tables.metal_rgb[light, metal]
        canonical = canonical + strength[:, None] * tables.canonical_metal_rgb[metal]
    if noise is not None:
        sigma = jnp.sqrt(noise.a * rgb + noise.b)
        rgb = jnp.maximum(rgb + sigma * draws_.normal(key_noise, rgb.shape, rgb.dtype), 0.0)
    mask = jnp.ones((n_slots,), bool)
    if clip is not None:
        mask = jnp.all(rgb <= clip, axis=-1)
    if slots is not None:
        live = jnp.arange(slots, dtype=jnp.int32) < n_surfaces
        rgb, canonical, mask = jnp.where(live[:, None], rgb, 0.0), jnp.where(live[:, None], canonical, 0.0), mask & live
    return Scenes(rgb=rgb, mask=mask, illuminant=white, canonical_rgb=canonical, light=light)


@partial(jax.jit, static_argnames=("n_surfaces", "specular", "noise", "clip", "metallic", "fluorescent"))
def sample_batch(
    keys: SceneKeys,
    tables: SceneTables,
    n_surfaces: int,
    specular: Specular | None = None,
    noise: ShotNoise | None = None,
    clip: float | None = None,
    metallic: Metallic | None = None,
    fluorescent: Fluorescent | None = None,
) -> Scenes:
    """Scenes for a batch of per-scene keys ``(B,)`` (the sweep engine's entry point).

    Arguments:
        keys: ``(B,)`` per-scene keys (:func:`scene_keys`).
        tables: the world's :class:`SceneTables`.
        n_surfaces: surfaces per scene.
        specular, noise, clip, metallic, fluorescent: the scene options (:mod:`ccjax.scenes._options`).

    Returns:
        The :class:`Scenes` of the batch.
    """
    return jax.vmap(lambda k: sample_one(k, tables, n_surfaces, specular, noise, clip, metallic, fluorescent))(keys)


@partial(jax.jit, static_argnames=("slots", "specular", "noise", "clip", "metallic", "fluorescent"))
def sample_batch_slots(
    keys: SceneKeys,
    tables: SceneTables,
    n_surfaces: Int[ArrayLike, ""],
    slots: int,
    specular: Specular | None = None,
    noise: ShotNoise | None = None,
    clip: float | None = None,
    metallic: Metallic | None = None,
    fluorescent: Fluorescent | None = None,
) -> Scenes:
    """:func:`sample_batch` in ``slots`` surface slots per scene: the first ``n_surfaces`` (a
    traced count, ``1 <= n_surfaces <= slots``) are the scene's, the others zero and masked out.
    The scenes are :func:`sample_batch`'s padded (:func:`sample_one` with ``slots``): bitwise with
    at most one scene option, to float rounding with several (another program may round their
    sums otherwise); and one compiled program serves every count (a sweep's counts padded to one
    size share it). Needs JAX's partitionable threefry (``jax_threefry_partitionable``, the
    default).

    Arguments:
        keys, tables: as for :func:`sample_batch`.
        n_surfaces: the scenes' surface count (may be traced).
        slots: surface slots per scene (static).
        specular, noise, clip, metallic, fluorescent: as for :func:`sample_batch`.

    Returns:
        The :class:`Scenes`, ``slots`` wide.
    """
    n_surfaces = jnp.asarray(n_surfaces, jnp.int32)
    return jax.vmap(lambda k: sample_one(k, tables, n_surfaces, specular, noise, clip, metallic, fluorescent, slots))(
        keys
    )


def scene_keys(key: PRNGKeyArray, start: int | Integer[ArrayLike, ""], count: int) -> SceneKeys:
    """Keys of scenes ``start .. start+count-1`` of a stream: independent of how it is chunked.

    Arguments:
        key: the stream's key.
        start: index of the first scene (may be traced, so one program serves every chunk).
        count: number of scenes (static).

    Returns:
        ``(count,)`` keys.
    """
    if isinstance(start, int):
        indices = jnp.arange(start, start + count, dtype=jnp.uint32)
    else:
        indices = jnp.arange(count, dtype=jnp.uint32) + jnp.asarray(start, jnp.uint32)
    return jax.vmap(lambda i: jax.random.fold_in(key, i))(indices)


def sweep_keys(
    key: PRNGKeyArray, n_surfaces: int | Integer[ArrayLike, ""], start: int | Integer[ArrayLike, ""], count: int
) -> SceneKeys:
    """Keys of scenes ``start .. start+count-1`` of the stream of ``n_surfaces``-surface scenes of
    a sweep with ``key`` (the stream is ``fold_in(key, n_surfaces)``, so every scene size has its
    own scenes and one size's scenes do not depend on which other sizes a sweep runs).

    Arguments:
        key: the sweep's key.
        n_surfaces: surfaces per scene (may be traced).
        start, count: the scenes' positions in the stream (``start`` may be traced).

    Returns:
        ``(count,)`` per-scene keys (for :func:`sample_batch` or :func:`draw_scenes`).
    """
    return scene_keys(jax.random.fold_in(key, n_surfaces), start, count)


def sample(
    key: PRNGKeyArray,
    world: World,
    n_scenes: SupportsIndex,
    n_surfaces: SupportsIndex,
    *,
    specular: Specular | bool | None = None,
    noise: ShotNoise | bool | None = None,
    clip: float | None = None,
    metallic: Metallic | bool | None = None,
    fluorescent: Fluorescent | bool | None = None,
    metals: Float[ArrayLike, "M 101"] | None = None,
    fluorescent_surfaces: RadianceModel | None = None,
    lights: str = "test",
) -> Scenes:
    """Draw a batch of synthetic scenes (Barnard 1999 §4.7).

    Arguments:
        key: a ``jax.random`` key.
        world: the world (test illuminants, reflectances, camera).
        n_scenes: number of scenes ``B`` (at most :data:`ccjax.limits.SAMPLE_SCENES`, and
            ``B * P`` at most :data:`ccjax.limits.SAMPLE_SURFACES`: every scene is held at once).
        n_surfaces: surfaces per scene ``P`` (drawn without replacement, at most the number of
            reflectances).
        specular: ``True`` for the thesis recipe (:class:`Specular` defaults) or a :class:`Specular`.
        noise: ``True`` for the chapter 3 model with defaults, or a :class:`ShotNoise`.
        clip: clip level on the unit scale (thesis levels 250, 300, 400 are ``250/255`` ...);
            surfaces with any channel above it are masked out.
        metallic: ``True`` for the §8.3 recipe (:class:`Metallic` defaults: p = 0.25, ``U(0, 4)``)
            or a :class:`Metallic`.
        fluorescent: ``True`` for the §7.3 recipe (:class:`Fluorescent` default: p = 0.3) or a
            :class:`Fluorescent`.
        metals: metal spectra ``(M, 101)`` of the highlights (default: the six metals'
            reflectances, :func:`ccjax.materials.scene_metal_spectra`).
        fluorescent_surfaces: the :class:`RadianceModel` of the fluorescent surfaces (default:
            the nine synthetic surfaces' physical model,
            :func:`ccjax.materials.synthetic_fluorescent_surfaces`).
        lights: ``"test"`` (the thesis' scenes, under the world's test illuminants) or
            ``"train"`` (under its training illuminants, the lights the estimators were fitted
            to); ``Scenes.light`` indexes that set.

    Returns:
        :class:`Scenes` with batch size ``n_scenes``.

    Raises:
        ValueError: a count out of range or past its limit, naming the argument (before any
            scene is drawn).

    Example:
        Scenes under the training lights, with per-scene light indices:

        >>> import jax, ccjax, numpy as np
        >>> world = ccjax.World.default()
        >>> scenes = ccjax.sample(jax.random.key(0), world, 4, 8, lights="train")
        >>> np.allclose(scenes.illuminant, world.train_whites[scenes.light])
        True
    """
    n_reflectances = int(world.reflectances.shape[0])
    n_scenes = require_count(n_scenes, "n_scenes", 1, limits.SAMPLE_SCENES)
    n_surfaces = require_count(n_surfaces, "n_surfaces", 1, n_reflectances)
    # Every scene is returned at once: what is held is the scenes times their surfaces.
    limits.require_product(((n_scenes, "scenes"), (n_surfaces, "surfaces")), "n_scenes", limits.SAMPLE_SURFACES)
    options = SceneOptions.resolve(specular, noise, clip, metallic, fluorescent)
    tables = SceneTables.from_world(
        world,
        metals=(True if metals is None else metals) if options.metallic is not None else None,
        fluorescent=default_fluorescent(fluorescent_surfaces) if options.fluorescent is not None else None,
        lights=lights,
    )
    keys = scene_keys(key, 0, n_scenes)
    return sample_batch(
        keys, tables, n_surfaces, options.specular, options.noise, clip, options.metallic, options.fluorescent
    )
