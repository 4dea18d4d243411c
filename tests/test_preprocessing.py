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


def _percentile_reference(values: list[float], q: float) -> float:
    """Linear interpolation between order statistics (the definition numpy.percentile follows)."""
    ordered = sorted(values)
    position = q / 100 * (len(ordered) - 1)
    low = int(position)
    high = min(low + 1, len(ordered) - 1)
    return ordered[low] + (position - low) * (ordered[high] - ordered[low])


def _usable_reference(rgb, clipped, dark, percentile, user=None):
    height, width, _ = rgb.shape
    candidate = [
        [not clipped[y, x] and min(rgb[y, x]) > 0 and (user is None or user[y, x]) for x in range(width)]
        for y in range(height)
    ]
    sums = [[float(rgb[y, x].sum()) for x in range(width)] for y in range(height)]
    values = [sums[y][x] for y in range(height) for x in range(width) if candidate[y][x]]
    threshold = dark * _percentile_reference(values, percentile)
    return np.array([[candidate[y][x] and sums[y][x] >= threshold for x in range(width)] for y in range(height)])


@pytest.mark.parametrize("percentile", [99.0, 100.0, 50.0])
def test_usable_pixels_reference(percentile):
    rgb, clipped = _random_image()
    rgb[5, 6, 1] = 0.0  # a zero channel
    user = np.ones(rgb.shape[:2], bool)
    user[:3, :4] = False
    got = preprocessing.usable_pixels(rgb, clipped, 0.02, percentile=percentile)
    np.testing.assert_array_equal(got, _usable_reference(rgb, clipped, 0.02, percentile))
    assert not got[2, 3] and not got[5, 6]
    masked = preprocessing.usable_pixels(rgb, clipped, 0.02, percentile=percentile, mask=user)
    np.testing.assert_array_equal(masked, _usable_reference(rgb, clipped, 0.02, percentile, user))
    # dark = 0: the protocol mask (not clipped, no zero channel, inside the user mask).
    protocol = preprocessing.usable_pixels(rgb, clipped, 0.0, mask=user)
    np.testing.assert_array_equal(protocol, ~clipped & (rgb.min(axis=-1) > 0) & user)


def test_usable_pixels_dark_rule_ignores_one_highlight():
    """The thesis-era rule (percentile 100: the brightest pixel) lets one highlight discard most of
    an image; the 99th percentile does not move."""
    rgb = np.random.default_rng(8).uniform(0.02, 0.06, (40, 40, 3)).astype(np.float32)
    clipped = np.zeros((40, 40), bool)
    before = preprocessing.usable_pixels(rgb, clipped).sum()
    rgb[7, 9] = 0.95
    assert preprocessing.usable_pixels(rgb, clipped).sum() == before == 1600
    assert preprocessing.usable_pixels(rgb, clipped, 0.05, percentile=100.0).sum() < 0.5 * before


def test_usable_pixels_validates():
    rgb, clipped = _random_image()
    with pytest.raises(ValueError, match="dark"):
        preprocessing.usable_pixels(rgb, clipped, 1.0)
    with pytest.raises(ValueError, match="percentile"):
        preprocessing.usable_pixels(rgb, clipped, percentile=0.0)
    with pytest.raises(ValueError, match=r"mask: expected shape \(13, 17\)"):
        preprocessing.usable_pixels(rgb, clipped, mask=np.ones((17, 13), bool))
    with pytest.raises(ValueError, match="mask: expected a boolean"):
        preprocessing.usable_pixels(rgb, clipped, mask=np.ones((13, 17)))


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


@pytest.mark.parametrize("block", [2, 3, 5])
def test_block_average_edges_reference(block):
    """ave<b>-edges: the partial tiles of the right and bottom edges too (13 x 17 leaves partial
    rows and columns for every block here), each kept when all its pixels are usable."""
    rgb, clipped = _random_image(1)
    usable = ~clipped
    height, width = usable.shape
    want = []
    for top in range(0, height, block):
        for left in range(0, width, block):
            tile = (slice(top, min(top + block, height)), slice(left, min(left + block, width)))
            if usable[tile].all():
                want.append(rgb[tile].reshape(-1, 3).astype(np.float64).mean(axis=0))
    got = preprocessing.block_average(rgb, usable, block, edges=True)
    np.testing.assert_allclose(got, np.array(want).reshape(-1, 3), rtol=1e-6)
    assert len(got) > len(preprocessing.block_average(rgb, usable, block))
    np.testing.assert_array_equal(Preprocessing.parse(f"ave{block}-edges").apply(rgb, usable), got)


def test_block_average_in_bands_equals_one_pass(monkeypatch):
    """The image is averaged in bands of tile rows; band boundaries change nothing."""
    rgb, clipped = _random_image(9, (61, 47))
    whole = preprocessing.block_average(rgb, ~clipped, 3, 0.2, edges=True)
    monkeypatch.setattr(preprocessing._reduction, "_CHUNK_PIXELS", 200)  # bands of 3 rows
    np.testing.assert_array_equal(preprocessing.block_average(rgb, ~clipped, 3, 0.2, edges=True), whole)


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
    assert Preprocessing.parse("ave5-edges-u0.04-hull") == Preprocessing(
        "ave5-edges-u0.04-hull", 5, None, "hull", 0.04, edges=True
    )
    assert Preprocessing.parse("pixels").pixels and not Preprocessing.parse("ave5").pixels
    assert len(set(preprocessing.TABLE_4_6)) == 63
    for name in preprocessing.TABLE_4_6:
        Preprocessing.parse(name)
    for bad in ("ave0", "ave5-hull-edges", "pixel"):
        with pytest.raises(ValueError, match="preprocessing"):
            Preprocessing.parse(bad)


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


# ---------------------------------------------------------------------------------------------
# prepare: per-model input


@pytest.fixture(scope="module")
def fitted(default_world):
    from ccjax.estimators import registry

    return {label: registry.fit(label, default_world) for label in ("GW", "DB-GW", "RETINEX", "grey-edge-1-1-0")}


def test_prepare_routes_each_model_to_its_default(fitted):
    rgb, clipped = _random_image(10, (20, 30))
    rgb[4, 4, 2] = 0.0
    image = LinearImage(rgb, clipped)
    user = np.ones((20, 30), bool)
    user[10:, 20:] = False  # e.g. a colour checker
    protocol = ~clipped & (rgb.min(axis=-1) > 0) & user
    for label in ("GW", "RETINEX", "grey-edge-1-1-0"):
        data, mask = preprocessing.prepare(fitted[label], image, mask=user)
        assert data is image.rgb  # the image itself, not a copy
        np.testing.assert_array_equal(mask, protocol)
        assert preprocessing.input_key(fitted[label]) == "pixels"
    data, mask = preprocessing.prepare(fitted["DB-GW"], image, mask=user)
    want = preprocessing.block_average(rgb, preprocessing.usable_pixels(rgb, clipped, mask=user), 5)
    np.testing.assert_array_equal(data[mask], want)
    assert preprocessing.input_key(fitted["DB-GW"]) == "ave5"
    # An explicit preprocessing overrides the default of surface models, never of image models.
    data, mask = preprocessing.prepare(fitted["GW"], image, "ave2")
    np.testing.assert_array_equal(data, preprocessing.surfaces(image, "ave2")[0])
    assert preprocessing.prepare(fitted["grey-edge-1-1-0"], image, "ave2")[0] is image.rgb
    assert preprocessing.prepare(fitted["DB-GW"], image, "pixels")[0] is image.rgb


def test_run_model_on_pixels_equals_the_pixel_list(fitted):
    rgb, clipped = _random_image(11, (16, 24))
    image = LinearImage(rgb, clipped)
    for label in ("GW", "DB-GW", "RETINEX"):
        model = fitted[label]
        data, mask = preprocessing.prepare(model, image, "pixels")
        got = preprocessing.run_model(model, jnp.asarray(data), jnp.asarray(mask))
        usable = ~clipped & (rgb.min(axis=-1) > 0)
        want = model(jnp.asarray(rgb[usable]), jnp.ones(int(usable.sum()), bool))
        np.testing.assert_allclose(np.asarray(got.illuminant), np.asarray(want.illuminant), rtol=1e-5)
        if label != "DB-GW":  # estimate_image's default is the per-pixel input
            default = preprocessing.estimate_image(model, image)
            np.testing.assert_allclose(np.asarray(default.illuminant), np.asarray(got.illuminant), rtol=1e-6)


def test_input_shapes_cover_every_prepared_input(fitted):
    assert preprocessing.input_shapes(fitted["GW"], (48, 64)) == [((48, 64, 3), (48, 64))]
    assert preprocessing.input_shapes(fitted["grey-edge-1-1-0"], (48, 64), "ave5") == [((48, 64, 3), (48, 64))]
    # 600 x 800 at ave5: 120 x 160 = 19,200 tiles at most -> classes 64 .. 32768.
    shapes = preprocessing.input_shapes(fitted["DB-GW"], (600, 800))
    assert [n for (n, _), _ in shapes] == [64 << k for k in range(10)]
    edges = preprocessing.input_shapes(fitted["DB-GW"], (12, 12), "ave5-edges")  # 9 tiles
    assert edges == [((64, 3), (64,))]
    rgb, clipped = _random_image(12, (43, 41))
    for name in ("ave1", "ave3-edges", "ave2-hull"):
        data, _ = preprocessing.prepare(fitted["DB-GW"], LinearImage(rgb, clipped), name)
        assert (data.shape, data.shape[:1]) in preprocessing.input_shapes(fitted["DB-GW"], (43, 41), name)


# ---------------------------------------------------------------------------------------------
# read_mask


def test_read_mask_grey_rgb_png_and_tiff(tmp_path):
    import tifffile

    from ccjax import io

    want = np.random.default_rng(13).random((6, 9)) < 0.7
    grey16 = np.where(want, 65535, 0).astype(np.uint16)
    tifffile.imwrite(tmp_path / "grey16.tif", grey16)
    tifffile.imwrite(tmp_path / "grey8.tif", np.where(want, 1, 0).astype(np.uint8))
    rgb8 = np.zeros((6, 9, 3), np.uint8)
    rgb8[..., 1] = np.where(want, 200, 0)  # any nonzero channel is usable
    io.write_png(tmp_path / "rgb8.png", rgb8)
    io.write_png(tmp_path / "rgb16.png", np.repeat(grey16[..., None], 3, axis=-1))
    for name in ("grey16.tif", "grey8.tif", "rgb8.png", "rgb16.png"):
        mask = io.read_mask(tmp_path / name, (6, 9))
        assert mask.dtype == bool
        np.testing.assert_array_equal(mask, want, err_msg=name)
    np.testing.assert_array_equal(io.read_mask(tmp_path / "rgb8.png", (6, 9, 3)), want)


def test_read_mask_errors_name_the_file(tmp_path):
    from ccjax import io

    io.write_png(tmp_path / "m.png", np.ones((4, 5, 3), np.uint8))
    with pytest.raises(ValueError, match=r"m\.png is 5x4 pixels \(width x height\), but its image is 6x4"):
        io.read_mask(tmp_path / "m.png", (4, 6))
    with pytest.raises(FileNotFoundError, match=r"missing\.png"):
        io.read_mask(tmp_path / "missing.png", (4, 5))
    (tmp_path / "m.jpg").write_bytes(b"")
    with pytest.raises(ValueError, match=r"m\.jpg: unsupported file type"):
        io.read_mask(tmp_path / "m.jpg", (4, 5))
    (tmp_path / "bad.png").write_bytes(b"not a png")
    with pytest.raises(ValueError, match=r"mask: cannot read .*bad\.png"):
        io.read_mask(tmp_path / "bad.png", (4, 5))
