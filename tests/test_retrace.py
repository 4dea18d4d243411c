"""No silent retrace in a training loop: every fitted model's inexact array leaves are
strong-typed, so a step compiled for a model is traced once over an optimiser's updates.

A weak-typed leaf (a Python number through ``jnp.asarray`` / ``jnp.full``, or an equinox converter)
changes type at the first update (weak + strong update = strong): jit traces the step again, at
the cost of a whole compilation. GW's ``scale`` did (three traces in 20 Adam steps)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
from small_world import small_world
from traces import count_traces, record_traces

from ccjax.estimators import neural, registry
from ccjax.estimators.simple import GreyWorld
from ccjax.estimators.spatial import GreyEdge
from ccjax.world import World

# Labels beyond each family's example whose fits take other branches (the other constraint and
# selectors, the MAP estimate, the flags of Colour by Correlation, an alias, another norm).
VARIANTS = (
    "gw",
    "MAX-RGB",
    "CRULE-MV",
    "ECRULE-AVE",
    "C-by-C-MAP",
    "FL-C-by-C-MMSE",
    "STD-RGB-C-by-C-MAP-counts",
    "grey-edge-0-inf-0",
)
# The nets' fits read trained weights: a tiny untrained net is saved for the world first, so
# their models come through the registry's own loading.
NET_RECIPE = neural.Recipe(hidden=(8,), min_surfaces=4, max_surfaces=16)
STEPS = 20


@pytest.fixture(scope="module")
def world() -> World:
    """The small test world, thinned (63 reflectances, 8 training lights): fast fits."""
    base = small_world()
    return World(
        reflectances=base.reflectances[::4],
        train_illuminants=base.train_illuminants[::2],
        test_illuminants=base.test_illuminants[::4],
        canonical=base.canonical,
        camera=base.camera,
        name="retrace test world",
    )


@pytest.fixture(scope="module")
def models(world, tmp_path_factory) -> dict:
    """Every registered family's example label and the :data:`VARIANTS`, fitted to ``world``."""
    labels = [entry.example for entry in registry.available()]
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("CCJAX_CACHE", str(tmp_path_factory.mktemp("cache")))
        for label in labels:
            if neural.is_net_label(label):
                patch.setitem(neural.RECIPES, label, NET_RECIPE)
                net = neural.Mlp(jax.random.key(0), NET_RECIPE.sizes())
                log = neural.TrainingLog(losses=[0.01], seconds=0.0)
                neural.save(net, world, label, NET_RECIPE, neural.Schedule(steps=1), log)
        return {label: registry.fit(label, world) for label in [*labels, *VARIANTS]}


def inexact_leaves(model) -> list[tuple[str, jax.Array]]:
    return [
        (jax.tree_util.keystr(path), leaf)
        for path, leaf in jax.tree_util.tree_leaves_with_path(model)
        if eqx.is_inexact_array(leaf)
    ]


def test_every_family_is_covered(models):
    """The fixture fits a label of every registered family (a new family cannot be left out)."""
    families = {registry.lookup(label)[0].pattern.pattern for label in models}
    assert families == {entry.pattern.pattern for entry in registry.available()}
    assert all(inexact_leaves(model) for model in models.values())  # each has something to train


def test_fitted_models_have_no_weak_typed_leaves(models):
    weak = {label: [path for path, leaf in inexact_leaves(model) if leaf.weak_type] for label, model in models.items()}
    assert {label: paths for label, paths in weak.items() if paths} == {}


def test_models_built_from_python_numbers_are_strong_typed():
    """However a model is built (here from Python numbers: ``jnp.full`` and grey edge's
    ``jnp.asarray`` converter make weak-typed arrays), its leaves are strong, dtype and value kept;
    also inside ``jit`` (a traced fit)."""
    grey = GreyWorld(scale=jnp.full(3, 2.0), fallback=jnp.ones(3, jnp.float32))
    edge = GreyEdge(p=6.0, fallback=jnp.ones(3, jnp.float32), order=1, sigma=1.0)
    assert jnp.full(3, 2.0).weak_type and jnp.asarray(6.0).weak_type  # what the constructors were given
    for leaf, value in ((grey.scale, 2.0), (edge.p, 6.0)):
        assert not leaf.weak_type and leaf.dtype == jnp.asarray(value).dtype
        np.testing.assert_array_equal(np.asarray(leaf), value)

    @jax.jit
    def traced(scale):
        model = GreyWorld(scale=jnp.full(3, 2.0) * scale, fallback=jnp.ones(3, jnp.float32))
        assert not model.scale.aval.weak_type  # a weak-typed tracer (a Python float argument) made strong
        return model.scale

    assert not traced(1.0).weak_type


def test_optimiser_steps_trace_once_for_every_model(models):
    """``STEPS`` optax Adam steps under ``eqx.filter_jit`` over the inexact leaves of every model
    at once: one trace. The trace depends only on the arguments' types, so a loss touching every
    leaf (their squares) checks every model; the real training steps are checked in
    tests/test_training.py and tests/test_sharpening.py."""
    params, static = eqx.partition(models, eqx.is_inexact_array)
    optimiser = optax.adam(1e-3)
    traces = []

    @eqx.filter_jit
    def step(params, state):
        traces.append(1)  # runs once per trace

        def loss(p):
            return sum(jnp.mean(leaf**2) for leaf in jax.tree_util.tree_leaves(p))

        grads = eqx.filter_grad(loss)(params)
        with jax.numpy_dtype_promotion("standard"):  # optax's bias correction mixes int and float
            updates, state = optimiser.update(grads, state, params)
        return eqx.apply_updates(params, updates), state

    start = jax.tree_util.tree_map(jax.typeof, params)
    state = optimiser.init(params)
    for _ in range(STEPS):
        params, state = step(params, state)
    changed = [
        label
        for label in models
        if jax.tree_util.tree_map(jax.typeof, params[label]) != start[label]  # types the updates changed
    ]
    assert (len(traces), changed) == (1, [])
    # The steps did update every model (a step that changed nothing would trace once too).
    moved = eqx.combine(params, static)
    assert all(
        not np.array_equal(np.asarray(a), np.asarray(b))
        for label in models
        for (_, a), (_, b) in zip(inexact_leaves(models[label]), inexact_leaves(moved[label]))
        if np.any(np.asarray(a) != 0)
    )


def test_grey_world_trained_through_its_estimate_traces_once(models):
    """The case that retraced: GW's scale trained on its own estimates' angular error."""
    model = models["GW"]
    rng = np.random.default_rng(0)
    rgb = jnp.asarray(rng.uniform(0.1, 1.0, (4, 6, 3)), jnp.float32)
    mask = jnp.ones((4, 6), bool)
    target = jnp.asarray(rng.uniform(0.5, 1.0, (4, 3)), jnp.float32)
    params, static = eqx.partition(model, eqx.is_inexact_array)
    optimiser = optax.adam(1e-2)
    traces = []

    @eqx.filter_jit
    def step(params, state):
        traces.append(1)

        def loss(p):
            estimate = jax.vmap(eqx.combine(p, static))(rgb, mask).illuminant
            cosine = jnp.sum(estimate * target, -1) / (
                jnp.linalg.norm(estimate, axis=-1) * jnp.linalg.norm(target, axis=-1)
            )
            return jnp.mean(1.0 - cosine)

        value, grads = eqx.filter_value_and_grad(loss)(params)
        with jax.numpy_dtype_promotion("standard"):
            updates, state = optimiser.update(grads, state, params)
        return eqx.apply_updates(params, updates), state, value

    state = optimiser.init(params)
    values = []
    for _ in range(STEPS):
        params, state, value = step(params, state)
        values.append(float(value))
    assert len(traces) == 1
    assert values[-1] < values[0]  # and it learned


def test_trace_log_counts_traces(caplog):
    """The log the training-loop checks count traces from (tests/test_training.py,
    tests/test_sharpening.py): a new shape is a trace, a repeated one is not."""
    record_traces(caplog)

    @eqx.filter_jit
    def retrace_probe(x):
        return x + 1

    for shape in (3, 3, 4):
        retrace_probe(jnp.zeros(shape))
    assert count_traces(caplog, "retrace_probe") == 2
