"""Ground-truth files: CSV with the header ``image,r,g,b``.

``image`` is the file name relative to the image folder (its stem also matches), ``r,g,b`` the
camera RGB of the light (any scale; only its direction is used). The first column may also be
called ``file`` (the Gehler–Shi files' header is ``File,R,G,B,Fold``). Further header columns are
ignored except an optional ``fold`` column (:func:`read_ground_truth_file` returns it with the
lights, so the file is parsed once); a row with more fields
than the header, a name given twice, two names that resolve to one file (``im0`` and ``im0.png``),
and absolute or ``..`` names are errors. A UTF-8 byte-order mark (as spreadsheet programs write)
is accepted.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path, PurePath

import numpy as np
from numpy.typing import ArrayLike

from ccjax import limits
from ccjax._numbers import decimal, whole
from ccjax.io.files import write_file
from ccjax.io.reading import list_images


def _check_name(path: Path, line: int, name: str) -> None:
    """Refuse an empty image name, an absolute one, or one that climbs out of the folder."""
    if not name:
        raise ValueError(f"ground truth: {path} line {line}: the image name is empty")
    pure = PurePath(name)
    if pure.is_absolute() or name.startswith(("/", "\\")) or ".." in pure.parts:
        raise ValueError(
            f"ground truth: {path} line {line}: image {name!r} must be a name relative to the image folder "
            "(no absolute path, no '..')"
        )


@dataclass(frozen=True)
class GroundTruth:
    """The rows of a ground-truth CSV.

    Attributes:
        lights: ``{image name: (3,) float64}`` camera RGB of each image's light, in file order.
        folds: ``{image name: fold label}`` from the file's ``fold`` column (any integers, as in
            the Gehler–Shi ``File,R,G,B,Fold`` files), or ``None`` when it has none.
    """

    lights: dict[str, np.ndarray]
    folds: dict[str, int] | None = None


def read_ground_truth_file(path: str | os.PathLike, *, with_folds: bool = True) -> GroundTruth:
    """Read a ground-truth CSV once: its lights and its optional ``fold`` column.

    The header is ``image,r,g,b`` or ``file,r,g,b`` (camera RGB of the light, any scale), then
    any columns; a column named ``fold`` (any case) gives each image's fold.

    Arguments:
        path: the CSV file (UTF-8, with or without a byte-order mark).
        with_folds: read the ``fold`` column (False: it is ignored like any other column, and
            ``folds`` is None).

    Returns:
        :class:`GroundTruth`.

    Raises:
        FileNotFoundError: no such file.
        ValueError: wrong header; a row with more fields than the header; a row that is not finite,
            non-negative and non-zero; a fold that is not an integer; an empty, absolute or ``..``
            image name; the same image on two rows (both lines are named); or no rows.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"ground truth: no such file: {path}")
    try:
        limits.check_csv(path)
    except ValueError as error:
        raise ValueError(f"ground truth: {error}") from None
    truth: dict[str, np.ndarray] = {}
    folds: dict[str, int] = {}
    lines: dict[str, int] = {}
    with open(path, newline="", encoding="utf-8-sig") as handle:
        reader = csv.DictReader(handle)
        try:
            fieldnames = reader.fieldnames
        except UnicodeDecodeError as error:
            raise ValueError(f"ground truth: {path} is not UTF-8 text ({error.reason})") from None
        names = [f.strip().lower() for f in fieldnames or []]
        header = names[:4]
        if header[:1] == ["file"]:
            header[0] = "image"
        if fieldnames is None or header != ["image", "r", "g", "b"]:
            raise ValueError(f"ground truth: {path} must have the header image,r,g,b (or file,r,g,b; got {fieldnames})")
        fold_column = fieldnames[names.index("fold")] if with_folds and "fold" in names else None
        try:
            for row in reader:
                line = reader.line_num
                try:
                    limits.check_csv(path, line)
                except ValueError as error:
                    raise ValueError(f"ground truth: {error}") from None
                if None in row:
                    raise ValueError(
                        f"ground truth: {path} line {line}: {len(fieldnames) + len(row[None])} fields, "
                        f"the header has {len(fieldnames)}"
                    )
                fold = None if fold_column is None else row[fold_column]
                row = dict(zip(["image", "r", "g", "b"], (row[k] for k in fieldnames[:4]), strict=True))
                try:
                    rgb = np.array([decimal(row["r"]), decimal(row["g"]), decimal(row["b"])])
                except (TypeError, ValueError) as error:
                    raise ValueError(
                        f"ground truth: {path} line {line}: r,g,b must be decimal numbers ({error})"
                    ) from None
                if not np.all(np.isfinite(rgb)) or np.any(rgb < 0) or rgb.sum() <= 0:
                    raise ValueError(
                        f"ground truth: {path} line {line}: r,g,b must be finite, non-negative, not all zero"
                    )
                limits.check_magnitudes(rgb, f"ground truth: {path} line {line}: r,g,b")
                name = row["image"].strip()
                _check_name(path, line, name)
                if name in truth:
                    raise ValueError(f"ground truth: {path} lines {lines[name]} and {line} both give image {name!r}")
                if fold_column is not None:
                    try:
                        folds[name] = whole(fold)  # type: ignore[arg-type]
                    except (TypeError, ValueError):
                        raise ValueError(
                            f"ground truth: {path} line {line}: fold must be an integer, got {fold!r}"
                        ) from None
                truth[name], lines[name] = rgb, line
        except UnicodeDecodeError as error:
            raise ValueError(f"ground truth: {path} is not UTF-8 text ({error.reason})") from None
    if not truth:
        raise ValueError(f"ground truth: {path} has no rows")
    return GroundTruth(truth, None if fold_column is None else folds)


def read_ground_truth(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """The lights of a ground-truth CSV (:func:`read_ground_truth_file` without the folds).

    Arguments:
        path: the CSV file (UTF-8, with or without a byte-order mark).

    Returns:
        ``{image name: (3,) float64}`` in file order.

    Raises:
        FileNotFoundError: no such file.
        ValueError: as :func:`read_ground_truth_file`.
    """
    return read_ground_truth_file(path, with_folds=False).lights


def write_ground_truth(path: str | os.PathLike, names: Iterable[str], illuminants: ArrayLike) -> None:
    """Write ``image,r,g,b`` rows (see :func:`read_ground_truth`), 9 significant digits, atomically.

    Arguments:
        path: the CSV file (written through a temporary file in the same folder).
        names: image names relative to the image folder.
        illuminants: ``(N, 3)`` camera RGB of each image's light.
    """
    text = io.StringIO(newline="")
    writer = csv.writer(text)
    writer.writerow(["image", "r", "g", "b"])
    for name, rgb in zip(names, np.asarray(illuminants, np.float64)):
        writer.writerow([name, *(f"{v:.9g}" for v in rgb)])
    write_file(path, text.getvalue())


def match_ground_truth(truth: dict[str, np.ndarray], directory: str | os.PathLike) -> list[tuple[Path, np.ndarray]]:
    """Pair each ground-truth row with its file in ``directory`` (by relative name, then by stem).

    Arguments:
        truth: ``{image name: (3,) light}`` (:func:`read_ground_truth`).
        directory: the image folder.

    Returns:
        ``[(file, (3,) light), ...]`` in the order of ``truth``.

    Raises:
        FileNotFoundError: no such folder.
        ValueError: rows whose image is not in the folder; a name outside the folder; a stem that
            matches several files (``a.png`` and ``a.tif``); two rows that resolve to the same file
            (``im0`` and ``im0.png``; both rows are named).
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise FileNotFoundError(f"images: no such folder: {directory}")
    root = directory.resolve()
    by_stem: dict[str, list[Path]] = {}
    for file in list_images([directory]):
        by_stem.setdefault(file.stem, []).append(file)
    pairs, missing = [], []
    claimed: dict[Path, str] = {}
    for name, rgb in truth.items():
        candidate = directory / name
        if not candidate.resolve().is_relative_to(root):
            raise ValueError(f"ground truth: row {name!r} points outside the image folder {directory}")
        if candidate.is_file():
            file = candidate
        elif PurePath(name).stem in by_stem:
            files = by_stem[PurePath(name).stem]
            if len(files) > 1:
                raise ValueError(
                    f"ground truth: row {name!r} matches {len(files)} files in {directory} "
                    f"({', '.join(f.name for f in files)}); give the file name with its suffix"
                )
            file = files[0]
        else:
            missing.append(name)
            continue
        key = file.resolve()
        if key in claimed:
            raise ValueError(
                f"ground truth: rows {claimed[key]!r} and {name!r} are the same image {file} (conflicting stems)"
            )
        claimed[key] = name
        pairs.append((file, rgb))
    if missing:
        raise ValueError(f"ground truth: {len(missing)} image(s) not found in {directory}, e.g. {missing[:3]}")
    return pairs


def unlisted_images(pairs: Iterable[tuple[Path, np.ndarray]], directory: str | os.PathLike) -> list[Path]:
    """The image files of ``directory`` that no ground-truth row names.

    Arguments:
        pairs: :func:`match_ground_truth`'s ``(file, light)`` pairs.
        directory: the image folder.

    Returns:
        The files, sorted (empty when every image has its row).
    """
    listed = {file.resolve() for file, _ in pairs}
    return [file for file in list_images([directory]) if file.resolve() not in listed]
