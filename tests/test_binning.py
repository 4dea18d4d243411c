"""Colour by Correlation is scale-free (the degenerate sweep's x1e-12 case): a scene
multiplied by any positive factor has the same chromaticities, so the same bins and the same
estimate; "black" is relative to the scene, not an absolute 1e-12."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from small_world import small_world

from ccjax import _colour, scenes
from ccjax.estimators import registry
from ccjax.estimators.correlation import _binning

SCALES = (1e-12, 1e-6, 1e6)

LABELS = ("C-by-C-MMSE", "C-by-C-MAP", "C-by-C-01", "soft-C-by-C-MMSE", "RGB-C-by-C-MMSE", "soft-RGB-C-by-C-MMSE")
"""2-D rows of Table 4.2 (chromaticity only: exactly scale-invariant; MLM scores as MAP), the soft 2-D form and
the 3-D form, whose brightness levels are relative to the scene's mean brightness."""


@pytest.fixture(scope="module", autouse=True)
def _private_cache(tmp_path_factory):
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("CCJAX_CACHE", str(tmp_path_factory.mktemp("ccjax-cache")))
        yield


@pytest.fixture(scope="module")
def world():
    return small_world()


@pytest.fixture(scope="module")
def surfaces(world):
    batch = scenes.sample(jax.random.key(5), world, 6, 12)
    rgb = np.array(batch.rgb, np.float32)
    rgb[0, :3] = 0.0  # some black surfaces: never evidence, at any scale
    mask = np.asarray(batch.mask)
    return rgb, mask


def _rg(rgb: np.ndarray) -> np.ndarray:
    rgb = np.asarray(rgb, np.float64)
    return rgb[..., :2] / rgb.sum(axis=-1, keepdims=True)


def test_chromaticity_matches_the_ratio_at_every_scale():
    rgb = np.random.default_rng(0).uniform(0.01, 1.0, (200, 3)).astype(np.float32)
    for scale in (1.0, *SCALES, 1e-30):
        got = np.asarray(_colour.rg(jnp.asarray(rgb * np.float32(scale))), np.float64)
        np.testing.assert_allclose(got, _rg(rgb), rtol=0, atol=1e-6)
    np.testing.assert_array_equal(_colour.rg(jnp.zeros((2, 3), jnp.float32)), np.full((2, 2), 1 / 3, np.float32))


def test_bins_do_not_depend_on_the_scale(surfaces):
    rgb = surfaces[0].reshape(-1, 3)
    expected = np.clip(np.floor(_rg(np.where(rgb.sum(-1, keepdims=True) > 0, rgb, 1.0)) * 50), 0, 49)
    lit = rgb.sum(-1) > 0
    for scale in (1.0, *SCALES):
        bins = np.asarray(_binning.rg_bins(jnp.asarray(rgb * np.float32(scale))))
        np.testing.assert_array_equal(bins[lit], expected[lit])


def test_black_is_relative_to_the_brightest_pixel():
    rgb = jnp.asarray([[0.5, 0.4, 0.3], [1e-14, 1e-14, 1e-14], [0.0, 0.0, 0.0], [1e-3, 2e-3, 1e-3]], jnp.float32)
    mask = jnp.ones(4, bool)
    for scale in (1.0, *SCALES):
        valid = _colour.valid_pixels(rgb * jnp.float32(scale), mask)
        # 3e-14 is 2.5e-14 of the brightest (1.2): black at every scale; 4e-3 is evidence at every scale.
        np.testing.assert_array_equal(valid, [True, False, False, True])
    assert not np.any(_colour.valid_pixels(jnp.zeros((4, 3), jnp.float32), mask))
    # The brightest pixel is taken over the masked-in pixels only.
    np.testing.assert_array_equal(
        _colour.valid_pixels(rgb * 1e-12, jnp.asarray([False, True, True, True])), [False, True, False, True]
    )


@pytest.mark.parametrize("label", LABELS)
def test_scaled_scenes_answer_as_the_original(world, surfaces, label):
    model = registry.fit(label, world)
    rgb, mask = surfaces
    run = jax.jit(jax.vmap(model))
    reference = run(jnp.asarray(rgb), jnp.asarray(mask))
    assert np.all(np.asarray(reference.ok))
    for scale in SCALES:
        scaled = run(jnp.asarray(rgb * np.float32(scale)), jnp.asarray(mask))
        assert np.all(np.asarray(scaled.ok)), (label, scale)
        np.testing.assert_allclose(
            _rg(np.asarray(scaled.illuminant)), _rg(np.asarray(reference.illuminant)), rtol=0, atol=1e-5
        )
