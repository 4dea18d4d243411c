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
from ccjax._numbers import decimal, first_not_decimal, whole
from ccjax.io.files import write_file
from ccjax.io.reading import list_images


def _check_names(path: Path, lines: dict[str, int]) -> None:
    """Refuse an empty image name, an absolute one, or one that climbs out of the folder (``lines``:
    each name's line), the first in file order."""
    for name, line in lines.items():
        if not name or "\0" in name or name.startswith(("/", "\\")) or ".." in name:
            _check_name(path, line, name)  # (a call for every name costs more than the test)


def _check_name(path: Path, line: int, name: str) -> None:
    """Refuse an empty image name, an absolute one, or one that climbs out of the folder."""
    if not name:
        raise ValueError(f"ground truth: {path} line {line}: the image name is empty")
    if "\0" in name:
        # A file name never holds a NUL byte: the operating system refuses it, and the message
        # it gives ("embedded null byte") would name neither the file nor the line.
        raise ValueError(f"ground truth: {path} line {line}: image {name!r} contains a NUL byte")
    pure = PurePath(name)
    if pure.is_absolute() or name.startswith(("/", "\\")) or ".." in pure.parts:
        raise ValueError(
            f"ground truth: {path} line {line}: image {name!r} must be a name relative to the image folder "
            "(no absolute path, no '..')"
        )


def csv_error_message(path: str | os.PathLike, line: int, error: Exception) -> str:
    """The one-line message of a ``csv.Error`` met while reading a ground-truth file (a field past
    Python's ``csv.field_size_limit``, a stray quote character), naming the file and the line.

    Arguments:
        path: the CSV file.
        line: the line the reader had reached (``csv.reader``'s ``line_num``).
        error: the ``csv.Error``.

    Returns:
        ``"ground truth: <path> line <n>: not readable as CSV (<reason>)"``.
    """
    reason = str(error)
    if "field limit" in reason:
        reason = f"a field is longer than {csv.field_size_limit():,} characters"
    return f"ground truth: {path} line {max(line, 1)}: not readable as CSV ({reason})"


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
        ValueError: wrong header; a line that is not readable as CSV (a field longer than
            ``csv.field_size_limit``; the line is named); a row with more fields than the header; a
            row that is not finite, non-negative and non-zero; a fold that is not an integer; an
            empty, absolute or ``..`` image name, or one with a NUL byte; the same image on two
            rows (both lines are named); or no rows.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"ground truth: no such file: {path}")
    try:
        limits.check_csv(path)
    except ValueError as error:
        raise ValueError(f"ground truth: {error}") from None
    folds: dict[str, int] = {}
    lines: dict[str, int] = {}  # each image's line, in file order
    cells: list[str] = []  # r, g, b of every row
    last_line = limits.CSV_ROWS.value + 1  # the header is line 1
    with open(path, newline="", encoding="utf-8-sig") as handle:
        reader = csv.DictReader(handle)
        try:
            fieldnames = reader.fieldnames
        except UnicodeDecodeError as error:
            raise ValueError(f"ground truth: {path} is not UTF-8 text ({error.reason})") from None
        except csv.Error as error:
            # The DictReader's own line_num is the last row it returned; its reader's is this one.
            raise ValueError(csv_error_message(path, reader.reader.line_num, error)) from None
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
                if line > last_line:
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
                cells.extend((row["r"], row["g"], row["b"]))
                name = row["image"].strip()
                if name in lines:
                    raise ValueError(f"ground truth: {path} lines {lines[name]} and {line} both give image {name!r}")
                if fold_column is not None:
                    try:
                        folds[name] = whole(fold)  # type: ignore[arg-type]
                    except (TypeError, ValueError):
                        raise ValueError(
                            f"ground truth: {path} line {line}: fold must be an integer, got {fold!r}"
                        ) from None
                lines[name] = line
        except UnicodeDecodeError as error:
            raise ValueError(f"ground truth: {path} is not UTF-8 text ({error.reason})") from None
        except csv.Error as error:
            # The DictReader's own line_num is the last row it returned; its reader's is this one.
            raise ValueError(csv_error_message(path, reader.reader.line_num, error)) from None
    if not lines:
        raise ValueError(f"ground truth: {path} has no rows")
    # The names and the numbers are checked at once (a call a cell cost more than the parsing);
    # the first that fails is then checked alone, for its message and its line.
    images = list(lines)
    _check_names(path, lines)
    bad = first_not_decimal(cells)
    if bad is not None:
        try:
            decimal(cells[bad])
        except ValueError as error:
            line = lines[images[bad // 3]]
            raise ValueError(f"ground truth: {path} line {line}: r,g,b must be decimal numbers ({error})") from None
    lights = np.array([float(cell) for cell in cells], np.float64).reshape(-1, 3)
    for index in np.flatnonzero(~_usable_lights(lights))[:1]:
        _check_light(path, lines[images[index]], lights[index])
    return GroundTruth(dict(zip(images, lights, strict=True)), None if fold_column is None else folds)


def _usable_lights(lights: np.ndarray) -> np.ndarray:
    """Which rows of ``(n, 3)`` ``lights`` are finite, non-negative, not all zero, and within the
    magnitudes of :func:`ccjax.limits.check_magnitudes`."""
    with np.errstate(invalid="ignore", over="ignore"):
        magnitude = np.abs(lights)
        return (
            np.all(np.isfinite(lights), axis=1)
            & np.all(lights >= 0, axis=1)
            & (lights.sum(axis=1) > 0)
            & np.all(magnitude <= limits.VALUE.value, axis=1)
            & ~np.any((magnitude > 0) & (magnitude < limits.SMALLEST_NORMAL), axis=1)
        )


def _check_light(path: Path, line: int, rgb: np.ndarray) -> None:
    """Refuse one row's light that :func:`_usable_lights` refuses, naming the file and line."""
    if not np.all(np.isfinite(rgb)) or np.any(rgb < 0) or rgb.sum() <= 0:
        raise ValueError(f"ground truth: {path} line {line}: r,g,b must be finite, non-negative, not all zero")
    limits.check_magnitudes(rgb, f"ground truth: {path} line {line}: r,g,b")


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
        ValueError: rows whose image is not in the folder; a name outside the folder or with a
            NUL byte; a stem that
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
        if "\0" in name:
            # The file system would refuse it with "embedded null byte", naming neither the row nor the folder.
            raise ValueError(f"ground truth: row {name!r} contains a NUL byte; no file in {directory} has that name")
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
