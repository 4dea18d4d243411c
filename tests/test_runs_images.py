"""The execution layer's image half: the image source (listed once, each header probed once, each
image read once per run, one failure record per bad file), the one image loop (shares of a
source's items gather to the whole run), the folder calls (estimate and correct against NumPy
oracles written here), the ground truth read once, and the training readers' usable-pixel rule."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from image_files import bad_files

import ccjax.io
from ccjax import cli, io, runs, training
from ccjax.evaluation import evaluate_folder
from ccjax.runs import sources


@pytest.fixture
def setup(small_world_commands):
    return small_world_commands


def _dataset(folder, count=5, seed=0, shape=(12, 16)):
    """Textured random images, a few clipped and zero-channel pixels each."""
    rng = np.random.default_rng(seed)
    rgb = rng.uniform(0.02, 0.9, (count, *shape, 3)) * rng.uniform(0.3, 1.0, (count, 1, 1, 3))
    rgb[:, 0, :3] = 1.0  # clipped
    rgb[:, 1, :2, 1] = 0.0  # a zero channel
    truth = rng.uniform(0.2, 1.0, (count, 3))
    return io.write_dataset(folder, rgb, truth)


def _usable_codes(path):
    """The protocol's usable pixels, from the file codes: no channel 0, none at or above 0.98 of 65535."""
    codes = io.read_png(path).astype(np.float64)
    usable = np.all(codes > 0, axis=-1) & np.all(codes < 0.98 * 65535, axis=-1)
    return codes, usable


def _angle(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))


def _counting(monkeypatch, name):
    calls = []
    original = getattr(ccjax.io, name)
    monkeypatch.setattr(ccjax.io, name, lambda path, *a, **k: calls.append(str(path)) or original(path, *a, **k))
    return calls


def test_source_probes_once_and_records_one_failure_per_bad_file(setup, monkeypatch):
    folder = setup / "set"
    _dataset(folder, count=2)
    bad = [(message, Path(str(path))) for message, path in bad_files(setup)]
    for _, path in bad:
        (folder / path.name).write_bytes(path.read_bytes())
    probes = _counting(monkeypatch, "probe_image")
    source = sources.image_folder(folder)
    assert sorted(probes) == sorted(map(str, source.paths)) and len(source) == 2 + len(bad)
    reads = _counting(monkeypatch, "read_image")
    items = list(source.prepared({}))
    assert sorted(probes) == sorted(map(str, source.paths))  # not probed again
    assert set(reads) == set(map(str, source.paths)) - set(source.failures)  # good headers read once each
    assert len(reads) == len(set(reads))
    failed = {str(item.path): item.failure for item in items if item.failure is not None}
    assert len(failed) == len(bad)
    for message, path in bad:
        line = failed[str(folder / path.name)]
        assert message in line and path.name in line and "\n" not in line


def test_shares_of_a_source_gather_to_the_whole_run(setup, small_test_world):
    """The seam for running a process's share: per-item arrays of two shares, concatenated in item
    order, equal the run over every item."""
    folder = setup / "set"
    _dataset(folder, count=5)
    source = sources.image_folder(folder)
    models = {label: [runs.store.fit(label, small_test_world)] for label in ("GW", "DB-GW", "grey-edge-1-6-2")}
    whole = runs.run_models(source, models)
    shares = [runs.run_models(source, models, items=items) for items in ([0, 2, 4], [1, 3])]
    order = np.argsort(np.concatenate([share.items for share in shares]))
    for label in models:
        gathered = np.concatenate([share.estimates[label] for share in shares])[order]
        np.testing.assert_array_equal(gathered, whole.estimates[label])
        np.testing.assert_array_equal(np.concatenate([s.status[label] for s in shares])[order], whole.status[label])
    assert whole.done.all() and whole.preprocessing == {"GW": "pixels", "DB-GW": "ave5", "grey-edge-1-6-2": "pixels"}


def test_estimate_folder_is_grey_world_on_the_usable_pixels(setup, small_test_world):
    folder = setup / "set"
    _dataset(folder, count=3)
    (folder / "bad.png").write_bytes(b"not a png")
    run = runs.estimate_folder(folder, "GW", world=small_test_world)
    assert list(run.done) == [False, True, True, True] and list(run.failures) == [str(folder / "bad.png")]
    for index in range(1, 4):
        codes, usable = _usable_codes(run.paths[index])
        assert _angle(run.estimates["GW"][index], codes[usable].mean(axis=0)) < 1e-4
    assert [r["path"] for r in run.records()] == run.paths[1:]


def test_correct_folder_applies_the_diagonal_map(setup, small_test_world, monkeypatch):
    monkeypatch.setattr(ccjax.io, "preview_matrix_cached", lambda w: np.eye(3, dtype=np.float32))
    folder = setup / "set"
    _dataset(folder, count=2)
    seen = []
    run = runs.correct_folder(folder, "GW", setup / "out", world=small_test_world, each=lambda *args: seen.append(args))
    assert run.done.all() and [item[0] for item in seen] == [0, 1]
    white = np.asarray(small_test_world.canonical_white, np.float64)
    for index, estimate, output, preview in seen:
        codes, _ = _usable_codes(run.paths[index])
        light = np.asarray(estimate.illuminant, np.float64)
        assert _angle(light, codes[_usable_codes(run.paths[index])[1]].mean(axis=0)) < 1e-4
        gains = white / light
        gains /= np.sum(gains * light / light.sum())  # a grey keeps its R+G+B
        want = np.clip(codes / 65535 * gains, 0, 1)
        # Clip to white: a pixel with a channel at saturation comes out as the canonical white with
        # its brightest channel at saturation (correct_folder's documented rule).
        want[np.any(codes >= 65535, axis=-1)] = white / white.max()
        got = io.read_image(output).rgb
        np.testing.assert_allclose(got, want, atol=1.0 / 65535)
        assert preview.name.endswith("_preview.png") and preview.exists()


def test_evaluate_probes_every_header_once(setup, monkeypatch, capsys):
    gt = _dataset(setup / "set", count=4)
    probes = _counting(monkeypatch, "probe_image")
    argv = ["evaluate", str(setup / "set"), "--ground-truth", str(gt), "--methods", "GW,grey-edge-1-6-2"]
    assert cli.main([*argv, "--no-progress", "--json", str(setup / "r.json")]) == 0
    capsys.readouterr()
    assert len(probes) == 4 and len(set(probes)) == 4
    assert len(json.loads((setup / "r.json").read_text())["images"]) == 8


def test_evaluate_folder_python_call_matches_the_command(setup, capsys):
    gt = _dataset(setup / "set", count=6)
    argv = ["evaluate", str(setup / "set"), "--ground-truth", str(gt), "--methods", "GW,AVE-ILLUM", "--folds", "3"]
    assert cli.main([*argv, "--camera", "Canon EOS 5D Mark II", "--no-progress", "--json", str(setup / "r.json")]) == 0
    capsys.readouterr()
    report = json.loads((setup / "r.json").read_text())
    evaluation = evaluate_folder(setup / "set", gt, ["GW", "AVE-ILLUM"], folds=3)
    assert evaluation.fold_source == "image i in fold i mod K" and evaluation.fold_of is not None
    assert evaluation.fold_of.tolist() == [0, 1, 2] * 2
    again = evaluation.report()
    assert again["images"] == report["images"] and again["folds"] == report["folds"]
    assert evaluation.check is not None  # AVE-ILLUM is world-based


def test_ground_truth_is_read_once_with_its_fold_column(tmp_path):
    path = tmp_path / "gt.csv"
    path.write_text("File,R,G,B,Fold\na.png,1,2,3,7\nb.png,4,5,6,2\n")
    table = io.read_ground_truth_file(path)
    assert list(table.lights) == ["a.png", "b.png"] and table.folds == {"a.png": 7, "b.png": 2}
    np.testing.assert_array_equal(table.lights["b.png"], [4.0, 5.0, 6.0])
    assert training.read_folds(path) == table.folds
    assert io.read_ground_truth_file(path, with_folds=False).folds is None
    (tmp_path / "plain.csv").write_text("image,r,g,b\na.png,1,1,1\n")
    assert io.read_ground_truth_file(tmp_path / "plain.csv").folds is None


def test_training_readers_use_the_usable_pixel_rule(setup):
    """``load_examples`` of an image estimator masks what ``evaluate`` masks: no clipped pixel and no
    zero channel (not only ``~clipped``)."""
    gt = _dataset(setup / "set", count=3)
    examples = training.load_examples(setup / "set", gt, "image")
    paths = sorted((setup / "set").glob("*.png"))
    for index, path in enumerate(paths):
        _, usable = _usable_codes(path)
        np.testing.assert_array_equal(np.asarray(examples.mask[index]), usable)
        assert not usable[1, :2].any()  # the zero-channel pixels are left out
