"""Ground-truth files: CSV with the header ``image,r,g,b``.

``image`` is the file name relative to the image folder (its stem also matches), ``r,g,b`` the
camera RGB of the light (any scale; only its direction is used).
"""

from __future__ import annotations

import csv
import os
from collections.abc import Iterable
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from ccjax.io.reading import list_images


def read_ground_truth(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a ground-truth CSV with header ``image,r,g,b`` (camera RGB of the light, any scale).

    Returns:
        ``{image name: (3,) float64}``.

    Raises:
        FileNotFoundError: no such file.
        ValueError: wrong header, a row that is not finite, non-negative and non-zero, or no rows.
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


def write_ground_truth(path: str | os.PathLike, names: Iterable[str], illuminants: ArrayLike) -> None:
    """Write ``image,r,g,b`` rows (see :func:`read_ground_truth`), 9 significant digits."""
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["image", "r", "g", "b"])
        for name, rgb in zip(names, np.asarray(illuminants, np.float64)):
            writer.writerow([name, *(f"{v:.9g}" for v in rgb)])


def match_ground_truth(truth: dict[str, np.ndarray], directory: str | os.PathLike) -> list[tuple[Path, np.ndarray]]:
    """Pair each ground-truth row with its file in ``directory`` (by relative name, then by stem).

    Returns:
        ``[(file, (3,) light), ...]`` in the order of ``truth``.

    Raises:
        FileNotFoundError: no such folder.
        ValueError: rows whose image is not in the folder.
    """
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
