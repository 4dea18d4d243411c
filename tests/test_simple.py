"""Simple estimators: against the NumPy reference, properties (hypothesis), gradients, validation."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import reference
from hypothesis import given, settings
from hypothesis import strategies as st
from jax.test_util import check_grads

import ccjax
from ccjax.estimators import registry
from ccjax.estimators.simple import average_illuminant

LABELS = ["GW", "DB-GW", "RETINEX", "shades-of-grey-p6", "shades-of-grey-p1", "NOTHING", "AVE-ILLUM"]
P = 16  # one padded shape for every property example, so XLA compiles once per method


@pytest.fixture(scope="module")
def models(default_world):
    return {label: registry.fit(label, default_world) for label in LABELS}


@pytest.fixture(scope="module")
def run():
    return jax.jit(lambda model, rgb, mask: model(rgb, mask))


def test_match_reference(models, run, default_world):
    rng = np.random.default_rng(0)
    w_c = np.asarray(default_world.canonical_white, dtype=np.float64)
    db_grey = np.asarray(default_world.canonical_rgb, dtype=np.float64).mean(axis=0)
    for _ in range(10):
        rgb = rng.uniform(0, 1, (P, 3))
        mask = rng.uniform(size=P) < 0.6
        mask[0] = True
        got = {
            label: np.asarray(run(models[label], jnp.asarray(rgb, jnp.float32), jnp.asarray(mask)).illuminant)
            for label in LABELS
        }
        np.testing.assert_allclose(got["GW"], reference.grey_world(rgb, mask, [2, 2, 2]), rtol=1e-5)
        np.testing.assert_allclose(got["DB-GW"], reference.grey_world(rgb, mask, w_c / db_grey), rtol=1e-4)
        np.testing.assert_allclose(got["RETINEX"], reference.max_rgb(rgb, mask), rtol=1e-6)
        np.testing.assert_allclose(got["shades-of-grey-p6"], reference.shades_of_grey(rgb, mask, 6), rtol=1e-4)
        np.testing.assert_allclose(got["shades-of-grey-p1"], got["GW"], rtol=1e-5)
        np.testing.assert_allclose(got["NOTHING"], w_c, rtol=1e-6)
        np.testing.assert_allclose(got["AVE-ILLUM"], np.asarray(default_world.train_whites).mean(axis=0), rtol=1e-5)


# A component is exactly 0 (a channel without light) or at least 2^-100 (~8e-31): XLA on CPU flushes
# subnormal float32 to zero, so a channel lit only near float32's floor (~1e-38) could go dark at
# one scale and not another. The properties are the estimators'; that floor is the number format's.
component = st.one_of(st.just(0.0), st.floats(2.0**-100, 1.0, width=32))
scene = st.integers(1, P).flatmap(
    lambda n: st.tuples(
        st.lists(st.tuples(*[component] * 3), min_size=n, max_size=n),
        st.randoms(use_true_random=False),
    )
)


def _pad(points):
    rgb = np.zeros((P, 3), np.float32)
    mask = np.zeros(P, bool)
    rgb[: len(points)] = points
    mask[: len(points)] = True
    return rgb, mask


@settings(max_examples=40, deadline=None)
@given(scene)
def test_permutation_and_padding_invariance(models, run, data):
    points, rnd = data
    rgb, mask = _pad(points)
    order = list(range(P))
    rnd.shuffle(order)
    garbage = rgb.copy()
    garbage[~mask] = 0.77  # values behind the mask must not matter
    for label in ["GW", "DB-GW", "RETINEX", "shades-of-grey-p6"]:
        base = run(models[label], rgb, mask)
        permuted = run(models[label], rgb[order], mask[order])
        padded = run(models[label], garbage, mask)
        np.testing.assert_allclose(permuted.illuminant, base.illuminant, rtol=1e-5, atol=1e-7)
        np.testing.assert_allclose(padded.illuminant, base.illuminant, rtol=1e-5, atol=1e-7)
        assert np.all(np.isfinite(base.illuminant))


@settings(max_examples=25, deadline=None)
@given(scene, st.floats(0.01, 100.0))
def test_scale_equivariance(models, run, data, scale):
    points, _ = data
    rgb, mask = _pad(points)
    if rgb[mask].sum() <= 1e-6:
        return
    for label in ["GW", "RETINEX", "DB-GW", "shades-of-grey-p6"]:
        base = run(models[label], rgb, mask)
        scaled = run(models[label], rgb * np.float32(scale), mask)
        if not bool(base.ok):  # a channel without light (grey world falls back): at any scale
            assert not bool(scaled.ok)
            np.testing.assert_array_equal(scaled.illuminant, base.illuminant)
            continue
        np.testing.assert_allclose(scaled.illuminant, np.asarray(base.illuminant) * scale, rtol=2e-4, atol=1e-6)


def test_degenerate_scenes_give_finite_fallback(models, run, default_world):
    fallback = np.asarray(average_illuminant(default_world))
    cases = {
        "all masked": (np.random.default_rng(0).uniform(size=(P, 3)).astype(np.float32), np.zeros(P, bool)),
        "all zero": (np.zeros((P, 3), np.float32), np.ones(P, bool)),
    }
    for name, (rgb, mask) in cases.items():
        for label in ["GW", "DB-GW", "RETINEX", "shades-of-grey-p6"]:
            est = run(models[label], rgb, mask)
            assert np.all(np.isfinite(est.illuminant)), (name, label)
            assert not bool(est.ok), (name, label)
            np.testing.assert_allclose(est.illuminant, fallback, rtol=1e-6)
    single = np.zeros((P, 3), np.float32)
    single[0] = [0.2, 0.5, 0.3]
    mask = np.zeros(P, bool)
    mask[0] = True
    for label in ["GW", "RETINEX", "shades-of-grey-p6"]:
        est = run(models[label], single, mask)
        assert bool(est.ok)
        np.testing.assert_allclose(np.asarray(est.illuminant) / np.sum(est.illuminant), [0.2, 0.5, 0.3], rtol=1e-5)


def test_constants_report_degenerate_scenes(models, run, default_world):
    """NOTHING and AVE-ILLUM keep their constant but say NO_DATA on scenes without a lit valid
    surface, and ESTIMATED otherwise."""
    from ccjax.estimators.base import Status

    lit = np.random.default_rng(1).uniform(0.1, 1.0, (P, 3)).astype(np.float32)
    cases = {
        "all masked": (lit, np.zeros(P, bool), False),
        "all zero": (np.zeros((P, 3), np.float32), np.ones(P, bool), False),
        "lit surfaces masked, black ones valid": (lit * np.arange(P)[:, None].__ge__(4), np.arange(P) < 4, False),
        "normal": (lit, np.ones(P, bool), True),
    }
    for label, constant in [
        ("NOTHING", default_world.canonical_white),
        ("AVE-ILLUM", average_illuminant(default_world)),
    ]:
        for name, (rgb, mask, ok) in cases.items():
            est = run(models[label], rgb.astype(np.float32), mask)
            assert bool(est.ok) is ok, (label, name)
            assert int(est.status) == (Status.ESTIMATED if ok else Status.NO_DATA), (label, name)
            np.testing.assert_array_equal(est.illuminant, np.asarray(constant))


def test_shades_of_grey_large_p_is_stable(run, default_world):
    """x^1000 overflows or underflows without per-channel scaling: every channel must stay positive
    and tend to the per-channel maximum (RETINEX's chromaticity), for bright and dim scenes."""
    rng = np.random.default_rng(5)
    rgb = rng.uniform(0.01, 1.0, (P, 3)).astype(np.float32) * np.array([1.0, 0.5, 0.05], np.float32)
    mask = np.ones(P, bool)
    model = registry.fit("shades-of-grey-p1000", default_world)
    for scale in [1.0, 1e6, 1e-12]:
        est = run(model, (rgb * scale).astype(np.float32), mask)
        assert bool(est.ok), scale
        illuminant = np.asarray(est.illuminant, np.float64)
        assert np.all(np.isfinite(illuminant)) and np.all(illuminant > 0), (scale, illuminant)
        chromaticity = illuminant / illuminant.sum()
        peak = rgb.max(axis=0).astype(np.float64)
        np.testing.assert_allclose(chromaticity, peak / peak.sum(), atol=2e-3)


def test_soft_retinex_is_scale_invariant_and_honest(run, default_world):
    rng = np.random.default_rng(6)
    rgb = rng.uniform(0.05, 1.0, (P, 3)).astype(np.float32)
    mask = np.ones(P, bool)
    model = registry.fit("soft-RETINEX-t0.01", default_world)
    base = np.asarray(run(model, rgb, mask).illuminant, np.float64)
    for scale in [1e6, 1e-12]:
        est = run(model, (rgb * np.float32(scale)).astype(np.float32), mask)
        assert bool(est.ok)
        got = np.asarray(est.illuminant, np.float64)
        np.testing.assert_allclose(got / got.sum(), base / base.sum(), rtol=1e-4)
    zero = run(model, np.zeros((P, 3), np.float32), mask)
    assert not bool(zero.ok)
    np.testing.assert_allclose(zero.illuminant, np.asarray(average_illuminant(default_world)), rtol=1e-6)


def test_gradients_match_finite_differences(default_world):
    with jax.enable_x64(True):
        rng = np.random.default_rng(3)
        rgb = jnp.asarray(rng.uniform(0.1, 1.0, (6, 3)))
        mask = jnp.array([True] * 5 + [False])
        truth = jnp.array([0.5, 0.8, 1.0])
        for label in ["GW", "shades-of-grey-p6", "soft-RETINEX-t0.05"]:
            model = registry.fit(label, default_world)
            model = jax.tree_util.tree_map(
                lambda x: jnp.asarray(x, jnp.float64) if isinstance(x, jax.Array) else x, model
            )
            # check_grads probes with NumPy arrays; the model takes JAX arrays.
            loss = jax.jit(
                lambda x, model=model: ccjax.metrics.angular_error(model(jnp.asarray(x), mask).illuminant, truth)
            )
            check_grads(loss, (rgb,), order=1, modes=["rev"], atol=1e-4, rtol=1e-4)
            assert float(jnp.linalg.norm(jax.grad(loss)(rgb))) > 0


def test_soft_retinex_approaches_hard(default_world):
    rng = np.random.default_rng(4)
    rgb = jnp.asarray(rng.uniform(0, 1, (P, 3)), jnp.float32)
    mask = jnp.ones(P, bool)
    hard = registry.fit("RETINEX", default_world)(rgb, mask).illuminant
    soft = registry.fit("soft-RETINEX-t0.001", default_world)(rgb, mask).illuminant
    np.testing.assert_allclose(soft, hard, atol=0.001 * np.log(P) + 1e-5)


def test_estimate_validates_input():
    good = np.random.default_rng(0).uniform(size=(8, 3))
    with pytest.raises(ValueError, match="rgb: contains NaN"):
        ccjax.estimate("GW", np.full((8, 3), np.nan))
    with pytest.raises(ValueError, match="rgb: contains negative"):
        ccjax.estimate("GW", -good)
    with pytest.raises(ValueError, match=r"rgb: expected shape"):
        ccjax.estimate("GW", np.ones((8, 4)))
    with pytest.raises(ValueError, match="rgb: expected a real numeric"):
        ccjax.estimate("GW", np.array([["a", "b", "c"]]))
    with pytest.raises(ValueError, match="mask: expected shape"):
        ccjax.estimate("GW", good, np.ones(7, bool))
    with pytest.raises(ValueError, match="mask: expected a boolean"):
        ccjax.estimate("GW", good, np.ones(8))
    with pytest.raises(ValueError, match="method: unknown label"):
        ccjax.estimate("NO-SUCH-METHOD", good)
    with pytest.raises(ValueError, match="p: expected"):
        ccjax.estimate("shades-of-grey-p0.5", good)


def test_estimate_batches(default_world):
    rgb = np.random.default_rng(1).uniform(size=(4, 8, 3)).astype(np.float32)
    batch = ccjax.estimate_batch(ccjax.fit("GW", default_world), jnp.asarray(rgb), jnp.ones(rgb.shape[:2], bool))
    one = ccjax.estimate("GW", rgb[2], world=default_world)
    assert batch.illuminant.shape == (4, 3)
    np.testing.assert_allclose(batch.illuminant[2], one.illuminant, rtol=1e-6)


@pytest.mark.parametrize("length", [1, 2, 3, 7, 8, 65, 1024])
def test_pairwise_reduce_equals_sum_and_max(length):
    from ccjax.estimators.base import pairwise_reduce

    x = np.random.default_rng(length).uniform(size=(length, 3)).astype(np.float32)
    np.testing.assert_allclose(pairwise_reduce(jnp.asarray(x), jnp.add), x.sum(axis=0), rtol=1e-5)
    np.testing.assert_array_equal(pairwise_reduce(jnp.asarray(x), jnp.maximum), x.max(axis=0))


def test_default_preprocessing_per_label(default_world):
    """Statistics methods take every usable pixel; the world-based and constant ones the thesis' ave5."""
    want = {
        "GW": "pixels",
        "shades-of-grey-p6": "pixels",
        "RETINEX": "pixels",
        "max-rgb": "pixels",
        "soft-RETINEX-t0.01": "pixels",
        "DB-GW": "ave5",
        "NOTHING": "ave5",
        "AVE-ILLUM": "ave5",
    }
    for label, name in want.items():
        assert registry.fit(label, default_world).default_preprocessing == name, label


def test_tiny_scenes_are_estimated(models, run):
    """with_fallback's light test is scale-free: a scene at 1e-30 (far below the old absolute
    1e-12 threshold on the estimate's sum) is still a scene, with the same chromaticity."""
    rgb = np.random.default_rng(7).uniform(0.1, 1.0, (P, 3)).astype(np.float32)
    mask = np.ones(P, bool)
    for label in ["GW", "DB-GW", "RETINEX"]:
        base = run(models[label], rgb, mask)
        tiny = run(models[label], rgb * np.float32(1e-30), mask)
        assert bool(tiny.ok), label
        np.testing.assert_allclose(np.asarray(tiny.illuminant) * 1e30, base.illuminant, rtol=1e-5)


@pytest.mark.parametrize(
    ("typo", "suggested"),
    [
        ("grey-egde-1-6-2", "'grey-edge-1-6-2' (grey-edge-<n>-<p>-<sigma>"),
        ("greyworld", "'GW'"),
        ("Grey World", "'GW'"),
        ("shades-of-gray-p6", "'shades-of-grey-p6' (shades-of-grey-p<P>)"),
        ("maxrgb", "'MAX-RGB'"),
    ],
)
def test_a_mistyped_label_gets_a_did_you_mean_and_a_short_message(typo, suggested):
    with pytest.raises(ValueError) as error:
        registry.lookup(typo)
    message = str(error.value)
    assert message.startswith(f"method: unknown label {typo!r}; did you mean {suggested}")
    assert "`ccjax methods`" in message and len(message) < 300  # not the ~900-character grammar
    with pytest.raises(ValueError, match=r"unknown label 'xyz'; `ccjax methods`"):
        registry.lookup("xyz")


def test_gw_and_max_rgb_are_accepted_in_lower_case(default_world):
    rgb = jnp.asarray(np.random.default_rng(2).uniform(0.1, 1.0, (16, 3)), jnp.float32)
    mask = jnp.ones(16, bool)
    for lower, upper in (("gw", "GW"), ("max-rgb", "RETINEX")):
        got = registry.fit(lower, default_world)(rgb, mask).illuminant
        np.testing.assert_array_equal(got, registry.fit(upper, default_world)(rgb, mask).illuminant)
    np.testing.assert_allclose(
        registry.fit("gw", default_world)(rgb, mask).illuminant, 2 * np.asarray(rgb, np.float64).mean(axis=0), rtol=1e-6
    )
