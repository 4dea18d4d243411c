"""Training on other cameras' labelled photographs: the pooled source (each folder mapped into a target
camera) against NumPy, the leave-one-camera-out protocol's rounds and its independence from the
scored folder's ground truth, and the commands' one-line refusals."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from image_files import one_line_error

from ccjax import cli, evaluation, io, scenes
from ccjax.preprocessing import input_rule
from ccjax.runs.pooled import MappedFolder, PooledImages
from ccjax.runs.sources import image_folder
from ccjax.transfer import GlobalMap, fit_camera_map

CANON, NIKON = "Canon EOS 600D", "Nikon D5300"
MATRIX = np.array([[1.1, -0.2, 0.05], [0.1, 0.9, 0.1], [-0.05, 0.2, 1.2]], np.float32)
"""A map with negative entries, so some saturated colours leave the positive octant."""


@pytest.fixture(scope="module")
def two_folders(small_test_world, tmp_path_factory):
    """Two folders of 8 small Mondrians each (the small world's lights), named canon and nikon."""
    root = tmp_path_factory.mktemp("cameras")
    for index, name in enumerate(("canon", "nikon")):
        batch = scenes.sample_mondrians(
            jax.random.key(3 + index), small_test_world, 8, height=12, width=12, n_patches=5
        )
        io.write_dataset(root / name, np.asarray(batch.image), np.asarray(batch.illuminant))
    return root


def _part(folder, camera_map, camera):
    paths = sorted(folder.glob("*.png"))
    truth = io.read_ground_truth(folder / "groundtruth.csv")
    lights = np.stack([truth[path.name] for path in paths])
    return MappedFolder(image_folder(paths), lights, [p.name for p in paths], camera, camera_map)


def test_the_pooled_source_maps_images_and_lights_as_numpy_does(two_folders):
    camera_map = GlobalMap(CANON, NIKON, jnp.asarray(MATRIX))
    pool = PooledImages(
        [_part(two_folders / "canon", camera_map, CANON), _part(two_folders / "nikon", None, NIKON)], NIKON
    )
    assert len(pool) == 16 and pool.counts() == {CANON: 8, NIKON: 8}  # labelled by camera by default
    rule = input_rule("image", "pixels")
    items = list(pool.prepared({rule.name: rule}))
    assert [item.index for item in items] == list(range(16))
    pooled_rg, oracle_rg = [], []
    for item in items:
        rgb, mask = item.inputs[rule.name]
        image = io.read_image(item.path)
        source = np.asarray(image.rgb, np.float64)
        usable = ~np.asarray(image.clipped) & np.all(source > 0, axis=-1)
        if item.index < 8:  # mapped: M x for every pixel, kept where every channel stays positive
            expected = source @ MATRIX.T.astype(np.float64)
            usable &= np.all(expected > 0, axis=-1)
        else:
            expected = source
        np.testing.assert_array_equal(mask, usable)
        np.testing.assert_allclose(rgb[usable], expected[usable], rtol=1e-5, atol=1e-7)
        if item.index < 8:  # a mapped entry that left the mask holds 0, not a wrong colour
            assert np.all(rgb[~usable] == 0)
        pooled_rg.append((rgb[mask] / rgb[mask].sum(-1, keepdims=True)).mean(0))
        oracle_rg.append((expected[usable] / expected[usable].sum(-1, keepdims=True)).mean(0))
    # The pool's statistic (mean chromaticity of the usable pixels, per image) against NumPy's.
    np.testing.assert_allclose(np.array(pooled_rg), np.array(oracle_rg), atol=1e-6)
    truth = io.read_ground_truth(two_folders / "canon" / "groundtruth.csv")
    mapped = np.stack([MATRIX @ truth[p.name] for p in sorted((two_folders / "canon").glob("*.png"))])
    np.testing.assert_allclose(pool.lights()[:8], mapped / mapped.max(1, keepdims=True), rtol=1e-5)
    own = np.stack([truth for truth in io.read_ground_truth(two_folders / "nikon" / "groundtruth.csv").values()])
    np.testing.assert_allclose(pool.lights()[8:], own / own.max(1, keepdims=True), rtol=1e-6)


def test_leave_one_camera_out_names_the_folders_without_a_camera():
    protocol = evaluation.LeaveOneCameraOut(("FFCC",))
    said = []
    rounds = protocol.rounds([CANON, None, NIKON, "Canon EOS-1Ds Mark III"], said.append)
    assert [(r.scored, r.training) for r in rounds] == [(0, (2, 3)), (2, (0, 3)), (3, (0, 2))]
    assert len(said) == 1 and "1 folder(s) without a camera" in said[0] and "index 1" in said[0]
    with pytest.raises(ValueError, match="at least two folders with a camera, got 1"):
        protocol.rounds([CANON, None], None)
    with pytest.raises(ValueError, match="camera_map: expected one of global, per-light"):
        evaluation.LeaveOneCameraOut(("FFCC",), "affine")  # type: ignore[arg-type]
    on = evaluation.TrainOn((0,), ("FFCC",))
    assert [(r.scored, r.training) for r in on.rounds([CANON, NIKON, None], None)] == [(1, (0,))]


def _loco(root, *extra):
    return [
        "evaluate",
        str(root / "canon"),
        str(root / "nikon"),
        "--ground-truth-name",
        "groundtruth.csv",
        f"--camera-for=canon={CANON}",
        f"--camera-for=nikon={NIKON}",
        "--leave-one-camera-out",
        "--train",
        "grey-edge-1-6-2",
        "--methods",
        "GW",
        "--no-progress",
        *extra,
    ]


@pytest.mark.slow
def test_each_folder_is_scored_by_a_model_that_never_saw_its_ground_truth(
    small_world_commands, small_test_world, two_folders, tmp_path, monkeypatch
):
    """Leave-one-camera-out on two folders, twice: the second time the canon folder's ground truth
    is rotated among its images. Each training is given only the other folder's images, with that
    folder's ground truth mapped into the scored camera (a spy on the training records them), so
    the model scoring the canon folder, and its estimates there, do not move."""
    import shutil

    from ccjax import training

    seen = []
    real = training.train_model

    def spy(start, examples, *args, **kwargs):
        seen.append((tuple(examples.names), np.asarray(examples.illuminant)))
        return real(start, examples, *args, **kwargs)

    monkeypatch.setattr(training, "train_model", spy)
    root = tmp_path / "sets"
    shutil.copytree(two_folders, root)
    assert cli.main(_loco(root, "--json", str(tmp_path / "a.json"))) == 0
    truth = (root / "canon" / "groundtruth.csv").read_text().splitlines()
    rows = truth[1:]
    lights = [row.split(",", 1)[1] for row in rows]
    rotated = [row.split(",", 1)[0] + "," + lights[(index + 3) % len(rows)] for index, row in enumerate(rows)]
    (root / "canon" / "groundtruth.csv").write_text("\n".join([truth[0], *rotated]) + "\n")
    assert cli.main(_loco(root, "--json", str(tmp_path / "b.json"))) == 0
    before, after = (json.loads((tmp_path / name).read_text()) for name in ("a.json", "b.json"))

    # Rounds in folder order: canon scored (trained on nikon), then nikon scored (trained on canon).
    assert [len(s[0]) for s in seen] == [8, 8, 8, 8]
    assert all(name.startswith("nikon/") for name in seen[0][0] + seen[2][0])
    assert all(name.startswith("canon/") for name in seen[1][0] + seen[3][0])
    np.testing.assert_array_equal(seen[0][1], seen[2][1])  # nikon's labels, both runs
    # ...mapped into the canon camera as the pool maps them: the per-light map of each image's light.
    own = np.stack(list(io.read_ground_truth(root / "nikon" / "groundtruth.csv").values()))
    camera_map = fit_camera_map(NIKON, CANON, kind="per-light", world=small_test_world)
    np.testing.assert_allclose(seen[0][1], np.stack([camera_map.map_light(e) for e in own]), rtol=1e-5)
    assert np.abs(seen[1][1] - seen[3][1]).max() > 0.01  # canon's rotated labels reached nikon's model

    def estimates(report, folder):
        images = report["sets"][folder]["evaluation"]["images"]
        return np.array([r["illuminant"] for r in images if r["method"] == "grey-edge-1-6-2 trained"])

    np.testing.assert_array_equal(estimates(before, "canon"), estimates(after, "canon"))
    for report in (before, after):
        assert set(report["sets"]) == {"canon", "nikon"}
        means = [report["sets"][f]["methods"]["grey-edge-1-6-2 trained"]["mean"] for f in ("canon", "nikon")]
        geometric = report["geometric_mean"]["methods"]["grey-edge-1-6-2 trained"]["mean"]
        assert geometric == pytest.approx(np.sqrt(means[0] * means[1]), rel=1e-9)
        notes = report["sets"]["canon"]["evaluation"]["training"]
        assert len(notes) == 1 and "nikon (Nikon D5300, mapped per-light)" in notes[0] and "canon (" not in notes[0]


@pytest.mark.slow
def test_a_model_for_one_camera_is_refused_on_another(small_world_commands, two_folders, capsys):
    model = small_world_commands / "for-nikon.eqx"
    argv = ["train", str(two_folders / "canon"), f"--camera-for=canon={CANON}", "--target-camera", NIKON]
    assert cli.main([*argv, "--method", "grey-edge-1-6-2", "--out", str(model), "--no-progress"]) == 0
    record = json.loads(model.with_suffix(".json").read_text())
    assert record["camera"] == NIKON and record["target_camera"] == NIKON and record["camera_map"] == "per-light"
    assert record["source_folders"]["canon"]["camera"] == CANON and record["images"] == 8
    capsys.readouterr()
    folder = str(two_folders / "canon")
    argv = ["evaluate", folder, "--ground-truth-name", "groundtruth.csv", "--camera", CANON, "--methods", str(model)]
    assert cli.main(argv) == 2
    one_line_error(capsys.readouterr(), "--methods", str(model), f"trained for the {NIKON}", CANON)


@pytest.mark.parametrize(
    ("extra", "needles"),
    [
        (["--camera-for=nikon=Canon EOS 601D"], ("--camera-for", "unknown camera", "Canon EOS 600D")),
        (["--camera-for=nikon="], ("--camera-for", "expected FOLDER=CAMERA")),
        (["--folds", "3"], ("--leave-one-camera-out", "leave out --folds")),
        (["--adapt"], ("--adapt", "give --train FFCC")),
    ],
)
def test_leave_one_camera_out_refuses_bad_options_in_one_line(
    small_world_commands, two_folders, capsys, extra, needles
):
    argv = _loco(two_folders)
    if extra[0].startswith("--camera-for=nikon"):
        argv = [a for a in argv if not a.startswith("--camera-for=nikon")]
    assert cli.main([*argv, *extra]) == 2
    one_line_error(capsys.readouterr(), *needles)


@pytest.mark.parametrize(
    ("extra", "needles"),
    [
        (["--target-camera", "Nikon D5301"], ("--target-camera", "unknown camera", NIKON)),
        (["--target-camera", NIKON, "--ground-truth-name", "gt.csv"], ("gt.csv",)),
        (["--camera-map", "global"], ("--camera-map", "--target-camera")),
        (["--target-camera", NIKON, "--adapt-on", "."], ("--adapt-on", "FFCC", "grey-edge-1-6-2")),
    ],
)
def test_training_for_a_camera_refuses_bad_options_in_one_line(
    small_world_commands, two_folders, capsys, extra, needles
):
    argv = ["train", str(two_folders / "canon"), f"--camera-for=canon={CANON}", "--method", "grey-edge-1-6-2"]
    assert cli.main([*argv, *extra, "--no-progress"]) == 2
    one_line_error(capsys.readouterr(), *needles)


def test_a_folder_without_a_camera_is_refused_for_training(small_world_commands, two_folders, capsys):
    argv = ["train", str(two_folders / "canon"), str(two_folders / "nikon"), f"--camera-for=canon={CANON}"]
    assert cli.main([*argv, "--target-camera", NIKON, "--method", "grey-edge-1-6-2", "--no-progress"]) == 2
    one_line_error(capsys.readouterr(), "--camera-for", "no camera for", str(two_folders / "nikon"))


@pytest.mark.slow  # two leave-one-camera-out runs that train FFCC: minutes on two shared cores
def test_adaptation_reads_the_scored_folders_images_never_its_ground_truth(
    small_world_commands, two_folders, tmp_path, monkeypatch
):
    """Leave-one-camera-out with --adapt, twice: the second time the canon folder's ground truth is
    poisoned (rows rotated, one light scaled 50x). The adapted model scoring canon (its bias map)
    and its estimates there are bit-identical; the adapted prior moved off the trained one."""
    import shutil

    from ccjax.estimators import ffcc

    biases = []
    real = ffcc.adapt_bias

    def spy(model, *args, **kwargs):
        adapted, q = real(model, *args, **kwargs)
        biases.append((np.asarray(model.bias), np.asarray(adapted.bias)))
        return adapted, q

    monkeypatch.setattr(ffcc, "adapt_bias", spy)
    root = tmp_path / "sets"
    shutil.copytree(two_folders, root)
    argv = [a if a != "grey-edge-1-6-2" else "FFCC" for a in _loco(root)] + ["--adapt"]
    assert cli.main([*argv, "--json", str(tmp_path / "a.json")]) == 0
    truth = (root / "canon" / "groundtruth.csv").read_text().splitlines()
    rows = truth[1:]
    lights = [row.split(",", 1)[1] for row in rows]
    poisoned = [row.split(",", 1)[0] + "," + lights[(index + 3) % len(rows)] for index, row in enumerate(rows)]
    name, light = poisoned[0].split(",", 1)
    poisoned[0] = name + "," + ",".join(str(50 * float(x)) for x in light.split(","))
    (root / "canon" / "groundtruth.csv").write_text("\n".join([truth[0], *poisoned]) + "\n")
    assert cli.main([*argv, "--json", str(tmp_path / "b.json")]) == 0
    before, after = (json.loads((tmp_path / name).read_text()) for name in ("a.json", "b.json"))

    # Rounds in folder order: canon scored first, in both runs.
    assert len(biases) == 4
    np.testing.assert_array_equal(biases[0][1], biases[2][1])
    assert np.abs(biases[0][1] - biases[0][0]).max() > 1e-3  # the adaptation did move the prior

    def estimates(report, label):
        images = report["sets"]["canon"]["evaluation"]["images"]
        return np.array([r["illuminant"] for r in images if r["method"] == label])

    adapted = estimates(before, "FFCC adapted")
    assert adapted.shape == (8, 3) and np.all(np.isfinite(adapted))
    np.testing.assert_array_equal(adapted, estimates(after, "FFCC adapted"))
    assert "light prior adapted to 8 unlabelled images of canon" in before["sets"]["canon"]["evaluation"]["training"][0]
