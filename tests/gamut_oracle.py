"""Exact per-scene oracle for 3-D gamut mapping, written from the spec as plain NumPy/SciPy.

Barnard 1999 §4.5.3 (and the gamut chapters' spec §1.7-1.8 / §9.5): the feasible set of diagonal maps is the polytope
``{d : (n_k * p_j) . d <= c_k for all observed p_j and canonical facets k}``; SciPy's
``HalfspaceIntersection`` gives its vertices, its exact centroid is a sum over tetrahedra (AVE),
the maximum of ``sum(log d)`` over it is a convex program (MV), and averages over the non-convex
ECRULE set (ICA, SCWIA) come from a fine quadrature over illuminant directions, with the ray
extent measured against the *exact polytope's own facets*, or from dense Monte-Carlo in map space.

Nothing here imports ccjax's gamut code: it is an independent reference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog, minimize
from scipy.spatial import ConvexHull, HalfspaceIntersection


def hull_halfspaces(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(A, b)`` with ``A x <= b`` describing ``conv({0} ∪ points)`` (Qhull's equations as they are)."""
    hull = ConvexHull(np.vstack([np.zeros(3), np.asarray(points, np.float64)]))
    return hull.equations[:, :3], -hull.equations[:, 3]


def illuminant_polygon(whites: np.ndarray) -> np.ndarray:
    """Equations ``E [r, g, 1] <= 0`` of the convex hull of the whites' (r,g) chromaticities."""
    whites = np.asarray(whites, np.float64)
    rg = whites[:, :2] / whites.sum(axis=1, keepdims=True)
    return ConvexHull(rg).equations


def polygon_vertices(equations: np.ndarray) -> np.ndarray:
    """Vertices of the polygon ``E [r, g, 1] <= 0`` (pairwise intersections of its edge lines
    that satisfy all the others)."""
    points = []
    for i in range(len(equations)):
        for j in range(i + 1, len(equations)):
            m = equations[[i, j], :2]
            if abs(np.linalg.det(m)) < 1e-12:
                continue
            x = np.linalg.solve(m, -equations[[i, j], 2])
            if np.all(equations[:, :2] @ x + equations[:, 2] <= 1e-9):
                points.append(x)
    return np.array(points)


def in_polygon(equations: np.ndarray, rg: np.ndarray) -> np.ndarray:
    return np.all(rg @ equations[:, :2].T + equations[:, 2] <= 0, axis=-1)


def map_cone_halfspaces(whites: np.ndarray, white: np.ndarray) -> np.ndarray:
    """Rows ``g`` with ``g . d <= 0`` for the convex cone spanned by the maps ``w_C / e_j``
    (the convex approximation of the illumination constraint used by ECRULE-AVE)."""
    maps = np.asarray(white, np.float64) / np.asarray(whites, np.float64)
    chroma = maps / maps.sum(axis=1, keepdims=True)
    hull = ConvexHull(chroma[:, :2])
    rows = []
    for a, b in hull.simplices:
        # The plane through the origin and the two generators (as 3-vectors on the simplex).
        normal = np.cross(chroma[a], chroma[b])
        if normal @ chroma.mean(axis=0) > 0:
            normal = -normal
        rows.append(normal)
    return np.array(rows)


def extreme_observations(observed: np.ndarray) -> np.ndarray:
    """The vertices of ``conv({0} ∪ observed)`` other than the origin: a map sends every observed
    RGB into the (convex, origin-containing) gamut iff it sends these (spec ch05-07 §1.4)."""
    observed = np.asarray(observed, np.float64)
    if len(observed) < 8:
        return observed
    hull = ConvexHull(np.vstack([np.zeros(3), observed]))
    return observed[hull.vertices[hull.vertices > 0] - 1]


def scene_constraints(A: np.ndarray, b: np.ndarray, observed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(n_k * p_j) . d <= c_k`` for every extreme observed RGB and facet, as one stacked system."""
    rows, rhs = [], []
    for p in extreme_observations(observed):
        for k in range(len(A)):
            rows.append(A[k] * p)
            rhs.append(b[k])
    return np.array(rows), np.array(rhs)


@dataclass
class Polytope:
    vertices: np.ndarray
    volume: float
    centroid: np.ndarray
    equations: np.ndarray  # the polytope's own facets, n . x + o <= 0


def chebyshev_centre(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and radius of the largest ball inside ``A x <= b`` (an LP)."""
    norms = np.linalg.norm(A, axis=1)
    cost = np.zeros(4)
    cost[3] = -1.0
    result = linprog(
        cost, A_ub=np.hstack([A, norms[:, None]]), b_ub=b, bounds=[(None, None)] * 3 + [(0, None)], method="highs"
    )
    if result.status != 0:
        return np.zeros(3), 0.0
    return result.x[:3], float(result.x[3])


def polytope(A: np.ndarray, b: np.ndarray, min_radius: float = 1e-7) -> Polytope | None:
    """The polytope ``A x <= b`` with its exact volume and centroid; None when it has no interior."""
    centre, radius = chebyshev_centre(A, b)
    if radius < min_radius:
        return None
    intersection = HalfspaceIntersection(np.hstack([A, -b[:, None]]), centre)
    vertices = intersection.intersections
    hull = ConvexHull(vertices)
    apex = vertices.mean(axis=0)
    volume = 0.0
    moment = np.zeros(3)
    for simplex in hull.simplices:
        p1, p2, p3 = vertices[simplex]
        tetra = abs(np.linalg.det(np.array([p1 - apex, p2 - apex, p3 - apex]))) / 6.0
        volume += tetra
        moment += tetra * (apex + p1 + p2 + p3) / 4.0
    return Polytope(
        vertices=hull.points[hull.vertices], volume=volume, centroid=moment / volume, equations=hull.equations
    )


def max_log_product(poly: Polytope) -> np.ndarray:
    """The map maximising ``d_r d_g d_b`` over the polytope (a concave program: SLSQP on the
    polytope's own facets, from its centroid)."""
    A, b = poly.equations[:, :3], -poly.equations[:, 3]
    start = poly.centroid
    result = minimize(
        lambda d: -np.sum(np.log(d)),
        start,
        jac=lambda d: -1.0 / d,
        constraints=[{"type": "ineq", "fun": lambda d: b - A @ d, "jac": lambda d: -A}],
        bounds=[(1e-9, None)] * 3,
        method="SLSQP",
        options={"ftol": 1e-15, "maxiter": 1000},
    )
    return result.x


def ray_extent(poly: Polytope, maps: np.ndarray) -> np.ndarray:
    """``T`` with ``T * m`` on the polytope's far boundary for each map direction ``m``, using the
    polytope's own facets; 0 where the ray does not enter the polytope at the origin."""
    normals, offsets = poly.equations[:, :3], poly.equations[:, 3]
    through_origin = np.abs(offsets) < 1e-10 * np.abs(offsets).max()
    den = maps @ normals.T
    enters = ~np.any((den > 0) & through_origin[None, :], axis=1)
    ratio = np.where((den > 0) & ~through_origin[None, :], -offsets[None, :] / np.where(den > 0, den, 1.0), np.inf)
    return np.where(enters, ratio.min(axis=1), 0.0)


def direction_quadrature(
    poly: Polytope, white: np.ndarray, polygon: np.ndarray | None, step: float = 5e-4, pad: float = 0.02
):
    """A fine (r,g) grid of illuminant directions covering the feasible ones, with their ``T``.

    Returns ``(rg (G, 2), T (G,))``, with ``T = 0`` outside the (surface, and if ``polygon`` is
    given illumination) constraints. Raises if feasible directions touch the grid's edge.
    """
    if polygon is not None:
        # Only directions inside the illuminant polygon count: cover its box.
        corners = polygon_vertices(polygon)
    else:
        directions = white / poly.vertices[np.all(poly.vertices > 1e-9, axis=1)]
        corners = directions[:, :2] / directions.sum(axis=1, keepdims=True)
    lo, hi = corners.min(axis=0) - pad, corners.max(axis=0) + pad
    r = np.arange(lo[0], hi[0], step)
    g = np.arange(lo[1], hi[1], step)
    rr, gg = np.meshgrid(r, g, indexing="ij")
    rg = np.stack([rr.ravel(), gg.ravel()], axis=1)
    rg = rg[(rg > 0).all(axis=1) & (rg.sum(axis=1) < 1)]
    u = np.column_stack([rg, 1 - rg.sum(axis=1)])
    extent = ray_extent(poly, white / u)
    if polygon is not None:
        extent = np.where(in_polygon(polygon, rg), extent, 0.0)
    feasible = extent > 0
    edge = (
        (rg[:, 0] < lo[0] + 2 * step)
        | (rg[:, 0] > hi[0] - 2 * step)
        | (rg[:, 1] < lo[1] + 2 * step)
        | (rg[:, 1] > hi[1] - 2 * step)
    )
    if np.any(feasible & edge):
        raise RuntimeError("feasible directions reach the quadrature grid's edge; increase pad")
    return rg, extent


def centroid_by_directions(rg: np.ndarray, extent: np.ndarray, white: np.ndarray) -> np.ndarray:
    """Map-space centroid from the direction quadrature (spec ch08-12 §1.8):
    ``(3/4) sum m T^4 / (rgb)^2 / sum T^3 / (rgb)^2``."""
    u = np.column_stack([rg, 1 - rg.sum(axis=1)])
    jac = 1.0 / np.prod(u, axis=1) ** 2
    maps = white / u
    weight = extent**3 * jac
    return 0.75 * np.sum(maps * (extent**4 * jac)[:, None], axis=0) / np.sum(weight)


def scwia_by_directions(rg: np.ndarray, extent: np.ndarray, white: np.ndarray, power: float) -> np.ndarray:
    """SCWIA-N (r,g) (spec ch08-12 §1.8): weights ``(T^3 prod(w_C) / (rgb))^(N/3) dOmega``."""
    u = np.column_stack([rg, 1 - rg.sum(axis=1)])
    feasible = extent > 0
    log_weight = np.full(len(rg), -np.inf)
    log_volume = 3 * np.log(extent[feasible]) + np.sum(np.log(white)) - np.sum(np.log(u[feasible]), axis=1)
    log_weight[feasible] = power / 3.0 * log_volume - 1.5 * np.log(np.sum(u[feasible] ** 2, axis=1))
    weight = np.exp(log_weight - log_weight.max())
    return np.sum(rg * weight[:, None], axis=0) / weight.sum()


def monte_carlo_centroid(A, b, poly: Polytope, white, polygon, n: int, rng) -> np.ndarray:
    """Centroid in map space of ``{A d <= b}`` (optionally with the illuminant of ``d`` inside the
    (r,g) polygon) by uniform samples in the polytope's bounding box."""
    lo, hi = poly.vertices.min(axis=0), poly.vertices.max(axis=0)
    samples = lo + (hi - lo) * rng.random((n, 3))
    keep = np.all(samples @ A.T <= b, axis=1) & np.all(samples > 0, axis=1)
    samples = samples[keep]
    if polygon is not None:
        illum = white / samples
        keep = in_polygon(polygon, illum[:, :2] / illum.sum(axis=1, keepdims=True))
        samples = samples[keep]
    return samples.mean(axis=0)
