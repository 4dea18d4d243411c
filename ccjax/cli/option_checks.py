"""Checks of option values shared by the commands: the error for an option found wrong after
parsing (:class:`OptionError`) and the argparse type of ``--data-dir`` (:func:`data_folder`)."""

from __future__ import annotations

import argparse
import os


class OptionError(ValueError):
    """An option's value, or options that contradict each other, found wrong after parsing: the
    command line (:func:`ccjax.cli.main`) prints the command's usage line, then
    ``ccjax <command>: error: <message>``, and exits 2, as argparse does for the errors it finds.
    The message starts with the option's name."""


def data_folder(text: str) -> str:
    """The argparse type of ``--data-dir``: an existing folder (a file, or a path that does not
    exist, is refused before any work instead of being searched for data files in vain).

    Arguments:
        text: the option's value.

    Returns:
        ``text``.

    Raises:
        argparse.ArgumentTypeError: no such path, or not a folder.
    """
    if "\0" in text:
        raise argparse.ArgumentTypeError(f"{text!r} contains a NUL byte")
    if not os.path.exists(text):
        raise argparse.ArgumentTypeError(f"no such folder: {text}")
    if not os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"{text} is not a folder (the external data directory)")
    return text


data_folder.__name__ = "folder"  # argparse names the type in its own messages
