"""The deprecated aliases of "one name per idea": each warns, naming its replacement, and returns
the same numbers as that replacement (and as an independent NumPy oracle)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ccjax
from ccjax import estimators, losses, metrics


def _numpy_angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles in degrees by the textbook formula, in float64."""
    cosine = np.sum(a * b, axis=-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def test_angular_errors_warns_and_matches_the_metric():
    key_a, key_b = jax.random.split(jax.random.key(3))
    estimate = jax.random.uniform(key_a, (16, 3), minval=0.05, maxval=1.0)
    truth = jax.random.uniform(key_b, (16, 3), minval=0.05, maxval=1.0)
    with pytest.warns(DeprecationWarning, match=r"ccjax\.metrics\.angular_error"):
        old = losses.angular_errors(estimate, truth)
    new = metrics.angular_error(estimate, truth)
    np.testing.assert_array_equal(np.asarray(old), np.asarray(new))
    oracle = _numpy_angles(np.asarray(estimate, np.float64), np.asarray(truth, np.float64))
    np.testing.assert_allclose(np.asarray(new), oracle, atol=2e-3)
    # The loss is still the mean of the per-item angles, with no warning on the way.
    np.testing.assert_allclose(float(losses.angular_loss(estimate, truth)), oracle.mean(), atol=2e-3)


def test_estimators_fit_warns_and_matches_fit_uncached(small_test_world):
    with pytest.warns(DeprecationWarning, match=r"ccjax\.estimators\.fit_uncached"):
        old = estimators.fit("GW", small_test_world)
    new = estimators.fit_uncached("GW", small_test_world)
    assert type(old) is type(new)
    rgb = jnp.asarray([[0.2, 0.4, 0.1], [0.6, 0.3, 0.2], [0.1, 0.1, 0.5]])
    mask = jnp.ones(3, bool)
    # Grey world's answer points along the mean of the surfaces (its closed form, up to scale).
    answer = np.asarray(new(rgb, mask).illuminant, np.float64)
    assert _numpy_angles(answer, np.asarray(rgb, np.float64).mean(axis=0)) < 1e-3
    np.testing.assert_array_equal(np.asarray(old(rgb, mask).illuminant), np.asarray(new(rgb, mask).illuminant))


def test_the_cached_fit_keeps_its_name():
    assert "fit" in ccjax.__all__
    assert "fit" not in estimators.__all__ and "fit_uncached" in estimators.__all__
