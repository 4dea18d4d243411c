"""ccjax.losses: values against the NumPy reference (tests/reference.py), gradients against finite
differences (check_grads, x64) at generic points and at zero error, and finite gradients at the
degenerate points (zero vectors, masked pixels holding NaN)."""

import jax
import jax.numpy as jnp
import jaxtyping
import numpy as np
import pytest
import reference
from jax.test_util import check_grads

from ccjax import losses
from ccjax.runs import store


@pytest.fixture
def pairs():
    rng = np.random.default_rng(3)
    return rng.uniform(0.05, 1.0, (16, 3)), rng.uniform(0.05, 1.0, (16, 3))


def _mapping_scene(rng, n_scenes=4, n_surfaces=6):
    rgb = rng.uniform(0.05, 1.0, (n_scenes, n_surfaces, 3))
    canonical = rng.uniform(0.05, 1.0, (n_scenes, n_surfaces, 3))
    mask = rng.random((n_scenes, n_surfaces)) < 0.8
    mask[:, 0] = True
    return rgb, mask, canonical


def test_values_match_reference(pairs):
    a, b = pairs
    weight = np.linspace(0.0, 2.0, len(a))
    angles = np.array([reference.angular_error(x, y) for x, y in zip(a, b)])
    distances = np.array([reference.rg_error(x, y) for x, y in zip(a, b)])
    assert float(losses.angular_loss(jnp.asarray(a), jnp.asarray(b))) == pytest.approx(angles.mean(), abs=2e-3)
    assert float(losses.angular_loss(a, b, weight)) == pytest.approx(np.average(angles, weights=weight), abs=2e-3)
    assert float(losses.rg_loss(a, b)) == pytest.approx(distances.mean(), abs=1e-6)
    # Reproduction error: angle between truth / estimate and the achromatic (1, 1, 1).
    reproduction = np.array([reference.angular_error(y / x, np.ones(3)) for x, y in zip(a, b)])
    assert float(losses.reproduction_loss(a, b)) == pytest.approx(reproduction.mean(), abs=2e-3)


def test_mapping_loss_matches_reference():
    rng = np.random.default_rng(4)
    rgb, mask, canonical = _mapping_scene(rng)
    estimate, white = rng.uniform(0.2, 1.0, (4, 3)), np.array([0.9, 1.0, 0.8])
    expected = [reference.mapping_errors(estimate[i], rgb[i], mask[i], canonical[i], white) for i in range(4)]
    rg_rms = np.mean([e[0] for e in expected])
    rgb_rms = np.mean([e[1] for e in expected])
    assert float(losses.mapping_loss(estimate, rgb, mask, canonical, white, space="rg")) == pytest.approx(
        rg_rms, rel=1e-5
    )
    assert float(losses.mapping_loss(estimate, rgb, mask, canonical, white)) == pytest.approx(rgb_rms, rel=1e-5)


@pytest.mark.slow
def test_check_grads_x64_generic_and_zero_error():
    rng = np.random.default_rng(5)
    with jax.enable_x64(True):
        truth = jnp.asarray(rng.uniform(0.1, 1.0, (5, 3)))
        generic = jnp.asarray(rng.uniform(0.1, 1.0, (5, 3)))
        # A power-of-two scale keeps the error exactly 0 in floating point (cross products cancel).
        exact = 2.0 * truth  # zero angular, (r,g) and reproduction error
        for loss in (losses.angular_loss, losses.reproduction_loss, losses.rg_loss):
            # At the cone's apex the central difference has an O(eps) curvature term: a smaller step.
            for estimate, eps in ((generic, 1e-6), (exact, 1e-8)):
                check_grads(
                    jax.jit(lambda e, loss=loss: loss(e, truth)), (estimate,), order=1, modes=("fwd", "rev"), eps=eps
                )
            # At zero error the gradient is defined as 0 (the cone's least-norm subgradient).
            np.testing.assert_array_equal(jax.grad(lambda e, loss=loss: loss(e, truth))(exact), 0.0)
            # Away from it the gradient is not zero.
            assert float(jnp.linalg.norm(jax.grad(lambda e, loss=loss: loss(e, truth))(generic))) > 1e-6

        rgb, mask, canonical = (jnp.asarray(x) for x in _mapping_scene(rng))
        white = jnp.asarray([0.9, 1.0, 0.8])
        estimate = jnp.asarray(rng.uniform(0.2, 1.0, (4, 3)))
        perfect_canonical = rgb * (white / estimate)[:, None, :]  # the estimate maps exactly
        for space in ("rgb", "rg"):
            for target, point in ((canonical, estimate), (perfect_canonical, estimate)):

                def loss(e, target=target, space=space):
                    return losses.mapping_loss(e, rgb, mask, target, white, space=space)

                check_grads(jax.jit(loss), (point,), order=1, modes=("fwd", "rev"), eps=1e-8)
            assert float(losses.mapping_loss(estimate, rgb, mask, perfect_canonical, white)) == pytest.approx(
                0, abs=1e-12
            )


def test_degenerate_inputs_give_finite_gradients():
    truth = jnp.asarray([[0.5, 0.4, 0.3], [0.2, 0.3, 0.5]])
    zero = jnp.zeros((2, 3))
    for loss in (losses.angular_loss, losses.reproduction_loss, losses.rg_loss):
        grad = jax.jit(jax.grad(lambda e, loss=loss: loss(e, truth)))(zero)
        assert np.all(np.isfinite(grad)), loss.__name__
        grad_truth = jax.jit(jax.grad(lambda t, loss=loss: loss(truth, t)))(zero)
        assert np.all(np.isfinite(grad_truth)), loss.__name__
    # A zero estimate is 90 degrees from any light, not 0.
    assert float(losses.angular_loss(zero, truth)) == pytest.approx(90.0)
    # Masked pixels holding NaN and infinity do not reach the mapping loss or its gradient.
    rgb = jnp.asarray([[[0.3, 0.3, 0.3], [jnp.nan, jnp.inf, 1.0]]])
    canonical = jnp.asarray([[[0.4, 0.3, 0.2], [jnp.nan, 0.0, 0.0]]])
    mask = jnp.asarray([[True, False]])
    estimate = jnp.asarray([[0.5, 0.5, 0.5]])
    value, grad = jax.jit(jax.value_and_grad(lambda e: losses.mapping_loss(e, rgb, mask, canonical, jnp.ones(3))))(
        estimate
    )
    assert np.isfinite(float(value)) and np.all(np.isfinite(grad)) and float(jnp.linalg.norm(grad)) > 0
    # No valid pixel at all: loss 0, gradient 0.
    empty = jax.jit(jax.grad(lambda e: losses.mapping_loss(e, rgb, jnp.zeros_like(mask), canonical, jnp.ones(3))))(
        estimate
    )
    np.testing.assert_array_equal(empty, 0.0)
    # Weights summing to 0: a defined 0, not 0 / 0.
    assert float(losses.angular_loss(truth, truth[::-1], jnp.zeros(2))) == 0.0


def test_jit_vmap_and_scene_loss(default_world):
    from ccjax import scenes
    from ccjax.estimators import registry

    batch = scenes.sample(jax.random.key(0), default_world, 16, 8)
    model = registry.fit("GW", default_world)
    value = jax.jit(lambda m: losses.scene_loss(m, batch))(model)
    direct = losses.angular_loss(jax.vmap(model)(batch.rgb, batch.mask).illuminant, batch.illuminant)
    assert float(value) == pytest.approx(float(direct), rel=1e-6)
    per_scene = jax.vmap(lambda e, t: losses.angular_loss(e, t))(batch.illuminant * 1.1, batch.illuminant)
    assert per_scene.shape == (16,) and float(jnp.max(per_scene)) < 1e-3
    mapping = losses.scene_loss(model, batch, "mapping_rgb", canonical_white=default_world.canonical_white)
    assert float(mapping) > 0


def test_bad_input_errors():
    # Under the suite's jaxtyping hook the annotation refuses the shape first; without it the
    # function's own check names the argument.
    with pytest.raises((ValueError, jaxtyping.TypeCheckError), match="estimate"):
        losses.angular_loss(jnp.ones((4, 2)), jnp.ones((4, 3)))
    with pytest.raises(ValueError, match="loss: expected one of"):
        losses.illuminant_loss("cosine", jnp.ones(3), jnp.ones(3))
    with pytest.raises(ValueError, match="space: expected"):
        losses.mapping_loss(
            jnp.ones(3), jnp.ones((2, 3)), jnp.ones(2, bool), jnp.ones((2, 3)), jnp.ones(3), space="lab"
        )
    with pytest.raises((ValueError, jaxtyping.TypeCheckError), match="mask"):
        losses.mapping_loss(jnp.ones(3), jnp.ones((2, 3)), jnp.ones(3, bool), jnp.ones((2, 3)), jnp.ones(3))


def _differentiable_examples():
    """Every differentiable example, slow; the soft gamut kernel's (about 70 s on 2 cores, its
    gradients checked on small batches by the gamut tests) manual."""
    from ccjax.estimators import registry

    labels = [entry.example for entry in registry.available() if entry.differentiable]
    return [
        pytest.param(label, marks=pytest.mark.manual if "ECRULE" in label else pytest.mark.slow) for label in labels
    ]


@pytest.mark.parametrize("label", _differentiable_examples())
def test_grad_through_vmapped_model_on_1000_scenes(label, default_world):
    """jax.grad of the angular loss through vmap(model) with respect to the
    input RGB is finite everywhere and non-zero, on 1000 scenes, for every estimator the registry
    calls differentiable."""
    from ccjax import scenes
    from ccjax.estimators import registry

    entry, _ = registry.lookup(label)
    model = store.fit(label, default_world)
    if entry.input_kind == "image":
        batch = scenes.sample_mondrians(jax.random.key(0), default_world, 1000, height=16, width=16, n_patches=6)
        x, mask, truth = batch.image, jnp.ones(batch.image.shape[:3], bool), batch.illuminant
    else:
        batch = scenes.sample(jax.random.key(0), default_world, 1000, 8)
        x, mask, truth = batch.rgb, batch.mask, batch.illuminant

    @jax.jit
    def gradient(x, mask, truth):
        return jax.grad(lambda x: losses.angular_loss(jax.vmap(model)(x, mask).illuminant, truth))(x)

    # The loss is a mean over scenes, so its gradient is the chunks' gradients weighted by their
    # share: 40 chunks of 25 scenes keep the soft gamut's (scenes x directions x facets) residuals
    # for the backward pass at about 1 GB instead of 38 GB.
    chunk = 25
    grad = np.concatenate(
        [
            np.asarray(gradient(x[i : i + chunk], mask[i : i + chunk], truth[i : i + chunk])) * (chunk / len(x))
            for i in range(0, len(x), chunk)
        ]
    )
    norm = float(np.linalg.norm(grad))
    per_scene = np.linalg.norm(grad.reshape(grad.shape[0], -1), axis=1)
    print(f"{label}: |grad| = {norm:.3e}, scenes with a non-zero gradient {np.mean(per_scene > 0):.3f}")
    assert np.all(np.isfinite(grad)), label
    assert norm > 0, label
