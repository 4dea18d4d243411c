"""Colour in Perspective (CIP-MV, CIP-AVE, CIP-ICA) against the independent SciPy oracle in
``tests/cip_oracle.py`` (exact polygon geometry, exact 1-D boundary maximisation, Monte-Carlo over
map directions), plus properties and degenerate input.

Scenes are padded to fixed shapes (8 pixels for the default tests, 64 in the slow ones) so each
selector compiles once per shape.
"""

from __future__ import annotations

import cip_oracle as oracle
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ccjax.estimators import registry
from ccjax.estimators.base import AbstractSurfaceEstimator, Estimate, Status
from ccjax.estimators.gamut import cip
from ccjax.scenes import sample

PAD = 8
BATCH = 32


@pytest.fixture(scope="module")
def models(default_world):
    return {selector: cip.fit(default_world, selector) for selector in cip.SELECTORS}


def batch_runner(model, pad):
    """Run a model on any number of scenes of ``pad`` pixels, in batches of :data:`BATCH` (one
    compiled shape per model and pad)."""
    batched = eqx.filter_jit(lambda estimator, rgb, mask: jax.vmap(estimator)(rgb, mask))
    compiled = lambda rgb, mask: batched(model, rgb, mask)

    def call(rgb, mask):
        rgb, mask = np.asarray(rgb, np.float32), np.asarray(mask, bool)
        n = len(rgb)
        size = -(-n // BATCH) * BATCH
        rgb = np.concatenate([rgb, np.zeros((size - n, pad, 3), np.float32)])
        mask = np.concatenate([mask, np.zeros((size - n, pad), bool)])
        illuminants, oks = [], []
        for start in range(0, size, BATCH):
            out = compiled(jnp.asarray(rgb[start : start + BATCH]), jnp.asarray(mask[start : start + BATCH]))
            illuminants.append(np.asarray(out.illuminant, np.float64))
            oks.append(np.asarray(out.ok))
        return np.concatenate(illuminants)[:n], np.concatenate(oks)[:n]

    return call


@pytest.fixture(scope="module")
def run(models):
    """``run(selector, rgb (B, PAD, 3), mask)``: compiled runners shared by the module's tests."""
    runners = {selector: batch_runner(model, PAD) for selector, model in models.items()}
    return lambda selector, rgb, mask: runners[selector](rgb, mask)


@pytest.fixture(scope="module")
def geometry(default_world):
    return oracle.make_world(default_world.canonical_rgb, default_world.train_whites, default_world.canonical_white)


@pytest.fixture(scope="module")
def pool(default_world):
    """One batch of 8-surface scenes for the default tests (sampling compiles once); the first
    ``n`` surfaces of a scene are an ``n``-surface scene (surfaces are drawn without replacement)."""
    scenes = sample(jax.random.key(0), default_world, 256, PAD)
    return np.asarray(scenes.rgb), np.asarray(scenes.illuminant, np.float64)


def _padded(rgb, n_surfaces, pad):
    out = np.zeros((len(rgb), pad, 3), np.float32)
    out[:, :n_surfaces] = rgb[:, :n_surfaces]
    mask = np.zeros((len(rgb), pad), bool)
    mask[:, :n_surfaces] = True
    return out, mask


def _scenes(source, n_scenes, n_surfaces, pad, seed):
    """Scenes from the pool (``source`` a pool, ``seed`` the first scene) or freshly sampled
    (``source`` a world)."""
    if isinstance(source, tuple):
        return _padded(source[0][seed : seed + n_scenes], n_surfaces, pad)
    scenes = sample(jax.random.key(seed), source, n_scenes, n_surfaces)
    return _padded(np.asarray(scenes.rgb), n_surfaces, pad)


def _compare(run, geometry, world, selector, n_surfaces, n_scenes, pad, seed, ica_samples=100_000):
    """Per-scene errors against the oracle on scenes whose exact feasible set is non-empty.

    AVE: ``|D_grid - D_exact| / |D_exact|`` (2-D map centroid); MV: relative error of the map
    area ``D1 D2``; ICA: (r,g) distance to the Monte-Carlo solid-angle centroid.
    """
    rgb, mask = _scenes(world, n_scenes, n_surfaces, pad, seed)
    estimates, ok = run(selector, rgb, mask)
    errors, grid_ok = [], []
    for scene in range(n_scenes):
        observed = rgb[scene, :n_surfaces].astype(np.float64)
        if selector == "ICA":
            exact, _ = oracle.ica(geometry, observed, ica_samples, seed=scene)
            if exact is None:
                continue
            ours = estimates[scene] / estimates[scene].sum()
            errors.append(np.linalg.norm(ours[:2] - exact[:2]))
        else:
            exact = (oracle.mv if selector == "MV" else oracle.ave)(geometry, observed)
            if exact is None:
                continue
            ours = oracle.map_of_illuminant(geometry, estimates[scene])
            if selector == "MV":
                errors.append(abs(ours.prod() / exact.prod() - 1.0))
            else:
                errors.append(np.linalg.norm(ours - exact) / np.linalg.norm(exact))
        grid_ok.append(ok[scene])
    errors = np.array(errors)
    print(
        f"CIP-{selector} {n_surfaces} surfaces: {len(errors)}/{n_scenes} scenes with a non-empty exact "
        f"feasible set; grid ok on {np.mean(grid_ok):.0%} of them; error median {np.median(errors):.2e}, "
        f"90th percentile {np.percentile(errors, 90):.2e}, max {errors.max():.2e}"
    )
    return errors, np.array(grid_ok)


# ---------------------------------------------------------------------------------------------
# oracle agreement

TOLERANCE = {"AVE": 0.005, "MV": 0.005, "ICA": 0.002}


@pytest.mark.parametrize("selector", cip.SELECTORS)
@pytest.mark.parametrize("n_surfaces", [4, 8])
def test_matches_oracle(run, geometry, pool, selector, n_surfaces):
    n_scenes = 8 if selector == "ICA" else 32
    errors, grid_ok = _compare(run, geometry, pool, selector, n_surfaces, n_scenes, PAD, seed=32 * (n_surfaces // 4))
    assert len(errors) >= n_scenes // 2
    assert np.median(errors) < TOLERANCE[selector]
    assert np.mean(grid_ok) >= 0.9


@pytest.mark.slow
@pytest.mark.parametrize("selector", cip.SELECTORS)
@pytest.mark.parametrize("n_surfaces", [4, 8, 64])
def test_matches_oracle_many_scenes(default_world, geometry, selector, n_surfaces):
    runner = batch_runner(cip.fit(default_world, selector), 64)

    def call(_, rgb, mask):
        return runner(rgb, mask)

    n_scenes = 40 if selector == "ICA" else 200
    errors, grid_ok = _compare(call, geometry, default_world, selector, n_surfaces, n_scenes, 64, seed=100 + n_surfaces)
    assert len(errors) >= n_scenes // 2
    assert np.median(errors) < TOLERANCE[selector]
    assert np.percentile(errors, 90) < 4 * TOLERANCE[selector]
    assert np.mean(grid_ok) >= 0.95


def test_ica_against_a_dense_monte_carlo(run, geometry, default_world):
    # One weakly constraining scene (a single grey surface under the average training light), so
    # the feasible cone is large; a 2M-sample Monte-Carlo pins its solid-angle centroid to about
    # 3e-4 in (r,g), which checks the weight w1 w2 w3 / (|m|^3 (rgb)^2) well below the scene-level
    # tolerance.
    observed = 0.3 * np.asarray(default_world.train_whites, np.float64).mean(axis=0, keepdims=True)
    exact, count = oracle.ica(geometry, observed, 2_000_000, seed=1)
    assert count > 100_000
    rgb = np.zeros((1, PAD, 3))
    rgb[0, 0] = observed[0]
    ours, ok = run("ICA", rgb, np.arange(PAD)[None] == 0)
    assert ok[0]
    ours = ours[0] / ours[0].sum()
    assert np.linalg.norm(ours[:2] - exact[:2]) < 1e-3


# ---------------------------------------------------------------------------------------------
# properties


def test_true_illuminant_is_feasible_under_the_diagonal_model(models, default_world):
    # Surfaces rendered from their canonical RGBs by an exact diagonal map of a training light:
    # that light's direction satisfies every perspective and illumination constraint.
    canonical = np.asarray(default_world.canonical_rgb)
    white = np.asarray(default_world.canonical_white)
    lights = np.asarray(default_world.train_whites)
    rng = np.random.default_rng(0)
    violation_of = eqx.filter_jit(models["ICA"].violation)
    for light in rng.choice(len(lights), 5, replace=False):
        rgb = canonical[rng.choice(len(canonical), PAD, replace=False)] * (lights[light] / white)
        u = lights[light] / lights[light].sum()
        violation = violation_of(
            jnp.asarray(u[None, :2], jnp.float32), jnp.asarray(rgb, jnp.float32), jnp.ones(PAD, bool)
        )
        # Illuminants on the hull boundary sit exactly on a facet: allow float32 rounding.
        assert float(violation[0]) <= 1e-5


@pytest.mark.parametrize("selector", cip.SELECTORS)
def test_scale_permutation_and_padding_invariance(run, pool, selector):
    rgb, mask = _scenes(pool, 6, 5, PAD, seed=100)
    base, _ = run(selector, rgb, mask)
    base = base / base.sum(axis=1, keepdims=True)
    scaled, _ = run(selector, rgb * 7.5, mask)
    order = np.random.default_rng(1).permutation(PAD)
    permuted, _ = run(selector, rgb[:, order], mask[:, order])
    junk = rgb.copy()
    junk[:, 5:] = 0.37  # padding content must not matter
    padded, _ = run(selector, junk, mask)
    for other in (scaled, permuted, padded):
        other = other / other.sum(axis=1, keepdims=True)
        np.testing.assert_allclose(other, base, atol=2e-4)


def test_mv_is_bluest_and_ica_least_biased(run, pool):
    # The thesis' finding (§4.7, Fig. 4.5): MV picks the bluest feasible light (largest 2-D map
    # area), AVE a little less, ICA is unbiased. Mean signed error in b = B/(R+G+B) over scenes.
    rgb, truth = pool[0][128:192], pool[1][128:192]
    truth_b = truth[:, 2] / truth.sum(axis=1)
    bias = {}
    for selector in cip.SELECTORS:
        estimate, _ = run(selector, rgb, np.ones(rgb.shape[:2], bool))
        bias[selector] = np.mean(estimate[:, 2] / estimate.sum(axis=1) - truth_b)
    assert bias["MV"] > bias["AVE"] > abs(bias["ICA"])


# ---------------------------------------------------------------------------------------------
# degenerate input


def test_degenerate_scenes_are_finite_and_flagged(run, default_world, pool):
    white = np.asarray(default_world.canonical_white, np.float32)
    some = pool[0][200]
    cases = {
        "all masked": (some, np.zeros(PAD, bool), False),
        "all black": (np.zeros((PAD, 3), np.float32), np.ones(PAD, bool), False),
        "blue channel zero": (some * np.array([1, 1, 0], np.float32), np.ones(PAD, bool), False),
        "one grey pixel": (np.where(np.arange(PAD)[:, None] == 0, 0.4 * white, 0.0), np.arange(PAD) == 0, True),
        "huge values": (some * 1e15, np.ones(PAD, bool), True),
        "tiny values": (some * 1e-15, np.ones(PAD, bool), True),
        "identical pixels": (np.tile(some[:1], (PAD, 1)), np.ones(PAD, bool), True),
        "pure red and pure blue": (
            np.array([[1, 0, 0], [0, 0, 1]] * (PAD // 2), np.float32),
            np.ones(PAD, bool),
            False,
        ),
    }
    rgb = np.stack([case[0] for case in cases.values()]).astype(np.float32)
    mask = np.stack([case[1] for case in cases.values()])
    for selector in cip.SELECTORS:
        estimate, ok = run(selector, rgb, mask)
        assert np.all(np.isfinite(estimate)), selector
        assert np.all(estimate.sum(axis=1) > 0), selector
        for (name, (_, _, expect_ok)), flag in zip(cases.items(), ok):
            if not expect_ok:
                assert not flag, f"{selector}: {name} should be flagged"
            elif name == "one grey pixel":
                assert flag, f"{selector}: {name} is feasible"


def test_relaxed_scene_stays_near_the_data(run, pool):
    # Scenes whose blue channel is cut fifty-fold: the diagonal map that explains them implies a
    # light far outside the illuminant hull, so no direction is feasible; they are relaxed,
    # flagged, and still give an illuminant inside the chromaticity triangle.
    rgb = pool[0][192:224] * np.array([1.0, 1.0, 0.02], np.float32)
    for selector in cip.SELECTORS:
        estimate, ok = run(selector, rgb, np.ones(rgb.shape[:2], bool))
        assert np.mean(~ok) > 0.9
        chromaticity = estimate / estimate.sum(axis=1, keepdims=True)
        assert np.all((chromaticity > 0) & (chromaticity < 1))


# ---------------------------------------------------------------------------------------------
# registry and validation


def test_registry_labels(default_world):
    for label, selector in (("CIP-MV", "MV"), ("CIP-AVE", "AVE"), ("CIP-HA", "AVE"), ("CIP-ICA", "ICA")):
        model = registry.fit(label, default_world)
        assert isinstance(model, cip.CIP)
        assert model.selector == selector
        assert not model.estimates_brightness
    assert registry.fit("CIP-AVE", default_world).illumination == "hull"
    assert registry.fit("CIP-MV", default_world).illumination == "exact"


def test_model_is_a_final_surface_estimator_and_a_jit_argument(models, pool):
    rgb, mask = _scenes(pool, 1, 8, PAD, seed=3)
    estimate = jax.jit(lambda m, *a: m(*a))(models["MV"], rgb[0], mask[0])
    assert isinstance(models["MV"], AbstractSurfaceEstimator)
    assert type(estimate) is Estimate
    assert int(estimate.status) in (Status.ESTIMATED, Status.RELAXED)
    assert (int(estimate.status) == Status.RELAXED) == (float(estimate.relaxation) > 0)
    nothing = jax.jit(lambda m, *a: m(*a))(models["MV"], rgb[0], np.zeros(PAD, bool))
    assert int(nothing.status) == Status.NO_DATA


@pytest.mark.parametrize(
    "options", [{"selector": "MAX"}, {"illumination": "convex"}, {"cone": "cube"}, {"fine": 2}, {"coarse": 3}]
)
def test_fit_rejects_bad_options(default_world, options):
    options = {"selector": "ICA", **options}
    with pytest.raises(ValueError, match=next(iter(set(options) - {"selector"}), "selector")):
        cip.fit(default_world, **options)


@pytest.mark.slow
def test_runs_under_x64(default_world, pool):
    rgb, mask = _scenes(pool, 4, 8, PAD, seed=224)
    model32 = cip.fit(default_world, "ICA")
    with jax.enable_x64(True):
        model64 = jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float64), model32)
        out = jax.jit(jax.vmap(model64))(jnp.asarray(rgb, jnp.float64), jnp.asarray(mask))
        assert out.illuminant.dtype == jnp.float64
        e64 = np.asarray(out.illuminant)
    e32 = np.asarray(jax.jit(jax.vmap(model32))(jnp.asarray(rgb), jnp.asarray(mask)).illuminant, np.float64)
    e32, e64 = e32 / e32.sum(1, keepdims=True), e64 / e64.sum(1, keepdims=True)
    np.testing.assert_allclose(e64, e32, atol=1e-3)
