"""Ctrl-C and SIGTERM held over a short critical section, and SIGTERM as an exception (standard
library only: the command line imports it before JAX)."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator


class Terminated(KeyboardInterrupt):
    """SIGTERM received by a command that asked for it as an exception (:func:`terminate_cleanly`):
    a ``KeyboardInterrupt``, so every clean-up that Ctrl-C runs (temporary files removed, outputs
    left whole) runs for it too; the command then exits with 143 (128 + SIGTERM)."""


def _raise_terminated(signum, frame) -> None:
    raise Terminated


def terminate_cleanly() -> None:
    """Make SIGTERM raise :class:`Terminated` in the main thread (instead of killing the process
    at once, which leaves temporary files behind and an output pair half replaced). Call it from
    the main thread of a process that runs one command.

    Returns:
        None.
    """
    signal.signal(signal.SIGTERM, _raise_terminated)


@contextlib.contextmanager
def interrupts_held() -> Iterator[None]:
    """Hold Ctrl-C (SIGINT), and SIGTERM where :func:`terminate_cleanly` made it an exception, while
    the block runs, and raise the first one received right after it.

    For work that must not stop half-way: writing a file through a temporary name (an interrupt
    between creating the temporary file and the ``try`` that removes it would leave it behind),
    putting a pair of files in place (both or neither), or importing an extension module (an
    interrupted initialisation is not always an ordinary exception). Outside the main thread, or
    when SIGINT has a handler other than Python's default (the caller's own), the block runs as
    it is.

    Returns:
        A context manager.

    Raises:
        KeyboardInterrupt: after the block, when Ctrl-C came during it (:class:`Terminated` for
            SIGTERM; also in place of an exception the block raised: the user asked to stop).
    """
    if threading.current_thread() is not threading.main_thread() or (
        signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    ):
        yield
        return
    term = signal.getsignal(signal.SIGTERM) is _raise_terminated
    received: list[int] = []
    signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    if term:
        signal.signal(signal.SIGTERM, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        if term:
            signal.signal(signal.SIGTERM, _raise_terminated)
        if received:
            raise Terminated if received[0] == signal.SIGTERM else KeyboardInterrupt
