"""Reductions over an image in row tiles, so that a camera-sized image (48 MP) needs working
memory for one tile at a time instead of several image-sized intermediates.

A tile is ``rows`` image rows plus ``halo`` rows above and below, gathered with the row index
clamped to the image (the rows a border tile lacks repeat the edge row, exactly what an
edge-replicating filter of the whole image sees there), so a filter of support radius at most
``halo`` gives every one of the tile's own rows the value it has in the whole image. The tiles
run one after another (``lax.map``) and each returns a small summary (sums, maxima, counts) that
the caller combines; sums differ from a one-pass reduction only by float rounding.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

__all__ = ["TILE_PIXELS", "map_row_tiles", "tile_rows"]

TILE_PIXELS = 1 << 21
"""Pixels of one tile (about 2 MP: 25 MB of float32 RGB); images no larger are not tiled."""


def tile_rows(height: int, width: int, pixels: int | None = None) -> int | None:
    """Rows per tile for an image of ``height x width``, or None when it fits in one tile.

    Arguments:
        height, width: the image size (static).
        pixels: the tile budget (default :data:`TILE_PIXELS`).

    Returns:
        The rows of a tile (at least 1), or None.
    """
    pixels = TILE_PIXELS if pixels is None else pixels
    if height * width <= pixels:
        return None
    return max(1, pixels // width)


def map_row_tiles(
    summary: Callable[[Float[Array, "T W 3"], Bool[Array, "T W"], Bool[Array, " R"]], Any],
    image: Float[Array, "H W 3"],
    mask: Bool[Array, "H W"],
    *,
    rows: int,
    halo: int = 0,
) -> Any:
    """``summary`` of every row tile of ``image`` and ``mask``, stacked along a leading tile axis.

    Arguments:
        summary: a function of ``(image tile (rows + 2 halo, W, 3), mask tile (rows + 2 halo, W),
            own (rows,))``: ``own[k]`` is False for rows past the image's last row (the last tile
            repeats that row to fill up); the tile's own rows are ``halo .. halo + rows``.
        image: ``(H, W, 3)``.
        mask: ``(H, W)``.
        rows: image rows per tile.
        halo: rows gathered above and below each tile (at least the support radius of any filter
            ``summary`` applies).

    Returns:
        ``summary``'s outputs with a leading axis of ``ceil(H / rows)`` tiles.
    """
    height = image.shape[0]
    count = -(-height // rows)
    offsets = jnp.arange(rows + 2 * halo) - halo
    own_offsets = jnp.arange(rows)

    def one(tile):
        start = tile * rows
        index = jnp.clip(start + offsets, 0, height - 1)
        return summary(image[index], mask[index], start + own_offsets < height)

    return jax.lax.map(one, jnp.arange(count))
