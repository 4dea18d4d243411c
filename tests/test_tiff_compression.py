"""Compressed TIFFs (LZW, deflate, JPEG) read through :mod:`ccjax.io` as tifffile expects, with
``imagecodecs`` (a dependency of ccjax) doing the decoding.

Oracle: the pixel codes written. Lossless codecs read back bit-exact (``rgb * (2^16 - 1)`` is the
code); JPEG (8-bit, lossy) reads back within a few codes of a smooth image.
"""

import pathlib
import tomllib

import numpy as np
import pytest
import tifffile

from ccjax.io import probe_image, read_image

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _codes(dtype=np.uint16, height=48, width=64, seed=0):
    # Every code from 0 to the maximum, in random order, plus a smooth ramp: lossless codecs must
    # return each one.
    rng = np.random.default_rng(seed)
    top = np.iinfo(dtype).max
    noise = rng.integers(0, top, size=(height, width, 3), endpoint=True, dtype=dtype)
    noise[0, 0] = 0
    noise[0, 1] = top
    return noise


def test_imagecodecs_is_a_dependency():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert any(dependency.split(">")[0].strip() == "imagecodecs" for dependency in project["dependencies"])


@pytest.mark.parametrize(
    ("compression", "predictor"),
    [("lzw", None), ("lzw", "horizontal"), ("deflate", None), ("zstd", None)],
)
def test_lossless_16_bit_tiff_reads_bit_exact(tmp_path, compression, predictor):
    codes = _codes()
    path = tmp_path / f"{compression}.tif"
    tifffile.imwrite(path, codes, photometric="rgb", compression=compression, predictor=predictor)
    with tifffile.TiffFile(path) as tif:
        assert compression.upper() in tif.pages[0].compression.name  # LZW, ADOBE_DEFLATE or DEFLATE, ZSTD
    info = probe_image(path)
    assert info.bit_depth == 16
    image = read_image(path, saturation=65536)  # no code clipped: every pixel is compared
    assert image.rgb.dtype == np.float32 and image.rgb.shape == codes.shape
    np.testing.assert_array_equal(np.rint(image.rgb.astype(np.float64) * 65536), codes)
    assert not image.clipped.any()
    # With the default saturation (the 16-bit maximum) the clip mask follows the codes.
    default = read_image(path)
    np.testing.assert_array_equal(np.rint(default.rgb.astype(np.float64) * 65535), codes)
    np.testing.assert_array_equal(default.clipped, (codes >= np.ceil(0.98 * 65535)).any(axis=-1))


def test_lzw_planar_and_float_tiffs(tmp_path):
    codes = _codes(seed=1)
    planar = tmp_path / "planar.tif"
    tifffile.imwrite(planar, np.moveaxis(codes, -1, 0), photometric="rgb", planarconfig="separate", compression="lzw")
    np.testing.assert_array_equal(np.rint(read_image(planar, saturation=65536).rgb.astype(np.float64) * 65536), codes)
    values = np.random.default_rng(2).random((32, 40, 3), dtype=np.float32) * 0.9
    floating = tmp_path / "float.tif"
    tifffile.imwrite(floating, values, photometric="rgb", compression="deflate", predictor="floatingpoint")
    np.testing.assert_array_equal(read_image(floating).rgb, values)


def test_jpeg_tiff_reads_close_to_the_codes(tmp_path):
    # A smooth 8-bit image (JPEG is lossy and made for smooth content).
    y, x = np.mgrid[0:64, 0:96]
    smooth = np.stack([40 + x, 60 + y, 200 - x - y // 2], axis=-1).astype(np.uint8)
    path = tmp_path / "jpeg.tif"
    tifffile.imwrite(path, smooth, photometric="rgb", compression="jpeg", compressionargs={"level": 95})
    with tifffile.TiffFile(path) as tif:
        assert tif.pages[0].compression.name == "JPEG"
    with pytest.raises(ValueError, match="8-bit"):
        read_image(path)  # 8-bit files are refused unless declared linear
    image = read_image(path, assume_linear=True)
    assert probe_image(path, assume_linear=True).bit_depth == 8
    error = np.abs(image.rgb.astype(np.float64) * 255 - smooth)
    assert error.mean() < 1.0 and error.max() <= 8


def test_corrupt_compressed_data_is_a_clear_error(tmp_path):
    path = tmp_path / "corrupt.tif"
    tifffile.imwrite(path, _codes(), photometric="rgb", compression="lzw")
    blob = bytearray(path.read_bytes())
    with tifffile.TiffFile(path) as tif:
        offset = tif.pages[0].dataoffsets[0]
    blob[offset : offset + 64] = b"\xff" * 64
    path.write_bytes(bytes(blob))
    with pytest.raises(ValueError, match=r"cannot read .*corrupt\.tif"):
        read_image(path)
