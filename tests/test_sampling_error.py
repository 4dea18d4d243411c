"""The sampling error of ``ccjax reproduce``'s cells and the status shares of ``ccjax compare``."""

import numpy as np
import pytest
import scipy.stats

from ccjax.estimators.base import Status
from ccjax.experiments.sweep_results import SweepResult, sampling_error


def test_mean_standard_error_is_scipy_sem():
    errors = np.random.default_rng(0).gamma(2.0, 1.5, size=500)
    assert sampling_error(errors, "mean") == pytest.approx(scipy.stats.sem(errors), rel=1e-12)


def test_rms_standard_error_matches_a_bootstrap():
    # Oracle: the standard deviation of the RMS over 4000 bootstrap resamples (NumPy).
    rng = np.random.default_rng(1)
    errors = rng.rayleigh(0.03, size=1000)
    resamples = rng.choice(errors, size=(4000, errors.size), replace=True)
    bootstrap = np.std(np.sqrt(np.mean(resamples**2, axis=1)), ddof=1)
    assert sampling_error(errors, "rms") == pytest.approx(bootstrap, rel=0.08)


def test_rms_interval_covers_the_true_rms():
    # Rayleigh(sigma) errors have E[e^2] = 2 sigma^2, so the true RMS is sqrt(2) sigma.
    rng = np.random.default_rng(2)
    sigma = 0.02
    true_rms = np.sqrt(2.0) * sigma
    covered = 0
    for _ in range(200):
        errors = rng.rayleigh(sigma, size=1000)
        rms = np.sqrt(np.mean(errors**2))
        covered += abs(rms - true_rms) <= 1.96 * sampling_error(errors, "rms")
    assert covered >= 186  # >= 93 % of the nominal 95 %


def test_zero_errors_and_bad_input():
    assert sampling_error(np.zeros(10)) == 0.0
    with pytest.raises(ValueError, match="at least 2"):
        sampling_error(np.ones(1))
    with pytest.raises(ValueError, match="NaN"):
        sampling_error(np.array([1.0, np.nan]))
    with pytest.raises(ValueError, match="summary"):
        sampling_error(np.ones(5), "median")


def _result(statuses):
    status = np.asarray(statuses, np.int32)
    n = status.size
    per_scene = {"rg": np.linspace(0.01, 0.02, n), "ok": status == Status.ESTIMATED, "status": status}
    return SweepResult(methods=["M"], surfaces=[8], n_scenes=n, errors={"M": {8: per_scene}})


def test_status_shares_per_surface_count():
    codes = [Status.ESTIMATED] * 6 + [Status.RELAXED] * 2 + [Status.NO_DATA, Status.EMPTY_SET]
    result = _result(codes)
    assert result.status_fraction("M", 8, "relaxed") == pytest.approx(0.2)
    assert result.status_fraction("M", 8, "fell_back") == pytest.approx(0.2)
    assert result.ok_fraction("M", 8) == pytest.approx(0.6)
    (row,) = result.rows()
    assert (row["relaxed_fraction"], row["fell_back_fraction"]) == (pytest.approx(0.2), pytest.approx(0.2))
    table = result.status_table()
    assert "20.0% / 20.0%" in table.splitlines()[-1]
    with pytest.raises(ValueError, match="status"):
        result.status_fraction("M", 8, "other")
