"""Numbers as people write them, parsed strictly: what a command line option or a CSV cell holds.

Python's ``float`` and ``int`` also take ``1_000`` (so a mistyped ``0_8`` is read as 8.0),
``nan``, ``inf``, ``infinity``, full-width digits and surrounding whitespace of any kind; a value
in a file or an option is none of those. :func:`decimal` and :func:`whole` accept plain decimal
notation only and refuse a value that is not finite, with a ``ValueError`` whose message the
caller prefixes with the option or the file and line.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence

__all__ = ["decimal", "first_not_decimal", "whole"]

_DECIMAL = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_WHOLE = re.compile(r"[+-]?[0-9]+")


def decimal(text: str) -> float:
    """A finite decimal number: ``0.8``, ``-5``, ``1e-3``, ``.5`` (spaces around it allowed).

    Arguments:
        text: the written value.

    Returns:
        The number.

    Raises:
        ValueError: anything else (``0_8``, ``0x10``, ``nan``, ``inf``, ``1e999``, an empty text).
    """
    value = str(text).strip(" \t")
    if not _DECIMAL.fullmatch(value):
        raise ValueError(f"{text!r} is not a finite decimal number")
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{text!r} is too large to be a finite number")
    return number


def first_not_decimal(texts: Sequence[str]) -> int | None:
    """Where the first text that :func:`decimal` refuses stands, for a whole column of a file in
    one call (a call per cell costs more than the parsing); the caller parses that one text with
    :func:`decimal` for the message.

    Arguments:
        texts: the written values.

    Returns:
        Its index, or None when every text is a finite decimal number.
    """
    for index, text in enumerate(texts):
        value = str(text).strip(" \t")
        if not _DECIMAL.fullmatch(value) or not math.isfinite(float(value)):
            return index
    return None


def whole(text: str) -> int:
    """A whole number in decimal digits: ``3``, ``-1`` (spaces around it allowed).

    Arguments:
        text: the written value.

    Returns:
        The number.

    Raises:
        ValueError: anything else (``1_0``, ``3.0``, ``0x10``, an empty text).
    """
    value = str(text).strip(" \t")
    if not _WHOLE.fullmatch(value):
        raise ValueError(f"{text!r} is not a whole number")
    return int(value)
