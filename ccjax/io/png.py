"""PNG files through libpng (``imagecodecs``): 8- and 16-bit, any colour type on reading.

16-bit RGB is what linear camera data needs, and Pillow (and so imageio) silently reduces it to
8 bits; libpng keeps all 16 (big-endian in the file, native ``uint16`` in memory).

The header and the chunk CRCs are read here, not by a library: imagecodecs has no header-only
PNG call (``png_check`` tests the signature, ``png_decode`` decodes every pixel, which probing
a folder before any work must not do), Pillow's lazy open hides the bit depth of 16-bit RGB
(mode ``"RGB"``), and libpng only warns about a bad CRC in an ancillary chunk.
"""

from __future__ import annotations

import os
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import imagecodecs
import numpy as np

from ccjax.io.files import write_file
from ccjax.io.icc import MAX_PROFILE_BYTES, icc_encoding

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
COMPRESSION_LEVEL = 6
"""zlib level of written files (libpng's default trade-off between size and speed)."""

_CHANNELS = {0: 1, 2: 3, 3: 3, 4: 2, 6: 4}  # PNG colour type -> channels after decoding (3: palette)


@dataclass(frozen=True)
class PngHeader:
    """What a PNG's IHDR chunk says (read without decoding pixels).

    Attributes:
        width, height: the size in pixels.
        bit_depth: bits per sample (1, 2, 4, 8 or 16; palette files decode to 8-bit RGB).
        channels: samples per pixel after decoding (1 grey, 2 grey + alpha, 3 RGB/palette, 4 RGBA).
    """

    width: int
    height: int
    bit_depth: int
    channels: int


def _chunks(blob: bytes) -> Iterator[tuple[bytes, memoryview]]:
    """``(type, data)`` of each chunk after the signature, CRC-checked (ValueError naming the chunk);
    the data are views into ``blob`` (no copies: a camera-sized IDAT is checked in place)."""
    view = memoryview(blob)
    offset = len(PNG_SIGNATURE)
    while offset < len(blob):
        if offset + 12 > len(blob):
            raise ValueError(f"truncated PNG (a chunk header at byte {offset} is cut off)")
        (length,) = struct.unpack(">I", blob[offset : offset + 4])
        end = offset + 12 + length
        if end > len(blob):
            raise ValueError(f"truncated PNG (chunk at byte {offset} needs {length} bytes)")
        kind = blob[offset + 4 : offset + 8]
        data = view[offset + 8 : end - 4]
        (stored,) = struct.unpack(">I", blob[end - 4 : end])
        if zlib.crc32(data, zlib.crc32(kind)) != stored:
            name = kind.decode("latin-1", "replace")
            raise ValueError(f"corrupt PNG: CRC mismatch in chunk {name!r} at byte {offset}")
        yield kind, data
        if kind == b"IEND":
            return
        offset = end
    raise ValueError("truncated PNG (no IEND chunk)")


def _header(kind: bytes, data: bytes | memoryview) -> PngHeader:
    if kind != b"IHDR" or len(data) != 13:
        raise ValueError("corrupt PNG: the first chunk is not a 13-byte IHDR")
    width, height, depth, colour = struct.unpack(">IIBB", data[:10])
    if colour not in _CHANNELS or width == 0 or height == 0:
        raise ValueError(f"corrupt PNG: IHDR gives size {width}x{height}, colour type {colour}")
    return PngHeader(width=width, height=height, bit_depth=8 if colour == 3 else depth, channels=_CHANNELS[colour])


def png_header(path: str | os.PathLike) -> PngHeader:
    """The size, bit depth and channels of a PNG from its IHDR chunk (CRC-checked), without
    reading the rest of the file.

    Arguments:
        path: the file.

    Returns:
        A :class:`PngHeader`.

    Raises:
        ValueError: not a PNG file, or a truncated or corrupt header.
    """
    with open(path, "rb") as handle:
        blob = handle.read(len(PNG_SIGNATURE) + 25)
    if not blob.startswith(PNG_SIGNATURE):
        raise ValueError("not a PNG file (bad signature)")
    if len(blob) < len(PNG_SIGNATURE) + 25:
        raise ValueError("truncated PNG (the header is cut off)")
    (length,) = struct.unpack(">I", blob[8:12])
    kind, data = blob[12:16], blob[16 : 16 + min(length, 13)]
    (stored,) = struct.unpack(">I", blob[29:33])
    if length != 13 or zlib.crc32(data, zlib.crc32(kind)) != stored:
        raise ValueError(
            "corrupt PNG: CRC mismatch in chunk 'IHDR' at byte 8"
            if length == 13
            else "corrupt PNG: the first chunk is not a 13-byte IHDR"
        )
    return _header(kind, data)


LINEAR_GAMMA = 100000
"""A ``gAMA`` chunk's value for linear data (file gamma 1.0, in units of 1e-5)."""


def png_encoding(path: str | os.PathLike) -> str | None:
    """What a PNG's ancillary chunks before its image data say about its tone curve: ``"sRGB"``
    (an ``sRGB`` chunk), ``"gAMA <g>"`` (a file gamma other than 1), ``"sRGB (ICC profile ...)"``
    (an ``iCCP`` profile describing sRGB-encoded RGB, :func:`ccjax.io.icc.icc_encoding`), or None
    (no such chunk, gamma 1 or a linear profile: linear). Only chunk headers are read (a seek
    past each chunk's data), and an ``iCCP`` chunk's data.

    Arguments:
        path: the file (its IHDR already checked, :func:`png_header`).

    Returns:
        The encoding the file declares, or None.
    """
    for kind, length, handle in _leading_chunks(path):
        if kind == b"sRGB":
            return "sRGB"
        if kind == b"gAMA" and length == 4:
            (gamma,) = struct.unpack(">I", handle.read(4))
            if gamma != LINEAR_GAMMA:
                return f"gAMA {gamma / 1e5:g}"
        if kind == b"iCCP" and length <= MAX_PROFILE_BYTES and (profile := _profile(handle.read(length))):
            if (encoding := icc_encoding(profile)) is not None:
                return encoding
    return None


def _leading_chunks(path: str | os.PathLike) -> Iterator[tuple[bytes, int, BinaryIO]]:
    """``(kind, length, handle)`` of each chunk after IHDR and before the image data (the handle at
    the chunk's data), reading only what the caller reads of each."""
    with open(path, "rb") as handle:
        size = os.fstat(handle.fileno()).st_size
        offset = len(PNG_SIGNATURE) + 25
        while offset + 8 <= size:
            handle.seek(offset)
            length, kind = struct.unpack(">I4s", handle.read(8))
            if kind in (b"IDAT", b"IEND") or offset + 12 + length > size:
                return
            yield kind, length, handle
            offset += 12 + length


def _profile(data: bytes) -> bytes:
    """The ICC profile of an ``iCCP`` chunk's data (name, NUL, method 0, zlib stream), at most
    :data:`~ccjax.io.icc.MAX_PROFILE_BYTES` of it (a small chunk can inflate to gigabytes); empty
    when the data are not a readable profile."""
    name_end = data.find(b"\0", 0, 80)
    if name_end < 1 or data[name_end + 1 : name_end + 2] != b"\0":
        return b""
    try:
        return zlib.decompressobj().decompress(data[name_end + 2 :], MAX_PROFILE_BYTES)
    except zlib.error:
        return b""


def read_png(path: str | os.PathLike) -> np.ndarray:
    """Read an 8- or 16-bit PNG (grey, grey + alpha, RGB or RGBA; interlaced or not).

    Arguments:
        path: the file.

    Returns:
        ``uint8`` or ``uint16`` pixels, ``(H, W)`` for grey, else ``(H, W, C)``.

    Raises:
        ValueError: not a PNG file, a chunk whose CRC does not match (every chunk is checked,
            ancillary ones too, which libpng would only warn about), or truncated or corrupt data
            (the decoder's message).
    """
    blob = Path(path).read_bytes()
    if not blob.startswith(PNG_SIGNATURE):
        raise ValueError("not a PNG file (bad signature)")
    chunks = _chunks(blob)
    _header(*next(chunks))
    for _ in chunks:
        pass
    try:
        return np.asarray(imagecodecs.png_decode(blob))
    except imagecodecs.PngError as error:
        raise ValueError(f"corrupt or truncated PNG ({error})") from None


def write_png(
    path: str | os.PathLike, pixels: np.ndarray, *, overwrite: bool = True, srgb: bool = False, run: str | None = None
) -> None:
    """Write ``uint16`` or ``uint8`` ``(H, W, 3)`` as an RGB PNG, atomically
    (:func:`ccjax.io.files.write_file`: readers never see a partial file).

    Arguments:
        path: the file (missing folders are created).
        pixels: the file codes; 16-bit values are stored big-endian, as PNG requires.
        overwrite: replace a file already at ``path`` (else ``FileExistsError``:
            :func:`ccjax.io.outputs.put_in_place`).
        srgb: the codes are sRGB-encoded (:func:`png_bytes`).
        run: the identifier of the run that wrote it (:func:`png_bytes`), or None.

    Raises:
        ValueError: ``pixels`` is not ``uint8``/``uint16`` ``(H, W, 3)`` with at least one pixel.
    """
    write_file(path, png_bytes(pixels, srgb=srgb, run=run), overwrite=overwrite)


RUN_KEYWORD = b"ccjax run"
"""The keyword of the ``tEXt`` chunk holding the identifier of the run that wrote a PNG."""


def png_bytes(pixels: np.ndarray, *, srgb: bool = False, run: str | None = None) -> bytes:
    """The PNG file of ``uint16`` or ``uint8`` ``(H, W, 3)`` codes.

    Arguments:
        pixels: the file codes; 16-bit values are stored big-endian, as PNG requires.
        srgb: the codes are sRGB-encoded: an ``sRGB`` chunk (rendering intent 0, perceptual) goes
            before the image data, so viewers show the colours right and readers (ccjax's own
            included) know the codes are not linear. False: no colour chunk (linear data).
        run: an identifier (printable ASCII) stored in a ``tEXt`` chunk, keyword
            :data:`RUN_KEYWORD`: files written together (an image and its preview) carry the same
            one (:func:`png_run`).

    Returns:
        The file's bytes.

    Raises:
        ValueError: ``pixels`` is not ``uint8``/``uint16`` ``(H, W, 3)`` with at least one pixel, or
            ``run`` is not printable ASCII.
    """
    pixels = np.asarray(pixels)
    if pixels.ndim != 3 or pixels.shape[2] != 3 or pixels.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"pixels: expected uint8/uint16 (H, W, 3), got {pixels.dtype} {pixels.shape}")
    if pixels.size == 0:
        raise ValueError(f"pixels: a PNG needs at least one pixel, got shape {pixels.shape}")
    if run is not None and not (run.isascii() and run.isprintable()):
        raise ValueError(f"run: expected printable ASCII, got {run!r}")
    blob = bytes(imagecodecs.png_encode(np.ascontiguousarray(pixels), level=COMPRESSION_LEVEL))
    at = len(PNG_SIGNATURE) + 25  # right after IHDR, before any PLTE or IDAT (PNG 1.2 §4.2.2.5)
    extra = _chunk(b"sRGB", b"\0") if srgb else b""
    if run is not None:
        extra += _chunk(b"tEXt", RUN_KEYWORD + b"\0" + run.encode("ascii"))
    return blob[:at] + extra + blob[at:]


def png_run(path: str | os.PathLike) -> str | None:
    """The run identifier a PNG carries (:func:`png_bytes`), read from the chunks before its image
    data, or None.

    Arguments:
        path: the file.

    Returns:
        The identifier, or None.
    """
    for kind, length, handle in _leading_chunks(path):
        if kind == b"tEXt" and length <= 200:
            keyword, _, text = handle.read(length).partition(b"\0")
            if keyword == RUN_KEYWORD:
                return text.decode("ascii", "replace")
    return None


def _chunk(kind: bytes, data: bytes) -> bytes:
    """A PNG chunk: length, type, data, CRC of type and data."""
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(data, zlib.crc32(kind)))
