"""The ``ccjax`` command line: parse, call the library, format.

One module per command group; each declares ``add_<command>(subparsers)`` (its arguments) and
``run_<command>(args)`` and lists its ``add_`` functions in ``COMMANDS``. :func:`main` (the
``ccjax`` entry point) shows the groups in the order of :data:`GROUPS`.
"""

from __future__ import annotations

import argparse
import os
import sys

from ccjax.cli import (
    calibrate,
    catalogue,
    indexing,
    photos,
    sharpen,
    synthetic,
    training,
)

GROUPS = (synthetic, catalogue, photos, indexing, training, sharpen, calibrate)
"""The command groups, in ``ccjax --help`` order."""

COMMANDS = [add for group in GROUPS for add in group.COMMANDS]

# Old paths of the single-module CLI, kept for one release.
DEFAULT_COMPARE_METHODS = synthetic.DEFAULT_COMPARE_METHODS
DEFAULT_INDEXING_METHODS = indexing.DEFAULT_INDEXING_METHODS


def build_parser() -> argparse.ArgumentParser:
    """The ``ccjax`` argument parser with every sub-command."""
    parser = argparse.ArgumentParser(
        prog="ccjax",
        description="JAX colour constancy: estimate and correct the colour of the light.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    for add in COMMANDS:
        add(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``ccjax`` with ``argv`` (default: the process arguments).

    Errors in arguments, files and folders (``ValueError``, ``OSError``) print one line and give 2;
    Ctrl-C prints one line and gives 130 (128 + SIGINT), without a traceback.

    Arguments:
        argv: the arguments after ``ccjax``.

    Returns:
        The exit code.
    """
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, OSError) as error:
        if isinstance(error, BrokenPipeError):
            # The reader closed the pipe (``ccjax cameras | head``): stop quietly, as Unix tools do;
            # stdout goes to devnull so the interpreter's final flush does not raise again.
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 1
        print(f"ccjax {args.command}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"ccjax {args.command}: interrupted", file=sys.stderr)
        return 130


__all__ = ["COMMANDS", "DEFAULT_COMPARE_METHODS", "DEFAULT_INDEXING_METHODS", "GROUPS", "build_parser", "main"]
