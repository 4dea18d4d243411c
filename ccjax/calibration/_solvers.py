"""The quadratic programmes behind every chapter-3 fit, solved with jaxopt (Barnard 1999 §3.4).

Each fit of Barnard 1999 §3.4 is a least-squares problem with linear constraints, i.e. a convex
quadratic programme in the stacked unknowns ``x`` (sensor samples, then linearisation parameters):

    minimise  ½ xᵀ Q x − cᵀ x   subject to   lower <= x <= upper   [and  g_lo <= G x <= g_hi].

* Bounds only (positivity (3.7), the range constraint (3.8)): jaxopt ``ProjectedGradient``
  (accelerated, fixed step 1/‖Q‖) in rounds, each finished by a Lawson–Hanson active-set polish
  (the step OSQP calls "polishing"): with the active bounds fixed, the other unknowns solve a
  linear system exactly, so the answer is exact once the active set is right. The result with the
  smaller KKT residual is kept. With no bound at all the polish is the normal equations.
* General linear inequalities (the error bounds (3.9), (3.13)): jaxopt ``BoxOSQP``.
* Smoothness 0 and no constraint (the pseudo-inverse, eq. 3.3): the SVD least-squares solution.

All solvers work on the Jacobi-scaled problem (unit diagonal), which leaves box constraints boxes
and makes one step size fit every channel. Everything here is jit- and vmap-able; jaxopt is
imported only in this module and only its own DeprecationWarning is silenced.
"""

from __future__ import annotations

import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ccjax.precision import highest_within, matmul

with warnings.catch_warnings():
    # jaxopt announces on import that it is no longer maintained; the project uses it on purpose
    # (the project's choice of QP library), so silence exactly that warning and nothing else.
    warnings.filterwarnings("ignore", category=DeprecationWarning, module="jaxopt")
    import jaxopt

POLISH_STEPS = 300


class Solution(NamedTuple):
    """A QP solution and how it was reached (one problem; batched under ``vmap``)."""

    x: Float[Array, " n"]
    kkt_residual: Float[Array, ""]  # max |y - clip(y - grad)| / gradient scale, Jacobi-scaled problem
    iterations: Int[Array, ""]
    converged: Bool[Array, ""]


def _tolerance(dtype) -> float:
    """Relative KKT residual accepted as converged (a few hundred ulps of the gradient's terms)."""
    return 1e-12 if jnp.finfo(dtype).bits == 64 else 1e-5


def _jacobi(Q, c, lower, upper):
    """Scale unknowns so ``Q`` has a unit diagonal: ``x = d * y``."""
    diag = jnp.diag(Q)
    d = 1.0 / jnp.sqrt(jnp.maximum(diag, 1e-12 * jnp.max(diag)))
    return Q * d[:, None] * d[None, :], c * d, lower / d, upper / d, d


def _kkt_residual(Qs, cs, y, lower, upper):
    """Projected-gradient residual ``max |y - clip(y - grad)|`` and the rounding level it is
    compared with (the size of the terms that make up the gradient)."""
    grad = matmul(Qs, y) - cs
    residual = jnp.max(jnp.abs(y - jnp.clip(y - grad, lower, upper)))
    size = jnp.maximum(1.0, jnp.max(jnp.abs(cs)) + jnp.max(matmul(jnp.abs(Qs), jnp.abs(y))))
    return residual, size


def _relative_residual(Qs, cs, y, lower, upper):
    """KKT residual relative to the gradient's scale; ``inf`` for a non-finite point."""
    residual, size = _kkt_residual(Qs, cs, y, lower, upper)
    return jnp.where(jnp.all(jnp.isfinite(y)) & jnp.isfinite(residual), residual / size, jnp.inf)


def _polish(Qs, cs, y, lower, upper):
    """Lawson–Hanson active-set iterations (Lawson & Hanson 1974, ch. 23), warm-started at ``y``.

    Bounds are taken per unknown as fixed (``lower == upper``), free, or one-sided (the upper-bounded
    ones are mirrored into lower-bounded ones) — the only kinds the sensor fits create. With the
    passive set P, the passive unknowns solve the equality-constrained problem exactly (Cholesky of
    the passive block); a step that would cross a bound is shortened to it and that unknown leaves
    P; then the bounded unknown with the most negative gradient enters P, until none has one (the
    KKT conditions hold) or ``POLISH_STEPS`` outer steps have been taken. Warm-started from the
    gradient method's support this usually ends after one solve; from a poor start it still
    converges, where a primal–dual active-set method can cycle on the ill-conditioned
    pseudo-inverse problems.
    """
    n = y.shape[0]
    dtype = y.dtype
    ridge = 10 * jnp.finfo(dtype).eps
    fixed = jnp.isfinite(lower) & (lower == upper)
    has_lower = jnp.isfinite(lower) & ~fixed
    has_upper = jnp.isfinite(upper) & ~fixed & ~has_lower
    bounded = has_lower | has_upper
    sign = jnp.where(has_upper, -1.0, 1.0).astype(dtype)
    offset = jnp.where(has_lower | fixed, jnp.where(jnp.isfinite(lower), lower, 0.0), jnp.where(has_upper, upper, 0.0))
    # x = offset + sign * z with z >= 0 on bounded unknowns, z free on free ones, z = 0 on fixed ones.
    Qz = Qs * sign[:, None] * sign[None, :]
    cz = sign * (cs - matmul(Qs, offset))
    z = jnp.where(fixed, 0.0, sign * (y - offset))
    z = jnp.where(bounded, jnp.maximum(z, 0.0), z)
    passive = ~fixed & (~bounded | (z > 0))
    tiny = jnp.finfo(dtype).tiny

    def solve_on(P):
        p = P.astype(dtype)
        K = Qz * p[:, None] * p[None, :] + jnp.diag(1.0 - p + ridge * p)
        return p * jax.scipy.linalg.cho_solve(jax.scipy.linalg.cho_factor(K), p * cz)

    def inner_step(state):
        z, P, _, count = state
        s = solve_on(P)
        # A numerically singular passive block (more passive unknowns than independent rows, in
        # float32): keep z and drop the passive set back to what z supports.
        finite = jnp.all(jnp.isfinite(s))
        s = jnp.where(finite, s, z)
        crossing = P & bounded & (s <= 0)
        ok = ~jnp.any(crossing)
        ratio = jnp.where(crossing, z / jnp.maximum(z - s, tiny), jnp.inf)
        j = jnp.argmin(ratio)
        alpha = jnp.clip(ratio[j], 0.0, 1.0)
        z_new = jnp.where(ok, s, z + alpha * (s - z))
        z_new = jnp.where(bounded, jnp.maximum(z_new, 0.0), z_new)
        leaving = bounded & (z_new <= 0)
        P_new = jnp.where(ok, P, P & ~leaving & (jnp.arange(n) != j))
        z_new = jnp.where(P_new | ~bounded, z_new, 0.0)
        P_new = jnp.where(finite, P_new, P & (~bounded | (z > 0)))
        return z_new, P_new, ok | ~finite, count + 1

    def consistent(z, P):
        return jax.lax.while_loop(
            lambda st: ~st[2] & (st[3] < n), inner_step, (z, P, jnp.asarray(False), jnp.asarray(0))
        )[:2]

    def outer_step(state):
        z, P, _, steps = state
        gradient = cz - matmul(Qz, z)  # the negative gradient
        size = jnp.maximum(1.0, jnp.max(jnp.abs(cz)) + jnp.max(matmul(jnp.abs(Qz), jnp.abs(z))))
        candidates = bounded & ~P
        j = jnp.argmax(jnp.where(candidates, gradient, -jnp.inf))
        done = ~jnp.any(candidates) | (gradient[j] <= _tolerance(dtype) * size)
        z_new, P_new = jax.lax.cond(done, lambda: (z, P), lambda: consistent(z, P.at[j].set(True)))
        # Rounding can make the entering unknown leave again at once; then nothing more can be
        # gained (and Lawson–Hanson would cycle), so stop.
        stalled = ~P_new[j]
        return z_new, P_new, done | stalled, steps + 1

    if n == 0:
        return y
    z, passive = consistent(z, passive)
    z, _, _, _ = jax.lax.while_loop(
        lambda st: ~st[2] & (st[3] < POLISH_STEPS), outer_step, (z, passive, jnp.asarray(False), jnp.asarray(0))
    )
    return jnp.where(fixed, lower, offset + sign * z)


def solve_box_qp(
    Q: Float[Array, "n n"],
    c: Float[Array, " n"],
    lower: Float[Array, " n"],
    upper: Float[Array, " n"],
    *,
    maxiter: Int[Array, ""] | int = 3000,
    round_length: int = 150,
) -> Solution:
    """``min ½xᵀQx − cᵀx`` s.t. ``lower <= x <= upper`` (bounds may be ±inf): ProjectedGradient.

    Rounds of ``round_length`` accelerated projected-gradient iterations, each followed by the
    active-set polish, until the KKT residual is below the dtype's tolerance or ``maxiter`` gradient
    iterations have been spent. Well-conditioned (smoothed) fits finish in the first round; the
    ill-conditioned pseudo-inverse with positivity needs more.

    Arguments:
        Q: positive semi-definite ``(n, n)``.
        c: linear term ``(n,)``.
        lower, upper: bounds ``(n,)``; ``-inf`` / ``inf`` where an unknown is free.
        maxiter: cap on projected-gradient iterations (may be traced).
        round_length: projected-gradient iterations between polishes.

    Returns:
        :class:`Solution` (``converged`` when the scaled KKT residual is below the tolerance).
    """
    Qs, cs, lo, hi, d = _jacobi(Q, c, lower, upper)
    tol = _tolerance(Qs.dtype)
    start = jnp.clip(jnp.zeros_like(cs), lo, hi)
    # Dividing the objective by a Lipschitz constant leaves the minimiser alone and makes 1 a safe
    # fixed step. The Frobenius norm bounds the top eigenvalue from above and is close to it here
    # (Gram matrices of spectra are dominated by a few directions); it costs one pass over Q,
    # where an eigenvalue solver takes far longer than the whole fit on CPU.
    lipschitz = jnp.maximum(jnp.linalg.norm(Qs), jnp.finfo(Qs.dtype).tiny)
    Qn, cn = Qs / lipschitz, cs / lipschitz
    solver = jaxopt.ProjectedGradient(
        fun=lambda y, Q, c: 0.5 * matmul(y, matmul(Q, y)) - matmul(c, y),
        projection=jaxopt.projection.projection_box,
        stepsize=1.0,
        maxiter=round_length,
        tol=0.0,
        acceleration=True,
        implicit_diff=False,
        jit=True,
    )
    rounds = jnp.maximum(1, jnp.asarray(maxiter) // round_length)

    def one_round(state):
        y, best, best_residual, done_rounds, iterations = state
        result = solver.run(y, (lo, hi), Qn, cn)
        y_pg = result.params
        y_polished = jnp.clip(_polish(Qs, cs, y_pg, lo, hi), lo, hi)
        r_pg = _relative_residual(Qs, cs, y_pg, lo, hi)
        r_polished = _relative_residual(Qs, cs, y_polished, lo, hi)
        candidate = jnp.where(r_polished < r_pg, y_polished, y_pg)
        r_candidate = jnp.minimum(r_pg, r_polished)
        improved = r_candidate < best_residual
        best = jnp.where(improved, candidate, best)
        best_residual = jnp.minimum(r_candidate, best_residual)
        # Continue the gradient method from its own iterate (the polish may have jumped off path).
        return y_pg, best, best_residual, done_rounds + 1, iterations + result.state.iter_num

    def keep_going(state):
        return (state[2] > tol) & (state[3] < rounds)

    r_start = _relative_residual(Qs, cs, start, lo, hi)
    init = (start, start, r_start, jnp.asarray(0), jnp.asarray(0))
    _, y, residual, _, iterations = jax.lax.while_loop(keep_going, one_round, init)
    return Solution(x=y * d, kkt_residual=residual, iterations=iterations, converged=residual <= tol)


def _polish_qp(Qs, cs, A, lower, upper, x, z, y):
    """OSQP-style solution polishing (Stellato et al. 2020, §5.2): take the constraints ADMM left at a
    bound with a non-zero dual as equalities and solve the equality-constrained QP's KKT system
    exactly. Returns the polished point and whether it is feasible with correctly signed duals."""
    n = x.shape[0]
    m = A.shape[0]
    dtype = x.dtype
    at_lower = (z <= lower) & (y < 0)
    at_upper = (z >= upper) & (y > 0) & ~at_lower
    active = (at_lower | at_upper).astype(dtype)
    target = jnp.where(at_lower, lower, jnp.where(at_upper, upper, 0.0))
    reg = 1e3 * jnp.finfo(dtype).eps
    K = jnp.block(
        [
            [Qs + reg * jnp.eye(n, dtype=dtype), A.T * active[None, :]],
            [A * active[:, None], -jnp.diag(1.0 - active + reg * active)],
        ]
    )
    rhs = jnp.concatenate([cs, active * target])
    solution = jnp.linalg.solve(K, rhs)
    for _ in range(2):  # iterative refinement against the regularisation
        residual = rhs - matmul(
            jnp.block([[Qs, A.T * active[None, :]], [A * active[:, None], -jnp.diag(1.0 - active)]]), solution
        )
        solution = solution + jnp.linalg.solve(K, residual)
    xp, nu = solution[:n], solution[n:]
    Ax = matmul(A, xp)
    scale = (
        1.0
        + jnp.max(jnp.abs(jnp.where(jnp.isfinite(lower), lower, 0.0)))
        + jnp.max(jnp.abs(jnp.where(jnp.isfinite(upper), upper, 0.0)))
    )
    tol = jnp.sqrt(jnp.finfo(dtype).eps) * scale
    feasible = jnp.all((Ax >= lower - tol) & (Ax <= upper + tol))
    # Stationarity Qx - c + Aᵀnu = 0 with nu <= 0 on lower-active and >= 0 on upper-active rows.
    signs = jnp.all(jnp.where(at_lower, nu <= tol, True) & jnp.where(at_upper, nu >= -tol, True))
    ok = feasible & signs & jnp.all(jnp.isfinite(xp)) & (m > 0)
    return xp, ok


def solve_qp(
    Q: Float[Array, "n n"],
    c: Float[Array, " n"],
    lower: Float[Array, " n"],
    upper: Float[Array, " n"],
    G: Float[Array, "m n"],
    g_lower: Float[Array, " m"],
    g_upper: Float[Array, " m"],
    *,
    maxiter: int = 20000,
) -> Solution:
    """``min ½xᵀQx − cᵀx`` s.t. box bounds and ``g_lower <= G x <= g_upper``: jaxopt BoxOSQP,
    then OSQP's solution polishing (exact when the active set is right).

    Rows of ``G`` should be scaled like the objective (BoxOSQP does no equilibration).

    Returns:
        :class:`Solution`; ``converged`` when BoxOSQP reports "solved" or the polished solution
        is feasible with correctly signed multipliers.
    """
    Qs, cs, lo, hi, d = _jacobi(Q, c, lower, upper)
    Gs = G * d[None, :]
    # Unit-norm constraint rows (one step of Ruiz equilibration): ADMM stalls on badly scaled rows.
    norms = jnp.linalg.norm(Gs, axis=1)
    row_scale = jnp.where(norms > 0, 1.0 / jnp.where(norms > 0, norms, 1.0), 1.0)
    Gs = Gs * row_scale[:, None]
    n = Qs.shape[0]
    A = jnp.concatenate([jnp.eye(n, dtype=Qs.dtype), Gs], axis=0)
    row_lower = jnp.concatenate([lo, g_lower * row_scale])
    row_upper = jnp.concatenate([hi, g_upper * row_scale])
    # ADMM reaches ~1e-9 (x64) / ~1e-5 (float32) primal-dual residuals in a few thousand steps.
    solver = jaxopt.BoxOSQP(
        tol=1e-9 if jnp.finfo(Qs.dtype).bits == 64 else 1e-5,
        maxiter=maxiter,
        eq_qp_solve="lu",
        check_primal_dual_infeasability=True,
        implicit_diff=False,
        jit=True,
    )
    with highest_within():  # BoxOSQP's LU path forms A^T A and its matvecs at the default precision
        result = solver.run(params_obj=(Qs, -cs), params_eq=A, params_ineq=(row_lower, row_upper))
    x, z = result.params.primal
    polished, ok = _polish_qp(Qs, cs, A, row_lower, row_upper, x, z, result.params.dual_eq)
    y = jnp.where(ok, polished, x)
    residual = _relative_residual(Qs, cs, y, lo, hi)  # bound part only; the polish checks the rest
    return Solution(
        x=y * d, kkt_residual=residual, iterations=result.state.iter_num, converged=ok | (result.state.status == 1)
    )


def solve_least_squares(A: Float[Array, "m n"], b: Float[Array, " m"]) -> Solution:
    """Minimum-norm least squares ``A x ≈ b`` by SVD: the pseudo-inverse method (eq. 3.3)."""
    x, *_ = jnp.linalg.lstsq(A, b)
    ok = jnp.all(jnp.isfinite(x))
    return Solution(
        x=jnp.where(ok, x, 0.0), kkt_residual=jnp.asarray(0.0, A.dtype), iterations=jnp.asarray(1), converged=ok
    )
