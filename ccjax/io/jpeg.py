"""JPEG files: the header's layout and the whole, upright pixels, or a clear error.

Decoded by Pillow (libjpeg), with its own pixel limit lifted: the caller's budget
(:data:`ccjax.limits.PIXELS`, ``--max-pixels``) is checked from the header first, and Pillow's
fixed 179 MP limit must not override it. A file whose data ends early is an error (libjpeg
would fill the missing rows with grey and call the image read). The EXIF orientation is applied
(a camera held upright writes its rows sideways and says so in the tag), so a corrected image
comes out as the photographer saw it.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

import numpy as np

ORIENTATION_TAG = 0x0112
"""EXIF's orientation tag: 1 upright; 2-8 mirrored and/or rotated (5-8 swap width and height)."""


@contextlib.contextmanager
def _opened(path: Path) -> Iterator:
    """The file opened by Pillow as a JPEG, with Pillow's own pixel limit lifted for this open."""
    from PIL import Image

    limit, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
    try:
        image = Image.open(path)
    finally:
        Image.MAX_IMAGE_PIXELS = limit
    with image:
        if image.format != "JPEG":
            raise ValueError(f"not a JPEG file ({image.format})")
        yield image


def _orientation(image) -> int:
    value = image.getexif().get(ORIENTATION_TAG, 1)
    return value if isinstance(value, int) and 1 <= value <= 8 else 1


def jpeg_layout(path: Path) -> tuple[tuple[int, ...], np.dtype]:
    """Shape (upright, channels last) and sample type of a JPEG from its header alone.

    Arguments:
        path: the file.

    Returns:
        ``((height, width[, channels]), uint8)``, height and width after the EXIF orientation.

    Raises:
        ValueError: not a JPEG, or a colour mode other than RGB or grey.
    """
    with _opened(path) as image:
        width, height = image.size
        channels = {"L": 1, "RGB": 3}.get(image.mode)
        if channels is None:
            raise ValueError(f"JPEG colour mode {image.mode} is not supported; expected RGB")
        if _orientation(image) >= 5:
            width, height = height, width
    return (height, width) + ((channels,) if channels > 1 else ()), np.dtype(np.uint8)


_ARITHMETIC_FRAMES = (b"\xff\xc9", b"\xff\xca", b"\xff\xcb", b"\xff\xcd", b"\xff\xce", b"\xff\xcf")
"""Start-of-frame markers of arithmetic-coded JPEG, whose blocks may take less than a bit."""


def _check_data_size(path: Path, pixels: int) -> None:
    """Refuse a Huffman-coded JPEG too small for the pixels its header claims.

    Each 8x8 block of the luminance carries a DC coefficient coded with at least one bit
    (baseline and progressive alike), so a file of ``n`` bytes holds at most ``8 n`` blocks.
    libjpeg fills the blocks a file lacks with grey and only warns: a 630-byte file claiming
    10000 x 10000 pixels decoded (3 GB) as a flat grey image and was estimated "ok".
    """
    size = path.stat().st_size
    if 8 * size >= pixels / 64:
        return
    blob = path.read_bytes()  # small: under a bit per block of the claimed size
    if any(marker in blob for marker in _ARITHMETIC_FRAMES):
        return
    raise ValueError(
        f"its header claims {pixels:,} pixels, more than its {size:,} bytes can hold (at least one bit per "
        "8x8 block): the file is cut short or its header is wrong"
    )


def read_jpeg(path: Path) -> np.ndarray:
    """The pixels of a JPEG, upright (its EXIF orientation applied).

    Arguments:
        path: the file (its layout already checked by :func:`jpeg_layout`).

    Returns:
        ``(H, W, 3)`` (or ``(H, W)`` grey) ``uint8`` codes.

    Raises:
        ValueError: the data ends early, is too small for the claimed size, or does not decode.
    """
    with _opened(path) as image:
        _check_data_size(path, image.size[0] * image.size[1])
        orientation = _orientation(image)
        try:
            image.load()
        except OSError as error:  # "image file is truncated", broken data
            raise ValueError(f"the JPEG data is damaged or cut short ({error})") from None
        pixels = np.asarray(image)
    return np.ascontiguousarray(orient(pixels, orientation))


def orient(pixels: np.ndarray, orientation: int) -> np.ndarray:
    """Rows and columns as EXIF ``orientation`` says the upright image has them.

    Arguments:
        pixels: ``(H, W, ...)`` as stored.
        orientation: the EXIF value (1-8).

    Returns:
        A view of ``pixels``, upright.
    """
    # EXIF 2.3 Table 4: 2 mirror, 3 rotate 180, 4 flip, 5 transpose, 6 rotate 90 clockwise,
    # 7 transverse, 8 rotate 90 anticlockwise (what to do to the stored rows to see it upright).
    if orientation in (5, 6, 7, 8):
        pixels = np.swapaxes(pixels, 0, 1)  # transpose: 5 done
        orientation = {5: 1, 6: 2, 7: 3, 8: 4}[orientation]
    if orientation == 2:
        return pixels[:, ::-1]
    if orientation == 3:
        return pixels[::-1, ::-1]
    if orientation == 4:
        return pixels[::-1]
    return pixels


__all__ = ["ORIENTATION_TAG", "jpeg_layout", "orient", "read_jpeg"]
