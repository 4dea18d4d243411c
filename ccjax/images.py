"""Real images: read linear camera data, preprocess as the thesis did, estimate, correct, write.

Pipeline (Barnard 1999 §4.6; spec ch02-04 §2.7, §7.3, §7.4):

1. :func:`read_image` reads a *linear* image — 16-bit PNG, TIFF (8/16-bit, float) or, with the
   ``raw`` extra, a camera raw file through rawpy — subtracts the black level, divides by
   ``saturation - black`` (so the sensor's full well is 1.0) and marks clipped pixels (any channel
   at or above the saturation level). 8-bit files are refused unless ``assume_linear``: they are
   almost always gamma-encoded, and estimating on gamma-encoded data is silently wrong.
2. :func:`surfaces` turns the image into the estimator input ``(rgb (N, 3), mask (N,))``: drop
   clipped pixels (the thesis discards them, §2.7) and too-dark pixels (R+G+B below ``dark`` times
   the brightest usable pixel's; spec A9), then one of the preprocessing methods of Table 4.6
   (:data:`TABLE_4_6`): block averaging (default 5x5, "roughly optimal", §4.6), block averaging +
   RGB clustering, block averaging + convex-hull reduction, or region-growing segmentation.
   Image-only estimators (``input_kind == "image"``, e.g. grey edge) get the image and the
   unclipped-pixel mask instead.
3. :func:`correct` maps the image to the canonical light by the diagonal map ``w_C / e`` (§2.5),
   or a sharpened diagonal map ``T^-1 diag(T w_C / T e) T``; :func:`write_linear` writes it as a
   16-bit PNG/TIFF and :func:`write_preview` an 8-bit sRGB preview.

Ground-truth files (:func:`read_ground_truth`) are CSV with the header ``image,r,g,b``: ``image``
is the file name relative to the image folder (its stem also matches), ``r,g,b`` the camera RGB of
the light (any scale; only its direction is used).

Fitted models and worlds are cached on disk (DESIGN.md §2): :func:`cached_world`,
:func:`cached_fit`; directory ``$CCJAX_CACHE``, else the platform cache directory.
"""

from __future__ import annotations

import csv
import hashlib
import os
import pickle
import re
import struct
import sys
import tempfile
import zlib
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ccjax.estimators.base import Estimate, Estimator

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
RAW_SUFFIXES = (".dng", ".cr2", ".cr3", ".nef", ".arw", ".orf", ".rw2", ".raf", ".pef", ".srw", ".raw")
IMAGE_SUFFIXES = (".png", ".tif", ".tiff") + RAW_SUFFIXES
DEFAULT_PREPROCESSING = "ave5"
DEFAULT_DARK = 0.02


# ---------------------------------------------------------------------------------------------
# PNG (16-bit RGB is not supported by Pillow, which imageio uses: it silently reduces to 8 bits)


def _png_chunks(blob: bytes):
    if blob[:8] != PNG_SIGNATURE:
        raise ValueError("not a PNG file (bad signature)")
    position = 8
    while position + 8 <= len(blob):
        length, kind = struct.unpack(">I4s", blob[position : position + 8])
        data = blob[position + 8 : position + 8 + length]
        if len(data) != length:
            raise ValueError("truncated PNG chunk")
        yield kind, data
        position += 12 + length
        if kind == b"IEND":
            return
    raise ValueError("truncated PNG (no IEND chunk)")


def _unfilter(filtered: np.ndarray, types: np.ndarray, bpp: int) -> np.ndarray:
    """Undo PNG row filters. ``filtered`` is ``(H, W, bpp)`` uint8, ``types`` ``(H,)``.

    Sub/Average/Paeth need the reconstructed left neighbour, Up/Average/Paeth the row above, so
    pixel (i, j) depends only on anti-diagonals i + j - 1 and i + j - 2. The image is skewed so
    that each anti-diagonal is one contiguous row and swept in H + W - 1 vectorised steps.
    """
    if not np.any(types):
        return filtered
    if np.any(types > 4):
        raise ValueError("PNG row with an unknown filter type")
    height, width, _ = filtered.shape
    rows = np.arange(height)
    steps = height + width - 1
    column = np.arange(steps)[:, None] - rows[None, :]  # (steps, H): column j of row i on diagonal t
    inside = (column >= 0) & (column < width)
    skewed = np.where(inside[..., None], filtered[rows[None, :], np.clip(column, 0, width - 1)], 0).astype(np.int16)
    recon = np.zeros((steps + 2, height + 1, bpp), np.int16)  # two zero diagonals and a zero row -1
    kind = types[:, None].astype(np.int16)
    present = set(np.unique(types).tolist())
    for t in range(steps):
        a = recon[t + 1, 1:]  # left: (i, j-1) on diagonal t-1
        b = recon[t + 1, :-1]  # above: (i-1, j) on diagonal t-1
        c = recon[t, :-1]  # above-left: (i-1, j-1) on diagonal t-2
        predictor = np.zeros_like(a)
        if 1 in present:
            predictor = np.where(kind == 1, a, predictor)
        if 2 in present:
            predictor = np.where(kind == 2, b, predictor)
        if 3 in present:
            predictor = np.where(kind == 3, (a + b) >> 1, predictor)
        if 4 in present:
            p = a + b - c
            pa, pb, pc = np.abs(p - a), np.abs(p - b), np.abs(p - c)
            paeth = np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))
            predictor = np.where(kind == 4, paeth, predictor)
        recon[t + 2, 1:] = np.where(inside[t][:, None], (skewed[t] + predictor) & 0xFF, 0)
    ii, jj = np.meshgrid(rows, np.arange(width), indexing="ij")
    return recon[ii + jj + 2, ii + 1].astype(np.uint8)


def read_png(path: str | os.PathLike) -> np.ndarray:
    """Read a non-interlaced 8- or 16-bit grey/RGB(A) PNG into ``uint8``/``uint16`` ``(H, W, C)``."""
    blob = Path(path).read_bytes()
    header, idat = None, []
    for kind, data in _png_chunks(blob):
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", data)
        elif kind == b"IDAT":
            idat.append(data)
    if header is None:
        raise ValueError("PNG without IHDR chunk")
    width, height, depth, colour, _, _, interlace = header
    channels = {0: 1, 2: 3, 4: 2, 6: 4}.get(colour)
    if channels is None or depth not in (8, 16):
        raise ValueError(f"unsupported PNG type (colour type {colour}, {depth}-bit); linear data needs 16-bit RGB")
    if interlace:
        raise ValueError("interlaced PNG is not supported; save it without interlacing")
    if width == 0 or height == 0:
        return np.zeros((height, width, channels), np.uint16 if depth == 16 else np.uint8)
    bpp = channels * depth // 8
    try:
        raw = zlib.decompress(b"".join(idat))
    except zlib.error as error:
        raise ValueError(f"corrupt PNG data ({error})") from None
    if len(raw) < height * (1 + width * bpp):
        raise ValueError("truncated PNG image data")
    rows = np.frombuffer(raw, np.uint8, count=height * (1 + width * bpp)).reshape(height, 1 + width * bpp)
    pixels = _unfilter(rows[:, 1:].reshape(height, width, bpp), rows[:, 0], bpp)
    if depth == 16:
        return pixels.reshape(height, width * bpp).view(">u2").astype(np.uint16).reshape(height, width, channels)
    return pixels.reshape(height, width, channels)


def write_png(path: str | os.PathLike, pixels: np.ndarray) -> None:
    """Write ``uint16`` or ``uint8`` ``(H, W, 3)`` as an RGB PNG (no filtering, zlib level 6)."""
    pixels = np.asarray(pixels)
    if pixels.ndim != 3 or pixels.shape[2] != 3 or pixels.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"pixels: expected uint8/uint16 (H, W, 3), got {pixels.dtype} {pixels.shape}")
    height, width, _ = pixels.shape
    depth = 16 if pixels.dtype == np.uint16 else 8
    body = pixels.astype(">u2" if depth == 16 else np.uint8).reshape(height, -1).view(np.uint8)
    rows = np.concatenate([np.zeros((height, 1), np.uint8), body], axis=1)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, depth, 2, 0, 0, 0)
    blob = PNG_SIGNATURE + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(rows.tobytes(), 6)) + chunk(b"IEND", b"")
    _atomic_write(Path(path), blob)


def _atomic_write(path: Path, blob: bytes) -> None:
    descriptor, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(descriptor, "wb") as handle:
            handle.write(blob)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temporary, 0o666 & ~umask)  # mkstemp's 0600 is for the temporary name only
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


# ---------------------------------------------------------------------------------------------
# Reading linear images


@dataclass(frozen=True)
class LinearImage:
    """A linear camera image on the unit scale (the saturation level is 1.0).

    Attributes:
        rgb: ``(H, W, 3)`` float32, black level subtracted, divided by ``saturation - black``.
        clipped: ``(H, W)`` True where any channel reached the saturation level.
        path: where it came from.
        bit_depth: 8 or 16 for integer files, 32/64 for float TIFF, 16 for raw.
    """

    rgb: np.ndarray
    clipped: np.ndarray
    path: str = ""
    bit_depth: int = 16

    @property
    def shape(self) -> tuple[int, int]:
        return self.rgb.shape[:2]


_RAW_CLIP = 0.999  # LibRaw's scaled white level can round down by a code or two


def _read_raw(path: Path) -> tuple[np.ndarray, float, float]:
    try:
        import rawpy
    except ImportError:
        raise ValueError(
            f"image: {path} is a camera raw file; install the raw extra (pip install 'ccjax[raw]')"
        ) from None
    with rawpy.imread(str(path)) as raw:
        # Camera-native RGB, no white balance, no colour matrix, linear, one pixel per Bayer quad
        # (half_size: no demosaicing, so pixels are not interpolated across edges).
        pixels = raw.postprocess(
            output_color=rawpy.ColorSpace.raw,
            gamma=(1, 1),
            no_auto_bright=True,
            output_bps=16,
            use_camera_wb=False,
            use_auto_wb=False,
            user_wb=[1.0, 1.0, 1.0, 1.0],
            half_size=True,
            user_flip=0,
            adjust_maximum_thr=0.0,  # keep the camera's white level (LibRaw would lower it to the data's maximum)
        )
    # LibRaw has subtracted the black level and scaled the white level to 65535 (give or take its
    # rounding: a saturated pixel comes out as 65534, see _RAW_CLIP).
    return pixels, 0.0, 65535.0


def _read_pixels(path: Path) -> np.ndarray:
    suffix = path.suffix.lower()
    if suffix == ".png":
        return read_png(path)
    if suffix in (".tif", ".tiff"):
        import tifffile

        pixels = tifffile.imread(path)
        if pixels.ndim == 3 and pixels.shape[0] in (3, 4) and pixels.shape[2] not in (3, 4):
            pixels = np.moveaxis(pixels, 0, -1)  # planar (separate) configuration
        return pixels
    raise ValueError(f"unsupported file type {suffix!r}; expected one of {', '.join(IMAGE_SUFFIXES)}")


def read_image(
    path: str | os.PathLike,
    *,
    black_level: float = 0.0,
    saturation: float | None = None,
    assume_linear: bool = False,
) -> LinearImage:
    """Read a linear image (16-bit PNG, TIFF, or camera raw with the ``raw`` extra).

    Arguments:
        path: the file.
        black_level: value of a black pixel in file units (subtracted). Raw files: LibRaw applies
            the camera's own black and white levels.
        saturation: file value at which the sensor saturates (default: the format's maximum, 65535
            for 16-bit, 255 for 8-bit, 1.0 for float TIFF); pixels with any channel at or above it
            are marked clipped.
        assume_linear: accept 8-bit files as linear data (otherwise they are refused).

    Returns:
        A :class:`LinearImage`.

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: unreadable, not RGB, empty, 8-bit without ``assume_linear``, or every pixel
            clipped; the message names the file.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"image: no such file: {path}")
    try:
        if path.suffix.lower() in RAW_SUFFIXES:
            pixels, black_level, default_saturation = _read_raw(path)
        else:
            pixels = _read_pixels(path)
            default_saturation = None
    except ValueError as error:
        raise ValueError(f"image: cannot read {path}: {error}") from None
    except Exception as error:  # a decoder's own exception types: report them the same way
        raise ValueError(f"image: cannot read {path}: {type(error).__name__}: {error}") from None
    if pixels.ndim == 2 or (pixels.ndim == 3 and pixels.shape[2] < 3):
        raise ValueError(f"image: {path} is a greyscale image; colour constancy needs RGB")
    if pixels.ndim != 3 or pixels.shape[2] not in (3, 4):
        raise ValueError(f"image: {path} has shape {pixels.shape}; expected (height, width, 3)")
    pixels = pixels[..., :3]  # drop alpha
    if pixels.size == 0:
        raise ValueError(f"image: {path} has no pixels (size {pixels.shape[0]}x{pixels.shape[1]})")
    if pixels.dtype == np.uint8 and not assume_linear:
        raise ValueError(
            f"image: {path} is 8-bit; 8-bit files are almost always gamma-encoded (sRGB), not linear "
            "camera data. Use a 16-bit linear file (or raw), or pass --assume-linear if it really is linear"
        )
    if np.issubdtype(pixels.dtype, np.integer):
        bit_depth = 8 * pixels.dtype.itemsize
        full_scale = float(np.iinfo(pixels.dtype).max)
    elif np.issubdtype(pixels.dtype, np.floating):
        bit_depth, full_scale = 8 * pixels.dtype.itemsize, 1.0
    else:
        raise ValueError(f"image: {path} has unsupported sample type {pixels.dtype}")
    level = float(saturation if saturation is not None else default_saturation or full_scale)
    if not level > black_level:
        raise ValueError(f"saturation: {level} must be above the black level {black_level}")
    values = pixels.astype(np.float32)
    if not np.all(np.isfinite(values)):
        raise ValueError(f"image: {path} contains NaN or infinite values")
    clip_level = level * (_RAW_CLIP if default_saturation is not None and saturation is None else 1.0)
    clipped = np.any(values >= clip_level, axis=-1)
    if np.all(clipped):
        raise ValueError(
            f"image: every pixel of {path} is clipped (a channel at or above the saturation level {level:g})"
        )
    rgb = np.maximum(values - np.float32(black_level), 0.0) / np.float32(level - black_level)
    return LinearImage(rgb=rgb, clipped=clipped, path=str(path), bit_depth=bit_depth)


def list_images(paths) -> list[Path]:
    """Expand files and folders (a folder gives its image files, sorted, not recursive)."""
    found: list[Path] = []
    for item in map(Path, paths):
        if item.is_dir():
            found += sorted(p for p in item.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
        else:
            found.append(item)
    return found


def quantise(rgb, levels: int = 65535) -> np.ndarray:
    """``rgb`` on the unit scale to integer file codes (``uint16`` for 65535 levels), clamped."""
    dtype = np.uint16 if levels > 255 else np.uint8
    return np.round(np.clip(np.asarray(rgb, np.float64), 0.0, 1.0) * levels).astype(dtype)


def write_linear(path: str | os.PathLike, rgb) -> None:
    """Write a unit-scale linear image as 16-bit PNG or TIFF (by suffix); values clamp to [0, 1]."""
    path = Path(path)
    codes = quantise(rgb)
    if path.suffix.lower() == ".png":
        write_png(path, codes)
    elif path.suffix.lower() in (".tif", ".tiff"):
        import tifffile

        tifffile.imwrite(path, codes, photometric="rgb")
    else:
        raise ValueError(f"output: {path} must end in .png, .tif or .tiff")


# ---------------------------------------------------------------------------------------------
# Preprocessing (Barnard 1999 §4.6, Table 4.6)


def usable_pixels(rgb: np.ndarray, clipped: np.ndarray, dark: float = DEFAULT_DARK) -> np.ndarray:
    """Pixels the thesis keeps: not clipped, and R+G+B at least ``dark`` times the brightest
    unclipped pixel's (the thesis drops "overly dark" pixels, §4.6; spec A9 gives 2 %)."""
    if not 0 <= dark < 1:
        raise ValueError(f"dark: expected a fraction in [0, 1), got {dark!r}")
    brightness = rgb.sum(axis=-1)
    peak = brightness[~clipped].max(initial=0.0)
    return ~clipped & (brightness >= dark * peak) & (brightness > 0)


def block_average(rgb: np.ndarray, usable: np.ndarray, block: int, max_rg_spread: float | None = None) -> np.ndarray:
    """Means of non-overlapping ``block x block`` tiles whose pixels are all usable (spec §10
    item 31); edge rows/columns that do not fill a tile are dropped. Returns ``(n, 3)``.

    ``max_rg_spread`` (an extension, not in the thesis) also drops tiles whose pixels' (r,g)
    bounding box has a diagonal above it: tiles straddling a boundary between surfaces, whose
    mean is a mixture no surface produces (harmless for gamut mapping, which is convex, but it
    fills histogram cells for Colour by Correlation).
    """
    height, width = (rgb.shape[0] // block) * block, (rgb.shape[1] // block) * block
    tiles = rgb[:height, :width].reshape(height // block, block, width // block, block, 3)
    ok = usable[:height, :width].reshape(height // block, block, width // block, block).all(axis=(1, 3))
    if max_rg_spread is not None:
        total = tiles.sum(axis=-1, keepdims=True, dtype=np.float64)
        chroma = tiles[..., :2] / np.where(total > 0, total, 1.0)
        spread = chroma.max(axis=(1, 3)) - chroma.min(axis=(1, 3))
        ok &= np.sqrt((spread**2).sum(axis=-1)) <= max_rg_spread
    return tiles.mean(axis=(1, 3), dtype=np.float64)[ok].astype(np.float32)


def cluster_rgb(rgb: np.ndarray, divisions: int = 100) -> np.ndarray:
    """RGB clustering (§4.6): bin in RGB (``divisions`` per channel over ``[0, max]``) and replace
    each occupied bin by the mean of its members (removes near-duplicates)."""
    if len(rgb) == 0:
        return rgb
    top = max(float(rgb.max()), 1e-12)
    cells = np.minimum((rgb / top * divisions).astype(np.int64), divisions - 1)
    keys = (cells[:, 0] * divisions + cells[:, 1]) * divisions + cells[:, 2]
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    sums = np.zeros((len(counts), 3))
    np.add.at(sums, inverse.ravel(), rgb)
    return (sums / counts[:, None]).astype(np.float32)


def hull_reduce(rgb: np.ndarray) -> np.ndarray:
    """Keep only the vertices of the RGB convex hull (§4.6); degenerate sets are kept whole."""
    from scipy.spatial import ConvexHull, QhullError

    if len(rgb) < 5:
        return rgb
    try:
        return rgb[np.sort(ConvexHull(rgb.astype(np.float64)).vertices)]
    except QhullError:
        return rgb


def segment(
    rgb: np.ndarray, usable: np.ndarray, min_size: int, rg_tolerance: float, brightness_tolerance: float
) -> np.ndarray:
    """Region growing (§4.6; semantics of spec §10 item 30) and the mean RGB of each region.

    Seeds are taken in scan order; a region grows over 4-connected usable pixels while the
    diagonal of its (r,g) bounding box stays within ``rg_tolerance`` and ``(max - min) / min`` of
    its R+G+B within ``brightness_tolerance``; regions smaller than ``min_size`` are dropped.
    Plain Python region growing: a few seconds per megapixel (a preprocessing option, not the
    default).
    """
    height, width, _ = rgb.shape
    total = rgb.sum(axis=-1, dtype=np.float64)
    safe = np.where(total > 0, total, 1.0)
    r, g = (rgb[..., 0] / safe).tolist(), (rgb[..., 1] / safe).tolist()
    brightness = total.tolist()
    free = usable.copy()
    means = []
    rg_limit = rg_tolerance**2
    for y0, x0 in zip(*np.nonzero(usable)):
        if not free[y0, x0]:
            continue
        free[y0, x0] = False
        members = [(y0, x0)]
        r_lo = r_hi = r[y0][x0]
        g_lo = g_hi = g[y0][x0]
        b_lo = b_hi = brightness[y0][x0]
        queue = deque(members)
        while queue:
            y, x = queue.popleft()
            for ny, nx in ((y - 1, x), (y + 1, x), (y, x - 1), (y, x + 1)):
                if 0 <= ny < height and 0 <= nx < width and free[ny, nx]:
                    rr, gg, bb = r[ny][nx], g[ny][nx], brightness[ny][nx]
                    nr_lo, nr_hi, ng_lo, ng_hi = min(r_lo, rr), max(r_hi, rr), min(g_lo, gg), max(g_hi, gg)
                    nb_lo, nb_hi = min(b_lo, bb), max(b_hi, bb)
                    if (nr_hi - nr_lo) ** 2 + (
                        ng_hi - ng_lo
                    ) ** 2 <= rg_limit and nb_hi - nb_lo <= brightness_tolerance * nb_lo:
                        r_lo, r_hi, g_lo, g_hi, b_lo, b_hi = nr_lo, nr_hi, ng_lo, ng_hi, nb_lo, nb_hi
                        free[ny, nx] = False
                        members.append((ny, nx))
                        queue.append((ny, nx))
        if len(members) >= min_size:
            ys, xs = np.array(members).T
            means.append(rgb[ys, xs].mean(axis=0, dtype=np.float64))
    return np.array(means, np.float32).reshape(-1, 3)


@dataclass(frozen=True)
class Preprocessing:
    """One of the thesis' preprocessing methods (Table 4.6), parsed from a name:

    ``ave<b>`` (block averaging, ``ave1`` = single pixels), ``ave<b>-cluster`` (+ RGB clustering,
    100 divisions), ``ave<b>-hull`` (+ convex-hull reduction), ``seg-<min size>-<rg tol>-<rel
    R+G+B tol>`` (segmentation, e.g. ``seg-5-0.005-0.2``), ``seg-...-hull``, and ``generic``
    (Table 4.5's segmentation, ``seg-5-0.05-0.1``). Extension: ``ave<b>-u<spread>`` keeps only
    blocks whose (r,g) spread is at most ``<spread>`` (e.g. ``ave5-u0.04``; :func:`block_average`),
    combinable with ``-cluster``/``-hull``.
    """

    name: str
    block: int = 5
    segmentation: tuple[int, float, float] | None = None
    reduction: str | None = None  # None, "cluster" or "hull"
    max_rg_spread: float | None = None

    @classmethod
    def parse(cls, name: str) -> Preprocessing:
        text = "seg-5-0.05-0.1" if name == "generic" else name
        number = r"(\d+(?:\.\d*)?|\.\d+)"
        match = re.fullmatch(rf"ave(\d+)(?:-u{number})?(?:-(cluster|hull))?", text)
        if match and int(match[1]) >= 1:
            spread = None if match[2] is None else float(match[2])
            return cls(name=name, block=int(match[1]), reduction=match[3], max_rg_spread=spread)
        match = re.fullmatch(rf"seg-(\d+)-{number}-{number}(?:-(hull))?", text)
        if match:
            return cls(
                name=name, block=1, segmentation=(int(match[1]), float(match[2]), float(match[3])), reduction=match[4]
            )
        raise ValueError(
            f"preprocessing: unknown method {name!r}; expected ave<b>[-u<spread>][-cluster|-hull], "
            "seg-<min>-<rg>-<rel>[-hull] or generic"
        )

    def apply(self, rgb: np.ndarray, usable: np.ndarray) -> np.ndarray:
        """The surface list ``(n, 3)`` for one image (``usable`` from :func:`usable_pixels`)."""
        if self.segmentation is not None:
            data = segment(rgb, usable, *self.segmentation)
        else:
            data = block_average(rgb, usable, self.block, self.max_rg_spread)
        if self.reduction == "cluster":
            data = cluster_rgb(data)
        elif self.reduction == "hull":
            data = hull_reduce(data)
        return data


TABLE_4_6 = (
    [f"seg-{m}-{t}-{b}" for t in (0.0025, 0.005, 0.01, 0.02) for b in (0.1, 0.2, 0.3, 0.4) for m in (5, 10, 20)]
    + [f"ave{b}" for b in (1, 2, 3, 5, 7)]
    + [f"ave{b}-cluster" for b in (1, 2, 3, 5, 7)]
    + [f"ave{b}-hull" for b in (1, 2, 3, 5, 7)]
)
"""The 63 well-defined preprocessing methods of Table 4.6 (48 segmentations, 5 block sizes, 5 with
RGB clustering, 5 with hull reduction). The thesis' remaining two ("two selected segmentations +
hull reduction") do not say which segmentations; any ``seg-...-hull`` name runs such a variant."""


def _bucket(count: int) -> int:
    """Pad surface lists to a few sizes so jit compiles once per size class, not per image."""
    return max(64, 1 << int(np.ceil(np.log2(max(count, 1)))))


def surfaces(
    image: LinearImage,
    preprocessing: str | Preprocessing = DEFAULT_PREPROCESSING,
    *,
    dark: float = DEFAULT_DARK,
    pad: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Estimator input of a surface-list method: ``(rgb (N, 3), mask (N,))``.

    Arguments:
        image: a :class:`LinearImage`.
        preprocessing: a :class:`Preprocessing` or its name (default ``ave5``).
        dark: dark-pixel fraction (:func:`usable_pixels`).
        pad: pad to a power of two (>= 64) with masked rows, so batches share compiled code.
    """
    method = preprocessing if isinstance(preprocessing, Preprocessing) else Preprocessing.parse(preprocessing)
    data = method.apply(image.rgb, usable_pixels(image.rgb, image.clipped, dark))
    size = _bucket(len(data)) if pad else len(data)
    rgb = np.zeros((size, 3), np.float32)
    rgb[: len(data)] = data
    mask = np.arange(size) < len(data)
    return rgb, mask


def model_input(
    model: Estimator, image: LinearImage, preprocessing=DEFAULT_PREPROCESSING, *, dark: float = DEFAULT_DARK
):
    """What ``model`` is called with: the image and its unclipped mask for image-only methods,
    the preprocessed surface list otherwise."""
    if model.input_kind == "image":
        return image.rgb, ~image.clipped
    return surfaces(image, preprocessing, dark=dark)


@eqx.filter_jit
def _run_model(model, rgb, mask) -> Estimate:
    return model(rgb, mask)


def estimate_image(
    model: Estimator, image: LinearImage, preprocessing=DEFAULT_PREPROCESSING, *, dark: float = DEFAULT_DARK
) -> Estimate:
    """Estimate the light of one image with a fitted model (jit-compiled per input size)."""
    rgb, mask = model_input(model, image, preprocessing, dark=dark)
    return _run_model(model, jnp.asarray(rgb), jnp.asarray(mask))


# ---------------------------------------------------------------------------------------------
# Correction and output


@jax.jit
def correction_map(
    illuminant: Float[Array, "3"], canonical_white: Float[Array, "3"], sharpening: Float[Array, "3 3"] | None = None
) -> Float[Array, "3 3"]:
    """The 3x3 map taking the estimated light to the canonical one (Barnard 1999 §2.5).

    Diagonal: ``diag(w_C / e)``; sharpened diagonal with ``T`` (rows: sharpened sensors as
    combinations of R, G, B): ``T^-1 diag(T w_C / T e) T``. The map is scaled so that it keeps the
    brightness ``R+G+B`` of a grey (chromaticity methods leave the magnitude of ``e`` arbitrary).
    """
    transform = jnp.eye(3, dtype=illuminant.dtype) if sharpening is None else jnp.asarray(sharpening, illuminant.dtype)
    target, source = transform @ canonical_white, transform @ illuminant
    diagonal = target / jnp.where(jnp.abs(source) > 1e-12, source, 1e-12)
    matrix = jnp.linalg.solve(transform, diagonal[:, None] * transform)
    grey = illuminant / jnp.maximum(jnp.sum(illuminant), 1e-12)
    return matrix / jnp.maximum(jnp.sum(matrix @ grey), 1e-12)


@jax.jit
def diagonal_gains(illuminant: Float[Array, "3"], canonical_white: Float[Array, "3"]) -> Float[Array, "3"]:
    """The diagonal of :func:`correction_map` without sharpening (per-channel gains)."""
    gains = canonical_white / jnp.where(illuminant > 1e-12, illuminant, 1e-12)
    grey = illuminant / jnp.maximum(jnp.sum(illuminant), 1e-12)
    return gains / jnp.maximum(jnp.sum(gains * grey), 1e-12)


@jax.jit
def apply_map(rgb: Float[Array, "... 3"], matrix: Float[Array, "3 3"]) -> Float[Array, "... 3"]:
    """Apply a 3x3 colour map to every pixel."""
    return jnp.einsum("...c,kc->...k", rgb, matrix)


def correct(rgb, illuminant, canonical_white, sharpening=None) -> Float[Array, "... 3"]:
    """Map an image from the estimated light to the canonical light (jit-able; a diagonal map is
    applied as per-channel gains, a sharpened one as a 3x3 matrix)."""
    rgb, illuminant, canonical_white = jnp.asarray(rgb), jnp.asarray(illuminant), jnp.asarray(canonical_white)
    if sharpening is None:
        return rgb * diagonal_gains(illuminant, canonical_white)
    return apply_map(rgb, correction_map(illuminant, canonical_white, sharpening))


def masked_mean(rgb: Float[Array, "H W 3"], mask: Bool[Array, "H W"]) -> Float[Array, "3"]:
    """Mean RGB of the masked pixels (0 if none). Summed as a matrix-vector product over rows of
    ``W * 3`` values: XLA's CPU reductions over a minor axis of 3 are several times slower."""
    height, width, _ = rgb.shape
    rows = jnp.where(mask[..., None], rgb, 0.0).reshape(height, width * 3)
    total = (jnp.ones((height,), rgb.dtype) @ rows).reshape(width, 3).sum(axis=0)
    return total / jnp.maximum(jnp.sum(mask), 1)


def estimate_pixels(model: Estimator, rgb: Float[Array, "H W 3"], mask: Bool[Array, "H W"]) -> Estimate:
    """Run a model on every masked pixel of an image (no block averaging), jit-able.

    Image-only models get the image; grey-world models (linear in the pixels) get the masked mean
    as a single datum, which gives the same estimate with one fast reduction; others get the
    pixel list.
    """
    from ccjax.estimators.simple import GreyWorld

    if model.input_kind == "image":
        return model(rgb, mask)
    if isinstance(model, GreyWorld):
        return model(masked_mean(rgb, mask)[None], jnp.any(mask)[None])
    return model(rgb.reshape(-1, 3), mask.reshape(-1))


_XYZ_TO_SRGB = np.array(
    [[3.2404542, -1.5371385, -0.4985314], [-0.9692660, 1.8760108, 0.0415560], [0.0556434, -0.2040259, 1.0572252]]
)


def preview_matrix(world) -> np.ndarray:
    """Camera RGB under the world's canonical light -> linear sRGB (D65), by least squares over
    the world's reflectances (CIE 1931 2° observer), with the canonical white mapped to sRGB
    white exactly (a corrected image shows greys as grey)."""
    import colour

    from ccjax.spectra import resample

    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    xyz_curves = resample(np.asarray(cmfs.wavelengths), np.asarray(cmfs.values), kind="sensor")
    d65 = colour.SDS_ILLUMINANTS["D65"]
    d65 = resample(np.asarray(d65.wavelengths), np.asarray(d65.values), kind="spectrum")
    reflectances = np.asarray(world.reflectances, np.float64)
    camera = reflectances * np.asarray(world.canonical, np.float64) @ np.asarray(world.camera.sensors, np.float64)
    xyz = (reflectances * d65) @ xyz_curves
    white_camera = np.asarray(world.canonical_white, np.float64)
    white_xyz = d65 @ xyz_curves
    camera, xyz = camera / white_camera.max(), xyz / white_xyz[1]
    matrix = np.linalg.lstsq(camera, xyz, rcond=None)[0].T  # xyz ~ matrix @ camera
    srgb = _XYZ_TO_SRGB @ matrix
    # Scale rows so the canonical white lands exactly on (1, 1, 1) * its brightest channel.
    white = srgb @ (white_camera / white_camera.max())
    assert np.all(white > 0), "preview matrix maps white outside the sRGB gamut"
    return (srgb / white[:, None]).astype(np.float32)


def srgb_preview(rgb: np.ndarray, matrix: np.ndarray | None = None, percentile: float = 99.0) -> np.ndarray:
    """8-bit sRGB rendering of a linear camera image: colour matrix, exposure so the
    ``percentile``-th brightest value is 1, sRGB transfer curve."""
    linear = np.asarray(rgb, np.float32) @ (np.eye(3, dtype=np.float32) if matrix is None else matrix).T
    scale = np.percentile(linear.max(axis=-1), percentile)
    linear = np.clip(linear / max(float(scale), 1e-12), 0.0, 1.0)
    encoded = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * np.power(linear, 1 / 2.4) - 0.055)
    return np.round(encoded * 255).astype(np.uint8)


def write_preview(path: str | os.PathLike, rgb: np.ndarray, matrix: np.ndarray | None = None) -> None:
    """Write :func:`srgb_preview` as an 8-bit PNG."""
    write_png(path, srgb_preview(rgb, matrix))


# ---------------------------------------------------------------------------------------------
# Ground truth


def read_ground_truth(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a ground-truth CSV with header ``image,r,g,b`` (camera RGB of the light, any scale).

    Returns:
        ``{image name: (3,) float64}``.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"ground truth: no such file: {path}")
    truth: dict[str, np.ndarray] = {}
    with open(path, newline="") as handle:
        reader = csv.DictReader(handle)
        if reader.fieldnames is None or [f.strip().lower() for f in reader.fieldnames[:4]] != ["image", "r", "g", "b"]:
            raise ValueError(f"ground truth: {path} must have the header image,r,g,b (got {reader.fieldnames})")
        for line, row in enumerate(reader, start=2):
            row = {k.strip().lower(): v for k, v in row.items() if k is not None}
            try:
                rgb = np.array([float(row["r"]), float(row["g"]), float(row["b"])])
            except (TypeError, ValueError):
                raise ValueError(f"ground truth: {path} line {line}: r,g,b must be numbers") from None
            if not np.all(np.isfinite(rgb)) or np.any(rgb < 0) or rgb.sum() <= 0:
                raise ValueError(f"ground truth: {path} line {line}: r,g,b must be finite, non-negative, not all zero")
            truth[row["image"].strip()] = rgb
    if not truth:
        raise ValueError(f"ground truth: {path} has no rows")
    return truth


def write_ground_truth(path: str | os.PathLike, names, illuminants) -> None:
    """Write ``image,r,g,b`` rows (see :func:`read_ground_truth`)."""
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["image", "r", "g", "b"])
        for name, rgb in zip(names, np.asarray(illuminants, np.float64)):
            writer.writerow([name, *(f"{v:.9g}" for v in rgb)])


def match_ground_truth(truth: dict[str, np.ndarray], directory: str | os.PathLike) -> list[tuple[Path, np.ndarray]]:
    """Pair each ground-truth row with its file in ``directory`` (by relative name, then by stem)."""
    directory = Path(directory)
    if not directory.is_dir():
        raise FileNotFoundError(f"images: no such folder: {directory}")
    by_stem = {p.stem: p for p in list_images([directory])}
    pairs, missing = [], []
    for name, rgb in truth.items():
        candidate = directory / name
        if candidate.is_file():
            pairs.append((candidate, rgb))
        elif Path(name).stem in by_stem:
            pairs.append((by_stem[Path(name).stem], rgb))
        else:
            missing.append(name)
    if missing:
        raise ValueError(f"ground truth: {len(missing)} image(s) not found in {directory}, e.g. {missing[:3]}")
    return pairs


# ---------------------------------------------------------------------------------------------
# On-disk cache of worlds and fitted models (DESIGN.md §2)


def cache_directory() -> Path:
    """``$CCJAX_CACHE``, else the platform's user cache directory + ``ccjax``."""
    if os.environ.get("CCJAX_CACHE"):
        return Path(os.environ["CCJAX_CACHE"])
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA", Path.home() / "AppData" / "Local"))
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    return base / "ccjax"


def enable_compilation_cache() -> None:
    """Keep XLA's compiled programs in ``<cache>/xla`` (unless the user configured a cache), so a
    second run of a command skips compilation as well as fitting."""
    if not jax.config.jax_compilation_cache_dir:
        jax.config.update("jax_compilation_cache_dir", str(cache_directory() / "xla"))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)


def _code_fingerprint() -> str:
    """Hash of the package's source: a code change invalidates every cached object."""
    digest = hashlib.sha256()
    for source in sorted(Path(__file__).parent.rglob("*.py")):
        digest.update(source.read_bytes())
    return digest.hexdigest()


def _world_fingerprint(world) -> str:
    digest = hashlib.sha256(world.name.encode())
    for leaf in jax.tree_util.tree_leaves(world):
        array = np.asarray(leaf)
        digest.update(str(array.shape).encode() + array.tobytes())
    return digest.hexdigest()


def _cached(key_parts: tuple, build):
    key = hashlib.sha256(repr((_code_fingerprint(),) + key_parts).encode()).hexdigest()[:32]
    path = cache_directory() / f"{key}.pkl"
    if path.is_file():
        try:
            with open(path, "rb") as handle:
                return pickle.load(handle)
        except Exception:  # a truncated or stale file: rebuild it
            pass
    value = build()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        _atomic_write(path, pickle.dumps(value))
    except OSError:
        pass  # a read-only cache directory only costs speed
    return value


def cached_world(kind: str = "default", camera: str | None = None, *, seed: int = 0, data_dir=None):
    """``World.default(camera)`` or ``World.barnard1999()``, built once and then loaded from disk."""
    from ccjax.world import World

    if kind == "barnard1999":
        from ccjax.data import find_data_file

        source = find_data_file("sfu_barnard/sony_dxc930_380-780-4nm.csv", data_dir)
        return _cached(("world", kind, str(source), seed), lambda: World.barnard1999(data_dir, seed=seed))
    if kind != "default":
        raise ValueError(f"world: expected 'default' or 'barnard1999', got {kind!r}")
    camera = camera or "Canon EOS 5D Mark II"
    return _cached(("world", kind, camera, seed), lambda: World.default(camera, seed=seed))


def cached_fit(label: str, world, **options) -> Estimator:
    """``registry.fit(label, world, **options)``, cached on disk by world content and options."""
    from ccjax.estimators import registry

    registry.lookup(label)  # unknown labels fail before anything is hashed or written
    return _cached(
        ("fit", label, sorted(options.items()), _world_fingerprint(world)),
        lambda: registry.fit(label, world, **options),
    )


# ---------------------------------------------------------------------------------------------
# Running estimators over image files, and evaluating them against ground truth


@dataclass
class ImageResults:
    """Estimates of several methods over a list of images.

    Attributes:
        paths: the image files, in order.
        estimates: ``{method: (N, 3)}`` illuminant RGB (unit scale of each image).
        ok: ``{method: (N,)}`` False where the method fell back or relaxed its constraints.
        truth: ``(N, 3)`` ground truth when known.
    """

    paths: list[str]
    estimates: dict[str, np.ndarray]
    ok: dict[str, np.ndarray]
    truth: np.ndarray | None = None

    def angular(self, method: str) -> np.ndarray:
        from ccjax.metrics import angular_error

        return np.asarray(
            angular_error(jnp.asarray(self.estimates[method]), jnp.asarray(self.truth, jnp.float32)), np.float64
        )

    def summary(self, method: str) -> dict[str, float]:
        from ccjax.metrics import summarise

        errors = self.angular(method)
        row = {name: summarise(errors, name) for name in ("mean", "median", "trimean", "best25", "worst25", "max")}
        row["not_ok"] = float(1.0 - np.mean(self.ok[method]))
        return row

    def table(self) -> str:
        """Angular error (degrees) per method: the statistics of DESIGN.md §7."""
        header = (
            f"{'method':<24}{'mean':>8}{'median':>8}{'trimean':>9}{'best25':>8}{'worst25':>9}{'max':>8}{'not ok':>9}"
        )
        lines = [f"angular error (degrees) over {len(self.paths)} images", header]
        for method in self.estimates:
            row = self.summary(method)
            lines.append(
                f"{method:<24}{row['mean']:8.3f}{row['median']:8.3f}{row['trimean']:9.3f}{row['best25']:8.3f}"
                f"{row['worst25']:9.3f}{row['max']:8.3f}{100 * row['not_ok']:8.1f}%"
            )
        return "\n".join(lines)

    def records(self) -> list[dict]:
        """One record per image and method (path, method, illuminant, rg, ok, angular error)."""
        from ccjax.spectra import chromaticity

        rows = []
        for method, estimates in self.estimates.items():
            errors = self.angular(method) if self.truth is not None else [None] * len(self.paths)
            for path, rgb, ok, error in zip(self.paths, estimates, self.ok[method], errors):
                rows.append(
                    {
                        "path": path,
                        "method": method,
                        "illuminant": [float(v) for v in rgb],
                        "rg": [float(v) for v in chromaticity(np.asarray(rgb, np.float64))],
                        "ok": bool(ok),
                        **({} if error is None else {"angular": float(error)}),
                    }
                )
        return rows


def run_images(
    paths,
    models: dict[str, list[Estimator]],
    *,
    fold_of: np.ndarray | None = None,
    preprocessing: str = DEFAULT_PREPROCESSING,
    dark: float = DEFAULT_DARK,
    read_options: dict | None = None,
    progress: bool = False,
    truth: np.ndarray | None = None,
) -> ImageResults:
    """Read each image once and run every method on it (preprocessing shared between methods).

    Arguments:
        paths: image files.
        models: ``{label: [model]}``, or one model per fold (``[model_fold0, model_fold1, ...]``).
        fold_of: ``(N,)`` fold of each image (selects its model); ``None``: fold 0.
        preprocessing, dark: see :func:`surfaces`.
        read_options: keyword arguments of :func:`read_image`.
        progress: show a progress bar on stderr.
        truth: optional ``(N, 3)`` ground truth, stored in the result.
    """
    from tqdm.auto import tqdm

    paths = [Path(p) for p in paths]
    method = Preprocessing.parse(preprocessing) if isinstance(preprocessing, str) else preprocessing
    estimates = {label: np.zeros((len(paths), 3), np.float32) for label in models}
    ok = {label: np.zeros(len(paths), bool) for label in models}
    for index, path in enumerate(tqdm(paths, desc="images", unit="image", disable=not progress, file=sys.stderr)):
        image = read_image(path, **(read_options or {}))
        surface_input = None
        for label, fold_models in models.items():
            model = fold_models[0 if fold_of is None else int(fold_of[index])]
            if model.input_kind == "image":
                rgb, mask = image.rgb, ~image.clipped
            else:
                if surface_input is None:
                    surface_input = surfaces(image, method, dark=dark)
                rgb, mask = surface_input
            result = _run_model(model, jnp.asarray(rgb), jnp.asarray(mask))
            estimates[label][index] = np.asarray(result.illuminant)
            ok[label][index] = bool(result.ok)
    return ImageResults(paths=[str(p) for p in paths], estimates=estimates, ok=ok, truth=truth)


def fold_worlds(world, truth: np.ndarray, folds: int) -> tuple[np.ndarray, list]:
    """Worlds for K-fold cross-validation of trained methods on an image set.

    Image ``i`` is in fold ``i mod K``. The world of fold ``k`` keeps everything but its training
    illuminants, which become the lights of the *other* folds' ground truths: each ground-truth RGB
    is matched to the world illuminant (training or test set) of nearest (r,g) chromaticity, so the
    methods that learn from the expected lights (AVE-ILLUM, the illumination constraint of ECRULE,
    Colour by Correlation, the nets) learn those of the data set without seeing the held-out fold.

    Returns:
        ``(fold of each image (N,), [world_0, ..., world_{K-1}])``.
    """
    from ccjax.spectra import chromaticity

    truth = np.asarray(truth, np.float64)
    if not isinstance(folds, int) or not 2 <= folds <= len(truth):
        raise ValueError(f"folds: expected an integer in [2, {len(truth)}] (number of images), got {folds!r}")
    pool = np.concatenate([np.asarray(world.train_illuminants), np.asarray(world.test_illuminants)])
    pool_rg = chromaticity(pool @ np.asarray(world.camera.sensors, np.float64))
    nearest = np.argmin(((chromaticity(truth)[:, None, :] - pool_rg[None]) ** 2).sum(-1), axis=1)
    fold_of = np.arange(len(truth)) % folds
    worlds = []
    for fold in range(folds):
        chosen = np.unique(nearest[fold_of != fold])
        spectra = jnp.asarray(pool[chosen], world.train_illuminants.dtype)
        worlds.append(eqx.tree_at(lambda w: w.train_illuminants, world, spectra))
    return fold_of, worlds


def preview_matrix_cached(world) -> np.ndarray:
    """:func:`preview_matrix`, cached on disk (importing colour-science is slow)."""
    return _cached(("preview", _world_fingerprint(world)), lambda: preview_matrix(world))


def write_dataset(directory: str | os.PathLike, rgb, illuminants, *, prefix: str = "image") -> Path:
    """Write unit-scale images ``(B, H, W, 3)`` as 16-bit PNGs ``<prefix>-0000.png ...`` and their
    lights ``(B, 3)`` as ``groundtruth.csv`` (header ``image,r,g,b``); returns the CSV path."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    rgb = np.asarray(rgb)
    names = [f"{prefix}-{index:04d}.png" for index in range(len(rgb))]
    for name, image in zip(names, rgb):
        write_png(directory / name, quantise(image))
    write_ground_truth(directory / "groundtruth.csv", names, illuminants)
    return directory / "groundtruth.csv"
