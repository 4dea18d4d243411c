"""Ctrl-C held over a short critical section (standard library only: the command line imports it
before JAX)."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator


@contextlib.contextmanager
def interrupts_held() -> Iterator[None]:
    """Hold Ctrl-C (SIGINT) while the block runs and raise ``KeyboardInterrupt`` right after it.

    For work that must not stop half-way: writing a file through a temporary name (an interrupt
    between creating the temporary file and the ``try`` that removes it would leave it behind), or
    importing an extension module (an interrupted initialisation is not always an ordinary
    exception). Outside the main thread, or when SIGINT has a handler other than Python's default
    (the caller's own), the block runs as it is.

    Returns:
        A context manager.

    Raises:
        KeyboardInterrupt: after the block, when Ctrl-C came during it (also in place of an
            exception the block raised: the user asked to stop).
    """
    if threading.current_thread() is not threading.main_thread() or (
        signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    ):
        yield
        return
    received: list[int] = []
    signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        if received:
            raise KeyboardInterrupt
