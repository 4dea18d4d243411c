"""Small DNG files for the camera raw tests, written with tifffile from the DNG specification 1.6
(an uncompressed RGGB Bayer CFA image in IFD 0, with the tags LibRaw needs to read it)."""

from __future__ import annotations

import numpy as np
import tifffile

# Adobe's D65 ColorMatrix (XYZ -> camera) for the Canon EOS 5D Mark II, times 10000, as published
# in dcraw's adobe_coeff table ("Thanks to Adobe for providing these excellent CAM -> XYZ
# matrices!"; the same entry is in LibRaw's src/tables/colordata.cpp), which Adobe DNG Converter
# writes for that camera.
EOS_5D_MARK_II_D65 = (4716, 603, -830, -7798, 15474, 2480, -1496, 1937, 6651)
# The same table's entry for the (original) Canon EOS 5D: a second, different real matrix.
EOS_5D = (6347, -479, -972, -8297, 15954, 2480, -1968, 2131, 7649)
# The Canon EOS 5D Mark II's black and white levels (dcraw's table: white 0x3cf0; black about 1024).
BLACK, WHITE = 1024, 15600
D65, ILLUMINANT_A = 21, 17
"""EXIF LightSource codes of CalibrationIlluminant."""

SRATIONAL, RATIONAL = 10, 5
"""TIFF data types."""


def _pairs(numbers, denominator: int) -> tuple[int, ...]:
    """Numerator, denominator pairs of numbers already multiplied by ``denominator``."""
    return tuple(value for number in numbers for value in (int(number), denominator))


def bayer(red: int, green: int, blue: int, height: int, width: int) -> np.ndarray:
    """An RGGB mosaic of one colour: ``(height, width)`` uint16 codes."""
    cfa = np.empty((height, width), np.uint16)
    cfa[0::2, 0::2], cfa[0::2, 1::2], cfa[1::2, 0::2], cfa[1::2, 1::2] = red, green, green, blue
    return cfa


def write_dng(
    path,
    cfa: np.ndarray,
    *,
    black: int = BLACK,
    white: int = WHITE,
    matrices=((EOS_5D_MARK_II_D65, D65),),
    analog_balance=None,
    as_shot_neutral=(0.4735, 1.0, 0.6840),
    orientation: int = 6,
    make: str = "Canon",
    model: str = "Canon EOS 5D Mark II",
) -> None:
    """Write an uncompressed RGGB DNG.

    Arguments:
        path: the ``.dng`` file.
        cfa: ``(H, W)`` uint16 sensor codes, RGGB from the top-left corner.
        black, white: BlackLevel and WhiteLevel.
        matrices: up to two ``(ColorMatrix times 10000, CalibrationIlluminant)``: ColorMatrix1
            and ColorMatrix2 (XYZ -> camera, row-major), none for a file without a matrix.
        analog_balance: AnalogBalance (three numbers) or None.
        as_shot_neutral: AsShotNeutral (camera RGB of the light; it plays no part in reading).
        orientation: the TIFF Orientation (6: the camera was turned, rotate 90° clockwise to view).
        make, model: Make and Model; UniqueCameraModel is the model. LibRaw looks the model up in
            its own table of colour matrices.

    Returns:
        None.
    """
    tags = [
        (274, "H", 1, orientation, True),
        (33421, "H", 2, (2, 2), True),  # CFARepeatPatternDim
        (33422, "B", 4, (0, 1, 1, 2), True),  # CFAPattern: RGGB (0 red, 1 green, 2 blue)
        (50706, "B", 4, (1, 4, 0, 0), True),  # DNGVersion
        (50707, "B", 4, (1, 1, 0, 0), True),  # DNGBackwardVersion
        (50708, "s", 0, model, True),  # UniqueCameraModel
        (50714, "H", 1, black, True),  # BlackLevel
        (50717, "H", 1, white, True),  # WhiteLevel
        (50728, RATIONAL, 3, _pairs(np.round(np.asarray(as_shot_neutral) * 10000), 10000), True),  # AsShotNeutral
        (271, "s", 0, make, True),
        (272, "s", 0, model, True),
    ]
    for index, (matrix, illuminant) in enumerate(matrices):
        tags.append((50721 + index, SRATIONAL, 9, _pairs(matrix, 10000), True))  # ColorMatrix1/2
        tags.append((50778 + index, "H", 1, illuminant, True))  # CalibrationIlluminant1/2
    if analog_balance is not None:
        tags.append((50727, RATIONAL, 3, _pairs(np.round(np.asarray(analog_balance) * 10000), 10000), True))
    tifffile.imwrite(path, cfa, photometric=32803, extratags=tags, metadata=None)


GREY_CARD = (24, 36, 16, 24)
"""The rectangle ``X,Y,W,H`` inside :func:`photo_dng`'s grey card, in the upright half-size image
that estimation reads (the card covers columns 20-43 and rows 32-63 there)."""


def photo_dng(path, seed: int = 0) -> None:
    """A small raw photograph: a 128 x 192 RGGB sensor (Orientation 6: upright, 192 rows by 128
    columns at full size, 96 by 64 at half size) of flat coloured patches and a grey card
    (reflectance 0.45, sensor rows 40-87, columns 64-127) under a warm light whose camera RGB is
    (0.9, 1.0, 0.55), with the Canon EOS 5D Mark II's make, model and colour matrix.

    Arguments:
        path: the ``.dng`` file.
        seed: the patches' colours.

    Returns:
        None.
    """
    rng = np.random.default_rng(seed)
    reflectance = rng.uniform(0.05, 0.8, (8, 12, 3)).repeat(16, 0).repeat(16, 1)
    reflectance[40:88, 64:128] = 0.45
    codes = np.round(BLACK + reflectance * np.array([0.9, 1.0, 0.55]) * 0.9 * (WHITE - BLACK)).astype(np.uint16)
    cfa = np.empty(codes.shape[:2], np.uint16)
    cfa[0::2, 0::2], cfa[0::2, 1::2] = codes[0::2, 0::2, 0], codes[0::2, 1::2, 1]
    cfa[1::2, 0::2], cfa[1::2, 1::2] = codes[1::2, 0::2, 1], codes[1::2, 1::2, 2]
    path.parent.mkdir(parents=True, exist_ok=True)
    write_dng(path, cfa)
