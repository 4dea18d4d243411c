"""The field's per-pixel protocol on synthetic raw photographs.

Mondrians of the default world's real camera (Canon EOS 5D Mark II) with specular highlights,
shot noise, exposures that clip some of them, and zero channels (black-clamped noise), written as
16-bit PNGs. Grey world and shades of grey (p = 6) must equal a NumPy per-pixel implementation
on the protocol mask (no channel 0, none at or above 0.98 of the maximum; tests/pixel_reference.py)
to 1e-4 degrees, through the library and through ``ccjax evaluate``. The dark rule of the
surface-list path (relative to the 99th percentile of brightness) must barely notice one added
unclipped highlight pixel, which the old rule (relative to the brightest pixel) does not survive.
30 images in the default suite, the full 200 in the slow one.
"""

from __future__ import annotations

import csv

import jax
import jax.numpy as jnp
import numpy as np
import pixel_reference as reference
import pytest

from ccjax import cli, io, preprocessing, scenes
from ccjax.runs import store

SIZE = 128  # an unclipped highlight is real data: in 625 ave5 blocks it moves GW by < 0.5 %
HIGHLIGHT = round(0.95 * 65535)
STATISTICS = ("GW", "shades-of-grey-p6")
ORACLES = {"GW": reference.grey_world, "shades-of-grey-p6": reference.shades_of_grey}


def _protocol_set(world, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``(codes (count, SIZE, SIZE, 3) uint16, truth (count, 3))``; image ``i`` is the same
    whatever ``count`` (its own keys and seeds)."""
    batch = scenes.sample_mondrians(
        jax.random.key(12), world, count, height=SIZE, width=SIZE, n_patches=12, specular=True, noise=True
    )
    images = np.asarray(batch.image, np.float64)
    codes = np.zeros(images.shape, np.uint16)
    for index in range(count):
        rng = np.random.default_rng([12, index])
        # Exposures from dim (brightest value 0.3 of saturation) to over-exposed (highlights clip
        # at 65535, and others between 0.98 and 1 are clipped by the protocol only).
        codes[index] = io.quantise(images[index] * rng.uniform(0.3, 1.6))
        # Zero channels: 1 % of the pixels lose one channel to black (clamped noise, dead photosites).
        dead = np.argwhere(rng.random((SIZE, SIZE)) < 0.01)
        codes[index, dead[:, 0], dead[:, 1], rng.integers(0, 3, len(dead))] = 0
    return codes, np.asarray(batch.illuminant, np.float64)


def _write(folder, codes, truth) -> tuple[list, str]:
    names = [f"image-{index:04d}.png" for index in range(len(codes))]
    for name, image in zip(names, codes, strict=True):
        io.write_png(folder / name, image)
    io.write_ground_truth(folder / "groundtruth.csv", names, truth)
    return [folder / name for name in names], str(folder / "groundtruth.csv")


def _with_highlight(codes: np.ndarray, seed: int) -> np.ndarray:
    """A copy with one usable pixel replaced by an unclipped white highlight (0.95 of saturation)."""
    usable = np.argwhere(reference.protocol_mask(codes))
    y, x = usable[np.random.default_rng(seed).integers(len(usable))]
    bright = codes.copy()
    bright[y, x] = HIGHLIGHT
    return bright


@pytest.fixture(scope="module")
def protocol_sets(default_world, tmp_path_factory):
    """``sets(count) -> (codes, truth, paths, ground-truth CSV)``, each count made once per module."""
    made = {}

    def sets(count: int):
        if count not in made:
            codes, truth = _protocol_set(default_world, count)
            paths, ground_truth = _write(tmp_path_factory.mktemp(f"protocol-{count}"), codes, truth)
            made[count] = codes, truth, paths, ground_truth
        return made[count]

    return sets


COUNTS = [30, pytest.param(200, marks=pytest.mark.slow)]


@pytest.mark.parametrize("count", COUNTS)
def test_library_statistics_methods_match_the_per_pixel_reference(default_world, protocol_sets, count):
    codes, _, paths, _ = protocol_sets(count)
    models = {label: store.fit(label, default_world) for label in STATISTICS}
    worst = {label: 0.0 for label in STATISTICS}
    zero_pixels = clipped_pixels = 0
    for image_codes, path in zip(codes, paths, strict=True):
        image = io.read_image(path)
        want_mask = reference.protocol_mask(image_codes)
        zero_pixels += int(np.sum(np.any(image_codes == 0, axis=-1)))
        clipped_pixels += int(np.sum(image.clipped))
        for label, model in models.items():
            assert model.default_preprocessing == "pixels"
            rgb, mask = preprocessing.prepare(model, image)
            assert rgb.shape == (SIZE, SIZE, 3)
            np.testing.assert_array_equal(mask, want_mask)
            estimate = preprocessing.run_model(model, jnp.asarray(rgb), jnp.asarray(mask))
            assert bool(estimate.ok)
            worst[label] = max(worst[label], reference.angle_degrees(estimate.illuminant, ORACLES[label](image_codes)))
    print(f"{count} images: worst angle to the reference {worst}; {zero_pixels} zero-channel, {clipped_pixels} clipped")
    assert zero_pixels > 0 and clipped_pixels > 0  # both rules are exercised
    assert max(worst.values()) <= 1e-4, worst


@pytest.mark.parametrize("count", COUNTS)
def test_evaluate_statistics_methods_match_the_per_pixel_reference(
    default_world, protocol_sets, tmp_path, monkeypatch, count
):
    """``ccjax evaluate`` GW and shades-of-grey-p6 (CSV output) equal the reference per image."""
    monkeypatch.setattr(store, "world", lambda *a, **k: default_world)
    codes, _, paths, ground_truth = protocol_sets(count)
    out = tmp_path / "per-image.csv"
    argv = ["evaluate", str(paths[0].parent), "--ground-truth", ground_truth, "--methods", ",".join(STATISTICS)]
    assert cli.main([*argv, "--csv", str(out), "--no-progress"]) == 0
    with out.open() as file:
        rows = list(csv.DictReader(file))
    assert len(rows) == len(STATISTICS) * count
    by_name = {path.name: index for index, path in enumerate(paths)}
    worst = {label: 0.0 for label in STATISTICS}
    for row in rows:
        index = by_name[row["path"].replace("\\", "/").split("/")[-1]]
        got = np.array([float(row[c]) for c in "RGB"])
        angle = reference.angle_degrees(got, ORACLES[row["method"]](codes[index]))
        worst[row["method"]] = max(worst[row["method"]], angle)
    print(f"ccjax evaluate, {count} images: worst angle to the reference {worst}")
    assert max(worst.values()) <= 1e-4, worst


def _relative(a, b) -> float:
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(np.linalg.norm(a - b) / np.linalg.norm(a))


@pytest.mark.parametrize("count", COUNTS)
def test_dark_rule_survives_one_unclipped_highlight(default_world, protocol_sets, tmp_path, count):
    """One white pixel at 0.95 of saturation per image: with the dark rule relative to the 99th
    percentile, the usable-pixel count and the ave5 estimates move by less than 1 %; relative to
    the brightest pixel (``percentile=100``, the old rule) the count does not."""
    codes, _, paths, _ = protocol_sets(count)
    bright_paths = []
    for index, image_codes in enumerate(codes):
        bright_paths.append(tmp_path / f"bright-{index:04d}.png")
        io.write_png(bright_paths[-1], _with_highlight(image_codes, index))
    models = {
        "DB-GW": store.fit("DB-GW", default_world),  # world-based: ave5 by default
        "GW at ave5": store.fit("GW", default_world),
    }
    assert models["DB-GW"].default_preprocessing == "ave5"
    worst = {"count": 0.0, "old-rule count": 0.0, **{label: 0.0 for label in models}}
    for path, bright_path in zip(paths, bright_paths, strict=True):
        plain, bright = io.read_image(path), io.read_image(bright_path)
        for key, percentile in (("count", 99.0), ("old-rule count", 100.0)):
            before = preprocessing.usable_pixels(plain.rgb, plain.clipped, percentile=percentile).sum()
            after = preprocessing.usable_pixels(bright.rgb, bright.clipped, percentile=percentile).sum()
            worst[key] = max(worst[key], abs(int(after) - int(before)) / int(before))
        for label, model in models.items():
            estimates = [preprocessing.estimate_image(model, image, "ave5").illuminant for image in (plain, bright)]
            worst[label] = max(worst[label], _relative(*estimates))
    print(f"{count} images, worst relative change: {worst}")
    assert worst["count"] < 0.01 and worst["DB-GW"] < 0.01 and worst["GW at ave5"] < 0.01, worst
    assert worst["old-rule count"] >= 0.01, worst  # the rule it replaces fails the same test


def test_read_image_clips_at_the_protocol_level(tmp_path):
    """Default: any channel at or above 0.98 of the file maximum is clipped (codes 64224 / 64225
    straddle 0.98 * 65535 = 64224.3); an explicit saturation clips exactly at that value; the unit
    scale (1.0 = the saturation level, the file maximum by default) does not change."""
    codes = np.array([[[64224, 9, 9], [9, 64225, 9], [9, 9, 65535], [0, 500, 500]]], np.uint16)
    io.write_png(tmp_path / "a.png", codes)
    image = io.read_image(tmp_path / "a.png")
    np.testing.assert_array_equal(image.clipped, [[False, True, True, False]])
    np.testing.assert_array_equal(image.clipped, ~reference.protocol_mask(codes) & (codes.min(axis=-1) > 0))
    np.testing.assert_allclose(image.rgb, codes / 65535.0, rtol=1e-6)
    exact = io.read_image(tmp_path / "a.png", saturation=64225)
    np.testing.assert_array_equal(exact.clipped, [[False, True, True, False]])
    np.testing.assert_allclose(exact.rgb, codes / 64225.0, rtol=1e-6)
    assert not io.read_image(tmp_path / "a.png", saturation=65536).clipped.any()
    # The zero-channel pixel is not clipped, but it is not usable either.
    assert not preprocessing.usable_pixels(image.rgb, image.clipped, 0.0)[0, 3]
