"""Fit-time geometry of gamut mapping (NumPy/SciPy, run once per world).

* The canonical gamut (Barnard 1999 §2.3.4, §4.5.3): the convex hull of the
  origin and the canonical RGBs of the reflectance database, in H-form ``n_k . x <= c_k``, with
  ``c_k = 0`` *exactly* for the facets through the origin (those alone decide which illuminant
  chromaticities are feasible; the others bound brightness).
* The ND gamut (§6.1): the hull of the canonical gamut and every training
  illuminant's gamut mapped white-to-white into the canonical light.
* Cones through the origin given by generator directions (the training illuminants for the
  illumination constraint of ECRULE, §2.3.4; their map directions ``w_C / e`` for the convex
  approximation used by ECRULE-AVE), as unit outward face normals: a direction ``x`` is inside iff
  ``max_l n_l . x / |x| <= 0``, and that maximum is the sine of how far outside it lies.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ccjax._colour import rg_numpy

# Two triangulated facets of one plane are merged when their unit equations agree to this much.
_COPLANAR = 1e-9


@dataclass(frozen=True)
class Facets:
    """A convex polytope containing the origin, ``{x : n_k . x <= c_k}`` (float64 NumPy arrays).

    Attributes:
        origin_normals: ``(K0, 3)`` unit outward normals of the facets through the origin (``c = 0``).
        top_normals: ``(K1, 3)`` unit outward normals of the other facets.
        top_offsets: ``(K1,)`` their offsets ``c_k > 0``.
        vertices: ``(V, 3)`` the hull's vertices (the origin included).
    """

    origin_normals: np.ndarray
    top_normals: np.ndarray
    top_offsets: np.ndarray
    vertices: np.ndarray


def gamut_facets(points: np.ndarray) -> Facets:
    """H-form of ``conv({0} ∪ points)`` by Qhull (Barnard 1999 §4.5.3).

    Arguments:
        points: ``(S, 3)`` non-negative RGBs spanning 3-D.

    Returns:
        The facets; a facet is an origin facet iff its Qhull simplex contains the origin, and then
        its offset is set to exactly 0 (Qhull's is only ~1e-17).
    """
    from scipy.spatial import ConvexHull  # imported on use: scipy.spatial is slow to import

    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 3:
        raise ValueError(f"points: expected (S >= 3, 3) RGBs, got shape {points.shape}")
    if not np.all(np.isfinite(points)) or np.any(points < 0):
        raise ValueError("points: expected finite non-negative RGBs")
    cloud = np.vstack([np.zeros(3), points])
    hull = ConvexHull(cloud)
    normals = hull.equations[:, :3]
    lengths = np.linalg.norm(normals, axis=1)
    normals = normals / lengths[:, None]
    offsets = -hull.equations[:, 3] / lengths
    through_origin = np.any(hull.simplices == 0, axis=1)
    offsets[through_origin] = 0.0
    # Qhull triangulates non-simplicial facets; merge the copies of one plane.
    keys = np.hstack([normals, offsets[:, None]])
    keep = np.ones(len(keys), bool)
    for i in range(len(keys)):
        if keep[i]:
            same = np.all(np.abs(keys[i + 1 :] - keys[i]) < _COPLANAR, axis=1)
            keep[i + 1 :] &= ~same
    origin = through_origin & keep
    top = ~through_origin & keep
    return Facets(
        origin_normals=normals[origin],
        top_normals=normals[top],
        top_offsets=offsets[top],
        vertices=cloud[hull.vertices],
    )


def nd_points(
    reflectances: np.ndarray, sensors: np.ndarray, illuminants: np.ndarray, canonical: np.ndarray
) -> np.ndarray:
    """Points of the ND gamut (§6.1): each illuminant's database RGBs mapped white-to-white.

    Arguments:
        reflectances: ``(S, 101)``.
        sensors: ``(101, 3)``.
        illuminants: ``(I, 101)`` the representative illuminants (the training set).
        canonical: ``(101,)`` the canonical light.

    Returns:
        ``(S * (I + 1), 3)``: the canonical RGBs, then ``diag(w_C / w_i) X_i`` for every i.
    """
    reflectances = np.asarray(reflectances, np.float64)
    sensors = np.asarray(sensors, np.float64)
    white_c = np.asarray(canonical, np.float64) @ sensors
    blocks = [(reflectances * canonical) @ sensors]
    for light in np.asarray(illuminants, np.float64):
        white = light @ sensors
        blocks.append(((reflectances * light) @ sensors) * (white_c / white))
    return np.vstack(blocks)


def cone_planes(directions: np.ndarray) -> np.ndarray:
    """Unit outward face normals of the convex cone spanned by non-negative 3-vectors.

    The cone's cross-section is the convex hull of the directions' chromaticities (any central
    projection gives the same cone); each hull edge ``(a, b)`` gives the
    face normal ``a x b`` oriented away from the cone's interior.

    Arguments:
        directions: ``(N >= 3, 3)`` non-negative vectors with positive sums whose chromaticities
            are not collinear.

    Returns:
        ``(L, 3)`` unit normals, one per face.
    """
    from scipy.spatial import ConvexHull  # imported on use: scipy.spatial is slow to import

    directions = np.asarray(directions, np.float64)
    if directions.ndim != 2 or directions.shape[1] != 3 or len(directions) < 3:
        raise ValueError(f"directions: expected (N >= 3, 3) vectors, got shape {directions.shape}")
    if np.any(directions < 0) or np.any(directions.sum(axis=1) <= 0):
        raise ValueError("directions: expected non-negative vectors with positive sums")
    chroma = directions / directions.sum(axis=1, keepdims=True)
    hull = ConvexHull(chroma[:, :2])
    inside = chroma[hull.vertices].mean(axis=0)
    planes = []
    for a, b in hull.simplices:
        normal = np.cross(chroma[a], chroma[b])
        normal /= np.linalg.norm(normal)
        planes.append(-normal if normal @ inside > 0 else normal)
    return np.asarray(planes)


def cone_violation(planes: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``max_l n_l . x / |x|``: <= 0 inside the cone, else the sine of the angle outside it."""
    x = np.asarray(x, np.float64)
    return np.max(x @ planes.T, axis=-1) / np.linalg.norm(x, axis=-1)


def map_cone_chromaticities(white: np.ndarray, whites: np.ndarray, samples: int = 257) -> np.ndarray:
    """(r,g) chromaticities of the illuminants ``w_C / d`` for map directions ``d`` on the boundary
    of the convex cone of the training maps ``w_C / e_j`` (Barnard 1995's convex approximation of
    the illumination constraint): their box bounds every direction that approximation allows.

    Arguments:
        white: ``(3,)`` canonical white; whites: ``(N, 3)`` the training illuminants' whites.
        samples: points per edge of the cone's cross-section.

    Returns:
        ``(E * samples, 2)`` chromaticities.
    """
    from scipy.spatial import ConvexHull  # imported on use: scipy.spatial is slow to import

    maps = np.asarray(white, np.float64) / np.asarray(whites, np.float64)
    projected = maps / maps.sum(axis=1, keepdims=True)
    extreme = projected[ConvexHull(projected[:, :2]).vertices]
    t = np.linspace(0.0, 1.0, samples)[:, None, None]
    boundary = ((1 - t) * extreme[None] + t * np.roll(extreme, -1, axis=0)[None]).reshape(-1, 3)
    illuminants = white / boundary
    return rg_numpy(illuminants)


def simplex_grid(step: float, box: tuple[float, float, float, float] = (0.0, 1.0, 0.0, 1.0)) -> np.ndarray:
    """Cell centres ``(r, g)`` of a square grid of ``step`` over ``box = (r0, r1, g0, g1)`` that lie
    inside the chromaticity triangle (``r, g > 0``, ``r + g < 1``)."""
    r0, r1, g0, g1 = box
    r = np.arange(r0 + step / 2, r1, step)
    g = np.arange(g0 + step / 2, g1, step)
    rr, gg = np.meshgrid(r, g, indexing="ij")
    rg = np.stack([rr.ravel(), gg.ravel()], axis=1)
    inside = (rg[:, 0] > 0) & (rg[:, 1] > 0) & (rg.sum(axis=1) < 1.0)
    return rg[inside]


def preimage_box(planes_map: np.ndarray, white: np.ndarray, step: float = 0.002) -> tuple[float, float, float, float]:
    """Bounding box in illuminant ``(r, g)`` of the directions ``u`` whose map direction ``w_C / u``
    lies in the cone given by ``planes_map`` (found on a fine grid over the triangle)."""
    rg = simplex_grid(step)
    u = np.column_stack([rg, 1.0 - rg.sum(axis=1)])
    inside = cone_violation(planes_map, white / u) <= 0
    if not np.any(inside):
        raise ValueError("planes_map: the cone contains no map direction of a chromaticity")
    chosen = rg[inside]
    return (chosen[:, 0].min(), chosen[:, 0].max(), chosen[:, 1].min(), chosen[:, 1].max())
