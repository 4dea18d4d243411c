"""Grey edge (estimators/spatial.py) against the NumPy/SciPy reference, special cases, batching,
fallbacks and gradients."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads
from small_world import small_world
from spatial_reference import grey_edge_reference

from ccjax.estimators import registry
from ccjax.estimators.spatial import GreyEdge, fit_grey_edge
from ccjax.world import World

FALLBACK = jnp.array([0.5, 0.6, 0.7])


def _image(seed=0, shape=(23, 31)):
    rng = np.random.default_rng(seed)
    # Smooth structure plus texture, so every derivative order has signal in every channel.
    y, x = np.mgrid[: shape[0], : shape[1]]
    base = np.stack([np.sin(x / 4.0 + c) * np.cos(y / 5.0 - c) for c in range(3)], -1)
    image = (0.5 + 0.3 * base + 0.2 * rng.random(shape + (3,))) * np.array([0.9, 0.6, 0.4])
    mask = np.ones(shape, bool)
    h, w = shape
    mask[h // 4, w // 4] = mask[2 * h // 3, 2 * w // 3] = mask[0, w - 1] = (
        False  # isolated invalid pixels (e.g. clipped)
    )
    return image.astype(np.float32), mask


CASES = [(order, p, sigma) for order in (0, 1, 2) for p in (1.0, 6.0, math.inf) for sigma in (0.0, 1.0, 2.0)]


@pytest.fixture(scope="module")
def all_estimates():
    """Every (n, p, sigma) case of the acceptance grid in one compiled function (one compile)."""
    image, mask = _image()
    models = [GreyEdge(order=o, p=p, sigma=s, fallback=FALLBACK) for o, p, s in CASES]
    run = jax.jit(lambda x, m: [model(x, m) for model in models])
    return image, mask, run(jnp.asarray(image), jnp.asarray(mask))


@pytest.mark.parametrize("case", range(len(CASES)), ids=[f"n{o}-p{p}-s{s}" for o, p, s in CASES])
def test_matches_reference(all_estimates, case):
    image, mask, estimates = all_estimates
    order, p, sigma = CASES[case]
    want = grey_edge_reference(image.astype(np.float64), mask, order, p, sigma)
    assert bool(estimates[case].ok)
    np.testing.assert_allclose(np.asarray(estimates[case].illuminant), want, rtol=1e-4)


def _rg(v):
    v = np.asarray(v, np.float64)
    return v[:2] / v.sum()


def test_special_cases_match_surface_methods():
    """(0, 1, 0) is grey world, (0, inf, 0) max-RGB, (0, p, 0) shades of grey (chromaticity)."""
    from ccjax.estimators.simple import GreyWorld, MaxRGB, ShadesOfGrey

    image, mask = _image(3)
    x, m = jnp.asarray(image), jnp.asarray(mask)
    px, pm = x.reshape(-1, 3), m.ravel()
    pairs = [
        (GreyEdge(order=0, p=1.0, sigma=0.0, fallback=FALLBACK), GreyWorld(scale=jnp.full(3, 2.0), fallback=FALLBACK)),
        (GreyEdge(order=0, p=math.inf, sigma=0.0, fallback=FALLBACK), MaxRGB(fallback=FALLBACK)),
        (GreyEdge(order=0, p=6.0, sigma=0.0, fallback=FALLBACK), ShadesOfGrey(p=6.0, fallback=FALLBACK)),
    ]
    run = jax.jit(lambda: [(edge(x, m).illuminant, pixels(px, pm).illuminant) for edge, pixels in pairs])
    for edge, pixels in run():
        np.testing.assert_allclose(_rg(edge), _rg(pixels), atol=1e-6)


def test_labels_parse():
    entry, match = registry.lookup("grey-edge-1-inf-1")
    assert (match["n"], match["p"], match["sigma"]) == ("1", "inf", "1")
    assert (entry.input_kind, entry.traceable_fit, entry.differentiable) == ("image", True, True)
    model = registry.fit("grey-edge-1-inf-1", World.default())
    assert (model.order, float(model.p), model.sigma) == (1, math.inf, 1.0)
    with pytest.raises(ValueError, match="method"):
        registry.lookup("grey-edge-3-1-1")


def test_fit_validates():
    world = small_world()  # only the fallback is taken from the world
    for kwargs, name in [({"order": 3}, "order"), ({"p": 0.5}, "p"), ({"sigma": -1.0}, "sigma")]:
        with pytest.raises(ValueError, match=name):
            fit_grey_edge(world, **kwargs)


def test_vmap_over_batch_equals_per_image():
    images = np.stack([_image(s)[0] for s in range(3)])
    masks = np.stack([_image(s)[1] for s in range(3)])
    model = GreyEdge(order=1, p=6.0, sigma=0.0, fallback=FALLBACK)
    batched = jax.jit(jax.vmap(model))(jnp.asarray(images), jnp.asarray(masks))
    for i in range(3):
        single = eqx.filter_jit(model)(jnp.asarray(images[i]), jnp.asarray(masks[i]))
        np.testing.assert_allclose(np.asarray(batched.illuminant[i]), np.asarray(single.illuminant), rtol=1e-5)


def test_flat_or_masked_image_falls_back():
    model = eqx.filter_jit(GreyEdge(order=1, p=6.0, sigma=1.0, fallback=FALLBACK))
    image, _ = _image()
    flat = model(jnp.full(image.shape, 0.4, jnp.float32), jnp.ones(image.shape[:2], bool))
    assert not bool(flat.ok) and np.allclose(flat.illuminant, FALLBACK)
    masked = model(jnp.asarray(image), jnp.zeros(image.shape[:2], bool))
    assert not bool(masked.ok) and np.all(np.isfinite(masked.illuminant))


def test_scale_equivariance_and_channel_independence():
    image, mask = _image(5)
    model = eqx.filter_jit(GreyEdge(order=2, p=6.0, sigma=1.0, fallback=FALLBACK))
    base = np.asarray(model(jnp.asarray(image), jnp.asarray(mask)).illuminant)
    scaled = np.asarray(model(jnp.asarray(image * np.array([2.0, 0.5, 3.0], np.float32)), jnp.asarray(mask)).illuminant)
    np.testing.assert_allclose(scaled, base * np.array([2.0, 0.5, 3.0]), rtol=1e-5)


@pytest.mark.parametrize(
    "order, p, sigma",
    [
        (1, 6.0, 1.0),
        pytest.param(2, 1.0, 0.0, marks=pytest.mark.slow),
        pytest.param(0, math.inf, 1.0, marks=pytest.mark.slow),
    ],
)
def test_gradients(order, p, sigma):
    with jax.enable_x64(True):
        image, mask = _image(7, (9, 11))
        model = GreyEdge(order=order, p=p, sigma=sigma, fallback=jnp.asarray(FALLBACK, jnp.float64))
        mask_j = jnp.asarray(mask)

        @jax.jit
        def chromaticity(x):
            e = model(x, mask_j).illuminant
            return e / jnp.sum(e)

        x = jnp.asarray(image, jnp.float64)
        check_grads(chromaticity, (x,), order=1, modes=("rev",), eps=1e-6, atol=1e-5, rtol=1e-5)
        gradient = jax.grad(lambda x: chromaticity(x)[0])(x)
        assert float(jnp.linalg.norm(gradient)) > 0


@pytest.mark.slow
def test_gradient_with_respect_to_the_norm():
    """``p`` is a learnable array: d(chromaticity)/dp matches finite differences (x64), is non-zero,
    and the jitted model (p traced) gives the eager answer."""
    with jax.enable_x64(True):
        image, mask = _image(3, (9, 11))
        image, mask_j = jnp.asarray(image, jnp.float64), jnp.asarray(mask)
        model = GreyEdge(order=1, p=jnp.asarray(4.0), sigma=1.0, fallback=jnp.asarray(FALLBACK, jnp.float64))

        def chromaticity(p):
            e = eqx.tree_at(lambda m: m.p, model, jnp.asarray(p))(image, mask_j).illuminant  # probes are NumPy
            return e / jnp.sum(e)

        check_grads(chromaticity, (jnp.asarray(4.0),), order=1, modes=("rev",), eps=1e-6, atol=1e-6, rtol=1e-5)
        assert float(jnp.linalg.norm(jax.jacrev(chromaticity)(jnp.asarray(4.0)))) > 1e-6
        traced = jax.jit(lambda m, x, k: m(x, k))(model, image, mask_j).illuminant
        np.testing.assert_allclose(traced, model(image, mask_j).illuminant, rtol=1e-12)


def test_tiny_images_are_estimated():
    """No absolute threshold: an image scaled by 1e-15 gives the same estimate scaled by 1e-15
    (the old 1e-12 floor on the edges made it fall back; much smaller and float32 squares of the
    derivatives underflow); a black image still falls back."""
    image, mask = _image(3)
    estimator = GreyEdge(order=1, p=6.0, sigma=1.0, fallback=FALLBACK)
    assert estimator.default_preprocessing == "pixels"
    model = eqx.filter_jit(estimator)
    base = model(jnp.asarray(image), jnp.asarray(mask))
    tiny = model(jnp.asarray(image * np.float32(1e-15)), jnp.asarray(mask))
    assert bool(base.ok) and bool(tiny.ok)
    np.testing.assert_allclose(np.asarray(tiny.illuminant) * 1e15, base.illuminant, rtol=1e-4)
    black = model(jnp.zeros(image.shape, jnp.float32), jnp.asarray(mask))
    assert not bool(black.ok) and np.allclose(black.illuminant, FALLBACK)
