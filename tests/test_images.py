"""Image I/O, preprocessing, correction, cache, Mondrians and the image CLI (ccjax/images.py)."""

from __future__ import annotations

import json
import struct
import zlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import tifffile
from small_world import small_world

from ccjax import cli, images, scenes
from ccjax.images import LinearImage, Preprocessing
from ccjax.metrics import angular_error


@pytest.fixture(scope="module")
def world():
    return small_world()


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


# ---------------------------------------------------------------------------------------------
# PNG: an independent encoder written from the PNG specification (filters 0-4, plain loops)


def _paeth(a, b, c):
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    return a if pa <= pb and pa <= pc else (b if pb <= pc else c)


def _reference_png(pixels: np.ndarray, filters) -> bytes:
    height, width, channels = pixels.shape
    depth = 16 if pixels.dtype == np.uint16 else 8
    bpp = channels * depth // 8
    rows = [bytes(pixels[y].astype(">u2" if depth == 16 else np.uint8).tobytes()) for y in range(height)]
    out, previous = bytearray(), bytes(len(rows[0]))
    for y, row in enumerate(rows):
        kind = filters[y % len(filters)]
        out.append(kind)
        for x in range(len(row)):
            a = row[x - bpp] if x >= bpp else 0
            b = previous[x]
            c = previous[x - bpp] if x >= bpp else 0
            predictor = [0, a, b, (a + b) // 2, _paeth(a, b, c)][kind]
            out.append((row[x] - predictor) % 256)
        previous = row

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    colour = {1: 0, 3: 2, 4: 6}[channels]
    header = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(bytes(out))) + chunk(b"IEND", b"")
    )


@pytest.mark.parametrize("dtype", [np.uint16, np.uint8])
@pytest.mark.parametrize("filters", [[0], [1], [2], [3], [4], [0, 1, 2, 3, 4], [4, 3, 1]])
def test_png_decoder_undoes_every_filter(tmp_path, dtype, filters):
    rng = np.random.default_rng(len(filters))
    pixels = rng.integers(0, np.iinfo(dtype).max, (7, 6, 3), endpoint=True).astype(dtype)
    pixels[:3] = pixels[0, 0]  # flat rows make the predictors matter
    path = tmp_path / "f.png"
    path.write_bytes(_reference_png(pixels, filters))
    np.testing.assert_array_equal(images.read_png(path), pixels)


@pytest.mark.parametrize("shape", [(1, 1), (3, 17), (16, 2)])
def test_png_writer_round_trip(tmp_path, shape):
    pixels = np.random.default_rng(0).integers(0, 65535, shape + (3,), endpoint=True).astype(np.uint16)
    images.write_png(tmp_path / "w.png", pixels)
    np.testing.assert_array_equal(images.read_png(tmp_path / "w.png"), pixels)


# ---------------------------------------------------------------------------------------------
# read_image


def test_read_16bit_black_saturation_and_clipping(tmp_path):
    codes = np.array([[[100, 1100, 60000], [64000, 50, 100]], [[65535, 65535, 65535], [3000, 2000, 1000]]], np.uint16)
    images.write_png(tmp_path / "a.png", codes)
    image = images.read_image(tmp_path / "a.png", black_level=100, saturation=64000)
    want = np.maximum(codes.astype(np.float64) - 100, 0) / (64000 - 100)
    np.testing.assert_allclose(image.rgb, want, rtol=1e-6)
    np.testing.assert_array_equal(image.clipped, [[False, True], [True, False]])
    assert image.bit_depth == 16


def test_read_tiff_integer_float_and_planar(tmp_path):
    codes = np.random.default_rng(1).integers(0, 60000, (4, 5, 3)).astype(np.uint16)
    tifffile.imwrite(tmp_path / "a.tif", codes, photometric="rgb")
    np.testing.assert_allclose(images.read_image(tmp_path / "a.tif").rgb, codes / 65535.0, rtol=1e-6)
    tifffile.imwrite(tmp_path / "p.tif", np.moveaxis(codes, -1, 0), photometric="rgb", planarconfig="separate")
    np.testing.assert_allclose(images.read_image(tmp_path / "p.tif").rgb, codes / 65535.0, rtol=1e-6)
    floats = np.random.default_rng(2).random((4, 5, 3)).astype(np.float32) * 0.9
    tifffile.imwrite(tmp_path / "f.tif", floats, photometric="rgb")
    np.testing.assert_allclose(images.read_image(tmp_path / "f.tif").rgb, floats, rtol=1e-6)


def _zero_size_png(path):
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = struct.pack(">IIBBBBB", 0, 0, 16, 2, 0, 0, 0)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b"")
    )


def _bad_files(tmp_path):
    eight = tmp_path / "eight.png"
    images.write_png(eight, np.full((4, 4, 3), 100, np.uint8))
    garbage = tmp_path / "garbage.png"
    garbage.write_bytes(b"this is not an image")
    clipped = tmp_path / "clipped.png"
    images.write_png(clipped, np.full((4, 4, 3), 65535, np.uint16))
    empty = tmp_path / "empty.png"
    _zero_size_png(empty)
    grey = tmp_path / "grey.tif"
    tifffile.imwrite(grey, np.ones((4, 4), np.uint16))
    return {"8-bit": eight, "cannot read": garbage, "clipped": clipped, "no pixels": empty, "greyscale": grey}


def test_bad_files_raise_clear_errors(tmp_path):
    for message, path in _bad_files(tmp_path).items():
        with pytest.raises(ValueError, match=message) as error:
            images.read_image(path)
        assert str(path) in str(error.value)
    with pytest.raises(FileNotFoundError):
        images.read_image(tmp_path / "missing.png")
    linear = images.read_image(tmp_path / "eight.png", assume_linear=True)
    np.testing.assert_allclose(linear.rgb, 100 / 255.0, rtol=1e-6)


# ---------------------------------------------------------------------------------------------
# Preprocessing, against plain-loop references


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
    np.testing.assert_array_equal(images.usable_pixels(rgb, clipped, 0.02), want)
    assert not want[2, 3]


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
    np.testing.assert_allclose(images.block_average(rgb, usable, block), np.array(want).reshape(-1, 3), rtol=1e-6)


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
    got = images.Preprocessing.parse("ave5-u0.04").apply(rgb, usable)
    assert len(want) == 2 and len(images.block_average(rgb, usable, 5)) == 4
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
    got = sorted(tuple(v) for v in images.cluster_rgb(data, 10).round(6))
    np.testing.assert_allclose(np.array(got), np.array(want), atol=2e-6)
    assert len(got) < len(data)


def test_hull_reduction_keeps_the_hull():
    from scipy.spatial import ConvexHull

    data = np.random.default_rng(3).random((60, 3)).astype(np.float32)
    reduced = images.hull_reduce(data)
    assert len(reduced) < len(data)
    assert ConvexHull(reduced).volume == pytest.approx(ConvexHull(data).volume, rel=1e-9)
    assert {tuple(v) for v in reduced} <= {tuple(v) for v in data}
    np.testing.assert_array_equal(images.hull_reduce(data[:3]), data[:3])  # degenerate: kept whole


def test_segmentation_regions():
    rgb = np.zeros((10, 12, 3), np.float32)
    rgb[:, :6] = [0.6, 0.3, 0.1]
    rgb[:, 6:] = [0.1, 0.3, 0.6]
    rgb[:, 6:] *= np.linspace(1.0, 1.15, 6)[None, :, None].astype(np.float32)  # 15 % brightness ramp
    rgb[0:2, 0:2] = [0.3, 0.3, 0.3]  # a 4-pixel region: below the minimum size
    usable = np.ones((10, 12), bool)
    regions = images.segment(rgb, usable, min_size=5, rg_tolerance=0.01, brightness_tolerance=0.2)
    assert len(regions) == 2
    np.testing.assert_allclose(
        regions[0], rgb[:, :6][~np.pad(np.ones((2, 2), bool), ((0, 8), (0, 4)))].mean(axis=0), rtol=1e-5
    )
    np.testing.assert_allclose(regions[1], rgb[:, 6:].reshape(-1, 3).mean(axis=0), rtol=1e-5)
    # A tighter brightness tolerance splits the ramp.
    assert len(images.segment(rgb, usable, 5, 0.01, 0.05)) > 2


def test_preprocessing_names():
    assert Preprocessing.parse("ave5") == Preprocessing("ave5", 5, None, None)
    assert Preprocessing.parse("ave3-hull").reduction == "hull"
    assert Preprocessing.parse("generic").segmentation == (5, 0.05, 0.1)
    assert Preprocessing.parse("seg-20-0.005-0.4-hull").segmentation == (20, 0.005, 0.4)
    assert Preprocessing.parse("ave5-u0.04-cluster") == Preprocessing("ave5-u0.04-cluster", 5, None, "cluster", 0.04)
    assert len(set(images.TABLE_4_6)) == 63
    for name in images.TABLE_4_6:
        Preprocessing.parse(name)
    with pytest.raises(ValueError, match="preprocessing"):
        Preprocessing.parse("ave0")


def test_surfaces_are_padded_with_a_mask():
    rgb, clipped = _random_image(4, (40, 40))
    data, mask = images.surfaces(LinearImage(rgb, clipped), "ave2")
    assert data.shape == (images._bucket(mask.sum()), 3) and mask.sum() > 0
    assert np.all(data[~mask] == 0)


# ---------------------------------------------------------------------------------------------
# Correction and preview


def test_diagonal_and_sharpened_correction():
    rng = np.random.default_rng(5)
    light, canonical = np.array([0.9, 0.6, 0.3], np.float32), np.array([0.7, 1.0, 0.8], np.float32)
    corrected = np.asarray(images.correct(light, light, canonical))
    np.testing.assert_allclose(corrected / corrected.sum(), canonical / canonical.sum(), rtol=1e-5)
    assert corrected.sum() == pytest.approx(light.sum(), rel=1e-5)  # grey keeps its R+G+B
    transform = np.eye(3, dtype=np.float32) + 0.2 * rng.standard_normal((3, 3)).astype(np.float32)
    sharpened = np.asarray(images.correct(light, light, canonical, transform))
    ratio = (transform @ sharpened) / (transform @ canonical)
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-4)  # T e maps to the direction of T w_C
    pixels = rng.random((4, 5, 3)).astype(np.float32)
    matrix = np.asarray(images.correction_map(jnp.asarray(light), jnp.asarray(canonical)))
    np.testing.assert_allclose(np.asarray(images.correct(pixels, light, canonical)), pixels @ matrix.T, rtol=1e-5)


def test_preview_renders_the_canonical_white_grey(world):
    matrix = images.preview_matrix(world)
    white = np.asarray(world.canonical_white)[None, None] * np.ones((2, 2, 1), np.float32)
    preview = images.srgb_preview(white, matrix)
    assert preview.dtype == np.uint8 and np.all(preview == preview[0, 0, 0])


# ---------------------------------------------------------------------------------------------
# Ground truth, cache, folds


def test_ground_truth_round_trip_and_errors(tmp_path):
    images.write_ground_truth(tmp_path / "gt.csv", ["a.png", "b.png"], [[0.2, 0.3, 0.5], [1.0, 2.0, 3.0]])
    truth = images.read_ground_truth(tmp_path / "gt.csv")
    np.testing.assert_allclose(truth["b.png"], [1.0, 2.0, 3.0])
    (tmp_path / "bad.csv").write_text("name,red,green,blue\na,1,2,3\n")
    with pytest.raises(ValueError, match="image,r,g,b"):
        images.read_ground_truth(tmp_path / "bad.csv")
    (tmp_path / "neg.csv").write_text("image,r,g,b\na,-1,2,3\n")
    with pytest.raises(ValueError, match="line 2"):
        images.read_ground_truth(tmp_path / "neg.csv")
    with pytest.raises(ValueError, match="not found"):
        images.match_ground_truth(truth, tmp_path)


def test_cached_fit_loads_from_disk(world, cache, monkeypatch):
    from ccjax.estimators import registry

    first = images.cached_fit("DB-GW", world)
    assert len(list(cache.glob("*.pkl"))) == 1
    monkeypatch.setattr(registry, "fit", lambda *a, **k: pytest.fail("refitted instead of loading the cache"))
    second = images.cached_fit("DB-GW", world)
    np.testing.assert_array_equal(np.asarray(first.scale), np.asarray(second.scale))


def test_fold_worlds_learn_only_other_folds(world):
    pool = np.concatenate([np.asarray(world.train_illuminants), np.asarray(world.test_illuminants)])
    whites = pool @ np.asarray(world.camera.sensors)
    truth = whites[[0, 5, 9, 20, 25, 30]] * 3.0  # any scale
    fold_of, worlds = images.fold_worlds(world, truth, 3)
    np.testing.assert_array_equal(fold_of, [0, 1, 2, 0, 1, 2])
    for fold, fold_world in enumerate(worlds):
        learned = np.asarray(fold_world.train_whites)
        want = truth[fold_of != fold]
        rg = lambda v: v[:, :2] / v.sum(axis=1, keepdims=True)
        np.testing.assert_allclose(np.sort(rg(learned), axis=0), np.sort(rg(want), axis=0), atol=1e-5)


# ---------------------------------------------------------------------------------------------
# Synthetic Mondrians


NOISE = scenes.ShotNoise(a=1e-4, b=0.0)


@pytest.fixture(scope="module")
def mondrians(world):
    """50 clean and 50 noisy 64x64 Mondrians with 12 patches, same keys (two compiles in all)."""
    clean = scenes.sample_mondrians(jax.random.key(3), world, 50, height=64, width=64, n_patches=12)
    noisy = scenes.sample_mondrians(jax.random.key(3), world, 50, height=64, width=64, n_patches=12, noise=NOISE)
    return clean, noisy


def test_mondrian_layout_and_spectral_rendering(world, mondrians):
    batch = mondrians[0]
    refl, sensors = np.asarray(world.reflectances, np.float64), np.asarray(world.camera.sensors, np.float64)
    lights = np.asarray(world.test_illuminants, np.float64)
    whites = lights @ sensors
    for b in range(4):
        labels, image = np.asarray(batch.labels[b]), np.asarray(batch.image[b], np.float64)
        assert sorted(np.unique(labels)) == list(range(12))
        assert image.max() == pytest.approx(1.0)
        illuminant = np.asarray(batch.illuminant[b], np.float64)
        light = int(
            np.argmin(np.abs(whites / whites.max(axis=1, keepdims=True) - illuminant / illuminant.max()).sum(axis=1))
        )
        scale = illuminant[0] / whites[light, 0]  # the image's normalisation
        for patch in range(12):
            expected = (refl[int(batch.surfaces[b, patch])] * lights[light]) @ sensors * scale
            shade = image[labels == patch] / expected
            assert np.allclose(shade, shade.flat[0], rtol=1e-4) and 0.3 - 1e-6 <= shade.flat[0] <= 1.0 + 1e-6


def test_mondrian_noise_and_normalisation(mondrians):
    clean, noisy = mondrians
    assert np.allclose(np.asarray(noisy.image).max(axis=(1, 2, 3)), 1.0)
    # Same key: same layout, light and shading; residual variance ~ 1e-4 * rho.
    scale = np.asarray(noisy.illuminant) / np.asarray(clean.illuminant)
    residual = np.asarray(noisy.image) / scale[:, None, None, :1] - np.asarray(clean.image)
    ratio = np.mean(residual**2) / np.mean(1e-4 * np.asarray(clean.image))
    assert 0.8 < ratio < 1.2


def test_mondrian_highlights_are_the_light_colour():
    labels = jnp.asarray(np.repeat(np.arange(4), 64).reshape(16, 16))
    patch_rgb = jnp.asarray(np.random.default_rng(8).random((4, 3)), jnp.float32)
    white = jnp.array([0.9, 1.0, 0.6], jnp.float32)
    render = jax.jit(
        lambda spec, clip: scenes.render_mondrian(
            jax.random.key(0), labels, patch_rgb, white, specular=spec, clip=clip, normalise=False
        )[0],
        static_argnums=(0, 1),
    )
    matte = np.asarray(render(None, None))
    shiny = np.asarray(render(scenes.Specular(probability=1.0, max_amount=2.0), None))
    extra = shiny - matte
    assert extra.max() > 0.05
    direction = extra / np.maximum(extra.sum(-1, keepdims=True), 1e-12)
    big = extra.sum(-1) > 1e-3
    np.testing.assert_allclose(
        direction[big], np.broadcast_to(np.asarray(white) / float(white.sum()), direction[big].shape), atol=1e-4
    )


# ---------------------------------------------------------------------------------------------
# Command line


def _patch_world(monkeypatch, world):
    monkeypatch.setattr(images, "cached_world", lambda *a, **k: world)


@pytest.mark.parametrize("command", ["estimate", "correct", "evaluate"])
def test_cli_bad_files_exit_non_zero_and_write_nothing(tmp_path, world, cache, monkeypatch, capsys, command):
    _patch_world(monkeypatch, world)
    good = tmp_path / "good"
    images.write_dataset(good, np.full((1, 8, 8, 3), 0.5), [[1.0, 1.0, 1.0]])
    for message, bad in _bad_files(tmp_path).items():
        folder = tmp_path / f"set-{bad.stem}"
        folder.mkdir()
        (folder / "a.png").write_bytes((good / "image-0000.png").read_bytes())
        (folder / bad.name).write_bytes(bad.read_bytes())
        images.write_ground_truth(folder / "gt.csv", ["a.png", bad.name], [[1, 1, 1], [1, 1, 1]])
        out = tmp_path / f"out-{bad.stem}"
        argv = {
            "estimate": ["estimate", str(folder), "--method", "GW", "--json"],
            "correct": ["correct", str(folder), str(out), "--method", "GW"],
            "evaluate": [
                "evaluate",
                str(folder),
                "--ground-truth",
                str(folder / "gt.csv"),
                "--methods",
                "GW",
                "--json",
                str(out),
            ],
        }[command]
        assert cli.main(argv + ["--no-progress"]) == 2
        captured = capsys.readouterr()
        assert message in captured.err and str(bad.name) in captured.err
        assert captured.out == "" and not out.exists()


def test_cli_estimate_json_and_correct(tmp_path, world, cache, monkeypatch, capsys, mondrians):
    _patch_world(monkeypatch, world)
    batch = mondrians[1]
    images.write_dataset(tmp_path / "in", batch.image[:2], batch.illuminant[:2])
    assert cli.main(["estimate", str(tmp_path / "in"), "--method", "GW", "--json", "--no-progress"]) == 0
    records = json.loads(capsys.readouterr().out)
    assert [r["path"].endswith(f"image-000{i}.png") for i, r in enumerate(records)] == [True, True]
    assert all(set(r) == {"path", "illuminant", "rg", "ok"} and r["ok"] for r in records)
    assert cli.main(["correct", str(tmp_path / "in"), str(tmp_path / "out"), "--method", "GW", "--no-progress"]) == 0
    corrected = images.read_image(tmp_path / "out" / "image-0000.png")
    assert corrected.rgb.shape == (64, 64, 3)
    assert images.read_png(tmp_path / "out" / "image-0000_preview.png").dtype == np.uint8


def test_round_trip_files_equal_memory(tmp_path, world, cache, monkeypatch, mondrians):
    """Acceptance: 50 Mondrians written as 16-bit PNG; `ccjax evaluate` on the files agrees with the
    same estimators on the in-memory images quantised the same way, within 1e-3 degrees."""
    _patch_world(monkeypatch, world)
    methods = ["GW", "DB-GW", "RETINEX", "grey-edge-1-6-2"]
    batch = mondrians[1]
    gt = images.write_dataset(tmp_path / "set", batch.image, batch.illuminant)
    assert (
        cli.main(
            [
                "evaluate",
                str(tmp_path / "set"),
                "--ground-truth",
                str(gt),
                "--methods",
                ",".join(methods),
                "--json",
                str(tmp_path / "r.json"),
                "--no-progress",
            ]
        )
        == 0
    )
    records = json.loads((tmp_path / "r.json").read_text())["images"]
    codes = images.quantise(np.asarray(batch.image))
    for method in methods:
        model = images.cached_fit(method, world)
        file_errors = [r["angular"] for r in records if r["method"] == method]
        for index in range(50):
            memory = LinearImage(codes[index].astype(np.float32) / 65535.0, np.any(codes[index] >= 65535, axis=-1))
            estimate = images.estimate_image(model, memory)
            error = float(angular_error(estimate.illuminant, jnp.asarray(batch.illuminant[index])))
            assert abs(error - file_errors[index]) <= 1e-3, (method, index)


def _write_dng(path, cfa, white):
    """A minimal uncompressed RGGB DNG (tifffile + the DNG tags LibRaw needs)."""
    extratags = [
        (33421, "H", 2, (2, 2), True),  # CFARepeatPatternDim
        (33422, "B", 4, (0, 1, 1, 2), True),  # CFAPattern: RGGB
        (50706, "B", 4, (1, 4, 0, 0), True),  # DNGVersion
        (50707, "B", 4, (1, 1, 0, 0), True),  # DNGBackwardVersion
        (50708, "s", 0, "ccjax test", True),  # UniqueCameraModel
        (50714, "H", 1, 0, True),  # BlackLevel
        (50717, "H", 1, white, True),  # WhiteLevel
        (50721, "2i", 9, (1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1), True),  # ColorMatrix1
        (50778, "H", 1, 21, True),  # CalibrationIlluminant1
        (271, "s", 0, "Canon", True),
        (272, "s", 0, "Canon EOS 5D Mark II", True),
    ]
    tifffile.imwrite(path, cfa, photometric=32803, extratags=extratags, metadata=None)


def test_raw_file_through_rawpy(tmp_path):
    pytest.importorskip("rawpy", reason="the raw extra (rawpy) is not installed")
    cfa = np.zeros((64, 96), np.uint16)
    cfa[0::2, 0::2], cfa[0::2, 1::2], cfa[1::2, 0::2], cfa[1::2, 1::2] = 1000, 2000, 2000, 3000
    cfa[:2, :2] = 4095  # one saturated Bayer quad
    _write_dng(tmp_path / "a.dng", cfa, 4095)
    image = images.read_image(tmp_path / "a.dng")
    assert image.rgb.shape == (32, 48, 3)  # one pixel per Bayer quad (no demosaicing)
    np.testing.assert_allclose(image.rgb[5, 5], np.array([1000, 2000, 3000]) / 4095, rtol=2e-4)
    assert image.clipped[0, 0] and image.clipped.sum() == 1
