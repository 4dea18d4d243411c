"""Calibration data files for ``ccjax calibrate`` and fitted-sensor output.

Format of a calibration file (CSV, one measurement per line):

* optional lines starting with ``#`` (comments);
* an optional header ``380,384,...,780,R,G,B`` (the 101 wavelengths of
  :data:`ccjax.spectra.WAVELENGTHS` in nm, then ``R,G,B``);
* then rows of 104 numbers: the measured spectrum (e.g. radiance from a spectroradiometer) at the 101
  wavelengths, followed by the camera's raw R, G, B for the same patch (e.g. 0–255 pixel values,
  averaged over a window and frames). Clipped measurements should be left out.

Every value must be finite and non-negative; errors name the line and the column.
"""

from __future__ import annotations

import csv
import io
import os
from dataclasses import dataclass

import numpy as np

from ccjax import limits
from ccjax.spectra import N_WAVELENGTHS, WAVELENGTHS

MIN_ROWS = 12
"""Fewest measurements a calibration file may hold (the thesis' smallest robustness subset is 15)."""

COLUMNS = tuple(f"{w:g}" for w in WAVELENGTHS) + ("R", "G", "B")


class CalibrationFileError(ValueError):
    """A malformed calibration file; the message names the line and column."""


@dataclass(frozen=True)
class CalibrationData:
    """Measurements read from a file: ``spectra (M, 101)``, raw ``responses (M, 3)``, source lines.

    Attributes:
        spectra: ``(M, 101)`` measured spectra on the ccjax grid.
        responses: ``(M, 3)`` raw camera responses.
        lines: ``(M,)`` the file's line number of each measurement.
    """

    spectra: np.ndarray
    responses: np.ndarray
    lines: np.ndarray  # (M,) 1-based line numbers in the file


def _column_name(index: int) -> str:
    return (
        f"{index + 1} ({COLUMNS[index]} {'nm' if index < N_WAVELENGTHS else 'response'})"
        if index < len(COLUMNS)
        else str(index + 1)
    )


def read_calibration_csv(path: str | os.PathLike, *, min_rows: int = MIN_ROWS) -> CalibrationData:
    """Read and validate a calibration file (format in the module docstring).

    Raises:
        CalibrationFileError: wrong column count, a value that is not a number, non-finite or
            negative (naming line and column), a header that does not match the grid, a line
            that is not readable as CSV (a field past ``csv.field_size_limit``), bytes that are not
            text, or fewer than ``min_rows`` measurements.
        FileNotFoundError: the file does not exist.

    Arguments:
        path: the CSV file.
        min_rows: the least number of measurements accepted.

    Returns:
        The :class:`CalibrationData`.
    """
    path = os.fspath(path)
    rows: list[list[float]] = []
    lines: list[int] = []
    limits.check_csv(path)
    with open(path, newline="") as f:
        reader = csv.reader(f)
        try:
            for line_number, fields in enumerate(reader, start=1):
                limits.check_csv(path, line_number)
                if not fields or not "".join(fields).strip() or fields[0].lstrip().startswith("#"):
                    continue
                fields = [field.strip() for field in fields]
                if not rows and not lines and _is_header(fields):
                    _check_header(path, line_number, fields)
                    continue
                if len(fields) != len(COLUMNS):
                    raise CalibrationFileError(
                        f"{path}: line {line_number}: expected {len(COLUMNS)} columns (101 spectrum samples at "
                        f"380..780 nm in 4 nm steps, then R,G,B), found {len(fields)}"
                    )
                values = []
                for column, text in enumerate(fields):
                    try:
                        value = float(text)
                    except ValueError:
                        raise CalibrationFileError(
                            f"{path}: line {line_number}, column {_column_name(column)}: not a number: {text!r}"
                        ) from None
                    if not np.isfinite(value):
                        raise CalibrationFileError(
                            f"{path}: line {line_number}, column {_column_name(column)}: not a finite number: {text!r}"
                        )
                    if value < 0:
                        raise CalibrationFileError(
                            f"{path}: line {line_number}, column {_column_name(column)}: negative value {value:g}"
                        )
                    values.append(value)
                rows.append(values)
                lines.append(line_number)
        except csv.Error as error:
            # A field past Python's csv.field_size_limit or a stray quote: one line naming the file
            # and the line (the reader's line_num is the line it stopped at).
            reason = str(error)
            if "field limit" in reason:
                reason = f"a field is longer than {csv.field_size_limit():,} characters"
            raise CalibrationFileError(
                f"{path}: line {max(reader.line_num, 1)}: not readable as CSV ({reason})"
            ) from None
        except UnicodeDecodeError as error:
            raise CalibrationFileError(
                # Text is decoded in blocks of many lines: the bad byte's line is not known here.
                f"{path}: not text in the locale's encoding ({error.reason})"
            ) from None
    if len(rows) < min_rows:
        raise CalibrationFileError(
            f"{path}: {len(rows)} measurement rows; at least {min_rows} are needed to fit sensors"
        )
    table = np.asarray(rows, dtype=np.float64)
    spectra, responses = table[:, :N_WAVELENGTHS], table[:, N_WAVELENGTHS:]
    for k in range(3):
        if np.all(responses[:, k] == 0):
            raise CalibrationFileError(f"{path}: column {_column_name(N_WAVELENGTHS + k)}: every response is 0")
    empty = np.flatnonzero(spectra.sum(axis=1) == 0)
    if empty.size:
        raise CalibrationFileError(f"{path}: line {lines[empty[0]]}: the spectrum is zero at every wavelength")
    return CalibrationData(spectra=spectra, responses=responses, lines=np.asarray(lines))


def _is_header(fields: list[str]) -> bool:
    try:
        [float(x) for x in fields]
    except ValueError:
        return True
    return False


def _check_header(path: str, line_number: int, fields: list[str]) -> None:
    if len(fields) != len(COLUMNS):
        raise CalibrationFileError(
            f"{path}: line {line_number} (header): expected {len(COLUMNS)} columns "
            f"(380,384,...,780,R,G,B), found {len(fields)}"
        )
    for column, (got, want) in enumerate(zip(fields, COLUMNS)):
        if column < N_WAVELENGTHS:
            try:
                ok = abs(float(got) - float(want)) < 1e-6
            except ValueError:
                ok = False
        else:
            ok = got.upper() == want
        if not ok:
            raise CalibrationFileError(
                f"{path}: line {line_number} (header), column {column + 1}: expected {want!r}, found {got!r}"
            )


def write_calibration_csv(
    path: str | os.PathLike, spectra: np.ndarray, responses: np.ndarray, *, overwrite: bool = True
) -> None:
    """Write measurements in the calibration-file format (with the header), atomically
    (:func:`ccjax.io.writing.write_file`).

    Arguments:
        path: the CSV file to write.
        spectra: ``(M, 101)`` spectra.
        responses: ``(M, 3)`` raw responses.
        overwrite: replace a file already at ``path``.
    """
    spectra = np.asarray(spectra, dtype=np.float64)
    responses = np.asarray(responses, dtype=np.float64)
    if spectra.ndim != 2 or spectra.shape[1] != N_WAVELENGTHS or responses.shape != (spectra.shape[0], 3):
        raise ValueError(
            f"spectra/responses: expected (M, {N_WAVELENGTHS}) and (M, 3), got {spectra.shape} and {responses.shape}"
        )
    from ccjax.io.writing import write_file

    text = io.StringIO(newline="")
    writer = csv.writer(text)
    writer.writerow(COLUMNS)
    for s, r in zip(spectra, responses):
        writer.writerow([f"{v:.9g}" for v in np.concatenate([s, r])])
    write_file(path, text.getvalue(), overwrite=overwrite)


def write_sensors_csv(
    path: str | os.PathLike, sensors: np.ndarray, linearisation=None, *, overwrite: bool = True
) -> None:
    """Write fitted curves as ``wavelength_nm,R,G,B`` (101 rows); the linearisation, if any, as a
    leading ``#`` comment; atomically (:func:`ccjax.io.writing.write_file`: through a temporary
    file, never through a symbolic link).

    Arguments:
        path: the CSV file to write.
        sensors: ``(101, 3)`` sensor curves.
        linearisation: an optional :class:`Linearisation` written as a comment.
        overwrite: replace a file already at ``path``.
    """
    from ccjax.io.writing import write_file

    sensors = np.asarray(sensors, dtype=np.float64)
    text = io.StringIO(newline="")
    if linearisation is not None:
        text.write(
            "# F(x) = x - a0 - a1 exp(-C (x - b)) per channel: "
            f"a0={list(linearisation.a0)} a1={list(linearisation.a1)} "
            f"C={list(linearisation.exp_rate)} b={list(linearisation.black)}\n"
        )
    writer = csv.writer(text)
    writer.writerow(["wavelength_nm", "R", "G", "B"])
    for w, row in zip(WAVELENGTHS, sensors):
        writer.writerow([f"{w:g}"] + [f"{v:.9g}" for v in row])
    write_file(path, text.getvalue(), overwrite=overwrite)
