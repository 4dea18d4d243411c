"""Every limit on what ccjax reads or samples, in one table.

The readers (images, CSV files, model records, cache entries), the samplers (``ccjax.sample``,
``compare --scenes``) and the command line all take their bounds from here, so that an input
within its documented limit runs in bounded memory and one past it is refused up front, with the
limit and the option that changes it named (:func:`describe`). The table is also the "Limits"
section of the docs.
"""

from __future__ import annotations

import operator
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

SCENES = Limit(1_000_000, "scenes of one synthetic run", "--scenes / n_scenes")
"""``compare``'s and ``sharpen``'s scene count: the scenes stream through in chunks, but each
(method, surface count) keeps eight numbers per scene (32 MB per cell at the limit);
:data:`SCENE_RESULTS` bounds ``compare``'s cells times its scenes."""

SCENE_RESULTS = Limit(
    50_000_000,
    "per-scene results held by one comparison (scenes x surface counts x methods)",
    "--scenes, --surfaces, --methods / n_scenes, n_surfaces, methods",
)
"""``compare`` (``ccjax.experiments.sweep``) keeps eight float32 numbers per scene, surface
count and method to the end of the run. Measured peak (``benchmarks/limits.py``; NOTHING and GW
at 4 and 8 surfaces): 509 MB at 200,000 scene results and 635 MB at 4,000,000, so 35 bytes each
and a projected 1.75 GB at the limit (narrower pairs of sizes read 32 to 61 bytes, the peaks
varying by a few tens of MB between runs). The limit is the default comparison (5 surface
counts x 10 methods) at :data:`SCENES`' million scenes; ``--surfaces 1..300`` at a million
scenes (300 counts) is refused."""

SAMPLE_SCENES = Limit(100_000, "scenes held at once by ccjax.sample", "n_scenes (sample in several calls)")
"""``ccjax.sample`` returns every scene at once; :data:`SAMPLE_SURFACES` bounds their surfaces."""

SAMPLE_SURFACES = Limit(
    6_400_000,
    "surfaces held at once by ccjax.sample (scenes x surfaces per scene)",
    "n_scenes, n_surfaces (sample in several calls)",
)
"""100,000 scenes of 64 surfaces, or 3,211 of 1,993. Measured peak (``benchmarks/limits.py``):
34 bytes a surface (2.2 KB a 64-surface scene) without options, 180 to 190 with every option
(specular, noise, clip, metallic, fluorescent), so a projected peak of 0.6 GB at the limit
without options and 1.6 GB with every option (the world's tables included; checked at 50,000
scenes of 64 surfaces with every option: 1.0 GB measured, 1.05 GB projected)."""

SIGMA = Limit(64.0, "grey edge's Gaussian sigma, in pixels", "the method label (e.g. grey-edge-1-6-2)")
"""A Gaussian of sigma ``s`` has ``8 s + 1`` taps; past 64 pixels (a 513-tap kernel) the estimate
is a global average of the image, and the kernel's cost grows without bound."""

CSV_ROWS = Limit(100_000, "rows of a CSV file (ground truth, calibration data)", "")
"""The largest photo sets have a few thousand images; a checked ground-truth row costs a few
kilobytes (``cameras --check``), so the limit bounds that at a few hundred megabytes."""

CSV_BYTES = Limit(64 << 20, "bytes of a CSV file", "")
"""Checked from the file's size before it is read."""

RECORD_BYTES = Limit(1 << 20, "bytes of a model record (.json)", "")
"""A written record is a few kilobytes."""

NESTING = Limit(64, "nesting depth of a JSON record", "")
"""A written model record nests at most 5 deep."""

CACHE_ENTRY_BYTES = Limit(4 << 30, "bytes of one cache entry's arrays", "")
"""Checked from the archive's headers before an array is allocated."""

SEED = Limit(2**32 - 1, "seed", "--seed")
"""Seeds are 32-bit: JAX's keys (without x64) take a seed's low 32 bits, so larger seeds would
give the same scenes as smaller ones."""

OBJECTS = Limit(10_000, "objects of an indexing experiment", "--objects / n_objects")
"""200 times the default of 50. The images are rendered and scored in blocks of 0.5 MP
(:data:`ccjax.experiments.indexing.BLOCK_PIXELS`), so what grows with the objects is only what is
kept: each object's histogram (1 KB), each query's rank and error per method, a block's scores
against every object (a few KB an object in all). Measured peak (``benchmarks/limits.py``;
ACTUAL and GW, 20 lights, 64 x 64 images): 585 MB at 130 objects, 620 to 650 MB at 520 and at
1,040 (no growth measurable between them), so well under 1 GB at the limit; the run time grows
as the objects squared."""

INDEXING_SIZE = Limit(1024, "image side of an indexing experiment, in pixels", "--size / size")
"""16 times the default 64. An image is 12 bytes a pixel (12 MB at the limit) and a block holds at
least one, with its estimators' working copies: measured (``benchmarks/limits.py``, from 128 x
128 to 512 x 512), 180 to 500 bytes a pixel with a gamut method (whose surface lists grow with
the image), so a projected 0.9 to 1.2 GB at the limit."""

RENDERED_IMAGES = Limit(20_000, "images rendered for training", "--pretrain-images / --rendered / Pretraining.images")
"""Ten times the default of 2,000; rendered and prepared images are held at once, about 0.18 MB
each at 64 x 64 (measured peak: 721 MiB at 500 images, 992 MiB at 2,000, so about 4.3 GB at the
limit)."""

SHARPENING_PENALTY = Limit(1e8, "a sharpening penalty weight", "--lambda-p / lambda_p, lambda_n")
"""The new method's search tries weights up to 1e7; past 1e8 the objective's other terms vanish
in float32."""

VALUE = Limit(1e30, "magnitude of a light or pixel value given as an array or a CSV number", "")
"""Lights and pixels may be on any scale up to this (files are read on the unit scale); past it a
float32 sum of three channels, or the reciprocal of a peak, leaves the normal range. The other
end: a non-zero value must be a normal float32 (at least about 1.2e-38), as devices flush
smaller ones to zero."""

TABLE: tuple[Limit, ...] = (
    PIXELS,
    SCENES,
    SCENE_RESULTS,
    SAMPLE_SCENES,
    SAMPLE_SURFACES,
    SIGMA,
    CSV_ROWS,
    CSV_BYTES,
    RECORD_BYTES,
    NESTING,
    CACHE_ENTRY_BYTES,
    SEED,
    OBJECTS,
    INDEXING_SIZE,
    RENDERED_IMAGES,
    SHARPENING_PENALTY,
    VALUE,
)
"""Every limit above, in the order of the docs' table."""


def require_count(value, name: str, low: int, high: int | Limit | None = None) -> int:
    """``value`` as a Python ``int`` (any integer-like value, e.g. ``np.int64``, via
    ``operator.index``); a ``ValueError`` naming ``name`` when it is not an integer in range.

    Arguments:
        value: the count to check.
        name: the argument's name, for the error.
        low: smallest allowed value.
        high: largest allowed value, or a :class:`ccjax.Limit` (named in the error with
            the option that changes it); ``None``: no bound.

    Returns:
        ``value`` as an ``int``.
    """
    top = int(high.value) if isinstance(high, Limit) else high
    span = f"an integer >= {low}" if top is None else f"an integer in [{low}, {top}]"
    if isinstance(value, bool):
        raise ValueError(f"{name}: expected {span}, got the boolean {value!r}")
    try:
        number = operator.index(value)
    except TypeError:
        raise ValueError(f"{name}: expected {span}, got {value!r} of type {type(value).__name__}") from None
    if isinstance(high, Limit) and number > high.value:
        raise ValueError(f"{name}: {number:,} is over {describe(high)}")
    if number < low or (top is not None and number > top):
        raise ValueError(f"{name}: expected {span}, got {number}")
    return number


def require_product(factors: tuple[tuple[int, str], ...], name: str, limit: Limit) -> int:
    """The product of counts that are held at once together (``compare``'s scenes times surface
    counts times methods); a ``ValueError`` naming ``name``, each factor and ``limit`` when it
    is over the limit.

    Arguments:
        factors: ``(count, what)`` pairs, e.g. ``((1000, "scenes"), (5, "surface counts"))``.
        name: the argument's name, for the error.
        limit: the bound on the product.

    Returns:
        The product.

    Raises:
        ValueError: the product is over ``limit``.
    """
    total = 1
    for count, _ in factors:
        total *= count
    if total > limit.value:
        spelled = " x ".join(f"{count:,} {what}" for count, what in factors)
        raise ValueError(f"{name}: {spelled} = {total:,} is over {describe(limit)}")
    return total


def check_csv(path, line: int | None = None) -> None:
    """Refuse a CSV file over :data:`CSV_BYTES` (from its size, before reading) or, given the
    line being read, one past :data:`CSV_ROWS`.

    Arguments:
        path: the file (a path; for the size and the message).
        line: the line number being read (``None``: check the size only).

    Raises:
        ValueError: past either limit, naming the file.
    """
    import os

    if line is None:
        size = os.stat(path).st_size
        if size > CSV_BYTES.value:
            raise ValueError(f"{path}: {size:,} bytes is over {describe(CSV_BYTES)}")
    elif line > CSV_ROWS.value + 1:  # the header is line 1
        raise ValueError(f"{path}: line {line} is past {describe(CSV_ROWS)}")


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


SMALLEST_NORMAL = 1.1754944e-38
"""float32's smallest normal number: smaller non-zero values are flushed to zero on devices."""


def check_magnitudes(values, argument: str) -> None:
    """Refuse values whose non-zero magnitudes lie outside ``[SMALLEST_NORMAL, VALUE]``.

    Arguments:
        values: a NumPy array (already checked finite).
        argument: the argument's name for the message.

    Raises:
        ValueError: a value past either end, named with its limit.
    """
    import numpy as np

    magnitude = np.abs(np.asarray(values, np.float64))
    if magnitude.size and magnitude.max() > VALUE.value:
        raise ValueError(f"{argument}: {magnitude.max():g} is over the limit of {VALUE.value:g} ({VALUE.what})")
    tiny = magnitude[(magnitude > 0) & (magnitude < SMALLEST_NORMAL)]
    if tiny.size:
        raise ValueError(
            f"{argument}: {tiny[0]:g} is below float32's smallest normal number {SMALLEST_NORMAL:g} "
            "(devices read it as zero); scale the values up"
        )


def describe(limit: Limit) -> str:
    """The limit for a message: ``"the limit of 1,000,000 scenes ... (see --scenes / n_scenes)"``.

    Arguments:
        limit: the bound.

    Returns:
        The phrase.
    """
    value = f"{limit.value:,}" if isinstance(limit.value, int) else f"{limit.value:g}"
    return f"the limit of {value} ({limit.what}){_how(limit)}"


def _how(limit: Limit) -> str:
    return f" (see {limit.option})" if limit.option else ""


__all__ = [
    "CACHE_ENTRY_BYTES",
    "CSV_BYTES",
    "CSV_ROWS",
    "INDEXING_SIZE",
    "NESTING",
    "OBJECTS",
    "PIXELS",
    "RECORD_BYTES",
    "SAMPLE_SCENES",
    "SAMPLE_SURFACES",
    "SCENES",
    "SCENE_RESULTS",
    "SEED",
    "SHARPENING_PENALTY",
    "SIGMA",
    "SMALLEST_NORMAL",
    "TABLE",
    "VALUE",
    "Limit",
    "check_csv",
    "check_magnitudes",
    "check_value",
    "describe",
    "require_count",
    "require_product",
]
