"""Relighting keeps what the images were drawn with, takes the options as `sample_mondrians` does,
and x64 means float64 without changing the scenes.

Oracles: properties of the rendering model (a matte, noise-free patch is flat; a highlight or noise
makes it vary; clipping caps it; without normalisation a patch is its shading times its table
colour), the tables' spectral products for fluorescent patches, and the float32 scenes of the same
key for the float64 ones (equal indices, values equal to float32 rounding)."""

from __future__ import annotations

import doctest

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ccjax
from ccjax.augment import relight_mondrians, relight_surfaces
from ccjax.camera import Camera
from ccjax.estimators import estimate_batch
from ccjax.estimators.simple import GreyWorld
from ccjax.scenes import (
    Fluorescent,
    Metallic,
    SceneOptions,
    SceneTables,
    ShotNoise,
    Specular,
    draw_scenes,
    sample,
    sample_mondrians,
    scene_keys,
)
from ccjax.world import World

SIZE = dict(height=24, width=24, n_patches=4)


@pytest.fixture(scope="module")
def tables(default_world):
    from ccjax.materials import synthetic_fluorescent_surfaces

    return SceneTables.from_world(default_world, metals=True, fluorescent=synthetic_fluorescent_surfaces())


def patch_ranges(images) -> np.ndarray:
    """``(B, P)`` the largest spread (max - min over a patch's pixels, any channel) of each patch."""
    image, labels = np.asarray(images.image, np.float64), np.asarray(images.labels)
    spreads = np.zeros(labels.shape[:1] + (SIZE["n_patches"],))
    for b in range(labels.shape[0]):
        for p in range(SIZE["n_patches"]):
            pixels = image[b][labels[b] == p]
            spreads[b, p] = np.max(pixels.max(axis=0) - pixels.min(axis=0))
    return spreads


def draw(world, **options):
    return sample_mondrians(jax.random.key(3), world, 3, **SIZE, **options)


def test_a_matte_relight_stays_matte(default_world, tables):
    """The control of the tests below: noise-free matte patches are flat, before and after."""
    images = draw(default_world)
    assert np.all(patch_ranges(images) < 1e-6)
    assert np.all(patch_ranges(relight_mondrians(jax.random.key(4), tables, images)) < 1e-6)


@pytest.mark.parametrize(
    "options",
    [{"specular": Specular(probability=1.0)}, {"metallic": Metallic(probability=1.0)}, {"noise": ShotNoise(a=1e-3)}],
    ids=["highlights", "metals", "noise"],
)
def test_a_relight_keeps_highlights_metals_and_noise(default_world, tables, options):
    """Issue 56, item 1: images drawn with highlights (dielectric or metallic, on every patch) or
    noise are relit with them by default (every patch varies), and ``False`` turns them off."""
    images = draw(default_world, **options)
    assert np.all(patch_ranges(images) > 1e-4)
    relit = relight_mondrians(jax.random.key(4), tables, images)
    assert np.all(patch_ranges(relit) > 1e-4)
    off = relight_mondrians(jax.random.key(4), tables, images, **{name: False for name in options})
    assert np.all(patch_ranges(off) < 1e-6)


def test_a_relight_keeps_the_fluorescent_patches(default_world, tables):
    """Every patch drawn fluorescent: relit, each is still the same fluorescent surface, its colour
    that surface's under the new light (the tables' spectral product, up to the patch's shading)."""
    images = draw(default_world, fluorescent=Fluorescent(probability=1.0))
    relit = relight_mondrians(jax.random.key(4), tables, images)
    np.testing.assert_array_equal(np.asarray(relit.fluorescent), np.asarray(images.fluorescent))
    identity, light = np.asarray(relit.fluorescent), np.asarray(relit.light)
    assert np.all(identity >= 0)
    colours = np.asarray(tables.fluorescent_rgb, np.float64)
    image, labels = np.asarray(relit.image, np.float64), np.asarray(relit.labels)
    for b in range(image.shape[0]):
        for p in range(SIZE["n_patches"]):
            got = image[b][labels[b] == p][0]
            want = colours[light[b], identity[b, p]]
            np.testing.assert_allclose(got / got.sum(), want / want.sum(), rtol=1e-5)


def test_a_relight_keeps_clipping_shading_and_scale(default_world, tables):
    """Drawn with a clip level, a fixed shading and no normalisation, a relit patch is exactly its
    shading times its reflectance's colour under the new light (no rescaling), capped at the level."""
    images = draw(default_world, clip=0.2, shading=(0.5, 0.5), normalise=False)
    relit = relight_mondrians(jax.random.key(4), tables, images)
    surface_rgb = np.asarray(tables.surface_rgb, np.float64)
    surfaces, light = np.asarray(relit.surfaces), np.asarray(relit.light)
    labels = np.asarray(relit.labels)
    for b in range(labels.shape[0]):
        want = np.minimum(0.5 * surface_rgb[light[b], surfaces[b]][labels[b]], 0.2)
        np.testing.assert_allclose(np.asarray(relit.image[b], np.float64), want, rtol=1e-6, atol=1e-7)
    assert np.max(np.asarray(relit.image)) <= np.float32(0.2) and np.any(np.asarray(relit.image) == np.float32(0.2))
    # Told otherwise: normalised, unclipped.
    scaled = relight_mondrians(jax.random.key(4), tables, images, clip=False, normalise=True)
    np.testing.assert_allclose(np.asarray(scaled.image).max(axis=(1, 2, 3)), 1.0, rtol=1e-6)


def test_relight_takes_true_as_sample_mondrians_does(default_world, tables):
    """Issue 56, item 2: ``True`` (the thesis recipe) for every option ``sample_mondrians`` takes it for."""
    images = draw(default_world)
    relit = relight_mondrians(jax.random.key(4), tables, images, specular=True, noise=True)
    assert relit.options == SceneOptions(Specular(), ShotNoise())
    relit = relight_mondrians(jax.random.key(4), tables, images, metallic=True, fluorescent=True)
    assert relit.options == SceneOptions(metallic=Metallic(), fluorescent=Fluorescent())
    assert np.isfinite(np.asarray(relit.image)).all()


def test_relight_names_missing_tables(default_world):
    """Images drawn with metallic highlights need the metals' colours: a clear error, not a matte relight."""
    images = draw(default_world, metallic=True)
    with pytest.raises(ValueError, match="metallic"):
        relight_mondrians(jax.random.key(4), SceneTables.from_world(default_world), images)


def test_scenes_carry_their_light(default_world, tables):
    """Scenes, Mondrians and relit scenes say which of the tables' lights they were drawn under
    (the ground truth is that light's white), test lights by default, training ones on request."""
    for lights, whites in [("test", default_world.test_whites), ("train", default_world.train_whites)]:
        scenes = sample(jax.random.key(5), default_world, 6, 8, lights=lights)
        np.testing.assert_allclose(np.asarray(scenes.illuminant), np.asarray(whites)[np.asarray(scenes.light)], 1e-6)
        images = sample_mondrians(jax.random.key(5), default_world, 2, **SIZE, normalise=False, lights=lights)
        np.testing.assert_allclose(np.asarray(images.illuminant), np.asarray(whites)[np.asarray(images.light)], 1e-6)
    relit = relight_surfaces(jax.random.key(6), tables, jnp.zeros((4, 3), jnp.int32), jnp.ones((4, 3), bool))
    np.testing.assert_allclose(
        np.asarray(relit.illuminant), np.asarray(default_world.test_whites)[np.asarray(relit.light)], 1e-6
    )
    with pytest.raises(ValueError, match="lights"):
        sample(jax.random.key(5), default_world, 2, 4, lights="training")


def test_docstring_examples_run(default_world, monkeypatch):
    """The examples of the options added for issue 56 run as written (on the session's default world)."""
    from ccjax import augment, scenes

    monkeypatch.setattr(World, "default", classmethod(lambda cls, *args, **kwargs: default_world))
    for function in (scenes.Scenes, scenes.sample, scenes.sample_mondrians, augment.relight_mondrians):
        finder = doctest.DocTestFinder(recurse=False)
        runner = doctest.DocTestRunner(optionflags=doctest.NORMALIZE_WHITESPACE)
        tests = finder.find(function, globs={"relight_mondrians": relight_mondrians})
        assert tests and tests[0].examples, function
        for test in tests:
            runner.run(test)
        assert runner.failures == 0, function


def small_world() -> World:
    """A small world through the public constructor (so its dtype is the constructor's choice)."""
    camera = Camera.from_name("Canon EOS 5D Mark II")
    metres = np.linspace(380e-9, 780e-9, 101)
    planck = lambda kelvin: 1.0 / (metres**5 * (np.exp(1.4388e-2 / (metres * kelvin)) - 1.0))
    sources = np.stack([planck(t) for t in np.arange(2500.0, 10001.0, 500.0)])
    return World.from_sources(
        reflectances=ccjax.data.sfu_reflectances().values[::6],
        sources=sources,
        n_priority=2,
        canonical=planck(6500.0),
        camera=camera,
    )


OPTIONS = dict(specular=True, noise=True, metallic=True, fluorescent=True)


@pytest.fixture(scope="module")
def drawn_both_ways():
    """The same keys' draws from a world built under x64 (float64) and from its float32 copy."""
    with jax.enable_x64(True):
        wide = small_world()
    narrow = jax.tree.map(lambda leaf: leaf.astype(jnp.float32), wide)
    keys = scene_keys(jax.random.key(7), 0, 64)
    n_lights, n_reflectances = narrow.test_illuminants.shape[0], narrow.reflectances.shape[0]

    def draws(world):
        return (
            draw_scenes(keys, n_lights, n_reflectances, 10),
            sample(jax.random.key(7), world, 32, 10, **OPTIONS),
            sample_mondrians(jax.random.key(7), world, 3, **SIZE, **OPTIONS),
        )

    want = draws(narrow)
    with jax.enable_x64(True):
        got = draws(wide)
    return wide, want, got


@pytest.mark.slow
def test_a_world_built_under_x64_is_float64(drawn_both_ways):
    """Issue 56, item 3: the world, its responses, its scenes and the estimates on them are float64."""
    wide, _, (_, scenes, images) = drawn_both_ways
    with jax.enable_x64(True):
        for leaf in jax.tree.leaves(wide):
            assert leaf.dtype == np.float64
        assert wide.responses(wide.train_illuminants).dtype == np.float64
        assert wide.canonical_white.dtype == np.float64
        assert scenes.rgb.dtype == scenes.canonical_rgb.dtype == images.image.dtype == np.float64
        grey_world = GreyWorld(scale=2.0 * jnp.ones(3, jnp.float64), fallback=wide.canonical_white)
        assert estimate_batch(grey_world, scenes.rgb, scenes.mask).illuminant.dtype == np.float64


@pytest.mark.slow
def test_x64_draws_the_same_scenes(drawn_both_ways):
    """Issue 56, item 3: the same key draws the same lights, surfaces, layouts and options with and
    without x64 (the indices exactly, the values to float32 rounding)."""
    _, (want_draw, want, want_images), (got_draw, got, got_images) = drawn_both_ways
    np.testing.assert_array_equal(np.asarray(got_draw.light), np.asarray(want_draw.light))
    np.testing.assert_array_equal(np.asarray(got_draw.surfaces), np.asarray(want_draw.surfaces))
    np.testing.assert_array_equal(np.asarray(got.light), np.asarray(want.light))
    np.testing.assert_allclose(np.asarray(got.rgb), np.asarray(want.rgb, np.float64), rtol=2e-5, atol=1e-7)
    np.testing.assert_allclose(np.asarray(got.canonical_rgb), np.asarray(want.canonical_rgb, np.float64), rtol=2e-5)
    for name in ("labels", "surfaces", "fluorescent", "light"):
        np.testing.assert_array_equal(np.asarray(getattr(got_images, name)), np.asarray(getattr(want_images, name)))
    np.testing.assert_allclose(np.asarray(got_images.image), np.asarray(want_images.image, np.float64), atol=2e-5)
