"""Validation of the sensor-fitting options and data, and their translation into the kernel's
traced options plus the static choices (solver, C search) (Barnard 1999 §3.4)."""

from __future__ import annotations

from typing import Literal, NamedTuple

import jax.numpy as jnp
import numpy as np

from ccjax.calibration._kernel import FitOptions
from ccjax.spectra import N_WAVELENGTHS, WAVELENGTHS

DEFAULT_SMOOTHNESS = 0.03
"""Default lambda (unit-free, see the module docstring). On the thesis' synthetic experiment (Sony
DXC-930, 614 measurements) five-fold cross-validation finds a flat optimum of held-out error between
0.01 and 0.1 (``ccjax calibrate --synthetic --cv``); on random subsets of 15–50 measurements (the
robustness experiment, Fig. 3.6) 0.01–0.03 is best, because with the thesis' summed data term a
fixed lambda smooths small data sets harder. 0.03 serves both."""

DEFAULT_FLOOR_FRACTION = 0.02
"""Default cap on the relative-error weight: rows below 2 % of the channel's largest response are
weighted as if they were at 2 % (the thesis caps the weight 1/rho, Barnard 1999 §3.4; about 5
pixel units on the 0–255 scale)."""

ErrorKind = Literal["relative", "absolute"]
LinearisationKind = Literal[None, "offset", "exp"]


def check_data(spectra, responses, mask=None):
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


class FitPlan(NamedTuple):
    options: FitOptions
    solver: str  # "box" (ProjectedGradient + polish), "osqp" (BoxOSQP), "lstsq" (SVD)
    search: bool  # search C
    kind: str | None


def plan_fit(
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
) -> FitPlan:
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
    options = FitOptions(
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
    search = linearisation == "exp" and exp_rate is None
    return FitPlan(options=options, solver=solver, search=search, kind=linearisation)


def data_arrays(spectra, responses, mask, plan: FitPlan):
    spectra, responses = check_data(spectra, responses, mask)
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
