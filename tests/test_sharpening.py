"""Sensor sharpening (Barnard 1999 ch. 5): NumPy oracles written from the thesis' equations as
plain loops, closed forms, invariants and gradients on the embedded default world; the thesis'
Sony numbers (external data) are marked ``external_data``."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from traces import count_traces, record_traces

from ccjax import sharpening as sh
from ccjax.camera import Camera
from ccjax.estimators import registry
from ccjax.estimators.base import AbstractSurfaceEstimator, Estimate, Status
from ccjax.experiments import chapter5
from ccjax.spectra import WAVELENGTHS
from ccjax.world import World

# ---------------------------------------------------------------------------------------------
# NumPy oracles (plain code from the thesis equations, not ports of the JAX kernels)


def oracle_best_diagonal(source, target, transform):
    """argmin_d |((X T) * d) T^-1 - X_c|_F by an explicit 3-column design matrix."""
    inverse = np.linalg.inv(transform)
    sharp = source @ transform
    design = np.stack([np.outer(sharp[:, k], inverse[k]).ravel() for k in range(3)], axis=1)
    return np.linalg.lstsq(design, target.ravel(), rcond=None)[0]


def oracle_mapping_error(source, target, transform, d):
    inverse = np.linalg.inv(transform)
    total = 0.0
    for x, c in zip(source, target):
        mapped = ((x @ transform) * d) @ inverse
        total += np.sum((mapped - c) ** 2)
    return np.sqrt(total / len(source))


def oracle_objective(transform, train, canonical, lambda_p, lambda_n, offset):
    """Eqs. 5.1-5.4 literally: loop over training lights, explicit Frobenius norms."""
    inverse = np.linalg.inv(transform)
    e = p = 0.0
    for x in train:
        y = x @ transform
        d = (canonical @ transform).mean(axis=0) / y.mean(axis=0)
        e += np.sqrt(np.sum(((y * d) @ inverse - canonical) ** 2))
        for value in y.ravel():
            if value < offset:
                p += (value - offset) ** 2
    n = (np.trace(transform.T @ transform) - 3.0) ** 2
    return e + lambda_p * p + lambda_n * n


def random_database(seed, n_surfaces=60, n_lights=4):
    rng = np.random.default_rng(seed)
    canonical = rng.uniform(0.05, 1.0, (n_surfaces, 3))
    mixing = np.eye(3) + 0.15 * rng.normal(size=(n_lights, 3, 3))
    train = np.einsum("sa,iab->isa", canonical, mixing) + 0.01 * rng.normal(size=(n_lights, n_surfaces, 3))
    return np.abs(train), canonical


def gaussian_camera(width: float | None) -> Camera:
    """Gaussian sensors; ``width=None``: delta functions (one wavelength sample each)."""
    centres = np.array([600.0, 540.0, 452.0])
    if width is None:
        sensors = (WAVELENGTHS[:, None] == centres).astype(float)
    else:
        sensors = np.exp(-0.5 * ((WAVELENGTHS[:, None] - centres) / width) ** 2)
    return Camera.from_array(sensors, name=f"gaussian-{width}")


@pytest.fixture(scope="module")
def small_world(default_world) -> World:
    """A quick world: 300 reflectances, 17 training and 30 test lights of the embedded default
    world (no external data)."""
    return World(
        reflectances=default_world.reflectances[::6][:300],
        train_illuminants=default_world.train_illuminants[::4][:20],
        test_illuminants=default_world.test_illuminants[::7][:40],
        canonical=default_world.canonical,
        camera=default_world.camera,
        name="small",
    )


# ---------------------------------------------------------------------------------------------
# error measures


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 10_000))
@example(895)  # a transform of condition number 1.5e4: float32 normal equations fail there
def test_best_linear_and_diagonal_match_numpy(seed):
    train, canonical = random_database(seed)
    source = train[0]
    rng = np.random.default_rng(seed + 1)
    transform = np.eye(3) + 0.3 * rng.normal(size=(3, 3))
    m = np.asarray(sh.best_linear_map(jnp.asarray(source), jnp.asarray(canonical)))
    np.testing.assert_allclose(m, np.linalg.lstsq(source, canonical, rcond=None)[0], rtol=2e-3, atol=2e-4)
    d = np.asarray(sh.best_diagonal_map(jnp.asarray(source), jnp.asarray(canonical), jnp.asarray(transform)))
    d_ref = oracle_best_diagonal(source, canonical, transform)
    np.testing.assert_allclose(d, d_ref, rtol=2e-3, atol=2e-4)
    err = float(
        sh.mapping_error(jnp.asarray(source), jnp.asarray(canonical), jnp.asarray(transform), jnp.asarray(d_ref))
    )
    assert err == pytest.approx(oracle_mapping_error(source, canonical, transform, d_ref), rel=1e-3)
    # The best linear map can never be worse than a generalised diagonal one (§5.61).
    assert float(sh.best_linear_error(jnp.asarray(source), jnp.asarray(canonical))) <= err * (1 + 1e-4)


@pytest.mark.external_data
def test_sony_sharpness_ratio_matches_thesis(barnard_world):
    """Table 5.1: BEST-LINEAR 3.0 / BEST-DIAGONAL 4.3 -> sharpness 0.70 (within +-10 %)."""
    out = sh.sharpness(barnard_world)
    assert out["ratio"] == pytest.approx(0.70, rel=0.10)
    assert out["best_linear"] == pytest.approx(3.0, rel=0.15)
    assert out["best_diagonal"] == pytest.approx(4.3, rel=0.15)


def test_narrow_sensors_are_sharper(default_world):
    """Sharpness is 1 for delta-function sensors (§5.7) and below 1 for broad ones."""
    results = []
    for width in (None, 40.0):
        world = World(
            reflectances=default_world.reflectances[::10],
            train_illuminants=default_world.train_illuminants[:5],
            test_illuminants=default_world.test_illuminants[::20],
            canonical=default_world.canonical,
            camera=gaussian_camera(width),
        )
        out = sh.sharpness(world)
        white = 255.0 * float(np.max(np.asarray(world.canonical_white)))  # errors relative to white
        results.append((out["best_linear"] / white, out["best_diagonal"] / white, out["ratio"]))
    # Delta sensors: the diagonal model is exact, both errors vanish (float32 round-off only).
    assert results[0][0] < 1e-5 and results[0][1] < 1e-5
    assert results[1][1] > 1e-3 and results[1][2] < 0.9


# ---------------------------------------------------------------------------------------------
# database sharpening


def test_database_sharpening_diagonalises_the_best_linear_map():
    """With real eigenvectors, T from M makes BEST-DIAGONAL equal BEST-LINEAR (§5.1)
    and T's columns are M's eigenvectors in the thesis' gauge (unit, positive diagonal)."""
    rng = np.random.default_rng(3)
    canonical = rng.uniform(0.05, 1.0, (200, 3))
    vectors = np.eye(3) + 0.2 * rng.normal(size=(3, 3))
    linear = vectors @ np.diag([0.7, 1.0, 1.6]) @ np.linalg.inv(vectors)
    source = canonical @ np.linalg.inv(linear) + 1e-3 * rng.normal(size=canonical.shape)
    t = sh.database_sharpening(source, canonical)
    np.testing.assert_allclose(np.linalg.norm(t, axis=0), 1.0, atol=1e-12)
    assert np.all(np.diag(t) > 0)
    m = np.linalg.lstsq(source, canonical, rcond=None)[0]
    for k in range(3):  # every column is an eigenvector of M: M t = lambda t
        image = m @ t[:, k]
        assert np.linalg.norm(image - (image @ t[:, k]) * t[:, k]) < 1e-9
    best_diag = oracle_mapping_error(source, canonical, t, oracle_best_diagonal(source, canonical, t))
    best_linear = np.sqrt(np.mean(np.sum((source @ m - canonical) ** 2, axis=1)))
    assert best_diag == pytest.approx(best_linear, rel=1e-6)


def test_complex_eigenvectors_keep_t_invertible():
    """A rotation block gives a conjugate pair: zeroing imaginary parts (the thesis' literal rule)
    makes T singular, the real block form does not, and it spans the same invariant plane."""
    angle = 0.3
    block = np.array([[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0.0, 0.0, 1.3]])
    rng = np.random.default_rng(5)
    basis = np.eye(3) + 0.1 * rng.normal(size=(3, 3))
    linear = basis @ block @ np.linalg.inv(basis)
    canonical = rng.uniform(0.05, 1.0, (100, 3))
    source = canonical @ np.linalg.inv(linear)
    values, vectors = np.linalg.eig(np.linalg.lstsq(source, canonical, rcond=None)[0])
    assert np.sum(np.abs(values.imag) > 1e-9) == 2
    assert np.linalg.matrix_rank(vectors.real, tol=1e-9) == 2  # the literal rule: singular
    t = sh.database_sharpening(source, canonical)
    assert np.linalg.cond(t) < 100
    # The plane of the pair is invariant under M: M maps it into itself, i.e. T^-1 M T is block
    # diagonal with a 2x2 and a 1x1 block.
    inner = np.linalg.solve(t, linear @ t)
    assert np.sum(np.abs(inner) > 1e-8) == 5


def test_normalise_transform_gauge_and_invariance():
    raw = np.array([[0.1, 0.9, -0.05], [-1.2, 0.2, 0.1], [0.05, 0.1, 3.0]])
    t = sh.normalise_transform(raw)
    np.testing.assert_allclose(np.linalg.norm(t, axis=0), 1.0)
    assert np.all(np.diag(t) > 0.5)
    # Mapping errors of T ... T^-1 are invariant to the gauge (§5.2).
    train, canonical = random_database(7)
    e_raw = oracle_mapping_error(train[0], canonical, raw, oracle_best_diagonal(train[0], canonical, raw))
    e_t = oracle_mapping_error(train[0], canonical, t, oracle_best_diagonal(train[0], canonical, t))
    assert e_t == pytest.approx(e_raw, rel=1e-9)


# ---------------------------------------------------------------------------------------------
# the new method


def test_objective_matches_the_literal_equations():
    train, canonical = random_database(11, n_surfaces=40, n_lights=3)
    rng = np.random.default_rng(1)
    offset = 0.05  # large enough that the positivity term is active
    for _ in range(3):
        t = np.eye(3) + 0.4 * rng.normal(size=(3, 3))
        ours = float(
            sh.objective(
                jnp.asarray(t, jnp.float32),
                jnp.asarray(train, jnp.float32),
                jnp.asarray(canonical, jnp.float32),
                3.0,
                0.7,
                offset,
            )
        )
        assert ours == pytest.approx(oracle_objective(t, train, canonical, 3.0, 0.7, offset), rel=1e-4)


def test_objective_gradients_x64():
    from jax.test_util import check_grads

    train, canonical = random_database(13, n_surfaces=30, n_lights=3)
    with jax.enable_x64(True):
        tr, ca = jnp.asarray(train, jnp.float64), jnp.asarray(canonical, jnp.float64)
        t = jnp.asarray(np.eye(3) + 0.2 * np.random.default_rng(0).normal(size=(3, 3)), jnp.float64)
        fn = jax.jit(lambda m: sh.objective(m, tr, ca, 10.0, 2.0, 0.05))
        check_grads(fn, (t,), order=1, modes=("fwd", "rev"), eps=1e-6)
        assert float(jnp.linalg.norm(jax.grad(fn)(t))) > 0


def test_new_method_converges_and_respects_positivity(small_world):
    result = sh.new_sharpening(small_world, candidates=(0.0, 1e2, 1e4), bisections=0)
    print(
        f"\nnew method (small world): lambda_P {result.lambda_p:g}, {result.iterations} iterations, "
        f"J {result.initial_objective:.4f} -> {result.objective:.4f}, negative {result.negative_fraction:.4%}"
    )
    assert result.converged
    assert result.mapping < result.initial_mapping
    assert result.negative_fraction < sh.NEGATIVE_TOLERANCE
    canonical = np.asarray(small_world.canonical_rgb) @ result.transform
    assert result.negative_calibration == 0 and np.all(canonical > 0)
    train = sh.database_responses(small_world, small_world.train_illuminants)
    assert np.all(np.isfinite(result.transform)) and np.linalg.cond(result.transform) < 10
    assert float(jnp.mean(train @ jnp.asarray(result.transform, jnp.float32) < 0)) < sh.NEGATIVE_TOLERANCE


# ---------------------------------------------------------------------------------------------
# the sharpened-space wrapper


def test_grey_world_is_invariant_to_sharpening(small_world):
    """GW's estimate is the same under any invertible T (§5.6); DB-GW's is not."""
    rng = np.random.default_rng(0)
    t = np.eye(3) + 0.2 * rng.normal(size=(3, 3))
    rgb = jnp.asarray(np.asarray(small_world.canonical_rgb)[:8] * np.array([0.9, 1.0, 0.7]))
    mask = jnp.ones(8, bool)
    plain = registry.fit("GW", small_world)(rgb, mask).illuminant
    sharp = sh.sharpened("GW", t, small_world)(rgb, mask).illuminant
    np.testing.assert_allclose(sharp, plain, rtol=1e-4)
    db_plain = registry.fit("DB-GW", small_world)(rgb, mask).illuminant
    db_sharp = sh.sharpened("DB-GW", t, small_world)(rgb, mask).illuminant
    assert float(jnp.max(jnp.abs(db_sharp - db_plain))) > 1e-4


def test_sharpened_retinex_matches_closed_form(small_world):
    t = np.array([[1.0, 0.0, -1.0 / 3.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    rgb = np.array([[1.0, 1.0, 1.0], [0.5, 1.0, 1.0]])
    out = sh.sharpened("RETINEX", t, small_world)(jnp.asarray(rgb), jnp.ones(2, bool)).illuminant
    expected = np.max(rgb @ t, axis=0) @ np.linalg.inv(t)  # §5.6 example: max per sharpened channel
    np.testing.assert_allclose(out, expected, rtol=1e-6)


def test_revert_reproduces_the_unsharpened_result_exactly(small_world):
    """§5.2: where a positivity-requiring estimator meets negative sharpened data it returns the
    unsharpened answer bit for bit and counts the scene."""
    t = np.array([[1.0, -0.6, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    model = sh.sharpened("RETINEX", t, small_world, requires_positive=True)
    rgb = jnp.asarray([[0.2, 0.5, 0.3], [0.6, 0.2, 0.4]])  # second row: 0.2 - 0.36 < 0
    mask = jnp.ones(2, bool)
    out, reverted = model.estimate_and_revert(rgb, mask)
    plain = registry.fit("RETINEX", small_world)(rgb, mask)
    assert bool(reverted)
    np.testing.assert_array_equal(np.asarray(out.illuminant), np.asarray(plain.illuminant))
    np.testing.assert_array_equal(np.asarray(out.status), np.asarray(plain.status))
    # Masked-out negative pixels do not trigger a revert unless calibration data is negative.
    _, masked_reverted = model.estimate_and_revert(rgb, jnp.array([True, False]))
    assert bool(masked_reverted) == (not bool(model.calibration_ok))
    # The thesis' simple algorithms never revert (their counts are 0 in Tables 5.1-5.3).
    assert not bool(sh.sharpened("RETINEX", t, small_world).estimate_and_revert(rgb, mask)[1])


def test_sharpened_rejects_singular_transform(small_world):
    with pytest.raises(ValueError, match="transform"):
        sh.sharpened("GW", np.ones((3, 3)), small_world)
    with pytest.raises(ValueError, match="transform"):
        sh.sharpened("GW", np.eye(2), small_world)


def test_actual_has_zero_angle_and_chapter5_rows(small_world):
    """ACTUAL: zero angular error under any T (§5.7); BEST-LINEAR <= BEST-DIAGONAL."""
    methods = ["BEST-LINEAR", "BEST-DIAGONAL", "ACTUAL"]
    result = chapter5.chapter5_errors(small_world, methods, ("none", "opt"), n_scenes=32)
    rows = {(r["method"], r["sharpening"]): r for r in result.rows()}
    for sharpening in ("none", "opt"):
        assert rows[("ACTUAL", sharpening)]["angular"] < 1e-3
        assert rows[("BEST-LINEAR", "none")]["map_rgb"] <= rows[("BEST-DIAGONAL", sharpening)]["map_rgb"] * (1 + 1e-3)
    # opt is best-linear for BEST-DIAGONAL (§5.1; real eigenvectors nearly always).
    assert rows[("BEST-DIAGONAL", "opt")]["map_rgb"] == pytest.approx(
        rows[("BEST-LINEAR", "none")]["map_rgb"], rel=0.05
    )


@pytest.mark.slow
def test_per_scene_sharpening_keeps_grey_world_estimate(small_world):
    """ "opt" refits GW for every scene's own T (traced through vmap): the estimate never changes."""
    result = chapter5.chapter5_errors(small_world, ["GW", "DB-GW"], ("none", "opt"), n_scenes=32)
    rows = {(r["method"], r["sharpening"]): r for r in result.rows()}
    assert rows[("GW", "opt")]["angular"] == pytest.approx(rows[("GW", "none")]["angular"], rel=1e-3)
    assert rows[("DB-GW", "opt")]["angular"] != pytest.approx(rows[("DB-GW", "none")]["angular"], rel=1e-4)


@pytest.mark.slow
def test_learning_signal_through_grey_world(small_world):
    """Through GW the angular loss has no gradient in T (its estimate is T-invariant, §5.6)
    while the chapter-5 mapping loss has a finite, non-zero one."""
    train = sh.database_responses(small_world, small_world.train_illuminants)
    plain = registry.fit("GW", small_world)
    lights = jnp.arange(4)
    surfaces = jnp.stack([jnp.arange(8) + 10 * k for k in range(4)])
    parameters = jnp.eye(3) + 0.05 * jnp.asarray(np.random.default_rng(0).normal(size=(3, 3)), jnp.float32)

    def total(p, loss):
        errors = sh.scene_losses(p, "GW", loss, small_world, train, small_world.train_whites, lights, surfaces, plain)
        return jnp.mean(errors**2)

    gradient = jax.jit(jax.grad(total), static_argnums=1)
    mapping_grad = gradient(parameters, "mapping")
    angular_grad = gradient(parameters, "angular")
    assert np.all(np.isfinite(mapping_grad)) and float(jnp.linalg.norm(mapping_grad)) > 1e-3
    assert float(jnp.linalg.norm(angular_grad)) < 1e-3 * float(jnp.linalg.norm(mapping_grad))


def test_learned_sharpenings_losses_is_a_deprecated_alias_of_its_rms_errors(small_world):
    """``losses`` (the old name of an RMS, where ccjax's other ``losses`` are objectives or means)
    warns and returns ``rms_errors``: one finite, non-negative value per step."""
    learned = sh.learned_sharpening(small_world, "GW", steps=2, batch_size=2, n_surfaces=5)
    assert len(learned.rms_errors) == 2 and all(np.isfinite(learned.rms_errors)) and min(learned.rms_errors) >= 0
    with pytest.warns(DeprecationWarning, match="rms_errors"):
        assert learned.losses == learned.rms_errors


def test_learned_sharpening_compiles_once_per_shape(small_world, caplog):
    """The training step is compiled once per shape: calls with other step counts and rates trace
    nothing (the count is the loop's length: a shorter run is the longer one's beginning); an
    optax optimiser is part of the key (two calls with one object: one more trace), and
    ``optax.adam(rate)`` takes the steps of the default Adam at that rate."""
    record_traces(caplog)
    options = dict(batch_size=3, n_surfaces=3)  # shapes no other test uses: the first call compiles
    longer = sh.learned_sharpening(small_world, "GW", steps=4, learning_rate=3e-3, **options)
    shorter = sh.learned_sharpening(small_world, "GW", steps=2, learning_rate=3e-3, **options)
    faster = sh.learned_sharpening(small_world, "GW", steps=2, learning_rate=3e-2, **options)
    assert count_traces(caplog, "_sharpening_step") == 1
    assert shorter.rms_errors == longer.rms_errors[:2]
    assert faster.rms_errors[0] == longer.rms_errors[0] and faster.rms_errors[1] != longer.rms_errors[1]  # T = I first
    adam = optax.adam(3e-3)
    with_optax = sh.learned_sharpening(small_world, "GW", steps=4, optimizer=adam, **options)
    sh.learned_sharpening(small_world, "GW", steps=1, optimizer=adam, **options)
    assert count_traces(caplog, "_sharpening_step") == 2
    np.testing.assert_allclose(with_optax.rms_errors, longer.rms_errors, rtol=1e-5)
    np.testing.assert_allclose(with_optax.transform, longer.transform, rtol=1e-5, atol=1e-6)
    assert not np.allclose(longer.transform, np.eye(3), atol=1e-3)  # it did move
    with pytest.raises(ValueError, match="learning_rate"):
        sh.learned_sharpening(small_world, "GW", steps=1, learning_rate=1e-3, optimizer=adam)
    with pytest.raises(TypeError, match="optimizer"):
        sh.learned_sharpening(small_world, "GW", steps=1, optimizer=3e-3)  # pyright: ignore[reportArgumentType]


@pytest.mark.slow
@pytest.mark.external_data
def test_table_5_1_unsharpened_rows(barnard_world):
    """Table 5.1 without sharpening (500 scenes; tolerance +-15 %)."""
    from ccjax import thesis

    methods = ["BEST-LINEAR", "BEST-DIAGONAL", "ACTUAL", "NOTHING", "GW", "DB-GW", "RETINEX"]
    result = chapter5.chapter5_errors(barnard_world, methods, ("none",), n_scenes=500)
    for row in result.rows():
        target = thesis.TABLES["5.1"][row["method"]]
        for column in ("map_rgb", "angular"):
            reference = target.get(f"{column}@none")
            if reference:  # ACTUAL's 0.00 angle is checked elsewhere
                assert row[column] == pytest.approx(reference, rel=0.15), (row, column)
        assert row["reverted"] == 0


# ---------------------------------------------------------------------------------------------
# the wrapper as an estimator (one contract: a final surface estimator returning Estimate)


def test_sharpened_is_a_surface_estimator_under_jit_vmap_and_grad(small_world):
    """The wrapper is a final AbstractSurfaceEstimator returning the one Estimate, a valid
    jit/vmap argument, and differentiable with respect to T through its construction (§5.4)."""
    t = jnp.asarray(np.eye(3) + 0.1 * np.random.default_rng(4).normal(size=(3, 3)), jnp.float32)
    model = sh.sharpened("DB-GW", t, small_world)
    assert isinstance(model, AbstractSurfaceEstimator)
    assert getattr(sh.Sharpened, "__final__", False)  # typing.final: concrete and closed
    rgb = jnp.asarray(np.asarray(small_world.canonical_rgb)[:64].reshape(8, 8, 3) * np.array([0.9, 1.0, 0.7]))
    mask = jnp.ones((8, 8), bool)
    batched = eqx.filter_jit(lambda m, r, k: jax.vmap(m)(r, k))(model, rgb, mask)
    assert isinstance(batched, Estimate) and batched.illuminant.shape == (8, 3)
    for index in range(8):
        one = model(rgb[index], mask[index])
        np.testing.assert_allclose(np.asarray(batched.illuminant[index]), np.asarray(one.illuminant), rtol=1e-5)
    assert np.all(np.asarray(batched.status) == Status.ESTIMATED)

    # grad with respect to the model's arrays (filter_grad over the PyTree) and through T.
    def loss_model(m):
        return jnp.sum(jax.vmap(m)(rgb, mask).illuminant ** 2)

    grads = eqx.filter_grad(loss_model)(model)
    assert float(jnp.linalg.norm(grads.inverse)) > 0

    def loss_transform(matrix):
        return jnp.sum(jax.vmap(sh.sharpened("DB-GW", matrix, small_world))(rgb, mask).illuminant ** 2)

    gradient = jax.jit(jax.grad(loss_transform))(t)
    assert np.all(np.isfinite(np.asarray(gradient))) and float(jnp.linalg.norm(gradient)) > 0


def test_sharpened_passes_the_status_of_the_run_that_answered(small_world):
    """A scene without usable data keeps the inner estimator's NO_DATA status (and ok False)."""
    t = np.eye(3) + 0.05 * np.random.default_rng(6).normal(size=(3, 3))
    model = sh.sharpened("GW", t, small_world)
    rgb = jnp.asarray(np.asarray(small_world.canonical_rgb)[:8])
    empty = model(rgb, jnp.zeros(8, bool))
    full, reverted = model.estimate_and_revert(rgb, jnp.ones(8, bool))
    assert int(empty.status) == Status.NO_DATA and not bool(empty.ok)
    assert int(full.status) == Status.ESTIMATED and bool(full.ok) and not bool(reverted)
    np.testing.assert_array_equal(np.asarray(model(rgb, jnp.ones(8, bool)).illuminant), np.asarray(full.illuminant))


def test_chapter5_scenes_are_the_sampled_scenes(small_world):
    """Chapter 5 draws its scenes with the scene sampler's draw function: scene k of the
    experiment has the light and surfaces of scene k of ``sample`` on the same stream."""
    from ccjax import scenes

    key = jax.random.key(7)
    data = chapter5.Chapter5Data.of(small_world)
    drawn = chapter5.Chapter5Scenes.draw(key, data.database.shape[0], data.database.shape[1], 40, 8)
    sampled = scenes.sample(jax.random.fold_in(key, 8), small_world, 40, 8)
    np.testing.assert_allclose(
        np.asarray(sampled.rgb), np.asarray(data.database[drawn.light[:, None], drawn.surfaces]), rtol=1e-5, atol=1e-8
    )
    np.testing.assert_array_equal(np.asarray(sampled.illuminant), np.asarray(data.whites[drawn.light]))
    assert len(np.unique(np.asarray(drawn.light))) > 5
