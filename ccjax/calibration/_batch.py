"""Many fits at once: batches of data sets, subsets of one data set, and cross-validation.

Every fit here is :func:`ccjax.calibration.fitting.fit_sensors`' kernel under ``jax.vmap``: data
sets of the same shape (pad with ``mask=False`` rows), or one data set with many row masks (the
robustness experiment of §3.6 / Fig. 3.6, held-out evaluation, K-fold cross-validation of the
smoothness, which Barnard 1999 §3.4 sets by hand).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from ccjax.calibration._kernel import FitOptions, fit_data_set
from ccjax.calibration._plan import DEFAULT_SMOOTHNESS, check_data, plan_fit
from ccjax.calibration.errors import FitErrors, fit_errors
from ccjax.calibration.fitting import SensorFit, fit_sensors
from ccjax.calibration.linearisation import apply_linearisation
from ccjax.precision import matmul
from ccjax.spectra import N_WAVELENGTHS


class BatchFit(eqx.Module):
    """Fits of a batch (leading axis ``B``).

    Attributes:
        sensors: ``(B, 101, 3)``.
        a0, a1, exp_rate, black: ``(B, 3)`` linearisation parameters (zeros when not fitted).
        errors: :class:`FitErrors` of each fit on its own measurements, leaves ``(B,)``.
        converged: ``(B, 3)`` solver status per channel.
    """

    sensors: Float[Array, "B 101 3"]
    a0: Float[Array, "B 3"]
    a1: Float[Array, "B 3"]
    exp_rate: Float[Array, "B 3"]
    black: Float[Array, "B 3"]
    errors: FitErrors
    converged: Bool[Array, "B 3"]

    def linearise(self, raw: Float[Array, "B M 3"]) -> Float[Array, "B M 3"]:
        """Each fit's F applied to its raw responses.

        Arguments:
            raw: ``(B, M, 3)`` raw responses, one data set per fit.

        Returns:
            ``(B, M, 3)`` linear responses.
        """
        return apply_linearisation(raw, self.a0[:, None], self.a1[:, None], self.exp_rate[:, None], self.black[:, None])


def _options_for(**options):
    keys = (
        "smoothness",
        "error",
        "positive",
        "support",
        "max_abs_error",
        "max_rel_error",
        "weight_cap",
        "linearisation",
        "black",
        "exp_rate",
        "maxiter",
    )
    unknown = set(options) - set(keys)
    if unknown:
        raise ValueError(f"unknown fitting option(s): {sorted(unknown)}")
    full = dict(
        smoothness=DEFAULT_SMOOTHNESS,
        error="relative",
        positive=True,
        support=None,
        max_abs_error=None,
        max_rel_error=None,
        weight_cap=None,
        linearisation=None,
        black=None,
        exp_rate=None,
        maxiter=None,
    )
    full.update(options)
    return plan_fit(**full)


@functools.partial(jax.jit, static_argnames=("solver", "search"))
def _fit_many(spectra, raw, masks, options: FitOptions, smoothness, solver: str, search: bool):
    """Fits for a batch: every argument but ``options`` has a leading batch axis."""

    def one(spectra, raw, mask, lam):
        fits, rates = fit_data_set(spectra, raw, mask, options._replace(smoothness=lam), solver, search)
        sensors = fits.sensor.T
        return (
            sensors,
            fits.a0,
            fits.a1,
            rates,
            fits.solution.converged,
            fit_errors(matmul(spectra, sensors), fits.linear.T, mask),
        )

    return jax.vmap(one)(spectra, raw, masks, smoothness)


DEFAULT_CHUNK = 20


def _run_chunks(spectra, raw, masks, smoothness, plan, chunk_size: int):
    """Run :func:`_fit_many` over the batch in chunks of exactly ``chunk_size`` (the last one padded
    by repeating its first entry), so every batch size reuses one compiled program."""
    dtype = plan.options.smoothness.dtype
    total = masks.shape[0]
    chunks = []
    for start in range(0, total, chunk_size):
        index = np.arange(start, min(start + chunk_size, total))
        padded = np.concatenate([index, np.full(chunk_size - index.size, index[0])])
        out = _fit_many(
            jnp.asarray(
                spectra[padded] if spectra.ndim == 3 else np.broadcast_to(spectra, (chunk_size,) + spectra.shape), dtype
            ),
            jnp.asarray(raw[padded] if raw.ndim == 3 else np.broadcast_to(raw, (chunk_size,) + raw.shape), dtype),
            jnp.asarray(masks[padded]),
            plan.options,
            jnp.asarray(smoothness[padded], dtype),
            plan.solver,
            plan.search,
        )
        chunks.append(jax.tree_util.tree_map(lambda leaf, size=index.size: leaf[:size], out))
    return jax.tree_util.tree_map(lambda *leaves: jnp.concatenate(leaves), *chunks)


def _batch_fit(outputs, options: FitOptions, linearised: bool) -> BatchFit:
    sensors, a0, a1, rates, converged, errors = outputs
    b = sensors.shape[0]
    return BatchFit(
        sensors=sensors,
        a0=a0,
        a1=a1,
        exp_rate=rates if linearised else jnp.zeros_like(rates),
        black=jnp.broadcast_to(options.black, (b, 3)),
        errors=errors,
        converged=converged,
    )


def fit_sensors_batch(
    spectra: Float[ArrayLike, "B M 101"],
    responses: Float[ArrayLike, "B M 3"],
    *,
    mask: Bool[ArrayLike, "B M"] | None = None,
    chunk_size: int | None = None,
    **options,
) -> BatchFit:
    """Fit many data sets of equal shape in one vmapped program (e.g. one per camera).

    Arguments:
        spectra: ``(B, M, 101)`` measured spectra, one data set per fit.
        responses: ``(B, M, 3)`` their camera responses.
        mask: ``(B, M)`` usable rows (pad unequal data sets with ``False`` rows; ``None``: all).
        chunk_size: data sets per compiled call (bounded memory; default 20); the last chunk is
            padded, so any batch size reuses the program compiled for this chunk size.
        **options: as :func:`ccjax.calibration.fit_sensors` (``smoothness``, ``error``,
            ``positive``, ``support``, ``linearisation``, ``black``, ``exp_rate``, ...).

    Returns:
        A :class:`BatchFit`.
    """
    spectra = np.asarray(spectra, dtype=np.float64)
    responses = np.asarray(responses, dtype=np.float64)
    if spectra.ndim != 3 or spectra.shape[2] != N_WAVELENGTHS:
        raise ValueError(f"spectra: expected shape (B, M, {N_WAVELENGTHS}), got {spectra.shape}")
    if responses.shape != spectra.shape[:2] + (3,):
        raise ValueError(f"responses: expected shape {spectra.shape[:2] + (3,)}, got {responses.shape}")
    mask = np.ones(spectra.shape[:2], bool) if mask is None else np.asarray(mask, bool)
    if mask.shape != spectra.shape[:2]:
        raise ValueError(f"mask: expected shape {spectra.shape[:2]}, got {mask.shape}")
    for b in range(spectra.shape[0]):
        check_data(spectra[b], responses[b], mask[b])
    plan = _options_for(**options)
    smoothness = np.full(spectra.shape[0], float(plan.options.smoothness))
    outputs = _run_chunks(spectra, responses, mask, smoothness, plan, chunk_size or DEFAULT_CHUNK)
    return _batch_fit(outputs, plan.options, plan.kind == "exp")


def fit_subsets(
    spectra: Float[ArrayLike, "M 101"],
    responses: Float[ArrayLike, "M 3"],
    masks: Bool[ArrayLike, "B M"],
    *,
    smoothness=None,
    chunk_size: int = DEFAULT_CHUNK,
    **options,
) -> BatchFit:
    """Fit one data set many times, each on the rows one mask selects (vmapped, in chunks).

    Arguments:
        spectra: ``(M, 101)`` measured spectra.
        responses: ``(M, 3)`` their camera responses.
        masks: ``(B, M)`` row selections.
        smoothness: a scalar, or ``(B,)`` one lambda per fit (cross-validation grids).
        chunk_size: fits per compiled call (bounded memory); the last chunk is padded.
        **options: as :func:`ccjax.calibration.fit_sensors`.

    Returns:
        The :class:`BatchFit` of the ``B`` fits.
    """
    spectra, responses = check_data(spectra, responses)
    masks = np.asarray(masks, bool)
    if masks.ndim != 2 or masks.shape[1] != spectra.shape[0]:
        raise ValueError(f"masks: expected shape (B, {spectra.shape[0]}), got {masks.shape}")
    if not np.all(masks.any(axis=1)):
        raise ValueError("masks: a mask selects no measurement")
    lam = np.broadcast_to(
        np.asarray(DEFAULT_SMOOTHNESS if smoothness is None else smoothness, dtype=np.float64), (masks.shape[0],)
    )
    if not np.all(np.isfinite(lam)) or np.any(lam < 0):
        raise ValueError("smoothness: expected finite values >= 0")
    plan = _options_for(smoothness=float(lam[0]), **options)
    if plan.solver == "lstsq" and np.any(lam > 0):
        plan = _options_for(smoothness=float(lam.max()), **options)  # a smoothed fit needs the QP solver
    outputs = _run_chunks(spectra, responses, masks, lam, plan, chunk_size)
    return _batch_fit(outputs, plan.options, plan.kind == "exp")


def evaluate_batch(fits: BatchFit, spectra, responses, mask=None, *, linearised: bool) -> FitErrors:
    """Table 3.1 errors of every fit in ``fits`` on one data set (e.g. all 612 measurements).

    Arguments:
        fits: the batch of fits.
        spectra: ``(M, 101)`` measured spectra.
        responses: ``(M, 3)`` their camera responses.
        mask: ``(M,)`` the rows to score (``None``: all).
        linearised: True when ``responses`` are raw and each fit's own F is to be applied (joint
            fits); False when they are already linear.

    Returns:
        The :class:`FitErrors` of every fit, batched over the fits.
    """
    spectra, responses = check_data(spectra, responses, mask)
    dtype = fits.sensors.dtype
    spectra = jnp.asarray(spectra, dtype)
    raw = jnp.broadcast_to(jnp.asarray(responses, dtype), (fits.sensors.shape[0],) + responses.shape)
    linear = fits.linearise(raw) if linearised else raw
    mask = jnp.ones(responses.shape[0], bool) if mask is None else jnp.asarray(mask, bool)
    return jax.vmap(lambda s, lin: fit_errors(matmul(spectra, s), lin, mask))(fits.sensors, linear)


def random_subsets(n_rows: int, size: int, count: int, seed: int = 0, within=None) -> np.ndarray:
    """``count`` random row subsets of ``size`` rows (without replacement) as ``(count, n_rows)``
    masks; ``within`` restricts the draw to the rows a mask selects.

    Arguments:
        n_rows: rows of the data set.
        size: rows per subset.
        count: number of subsets.
        seed: NumPy seed.
        within: optional ``(n_rows,)`` mask of the rows to draw from.

    Returns:
        ``(count, n_rows)`` boolean masks.
    """
    rows = np.flatnonzero(np.ones(n_rows, bool) if within is None else np.asarray(within, bool))
    if not 0 < size <= rows.size:
        raise ValueError(f"size: expected 1..{rows.size}, got {size}")
    rng = np.random.default_rng(seed)
    masks = np.zeros((count, n_rows), bool)
    for i in range(count):
        masks[i, rng.choice(rows, size, replace=False)] = True
    return masks


@dataclass(frozen=True)
class CrossValidation:
    """Cross-validation of the smoothness: held-out RMS relative error per lambda and fold.

    Attributes:
        smoothness: the lambda grid.
        errors: held-out RMS relative errors, per lambda and fold.
        best: the lambda with the least mean held-out error.
    """

    smoothness: np.ndarray  # (G,)
    errors: np.ndarray  # (G, K)
    best: float

    @property
    def mean(self) -> np.ndarray:
        return self.errors.mean(axis=1)

    def table(self) -> str:
        lines = ["smoothness  held-out RMS relative error (mean over folds)"]
        for lam, err in zip(self.smoothness, self.mean):
            mark = "  <- best" if lam == self.best else ""
            lines.append(f"{lam:10.4g}  {100 * err:7.3f} %{mark}")
        return "\n".join(lines)


DEFAULT_CV_GRID = tuple(float(v) for v in np.geomspace(0.01, 3.0, 11))


def fit_sensors_cv(
    spectra: Float[ArrayLike, "M 101"],
    responses: Float[ArrayLike, "M 3"],
    *,
    smoothness=DEFAULT_CV_GRID,
    folds: int = 5,
    seed: int = 0,
    mask=None,
    name: str = "fitted",
    **options,
) -> tuple[SensorFit, CrossValidation]:
    """Choose lambda by K-fold cross-validation, then fit all data with it (Barnard 1999 §3.4 chose it by hand).

    Each candidate lambda is fitted on K-1 folds and scored by the RMS relative error on the held-out
    fold (responses linearised by that fit's own F for joint fits), mirroring the thesis' use of
    held-out error in Fig. 3.6. All ``len(smoothness) x folds`` fits run as one vmapped batch.

    Arguments:
        spectra: ``(M, 101)`` measured spectra.
        responses: ``(M, 3)`` their camera responses.
        smoothness: candidate lambdas (default: 11 values from 0.01 to 3, geometric).
        folds: K.
        seed: NumPy seed of the fold assignment.
        mask: optional rows to use at all.
        name: the fitted sensors' name.
        **options: as :func:`ccjax.calibration.fit_sensors`.

    Returns:
        ``(fit, cv)``: the fit of all (masked) data with the best lambda, and the
        :class:`CrossValidation` table.
    """
    spectra, responses = check_data(spectra, responses, mask)
    grid = np.asarray(smoothness, dtype=np.float64).ravel()
    if grid.size == 0 or not np.all(np.isfinite(grid)) or np.any(grid < 0):
        raise ValueError("smoothness: expected one or more finite values >= 0")
    usable = np.ones(spectra.shape[0], bool) if mask is None else np.asarray(mask, bool)
    rows = np.flatnonzero(usable)
    if not 2 <= folds <= rows.size:
        raise ValueError(f"folds: expected 2..{rows.size} (the number of usable rows), got {folds}")
    fold_of = np.empty(spectra.shape[0], int)
    fold_of[rows] = np.random.default_rng(seed).permutation(rows.size) % folds
    held_out = np.stack([usable & (fold_of == k) for k in range(folds)])  # (K, M)
    train = usable[None, :] & ~held_out
    lam = np.repeat(grid, folds)
    masks = np.tile(train, (grid.size, 1))
    linearised = options.get("linearisation") is not None
    fits = fit_subsets(spectra, responses, masks, smoothness=lam, **options)
    dtype = fits.sensors.dtype
    raw = jnp.broadcast_to(jnp.asarray(responses, dtype), (lam.size,) + responses.shape)
    linear = fits.linearise(raw) if linearised else raw
    held = jnp.asarray(np.tile(held_out, (grid.size, 1)))
    errors = jax.vmap(lambda s, lin, m: fit_errors(matmul(jnp.asarray(spectra, dtype), s), lin, m).rms_relative)(
        fits.sensors, linear, held
    )
    errors = np.asarray(errors).reshape(grid.size, folds)
    best = float(grid[int(np.argmin(errors.mean(axis=1)))])
    fit = fit_sensors(spectra, responses, smoothness=best, mask=mask, name=name, **options)
    return fit, CrossValidation(smoothness=grid, errors=errors, best=best)
