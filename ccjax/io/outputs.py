"""Output files: the one rule of every command that writes.

* Outputs never name an input or each other (compared absolute, links resolved, case folded:
  :func:`path_key`).
* They are checked before any work (:func:`check_outputs`): a folder, a symbolic link, a file
  that exists without ``overwrite``, or a folder that cannot be written is refused then, not
  after an hour of estimation.
* They are written through a temporary file in the same folder and put in place without
  replacing a file that appeared since the check (a hard link, which never replaces, then the
  temporary name removed: :func:`put_in_place`) unless ``overwrite``; a reader never sees a
  partial file.
* Never through a symbolic link: a link at an output path is refused by the check, and putting
  in place acts on the name itself, never on what a link points to.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from ccjax._cache import put_in_place

__all__ = [
    "STANDARD_OUTPUT",
    "check_output_file",
    "check_output_folder",
    "check_outputs",
    "path_key",
    "put_in_place",
]

STANDARD_OUTPUT = "-"
"""The path that names standard output (always accepted, never a file)."""


def path_key(path: str | os.PathLike) -> str:
    """A comparison key for ``path``: absolute, symbolic links resolved, case folded (two outputs
    differing only in case would overwrite each other on case-insensitive file systems).

    Arguments:
        path: any path.

    Returns:
        The key.
    """
    return str(Path(path).resolve()).casefold()


def check_output_folder(folder: str | os.PathLike, option: str, *, written: str | os.PathLike | None = None) -> None:
    """Refuse an output folder that cannot be written (or created), before any work is done.

    Arguments:
        folder: the folder (may not exist yet if its nearest existing ancestor is writable).
        option: the argument's name for the message.
        written: the file to be written there, for the message (default: the folder).

    Returns:
        None.

    Raises:
        ValueError: ``folder`` or an ancestor is a file, or the nearest existing one is not writable.
    """
    folder = Path(folder).absolute()
    written = folder if written is None else written
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise ValueError(f"{option}: {written} cannot be written: {existing} is not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ValueError(f"{option}: {written} cannot be written: folder {existing} is not writable")


def check_output_file(path: str | os.PathLike, option: str, *, overwrite: bool) -> None:
    """Refuse an output file that cannot or must not be written, before any work is done.

    Arguments:
        path: the output file (:data:`STANDARD_OUTPUT` is always accepted).
        option: the argument's name for the message (``"--json"``, ``"output"``).
        overwrite: whether an existing file may be replaced.

    Returns:
        None.

    Raises:
        ValueError: ``path`` is a symbolic link or a folder, exists while ``overwrite`` is false,
            or its folder is missing or not writable.
    """
    if str(path) == STANDARD_OUTPUT:
        return
    path = Path(path)
    if path.is_symlink():
        raise ValueError(f"{option}: {path} is a symbolic link; outputs are never written through one (remove it)")
    if path.is_dir():
        raise ValueError(f"{option}: {path} is a folder; give a file name")
    if path.exists() and not overwrite:
        raise ValueError(f"{option}: {path} exists (use --overwrite to replace it)")
    check_output_folder(path.parent, option, written=path)


def check_outputs(
    inputs: Iterable[str | os.PathLike],
    outputs: Iterable[tuple[str, str | os.PathLike | None]],
    *,
    overwrite: bool,
) -> None:
    """The whole check of a command's outputs, before any work: none names an input or another
    output, and each can be written (:func:`check_output_file`).

    Arguments:
        inputs: every file the command reads.
        outputs: ``(option, path)`` of every file it writes (None paths: not asked for;
            :data:`STANDARD_OUTPUT` is not a file).
        overwrite: whether existing outputs may be replaced.

    Returns:
        None.

    Raises:
        ValueError: naming the option and the paths.
    """
    files = [(option, path) for option, path in outputs if path is not None and str(path) != STANDARD_OUTPUT]
    read = {path_key(path): Path(path) for path in inputs}
    written: dict[str, tuple[str, Path]] = {}
    for option, path in files:
        key = path_key(path)
        if key in read:
            raise ValueError(f"{option}: {path} would overwrite the input {read[key]}")
        if key in written:
            other, first = written[key]
            raise ValueError(f"{option}: {path} and {other} {first} are the same file")
        written[key] = (option, Path(path))
    for option, path in files:
        check_output_file(path, option, overwrite=overwrite)
