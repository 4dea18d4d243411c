"""``ccjax evaluate`` as a researcher uses it: each method on its own input,
inputs shared, the field's statistics, per-method seconds with compilation apart, fallback
reasons, one CSV row per image and method, masks."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from ccjax import cli, evaluation, io
from ccjax.runs import images as run_images
from ccjax.runs import sources as run_sources
from ccjax.runs import store

METHODS = ["GW", "shades-of-grey-p6", "DB-GW", "AVE-ILLUM"]


@pytest.fixture(scope="module")
def world(small_test_world):
    return small_test_world


@pytest.fixture
def setup(small_world_commands):
    return small_world_commands


def _dataset(folder, count=6, seed=0, shape=(20, 30)):
    """Textured random images with a few clipped and zero-channel pixels; one image has a zero
    blue channel everywhere (no usable pixel: the statistics methods fall back)."""
    rng = np.random.default_rng(seed)
    rgb = rng.uniform(0.02, 0.9, (count, *shape, 3)) * rng.uniform(0.3, 1.0, (count, 1, 1, 3))
    rgb[:, 0, :4] = 1.0  # clipped
    rgb[:, 1, :3, 2] = 0.0  # a zero channel
    rgb[-1, ..., 2] = 0.0
    truth = rng.uniform(0.2, 1.0, (count, 3))
    return io.write_dataset(folder, rgb, truth)


def _numpy_gw(path):
    """Independent grey world on the protocol mask: no channel 0, none at or above 0.98 of 65535."""
    codes = io.read_png(path).astype(np.float64)
    usable = np.all(codes > 0, axis=-1) & np.all(codes < 0.98 * 65535, axis=-1)
    return 2.0 * codes[usable].mean(axis=0) / 65535 if usable.any() else None


def _angle(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))


def test_evaluate_reports_statistics_times_reasons_and_csv(setup, capsys):
    gt = _dataset(setup / "set")
    argv = ["evaluate", str(setup / "set"), "--ground-truth", str(gt), "--methods", ",".join(METHODS)]
    argv += ["--camera", "Canon EOS 5D Mark II", "--csv", str(setup / "r.csv"), "--json", str(setup / "r.json")]
    assert cli.main([*argv, "--no-progress"]) == 0
    out = capsys.readouterr().out
    for heading in ("mean", "median", "trimean", "best25", "worst25", "p95", "max", "mean 95% CI", "warm-up s"):
        assert heading in out
    assert "GW" in out and "no data 1" in out  # the image without a usable pixel, and why
    rows = list(csv.DictReader((setup / "r.csv").read_text().splitlines()))
    assert len(rows) == 6 * len(METHODS) and set(rows[0]) >= {"path", "method", "preprocessing", "status", "angular"}
    prepared = {row["method"]: row["preprocessing"] for row in rows}
    assert prepared == {"GW": "pixels", "shades-of-grey-p6": "pixels", "DB-GW": "ave5", "AVE-ILLUM": "ave5"}
    gw = [row for row in rows if row["method"] == "GW"]
    assert [row["status"] for row in gw] == ["estimated"] * 5 + ["no_data"]
    truth = io.read_ground_truth(gt)
    for row in gw[:5]:
        want = _numpy_gw(row["path"])
        estimate = [float(row[k]) for k in "RGB"]
        assert _angle(estimate, want) < 1e-4
        name = row["path"].rsplit("/", 1)[1]
        assert float(row["angular"]) == pytest.approx(_angle(estimate, truth[name]), abs=1e-3)
    report = json.loads((setup / "r.json").read_text())
    summary = report["summary"]["GW"]
    errors = [float(row["angular"]) for row in gw]
    assert summary["p95"] == pytest.approx(np.percentile(errors, 95), abs=1e-4)
    assert summary["mean_low"] <= summary["mean"] <= summary["mean_high"]
    assert summary["status"] == {"no_data": 1} and summary["seconds"] > 0 and summary["warmup_seconds"] > 0


def test_inputs_are_prepared_once_per_kind_and_compiled_before_timing(setup, monkeypatch, world):
    gt = _dataset(setup / "set", count=4)
    paths = [p for p, _ in io.match_ground_truth(io.read_ground_truth(gt), setup / "set")]
    events = []
    prepare, timed = run_sources.prepare_input, run_images._timed
    monkeypatch.setattr(run_sources, "prepare_input", lambda *a, **k: events.append("prepare") or prepare(*a, **k))
    monkeypatch.setattr(run_images, "_timed", lambda m, r, v: events.append(("run", r.shape)) or timed(m, r, v))

    models = {label: [store.fit(label, world)] for label in METHODS}
    results = evaluation.run_images(paths, models)
    assert events.count("prepare") == 2 * 4  # pixels and ave5, once per image each
    runs = [event for event in events if event != "prepare"]
    # Pixel inputs compiled before the first image (one warm-up per pixel method), surface lists
    # at the first image of each size class; every other call is a timed run.
    assert runs[:2] == [("run", (20, 30, 3))] * 2 and events[2] == "prepare"
    assert len(runs) == 4 * len(METHODS) + 2 + 2
    assert set(results.warmup) == set(METHODS) and all(results.seconds[m] > 0 for m in METHODS)
    single = evaluation.run_images(paths, models, preprocessing="ave5")
    assert set(single.preprocessing.values()) == {"ave5"}
    np.testing.assert_allclose(single.estimates["DB-GW"], results.estimates["DB-GW"])


def test_mask_folder(setup, capsys):
    gt = _dataset(setup / "set", count=2)
    masks = setup / "masks"
    masks.mkdir()
    for index in range(2):
        keep = np.zeros((20, 30), np.uint8)
        keep[:, 15:] = 255  # the right half only
        io.write_png(masks / f"image-{index:04d}.png", np.repeat(keep[..., None], 3, axis=-1))
    argv = ["estimate", str(setup / "set"), "--method", "GW", "--json", "--no-progress", "--mask", str(masks)]
    assert cli.main(argv) == 0
    records = json.loads(capsys.readouterr().out)
    codes = io.read_png(setup / "set" / "image-0000.png").astype(np.float64)[:, 15:]
    usable = np.all(codes > 0, axis=-1) & np.all(codes < 0.98 * 65535, axis=-1)
    assert _angle(records[0]["illuminant"], codes[usable].mean(axis=0)) < 1e-4
    (masks / "image-0001.png").unlink()
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert "--mask" in err and "image-0001.png" in err
    del gt


def test_images_without_a_ground_truth_row_are_named_and_refused_unless_allowed(setup, capsys):
    """Four images, two ground-truth rows: ``evaluate`` names both unlisted files and exits 2;
    ``--allow-missing`` scores the two listed ones and still names the others (also in the JSON)."""
    from ccjax.evaluation import evaluate_folder

    gt = _dataset(setup / "set", count=4)
    truth = io.read_ground_truth(gt)
    listed = sorted(truth)[:2]
    io.write_ground_truth(setup / "two.csv", listed, np.stack([truth[name] for name in listed]))
    unlisted = [str(setup / "set" / name) for name in sorted(truth)[2:]]
    argv = ["evaluate", str(setup / "set"), "--ground-truth", str(setup / "two.csv"), "--methods", "GW"]
    assert cli.main([*argv, "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "--ground-truth: 2 image(s)" in err and all(path in err for path in unlisted), err
    json_path = setup / "r.json"
    plot = setup / "errors.png"
    assert cli.main([*argv, "--no-progress", "--allow-missing", "--json", str(json_path), "--plot", str(plot)]) == 0
    assert io.png_header(plot).width > 600  # the per-image errors' figure
    out = capsys.readouterr().out
    assert f"not scored, no ground-truth row (2): {', '.join(unlisted)}" in out
    assert "over 2 images" in out
    # No --camera: the header names no camera (only methods that use none ran).
    assert out.splitlines()[0].startswith("camera: none given") and "Canon" not in out.splitlines()[0]
    assert json.loads(json_path.read_text())["unlisted"] == unlisted
    with pytest.raises(ValueError, match=r"ground_truth: 2 image\(s\) .*allow_missing=True"):
        evaluate_folder(setup / "set", setup / "two.csv", ["GW"])
    allowed = evaluate_folder(setup / "set", setup / "two.csv", ["GW"], allow_missing=True)
    assert allowed.unlisted == unlisted and len(allowed.results.paths) == 2
