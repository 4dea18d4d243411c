"""An advisory lock on folders while several files that belong together are put in place.

Two processes writing the same pair of files (two ``correct --overwrite`` runs of one output, two
trainings of one model) could otherwise interleave their renames and leave the image of one beside
the preview of the other. The lock is ``flock`` on each folder itself, so nothing is created in
the folder.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterable, Iterator
from pathlib import Path

__all__ = ["folders_locked"]


@contextlib.contextmanager
def folders_locked(folders: Iterable[Path]) -> Iterator[None]:
    """Hold an exclusive advisory lock (``flock``) on each folder for the body of the ``with``.

    The folders are locked in sorted order, so two writers locking overlapping sets cannot
    deadlock. Where ``flock`` is missing (Windows) or a folder cannot be opened or locked, the body
    runs without that folder's lock, as an unlocked write would.

    Arguments:
        folders: the folders to lock (repeats are locked once).

    Returns:
        A context manager; the locks are released (the descriptors closed) when it exits.
    """
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows has no flock
        yield
        return
    with contextlib.ExitStack() as stack:
        for folder in sorted({Path(folder) for folder in folders}):
            try:
                descriptor = os.open(folder, os.O_RDONLY)
            except OSError:
                continue
            stack.callback(os.close, descriptor)
            try:
                fcntl.flock(descriptor, fcntl.LOCK_EX)
            except OSError:
                continue
        yield
