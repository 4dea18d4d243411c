"""Camera raw files through rawpy (LibRaw): DNG files written by tests/dng_files.py are read at
half and full size, upright, on the unit scale of their own black and white levels, with their
own colour matrix; the camera-to-sRGB matrix of a corrected image against closed forms."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from dng_files import BLACK, D65, EOS_5D, EOS_5D_MARK_II_D65, ILLUMINANT_A, WHITE, bayer, write_dng

from ccjax import io
from ccjax.io import raw as raw_io

rawpy = pytest.importorskip("rawpy", reason="camera raw files are read through rawpy (pip install 'ccjax[raw]')")

HEIGHT, WIDTH = 64, 96
LEFT, RIGHT = (5000, 9000, 3000), (2000, 4000, 12000)
"""RGGB codes (red, green, blue) of the left and right halves of the test sensor."""


def _sensor() -> np.ndarray:
    """The test CFA: two flat colours, left and right of column 48."""
    cfa = bayer(*LEFT, HEIGHT, WIDTH)
    cfa[:, WIDTH // 2 :] = bayer(*RIGHT, HEIGHT, WIDTH // 2)
    return cfa


def _oracle(height: int, width: int) -> np.ndarray:
    """Oracle: the colour of each pixel of an ``(height, width)`` grid over the sensor (as stored,
    before orientation), ``(code - black) / (white - black)``."""
    rgb = np.empty((height, width, 3))
    rgb[:, : width // 2] = (np.array(LEFT) - BLACK) / (WHITE - BLACK)
    rgb[:, width // 2 :] = (np.array(RIGHT) - BLACK) / (WHITE - BLACK)
    return rgb


def _upright(rgb: np.ndarray) -> np.ndarray:
    """Orientation 6 (TIFF: row 0 is the right side, column 0 the top): a quarter turn clockwise."""
    return np.rot90(rgb, k=-1)


def test_libraw_reads_the_test_dng(tmp_path):
    """The helper's DNG is what it says, as LibRaw sees it."""
    write_dng(tmp_path / "a.dng", _sensor())
    with rawpy.imread(str(tmp_path / "a.dng")) as raw:
        assert raw.raw_image.shape == (HEIGHT, WIDTH)
        assert list(raw.black_level_per_channel) == [BLACK] * 4
        assert raw.white_level == WHITE
        assert raw.sizes.flip == 6  # LibRaw's code for TIFF orientation 6
        np.testing.assert_array_equal(raw.raw_image, _sensor())


def test_half_and_full_size_are_upright_on_the_files_levels(tmp_path):
    """Half size: one pixel per Bayer quad, exactly the quad's codes; full size: the sensor's
    size, demosaiced (flat areas keep their colour away from the edge between them); both turned
    upright (Orientation 6: height and width swapped) and scaled by the file's black and white."""
    write_dng(tmp_path / "a.dng", _sensor())
    half = io.read_image(tmp_path / "a.dng")
    assert half.rgb.shape == (WIDTH // 2, HEIGHT // 2, 3)
    np.testing.assert_allclose(half.rgb, _upright(_oracle(HEIGHT // 2, WIDTH // 2)), rtol=2e-4)
    info = io.probe_image(tmp_path / "a.dng", raw_full_size=True)
    assert (info.height, info.width) == (WIDTH, HEIGHT)
    full = io.read_image(tmp_path / "a.dng", raw_full_size=True)
    assert full.rgb.shape == (WIDTH, HEIGHT, 3) and full.rgb.dtype == np.float32
    expected = _upright(_oracle(HEIGHT, WIDTH))
    # Upright, the left half of the sensor is the top half; compare 4 pixels from every edge.
    for rows in (slice(4, WIDTH // 2 - 4), slice(WIDTH // 2 + 4, WIDTH - 4)):
        np.testing.assert_allclose(full.rgb[rows, 4:-4], expected[rows, 4:-4], rtol=2e-4)
    assert not full.clipped.any()
    np.testing.assert_allclose(full.camera_to_xyz, np.linalg.inv(np.reshape(EOS_5D_MARK_II_D65, (3, 3)) / 1e4))


def test_clipping_at_full_size(tmp_path):
    """A saturated area of the sensor is clipped where it lands upright."""
    cfa = _sensor()
    cfa[:16, 72:] = WHITE  # stored top right: upright, the bottom right
    write_dng(tmp_path / "a.dng", cfa)
    full = io.read_image(tmp_path / "a.dng", raw_full_size=True)
    expected = np.zeros((HEIGHT, WIDTH), bool)
    expected[:16, 72:] = True
    expected = _upright(expected)
    interior = np.zeros_like(expected)
    interior[2:-2, 2:-2] = True
    np.testing.assert_array_equal(full.clipped[interior & expected], True)
    away = np.ones_like(expected)
    away[60:, 44:] = False  # the clipped area and 4 pixels around it
    np.testing.assert_array_equal(full.clipped[away & interior], False)


def test_matrix_from_the_dng_tags(tmp_path):
    """A DNG's own ColorMatrix, inverted: camera RGB -> XYZ. LibRaw's ``rgb_xyz_matrix`` is its
    table's entry for the model (zeros for a model it does not know), not the file's matrix."""
    oracle = np.linalg.inv(np.reshape(EOS_5D_MARK_II_D65, (3, 3)) / 1e4)
    write_dng(tmp_path / "a.dng", _sensor(), make="ccjax", model="ccjax test camera")
    with rawpy.imread(str(tmp_path / "a.dng")) as raw:
        assert not np.any(raw.rgb_xyz_matrix)
    np.testing.assert_allclose(raw_io.camera_to_xyz(tmp_path / "a.dng"), oracle, rtol=1e-6)
    np.testing.assert_allclose(io.read_image(tmp_path / "a.dng").camera_to_xyz, oracle, rtol=1e-6)
    # Two matrices: the D65 one (ColorMatrix2 here), with AnalogBalance applied (DNG 1.6, ch. 6:
    # XYZ -> camera = AnalogBalance @ CameraCalibration @ ColorMatrix).
    balance = np.array([0.9, 1.0, 1.1])
    matrices = ((EOS_5D, ILLUMINANT_A), (EOS_5D_MARK_II_D65, D65))
    write_dng(tmp_path / "b.dng", _sensor(), matrices=matrices, analog_balance=balance, model="ccjax test camera")
    xyz_to_camera = np.diag(balance) @ np.reshape(EOS_5D_MARK_II_D65, (3, 3)) / 1e4
    np.testing.assert_allclose(raw_io.camera_to_xyz(tmp_path / "b.dng"), np.linalg.inv(xyz_to_camera), rtol=1e-6)
    # Only an illuminant-A matrix: that one.
    write_dng(tmp_path / "c.dng", _sensor(), matrices=((EOS_5D, ILLUMINANT_A),), model="ccjax test camera")
    oracle_a = np.linalg.inv(np.reshape(EOS_5D, (3, 3)) / 1e4)
    np.testing.assert_allclose(raw_io.camera_to_xyz(tmp_path / "c.dng"), oracle_a, rtol=1e-6)


def test_matrix_from_libraws_table_or_none(tmp_path):
    """Without a matrix in the file: LibRaw's table for the model, Adobe's published numbers
    / 10000 (LibRaw does not rescale them), inverted; None for a camera LibRaw does not know, and
    for a file whose matrix is all zeros."""
    write_dng(tmp_path / "a.dng", _sensor(), matrices=())
    oracle = np.linalg.inv(np.reshape(EOS_5D_MARK_II_D65, (3, 3)) / 1e4)
    np.testing.assert_allclose(raw_io.camera_to_xyz(tmp_path / "a.dng"), oracle, rtol=1e-6)
    write_dng(tmp_path / "b.dng", _sensor(), matrices=(), model="ccjax test camera")
    assert raw_io.camera_to_xyz(tmp_path / "b.dng") is None
    assert io.read_image(tmp_path / "b.dng").camera_to_xyz is None
    write_dng(tmp_path / "c.dng", _sensor(), matrices=(((0,) * 9, D65),), model="ccjax test camera")
    assert raw_io.camera_to_xyz(tmp_path / "c.dng") is None


# sRGB (IEC 61966-2-1): linear sRGB -> XYZ, the standard's published matrix.
SRGB_TO_XYZ = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])


def test_camera_to_srgb_pins_the_white_and_keeps_primaries():
    """The canonical white lands on (1, 1, 1) times its brightest channel; the rows are those of
    colour-science's XYZ -> sRGB times the camera matrix, each scaled; and when the white is the
    camera's response to D65 (sRGB's white), a colour with the XYZ of sRGB's red primary lands on
    pure red."""
    import colour

    xyz_to_camera = np.reshape(EOS_5D_MARK_II_D65, (3, 3)) / 1e4
    camera_to_xyz = np.linalg.inv(xyz_to_camera)
    white = np.array([0.6, 1.3, 0.9])
    matrix = raw_io.camera_to_srgb(camera_to_xyz, white)
    assert matrix.shape == (3, 3) and matrix.dtype == np.float32
    np.testing.assert_allclose(matrix @ white, np.full(3, 1.3), rtol=1e-5)
    unscaled = np.asarray(colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB) @ camera_to_xyz
    ratios = matrix / unscaled
    np.testing.assert_allclose(ratios, ratios[:, :1].repeat(3, axis=1), rtol=1e-5)
    d65_white = xyz_to_camera @ SRGB_TO_XYZ.sum(axis=1)  # XYZ of sRGB white (1, 1, 1)
    pinned = raw_io.camera_to_srgb(camera_to_xyz, d65_white)
    for primary in range(3):
        expected = np.eye(3)[primary] * d65_white.max()
        np.testing.assert_allclose(pinned @ xyz_to_camera @ SRGB_TO_XYZ[:, primary], expected, atol=1e-3)


def test_camera_to_srgb_refuses_bad_input():
    identity = np.eye(3)
    with pytest.raises(ValueError, match="camera_to_xyz: expected a finite 3x3"):
        raw_io.camera_to_srgb(np.eye(4), [1, 1, 1])
    with pytest.raises(ValueError, match="white: expected three positive"):
        raw_io.camera_to_srgb(identity, [1, 0, 1])
    with pytest.raises(ValueError, match="white: camera_to_xyz maps the white"):
        raw_io.camera_to_srgb(-identity, [1, 1, 1])


PEAK_SCRIPT = """
import re, sys
from ccjax import io
image = io.read_image(sys.argv[1], raw_full_size=True)
assert image.rgb.shape == (6000, 4000, 3), image.rgb.shape
# VmHWM: this program's own peak (ru_maxrss would count the forking test process's size too).
print(re.search(r"VmHWM:\\s+(\\d+) kB", open("/proc/self/status").read()).group(1))
"""


@pytest.mark.slow
def test_full_size_24_mp_peak_memory(tmp_path):
    """A 24 MP raw (6000 x 4000 sensor, turned upright) read at full size peaks well under 2 GB
    of resident memory (float32 only: the demosaiced uint16 and one float32 copy)."""
    rng = np.random.default_rng(0)
    cfa = rng.integers(BLACK, WHITE, (4000, 6000), dtype=np.uint16)
    write_dng(tmp_path / "big.dng", cfa)
    del cfa
    result = subprocess.run(
        [sys.executable, "-c", PEAK_SCRIPT, str(tmp_path / "big.dng")], capture_output=True, text=True, check=True
    )
    peak_bytes = int(result.stdout.split()[-1]) * 1024  # VmHWM is in KiB
    assert peak_bytes < 1.5 * 2**30, f"peak resident memory {peak_bytes / 2**20:.0f} MiB"
