"""The precision policy (ccjax/precision.py): every product that carries physics or statistics is
``precision=HIGHEST``, checked on CPU at the jaxpr level (a GPU would compute a product of default
precision in TF32: measured on an H200, world responses off by 2e-4 relative, one sharpening-map
entry by 30 %).

The checker is tested first on products it must find (plain ``@``, ``einsum``, ``dot`` inside
jit, scan, while, cond and custom_jvp) and on those it must accept (the helpers, the opt-in, the
solves), then run over every registered label family (with each gamut selector), world responses
and scene tables, sharpening, calibration (each solver), correction and the losses with their
gradients.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from small_world import small_world

from ccjax import correction, losses, precision, scenes
from ccjax.calibration import fitting
from ccjax.estimators import neural, registry
from ccjax.scenes import SceneTables
from ccjax.sharpening import _new_method, best_diagonal_map, best_linear_map, sharpened
from ccjax.sharpening._transforms import actual_error, best_linear_error, diagonal_error

A = jnp.ones((4, 3))
B = jnp.ones((3, 5))


@pytest.fixture(scope="module")
def world():
    return small_world()


def _found(fn, *args) -> list[str]:
    return precision.low_precision_products(fn, *args)


# ---------------------------------------------------------------------------------------------
# the checker


@pytest.mark.parametrize(
    "fn",
    [
        lambda a, b: a @ b,
        lambda a, b: jnp.einsum("ij,jk->ik", a, b),
        lambda a, b: jnp.dot(a, b),
        lambda a, b: jax.jit(jnp.matmul)(a, b),
        lambda a, b: jax.lax.scan(lambda c, _: (c, c @ b), a, None, length=2)[1],
        lambda a, b: jax.lax.while_loop(lambda c: c[0, 0] < 0, lambda c: c @ b @ b.T, a),
        lambda a, b: jax.lax.cond(a[0, 0] > 0, lambda: a @ b, lambda: jnp.zeros((4, 5))),
        lambda a, b: jax.nn.relu(a @ b),
        lambda a, b: jax.grad(lambda x: jnp.sum(precision.matmul(x, b) @ b.T))(a),
    ],
)
def test_checker_finds_default_precision_products(fn):
    found = _found(fn, A, B)
    assert found, "a product at the default precision went unnoticed"
    assert all("precision=None" in line for line in found)


def test_checker_finds_products_in_custom_jvp():
    @jax.custom_jvp
    def f(a):
        return a @ B

    f.defjvp(lambda primals, tangents: (f(*primals), precision.matmul(tangents[0], B)))
    assert len(_found(f, A)) == 1


@pytest.mark.parametrize(
    "fn",
    [
        precision.matmul,
        lambda a, b: precision.einsum("ij,jk->ik", a, b),
        lambda a, b: jax.grad(lambda x: jnp.sum(precision.matmul(precision.matmul(x, b), b.T)))(a),
        precision.fast_matmul,
        lambda a, b: jax.jit(precision.fast_matmul)(a, b),
        lambda a, b: jnp.linalg.solve(precision.matmul(a.T, a) + jnp.eye(3), b),
        lambda a, b: jnp.linalg.lstsq(a, jnp.ones(4))[0],
        lambda a, b: jnp.linalg.inv(a[:3]),
        lambda a, b: jnp.einsum("ij,ij->i", a > 0, a > 0),  # boolean operands: exact
    ],
)
def test_checker_accepts_highest_opt_ins_and_solves(fn):
    assert _found(fn, A, B) == []


def test_opt_in_is_exact_on_cpu_and_the_helpers_agree_with_numpy():
    a = np.random.default_rng(0).standard_normal((6, 101)).astype(np.float32)
    b = np.random.default_rng(1).standard_normal((101, 3)).astype(np.float32)
    exact = a.astype(np.float64) @ b.astype(np.float64)
    for product in (precision.matmul(a, b), precision.fast_matmul(a, b), precision.einsum("il,lc->ic", a, b)):
        np.testing.assert_allclose(np.asarray(product), exact, rtol=1e-5, atol=1e-5)


# ---------------------------------------------------------------------------------------------
# the library

# Every registered family's example, each gamut selector and constraint, and C-by-C's selectors.
EXTRA_LABELS = (
    "CRULE-AVE",
    "CRULE-MV",
    "ECRULE-MV",
    "ND-ECRULE-MV",
    "ECRULE-ICA",
    "soft-ECRULE-MV",
    "C-by-C-MAP",
    "C-by-C-MLM",
)


def _labels() -> list[str]:
    examples = [entry.example for entry in registry.available() if "NEURAL-NET" not in entry.example]
    return examples + [label for label in EXTRA_LABELS if label not in examples]


@pytest.mark.parametrize("label", _labels())
def test_estimators_use_highest(world, label):
    model = registry.fit(label, world)
    if model.input_kind == "surfaces":
        x, mask = jnp.ones((8, 16, 3)), jnp.ones((8, 16), bool)
    else:
        x, mask = jnp.ones((2, 8, 8, 3)), jnp.ones((2, 8, 8), bool)
    assert _found(lambda x, m: jax.vmap(model)(x, m).illuminant, x, mask) == []


def test_neural_net_uses_highest():
    # NEURAL-NET's fit reads trained weights; the model itself is its Mlp and a fallback.
    model = neural.NeuralNet(net=neural.Mlp(jax.random.key(0), (2500, 8, 4, 2)), fallback=jnp.ones(3))
    rgb, mask = jnp.ones((16, 3)), jnp.ones(16, bool)
    assert _found(lambda rgb: model(rgb, mask).illuminant, rgb) == []
    assert _found(lambda x: model.net(x), jnp.ones(2500)) == []


def test_world_responses_and_scene_tables_use_highest(world):
    assert _found(world.responses, world.train_illuminants) == []
    assert _found(lambda w: SceneTables.from_world(w).surface_rgb, world) == []
    assert _found(lambda key: scenes.sample(key, world, 4, 8).rgb, jax.random.key(0)) == []


def test_sharpening_uses_highest(world):
    source, target = world.responses(world.train_illuminants[0]), world.responses(world.canonical)
    transform = jnp.eye(3) + 0.1
    assert _found(best_linear_map, source, target) == []
    assert _found(best_linear_error, source, target) == []
    assert _found(best_diagonal_map, source, target, transform) == []
    assert _found(diagonal_error, source, target, transform) == []
    truth, white = jnp.ones(3), jnp.ones(3)
    assert _found(actual_error, source, target, transform, truth, white) == []
    train = world.responses(world.train_illuminants)
    grad = jax.grad(_new_method.objective)
    assert _found(lambda t: grad(t, train, target, 1.0, 1.0), transform) == []
    model = sharpened("DB-GW", transform, world)
    assert _found(lambda rgb: model(rgb, jnp.ones(16, bool)).illuminant, jnp.ones((16, 3))) == []


@pytest.mark.parametrize(
    "options",
    [
        {},  # box-constrained: projected gradient and the active-set polish
        pytest.param({"max_abs_error": 0.05}, marks=pytest.mark.slow),  # error bounds: BoxOSQP
        {"smoothness": 0.0, "positive": False},  # the SVD pseudo-inverse
        {"linearisation": "exp", "exp_rate": 0.01},
    ],
)
def test_calibration_uses_highest(world, monkeypatch, options):
    # fit_sensors converts its results to NumPy, so the jitted kernel is traced where it is called.
    traced = []
    kernel = fitting.fit_data_set

    def recording(*args):
        traced.append(kernel.trace(*args).jaxpr)
        return kernel(*args)

    monkeypatch.setattr(fitting, "fit_data_set", recording)
    lights, reflectances = np.asarray(world.test_illuminants[:12]), np.asarray(world.reflectances[:3])
    spectra = (lights[:, None] * reflectances[None]).reshape(-1, lights.shape[-1])
    responses = spectra @ np.asarray(world.camera.sensors) + 0.01
    fitting.fit_sensors(spectra, responses, maxiter=20, **options)
    assert traced and [precision.jaxpr_low_precision_products(j) for j in traced] == [[]] * len(traced)


def test_correction_uses_highest():
    white, light = jnp.ones(3), jnp.asarray([0.8, 1.0, 0.6])
    assert _found(correction.correction_map, light, white, jnp.eye(3) + 0.1) == []
    assert _found(correction.apply_map, jnp.ones((4, 4, 3)), jnp.eye(3)) == []


@pytest.mark.parametrize("name", losses.LOSSES)
def test_losses_and_gradients_use_highest(world, name):
    estimate, truth = jnp.ones((4, 3)), jnp.asarray([[0.5, 1.0, 0.7]] * 4)
    if name.startswith("mapping"):
        batch = scenes.sample(jax.random.key(0), world, 4, 8)
        model = registry.fit("DB-GW", world)
        white = world.canonical_white

        def loss(model):
            return losses.scene_loss(model, batch, name, canonical_white=white)

        assert _found(loss, model) == []
        assert _found(jax.grad(loss, allow_int=True), model) == []
    else:
        assert _found(lambda e: losses.illuminant_loss(name, e, truth), estimate) == []
        assert _found(jax.grad(lambda e: losses.illuminant_loss(name, e, truth)), estimate) == []
