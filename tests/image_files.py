"""Image files for the I/O and command-line tests: an independent PNG encoder and decoder written
from the PNG specification (filters 0-4, plain loops), and a set of files that must be refused."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import tifffile

from ccjax.io import write_png

SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _paeth(a, b, c):
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    return a if pa <= pb and pa <= pc else (b if pb <= pc else c)


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def reference_png(pixels: np.ndarray, filters) -> bytes:
    """PNG bytes of ``(H, W, C)`` uint8/uint16 pixels (C = 1, 3 or 4), row ``y`` filtered with
    ``filters[y % len(filters)]``."""
    height, width, channels = pixels.shape
    depth = 16 if pixels.dtype == np.uint16 else 8
    bpp = channels * depth // 8
    rows = [bytes(pixels[y].astype(">u2" if depth == 16 else np.uint8).tobytes()) for y in range(height)]
    out, previous = bytearray(), bytes(len(rows[0]))
    for y, row in enumerate(rows):
        kind = filters[y % len(filters)]
        out.append(kind)
        for x in range(len(row)):
            a = row[x - bpp] if x >= bpp else 0
            b = previous[x]
            c = previous[x - bpp] if x >= bpp else 0
            predictor = [0, a, b, (a + b) // 2, _paeth(a, b, c)][kind]
            out.append((row[x] - predictor) % 256)
        previous = row
    colour = {1: 0, 3: 2, 4: 6}[channels]
    header = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, 0)
    return SIGNATURE + _chunk(b"IHDR", header) + _chunk(b"IDAT", zlib.compress(bytes(out))) + _chunk(b"IEND", b"")


def reference_decode_rgb(blob: bytes) -> tuple[int, np.ndarray]:
    """``(bit depth, (H, W, 3) pixels)`` of a non-interlaced RGB PNG, undoing filters 0-4 in plain
    loops; 16-bit samples are read big-endian, as the PNG specification says."""
    assert blob[:8] == SIGNATURE
    position, header, idat = 8, None, b""
    while position < len(blob):
        (length,) = struct.unpack(">I", blob[position : position + 4])
        kind, data = blob[position + 4 : position + 8], blob[position + 8 : position + 8 + length]
        header = struct.unpack(">IIBBBBB", data) if kind == b"IHDR" else header
        idat += data if kind == b"IDAT" else b""
        position += 12 + length
    assert header is not None
    width, height, depth, colour, _, _, interlace = header
    assert colour == 2 and interlace == 0, header
    bpp, stride = 3 * depth // 8, 3 * depth // 8 * width
    raw, rows, previous = zlib.decompress(idat), [], bytearray(stride)
    for y in range(height):
        kind, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1 : (y + 1) * (stride + 1)])
        for x in range(stride):
            a = line[x - bpp] if x >= bpp else 0
            b = previous[x]
            c = previous[x - bpp] if x >= bpp else 0
            line[x] = (line[x] + [0, a, b, (a + b) // 2, _paeth(a, b, c)][kind]) % 256
        rows.append(bytes(line))
        previous = line
    pixels = np.frombuffer(b"".join(rows), ">u2" if depth == 16 else np.uint8).reshape(height, width, 3)
    return depth, pixels.astype(np.uint16 if depth == 16 else np.uint8)


def zero_size_png(path) -> None:
    """A PNG whose header declares 0 x 0 pixels (invalid: PNG requires at least one)."""
    header = struct.pack(">IIBBBBB", 0, 0, 16, 2, 0, 0, 0)
    path.write_bytes(SIGNATURE + _chunk(b"IHDR", header) + _chunk(b"IDAT", zlib.compress(b"")) + _chunk(b"IEND", b""))


def bad_files(tmp_path) -> list[tuple[str, object]]:
    """``[(part of the error message, file)]`` of files ``read_image`` must refuse."""
    eight = tmp_path / "eight.png"
    write_png(eight, np.full((4, 4, 3), 100, np.uint8))
    garbage = tmp_path / "garbage.png"
    garbage.write_bytes(b"this is not an image")
    clipped = tmp_path / "clipped.png"
    write_png(clipped, np.full((4, 4, 3), 65535, np.uint16))
    empty = tmp_path / "empty.png"
    zero_size_png(empty)
    truncated = tmp_path / "truncated.png"
    blob = reference_png(np.random.default_rng(0).integers(0, 65535, (16, 16, 3)).astype(np.uint16), [0])
    truncated.write_bytes(blob[: len(blob) // 2])
    grey = tmp_path / "grey.tif"
    tifffile.imwrite(grey, np.ones((4, 4), np.uint16))
    grey_png = tmp_path / "grey16.png"
    grey_png.write_bytes(reference_png(np.ones((4, 4, 1), np.uint16), [0]))
    nan = tmp_path / "nan.tif"
    floats = np.full((4, 4, 3), 0.5, np.float32)
    floats[1, 2, 0] = np.nan
    tifffile.imwrite(nan, floats, photometric="rgb")
    return [
        ("8-bit", eight),
        ("cannot read", garbage),
        ("clipped", clipped),
        ("cannot read", empty),
        ("cannot read", truncated),
        ("greyscale", grey),
        ("greyscale", grey_png),
        ("NaN", nan),
    ]


def textured_image(path, colour=(0.5, 0.4, 0.3)):
    """A small 16-bit linear image of ``colour`` with some darker pixels, written at ``path``."""
    from ccjax.io import writing

    rgb = np.broadcast_to(np.asarray(colour), (6, 6, 3)).copy()
    rgb[::2, ::3] *= 0.5
    writing.write_linear(path, rgb)
    return path


def one_line_error(captured, *needles):
    """A command's stderr is one ``ccjax ...`` line naming every needle, without a traceback
    (notices, which say what a command chose, are not errors: they are left out)."""
    assert "Traceback" not in captured.err
    lines = [line for line in captured.err.strip().splitlines() if ": notice: " not in line]
    assert len(lines) == 1 and lines[0].startswith("ccjax "), captured.err
    for needle in needles:
        assert str(needle) in lines[0], (needle, lines[0])
