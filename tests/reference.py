"""Plain NumPy reference implementations, written from the thesis spec (ch02-04 §6–7) with loops,
independent of the JAX kernels they check."""

from __future__ import annotations

import math

import numpy as np


def rg(rgb):
    total = rgb[0] + rgb[1] + rgb[2]
    return (rgb[0] / total, rgb[1] / total)


def angular_error(a, b):
    dot = sum(x * y for x, y in zip(a, b))
    na = math.sqrt(sum(x * x for x in a))
    nb = math.sqrt(sum(y * y for y in b))
    cosine = max(-1.0, min(1.0, dot / (na * nb)))
    return math.degrees(math.acos(cosine))


def rg_error(a, b):
    ra, ga = rg(a)
    rb, gb = rg(b)
    return math.hypot(ra - rb, ga - gb)


def mapping_errors(estimate, rgb, mask, canonical_rgb, canonical_white):
    d = [canonical_white[k] / estimate[k] for k in range(3)]
    rg_sq, rgb_sq, count = 0.0, 0.0, 0
    for p, q, valid in zip(rgb, canonical_rgb, mask):
        if not valid:
            continue
        mapped = [p[k] * d[k] for k in range(3)]
        mr, mg = rg(mapped)
        qr, qg = rg(q)
        rg_sq += (mr - qr) ** 2 + (mg - qg) ** 2
        rgb_sq += sum((mapped[k] - q[k]) ** 2 for k in range(3))
        count += 1
    return math.sqrt(rg_sq / count), math.sqrt(rgb_sq / count)


def grey_world(rgb, mask, scale):
    total = [0.0, 0.0, 0.0]
    count = 0
    for p, valid in zip(rgb, mask):
        if valid:
            for k in range(3):
                total[k] += p[k]
            count += 1
    return [total[k] / count * scale[k] for k in range(3)]


def max_rgb(rgb, mask):
    best = [0.0, 0.0, 0.0]
    for p, valid in zip(rgb, mask):
        if valid:
            for k in range(3):
                best[k] = max(best[k], p[k])
    return best


def shades_of_grey(rgb, mask, p):
    values = [q for q, valid in zip(rgb, mask) if valid]
    return [2.0 * (sum(q[k] ** p for q in values) / len(values)) ** (1.0 / p) for k in range(3)]


def trimean(values):
    q1, q2, q3 = np.percentile(values, [25, 50, 75])
    return (q1 + 2 * q2 + q3) / 4


def bca_interval(errors, statistic, level=0.95, resamples=2000, seed=0):
    """BCa bootstrap interval of the mean or median written out (Efron & Tibshirani 1993, §14.3):
    bias correction z0 from the mid-rank share of resampled statistics below the observed one,
    acceleration from the jackknife, the interval's ends as quantiles of the resampled statistics."""
    from statistics import NormalDist

    function = {"mean": np.mean, "median": np.median}[statistic]
    errors = np.asarray(errors, dtype=np.float64).ravel()
    n, observed = errors.size, float(function(errors))
    rng = np.random.default_rng(seed)
    draws = function(errors[rng.integers(0, n, (resamples, n))], axis=1)
    normal = NormalDist()
    below = (np.sum(draws < observed) + 0.5 * np.sum(draws == observed)) / draws.size
    z0 = normal.inv_cdf(float(np.clip(below, 0.5 / draws.size, 1 - 0.5 / draws.size)))
    jackknife = np.array([function(np.delete(errors, i)) for i in range(n)])
    spread = jackknife.mean() - jackknife
    acceleration = float(np.sum(spread**3) / (6.0 * np.sum(spread**2) ** 1.5))
    quantiles = []
    for tail in ((1 - level) / 2, (1 + level) / 2):
        z = z0 + normal.inv_cdf(tail)
        quantiles.append(normal.cdf(z0 + z / (1 - acceleration * z)))
    low, high = np.quantile(draws, quantiles)
    return float(low), float(high)
