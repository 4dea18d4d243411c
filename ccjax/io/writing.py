"""Writing linear images (16-bit PNG or TIFF) and labelled image sets."""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from ccjax.io.files import write_file
from ccjax.io.ground_truth import write_ground_truth
from ccjax.io.png import write_png


def quantise(rgb: ArrayLike, levels: int = 65535) -> np.ndarray:
    """``rgb`` on the unit scale to integer file codes, clamped to ``[0, 1]`` first.

    Arguments:
        rgb: any shape, unit scale (1.0 = saturation).
        levels: the largest code (``uint16`` above 255, else ``uint8``).

    Returns:
        The rounded codes.
    """
    dtype = np.uint16 if levels > 255 else np.uint8
    return np.round(np.clip(np.asarray(rgb, np.float64), 0.0, 1.0) * levels).astype(dtype)


def write_linear(path: str | os.PathLike, rgb: ArrayLike) -> None:
    """Write a unit-scale linear image ``(H, W, 3)`` as 16-bit PNG or TIFF (by suffix), atomically
    (:func:`write_file`); values clamp to [0, 1].

    Arguments:
        path: ``.png``, ``.tif`` or ``.tiff`` file.
        rgb: ``(H, W, 3)`` unit-scale linear RGB.

    Returns:
        None.

    Raises:
        ValueError: the suffix is not ``.png``, ``.tif`` or ``.tiff``.
    """
    write_codes(path, quantise(rgb))


def write_codes(path: str | os.PathLike, codes: np.ndarray) -> None:
    """Write file codes ``(H, W, 3)`` (``uint8`` or ``uint16``) as a PNG or TIFF (by suffix),
    atomically (:func:`write_file`).

    Arguments:
        path: ``.png``, ``.tif`` or ``.tiff`` file.
        codes: ``(H, W, 3)`` ``uint8`` or ``uint16``.

    Returns:
        None.

    Raises:
        ValueError: the suffix is not ``.png``, ``.tif`` or ``.tiff``.
    """
    path = Path(path)
    if path.suffix.lower() not in (".png", ".tif", ".tiff"):
        raise ValueError(f"output: {path} must end in .png, .tif or .tiff")
    if path.suffix.lower() == ".png":
        write_png(path, codes)
    else:
        import tifffile

        buffer = io.BytesIO()
        tifffile.imwrite(buffer, codes, photometric="rgb")
        write_file(path, buffer.getvalue())


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
