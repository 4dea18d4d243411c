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

The relative joint fit (eq. 3.16 with the weights of 3.12) weights rows by the linearised
response, first estimated as ``r - b`` and then, in a second pass, as F(r) from the first pass.
Channels are independent (``vmap`` over channels). The kernel is in ``_kernel``, the option checks
in ``_plan``, F in :mod:`~ccjax.calibration.linearisation`, the error measures in
:mod:`~ccjax.calibration.errors` (the public names of all four: :mod:`ccjax.calibration`).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ccjax.calibration._kernel import ChannelFit, fit_data_set
from ccjax.calibration._plan import (
    DEFAULT_SMOOTHNESS,
    ErrorKind,
    FitPlan,
    LinearisationKind,
    check_data,
    data_arrays,
    plan_fit,
)
from ccjax.calibration.errors import FitErrors, fit_errors
from ccjax.calibration.linearisation import Linearisation
from ccjax.camera import Camera
from ccjax.precision import matmul


class FitStatus(eqx.Module):
    """How the solver did, per channel.

    Attributes:
        solver: the solver's name.
        converged: ``(3,)`` whether each channel's solve converged.
        kkt_residual: ``(3,)`` the optimality (KKT) residual per channel.
        iterations: ``(3,)`` iterations per channel.
    """

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

    def fitted_linearisation(self) -> Linearisation:
        """The fitted F; only fits with ``linearisation="offset"`` or ``"exp"`` have one.

        Returns:
            The fitted :class:`Linearisation`.
        """
        if self.linearisation is None:
            raise ValueError(f"{self.camera.name}: fitted to linear data, there is no linearisation")
        return self.linearisation

    def evaluate(self, spectra, raw, mask=None) -> FitErrors:
        """Table 3.1 errors of this model on other measurements (raw responses are linearised by F).

        Arguments:
            spectra: ``(M, 101)`` measured spectra.
            raw: ``(M, 3)`` their raw camera responses.
            mask: ``(M,)`` the rows to score (``None``: all).

        Returns:
            The :class:`FitErrors`.
        """
        spectra, raw = check_data(spectra, raw)
        linear = self.linearisation(raw) if self.linearisation is not None else jnp.asarray(raw)
        return fit_errors(matmul(jnp.asarray(spectra), self.sensors.astype(jnp.asarray(spectra).dtype)), linear, mask)


def fit_sensors(
    spectra: Float[ArrayLike, "M 101"],
    responses: Float[ArrayLike, "M 3"],
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
    plan = plan_fit(
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
    data = data_arrays(spectra, responses, mask, plan)
    fits, rates = fit_data_set(*data, plan.options, plan.solver, plan.search)
    return _assemble(fits, rates, data, plan, float(smoothness), name)


SOLVER_NAMES = {
    "box": "jaxopt.ProjectedGradient + active-set polish",
    "osqp": "jaxopt.BoxOSQP",
    "lstsq": "SVD pseudo-inverse",
}


def _assemble(fits: ChannelFit, rates, data, plan: FitPlan, smoothness: float, name: str) -> SensorFit:
    spectra, _, mask = data
    sensors = fits.sensor.T  # (101, 3)
    linear = fits.linear.T  # (M, 3)
    predicted = matmul(spectra, sensors)
    if plan.kind is None:
        lin = None
    else:
        lin = Linearisation.per_channel(
            a0=np.asarray(fits.a0),
            a1=np.asarray(fits.a1),
            exp_rate=np.asarray(rates) if plan.kind == "exp" else 0.0,
            black=np.asarray(plan.options.black),
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

    Arguments:
        spectra: ``(M, 101)`` measured spectra.
        responses: ``(M, 3)`` linear responses.
        positive: constrain the curves to be non-negative.
        mask: optional ``(M,)`` selection of measurements (True = use).
        name: the fit's label.

    Returns:
        The :class:`SensorFit`.
    """
    return fit_sensors(spectra, responses, smoothness=0.0, error="absolute", positive=positive, mask=mask, name=name)
