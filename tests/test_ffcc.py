"""FFCC (Barron & Tsai 2017) against independent NumPy references (tests/ffcc_oracle.py): the
edge channel, the wrapped histogram, the Fourier-domain convolution, the von Mises fit; the
preconditioned regulariser against its spatial definition (total variation and L2, by Parseval);
gradients of the training objective by finite differences (x64); training on synthetic scenes."""

from __future__ import annotations

import equinox as eqx
import ffcc_oracle as oracle
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from ccjax import metrics, training
from ccjax.estimators import registry
from ccjax.estimators.base import estimate_batch
from ccjax.estimators.ffcc import (
    FFCC,
    Hyperparameters,
    block_means,
    choose,
    convolve,
    featurize,
    fit_von_mises,
    init_ffcc,
    local_absolute_deviation,
    train,
    wrapped_histogram,
)
from ccjax.estimators.ffcc._fitting import from_latent, loss, preconditioner
from ccjax.runs import store


def _image(seed: int, height: int = 7, width: int = 9):
    rng = np.random.default_rng(seed)
    image = rng.uniform(0.001, 1.0, (height, width, 3)).astype(np.float32)
    mask = rng.uniform(size=(height, width)) > 0.25
    return image, mask


def test_local_absolute_deviation_matches_oracle():
    image, mask = _image(0)
    got = np.asarray(local_absolute_deviation(jnp.asarray(image), jnp.asarray(mask)))
    np.testing.assert_allclose(got, oracle.local_absolute_deviation(image, mask), rtol=1e-5, atol=1e-7)


def test_wrapped_histogram_matches_oracle():
    rng = np.random.default_rng(1)
    # Log-chromas spread over 3 times the grid's range, so many wrap around the torus.
    rgb = np.exp(rng.uniform(-3.0, 3.0, (400, 3))).astype(np.float32)
    valid = rng.uniform(size=400) > 0.2
    origin = np.array([-0.3, 0.1], np.float32)
    got = np.asarray(wrapped_histogram(jnp.asarray(rgb), jnp.asarray(valid), jnp.asarray(origin), 16, 0.125))
    np.testing.assert_allclose(got, oracle.histogram(rgb, valid, origin, 16, 0.125), atol=1e-6)
    assert got.sum() == pytest.approx(1.0, abs=1e-5)


def test_wrapped_histograms_of_a_stack_match_oracle_one_by_one():
    rng = np.random.default_rng(11)
    rgb = np.exp(rng.uniform(-2.0, 2.0, (2, 3, 50, 3))).astype(np.float32)
    valid = rng.uniform(size=(2, 3, 50)) > 0.3
    valid[1, 2] = False  # a stack entry with nothing valid stays all zeros
    origin = np.array([0.2, -0.4], np.float32)
    got = np.asarray(wrapped_histogram(jnp.asarray(rgb), jnp.asarray(valid), jnp.asarray(origin), 8, 0.25))
    assert got.shape == (2, 3, 8, 8)
    for i in range(2):
        for j in range(3):
            np.testing.assert_allclose(got[i, j], oracle.histogram(rgb[i, j], valid[i, j], origin, 8, 0.25), atol=1e-6)


def test_blocked_batch_estimates_equal_one_image_at_a_time():
    """estimate_batch's blocks (the CPU block is 128 images) give each image's own answer."""
    rng = np.random.default_rng(12)
    model = eqx.tree_at(
        lambda m: (m.filters, m.bias),
        init_ffcc(),
        (jnp.asarray(rng.normal(size=(2, 64, 64)), jnp.float32), jnp.asarray(rng.normal(size=(64, 64)), jnp.float32)),
    )
    images = jnp.asarray(rng.uniform(0.01, 1.0, (130, 6, 5, 3)), jnp.float32)
    masks = jnp.asarray(rng.uniform(size=(130, 6, 5)) > 0.2)
    batched = estimate_batch(model, images, masks).illuminant
    for i in (0, 77, 129):
        np.testing.assert_allclose(np.asarray(batched[i]), np.asarray(model(images[i], masks[i]).illuminant), rtol=1e-5)


def test_featurize_counts_pixels_and_edges_above_the_minimum():
    image, mask = _image(2)
    origin = np.array([-1.0, -1.0], np.float32)
    got = np.asarray(
        featurize(
            jnp.asarray(image), jnp.asarray(mask), origin=jnp.asarray(origin), bins=16, bin_size=0.125, minimum=0.05
        )
    )
    edges = oracle.local_absolute_deviation(image, mask)
    for channel, values in enumerate((image.astype(np.float64), edges)):
        rgb = values.reshape(-1, 3)
        valid = mask.reshape(-1) & np.all(rgb >= 0.05, axis=-1)
        np.testing.assert_allclose(got[channel], oracle.histogram(rgb, valid, origin, 16, 0.125), atol=1e-6)


def test_fourier_convolution_matches_direct_periodic_convolution():
    rng = np.random.default_rng(3)
    histogram = rng.uniform(size=(2, 8, 8)).astype(np.float32)
    filters = rng.normal(size=(2, 8, 8)).astype(np.float32)
    bias = rng.normal(size=(8, 8)).astype(np.float32)
    got = np.asarray(convolve(jnp.asarray(histogram), jnp.asarray(filters), jnp.asarray(bias)))
    want = sum(oracle.periodic_convolution(histogram[c], filters[c]) for c in range(2)) + bias
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize("seed", [4, 5, 6])
def test_von_mises_fit_matches_oracle(seed):
    rng = np.random.default_rng(seed)
    n = 16
    # A peaked PMF near a random bin (wrapping around the edges) on a random floor.
    centre = rng.uniform(0, n, 2)
    i = np.arange(n)
    d = [((i - c + n / 2) % n) - n / 2 for c in centre]
    probability = np.exp(
        -0.5 * (d[0][:, None] ** 2 / 2.0 + d[1][None, :] ** 2 / 3.0 - d[0][:, None] * d[1][None, :] / 4)
    )
    probability += 0.01 * rng.uniform(size=(n, n))
    probability /= probability.sum()
    mean, covariance = fit_von_mises(jnp.asarray(probability, jnp.float32), 1.0)
    want_mean, want_covariance = oracle.von_mises_fit(probability, 1.0)
    np.testing.assert_allclose(np.asarray(mean), want_mean, atol=2e-4)
    np.testing.assert_allclose(np.asarray(covariance), want_covariance, rtol=1e-4, atol=1e-4)


def test_von_mises_mean_of_a_point_mass_is_its_bin():
    probability = np.zeros((16, 16), np.float32)
    probability[13, 2] = 1.0
    mean, covariance = fit_von_mises(jnp.asarray(probability), 0.5)
    np.testing.assert_allclose(np.asarray(mean), [13.0, 2.0], atol=1e-4)
    np.testing.assert_allclose(np.asarray(covariance), 0.5 * np.eye(2), atol=1e-5)


def test_preconditioned_regulariser_is_total_variation_plus_l2():
    """||z||^2 = n^2 (tv sum |periodic differences of F|^2 / 8 + l2 sum F^2) (Parseval)."""
    rng = np.random.default_rng(7)
    n, tv, l2 = 8, 0.3, 0.02
    latent = rng.normal(size=(n, n)).astype(np.float32)
    field = np.asarray(from_latent(jnp.asarray(latent), preconditioner(n, tv, l2)), np.float64)
    differences = np.sum((np.roll(field, -1, 0) - field) ** 2) + np.sum((np.roll(field, -1, 1) - field) ** 2)
    spatial = n**2 * (tv * differences / 8 + l2 * np.sum(field**2))
    assert spatial == pytest.approx(float(np.sum(latent.astype(np.float64) ** 2)), rel=1e-4)


@pytest.mark.slow
def test_training_objective_gradients_x64():
    rng = np.random.default_rng(8)
    n = 8
    with jax.enable_x64(True):
        histograms = rng.uniform(size=(3, 2, n, n))
        histograms /= histograms.sum(axis=(2, 3), keepdims=True)
        histogram_fft = jnp.fft.rfft2(jnp.asarray(histograms))
        truth = jnp.asarray(rng.uniform(1, n - 2, (3, 2)))
        scales = (jnp.stack([preconditioner(n, 0.1, 0.01)] * 2), preconditioner(n, 0.2, 0.01))
        latent = (jnp.asarray(rng.normal(size=(2, n, n)) * 0.3), jnp.asarray(rng.normal(size=(n, n)) * 0.3))
        weights = jnp.asarray([0.3, 0.5, 0.2])

        def objective(filters, bias):
            return loss((jnp.asarray(filters), jnp.asarray(bias)), scales, histogram_fft, truth, weights, 1.0, 0.125)

        assert np.isfinite(float(objective(*latent)))
        check_grads(jax.jit(objective), latent, order=1, modes=["rev"], eps=1e-6)


def _synthetic_scenes(seed: int, count: int, size: int = 12):
    """Mondrians under lights along a locus; every scene's reflectances lean the same way (a
    greenish world), so the grey world is biased and FFCC can learn the bias from examples."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(-1, 1, count)
    lights = np.stack([np.exp(0.5 * t), np.full(count, 1.6), np.exp(-0.5 * t) * 1.1], axis=1)
    tint = np.array([0.7, 1.0, 0.5]) * np.exp(rng.normal(0, 0.05, (count, 1, 1, 3)))
    patches = rng.uniform(0.05, 0.9, (count, 4, 4, 3)) * tint
    reflectance = np.repeat(np.repeat(patches, size // 4, axis=1), size // 4, axis=2)
    images = (reflectance * lights[:, None, None, :] * 0.4).clip(0, 1).astype(np.float32)
    return images, np.ones(images.shape[:3], bool), lights.astype(np.float32)


@pytest.mark.parametrize("block", [1, 2, 3])
def test_block_means_match_oracle(block):
    """7 x 9 is no multiple of 2 or 3: the edge tiles average the pixels they have; a tile with no
    usable pixel is unusable."""
    image, mask = _image(5)
    mask[:3, :3] = False  # a whole 2 x 2 and 3 x 3 tile unusable
    means, usable = block_means(jnp.asarray(image), jnp.asarray(mask), block)
    expected, expected_usable = oracle.block_means(image, mask, block)
    np.testing.assert_array_equal(np.asarray(usable), expected_usable)
    np.testing.assert_allclose(np.asarray(means)[expected_usable], expected[expected_usable], rtol=1e-6)
    with pytest.raises(ValueError, match="pool"):
        init_ffcc(pool=0)


def test_pooled_model_histograms_block_means_and_keeps_its_pool(default_world, tmp_path):
    """``FFCC-pool2`` histograms the 2 x 2 block means (pixels and their edges); training (here
    without iterations) and a model file keep the pool."""
    image, mask = _image(6)
    model = registry.fit("FFCC-pool2", default_world)
    assert isinstance(model, FFCC) and model.pool == 2
    means, usable = oracle.block_means(image, mask, 2)
    edges = oracle.local_absolute_deviation(means, usable)
    got = np.asarray(model.histogram(jnp.asarray(image), jnp.asarray(mask)))
    for channel, values in enumerate((means, edges)):
        rgb = values.reshape(-1, 3)
        valid = usable.reshape(-1) & np.all(rgb >= model.minimum, axis=-1)
        np.testing.assert_allclose(
            got[channel], oracle.histogram(rgb, valid, np.asarray(model.origin), 64, 1 / 32), atol=1e-6
        )
    images, masks, lights = _synthetic_scenes(13, 8)
    trained, _ = train(model, images, masks, lights, Hyperparameters(pretrain_iterations=0, iterations=0))
    assert trained.pool == 2
    path = store.save_trained(tmp_path / "ffcc.eqx", trained, label="FFCC-pool2", camera=None)
    assert store.load_model(path).pool == 2


@pytest.mark.slow  # over 30 s on 2 cores: the default run stays under 10 minutes
def test_training_on_synthetic_scenes_beats_grey_world(tmp_path, default_world):
    """Trained through the training layer's dispatch (L-BFGS, not the Adam loop), saved and read
    back as a model file."""
    images, masks, lights = _synthetic_scenes(9, 200)
    start = registry.fit("FFCC", default_world)
    examples = training.Examples(jnp.asarray(images[:160]), jnp.asarray(masks[:160]), jnp.asarray(lights[:160]))
    model, log = training.train_model(start, examples, progress=False)
    assert isinstance(model, FFCC) and len(log.train_loss) == 2 and all(np.isfinite(log.train_loss))
    test_images, test_masks = jnp.asarray(images[160:]), jnp.asarray(masks[160:])
    estimate = jax.vmap(model)(test_images, test_masks)
    errors = np.asarray(metrics.angular_error(estimate.illuminant, jnp.asarray(lights[160:])))
    grey = images[160:].reshape(40, -1, 3).mean(axis=1)
    grey_errors = np.asarray(metrics.angular_error(jnp.asarray(grey), jnp.asarray(lights[160:])))
    assert np.all(np.isfinite(errors)) and bool(jnp.all(estimate.ok))
    assert np.median(errors) < 0.7 * np.median(grey_errors)
    posterior = jax.vmap(model.posterior)(test_images, test_masks)
    assert np.all(np.linalg.eigvalsh(np.asarray(posterior.covariance)) > 0)
    assert np.all((np.asarray(posterior.confidence) > 0) & (np.asarray(posterior.confidence) <= 1 + 1e-6))
    path = store.save_trained(tmp_path / "ffcc.eqx", model, label="FFCC", camera="Canon EOS 5D Mark II")
    loaded = store.load_model(path)
    again = jax.vmap(loaded)(test_images, test_masks)
    np.testing.assert_allclose(np.asarray(again.illuminant), np.asarray(estimate.illuminant), rtol=1e-6)


@pytest.mark.slow  # over 30 s on 2 cores: the default run stays under 10 minutes
def test_choose_keeps_the_candidate_that_validates_better_in_either_order():
    """An untrained candidate (no L-BFGS iteration: a uniform distribution) loses to a trained one
    within the training images, whichever comes first; too few images give the first, unscored."""
    images, masks, lights = _synthetic_scenes(10, 40)
    untrained = Hyperparameters(pretrain_iterations=0, iterations=0)
    trained = Hyperparameters()
    for candidates in ((untrained, trained), (trained, untrained)):
        chosen, scores = choose(init_ffcc(), images, masks, lights, candidates)
        assert chosen is trained and len(scores) == 2 and all(np.isfinite(scores))
        assert scores[candidates.index(trained)] < 0.7 * scores[candidates.index(untrained)]
    chosen, scores = choose(init_ffcc(), images[:7], masks[:7], lights[:7], (untrained, trained))
    assert chosen is untrained and scores == []


def test_registry_builds_an_untrained_image_estimator_and_no_data_is_flagged(default_world):
    model = registry.fit("FFCC", default_world)
    assert isinstance(model, FFCC) and model.input_kind == "image"
    trained = eqx.tree_at(
        lambda m: m.bias, model, jnp.asarray(np.random.default_rng(0).normal(size=(64, 64)), jnp.float32)
    )
    estimate = trained(jnp.zeros((8, 8, 3), jnp.float32), jnp.ones((8, 8), bool))
    assert not bool(estimate.ok) and np.all(np.isfinite(np.asarray(estimate.illuminant)))


def test_training_sets_are_padded_to_few_sizes_and_small_ones_stay_small():
    from ccjax.estimators.ffcc._fitting import PAD, padded_count

    # Closed form: the next power of two (at least 8) below PAD, then multiples of PAD.
    expected = {1: 8, 8: 8, 9: 16, 12: 16, 24: 32, 100: 128, 127: 128, 128: 128, 129: 256, 1140: 1152}
    assert PAD == 128
    assert {count: padded_count(count) for count in expected} == expected
    sizes = {padded_count(count) for count in range(1, 2049)}
    assert len(sizes) == 5 + 15  # 8, 16, 32, 64, 128 and 256 ... 2048


def test_a_window_of_lights_sets_the_grid_so_that_each_of_them_lies_inside_the_torus():
    """``window``: lights outside the training lights' range get a grid that holds them without
    wrapping (bin size doubled until the union fills at most 3/4 of the width, centred on it); the
    grid of the training lights alone wraps them. Checked in log-chroma by hand, not by the
    trainer's helpers."""
    images, masks, lights = _synthetic_scenes(13, 8)
    # Far from the training lights: a deep red and a deep blue light.
    window = np.array([[1.0, 0.25, 0.08], [0.3, 0.8, 1.0]], np.float32)
    no_iterations = Hyperparameters(pretrain_iterations=0, iterations=0)
    plain, _ = train(init_ffcc(), images, masks, lights, no_iterations)
    wide, _ = train(init_ffcc(), images, masks, lights, no_iterations, window=window)

    def uv(rgb):
        rgb = np.asarray(rgb, np.float64)
        return np.stack([np.log(rgb[:, 1] / rgb[:, 0]), np.log(rgb[:, 1] / rgb[:, 2])], axis=1)

    held = np.concatenate([uv(lights), uv(window)])
    span = held.max(axis=0) - held.min(axis=0)
    size = 1 / 32
    while span.max() > 0.75 * 64 * size:
        size *= 2
    assert float(wide.bin_size) == size > float(plain.bin_size)
    bins = (held - np.asarray(wide.origin, np.float64)) / float(wide.bin_size)
    assert np.all(bins >= 0) and np.all(bins < 64)
    outside = (uv(window) - np.asarray(plain.origin, np.float64)) / float(plain.bin_size)
    assert np.any((outside < 0) | (outside >= 64))
    with pytest.raises(ValueError, match="window"):
        train(init_ffcc(), images, masks, lights, no_iterations, window=-window)
