"""Correction to the canonical light (ccjax.correction, Barnard 1999 §2.5)."""

from __future__ import annotations

import re

import jax.numpy as jnp
import numpy as np
import pytest

from ccjax import correction


def test_diagonal_and_sharpened_correction():
    rng = np.random.default_rng(5)
    light, canonical = np.array([0.9, 0.6, 0.3], np.float32), np.array([0.7, 1.0, 0.8], np.float32)
    corrected = np.asarray(correction.correct(light, light, canonical))
    np.testing.assert_allclose(corrected / corrected.sum(), canonical / canonical.sum(), rtol=1e-5)
    assert corrected.sum() == pytest.approx(light.sum(), rel=1e-5)  # grey keeps its R+G+B
    transform = np.eye(3, dtype=np.float32) + 0.2 * rng.standard_normal((3, 3)).astype(np.float32)
    sharpened = np.asarray(correction.correct(light, light, canonical, transform))
    ratio = (transform @ sharpened) / (transform @ canonical)
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-4)  # T e maps to the direction of T w_C
    pixels = rng.random((4, 5, 3)).astype(np.float32)
    matrix = np.asarray(correction.correction_map(jnp.asarray(light), jnp.asarray(canonical)))
    np.testing.assert_allclose(np.asarray(correction.correct(pixels, light, canonical)), pixels @ matrix.T, rtol=1e-5)


def test_gains_are_the_diagonal_of_the_map():
    light, canonical = jnp.array([0.2, 0.5, 0.9]), jnp.array([1.0, 0.9, 0.7])
    np.testing.assert_allclose(
        np.diag(np.asarray(correction.correction_map(light, canonical))),
        np.asarray(correction.diagonal_gains(light, canonical)),
        rtol=1e-6,
    )
    np.testing.assert_allclose(
        np.asarray(correction.apply_map(jnp.ones((2, 3)), jnp.diag(jnp.array([1.0, 2.0, 3.0])))), [[1, 2, 3]] * 2
    )


def test_clipped_pixels_come_out_as_the_canonical_white():
    """Clip to white: a pixel with a channel at saturation becomes the canonical white at full
    scale; the others get the gains (NumPy oracle: rgb * gains)."""
    light, canonical = np.array([0.9, 0.6, 0.3], np.float32), np.array([0.5, 1.0, 0.7], np.float32)
    rng = np.random.default_rng(1)
    rgb = rng.uniform(0.05, 0.9, (6, 7, 3)).astype(np.float32)
    rgb[0, 0] = 1.0  # every channel clipped
    rgb[1, 1, 0] = 1.0  # one channel clipped
    gains = np.asarray(correction.diagonal_gains(jnp.asarray(light), jnp.asarray(canonical)))
    for sharpening in (None, np.eye(3, dtype=np.float32)):
        got = np.asarray(correction.correct(rgb, light, canonical, sharpening, 1.0))
        np.testing.assert_allclose(got[0, 0], canonical / canonical.max(), rtol=1e-6)
        np.testing.assert_allclose(got[1, 1], canonical / canonical.max(), rtol=1e-6)
        others = np.ones(rgb.shape[:2], bool)
        others[0, 0] = others[1, 1] = False
        np.testing.assert_allclose(got[others], rgb[others] * gains, rtol=1e-5)
    # Without the rule a clipped white takes the gains' colour (what the rule prevents).
    plain = np.asarray(correction.correct(rgb, light, canonical))[0, 0]
    assert np.ptp(plain / canonical) > 0.5


def test_a_clipped_white_blob_stays_neutral_after_ccjax_correct(small_world_commands, capsys):
    """A saturated (65535, 65535, 65535) blob in a 16-bit PNG under a coloured light: the corrected
    file shows it as the canonical white at full scale, the sRGB preview as neutral white."""
    from ccjax import cli, io
    from ccjax.runs import store

    folder = small_world_commands
    rng = np.random.default_rng(2)
    rgb = rng.uniform(0.05, 0.6, (32, 40, 3)) * np.array([1.0, 0.7, 0.4])
    rgb[8:16, 10:20] = 1.0
    io.write_png(folder / "in.png", io.quantise(rgb))
    status = cli.main(["correct", str(folder / "in.png"), str(folder / "out.png"), "--method", "GW", "--no-progress"])
    assert status == 0
    # The estimate is printed with five decimals, not float32 noise (0.030889999121427536).
    printed = capsys.readouterr().out
    assert re.search(r": light \[\d\.\d{5}, \d\.\d{5}, \d\.\d{5}\] \(estimated\) -> ", printed), printed
    out, preview = io.read_png(folder / "out.png"), io.read_png(folder / "out_preview.png")
    canonical = np.asarray(store.world().canonical_white, np.float64)
    want = np.round(canonical / canonical.max() * 65535)
    assert np.all(np.abs(out[8:16, 10:20].astype(np.float64) - want) <= 1), (out[8, 10], want)
    blob = preview[8:16, 10:20].astype(int)
    # Neutral, and among the brightest of the preview (its exposure is set by the 99th percentile).
    assert np.all(blob.max(axis=-1) - blob.min(axis=-1) <= 1) and blob.min() >= np.percentile(preview, 90), preview[
        8, 10
    ]


@pytest.mark.parametrize("bits", [8, 16])
def test_correct_srgb_writes_full_resolution_srgb(small_world_commands, bits):
    """``--srgb 8|16``: the corrected image through the world's camera-to-sRGB matrix and the
    IEC 61966-2-1 curve (written out here), no exposure change; the clipped blob is sRGB white."""
    from ccjax import cli, correction, io
    from ccjax.runs import store

    folder = small_world_commands
    rng = np.random.default_rng(3)
    rgb = rng.uniform(0.05, 0.6, (24, 30, 3)) * np.array([1.0, 0.7, 0.4])
    rgb[4:8, 4:9] = 1.0
    io.write_png(folder / "in.png", io.quantise(rgb))
    argv = ["correct", str(folder / "in.png"), str(folder / "out.tif"), "--method", "GW", "--srgb", str(bits)]
    assert cli.main([*argv, "--no-progress"]) == 0
    import tifffile

    got = tifffile.imread(folder / "out.tif")
    assert got.dtype == (np.uint8 if bits == 8 else np.uint16) and got.shape == rgb.shape
    world = store.world()
    read = io.read_png(folder / "in.png").astype(np.float64) / 65535
    estimate = np.asarray(io.read_png(folder / "in.png"), np.float64)[~np.any(read >= 0.98, -1)]
    estimate = 2 * (estimate[np.all(estimate > 0, -1)] / 65535).mean(axis=0)  # grey world
    corrected = np.asarray(correction.correct(read.astype(np.float32), estimate, world.canonical_white, None, 1.0))
    linear = np.clip(corrected @ np.asarray(io.preview_matrix(world), np.float64).T, 0, 1)
    encoded = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
    want = np.round(encoded * (2**bits - 1))
    assert np.max(np.abs(got.astype(np.float64) - want)) <= 1 + (2**bits - 1) * 2e-4
    assert np.all(got[4:8, 4:9] == 2**bits - 1)  # the clipped blob: sRGB white


@pytest.mark.parametrize("saturation", [None, "64224", "65535"])
def test_correction_whitens_exactly_the_pixels_estimation_leaves_out(small_world_commands, saturation):
    """One clip rule: patches just under full scale (a near white [60000, 64500, 64500] and a
    green-clipped [30000, 65000, 20000]) are clipped at the default level (0.98 of 65535 = 64224.3)
    and at ``--saturation 64224``, so they come out sRGB white; with ``--saturation 65535`` they are
    not clipped and are mapped like the other pixels. The oracle is the rule written here in NumPy:
    a channel at or above the level."""
    from ccjax import cli, io

    folder = small_world_commands
    rng = np.random.default_rng(4)
    codes = np.round(rng.uniform(0.05, 0.6, (20, 24, 3)) * np.array([1.0, 0.7, 0.4]) * 65535).astype(np.uint16)
    codes[2:6, 2:6] = [60000, 64500, 64500]
    codes[10:14, 10:14] = [30000, 65000, 20000]
    codes[15:18, 3:7] = [64000, 64000, 64000]  # under every level: never clipped
    io.write_png(folder / "near.png", codes)
    argv = ["correct", str(folder / "near.png"), str(folder / "near-out.png"), "--method", "GW", "--srgb", "8"]
    argv += ["--no-progress", *(["--saturation", saturation] if saturation else [])]
    assert cli.main(argv) == 0
    level = 0.98 * 65535 if saturation is None else float(saturation)
    clipped = np.any(codes >= level, axis=-1)
    got = io.read_png(folder / "near-out.png")
    white = np.all(got == 255, axis=-1)
    assert clipped[2:6, 2:6].all() == clipped[10:14, 10:14].all() == (saturation != "65535")
    np.testing.assert_array_equal(white[clipped], True)
    assert not white[15:18, 3:7].any()
    if saturation == "65535":
        assert not white[2:6, 2:6].any() and not white[10:14, 10:14].any()
