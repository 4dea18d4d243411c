"""Camera raw files through rawpy (LibRaw; the optional ``raw`` extra): linear camera RGB and the
file's own colour matrix.

Developing (:func:`read_raw`): camera-native RGB, linear, no white balance, no colour matrix.
LibRaw subtracts the file's black level and scales its white level to 65535 (so the unit scale
of :func:`ccjax.io.read_image` is ``(code - black) / (white - black)``), and the image is turned
upright by the file's orientation. By default one pixel per Bayer quad (LibRaw's ``half_size``):
every channel of a pixel is measured on the sensor, none is interpolated from its neighbours, so
no pixel mixes the colours of two surfaces across an edge. The thesis' estimators assume such
unmixed pixels (each pixel one surface under one light), so this is the size for estimation.
``full_size`` demosaics (LibRaw's AHD) at the sensor's size, for writing corrected images at the
camera's resolution.

The colour matrix (:func:`camera_to_xyz`): camera RGB on that unit scale to CIE XYZ, from the
file's DNG ``ColorMatrix`` tags, else LibRaw's table for the camera (Adobe's matrices, which is
all a proprietary raw file offers); :func:`camera_to_srgb` turns it into the matrix that shows a
corrected image in sRGB.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

# DNG tags (DNG specification 1.6, chapter 6 "Mapping Camera Color Space to CIE XYZ Space").
_COLOR_MATRIX = (50721, 50722)
_CAMERA_CALIBRATION = (50723, 50724)
_CALIBRATION_ILLUMINANT = (50778, 50779)
_ANALOG_BALANCE = 50727
_D65 = 21
# EXIF LightSource codes LibRaw also takes for daylight when a DNG has no D65 matrix: Daylight,
# Flash, D55, D75, D50 (any of them; of two, the first matrix).
_DAYLIGHT_LIKE = (1, 4, 20, 22, 23)

__all__ = ["camera_to_srgb", "camera_to_xyz", "raw_layout", "raw_module", "read_raw"]


def raw_module(path: Path):
    """The rawpy module (the optional ``raw`` extra).

    Arguments:
        path: the raw file being read (for the message).

    Returns:
        The imported ``rawpy`` module.

    Raises:
        ValueError: rawpy is not installed; the message names ``path`` and the extra.
    """
    try:
        import rawpy  # pyright: ignore[reportMissingImports]  (the optional raw extra)
    except ImportError:
        raise ValueError(f"{path} is a camera raw file; install the raw extra (pip install 'ccjax[raw]')") from None
    return rawpy


def raw_layout(path: Path, full_size: bool = False) -> tuple[tuple[int, int, int], np.dtype]:
    """Shape and sample type :func:`read_raw` will give, from LibRaw's reading of the header.

    Arguments:
        path: the raw file.
        full_size: as :func:`read_raw`.

    Returns:
        ``((height, width, 3), uint16)``: the sensor's visible size (halved unless ``full_size``),
        height and width swapped when the file's orientation turns the image by 90°.

    Raises:
        ValueError: rawpy is not installed.
    """
    with raw_module(path).imread(str(path)) as raw:
        sizes = raw.sizes
        height, width = (sizes.height, sizes.width) if full_size else (sizes.height // 2, sizes.width // 2)
        if sizes.flip & 4:  # LibRaw's flip codes 5 and 6: a quarter turn swaps the sides
            height, width = width, height
        return (height, width, 3), np.dtype(np.uint16)


def read_raw(path: Path, full_size: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """Develop a raw file to linear camera-native RGB on LibRaw's scale, and read its colour matrix.

    Arguments:
        path: the raw file.
        full_size: demosaic at the sensor's size (module docstring); default one pixel per Bayer
            quad, the unmixed pixels estimation wants.

    Returns:
        ``(pixels, matrix)``: ``(H, W, 3)`` uint16 with black at 0 and the file's white level at
        65535, upright; and :func:`camera_to_xyz`'s matrix (None if the file has none).

    Raises:
        ValueError: rawpy is not installed. LibRaw's own errors (rawpy's exception types) pass
            through for the caller to report with the file's name.
    """
    rawpy = raw_module(path)
    with rawpy.imread(str(path)) as raw:
        pixels = raw.postprocess(
            output_color=rawpy.ColorSpace.raw,  # camera-native: no colour matrix
            gamma=(1, 1),
            no_auto_bright=True,
            output_bps=16,
            use_camera_wb=False,
            use_auto_wb=False,
            user_wb=[1.0, 1.0, 1.0, 1.0],  # no white balance: every channel scaled alike
            half_size=not full_size,
            # Keep the camera's white level (LibRaw would lower it to the data's maximum, so a dim
            # image's brightest pixel would read as saturated).
            adjust_maximum_thr=0.0,
        )
        table = np.asarray(raw.rgb_xyz_matrix, np.float64)[:3]
    return pixels, _matrix(path, table)


def camera_to_xyz(path: Path) -> np.ndarray | None:
    """The raw file's camera RGB -> CIE XYZ matrix, for the D65 illuminant.

    Convention: ``xyz = matrix @ camera_rgb``, with ``camera_rgb`` on the unit scale of
    :func:`ccjax.io.read_image` (black 0, the file's white level 1; the matrix is the same at
    half and full size). It is the inverse of the DNG specification's XYZ -> camera matrix
    ``AnalogBalance @ CameraCalibration @ ColorMatrix`` (DNG 1.6, chapter 6), taken from:

    * a DNG's own tags: the ``ColorMatrix`` whose ``CalibrationIlluminant`` is D65 (21), else a
      daylight-like one (Daylight, Flash, D55, D75, D50), else the first (then it holds for that
      illuminant, e.g. A); with its ``CameraCalibration`` and the ``AnalogBalance`` when present;
    * otherwise LibRaw's ``rgb_xyz_matrix``: its table of Adobe's D65 ``ColorMatrix`` for the
      camera's make and model (LibRaw does not rescale it: the entries are Adobe's published
      numbers / 10000). LibRaw gives this table entry even for a DNG, whose own tags it ignores
      there, and zeros for a camera its table lacks; that is why a DNG's tags come first.

    XYZ is relative to the light the matrix was made for (not adapted to another white): the
    camera's response to a D65 white maps to D65's XYZ. Adobe scales these matrices so that
    white's brightest camera channel is about 1 at ``Y = 1``; :func:`camera_to_srgb` needs no
    particular scale.

    Arguments:
        path: the raw file.

    Returns:
        ``(3, 3)`` float64, or None when the file has no matrix (LibRaw's is all zeros and a DNG
        has no usable ``ColorMatrix``) or it is singular.

    Raises:
        ValueError: rawpy is not installed.
    """
    with raw_module(path).imread(str(path)) as raw:
        table = np.asarray(raw.rgb_xyz_matrix, np.float64)[:3]
    return _matrix(path, table)


def _matrix(path: Path, table: np.ndarray) -> np.ndarray | None:
    """camera -> XYZ from the DNG's tags, else from LibRaw's table ``table`` (XYZ -> camera)."""
    xyz_to_camera = _dng_xyz_to_camera(path) if path.suffix.lower() == ".dng" else None
    if xyz_to_camera is None:
        xyz_to_camera = table
    if not np.all(np.isfinite(xyz_to_camera)) or not np.any(xyz_to_camera):
        return None
    try:
        inverse = np.linalg.inv(xyz_to_camera)
    except np.linalg.LinAlgError:
        return None
    return inverse if np.all(np.isfinite(inverse)) else None


def _rationals(value, count: int) -> np.ndarray | None:
    """A (S)RATIONAL tag's ``count`` numbers (tifffile gives numerator, denominator pairs), or None."""
    pairs = np.asarray(value, np.float64).reshape(-1)
    if pairs.size != 2 * count or not np.all(np.isfinite(pairs)) or np.any(pairs[1::2] == 0):
        return None
    return pairs[0::2] / pairs[1::2]


def _dng_xyz_to_camera(path: Path) -> np.ndarray | None:
    """``AnalogBalance @ CameraCalibration @ ColorMatrix`` of a DNG's first IFD, or None."""
    import tifffile

    try:
        with tifffile.TiffFile(path) as tif:
            tags = {tag.code: tag.value for tag in tif.pages.first.tags}
    except (OSError, ValueError):  # tifffile cannot parse it: LibRaw's table is all there is
        return None
    matrices = {
        index: matrix
        for index, code in enumerate(_COLOR_MATRIX)
        if code in tags and (matrix := _rationals(tags[code], 9)) is not None and np.any(matrix)
    }
    if not matrices:
        return None

    def preference(index: int) -> tuple[bool, bool, int]:
        illuminant = tags.get(_CALIBRATION_ILLUMINANT[index])
        return illuminant != _D65, illuminant not in _DAYLIGHT_LIKE, index

    index = min(matrices, key=preference)
    matrix = matrices[index].reshape(3, 3)
    calibration = _rationals(tags.get(_CAMERA_CALIBRATION[index], ()), 9)
    if calibration is not None:
        matrix = calibration.reshape(3, 3) @ matrix
    balance = _rationals(tags.get(_ANALOG_BALANCE, ()), 3)
    if balance is not None:
        matrix = balance[:, None] * matrix
    return matrix


def camera_to_srgb(camera_to_xyz: np.ndarray, white) -> np.ndarray:
    """Camera RGB -> linear sRGB for a corrected image: the file's matrix with the canonical white
    pinned to sRGB white.

    ``srgb = matrix @ camera_rgb``; the rows of ``XYZ_to_sRGB @ camera_to_xyz`` are scaled so that
    ``white`` maps to ``(1, 1, 1) * max(white)``, the normalisation of
    :func:`ccjax.io.preview_matrix` (a grey of the corrected image shows grey).

    Arguments:
        camera_to_xyz: ``(3, 3)`` camera RGB -> XYZ (:func:`camera_to_xyz`,
            ``LinearImage.camera_to_xyz``); its overall scale does not matter.
        white: the camera RGB of the canonical white the image was corrected to (e.g. a world's
            ``canonical_white``), three positive numbers.

    Returns:
        ``(3, 3)`` float32 (to pass to :func:`ccjax.io.srgb_preview` or :func:`ccjax.io.write_preview`).

    Raises:
        ValueError: ``camera_to_xyz`` is not a finite 3x3 matrix, ``white`` not three positive
            finite numbers, or the matrix maps ``white`` outside sRGB (a channel not positive).
    """
    import colour

    matrix = np.asarray(camera_to_xyz, np.float64)
    if matrix.shape != (3, 3) or not np.all(np.isfinite(matrix)):
        raise ValueError(f"camera_to_xyz: expected a finite 3x3 matrix, got shape {matrix.shape}")
    white = np.asarray(white, np.float64)
    if white.shape != (3,) or not np.all(np.isfinite(white)) or not np.all(white > 0):
        raise ValueError(f"white: expected three positive finite numbers (camera RGB), got {white.tolist()}")
    srgb = np.asarray(colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB, np.float64) @ matrix
    landed = srgb @ (white / white.max())
    if not np.all(landed > 0):
        raise ValueError(f"white: camera_to_xyz maps the white {white.tolist()} outside sRGB (to {landed.tolist()})")
    # Scale rows so the white lands exactly on (1, 1, 1) * its brightest channel.
    return (srgb / landed[:, None]).astype(np.float32)
