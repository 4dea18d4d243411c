"""The ``ccjax`` command line: parse, call the library, format.

One module per command group; each declares ``add_<command>(subparsers)`` (its arguments) and
``run_<command>(args)`` and lists its ``add_`` functions in ``COMMANDS``. :func:`main` (the
``ccjax`` entry point) shows the groups in the order of :data:`GROUPS`.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import os
import pathlib
import signal
import sys
import threading
import time
import traceback
import warnings
from typing import TYPE_CHECKING

STARTED = time.perf_counter()
"""When the command line was imported: the start of a command's timing breakdown."""

# Nothing here imports more than the standard library at module level: the console script imports
# this module before :func:`main` can catch Ctrl-C, so the command groups (and through them JAX) are
# imported inside :func:`main` and on first use of ``GROUPS`` / ``COMMANDS`` (PEP 562 ``__getattr__``).
if TYPE_CHECKING:
    import argparse
    from collections.abc import Callable
    from types import ModuleType

    GROUPS: tuple[ModuleType, ...]
    """The command groups, in ``ccjax --help`` order (:func:`groups`, imported on first use)."""
    COMMANDS: list[Callable[..., None]]
    """Every group's ``add_<command>`` functions, in ``ccjax --help`` order (imported on first use)."""


def groups() -> tuple[ModuleType, ...]:
    """The command groups, in ``ccjax --help`` order (``GROUPS``).

    Returns:
        The ``ccjax.cli`` group modules (synthetic, catalogue, photos, indexing, training, sharpen,
        calibrate), imported on this call; each lists its ``add_<command>`` functions in
        ``COMMANDS``.
    """
    from ccjax.cli import calibrate, catalogue, indexing, photos, sharpen, synthetic, training

    return (synthetic, catalogue, photos, indexing, training, sharpen, calibrate)


def __getattr__(name: str) -> object:
    """``GROUPS`` and ``COMMANDS`` (every group's ``add_`` functions)."""
    if name == "GROUPS":
        return groups()
    if name == "COMMANDS":
        return [add for group in groups() for add in group.COMMANDS]
    if not name.startswith("_") and importlib.util.find_spec(f"{__name__}.{name}") is not None:
        return importlib.import_module(f"{__name__}.{name}")  # ``ccjax.cli.photos`` and the other groups
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def build_parser() -> argparse.ArgumentParser:
    """The ``ccjax`` argument parser with every sub-command.

    Returns:
        A new parser (``prog="ccjax"``) whose required sub-command is stored in ``command``; each
        sub-command sets ``func``, the ``run_<command>(args)`` that :func:`main` calls.
    """
    from ccjax._version import __version__
    from ccjax.cli.common import CommandParser

    # A CommandParser, so its sub-commands' parsers are too: their --json / --csv never take a
    # positional argument as PATH.
    parser = CommandParser(
        prog="ccjax",
        description="JAX colour constancy: estimate and correct the colour of the light.",
    )
    parser.add_argument("--version", action="version", version=f"ccjax {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for group in groups():
        for add in group.COMMANDS:
            add(sub)
    parser.commands = dict(sub.choices)  # each command's usage line, for an OptionError
    return parser


def prefix(command: str | None) -> str:
    """``"ccjax <command>"`` for messages, ``"ccjax"`` before the command is known.

    Arguments:
        command: the sub-command's name, or ``None`` (or empty) when it was not parsed yet.

    Returns:
        The prefix for error and interrupt messages, e.g. ``"ccjax compare"``.
    """
    return f"ccjax {command}" if command else "ccjax"


def terminated(error: BaseException) -> bool:
    """Whether ``error`` is SIGTERM's :class:`ccjax._signals.Terminated` or was caused by it.

    Arguments:
        error: the exception that stopped the command.

    Returns:
        True when ``error`` or an exception in its cause/context chain is ``Terminated``.
    """
    from ccjax._signals import Terminated

    return _in_chain(error, Terminated)


def _in_chain(error: BaseException, kind: type[BaseException]) -> bool:
    """Whether ``error`` or an exception in its cause/context chain (followed once each, so a
    cyclic chain ends) is a ``kind``."""
    seen: set[int] = set()
    current: BaseException | None = error
    while current is not None and id(current) not in seen:
        if isinstance(current, kind):
            return True
        seen.add(id(current))
        current = current.__cause__ or current.__context__
    return False


def interrupted(error: BaseException) -> bool:
    """Whether ``error`` is Ctrl-C or was caused by it: a ``KeyboardInterrupt`` raised while an
    extension module initialises (numpy, jaxlib) reaches the caller as an ``ImportError`` whose
    ``__cause__`` / ``__context__`` chain holds it.

    Arguments:
        error: the exception that stopped the command.

    Returns:
        True when ``error`` or any exception in its cause/context chain (followed once each, so a
        cyclic chain ends) is a ``KeyboardInterrupt``.
    """
    return _in_chain(error, KeyboardInterrupt)


def redeliver_interrupts(unraisable) -> None:
    """A ``sys.unraisablehook`` that passes Ctrl-C on instead of swallowing it.

    Python runs the SIGINT handler at the next Python code, which after a long C call (an XLA
    compilation) is often a garbage-collector callback (JAX registers one) or a ``__del__``; an
    exception there cannot propagate, so Python would print "Exception ignored in ..." and go on.
    Instead the interrupt is delivered again a moment later, from a helper thread, to the code that
    runs then (again, until it lands in ordinary code, which stops the command as Ctrl-C should).

    Arguments:
        unraisable: what Python passes to ``sys.unraisablehook``.

    Returns:
        None.
    """
    if isinstance(unraisable.exc_value, KeyboardInterrupt):
        import _thread

        # One Ctrl-C is one interrupt: a single KeyboardInterrupt can be reported by several
        # callbacks in a row, and a second redelivery would arrive after the command has already
        # stopped (an uncaught KeyboardInterrupt at exit kills the process by SIGINT, not 130).
        if any(timer.is_alive() for timer in _REDELIVERIES):
            return
        timer = threading.Timer(0.01, _thread.interrupt_main)
        timer.daemon = True  # never delays the exit
        _REDELIVERIES[:] = [timer]
        timer.start()
    else:
        sys.__unraisablehook__(unraisable)


_REDELIVERIES: list = []
"""The pending redelivery of :func:`redeliver_interrupts` (at most one), cancelled when
:func:`main` returns."""


def import_holding_interrupts(*names: str) -> None:
    """Import modules with Ctrl-C held until they are loaded, then raise it.

    A ``KeyboardInterrupt`` inside an extension module's initialisation is not always an ordinary
    exception: numpy's C API prints it and raises an unrelated ``ImportError`` in jaxlib's
    initialisation, and an interrupted jaxlib has crashed the interpreter (SIGSEGV) at exit. JAX
    is therefore imported whole, and an interrupt received meanwhile is raised right after.

    Arguments:
        names: the modules, imported in this order.

    Returns:
        None.

    Raises:
        KeyboardInterrupt: Ctrl-C came during the imports.
    """
    from ccjax._signals import interrupts_held

    with interrupts_held():
        for name in names:
            __import__(name)  # as the import statement does (``-X importtime`` reports it)


def one_line_warnings(command: str | None, original: Callable[..., str]) -> Callable[..., str]:
    """A ``warnings.formatwarning`` that writes ccjax's own warnings (e.g. a rejected cache entry)
    as one line, ``ccjax <command>: warning: <message>``, JAX's compilation-cache failures (a
    full disk) as one such line for the whole run, and others as ``original`` does.

    Arguments:
        command: the sub-command (for the prefix).
        original: the format used for other warnings.

    Returns:
        The format function.
    """

    said: set[str] = set()

    def format_warning(message, category, filename, lineno, line=None) -> str:
        if category.__module__.startswith("ccjax."):
            return f"{prefix(command)}: warning: {message}\n"
        text = str(message)
        for action, verb in (("reading", "read"), ("writing", "write")):
            # JAX warns once per program when its compilation cache fails (a full disk): say it
            # once, in ccjax's words; the run goes on compiling without the cache.
            if text.startswith(f"Error {action} persistent compilation cache entry"):
                if action in said:
                    return ""
                said.add(action)
                reason = text.split("': ", 1)[-1]
                return (
                    f"{prefix(command)}: warning: cannot {verb} "
                    f"the compilation cache ({reason}); programs are compiled without it\n"
                )
        return original(message, category, filename, lineno, line)

    return format_warning


TRACEBACK_VARIABLE = "CCJAX_TRACEBACK"
"""Set (to anything) in the environment, an unexpected error shows its whole traceback."""


def unexpected_error_line(command: str | None, error: Exception) -> str:
    """One line for an error ccjax did not expect (a bug, not a bad input): the usual prefix, the
    error's type and message, and the place in ccjax it came from, so that a report can name it.

    Arguments:
        command: the subcommand (None: before the arguments were parsed).
        error: the exception.

    Returns:
        ``"ccjax CMD: error: unexpected TypeName at ccjax/FILE.py:LINE: message (...)"``.
    """
    # The place is the deepest frame in the installed package, found by its directory rather than
    # by a "ccjax" path segment: a clone named ccjax holds tests and scripts that are not ccjax.
    package = pathlib.Path(__file__).resolve().parent.parent
    frames = traceback.extract_tb(error.__traceback__)
    place = ""
    for frame in reversed(frames):
        path = pathlib.Path(frame.filename).resolve()
        if path.is_relative_to(package):
            place = f" at ccjax/{path.relative_to(package).as_posix()}:{frame.lineno}"
            break
    else:
        if frames:
            place = f" at {pathlib.Path(frames[-1].filename).name}:{frames[-1].lineno}"
    message = " ".join(str(error).split())[:300] or "(no message)"
    return (
        f"{prefix(command)}: error: unexpected {type(error).__name__}{place}: {message} "
        f"(a ccjax bug: please report it; {TRACEBACK_VARIABLE}=1 shows the traceback)"
    )


def _stop_on_interrupt(command: str | None, whole_process: bool, terminated: bool = False) -> int:
    """The end of a command stopped by Ctrl-C: late interrupts ignored first (when this is the
    process's own command line, on the main thread), then one line, then 130 — or an immediate
    exit when a worker thread would hold the interpreter's exit.

    Arguments:
        command: the command's name, for the line (``None`` before the arguments were read).
        whole_process: ``main`` runs the process (``argv`` not given), so the process may ignore
            SIGINT from now on and exit at once.
        terminated: the stop came from SIGTERM (:class:`ccjax._signals.Terminated`).

    Returns:
        130 (128 + SIGINT), or 143 (128 + SIGTERM) when ``terminated``.
    """
    process = whole_process and threading.current_thread() is threading.main_thread()
    if process:
        # The process is stopping on this interrupt: a late one (a redelivery in flight, a second
        # Ctrl-C) must not turn the exit into death by SIGINT. Ignored before anything else, so
        # that one landing here is the last (main retries this function once it has).
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    for timer in _REDELIVERIES:
        timer.cancel()
    code = 143 if terminated else 130
    print(f"{prefix(command)}: {'terminated' if terminated else 'interrupted'}", file=sys.stderr)
    if process:
        # Stop now, without the interpreter's shutdown: a worker thread still busy (a sweep
        # compiling programs ahead) would hold the exit until it finished, and XLA's own compile
        # threads, invisible to Python, crashed the shutdown (a segmentation fault in 9 of 13
        # `train` runs stopped while compiling). Every file ccjax writes is written atomically and
        # the temporaries are gone by now (their clean-up ran as the interrupt unwound).
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(OSError, ValueError):
                stream.flush()
        os._exit(code)
    return code


def main(argv: list[str] | None = None) -> int:
    """Run ``ccjax`` with ``argv`` (default: the process arguments).

    Errors in arguments, files and folders (``ValueError``, ``OSError``) print one line and give 2,
    an option's value or a contradiction of options found after parsing
    (:class:`ccjax.cli.option_checks.OptionError`) with the command's usage line before it, as argparse's own;
    any other error (a bug) prints one line naming its type and place in ccjax and gives 1
    (``CCJAX_TRACEBACK=1``: the traceback instead);
    Ctrl-C at any time, also while JAX is being imported (``import ccjax`` defers it to first use),
    prints one line and gives 130 (128 + SIGINT), without a traceback.

    Arguments:
        argv: the arguments after ``ccjax``.

    Returns:
        The exit code.
    """
    command = None
    parser = None
    if argv is None and threading.current_thread() is threading.main_thread():
        # SIGTERM stops the command as Ctrl-C does, through the same clean-up (no temporaries
        # left, no output pair half replaced), with one line and 143.
        from ccjax._signals import terminate_cleanly

        terminate_cleanly()
    previous_hook, sys.unraisablehook = sys.unraisablehook, redeliver_interrupts
    previous_format = warnings.formatwarning
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        command = args.command
        warnings.formatwarning = one_line_warnings(command, previous_format)
        import_holding_interrupts("numpy", "jax")  # every command needs them
        return int(args.func(args) or 0)
    except BaseException as error:
        if interrupted(error):
            while True:
                try:
                    return _stop_on_interrupt(command, whole_process=argv is None, terminated=terminated(error))
                except KeyboardInterrupt:
                    # A late copy of this Ctrl-C (a redelivery in flight) landed before late ones
                    # were ignored: it is the same interrupt, so stop once, not die by SIGINT.
                    continue
        if isinstance(error, BrokenPipeError):
            # The reader closed the pipe (``ccjax cameras | head``): stop quietly, as Unix tools do;
            # stdout goes to devnull so the interpreter's final flush does not raise again.
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 1
        if isinstance(error, (ValueError, OSError)):
            from ccjax.cli.option_checks import OptionError

            if isinstance(error, OptionError) and parser is not None:
                # As argparse reports the errors it finds: the command's usage line first.
                commands = getattr(parser, "commands", {})
                sys.stderr.write(commands.get(command, parser).format_usage())
            print(f"{prefix(command)}: error: {error}", file=sys.stderr)
            return 2
        if isinstance(error, Exception) and not os.environ.get(TRACEBACK_VARIABLE):
            print(unexpected_error_line(command, error), file=sys.stderr)
            return 1
        raise
    finally:
        sys.unraisablehook = previous_hook
        warnings.formatwarning = previous_format
        for timer in _REDELIVERIES:
            timer.cancel()
        if argv is None and threading.current_thread() is threading.main_thread():
            # The command is over: a signal now (during the interpreter's exit) must not turn its
            # exit code into death by the signal.
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            signal.signal(signal.SIGTERM, signal.SIG_IGN)


__all__ = [
    "COMMANDS",
    "GROUPS",
    "STARTED",
    "TRACEBACK_VARIABLE",
    "build_parser",
    "groups",
    "import_holding_interrupts",
    "interrupted",
    "main",
    "one_line_warnings",
    "prefix",
    "redeliver_interrupts",
    "terminated",
    "unexpected_error_line",
]
