"""The quadratic programmes behind every chapter-3 fit, solved with jaxopt (DESIGN.md §6).

Each fit of Barnard 1999 §3.4 is a least-squares problem with linear constraints, i.e. a convex
quadratic programme in the stacked unknowns ``x`` (sensor samples, then linearisation parameters):

    minimise  ½ xᵀ Q x − cᵀ x   subject to   lower <= x <= upper   [and  g_lo <= G x <= g_hi].

* Bounds only (positivity (3.7), the range constraint (3.8)): jaxopt ``ProjectedGradient``
  (accelerated, fixed step 1/‖Q‖) in rounds, each finished by a primal–dual active-set polish (the step OSQP calls "polishing"): with the active
  bounds fixed, the free unknowns solve a linear system exactly, so the answer is exact once the
  gradient method has found the active set. The result with the smaller KKT residual is kept.
* General linear inequalities (the error bounds (3.9), (3.13)): jaxopt ``BoxOSQP``.
* No constraint at all: the normal equations, solved directly.

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

with warnings.catch_warnings():
    # jaxopt announces on import that it is no longer maintained; the project uses it on purpose
    # (DESIGN.md §6), so silence exactly that warning and nothing else.
    warnings.filterwarnings("ignore", category=DeprecationWarning, module="jaxopt")
    import jaxopt

POLISH_STEPS = 12


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
    grad = Qs @ y - cs
    residual = jnp.max(jnp.abs(y - jnp.clip(y - grad, lower, upper)))
    size = jnp.maximum(1.0, jnp.max(jnp.abs(cs)) + jnp.max(jnp.abs(Qs) @ jnp.abs(y)))
    return residual, size


def _relative_residual(Qs, cs, y, lower, upper):
    residual, size = _kkt_residual(Qs, cs, y, lower, upper)
    return residual / size


def _polish(Qs, cs, y, lower, upper):
    """Primal–dual active-set iterations (Hintermüller, Ito & Kunisch 2002) from ``y``.

    Each step fixes the unknowns whose trial step ``y - grad`` leaves the box at that bound and
    solves for the others exactly (Cholesky of the free block); it stops when the active set no
    longer changes (then ``y`` is the exact minimiser) or after ``POLISH_STEPS`` steps.
    """
    n = y.shape[0]
    ridge = 10 * jnp.finfo(y.dtype).eps

    def active_sets(y):
        trial = y - (Qs @ y - cs)
        at_lower = jnp.isfinite(lower) & (trial <= lower)
        at_upper = jnp.isfinite(upper) & (trial >= upper) & ~at_lower
        return at_lower, at_upper

    def step(state):
        y, (at_lower, at_upper), _, count = state
        fixed = at_lower | at_upper
        y_fixed = jnp.where(at_lower, lower, jnp.where(at_upper, upper, 0.0))
        free = (~fixed).astype(y.dtype)
        K = Qs * free[:, None] * free[None, :] + jnp.diag(1.0 - free + ridge * free)
        rhs = free * (cs - Qs @ y_fixed) + (1.0 - free) * y_fixed
        y_new = jax.scipy.linalg.cho_solve(jax.scipy.linalg.cho_factor(K), rhs)
        y_new = jnp.where(jnp.all(jnp.isfinite(y_new)), y_new, y)
        new_sets = active_sets(y_new)
        changed = jnp.any(new_sets[0] != at_lower) | jnp.any(new_sets[1] != at_upper)
        return y_new, new_sets, changed, count + 1

    def keep_going(state):
        return state[2] & (state[3] < POLISH_STEPS)

    if n == 0:
        return y
    return jax.lax.while_loop(keep_going, step, (y, active_sets(y), jnp.asarray(True), jnp.asarray(0)))[0]


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
    # Dividing the objective by its Lipschitz constant (the top eigenvalue; Gershgorin would be
    # safe but loose) leaves the minimiser alone and makes 1 the optimal fixed step.
    lipschitz = jnp.linalg.eigvalsh(Qs)[-1]
    Qn, cn = Qs / lipschitz, cs / lipschitz
    solver = jaxopt.ProjectedGradient(
        fun=lambda y, Q, c: 0.5 * y @ (Q @ y) - c @ y,
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
    """``min ½xᵀQx − cᵀx`` s.t. box bounds and ``g_lower <= G x <= g_upper``: jaxopt BoxOSQP.

    Rows of ``G`` with infinite bounds on both sides are inactive (used for masked measurements).

    Returns:
        :class:`Solution`; ``converged`` is BoxOSQP's "solved" status (False when the constraints
        are infeasible or the iteration cap was hit).
    """
    Qs, cs, lo, hi, d = _jacobi(Q, c, lower, upper)
    Gs = G * d[None, :]
    n = Qs.shape[0]
    A = jnp.concatenate([jnp.eye(n, dtype=Qs.dtype), Gs], axis=0)
    l = jnp.concatenate([lo, g_lower])
    u = jnp.concatenate([hi, g_upper])
    # ADMM reaches ~1e-9 (x64) / ~1e-5 (float32) primal-dual residuals in a few thousand steps.
    solver = jaxopt.BoxOSQP(
        tol=1e-9 if jnp.finfo(Qs.dtype).bits == 64 else 1e-5,
        maxiter=maxiter,
        eq_qp_solve="lu",
        check_primal_dual_infeasability=True,
        implicit_diff=False,
        jit=True,
    )
    result = solver.run(params_obj=(Qs, -cs), params_eq=A, params_ineq=(l, u))
    y = result.params.primal[0]
    residual = _relative_residual(Qs, cs, y, lo, hi)  # bound part only; BoxOSQP checks the rest
    return Solution(x=y * d, kkt_residual=residual, iterations=result.state.iter_num, converged=result.state.status == 1)


def solve_unconstrained(Q: Float[Array, "n n"], c: Float[Array, " n"]) -> Solution:
    """The normal equations ``Q x = c`` (smooth fit without positivity); exact."""
    Qs, cs, _, _, d = _jacobi(Q, c, jnp.zeros_like(c), jnp.zeros_like(c))
    y = jnp.linalg.solve(Qs, cs)
    ok = jnp.all(jnp.isfinite(y))
    y = jnp.where(ok, y, 0.0)
    residual = _relative_residual(Qs, cs, y, jnp.full_like(y, -jnp.inf), jnp.full_like(y, jnp.inf))
    return Solution(x=y * d, kkt_residual=residual, iterations=jnp.asarray(1), converged=ok)


def solve_least_squares(A: Float[Array, "m n"], b: Float[Array, " m"]) -> Solution:
    """Minimum-norm least squares ``A x ≈ b`` by SVD: the pseudo-inverse method (eq. 3.3)."""
    x, *_ = jnp.linalg.lstsq(A, b)
    ok = jnp.all(jnp.isfinite(x))
    return Solution(x=jnp.where(ok, x, 0.0), kkt_residual=jnp.asarray(0.0, A.dtype), iterations=jnp.asarray(1), converged=ok)
