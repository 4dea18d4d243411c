"""Independent NumPy references for FFCC (Barron & Tsai 2017), written from the paper's and the
reference code's definitions with plain loops: the masked local absolute deviation, the wrapped
log-chroma histogram (nearest bin centre on the torus), periodic 2-D convolution by explicit
shifts, the bivariate von Mises fit from the marginals' circular moments, and the masked block
means of a statistics image."""

from __future__ import annotations

import numpy as np


def local_absolute_deviation(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Per pixel and channel, the mean |neighbour - pixel| over the usable 3x3 neighbours (the
    border replicated), 0 where there is none or the pixel is unusable."""
    height, width, _ = image.shape
    out = np.zeros_like(image, dtype=np.float64)
    for y in range(height):
        for x in range(width):
            if not mask[y, x]:
                continue
            total, count = np.zeros(3), 0
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    if dy == 0 and dx == 0:
                        continue
                    yy, xx = min(max(y + dy, 0), height - 1), min(max(x + dx, 0), width - 1)
                    if mask[yy, xx]:
                        total += np.abs(image[yy, xx].astype(np.float64) - image[y, x])
                        count += 1
            if count:
                out[y, x] = total / count
    return out


def block_means(image: np.ndarray, mask: np.ndarray, block: int) -> tuple[np.ndarray, np.ndarray]:
    """Per ``block x block`` tile (the last row and column of tiles cut short at the image's
    edge), the mean of its usable pixels and whether it has any (the reference code's weighted
    downsampling: the masked sum over the tile divided by the usable count)."""
    height, width, _ = image.shape
    rows, cols = -(-height // block), -(-width // block)
    means, usable = np.zeros((rows, cols, 3)), np.zeros((rows, cols), bool)
    for i in range(rows):
        for j in range(cols):
            tile = image[i * block : (i + 1) * block, j * block : (j + 1) * block].reshape(-1, 3)
            keep = mask[i * block : (i + 1) * block, j * block : (j + 1) * block].reshape(-1)
            if keep.any():
                means[i, j], usable[i, j] = tile[keep].astype(np.float64).mean(axis=0), True
    return means, usable


def nearest_bin(value: float, origin: float, bins: int, bin_size: float) -> int:
    """The bin whose centre ``origin + bin_size * i`` is nearest ``value`` on the circle of
    circumference ``bins * bin_size``."""
    centres = origin + bin_size * np.arange(bins)
    period = bins * bin_size
    distance = np.abs((value - centres + period / 2) % period - period / 2)
    return int(np.argmin(distance))


def histogram(rgb: np.ndarray, valid: np.ndarray, origin, bins: int, bin_size: float) -> np.ndarray:
    """Normalised counts of the valid colours' (log(G/R), log(G/B)) in their nearest bins."""
    counts = np.zeros((bins, bins))
    for colour, ok in zip(rgb.astype(np.float64), valid):
        if ok:
            u, v = np.log(colour[1] / colour[0]), np.log(colour[1] / colour[2])
            counts[nearest_bin(u, origin[0], bins, bin_size), nearest_bin(v, origin[1], bins, bin_size)] += 1
    return counts / max(counts.sum(), 1.0)


def periodic_convolution(signal: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """``out[i, j] = sum_{a, b} signal[a, b] kernel[(i - a) % n, (j - b) % n]``."""
    n, m = signal.shape
    out = np.zeros((n, m))
    for a in range(n):
        for b in range(m):
            out += signal[a, b] * np.roll(np.roll(kernel, a, axis=0), b, axis=1)
    return out


def von_mises_fit(probability: np.ndarray, diagonal: float) -> tuple[np.ndarray, np.ndarray]:
    """Circular mean of each marginal (the angle of its first trigonometric moment, in bins), and
    the covariance of the bin offsets from the rounded mean taken to the nearest copy on the torus
    (ties to +n/2), plus ``diagonal`` on the diagonal."""
    n = probability.shape[0]
    theta = 2 * np.pi * np.arange(n) / n
    marginals = [probability.sum(axis=1), probability.sum(axis=0)]
    mean = np.array([(np.angle(np.sum(p * np.exp(1j * theta))) % (2 * np.pi)) * n / (2 * np.pi) for p in marginals])
    offsets = []
    for axis in range(2):
        centre = np.round(mean[axis])
        row = []
        for i in range(n):
            d = i - centre
            while d > n / 2:
                d -= n
            while d <= -n / 2:
                d += n
            row.append(d)
        offsets.append(np.array(row))
    joint = np.array([[probability[i, j] for j in range(n)] for i in range(n)])
    e = [np.sum(marginals[k] * offsets[k]) for k in range(2)]
    cov = np.zeros((2, 2))
    for k in range(2):
        cov[k, k] = np.sum(marginals[k] * offsets[k] ** 2) - e[k] ** 2
    cov[0, 1] = cov[1, 0] = np.sum(joint * np.outer(offsets[0], offsets[1])) - e[0] * e[1]
    return mean, cov + diagonal * np.eye(2)
