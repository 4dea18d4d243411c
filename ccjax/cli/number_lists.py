"""The argparse type of an option holding numbers separated by commas (``--light R,G,B``,
``--surfaces 4,8,16``): one place that splits, parses strictly and refuses a wrong count."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import TypeVar

_Number = TypeVar("_Number", int, float)


def number_list(
    parse: Callable[[str], _Number],
    what: str,
    count: int | None = None,
    *,
    check: Callable[[tuple[_Number, ...]], str | None] | None = None,
) -> Callable[[str], tuple[_Number, ...]]:
    """An argparse type: comma-separated numbers, each read by ``parse`` (a strict parser of
    :mod:`ccjax._numbers`, so ``0_8``, ``nan`` and ``inf`` are refused).

    Arguments:
        parse: reads one number, raising ``ValueError`` on anything else.
        what: what is expected, for the message ``expected <what>, got '<text>'``.
        count: exactly this many numbers, each between its commas (None: one or more; blank items,
            as a trailing comma leaves, are passed over).
        check: given the numbers, what is expected instead when they are out of range (the
            message is then ``expected <its answer>, got '<text>'``), else None.

    Returns:
        The type function, returning the numbers as a tuple.
    """

    def read(text: str) -> tuple[_Number, ...]:
        parts = text.split(",")
        if count is None:  # an open list: "4,8," is 4 and 8; a fixed one (R,G,B) has no blank place
            parts = [part for part in parts if part.strip()]
        try:
            values = tuple(parse(part) for part in parts)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not values and count is None:
            raise argparse.ArgumentTypeError("empty list")
        if count is not None and len(values) != count:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        fault = None if check is None else check(values)
        if fault is not None:
            raise argparse.ArgumentTypeError(f"expected {fault}, got {text!r}")
        return values

    read.__name__ = "list"  # argparse names the type in its own messages
    return read
