"""Camera handling of the image commands: world-based methods need --camera, the
curve check flags ground truth of another camera's curves, and ``ccjax cameras`` lists cleanly."""

from __future__ import annotations

import numpy as np
import pytest

import ccjax.io
from ccjax import cli, io
from ccjax.experiments import _cameras as cameras
from ccjax.runs import store
from ccjax.world import World

SAME_CAMERA = ("Nikon D5100", "Nikon D5300", "Canon EOS 5D Mark II", "Sony ILCE-7M3")


@pytest.fixture(scope="module")
def worlds():
    """The default world of each camera: the check's reference."""
    return {name: World.default(name) for name in SAME_CAMERA}


@pytest.fixture(scope="module")
def lights():
    """Independent lights for the ground truth: the test set of another seed's world (other
    random mixtures than seed 0's, among the daylight, blackbody and lamp sources)."""
    return np.asarray(World.default("Nikon D5100", seed=7).test_illuminants, np.float64)


def _truth(world: World, lights, rng, count: int | None = None) -> np.ndarray:
    """Ground truth as a data set gives it: the white of ``world``'s camera under each light
    (``count`` lights drawn at random, default all), any scale."""
    if count is not None:
        lights = lights[rng.choice(len(lights), count, replace=False)]
    whites = lights @ np.asarray(world.camera.sensors, np.float64)
    return whites * rng.uniform(0.2, 5.0, (len(whites), 1))


def test_check_is_the_median_distance_to_the_nearest_white(worlds):
    world = worlds["Nikon D5100"]
    whites = np.concatenate([np.asarray(world.train_whites), np.asarray(world.test_whites)]).astype(np.float64)
    assert cameras.curve_check(whites[:40] * 3.0, world).distance == pytest.approx(0.0, abs=1e-7)
    # Oracle: brute force over the whites in (r,g).
    rng = np.random.default_rng(0)
    truth = rng.uniform(0.1, 1.0, (25, 3))
    rg = lambda v: v[:, :2] / v.sum(axis=1, keepdims=True)
    want = np.median([min(np.hypot(*(t - w)) for w in rg(whites)) for t in rg(truth)])
    check = cameras.curve_check(truth, world)
    assert check.distance == pytest.approx(want, rel=1e-6) and check.passed == (want <= cameras.CURVE_THRESHOLD)
    with pytest.raises(ValueError, match="truth"):
        cameras.curve_check(np.zeros((3, 3)), world)
    with pytest.raises(ValueError, match="truth"):
        cameras.curve_check(np.ones(3), world)


def test_d5100_truth_is_flagged_against_the_d5300_and_matching_cameras_pass(worlds, lights):
    """Synthetic truths of the Nikon D5100 checked against the D5300's
    curves are flagged (and the reverse); every camera checked against its own curves passes."""
    rng = np.random.default_rng(1)
    d5100 = _truth(worlds["Nikon D5100"], lights, rng)
    d5300 = _truth(worlds["Nikon D5300"], lights, rng)
    wrong = cameras.curve_check(d5100, worlds["Nikon D5300"])
    assert not wrong.passed and wrong.distance > 2 * cameras.CURVE_THRESHOLD, wrong.message()
    assert "probably not taken" in wrong.message() and f"{wrong.distance:.4f}" in wrong.message()
    assert not cameras.curve_check(d5300, worlds["Nikon D5100"]).passed
    for name, world in worlds.items():
        check = cameras.curve_check(_truth(world, lights, rng), world)
        assert check.passed and check.distance < 0.75 * cameras.CURVE_THRESHOLD, (name, check.distance)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


def test_cameras_check_command(tmp_path, cache, worlds, lights, capsys):
    rng = np.random.default_rng(2)
    truth = _truth(worlds["Nikon D5100"], lights, rng, 80)
    io.write_ground_truth(tmp_path / "gt.csv", [f"i{k}.png" for k in range(len(truth))], truth)
    argv = ["cameras", "--check", str(tmp_path / "gt.csv"), "--camera"]
    assert cli.main([*argv, "Nikon D5300", "--plot", str(tmp_path / "check.png")]) == 1
    out = capsys.readouterr().out
    assert "Nikon D5300" in out and "probably not taken" in out
    assert (tmp_path / "check.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary left
    assert cli.main([*argv, "Nikon D5100"]) == 0
    assert "consistent with its curves" in capsys.readouterr().out
    assert cli.main(["cameras", "--check", str(tmp_path / "gt.csv")]) == 2
    assert "--camera" in capsys.readouterr().err


def test_cameras_plot_path_is_checked_before_any_work(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(store, "world", lambda *a, **k: pytest.fail("work before the check"))
    (tmp_path / "gt.csv").write_text("image,r,g,b\na.png,1,1,1\n")
    argv = ["cameras", "--check", str(tmp_path / "gt.csv"), "--camera", "Nikon D5100", "--plot"]
    (tmp_path / "d.png").mkdir()
    for bad, problem in (
        (tmp_path / "gt.csv" / "p.png", "is not a folder"),
        (tmp_path / "p.pdf", ".png"),
        (tmp_path, "folder"),
    ):
        assert cli.main([*argv, str(bad)]) == 2
        assert problem in capsys.readouterr().err
    assert cli.main(["world", "--plot", str(tmp_path / "p.txt")]) == 2
    assert ".png" in capsys.readouterr().err


def test_camera_listing_columns_never_touch(capsys):
    assert cli.main(["cameras"]) == 0
    lines = capsys.readouterr().out.splitlines()
    start = lines[0].index("source")
    names = list(ccjax.camera.cameras())
    assert len(lines) == len(names) + 1
    for line, name in zip(lines[1:], names, strict=True):
        assert line[:start].rstrip() == name and line[start - 2 : start] == "  " and line[start] != " "


def test_unknown_camera_points_to_the_command(tmp_path, capsys):
    assert cli.main(["estimate", str(tmp_path), "--method", "GW", "--camera", "Nikon D5301"]) == 2
    err = capsys.readouterr().err
    assert "`ccjax cameras`" in err and "'Nikon D5300'" in err and "ccjax.cameras()" not in err


@pytest.mark.parametrize("command", ["estimate", "correct", "evaluate"])
def test_world_based_methods_need_a_camera_before_any_image_is_read(tmp_path, monkeypatch, capsys, command):
    monkeypatch.setattr(ccjax.io, "probe_image", lambda *a, **k: pytest.fail("an image was looked at"))
    monkeypatch.setattr(ccjax.io, "read_image", lambda *a, **k: pytest.fail("an image was read"))
    (tmp_path / "gt.csv").write_text("image,r,g,b\na.png,1,1,1\n")
    argv = {
        "estimate": ["estimate", str(tmp_path), "--method", "ECRULE-MV"],
        "correct": ["correct", str(tmp_path), str(tmp_path / "out"), "--method", "C-by-C-MMSE"],
        "evaluate": ["evaluate", str(tmp_path), "--ground-truth", str(tmp_path / "gt.csv"), "--methods", "GW,DB-GW"],
    }[command]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert "--camera" in err and "`ccjax cameras`" in err and "GW," not in err


def test_world_based_models():
    """The model hook decides: fitted to the world's lights or reflectances as its camera sees them
    (needs --camera on photographs), or statistics of the image (the world gives a fallback only)."""
    world = World.default()
    for label in ("ECRULE-MV", "C-by-C-MMSE", "DB-GW", "AVE-ILLUM", "NOTHING", "CIP-MV"):
        assert store.fit(label, world).world_based, label
    for label in ("GW", "RETINEX", "max-rgb", "shades-of-grey-p6", "soft-RETINEX-t0.1", "grey-edge-0-1-0"):
        assert not store.fit(label, world).world_based, label


def test_world_based_agrees_with_the_models_default_input():
    """A world-free method gets every pixel by default, a world-based one the thesis' blocks."""
    world = World.default()
    for label in ("GW", "DB-GW", "RETINEX", "shades-of-grey-p6", "grey-edge-1-6-2", "AVE-ILLUM"):
        model = store.fit(label, world)
        assert model.world_based == (model.default_preprocessing != "pixels"), label


def test_evaluate_warns_when_the_truth_is_another_cameras(tmp_path, cache, worlds, lights, capsys):
    """Images rendered with the D5100's curves (a grey card under each light), evaluated with the
    D5300 named as the camera: evaluate warns with the distance; with the D5100 it does not."""
    rng = np.random.default_rng(3)
    truth = _truth(worlds["Nikon D5100"], lights, rng, 80)
    grey = truth / truth.max(axis=1, keepdims=True) * 0.5
    images = np.broadcast_to(grey[:, None, None, :], (len(grey), 6, 6, 3))
    gt = io.write_dataset(tmp_path / "set", images, truth)
    argv = ["evaluate", str(tmp_path / "set"), "--ground-truth", str(gt), "--methods", "GW", "--no-progress"]
    assert cli.main([*argv, "--camera", "Nikon D5300"]) == 0
    captured = capsys.readouterr()
    assert "warning: camera check" in captured.err and "Nikon D5300" in captured.err
    assert "camera check" in captured.out
    assert cli.main([*argv, "--camera", "Nikon D5100"]) == 0
    captured = capsys.readouterr()
    assert "warning" not in captured.err and "consistent with its curves" in captured.out
