"""Preprocessing (ccjax.preprocessing, Barnard 1999 §4.6, Table 4.6), against plain-loop references."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from ccjax import preprocessing
from ccjax.estimators.simple import GreyWorld
from ccjax.io import LinearImage
from ccjax.preprocessing import Preprocessing


def _random_image(seed=0, shape=(13, 17)):
    rng = np.random.default_rng(seed)
    rgb = rng.random(shape + (3,)).astype(np.float32)
    rgb[2, 3] = 0.001  # dark
    clipped = rng.random(shape) < 0.05
    return rgb, clipped


def test_usable_pixels_reference():
    rgb, clipped = _random_image()
    peak = max(rgb[y, x].sum() for y in range(rgb.shape[0]) for x in range(rgb.shape[1]) if not clipped[y, x])
    want = np.array(
        [
            [not clipped[y, x] and rgb[y, x].sum() >= 0.02 * peak for x in range(rgb.shape[1])]
            for y in range(rgb.shape[0])
        ]
    )
    np.testing.assert_array_equal(preprocessing.usable_pixels(rgb, clipped, 0.02), want)
    assert not want[2, 3]
    with pytest.raises(ValueError, match="dark"):
        preprocessing.usable_pixels(rgb, clipped, 1.0)


@pytest.mark.parametrize("block", [1, 2, 3, 5])
def test_block_average_reference(block):
    rgb, clipped = _random_image(1)
    usable = ~clipped
    want = []
    for ty in range(rgb.shape[0] // block):
        for tx in range(rgb.shape[1] // block):
            tile = (slice(ty * block, (ty + 1) * block), slice(tx * block, (tx + 1) * block))
            if usable[tile].all():
                want.append(rgb[tile].reshape(-1, 3).mean(axis=0))
    got = preprocessing.block_average(rgb, usable, block)
    np.testing.assert_allclose(got, np.array(want).reshape(-1, 3), rtol=1e-6)


def test_block_spread_filter_reference():
    rgb = np.full((10, 10, 3), [0.5, 0.3, 0.2], np.float32)
    rgb[:, 7:] = [0.2, 0.3, 0.5]  # a boundary inside the second column of 5x5 tiles
    rgb += np.random.default_rng(6).normal(0, 0.002, rgb.shape).astype(np.float32)
    usable = np.ones((10, 10), bool)
    want = []
    for ty in range(2):
        for tx in range(2):
            tile = rgb[ty * 5 : ty * 5 + 5, tx * 5 : tx * 5 + 5].reshape(-1, 3)
            chroma = tile[:, :2] / tile.sum(axis=1, keepdims=True)
            if np.hypot(*(chroma.max(axis=0) - chroma.min(axis=0))) <= 0.04:
                want.append(tile.mean(axis=0))
    got = Preprocessing.parse("ave5-u0.04").apply(rgb, usable)
    assert len(want) == 2 and len(preprocessing.block_average(rgb, usable, 5)) == 4
    np.testing.assert_allclose(got, np.array(want), rtol=1e-5)


def test_cluster_rgb_reference():
    rng = np.random.default_rng(2)
    data = np.concatenate([rng.random((40, 3)), rng.random((5, 3)) * 0.001 + 0.5]).astype(np.float32)
    top = data.max()
    groups: dict = {}
    for value in data:
        cell = tuple(min(int(v / top * 10), 9) for v in value)
        groups.setdefault(cell, []).append(value)
    want = sorted(tuple(np.mean(members, axis=0).round(6)) for members in groups.values())
    got = sorted(tuple(v) for v in preprocessing.cluster_rgb(data, 10).round(6))
    np.testing.assert_allclose(np.array(got), np.array(want), atol=2e-6)
    assert len(got) < len(data)


def test_hull_reduction_keeps_the_hull():
    from scipy.spatial import ConvexHull

    data = np.random.default_rng(3).random((60, 3)).astype(np.float32)
    reduced = preprocessing.hull_reduce(data)
    assert len(reduced) < len(data)
    assert ConvexHull(reduced).volume == pytest.approx(ConvexHull(data).volume, rel=1e-9)
    assert {tuple(v) for v in reduced} <= {tuple(v) for v in data}
    np.testing.assert_array_equal(preprocessing.hull_reduce(data[:3]), data[:3])  # degenerate: kept whole


def test_segmentation_regions():
    rgb = np.zeros((10, 12, 3), np.float32)
    rgb[:, :6] = [0.6, 0.3, 0.1]
    rgb[:, 6:] = [0.1, 0.3, 0.6]
    rgb[:, 6:] *= np.linspace(1.0, 1.15, 6)[None, :, None].astype(np.float32)  # 15 % brightness ramp
    rgb[0:2, 0:2] = [0.3, 0.3, 0.3]  # a 4-pixel region: below the minimum size
    usable = np.ones((10, 12), bool)
    regions = preprocessing.segment(rgb, usable, min_size=5, rg_tolerance=0.01, brightness_tolerance=0.2)
    assert len(regions) == 2
    np.testing.assert_allclose(
        regions[0], rgb[:, :6][~np.pad(np.ones((2, 2), bool), ((0, 8), (0, 4)))].mean(axis=0), rtol=1e-5
    )
    np.testing.assert_allclose(regions[1], rgb[:, 6:].reshape(-1, 3).mean(axis=0), rtol=1e-5)
    # A tighter brightness tolerance splits the ramp.
    assert len(preprocessing.segment(rgb, usable, 5, 0.01, 0.05)) > 2


def test_preprocessing_names():
    assert Preprocessing.parse("ave5") == Preprocessing("ave5", 5, None, None)
    assert Preprocessing.parse("ave3-hull").reduction == "hull"
    assert Preprocessing.parse("generic").segmentation == (5, 0.05, 0.1)
    assert Preprocessing.parse("seg-20-0.005-0.4-hull").segmentation == (20, 0.005, 0.4)
    assert Preprocessing.parse("ave5-u0.04-cluster") == Preprocessing("ave5-u0.04-cluster", 5, None, "cluster", 0.04)
    assert len(set(preprocessing.TABLE_4_6)) == 63
    for name in preprocessing.TABLE_4_6:
        Preprocessing.parse(name)
    with pytest.raises(ValueError, match="preprocessing"):
        Preprocessing.parse("ave0")


@pytest.mark.parametrize(("count", "size"), [(0, 64), (1, 64), (64, 64), (65, 128), (1000, 1024)])
def test_padded_size(count, size):
    assert preprocessing.padded_size(count) == size


def test_surfaces_are_padded_with_a_mask():
    rgb, clipped = _random_image(4, (40, 40))
    data, mask = preprocessing.surfaces(LinearImage(rgb, clipped), "ave2")
    want = preprocessing.block_average(rgb, preprocessing.usable_pixels(rgb, clipped), 2)
    assert data.shape == (preprocessing.padded_size(mask.sum()), 3) and mask.sum() == len(want) > 0
    np.testing.assert_array_equal(data[mask], want)
    assert np.all(data[~mask] == 0)
    unpadded, all_valid = preprocessing.surfaces(LinearImage(rgb, clipped), "ave2", pad=False)
    np.testing.assert_array_equal(unpadded, want)
    assert all_valid.all()


def test_estimate_pixels_grey_world_is_the_masked_mean():
    rgb, clipped = _random_image(5, (16, 20))
    model = GreyWorld(scale=jnp.full(3, 2.0), fallback=jnp.ones(3))
    fast = preprocessing.estimate_pixels(model, jnp.asarray(rgb), jnp.asarray(~clipped))
    slow = model(jnp.asarray(rgb.reshape(-1, 3)), jnp.asarray(~clipped.reshape(-1)))
    np.testing.assert_allclose(np.asarray(fast.illuminant), np.asarray(slow.illuminant), rtol=1e-5)
    np.testing.assert_allclose(
        np.asarray(preprocessing.masked_mean(jnp.asarray(rgb), jnp.asarray(~clipped))), rgb[~clipped].mean(0), rtol=1e-5
    )
