"""sRGB-encoded files: what a file's tags say about its tone curve (:func:`declared_encoding`),
and sRGB-encoded file codes decoded to linear values in bounded memory (IEC 61966-2-1, the
transfer curve colour-science gives)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ccjax.io.icc import MAX_PROFILE_BYTES, icc_encoding
from ccjax.io.png import png_encoding

ICC_PROFILE_TAG = 34675
"""TIFF's tag for an embedded ICC profile (InterColorProfile, TIFF/EP; Adobe's TIFF technote 4)."""


def tiff_encoding(tif) -> str | None:
    """What a TIFF's ICC profile (tag 34675 of its first page) says, when it describes
    sRGB-encoded RGB (:func:`ccjax.io.icc.icc_encoding`).

    Arguments:
        tif: an open ``tifffile.TiffFile``.

    Returns:
        ``"sRGB (ICC profile '...')"``, or None (no profile, or one that does not describe sRGB
        codes, or one over :data:`~ccjax.io.icc.MAX_PROFILE_BYTES`).
    """
    tag = tif.pages[0].tags.get(ICC_PROFILE_TAG)
    if tag is None or tag.count > MAX_PROFILE_BYTES:
        return None
    value = tag.value  # bytes for the UNDEFINED type the TIFF/EP gives; some writers use BYTE
    return icc_encoding(bytes(value)) if isinstance(value, (bytes, bytearray, tuple)) else None


def declared_encoding(path: str | os.PathLike) -> str | None:
    """What a PNG's or TIFF's tags say about its tone curve, when they declare gamma-encoded
    codes: a PNG's ``sRGB``, ``gAMA`` or ``iCCP`` chunk (:func:`ccjax.io.png.png_encoding`), a
    TIFF's ICC profile (:func:`tiff_encoding`). Other files (JPEG, raw) declare nothing here.

    Arguments:
        path: the file (its header already checked).

    Returns:
        The encoding (e.g. ``"sRGB"``, ``"gAMA 0.45455"``, ``"sRGB (ICC profile 'sRGB built-in')"``),
        or None: no such tag, or one that declares linear data.
    """
    suffix = Path(path).suffix.lower()
    if suffix == ".png":
        return png_encoding(path)
    if suffix in (".tif", ".tiff"):
        import tifffile

        with tifffile.TiffFile(path) as tif:
            return tiff_encoding(tif)
    return None


DECODE_ROWS = 256
"""Rows decoded from sRGB at a time: colour-science computes in float64 with several temporaries
(about 175 bytes per pixel for a whole image: 2.4 GB for 12 MP), so only this many rows'
worth of them exist at once."""


def decode_srgb_codes(pixels: np.ndarray, full_scale: float) -> np.ndarray:
    """sRGB-encoded file codes as linear float32 on the format's scale (IEC 61966-2-1 through
    colour-science): integer codes through a table of every code, floats by blocks of
    :data:`DECODE_ROWS` rows, so that memory stays a few bytes per pixel.

    Arguments:
        pixels: ``(H, W, ...)`` codes (integers, or floats on the scale ``full_scale``).
        full_scale: the code of full scale (255, 65535, or 1 for floats).

    Returns:
        The linear values, float32, same shape, on the same scale.
    """
    import colour

    out = np.empty(pixels.shape, np.float32)
    if np.issubdtype(pixels.dtype, np.integer) and pixels.dtype.itemsize <= 2:
        codes = np.arange(int(np.iinfo(pixels.dtype).max) + 1, dtype=np.float64)
        table = (colour.cctf_decoding(codes / full_scale, function="sRGB") * full_scale).astype(np.float32)
        for start in range(0, pixels.shape[0], DECODE_ROWS):
            np.take(table, pixels[start : start + DECODE_ROWS], out=out[start : start + DECODE_ROWS])
        return out
    for start in range(0, pixels.shape[0], DECODE_ROWS):
        block = pixels[start : start + DECODE_ROWS].astype(np.float64) / full_scale
        out[start : start + DECODE_ROWS] = colour.cctf_decoding(block, function="sRGB") * full_scale
    return out


__all__ = ["DECODE_ROWS", "ICC_PROFILE_TAG", "declared_encoding", "decode_srgb_codes", "tiff_encoding"]
