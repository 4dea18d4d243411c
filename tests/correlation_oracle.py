"""NumPy reference for Colour by Correlation, written from the specs as plain loops.

2-D: spec ch02-04 §6.5 (Barnard 1999 §4.5.4): 50 x 50 (r,g) bins of 0.02; per training illuminant
count the reflectances' bins, smooth with a sampled Gaussian (taps to 4 sigma, zero outside the
grid), normalise, floor at ``floor`` x the maximum, log. Scene evidence: the set of bins present.
C-by-C-01: 0/1 matrix of bins whose centre lies in the convex hull of the reflectances' (r,g) (or
that hold one of them); estimate = mean (r,g) of the illuminants within ``tolerance`` of the best
count.

3-D: spec ch08-12 §4 (chapter 10): cells (r bin, g bin, floor(l_bins * L / L_white)); possible
(r,g) bins only (i + j <= 49), anything else is "outside" at the floor; brightness hypotheses
``b_q = B0 * 3^(2q/100 - 1)``, ``B0 = 4.3 mean(R+G+B)``; remedy 1 sums the log-probabilities of the
distinct input colours, remedy 2 those of the occupied cells minus ``n_occ log(b_q / B0)``.

Nothing here is shared with ``ccjax.estimators.correlation``: hulls by Andrew's monotone chain,
smoothing by explicit shifted sums.
"""

from __future__ import annotations

import math

import numpy as np

BINS = 50


def gaussian_taps(sigma: float) -> np.ndarray:
    radius = int(4.0 * sigma + 0.5)
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    taps = np.exp(-0.5 * (x / sigma) ** 2)
    return taps / taps.sum()


def smooth_axis(values: np.ndarray, axis: int, sigma: float) -> np.ndarray:
    """Zero-padded convolution with the sampled Gaussian along one axis, as a sum of shifts."""
    if sigma == 0:
        return values
    taps = gaussian_taps(sigma)
    radius = len(taps) // 2
    moved = np.moveaxis(values, axis, 0)
    out = np.zeros_like(moved)
    n = moved.shape[0]
    for k, weight in zip(range(-radius, radius + 1), taps):
        # out[x] += w_k * in[x - k]
        if k >= 0:
            out[k:] += weight * moved[: n - k]
        else:
            out[: n + k] += weight * moved[-k:]
    return np.moveaxis(out, 0, axis)


def responses(reflectances: np.ndarray, light: np.ndarray, sensors: np.ndarray) -> np.ndarray:
    return (reflectances * light[None, :]) @ sensors


def rg_bin(rgb) -> tuple[int, int]:
    total = float(rgb[0] + rgb[1] + rgb[2])
    r, g = float(rgb[0]) / total, float(rgb[1]) / total
    return min(int(math.floor(r * BINS)), BINS - 1), min(int(math.floor(g * BINS)), BINS - 1)


def rg_bins(rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`rg_bin` for many colours at once."""
    rg = rgb[:, :2] / rgb.sum(axis=1, keepdims=True)
    bins = np.minimum(np.floor(rg * BINS).astype(int), BINS - 1)
    return bins[:, 0], bins[:, 1]


def _normalised_log(counts: np.ndarray, floor: float) -> np.ndarray:
    p = counts / counts.sum()
    return np.log(np.maximum(p, floor * p.max()))


def chromaticity_log_probability(reflectances, lights, sensors, sigma=1.0, floor=1e-6) -> np.ndarray:
    """``(I, 50, 50)`` log P(bin | illuminant)."""
    out = []
    for light in lights:
        counts = np.zeros((BINS, BINS))
        i, j = rg_bins(responses(reflectances, light, sensors))
        np.add.at(counts, (i, j), 1.0)
        counts = smooth_axis(smooth_axis(counts, 0, sigma), 1, sigma)
        out.append(_normalised_log(counts, floor))
    return np.stack(out)


def _monotone_chain(points: np.ndarray) -> list[tuple[float, float]]:
    pts = sorted(set(map(tuple, points.tolist())))

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]  # counter-clockwise


def hull_compatibility(reflectances, lights, sensors) -> np.ndarray:
    """``(I, 50, 50)`` 0/1: bin centre inside the hull of the (r,g), or a bin holding one of them."""
    i, j = np.meshgrid(np.arange(BINS), np.arange(BINS), indexing="ij")
    centres = np.stack([(i + 0.5) / BINS, (j + 0.5) / BINS], axis=-1)
    out = []
    for light in lights:
        rgb = responses(reflectances, light, sensors)
        rg = rgb[:, :2] / rgb.sum(axis=1, keepdims=True)
        hull = _monotone_chain(rg)
        inside = np.ones((BINS, BINS), bool)
        for a, b in zip(hull, hull[1:] + hull[:1]):
            edge_cross = (b[0] - a[0]) * (centres[..., 1] - a[1]) - (b[1] - a[1]) * (centres[..., 0] - a[0])
            inside &= edge_cross >= -1e-12
        for colour in rgb:
            inside[rg_bin(colour)] = True
        out.append(inside.astype(np.float64))
    return np.stack(out)


def brightness_log_probability(
    reflectances, lights, sensors, *, l_bins=50, sigma=0.75, sigma_l=0.5, floor=1e-6, specular=None
) -> np.ndarray:
    """``(I, 50, 50, l_total)`` log P(cell | illuminant) over (r bin, g bin, L / L_white bin).

    ``specular``: ``(probability, max_amount)``: each surface also appears with ``s`` x white added,
    ``s`` = midpoints of 8 steps of ``[0, max_amount]``, weight ``probability / 8`` (matte copy
    ``1 - probability``); the L axis then reaches ``1 + max_amount``.
    """
    reach = 1.0 if specular is None else 1.0 + specular[1]
    l_total = int(math.ceil(reach * l_bins))
    out = []
    for light in lights:
        white = light @ sensors
        counts = np.zeros((BINS, BINS, l_total))
        entries = [(rgb, 1.0) for rgb in responses(reflectances, light, sensors)]
        if specular is not None:
            probability, amount = specular
            matte = entries
            entries = [(rgb, 1.0 - probability) for rgb, _ in matte]
            for step in range(8):
                s = (step + 0.5) / 8 * amount
                entries += [(rgb + s * white, probability / 8) for rgb, _ in matte]
        colours = np.stack([rgb for rgb, _ in entries])
        weights = np.array([weight for _, weight in entries])
        levels = np.floor(colours.sum(axis=1) / white.sum() * l_bins).astype(int)
        assert levels.max() < l_total, "training colour brighter than the modelled L range"
        i, j = rg_bins(colours)
        np.add.at(counts, (i, j, levels), weights)
        for axis, s in ((0, sigma), (1, sigma), (2, sigma_l)):
            counts = smooth_axis(counts, axis, s)
        out.append(_normalised_log(counts, floor))
    return np.stack(out)


def posterior_2d(log_p: np.ndarray, rgb: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Posterior over the training illuminants (uniform prior), eqs. 4.2–4.5."""
    present = set()
    for colour, valid in zip(rgb, mask):
        if valid and colour.sum() > 0:
            present.add(rg_bin(colour))
    scores = np.zeros(log_p.shape[0])
    for cell in present:
        scores += log_p[:, cell[0], cell[1]]
    weights = np.exp(scores - scores.max())
    return weights / weights.sum()


def estimate_2d(selector, log_p, illuminant_rg, rgb, mask, mlm_width=None) -> tuple[np.ndarray, int | None]:
    """(estimated (r,g), chosen illuminant index or None for MMSE)."""
    p = posterior_2d(log_p, rgb, mask)
    if selector == "MMSE":
        return p @ illuminant_rg, None
    if selector == "MAP":
        best = int(np.argmax(p))
        return illuminant_rg[best], best
    spread = (mlm_width / BINS) ** 2
    local = np.zeros(len(p))
    for i in range(len(p)):  # the posterior convolved with the Gaussian mask, at illuminant i
        local[i] = np.sum(p * np.exp(-0.5 * np.sum((illuminant_rg[i] - illuminant_rg) ** 2, axis=1) / spread))
    best = int(np.argmax(local))
    return illuminant_rg[best], best


def estimate_01(compatible, illuminant_rg, rgb, mask, tolerance=1.0) -> np.ndarray:
    present = {rg_bin(c) for c, v in zip(rgb, mask) if v and c.sum() > 0}
    counts = np.array([sum(compatible[i, a, b] for a, b in present) for i in range(len(compatible))])
    chosen = counts >= counts.max() - tolerance
    return illuminant_rg[chosen].mean(axis=0)


def posterior_3d(log_p, rgb, mask, *, method="presence", l_bins=50, factor=4.3, k=3.0, n_levels=101):
    """Joint posterior ``(n_levels, I)`` over (brightness level, illuminant) and the levels ``b_q``."""
    n_lights, _, _, l_total = log_p.shape
    floor_row = log_p.reshape(n_lights, -1).min(axis=1)
    colours = [c for c, v in zip(rgb, mask) if v and c.sum() > 0]
    if method == "counts":  # remove exact duplicate colours first
        distinct = []
        for c in colours:
            if not any(np.array_equal(c, d) for d in distinct):
                distinct.append(c)
        colours = distinct
    initial = factor * float(np.mean([c.sum() for c in colours]))
    levels = np.array([initial * k ** (2.0 * q / (n_levels - 1) - 1.0) for q in range(n_levels)])
    scores = np.zeros((n_levels, n_lights))
    for q, b in enumerate(levels):
        occupied = []
        for c in colours:
            i, j = rg_bin(c)
            level = int(math.floor(float(c.sum()) / b * l_bins))
            cell = (i, j, level) if (i + j <= BINS - 1 and level < l_total) else None
            if method == "presence" and cell is not None and cell in occupied:
                continue
            occupied.append(cell)
            scores[q] += floor_row if cell is None else log_p[:, i, j, level]
        if method == "presence":
            scores[q] -= len(occupied) * math.log(b / initial)
    weights = np.exp(scores - scores.max())
    return weights / weights.sum(), levels


def estimate_3d(selector, log_p, illuminant_rg, rgb, mask, **options):
    """(illuminant RGB, (level, illuminant) of the MAP or None)."""
    return estimate_from_posterior_3d(selector, *posterior_3d(log_p, rgb, mask, **options), illuminant_rg)


def estimate_from_posterior_3d(selector, p, levels, illuminant_rg):
    if selector == "MAP":
        q, i = np.unravel_index(int(np.argmax(p)), p.shape)
        r, g = illuminant_rg[i]
        return levels[q] * np.array([r, g, 1.0 - r - g]), (int(q), int(i))
    r, g = p.sum(axis=0) @ illuminant_rg
    return float(p.sum(axis=1) @ levels) * np.array([r, g, 1.0 - r - g]), None
