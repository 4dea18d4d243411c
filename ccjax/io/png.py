"""PNG files through libpng (``imagecodecs``): 8- and 16-bit, any colour type on reading.

16-bit RGB is what linear camera data needs, and Pillow (and so imageio) silently reduces it to
8 bits; libpng keeps all 16 (big-endian in the file, native ``uint16`` in memory).
"""

from __future__ import annotations

import os
from pathlib import Path

import imagecodecs
import numpy as np

from ccjax._cache import atomic_write

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
COMPRESSION_LEVEL = 6
"""zlib level of written files (libpng's default trade-off between size and speed)."""


def read_png(path: str | os.PathLike) -> np.ndarray:
    """Read an 8- or 16-bit PNG (grey, grey + alpha, RGB or RGBA; interlaced or not).

    Arguments:
        path: the file.

    Returns:
        ``uint8`` or ``uint16`` pixels, ``(H, W)`` for grey, else ``(H, W, C)``.

    Raises:
        ValueError: not a PNG file, or truncated or corrupt data (the decoder's message).
    """
    blob = Path(path).read_bytes()
    if not blob.startswith(PNG_SIGNATURE):
        raise ValueError("not a PNG file (bad signature)")
    try:
        return np.asarray(imagecodecs.png_decode(blob))
    except imagecodecs.PngError as error:
        raise ValueError(f"corrupt or truncated PNG ({error})") from None


def write_png(path: str | os.PathLike, pixels: np.ndarray) -> None:
    """Write ``uint16`` or ``uint8`` ``(H, W, 3)`` as an RGB PNG, atomically (readers never see a
    partial file).

    Arguments:
        path: the file (missing folders are created).
        pixels: the file codes; 16-bit values are stored big-endian, as PNG requires.

    Raises:
        ValueError: ``pixels`` is not ``uint8``/``uint16`` ``(H, W, 3)`` with at least one pixel.
    """
    pixels = np.asarray(pixels)
    if pixels.ndim != 3 or pixels.shape[2] != 3 or pixels.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"pixels: expected uint8/uint16 (H, W, 3), got {pixels.dtype} {pixels.shape}")
    if pixels.size == 0:
        raise ValueError(f"pixels: a PNG needs at least one pixel, got shape {pixels.shape}")
    atomic_write(Path(path), bytes(imagecodecs.png_encode(np.ascontiguousarray(pixels), level=COMPRESSION_LEVEL)))
