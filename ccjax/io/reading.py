"""Reading linear camera images (Barnard 1999 §2.7, §4.6): 16-bit PNG, TIFF, camera raw.

:func:`read_image` subtracts the black level and divides by ``saturation - black``: on the unit
scale, **1.0 is the saturation level** (default: the file format's maximum, 65535 for 16-bit; for
raw files LibRaw's white level), so a corrected image written back with
:func:`ccjax.io.write_linear` keeps the file's codes. This is the image counterpart of the
library's scale (docs/concepts.md, "Spectra and the scale": the brightest channel of a perfect
white under the light is 1.0 for synthetic data); an image's white is wherever the exposure put
it, below 1.0.

Clipped pixels (the thesis discards them, §2.7) are those with any channel at or above the
*clip level*: by default :data:`CLIP_FRACTION` = 0.98 of the saturation level (the file
maximum; the field's protocol for linear photographs: a sensor's response flattens, and
demosaicing and noise smear saturation, below the file's last code, so pixels at the maximum
alone miss most clipped ones), or exactly the ``saturation`` value when the caller gives one (the
caller then knows the level).
8-bit files (JPEG always) are refused unless ``decode_srgb`` or ``assume_linear``: they are
almost always gamma-encoded, and estimating on gamma-encoded data is silently wrong; so are files
whose tags declare a gamma-encoded tone curve (:func:`ccjax.io.srgb.declared_encoding`): a PNG's
``sRGB`` chunk or ``gAMA`` other than 1.0, a PNG's ``iCCP`` or a TIFF's ICC profile describing
sRGB (ccjax's own ``--srgb`` outputs carry such tags); a ``gAMA`` of 1.0 or a linear profile
declares linear data.
``decode_srgb`` undoes the sRGB transfer curve (IEC 61966-2-1, colour-science's) of the files that
are sRGB-encoded, and only those: 8-bit files, JPEG, and files whose tags declare an encoding as
above. A 16-bit or float file without such a tag is read as linear with or without it (a folder
may mix JPEGs with linear 16-bit exports), as are raw files. The decoded result is linear in the
light, not camera data (the camera's curves are mixed into sRGB primaries; highlights stay
clipped). A multi-page TIFF is refused rather than read as its first page, and a header claiming
more than ``max_pixels`` pixels (default :data:`MAX_PIXELS`) before any decoding.

Alpha (RGBA PNG, RGB + extra-sample TIFF) is a mask: a pixel whose alpha is below full opacity
(the format's maximum: 255, 65535, or 1.0 for float) is *transparent* and is marked in ``clipped``
too, so no estimator or preprocessing step uses it (partly transparent pixels are excluded as well:
their colour is blended, or premultiplied in associated-alpha TIFFs). :func:`read_mask` reads a
separate mask file (nonzero = usable). :func:`probe_image` checks a file's format, bit depth,
channels and size from its header alone, so a command can validate every input before any work
and then decode each file once.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ccjax import limits
from ccjax.io.jpeg import jpeg_layout, read_jpeg
from ccjax.io.png import png_header, read_png
from ccjax.io.raw import raw_layout, read_raw
from ccjax.io.srgb import declared_encoding, decode_srgb_codes

RAW_SUFFIXES = (".dng", ".cr2", ".cr3", ".nef", ".arw", ".orf", ".rw2", ".raf", ".pef", ".srw", ".raw")
"""The suffixes read as camera raw files (lower case; read through ``rawpy``)."""
JPEG_SUFFIXES = (".jpg", ".jpeg")
IMAGE_SUFFIXES = (".png", ".tif", ".tiff", *JPEG_SUFFIXES, *RAW_SUFFIXES)
"""Every suffix :func:`read_image` reads (lower case): PNG, TIFF, JPEG and the raw formats."""

CLIP_FRACTION = 0.98
"""Default clip level as a fraction of the saturation level (module docstring)."""

MAX_PIXELS = int(limits.PIXELS.value)
"""Default pixel budget (:data:`ccjax.limits.PIXELS`) of :func:`probe_image` and
:func:`read_image` (100 MP): a 48 MP camera image passes, a file whose header claims more is
refused before anything is allocated for it (a 74-byte PNG can claim 100000 x 100000 pixels;
decoding it would need 60 GB)."""


@dataclass(frozen=True)
class LinearImage:
    """A linear camera image on the unit scale (the saturation level is 1.0; module docstring).

    Attributes:
        rgb: ``(H, W, 3)`` float32, black level subtracted, divided by ``saturation - black``.
        clipped: ``(H, W)`` True where a pixel is not usable: any channel reached the clip level
            (default 0.98 of saturation), or the pixel is transparent (every consumer masks with
            ``~clipped``; :func:`ccjax.preprocessing.usable_pixels` adds the zero-channel and dark rules).
        path: where it came from.
        bit_depth: 8 or 16 for integer files, 32/64 for float TIFF, 16 for raw.
        transparent: ``(H, W)`` True where the file's alpha is below full opacity (these pixels
            are also in ``clipped``); None for files without alpha.
        camera_to_xyz: ``(3, 3)`` camera RGB (``rgb``'s unit scale) -> CIE XYZ for the D65
            illuminant, ``xyz = camera_to_xyz @ rgb[y, x]``, from a raw file's own colour matrix
            (:func:`ccjax.io.raw.camera_to_xyz`); None for other files and raw files without one.
            :func:`ccjax.io.raw.camera_to_srgb` turns it into a corrected image's preview matrix.
    """

    rgb: np.ndarray
    clipped: np.ndarray
    path: str = ""
    bit_depth: int = 16
    transparent: np.ndarray | None = None
    camera_to_xyz: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """``(height, width)``."""
        return self.rgb.shape[:2]


_UNSUPPORTED_PHOTOMETRIC = ("SEPARATED", "CIELAB", "ICCLAB", "ITULAB", "LOGL", "LOGLUV")


def _tiff_layout(tif) -> tuple[tuple[int, ...], np.dtype]:
    """Shape (channels last) and sample type of a TIFF's first series, from its tags alone."""
    if len(tif.series) > 1:
        raise ValueError(f"the TIFF holds {len(tif.series)} images (pages); give a file with one image")
    series = tif.series[0]
    photometric = getattr(tif.pages[0].photometric, "name", str(tif.pages[0].photometric))
    if photometric in _UNSUPPORTED_PHOTOMETRIC:
        raise ValueError(f"TIFF colour space {photometric} is not supported; expected RGB")
    shape = tuple(series.shape)
    if len(shape) == 3 and shape[0] in (3, 4) and shape[2] not in (3, 4):
        shape = (*shape[1:], shape[0])  # planar (separate) configuration
    return shape, np.dtype(series.dtype)


def _read_pixels(path: Path) -> np.ndarray:
    suffix = path.suffix.lower()
    if suffix == ".png":
        return read_png(path)
    if suffix in (".tif", ".tiff"):
        import tifffile

        with tifffile.TiffFile(path) as tif:
            _tiff_layout(tif)
            pixels = tif.asarray()  # what tifffile.imread gives (compressed files through imagecodecs)
        if pixels.ndim == 3 and pixels.shape[0] in (3, 4) and pixels.shape[2] not in (3, 4):
            pixels = np.moveaxis(pixels, 0, -1)  # planar (separate) configuration
        return pixels
    if suffix in JPEG_SUFFIXES:
        return read_jpeg(path)
    raise ValueError(f"unsupported file type {suffix!r}; expected one of {', '.join(IMAGE_SUFFIXES)}")


def _check_layout(
    path: Path, shape: tuple[int, ...], dtype: np.dtype, assume_linear: bool, decode_srgb: bool = False
) -> int:
    """Refuse what :func:`read_image` refuses before looking at pixel values; return the bit depth."""
    if len(shape) == 2 or (len(shape) == 3 and shape[2] < 3):
        raise ValueError(f"image: {path} is a greyscale image; colour constancy needs RGB")
    if len(shape) != 3 or shape[2] not in (3, 4):
        raise ValueError(f"image: {path} has shape {shape}; expected (height, width, 3)")
    if shape[0] * shape[1] == 0:
        raise ValueError(f"image: {path} has no pixels (size {shape[0]}x{shape[1]})")
    if dtype == np.uint8 and not (assume_linear or decode_srgb):
        raise ValueError(
            f"image: {path} is 8-bit; 8-bit files are almost always gamma-encoded (sRGB), not linear "
            "camera data. Use a 16-bit linear file (or raw); pass --decode-srgb to decode it from sRGB "
            "(JPEG and most 8-bit files), or --assume-linear if it really is linear"
        )
    if not (np.issubdtype(dtype, np.integer) or np.issubdtype(dtype, np.floating)):
        raise ValueError(f"image: {path} has unsupported sample type {dtype}")
    return 8 * dtype.itemsize


def _header_layout(path: Path, raw_full_size: bool = False) -> tuple[tuple[int, ...], np.dtype]:
    """Shape (channels last) and sample type of a PNG, TIFF or raw file from its header alone
    (a raw file's as :func:`read_image` develops it with ``raw_full_size``)."""
    suffix = path.suffix.lower()
    if suffix == ".png":
        header = png_header(path)
        dtype = np.dtype(np.uint16 if header.bit_depth == 16 else np.uint8)
        return (header.height, header.width) + ((header.channels,) if header.channels > 1 else ()), dtype
    if suffix in (".tif", ".tiff"):
        import tifffile

        with tifffile.TiffFile(path) as tif:
            return _tiff_layout(tif)
    if suffix in JPEG_SUFFIXES:
        return jpeg_layout(path)
    if suffix in RAW_SUFFIXES:
        return raw_layout(path, raw_full_size)
    raise ValueError(f"unsupported file type {suffix!r}; expected one of {', '.join(IMAGE_SUFFIXES)}")


def _check_file(path: Path, kind: str) -> None:
    """Refuse a path that is not a regular file (missing, a folder, a device such as /dev/zero)."""
    if not path.exists():
        if path.is_symlink():
            raise ValueError(f"{kind}: {path} is a symbolic link to nothing (dangling, or a loop)")
        raise FileNotFoundError(f"{kind}: no such file: {path}")
    if not path.is_file():
        what = "a folder" if path.is_dir() else "not a regular file (a FIFO, socket or device)"
        raise ValueError(f"{kind}: {path} is {what}")


def check_pixels(path: str | os.PathLike, height: int, width: int, max_pixels: int | None) -> None:
    """Refuse an image larger than the pixel budget, from its header's size.

    Arguments:
        path: the file (for the message).
        height, width: the size its header gives.
        max_pixels: the budget (None: no limit).

    Returns:
        None.

    Raises:
        ValueError: ``height * width > max_pixels``; the message names the file and ``--max-pixels``.
    """
    if max_pixels is not None and height * width > max_pixels:
        raise ValueError(
            f"image: {path} claims {width}x{height} pixels ({height * width / 1e6:.1f} MP), more than the pixel "
            f"budget of {max_pixels / 1e6:g} MP (raise it with --max-pixels / max_pixels if the image is real)"
        )


@dataclass(frozen=True)
class ImageInfo:
    """What :func:`probe_image` learns from a file's header.

    Attributes:
        path: the file.
        height, width: the size in pixels (raw files: upright, half the sensor's visible size,
            as :func:`read_image` develops them one pixel per Bayer quad, or the full size with
            ``raw_full_size``).
        channels: 3 (RGB) or 4 (RGB + alpha).
        bit_depth: bits per sample as :func:`read_image` will see them.
        encoding: why the codes are sRGB-encoded (``"8-bit"``, ``"JPEG"``, or what the file's
            tags declare, :func:`ccjax.io.srgb.declared_encoding`), or None: linear data, which
            ``decode_srgb`` leaves as they are.
    """

    path: str
    height: int
    width: int
    channels: int
    bit_depth: int
    encoding: str | None = None


def probe_image(
    path: str | os.PathLike,
    *,
    black_level: float | int = 0.0,
    saturation: float | int | None = None,
    assume_linear: bool = False,
    max_pixels: int | None = MAX_PIXELS,
    decode_srgb: bool = False,
    raw_full_size: bool = False,
) -> ImageInfo:
    """Check that :func:`read_image` can read a file, from its header alone (no pixel decoding).

    Checks that it is a regular file, its type, PNG signature and header CRC, TIFF tags (colour
    space, sample type, layout, one image per file), channels, bit depth, and the size against
    the pixel budget; the pixel-value checks (NaN, every pixel clipped, corrupt compressed data)
    need the pixels and remain with :func:`read_image`.

    Arguments:
        path: the file.
        black_level, saturation, assume_linear, decode_srgb, max_pixels, raw_full_size: as :func:`read_image`
            (so a command can pass the same options to both); the saturation level must lie above the
            black level.

    Returns:
        An :class:`ImageInfo`.

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: what :func:`read_image` would refuse from the header (a size over
            ``max_pixels`` too); the message names the file.
    """
    path = Path(path)
    _check_file(path, "image")
    suffix = path.suffix.lower()
    try:
        shape, dtype = _header_layout(path, raw_full_size)
    except ValueError as error:
        raise ValueError(f"image: cannot read {path}: {error}") from None
    except Exception as error:  # a decoder's own exception types: report them the same way
        raise ValueError(f"image: cannot read {path}: {type(error).__name__}: {error}") from None
    bit_depth = _check_layout(path, shape, dtype, assume_linear, decode_srgb)
    check_pixels(path, shape[0], shape[1], max_pixels)
    try:
        encoding = declared_encoding(path)
    except Exception as error:  # a decoder's own exception types: report them as above
        raise ValueError(f"image: cannot read {path}: {type(error).__name__}: {error}") from None
    if encoding is not None and not (assume_linear or decode_srgb):
        raise ValueError(
            f"image: {path} is tagged {encoding}: its codes are gamma-encoded, not linear camera data. Use a "
            "linear file (or raw), pass --decode-srgb (decode_srgb) to undo the sRGB curve, or --assume-linear "
            "(assume_linear) if it really is linear"
        )
    if encoding is None:  # JPEG and 8-bit files are sRGB-encoded without saying so
        encoding = "JPEG" if suffix in JPEG_SUFFIXES else "8-bit" if dtype == np.uint8 else None
    if suffix in RAW_SUFFIXES:
        black_level, full_scale = 0.0, 65535.0  # LibRaw's scale (see read_image)
    else:
        full_scale = float(np.iinfo(dtype).max) if np.issubdtype(dtype, np.integer) else 1.0
    level = float(saturation if saturation is not None else full_scale)
    if not level > black_level:
        raise ValueError(f"saturation: {level} must be above the black level {black_level}")
    return ImageInfo(str(path), shape[0], shape[1], shape[-1], bit_depth, encoding)


def read_image(
    path: str | os.PathLike,
    *,
    black_level: float | int = 0.0,
    saturation: float | int | None = None,
    assume_linear: bool = False,
    max_pixels: int | None = MAX_PIXELS,
    decode_srgb: bool = False,
    raw_full_size: bool = False,
) -> LinearImage:
    """Read a linear image (16-bit PNG, TIFF, or camera raw with the ``raw`` extra; with
    ``decode_srgb`` also sRGB-encoded PNG, TIFF and JPEG files, decoded to linear).

    Arguments:
        path: the file.
        black_level: value of a black pixel in file units (subtracted). Raw files: LibRaw applies
            the camera's own black and white levels.
        saturation: file value at which the sensor saturates, 1.0 on the unit scale (default:
            the format's maximum, 65535 for 16-bit, 255 for 8-bit, 1.0 for float TIFF, LibRaw's
            white level for raw). Given, pixels with any channel at or above it are clipped;
            by default those with any channel at or above :data:`CLIP_FRACTION` (0.98) of it.
        assume_linear: accept 8-bit and gamma-tagged files as linear data (else they are refused).
        max_pixels: the pixel budget: a file whose header claims more pixels is refused before
            its pixels are decoded (default :data:`MAX_PIXELS`, 100 MP; None: no limit).
        decode_srgb: decode sRGB-encoded files: 8-bit files, JPEG, and files whose tags declare
            a gamma-encoded tone curve (an ``sRGB`` or non-1 ``gAMA`` PNG chunk, an sRGB ICC
            profile: :attr:`ImageInfo.encoding`) have their codes, divided by the format's
            maximum, decoded with the sRGB curve (module docstring); clipping is judged on the
            codes as without it. A 16-bit or float file without such a tag, and a raw file, is
            read as linear all the same.
        raw_full_size: develop a raw file at the sensor's full size (demosaiced; for writing a
            corrected image at the camera's resolution) instead of the default one pixel per
            Bayer quad, whose channels are all measured, none interpolated: the unmixed pixels the
            thesis' estimators assume, so keep the default for estimation. Raw files are turned
            upright by their orientation at either size (:mod:`ccjax.io.raw`).

    Returns:
        A :class:`LinearImage`.

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: unreadable, not RGB, empty, over the pixel budget, 8-bit or tagged as
            gamma-encoded without ``assume_linear`` or ``decode_srgb``, or every pixel clipped;
            the message names the file.
    """
    path = Path(path)
    # The header first: nothing is decoded (or allocated) for a file it refuses.
    info = probe_image(
        path,
        black_level=black_level,
        saturation=saturation,
        assume_linear=assume_linear,
        max_pixels=max_pixels,
        decode_srgb=decode_srgb,
        raw_full_size=raw_full_size,
    )
    default_saturation, camera_to_xyz = None, None
    try:
        if path.suffix.lower() in RAW_SUFFIXES:
            # LibRaw has subtracted the black level and scaled the white level to 65535 (give or
            # take its rounding: a saturated pixel can come out as 65534, well above the clip level).
            (pixels, camera_to_xyz), black_level, default_saturation = read_raw(path, raw_full_size), 0.0, 65535.0
        else:
            pixels = _read_pixels(path)
    except ValueError as error:
        raise ValueError(f"image: cannot read {path}: {error}") from None
    except Exception as error:  # a decoder's own exception types: report them the same way
        raise ValueError(f"image: cannot read {path}: {type(error).__name__}: {error}") from None
    bit_depth = _check_layout(path, pixels.shape, pixels.dtype, assume_linear, decode_srgb)
    full_scale = float(np.iinfo(pixels.dtype).max) if np.issubdtype(pixels.dtype, np.integer) else 1.0
    transparent = pixels[..., 3] < pixels.dtype.type(full_scale) if pixels.shape[2] == 4 else None
    pixels = pixels[..., :3]
    level = float(saturation if saturation is not None else default_saturation or full_scale)
    if not level > black_level:
        raise ValueError(f"saturation: {level} must be above the black level {black_level}")
    if np.issubdtype(pixels.dtype, np.floating) and not np.all(np.isfinite(pixels)):
        raise ValueError(f"image: {path} contains NaN or infinite values")
    clip_level = level * (CLIP_FRACTION if saturation is None else 1.0)
    # On the file's own codes, channel by channel: (H, W) booleans only (48-MP images). Integer
    # codes compare with the smallest integer code at or above the level (same pixels, and no
    # conversion of every code to float64 for the comparison).
    integer = np.issubdtype(pixels.dtype, np.integer)
    threshold = pixels.dtype.type(min(math.ceil(clip_level), full_scale)) if integer else clip_level
    clipped = pixels[..., 0] >= threshold
    clipped |= pixels[..., 1] >= threshold
    clipped |= pixels[..., 2] >= threshold
    if integer and math.ceil(clip_level) > full_scale:
        clipped[:] = False  # a level above the format's maximum: no code reaches it
    if transparent is not None:
        if np.all(transparent):
            raise ValueError(f"image: every pixel of {path} is transparent (alpha below full opacity)")
        clipped |= transparent
    if np.all(clipped):
        raise ValueError(
            f"image: every pixel of {path} is clipped (a channel at or above the clip level {clip_level:g}"
            + (", or transparent)" if transparent is not None else ")")
        )
    # One float32 copy, scaled in place: the file's codes and this copy are the only full-size arrays.
    if decode_srgb and info.encoding is not None:
        # Decoded on the format's scale (sRGB codes run from 0 to the maximum), before the levels.
        rgb = decode_srgb_codes(pixels, full_scale)
    else:
        rgb = pixels.astype(np.float32)
    del pixels
    if black_level:
        rgb -= np.float32(black_level)
    np.maximum(rgb, 0.0, out=rgb)
    rgb /= np.float32(level - black_level)
    return LinearImage(rgb, clipped, str(path), bit_depth, transparent=transparent, camera_to_xyz=camera_to_xyz)


MASK_SUFFIXES = (".png", ".tif", ".tiff")


def read_mask(path: str | os.PathLike, shape: tuple[int, ...]) -> np.ndarray:
    """Read a pixel mask file: which pixels of an image an estimator may use.

    For data sets that ship masks (e.g. one excluding the colour checker that gave the ground
    truth). A pixel is usable where the mask is nonzero and excluded where it is zero: in an RGB
    mask, excluded where every colour channel is zero (black); an alpha channel is ignored.

    Arguments:
        path: an 8- or 16-bit PNG or TIFF (1-bit and float TIFF too), greyscale or RGB, with or
            without alpha.
        shape: the image's ``(height, width)`` (e.g. ``LinearImage.shape``); extra trailing
            entries (``(H, W, 3)``) are ignored.

    Returns:
        ``(H, W)`` bool, True where usable (pass it as ``mask=`` to
        :func:`ccjax.preprocessing.prepare`).

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: unreadable, not PNG/TIFF, not a regular file, or its size differs from
            ``shape`` (checked from the header, before decoding); the message names the file.
    """
    path = Path(path)
    _check_file(path, "mask")
    if path.suffix.lower() not in MASK_SUFFIXES:
        raise ValueError(f"mask: {path}: unsupported file type {path.suffix!r}; expected .png, .tif or .tiff")
    want = tuple(int(n) for n in shape[:2])
    try:
        size = _header_layout(path)[0][:2]
    except ValueError as error:
        raise ValueError(f"mask: cannot read {path}: {error}") from None
    except Exception as error:  # a decoder's own exception types: report them the same way
        raise ValueError(f"mask: cannot read {path}: {type(error).__name__}: {error}") from None
    # The size from the header first: a mask that cannot fit its image is never decoded.
    if tuple(size) != want:
        raise ValueError(
            f"mask: {path} is {size[1]}x{size[0]} pixels (width x height), but its image is {want[1]}x{want[0]}"
        )
    try:
        pixels = _read_pixels(path)
    except ValueError as error:
        raise ValueError(f"mask: cannot read {path}: {error}") from None
    except Exception as error:  # a decoder's own exception types: report them the same way
        raise ValueError(f"mask: cannot read {path}: {type(error).__name__}: {error}") from None
    if pixels.ndim == 3 and pixels.shape[2] in (2, 4):
        pixels = pixels[..., : pixels.shape[2] - 1]  # drop alpha
    if pixels.ndim not in (2, 3) or (pixels.ndim == 3 and pixels.shape[2] not in (1, 3)):
        raise ValueError(f"mask: {path} has shape {pixels.shape}; expected greyscale (H, W) or RGB (H, W, 3)")
    usable = pixels != 0
    return usable.any(axis=-1) if usable.ndim == 3 else usable


def list_images(paths: Iterable[str | os.PathLike]) -> list[Path]:
    """Expand files and folders (a folder gives its entries named as images, sorted, not
    recursive; entries that are not regular files are kept, for the reader to refuse by name).

    Arguments:
        paths: files and folders.

    Returns:
        The files, folders expanded in place.
    """
    found: list[Path] = []
    for item in map(Path, paths):
        if item.is_dir():
            # Every entry named as an image, regular file or not: a dangling or looping link, a
            # FIFO or a folder named ``*.png`` is the reader's to refuse (a failure the run
            # reports), never dropped without a word.
            found += sorted(p for p in item.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        else:
            found.append(item)
    return found
