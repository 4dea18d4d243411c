"""Output files written atomically: every file ccjax writes (images, previews, ground truth,
reports, plots) goes through :func:`write_file`, so readers never see a partial file."""

from __future__ import annotations

import io
import os
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

from ccjax._cache import atomic_write
from ccjax._signals import interrupts_held


def write_file(
    path: str | os.PathLike, data: bytes | str | Callable[[BinaryIO], object], *, overwrite: bool = True
) -> None:
    """Write ``data`` to ``path`` atomically: through a temporary file in the same folder renamed into
    place, so an interrupted write never leaves a partial file under ``path`` and an old file is only
    replaced once the new one is complete. Ctrl-C during the write is held until the file is in
    place (then raised), so it never leaves the temporary file behind either; a killed process
    (SIGKILL) can leave one, named ``.<name>.<random>``, never a partial file under ``path``.

    Arguments:
        path: the file (missing folders are created).
        data: the contents; text is encoded as UTF-8; a function of the open binary file
            writes them itself (large files are streamed, never held in memory twice).
        overwrite: replace a file already at ``path`` (else ``FileExistsError``:
            :func:`ccjax.io.outputs.put_in_place`).

    Returns:
        None.
    """
    blob = data.encode("utf-8") if isinstance(data, str) else data if callable(data) else bytes(data)
    with interrupts_held():
        atomic_write(Path(path), blob, replace=overwrite)


FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")
"""First characters with which a spreadsheet reads a CSV cell as a formula (OWASP, "CSV injection")."""


def csv_text_cell(value):
    """A text cell of a CSV report made safe to open in a spreadsheet: a string starting with one of
    :data:`FORMULA_STARTS` (a file named ``=HYPERLINK(...).png``) gets a leading ``'``, which
    spreadsheets show as text; numbers and other values are returned as they are.

    Arguments:
        value: a cell's value.

    Returns:
        The value, neutralised when it is such a string.
    """
    return "'" + value if isinstance(value, str) and value.startswith(FORMULA_STARTS) else value


def new_figure(**options):
    """A matplotlib figure of its own, outside pyplot: no GUI backend is chosen, nothing has to be
    closed, and pyplot (half a second to import) is not loaded. Saved by :func:`write_figure`.

    Arguments:
        options: ``matplotlib.figure.Figure`` keywords (``figsize``).

    Returns:
        The ``Figure``; ``figure.subplots(...)`` gives its axes.
    """
    from matplotlib.figure import Figure

    return Figure(**options)


def write_figure(figure, path, **options) -> None:
    """Save a matplotlib figure atomically: rendered into memory, then :func:`write_file`, so an
    interrupted run never leaves a partial plot and an old plot is replaced only by a whole one.

    Arguments:
        figure: a ``matplotlib.figure.Figure``.
        path: the file; its suffix names the format (``.png``, ``.pdf``, ``.svg``...). A binary file
            object is passed to ``savefig`` as it is (PNG unless ``format`` is given).
        options: further ``savefig`` keywords (``dpi``, ``bbox_inches``).

    Returns:
        None.

    Raises:
        ValueError: ``path`` has no suffix, or matplotlib has no such format.
    """
    if hasattr(path, "write"):
        figure.savefig(path, **options)
        return
    path = Path(path)
    if not path.suffix:
        raise ValueError(f"plot: {path} has no suffix naming the image format (such as .png)")
    buffer = io.BytesIO()
    figure.savefig(buffer, format=path.suffix[1:].lower(), **options)
    write_file(path, buffer.getvalue())
