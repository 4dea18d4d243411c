"""The field's statistics of per-image errors: the 95th percentile and bootstrap
confidence intervals of mean and median, against NumPy/SciPy and by their coverage."""

from __future__ import annotations

import numpy as np
import pytest
import reference
from scipy import stats

from ccjax import metrics


@pytest.fixture(scope="module")
def errors():
    return np.random.default_rng(0).gamma(2.0, 1.5, 200)  # skewed, like angular errors


def test_percentile_and_field_statistics(errors):
    assert metrics.summarise(errors, "p95") == pytest.approx(np.percentile(errors, 95), rel=1e-12)
    row = metrics.error_statistics(errors)
    assert set(row) == {*metrics.FIELD_STATISTICS, "mean_low", "mean_high", "median_low", "median_high"}
    ordered = np.sort(errors)
    assert row["best25"] == pytest.approx(ordered[:50].mean()) and row["worst25"] == pytest.approx(ordered[-50:].mean())
    assert row["mean_low"] < row["mean"] < row["mean_high"] and row["median_low"] < row["median"] < row["median_high"]


@pytest.mark.parametrize("statistic", ["mean", "median"])
def test_interval_matches_scipy_bca(errors, statistic):
    """Oracle: scipy.stats.bootstrap's BCa interval (other resamples: agreement to Monte Carlo error)."""
    function = {"mean": np.mean, "median": np.median}[statistic]
    want = stats.bootstrap((errors,), function, method="BCa", n_resamples=20000, random_state=1).confidence_interval
    low, high = metrics.bootstrap_interval(errors, statistic, resamples=20000)
    width = want.high - want.low
    assert abs(low - want.low) < 0.05 * width and abs(high - want.high) < 0.05 * width


@pytest.mark.parametrize("statistic", ["mean", "median"])
@pytest.mark.parametrize("size", [30, 200])
def test_interval_agrees_with_the_bca_written_out(errors, statistic, size):
    """Oracle: BCa written out in NumPy (tests/reference.py, the formulas ccjax computed before it
    called SciPy); different resampling streams, so agreement to Monte Carlo error."""
    sample = errors[:size]
    want_low, want_high = reference.bca_interval(sample, statistic, resamples=20000, seed=3)
    low, high = metrics.bootstrap_interval(sample, statistic, resamples=20000)
    width = want_high - want_low
    assert abs(low - want_low) < 0.06 * width and abs(high - want_high) < 0.06 * width


def test_intervals_cover_the_true_mean_and_median():
    """95 % intervals cover the true mean in at least 93 of 100 simulated
    sets (gamma-distributed errors, 200 images; the true median from SciPy's quantile)."""
    shape, scale = 2.0, 1.5
    true_mean, true_median = shape * scale, stats.gamma.ppf(0.5, shape, scale=scale)
    rng = np.random.default_rng(0)
    sets = [rng.gamma(shape, scale, 200) for _ in range(100)]

    def covered(statistic, truth):
        intervals = (metrics.bootstrap_interval(x, statistic, seed=i) for i, x in enumerate(sets))
        return sum(low <= truth <= high for low, high in intervals)

    covered_mean, covered_median = covered("mean", true_mean), covered("median", true_median)
    assert covered_mean >= 93, covered_mean
    assert covered_median >= 90, covered_median


def test_intervals_are_seeded_and_degenerate_sets_are_finite(errors):
    assert metrics.bootstrap_interval(errors, seed=4) == metrics.bootstrap_interval(errors, seed=4)
    assert metrics.bootstrap_interval(errors, seed=4) != metrics.bootstrap_interval(errors, seed=5)
    assert metrics.bootstrap_interval([2.5], "median") == (2.5, 2.5)
    assert metrics.bootstrap_interval(np.full(10, 1.0)) == (1.0, 1.0)
    low, high = metrics.bootstrap_interval([1.0, 2.0])
    assert 1.0 <= low <= high <= 2.0
    for bad, message in (([], "empty"), ([1.0, np.nan], "NaN")):
        with pytest.raises(ValueError, match=message):
            metrics.bootstrap_interval(bad)
    with pytest.raises(ValueError, match="summary"):
        metrics.bootstrap_interval(errors, "trimean")
    with pytest.raises(ValueError, match="level"):
        metrics.bootstrap_interval(errors, level=1.5)
    with pytest.raises(ValueError, match="resamples"):
        metrics.bootstrap_interval(errors, resamples=10)
