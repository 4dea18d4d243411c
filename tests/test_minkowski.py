"""The one Minkowski mean of shades of grey and grey edge: shades of grey's norm is a learnable array
leaf as grey edge's, and its value and its derivative in ``p`` match NumPy's closed forms on every
branch of the power (whole ``p`` by multiplication, other ``p`` by ``exp(p log x)``)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ccjax.estimators.minkowski import unit_power
from ccjax.estimators.simple import ShadesOfGrey
from ccjax.training import constrain, learnable, learnable_types

RGB = np.random.default_rng(5).uniform(0.05, 1.0, (32, 3))


def _oracle(p: float) -> tuple[np.ndarray, np.ndarray]:
    """``w = 2 (mean x^p)^(1/p)`` per channel and ``dw/dp``, in float64 (the closed form:
    ``dw/dp = w (mean(x^p log x) / (p mean x^p) - log(mean x^p) / p^2)``)."""
    m = np.mean(RGB**p, axis=0)
    w = 2.0 * m ** (1.0 / p)
    return w, w * (np.mean(RGB**p * np.log(RGB), axis=0) / (p * m) - np.log(m) / p**2)


@pytest.mark.parametrize("p", [1.0, 2.5, 6.0, 9.0])
def test_shades_of_grey_and_its_derivative_in_p_match_the_closed_form(p):
    model = ShadesOfGrey(p=jnp.asarray(p), fallback=jnp.ones(3))
    rgb, mask = jnp.asarray(RGB, jnp.float32), jnp.ones(len(RGB), bool)
    value = model(rgb, mask).illuminant
    derivative = jax.jacfwd(lambda q: eqx.tree_at(lambda m: m.p, model, q)(rgb, mask).illuminant)(jnp.asarray(p))
    w, dw = _oracle(p)
    np.testing.assert_allclose(np.asarray(value), w, rtol=2e-5)
    np.testing.assert_allclose(np.asarray(derivative), dw, rtol=2e-3, atol=1e-6)


def test_the_whole_number_branches_equal_the_power():
    x = jnp.asarray(RGB.ravel(), jnp.float32)
    for p in [1.0, 2.0, 3.0, 6.0, 8.0, 8.5, 9.0]:
        np.testing.assert_allclose(np.asarray(unit_power(x, jnp.asarray(p))), RGB.ravel() ** p, rtol=2e-6)


def test_shades_of_grey_learns_its_norm_as_grey_edge_does():
    assert "ShadesOfGrey" in learnable_types()
    model = ShadesOfGrey(p=jnp.asarray(6.0), fallback=jnp.ones(3))
    spec = learnable(model)
    assert spec.p is True and spec.fallback is False
    below = eqx.tree_at(lambda m: m.p, model, jnp.asarray(0.25))
    assert float(constrain(below).p) == 1.0  # the norm stays a norm
    with pytest.raises(ValueError, match=r"p: expected a Minkowski norm >= 1"):
        ShadesOfGrey(p=jnp.asarray(0.5), fallback=jnp.ones(3))
