"""Writing linear images (16-bit PNG or TIFF), sRGB ones tagged as such, and labelled image sets.

An sRGB file says so, so that viewers show its colours right and readers (ccjax's own included,
:func:`ccjax.io.read_image`) do not take its codes for linear data: a PNG gets an ``sRGB`` chunk,
a TIFF the sRGB ICC profile, a JPEG the profile and EXIF ColorSpace 1. Linear files get no tag.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

import numpy as np
from numpy.typing import ArrayLike

from ccjax.io.files import write_file
from ccjax.io.ground_truth import write_ground_truth
from ccjax.io.icc import srgb_profile
from ccjax.io.jpeg import jpeg_run, save_jpeg
from ccjax.io.png import png_bytes, png_run, write_png

CHUNK_VALUES = 1 << 22
"""Values converted at a time by the writers (float64 working copies of about 32 MB)."""


def row_slices(shape: tuple[int, ...], values: int | None = None) -> list[slice]:
    """Slices of the first axis of an array of ``shape`` holding about ``values`` values each, so
    a 48 MP image is converted in pieces instead of in float64 copies of the whole.

    Arguments:
        shape: the array's shape (at least one axis).
        values: values per piece (default :data:`CHUNK_VALUES`).

    Returns:
        Slices covering ``range(shape[0])`` in order.
    """
    per_row = max(1, int(np.prod(shape[1:], dtype=np.int64)))
    rows = max(1, (CHUNK_VALUES if values is None else values) // per_row)
    return [slice(start, min(start + rows, shape[0])) for start in range(0, shape[0], rows)]


def quantise(rgb: ArrayLike, levels: int = 65535) -> np.ndarray:
    """``rgb`` on the unit scale to integer file codes, clamped to ``[0, 1]`` first (in pieces of
    :func:`row_slices`: the float64 working copy never holds the whole image).

    Arguments:
        rgb: any shape, unit scale (1.0 = saturation).
        levels: the largest code (``uint16`` above 255, else ``uint8``).

    Returns:
        The rounded codes.
    """
    dtype = np.uint16 if levels > 255 else np.uint8
    rgb = np.asarray(rgb)
    if rgb.ndim == 0:
        return np.asarray(np.round(np.clip(np.float64(rgb), 0.0, 1.0) * levels), dtype)
    codes = np.empty(rgb.shape, dtype)
    for rows in row_slices(rgb.shape):
        codes[rows] = np.round(np.clip(np.asarray(rgb[rows], np.float64), 0.0, 1.0) * levels)
    return codes


def write_linear(path: str | os.PathLike, rgb: ArrayLike, *, overwrite: bool = True) -> None:
    """Write a unit-scale linear image ``(H, W, 3)`` as 16-bit PNG or TIFF (by suffix), atomically
    (:func:`write_file`); values clamp to [0, 1].

    Arguments:
        path: ``.png``, ``.tif`` or ``.tiff`` file.
        rgb: ``(H, W, 3)`` unit-scale linear RGB.
        overwrite: replace a file already at ``path`` (else ``FileExistsError``:
            :func:`ccjax.io.outputs.put_in_place`).

    Returns:
        None.

    Raises:
        ValueError: the suffix is not ``.png``, ``.tif`` or ``.tiff``.
    """
    write_codes(path, quantise(rgb), overwrite=overwrite)


JPEG_QUALITY = 95
"""Quality of the JPEG files ccjax writes (libjpeg's 0-100 scale): visually lossless for photographs."""


def write_codes(
    path: str | os.PathLike,
    codes: np.ndarray,
    *,
    overwrite: bool = True,
    srgb: bool = False,
    exif: bytes | None = None,
    run: str | None = None,
) -> None:
    """Write file codes ``(H, W, 3)`` (``uint8`` or ``uint16``) as a PNG or TIFF, or ``uint8`` as a
    JPEG (quality :data:`JPEG_QUALITY`, Pillow), by suffix, atomically (:func:`write_file`; a TIFF
    or JPEG is streamed into its temporary file).

    Arguments:
        path: ``.png``, ``.tif``, ``.tiff``, ``.jpg`` or ``.jpeg`` file.
        codes: ``(H, W, 3)`` ``uint8`` or ``uint16`` (JPEG: ``uint8``).
        overwrite: replace a file already at ``path``.
        srgb: the codes are sRGB-encoded: tag the file so (module docstring). False: linear
            codes, no colour tag.
        exif: an EXIF block for a JPEG (:func:`ccjax.io.jpeg.upright_exif`); PNG and TIFF
            files are written without it.
        run: the identifier of the run that wrote it (:func:`file_run` reads it back), or None.

    Returns:
        None.

    Raises:
        ValueError: another suffix, or 16-bit codes for a JPEG (8 bits per channel).
    """
    write_file(path, encoded_codes(path, codes, srgb=srgb, exif=exif, run=run), overwrite=overwrite)


def encoded_codes(
    path: str | os.PathLike, codes: np.ndarray, *, srgb: bool = False, exif: bytes | None = None, run: str | None = None
) -> bytes | Callable[[BinaryIO], object]:
    """The file :func:`write_codes` writes, not yet written: bytes, or a function that streams it
    into an open binary file (TIFF, JPEG), for writers that put several files in place together
    (:func:`ccjax._cache.atomic_write_files`).

    Arguments:
        path: the file's name (its suffix chooses the format).
        codes, srgb, exif, run: as :func:`write_codes`.

    Returns:
        The bytes, or the streaming function.

    Raises:
        ValueError: as :func:`write_codes`.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".png", ".tif", ".tiff", ".jpg", ".jpeg"):
        raise ValueError(f"output: {path} must end in .png, .tif, .tiff, .jpg or .jpeg")
    if suffix in (".jpg", ".jpeg"):
        if codes.dtype != np.uint8:
            raise ValueError(f"output: {path} is a JPEG, which holds 8 bits per channel; got {codes.dtype} codes")
        return lambda handle: save_jpeg(handle, codes, JPEG_QUALITY, srgb=srgb, exif=exif, run=run)
    if suffix == ".png":
        return png_bytes(codes, srgb=srgb, run=run)
    import tifffile

    # tifffile's ``iccprofile`` writes tag 34675 (:data:`ccjax.io.srgb.ICC_PROFILE_TAG`); the run's
    # identifier is the ImageDescription (tifffile's own shape description is left out).
    icc = srgb_profile() if srgb else None
    description = {} if run is None else {"description": f"{TIFF_RUN_PREFIX}{run}", "metadata": None}
    return lambda handle: tifffile.imwrite(handle, codes, photometric="rgb", iccprofile=icc, **description)


TIFF_RUN_PREFIX = "ccjax run "
"""How a TIFF's ImageDescription names the run that wrote it."""


def file_run(path: str | os.PathLike) -> str | None:
    """The identifier of the run that wrote an image ccjax wrote (PNG ``tEXt``, JPEG EXIF
    ImageUniqueID, TIFF ImageDescription), or None: a corrected image and its preview written
    together carry the same one, so a pair from two runs is seen for what it is.

    Arguments:
        path: a ``.png``, ``.jpg``/``.jpeg`` or ``.tif``/``.tiff`` file.

    Returns:
        The identifier, or None.
    """
    suffix = Path(path).suffix.lower()
    if suffix == ".png":
        return png_run(path)
    if suffix in (".jpg", ".jpeg"):
        return jpeg_run(path)
    import tifffile

    try:
        with tifffile.TiffFile(path) as tiff:
            description = tiff.pages[0].description  # pyright: ignore[reportAttributeAccessIssue]
    except Exception:  # not a TIFF tifffile can open: no identifier
        return None
    return description.removeprefix(TIFF_RUN_PREFIX) if description.startswith(TIFF_RUN_PREFIX) else None


def write_dataset(
    directory: str | os.PathLike, rgb: ArrayLike, illuminants: ArrayLike, *, prefix: str = "image"
) -> Path:
    """Write an image set with its ground truth, as ``ccjax evaluate`` reads it.

    Arguments:
        directory: the folder (created).
        rgb: ``(B, H, W, 3)`` unit-scale images, written as 16-bit PNGs ``<prefix>-0000.png ...``.
        illuminants: ``(B, 3)`` camera RGB of each image's light, written as ``groundtruth.csv``.
        prefix: file name prefix.

    Returns:
        The path of the CSV (header ``image,r,g,b``).
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    rgb = np.asarray(rgb)
    names = [f"{prefix}-{index:04d}.png" for index in range(len(rgb))]
    for name, image in zip(names, rgb, strict=True):
        write_png(directory / name, quantise(image))
    write_ground_truth(directory / "groundtruth.csv", names, illuminants)
    return directory / "groundtruth.csv"
