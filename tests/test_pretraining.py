"""Pretraining from spectra: the renderer against a NumPy image formation, FFCC's fine-tune from a
prior (closed-form properties), and a small end-to-end run on rendered "photographs"."""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ccjax import metrics, training
from ccjax.estimators.ffcc import Hyperparameters, init_ffcc
from ccjax.estimators.ffcc import train as train_ffcc
from ccjax.estimators.ffcc._fitting import from_latent, loss, preconditioner, to_latent
from ccjax.preprocessing import Preprocessing
from ccjax.runs import store
from ccjax.scenes import ShotNoise, Specular
from ccjax.spectra import WAVELENGTHS
from ccjax.training import Pretraining, fine_tune, pretrain, render_examples, render_images
from ccjax.training._pretraining import CODES

CAMERA = "Canon EOS 600D"


def _chroma(rgb: np.ndarray) -> np.ndarray:
    return rgb / np.sum(rgb, axis=-1, keepdims=True)


def test_rendered_pixels_are_camera_responses_to_light_times_reflectance(default_world):
    """Without highlights or noise, every usable pixel is ``shade * sum_lambda S(l) E(l) R(l)``
    for one of the world's reflectances under the image's light, ``shade`` in the shading range
    times the exposure (NumPy image formation, Barnard 1999 §4.2), and the light lies near the
    Planckian locus (Planck's law, computed here)."""
    setting = Pretraining(CAMERA, images=12, height=16, width=16, patches=6, specular=Specular(0.0, 0.0))
    setting = dataclasses.replace(setting, noise=ShotNoise(a=0.0, b=0.0))
    rgb, clipped, lights = (np.asarray(a) for a in render_images(setting))
    rgb, lights = rgb.astype(np.float64), lights.astype(np.float64)
    world = store.world("default", CAMERA)
    sensors = np.asarray(world.camera.sensors, np.float64)
    spectra = np.asarray(world.test_illuminants, np.float64)
    reflectances = np.asarray(world.reflectances, np.float64)
    whites = spectra @ sensors
    # The codes are whole steps of the 16-bit scale.
    np.testing.assert_allclose(rgb * CODES, np.round(rgb * CODES), atol=1e-3)
    metres = WAVELENGTHS * 1e-9
    kelvin = np.arange(2000.0, 20001.0, 50.0)
    planck = (metres**-5 / np.expm1(1.4388e-2 / (metres * kelvin[:, None]))) @ sensors
    locus = np.stack([np.log(planck[:, 1] / planck[:, 0]), np.log(planck[:, 1] / planck[:, 2])], axis=-1)
    for image, clip, light in zip(rgb, clipped, lights, strict=True):
        which = np.argmin(np.linalg.norm(_chroma(whites) - _chroma(light), axis=-1))
        np.testing.assert_allclose(_chroma(whites[which]), _chroma(light), atol=1e-5)
        uv = np.log(light[1] / light[[0, 2]])
        assert np.min(np.linalg.norm(locus - uv, axis=-1)) <= setting.locus + 1e-6
        expected = (reflectances * spectra[which]) @ sensors  # (S, 3) every surface under the light
        usable = ~clip & np.all(image > 0.02, axis=-1)
        pixels = image[usable]
        assert len(pixels) > 0
        # Each pixel on the white's scale: its ratio to a surface's response is one shade for all channels.
        scaled = expected / whites[which] * light  # (S, 3) responses on the image's white scale
        ratio = pixels[:, None, :] / scaled[None, :, :]  # (P, S, 3)
        spread = np.max(ratio, axis=-1) / np.min(ratio, axis=-1)
        best = np.argmin(spread, axis=1)
        assert np.all(np.min(spread, axis=1) < 1.01)
        shade = ratio[np.arange(len(pixels)), best].mean(axis=-1)
        assert np.all((shade > 0.3 - 0.01) & (shade < 1.0 + 0.01))


def test_rendered_examples_get_the_photographs_clip_rule(default_world):
    setting = Pretraining(CAMERA, images=8, height=16, width=16, patches=6, exposure=(1.0, 1.0))
    rgb, clipped, _ = (np.asarray(a) for a in render_images(setting))
    examples = render_examples(setting, Preprocessing.parse("pixels"), "image")
    # The pixels rule: usable = not clipped and no zero channel (ccjax.preprocessing.usable_pixels).
    np.testing.assert_array_equal(np.asarray(examples.mask), ~clipped & np.all(rgb > 0, axis=-1))
    assert np.any(clipped) and examples.x.shape == (8, 16, 16, 3)


def test_pretraining_settings_are_checked():
    with pytest.raises(ValueError, match="images"):
        Pretraining(CAMERA, images=0)
    with pytest.raises(ValueError, match="exposure"):
        Pretraining(CAMERA, exposure=(1.0, 0.0))


@pytest.mark.slow
def test_latent_round_trip_and_anchored_regulariser():
    rng = np.random.default_rng(3)
    n = 8
    scale = preconditioner(n, 0.3, 0.02)
    field = jnp.asarray(rng.normal(size=(n, n)), jnp.float32)
    np.testing.assert_allclose(np.asarray(from_latent(to_latent(field, scale), scale)), np.asarray(field), atol=1e-4)
    scales = (jnp.stack([scale, scale]), scale)
    latent = (jnp.asarray(rng.normal(size=(2, n, n)), jnp.float32), jnp.asarray(rng.normal(size=(n, n)), jnp.float32))
    histogram_fft = jnp.fft.rfft2(jnp.asarray(rng.uniform(size=(2, 2, n, n)), jnp.float32))
    truth = jnp.asarray(rng.uniform(1, n - 2, (2, 2)), jnp.float32)
    zero = jnp.zeros(3, jnp.float32)
    # Data weights 0: the objective is the regulariser alone, 0.5 ||latent - anchor||^2.
    assert float(loss(latent, scales, histogram_fft, truth, zero, 1.0, 0.1, anchor=latent)) == pytest.approx(0.0)
    expected = 0.5 * sum(float(np.sum(np.asarray(x, np.float64) ** 2)) for x in latent)
    assert float(loss(latent, scales, histogram_fft, truth, zero, 1.0, 0.1)) == pytest.approx(expected, rel=1e-5)


def _lights(count: int, rng) -> np.ndarray:
    t = rng.uniform(-1, 1, count)
    return np.stack([np.exp(0.4 * t), np.full(count, 1.5), np.exp(-0.4 * t)], axis=1).astype(np.float32)


def test_fine_tune_without_iterations_is_the_prior_on_the_recentred_grid():
    """Zero iterations: the fine-tuned model is the prior, its grid re-centred on the new lights
    by whole bins: filters unchanged, the bias map rolled by the same bins (np.roll)."""
    rng = np.random.default_rng(4)
    n = 16
    prior = init_ffcc(bins=n, bin_size=1 / 16)
    prior = eqx.tree_at(
        lambda m: (m.filters, m.bias),
        prior,
        (jnp.asarray(rng.normal(size=(2, n, n)), jnp.float32), jnp.asarray(rng.normal(size=(n, n)), jnp.float32)),
    )
    lights = _lights(6, rng)
    images = rng.uniform(0.05, 0.9, (6, 8, 8, 3)).astype(np.float32)
    masks = np.ones((6, 8, 8), bool)
    none = Hyperparameters(pretrain_iterations=0, iterations=0)
    tuned, _ = train_ffcc(init_ffcc(bins=n, bin_size=1 / 64), images, masks, lights, none, prior=prior)
    assert float(tuned.bin_size) == pytest.approx(1 / 16)  # the prior's, not the start's
    shift = np.round((np.asarray(tuned.origin) - np.asarray(prior.origin)) * 16).astype(int)
    assert np.any(shift != 0)
    np.testing.assert_allclose(np.asarray(tuned.filters), np.asarray(prior.filters), atol=1e-4)
    np.testing.assert_allclose(np.asarray(tuned.bias), np.roll(np.asarray(prior.bias), -shift, axis=(0, 1)), atol=1e-4)
    with pytest.raises(ValueError, match="prior"):
        train_ffcc(init_ffcc(bins=8), images, masks, lights, none, prior=prior)


@pytest.mark.slow  # over 30 s on 2 cores: the default run stays under 10 minutes
def test_pretraining_helps_ffcc_with_few_photographs(default_world):
    """Rendered "photographs" (another seed of the renderer): FFCC fine-tuned from its pretraining
    on 8 of them beats FFCC trained from scratch on the same 8, on 96 held out."""
    pixels = Preprocessing.parse("pixels")
    setting = Pretraining(CAMERA, images=256, height=24, width=24, patches=12)
    photos = render_examples(dataclasses.replace(setting, images=104, seed=7), pixels, "image")
    start = init_ffcc()
    pretrained, log = pretrain(start, setting, pixels)
    assert len(log.train_loss) == 2 and np.all(np.isfinite(log.train_loss))
    few, held = photos.take(np.arange(8)), photos.take(np.arange(8, 104))
    tuned, _ = fine_tune(pretrained, few)
    scratch, _ = training.train_model(start, few, progress=False)
    errors = {name: training.angular_errors(model, held) for name, model in [("tuned", tuned), ("scratch", scratch)]}
    assert all(np.all(np.isfinite(e)) for e in errors.values())
    assert np.median(errors["tuned"]) < 0.8 * np.median(errors["scratch"])
    sums = jnp.sum(jnp.where(held.mask[..., None], held.x, 0.0), axis=(1, 2))
    grey = np.asarray(metrics.angular_error(sums, held.illuminant))
    assert np.median(errors["tuned"]) < 0.5 * np.median(grey)


@pytest.mark.manual  # about 90 s on 2 cores; pretraining and fine-tuning are tested in the slow suite
def test_evaluate_train_pretrains_then_fine_tunes_in_every_fold(tmp_path, monkeypatch, capsys):
    """``ccjax evaluate --train FFCC --pretrain-camera``: FFCC is pretrained once on rendered
    images, and every fold's fit is a fine-tune of that model (its prior)."""
    import ccjax.training._procedures as procedures
    from ccjax import cli, io

    rgb, _, lights = render_images(Pretraining(CAMERA, images=12, height=24, width=24, patches=8, seed=3))
    truth = io.write_dataset(tmp_path / "set", np.asarray(rgb), np.asarray(lights))
    priors = []
    original = procedures.train_ffcc

    def spy(*args, prior=None, **kwargs):
        priors.append(prior)
        return original(*args, prior=prior, **kwargs)

    monkeypatch.setattr(procedures, "train_ffcc", spy)
    argv = ["evaluate", str(tmp_path / "set"), "--ground-truth", str(truth), "--methods", "GW", "--folds", "2"]
    argv += ["--train", "FFCC", "--pretrain-camera", CAMERA, "--pretrain-images", "64", "--no-progress"]
    assert cli.main([*argv, "--json", str(tmp_path / "report.json")]) == 0
    assert "pretrained on 64 images rendered with Canon EOS 600D" in capsys.readouterr().err
    # The pretraining fit (no prior), then one fine-tune per fold, each from that same model.
    assert priors[0] is None and len(priors) == 3
    assert priors[1] is not None and priors[1] is priors[2]
    capsys.readouterr()
    assert (
        cli.main(["evaluate", str(tmp_path / "set"), "--ground-truth", str(truth), "--methods", "GW"] + argv[10:12])
        == 2
    )
    assert "applies to --train" in capsys.readouterr().err
    assert cli.main([*argv[:10], "--pretrain-images", "64", "--no-progress"]) == 2
    assert "--pretrain-images" in capsys.readouterr().err


def test_train_refuses_pretrain_images_without_a_camera(tmp_path, capsys):
    from ccjax import cli

    assert cli.main(["train", str(tmp_path), "--method", "FFCC", "--pretrain-images", "64"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: ccjax train") and "--pretrain-images: applies with --pretrain-camera only" in err
    with pytest.raises(SystemExit) as stop:
        cli.main(["train", str(tmp_path), "--method", "FFCC", "--pretrain-camera", CAMERA, "--pretrain-images", "0"])
    assert (
        stop.value.code == 2
        and "argument --pretrain-images: expected an integer in [1, 20000], got 0" in capsys.readouterr().err
    )


@pytest.mark.slow
def test_colour_by_correlation_matrices_pretrain_on_surface_lists(default_world):
    """The Adam loop's families pretrain on the rendered images' surface lists (their own rule,
    ave5): the matrices move, every number stays finite, and fine-tuning starts from them."""
    from ccjax.preprocessing import resolve

    start = store.fit("RGB-C-by-C-MMSE", default_world)
    rule = resolve(start)
    setting = Pretraining(CAMERA, images=48, height=24, width=24, patches=8)
    schedule = training.Schedule(epochs=1, batch_size=16)
    pretrained, log = pretrain(start, setting, rule, schedule)
    examples = render_examples(setting, rule, "surfaces")
    assert examples.x.ndim == 3 and rule.name == "ave5"
    before, after = (jax.tree_util.tree_leaves(eqx.partition(m, training.learnable(m))[0]) for m in (start, pretrained))
    moved = [float(np.max(np.abs(np.asarray(a) - np.asarray(b)))) for a, b in zip(before, after, strict=True)]
    assert max(moved) > 0 and np.all(np.isfinite(log.train_loss))
    photos = render_examples(dataclasses.replace(setting, images=16, seed=2), rule, "surfaces")
    tuned, _ = fine_tune(pretrained, photos, schedule)
    assert np.all(np.isfinite(training.angular_errors(tuned, photos)))


def test_curve_summary_averages_each_subsets_pooled_statistics():
    from ccjax.experiments.pretraining import PretrainingCurve

    errors = {
        (0.1, 0, "not pretrained"): np.array([1.0, 2.0, 6.0]),
        (0.1, 1, "not pretrained"): np.array([2.0, 4.0, 3.0]),
        (0.1, 0, "pretrained"): np.array([1.0, 1.0, 4.0]),
        (0.1, 1, "pretrained"): np.array([0.5, 1.0, 1.5]),
    }
    rows = PretrainingCurve("FFCC", CAMERA, errors).summary()
    assert [(r["fraction"], r["arm"], r["subsets"]) for r in rows] == [
        (0.1, "not pretrained", 2),
        (0.1, "pretrained", 2),
    ]
    # Subset means 3 and 3, medians 2 and 3; pretrained: means 2 and 1, medians 1 and 1.
    assert rows[0]["mean"] == pytest.approx(3.0) and rows[0]["mean_sd"] == pytest.approx(0.0)
    assert rows[0]["median"] == pytest.approx(2.5) and rows[0]["median_sd"] == pytest.approx(0.5)
    assert rows[1]["mean"] == pytest.approx(1.5) and rows[1]["mean_sd"] == pytest.approx(0.5)
    assert rows[1]["median"] == pytest.approx(1.0) and rows[1]["median_sd"] == pytest.approx(0.0)


def test_pretraining_shows_its_progress(tmp_path, monkeypatch, capsys):
    """Rendering and preparing the images each show a bar counting them to the total, on stderr."""
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path / "cache"))  # not read from an earlier run's cache
    setting = Pretraining(CAMERA, images=6, height=8, width=8, patches=4, seed=11)
    render_examples(setting, Preprocessing.parse("pixels"), "image", progress=True)
    err = capsys.readouterr().err
    assert "render" in err and "prepare" in err and "6/6" in err
