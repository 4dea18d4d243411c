"""``ccjax.estimate`` on images: the command line's pixel rule (clipped and zero-channel pixels
dropped) applied by default, for every family, against NumPy oracles."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import ndimage
from spatial_reference import grey_edge_reference

import ccjax
from ccjax.io.reading import LinearImage
from ccjax.preprocessing import estimate_image
from ccjax.runs import store

CAST = np.array([1.0, 0.62, 0.35])  # a warm (tungsten-like) light, camera RGB


def degrees(a, b) -> float:
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    cosine = a @ b / np.linalg.norm(a) / np.linalg.norm(b)
    return float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))))


def photo(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A 48x64 image of smooth grey-ish surfaces under ``CAST``, with one clipped patch (a
    saturated highlight: red at the sensor's limit, green and blue not), and its clipped mask."""
    rng = np.random.default_rng(seed)
    albedo = ndimage.gaussian_filter(rng.uniform(0.2, 1.0, (48, 64, 3)), (3, 3, 0))
    image = (0.55 * albedo * CAST).astype(np.float32)
    image[10:22, 30:46] = [1.0, 0.93, 0.41]  # a red-clipped patch: its colour is the sensor's, not the light's
    clipped = np.any(image >= 0.98, axis=-1)
    assert clipped.sum() == 12 * 16
    return image, clipped


def test_grey_edge_drops_the_clipped_patch_as_the_numpy_oracle_does():
    """Without a mask the array API drops the clipped patch (saturation 0.98 by default): the
    NumPy grey edge on the unclipped pixels agrees, and the estimate is near the cast; with
    ``saturation=None`` every pixel is used, as the oracle with an all-True mask."""
    image, clipped = photo()
    got = np.asarray(ccjax.estimate("grey-edge-1-6-2", image).illuminant)
    want = grey_edge_reference(image.astype(np.float64), ~clipped, 1, 6.0, 2.0)
    assert degrees(got, want) < 0.01
    everything = grey_edge_reference(image.astype(np.float64), np.ones(clipped.shape, bool), 1, 6.0, 2.0)
    assert degrees(want, everything) > 2.0  # the patch matters: the test can tell the rules apart
    assert degrees(got, CAST) < degrees(everything, CAST)
    unmasked = np.asarray(ccjax.estimate("grey-edge-1-6-2", image, saturation=None).illuminant)
    assert degrees(unmasked, everything) < 0.01


def test_saturation_is_in_the_inputs_units_and_a_user_mask_combines_with_it():
    image, clipped = photo()
    scaled = np.asarray(ccjax.estimate("grey-edge-1-6-2", image * 1000, saturation=980.0).illuminant)
    want = grey_edge_reference(image.astype(np.float64), ~clipped, 1, 6.0, 2.0)
    assert degrees(scaled, want) < 0.01
    user = np.ones(clipped.shape, bool)
    user[:, :8] = False
    got = np.asarray(ccjax.estimate("grey-edge-1-6-2", image, user).illuminant)
    assert degrees(got, grey_edge_reference(image.astype(np.float64), user & ~clipped, 1, 6.0, 2.0)) < 0.01


@pytest.mark.parametrize(
    ("saturation", "message"),
    [(0.0, "saturation: expected a positive number"), (float("nan"), "saturation: expected a positive number")],
)
def test_bad_saturation_is_refused(saturation, message):
    image, _ = photo()
    with pytest.raises(ValueError, match=message):
        ccjax.estimate("GW", image, saturation=saturation)


def test_integer_images_with_a_unit_saturation_are_refused():
    image, _ = photo()
    with pytest.raises(ValueError, match=r"saturation: 0.98 is on the unit scale but the image holds integers"):
        ccjax.estimate("GW", (image * 65535).astype(np.uint16))


@pytest.mark.parametrize("label", ["GW", "shades-of-grey-p6", "MAX-RGB"])
def test_statistics_methods_take_an_image_and_match_numpy(label):
    """Grey world, shades of grey and max-RGB on an image: the Minkowski mean of the usable pixels
    (no clipped, no zero channel), in NumPy."""
    image, clipped = photo(1)
    image[0, :5] = [0.0, 0.2, 0.1]  # a zero channel: no information on red, dropped
    usable = ~clipped & np.all(image > 0, axis=-1)
    pixels = image[usable].astype(np.float64)
    p = {"GW": 1.0, "shades-of-grey-p6": 6.0, "MAX-RGB": np.inf}[label]
    want = pixels.max(axis=0) if np.isinf(p) else np.mean(pixels**p, axis=0) ** (1 / p)
    got = np.asarray(ccjax.estimate(label, image).illuminant)
    assert degrees(got, want) < 0.01, label


def test_a_world_based_method_gets_the_command_lines_input_and_ignores_the_clipped_patch():
    """DB-GW (block averages, ave5) on an image: the same estimate as the image pipeline on the
    photograph with its clipped mask; the patch's pixels, replaced by anything, change nothing."""
    image, clipped = photo(2)
    model = store.fit("DB-GW", store.world())
    got = np.asarray(ccjax.estimate(model, image).illuminant)
    want = np.asarray(estimate_image(model, LinearImage(rgb=image, clipped=clipped)).illuminant)
    np.testing.assert_allclose(got, want, rtol=1e-6)
    other = image.copy()
    other[clipped] = [0.99, 0.2, 0.99]
    np.testing.assert_allclose(np.asarray(ccjax.estimate(model, other).illuminant), got, rtol=1e-6)


def test_image_batches_take_the_same_rule_as_single_images():
    first, _ = photo(3)
    second, _ = photo(4)
    batch = np.stack([first, second])
    for label in ("GW", "grey-edge-1-6-2"):
        many = np.asarray(ccjax.estimate(label, batch).illuminant)
        for index, image in enumerate((first, second)):
            one = np.asarray(ccjax.estimate(label, image).illuminant)
            np.testing.assert_allclose(many[index], one, rtol=2e-5, err_msg=label)
    with pytest.raises(ValueError, match=r"image: GreyWorld takes ave5 surface lists .*one image \(H, W, 3\)"):
        ccjax.estimate("DB-GW", batch)


def test_surface_lists_are_unchanged():
    """A ``(P, 3)`` surface list is used as given: values above the clip level count."""
    rgb = np.array([[0.99, 0.5, 0.2], [0.2, 0.4, 0.6]], np.float32)
    got = np.asarray(ccjax.estimate("GW", rgb).illuminant)
    assert degrees(got, rgb.mean(axis=0)) < 1e-4


def test_estimate_inside_jit_says_to_fit_outside_and_the_advice_works():
    rgb = jnp.asarray(np.random.default_rng(0).uniform(0.1, 1.0, (12, 3)), jnp.float32)
    with pytest.raises(TypeError, match=r"x: ccjax.estimate was called on a traced value.*ccjax.fit"):
        jax.jit(lambda x: ccjax.estimate("GW", x).illuminant)(rgb)
    model = ccjax.fit("GW", ccjax.World.default())
    inside = jax.jit(lambda x: model(x, jnp.ones(x.shape[0], bool)).illuminant)(rgb)
    # Grey world's estimate is the mean of the surfaces, up to its fitted scale (a closed form).
    mean = np.asarray(rgb, np.float64).mean(axis=0)
    np.testing.assert_allclose(np.asarray(inside) / np.asarray(inside)[1], mean / mean[1], rtol=1e-5)
