"""Tests of the neural-net estimator (Barnard 1999 §4.5.5): the binarised histogram against a plain
NumPy loop written from the spec, the sparse first layer against the dense one, the projection into
the chromaticity triangle against a brute-force search, the weight cache, training and the
missing-weights error."""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ccjax import cli
from ccjax.camera import Camera
from ccjax.estimators import neural, registry
from ccjax.estimators.base import Status
from ccjax.experiments.sweeps import weights_ready
from ccjax.scenes import SceneTables
from ccjax.spectra import WAVELENGTHS
from ccjax.world import World

P = 16  # fixed padded scene size: one compilation for every hypothesis example


# ---------------------------------------------------------------------------------------------
# references written from the spec (ch02-04 §6.6): 50 x 50 bins of width 0.02 on [0, 1]^2


def histogram_reference(rgb: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Binarised (r,g) histogram by a plain loop: bin (i, j) at i * 50 + j, r = 1 in the last bin."""
    histogram = np.zeros(2500)
    for (red, green, blue), valid in zip(rgb.astype(np.float64), mask):
        total = red + green + blue
        if not valid or total <= 0:
            continue
        i = min(int(red / total / 0.02), 49)
        j = min(int(green / total / 0.02), 49)
        histogram[i * 50 + j] = 1.0
    return histogram


def nearest_in_triangle(point: np.ndarray, margin: float, steps: int = 801) -> np.ndarray:
    """Nearest point of {r, g >= margin, r + g <= 1 - margin} by exhaustive search on a fine grid."""
    grid = np.linspace(margin, 1 - margin, steps)
    r, g = np.meshgrid(grid, grid, indexing="ij")
    inside = r + g <= 1 - margin + 1e-12
    candidates = np.stack([r[inside], g[inside]], axis=1)
    return candidates[np.argmin(np.sum((candidates - point) ** 2, axis=1))]


def tiny_world(name: str = "tiny", seed: int = 0) -> World:
    """A small world with structure: 120 smooth reflectances, 12 tilted lights (bluish to reddish),
    Gaussian sensors. Cheap to build and to train on."""
    rng = np.random.default_rng(seed)
    x = (WAVELENGTHS - 580.0) / 200.0
    basis = np.stack([np.ones_like(x), x, x**2, np.sin(3 * x), np.cos(3 * x)])
    reflectances = np.clip(0.5 + 0.25 * rng.normal(size=(120, 5)) @ basis / 2, 0.02, 1.0)
    tilts = np.linspace(-2.0, 2.0, 12)
    lights = np.exp(tilts[:, None] * x[None, :])
    sensors = np.stack([np.exp(-0.5 * ((WAVELENGTHS - c) / 30.0) ** 2) for c in (450.0, 540.0, 610.0)], axis=1)
    camera = Camera.from_array(sensors, name="gaussian")
    lights = lights / np.max(lights @ sensors, axis=1, keepdims=True)
    f32 = lambda a: jnp.asarray(a, jnp.float32)
    return World(
        reflectances=f32(reflectances),
        train_illuminants=f32(lights),
        test_illuminants=f32(lights[::-1]),
        canonical=f32(lights[6]),
        camera=camera,
        name=name,
    )


SMALL = neural.Recipe(hidden=(24, 8), min_surfaces=4, max_surfaces=16)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path))
    return tmp_path


# ---------------------------------------------------------------------------------------------
# input encoding


def test_histogram_matches_loop_reference_x64():
    rng = np.random.default_rng(1)
    rgb = rng.uniform(0, 1, size=(40, P, 3)) ** 3  # skewed: many saturated chromaticities
    rgb[0, :3] = [[1, 0, 0], [0, 1, 0], [0, 0, 0]]  # r = 1, g = 1, black (ignored)
    mask = rng.uniform(size=(40, P)) < 0.8
    with jax.enable_x64(True):
        ours = np.asarray(jax.jit(jax.vmap(neural.binarised_histogram))(jnp.asarray(rgb), jnp.asarray(mask)))
    for b in range(len(rgb)):
        np.testing.assert_array_equal(ours[b], histogram_reference(rgb[b], mask[b]), err_msg=f"scene {b}")
    assert ours[0, 49 * 50 + 0] == 1 and ours[0, 0 * 50 + 49] == 1


def test_histogram_matches_loop_reference_float32():
    rng = np.random.default_rng(2)
    rgb = rng.uniform(0, 1, size=(40, P, 3)).astype(np.float32)
    chromaticity = rgb[..., :2].astype(np.float64) / rgb.astype(np.float64).sum(-1, keepdims=True) * 50
    # float32 and float64 may bin a chromaticity within rounding of a cell edge differently.
    away_from_edges = np.all(np.abs(chromaticity - np.round(chromaticity)) > 1e-4, axis=-1)
    mask = (rng.uniform(size=(40, P)) < 0.8) & away_from_edges
    ours = np.asarray(jax.jit(jax.vmap(neural.binarised_histogram))(jnp.asarray(rgb), jnp.asarray(mask)))
    for b in range(len(rgb)):
        np.testing.assert_array_equal(ours[b], histogram_reference(rgb[b], mask[b]), err_msg=f"scene {b}")


@eqx.filter_jit
def sparse_and_dense(net, rgb, mask):
    bins, weight = neural.occupied_bins(rgb, mask)
    histogram = neural.binarised_histogram(rgb, mask)
    return jnp.zeros(2500).at[bins].add(weight), histogram, net.from_bins(bins, weight), net(histogram)


NET = neural.Mlp(jax.random.key(7), (2500, 40, 8, 2))


@eqx.filter_jit
def run(model, rgb, mask):
    """The estimator on one scene ``(P, 3)`` or a batch ``(B, P, 3)``, compiled."""
    return jax.vmap(model)(rgb, mask) if rgb.ndim == 3 else model(rgb, mask)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.floats(0.0, 1.0))
def test_sparse_first_layer_equals_dense(seed, keep):
    rng = np.random.default_rng(seed)
    # Few distinct colours repeated: the list form must count each occupied bin once.
    palette = rng.uniform(0, 1, size=(4, 3))
    rgb = jnp.asarray(palette[rng.integers(0, 4, P)], jnp.float32)
    mask = jnp.asarray(rng.uniform(size=P) < keep)
    from_list, histogram, sparse, dense = sparse_and_dense(NET, rgb, mask)
    np.testing.assert_array_equal(np.asarray(from_list), np.asarray(histogram))
    np.testing.assert_allclose(sparse, dense, atol=1e-5)


# ---------------------------------------------------------------------------------------------
# the estimator


def constant_net(rg) -> neural.Mlp:
    """A net whose output is ``rg`` whatever the input (zero weights, output bias ``rg``)."""
    net = neural.Mlp(jax.random.key(0), (2500, 8, 4, 2))
    last = net.layers[-1]
    net = eqx.tree_at(lambda n: n.layers[-1].weight, net, jnp.zeros_like(last.weight))
    return eqx.tree_at(lambda n: n.layers[-1].bias, net, jnp.asarray(rg, jnp.float32))


@pytest.mark.parametrize("rg", [(0.9, 0.5), (-0.2, 0.3), (0.5, -1.0), (2.0, 2.0), (-0.5, -0.5)])
def test_outside_prediction_is_projected_into_triangle(rg):
    model = neural.NeuralNet(net=constant_net(rg), fallback=jnp.ones(3))
    estimate = run(model, jnp.full((P, 3), 0.3), jnp.ones(P, bool))
    illuminant = np.asarray(estimate.illuminant)
    assert not bool(estimate.ok) and int(estimate.status) == Status.RELAXED
    assert np.all(illuminant > 0) and abs(illuminant.sum() - 1) < 1e-6
    expected = nearest_in_triangle(np.asarray(rg), neural.SIMPLEX_MARGIN)
    np.testing.assert_allclose(illuminant[:2], expected, atol=2e-3)


def test_inside_prediction_is_the_estimate():
    model = neural.NeuralNet(net=constant_net((0.3, 0.45)), fallback=jnp.ones(3))
    estimate = run(model, jnp.full((P, 3), 0.3), jnp.ones(P, bool))
    assert bool(estimate.ok) and int(estimate.status) == Status.ESTIMATED
    np.testing.assert_allclose(estimate.illuminant, [0.3, 0.45, 0.25], atol=1e-6)


@pytest.mark.parametrize("case", ["all masked", "all black"])
def test_empty_scene_gives_fallback_without_nan(case):
    fallback = jnp.asarray([0.7, 1.0, 0.6])
    model = neural.NeuralNet(net=NET, fallback=fallback)
    rgb = jnp.zeros((2, P, 3)) if case == "all black" else jnp.ones((2, P, 3))
    mask = jnp.ones((2, P), bool) if case == "all black" else jnp.zeros((2, P), bool)
    estimate = run(model, rgb, mask)
    assert np.all(np.isfinite(estimate.illuminant))
    np.testing.assert_allclose(estimate.illuminant, np.broadcast_to(fallback, (2, 3)))
    assert not np.any(estimate.ok) and np.all(np.asarray(estimate.status) == Status.NO_DATA)


def test_estimator_runs_under_x64_and_agrees_with_float32():
    model = neural.NeuralNet(net=NET, fallback=jnp.ones(3))
    rgb = np.random.default_rng(4).uniform(0.05, 1, size=(5, P, 3))
    mask = np.ones((5, P), bool)
    single = np.asarray(run(model, jnp.asarray(rgb, jnp.float32), jnp.asarray(mask)).illuminant)
    with jax.enable_x64(True):
        double = run(model, jnp.asarray(rgb, jnp.float64), jnp.asarray(mask)).illuminant
        assert np.all(np.isfinite(double))
    np.testing.assert_allclose(double, single, atol=1e-5)


@pytest.mark.parametrize("scale", [1e-12, 1e-6, 1e6])
def test_scaled_scenes_answer_as_the_original(scale):
    # The net's input is a chromaticity histogram, so a scene times any positive factor is the same
    # scene to it; "black" is relative to the scene's brightest pixel, as in Colour by Correlation.
    model = neural.NeuralNet(net=NET, fallback=jnp.ones(3))
    rgb = np.random.default_rng(6).uniform(0.05, 1, size=(6, P, 3)).astype(np.float32)
    rgb[0, :3] = 0.0  # black surfaces: never evidence, at any scale
    mask = np.ones((6, P), bool)
    reference = run(model, jnp.asarray(rgb), jnp.asarray(mask))
    scaled = run(model, jnp.asarray(rgb * np.float32(scale)), jnp.asarray(mask))
    histogram = jax.jit(jax.vmap(neural.binarised_histogram))
    np.testing.assert_array_equal(histogram(jnp.asarray(rgb * np.float32(scale)), mask), histogram(rgb, mask))
    assert np.all(np.asarray(scaled.status) == np.asarray(reference.status))
    assert np.all(np.asarray(reference.status) != Status.NO_DATA)
    np.testing.assert_allclose(scaled.illuminant, reference.illuminant, rtol=0, atol=1e-6)


# ---------------------------------------------------------------------------------------------
# cache, registry, CLI


def test_save_load_round_trip(cache):
    world = tiny_world()
    net = neural.Mlp(jax.random.key(5), SMALL.sizes())
    log = neural.TrainingLog(losses=[0.01], seconds=1.0)
    path = neural.save(net, world, "NEURAL-NET", SMALL, neural.Schedule(steps=1), log)
    assert path.is_file() and path.parent == cache / "neural" and path.with_suffix(".json").is_file()
    loaded = neural.load(world, "NEURAL-NET", SMALL)
    for a, b in zip(jax.tree_util.tree_leaves(net), jax.tree_util.tree_leaves(loaded)):
        np.testing.assert_array_equal(a, b)


def test_cache_key_follows_world_arrays_and_recipe():
    world = tiny_world()
    assert neural.cache_key(world, SMALL) == neural.cache_key(tiny_world(), SMALL)
    assert neural.cache_key(world, SMALL) != neural.cache_key(world, dataclasses.replace(SMALL, noise=0.02))
    changed = eqx.tree_at(lambda w: w.reflectances, world, world.reflectances * 0.99)
    assert neural.cache_key(world, SMALL) != neural.cache_key(changed, SMALL)
    # The test illuminants do not enter training, so they do not enter the key.
    other_test = eqx.tree_at(lambda w: w.test_illuminants, world, world.test_illuminants[:3])
    assert neural.cache_key(world, SMALL) == neural.cache_key(other_test, SMALL)


@pytest.mark.parametrize(
    "label, name, command",
    [
        ("NEURAL-NET", "barnard1999", "ccjax train-net --world barnard1999`"),
        ("SP-NEURAL-NET", "barnard1999", "ccjax train-net --world barnard1999 --specular`"),
        (
            "NEURAL-NET",
            "default (Canon EOS 5D Mark II)",
            'ccjax train-net --world default --camera "Canon EOS 5D Mark II"`',
        ),
    ],
)
def test_missing_weights_error_says_how_to_train(cache, label, name, command):
    world = tiny_world(name)
    registry.lookup(label)  # the label is known ...
    with pytest.raises(neural.MissingWeightsError) as error:  # ... but building it never trains
        registry.fit(label, world)
    assert isinstance(error.value, FileNotFoundError)
    assert command in str(error.value) and name in str(error.value)
    assert not weights_ready(label, world) and weights_ready("GW", world)


@pytest.mark.slow
def test_training_learns_from_the_histogram():
    world = tiny_world()
    schedule = neural.Schedule(steps=300, batch_size=32, learning_rate=1e-2)
    net, log = neural.train(world, SMALL, schedule)
    tables = SceneTables.from_world(neural.training_world(world))
    histograms, targets = neural.training_batch(jax.random.key(123), tables, SMALL, 512)
    loss = float(neural.training_loss(net, histograms, targets))
    # A net ignoring its input can do no better than the targets' variance.
    constant = float(jnp.mean(jnp.sum((targets - targets.mean(0)) ** 2, axis=-1)))
    assert loss < 0.3 * constant, (loss, constant)
    assert log.losses[-1] < 0.25 * log.losses[0]
    # Training targets are the TRAINING illuminants' chromaticities.
    train_rg = np.asarray(world.train_whites[:, :2] / world.train_whites.sum(-1, keepdims=True))
    assert np.all(np.min(np.linalg.norm(np.asarray(targets)[:, None] - train_rg[None], axis=-1), axis=1) < 1e-6)


def test_cli_train_net_saves_weights_the_registry_loads(cache, monkeypatch, capsys):
    world = tiny_world("barnard1999")
    monkeypatch.setitem(neural.RECIPES, "NEURAL-NET", SMALL)
    monkeypatch.setattr(cli.training, "build_world", lambda args: world)
    assert cli.main(["train-net", "--steps", "50", "--batch-size", "32", "--no-progress"]) == 0
    assert "saved" in capsys.readouterr().out
    assert weights_ready("NEURAL-NET", world) and not weights_ready("SP-NEURAL-NET", world)
    model = registry.fit("NEURAL-NET", world)
    estimate = run(model, world.camera.response(world.reflectances[:8] * world.train_illuminants[0]), jnp.ones(8, bool))
    assert np.all(np.isfinite(estimate.illuminant)) and abs(float(estimate.illuminant.sum()) - 1) < 1e-6
    assert cli.main(["train-net", "--steps", "0", "--no-progress"]) == 2  # invalid budget: clean error


# ---------------------------------------------------------------------------------------------
# the thesis' numbers (slow: trains the full net)


@pytest.mark.slow
@pytest.mark.external_data
def test_trained_net_reproduces_table_4_2(barnard_world, cache):
    from ccjax import experiments, thesis

    neural.train_and_save(barnard_world, "NEURAL-NET")
    result = experiments.reproduce("4.2", barnard_world, ["NEURAL-NET"], 1000, jax.random.key(0), progress=False)
    for row in result.rows:
        assert abs(row["relative_difference"]) <= 0.15, row
    assert {row["column"] for row in result.rows} == set(thesis.TABLES["4.2"]["NEURAL-NET"])


# ---------------------------------------------------------------------------------------------
# the log-chroma histogram baseline (beyond the thesis)


def log_chroma_reference(rgb: np.ndarray, mask: np.ndarray, bins: int = 32, extent: float = 2.0) -> np.ndarray:
    """sqrt of the normalised histogram of (log G/R, log G/B) by a plain loop (edge bins clamp; a
    surface counts when every channel is above 1e-12 of the brightest masked channel)."""
    counts, total = np.zeros(bins * bins), 0
    brightest = max([float(np.max(x)) for x, valid in zip(rgb, mask) if valid] or [0.0])
    for (red, green, blue), valid in zip(rgb.astype(np.float64), mask):
        if not valid or min(red, green, blue) <= 1e-12 * brightest or brightest == 0:
            continue
        u, v = np.log(green / red), np.log(green / blue)
        i = min(max(int(np.floor((u + extent) / (2 * extent) * bins)), 0), bins - 1)
        j = min(max(int(np.floor((v + extent) / (2 * extent) * bins)), 0), bins - 1)
        counts[i * bins + j] += 1
        total += 1
    return np.sqrt(counts / max(total, 1))


def test_log_chroma_histogram_matches_loop_reference():
    rng = np.random.default_rng(4)
    rgb = rng.uniform(0.0, 1.0, (40, 3)) ** 3  # wide log-chroma range, some beyond the edges
    rgb[3] = 0.0
    mask = rng.random(40) < 0.8
    got = neural.log_chroma_histogram(jnp.asarray(rgb, jnp.float32), jnp.asarray(mask))
    np.testing.assert_allclose(got, log_chroma_reference(rgb, mask), atol=1e-6)


@pytest.mark.parametrize("scale", [1.0, 1e-12, 1e6])
def test_log_chroma_histogram_is_scale_free(scale):
    rng = np.random.default_rng(5)
    rgb = rng.uniform(0.01, 1.0, (40, 3))
    rgb[3] = 0.0
    rgb[5, 2] = 0.0  # one zero channel: no log-chroma
    mask = rng.random(40) < 0.8
    got = neural.log_chroma_histogram(jnp.asarray(rgb * scale, jnp.float32), jnp.asarray(mask))
    np.testing.assert_allclose(got, log_chroma_reference(rgb, mask), atol=1e-6)


@pytest.mark.slow
def test_log_chroma_net_starts_grey_and_trains(default_world):
    from ccjax import losses, training

    model = registry.fit("log-chroma-mlp", default_world)
    rgb = jnp.asarray(np.random.default_rng(0).uniform(0.1, 1.0, (4, 16, 3)), jnp.float32)
    mask = jnp.ones((4, 16), bool)
    estimate = jax.vmap(model)(rgb, mask)
    np.testing.assert_allclose(estimate.illuminant, 1 / 3, rtol=1e-6)
    empty = model(rgb[0], jnp.zeros(16, bool))
    assert not bool(empty.ok) and np.all(np.isfinite(empty.illuminant))
    spec = training.learnable(model)
    params, static = eqx.partition(model, spec)
    truth = jnp.asarray([[0.5, 0.3, 0.2]] * 4, jnp.float32)
    grads = jax.grad(lambda p: losses.angular_loss(jax.vmap(eqx.combine(p, static))(rgb, mask).illuminant, truth))(
        params
    )
    norm = sum(float(jnp.sum(g**2)) for g in jax.tree_util.tree_leaves(grads))
    assert np.isfinite(norm) and norm > 0
