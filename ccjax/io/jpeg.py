"""JPEG files: the header's layout and the whole, upright pixels, or a clear error; writing
them with their colour space and their input's EXIF.

Decoded by Pillow (libjpeg), with its own pixel limit lifted: the caller's budget
(:data:`ccjax.limits.PIXELS`, ``--max-pixels``) is checked from the header first, and Pillow's
fixed 179 MP limit must not override it. A file whose data ends early is an error (libjpeg
would fill the missing rows with grey and call the image read). The EXIF orientation is applied
(a camera held upright writes its rows sideways and says so in the tag), so a corrected image
comes out as the photographer saw it.

Written by Pillow too, which embeds an ICC profile and EXIF (libjpeg through imagecodecs writes
neither): an sRGB JPEG carries the sRGB profile and EXIF ColorSpace 1, and the input's EXIF
(:func:`upright_exif`: camera, times, exposure, GPS) with its orientation reset to 1, since the
pixels written are already upright.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

import numpy as np

from ccjax.io.icc import srgb_profile

ORIENTATION_TAG = 0x0112
"""EXIF's orientation tag: 1 upright; 2-8 mirrored and/or rotated (5-8 swap width and height)."""
EXIF_IFD, GPS_IFD = 0x8769, 0x8825
"""The EXIF and GPS sub-directories' tags in the first image directory."""
CARRIED_TAGS = (0x010E, 0x010F, 0x0110, 0x0132, 0x013B, 0x8298)
"""First-directory tags carried to an output: ImageDescription, Make, Model, DateTime, Artist,
Copyright. The others describe the input's own layout (strips, sizes, resolution of a TIFF)."""
DROPPED_EXIF_TAGS = (0xA002, 0xA003, 0xA005)
"""EXIF-directory tags not carried: PixelX/YDimension (the output's own size is written) and the
interoperability directory's offset (it points into the input file)."""
MAKER_NOTE, COLOR_SPACE = 0x927C, 0xA001
EXIF_FORMATS = ("JPEG", "MPO", "TIFF")
"""Pillow's formats whose EXIF :func:`upright_exif` reads from the header (TIFF covers DNG and
the TIFF-based raw files Pillow opens; a PNG's ``eXIf`` chunk may follow the image data, and
Pillow would decode every pixel to find it)."""
MAX_EXIF_BYTES = 65000
"""The most EXIF bytes :func:`upright_exif` gives: a JPEG's APP1 segment holds 65533 (with
``Exif\\0\\0``), less room for the tags :func:`save_jpeg` adds. A maker note that would
overflow it is dropped."""


@contextlib.contextmanager
def _pillow(path: Path) -> Iterator:
    """The file opened by Pillow (lazily: the header), with Pillow's own pixel limit lifted for this open."""
    from PIL import Image

    limit, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
    try:
        image = Image.open(path)
    finally:
        Image.MAX_IMAGE_PIXELS = limit
    with image:
        yield image


@contextlib.contextmanager
def _opened(path: Path) -> Iterator:
    """The file opened by Pillow as a JPEG, with Pillow's own pixel limit lifted for this open.
    A multi-picture JPEG (``MPO``: cameras append previews so) gives its first, primary image."""
    with _pillow(path) as image:
        if image.format not in ("JPEG", "MPO"):
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


def upright_exif(path: str | os.PathLike) -> bytes | None:
    """An input's EXIF, ready for a JPEG output of its upright pixels: the camera and image tags
    of :data:`CARRIED_TAGS`, the EXIF directory (DateTimeOriginal, exposure, lens; less
    :data:`DROPPED_EXIF_TAGS`) and the GPS directory, with Orientation 1 (:func:`read_jpeg`
    applied the input's orientation to the pixels; the tag must not rotate them again).

    Arguments:
        path: the input: a JPEG, or a TIFF or DNG where Pillow reads its EXIF.

    Returns:
        The EXIF block (``Exif\\0\\0`` and a TIFF structure, as :func:`save_jpeg` takes it), or None
        when the file has none Pillow can read.
    """
    from PIL import Image

    try:
        try:
            with _pillow(Path(path)) as image:
                if image.format not in EXIF_FORMATS:
                    return None
                source = image.getexif()
                tags = {tag: source[tag] for tag in CARRIED_TAGS if tag in source}
                exif = {tag: value for tag, value in source.get_ifd(EXIF_IFD).items() if tag not in DROPPED_EXIF_TAGS}
                gps = dict(source.get_ifd(GPS_IFD))
        except Exception:
            # Pillow opens no raw sensor data (a DNG's CFA image): its first directory's tags,
            # read by tifffile, still name the camera and the time.
            tags, exif, gps = _tiff_tags(Path(path)), {}, {}
        if not (tags or exif or gps):
            return None
        out = Image.Exif()
        out.update(tags)
        out[ORIENTATION_TAG] = 1
        if gps:
            out[GPS_IFD] = gps
        if exif:
            out[EXIF_IFD] = exif
        blob = out.tobytes()
        if len(blob) > MAX_EXIF_BYTES and exif.pop(MAKER_NOTE, None) is not None:
            out[EXIF_IFD] = exif
            blob = out.tobytes()
    except Exception:  # metadata is carried at best: a file Pillow cannot parse has none to give
        return None
    return blob if len(blob) <= MAX_EXIF_BYTES else None


def _tiff_tags(path: Path) -> dict:
    """The :data:`CARRIED_TAGS` of a TIFF-based file's first directory (tifffile), text only."""
    import tifffile

    with tifffile.TiffFile(path) as tiff:
        page_tags = tiff.pages[0].tags  # pyright: ignore[reportAttributeAccessIssue]
        return {
            tag: page_tags[tag].value
            for tag in CARRIED_TAGS
            if tag in page_tags and isinstance(page_tags[tag].value, str)
        }


IMAGE_UNIQUE_ID = 0xA420
"""EXIF's ImageUniqueID (in the EXIF directory): ccjax stores the identifier of the run that wrote
a JPEG there, shared with the files written with it (its preview)."""


def save_jpeg(
    handle: BinaryIO,
    codes: np.ndarray,
    quality: int,
    *,
    srgb: bool = False,
    exif: bytes | None = None,
    run: str | None = None,
) -> None:
    """Encode ``uint8`` RGB codes as a JPEG (Pillow, libjpeg) into an open file.

    Arguments:
        handle: a binary file open for writing.
        codes: ``(H, W, 3)`` ``uint8``.
        quality: libjpeg's 0-100 quality.
        srgb: the codes are sRGB: embed the sRGB ICC profile (:func:`ccjax.io.icc.srgb_profile`)
            and set EXIF ColorSpace to 1 (sRGB). False: neither, and no ColorSpace carried.
        exif: an EXIF block to write (:func:`upright_exif`); its PixelX/YDimension are set to
            the codes' size.
        run: the identifier of the run that wrote it, as EXIF ImageUniqueID (:func:`jpeg_run`).

    Returns:
        None.
    """
    from PIL import Image

    tags = Image.Exif()
    if exif:
        tags.load(exif)
    if exif or srgb or run is not None:
        directory = dict(tags.get_ifd(EXIF_IFD))
        directory.pop(COLOR_SPACE, None)
        directory.pop(IMAGE_UNIQUE_ID, None)  # the input's own is not this file's
        if srgb:
            directory[COLOR_SPACE] = 1
        if run is not None:
            directory[IMAGE_UNIQUE_ID] = run
        directory[0xA002], directory[0xA003] = int(codes.shape[1]), int(codes.shape[0])
        tags[EXIF_IFD] = directory
    image = Image.fromarray(np.ascontiguousarray(codes))
    options = {"icc_profile": srgb_profile()} if srgb else {}
    image.save(handle, "JPEG", quality=quality, exif=tags.tobytes() if len(tags) else b"", **options)


def jpeg_run(path: str | os.PathLike) -> str | None:
    """The run identifier a JPEG written by ccjax carries (EXIF ImageUniqueID), or None.

    Arguments:
        path: the file.

    Returns:
        The identifier, or None.
    """
    try:
        with _opened(Path(path)) as image:
            value = image.getexif().get_ifd(EXIF_IFD).get(IMAGE_UNIQUE_ID)
    except Exception:  # not a JPEG Pillow can open: no identifier
        return None
    return value if isinstance(value, str) else None


__all__ = [
    "IMAGE_UNIQUE_ID",
    "ORIENTATION_TAG",
    "jpeg_layout",
    "jpeg_run",
    "orient",
    "read_jpeg",
    "save_jpeg",
    "upright_exif",
]
