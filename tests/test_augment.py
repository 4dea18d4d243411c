"""ccjax.augment: spectral relighting against a NumPy rendering of the spectra, von Kries relighting
against its closed form, and reproducibility from the key."""

import jax
import jax.numpy as jnp
import jaxtyping
import numpy as np
import pytest
import small_world

from ccjax import augment, scenes


@pytest.fixture(scope="module")
def world():
    return small_world.small_world()


def _numpy_lights(world):
    lights = np.asarray(world.test_illuminants, np.float64)
    sensors = np.asarray(world.camera.sensors, np.float64)
    reflectances = np.asarray(world.reflectances, np.float64)
    return lights, sensors, reflectances


def test_relight_surfaces_matches_spectral_rendering(world):
    tables = scenes.SceneTables.from_world(world)
    rng = np.random.default_rng(0)
    n_refl = world.reflectances.shape[0]
    surfaces = np.stack([rng.choice(n_refl, 5, replace=False) for _ in range(6)]).astype(np.int32)
    mask = np.ones((6, 5), bool)
    mask[:, -1] = False
    relit = jax.jit(augment.relight_surfaces)(jax.random.key(1), tables, jnp.asarray(surfaces), jnp.asarray(mask))
    lights, sensors, reflectances = _numpy_lights(world)
    whites = lights @ sensors
    canonical = (reflectances * np.asarray(world.canonical, np.float64)) @ sensors
    for b in range(6):
        # The ground truth names the light; the surfaces must be rendered under exactly that light.
        light = int(np.argmin(np.linalg.norm(whites - np.asarray(relit.illuminant[b]), axis=1)))
        expected = (reflectances[surfaces[b]] * lights[light]) @ sensors
        np.testing.assert_allclose(relit.rgb[b, :4], expected[:4], rtol=1e-4, atol=1e-7)
        np.testing.assert_array_equal(relit.rgb[b, 4], 0.0)
        np.testing.assert_allclose(relit.illuminant[b], whites[light], rtol=1e-5)
        np.testing.assert_allclose(relit.canonical_rgb[b], canonical[surfaces[b]], rtol=1e-4, atol=1e-7)
    # A pure function of the key.
    again = augment.relight_surfaces(jax.random.key(1), tables, jnp.asarray(surfaces), jnp.asarray(mask))
    np.testing.assert_array_equal(again.rgb, relit.rgb)
    other = augment.relight_surfaces(jax.random.key(2), tables, jnp.asarray(surfaces), jnp.asarray(mask))
    assert not np.array_equal(other.illuminant, relit.illuminant)


def test_relight_mondrians_renders_the_same_surfaces_under_the_new_light(world):
    images = scenes.sample_mondrians(jax.random.key(0), world, 3, height=24, width=24, n_patches=4)
    tables = scenes.SceneTables.from_world(world)
    relit = augment.relight_mondrians(jax.random.key(5), tables, images)
    np.testing.assert_array_equal(relit.labels, images.labels)
    np.testing.assert_array_equal(relit.surfaces, images.surfaces)
    lights, sensors, reflectances = _numpy_lights(world)
    whites = lights @ sensors
    for b in range(3):
        image, white = np.asarray(relit.image[b], np.float64), np.asarray(relit.illuminant[b], np.float64)
        # The white is a world light's white on the image's scale (brightest pixel 1).
        chroma = whites / whites.sum(axis=1, keepdims=True)
        light = int(np.argmin(np.linalg.norm(chroma - white / white.sum(), axis=1)))
        assert np.linalg.norm(chroma[light] - white / white.sum()) < 1e-6
        scale = white / whites[light]
        np.testing.assert_allclose(scale, scale[0], rtol=1e-5)
        assert image.max() == pytest.approx(1.0, rel=1e-6)
        for patch in range(4):
            pixels = image[np.asarray(relit.labels[b]) == patch]
            expected = (reflectances[int(images.surfaces[b, patch])] * lights[light]) @ sensors * scale[0]
            # Matte and noise-free: every pixel of a patch is its response times one shading factor.
            shading = pixels / expected
            np.testing.assert_allclose(shading, shading[0, 0], rtol=1e-4)
            assert 0.3 - 1e-5 <= shading[0, 0] <= 1.0 + 1e-5


def test_von_kries_relight_closed_form():
    rng = np.random.default_rng(2)
    rgb = jnp.asarray(rng.uniform(0, 1, (4, 7, 3)), jnp.float32)
    illuminant = jnp.asarray(rng.uniform(0.2, 1, (4, 3)), jnp.float32)
    targets = jnp.asarray(rng.uniform(0.2, 1, (5, 3)), jnp.float32)
    mask = jnp.asarray(rng.random((4, 7)) < 0.7)
    relit, new = jax.jit(augment.von_kries_relight)(jax.random.key(3), rgb, illuminant, targets, mask)
    for b in range(4):
        # The new white has one target's chromaticity and the old white's brightest channel.
        ratios = np.asarray(targets) / np.asarray(new[b])
        match = np.isclose(ratios, ratios[:, :1], rtol=1e-5).all(axis=1)
        assert match.any()
        assert float(jnp.max(new[b])) == pytest.approx(float(jnp.max(illuminant[b])), rel=1e-6)
        gains = np.asarray(new[b]) / np.asarray(illuminant[b])
        expected = np.where(np.asarray(mask[b])[:, None], np.asarray(rgb[b]) * gains, np.asarray(rgb[b]))
        np.testing.assert_allclose(relit[b], expected, rtol=1e-5)
    # Images as well as surface lists.
    image = jnp.ones((2, 3, 4, 3), jnp.float32)
    relit_image, new_image = augment.von_kries_relight(jax.random.key(0), image, illuminant[:2], targets)
    np.testing.assert_allclose(relit_image[:, 1, 2], new_image / illuminant[:2], rtol=1e-6)


def test_von_kries_bad_shapes():
    with pytest.raises(ValueError, match="targets"):
        augment.von_kries_relight(jax.random.key(0), jnp.ones((2, 4, 3)), jnp.ones((2, 3)), jnp.ones((0, 3)))
    with pytest.raises((ValueError, jaxtyping.TypeCheckError), match="illuminant"):
        augment.von_kries_relight(jax.random.key(0), jnp.ones((2, 4, 3)), jnp.ones((3, 3)), jnp.ones((1, 3)))
