"""Nothing given is dropped or altered without a word: entries of an image folder that are not
regular files are named in the failure list, a JPEG's EXIF orientation is applied (outputs come out
upright), and JAX's compilation-cache failures (a full disk) are one ccjax warning line."""

from __future__ import annotations

import os
import warnings

import numpy as np
import pytest
from image_files import textured_image
from PIL import Image, ImageOps

from ccjax import cli, io


@pytest.fixture
def odd_folder(tmp_path):
    folder = tmp_path / "photos"
    folder.mkdir()
    textured_image(folder / "good.png")
    (folder / "loop.png").symlink_to("loop.png")
    (folder / "dangling.png").symlink_to("nothing.png")
    os.mkfifo(folder / "fifo.png")
    (folder / "folder.png").mkdir()
    (folder / "notes.txt").write_text("not an image")
    return folder


def test_entries_named_as_images_are_listed_whatever_they_are(odd_folder):
    names = [path.name for path in io.list_images([odd_folder])]
    assert names == ["dangling.png", "fifo.png", "folder.png", "good.png", "loop.png"]


def test_odd_entries_are_named_in_the_failure_list(odd_folder, plain_preview_commands, capsys):
    assert cli.main(["estimate", str(odd_folder), "--method", "GW", "--no-progress"]) == 2
    captured = capsys.readouterr()
    assert "good.png" in captured.out and "Traceback" not in captured.err
    assert "4 of 5 images cannot be used" in captured.err
    for name, what in [
        ("dangling.png", "symbolic link to nothing"),
        ("loop.png", "symbolic link to nothing"),
        ("fifo.png", "not a regular file"),
        ("folder.png", "is a folder"),
    ]:
        (line,) = [line for line in captured.err.splitlines() if name in line]
        assert what in line


@pytest.mark.parametrize("orientation", range(1, 9))
def test_a_jpegs_exif_orientation_is_applied(tmp_path, orientation):
    pixels = (np.random.default_rng(orientation).uniform(0.1, 0.9, (24, 40, 3)) * 255).astype(np.uint8)
    exif = Image.Exif()
    exif[0x0112] = orientation
    path = tmp_path / "photo.jpg"
    Image.fromarray(pixels).save(path, quality=95, exif=exif)
    # The oracle: Pillow's own transposition by the tag, of the same decoded codes.
    with Image.open(path) as image:
        upright = np.asarray(ImageOps.exif_transpose(image))
    info = io.probe_image(path, decode_srgb=True)
    assert (info.height, info.width) == upright.shape[:2]
    read = io.read_image(path, assume_linear=True)
    np.testing.assert_array_equal(np.round(np.asarray(read.rgb) * 255).astype(np.uint8), upright)


def test_correct_writes_a_rotated_jpeg_upright(tmp_path, plain_preview_commands):
    pixels = np.full((24, 40, 3), 120, np.uint8)
    pixels[:4, :, 0] = 250  # a red band along the stored top row
    exif = Image.Exif()
    exif[0x0112] = 6  # stored rotated: the upright image is 40 high, 24 wide, band on the right
    Image.fromarray(pixels).save(tmp_path / "photo.jpg", quality=95, exif=exif)
    out = tmp_path / "out.png"
    argv = ["correct", str(tmp_path / "photo.jpg"), str(out), "--method", "GW", "--decode-srgb", "--no-progress"]
    assert cli.main(argv) == 0
    corrected = io.read_image(out).rgb
    assert corrected.shape == (40, 24, 3)
    red = np.asarray(corrected[..., 0]) / np.asarray(corrected[..., 1])
    assert red[:, -3:].mean() > red[:, :-6].mean()


def test_compilation_cache_failures_are_one_line_per_run():
    formatted = cli.one_line_warnings("compare", warnings.formatwarning)
    jax_text = "Error writing persistent compilation cache entry for '{}': OSError: [Errno 28] No space left on device"
    first = formatted(UserWarning(jax_text.format("jit_a")), UserWarning, "compiler.py", 834)
    again = formatted(UserWarning(jax_text.format("jit_b")), UserWarning, "compiler.py", 834)
    assert first == (
        "ccjax compare: warning: cannot write the compilation cache (OSError: [Errno 28] No space left on device); "
        "programs are compiled without it\n"
    )
    assert again == ""
