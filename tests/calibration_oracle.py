"""SciPy oracle for the chapter-3 sensor fits, written from Barnard 1999 §3.4 (eqs. 3.5-3.16), not from ccjax.

Each fit is the stacked least-squares system of eqs. 3.5 / 3.12 / 3.16,

    [ W L        W 1      W e ] [ R  ]   [ W r ]
    [ (lam/s) S   0        0  ] [ a0 ] = [  0  ]
                                [ a1 ]

with W = diag(weights), solved with scipy.optimize.lsq_linear under bounds (positivity 3.7, range
3.8) or scipy.optimize.minimize(method="SLSQP") under the error bounds 3.9 / 3.13. The conventions it
shares with ccjax (they define the problem, not the solution): relative weights 1 / max(rho, 2 % of
the channel's largest rho), absolute weights 1 / mean(rho); the smoothness scale
s = mean(rho) / mean(row sums of L); relative joint fits weight the rows by r - b in a first pass
and by F(r) of that pass in a second.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import lsq_linear, minimize

WAVELENGTHS = np.arange(380.0, 781.0, 4.0)


def second_difference(n: int) -> np.ndarray:
    S = np.zeros((n - 2, n))
    for i in range(n - 2):
        S[i, i] = -1.0
        S[i, i + 1] = 2.0
        S[i, i + 2] = -1.0
    return S


def _weights(rho: np.ndarray, relative: bool, floor_fraction: float = 0.02) -> np.ndarray:
    floor = floor_fraction * rho.max()
    if relative:
        return 1.0 / np.maximum(rho, floor)
    return np.full_like(rho, 1.0 / max(rho[rho > 0].mean(), floor))


def _system(L, r, rho, smoothness, relative, columns):
    """Stack the weighted data rows (with the extra linearisation columns) over the smoothness rows."""
    n = L.shape[1]
    w = _weights(rho, relative)
    s = np.mean(np.maximum(rho, 0.0)) / np.mean(L.sum(axis=1))
    data = np.hstack([L] + [c[:, None] for c in columns]) * w[:, None]
    smooth = np.hstack([(smoothness / s) * second_difference(n), np.zeros((n - 2, len(columns)))])
    A = np.vstack([data, smooth])
    b = np.concatenate([w * r, np.zeros(n - 2)])
    return A, b


def bounds_for(positive: bool, support=None, n_extra: int = 0):
    lower = np.full(101, 0.0 if positive else -np.inf)
    upper = np.full(101, np.inf)
    if support is not None:
        lo, hi = support
        upper[(WAVELENGTHS < lo) | (WAVELENGTHS > hi)] = 0.0
    return np.concatenate([lower, np.full(n_extra, -np.inf)]), np.concatenate([upper, np.full(n_extra, np.inf)])


def _bounded_least_squares(A, b, lower, upper):
    """lsq_linear, with unknowns whose bounds coincide (R = 0 outside the range) eliminated."""
    fixed = lower == upper
    x = np.where(fixed, lower, 0.0)
    reduced = lsq_linear(
        A[:, ~fixed],
        b - A[:, fixed] @ x[fixed],
        bounds=(lower[~fixed], upper[~fixed]),
        method="bvls",
        tol=1e-13,
        max_iter=10000,
    )
    x[~fixed] = reduced.x
    return x


def fit_channel(L, r, *, smoothness, relative=True, positive=True, support=None, black=None, exp_rate=None):
    """One channel with ``lsq_linear`` (bounds only). ``exp_rate`` given -> the joint fit of eq. 3.14.

    Returns ``(R, a0, a1)`` (a0 = a1 = 0 for linear data).
    """
    lower, upper = bounds_for(positive, support, 0 if exp_rate is None else 2)
    if exp_rate is None:
        A, b = _system(L, r, r, smoothness, relative, [])
        return _bounded_least_squares(A, b, lower, upper), 0.0, 0.0
    decay = np.exp(-exp_rate * (r - black))
    rho = r - black
    for _ in range(2 if relative else 1):
        A, b = _system(L, r, rho, smoothness, relative, [np.ones_like(r), decay])
        x = _bounded_least_squares(A, b, lower, upper)
        rho = r - x[101] - x[102] * decay
    return x[:101], x[101], x[102]


def fit_channel_slsqp(L, r, *, smoothness, relative=True, positive=True, max_abs_error=None, max_rel_error=None):
    """One channel of linear data with the error bounds (3.9) / (3.13) through SLSQP.

    Unknowns are scaled so the objective's Hessian has a unit diagonal (x = D u, bounds stay
    bounds) and each error constraint is divided by its bound, which SLSQP needs to converge in a
    reasonable number of steps. Returns ``(R, scipy result)``.
    """
    A, b = _system(L, r, r, smoothness, relative, [])
    Q = A.T @ A
    c = A.T @ b
    D = 1.0 / np.sqrt(np.diag(Q))
    Qs = Q * D[:, None] * D[None, :]
    cs = c * D
    start = lsq_linear(A, b, bounds=bounds_for(positive), method="bvls").x / D
    deviation = np.full_like(r, np.inf)
    if max_abs_error is not None:
        deviation = np.minimum(deviation, max_abs_error)
    if max_rel_error is not None:
        deviation = np.minimum(deviation, max_rel_error * np.maximum(r, 0.02 * r.max()))
    G = (L * D[None, :]) / deviation[:, None]
    lo = (r - deviation) / deviation
    hi = (r + deviation) / deviation
    constraints = [
        {"type": "ineq", "fun": lambda u: G @ u - lo, "jac": lambda u: G},
        {"type": "ineq", "fun": lambda u: hi - G @ u, "jac": lambda u: -G},
    ]
    result = minimize(
        lambda u: 0.5 * u @ Qs @ u - cs @ u,
        start,
        jac=lambda u: Qs @ u - cs,
        bounds=[(0.0, None) if positive else (None, None)] * L.shape[1],
        constraints=constraints,
        method="SLSQP",
        options={"ftol": 1e-13, "maxiter": 1000},
    )
    return D * result.x, result
