"""Sensor fitting (Barnard 1999 §3.4): smooth, constrained, relative-error least squares.

For channel k, with spectra ``L`` (rows = measurements) and responses ``r``, the fit minimises

    sum_i w_i^2 (L_i . R + a0 + a1 e_i - r_i)^2  +  lambda^2 |S R|^2 / s^2          (3.5, 3.12, 3.16)

subject to positivity (3.7), the range constraint (3.8) and optional error bounds (3.9)/(3.13):

* ``w_i = 1 / max(rho_i, floor)`` for the relative error (3.10–3.12; the floor is the thesis' cap on
  the weight 1/rho), ``w_i = 1 / mean(rho)`` for the absolute error (3.5–3.6);
* ``a0, a1`` are the linearisation parameters of F(x) = x - a0 - a1 exp(-C (x - b)) (3.14), fitted
  jointly with R when ``linearisation="exp"`` (``"offset"``: a1 = 0, eq. 3.15; ``None``: the
  responses are already linear); ``e_i = exp(-C (r_i - b))``;
* ``S`` is the second-difference matrix (3.4) and ``s = mean(rho) / mean(sum_lambda L)`` the scale
  of a typical sensor value, so ``lambda`` does not depend on the units of spectra or responses.

The relative joint fit is the reconstruction of spec ch02-04 §4.3 (item 33): rows are weighted by the
linearised response, first estimated as ``r - b`` and then, in a second pass, as F(r) from the first
pass. Channels are independent (``vmap`` over channels); the QPs are solved in ``_solvers``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ccjax.calibration import _solvers
from ccjax.camera import Camera
from ccjax.spectra import N_WAVELENGTHS, WAVELENGTHS

DEFAULT_SMOOTHNESS = 0.03
"""Default lambda (unit-free, see the module docstring). On the thesis' synthetic experiment (Sony
DXC-930, 614 measurements) five-fold cross-validation finds a flat optimum of held-out error between
0.01 and 0.1 (``ccjax calibrate --synthetic --cv``); on random subsets of 15–50 measurements (the
robustness experiment, Fig. 3.6) 0.01–0.03 is best, because with the thesis' summed data term a
fixed lambda smooths small data sets harder. 0.03 serves both."""

DEFAULT_FLOOR_FRACTION = 0.02
"""Default cap on the relative-error weight: rows below 2 % of the channel's largest response are
weighted as if they were at 2 % (VERIFIED.md §7; about 5 pixel units on the 0–255 scale)."""

ErrorKind = Literal["relative", "absolute"]
LinearisationKind = Literal[None, "offset", "exp"]


def second_difference(n: int = N_WAVELENGTHS) -> np.ndarray:
    """The ``(n-2, n)`` second-difference matrix S of eq. 3.4 (rows ``-1, 2, -1``)."""
    S = np.zeros((n - 2, n))
    for row in range(n - 2):
        S[row, row : row + 3] = (-1.0, 2.0, -1.0)
    return S


@dataclass(frozen=True)
class Linearisation:
    """The fitted linearisation ``F(x) = x - a0 - a1 exp(-C (x - b))`` per channel (eq. 3.14).

    Hashable, so it can be a :class:`~ccjax.camera.Camera`'s static ``linearisation``. Calling it
    maps raw responses ``(..., 3)`` to linear ones. ``a1 = 0`` is the offset-only form (3.15).
    """

    a0: tuple[float, float, float]
    a1: tuple[float, float, float]
    exp_rate: tuple[float, float, float]
    black: tuple[float, float, float]

    def __call__(self, raw: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
        return apply_linearisation(
            raw, jnp.asarray(self.a0), jnp.asarray(self.a1), jnp.asarray(self.exp_rate), jnp.asarray(self.black)
        )


def apply_linearisation(raw, a0, a1, exp_rate, black):
    """``F(raw) = raw - a0 - a1 exp(-C (raw - b))`` element-wise per channel (eq. 3.14)."""
    raw = jnp.asarray(raw)
    return raw - a0 - a1 * jnp.exp(-exp_rate * (raw - black))


def invert_linearisation(linear, a0, a1, exp_rate, black, *, steps: int = 60):
    """Raw values ``x`` with ``F(x) = linear`` (Newton; F is strictly increasing for a1, C >= 0)."""
    linear = np.asarray(linear, dtype=np.float64)
    x = linear + a0 + np.maximum(a1, 0.0)
    for _ in range(steps):
        e = np.exp(-exp_rate * (x - black))
        x = x - (x - a0 - a1 * e - linear) / (1.0 + a1 * exp_rate * e)
    return x


class FitErrors(eqx.Module):
    """The error columns of Table 3.1, over measurements and channels.

    Attributes:
        rms_relative: RMS of ``(predicted - measured) / measured`` as a fraction (1.02 % = 0.0102).
        rms_absolute: RMS of ``predicted - measured`` in response units (thesis: 0–255 pixel units).
        rms_r, rms_g: RMS absolute error of the (r, g) chromaticity.
    """

    rms_relative: Float[Array, ""]
    rms_absolute: Float[Array, ""]
    rms_r: Float[Array, ""]
    rms_g: Float[Array, ""]

    def as_dict(self) -> dict[str, float]:
        return {name: float(getattr(self, name)) for name in ("rms_relative", "rms_absolute", "rms_r", "rms_g")}


def fit_errors(
    predicted: Float[Array, "M 3"], measured: Float[Array, "M 3"], mask: Bool[Array, " M"] | None = None
) -> FitErrors:
    """Table 3.1's errors of predicted against measured linear responses (jit-able).

    Relative errors use only entries with a positive measured response; chromaticity errors only
    rows with a positive sum. ``mask`` (True = use) selects measurements.
    """
    predicted = jnp.asarray(predicted)
    measured = jnp.asarray(measured)
    mask = jnp.ones(measured.shape[0], bool) if mask is None else jnp.asarray(mask, bool)
    entries = mask[:, None] & jnp.ones(measured.shape, bool)
    positive = entries & (measured > 0)
    relative = jnp.where(positive, (predicted - measured) / jnp.where(positive, measured, 1.0), 0.0)
    absolute = jnp.where(entries, predicted - measured, 0.0)

    def rms(values, where):
        return jnp.sqrt(jnp.sum(jnp.where(where, values**2, 0.0)) / jnp.maximum(jnp.sum(where), 1))

    sum_p = predicted.sum(-1, keepdims=True)
    sum_m = measured.sum(-1, keepdims=True)
    rows = mask & (sum_p[:, 0] > 0) & (sum_m[:, 0] > 0)
    rg_p = predicted[:, :2] / jnp.where(sum_p > 0, sum_p, 1.0)
    rg_m = measured[:, :2] / jnp.where(sum_m > 0, sum_m, 1.0)
    return FitErrors(
        rms_relative=rms(relative, positive),
        rms_absolute=rms(absolute, entries),
        rms_r=rms(rg_p[:, 0] - rg_m[:, 0], rows),
        rms_g=rms(rg_p[:, 1] - rg_m[:, 1], rows),
    )


class FitStatus(eqx.Module):
    """How the solver did, per channel."""

    solver: str = eqx.field(static=True)
    converged: Bool[Array, "3"]
    kkt_residual: Float[Array, "3"]
    iterations: Int[Array, "3"]


class SensorFit(eqx.Module):
    """A fitted camera model and its diagnostics (one data set).

    Attributes:
        camera: the fitted :class:`Camera` (its ``linearisation`` is the fitted F, if any).
        sensors: ``(101, 3)`` fitted curves; may be negative for fits without positivity, which is
            why they are also kept here (``camera.sensors`` is the same array).
        linearisation: the fitted :class:`Linearisation`, or ``None`` for linear data.
        smoothness: the lambda used.
        linear: ``(M, 3)`` measured responses after the fitted linearisation.
        predicted: ``(M, 3)`` ``spectra @ sensors``.
        mask: ``(M,)`` the measurements the fit used.
        errors: Table 3.1 errors of ``predicted`` against ``linear`` on the fitted measurements.
        status: solver diagnostics.
    """

    camera: Camera
    sensors: Float[Array, "101 3"]
    linearisation: Linearisation | None = eqx.field(static=True)
    smoothness: float = eqx.field(static=True)
    linear: Float[Array, "M 3"]
    predicted: Float[Array, "M 3"]
    mask: Bool[Array, " M"]
    errors: FitErrors
    status: FitStatus

    def evaluate(self, spectra, raw, mask=None) -> FitErrors:
        """Table 3.1 errors of this model on other measurements (raw responses are linearised by F)."""
        spectra, raw = _check_data(spectra, raw)
        linear = self.linearisation(raw) if self.linearisation is not None else jnp.asarray(raw)
        return fit_errors(jnp.asarray(spectra) @ self.sensors.astype(jnp.asarray(spectra).dtype), linear, mask)


# ---------------------------------------------------------------------------------------------
# the kernel


class _Options(NamedTuple):
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


class _ChannelFit(NamedTuple):
    sensor: Float[Array, " 101"]
    a0: Float[Array, ""]
    a1: Float[Array, ""]
    linear: Float[Array, " M"]
    objective: Float[Array, ""]
    solution: _solvers.Solution


def _masked_mean(values, mask):
    return jnp.sum(jnp.where(mask, values, 0.0)) / jnp.maximum(jnp.sum(mask), 1)


def _fit_channel(spectra, raw, mask, options: _Options, lower, upper, black, exp_rate, solver: str) -> _ChannelFit:
    """One channel. The unknowns are always ``[R (101), a0, a1]``; a0, a1 are pinned to 0 by their
    bounds when they are not fitted, so every linearisation shares one compiled program."""
    dtype = spectra.dtype
    m, n_wl = spectra.shape
    tiny = jnp.finfo(dtype).tiny
    # exp(-C (r - b)), with the exponent capped so far-below-black values cannot overflow.
    decay = jnp.exp(jnp.minimum(-exp_rate * (raw - black), 60.0))
    design = jnp.concatenate([spectra, jnp.ones((m, 1), dtype), decay[:, None]], axis=1)
    S = jnp.asarray(second_difference(n_wl), dtype)
    roughness = jnp.zeros((n_wl + 2, n_wl + 2), dtype).at[:n_wl, :n_wl].set(S.T @ S)
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
        Q = weighted.T @ weighted + penalty
        c = weighted.T @ (weight * raw)
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
        residual = weight * (design @ sol.x - raw)
        objective = jnp.sum(residual**2) + sol.x @ (penalty @ sol.x)
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
    return _ChannelFit(
        sensor=sol.x[:n_wl],
        a0=sol.x[n_wl],
        a1=sol.x[n_wl + 1],
        linear=linearised(sol.x),
        objective=objective,
        solution=sol,
    )


@functools.partial(jax.jit, static_argnames="solver")
def _fit_kernel(spectra, raw, mask, options: _Options, solver: str) -> _ChannelFit:
    """One data set, the three channels vmapped. Leaves of the result have a leading axis of 3.

    BoxOSQP's channels run one after the other (``lax.map``) instead: under ``vmap`` its
    data-dependent refactorisations (``lax.cond``) would run at every ADMM iteration.
    """
    one = lambda r, lo, hi, b, C: _fit_channel(spectra, r, mask, options, lo, hi, b, C, solver)
    per_channel = (raw.T, options.lower.T, options.upper.T, options.black, options.exp_rate)
    if solver == "osqp":
        return jax.lax.map(lambda args: one(*args), per_channel)
    return jax.vmap(one)(*per_channel)


@functools.partial(jax.jit, static_argnames="solver")
def _fit_kernel_grid(spectra, raw, mask, options: _Options, exp_rates, solver: str) -> _ChannelFit:
    """:func:`_fit_kernel` for every row of ``exp_rates (G, 3)``; leaves gain a leading ``G`` axis."""
    return jax.vmap(lambda C: _fit_kernel(spectra, raw, mask, options._replace(exp_rate=C), solver))(exp_rates)


def _pick(fits: _ChannelFit, exp_rates):
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
def _fit_data_set(spectra, raw, mask, options: _Options, solver: str, search: bool):
    """Fit one data set; with ``search``, C is the thesis' "trial and error" (§3.4) per channel: an
    11-point geometric grid of ``C * max(raw)`` over :data:`SEARCH_RANGE`, then 11 points spanning
    the neighbouring grid steps of the best one. Returns the fits and the C used ``(3,)``."""
    if not search:
        return _fit_kernel(spectra, raw, mask, options, solver), options.exp_rate
    top = jnp.maximum(jnp.max(jnp.where(mask[:, None], raw, 0.0)), jnp.finfo(raw.dtype).tiny)
    lo, hi = SEARCH_RANGE
    steps = jnp.linspace(0.0, 1.0, SEARCH_POINTS, dtype=raw.dtype)
    coarse = (lo * (hi / lo) ** steps / top)[:, None] * jnp.ones((1, 3), raw.dtype)
    _, best = _pick(_fit_kernel_grid(spectra, raw, mask, options, coarse, solver), coarse)
    ratio = (hi / lo) ** (1.0 / (SEARCH_POINTS - 1))
    fine = best[None, :] * (ratio ** (2.0 * steps - 1.0))[:, None]
    return _pick(_fit_kernel_grid(spectra, raw, mask, options, fine, solver), fine)


# ---------------------------------------------------------------------------------------------
# the public API


def _check_data(spectra, responses, mask=None):
    spectra = np.asarray(spectra, dtype=np.float64)
    responses = np.asarray(responses, dtype=np.float64)
    if spectra.ndim != 2 or spectra.shape[1] != N_WAVELENGTHS:
        raise ValueError(
            f"spectra: expected shape (M, {N_WAVELENGTHS}) on ccjax.spectra.WAVELENGTHS, got {spectra.shape}"
        )
    if responses.shape != (spectra.shape[0], 3):
        raise ValueError(f"responses: expected shape ({spectra.shape[0]}, 3) to match spectra, got {responses.shape}")
    if not np.all(np.isfinite(spectra)):
        raise ValueError("spectra: contains NaN or infinite values")
    if not np.all(np.isfinite(responses)):
        raise ValueError("responses: contains NaN or infinite values")
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != (spectra.shape[0],):
            raise ValueError(f"mask: expected shape ({spectra.shape[0]},), got {mask.shape}")
    return spectra, responses


def _per_channel(value, name, default):
    value = default if value is None else value
    out = np.broadcast_to(np.asarray(value, dtype=np.float64), (3,)).copy()
    if not np.all(np.isfinite(out)):
        raise ValueError(f"{name}: must be finite")
    return out


def _support_bounds(support, positive: bool) -> tuple[np.ndarray, np.ndarray]:
    """Sensor bounds ``(101, 3)`` from positivity (3.7) and the range constraint (3.8)."""
    lower = np.full((N_WAVELENGTHS, 3), 0.0 if positive else -np.inf)
    upper = np.full((N_WAVELENGTHS, 3), np.inf)
    if support is not None:
        support = np.asarray(support, dtype=np.float64)
        if support.shape != (3, 2) or not np.all(np.isfinite(support)) or np.any(support[:, 0] > support[:, 1]):
            raise ValueError("support: expected (3, 2) finite [min_nm, max_nm] per channel with min <= max")
        outside = (WAVELENGTHS[:, None] < support[None, :, 0]) | (WAVELENGTHS[:, None] > support[None, :, 1])
        upper = np.where(outside, 0.0, upper)  # (3.8): R_i <= 0 outside [min, max]
    return lower, upper


class _Plan(NamedTuple):
    options: _Options
    solver: str  # "box" (ProjectedGradient + polish), "osqp" (BoxOSQP), "lstsq" (SVD)
    search: bool  # search C
    kind: str | None


def _plan(
    *,
    smoothness,
    error,
    positive,
    support,
    max_abs_error,
    max_rel_error,
    weight_cap,
    linearisation,
    black,
    exp_rate,
    maxiter,
) -> _Plan:
    """Validate the fitting options and turn them into traced arrays plus the static choices."""
    if error not in ("relative", "absolute"):
        raise ValueError(f"error: expected 'relative' or 'absolute', got {error!r}")
    if linearisation not in (None, "offset", "exp"):
        raise ValueError(f"linearisation: expected None, 'offset' or 'exp', got {linearisation!r}")
    if np.ndim(smoothness) != 0 or not np.isfinite(smoothness) or smoothness < 0:
        raise ValueError(f"smoothness: expected a finite scalar >= 0, got {smoothness!r}")
    if weight_cap is not None and not (np.isfinite(weight_cap) and weight_cap > 0):
        raise ValueError(f"weight_cap: expected a positive finite number (maximum weight 1/rho), got {weight_cap!r}")
    for name, value in (("max_abs_error", max_abs_error), ("max_rel_error", max_rel_error)):
        if value is not None and not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name}: expected a positive finite number, got {value!r}")
    if linearisation != "exp" and exp_rate is not None:
        raise ValueError("exp_rate: only used with linearisation='exp'")
    if linearisation is None and black is not None:
        raise ValueError("black: only used with a linearisation ('offset' or 'exp')")
    if exp_rate is not None and np.any(np.asarray(exp_rate, dtype=np.float64) <= 0):
        raise ValueError(f"exp_rate: expected C > 0, got {exp_rate!r}")
    if maxiter is not None and int(maxiter) < 1:
        raise ValueError(f"maxiter: expected a positive integer, got {maxiter!r}")
    lower, upper = _support_bounds(support, positive)
    # a0 and a1 are free when fitted and pinned to 0 by their bounds otherwise.
    free_a0 = linearisation is not None
    free_a1 = linearisation == "exp"
    lower = np.concatenate(
        [lower, np.full((1, 3), -np.inf if free_a0 else 0.0), np.full((1, 3), -np.inf if free_a1 else 0.0)]
    )
    upper = np.concatenate(
        [upper, np.full((1, 3), np.inf if free_a0 else 0.0), np.full((1, 3), np.inf if free_a1 else 0.0)]
    )
    if max_abs_error is not None or max_rel_error is not None:
        solver = "osqp"
    elif positive or support is not None or smoothness > 0 or linearisation is not None:
        solver = "box"  # without any bound the polish is exactly the normal equations
    else:
        solver = "lstsq"
    dtype = jnp.zeros(0).dtype  # float32, or float64 under jax_enable_x64
    options = _Options(
        smoothness=jnp.asarray(smoothness, dtype),
        relative=jnp.asarray(error == "relative"),
        linearised=jnp.asarray(linearisation is not None),
        fit_exp=jnp.asarray(linearisation == "exp"),
        maxiter=jnp.asarray(3000 if maxiter is None else int(maxiter)),
        floor_fraction=jnp.asarray(0.0 if weight_cap is not None else DEFAULT_FLOOR_FRACTION, dtype),
        floor_absolute=jnp.asarray(0.0 if weight_cap is None else 1.0 / weight_cap, dtype),
        max_abs=jnp.asarray(np.inf if max_abs_error is None else max_abs_error, dtype),
        max_rel=jnp.asarray(np.inf if max_rel_error is None else max_rel_error, dtype),
        black=jnp.asarray(_per_channel(black, "black", 0.0), dtype),
        # C = 1 (any positive value) when unused: a1 is pinned to 0 and the column stays finite.
        exp_rate=jnp.asarray(_per_channel(exp_rate, "exp_rate", 1.0), dtype),
        lower=jnp.asarray(lower, dtype),
        upper=jnp.asarray(upper, dtype),
    )
    return _Plan(options=options, solver=solver, search=linearisation == "exp" and exp_rate is None, kind=linearisation)


def _data_arrays(spectra, responses, mask, plan: _Plan):
    spectra, responses = _check_data(spectra, responses, mask)
    mask = np.ones(spectra.shape[0], bool) if mask is None else np.asarray(mask, bool)
    if not mask.any():
        raise ValueError("mask: selects no measurement")
    if plan.kind is None and bool(plan.options.relative) and np.any(responses[mask] <= 0):
        raise ValueError(
            "responses: relative-error fitting of linear responses needs every used response > 0 (mask the others)"
        )
    flat = np.flatnonzero(np.all(responses[mask] <= responses[mask].min(axis=0), axis=0))
    if flat.size:
        raise ValueError(
            f"responses: channel {'RGB'[flat[0]]} has the same value in every used measurement; nothing to fit"
        )
    dtype = plan.options.smoothness.dtype
    return jnp.asarray(spectra, dtype), jnp.asarray(responses, dtype), jnp.asarray(mask)


def fit_sensors(
    spectra: Float[np.ndarray, "M 101"],
    responses: Float[np.ndarray, "M 3"],
    *,
    smoothness: float = DEFAULT_SMOOTHNESS,
    error: ErrorKind = "relative",
    positive: bool = True,
    support=None,
    max_abs_error: float | None = None,
    max_rel_error: float | None = None,
    weight_cap: float | None = None,
    linearisation: LinearisationKind = None,
    black=None,
    exp_rate=None,
    mask=None,
    name: str = "fitted",
    maxiter: int | None = None,
) -> SensorFit:
    """Fit sensor curves (and optionally the linearisation F) to calibration data (§3.4).

    Arguments:
        spectra: ``(M, 101)`` measured colour signals on :data:`ccjax.spectra.WAVELENGTHS`.
        responses: ``(M, 3)`` camera responses; linear ones for ``linearisation=None``, raw pixel
            values otherwise.
        smoothness: lambda of the second-difference regulariser (unit-free; 0 = none).
        error: ``"relative"`` (eqs. 3.10–3.12, the thesis' choice) or ``"absolute"`` (3.5–3.6).
        positive: positivity constraint R >= 0 (3.7).
        support: optional ``(3, 2)`` wavelength ranges [min, max] in nm per channel; the sensor is
            held at <= 0 outside (3.8), i.e. zero there together with positivity.
        max_abs_error: optional bound delta on |L.R - rho| (3.9), in response units.
        max_rel_error: optional bound zeta on the relative error (3.13), a fraction.
        weight_cap: upper bound on the relative-error weight 1/rho (response units^-1); default:
            rows below 2 % of the channel's largest response get the weight of 2 %.
        linearisation: ``None`` (responses are linear), ``"offset"`` (F(x) = x - a0, eq. 3.15) or
            ``"exp"`` (F(x) = x - a0 - a1 exp(-C (x - b)), eq. 3.14); a0, a1 are fitted with R.
        black: camera black b per channel (scalar or (3,)), default 0. Note that b only fixes the
            meaning of a1 (a1 exp(C b) is what the data determine), so it is given, not searched.
        exp_rate: C per channel (scalar or (3,)) for ``"exp"``; ``None`` searches a grid
            (:data:`SEARCH_RANGE`) per channel for the lowest objective, as the thesis' "trial
            and error".
        mask: optional ``(M,)`` booleans, True for the measurements to fit.
        name: the camera name.
        maxiter: cap on ProjectedGradient iterations (default 3000).

    Returns:
        A :class:`SensorFit`. Solver: jaxopt ``BoxOSQP`` with error bounds, otherwise jaxopt
        ``ProjectedGradient`` plus an exact active-set polish (with no bound at all the polish is
        the normal equations); the SVD pseudo-inverse for ``smoothness=0`` without any constraint.
    """
    plan = _plan(
        smoothness=smoothness,
        error=error,
        positive=positive,
        support=support,
        max_abs_error=max_abs_error,
        max_rel_error=max_rel_error,
        weight_cap=weight_cap,
        linearisation=linearisation,
        black=black,
        exp_rate=exp_rate,
        maxiter=maxiter,
    )
    data = _data_arrays(spectra, responses, mask, plan)
    fits, rates = _fit_data_set(*data, plan.options, plan.solver, plan.search)
    return _assemble(fits, rates, data, plan, float(smoothness), name)


SOLVER_NAMES = {
    "box": "jaxopt.ProjectedGradient + active-set polish",
    "osqp": "jaxopt.BoxOSQP",
    "lstsq": "SVD pseudo-inverse",
}


def _assemble(fits: _ChannelFit, rates, data, plan: _Plan, smoothness: float, name: str) -> SensorFit:
    spectra, _, mask = data
    sensors = fits.sensor.T  # (101, 3)
    linear = fits.linear.T  # (M, 3)
    predicted = spectra @ sensors
    if plan.kind is None:
        lin = None
    else:
        lin = Linearisation(
            a0=tuple(float(v) for v in fits.a0),
            a1=tuple(float(v) for v in fits.a1),
            exp_rate=tuple(float(v) for v in rates) if plan.kind == "exp" else (0.0,) * 3,
            black=tuple(float(v) for v in plan.options.black),
        )
    return SensorFit(
        camera=_camera(sensors, name, lin),
        sensors=sensors,
        linearisation=lin,
        smoothness=smoothness,
        linear=linear,
        predicted=predicted,
        mask=mask,
        errors=fit_errors(predicted, linear, mask),
        status=FitStatus(
            solver=SOLVER_NAMES[plan.solver],
            converged=fits.solution.converged,
            kkt_residual=fits.solution.kkt_residual,
            iterations=fits.solution.iterations,
        ),
    )


def _camera(sensors, name: str, linearisation: Linearisation | None) -> Camera:
    """The fitted camera: validated by ``Camera.from_array`` when the curves are physical
    (non-negative, some response per channel); fits without positivity keep their negative lobes."""
    values = np.asarray(sensors)
    if np.all(values >= 0) and np.all(values.sum(axis=0) > 0):
        sensors = Camera.from_array(values, name=name).sensors.astype(values.dtype)
    return Camera(sensors=jnp.asarray(sensors), name=name, linearisation=linearisation)


def pseudo_inverse(spectra, responses, *, positive: bool = False, mask=None, name: str = "pseudo-inverse") -> SensorFit:
    """The pseudo-inverse baselines of §3.3 / Table 3.1 on linear responses (eq. 3.3).

    ``positive=False``: the minimum-norm least-squares solution of ``r = L R`` (no constraint, no
    smoothing; spiky and with negative lobes, Fig. 3.4). ``positive=True``: the same absolute error
    with R >= 0 (Fig. 3.5), solved by :func:`fit_sensors` with ``smoothness=0``.
    """
    return fit_sensors(spectra, responses, smoothness=0.0, error="absolute", positive=positive, mask=mask, name=name)


def support_of(sensors: Float[np.ndarray, "101 3"], threshold: float = 0.01) -> np.ndarray:
    """The main-peak range of each curve: the contiguous wavelengths around the peak where the
    curve stays above ``threshold`` x its peak ("the obvious boundaries of the main peaks", §3.6).

    Returns:
        ``(3, 2)`` [min_nm, max_nm] per channel, for ``fit_sensors(support=...)``.
    """
    sensors = np.asarray(sensors, dtype=np.float64)
    out = np.zeros((3, 2))
    for k in range(3):
        curve = sensors[:, k]
        peak = int(np.argmax(curve))
        above = curve >= threshold * curve[peak]
        lo = peak
        while lo > 0 and above[lo - 1]:
            lo -= 1
        hi = peak
        while hi < len(curve) - 1 and above[hi + 1]:
            hi += 1
        out[k] = WAVELENGTHS[lo], WAVELENGTHS[hi]
    return out


def curve_error(fitted: Float[np.ndarray, "101 3"], truth: Float[np.ndarray, "101 3"]) -> np.ndarray:
    """RMS over wavelengths of ``fitted - truth`` as a fraction of each true curve's peak, ``(3,)``."""
    fitted = np.asarray(fitted, dtype=np.float64)
    truth = np.asarray(truth, dtype=np.float64)
    return np.sqrt(np.mean((fitted - truth) ** 2, axis=0)) / truth.max(axis=0)
