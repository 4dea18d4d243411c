"""8-bit sRGB previews of linear camera images.

The camera-to-sRGB matrix is fitted by least squares over the world's reflectances (CIE 1931 2°
observer, D65) with the canonical white pinned to sRGB white, so a corrected image (Barnard 1999
§2.5) shows greys as grey.
"""

from __future__ import annotations

import os
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike

from ccjax._cache import content_key
from ccjax._entries import Expect, cached_arrays
from ccjax.io.png import write_png
from ccjax.io.writing import row_slices

PREVIEW_METHOD = "lstsq-reflectances-d65-v2"
"""Names the fit of :func:`preview_matrix` in its cache key: change it when the fit changes."""


def preview_matrix(world) -> np.ndarray:
    """Camera RGB under the world's canonical light -> linear sRGB (D65).

    Arguments:
        world: a :class:`ccjax.world.World` (reflectances, canonical light, camera).

    Returns:
        ``(3, 3)`` float32, ``srgb = matrix @ camera_rgb``; the canonical white maps to
        ``(1, 1, 1)`` times its brightest channel.
    """
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
    srgb = np.asarray(colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB, np.float64) @ matrix
    # Scale rows so the canonical white lands exactly on (1, 1, 1) * its brightest channel.
    white = srgb @ (white_camera / white_camera.max())
    if not np.all(white > 0):
        raise ValueError(f"world: the preview matrix of {world.name!r} maps its canonical white outside sRGB")
    return (srgb / white[:, None]).astype(np.float32)


def preview_matrix_cached(world) -> np.ndarray:
    """:func:`preview_matrix`, cached on disk by the world's content (importing colour-science is slow).

    Arguments:
        world: the world whose camera the matrix is for.

    Returns:
        The ``(3, 3)`` camera-to-linear-sRGB matrix of :func:`preview_matrix`.
    """
    key = content_key("preview", PREVIEW_METHOD, world)
    # The rows of a camera-to-sRGB matrix are of order one; one far out is not a preview matrix.
    layout = {"matrix": Expect((3, 3), "f", -1e3, 1e3)}
    facts = {"world": world.name, "method": PREVIEW_METHOD}
    return cached_arrays("preview", key, lambda: {"matrix": preview_matrix(world)}, layout, facts)["matrix"]


def encode_srgb(linear: ArrayLike, bits: int = 8) -> np.ndarray:
    """Linear sRGB as sRGB file codes: clipped to [0, 1], the IEC 61966-2-1 transfer curve
    (colour-science's), ``bits`` per sample.

    Arguments:
        linear: ``(..., 3)`` linear sRGB (1 = full scale).
        bits: 8 (``uint8``) or 16 (``uint16``).

    Returns:
        The codes.
    """
    import colour

    if bits not in (8, 16):
        raise ValueError(f"bits: expected 8 or 16, got {bits!r}")
    encoded = colour.cctf_encoding(np.clip(np.asarray(linear, np.float32), 0.0, 1.0), function="sRGB")
    return np.round(encoded * (2**bits - 1)).astype(np.uint8 if bits == 8 else np.uint16)


def srgb_preview(rgb: ArrayLike, matrix: np.ndarray | None = None, percentile: float = 99.0) -> np.ndarray:
    """8-bit sRGB rendering of a linear camera image.

    Arguments:
        rgb: ``(H, W, 3)`` linear camera RGB.
        matrix: camera -> linear sRGB (:func:`preview_matrix`); identity if None.
        percentile: exposure: this percentile of the brightest channel becomes 1.

    Returns:
        ``(H, W, 3)`` ``uint8`` sRGB (:func:`encode_srgb`).
    """
    rgb = np.asarray(rgb)
    return srgb_preview_rows(lambda rows: rgb[rows], rgb.shape, matrix, percentile)


def preview_factor(shape: tuple[int, ...], size: int | None) -> int:
    """The block side by which a preview of an image of ``shape`` is reduced so that its longer
    side is at most ``size`` (1: full size).

    Arguments:
        shape: the image's shape ``(H, W, ...)``.
        size: the preview's longest side in pixels, or None for full size.

    Returns:
        The integer factor.

    Raises:
        ValueError: ``size`` is not a positive integer.
    """
    if size is None:
        return 1
    if isinstance(size, bool) or not isinstance(size, int) or size < 1:
        raise ValueError(f"size: expected a positive number of pixels or None, got {size!r}")
    return max(1, -(-max(shape[0], shape[1]) // size))


def _block_means(pixels: np.ndarray, factor: int) -> np.ndarray:
    """Means of ``factor`` x ``factor`` blocks (the last row and column of blocks may be partial)."""
    if factor == 1:
        return pixels
    rows, columns = np.arange(0, pixels.shape[0], factor), np.arange(0, pixels.shape[1], factor)
    sums = np.add.reduceat(np.add.reduceat(pixels, rows, axis=0), columns, axis=1)
    counts = np.diff([*rows, pixels.shape[0]])[:, None] * np.diff([*columns, pixels.shape[1]])[None, :]
    return sums / counts[..., None].astype(pixels.dtype)


def srgb_preview_rows(
    rows_of: Callable[[slice], np.ndarray],
    shape: tuple[int, ...],
    matrix: np.ndarray | None = None,
    percentile: float = 99.0,
    size: int | None = None,
) -> np.ndarray:
    """:func:`srgb_preview` of an image given a piece of rows at a time (two passes: the exposure
    needs every pixel's brightest channel first), so a 48 MP image (or one computed piece by
    piece, such as a corrected image) is never held in float copies of the whole.

    Arguments:
        rows_of: the image's rows ``rows`` (a slice of the first axis) as linear camera RGB.
        shape: the image's shape ``(H, W, 3)``.
        matrix: camera -> linear sRGB (:func:`preview_matrix`); identity if None.
        percentile: exposure: this percentile of the brightest channel (of the reduced image)
            becomes 1.
        size: the preview's longest side at most (pixels): the image is reduced by the smallest
            integer factor that fits (:func:`preview_factor`), each preview pixel the mean of its
            block in linear light; None: full size.

    Returns:
        ``(ceil(H / f), ceil(W / f), 3)`` ``uint8`` sRGB (:func:`encode_srgb`), ``f`` the factor.
    """
    transform = (np.eye(3, dtype=np.float32) if matrix is None else matrix).T
    factor = preview_factor(shape, size)
    height, width = -(-shape[0] // factor), -(-shape[1] // factor)
    # Pieces of whole blocks: about CHUNK_VALUES values each, a multiple of ``factor`` rows.
    step = factor * max(1, row_slices(tuple(shape))[0].stop // factor)
    pieces = [slice(start, min(start + step, shape[0])) for start in range(0, shape[0], step)]

    def reduced(rows: slice) -> np.ndarray:
        return _block_means(np.asarray(rows_of(rows), np.float32), factor) @ transform

    brightest = np.empty((height, width), np.float32)
    for rows in pieces:
        brightest[rows.start // factor : -(-rows.stop // factor)] = reduced(rows).max(axis=-1)
    scale = max(float(np.percentile(brightest, percentile)), 1e-12)
    del brightest
    encoded = np.empty((height, width, 3), np.uint8)
    for rows in pieces:
        encoded[rows.start // factor : -(-rows.stop // factor)] = encode_srgb(reduced(rows) / scale, 8)
    return encoded


def write_preview(
    path: str | os.PathLike, rgb: ArrayLike, matrix: np.ndarray | None = None, *, overwrite: bool = True
) -> None:
    """Write :func:`srgb_preview` of ``rgb`` as an 8-bit PNG (:func:`ccjax.io.write_png`).

    Arguments:
        path: the ``.png`` file.
        rgb: ``(H, W, 3)`` unit-scale camera RGB.
        matrix: camera RGB to linear sRGB (:func:`srgb_preview`).
        overwrite: replace a file already at ``path``.

    Returns:
        None.
    """
    write_png(path, srgb_preview(rgb, matrix), overwrite=overwrite)
