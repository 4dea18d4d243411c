"""Reducing an image's usable pixels to a list of surfaces (Barnard 1999 §4.6, Table 4.6): block
averages, RGB clustering, convex-hull reduction and region-growing segmentation."""

from __future__ import annotations

from collections import deque

import numpy as np

_CHUNK_PIXELS = 1 << 20  # pixels per chunk of block averaging (bounded working memory)


def _tile_starts(length: int, block: int) -> np.ndarray:
    return np.arange(0, length, block)


def _tile_sizes(length: int, block: int) -> np.ndarray:
    return np.diff(np.append(_tile_starts(length, block), length))


def block_average(
    rgb: np.ndarray,
    usable: np.ndarray,
    block: int,
    max_rg_spread: float | None = None,
    *,
    edges: bool = False,
) -> np.ndarray:
    """Means of non-overlapping ``block x block`` tiles whose pixels are all usable (§4.6, the
    thesis' ``ave<b>``).

    Arguments:
        rgb: ``(H, W, 3)`` linear image.
        usable: ``(H, W)`` from :func:`usable_pixels`.
        block: tile side in pixels.
        max_rg_spread: an extension, not in the thesis: also drop tiles whose pixels' (r,g)
            bounding box has a diagonal above it, i.e. tiles straddling a boundary between surfaces,
            whose mean is a mixture no surface produces (harmless for gamut mapping, which is
            convex, but it fills histogram cells for Colour by Correlation).
        edges: an extension (``ave<b>-edges``): also keep the partial tiles of the right and bottom
            edges (fewer than ``block`` rows or columns), under the same rule (all their pixels
            usable). Without it those edge rows and columns are dropped, as in the thesis.

    Returns:
        ``(n, 3)`` float32 tile means (summed in float64), in scan order.

    The image is processed in bands of whole tile rows, so the working memory stays small (a few
    megabytes) whatever the image size: no copy of the image is made.
    """
    if block < 1:
        raise ValueError(f"block: expected a tile side >= 1, got {block!r}")
    height, width = rgb.shape[:2]
    if not edges:
        height, width = (height // block) * block, (width // block) * block
    if height == 0 or width == 0:
        return np.zeros((0, 3), np.float32)
    columns = _tile_starts(width, block)
    column_sizes = _tile_sizes(width, block)
    band = block * max(1, _CHUNK_PIXELS // (block * width))
    means = []
    for top in range(0, height, band):
        bottom = min(top + band, height)
        rows = _tile_starts(bottom - top, block)
        part = rgb[top:bottom, :width]
        sums = np.add.reduceat(np.add.reduceat(part, rows, axis=0, dtype=np.float64), columns, axis=1)
        counts = np.add.reduceat(
            np.add.reduceat(usable[top:bottom, :width], rows, axis=0, dtype=np.int32), columns, axis=1
        )
        sizes = _tile_sizes(bottom - top, block)[:, None] * column_sizes[None, :]
        ok = counts == sizes
        if max_rg_spread is not None:
            total = part.sum(axis=-1, keepdims=True, dtype=np.float64)
            chroma = part[..., :2] / np.where(total > 0, total, 1.0)
            high = np.maximum.reduceat(np.maximum.reduceat(chroma, rows, axis=0), columns, axis=1)
            low = np.minimum.reduceat(np.minimum.reduceat(chroma, rows, axis=0), columns, axis=1)
            ok &= np.sqrt(((high - low) ** 2).sum(axis=-1)) <= max_rg_spread
        means.append((sums / sizes[..., None])[ok])
    return np.concatenate(means).astype(np.float32)


def cluster_rgb(rgb: np.ndarray, divisions: int = 100) -> np.ndarray:
    """RGB clustering (§4.6): bin in RGB (``divisions`` per channel over ``[0, max]``) and replace
    each occupied bin by the mean of its members (removes near-duplicates).

    Arguments:
        rgb: ``(n, 3)`` surfaces.
        divisions: bins per channel.

    Returns:
        ``(m, 3)`` float32, one row per occupied bin.
    """
    if len(rgb) == 0:
        return rgb
    top = max(float(rgb.max()), 1e-12)
    cells = np.minimum((rgb / top * divisions).astype(np.int64), divisions - 1)
    keys = (cells[:, 0] * divisions + cells[:, 1]) * divisions + cells[:, 2]
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    sums = np.zeros((len(counts), 3))
    np.add.at(sums, inverse.ravel(), rgb)
    return (sums / counts[:, None]).astype(np.float32)


def hull_reduce(rgb: np.ndarray) -> np.ndarray:
    """Keep only the vertices of the RGB convex hull (§4.6), in their original order; degenerate
    sets (fewer than 5 points, or flat) are kept whole.

    Arguments:
        rgb: ``(n, 3)`` surfaces.

    Returns:
        ``(m, 3)`` the hull's vertices (or ``rgb`` itself when degenerate).
    """
    from scipy.spatial import ConvexHull, QhullError

    if len(rgb) < 5:
        return rgb
    try:
        return rgb[np.sort(ConvexHull(rgb.astype(np.float64)).vertices)]
    except QhullError:
        return rgb


def segment(
    rgb: np.ndarray, usable: np.ndarray, min_size: int, rg_tolerance: float, brightness_tolerance: float
) -> np.ndarray:
    """Region growing (§4.6) and the mean RGB of each region.

    Seeds are taken in scan order; a region grows over 4-connected usable pixels while the
    diagonal of its (r,g) bounding box stays within ``rg_tolerance`` and ``(max - min) / min`` of
    its R+G+B within ``brightness_tolerance``; regions smaller than ``min_size`` are dropped.
    Plain Python region growing: a few seconds per megapixel (a preprocessing option, not the
    default).

    Arguments:
        rgb: ``(H, W, 3)`` linear image.
        usable: ``(H, W)`` from :func:`~ccjax.preprocessing.usable_pixels`.
        min_size: the fewest pixels a region may have.
        rg_tolerance: the largest diagonal of a region's (r,g) bounding box.
        brightness_tolerance: the largest ``(max - min) / min`` of a region's R+G+B.

    Returns:
        ``(regions, 3)`` float32 region means, in seed order.
    """
    height, width, _ = rgb.shape
    total = rgb.sum(axis=-1, dtype=np.float64)
    safe = np.where(total > 0, total, 1.0)
    r, g = (rgb[..., 0] / safe).tolist(), (rgb[..., 1] / safe).tolist()
    brightness = total.tolist()
    free = usable.copy()
    means = []
    rg_limit = rg_tolerance**2
    for y0, x0 in zip(*np.nonzero(usable)):
        if not free[y0, x0]:
            continue
        free[y0, x0] = False
        members = [(y0, x0)]
        r_lo = r_hi = r[y0][x0]
        g_lo = g_hi = g[y0][x0]
        b_lo = b_hi = brightness[y0][x0]
        queue = deque(members)
        while queue:
            y, x = queue.popleft()
            for ny, nx in ((y - 1, x), (y + 1, x), (y, x - 1), (y, x + 1)):
                if 0 <= ny < height and 0 <= nx < width and free[ny, nx]:
                    rr, gg, bb = r[ny][nx], g[ny][nx], brightness[ny][nx]
                    nr_lo, nr_hi, ng_lo, ng_hi = min(r_lo, rr), max(r_hi, rr), min(g_lo, gg), max(g_hi, gg)
                    nb_lo, nb_hi = min(b_lo, bb), max(b_hi, bb)
                    if (nr_hi - nr_lo) ** 2 + (
                        ng_hi - ng_lo
                    ) ** 2 <= rg_limit and nb_hi - nb_lo <= brightness_tolerance * nb_lo:
                        r_lo, r_hi, g_lo, g_hi, b_lo, b_hi = nr_lo, nr_hi, ng_lo, ng_hi, nb_lo, nb_hi
                        free[ny, nx] = False
                        members.append((ny, nx))
                        queue.append((ny, nx))
        if len(members) >= min_size:
            ys, xs = np.array(members).T
            means.append(rgb[ys, xs].mean(axis=0, dtype=np.float64))
    return np.array(means, np.float32).reshape(-1, 3)
