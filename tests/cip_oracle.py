"""Independent NumPy/SciPy reference for Colour in Perspective (CIP-MV, CIP-AVE, CIP-ICA).

Written from the spec (ch02-04 §6.4, Table 4.1; ch08-12 §1.6), not from ccjax's kernel: everything
is done directly in perspective chromaticity ``(R/B, G/B)`` and in the 2-D map space ``D``, with
exact plane geometry instead of a direction grid.

* canonical polygon ``C2`` = convex hull of the reflectances' canonical ``(R/B, G/B)``;
* surface constraints: ``D * p in C2`` for every observed ``p`` -> half-planes in ``D``, whose
  intersection ``P_S`` is a convex polygon;
* illumination constraint: the illuminant ``e' = c / D`` lies in the convex hull ``I`` of the
  training illuminants' ``(R/B, G/B)`` (exact, non-convex in ``D``), or ``D`` lies in the convex
  hull of the training maps ``c / e'_j`` (its convex approximation);
* CIP-AVE: exact area centroid of ``P_S`` clipped by the convex approximation (half-space
  intersection + shoelace formulas);
* CIP-MV: exact maximum of ``D1 D2`` over ``P_S ∩ {c / D in I}``; the maximum of an increasing
  function lies on the boundary, which consists of edges of ``P_S`` (restricted to the illuminant
  set) and images of edges of ``I`` (restricted to ``P_S``); along each piece membership in the
  other set is a set of quadratic inequalities in the edge parameter, solved exactly;
* CIP-ICA: Monte-Carlo average of the 3-D map directions ``(D1, D2, 1) / |.|`` over the feasible
  cones, uniform in solid angle: ``D`` is drawn uniformly in a bounding box and weighted by the
  solid-angle density of the plane ``d3 = 1``, ``dOmega = dD1 dD2 / (D1^2 + D2^2 + 1)^(3/2)``.

Estimates are returned as illuminant RGB directions ``e = w_C / d`` with ``d = (D1, D2, 1)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, HalfspaceIntersection


@dataclass
class CIPWorld:
    """Fixed geometry: ``a . x <= b`` half-planes of the canonical polygon and of the illuminant
    hull (both in perspective chromaticity), the training maps and the canonical white."""

    white: np.ndarray  # (3,) canonical white RGB
    c: np.ndarray  # (2,) canonical white perspective chromaticity
    canonical_a: np.ndarray  # (K, 2)
    canonical_b: np.ndarray  # (K,)
    illum_a: np.ndarray  # (L, 2)
    illum_b: np.ndarray  # (L,)
    illum_points: np.ndarray  # (I, 2) training illuminants (R/B, G/B)


def perspective(rgb: np.ndarray) -> np.ndarray:
    rgb = np.asarray(rgb, dtype=np.float64)
    return rgb[..., :2] / rgb[..., 2:3]


def _halfplanes(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    hull = ConvexHull(points)
    return hull.equations[:, :2], -hull.equations[:, 2]


def make_world(canonical_rgb, train_whites, canonical_white) -> CIPWorld:
    canonical_rgb = np.asarray(canonical_rgb, dtype=np.float64)
    canonical_rgb = canonical_rgb[canonical_rgb[:, 2] > 0]
    white = np.asarray(canonical_white, dtype=np.float64)
    canonical_a, canonical_b = _halfplanes(perspective(canonical_rgb))
    illum_points = perspective(train_whites)
    illum_a, illum_b = _halfplanes(illum_points)
    return CIPWorld(white, perspective(white), canonical_a, canonical_b, illum_a, illum_b, illum_points)


def surface_halfplanes(world: CIPWorld, rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(a_k * p) . D <= b_k`` for every observed perspective chromaticity ``p``; only the
    vertices of the observed points' hull can be binding."""
    p = perspective(rgb)
    if len(p) >= 3:
        try:
            p = p[ConvexHull(p).vertices]
        except Exception:  # collinear or repeated points: keep them all
            pass
    a = (world.canonical_a[None, :, :] * p[:, None, :]).reshape(-1, 2)
    b = np.tile(world.canonical_b, len(p))
    return a, b


def polygon(a: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """Vertices (counter-clockwise) of ``{x : a x <= b}``, or None when empty / degenerate."""
    norms = np.linalg.norm(a, axis=1)
    # Chebyshev centre: the deepest interior point.
    res = linprog(
        c=[0.0, 0.0, -1.0],
        A_ub=np.column_stack([a, norms]),
        b_ub=b,
        bounds=[(None, None), (None, None), (0.0, None)],
        method="highs",
    )
    if res.status != 0 or res.x[2] <= 1e-12 * max(1.0, np.abs(res.x[:2]).max()):
        return None
    inside = res.x[:2]
    vertices = HalfspaceIntersection(np.column_stack([a, -b]), inside).intersections
    hull = ConvexHull(vertices)
    return vertices[hull.vertices]


def polygon_centroid(vertices: np.ndarray) -> tuple[float, np.ndarray]:
    """Area and centroid of a simple polygon (shoelace)."""
    x, y = vertices[:, 0], vertices[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = cross.sum() / 2.0
    cx = ((x + xn) * cross).sum() / (6.0 * area)
    cy = ((y + yn) * cross).sum() / (6.0 * area)
    return abs(area), np.array([cx, cy])


def illuminant_of_map(world: CIPWorld, D: np.ndarray) -> np.ndarray:
    d = np.array([D[0], D[1], 1.0])
    e = world.white / d
    return e / e.sum()


def map_of_illuminant(world: CIPWorld, e: np.ndarray) -> np.ndarray:
    d = world.white / np.asarray(e, dtype=np.float64)
    return d[:2] / d[2]


# ---------------------------------------------------------------------------------------------
# CIP-AVE: exact centroid of the convex set


def ave(world: CIPWorld, rgb: np.ndarray) -> np.ndarray | None:
    """Area centroid ``D`` of ``P_S`` ∩ convex hull of the training maps, or None if empty."""
    a_s, b_s = surface_halfplanes(world, rgb)
    maps = world.c[None, :] / world.illum_points
    a_i, b_i = _halfplanes(maps)
    vertices = polygon(np.vstack([a_s, a_i]), np.concatenate([b_s, b_i]))
    if vertices is None:
        return None
    return polygon_centroid(vertices)[1]


# ---------------------------------------------------------------------------------------------
# CIP-MV: exact maximum of D1 D2 over the non-convex feasible set


def _quadratics(a: np.ndarray, b: np.ndarray, scale: np.ndarray, start: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Coefficients ``(K, 3)`` (constant, linear, quadratic) in ``s`` of
    ``a1 s1 x2 + a2 s2 x1 - b x1 x2 <= 0`` with ``x(s) = start + s delta`` — the constraint
    ``a . (scale / x) <= b`` multiplied by ``x1 x2 > 0``."""
    (x1, x2), (d1, d2) = start, delta
    u, v = a[:, 0] * scale[0], a[:, 1] * scale[1]
    const = u * x2 + v * x1 - b * x1 * x2
    linear = u * d2 + v * d1 - b * (x1 * d2 + x2 * d1)
    quadratic = -b * d1 * d2
    return np.column_stack([const, linear, quadratic])


def _feasible_intervals(coefficients: np.ndarray) -> list[tuple[float, float]]:
    """Sub-intervals of [0, 1] where every quadratic ``c0 + c1 s + c2 s^2`` is <= 0."""
    c0, c1, c2 = coefficients.T
    breaks = [np.array([0.0, 1.0])]
    linear = np.abs(c2) <= 1e-14 * (np.abs(c0) + np.abs(c1) + 1e-300)
    with np.errstate(divide="ignore", invalid="ignore"):
        breaks.append(-c0[linear & (c1 != 0)] / c1[linear & (c1 != 0)])
        q = ~linear
        disc = c1[q] ** 2 - 4 * c0[q] * c2[q]
        real = disc >= 0
        root = np.sqrt(disc[real])
        for sign in (-1.0, 1.0):
            breaks.append((-c1[q][real] + sign * root) / (2 * c2[q][real]))
    breaks = np.concatenate(breaks)
    breaks = np.unique(breaks[(breaks >= 0.0) & (breaks <= 1.0)])
    mids = 0.5 * (breaks[:-1] + breaks[1:])
    values = c0[:, None] + c1[:, None] * mids[None, :] + c2[:, None] * mids[None, :] ** 2
    ok = np.all(values <= 0.0, axis=0)
    intervals: list[tuple[float, float]] = []
    for lo, hi, good in zip(breaks[:-1], breaks[1:], ok):
        if not good:
            continue
        if intervals and intervals[-1][1] == lo:
            intervals[-1] = (intervals[-1][0], hi)
        else:
            intervals.append((float(lo), float(hi)))
    return intervals


def mv(world: CIPWorld, rgb: np.ndarray) -> np.ndarray | None:
    """``D`` maximising ``D1 D2`` over ``P_S ∩ {D : c / D in I}`` (exact), or None if empty."""
    a_s, b_s = surface_halfplanes(world, rgb)
    surface_polygon = polygon(a_s, b_s)
    if surface_polygon is None:
        return None
    best, best_value = None, -np.inf

    def consider(D):
        nonlocal best, best_value
        value = np.log(D[0]) + np.log(D[1])
        if value > best_value:
            best, best_value = np.asarray(D, dtype=float), value

    # Edges of P_S, restricted to the (non-convex) illuminant set.
    for start, end in zip(surface_polygon, np.roll(surface_polygon, -1, axis=0)):
        delta = end - start
        quads = _quadratics(world.illum_a, world.illum_b, world.c, start, delta)
        for lo, hi in _feasible_intervals(quads):
            candidates = [lo, hi]
            # Stationary point of log D1 + log D2 along the line (a concave function of s).
            if delta[0] * delta[1] != 0:
                s = -(delta[0] * start[1] + delta[1] * start[0]) / (2 * delta[0] * delta[1])
                candidates.append(min(max(s, lo), hi))
            for s in candidates:
                consider(start + s * delta)
    # Images of the edges of I (curves in D), restricted to P_S. Along them log D1 + log D2 =
    # const - log e1(s) - log e2(s) is convex in s, so its maximum is at an interval end.
    vertices = world.illum_points[ConvexHull(world.illum_points).vertices]
    for start, end in zip(vertices, np.roll(vertices, -1, axis=0)):
        delta = end - start
        quads = _quadratics(a_s, b_s, world.c, start, delta)
        for lo, hi in _feasible_intervals(quads):
            for s in (lo, hi):
                consider(world.c / (start + s * delta))
    return best


# ---------------------------------------------------------------------------------------------
# CIP-ICA: Monte-Carlo average over 3-D map directions


def ica(world: CIPWorld, rgb: np.ndarray, n_samples: int = 100_000, seed: int = 0) -> tuple[np.ndarray | None, int]:
    """Solid-angle centroid of the feasible 3-D map directions (exact illumination constraint).

    Returns:
        ``(e, n_feasible)``: the illuminant RGB direction (sum 1) and how many samples were
        feasible; ``e`` is None when no sample was.
    """
    a_s, b_s = surface_halfplanes(world, rgb)
    surface_polygon = polygon(a_s, b_s)
    if surface_polygon is None:
        return None, 0
    illum = world.illum_points
    low = np.maximum(surface_polygon.min(axis=0), world.c / illum.max(axis=0))
    high = np.minimum(surface_polygon.max(axis=0), world.c / illum.min(axis=0))
    if np.any(high <= low):
        return None, 0
    rng = np.random.default_rng(seed)
    total, weight_sum, count = np.zeros(3), 0.0, 0
    chunk = 50_000
    for _ in range(max(1, n_samples // chunk)):
        D = low + (high - low) * rng.random((chunk, 2))
        ok = np.all((world.c / D) @ world.illum_a.T <= world.illum_b, axis=1)
        D = D[ok]
        ok = np.all(D @ a_s.T <= b_s, axis=1)
        d = np.column_stack([D[ok], np.ones(ok.sum())])
        length = np.linalg.norm(d, axis=1)
        weight = 1.0 / length**3
        total += (weight[:, None] * d / length[:, None]).sum(axis=0)
        weight_sum += weight.sum()
        count += int(ok.sum())
    if count == 0:
        return None, 0
    omega = total / weight_sum
    e = world.white / omega
    return e / e.sum(), count
