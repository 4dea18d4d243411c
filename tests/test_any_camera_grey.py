"""Shades of grey's observation in the any-camera estimator: checked against NumPy's shades of grey
(Finlayson & Trezzi 2004), NumPy's sample mean and covariance, and the closed-form product of two
Gaussians (Bishop 2006, §2.3.3)."""

from __future__ import annotations

import json

import jax.numpy as jnp
import numpy as np
import pytest

from ccjax.estimators import conditioned, ffcc


def numpy_grey_log_chroma(image: np.ndarray, mask: np.ndarray, p: int = 6) -> np.ndarray:
    """``(log(G/R), log(G/B))`` of ``mean(rho^p)^(1/p)`` over the masked pixels."""
    pixels = image[mask].astype(np.float64)
    grey = np.mean(pixels**p, axis=0) ** (1.0 / p)
    return np.array([np.log(grey[1] / grey[0]), np.log(grey[1] / grey[2])])


def images(seed: int, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    lights = rng.uniform(0.3, 1.0, (count, 3))
    surfaces = rng.uniform(0.02, 1.0, (count, 10, 10, 3))
    masks = rng.uniform(size=(count, 10, 10)) > 0.2
    return (surfaces * lights[:, None, None]).astype(np.float32), masks, lights.astype(np.float32)


def test_the_observation_is_shades_of_grey_less_its_bias_and_combines_as_a_product_of_gaussians():
    image, mask, _ = images(0, 1)
    bias = np.array([0.03, -0.05])
    precision = np.array([[40.0, 5.0], [5.0, 30.0]])
    observation = conditioned.GreyObservation(
        bias=jnp.asarray(bias, jnp.float32), precision=jnp.asarray(precision, jnp.float32), posterior_scale=0.5
    )
    observed, ok = observation.observe(jnp.asarray(image[0]), jnp.asarray(mask[0]))
    expected = numpy_grey_log_chroma(image[0], mask[0]) - bias
    assert bool(ok)
    np.testing.assert_allclose(np.asarray(observed), expected, atol=2e-5)

    mean = np.array([0.2, -0.1])
    covariance = np.array([[0.004, 0.001], [0.001, 0.002]])
    combined = observation.combine(
        jnp.asarray(mean, jnp.float32), jnp.asarray(covariance, jnp.float32), jnp.asarray(expected, jnp.float32), ok
    )
    widened = np.linalg.inv(0.5 * covariance)
    oracle = np.linalg.solve(widened + precision, widened @ mean + precision @ expected)
    np.testing.assert_allclose(np.asarray(combined), oracle, atol=1e-5)
    # Between the two answers, on the segment's side of each (a product of Gaussians).
    assert np.linalg.norm(oracle - mean) < np.linalg.norm(expected - mean)

    # Without an observation (or with one left out) the answer is FFCC's mean.
    alone = conditioned.no_grey_observation().combine(
        jnp.asarray(mean, jnp.float32), jnp.asarray(covariance, jnp.float32), jnp.asarray(expected, jnp.float32), ok
    )
    np.testing.assert_allclose(np.asarray(alone), mean, rtol=1e-6)
    dropped = observation.combine(
        jnp.asarray(mean, jnp.float32), jnp.asarray(covariance, jnp.float32), jnp.asarray(expected), jnp.asarray(False)
    )
    np.testing.assert_allclose(np.asarray(dropped), mean, rtol=1e-6)


def test_an_image_without_usable_pixels_is_left_out_and_stays_finite():
    observation = conditioned.GreyObservation(bias=jnp.zeros(2), precision=jnp.eye(2) * 50.0)
    observed, ok = observation.observe(jnp.zeros((4, 4, 3)), jnp.zeros((4, 4), bool))
    assert not bool(ok)
    assert np.all(np.isfinite(np.asarray(observed)))


def test_the_fitted_bias_and_precision_are_the_training_residuals_mean_and_inverse_covariance():
    image, mask, lights = images(1, 40)
    fitted = conditioned.fit_grey_observation(image, mask, lights, posterior_scale=0.75)
    truth = np.stack([np.log(lights[:, 1] / lights[:, 0]), np.log(lights[:, 1] / lights[:, 2])], axis=1)
    residual = np.stack([numpy_grey_log_chroma(i, m) for i, m in zip(image, mask, strict=True)]) - truth
    np.testing.assert_allclose(np.asarray(fitted.bias), residual.mean(axis=0), atol=1e-5)
    np.testing.assert_allclose(np.asarray(fitted.precision), np.linalg.inv(np.cov(residual.T)), rtol=1e-3)
    assert fitted.posterior_scale == 0.75


@pytest.mark.slow
def test_a_model_without_the_observation_answers_as_its_ffcc_alone():
    core = ffcc.init_ffcc(16)
    rng = np.random.default_rng(2)
    bias = rng.normal(size=(16, 16)).astype(np.float32)
    core = ffcc.FFCC(filters=core.filters, bias=jnp.asarray(bias), origin=core.origin, bin_size=core.bin_size)
    image, mask, _ = images(3, 1)
    plain = conditioned.AnyCamera(core=core, grey=conditioned.no_grey_observation(), matrix=jnp.eye(3))
    estimate = plain(jnp.asarray(image[0]), jnp.asarray(mask[0]))
    posterior = core.posterior(jnp.asarray(image[0]), jnp.asarray(mask[0]))
    np.testing.assert_allclose(np.asarray(estimate.illuminant), np.asarray(ffcc.uv_to_rgb(posterior.mean)), rtol=1e-5)
    # With an observation the answer moves towards shades of grey's.
    grey = conditioned.GreyObservation(bias=jnp.zeros(2), precision=jnp.eye(2) * 1e6)
    pulled = conditioned.AnyCamera(core=core, grey=grey, matrix=jnp.eye(3))(jnp.asarray(image[0]), jnp.asarray(mask[0]))
    target = numpy_grey_log_chroma(image[0], mask[0])
    rgb = np.array([np.exp(-target[0]), 1.0, np.exp(-target[1])])
    np.testing.assert_allclose(np.asarray(pulled.illuminant), rgb / rgb.sum(), atol=1e-4)


def test_a_model_file_without_the_observation_is_refused_in_one_sentence(tmp_path):
    import equinox as eqx
    import pytest

    from ccjax.runs import store

    # A file and record as any-camera writes them, then the leaves it held before the observation
    # (its FFCC and its map, no more) written over the file.
    path = tmp_path / "old.eqx"
    model = conditioned.init_any_camera()
    store.save_trained(path, model, label="any-camera", camera=None, record={"conditioned": True})
    eqx.tree_serialise_leaves(path, {"core": model.core, "matrix": model.matrix})
    # Such a file's record names no digest of its model file (written before records held one).
    record = json.loads(path.with_suffix(".json").read_text())
    del record["weights_sha256"]
    path.with_suffix(".json").write_text(json.dumps(record))
    with pytest.raises(ValueError, match=r"old\.eqx does not fit a AnyCamera .*must be trained again"):
        store.load_model(path, camera="Canon EOS 600D")
