"""The estimator contract, for every label ccjax names: the registry's examples, every row of the
thesis tables that the registry accepts, and the defaults of ``ccjax compare``.

Each label is fitted once on the embedded default world (nets: a small net trained for 50 steps in
a private cache). A fitted model must be a valid ``jax.jit`` / ``jax.vmap`` / ``jax.grad`` argument;
surface estimators take ``(P, 3)`` and ``(B, P, 3)``, image estimators ``(H, W, 3)`` and
``(B, H, W, 3)``; the wrong kind of input is a clear ``ValueError``; degenerate scenes (all masked,
all zero) give finite estimates that are not ``ok``.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ccjax
from ccjax import scenes, thesis
from ccjax.estimators import neural, registry
from ccjax.estimators.base import (
    AbstractImageEstimator,
    AbstractSurfaceEstimator,
    Estimate,
    Status,
    estimate_batch,
)
from ccjax.estimators.inputs import require_kind
from ccjax.runs import store
from ccjax.world import World


def _compare_defaults() -> list[str]:
    from ccjax.cli import synthetic

    return list(synthetic.DEFAULT_COMPARE_METHODS)


def _registered(label: str) -> bool:
    try:
        registry.lookup(label)
    except ValueError:
        return False
    return True


EXAMPLES = [entry.example for entry in registry.available()]
THESIS_ROWS = sorted({label for table in thesis.TABLES.values() for label in table if _registered(label)})
LABELS = sorted(set(EXAMPLES) | set(THESIS_ROWS) | set(_compare_defaults()))
GAMUT_FAMILIES = ("ccjax.estimators.gamut", "ccjax.estimators.gamut.cip")


def _param(label: str):
    """Gamut-mapping kernels take 10-20 s each to compile: their registry examples run by default,
    their other labels (same kernels, other selectors and constraint sets) are marked slow, and the
    SCWIA weights other than 12 (the same program with another exponent) are marked manual."""
    entry, _ = registry.lookup(label)
    heavy = entry.build.__module__.startswith(GAMUT_FAMILIES) and label != entry.example
    if heavy and "-SCWIA-" in label and not label.endswith("-SCWIA-12"):
        return pytest.param(label, marks=pytest.mark.manual)
    return pytest.param(label, marks=pytest.mark.slow) if heavy else label


LABEL_PARAMS = [_param(label) for label in LABELS]
CONSTANT = {"NOTHING", "AVE-ILLUM"}  # scene-independent: an empty scene is no reason to fall back
P, SIDE = 8, 12  # small fixed shapes: one compilation per label


@pytest.fixture(scope="session")
def world() -> World:
    return World.default()


@pytest.fixture(scope="session")
def fitted(world, tmp_path_factory):
    """``label -> model`` for every label, fitted once per session into a private cache. Nets are
    trained first, for 50 steps with a small recipe (training is not what this file tests); the
    other labels are fitted on first use."""
    cache = str(tmp_path_factory.mktemp("contract-cache"))
    models: dict[str, object] = {}
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("CCJAX_CACHE", cache)
        small, schedule = neural.Recipe(hidden=(24, 8), min_surfaces=4, max_surfaces=16), neural.Schedule(50, 32)
        net, log = neural.train(world, small, schedule)  # one small net stands in for both labels
        for label in [label for label in LABELS if neural.is_net_label(label)]:
            patch.setitem(neural.RECIPES, label, small)
            neural.save(net, world, label, small, schedule, log)
            models[label] = registry.fit(label, world)

    def get(label: str):
        if label not in models:
            with pytest.MonkeyPatch.context() as patch:
                patch.setenv("CCJAX_CACHE", cache)
                models[label] = registry.fit(label, world)
        return models[label]

    return get


@pytest.fixture(scope="session")
def surface_batch(world):
    """``(3, P, 3)``: a real scene, the same scene all masked, an all-zero scene."""
    batch = scenes.sample(jax.random.key(5), world, 1, P)
    rgb = jnp.concatenate([batch.rgb, batch.rgb, jnp.zeros_like(batch.rgb)])
    mask = jnp.stack([jnp.ones(P, bool), jnp.zeros(P, bool), jnp.ones(P, bool)])
    return rgb, mask


@pytest.fixture(scope="session")
def image_batch():
    """``(3, SIDE, SIDE, 3)``: a textured image, the same image all masked, an all-zero image."""
    rng = np.random.default_rng(2)
    y, x = np.mgrid[:SIDE, :SIDE]
    base = np.stack([np.sin(x / 2.0 + c) * np.cos(y / 3.0 - c) for c in range(3)], -1)
    image = ((0.5 + 0.3 * base + 0.2 * rng.random((SIDE, SIDE, 3))) * [0.9, 0.6, 0.4]).astype(np.float32)
    images = jnp.asarray(np.stack([image, image, np.zeros_like(image)]))
    mask = jnp.stack([jnp.ones((SIDE, SIDE), bool), jnp.zeros((SIDE, SIDE), bool), jnp.ones((SIDE, SIDE), bool)])
    return images, mask


def _batch_for(model, surface_batch, image_batch):
    return image_batch if model.input_kind == "image" else surface_batch


@jax.jit
def _one_and_batch(model, x, mask):
    # One compilation per label holds both contract calls: a single scene, and the vmapped batch.
    return model(x[0], mask[0]), jax.vmap(lambda m, a, k: m(a, k), in_axes=(None, 0, 0))(model, x, mask)


@pytest.mark.parametrize("label", LABEL_PARAMS)
def test_jit_and_vmap_and_degenerate_scenes(label, fitted, surface_batch, image_batch):
    model = fitted(label)
    assert isinstance(model, (AbstractSurfaceEstimator, AbstractImageEstimator)), type(model)
    assert type(model).__name__ and not type(model).__abstractmethods__
    x, mask = _batch_for(model, surface_batch, image_batch)
    one, many = _one_and_batch(model, x, mask)
    assert isinstance(one, Estimate) and one.illuminant.shape == (3,)
    assert many.illuminant.shape == (3, 3) and many.ok.shape == many.status.shape == (3,)
    # MV's pattern search runs in float32; one scene and the vmapped batch compile to differently
    # fused programs, whose rounding moves its optimum by ~1e-5 relative (measured 1.5e-5, CRULE-MV).
    rtol = 1e-4 if label.endswith("-MV") else 1e-5
    np.testing.assert_allclose(one.illuminant, many.illuminant[0], rtol=rtol, atol=1e-7)
    illuminant, status = np.asarray(many.illuminant), np.asarray(many.status)
    assert np.all(np.isfinite(illuminant)), illuminant
    assert set(status.tolist()) <= {int(s) for s in Status}
    np.testing.assert_array_equal(np.asarray(many.ok), status == Status.ESTIMATED)
    assert np.all(np.isfinite(np.asarray(many.relaxation)))
    if label not in CONSTANT:
        # All masked and all zero: no data, so not ok (status says why).
        assert not np.any(np.asarray(many.ok)[1:]), (label, status)


@pytest.mark.parametrize("label", LABELS)
def test_model_is_a_valid_grad_argument(label, fitted):
    """Every leaf of a fitted model is a floating-point array (configuration is static), so the
    model itself can be the argument of ``jax.grad``."""
    model = fitted(label)
    leaves = jax.tree_util.tree_leaves(model)
    assert all(isinstance(leaf, jax.Array) and jnp.issubdtype(leaf.dtype, jnp.floating) for leaf in leaves), [
        (type(leaf).__name__, getattr(leaf, "dtype", None)) for leaf in leaves
    ]
    gradient = jax.grad(lambda m: sum(jnp.sum(leaf) for leaf in jax.tree_util.tree_leaves(m)))(model)
    assert jax.tree_util.tree_structure(gradient) == jax.tree_util.tree_structure(model)


DIFFERENTIABLE = [entry.example for entry in registry.available() if entry.differentiable]


@pytest.mark.parametrize("label", DIFFERENTIABLE)
def test_differentiable_entries_have_input_and_parameter_gradients(label, fitted, surface_batch, image_batch):
    model = fitted(label)
    x, mask = _batch_for(model, surface_batch, image_batch)
    direction = jnp.asarray([0.3, -0.5, 0.2])

    def loss(m, a):
        e = m(a, mask[0]).illuminant
        return (e / jnp.sum(e)) @ direction

    d_model, d_input = jax.jit(jax.grad(loss, argnums=(0, 1)))(model, x[0])
    assert np.all(np.isfinite(np.asarray(d_input))) and float(jnp.linalg.norm(d_input)) > 0, label
    assert all(np.all(np.isfinite(np.asarray(leaf))) for leaf in jax.tree_util.tree_leaves(d_model)), label


TRACEABLE = [entry.example for entry in registry.available() if entry.traceable_fit]


@pytest.mark.parametrize("label", TRACEABLE)
def test_traceable_fits_trace(label, world):
    """``traceable_fit`` entries: ``jax.jit`` of the fit over the world gives the eager model."""
    traced = jax.jit(lambda w: registry.fit(label, w))(world)
    eager = registry.fit(label, world)
    assert jax.tree_util.tree_structure(traced) == jax.tree_util.tree_structure(eager)
    for a, b in zip(jax.tree_util.tree_leaves(traced), jax.tree_util.tree_leaves(eager)):
        np.testing.assert_allclose(a, b, rtol=1e-6)


# ---------------------------------------------------------------------------------------------
# dispatch on the input kind


def test_estimate_dispatches_on_the_input_kind(image_batch, surface_batch, world):
    images, image_mask = image_batch
    one = ccjax.estimate("grey-edge-1-6-2", images[0])
    many = ccjax.estimate("grey-edge-1-6-2", images, image_mask)
    assert one.illuminant.shape == (3,) and many.illuminant.shape == (3, 3) and bool(one.ok)
    np.testing.assert_allclose(one.illuminant, many.illuminant[0], rtol=1e-6)
    rgb, mask = surface_batch
    assert ccjax.estimate("GW", rgb[0]).illuminant.shape == (3,)
    assert estimate_batch(registry.fit("GW", world), rgb, mask).illuminant.shape == (3, 3)


def test_wrong_input_kind_is_a_clear_error(image_batch, surface_batch, world):
    rgb, _ = surface_batch
    images, _ = image_batch
    with pytest.raises(ValueError, match=r"image: GreyEdge is an image estimator .*\(H, W, 3\).*\(8, 3\)"):
        ccjax.estimate("grey-edge-1-6-2", rgb[0])
    # An image to a surface estimator is one scene (tests/test_estimate_images.py), not H surface lists.
    assert ccjax.estimate("GW", images[0]).illuminant.shape == (3,)
    with pytest.raises(ValueError, match=r"mask: expected shape \(12, 12\)"):
        ccjax.estimate("grey-edge-1-6-2", images[0], np.ones((8,), bool))
    grey_edge = registry.fit("grey-edge-1-6-2", world)
    with pytest.raises(
        ValueError, match=r"x: GreyEdge is an image estimator and estimates batches image \(B, H, W, 3\)"
    ):
        estimate_batch(grey_edge, rgb, jnp.ones(rgb.shape[:2], bool))
    with pytest.raises(ValueError, match="method: expected a label or a fitted estimator"):
        ccjax.estimate(object(), rgb[0])


def test_require_kind_names_caller_estimator_and_remedy(world):
    grey_edge = registry.fit("grey-edge-1-6-2", world)
    gw = registry.fit("GW", world)
    require_kind(gw, "surfaces", "methods")
    require_kind(grey_edge, "image", "methods")
    with pytest.raises(ValueError, match=r"^methods: GreyEdge is an image estimator .* needs a surface estimator"):
        require_kind(grey_edge, "surfaces", "methods")
    with pytest.raises(ValueError, match=r"^estimator: GreyWorld is a surface estimator .*image pipeline"):
        require_kind(gw, "image", "estimator")
    with pytest.raises(ValueError, match="kind"):
        require_kind(gw, "pixels", "methods")


# ---------------------------------------------------------------------------------------------
# the registry


def test_entries_state_grammar_kind_and_traceability():
    entries = registry.available()
    for entry in entries:
        assert entry.pattern.fullmatch(entry.example), entry
        assert entry.input_kind in ("surfaces", "image") and entry.grammar and entry.description
    kinds = {entry.example: entry.input_kind for entry in entries}
    assert kinds["grey-edge-1-6-2"] == "image" and kinds["GW"] == "surfaces"
    traceable = {entry.example: entry.traceable_fit for entry in entries}
    assert traceable["GW"] and not traceable["C-by-C-MMSE"] and not traceable["NEURAL-NET"]


def test_register_forms_and_checks(monkeypatch):
    monkeypatch.setattr(registry, "_ENTRIES", list(registry._ENTRIES))
    registry.register(r"PROBE-(?P<n>\d)", "PROBE-1", "a probe in the older positional form")(
        lambda world, match, **options: registry.fit("GW", world)
    )
    entry, match = registry.lookup("PROBE-3")
    assert (entry.input_kind, entry.grammar, entry.traceable_fit, match["n"]) == ("surfaces", "PROBE-1", False, "3")
    with pytest.raises(ValueError, match="does not match"):
        registry.register(r"PROBE-A", example="PROBE-B", description="x")
    with pytest.raises(ValueError, match="input_kind"):
        registry.register(r"PROBE-C", example="PROBE-C", description="x", input_kind="pixels")
    registry.register(r"PROBE-D", example="PROBE-D", description="declared image, builds surfaces", input_kind="image")(
        lambda world, match, **options: registry.fit("GW", world)
    )
    with pytest.raises(TypeError, match="input_kind 'image'"):
        registry.fit("PROBE-D", World.default())


def test_store_memoises_fits_by_content(world):
    first = store.fit("shades-of-grey-p6", world)
    assert store.fit("shades-of-grey-p6", World.default()) is first  # equal content, same model
    assert store.fit("soft-RETINEX-t0.01", world) is not first
    softer = store.fit("RETINEX", world, temperature=0.5)
    assert softer is not store.fit("RETINEX", world, temperature=0.25)
    assert math.isclose(float(softer.temperature), 0.5)
    with pytest.raises(ValueError, match="unknown label"):
        store.fit("NO-SUCH-METHOD", world)
