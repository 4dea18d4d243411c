"""Every limit on what ccjax reads or samples, in one table.

The readers (images, CSV files, model records, cache entries), the samplers (``ccjax.sample``,
``compare --scenes``) and the command line all take their bounds from here, so that an input
within its documented limit runs in bounded memory and one past it is refused up front, with the
limit and the option that changes it named (:func:`check_count`). The table is also the "Limits"
section of the docs.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Limit:
    """One bound: its value, what it bounds and how to change it.

    Attributes:
        value: the largest accepted value.
        what: what is bounded, for messages (``"scenes"``).
        option: the command-line option or argument that changes it (``""``: fixed).
    """

    value: int | float
    what: str
    option: str = ""


PIXELS = Limit(100_000_000, "pixels per image (from the file's header, before decoding)", "--max-pixels / max_pixels")
"""An image whose header claims more pixels is refused before anything is allocated for it."""

SCENES = Limit(10_000_000, "scenes of one synthetic run (sampled in chunks)", "--scenes / n_scenes")
"""``ccjax.sample``'s and ``compare``'s scene count (a sweep streams them in chunks; a sample
holds them all: 10 M scenes of 64 surfaces hold about 8 GB, so ``ccjax.sample`` has its own
bound, :data:`SAMPLE_SCENES`)."""

SAMPLE_SCENES = Limit(1_000_000, "scenes held at once by ccjax.sample", "n_scenes (sample in several calls)")
"""``ccjax.sample`` returns every scene at once (a 64-surface scene is about 800 bytes)."""

SIGMA = Limit(64.0, "grey edge's Gaussian sigma, in pixels", "the method label (e.g. grey-edge-1-6-2)")
"""A Gaussian of sigma ``s`` has ``8 s + 1`` taps; past 64 pixels (a 513-tap kernel) the estimate
is a global average of the image, and the kernel's cost grows without bound."""

CSV_ROWS = Limit(1_000_000, "rows of a CSV file (ground truth, sensor curves)", "")
"""A ground-truth table of a million photographs, or a sensor curve at 0.001 nm, fits."""

CSV_BYTES = Limit(256 << 20, "bytes of a CSV file", "")
"""Read whole before parsing."""

RECORD_BYTES = Limit(1 << 20, "bytes of a model record (.json)", "")
"""A written record is a few kilobytes."""

NESTING = Limit(64, "nesting depth of a JSON record", "")
"""A written model record nests at most 5 deep."""

CACHE_ENTRY_BYTES = Limit(4 << 30, "bytes of one cache entry's arrays", "")
"""Checked from the archive's headers before an array is allocated."""

SEED = Limit(2**63 - 1, "seed", "--seed")
"""Seeds are 64-bit signed integers (JAX's and NumPy's keys)."""

OBJECTS = Limit(100_000, "objects of an indexing experiment", "--objects")
"""Each object is a rendered set of surfaces held at once."""

SHARPENING_PENALTY = Limit(1e6, "a sharpening penalty weight (--lambda-p, --lambda-n)", "--lambda-p")
"""Penalty weights past a million only scale the objective's other terms away."""

TABLE: tuple[Limit, ...] = (
    PIXELS,
    SCENES,
    SAMPLE_SCENES,
    SIGMA,
    CSV_ROWS,
    CSV_BYTES,
    RECORD_BYTES,
    NESTING,
    CACHE_ENTRY_BYTES,
    SEED,
    OBJECTS,
    SHARPENING_PENALTY,
)
"""Every limit above, in the order of the docs' table."""


def check_count(value: object, limit: Limit, argument: str, *, low: int = 1) -> int:
    """``value`` as an integer in ``[low, limit.value]``, else a ``ValueError`` naming ``argument``
    and the limit.

    Arguments:
        value: an integer (a float with an integral value, such as ``1e6``, is accepted).
        limit: the bound.
        argument: the argument's name for the message (``"n_scenes"``, ``"--scenes"``).
        low: the smallest accepted value.

    Returns:
        The value as an ``int``.

    Raises:
        ValueError: not an integer, or outside ``[low, limit.value]``.
    """
    if isinstance(value, bool) or (not isinstance(value, (int, float)) and not hasattr(value, "__index__")):
        raise ValueError(f"{argument}: expected an integer, got {value!r}")
    if isinstance(value, float):
        if not value.is_integer():
            raise ValueError(f"{argument}: expected an integer, got {value!r}")
        value = int(value)
    number = int(value)  # pyright: ignore[reportArgumentType]
    if number < low:
        raise ValueError(f"{argument}: expected an integer >= {low}, got {number}")
    if number > limit.value:
        raise ValueError(f"{argument}: {number} is over the limit of {limit.value:,} {limit.what}{_how(limit)}")
    return number


def check_value(value: float, limit: Limit, argument: str, *, low: float = 0.0) -> float:
    """``value`` as a finite float in ``[low, limit.value]``, else a ``ValueError`` naming
    ``argument`` and the limit.

    Arguments:
        value: the number.
        limit: the bound.
        argument: the argument's name for the message.
        low: the smallest accepted value.

    Returns:
        The value as a ``float``.

    Raises:
        ValueError: NaN, infinite, or outside ``[low, limit.value]``.
    """
    number = float(value)
    if number != number or number in (float("inf"), float("-inf")):
        raise ValueError(f"{argument}: expected a finite number, got {value!r}")
    if number < low:
        raise ValueError(f"{argument}: expected a number >= {low:g}, got {number:g}")
    if number > limit.value:
        raise ValueError(f"{argument}: {number:g} is over the limit of {limit.value:g} ({limit.what}){_how(limit)}")
    return number


def _how(limit: Limit) -> str:
    return f" (see {limit.option})" if limit.option else ""


__all__ = [
    "CACHE_ENTRY_BYTES",
    "CSV_BYTES",
    "CSV_ROWS",
    "NESTING",
    "OBJECTS",
    "PIXELS",
    "RECORD_BYTES",
    "SAMPLE_SCENES",
    "SCENES",
    "SEED",
    "SHARPENING_PENALTY",
    "SIGMA",
    "TABLE",
    "Limit",
    "check_count",
    "check_value",
]
