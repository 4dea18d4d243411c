"""sRGB-encoded file codes decoded to linear values in bounded memory (IEC 61966-2-1, the
transfer curve colour-science gives)."""

from __future__ import annotations

import numpy as np

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


__all__ = ["DECODE_ROWS", "decode_srgb_codes"]
