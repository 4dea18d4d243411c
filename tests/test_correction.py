"""Correction to the canonical light (ccjax.correction, Barnard 1999 §2.5)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from ccjax import correction


def test_diagonal_and_sharpened_correction():
    rng = np.random.default_rng(5)
    light, canonical = np.array([0.9, 0.6, 0.3], np.float32), np.array([0.7, 1.0, 0.8], np.float32)
    corrected = np.asarray(correction.correct(light, light, canonical))
    np.testing.assert_allclose(corrected / corrected.sum(), canonical / canonical.sum(), rtol=1e-5)
    assert corrected.sum() == pytest.approx(light.sum(), rel=1e-5)  # grey keeps its R+G+B
    transform = np.eye(3, dtype=np.float32) + 0.2 * rng.standard_normal((3, 3)).astype(np.float32)
    sharpened = np.asarray(correction.correct(light, light, canonical, transform))
    ratio = (transform @ sharpened) / (transform @ canonical)
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-4)  # T e maps to the direction of T w_C
    pixels = rng.random((4, 5, 3)).astype(np.float32)
    matrix = np.asarray(correction.correction_map(jnp.asarray(light), jnp.asarray(canonical)))
    np.testing.assert_allclose(np.asarray(correction.correct(pixels, light, canonical)), pixels @ matrix.T, rtol=1e-5)


def test_gains_are_the_diagonal_of_the_map():
    light, canonical = jnp.array([0.2, 0.5, 0.9]), jnp.array([1.0, 0.9, 0.7])
    np.testing.assert_allclose(
        np.diag(np.asarray(correction.correction_map(light, canonical))),
        np.asarray(correction.diagonal_gains(light, canonical)),
        rtol=1e-6,
    )
    np.testing.assert_allclose(
        np.asarray(correction.apply_map(jnp.ones((2, 3)), jnp.diag(jnp.array([1.0, 2.0, 3.0])))), [[1, 2, 3]] * 2
    )
