"""Image files (ccjax.io): PNG through libpng against a reference codec, reading linear images,
refusing bad files, ground truth, previews, raw files."""

from __future__ import annotations

import numpy as np
import pytest
import tifffile
from image_files import bad_files, reference_decode_rgb, reference_png
from small_world import small_world

from ccjax import io

# ---------------------------------------------------------------------------------------------
# PNG


@pytest.mark.parametrize("dtype", [np.uint16, np.uint8])
@pytest.mark.parametrize("filters", [[0], [1], [2], [3], [4], [0, 1, 2, 3, 4], [4, 3, 1]])
def test_png_decoder_undoes_every_filter(tmp_path, dtype, filters):
    rng = np.random.default_rng(len(filters))
    pixels = rng.integers(0, np.iinfo(dtype).max, (7, 6, 3), endpoint=True).astype(dtype)
    pixels[:3] = pixels[0, 0]  # flat rows make the predictors matter
    path = tmp_path / "f.png"
    path.write_bytes(reference_png(pixels, filters))
    np.testing.assert_array_equal(io.read_png(path), pixels)


@pytest.mark.parametrize("dtype", [np.uint16, np.uint8])
@pytest.mark.parametrize("shape", [(1, 1), (3, 17), (16, 2)])
def test_png_writer_matches_the_reference_decoder(tmp_path, dtype, shape):
    pixels = np.random.default_rng(0).integers(0, np.iinfo(dtype).max, shape + (3,), endpoint=True).astype(dtype)
    pixels[0, 0] = [0x0102, 0x0304, 0xFF00] if dtype == np.uint16 else [1, 2, 255]  # byte order shows
    io.write_png(tmp_path / "w.png", pixels)
    depth, decoded = reference_decode_rgb((tmp_path / "w.png").read_bytes())
    assert depth == 8 * np.dtype(dtype).itemsize
    np.testing.assert_array_equal(decoded, pixels)
    np.testing.assert_array_equal(io.read_png(tmp_path / "w.png"), pixels)


def test_png_writer_refuses_what_it_cannot_write(tmp_path):
    for pixels in (np.zeros((4, 4), np.uint16), np.zeros((4, 4, 3), np.float32), np.zeros((0, 4, 3), np.uint16)):
        with pytest.raises(ValueError, match="pixels"):
            io.write_png(tmp_path / "x.png", pixels)
    assert not (tmp_path / "x.png").exists()


def test_png_write_is_atomic_and_replaces(tmp_path):
    path = tmp_path / "a.png"
    io.write_png(path, np.zeros((2, 2, 3), np.uint16))
    io.write_png(path, np.full((2, 2, 3), 7, np.uint16))
    np.testing.assert_array_equal(io.read_png(path), 7)
    assert [p.name for p in tmp_path.iterdir()] == ["a.png"]  # no temporary file left behind


def test_png_alpha_is_a_mask(tmp_path):
    pixels = np.random.default_rng(9).integers(0, 60000, (3, 4, 4)).astype(np.uint16)
    pixels[..., 3] = 65535
    pixels[0, 0, 3] = 0  # one hidden pixel: its RGB is still read, but it is not usable
    (tmp_path / "a.png").write_bytes(reference_png(pixels, [4]))
    image = io.read_image(tmp_path / "a.png")
    np.testing.assert_allclose(image.rgb, pixels[..., :3] / 65535.0, rtol=1e-6)
    assert image.clipped[0, 0] and image.clipped.sum() == 1


# ---------------------------------------------------------------------------------------------
# read_image


def test_read_16bit_black_saturation_and_clipping(tmp_path):
    codes = np.array([[[100, 1100, 60000], [64000, 50, 100]], [[65535, 65535, 65535], [3000, 2000, 1000]]], np.uint16)
    io.write_png(tmp_path / "a.png", codes)
    image = io.read_image(tmp_path / "a.png", black_level=100, saturation=64000)
    want = np.maximum(codes.astype(np.float64) - 100, 0) / (64000 - 100)
    np.testing.assert_allclose(image.rgb, want, rtol=1e-6)
    np.testing.assert_array_equal(image.clipped, [[False, True], [True, False]])
    assert image.bit_depth == 16


def test_read_tiff_integer_float_and_planar(tmp_path):
    codes = np.random.default_rng(1).integers(0, 60000, (4, 5, 3)).astype(np.uint16)
    tifffile.imwrite(tmp_path / "a.tif", codes, photometric="rgb")
    np.testing.assert_allclose(io.read_image(tmp_path / "a.tif").rgb, codes / 65535.0, rtol=1e-6)
    tifffile.imwrite(tmp_path / "p.tif", np.moveaxis(codes, -1, 0), photometric="rgb", planarconfig="separate")
    np.testing.assert_allclose(io.read_image(tmp_path / "p.tif").rgb, codes / 65535.0, rtol=1e-6)
    floats = np.random.default_rng(2).random((4, 5, 3)).astype(np.float32) * 0.9
    tifffile.imwrite(tmp_path / "f.tif", floats, photometric="rgb")
    np.testing.assert_allclose(io.read_image(tmp_path / "f.tif").rgb, floats, rtol=1e-6)


def test_bad_files_raise_clear_errors(tmp_path):
    for message, path in bad_files(tmp_path):
        with pytest.raises(ValueError, match=message) as error:
            io.read_image(path)
        assert str(path) in str(error.value)
    with pytest.raises(FileNotFoundError):
        io.read_image(tmp_path / "missing.png")
    with pytest.raises(ValueError, match="unsupported file type"):
        (tmp_path / "a.bmp").write_bytes(b"")
        io.read_image(tmp_path / "a.bmp")
    linear = io.read_image(tmp_path / "eight.png", assume_linear=True)
    np.testing.assert_allclose(linear.rgb, 100 / 255.0, rtol=1e-6)


def test_write_linear_png_and_tiff(tmp_path):
    rgb = np.random.default_rng(4).random((5, 6, 3)) * 1.2 - 0.1  # out of range values clamp
    for name in ("a.png", "a.tif"):
        io.write_linear(tmp_path / name, rgb)
        image = io.read_image(tmp_path / name)
        np.testing.assert_allclose(image.rgb, np.clip(rgb, 0, 1), atol=0.5 / 65535 + 1e-7)
        # Clipped: some channel at the default clip level, 0.98 of saturation (ccjax.io.reading).
        codes = io.writing.quantise(rgb)
        np.testing.assert_array_equal(image.clipped, np.any(codes >= io.reading.CLIP_FRACTION * 65535, axis=-1))
    with pytest.raises(ValueError, match="JPEG, which holds 8 bits per channel"):
        io.write_linear(tmp_path / "a.jpg", rgb)  # linear 16-bit codes have no JPEG


# ---------------------------------------------------------------------------------------------
# Ground truth and preview


def test_ground_truth_round_trip_and_errors(tmp_path):
    io.write_ground_truth(tmp_path / "gt.csv", ["a.png", "b.png"], [[0.2, 0.3, 0.5], [1.0, 2.0, 3.0]])
    truth = io.read_ground_truth(tmp_path / "gt.csv")
    np.testing.assert_allclose(truth["b.png"], [1.0, 2.0, 3.0])
    (tmp_path / "bad.csv").write_text("name,red,green,blue\na,1,2,3\n")
    with pytest.raises(ValueError, match="image,r,g,b"):
        io.read_ground_truth(tmp_path / "bad.csv")
    (tmp_path / "neg.csv").write_text("image,r,g,b\na,-1,2,3\n")
    with pytest.raises(ValueError, match="line 2"):
        io.read_ground_truth(tmp_path / "neg.csv")
    with pytest.raises(ValueError, match="not found"):
        io.match_ground_truth(truth, tmp_path)


def test_ground_truth_matches_by_name_then_stem(tmp_path):
    truth_path = io.write_dataset(tmp_path, np.full((2, 3, 3, 3), 0.25), [[1.0, 2.0, 3.0], [3.0, 2.0, 1.0]])
    truth = io.read_ground_truth(truth_path)
    truth["image-0001.tif"] = truth.pop("image-0001.png")  # another suffix: found by its stem
    pairs = io.match_ground_truth(truth, tmp_path)
    assert [p.name for p, _ in pairs] == ["image-0000.png", "image-0001.png"]
    np.testing.assert_allclose(pairs[1][1], [3.0, 2.0, 1.0])


def test_preview_renders_the_canonical_white_grey():
    world = small_world()
    matrix = io.preview_matrix(world)
    white = np.asarray(world.canonical_white)[None, None] * np.ones((2, 2, 1), np.float32)
    preview = io.srgb_preview(white, matrix)
    assert preview.dtype == np.uint8 and np.all(preview == preview[0, 0, 0])


def test_preview_encodes_with_the_iec_61966_2_1_curve():
    """Oracle: the sRGB transfer curve of IEC 61966-2-1 written out (linear toe below 0.0031308);
    the identity matrix and a 100th-percentile exposure leave the values as given."""
    linear = np.linspace(0.0, 1.0, 301, dtype=np.float32).reshape(1, 301, 1) * np.ones((1, 1, 3), np.float32)
    want = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * np.power(linear.astype(np.float64), 1 / 2.4) - 0.055)
    got = io.srgb_preview(linear, None, percentile=100.0)
    assert np.max(np.abs(got.astype(int) - np.round(want * 255).astype(int))) == 0
    # The XYZ -> sRGB matrix colour-science derives from the primaries and D65 is IEC 61966-2-1's
    # published one (the constants the previews used) to its 4 decimals.
    import colour

    iec = [[3.2404542, -1.5371385, -0.4985314], [-0.9692660, 1.8760108, 0.0415560], [0.0556434, -0.2040259, 1.0572252]]
    np.testing.assert_allclose(colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB, iec, atol=5e-4)


def test_preview_matrix_is_cached_as_arrays(tmp_path, monkeypatch):
    from ccjax.io import preview

    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path / "cache"))
    world, cache = small_world(), tmp_path / "cache"

    first = io.preview_matrix_cached(world)
    np.testing.assert_array_equal(first, io.preview_matrix(world))
    stored = list((cache / "preview").glob("*.npz"))
    assert len(stored) == 1
    with np.load(stored[0], allow_pickle=False) as arrays:  # no pickle in the file
        np.testing.assert_array_equal(arrays["matrix"], first)
    monkeypatch.setattr(preview, "preview_matrix", lambda world: pytest.fail("recomputed instead of loading"))
    np.testing.assert_array_equal(io.preview_matrix_cached(world), first)


# ---------------------------------------------------------------------------------------------
# Camera raw


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
    image = io.read_image(tmp_path / "a.dng")
    assert image.rgb.shape == (32, 48, 3)  # one pixel per Bayer quad (no demosaicing)
    np.testing.assert_allclose(image.rgb[5, 5], np.array([1000, 2000, 3000]) / 4095, rtol=2e-4)
    assert image.clipped[0, 0] and image.clipped.sum() == 1


def _srgb_decoded(codes, maximum):
    """Oracle: the IEC 61966-2-1 decoding curve written out."""
    v = codes.astype(np.float64) / maximum
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def test_decode_srgb_reads_8_bit_png_and_jpeg_as_linear(tmp_path):
    """``decode_srgb``: 8-bit PNG and JPEG are accepted and their codes decoded with the sRGB
    curve; without it both are refused, naming the file and the option."""
    import imagecodecs

    rng = np.random.default_rng(4)
    codes = rng.integers(1, 250, (12, 16, 3)).astype(np.uint8)
    io.write_png(tmp_path / "a.png", codes)
    (tmp_path / "b.jpg").write_bytes(imagecodecs.jpeg8_encode(codes, level=95))
    for name in ("a.png", "b.jpg"):
        with pytest.raises(ValueError, match=rf"{name} is 8-bit.*--decode-srgb"):
            io.probe_image(tmp_path / name)
        with pytest.raises(ValueError, match=rf"{name} is 8-bit.*--decode-srgb"):
            io.read_image(tmp_path / name)
        info = io.probe_image(tmp_path / name, decode_srgb=True)
        assert (info.height, info.width, info.channels, info.bit_depth) == (12, 16, 3, 8)
    png = io.read_image(tmp_path / "a.png", decode_srgb=True)
    np.testing.assert_allclose(png.rgb, _srgb_decoded(codes, 255), rtol=1e-5, atol=1e-7)
    jpeg = io.read_image(tmp_path / "b.jpg", decode_srgb=True)
    decoded = np.asarray(imagecodecs.jpeg8_decode((tmp_path / "b.jpg").read_bytes()))
    np.testing.assert_allclose(jpeg.rgb, _srgb_decoded(decoded, 255), rtol=1e-5, atol=1e-7)
    # A folder lists the JPEG (it was skipped without a word).
    assert [p.name for p in io.list_images([tmp_path])] == ["a.png", "b.jpg"]
