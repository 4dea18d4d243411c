"""Synthetic scenes (Barnard 1999 §4.7): sampling, the one draw function, specular recipe,
clipping, noise, reproducibility."""

import jax
import numpy as np
import pytest

from ccjax import scenes
from ccjax.scenes import (
    SceneTables,
    ShotNoise,
    Specular,
    draw_scene,
    draw_scenes,
    sample,
    sample_batch,
    scene_keys,
    sweep_keys,
)
from ccjax.scenes import _options as scene_options


@pytest.mark.parametrize("n_surfaces", [1, 8, 64, 65, 1024, 1993])
def test_draws_are_distinct_and_in_range(n_surfaces):
    keys = scene_keys(jax.random.key(0), 0, 20)
    draws = np.asarray(jax.vmap(lambda k: scenes.draw_without_replacement(k, 1993, n_surfaces))(keys))
    assert draws.min() >= 0 and draws.max() < 1993
    assert all(len(set(row)) == n_surfaces for row in draws.tolist())


@pytest.mark.parametrize("n_surfaces", [8, 200])
def test_rgb_is_physical(default_world, n_surfaces):
    batch = sample(jax.random.key(0), default_world, 50, n_surfaces)
    # rgb = reflectance x light: white under the scene light bounds each channel (reflectance <= 1).
    assert np.all(np.asarray(batch.rgb) <= np.asarray(batch.illuminant)[:, None, :] * 1.0001)
    assert np.all(np.asarray(batch.mask))


def test_floyd_sampler_is_uniform():
    keys = scene_keys(jax.random.key(3), 0, 20000)
    draws = jax.vmap(lambda k: scenes.draw_without_replacement(k, 10, 4))(keys)
    counts = np.bincount(np.asarray(draws).ravel(), minlength=10)
    expected = 20000 * 4 / 10
    assert np.all(np.abs(counts - expected) < 5 * np.sqrt(expected))
    assert all(len(set(row)) == 4 for row in np.asarray(draws)[:500].tolist())


def test_scene_rgb_matches_spectral_product(default_world):
    """One scene recomputed from spectra with NumPy (reflectance x illuminant @ sensors)."""
    batch = sample(jax.random.key(5), default_world, 3, 6)
    refl = np.asarray(default_world.reflectances, dtype=np.float64)
    lights = np.asarray(default_world.test_illuminants, dtype=np.float64)
    sensors = np.asarray(default_world.camera.sensors, dtype=np.float64)
    canon = refl @ (np.asarray(default_world.canonical, dtype=np.float64)[:, None] * sensors)
    whites = lights @ sensors
    for b in range(3):
        light = int(np.argmin(np.abs(whites - np.asarray(batch.illuminant[b])).sum(axis=1)))
        for p in range(6):
            s = int(np.argmin(np.abs(canon - np.asarray(batch.canonical_rgb[b, p])).sum(axis=1)))
            want = (refl[s] * lights[light]) @ sensors
            np.testing.assert_allclose(np.asarray(batch.rgb[b, p]), want, rtol=2e-4, atol=1e-6)


def test_specular_recipe(default_world):
    matte = sample(jax.random.key(9), default_world, 4000, 8)
    spec = sample(jax.random.key(9), default_world, 4000, 8, specular=True)
    # Same key -> same surfaces and lights; the difference is amount x white with amount ~ U(0,2) w.p. 0.25.
    diff = np.asarray(spec.rgb - matte.rgb)
    white = np.asarray(spec.illuminant)[:, None, :]
    amount = (diff / white)[..., 1]
    np.testing.assert_allclose(diff, amount[..., None] * white, atol=1e-5)
    specular = amount > 1e-6
    assert abs(specular.mean() - 0.25) < 0.01
    assert abs(amount[specular].mean() - 1.0) < 0.03 and amount.max() <= 2.0


def test_clip_masks_surfaces_above_the_level(default_world):
    batch = sample(jax.random.key(1), default_world, 500, 8, specular=True, clip=300 / 255)
    rgb, mask = np.asarray(batch.rgb), np.asarray(batch.mask)
    np.testing.assert_array_equal(mask, np.all(rgb <= 300 / 255, axis=-1))
    assert 0 < (~mask).mean() < 0.3


def test_noise_statistics(default_world):
    clean = sample(jax.random.key(2), default_world, 2000, 16)
    noise = ShotNoise(a=1e-3, b=1e-6)
    noisy = sample(jax.random.key(2), default_world, 2000, 16, noise=noise)
    rho = np.asarray(clean.rgb)
    z = (np.asarray(noisy.rgb) - rho) / np.sqrt(noise.a * rho + noise.b)
    bright = rho > 0.05  # away from the clamp at zero
    assert abs(z[bright].mean()) < 0.02 and abs(z[bright].std() - 1) < 0.02


def test_chunking_does_not_change_scenes(default_world):
    tables = SceneTables.from_world(default_world)
    key = jax.random.key(11)
    whole = sample_batch(scene_keys(key, 0, 10), tables, 8)
    part = sample_batch(scene_keys(key, 6, 4), tables, 8)
    np.testing.assert_array_equal(np.asarray(whole.rgb[6:]), np.asarray(part.rgb))


def test_bad_arguments(default_world):
    with pytest.raises(ValueError, match="n_surfaces"):
        sample(jax.random.key(0), default_world, 2, 5000)
    with pytest.raises(ValueError, match="n_scenes"):
        sample(jax.random.key(0), default_world, 0, 8)
    with pytest.raises(ValueError, match="clip"):
        sample(jax.random.key(0), default_world, 2, 8, clip=-1.0)
    with pytest.raises(ValueError, match=r"Specular\.probability"):
        sample(jax.random.key(0), default_world, 2, 8, specular=Specular(probability=2.0))


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: Specular(max_amount=float("nan")), "Specular.max_amount"),
        (lambda: Specular(max_amount=float("inf")), "Specular.max_amount"),
        (lambda: Specular(max_amount=-1.0), "Specular.max_amount"),
        (lambda: Specular(probability=-0.1), "Specular.probability"),
        (lambda: Specular(probability=1.5), "Specular.probability"),
        (lambda: Specular(probability=float("nan")), "Specular.probability"),
        (lambda: ShotNoise(b=float("nan")), "ShotNoise.b"),
        (lambda: ShotNoise(b=-1e-6), "ShotNoise.b"),
        (lambda: ShotNoise(a=-1.0), "ShotNoise.a"),
        (lambda: ShotNoise(a=float("nan")), "ShotNoise.a"),
    ],
)
def test_sampling_parameters_are_validated(make, field):
    """NaN, infinite, negative or out-of-range options are refused naming the field,
    instead of producing NaN RGB."""
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        make()


def test_sampling_parameters_at_the_edges_are_accepted(default_world):
    batch = sample(
        jax.random.key(0),
        default_world,
        3,
        4,
        specular=Specular(probability=1.0, max_amount=0.0),
        noise=ShotNoise(0.0, 0.0),
    )
    assert np.isfinite(np.asarray(batch.rgb)).all()


def test_integer_like_counts_are_accepted(default_world):
    key = jax.random.key(2)
    plain = sample(key, default_world, 3, 4)
    numpy_ints = sample(key, default_world, np.int32(3), np.int64(4))
    np.testing.assert_array_equal(np.asarray(plain.rgb), np.asarray(numpy_ints.rgb))
    assert numpy_ints.rgb.shape == (3, 4, 3)


@pytest.mark.parametrize("bad", [4.0, 4.5, "4", True, None])
def test_non_integer_counts_are_refused(default_world, bad):
    """A clear ValueError naming the count (under the suite's beartype hooks a non-integer is
    refused even earlier, by the ``SupportsIndex`` annotation of ``sample``)."""
    with pytest.raises(ValueError, match="n_surfaces: expected an integer in \\[1, 9\\]"):
        scene_options.require_count(bad, "n_surfaces", 1, 9)
    with pytest.raises((ValueError, TypeError), match=r"n_surfaces|n_scenes"):
        sample(jax.random.key(0), default_world, 2, bad)


def test_out_of_range_counts_name_the_argument(default_world):
    with pytest.raises(ValueError, match=r"n_surfaces: expected an integer in \[1, \d+\], got 0"):
        sample(jax.random.key(0), default_world, 2, np.int64(0))
    with pytest.raises(ValueError, match="n_patches"):
        scenes.sample_mondrians(jax.random.key(0), default_world, 1, height=8, width=8, n_patches=np.int64(10**6))
    images = scenes.sample_mondrians(
        jax.random.key(0), default_world, np.int64(1), height=np.int64(8), width=8, n_patches=4
    )
    assert images.image.shape[:3] == (1, 8, 8)


def test_samples_are_drawn_by_draw_scene(default_world):
    """``sample`` gathers the light and surfaces :func:`draw_scene` draws from each scene key."""
    key = jax.random.key(4)
    batch = sample(key, default_world, 30, 8, specular=True, noise=True)
    n_lights, n_reflectances = default_world.test_illuminants.shape[0], default_world.reflectances.shape[0]
    keys = scene_keys(key, 0, 30)
    drawn = draw_scenes(keys, n_lights, n_reflectances, 8)
    tables = SceneTables.from_world(default_world)
    np.testing.assert_array_equal(np.asarray(batch.illuminant), np.asarray(tables.whites[drawn.light]))
    # Canonical RGBs identify the surfaces (specular amounts add a multiple of white to both).
    matte = sample(key, default_world, 30, 8)
    np.testing.assert_array_equal(np.asarray(matte.canonical_rgb), np.asarray(tables.canonical_rgb[drawn.surfaces]))
    one = draw_scene(keys[3], n_lights, n_reflectances, 8)
    assert int(one.light) == int(drawn.light[3])
    np.testing.assert_array_equal(np.asarray(one.surfaces), np.asarray(drawn.surfaces[3]))
    assert all(len(set(row)) == 8 for row in np.asarray(drawn.surfaces).tolist())


def test_sweep_keys_are_the_surface_count_stream():
    key = jax.random.key(8)
    np.testing.assert_array_equal(
        jax.random.key_data(sweep_keys(key, 8, 5, 3)),
        jax.random.key_data(scene_keys(jax.random.fold_in(key, 8), 5, 3)),
    )
    assert not np.array_equal(
        jax.random.key_data(sweep_keys(key, 8, 0, 3)), jax.random.key_data(sweep_keys(key, 9, 0, 3))
    )


# -- materials: metallic highlights (§8.3) and fluorescent surfaces (§7.3) -----------------------


@pytest.fixture(scope="module")
def material_tables(default_world):
    from ccjax.materials import synthetic_fluorescent_surfaces

    return SceneTables.from_world(default_world, metals=True, fluorescent=synthetic_fluorescent_surfaces())


def _drawn(default_world, keys, n_surfaces):
    n_lights, n_reflectances = default_world.test_illuminants.shape[0], default_world.reflectances.shape[0]
    return draw_scenes(keys, n_lights, n_reflectances, n_surfaces)


def test_material_tables_are_spectral_products(default_world, material_tables):
    """Metal and fluorescent tables recomputed from spectra with NumPy; the scenes' metals are the
    six metals' own reflectances (§8.3: highlights at most four times a perfect white)."""
    from ccjax.materials import METALS, metal_reflectance, synthetic_fluorescent_surfaces

    lights = np.asarray(default_world.test_illuminants, dtype=np.float64)
    sensors = np.asarray(default_world.camera.sensors, dtype=np.float64)
    canonical = np.asarray(default_world.canonical, dtype=np.float64)
    metals = np.stack([metal_reflectance(name) for name in METALS])
    assert metals.max() <= 1.0
    np.testing.assert_allclose(
        np.asarray(material_tables.metal_rgb[7]), (metals * lights[7]) @ sensors, rtol=2e-4, atol=1e-6
    )
    np.testing.assert_allclose(
        np.asarray(material_tables.canonical_metal_rgb), (metals * canonical) @ sensors, rtol=2e-4, atol=1e-6
    )
    model = synthetic_fluorescent_surfaces()
    rho, emission = np.asarray(model.reflectance, np.float64), np.asarray(model.emission, np.float64)
    radiance = rho * lights[7] + emission @ lights[7]  # (F, 101)
    np.testing.assert_allclose(np.asarray(material_tables.fluorescent_rgb[7]), radiance @ sensors, rtol=2e-4, atol=1e-6)


def test_metallic_recipe(default_world, material_tables):
    """Same keys: the metallic scenes are the matte ones plus s * M under the scene light, s ~ U(0, 4)
    on a quarter of the surfaces, M uniform over the six metals; canonical RGBs gain s * M too."""
    keys = scene_keys(jax.random.key(9), 0, 3000)
    matte = sample_batch(keys, material_tables, 8)
    metal = sample_batch(keys, material_tables, 8, metallic=scenes.Metallic())
    light = np.asarray(_drawn(default_world, keys, 8).light)
    diff = np.asarray(metal.rgb - matte.rgb, dtype=np.float64)  # (B, P, 3)
    candidates = np.asarray(material_tables.metal_rgb, dtype=np.float64)[light]  # (B, M, 3)
    # Each difference is a non-negative multiple of exactly one metal's RGB under the scene light.
    strength = np.einsum("bpc,bmc->bpm", diff, candidates) / np.einsum("bmc,bmc->bm", candidates, candidates)[:, None]
    residual = np.linalg.norm(diff[:, :, None, :] - strength[..., None] * candidates[:, None], axis=-1)
    best = residual.argmin(axis=-1)
    s = np.take_along_axis(strength, best[..., None], axis=-1)[..., 0]
    assert np.all(residual.min(axis=-1) <= 1e-4 * (1 + np.linalg.norm(diff, axis=-1)))
    has = s > 1e-5
    assert abs(has.mean() - 0.25) < 0.01
    assert abs(s[has].mean() - 2.0) < 0.06 and s.max() <= 4.0 + 1e-4
    counts = np.bincount(best[has], minlength=6)
    assert np.all(np.abs(counts - has.sum() / 6) < 5 * np.sqrt(has.sum() / 6))
    canonical = np.asarray(material_tables.canonical_metal_rgb, dtype=np.float64)[best]
    np.testing.assert_allclose(
        np.asarray(metal.canonical_rgb - matte.canonical_rgb), s[..., None] * canonical, atol=2e-4
    )
    np.testing.assert_array_equal(np.asarray(metal.illuminant), np.asarray(matte.illuminant))


def test_fluorescent_recipe(default_world, material_tables):
    """Each slot fluorescent with p = 0.3 (A21), identity uniform over the nine, under the scene
    light and the canonical one; other slots keep their drawn reflectance."""
    keys = scene_keys(jax.random.key(3), 0, 3000)
    matte = sample_batch(keys, material_tables, 8)
    mixed = sample_batch(keys, material_tables, 8, fluorescent=scenes.Fluorescent())
    light = np.asarray(_drawn(default_world, keys, 8).light)
    table = np.asarray(material_tables.fluorescent_rgb)[light]  # (B, F, 3)
    rgb = np.asarray(mixed.rgb)
    distance = np.abs(rgb[:, :, None, :] - table[:, None]).max(axis=-1)  # (B, P, F)
    is_fluorescent = distance.min(axis=-1) <= 1e-6
    changed = np.any(rgb != np.asarray(matte.rgb), axis=-1)
    np.testing.assert_array_equal(is_fluorescent, changed)
    assert abs(is_fluorescent.mean() - 0.3) < 0.01
    identity = distance.argmin(axis=-1)[is_fluorescent]
    expected = is_fluorescent.sum() / 9
    assert np.all(np.abs(np.bincount(identity, minlength=9) - expected) < 5 * np.sqrt(expected))
    canonical = np.asarray(material_tables.canonical_fluorescent_rgb)[identity]
    np.testing.assert_allclose(np.asarray(mixed.canonical_rgb)[is_fluorescent], canonical, rtol=1e-6)


def test_materials_finite_reproducible_and_masked(default_world):
    """All options together: finite, the clip mask is exactly the level test, same key -> same scenes,
    and the options off leave the scenes exactly as before (their draws are folded off the key)."""
    key = jax.random.key(12)
    options = dict(specular=True, metallic=True, fluorescent=True, noise=True, clip=300 / 255)
    one = sample(key, default_world, 200, 16, **options)
    two = sample(key, default_world, 200, 16, **options)
    rgb, mask = np.asarray(one.rgb), np.asarray(one.mask)
    assert np.isfinite(rgb).all() and np.isfinite(np.asarray(one.canonical_rgb)).all()
    np.testing.assert_array_equal(mask, np.all(rgb <= 300 / 255, axis=-1))
    assert 0 < (~mask).mean() < 0.6
    np.testing.assert_array_equal(rgb, np.asarray(two.rgb))
    plain = sample(key, default_world, 200, 16, specular=True, noise=True, clip=300 / 255)
    off = sample(key, default_world, 200, 16, specular=True, noise=True, clip=300 / 255, metallic=False)
    np.testing.assert_array_equal(np.asarray(plain.rgb), np.asarray(off.rgb))


def test_material_options_are_validated(default_world):
    with pytest.raises(ValueError, match=r"Metallic\.probability"):
        scenes.Metallic(probability=float("nan"))
    with pytest.raises(ValueError, match=r"Metallic\.max_amount"):
        scenes.Metallic(max_amount=-1.0)
    with pytest.raises(ValueError, match=r"Fluorescent\.probability"):
        scenes.Fluorescent(probability=1.5)
    tables = SceneTables.from_world(default_world)
    keys = scene_keys(jax.random.key(0), 0, 2)
    with pytest.raises(ValueError, match="metallic: the scene tables have no metals"):
        sample_batch(keys, tables, 4, metallic=scenes.Metallic())
    with pytest.raises(ValueError, match="fluorescent: the scene tables have no fluorescent"):
        sample_batch(keys, tables, 4, fluorescent=scenes.Fluorescent())
    with pytest.raises(ValueError, match="metals"):
        SceneTables.from_world(default_world, metals=-np.ones((2, 101)))
    with pytest.raises(ValueError, match="metallic: expected True, None or a Metallic"):
        scene_options.resolve_materials("yes", None)
    with pytest.raises(ValueError, match="fluorescent: expected True, None or a Fluorescent"):
        scene_options.resolve_materials(None, scenes.Specular())


def test_mondrian_materials(default_world, material_tables):
    """Mondrians: fluorescent patches carry a fluorescent surface's RGB (times the patch shading),
    metallic highlights are a multiple of one metal's RGB under the image's light, and the options
    off leave every image unchanged."""
    keys = scene_keys(jax.random.key(21), 0, 40)
    render = lambda normalise=False, **options: scenes.mondrian_batch(
        keys, material_tables, 24, 24, 9, normalise=normalise, **options
    )
    matte = render()
    off = scenes.sample_mondrians(jax.random.key(21), default_world, 40, height=24, width=24, n_patches=9)
    np.testing.assert_array_equal(np.asarray(off.image), np.asarray(render(normalise=True).image))
    assert matte.fluorescent is None

    mixed = render(fluorescent=scenes.Fluorescent(probability=0.5))
    identity = np.asarray(mixed.fluorescent)
    assert 0.35 < (identity >= 0).mean() < 0.65 and identity.max() < 9
    light = np.argmin(
        np.abs(np.asarray(matte.illuminant)[:, None] - np.asarray(material_tables.whites)[None]).sum(-1), axis=1
    )
    labels, image = np.asarray(mixed.labels), np.asarray(mixed.image)
    shade = (
        np.asarray(matte.image)
        / np.asarray(material_tables.surface_rgb)[light[:, None], np.asarray(matte.surfaces)][
            np.arange(40)[:, None, None], labels
        ]
    )  # the patch shading, per pixel (same render key, same shading)
    fluorescent_rgb = np.asarray(material_tables.fluorescent_rgb)[light[:, None], np.maximum(identity, 0)]
    want = np.where(
        (identity >= 0)[np.arange(40)[:, None, None], labels][..., None],
        fluorescent_rgb[np.arange(40)[:, None, None], labels] * shade,
        np.asarray(matte.image),
    )
    np.testing.assert_allclose(image, want, rtol=1e-4, atol=1e-6)

    metal = render(metallic=scenes.Metallic(probability=1.0))
    diff = np.asarray(metal.image - matte.image, dtype=np.float64)  # (B, H, W, 3)
    candidates = np.asarray(material_tables.metal_rgb, dtype=np.float64)[light]  # (B, M, 3)
    unit = candidates / np.linalg.norm(candidates, axis=-1, keepdims=True)
    cosine = np.einsum("bhwc,bmc->bhwm", diff, unit) / np.maximum(np.linalg.norm(diff, axis=-1), 1e-12)[..., None]
    visible = np.linalg.norm(diff, axis=-1) > 1e-3
    assert visible.mean() > 0.2 and np.all(cosine.max(axis=-1)[visible] > 1 - 1e-4)
    assert np.isfinite(np.asarray(metal.image)).all()


@pytest.mark.slow
def test_materials_run_under_x64(default_world):
    """A float32 world under ``jax_enable_x64`` (strict promotion, as the suite runs): every option
    draws in the tables' dtype, so scenes and Mondrians stay float32 and finite."""
    with jax.enable_x64(True):
        options = dict(specular=True, metallic=True, fluorescent=True, noise=True, clip=300 / 255)
        batch = sample(jax.random.key(9), default_world, 5, 8, **options)
        images = scenes.sample_mondrians(jax.random.key(1), default_world, 2, height=16, width=16, **options)
    assert batch.rgb.dtype == images.image.dtype == np.float32
    assert np.isfinite(np.asarray(batch.rgb)).all() and np.isfinite(np.asarray(images.image)).all()


SLOTTED_OPTIONS = {
    "plain": {},
    "specular": {"specular": Specular()},
    "noise": {"noise": ShotNoise()},
    "clip": {"clip": 0.6},
    "noise+clip": {"noise": ShotNoise(), "clip": 0.6},
    "metallic": {"metallic": scenes.Metallic()},
    "fluorescent": {"fluorescent": scenes.Fluorescent()},
    "all": {
        "specular": Specular(),
        "noise": ShotNoise(),
        "clip": 0.9,
        "metallic": scenes.Metallic(),
        "fluorescent": scenes.Fluorescent(),
    },
}


@pytest.mark.parametrize("options", SLOTTED_OPTIONS, ids=list(SLOTTED_OPTIONS))
@pytest.mark.parametrize(("n_surfaces", "slots"), [(4, 32), (32, 32), (64, 128), (100, 128)])
def test_slotted_sampler_is_the_padded_sampler(material_tables, options, n_surfaces, slots):
    """One program for every count (a sweep's shared sampler) gives `sample_batch`'s scenes in
    the leading slots (the random bits of a longer draw extend a shorter one's) and masked-out
    zeros after them; bitwise with one option at a time (combined options may round the sums
    of highlights differently in another program)."""
    keys = scene_keys(jax.random.key(23), 0, 200)
    kwargs = SLOTTED_OPTIONS[options]
    want = sample_batch(keys, material_tables, n_surfaces, **kwargs)
    got = scenes.sample_batch_slots(keys, material_tables, np.int32(n_surfaces), slots, **kwargs)
    assert got.rgb.shape == (200, slots, 3) and got.mask.shape == (200, slots)
    np.testing.assert_array_equal(np.asarray(got.illuminant), np.asarray(want.illuminant))
    np.testing.assert_array_equal(np.asarray(got.mask[:, :n_surfaces]), np.asarray(want.mask))
    bitwise = options not in ("noise+clip", "all")
    same = np.testing.assert_array_equal if bitwise else lambda a, b: np.testing.assert_allclose(a, b, 2e-6)
    same(np.asarray(got.rgb[:, :n_surfaces]), np.asarray(want.rgb))
    same(np.asarray(got.canonical_rgb[:, :n_surfaces]), np.asarray(want.canonical_rgb))
    assert not np.any(np.asarray(got.mask[:, n_surfaces:]))
    assert not np.any(np.asarray(got.rgb[:, n_surfaces:])) and not np.any(np.asarray(got.canonical_rgb[:, n_surfaces:]))


@pytest.mark.slow
def test_slotted_sampler_runs_in_x64(material_tables):
    """Under jax_enable_x64 (integer aranges are int64 there) the traced count still compares
    without promotion, and the scenes are still the padded ones."""
    with jax.enable_x64(True):
        keys = scene_keys(jax.random.key(29), 0, 50)
        for n_surfaces, slots in [(4, 32), (70, 128)]:
            want = sample_batch(keys, material_tables, n_surfaces, Specular())
            got = scenes.sample_batch_slots(keys, material_tables, np.int32(n_surfaces), slots, Specular())
            np.testing.assert_array_equal(np.asarray(got.rgb[:, :n_surfaces]), np.asarray(want.rgb))
