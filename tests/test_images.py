"""The image pipeline end to end: cached worlds, fold worlds, synthetic Mondrians, the image
commands (estimate, correct, evaluate)."""

from __future__ import annotations

import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from image_files import bad_files
from small_world import small_world

from ccjax import cli, evaluation, io, preprocessing, scenes
from ccjax.io import LinearImage
from ccjax.metrics import angular_error
from ccjax.runs import store


@pytest.fixture(scope="module")
def world():
    return small_world()


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


# ---------------------------------------------------------------------------------------------
# Cache and folds


def test_fold_worlds_learn_only_other_folds(world):
    pool = np.concatenate([np.asarray(world.train_illuminants), np.asarray(world.test_illuminants)])
    whites = pool @ np.asarray(world.camera.sensors)
    truth = whites[[0, 5, 9, 20, 25, 30]] * 3.0  # any scale
    fold_of, worlds = evaluation.fold_worlds(world, truth, 3)
    np.testing.assert_array_equal(fold_of, [0, 1, 2, 0, 1, 2])
    for fold, fold_world in enumerate(worlds):
        learned = np.asarray(fold_world.train_whites)
        want = truth[fold_of != fold]
        rg = lambda v: v[:, :2] / v.sum(axis=1, keepdims=True)
        np.testing.assert_allclose(np.sort(rg(learned), axis=0), np.sort(rg(want), axis=0), atol=1e-5)


# ---------------------------------------------------------------------------------------------
# Synthetic Mondrians


NOISE = scenes.ShotNoise(a=1e-4, b=0.0)


@pytest.fixture(scope="module")
def mondrians(world):
    """50 clean and 50 noisy 64x64 Mondrians with 12 patches, same keys (two compiles in all)."""
    clean = scenes.sample_mondrians(jax.random.key(3), world, 50, height=64, width=64, n_patches=12)
    noisy = scenes.sample_mondrians(jax.random.key(3), world, 50, height=64, width=64, n_patches=12, noise=NOISE)
    return clean, noisy


def test_mondrian_layout_and_spectral_rendering(world, mondrians):
    batch = mondrians[0]
    refl, sensors = np.asarray(world.reflectances, np.float64), np.asarray(world.camera.sensors, np.float64)
    lights = np.asarray(world.test_illuminants, np.float64)
    whites = lights @ sensors
    for b in range(4):
        labels, image = np.asarray(batch.labels[b]), np.asarray(batch.image[b], np.float64)
        assert sorted(np.unique(labels)) == list(range(12))
        assert image.max() == pytest.approx(1.0)
        illuminant = np.asarray(batch.illuminant[b], np.float64)
        light = int(
            np.argmin(np.abs(whites / whites.max(axis=1, keepdims=True) - illuminant / illuminant.max()).sum(axis=1))
        )
        scale = illuminant[0] / whites[light, 0]  # the image's normalisation
        for patch in range(12):
            expected = (refl[int(batch.surfaces[b, patch])] * lights[light]) @ sensors * scale
            shade = image[labels == patch] / expected
            assert np.allclose(shade, shade.flat[0], rtol=1e-4) and 0.3 - 1e-6 <= shade.flat[0] <= 1.0 + 1e-6


def test_mondrian_noise_and_normalisation(mondrians):
    clean, noisy = mondrians
    assert np.allclose(np.asarray(noisy.image).max(axis=(1, 2, 3)), 1.0)
    # Same key: same layout, light and shading; residual variance ~ 1e-4 * rho.
    scale = np.asarray(noisy.illuminant) / np.asarray(clean.illuminant)
    residual = np.asarray(noisy.image) / scale[:, None, None, :1] - np.asarray(clean.image)
    ratio = np.mean(residual**2) / np.mean(1e-4 * np.asarray(clean.image))
    assert 0.8 < ratio < 1.2


def test_mondrian_highlights_are_the_light_colour():
    labels = jnp.asarray(np.repeat(np.arange(4), 64).reshape(16, 16))
    patch_rgb = jnp.asarray(np.random.default_rng(8).random((4, 3)), jnp.float32)
    white = jnp.array([0.9, 1.0, 0.6], jnp.float32)
    render = jax.jit(
        lambda spec, clip: scenes.render_mondrian(
            jax.random.key(0), labels, patch_rgb, white, specular=spec, clip=clip, normalise=False
        )[0],
        static_argnums=(0, 1),
    )
    matte = np.asarray(render(None, None))
    shiny = np.asarray(render(scenes.Specular(probability=1.0, max_amount=2.0), None))
    extra = shiny - matte
    assert extra.max() > 0.05
    direction = extra / np.maximum(extra.sum(-1, keepdims=True), 1e-12)
    big = extra.sum(-1) > 1e-3
    np.testing.assert_allclose(
        direction[big], np.broadcast_to(np.asarray(white) / float(white.sum()), direction[big].shape), atol=1e-4
    )


# ---------------------------------------------------------------------------------------------
# Command line


def _patch_world(monkeypatch, world):
    monkeypatch.setattr(store, "world", lambda *a, **k: world)


@pytest.mark.parametrize("command", ["estimate", "correct", "evaluate"])
def test_cli_folder_runs_go_on_past_bad_files(tmp_path, world, cache, monkeypatch, capsys, command):
    """A folder run reports every bad file with its reason, processes the good ones
    and exits non-zero (2). Header problems are found before any work, pixel-level ones (NaN,
    every pixel clipped, truncated data) in the work pass."""
    _patch_world(monkeypatch, world)
    good = tmp_path / "good"
    io.write_dataset(good, np.full((1, 8, 8, 3), 0.5), [[1.0, 1.0, 1.0]])
    for message, bad in bad_files(tmp_path):
        folder = tmp_path / f"set-{bad.stem}"
        folder.mkdir()
        (folder / "a.png").write_bytes((good / "image-0000.png").read_bytes())
        (folder / bad.name).write_bytes(bad.read_bytes())
        io.write_ground_truth(folder / "gt.csv", ["a.png", bad.name], [[1, 1, 1], [1, 1, 1]])
        out = tmp_path / f"out-{bad.stem}"
        argv = {
            "estimate": ["estimate", str(folder), "--method", "GW", "--json"],
            "correct": ["correct", str(folder), str(out), "--method", "GW"],
            "evaluate": [
                "evaluate",
                str(folder),
                "--ground-truth",
                str(folder / "gt.csv"),
                "--methods",
                "GW",
                "--json",
                f"{out}.json",
            ],
        }[command]
        assert cli.main(argv + ["--no-progress"]) == 2
        captured = capsys.readouterr()
        assert message in captured.err and str(bad.name) in captured.err
        assert "1 of 2 images cannot be used" in captured.err and "Traceback" not in captured.err
        if command == "estimate":
            assert [Path(r["path"]).name for r in json.loads(captured.out)] == ["a.png"]
        elif command == "correct":
            assert sorted(p.name for p in out.iterdir()) == ["a.png", "a_preview.png"]
        else:
            report = json.loads(Path(f"{out}.json").read_text())
            assert {Path(r["path"]).name for r in report["images"]} == {"a.png"}
            assert len(report["failures"]) == 1 and bad.name in report["failures"][0]
            assert "over 1 images" in captured.out


def test_cli_estimate_json_and_correct(tmp_path, world, cache, monkeypatch, capsys, mondrians):
    _patch_world(monkeypatch, world)
    batch = mondrians[1]
    io.write_dataset(tmp_path / "in", batch.image[:2], batch.illuminant[:2])
    assert cli.main(["estimate", str(tmp_path / "in"), "--method", "GW", "--json", "--no-progress"]) == 0
    records = json.loads(capsys.readouterr().out)
    assert [r["path"].endswith(f"image-000{i}.png") for i, r in enumerate(records)] == [True, True]
    assert all(set(r) == {"path", "illuminant", "rg", "ok", "status"} and r["ok"] for r in records)
    assert cli.main(["correct", str(tmp_path / "in"), str(tmp_path / "out"), "--method", "GW", "--no-progress"]) == 0
    corrected = io.read_image(tmp_path / "out" / "image-0000.png")
    assert corrected.rgb.shape == (64, 64, 3)
    assert io.read_png(tmp_path / "out" / "image-0000_preview.png").dtype == np.uint8


def test_round_trip_files_equal_memory(tmp_path, world, cache, monkeypatch, mondrians):
    """Acceptance: 50 Mondrians written as 16-bit PNG; `ccjax evaluate` on the files agrees with the
    same estimators on the in-memory images quantised the same way (each on its default input),
    within 1e-3 degrees."""
    _patch_world(monkeypatch, world)
    methods = ["GW", "DB-GW", "RETINEX", "grey-edge-1-6-2"]
    batch = mondrians[1]
    gt = io.write_dataset(tmp_path / "set", batch.image, batch.illuminant)
    assert (
        cli.main(
            [
                "evaluate",
                str(tmp_path / "set"),
                "--ground-truth",
                str(gt),
                "--methods",
                ",".join(methods),
                "--json",
                str(tmp_path / "r.json"),
                "--camera",
                "Canon EOS 5D Mark II",
                "--no-progress",
            ]
        )
        == 0
    )
    records = json.loads((tmp_path / "r.json").read_text())["images"]
    codes = io.quantise(np.asarray(batch.image))
    for method in methods:
        model = store.fit(method, world)
        file_errors = [r["angular"] for r in records if r["method"] == method]
        for index in range(50):
            clipped = np.any(codes[index] >= io.CLIP_FRACTION * 65535, axis=-1)  # read_image's default
            memory = LinearImage(codes[index].astype(np.float32) / 65535.0, clipped)
            estimate = preprocessing.estimate_image(model, memory)
            error = float(angular_error(estimate.illuminant, jnp.asarray(batch.illuminant[index])))
            assert abs(error - file_errors[index]) <= 1e-3, (method, index)
