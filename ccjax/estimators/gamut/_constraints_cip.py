"""The 2-D constraint set of Colour in Perspective (Barnard 1999 §4.5.3):
per-direction violations of the perspective and illumination constraints, and the
feasible fraction of each grid cell that CIP's averages integrate.

A perspective constraint "``D * p`` lies in the canonical polygon of ``(R/B, G/B)``" is a cone
through the origin in RGB, so for a direction ``u`` with map ``m(u) = w_C / u`` it reads
``n_k . (m(u) * p) <= 0`` for the cone's unit face normals ``n_k``: a mask on ``u`` with no
brightness bound. Its normalised violation ``max_{j,k} n_k . (p_j * m) / |p_j * m|`` is the sine
of how far the worst mapped colour lies outside the cone; the illumination constraint adds
``max_l h_l . x / |x|`` with ``x = u`` (exact, the training illuminants' cone) or ``x = m(u)``
(the convex hull of the training maps, Barnard 1995).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ccjax._colour import TINY
from ccjax.estimators.gamut._engine import OUTSIDE, directions


def _max_of_dots(x: Float[Array, "3 G"], vectors: Float[Array, "K 3"]) -> Float[Array, " G"]:
    # max_k x_g . vectors_k as unrolled multiply-adds and maxima on component-major rows: far
    # faster than (batched) length-3 matrix products on CPU.
    best = x[0] * vectors[0, 0] + x[1] * vectors[0, 1] + x[2] * vectors[0, 2]
    for k in range(1, vectors.shape[0]):
        best = jnp.maximum(best, x[0] * vectors[k, 0] + x[1] * vectors[k, 1] + x[2] * vectors[k, 2])
    return best


def violation(
    white: Float[Array, "3"],
    surface_planes: Float[Array, "K 3"],
    illuminant_planes: Float[Array, "L 3"],
    illumination: str,
    rg: Float[Array, "G 2"],
    rgb: Float[Array, "P 3"],
    valid: Bool[Array, " P"],
) -> Float[Array, " G"]:
    """Largest normalised violation (a sine) of the perspective and illumination constraints.

    Arguments:
        white: ``(3,)`` canonical white ``w_C``.
        surface_planes: ``(K, 3)`` unit face normals of the cone over the canonical polygon.
        illuminant_planes: ``(L, 3)`` unit face normals of the illumination constraint's cone.
        illumination: ``"exact"`` (the planes bound ``u``) or ``"hull"`` (they bound ``m(u)``).
        rg: ``(G, 2)`` directions; rgb: ``(P, 3)`` observations; valid: ``(P,)`` those that constrain.

    Returns:
        ``(G,)`` violations, ``<= 0`` exactly where feasible; ``OUTSIDE`` outside the triangle.
    """
    u, _, inside = directions(rg)
    # Component-major (3, G): every per-direction quantity is an elementwise expression on
    # contiguous rows, which XLA fuses into vectorised CPU loops.
    u = u.T
    m = white[:, None] / u
    scaled = surface_planes[None, :, :] * rgb[:, None, :]  # (P, K, 3): n_k * p_j

    # One observation at a time: memory stays O(G) whatever the number of observations, and each
    # step is one fused elementwise loop over the directions (measured as fast as evaluating all
    # of them at once, already for 8).
    def pixel(j, worst):
        along = _max_of_dots(m, scaled[j])  # max_k (n_k * p_j) . m
        length = jnp.sqrt(sum((m[c] * rgb[j, c]) ** 2 for c in range(3)))  # |p_j * m|
        return jnp.where(valid[j], jnp.maximum(worst, along / jnp.maximum(length, TINY)), worst)

    surface = jax.lax.fori_loop(0, rgb.shape[0], pixel, jnp.full(u.shape[1:], -1.0, u.dtype))
    x = u if illumination == "exact" else m
    x = x / jnp.sqrt(jnp.sum(x * x, axis=0))
    return jnp.where(inside, jnp.maximum(surface, _max_of_dots(x, illuminant_planes)), OUTSIDE)


def coverage(v: Float[Array, " G"], n: int) -> Float[Array, " G"]:
    """Fraction of each cell of an ``n x n`` grid where the violation is ``<= 0``.

    The violation is taken as linear across the cell with the central-difference slopes
    ``a, b`` (per cell width) of the grid, ``v0 + a s + b t`` with ``s, t`` uniform in
    ``[-1/2, 1/2]``; the covered fraction is the CDF at ``-v0`` of that trapezoidal distribution.
    This makes the boundary error of the integrals second order instead of first (a cell counts
    with the part of it that is feasible, not all or nothing).
    """
    grid = v.reshape(n, n)

    def slope(axis):
        padded = jnp.pad(grid, [(1, 1) if a == axis else (0, 0) for a in range(2)], mode="reflect", reflect_type="odd")
        centre = jax.lax.slice_in_dim(padded, 1, n + 1, axis=axis)
        ahead = jax.lax.slice_in_dim(padded, 2, n + 2, axis=axis) - centre
        behind = centre - jax.lax.slice_in_dim(padded, 0, n, axis=axis)
        return jnp.maximum(jnp.abs(ahead), jnp.abs(behind)).ravel()

    a, b = slope(0), slope(1)
    a, b = jnp.maximum(a, b), jnp.minimum(a, b)
    x = -v
    half = 0.5 * (a + b)
    knee = 0.5 * (a - b)
    flat = b <= 1e-6 * a  # one slope only: uniform distribution of width a
    a_safe = jnp.maximum(a, TINY)
    b_safe = jnp.where(flat, 1.0, jnp.maximum(b, TINY))
    ramp = jnp.where(
        x <= -knee,
        jnp.square(jnp.maximum(x + half, 0.0)) / (2.0 * a_safe * b_safe),
        jnp.where(
            x <= knee,
            b / (2.0 * a_safe) + (x + knee) / a_safe,
            1.0 - jnp.square(jnp.maximum(half - x, 0.0)) / (2.0 * a_safe * b_safe),
        ),
    )
    uniform = (x + 0.5 * a) / a_safe
    fraction = jnp.where(flat, uniform, ramp)
    # No slope at all (a constant violation): all or nothing.
    fraction = jnp.where(a <= TINY, (v <= 0).astype(v.dtype), fraction)
    # The violation is a maximum of smooth functions: beyond the tip of a feasible spike it has a
    # valley of small positive values that a linear model would read as a boundary crossing. An
    # infeasible centre only counts when a 4-neighbour is feasible (the boundary is really there).
    feasible = jnp.pad(grid <= 0, 1)
    near = feasible[:-2, 1:-1] | feasible[2:, 1:-1] | feasible[1:-1, :-2] | feasible[1:-1, 2:]
    fraction = jnp.where((v <= 0) | near.ravel(), fraction, 0.0)
    return jnp.clip(fraction, 0.0, 1.0)
