"""Nothing from a file is trusted: a header's size is checked against the pixel budget before
anything is allocated (a bad header is one file's failure, the run goes on), option files
(sharpening matrices, trained models) are checked and bounded, and odd files are named."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest
import tifffile

import ccjax.io
from ccjax import cli, io
from ccjax.io import reading, writing
from ccjax.runs import folders, sources

SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(data, zlib.crc32(kind)))


def claiming_png(path, width: int, height: int, idat: bytes = b"") -> None:
    """A 16-bit RGB PNG whose header claims ``width x height`` pixels, with ``idat`` as its data."""
    header = struct.pack(">IIBBBBB", width, height, 16, 2, 0, 0, 0)
    path.write_bytes(SIGNATURE + _chunk(b"IHDR", header) + _chunk(b"IDAT", idat) + _chunk(b"IEND", b""))


def png_bomb(path, side: int) -> None:
    """A real, valid ``side x side`` 16-bit RGB PNG of zeros: a small file that decodes to
    ``6 side^2`` bytes (12000: 144 MP, 864 MB of samples)."""
    compressor = zlib.compressobj(9)
    row = bytes(1 + 6 * side)  # filter byte 0 + the samples
    parts = [compressor.compress(row) for _ in range(side)]
    parts.append(compressor.flush())
    claiming_png(path, side, side, b"".join(parts))


@pytest.fixture
def setup(small_world_commands, monkeypatch):
    monkeypatch.setattr(ccjax.io, "preview_matrix_cached", lambda w: np.eye(3, dtype=np.float32))
    return small_world_commands


def _image(path, colour=(0.5, 0.4, 0.3)):
    rgb = np.broadcast_to(np.asarray(colour), (6, 6, 3)).copy()
    rgb[::2, ::3] *= 0.5
    writing.write_linear(path, rgb)
    return path


# ---------------------------------------------------------------------------------------------
# the pixel budget


def test_a_74_byte_header_claiming_100000_squared_is_refused_from_the_header(tmp_path, monkeypatch):
    claiming_png(tmp_path / "claim.png", 100_000, 100_000, zlib.compress(b"\0" * 7))
    assert (tmp_path / "claim.png").stat().st_size < 100
    monkeypatch.setattr(reading, "_read_pixels", lambda *a: pytest.fail("pixels decoded past the budget"))
    for call in (io.probe_image, io.read_image):
        with pytest.raises(ValueError, match=r"claim\.png claims 100000x100000 pixels \(10000\.0 MP\).*100 MP"):
            call(tmp_path / "claim.png")


def test_the_12000_squared_png_bomb_is_refused_from_its_header(tmp_path, monkeypatch):
    png_bomb(tmp_path / "bomb.png", 12000)
    assert (tmp_path / "bomb.png").stat().st_size < 2_000_000  # 864 MB of samples in under 2 MB
    assert io.png_header(tmp_path / "bomb.png").width == 12000
    monkeypatch.setattr(reading, "_read_pixels", lambda *a: pytest.fail("pixels decoded past the budget"))
    with pytest.raises(ValueError, match=r"bomb\.png claims 12000x12000 pixels \(144\.0 MP\)"):
        io.read_image(tmp_path / "bomb.png")
    source = sources.image_folder([tmp_path / "bomb.png"])
    assert source.usable() == [] and "144.0 MP" in source.failures[str(tmp_path / "bomb.png")]


def test_the_budget_is_an_option_and_a_48_mp_header_passes(tmp_path, small_test_world):
    claiming_png(tmp_path / "camera.png", 8000, 6000)
    assert io.probe_image(tmp_path / "camera.png").width == 8000  # 48 MP: inside the default budget
    with pytest.raises(ValueError, match=r"48\.0 MP\), more than the pixel budget of 40 MP"):
        io.probe_image(tmp_path / "camera.png", max_pixels=40_000_000)
    tifffile.imwrite(tmp_path / "small.tif", np.ones((10, 10, 3), np.uint16), photometric="rgb")
    assert io.read_image(tmp_path / "small.tif", max_pixels=100).shape == (10, 10)
    with pytest.raises(ValueError, match=r"small\.tif claims 10x10 pixels"):
        io.read_image(tmp_path / "small.tif", max_pixels=99)
    run = folders.estimate_folder(tmp_path / "small.tif", "GW", world=small_test_world, max_pixels=99)
    assert run.done.tolist() == [False] and "claims 10x10 pixels" in run.failures[str(tmp_path / "small.tif")]
    assert folders.estimate_folder(tmp_path / "small.tif", "GW", world=small_test_world).done.tolist() == [True]


def test_a_mask_is_checked_from_its_header_before_decoding(tmp_path, monkeypatch):
    claiming_png(tmp_path / "mask.png", 100_000, 100_000)
    monkeypatch.setattr(reading, "_read_pixels", lambda *a: pytest.fail("a mask of the wrong size was decoded"))
    with pytest.raises(ValueError, match=r"mask: .*mask\.png is 100000x100000 pixels .* its image is 8x6"):
        io.read_mask(tmp_path / "mask.png", (6, 8))


@pytest.mark.parametrize("command", ["estimate", "evaluate"])
def test_a_folder_with_a_bomb_header_reports_the_good_image_and_exits_2(setup, capsys, command):
    folder = setup / "set"
    folder.mkdir()
    _image(folder / "good.png")
    claiming_png(folder / "claim.png", 100_000, 100_000, zlib.compress(b"\0" * 7))
    (folder / "gt.csv").write_text("image,r,g,b\ngood.png,1,1,1\nclaim.png,1,1,1\n")
    if command == "estimate":
        argv = ["estimate", str(folder), "--method", "GW", "--no-progress"]
    else:
        argv = ["evaluate", str(folder), "--ground-truth", str(folder / "gt.csv"), "--methods", "GW", "--no-progress"]
    assert cli.main(argv) == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err and "RESOURCE_EXHAUSTED" not in captured.err
    assert "1 of 2 images cannot be used" in captured.err and "claim.png claims 100000x100000" in captured.err
    if command == "estimate":
        assert "good.png" in captured.out and "claim.png" not in captured.out
    else:
        assert "GW" in captured.out, captured.out


def test_the_warm_up_compiles_only_the_sizes_that_pass_the_budget(tmp_path, monkeypatch, small_test_world):
    from ccjax.runs import images as run_images
    from ccjax.runs import store

    _image(tmp_path / "good.png")
    claiming_png(tmp_path / "big.png", 9, 9)  # passes only without a budget of 50
    shapes = []
    real = run_images._timed

    def timed(model, rgb, mask):
        shapes.append(tuple(rgb.shape))
        return real(model, rgb, mask)

    monkeypatch.setattr(run_images, "_timed", timed)
    source = sources.image_folder(tmp_path, max_pixels=50)
    run = run_images.run_models(source, {"GW": [store.fit("GW", small_test_world)]})
    assert shapes and all(shape[0] * shape[1] <= 36 for shape in shapes), shapes
    assert run.done.tolist() == [False, True] and "big.png claims 9x9" in run.failures[str(tmp_path / "big.png")]
