"""Reading inputs safely: ground-truth duplicates, conflicting stems, BOM, extra fields and
paths outside the folder; alpha as a mask; PNG chunk CRCs; header-only probing; compressed TIFF."""

from __future__ import annotations

import struct
import zlib

import jax.numpy as jnp
import numpy as np
import pytest
import tifffile
from image_files import reference_png

from ccjax import io
from ccjax.estimators.simple import GreyWorld
from ccjax.preprocessing import estimate_image


def _codes(seed: int = 0, shape=(6, 8)) -> np.ndarray:
    return np.random.default_rng(seed).integers(1000, 60000, (*shape, 3)).astype(np.uint16)


# ---------------------------------------------------------------------------------------------
# ground truth


def _write(path, text: str, encoding: str = "utf-8") -> None:
    path.write_bytes(text.encode(encoding))


def test_duplicate_rows_name_both_lines(tmp_path):
    _write(tmp_path / "gt.csv", "image,r,g,b\na.png,1,1,1\nb.png,1,2,3\na.png,3,2,1\n")
    with pytest.raises(ValueError, match=r"lines 2 and 4 both give image 'a.png'"):
        io.read_ground_truth(tmp_path / "gt.csv")


def test_rows_that_resolve_to_one_image_are_refused(tmp_path):
    io.write_png(tmp_path / "im0.png", _codes())
    _write(tmp_path / "gt.csv", "image,r,g,b\nim0,1,1,1\nim0.png,1,2,3\n")
    truth = io.read_ground_truth(tmp_path / "gt.csv")
    with pytest.raises(ValueError, match=r"rows 'im0' and 'im0.png' are the same image .*conflicting stems"):
        io.match_ground_truth(truth, tmp_path)


def test_a_stem_matching_two_files_is_refused(tmp_path):
    io.write_png(tmp_path / "im0.png", _codes())
    tifffile.imwrite(tmp_path / "im0.tif", _codes(1))
    _write(tmp_path / "gt.csv", "image,r,g,b\nim0,1,1,1\n")
    with pytest.raises(ValueError, match=r"'im0' matches 2 files .*im0.png.*im0.tif"):
        io.match_ground_truth(io.read_ground_truth(tmp_path / "gt.csv"), tmp_path)


def test_byte_order_mark_is_accepted(tmp_path):
    _write(tmp_path / "gt.csv", "image,r,g,b\r\nä.png,1,2,3\r\n", encoding="utf-8-sig")
    assert (tmp_path / "gt.csv").read_bytes().startswith(b"\xef\xbb\xbf")
    truth = io.read_ground_truth(tmp_path / "gt.csv")
    assert list(truth) == ["ä.png"]
    np.testing.assert_array_equal(truth["ä.png"], [1.0, 2.0, 3.0])


def test_not_utf8_is_a_clear_error(tmp_path):
    (tmp_path / "gt.csv").write_bytes(b"image,r,g,b\n\xff\xfe.png,1,2,3\n")
    with pytest.raises(ValueError, match=r"gt.csv is not UTF-8"):
        io.read_ground_truth(tmp_path / "gt.csv")


def test_extra_fields_name_the_line(tmp_path):
    _write(tmp_path / "gt.csv", "image,r,g,b\na.png,1,1,1\nb.png,1,2,3,4\n")
    with pytest.raises(ValueError, match=r"line 3: 5 fields, the header has 4"):
        io.read_ground_truth(tmp_path / "gt.csv")


@pytest.mark.parametrize("name", ["/etc/a.png", "../a.png", "sub/../../a.png", "\\\\server\\a.png"])
def test_paths_outside_the_folder_are_refused(tmp_path, name):
    _write(tmp_path / "gt.csv", f"image,r,g,b\nok.png,1,1,1\n{name},1,2,3\n")
    with pytest.raises(ValueError, match=r"line 3: image .* must be a name relative to the image folder"):
        io.read_ground_truth(tmp_path / "gt.csv")


def test_symlink_out_of_the_folder_is_refused(tmp_path):
    (tmp_path / "images").mkdir()
    io.write_png(tmp_path / "outside.png", _codes())
    (tmp_path / "images" / "link").symlink_to(tmp_path)
    truth = {"link/outside.png": np.ones(3)}
    with pytest.raises(ValueError, match=r"'link/outside.png' points outside the image folder"):
        io.match_ground_truth(truth, tmp_path / "images")


def test_ground_truth_round_trip_is_unchanged(tmp_path):
    io.write_png(tmp_path / "a.png", _codes())
    io.write_png(tmp_path / "b.png", _codes(1))
    io.write_ground_truth(tmp_path / "gt.csv", ["a.png", "b"], [[0.2, 0.3, 0.5], [1.0, 2.0, 3.0]])
    pairs = io.match_ground_truth(io.read_ground_truth(tmp_path / "gt.csv"), tmp_path)
    assert [p.name for p, _ in pairs] == ["a.png", "b.png"]
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary left


# ---------------------------------------------------------------------------------------------
# alpha


def _rgba(codes: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    return np.concatenate([codes, alpha[..., None].astype(codes.dtype)], axis=-1)


def _hidden_garbage(codes: np.ndarray, hidden: np.ndarray) -> np.ndarray:
    changed = codes.copy()
    changed[hidden] = np.array([np.iinfo(codes.dtype).max * 3 // 4, 1, 1], codes.dtype)  # a strong red behind the mask
    return changed


@pytest.mark.parametrize("suffix", [".png", ".tif"])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_transparent_pixels_do_not_change_the_estimate(tmp_path, suffix, dtype):
    full = np.iinfo(dtype).max
    codes = (_codes(3) // (1 if dtype == np.uint16 else 257)).astype(dtype)
    hidden = np.zeros(codes.shape[:2], bool)
    hidden[:2] = True
    alpha = np.where(hidden, 0, full)
    alpha[2, 0] = full - 1  # partly transparent counts as hidden too
    hidden[2, 0] = True
    results = []
    for name, pixels in (("a", codes), ("b", _hidden_garbage(codes, hidden))):
        path = tmp_path / f"{name}{suffix}"
        rgba = _rgba(pixels, alpha)
        if suffix == ".png":
            path.write_bytes(reference_png(rgba, [0]) if dtype == np.uint16 else _png8(rgba))
        else:
            tifffile.imwrite(path, rgba, photometric="rgb", extrasamples=["unassalpha"])
        image = io.read_image(path, assume_linear=True)
        np.testing.assert_array_equal(image.transparent, hidden)
        assert np.all(image.clipped[hidden])
        np.testing.assert_array_equal(image.rgb, pixels.astype(np.float32) / np.float32(full))  # values unchanged
        results.append(
            np.asarray(estimate_image(GreyWorld(jnp.ones(3), jnp.ones(3)), image, "ave1", dark=0.0).illuminant)
        )
    np.testing.assert_array_equal(results[0], results[1])
    # and the estimate is that of the visible pixels alone
    visible = (codes.astype(np.float32) / np.float32(full))[~hidden]
    np.testing.assert_allclose(results[0] / results[0].sum(), visible.mean(0) / visible.mean(0).sum(), rtol=1e-5)


def _png8(pixels: np.ndarray) -> bytes:
    import imagecodecs

    return bytes(imagecodecs.png_encode(pixels))


def test_opaque_alpha_reads_like_rgb(tmp_path):
    codes = _codes(4)
    io.write_png(tmp_path / "rgb.png", codes)
    (tmp_path / "rgba.png").write_bytes(reference_png(_rgba(codes, np.full(codes.shape[:2], 65535)), [1]))
    rgb, rgba = io.read_image(tmp_path / "rgb.png"), io.read_image(tmp_path / "rgba.png")
    np.testing.assert_array_equal(rgb.rgb, rgba.rgb)
    np.testing.assert_array_equal(rgb.clipped, rgba.clipped)
    assert rgb.transparent is None and rgba.transparent is not None and not rgba.transparent.any()


def test_fully_transparent_image_is_refused(tmp_path):
    codes = _codes(5)
    (tmp_path / "a.png").write_bytes(reference_png(_rgba(codes, np.zeros(codes.shape[:2])), [0]))
    with pytest.raises(ValueError, match=r"every pixel of .*a.png is transparent"):
        io.read_image(tmp_path / "a.png")


# ---------------------------------------------------------------------------------------------
# PNG CRCs and probing


def _flip(blob: bytes, offset: int) -> bytes:
    data = bytearray(blob)
    data[offset] ^= 0x01
    return bytes(data)


def _chunk_offsets(blob: bytes) -> dict[bytes, int]:
    offsets, offset = {}, 8
    while offset < len(blob):
        (length,) = struct.unpack(">I", blob[offset : offset + 4])
        offsets.setdefault(blob[offset + 4 : offset + 8], offset)
        offset += 12 + length
    return offsets


def _with_text_chunk(blob: bytes) -> bytes:
    data = b"Comment\x00hello"
    chunk = struct.pack(">I", len(data)) + b"tEXt" + data + struct.pack(">I", zlib.crc32(data, zlib.crc32(b"tEXt")))
    return blob[:33] + chunk + blob[33:]


@pytest.mark.parametrize(
    ("chunk", "where"), [("IHDR", 10), ("IHDR", 8 + 13), ("IDAT", 9), ("IDAT", -1), ("tEXt", 9), ("tEXt", -1)]
)
def test_corrupted_chunk_is_a_clear_error(tmp_path, chunk, where):
    io.write_png(tmp_path / "good.png", _codes())
    blob = _with_text_chunk((tmp_path / "good.png").read_bytes())
    (tmp_path / "text.png").write_bytes(blob)
    np.testing.assert_array_equal(io.read_png(tmp_path / "text.png"), _codes())  # valid with the chunk
    start = _chunk_offsets(blob)[chunk.encode()]
    (length,) = struct.unpack(">I", blob[start : start + 4])
    offset = start + (where if where >= 0 else 12 + length + where)  # data byte, or the CRC's last byte
    (tmp_path / "bad.png").write_bytes(_flip(blob, offset))
    with pytest.raises(ValueError, match=rf"cannot read .*bad.png: corrupt PNG: CRC mismatch in chunk '{chunk}'"):
        io.read_image(tmp_path / "bad.png")
    if chunk == "IHDR":  # the header-only check sees it too
        with pytest.raises(ValueError, match=r"bad.png: corrupt PNG: CRC mismatch in chunk 'IHDR'"):
            io.probe_image(tmp_path / "bad.png")


def test_libpng_also_refuses_critical_crc_errors(tmp_path):
    """The decoder underneath verifies critical chunks on its own (our check adds ancillary ones
    and a uniform message)."""
    import imagecodecs

    io.write_png(tmp_path / "good.png", _codes())
    blob = (tmp_path / "good.png").read_bytes()
    with pytest.raises(imagecodecs.PngError, match="CRC"):
        imagecodecs.png_decode(_flip(blob, _chunk_offsets(blob)[b"IEND"] - 1))  # the IDAT CRC


def test_truncated_png_is_a_clear_error(tmp_path):
    io.write_png(tmp_path / "good.png", _codes())
    blob = (tmp_path / "good.png").read_bytes()
    (tmp_path / "cut.png").write_bytes(blob[:-20])
    with pytest.raises(ValueError, match=r"cut.png: truncated PNG"):
        io.read_image(tmp_path / "cut.png")
    (tmp_path / "head.png").write_bytes(blob[:20])
    with pytest.raises(ValueError, match=r"head.png: truncated PNG"):
        io.probe_image(tmp_path / "head.png")


def test_probe_reads_the_header_only(tmp_path, monkeypatch):
    io.write_png(tmp_path / "a.png", _codes(shape=(5, 7)))
    tifffile.imwrite(tmp_path / "b.tif", _codes(shape=(4, 9)), compression="zlib")
    tifffile.imwrite(
        tmp_path / "c.tif", np.moveaxis(_codes(shape=(3, 2)), -1, 0), photometric="rgb", planarconfig="separate"
    )
    import imagecodecs

    def no_decoding(*args, **kwargs):
        raise AssertionError("probe_image decoded pixels")

    monkeypatch.setattr(imagecodecs, "png_decode", no_decoding)
    monkeypatch.setattr(imagecodecs, "zlib_decode", no_decoding)
    monkeypatch.setattr(tifffile.TiffFile, "asarray", no_decoding)
    assert io.probe_image(tmp_path / "a.png") == io.ImageInfo(str(tmp_path / "a.png"), 5, 7, 3, 16)
    assert io.probe_image(tmp_path / "b.tif") == io.ImageInfo(str(tmp_path / "b.tif"), 4, 9, 3, 16)
    assert io.probe_image(tmp_path / "c.tif") == io.ImageInfo(str(tmp_path / "c.tif"), 3, 2, 3, 16)


def test_probe_refuses_what_read_image_refuses(tmp_path):
    grey = np.full((4, 4), 30000, np.uint16)
    tifffile.imwrite(tmp_path / "grey.tif", grey)
    (tmp_path / "eight.png").write_bytes(_png8(np.full((3, 3, 3), 9, np.uint8)))
    (tmp_path / "text.png").write_bytes(b"not a png at all")
    (tmp_path / "a.bmp").write_bytes(b"\xff\xd8")
    (tmp_path / "cut.jpg").write_bytes(b"\xff\xd8")  # a JPEG cut after its first marker
    tifffile.imwrite(tmp_path / "cmyk.tif", np.full((3, 3, 4), 9, np.uint8), photometric="separated")
    cases = {
        "grey.tif": "greyscale",
        "eight.png": "8-bit",
        "text.png": "not a PNG file",
        "a.bmp": "unsupported file type",
        "cut.jpg": "Error",  # the decoder's (Pillow's header reader, imagecodecs)
        "cmyk.tif": "SEPARATED is not supported",
    }
    for name, message in cases.items():
        for function in (io.probe_image, io.read_image):
            with pytest.raises(ValueError, match=rf"{name}.*{message}"):
                function(tmp_path / name)
    with pytest.raises(FileNotFoundError, match="no such file"):
        io.probe_image(tmp_path / "missing.png")
    assert io.probe_image(tmp_path / "eight.png", assume_linear=True).bit_depth == 8
    for function in (io.probe_image, io.read_image):
        with pytest.raises(ValueError, match=r"saturation: 100.0 must be above the black level 200"):
            function(tmp_path / "eight.png", black_level=200, saturation=100, assume_linear=True)


# ---------------------------------------------------------------------------------------------
# compressed TIFF


@pytest.mark.parametrize("compression", ["lzw", "zlib", "zstd"])
def test_compressed_16bit_tiff_round_trip(tmp_path, compression):
    codes = _codes(6, shape=(17, 23))
    tifffile.imwrite(tmp_path / "c.tif", codes, compression=compression, predictor=True)
    tifffile.imwrite(tmp_path / "plain.tif", codes)
    with tifffile.TiffFile(tmp_path / "c.tif") as tif:
        assert (
            tifffile.COMPRESSION(tif.pages[0].compression).name
            == {"lzw": "LZW", "zlib": "ADOBE_DEFLATE", "zstd": "ZSTD"}[compression]
        )
    image, plain = io.read_image(tmp_path / "c.tif"), io.read_image(tmp_path / "plain.tif")
    np.testing.assert_array_equal(image.rgb, plain.rgb)
    np.testing.assert_array_equal(image.rgb, codes.astype(np.float32) / np.float32(65535))


def test_jpeg_tiff_reads_as_8bit(tmp_path):
    ramp = np.linspace(40, 200, 16)
    codes = np.stack(np.broadcast_arrays(ramp[:, None], ramp[None, :], 120.0), -1).astype(np.uint8)
    tifffile.imwrite(tmp_path / "j.tif", codes, compression="jpeg", photometric="rgb")
    with pytest.raises(ValueError, match="8-bit"):
        io.read_image(tmp_path / "j.tif")
    image = io.read_image(tmp_path / "j.tif", assume_linear=True)
    assert image.shape == (16, 16) and image.bit_depth == 8
    assert np.abs(image.rgb * 255 - codes).mean() < 8  # lossy, but the same picture
