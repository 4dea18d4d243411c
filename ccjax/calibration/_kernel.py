"""The sensor-fitting kernel (Barnard 1999 §3.4): one data set, three channels, one compiled program.

For channel k the unknowns are ``[R (101), a0, a1]`` and the objective is

    sum_i w_i^2 (L_i . R + a0 + a1 e_i - r_i)^2  +  lambda^2 |S R|^2 / s^2          (3.5, 3.12, 3.16)

with ``S`` the second-difference matrix (3.4); the QPs are solved in ``_solvers``. Everything that
does not change the trace is in :class:`FitOptions` (traced arrays), so every linearisation and
every error kind shares one program per solver.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ccjax.calibration import _solvers
from ccjax.precision import matmul
from ccjax.spectra import N_WAVELENGTHS


def second_difference(n: int = N_WAVELENGTHS) -> np.ndarray:
    """The ``(n-2, n)`` second-difference matrix S of eq. 3.4 (rows ``-1, 2, -1``).

    Arguments:
        n: number of samples.

    Returns:
        The ``(n - 2, n)`` float64 matrix.
    """
    S = np.zeros((n - 2, n))
    for row in range(n - 2):
        S[row, row : row + 3] = (-1.0, 2.0, -1.0)
    return S


class FitOptions(NamedTuple):
    """Everything about one fit that does not change the compiled program (all traced)."""

    smoothness: Float[Array, ""]
    relative: Bool[Array, ""]
    linearised: Bool[Array, ""]  # the responses are raw: fit a0 (and a1 when ``fit_exp``)
    fit_exp: Bool[Array, ""]
    maxiter: Array
    floor_fraction: Float[Array, ""]
    floor_absolute: Float[Array, ""]
    max_abs: Float[Array, ""]
    max_rel: Float[Array, ""]
    black: Float[Array, "3"]
    exp_rate: Float[Array, "3"]
    lower: Float[Array, "n 3"]  # bounds of [R (101), a0, a1] per channel
    upper: Float[Array, "n 3"]


class ChannelFit(NamedTuple):
    sensor: Float[Array, " 101"]
    a0: Float[Array, ""]
    a1: Float[Array, ""]
    linear: Float[Array, " M"]
    objective: Float[Array, ""]
    solution: _solvers.Solution


def _masked_mean(values, mask):
    total = jnp.sum(jnp.where(mask, values, 0.0))
    return total / jnp.maximum(jnp.sum(mask), 1).astype(total.dtype)


def fit_channel(spectra, raw, mask, options: FitOptions, lower, upper, black, exp_rate, solver: str) -> ChannelFit:
    """One channel. The unknowns are always ``[R (101), a0, a1]``; a0, a1 are pinned to 0 by their
    bounds when they are not fitted, so every linearisation shares one compiled program."""
    dtype = spectra.dtype
    m, n_wl = spectra.shape
    tiny = jnp.finfo(dtype).tiny
    # exp(-C (r - b)), with the exponent capped so far-below-black values cannot overflow.
    decay = jnp.exp(jnp.minimum(-exp_rate * (raw - black), 60.0))
    design = jnp.concatenate([spectra, jnp.ones((m, 1), dtype), decay[:, None]], axis=1)
    S = jnp.asarray(second_difference(n_wl), dtype)
    roughness = jnp.zeros((n_wl + 2, n_wl + 2), dtype).at[:n_wl, :n_wl].set(matmul(S.T, S))
    row_sum = jnp.sum(spectra, axis=1)

    def linearised(x):
        return raw - x[n_wl] - x[n_wl + 1] * decay

    def solve(linear_estimate):
        top = jnp.max(jnp.where(mask, linear_estimate, 0.0))
        floor = jnp.maximum(jnp.maximum(options.floor_fraction * top, options.floor_absolute), tiny)
        typical = jnp.maximum(_masked_mean(linear_estimate, mask & (linear_estimate > 0)), floor)
        scale_rho = jnp.where(options.relative, jnp.maximum(linear_estimate, floor), typical)
        weight = jnp.where(mask, 1.0 / scale_rho, 0.0)
        sensor_scale = _masked_mean(jnp.maximum(linear_estimate, 0.0), mask) / jnp.maximum(
            _masked_mean(row_sum, mask), tiny
        )
        penalty = (options.smoothness / jnp.maximum(sensor_scale, tiny)) ** 2 * roughness
        weighted = design * weight[:, None]
        Q = matmul(weighted.T, weighted) + penalty
        c = matmul(weighted.T, weight * raw)
        if solver == "box":
            sol = _solvers.solve_box_qp(Q, c, lower, upper, maxiter=options.maxiter)
        elif solver == "osqp":
            # |design . x - raw| <= deviation, each row scaled by its weight so the constraint rows
            # are as well scaled as the objective (BoxOSQP does no equilibration of its own);
            # rows not fitted become 0 <= 0 +- 1 (inactive).
            deviation = jnp.minimum(options.max_abs, options.max_rel * jnp.maximum(linear_estimate, floor))
            target = weight * raw
            spread = jnp.where(mask, weight * deviation, 1.0)
            sol = _solvers.solve_qp(Q, c, lower, upper, weighted, target - spread, target + spread)
        else:
            sol = _solvers.solve_least_squares(weighted[:, :n_wl], weight * raw)
            sol = sol._replace(x=jnp.concatenate([sol.x, jnp.zeros(2, dtype)]))
        residual = weight * (matmul(design, sol.x) - raw)
        objective = jnp.sum(residual**2) + matmul(sol.x, matmul(penalty, sol.x))
        return sol, objective

    # Relative joint fits take two passes: rows weighted by r - b first, then by F(r) of pass one.
    passes = jnp.where(options.relative & options.linearised, 2, 1)

    def one_pass(_, carry):
        sol, objective = solve(carry[0])
        return linearised(sol.x), sol, objective

    empty = _solvers.Solution(
        x=jnp.zeros(n_wl + 2, dtype),
        kkt_residual=jnp.asarray(0.0, dtype),
        iterations=jnp.asarray(0),
        converged=jnp.asarray(False),
    )
    first = raw - jnp.where(options.linearised, black, 0.0)
    _, sol, objective = jax.lax.fori_loop(0, passes, one_pass, (first, empty, jnp.asarray(0.0, dtype)))
    return ChannelFit(
        sensor=sol.x[:n_wl],
        a0=sol.x[n_wl],
        a1=sol.x[n_wl + 1],
        linear=linearised(sol.x),
        objective=objective,
        solution=sol,
    )


@functools.partial(jax.jit, static_argnames="solver")
def fit_kernel(spectra, raw, mask, options: FitOptions, solver: str) -> ChannelFit:
    """One data set, the three channels vmapped. Leaves of the result have a leading axis of 3.

    BoxOSQP's channels run one after the other (``lax.map``) instead: under ``vmap`` its
    data-dependent refactorisations (``lax.cond``) would run at every ADMM iteration.
    """
    one = lambda r, lo, hi, b, C: fit_channel(spectra, r, mask, options, lo, hi, b, C, solver)
    per_channel = (raw.T, options.lower.T, options.upper.T, options.black, options.exp_rate)
    if solver == "osqp":
        return jax.lax.map(lambda args: one(*args), per_channel)
    return jax.vmap(one)(*per_channel)


@functools.partial(jax.jit, static_argnames="solver")
def fit_kernel_grid(spectra, raw, mask, options: FitOptions, exp_rates, solver: str) -> ChannelFit:
    """:func:`fit_kernel` for every row of ``exp_rates (G, 3)``; leaves gain a leading ``G`` axis."""
    return jax.vmap(lambda C: fit_kernel(spectra, raw, mask, options._replace(exp_rate=C), solver))(exp_rates)


def pick_lowest(fits: ChannelFit, exp_rates):
    """Per channel, the grid entry with the lowest objective."""
    best = jnp.argmin(fits.objective, axis=0)  # (3,)

    def take(leaf):
        index = best.reshape((1, 3) + (1,) * (leaf.ndim - 2))
        return jnp.take_along_axis(leaf, index, axis=0)[0]

    return jax.tree_util.tree_map(take, fits), jnp.take_along_axis(exp_rates, best[None, :], axis=0)[0]


SEARCH_POINTS = 11
SEARCH_RANGE = (2.0, 200.0)
"""C is searched over ``C * max(raw)`` in this range (the exponential then decays over 0.5 % to
50 % of the range of raw values)."""


@functools.partial(jax.jit, static_argnames=("solver", "search"))
def fit_data_set(spectra, raw, mask, options: FitOptions, solver: str, search: bool):
    """Fit one data set; with ``search``, C is the thesis' "trial and error" (§3.4) per channel: an
    11-point geometric grid of ``C * max(raw)`` over :data:`SEARCH_RANGE`, then 11 points spanning
    the neighbouring grid steps of the best one. Returns the fits and the C used ``(3,)``."""
    if not search:
        return fit_kernel(spectra, raw, mask, options, solver), options.exp_rate
    top = jnp.maximum(jnp.max(jnp.where(mask[:, None], raw, 0.0)), jnp.finfo(raw.dtype).tiny)
    lo, hi = SEARCH_RANGE
    steps = jnp.linspace(0.0, 1.0, SEARCH_POINTS, dtype=raw.dtype)
    coarse = (lo * (hi / lo) ** steps / top)[:, None] * jnp.ones((1, 3), raw.dtype)
    _, best = pick_lowest(fit_kernel_grid(spectra, raw, mask, options, coarse, solver), coarse)
    ratio = (hi / lo) ** (1.0 / (SEARCH_POINTS - 1))
    fine = best[None, :] * (ratio ** (2.0 * steps - 1.0))[:, None]
    return pick_lowest(fit_kernel_grid(spectra, raw, mask, options, fine, solver), fine)
