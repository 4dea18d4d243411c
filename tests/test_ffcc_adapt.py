"""FFCC's light prior adapted without labels (:func:`ccjax.estimators.ffcc.adapt_bias`) against
NumPy: the light density as a periodic Gaussian, the identity when nothing moves, the physics
prior's closed form, and EM's fixed point (Saerens et al. 2002)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from ccjax.estimators import ffcc

N, SIZE, ORIGIN = 16, 0.0625, -0.5


def _model(seed: int = 0) -> ffcc.FFCC:
    rng = np.random.default_rng(seed)
    return ffcc.FFCC(
        filters=jnp.asarray(rng.normal(size=(2, N, N)), jnp.float32),
        bias=jnp.asarray(rng.normal(size=(N, N)), jnp.float32),
        origin=jnp.full((2,), ORIGIN, jnp.float32),
        bin_size=jnp.asarray(SIZE, jnp.float32),
    )


def _torus_gaussian(centre: tuple[int, int], sigma_bins: float) -> np.ndarray:
    """A Gaussian wrapped on the n x n torus, summed over the nearest images (NumPy oracle)."""
    index = np.arange(N)
    total = np.zeros((N, N))
    for wrap_i in (-N, 0, N):
        for wrap_j in (-N, 0, N):
            di = index[:, None] - centre[0] + wrap_i
            dj = index[None, :] - centre[1] + wrap_j
            total += np.exp(-(di**2 + dj**2) / (2 * sigma_bins**2))
    return total / total.sum()


def test_a_light_on_a_bin_centre_is_a_wrapped_gaussian():
    options = ffcc.AdaptOptions(smoothing=1.5 * SIZE, floor=0.0)
    # A light on bin (3, 14)'s centre: the density wraps across the torus's edge.
    uv = np.array([[ORIGIN + 3 * SIZE, ORIGIN + 14 * SIZE]])
    density = np.asarray(ffcc.light_density(_model(), uv, options), np.float64)
    np.testing.assert_allclose(density, _torus_gaussian((3, 14), 1.5), atol=2e-6)
    floored = np.asarray(ffcc.light_density(_model(), uv, ffcc.AdaptOptions(smoothing=1.5 * SIZE, floor=0.1)))
    np.testing.assert_allclose(floored, 0.9 * _torus_gaussian((3, 14), 1.5) + 0.1 / N**2, atol=2e-6)


def test_without_rounds_or_physics_the_model_is_unchanged_and_physics_alone_is_its_log_ratio():
    model = _model()
    rng = np.random.default_rng(1)
    histograms = rng.random((5, 2, N, N)).astype(np.float32)
    train_uv = ORIGIN + SIZE * rng.uniform(4, 12, (30, 2))
    loci_uv = ORIGIN + SIZE * rng.uniform(5, 9, (10, 2))
    same, _ = ffcc.adapt_bias(model, histograms, train_uv, loci_uv, ffcc.AdaptOptions(rounds=0, physics=0.0))
    np.testing.assert_array_equal(np.asarray(same.bias), np.asarray(model.bias))
    options = ffcc.AdaptOptions(rounds=0, physics=1.0)
    moved, q = ffcc.adapt_bias(model, histograms, train_uv, loci_uv, options)
    ratio = np.log(np.asarray(ffcc.light_density(model, loci_uv, options), np.float64))
    ratio -= np.log(np.asarray(ffcc.light_density(model, train_uv, options), np.float64))
    np.testing.assert_allclose(np.asarray(moved.bias), np.asarray(model.bias) + ratio - ratio.mean(), atol=1e-4)
    np.testing.assert_allclose(np.asarray(q), np.asarray(ffcc.light_density(model, loci_uv, options)), rtol=1e-6)
    np.testing.assert_array_equal(np.asarray(moved.filters), np.asarray(model.filters))


def test_em_moves_the_prior_toward_the_unlabelled_images_lights():
    """Images whose posteriors all peak at one bin: EM's prior gains mass there round after round."""
    model = ffcc.FFCC(
        filters=jnp.zeros((2, N, N), jnp.float32),
        bias=jnp.zeros((N, N), jnp.float32),
        origin=jnp.full((2,), ORIGIN, jnp.float32),
        bin_size=jnp.asarray(SIZE, jnp.float32),
    )
    # Identity-like filters: a delta at bin (0, 0) makes the scores the histogram itself (x 8).
    model = ffcc.FFCC(
        filters=jnp.zeros((2, N, N), jnp.float32).at[0, 0, 0].set(8.0),
        bias=model.bias,
        origin=model.origin,
        bin_size=model.bin_size,
    )
    histograms = np.zeros((4, 2, N, N), np.float32)
    histograms[:, 0, 10, 5] = 1.0
    train_uv = ORIGIN + SIZE * np.array([[6.0, 6.0], [7.0, 8.0], [8.0, 7.0]])
    masses = []
    for rounds in (0, 1, 3):
        options = ffcc.AdaptOptions(rounds=rounds, physics=0.0)
        _, q = ffcc.adapt_bias(model, histograms, train_uv, train_uv, options)
        masses.append(float(np.asarray(q)[10, 5]))
    assert masses[0] < masses[1] < masses[2]


def test_bad_options_are_refused_by_name():
    with pytest.raises(ValueError, match="physics"):
        ffcc.AdaptOptions(physics=1.5)
    with pytest.raises(ValueError, match="rounds"):
        ffcc.AdaptOptions(rounds=-1)
    with pytest.raises(ValueError, match="histograms"):
        ffcc.adapt_bias(_model(), np.zeros((0, 2, N, N)), np.zeros((1, 2)), np.zeros((1, 2)))
