"""The thesis' new sharpening method, "gd-identity" (Barnard 1999 §5.3).

``T`` minimises ``J(T) = E + lambda_P P + lambda_N N`` (eq. 5.4) over the training illuminants from
the identity, by autodiff and optimistix BFGS, with ``lambda_P`` chosen as the smallest value
leaving under 0.1 % of the sharpened training responses negative.

Scale: white's brightest channel is 1, so the thesis' positivity offset 0.1 (white = 255) is
:data:`POSITIVITY_OFFSET` = ``0.1 / 255`` here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ccjax import limits
from ccjax.precision import einsum, matmul
from ccjax.sharpening._transforms import database_responses
from ccjax.world import World

POSITIVITY_OFFSET = 0.1 / 255.0
"""The thesis' offset 0.1 of eq. 5.2 (white = 255) on ccjax's scale (white = 1)."""

NEGATIVE_TOLERANCE = 1e-3
"""The new method's ``lambda_P`` is the smallest leaving under this fraction (0.1 %) of the
sharpened training responses negative (Barnard 1999 §5.3)."""


class ObjectiveTerms(eqx.Module):
    """The terms of eq. 5.4 for one ``T`` (Barnard 1999 §5.3).

    Attributes:
        mapping: ``E``, the mapping error (eq. 5.1).
        positivity: ``P``, the positivity penalty (eq. 5.2).
        norm: ``N``, the norm penalty (eq. 5.3).
    """

    mapping: Float[Array, ""]
    positivity: Float[Array, ""]
    norm: Float[Array, ""]


def objective_terms(
    transform: Float[Array, "3 3"],
    train: Float[Array, "I S 3"],
    canonical: Float[Array, "S 3"],
    offset: float = POSITIVITY_OFFSET,
) -> ObjectiveTerms:
    """The three terms of the new method's objective (Barnard 1999 §5.3, eqs. 5.1-5.3).

    ``E = sum_i |(Y_i * d_i) T^-1 - X_c|_F`` with ``Y_i = X_i T`` and ``d_i`` the ratio of the
    column means of ``X_c T`` and ``Y_i`` (the thesis' "best diagonal map");
    ``P = sum over sharpened training responses of (x - offset)^2 where x < offset``;
    ``N = (trace(T^T T) - 3)^2``.

    ``E`` is evaluated from 3x3 Gram matrices: with ``G_i = T diag(d_i) T^-1``,
    ``|X_i G_i - X_c|^2 = tr(G_i^T (X_i^T X_i) G_i) - 2 tr(G_i^T X_i^T X_c) + |X_c|^2``, which is
    exact and makes an evaluation cost O(I) instead of O(I S).

    Arguments:
        transform: ``(3, 3)`` sharpening ``T``.
        train: ``(I, S, 3)`` database under each training light.
        canonical: ``(S, 3)`` database under the canonical light.
        offset: positivity offset (unit scale).

    Returns:
        :class:`ObjectiveTerms`.
    """
    return _terms(transform, DatabaseStatistics.of(train, canonical), train, offset)


class DatabaseStatistics(eqx.Module):
    """What ``E`` of eq. 5.1 needs from the training and canonical databases (computed once per
    world; Barnard 1999 §5.3).

    Attributes:
        gram: ``(I, 3, 3)`` per training light, the Gram matrix of the responses.
        cross: ``(I, 3, 3)`` per training light, responses times canonical responses.
        train_mean: ``(I, 3)`` mean response per training light.
        canonical_mean: ``(3,)`` mean canonical response.
        canonical_square: sum of squared canonical responses.
    """

    gram: Float[Array, "I 3 3"]
    cross: Float[Array, "I 3 3"]
    train_mean: Float[Array, "I 3"]
    canonical_mean: Float[Array, " 3"]
    canonical_square: Float[Array, ""]

    @classmethod
    def of(cls, train: Float[Array, "I S 3"], canonical: Float[Array, "S 3"]) -> DatabaseStatistics:
        """The statistics of a database.

        Arguments:
            train: ``(I, S, 3)`` the surfaces under the training lights.
            canonical: ``(S, 3)`` the surfaces under the canonical light.

        Returns:
            The :class:`DatabaseStatistics`.
        """
        return cls(
            gram=einsum("isa,isb->iab", train, train),
            cross=einsum("isa,sb->iab", train, canonical),
            train_mean=jnp.mean(train, axis=1),
            canonical_mean=jnp.mean(canonical, axis=0),
            canonical_square=jnp.sum(canonical**2),
        )


def _terms(transform, stats: DatabaseStatistics, train, offset) -> ObjectiveTerms:
    inverse = jnp.linalg.inv(transform)
    maps = matmul(stats.canonical_mean, transform) / matmul(stats.train_mean, transform)
    generalised = einsum("ab,ib,bc->iac", transform, maps, inverse)
    residual = (
        einsum("iab,iac,icb->i", generalised, stats.gram, generalised)
        - 2.0 * einsum("iab,iab->i", generalised, stats.cross)
        + stats.canonical_square
    )
    # sqrt with a safe gradient at a perfect fit (possible only with delta sensors).
    positive = residual > 0
    mapping = jnp.sum(jnp.where(positive, jnp.sqrt(jnp.where(positive, residual, 1.0)), 0.0))
    below = jnp.minimum(matmul(train, transform) - offset, 0.0)
    positivity = jnp.sum(below**2)
    norm = (jnp.sum(transform**2) - 3.0) ** 2
    return ObjectiveTerms(mapping=mapping, positivity=positivity, norm=norm)


def objective(
    transform: Float[Array, "3 3"],
    train: Float[Array, "I S 3"],
    canonical: Float[Array, "S 3"],
    lambda_p,
    lambda_n,
    offset: float = POSITIVITY_OFFSET,
) -> Float[Array, ""]:
    """``J(T) = E + lambda_P P + lambda_N N`` (Barnard 1999 §5.3, eq. 5.4).

    Arguments:
        transform, train, canonical, offset: as :func:`objective_terms`.
        lambda_p, lambda_n: the positivity and norm weights.

    Returns:
        ``J`` (a scalar).
    """
    terms = objective_terms(transform, train, canonical, offset)
    return terms.mapping + lambda_p * terms.positivity + lambda_n * terms.norm


@dataclass
class NewSharpening:
    """Result of the new method (Barnard 1999 §5.3).

    Attributes:
        transform: ``(3, 3)`` NumPy ``T`` with unit columns (the optimiser's ``T`` rescaled per
            column, which changes neither ``E`` nor any diagonal-model algorithm).
        lambda_p, lambda_n: the weights used (``lambda_n = inf``: the norm held exactly).
        negative_fraction: share of sharpened training responses below 0.
        negative_calibration: non-positive sharpened canonical responses and training whites.
        iterations: optimiser steps of the final run; ``converged`` its stopping reason.
        objective: final ``J`` (unit scale), with ``initial_objective`` at the identity.
        mapping: final ``E`` (unit scale, summed over training illuminants), with
            ``initial_mapping`` at the identity.
        search: ``[(lambda_p, negative_fraction, negative_calibration, iterations)]`` of the
            ``lambda_P`` search.
    """

    transform: np.ndarray
    lambda_p: float
    lambda_n: float
    negative_fraction: float
    negative_calibration: int
    iterations: int
    converged: bool
    objective: float
    initial_objective: float
    mapping: float
    initial_mapping: float
    search: list = field(default_factory=list)


def on_sphere(parameters: Float[Array, "3 3"]) -> Float[Array, "3 3"]:
    """``T`` with ``|T|_F^2 = 3`` exactly: the ``lambda_N -> infinity`` limit of eq. 5.3
    (Barnard 1999 §5.3); the parametrisation of the new method and of learned sharpening.

    Arguments:
        parameters: any non-zero ``(3, 3)`` matrix.

    Returns:
        ``parameters`` scaled to squared Frobenius norm 3.
    """
    return parameters * jnp.sqrt(3.0 / jnp.sum(parameters**2))


@eqx.filter_jit
def _minimise(stats, train, lambda_p, lambda_n, max_steps, tolerance, offset=POSITIVITY_OFFSET):
    import optimistix as optx

    exact = lambda_n is None

    def fn(parameters, args):
        transform = on_sphere(parameters) if exact else parameters
        terms = _terms(transform, stats, train, offset)
        value = terms.mapping + lambda_p * terms.positivity
        return value if exact else value + lambda_n * terms.norm

    solver = optx.BFGS(rtol=tolerance, atol=tolerance)
    identity = jnp.eye(3, dtype=train.dtype)
    solution = optx.minimise(fn, solver, identity, max_steps=max_steps, throw=False)
    transform = on_sphere(solution.value) if exact else solution.value
    return transform, solution.stats["num_steps"], solution.result == optx.RESULTS.successful


def new_sharpening(
    world: World,
    lambda_p: float | None = None,
    lambda_n: float | None = None,
    *,
    candidates: Sequence[float] = (0.0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7),
    bisections: int = 2,
    max_steps: int = 1000,
    tolerance: float = 1e-6,
) -> NewSharpening:
    """The thesis' new sharpening method ("gd-identity", Barnard 1999 §5.3).

    ``T`` minimises ``E + lambda_P P + lambda_N N`` over the world's training illuminants,
    starting from the identity; optimistix BFGS (a quasi-Newton descent with a backtracking line
    search) replaces the thesis' finite-difference gradient descent, the gradient coming from
    autodiff.

    Arguments:
        world: training illuminants, reflectances, canonical light.
        lambda_p: positivity weight (unit scale); default: the smallest of ``candidates`` leaving
            under 0.1 % of the sharpened training responses negative and no sharpened canonical
            response or training white non-positive.
        lambda_n: norm weight. Default ``None`` is the thesis' "very large" taken to its limit:
            ``T`` is parametrised as ``sqrt(3) U / |U|_F`` so ``N = 0`` exactly (``E`` does not see
            the scale and a huge finite weight only makes the problem stiff).
        candidates: increasing ``lambda_P`` values tried, then ``bisections`` log-scale
            bisections between the last failing and the first passing one.
        bisections: how many.
        max_steps, tolerance: optimiser limits.

    Returns:
        A :class:`NewSharpening`.
    """
    # A NaN, infinite or negative weight gave a NaN objective and a "sharpened" camera.
    if lambda_p is not None:
        lambda_p = limits.check_value(lambda_p, limits.SHARPENING_PENALTY, "lambda_p")
    if lambda_n is not None:
        lambda_n = limits.check_value(lambda_n, limits.SHARPENING_PENALTY, "lambda_n")
    train = database_responses(world, world.train_illuminants)
    canonical = world.canonical_rgb
    stats = DatabaseStatistics.of(train, canonical)
    identity = jnp.eye(3, dtype=canonical.dtype)

    whites = world.train_whites

    def run(lp):
        lp_array = jnp.asarray(lp, canonical.dtype)
        ln = None if lambda_n is None else jnp.asarray(lambda_n, canonical.dtype)
        t, steps, converged = _minimise(stats, train, lp_array, ln, max_steps, tolerance)
        negative = float(jnp.mean(matmul(train, t) < 0))
        # Calibration data must stay positive too: a negative sharpened canonical
        # response or training white would make gamut mapping revert on every scene.
        calibration = int(jnp.sum(matmul(canonical, t) <= 0) + jnp.sum(matmul(whites, t) <= 0))
        return t, int(steps), bool(converged), negative, calibration

    def passes(outcome):
        return outcome[3] < NEGATIVE_TOLERANCE and outcome[4] == 0

    search = []
    if lambda_p is None:
        for lp in candidates:
            outcome = run(float(lp))
            search.append((float(lp), outcome[3], outcome[4], outcome[1]))
            if passes(outcome):
                break
        chosen = search[-1][0]
        # Refine between the last failing and the first passing candidate (log bisection).
        if len(search) > 1 and search[-2][0] > 0 and passes(outcome):
            low, high = search[-2][0], chosen
            for _ in range(bisections):
                middle = float(np.sqrt(low * high))
                trial = run(middle)
                search.append((middle, trial[3], trial[4], trial[1]))
                if passes(trial):
                    high, outcome = middle, trial
                else:
                    low = middle
            chosen = high
        t, steps, converged, negative, calibration = outcome
    else:
        chosen = float(lambda_p)
        t, steps, converged, negative, calibration = run(chosen)
    ln = 0.0 if lambda_n is None else float(lambda_n)
    initial = objective_terms(identity, train, canonical)
    final = objective_terms(t, train, canonical)  # at the optimiser's T, before rescaling

    def total(terms):
        return float(terms.mapping + chosen * terms.positivity + ln * terms.norm)

    # E, the signs of the responses and every diagonal-model algorithm are invariant to positive
    # column scales, which only the weak positivity term pins down; report T in the database
    # sharpening gauge (unit columns, as normalise_transform) so transforms compare.
    t64 = np.asarray(t, dtype=np.float64)
    return NewSharpening(
        transform=t64 / np.linalg.norm(t64, axis=0, keepdims=True),
        lambda_p=chosen,
        lambda_n=float("inf") if lambda_n is None else ln,
        negative_fraction=negative,
        negative_calibration=calibration,
        iterations=steps,
        converged=converged,
        objective=total(final),
        initial_objective=total(initial),
        mapping=float(final.mapping),
        initial_mapping=float(initial.mapping),
        search=search,
    )
