"""Colour by Correlation (2-D §4.5.4, 3-D chapter 10) against the NumPy loop oracle in
``tests/correlation_oracle.py``, gradient checks of the soft variants, properties and labels.

Everything but the thesis-number comparison runs on the embedded default world."""

from __future__ import annotations

import dataclasses

import correlation_oracle as oracle
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from jax.test_util import check_grads

from ccjax import metrics, scenes
from ccjax.estimators import correlation, registry

N_SCENES = 100


@pytest.fixture(scope="module", autouse=True)
def _private_cache(tmp_path_factory):
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("CCJAX_CACHE", str(tmp_path_factory.mktemp("ccjax-cache")))
        yield


@pytest.fixture(scope="module")
def spectra(default_world):
    world = default_world
    return (
        np.asarray(world.reflectances, np.float64),
        np.asarray(world.train_illuminants, np.float64),
        np.asarray(world.camera.sensors, np.float64),
    )


@pytest.fixture(scope="module")
def batch(default_world):
    return scenes.sample(jax.random.key(11), default_world, N_SCENES, 8)


@pytest.fixture(scope="module")
def illuminant_rg(spectra):
    _, lights, sensors = spectra
    whites = lights @ sensors
    return whites[:, :2] / whites.sum(axis=1, keepdims=True)


@pytest.fixture(scope="module")
def oracle_2d(spectra):
    return oracle.chromaticity_log_probability(*spectra, sigma=1.0, floor=1e-6)


@pytest.fixture(scope="module")
def oracle_3d(spectra):
    return oracle.brightness_log_probability(*spectra, l_bins=50, sigma=0.75, sigma_l=0.5, floor=1e-6)


def as64(model):
    return jax.tree.map(lambda x: x.astype(jnp.float64) if jnp.issubdtype(x.dtype, jnp.floating) else x, model)


@eqx.filter_jit
def run(model, rgb, mask):
    """One compiled runner per (model structure, shape): a scene ``(P, 3)`` or a batch."""
    return jax.vmap(model)(rgb, mask) if rgb.ndim == 3 else model(rgb, mask)


def compact_to_dense(matrix: np.ndarray, l_total: int) -> np.ndarray:
    """The documented 3-D layout -> ``(I, 50, 50, l_total)`` (impossible bins at NaN)."""
    n_lights = matrix.shape[1]
    dense = np.full((n_lights, 50, 50, l_total), np.nan)
    row = 0
    for i in range(50):
        for j in range(50 - i):
            dense[:, i, j, :] = matrix[row * l_total : (row + 1) * l_total].T
            row += 1
    assert row * l_total + 1 == matrix.shape[0]
    return dense


# -- matrices --------------------------------------------------------------------------------------


def test_chromaticity_matrix_matches_oracle(default_world, oracle_2d):
    ours = correlation.chromaticity_matrix(default_world, sigma=1.0, floor=1e-6)
    reference = oracle_2d.reshape(len(oracle_2d), -1).T
    assert ours.shape == reference.shape == (2500, default_world.train_illuminants.shape[0])
    np.testing.assert_allclose(ours, reference, atol=2e-5, rtol=0)


def test_brightness_matrix_matches_oracle(default_world, oracle_3d):
    matrix, l_total = correlation.brightness_matrix(default_world)
    assert l_total == 50
    dense = compact_to_dense(matrix, l_total)
    possible = np.add.outer(np.arange(50), np.arange(50)) <= 49
    np.testing.assert_allclose(dense[:, possible], oracle_3d[:, possible], atol=2e-5, rtol=0)
    floor = oracle_3d.reshape(len(oracle_3d), -1).min(axis=1)
    np.testing.assert_allclose(matrix[-1], floor, atol=2e-5, rtol=0)


def test_specular_brightness_matrix_matches_oracle(default_world, spectra):
    few = slice(0, 3)  # three illuminants keep the loop oracle quick
    world = dataclasses.replace(default_world, train_illuminants=default_world.train_illuminants[few])
    reflectances, lights, sensors = spectra
    reference = oracle.brightness_log_probability(reflectances, lights[few], sensors, specular=(0.25, 2.0))
    matrix, l_total = correlation.brightness_matrix(world, specular=scenes.Specular())
    assert l_total == 150
    possible = np.add.outer(np.arange(50), np.arange(50)) <= 49
    np.testing.assert_allclose(
        compact_to_dense(matrix, l_total)[:, possible], reference[:, possible], atol=2e-5, rtol=0
    )


def test_fluorescent_chromaticity_matrix_matches_oracle(default_world, spectra):
    """FL training (§7.2, A20): the characterised fluorescent surfaces join the counts with a
    weight that makes them 15 % of the occurrences; the oracle adds them bin by bin."""
    from ccjax.estimators.gamut._extensions import characterised_fluorescents

    few = slice(0, 3)
    world = dataclasses.replace(default_world, train_illuminants=default_world.train_illuminants[few])
    reflectances, lights, sensors = spectra
    emitted = np.asarray(characterised_fluorescents(world).radiance(lights[few]), np.float64) @ sensors
    n_s, n_f = len(reflectances), emitted.shape[1]
    weight = 0.15 * n_s / (0.85 * n_f)  # w F / (w F + S) = 0.15
    reference = []
    for light, fluorescent in zip(lights[few], emitted):
        counts = np.zeros((50, 50))
        np.add.at(counts, oracle.rg_bins(oracle.responses(reflectances, light, sensors)), 1.0)
        np.add.at(counts, oracle.rg_bins(fluorescent), weight)
        counts = oracle.smooth_axis(oracle.smooth_axis(counts, 0, 1.0), 1, 1.0)
        p = counts / counts.sum()
        reference.append(np.log(np.maximum(p, 1e-6 * p.max())).ravel())
    ours = correlation.chromaticity_matrix(world, sigma=1.0, floor=1e-6, fluorescent=0.15)
    np.testing.assert_allclose(ours, np.stack(reference).T, atol=2e-5, rtol=0)
    matte = correlation.chromaticity_matrix(world, sigma=1.0, floor=1e-6)
    assert np.max(np.abs(ours - matte)) > 1.0  # the fluorescent bins gained probability
    rgb, weights, _ = correlation.training_responses(world, fluorescent=0.15)
    assert rgb.shape[1] == n_s + n_f and abs(weights[n_s:].sum() / weights.sum() - 0.15) < 1e-12


def test_fluorescent_labels(default_world):
    few = dataclasses.replace(default_world, train_illuminants=default_world.train_illuminants[:3])
    for label, kind in (
        ("FL-C-by-C-MMSE", correlation.ColourByCorrelation),
        ("FL-C-by-C-MAP", correlation.ColourByCorrelation),
        ("FL-RGB-C-by-C-MAP-counts", correlation.ColourByCorrelation3D),
        ("FL-RGB-C-by-C-MMSE-counts", correlation.ColourByCorrelation3D),
        ("FL-SPEC-RGB-C-by-C-MMSE", correlation.ColourByCorrelation3D),
    ):
        model = registry.fit(label, few)
        assert isinstance(model, kind), label
        out = jax.vmap(model)(jnp.zeros((2, 4, 3)), jnp.asarray([[True] * 4, [False] * 4]))
        assert np.all(np.isfinite(np.asarray(out.illuminant))) and not np.any(np.asarray(out.ok)), label
    fl = registry.fit("FL-C-by-C-MMSE", few)
    matte = registry.fit("C-by-C-MMSE", few)
    assert np.max(np.abs(np.asarray(fl.log_probability) - np.asarray(matte.log_probability))) > 1.0
    with pytest.raises(ValueError, match="fluorescent"):
        registry.fit("C-by-C-MMSE", few, fluorescent=1.5)


@pytest.fixture(scope="module")
def oracle_hull(spectra):
    return oracle.hull_compatibility(*spectra)


def test_hull_matrix_matches_oracle(default_world, oracle_hull):
    ours = correlation.hull_matrix(default_world)
    reference = oracle_hull
    assert np.array_equal(ours, reference.reshape(len(reference), -1).T)


# -- estimates on 100 scenes -----------------------------------------------------------------------


@pytest.mark.parametrize("selector", ["MAP", "MMSE", "MLM"])
def test_chromaticity_estimates_match_oracle(default_world, batch, oracle_2d, illuminant_rg, selector):
    options = {"mlm_width": 2.0} if selector == "MLM" else {}  # the width search is tested below
    model = registry.fit(f"C-by-C-{selector}", default_world, **options)
    rgb, mask = np.asarray(batch.rgb, np.float64), np.asarray(batch.mask)
    with jax.enable_x64(True):
        model64 = as64(model)
        posterior = np.exp(run(eqx.Partial(type(model64).log_posterior, model64), jnp.asarray(rgb), jnp.asarray(mask)))
        estimate = np.asarray(run(model64, jnp.asarray(rgb), jnp.asarray(mask)).illuminant)
    for k in range(N_SCENES):
        np.testing.assert_allclose(posterior[k], oracle.posterior_2d(oracle_2d, rgb[k], mask[k]), atol=1e-5, rtol=0)
        rg, index = oracle.estimate_2d(selector, oracle_2d, illuminant_rg, rgb[k], mask[k], mlm_width=model.mlm_width)
        if index is None:
            np.testing.assert_allclose(estimate[k, :2], rg, atol=1e-5)
        else:
            assert np.array_equal(estimate[k, :2], illuminant_rg[index].astype(np.float32).astype(np.float64)), k


def test_hull_estimates_match_oracle(default_world, batch, oracle_hull, illuminant_rg):
    model = registry.fit("C-by-C-01", default_world)
    compatible = oracle_hull
    estimate = np.asarray(run(model, batch.rgb, batch.mask).illuminant)
    rgb, mask = np.asarray(batch.rgb, np.float64), np.asarray(batch.mask)
    for k in range(N_SCENES):
        np.testing.assert_allclose(
            estimate[k, :2], oracle.estimate_01(compatible, illuminant_rg, rgb[k], mask[k]), atol=1e-6
        )


def _check_brightness_against_oracle(world, batch, log_p, illuminant_rg, method, references):
    rgb, mask = np.asarray(batch.rgb, np.float64), np.asarray(batch.mask)
    outputs = {}
    with jax.enable_x64(True):
        for selector in ("MAP", "MMSE"):
            model = as64(correlation.fit_brightness(world, selector, method=method))
            outputs[selector] = np.asarray(run(model, jnp.asarray(rgb), jnp.asarray(mask)).illuminant)
        log_posterior = eqx.Partial(type(model).log_posterior, model)
        posteriors = np.exp(np.asarray(run(log_posterior, jnp.asarray(rgb), jnp.asarray(mask))))
    for k in range(N_SCENES):
        reference, levels = references[k] if references else oracle.posterior_3d(log_p, rgb[k], mask[k], method=method)
        np.testing.assert_allclose(posteriors[k], reference, atol=1e-5, rtol=0)
        best, _ = oracle.estimate_from_posterior_3d("MAP", reference, levels, illuminant_rg)
        np.testing.assert_allclose(outputs["MAP"][k], best, rtol=1e-6)  # same level and illuminant
        mean, _ = oracle.estimate_from_posterior_3d("MMSE", reference, levels, illuminant_rg)
        np.testing.assert_allclose(outputs["MMSE"][k], mean, rtol=1e-5)


@pytest.fixture(scope="module")
def oracle_3d_posteriors(batch, oracle_3d):
    rgb, mask = np.asarray(batch.rgb, np.float64), np.asarray(batch.mask)
    return [oracle.posterior_3d(oracle_3d, rgb[k], mask[k], method="presence") for k in range(N_SCENES)]


def test_brightness_estimates_match_oracle(default_world, batch, oracle_3d, illuminant_rg, oracle_3d_posteriors):
    """Remedy 2 (presence, the default): same MAP (level, illuminant), posterior within 1e-5."""
    _check_brightness_against_oracle(default_world, batch, oracle_3d, illuminant_rg, "presence", oracle_3d_posteriors)


@pytest.mark.slow
def test_brightness_counts_estimates_match_oracle(default_world, batch, oracle_3d, illuminant_rg):
    """Remedy 1 (duplicate counts, Table 10.1)."""
    _check_brightness_against_oracle(default_world, batch, oracle_3d, illuminant_rg, "counts", None)


def test_float32_agrees_with_oracle(default_world, batch, illuminant_rg, oracle_3d_posteriors):
    """The default float32 kernels: MMSE within 2e-4 in (r,g) on at least 98 of 100 scenes (a level
    boundary can fall between the float32 and float64 brightness of a pixel)."""
    estimate = run(registry.fit("RGB-C-by-C-MMSE", default_world), batch.rgb, batch.mask).illuminant
    reference = np.stack(
        [oracle.estimate_from_posterior_3d("MMSE", p, b, illuminant_rg)[0] for p, b in oracle_3d_posteriors]
    )
    distance = np.asarray(metrics.rg_error(estimate, jnp.asarray(reference, jnp.float32)))
    assert np.sum(distance < 2e-4) >= 98, np.sort(distance)[-5:]


# -- soft variants ---------------------------------------------------------------------------------

SOFT = {"softness": correlation.DEFAULT_SOFTNESS, "temperature": correlation.DEFAULT_TEMPERATURE}


@pytest.mark.parametrize(
    "label",
    [
        "C-by-C-MMSE",
        "RGB-C-by-C-MMSE",
        pytest.param("C-by-C-MAP", marks=pytest.mark.slow),
        pytest.param("RGB-C-by-C-MAP", marks=pytest.mark.slow),
    ],
)
def test_soft_estimate_close_to_hard(default_world, batch, label):
    """At the temperature of the gradient checks, the soft estimate's median (r,g) distance to the
    hard one over 100 scenes is below 0.005."""
    hard = registry.fit(label, default_world)
    soft = registry.fit(f"soft-{label}", default_world, **SOFT)
    distance = metrics.rg_error(
        run(soft, batch.rgb, batch.mask).illuminant, run(hard, batch.rgb, batch.mask).illuminant
    )
    assert float(jnp.median(distance)) < 0.005


@pytest.mark.parametrize("label", ["soft-C-by-C-MMSE", pytest.param("soft-RGB-C-by-C-MMSE", marks=pytest.mark.slow)])
def test_soft_gradients(default_world, batch, label):
    """check_grads (x64) with respect to the input RGB and the matrix, at the soft-vs-hard settings."""
    model = registry.fit(label, default_world, **SOFT)
    with jax.enable_x64(True):
        direction = jnp.array([0.3, -0.5, 0.2], jnp.float64)
        model64 = as64(model)
        rgb, mask = jnp.asarray(batch.rgb[0], jnp.float64), batch.mask[0]

        @jax.jit
        def of_rgb(x):
            return model64(x, mask).illuminant @ direction

        @jax.jit
        def of_matrix(matrix):
            return dataclasses.replace(model64, log_probability=jnp.asarray(matrix))(rgb, mask).illuminant @ direction

        check_grads(of_rgb, (rgb,), order=1, modes=("rev",), eps=1e-6, atol=1e-5, rtol=1e-4)
        check_grads(of_matrix, (model64.log_probability,), order=1, modes=("rev",), eps=1e-6, atol=1e-5, rtol=1e-4)
        assert float(jnp.linalg.norm(jax.grad(of_rgb)(rgb))) > 1e-3
        assert float(jnp.linalg.norm(jax.grad(of_matrix)(model64.log_probability))) > 1e-4


# -- properties ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def models(default_world):
    labels = ["C-by-C-MMSE", "C-by-C-01", "RGB-C-by-C-MMSE"]
    return {label: registry.fit(label, default_world) for label in labels}


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_permutation_and_padding_invariance(models, batch, seed):
    """Reordering each scene's surfaces and appending masked ones changes nothing (every example
    reuses the same two compiled shapes, 8 and 12 surfaces)."""
    rng = np.random.default_rng(seed)
    order = np.argsort(rng.random((N_SCENES, 8)), axis=1)
    shuffled = np.take_along_axis(np.asarray(batch.rgb), order[..., None], axis=1)
    padded = jnp.concatenate(
        [jnp.asarray(shuffled), jnp.asarray(rng.uniform(0, 1, (N_SCENES, 4, 3)), jnp.float32)], axis=1
    )
    padded_mask = jnp.concatenate([batch.mask, jnp.zeros((N_SCENES, 4), bool)], axis=1)
    for label, model in models.items():
        a, b = run(model, batch.rgb, batch.mask).illuminant, run(model, padded, padded_mask).illuminant
        np.testing.assert_allclose(a, b, rtol=1e-5, err_msg=label)


def test_scale(models, batch):
    """Chromaticity methods ignore the scale; the 3-D method's estimate scales with the input (a
    power of two changes no bin)."""
    for label, model in models.items():
        a = run(model, batch.rgb, batch.mask).illuminant
        b = run(model, 2.0 * batch.rgb, batch.mask).illuminant
        factor = 2.0 if label.startswith("RGB") else 1.0
        np.testing.assert_allclose(b, factor * a, rtol=1e-5, err_msg=label)


def test_degenerate_scenes_fall_back(models, default_world):
    fallback = np.asarray(default_world.train_whites).mean(axis=0)
    # All surfaces masked (first half of the batch) or all black (second half).
    rgb = jnp.concatenate([jnp.ones((N_SCENES // 2, 8, 3)), jnp.zeros((N_SCENES // 2, 8, 3))])
    mask = jnp.concatenate([jnp.zeros((N_SCENES // 2, 8), bool), jnp.ones((N_SCENES // 2, 8), bool)])
    for label, model in models.items():
        out = run(model, rgb, mask)
        assert not np.any(out.ok), label
        np.testing.assert_allclose(out.illuminant, np.broadcast_to(fallback, (N_SCENES, 3)), rtol=1e-6, err_msg=label)


def test_brightness_estimate_near_truth(models, batch):
    """The 3-D MMSE estimate's R+G+B is within 15 % of the truth (RMS of the ratio's log)."""
    estimate = run(models["RGB-C-by-C-MMSE"], batch.rgb, batch.mask).illuminant
    ratio = np.log(np.asarray(estimate.sum(-1) / batch.illuminant.sum(-1)))
    assert np.sqrt(np.mean(ratio**2)) < 0.15


# -- labels, options, cache ------------------------------------------------------------------------


def test_labels(default_world):
    few = dataclasses.replace(default_world, train_illuminants=default_world.train_illuminants[:3])
    spec = registry.fit("SPEC-RGB-C-by-C-MMSE-counts", few)
    assert (spec.method, spec.l_total, spec.selector) == ("counts", 150, "MMSE")
    std = registry.fit("STD-RGB-C-by-C-MAP", default_world)
    assert (std.method, std.l_total, std.selector) == ("presence", 50, "MAP")
    assert std.estimates_brightness and not registry.fit("C-by-C-MMSE", default_world).estimates_brightness
    mlm = registry.fit("C-by-C-MLM", default_world, mlm_width=1.5)
    n_lights = default_world.train_illuminants.shape[0]
    assert mlm.mlm_width == 1.5 and mlm.mlm_mask.shape == (n_lights, n_lights)
    soft = registry.fit("soft-RGB-C-by-C-MAP", default_world)
    assert soft.softness == correlation.DEFAULT_SOFTNESS


def test_mlm_width_minimises_mean_error(default_world):
    """The width search (§4.5.4) picks the least mean absolute (r,g) error on its validation scenes,
    and C-by-C-MLM uses the searched width."""
    width = registry.fit("C-by-C-MLM", default_world).mlm_width
    search = correlation.mlm_width_search(default_world)
    assert width == search["best"] == search["widths"][np.argmin(search["mean_error"])]
    assert search["mean_error"].shape == (len(correlation.MLM_WIDTHS),) and np.all(np.isfinite(search["mean_error"]))


def test_dropped_in_matrix_is_used(default_world, batch):
    model = registry.fit("C-by-C-MAP", default_world)
    favourite = 17
    rigged = model.log_probability.at[:, favourite].add(1000.0)
    out = run(dataclasses.replace(model, log_probability=rigged), batch.rgb, batch.mask).illuminant
    np.testing.assert_allclose(out[:, :2], np.broadcast_to(model.illuminant_rg[favourite], (N_SCENES, 2)))


@pytest.mark.parametrize(
    "label, options, argument",
    [
        ("C-by-C-MMSE", {"sigma": -1.0}, "sigma"),
        ("C-by-C-MMSE", {"floor": 0.0}, "floor"),
        ("C-by-C-MLM", {"mlm_width": 0.0}, "mlm_width"),
        ("C-by-C-01", {"tolerance": -1.0}, "tolerance"),
        ("RGB-C-by-C-MMSE", {"l_bins": 0}, "l_bins"),
        ("RGB-C-by-C-MMSE", {"brightness_range": 0.5}, "brightness_range"),
        ("RGB-C-by-C-MMSE", {"specular": "yes"}, "specular"),
        ("soft-C-by-C-MAP", {"temperature": 0.0}, "temperature"),
    ],
)
def test_invalid_options(default_world, label, options, argument):
    with pytest.raises(ValueError, match=argument):
        registry.fit(label, default_world, **options)


# -- thesis tables (slow) --------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.external_data
def test_table_10_2_correlation_rows(barnard_world):
    from ccjax import experiments

    rows = ["C-by-C-01", "C-by-C-MAP", "C-by-C-MMSE", "STD-RGB-C-by-C-MAP", "STD-RGB-C-by-C-MMSE"]
    result = experiments.reproduce("10.2", barnard_world, rows, n_scenes=500, progress=False)
    for row in result.rows:
        assert abs(row["relative_difference"]) <= 0.15, row
