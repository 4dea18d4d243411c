"""Metrics against the plain NumPy reference and closed forms."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import reference

from ccjax import metrics


@pytest.fixture
def pairs():
    rng = np.random.default_rng(1)
    return rng.uniform(0.01, 1.0, (200, 3)), rng.uniform(0.01, 1.0, (200, 3))


def test_angular_rg_rgb_brightness_match_reference(pairs):
    a, b = pairs
    ang = np.asarray(metrics.angular_error(jnp.asarray(a), jnp.asarray(b)))
    rge = np.asarray(metrics.rg_error(jnp.asarray(a), jnp.asarray(b)))
    rgbe = np.asarray(metrics.rgb_error(jnp.asarray(a), jnp.asarray(b)))
    bright = np.asarray(metrics.brightness_error(jnp.asarray(a), jnp.asarray(b)))
    for i in range(len(a)):
        assert ang[i] == pytest.approx(reference.angular_error(a[i], b[i]), abs=2e-3)
        assert rge[i] == pytest.approx(reference.rg_error(a[i], b[i]), abs=1e-6)
        assert rgbe[i] == pytest.approx(math.dist(a[i], b[i]), rel=1e-5)
        assert bright[i] == pytest.approx(a[i].sum() - b[i].sum(), abs=1e-5)


def test_closed_forms():
    assert float(metrics.angular_error(jnp.array([1.0, 0, 0]), jnp.array([0, 1.0, 0]))) == pytest.approx(90.0)
    assert float(metrics.angular_error(jnp.array([1.0, 1, 0]), jnp.array([1.0, 0, 0]))) == pytest.approx(45.0)
    assert float(metrics.angular_error(jnp.array([2.0, 2, 2]), jnp.array([1.0, 1, 1]))) == pytest.approx(0.0, abs=1e-5)
    np.testing.assert_allclose(metrics.rg(jnp.array([1.0, 2.0, 1.0])), [0.25, 0.5])
    np.testing.assert_allclose(metrics.rg(jnp.zeros(3)), [1 / 3, 1 / 3])
    np.testing.assert_allclose(metrics.rg_to_rgb(jnp.array([0.2, 0.3])), [0.2, 0.3, 0.5])


def test_angular_error_gradient_is_finite_at_zero_error():
    grad = jax.grad(lambda e: metrics.angular_error(e, jnp.array([0.3, 0.5, 0.2])))(jnp.array([0.3, 0.5, 0.2]))
    assert np.all(np.isfinite(grad))
    grad_rg = jax.grad(lambda e: metrics.rg_error(e, jnp.array([0.3, 0.5, 0.2])))(jnp.array([0.3, 0.5, 0.2]))
    assert np.all(np.isfinite(grad_rg))


@pytest.mark.parametrize("scale", [1e-30, 1e-19, 1e19, 1e30])
def test_angular_error_is_scale_free(pairs, scale):
    # The reference in float64 at unit scale; float32 squares of 1e-30 or 1e30 components under-
    # or overflow, so the scaled pairs must be measured on their direction alone.
    a, b = pairs
    want = np.array([reference.angular_error(x, y) for x, y in zip(a[:20], b[:20], strict=True)])
    for scaled_a, scaled_b in ((a[:20] * scale, b[:20]), (a[:20], b[:20] * scale), (a[:20] * scale, b[:20] * scale)):
        got = np.asarray(metrics.angular_error(jnp.asarray(scaled_a, jnp.float32), jnp.asarray(scaled_b, jnp.float32)))
        np.testing.assert_allclose(got, want, atol=2e-3)


def test_angular_error_of_a_large_white_against_red_is_the_closed_form():
    # (1,1,1) against (1,0,0): arccos(1/sqrt(3)) = 54.7356 degrees at any scale.
    want = math.degrees(math.acos(1 / math.sqrt(3)))
    for scale in (1e-30, 1.0, 1e20, 1e30):
        got = float(metrics.angular_error(jnp.array([1.0, 1.0, 1.0]) * scale, jnp.array([1.0, 0.0, 0.0])))
        assert got == pytest.approx(want, abs=1e-4)


def test_angular_error_of_a_zero_vector_is_90_against_non_zero_and_0_against_zero():
    ones, zeros = jnp.ones(3), jnp.zeros(3)
    assert float(metrics.angular_error(zeros, ones)) == 90.0
    assert float(metrics.angular_error(ones, zeros)) == 90.0
    assert float(metrics.angular_error(zeros, zeros)) == 0.0
    batch = metrics.angular_error(jnp.stack([zeros, ones, ones * 1e-30]), jnp.stack([ones * 1e30, zeros, ones]))
    np.testing.assert_array_equal(np.asarray(batch), [90.0, 90.0, 0.0])
    grad = jax.grad(lambda e: metrics.angular_error(e, ones))(zeros)
    assert np.all(np.isfinite(grad))


def test_mapping_errors_match_reference():
    rng = np.random.default_rng(2)
    for _ in range(20):
        rgb = rng.uniform(0.0, 1.0, (9, 3))
        canon = rng.uniform(0.05, 1.0, (9, 3))
        mask = rng.uniform(size=9) < 0.7
        mask[0] = True
        est = rng.uniform(0.2, 1.0, 3)
        white = rng.uniform(0.5, 1.0, 3)
        ours = metrics.mapping_errors(
            jnp.asarray(est), jnp.asarray(rgb), jnp.asarray(mask), jnp.asarray(canon), jnp.asarray(white)
        )
        want = reference.mapping_errors(est, rgb, mask, canon, white)
        assert float(ours[0]) == pytest.approx(want[0], rel=1e-4)
        assert float(ours[1]) == pytest.approx(want[1], rel=1e-4)


def test_mapping_error_is_zero_for_the_exact_diagonal_map():
    rgb = jnp.array([[0.2, 0.4, 0.6], [0.5, 0.1, 0.3]])
    white = jnp.array([0.9, 0.8, 1.0])
    truth = jnp.array([0.5, 0.7, 1.0])
    canon = rgb * white / truth
    rg_rms, rgb_rms = metrics.mapping_errors(truth, rgb, jnp.array([True, True]), canon, white)
    assert float(rg_rms) == pytest.approx(0.0, abs=1e-6) and float(rgb_rms) == pytest.approx(0.0, abs=1e-6)


def test_reproduction_error_zero_for_scaled_truth():
    assert float(
        metrics.reproduction_angular_error(jnp.array([0.4, 0.8, 0.6]), jnp.array([0.2, 0.4, 0.3]))
    ) == pytest.approx(0.0, abs=1e-4)


def test_summaries():
    errors = np.array([4.0, 1.0, 3.0, 2.0, 10.0, 6.0, 5.0, 7.0])
    assert metrics.summarise(errors, "rms") == pytest.approx(math.sqrt(np.mean(errors**2)))
    assert metrics.summarise(errors, "mean") == pytest.approx(4.75)
    assert metrics.summarise(errors, "median") == pytest.approx(4.5)
    assert metrics.summarise(errors, "trimean") == pytest.approx(reference.trimean(errors))
    assert metrics.summarise(errors, "best25") == pytest.approx(1.5)
    assert metrics.summarise(errors, "worst25") == pytest.approx(8.5)
    assert metrics.summarise(errors, "max") == 10.0
    with pytest.raises(ValueError, match="summary"):
        metrics.summarise(errors, "mode")
    with pytest.raises(ValueError, match="errors"):
        metrics.summarise([np.nan], "rms")
