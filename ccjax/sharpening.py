"""Sensor sharpening for colour constancy (Barnard 1999 ch. 5; spec ch05-07 §2, §8).

A sharpening transform ``T`` (3x3) replaces responses ``x`` (rows) by ``x @ T``; a diagonal-model
algorithm runs there and its map ``d#`` acts back in camera space as ``T diag(d#) T^-1``.

What is here:

* error measures of §5.4/§5.7: best linear map, best diagonal map for a given ``T``, the RMS RGB
  mapping error over the whole reflectance set, the sharpness ratio of a camera;
* database sharpening (§5.1/§5.2): ``T`` from the eigenvectors of the best linear map, with the
  thesis' column normalisation and ordering, for one illuminant ("opt": the scene's own light;
  "ave": the mean training light);
* the thesis' new method (§5.3, "gd-identity"): minimise ``E + lambda_P P + lambda_N N`` from the
  identity by autodiff and optimistix BFGS, with ``lambda_P`` chosen as the smallest value leaving
  under 0.1 % of the sharpened training responses negative;
* :func:`sharpened`: run any estimator in sharpened space and map back, reverting to the
  unsharpened result (and counting it) where negative values make it invalid (§5.2);
* learned end-to-end sharpening (beyond the thesis): ``T`` trained by gradient descent through a
  differentiable estimator on synthetic training scenes;
* :func:`reproduce_5_1`: Table 5.1's protocol (``ccjax reproduce 5.1``).

Scale (DESIGN.md §2): white's brightest channel is 1, so the thesis' positivity offset 0.1 is
``0.1 / 255`` here and mapping errors are multiplied by 255 for comparison with the thesis.
"""

from __future__ import annotations

import json
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ccjax import metrics
from ccjax.estimators.base import Estimate, Estimator
from ccjax.world import World

POSITIVITY_OFFSET = 0.1 / 255.0
"""The thesis' offset 0.1 of eq. 5.2 (white = 255) on ccjax's scale (white = 1)."""

NEGATIVE_TOLERANCE = 1e-3
"""The new method's ``lambda_P`` is the smallest leaving under this fraction (0.1 %) of the
sharpened training responses negative (spec ch05-07 §7 A2)."""

THESIS_SCALE = 255.0

SHARPENINGS = ("none", "opt", "ave", "new")


# ---------------------------------------------------------------------------------------------
# Database responses and the chapter-5 error measures


def database_responses(world: World, spectra: Float[Array, "... 101"]) -> Float[Array, "... S 3"]:
    """Camera responses of every reflectance of ``world`` under each illuminant spectrum.

    Arguments:
        world: the world (reflectances, camera).
        spectra: ``(..., 101)`` illuminant spectra.

    Returns:
        ``(..., S, 3)`` responses (rows are surfaces, the thesis' ``A``/``B`` matrices).
    """
    spectra = jnp.asarray(spectra)
    return world.camera.response(world.reflectances * spectra[..., None, :])


def best_linear_map(source: Float[Array, "S 3"], target: Float[Array, "S 3"]) -> Float[Array, "3 3"]:
    """Least-squares ``M`` with ``source @ M ~ target`` (§5.1; the normal equations, 3x3)."""
    gram = source.T @ source
    return jnp.linalg.solve(gram, source.T @ target)


def mapping_error(
    source: Float[Array, "S 3"],
    target: Float[Array, "S 3"],
    transform: Float[Array, "3 3"],
    diagonal: Float[Array, "3"],
) -> Float[Array, ""]:
    """RMS RGB mapping error over the whole reflectance set (§5.4, spec §2.7):
    ``sqrt(mean_j |((x_j T) * d#) T^-1 - c_j|^2)`` on the scale of its inputs.

    Arguments:
        source: ``(S, 3)`` database under the scene light.
        target: ``(S, 3)`` database under the canonical light.
        transform: sharpening ``T`` (identity: no sharpening).
        diagonal: ``d#``, the map in sharpened space.
    """
    mapped = ((source @ transform) * diagonal) @ jnp.linalg.inv(transform)
    return jnp.sqrt(jnp.mean(jnp.sum((mapped - target) ** 2, axis=-1)))


def best_linear_error(source: Float[Array, "S 3"], target: Float[Array, "S 3"]) -> Float[Array, ""]:
    """RMS RGB error of the best linear map (BEST-LINEAR of §5.7)."""
    residual = source @ best_linear_map(source, target) - target
    return jnp.sqrt(jnp.mean(jnp.sum(residual**2, axis=-1)))


def best_diagonal_map(
    source: Float[Array, "S 3"], target: Float[Array, "S 3"], transform: Float[Array, "3 3"]
) -> Float[Array, "3"]:
    """BEST-DIAGONAL's ``d#`` (§5.7): least squares in camera space over three unknowns,
    ``argmin_d |((X T) * d) T^-1 - X_c|_F`` (spec §7 A11).

    The mapped matrix is ``sum_k d_k y_k t_k`` (``y_k`` column k of ``X T``, ``t_k`` row k of
    ``T^-1``), so the normal equations are ``((Y^T Y) * (U U^T)) d = diag(Y^T X_c U^T)``.
    """
    sharp = source @ transform
    inverse = jnp.linalg.inv(transform)
    gram = (sharp.T @ sharp) * (inverse @ inverse.T)
    rhs = jnp.diagonal(sharp.T @ target @ inverse.T)
    return jnp.linalg.solve(gram, rhs)


def diagonal_error(
    source: Float[Array, "S 3"], target: Float[Array, "S 3"], transform: Float[Array, "3 3"]
) -> Float[Array, ""]:
    """Mapping error of the best diagonal map in the space sharpened by ``transform``."""
    return mapping_error(source, target, transform, best_diagonal_map(source, target, transform))


@jax.jit
def _sharpness_kernel(sensors, reflectances, target, spectra):
    def one(spectrum):
        source = (reflectances * spectrum) @ sensors
        return best_linear_error(source, target), diagonal_error(source, target, jnp.eye(3, dtype=target.dtype))

    return jax.lax.map(one, spectra)


def sharpness(world: World, spectra: Float[Array, "J 101"] | None = None) -> dict[str, float]:
    """Sharpness of the camera (§5.7): RMS over illuminants of BEST-LINEAR's error divided by that
    of BEST-DIAGONAL without sharpening (<= 1; 1 for delta-function sensors).

    Arguments:
        world: the world; its camera is measured.
        spectra: illuminants to average over (default: the world's test illuminants).

    Returns:
        ``{"best_linear", "best_diagonal", "ratio"}``, errors in thesis units (white = 255).
    """
    spectra = jnp.asarray(world.test_illuminants if spectra is None else spectra)
    count = spectra.shape[0]
    # Pad the light axis to a multiple of 64 so worlds of similar size share one compilation.
    padded = jnp.concatenate([spectra, jnp.repeat(spectra[:1], -count % 64, axis=0)])
    linear, diagonal = _sharpness_kernel(world.camera.sensors, world.reflectances, world.canonical_rgb, padded)
    linear, diagonal = linear[:count], diagonal[:count]
    rms_linear = float(jnp.sqrt(jnp.mean(linear**2))) * THESIS_SCALE
    rms_diagonal = float(jnp.sqrt(jnp.mean(diagonal**2))) * THESIS_SCALE
    return {"best_linear": rms_linear, "best_diagonal": rms_diagonal, "ratio": rms_linear / rms_diagonal}


# ---------------------------------------------------------------------------------------------
# Database sharpening (§5.1, §5.2)


def normalise_transform(transform: np.ndarray) -> np.ndarray:
    """The thesis' gauge for a sharpening transform (§5.2, spec §7 A9).

    Columns are scaled to unit length; then, greedily, the largest remaining ``|T_rc|`` (over rows
    and columns not yet placed) puts column ``c`` at position ``r``, negated if that entry is
    negative — so the diagonal is as large and positive as possible, which keeps sharpened
    responses positive more often. Errors using ``T ... T^-1`` do not change.
    """
    transform = np.asarray(transform, dtype=np.float64)
    columns = transform / np.linalg.norm(transform, axis=0, keepdims=True)
    out = np.empty_like(columns)
    rows, cols = set(range(3)), set(range(3))
    for _ in range(3):
        r, c = max(((r, c) for r in rows for c in cols), key=lambda rc: abs(columns[rc]))
        out[:, r] = columns[:, c] * np.sign(columns[r, c] or 1.0)
        rows.remove(r)
        cols.remove(c)
    return out


def database_sharpening(source, target) -> np.ndarray:
    """Database sharpening (§5.1): ``T`` = eigenvectors of the best linear map ``M`` from
    ``source`` to ``target``, normalised and ordered by :func:`normalise_transform`.

    Complex eigenvectors: the thesis zeroes their imaginary parts, but a conjugate pair
    ``a +- i b`` then gives two equal columns ``a`` and a singular ``T`` (spec §2.2, §7 A7). We use
    the real block form instead: the pair is replaced by ``a`` and ``b``, which span the same
    invariant plane of ``M`` and are linearly independent whenever the eigenvectors are (so ``T``
    stays invertible). ``M`` is then block diagonal (not diagonal) in that basis; the diagonal map
    used there is the best one (:func:`best_diagonal_map`), as for any other ``T``.

    Arguments:
        source: ``(S, 3)`` database under the source light.
        target: ``(S, 3)`` database under the canonical light.

    Returns:
        ``(3, 3)`` NumPy float64 ``T``.
    """
    source = np.asarray(source, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    linear = np.linalg.lstsq(source, target, rcond=None)[0]
    values, vectors = np.linalg.eig(linear)
    columns, used = [], set()
    for k in range(3):
        if k in used:
            continue
        if abs(values[k].imag) <= 1e-12 * abs(values[k]):
            columns.append(vectors[:, k].real)
            used.add(k)
        else:
            partner = next(j for j in range(3) if j != k and j not in used)
            columns += [vectors[:, k].real, vectors[:, k].imag]
            used |= {k, partner}
    return normalise_transform(np.stack(columns, axis=1))


def average_sharpening(world: World) -> np.ndarray:
    """ "ave" sharpening (§5.2): database sharpening for the mean normalised training illuminant."""
    mean_light = jnp.mean(world.train_illuminants, axis=0)
    return database_sharpening(database_responses(world, mean_light), world.canonical_rgb)


def optimal_sharpening(world: World, spectra: Float[Array, "J 101"] | None = None) -> np.ndarray:
    """ "opt" sharpening (§5.2): one database sharpening per illuminant (the scene's true light).

    Returns:
        ``(J, 3, 3)`` transforms for ``spectra`` (default: the world's test illuminants).
    """
    spectra = world.test_illuminants if spectra is None else spectra
    sources = np.asarray(database_responses(world, spectra))
    target = np.asarray(world.canonical_rgb)
    return np.stack([database_sharpening(source, target) for source in sources])


# ---------------------------------------------------------------------------------------------
# The new method (§5.3)


class ObjectiveTerms(eqx.Module):
    """The terms of eq. 5.4 for one ``T``: mapping ``E`` (eq. 5.1), positivity ``P`` (5.2), norm ``N`` (5.3)."""

    mapping: Float[Array, ""]
    positivity: Float[Array, ""]
    norm: Float[Array, ""]


def objective_terms(
    transform: Float[Array, "3 3"],
    train: Float[Array, "I S 3"],
    canonical: Float[Array, "S 3"],
    offset: float = POSITIVITY_OFFSET,
) -> ObjectiveTerms:
    """The three terms of the new method's objective (§5.3, spec §2.3).

    ``E = sum_i |(Y_i * d_i) T^-1 - X_c|_F`` with ``Y_i = X_i T`` and ``d_i`` the ratio of the
    column means of ``X_c T`` and ``Y_i`` (the thesis' "best diagonal map"; spec §7 A3);
    ``P = sum over sharpened training responses of (x - offset)^2 where x < offset``;
    ``N = (trace(T^T T) - 3)^2``.

    ``E`` is evaluated from 3x3 Gram matrices: with ``G_i = T diag(d_i) T^-1``,
    ``|X_i G_i - X_c|^2 = tr(G_i^T (X_i^T X_i) G_i) - 2 tr(G_i^T X_i^T X_c) + |X_c|^2``, which is
    exact and makes an evaluation cost O(I) instead of O(I S).
    """
    return _terms(transform, DatabaseStatistics.of(train, canonical), train, offset)


class DatabaseStatistics(eqx.Module):
    """What ``E`` needs from the training and canonical databases (computed once per world)."""

    gram: Float[Array, "I 3 3"]
    cross: Float[Array, "I 3 3"]
    train_mean: Float[Array, "I 3"]
    canonical_mean: Float[Array, "3"]
    canonical_square: Float[Array, ""]

    @classmethod
    def of(cls, train, canonical) -> DatabaseStatistics:
        return cls(
            gram=jnp.einsum("isa,isb->iab", train, train),
            cross=jnp.einsum("isa,sb->iab", train, canonical),
            train_mean=jnp.mean(train, axis=1),
            canonical_mean=jnp.mean(canonical, axis=0),
            canonical_square=jnp.sum(canonical**2),
        )


def _terms(transform, stats: DatabaseStatistics, train, offset) -> ObjectiveTerms:
    inverse = jnp.linalg.inv(transform)
    maps = (stats.canonical_mean @ transform) / (stats.train_mean @ transform)
    generalised = jnp.einsum("ab,ib,bc->iac", transform, maps, inverse)
    residual = (
        jnp.einsum("iab,iac,icb->i", generalised, stats.gram, generalised)
        - 2.0 * jnp.einsum("iab,iab->i", generalised, stats.cross)
        + stats.canonical_square
    )
    # sqrt with a safe gradient at a perfect fit (possible only with delta sensors).
    positive = residual > 0
    mapping = jnp.sum(jnp.where(positive, jnp.sqrt(jnp.where(positive, residual, 1.0)), 0.0))
    below = jnp.minimum(train @ transform - offset, 0.0)
    positivity = jnp.sum(below**2)
    norm = (jnp.sum(transform**2) - 3.0) ** 2
    return ObjectiveTerms(mapping=mapping, positivity=positivity, norm=norm)


def objective(transform, train, canonical, lambda_p, lambda_n, offset: float = POSITIVITY_OFFSET):
    """``J(T) = E + lambda_P P + lambda_N N`` (eq. 5.4)."""
    terms = objective_terms(transform, train, canonical, offset)
    return terms.mapping + lambda_p * terms.positivity + lambda_n * terms.norm


@dataclass
class NewSharpening:
    """Result of the new method.

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


def _on_sphere(parameters):
    """``T`` with ``|T|_F^2 = 3`` exactly: the ``lambda_N -> infinity`` limit of eq. 5.3."""
    return parameters * jnp.sqrt(3.0 / jnp.sum(parameters**2))


@eqx.filter_jit
def _minimise(stats, train, lambda_p, lambda_n, max_steps, tolerance, offset=POSITIVITY_OFFSET):
    import optimistix as optx

    exact = lambda_n is None

    def fn(parameters, args):
        transform = _on_sphere(parameters) if exact else parameters
        terms = _terms(transform, stats, train, offset)
        value = terms.mapping + lambda_p * terms.positivity
        return value if exact else value + lambda_n * terms.norm

    solver = optx.BFGS(rtol=tolerance, atol=tolerance)
    identity = jnp.eye(3, dtype=train.dtype)
    solution = optx.minimise(fn, solver, identity, max_steps=max_steps, throw=False)
    transform = _on_sphere(solution.value) if exact else solution.value
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
    """The thesis' new sharpening method ("gd-identity", §5.3).

    ``T`` minimises ``E + lambda_P P + lambda_N N`` over the world's training illuminants,
    starting from the identity; optimistix BFGS (a quasi-Newton descent with a backtracking line
    search) replaces the thesis' finite-difference gradient descent, the gradient coming from
    autodiff.

    Arguments:
        world: training illuminants, reflectances, canonical light.
        lambda_p: positivity weight (unit scale); default: the smallest of ``candidates`` leaving
            under 0.1 % of the sharpened training responses negative and no sharpened canonical
            response or training white non-positive (spec §7 A2).
        lambda_n: norm weight. Default ``None`` is the thesis' "very large" taken to its limit:
            ``T`` is parametrised as ``sqrt(3) U / |U|_F`` so ``N = 0`` exactly (``E`` does not see
            the scale and a huge finite weight only makes the problem stiff).
        candidates: increasing ``lambda_P`` values tried, then ``bisections`` log-scale
            bisections between the last failing and the first passing one.
        max_steps, tolerance: optimiser limits.

    Returns:
        A :class:`NewSharpening`.
    """
    train = database_responses(world, world.train_illuminants)
    canonical = world.canonical_rgb
    stats = DatabaseStatistics.of(train, canonical)
    identity = jnp.eye(3, dtype=canonical.dtype)

    whites = world.train_whites

    def run(lp):
        lp_array = jnp.asarray(lp, canonical.dtype)
        ln = None if lambda_n is None else jnp.asarray(lambda_n, canonical.dtype)
        t, steps, converged = _minimise(stats, train, lp_array, ln, max_steps, tolerance)
        negative = float(jnp.mean(train @ t < 0))
        # Calibration data must stay positive too (spec §7 A2): a negative sharpened canonical
        # response or training white would make gamut mapping revert on every scene.
        calibration = int(jnp.sum(canonical @ t <= 0) + jnp.sum(whites @ t <= 0))
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
        lambda_p = search[-1][0]
        # Refine between the last failing and the first passing candidate (log bisection).
        if len(search) > 1 and search[-2][0] > 0 and passes(outcome):
            low, high = search[-2][0], lambda_p
            for _ in range(bisections):
                middle = float(np.sqrt(low * high))
                trial = run(middle)
                search.append((middle, trial[3], trial[4], trial[1]))
                if passes(trial):
                    high, outcome = middle, trial
                else:
                    low = middle
            lambda_p = high
        t, steps, converged, negative, calibration = outcome
    else:
        t, steps, converged, negative, calibration = run(float(lambda_p))
    ln = 0.0 if lambda_n is None else float(lambda_n)
    initial = objective_terms(identity, train, canonical)
    final = objective_terms(t, train, canonical)  # at the optimiser's T, before rescaling

    def total(terms):
        return float(terms.mapping + lambda_p * terms.positivity + ln * terms.norm)

    # E, the signs of the responses and every diagonal-model algorithm are invariant to positive
    # column scales, which only the weak positivity term pins down; report T in the database
    # sharpening gauge (unit columns, as normalise_transform) so transforms compare.
    t64 = np.asarray(t, dtype=np.float64)
    return NewSharpening(
        transform=t64 / np.linalg.norm(t64, axis=0, keepdims=True),
        lambda_p=float(lambda_p),
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


# ---------------------------------------------------------------------------------------------
# Running an estimator in sharpened space (§5.4, §5.6) with the revert policy (§5.2)


def sharpened_world(world: World, transform: Float[Array, "3 3"]) -> World:
    """The world seen through sensors ``Q @ T``: every response (canonical gamut, training
    whites, database means) becomes ``x @ T``, which is how §5.4 runs an algorithm "entirely in
    sharpened space". Illuminants keep their (unsharpened) normalisation."""
    sensors = world.camera.sensors @ jnp.asarray(transform, world.camera.sensors.dtype)
    return eqx.tree_at(lambda w: w.camera.sensors, world, sensors)


_NEEDS_POSITIVE = re.compile(r"(^|-)(CRULE|ECRULE|CIP)(-|$)")


class SharpenedEstimate(Estimate):
    """An :class:`Estimate` that also says whether the scene reverted to the unsharpened result."""

    reverted: Bool[Array, "..."]


class Sharpened(Estimator):
    """An estimator run in the space sharpened by ``transform`` (§5.4).

    The input is sharpened (``x @ T``), ``inner`` (fitted in the sharpened world) estimates the
    sharpened white ``e#``, and the answer is ``e# @ T^-1``. Where negative values make the
    sharpened run invalid — a non-positive sharpened training white, canonical white or canonical
    reflectance response (``calibration_ok`` False; every scene), a non-positive sharpened input (that
    scene), or the inner estimator failing (``ok`` False: no feasible map) — and
    ``requires_positive`` is set (gamut mapping), the scene reverts to ``plain``'s unsharpened
    answer (§5.2: no clipping, offsetting or dropping), flagged in ``reverted``.
    """

    inner: Estimator
    plain: Estimator
    transform: Float[Array, "3 3"]
    inverse: Float[Array, "3 3"]
    calibration_ok: Bool[Array, ""]
    requires_positive: bool = eqx.field(static=True, default=False)

    @property
    def estimates_brightness(self) -> bool:  # type: ignore[override]
        return self.plain.estimates_brightness

    def run(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> SharpenedEstimate:
        sharp = rgb @ self.transform
        inner = self.inner(sharp, mask)
        plain = self.plain(rgb, mask)
        estimate = inner.illuminant @ self.inverse
        if self.requires_positive:
            inputs_ok = jnp.all(jnp.where(mask[:, None], sharp > 0, True))
            valid = self.calibration_ok & inputs_ok & inner.ok
        else:
            valid = jnp.all(jnp.isfinite(estimate))
        return SharpenedEstimate(
            illuminant=jnp.where(valid, estimate, plain.illuminant),
            ok=jnp.where(valid, inner.ok, plain.ok),
            reverted=~valid,
        )

    def sharp_white(self, illuminant: Float[Array, "3"]) -> Float[Array, "3"]:
        return illuminant @ self.transform

    def __call__(self, rgb, mask) -> Estimate:
        result = self.run(rgb, mask)
        return Estimate(illuminant=result.illuminant, ok=result.ok)


def _fitter(estimator) -> Callable[[World], Estimator]:
    if isinstance(estimator, str):
        from ccjax.estimators import registry

        return lambda w: registry.fit(estimator, w)
    if callable(estimator):
        return estimator
    raise ValueError(f"estimator: expected a label or a fit(world) callable, got {estimator!r}")


def sharpened(
    estimator: str | Callable[[World], Estimator],
    transform,
    world: World,
    *,
    requires_positive: bool | None = None,
    plain: Estimator | None = None,
) -> Sharpened:
    """Run any estimator in the space sharpened by ``transform`` (§5.4) with the revert policy.

    Arguments:
        estimator: a registry label (``"DB-GW"``, ``"ECRULE-ICA"``) or ``fit(world) -> Estimator``;
            it is fitted twice: to the sharpened world (sensors ``Q @ T``) and to ``world``.
        transform: ``(3, 3)`` invertible ``T``.
        world: the (unsharpened) world.
        requires_positive: revert on negative sharpened data; default True for gamut-mapping
            labels (CRULE/ECRULE/CIP), the only algorithms the thesis saw revert (§5.2).
        plain: the unsharpened model if already fitted.

    Returns:
        A :class:`Sharpened` estimator (``run`` also reports reverts). Works under ``jit``/``vmap``
        and ``grad`` with respect to ``transform`` when the estimator's fit is traceable.
    """
    t = jnp.asarray(transform, dtype=world.canonical_rgb.dtype)
    if t.shape != (3, 3):
        raise ValueError(f"transform: expected shape (3, 3), got {t.shape}")
    if not isinstance(t, jax.core.Tracer):  # concrete T: check at the boundary (traced T: caller's job)
        condition = np.linalg.cond(np.asarray(t, np.float64))
        if not np.isfinite(condition) or condition > 1e6:
            raise ValueError(f"transform: singular or badly conditioned (condition number {condition:.3g})")
    fit = _fitter(estimator)
    if requires_positive is None:
        requires_positive = isinstance(estimator, str) and bool(_NEEDS_POSITIVE.search(estimator))
    sharp = sharpened_world(world, t)
    # Calibration data that must be positive (spec §7 A8): the sharpened whites (illumination
    # constraint, w_c# / e#) and the sharpened canonical gamut, whose hull must keep the origin as
    # its vertex in the positive octant (with negative points the feasible maps become unbounded
    # and gamut estimates collapse to near-black lights).
    calibration_ok = (
        jnp.all(sharp.train_whites > 0) & jnp.all(sharp.canonical_white > 0) & jnp.all(sharp.canonical_rgb > 0)
    )
    plain = fit(world) if plain is None else plain
    try:
        inner = fit(sharp)
    except ValueError:
        # A fit that refuses negative sharpened calibration data (e.g. a gamut hull) cannot run in
        # this space at all: every scene reverts (§5.2; the thesis' DCS-200 "ave" rows).
        if not requires_positive:
            raise
        inner, calibration_ok = plain, jnp.asarray(False)
    return Sharpened(
        inner=inner,
        plain=plain,
        transform=t,
        inverse=jnp.linalg.inv(t),
        calibration_ok=calibration_ok,
        requires_positive=bool(requires_positive),
    )


# ---------------------------------------------------------------------------------------------
# Chapter 5 evaluation (§5.4, §5.7): mapping error over the whole reflectance set, angle, reverts


class Chapter5Scenes(eqx.Module):
    """Scenes of §5.7 by index: the light (into the world's test illuminants) and the surfaces.

    Drawn with the sweep engine's per-scene key scheme (:mod:`ccjax.scenes`), so scene ``k`` has
    the same light and surfaces as scene ``k`` of a matte sweep with the same key and size.
    """

    light: Int[Array, " B"]
    surfaces: Int[Array, "B P"]

    @classmethod
    def draw(cls, key, n_lights: int, n_reflectances: int, n_scenes: int, n_surfaces: int) -> Chapter5Scenes:
        from ccjax.scenes import _draw_without_replacement, scene_keys

        keys = scene_keys(jax.random.fold_in(key, n_surfaces), 0, n_scenes)

        def one(k):
            key_light, key_surf = jax.random.split(k, 5)[:2]
            light = jax.random.randint(key_light, (), 0, n_lights)
            return light, _draw_without_replacement(key_surf, n_reflectances, n_surfaces)

        light, surfaces = jax.vmap(one)(keys)
        return cls(light=light, surfaces=surfaces)


class Chapter5Data(eqx.Module):
    """Everything the chapter-5 errors need from a world: the database under every test light."""

    database: Float[Array, "J S 3"]
    canonical: Float[Array, "S 3"]
    whites: Float[Array, "J 3"]
    canonical_white: Float[Array, "3"]

    @classmethod
    def of(cls, world: World) -> Chapter5Data:
        return cls(
            database=database_responses(world, world.test_illuminants),
            canonical=world.canonical_rgb,
            whites=world.test_whites,
            canonical_white=world.canonical_white,
        )


def _scene_error(data: Chapter5Data, light, transform, illuminant):
    """Mapping error (unit scale) and angle of an estimate ``illuminant`` in camera space, with the
    sharpened map ``d# = (w_c T) / (e T)`` (§5.4)."""
    sharp_map = (data.canonical_white @ transform) / (illuminant @ transform)
    error = mapping_error(data.database[light], data.canonical, transform, sharp_map)
    return error, metrics.angular_error(illuminant, data.whites[light])


@eqx.filter_jit
def _run_fixed(model, data: Chapter5Data, scenes: Chapter5Scenes, transform):
    def one(light, surfaces):
        rgb = data.database[light, surfaces]
        mask = jnp.ones(surfaces.shape, bool)
        if isinstance(model, Sharpened):
            result = model.run(rgb, mask)
            reverted = result.reverted
        else:
            result = model(rgb, mask)
            reverted = jnp.asarray(False)
        error, angle = _scene_error(data, light, transform, result.illuminant)
        return error, angle, reverted

    return jax.vmap(one)(scenes.light, scenes.surfaces)


def _run_comparison(kind: str, data: Chapter5Data, scenes: Chapter5Scenes, transforms):
    """BEST-LINEAR / BEST-DIAGONAL / ACTUAL (§5.7) with one transform per scene."""

    def one(light, transform):
        source, target = data.database[light], data.canonical
        truth = data.whites[light]
        if kind == "BEST-LINEAR":
            return best_linear_error(source, target), jnp.nan
        if kind == "BEST-DIAGONAL":
            sharp_map = best_diagonal_map(source, target, transform)
            estimate = ((data.canonical_white @ transform) / sharp_map) @ jnp.linalg.inv(transform)
        else:  # ACTUAL: the true white in sharpened space
            sharp_map = (data.canonical_white @ transform) / (truth @ transform)
            estimate = truth
        return mapping_error(source, target, transform, sharp_map), metrics.angular_error(estimate, truth)

    error, angle = jax.jit(jax.vmap(one))(scenes.light, transforms)
    return error, angle, jnp.zeros(error.shape, bool)


COMPARISONS = ("BEST-LINEAR", "BEST-DIAGONAL", "ACTUAL")


def _run_per_scene(label: str, world: World, data, scenes, transforms, plain):
    """An estimator under a different ``T`` per scene ("opt"): traced through ``vmap`` when the
    estimator's fit is plain JAX, else refitted once per distinct light (gamut mapping uses Qhull)."""

    def one(light, surfaces, transform):
        model = sharpened(label, transform, world, plain=plain)
        rgb = data.database[light, surfaces]
        result = model.run(rgb, jnp.ones(surfaces.shape, bool))
        error, angle = _scene_error(data, light, transform, result.illuminant)
        return error, angle, result.reverted

    try:
        return jax.jit(jax.vmap(one))(scenes.light, scenes.surfaces, transforms)
    except (
        jax.errors.ConcretizationTypeError,
        jax.errors.TracerArrayConversionError,
        jax.errors.TracerBoolConversionError,
    ):
        pass
    lights = np.asarray(scenes.light)
    n = lights.shape[0]
    error, angle, reverted = np.zeros(n), np.zeros(n), np.zeros(n, bool)
    for light in np.unique(lights):
        rows = np.flatnonzero(lights == light)
        transform = transforms[rows[0]]
        model = sharpened(label, transform, world, plain=plain)
        subset = Chapter5Scenes(light=scenes.light[rows], surfaces=scenes.surfaces[rows])
        e, a, r = _run_fixed(model, data, subset, transform)
        error[rows], angle[rows], reverted[rows] = e, a, r
    return error, angle, reverted


@dataclass
class Chapter5Result:
    """Per-scene chapter-5 errors: ``errors[(method, sharpening)] = (mapping, angle, reverted)``
    NumPy arrays, mapping errors on the unit scale. ``info`` holds the transforms' metadata."""

    n_scenes: int
    errors: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    def rows(self) -> list[dict]:
        out = []
        for (method, sharpening), (mapping, angle, reverted) in self.errors.items():
            out.append(
                {
                    "method": method,
                    "sharpening": sharpening,
                    "map_rgb": None if method == "NOTHING" else float(np.sqrt(np.mean(mapping**2))) * THESIS_SCALE,
                    "angular": None if method == "BEST-LINEAR" else float(np.sqrt(np.mean(angle**2))),
                    "reverted": int(np.sum(reverted)),
                }
            )
        return out


def chapter5_errors(
    world: World,
    methods: Sequence[str],
    sharpenings: Sequence[str] = SHARPENINGS,
    n_scenes: int = 1000,
    n_surfaces: int = 8,
    key=None,
    *,
    new: NewSharpening | None = None,
    progress: bool = False,
) -> Chapter5Result:
    """The chapter-5 protocol (§5.7): ``n_scenes`` scenes of ``n_surfaces`` surfaces under random
    test lights; every method under every sharpening; mapping error over the whole reflectance set
    and angular error per scene, and revert counts (§5.2).

    Arguments:
        world: normally :meth:`World.barnard1999`.
        methods: estimator labels and/or ``BEST-LINEAR``, ``BEST-DIAGONAL``, ``ACTUAL``.
        sharpenings: any of ``none``, ``opt`` (per-scene database sharpening with the true light),
            ``ave`` (database sharpening with the mean training light), ``new`` (§5.3).
        new: a precomputed :func:`new_sharpening` result (computed if needed and not given).
    """
    unknown = [s for s in sharpenings if s not in SHARPENINGS]
    if unknown:
        raise ValueError(f"sharpenings: unknown {unknown}; expected some of {SHARPENINGS}")
    if not isinstance(n_scenes, int) or n_scenes < 1:
        raise ValueError(f"n_scenes: expected a positive integer, got {n_scenes!r}")
    from ccjax.estimators import registry

    key = jax.random.key(0) if key is None else key
    data = Chapter5Data.of(world)
    dtype = data.canonical.dtype
    scenes = Chapter5Scenes.draw(key, data.database.shape[0], data.database.shape[1], n_scenes, n_surfaces)
    result = Chapter5Result(n_scenes=n_scenes)
    fixed = {"none": np.eye(3)}
    if "ave" in sharpenings:
        fixed["ave"] = average_sharpening(world)
    if "new" in sharpenings:
        new = new_sharpening(world) if new is None else new
        fixed["new"] = new.transform
        result.info["new"] = new
    if "opt" in sharpenings:
        per_light = jnp.asarray(optimal_sharpening(world), dtype)
    for name, t in fixed.items():
        result.info[f"T_{name}"] = np.asarray(t)
    plain_models = {}
    for method in methods:
        for sharpening in sharpenings:
            if method in ("BEST-LINEAR", "NOTHING") and sharpening != "none":
                continue  # invariant to sharpening / no mapping error (§5.7)
            start = time.perf_counter()
            if sharpening == "opt":
                transforms = per_light[scenes.light]
            else:
                transforms = jnp.broadcast_to(jnp.asarray(fixed[sharpening], dtype), (n_scenes, 3, 3))
            if method in COMPARISONS:
                out = _run_comparison(method, data, scenes, transforms)
            else:
                if method not in plain_models:
                    plain_models[method] = registry.fit(method, world)
                plain = plain_models[method]
                if sharpening == "none":
                    out = _run_fixed(plain, data, scenes, transforms[0])
                elif sharpening == "opt":
                    out = _run_per_scene(method, world, data, scenes, transforms, plain)
                else:
                    model = sharpened(method, fixed[sharpening], world, plain=plain)
                    out = _run_fixed(model, data, scenes, transforms[0])
            result.errors[(method, sharpening)] = tuple(np.asarray(x) for x in out)
            if progress:
                print(f"  {method:<14}{sharpening:<6}{time.perf_counter() - start:6.1f} s", flush=True)
    return result


# ---------------------------------------------------------------------------------------------
# Table 5.1 (``ccjax reproduce 5.1``)


@dataclass
class Reproduction51:
    """Table 5.1 reproduced: one row per (method, sharpening, column) with ours, the thesis' value
    and ``ours / thesis - 1``; ``checks`` are the thesis' qualitative findings (§5.7)."""

    rows: list[dict]
    checks: list[dict]
    info: dict
    pending: list[str]

    def to_json(self) -> str:
        return json.dumps(
            {"table": "5.1", "rows": self.rows, "checks": self.checks, "info": self.info, "pending": self.pending},
            indent=1,
        )

    def text(self) -> str:
        lines = ["Table 5.1 (Sony DXC-930): ours vs thesis (mapping errors in thesis units, white = 255)"]
        lines.append(
            f"{'method':<15}{'sharpening':<11}{'column':<9}{'ours':>10}{'thesis':>10}{'diff':>9}{'reverted':>10}{'thesis':>8}"
        )
        for row in self.rows:
            diff = "" if row["relative_difference"] is None else f"{row['relative_difference']:+9.1%}"
            lines.append(
                f"{row['method']:<15}{row['sharpening']:<11}{row['column']:<9}{row['ours']:>10.4g}"
                f"{row['thesis']:>10.4g}{diff:>9}{row['reverted']:>10d}{row['thesis_reverted']:>8d}"
            )
        for key, value in self.info.items():
            lines.append(f"{key}: {value}")
        lines.append("thesis behaviour:")
        for check in self.checks:
            lines.append(f"  [{'ok' if check['holds'] else 'FAILS'}] {check['check']}: {check['evidence']}")
        if self.pending:
            lines.append(f"pending (not registered): {', '.join(self.pending)}")
        return "\n".join(lines)


def _behaviour_checks(values: dict, worst: dict) -> list[dict]:
    """The findings the issue checks for ``ave`` and ``opt`` (their numbers depend on the lights)."""
    checks = []
    for method in ("BEST-DIAGONAL", "ACTUAL"):
        if (method, "ave") in values and (method, "none") in values:
            a, n = values[(method, "ave")], values[(method, "none")]
            checks.append(
                {"check": f"{method}: ave worse than none", "holds": a > n, "evidence": f"{a:.2f} vs {n:.2f}"}
            )
    for method in ("GW", "DB-GW", "RETINEX"):
        if (method, "opt") in values and (method, "none") in values:
            o, n = values[(method, "opt")], values[(method, "none")]
            evidence = f"{o:.1f} vs {n:.1f} ({o / n:.2f}x); worst scene {worst[(method, 'opt')]:.1f} vs {worst[(method, 'none')]:.1f}"
            checks.append(
                {"check": f"{method}: opt mapping error >= 3x none", "holds": o >= 3 * n, "evidence": evidence}
            )
    return checks


def reproduce_5_1(
    world: World,
    methods: Sequence[str] | None = None,
    n_scenes: int = 1000,
    key=None,
    progress: bool = True,
) -> Reproduction51:
    """Run Table 5.1's protocol (§5.7: 1000 scenes of 8 surfaces, Sony DXC-930) and compare.

    Arguments:
        world: :meth:`World.barnard1999`.
        methods: rows (default: every row of the table that can run; unregistered ones, e.g.
            gamut mapping before it exists, are listed as pending).
        n_scenes: scenes (1000 in the thesis).
        key: PRNG key (default ``jax.random.key(0)``).
    """
    from ccjax import thesis
    from ccjax.experiments import _is_registered

    targets = thesis.TABLES["5.1"]
    if methods is None:
        methods = list(targets)
    unknown = [m for m in methods if m not in targets]
    if unknown:
        raise ValueError(f"methods: {unknown} are not rows of Table 5.1")
    runnable = [m for m in methods if m in COMPARISONS or _is_registered(m)]
    pending = [m for m in methods if m not in runnable]
    result = chapter5_errors(world, runnable, SHARPENINGS, n_scenes, 8, key, progress=progress)
    rows, mapping = [], {}
    for row in result.rows():
        method, sharpening = row["method"], row["sharpening"]
        if row["map_rgb"] is not None:
            mapping[(method, sharpening)] = row["map_rgb"]
        for column in ("map_rgb", "angular"):
            reference = targets[method].get(f"{column}@{sharpening}")
            if reference is None or row[column] is None:
                continue
            rows.append(
                {
                    "method": method,
                    "sharpening": sharpening,
                    "column": column,
                    "ours": row[column],
                    "thesis": reference,
                    "relative_difference": row[column] / reference - 1.0 if reference else None,
                    "reverted": row["reverted"],
                    "thesis_reverted": targets[method].get(f"reverted@{sharpening}", 0),
                }
            )
    new = result.info["new"]
    info = {
        "new: lambda_P": new.lambda_p,
        "new: negative training responses": f"{new.negative_fraction:.4%}",
        "new: non-positive sharpened canonical responses + training whites": new.negative_calibration,
        "new: lambda_P search (lambda_P, negative fraction, calibration negatives, iterations)": new.search,
        "new: iterations": new.iterations,
        "new: E at identity -> final": f"{new.initial_mapping:.4f} -> {new.mapping:.4f}",
        "new: T": np.round(new.transform, 4).tolist(),
        "ave: T": np.round(result.info["T_ave"], 4).tolist(),
    }
    worst = {pair: float(np.max(errors[0])) * THESIS_SCALE for pair, errors in result.errors.items()}
    return Reproduction51(rows=rows, checks=_behaviour_checks(mapping, worst), info=info, pending=pending)


# ---------------------------------------------------------------------------------------------
# Summaries and plots (``ccjax sharpen``)


def negative_lobes(sensors: Float[Array, "101 3"]) -> np.ndarray:
    """Per sensor, the share of its absolute area that is negative (0 for a physical sensor)."""
    sensors = np.asarray(sensors, dtype=np.float64)
    return np.sum(np.maximum(-sensors, 0.0), axis=0) / np.sum(np.abs(sensors), axis=0)


def _actual_error(source, target, transform, truth, canonical_white):
    sharp_map = (canonical_white @ transform) / (truth @ transform)
    return mapping_error(source, target, transform, sharp_map)


def summary(world: World, transform) -> dict:
    """What a transform does on ``world``: its sharpened sensors' negative lobes, the share of
    negative sharpened training responses, and RMS mapping errors over the test illuminants
    (thesis units) of BEST-LINEAR, and of BEST-DIAGONAL and ACTUAL with and without ``T``."""
    t = jnp.asarray(transform, world.canonical_rgb.dtype)
    identity = jnp.eye(3, dtype=t.dtype)
    sources = database_responses(world, world.test_illuminants)
    target, whites, white = world.canonical_rgb, world.test_whites, world.canonical_white

    def rms(values):
        return float(jnp.sqrt(jnp.mean(values**2))) * THESIS_SCALE

    out = {
        "negative_lobes": negative_lobes(world.camera.sensors @ t).tolist(),
        "negative_training_responses": float(jnp.mean(database_responses(world, world.train_illuminants) @ t < 0)),
        "best_linear": rms(jax.jit(jax.vmap(best_linear_error, (0, None)))(sources, target)),
    }
    diagonal = jax.jit(jax.vmap(diagonal_error, (0, None, None)))
    actual = jax.jit(jax.vmap(_actual_error, (0, None, None, 0, None)))
    for name, m in (("unsharpened", identity), ("sharpened", t)):
        out[f"best_diagonal_{name}"] = rms(diagonal(sources, target, m))
        out[f"actual_{name}"] = rms(actual(sources, target, m, whites, white))
    return out


def plot_sensors(world: World, transform, path, title: str | None = None) -> None:
    """Original and sharpened sensor curves (each normalised to a peak |value| of 1)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ccjax.spectra import WAVELENGTHS

    original = np.asarray(world.camera.sensors, dtype=np.float64)
    sharp = original @ np.asarray(transform, dtype=np.float64)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for ax, curves, name in ((axes[0], original, "original"), (axes[1], sharp, "sharpened")):
        for k, colour in enumerate("rgb"):
            ax.plot(WAVELENGTHS, curves[:, k] / np.max(np.abs(curves[:, k])), color=colour)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_title(f"{name} sensors")
        ax.set_xlabel("wavelength (nm)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("relative sensitivity")
    fig.suptitle(title or world.camera.name)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------
# Learned end-to-end sharpening (beyond the thesis; spec §8 "task-driven sharpening")


@dataclass
class LearnedSharpening:
    """``T`` learned through an estimator: ``transform`` (unit columns), the training loss per step
    (``losses``, RMS over the batch: thesis units for the mapping loss, degrees for the angle)."""

    transform: np.ndarray
    estimator: str
    loss: str
    losses: list
    seconds: float


def _scene_losses(parameters, label, loss, world, train, whites, lights, surfaces, plain):
    transform = _on_sphere(parameters)
    model = sharpened(label, transform, world, plain=plain)
    canonical, canonical_white = world.canonical_rgb, world.canonical_white

    def one(light, chosen):
        rgb = train[light, chosen]
        estimate = model.run(rgb, jnp.ones(chosen.shape, bool)).illuminant
        if loss == "angular":
            return metrics.angular_error(estimate, whites[light])
        sharp_map = (canonical_white @ transform) / (estimate @ transform)
        return mapping_error(train[light], canonical, transform, sharp_map) * THESIS_SCALE

    return jax.vmap(one)(lights, surfaces)


def learned_sharpening(
    world: World,
    estimator: str = "GW",
    loss: str = "mapping",
    *,
    steps: int = 300,
    batch_size: int = 128,
    n_surfaces: int = 8,
    learning_rate: float = 3e-3,
    key=None,
) -> LearnedSharpening:
    """Learn ``T`` by gradient descent through a differentiable estimator (beyond the thesis).

    Training scenes (``n_surfaces`` random reflectances under a random *training* illuminant, fresh
    every step) are run through ``sharpened(estimator, T)``; the loss is the mean square of the
    chapter-5 mapping error (``loss="mapping"``; the one to use for GW, whose chromaticity does not
    depend on ``T``, DESIGN.md §5) or of the angular error (``loss="angular"``, for non-linear
    estimators such as ``soft-RETINEX-t0.01`` or ``shades-of-grey-p6``). ``T`` starts at the
    identity and stays on ``|T|_F^2 = 3`` (the new method's norm constraint); Adam (optax).

    Arguments:
        world: training illuminants, reflectances, canonical light.
        estimator: a registry label whose fit is plain JAX (GW, DB-GW, shades of grey, soft RETINEX).
        loss: ``"mapping"`` or ``"angular"``.
        steps, batch_size, n_surfaces, learning_rate: the schedule.
        key: PRNG key (default ``jax.random.key(1)``).
    """
    import optax

    from ccjax.estimators import registry

    if loss not in ("mapping", "angular"):
        raise ValueError(f"loss: expected 'mapping' or 'angular', got {loss!r}")
    if not isinstance(steps, int) or steps < 1:
        raise ValueError(f"steps: expected a positive integer, got {steps!r}")
    key = jax.random.key(1) if key is None else key
    train = database_responses(world, world.train_illuminants)
    whites = world.train_whites
    plain = registry.fit(estimator, world)
    n_lights, n_reflectances = train.shape[:2]
    optimiser = optax.adam(learning_rate)

    @eqx.filter_jit
    def step(parameters, state, step_key):
        draws = Chapter5Scenes.draw(step_key, n_lights, n_reflectances, batch_size, n_surfaces)

        def batch_loss(p):
            errors = _scene_losses(p, estimator, loss, world, train, whites, draws.light, draws.surfaces, plain)
            return jnp.mean(errors**2)

        value, grad = jax.value_and_grad(batch_loss)(parameters)
        updates, state = optimiser.update(grad, state, parameters)
        return optax.apply_updates(parameters, updates), state, value

    parameters = jnp.eye(3, dtype=train.dtype)
    state = optimiser.init(parameters)
    losses = []
    start = time.perf_counter()
    for index in range(steps):
        parameters, state, value = step(parameters, state, jax.random.fold_in(key, index))
        losses.append(float(jnp.sqrt(value)))
    t = np.asarray(_on_sphere(parameters), dtype=np.float64)
    return LearnedSharpening(
        transform=t / np.linalg.norm(t, axis=0, keepdims=True),
        estimator=estimator,
        loss=loss,
        losses=losses,
        seconds=time.perf_counter() - start,
    )


def evaluate_transforms(
    world: World,
    label: str | Callable[[World], Estimator],
    transforms: dict,
    n_scenes: int = 1000,
    n_surfaces: int = 8,
    key=None,
    *,
    requires_positive: bool | None = None,
) -> dict:
    """RMS chapter-5 mapping error (thesis units), RMS angular error and revert count of an
    estimator (label or ``fit(world)``) under each named transform, on the same held-out scenes
    under the world's *test* lights."""
    key = jax.random.key(0) if key is None else key
    data = Chapter5Data.of(world)
    scenes = Chapter5Scenes.draw(key, data.database.shape[0], data.database.shape[1], n_scenes, n_surfaces)
    plain = _fitter(label)(world)
    out = {}
    for name, transform in transforms.items():
        t = jnp.asarray(transform, data.canonical.dtype)
        model = sharpened(label, t, world, plain=plain, requires_positive=requires_positive)
        mapping, angle, reverted = _run_fixed(model, data, scenes, t)
        out[name] = {
            "map_rgb": float(jnp.sqrt(jnp.mean(mapping**2))) * THESIS_SCALE,
            "angular": float(jnp.sqrt(jnp.mean(angle**2))),
            "reverted": int(jnp.sum(reverted)),
        }
    return out


def rank_cameras(data_dir=None, names: Sequence[str] | None = None, progress: bool = False) -> list[dict]:
    """Sharpness (BEST-LINEAR / BEST-DIAGONAL over the test lights, §5.7) of every available camera,
    each in ``World.default(camera=...)``, least sharp first.

    Returns:
        ``[{"camera", "source", "ratio", "best_linear", "best_diagonal"}]`` sorted by ratio.
    """
    from ccjax.camera import Camera, cameras

    available = cameras(data_dir)
    rows = []
    for name in names or list(available):
        world = World.default(Camera.from_name(name, data_dir))
        out = sharpness(world)
        rows.append({"camera": name, "source": available.get(name, "?"), **out})
        if progress:
            print(f"  {name:<36}{out['ratio']:.3f}", flush=True)
    return sorted(rows, key=lambda row: row["ratio"])
