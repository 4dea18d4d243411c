"""``ccjax correct``'s outputs for a photographer: previews named after the full output name (no
collision between two outputs of one stem), ``--preview none``, a bounded preview size, a folder
corrected to JPEGs under the same stems, a known light (``--light``) and a grey card
(``--white-region``) against a NumPy oracle, the notice naming the camera whose colours are used,
and a raw file corrected at its full size."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ccjax import cli, io


def _photo(path, seed=0, shape=(40, 60)):
    """A 16-bit linear photograph under a warm light with a grey card at rows 5-14, columns 5-19."""
    rng = np.random.default_rng(seed)
    rgb = rng.uniform(0.05, 0.5, (*shape, 3)) * np.array([1.0, 0.7, 0.4])
    rgb[5:15, 5:20] = np.array([0.6, 0.42, 0.24])
    codes = np.round(rgb * 65535).astype(np.uint16)
    io.write_png(path, codes)
    return codes


def _gains_oracle(light, canonical):
    """Barnard 1999 §2.5's diagonal map w_C / e, scaled so that a grey keeps its R+G+B (NumPy)."""
    light, canonical = np.asarray(light, np.float64), np.asarray(canonical, np.float64)
    gains = canonical / light
    return gains / np.sum(gains * light / light.sum())


def test_two_outputs_of_one_stem_get_their_own_previews(small_world_commands, capsys):
    folder = small_world_commands
    _photo(folder / "photo.png")
    for name in ("photo.png", "photo.tif"):
        argv = ["correct", str(folder / "photo.png"), str(folder / "out" / name), "--method", "GW", "--no-progress"]
        assert cli.main(argv) == 0, capsys.readouterr().err
    assert (folder / "out" / "photo_preview.png").is_file() and (folder / "out" / "photo_tif_preview.png").is_file()


def test_preview_none_writes_no_preview_and_says_none(small_world_commands, capsys):
    folder = small_world_commands
    _photo(folder / "photo.png")
    argv = ["correct", str(folder / "photo.png"), str(folder / "out.png"), "--method", "GW", "--preview", "none"]
    assert cli.main([*argv, "--no-progress"]) == 0
    assert sorted(p.name for p in folder.glob("out*")) == ["out.png"]
    assert "(sRGB preview)" not in capsys.readouterr().out


def test_preview_is_bounded_and_made_of_block_means(small_world_commands):
    """A 150 x 220 image with ``--preview-size 64``: reduced by ceil(220 / 64) = 4 to 38 x 55, each
    pixel the mean of its 4 x 4 block of the corrected image in linear light (partial blocks at the
    edges), exposed at the 99th percentile and sRGB-encoded (oracle in NumPy from the output file)."""
    from ccjax.runs import store

    folder = small_world_commands
    _photo(folder / "big.png", shape=(150, 220))
    argv = ["correct", str(folder / "big.png"), str(folder / "big-out.png"), "--method", "GW", "--preview-size", "64"]
    assert cli.main([*argv, "--no-progress"]) == 0
    preview = io.read_png(folder / "big-out_preview.png")
    factor = math.ceil(220 / 64)
    assert preview.shape == (math.ceil(150 / factor), math.ceil(220 / factor), 3)
    linear = io.read_png(folder / "big-out.png").astype(np.float64) / 65535
    blocks = np.zeros(preview.shape)
    for i in range(preview.shape[0]):
        for j in range(preview.shape[1]):
            blocks[i, j] = linear[i * factor : (i + 1) * factor, j * factor : (j + 1) * factor].mean(axis=(0, 1))
    srgb = blocks @ np.asarray(io.preview_matrix(store.world()), np.float64).T
    srgb = np.clip(srgb / np.percentile(srgb.max(axis=-1), 99), 0, 1)
    encoded = np.where(srgb <= 0.0031308, 12.92 * srgb, 1.055 * srgb ** (1 / 2.4) - 0.055)
    # The output file's 16-bit rounding and the float32 pipeline: within 2 codes of 255.
    assert np.max(np.abs(preview.astype(np.float64) - np.round(encoded * 255))) <= 2
    # Full size on request.
    argv = ["correct", str(folder / "big.png"), str(folder / "full.png"), "--method", "GW", "--preview-size", "0"]
    assert cli.main([*argv, "--no-progress"]) == 0
    assert io.read_png(folder / "full_preview.png").shape == (150, 220, 3)


def test_a_folder_corrected_for_viewing_becomes_jpegs_under_the_same_stems(small_world_commands, capsys):
    folder = small_world_commands
    for index, name in enumerate(["a.png", "b.png", "c.tif"]):
        codes = _photo(folder / "in" / "a.png" if index == 0 else folder / "tmp.png", seed=index)
        if index:
            import tifffile

            (folder / "tmp.png").unlink()
            if name.endswith(".tif"):
                tifffile.imwrite(folder / "in" / name, codes, photometric="rgb")
            else:
                io.write_png(folder / "in" / name, codes)
    argv = ["correct", str(folder / "in"), str(folder / "out"), "--method", "GW", "--srgb", "8", "--no-progress"]
    assert cli.main(argv) == 0, capsys.readouterr().err
    written = sorted(p.name for p in (folder / "out").iterdir())
    assert written == ["a.jpg", "a_jpg_preview.png", "b.jpg", "b_jpg_preview.png", "c.jpg", "c_jpg_preview.png"]
    from PIL import Image

    with Image.open(folder / "out" / "b.jpg") as image:
        assert image.format == "JPEG" and image.size == (60, 40)


@pytest.mark.parametrize("option", ["--light", "--white-region"])
def test_a_known_light_and_a_grey_card_correct_as_the_diagonal_map_says(small_world_commands, option, capsys):
    """``--light 0.6,0.42,0.24`` and ``--white-region 5,5,15,10`` (the grey card, whose pixels are
    that colour): every pixel times the gains of §2.5's diagonal map for that light, written in
    NumPy; the line says where the light came from."""
    from ccjax.runs import store

    folder = small_world_commands
    codes = _photo(folder / "card.png")
    value = "0.6,0.42,0.24" if option == "--light" else "5,5,15,10"
    argv = ["correct", str(folder / "card.png"), str(folder / "card-out.png"), option, value, "--no-progress"]
    assert cli.main(argv) == 0
    printed = capsys.readouterr().out
    assert ("(given)" if option == "--light" else "(from the white region)") in printed
    light = codes[5:15, 5:20].reshape(-1, 3).mean(axis=0) / 65535 if option == "--white-region" else [0.6, 0.42, 0.24]
    gains = _gains_oracle(light, store.world().canonical_white)
    want = np.clip(np.round(codes.astype(np.float64) * gains), 0, 65535)
    got = io.read_png(folder / "card-out.png").astype(np.float64)
    assert np.max(np.abs(got - want)) <= 1 + 65535 * 2e-6 * want.max() / 65535


def test_a_grey_card_outside_the_image_is_refused_before_any_output(small_world_commands, capsys):
    folder = small_world_commands
    _photo(folder / "card.png")
    argv = ["correct", str(folder / "card.png"), str(folder / "o.png"), "--white-region", "50,5,15,10"]
    assert cli.main([*argv, "--no-progress"]) == 2
    assert "--white-region: 50,5,15,10 does not fit inside" in capsys.readouterr().err
    assert not (folder / "o.png").exists()


@pytest.mark.parametrize("bad", ["0_6,1,1", "1,1", "nan,1,1", "0,0,0", "-1,1,1"])
def test_a_light_that_is_not_three_numbers_is_refused(small_world_commands, bad, capsys):
    folder = small_world_commands
    _photo(folder / "card.png")
    with pytest.raises(SystemExit) as stop:
        cli.main(["correct", str(folder / "card.png"), str(folder / "o.png"), "--light", bad])
    assert stop.value.code == 2 and "--light" in capsys.readouterr().err


def test_the_colours_camera_is_named_when_nobody_gave_it(small_world_commands, capsys):
    folder = small_world_commands
    _photo(folder / "photo.png")
    argv = ["correct", str(folder / "photo.png"), str(folder / "a.png"), "--method", "GW", "--no-progress"]
    assert cli.main(argv) == 0
    assert "notice: the sRGB colours (--srgb output, previews) use the curves of" in capsys.readouterr().err
    argv = ["correct", str(folder / "photo.png"), str(folder / "b.png"), "--method", "GW", "--preview", "none"]
    assert cli.main([*argv, "--no-progress"]) == 0
    assert "notice" not in capsys.readouterr().err  # linear output, no preview: no sRGB colours shown


def test_a_raw_file_is_corrected_at_full_size_with_its_own_colour_matrix(tmp_path, capsys):
    """The test DNG (64 x 96 sensor, Orientation 6): the output is the full sensor size, upright
    (96 x 64), and its sRGB colours come from the file's ColorMatrix1: the oracle is the inverse
    of that matrix, colour-science's XYZ -> sRGB and the canonical white pinned to white."""
    pytest.importorskip("rawpy")
    import colour
    from dng_files import EOS_5D_MARK_II_D65, bayer, write_dng

    from ccjax.runs import store

    write_dng(tmp_path / "shot.dng", bayer(6000, 9000, 5000, 64, 96))
    argv = ["correct", str(tmp_path / "shot.dng"), str(tmp_path / "shot.tif"), "--light", "1,1,1", "--srgb", "16"]
    assert cli.main([*argv, "--no-progress", "--preview", "none"]) == 0
    assert "notice" not in capsys.readouterr().err
    import tifffile

    got = tifffile.imread(tmp_path / "shot.tif")
    assert got.shape == (96, 64, 3)
    canonical = np.asarray(store.world().canonical_white, np.float64)
    to_xyz = np.linalg.inv(np.reshape(EOS_5D_MARK_II_D65, (3, 3)) / 1e4)
    to_srgb = np.asarray(colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB) @ to_xyz
    to_srgb /= (to_srgb @ (canonical / canonical.max()))[:, None]
    camera = (np.array([6000, 9000, 5000]) - 1024) / (15600 - 1024)
    linear = np.clip(to_srgb @ (camera * _gains_oracle([1, 1, 1], canonical)), 0, 1)
    encoded = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
    centre = got[40:56, 24:40].reshape(-1, 3).astype(np.float64)
    np.testing.assert_allclose(centre.mean(axis=0), encoded * 65535, atol=65535 * 2e-3)


PEAK_SCRIPT = """
import re, sys
from ccjax.cli import main
status = main(["correct", sys.argv[1], sys.argv[2], "--method", "GW", "--no-progress"])
# VmHWM: this program's own peak (ru_maxrss would count the forking test process's size too).
print(status, re.search(r"VmHWM:\\s+(\\d+) kB", open("/proc/self/status").read()).group(1))
"""


@pytest.mark.slow  # about 40 s on 2 shared cores: a 24 MP demosaic, estimate, correction and preview
def test_a_24_mp_raw_is_corrected_at_full_size_within_2_gb(tmp_path):
    """A 24 MP raw (6000 x 4000 sensor, Orientation 6) corrected by grey world: the 16-bit output
    is the full sensor size, upright, and the process's peak resident memory stays under 2 GB."""
    pytest.importorskip("rawpy")
    import subprocess
    import sys

    import tifffile
    from dng_files import BLACK, WHITE, write_dng

    rng = np.random.default_rng(0)
    write_dng(tmp_path / "big.dng", rng.integers(BLACK, WHITE, (4000, 6000), dtype=np.uint16))
    run = subprocess.run(
        [sys.executable, "-c", PEAK_SCRIPT, str(tmp_path / "big.dng"), str(tmp_path / "big.tif")],
        capture_output=True,
        text=True,
        check=True,
    )
    status, peak_kib = (int(value) for value in run.stdout.split()[-2:])
    assert status == 0, run.stderr
    with tifffile.TiffFile(tmp_path / "big.tif") as written:
        assert written.pages[0].shape == (6000, 4000, 3)
    assert peak_kib * 1024 < 2 * 10**9, f"peak resident memory {peak_kib / 1024:.0f} MiB"
    print(f"peak resident memory {peak_kib / 1024:.0f} MiB")
