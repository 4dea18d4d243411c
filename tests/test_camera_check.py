"""Camera handling of the image commands: world-based methods need --camera, the
curve check flags ground truth of another camera's curves, and ``ccjax cameras`` lists cleanly."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import ccjax.io
from ccjax import cli, data, io, spectra
from ccjax.camera import Camera
from ccjax.evaluation import camera_check as cameras
from ccjax.runs import store
from ccjax.world import World

SAME_CAMERA = ("Nikon D5100", "Nikon D5300", "Canon EOS 5D Mark II", "Canon EOS 600D", "Sony ILCE-7M3")


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


PLANCK_C2 = 1.4388e-2
"""Second radiation constant c2 in m K as CIE 015:2018 fixes it for colorimetry (ITS-90), for the
test's own Planck's law."""


def _rg(v: np.ndarray) -> np.ndarray:
    return v[:, :2] / v.sum(axis=1, keepdims=True)


def _oracle_polyline_distance(points: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Point by point, segment by segment: the perpendicular foot when it falls inside the
    segment, else the nearer end."""
    out = []
    for px, py in points:
        best = np.inf
        for (ax, ay), (bx, by) in itertools.pairwise(vertices):
            ends = min(np.hypot(px - ax, py - ay), np.hypot(px - bx, py - by))
            length = np.hypot(bx - ax, by - ay)
            along = ((px - ax) * (bx - ax) + (py - ay) * (by - ay)) / length
            inside = abs((px - ax) * (by - ay) - (py - ay) * (bx - ax)) / length if 0 <= along <= length else np.inf
            best = min(best, ends, inside)
        out.append(best)
    return np.array(out)


def test_polyline_distance_against_a_numpy_oracle():
    rng = np.random.default_rng(0)
    vertices = np.cumsum(rng.uniform(-1.0, 1.0, (9, 2)), axis=0)
    points = rng.uniform(-4.0, 4.0, (60, 2))
    got = cameras.polyline_distance(points, vertices)
    np.testing.assert_allclose(got, _oracle_polyline_distance(points, vertices), rtol=1e-12, atol=1e-12)
    # Closed forms: on a vertex, above the middle of a segment, beyond an end.
    square = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
    np.testing.assert_allclose(
        cameras.polyline_distance(np.array([[2.0, 2.0], [1.0, -0.5], [-3.0, 4.0], [2.0, 3.0]]), square),
        [0.0, 0.5, 5.0, 1.0],
        atol=1e-15,
    )
    with pytest.raises(ValueError, match="vertices"):
        cameras.polyline_distance(points, vertices[:1])
    with pytest.raises(ValueError, match="vertices"):
        cameras.polyline_distance(points, np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 1.0]]))


def test_locus_is_planck_and_cie_daylight_through_the_curves():
    """The locus' blackbodies against Planck's law written here; both ends of both families."""
    import colour

    camera = Camera.from_name("Nikon D5300")
    sensors = np.asarray(camera.sensors, np.float64)
    bodies, days = cameras.locus_whites(camera)
    metres = spectra.WAVELENGTHS * 1e-9
    low, high = cameras.LOCUS_BLACKBODY_KELVIN
    kelvin = 1e6 / np.linspace(1e6 / high, 1e6 / low, len(bodies))
    planck = metres[None] ** -5 / np.expm1(PLANCK_C2 / (metres[None] * kelvin[:, None]))
    np.testing.assert_allclose(_rg(bodies), _rg(planck @ sensors), rtol=1e-9)
    assert np.all(np.diff(1e6 / kelvin) <= cameras.LOCUS_MIRED_STEP + 1e-9)
    for kelvin, white in zip(cameras.LOCUS_DAYLIGHT_KELVIN, (days[-1], days[0]), strict=True):
        sd = colour.sd_CIE_illuminant_D_series(colour.temperature.CCT_to_xy_CIE_D(kelvin))
        want = np.interp(spectra.WAVELENGTHS, sd.wavelengths, sd.values) @ sensors
        np.testing.assert_allclose(_rg(white[None]), _rg(want[None]), rtol=1e-9)


def test_check_is_the_lower_quartile_of_the_distance_to_the_locus(worlds):
    world = worlds["Nikon D5100"]
    bodies, days = cameras.locus_whites(world.camera)
    on_locus = np.concatenate([bodies[::7], days[::5]]) * 3.0
    assert cameras.curve_check(on_locus, world).distance == pytest.approx(0.0, abs=1e-12)
    rng = np.random.default_rng(0)
    truth = rng.uniform(0.1, 1.0, (25, 3))
    distances = np.minimum(
        _oracle_polyline_distance(_rg(truth), _rg(bodies)), _oracle_polyline_distance(_rg(truth), _rg(days))
    )
    want = np.quantile(distances, 0.25)
    check = cameras.curve_check(truth, world)
    np.testing.assert_allclose(check.distances, distances, rtol=1e-9)
    assert check.distance == pytest.approx(want, rel=1e-9) and check.passed == (want <= cameras.CURVE_THRESHOLD)
    assert cameras.curve_check(truth, world, quantile=1.0).distance == pytest.approx(distances.max(), rel=1e-9)
    assert "lower-quartile" in check.message() and "locus of Nikon D5100" in check.message()
    for bad, name in ((np.zeros((3, 3)), "truth"), (np.ones(3), "truth"), (np.ones((0, 3)), "truth")):
        with pytest.raises(ValueError, match=name):
            cameras.curve_check(bad, world)
    with pytest.raises(ValueError, match="threshold"):
        cameras.curve_check(truth, world, threshold=0.0)
    for quantile in (0.0, 1.5, float("nan")):
        with pytest.raises(ValueError, match="quantile"):
            cameras.curve_check(truth, world, quantile=quantile)


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


def _planckian_lights(rng) -> np.ndarray:
    """Daylights and blackbodies at random temperatures: the lights most photographs are taken under."""
    return np.concatenate(
        [spectra.cie_daylight(rng.uniform(4000, 12000, 20)), spectra.blackbody(rng.uniform(2500, 7000, 20))]
    )


@pytest.mark.parametrize(
    ("taken", "checked"),
    [
        ("Canon EOS 600D", "Sony ILCE-7M3"),
        ("Sony ILCE-7M3", "Canon EOS 600D"),
        ("Canon EOS 600D", "Nikon D5100"),
        ("Nikon D5100", "Canon EOS 600D"),
    ],
)
def test_a_canon_is_told_from_other_makers(worlds, taken, checked):
    """The Canon EOS 600D's truths against a Sony's and a Nikon's curves, and theirs against the
    Canon's, are flagged, for the world's lights and for daylight and blackbody lights alike; each
    passes against its own curves. (The median distance to the nearest of the world's whites,
    the check before, passed the Canon's truths of both families against the Sony's curves, 0.0050
    and 0.0038, and the Sony's world lights against the Canon's, 0.0070.)"""
    world = worlds[taken]
    lights = np.concatenate([np.asarray(world.train_illuminants), np.asarray(world.test_illuminants)])
    for family in (lights.astype(np.float64), _planckian_lights(np.random.default_rng(4))):
        truth = family @ np.asarray(world.camera.sensors, np.float64)
        assert cameras.curve_check(truth, world).passed
        check = cameras.curve_check(truth, worlds[checked])
        assert not check.passed, check.message()


def test_planckian_truths_of_every_embedded_camera_lie_on_its_locus():
    """Daylight and blackbody truths rendered through each of the 52 embedded cameras lie on its
    own locus (the chords of the polyline only)."""
    rng = np.random.default_rng(5)
    planckian = _planckian_lights(rng)
    names = list(data.rawtoaces_cameras())
    assert len(names) == 52
    for name in names:
        camera = Camera.from_name(name)
        distance = cameras.locus_distance(planckian @ np.asarray(camera.sensors, np.float64), camera)
        assert distance.max() < 5e-5, (name, distance.max())


@pytest.mark.manual  # about 60 s on 2 cores (every embedded camera)
def test_rendered_truths_pass_for_every_embedded_camera():
    """The calibration's requirement (``CURVE_THRESHOLD``): the default world's training and test
    lights, and the seed-7 world's test lights, rendered through each embedded camera's curves
    pass against its own curves (0 same-camera failures)."""
    for name in data.rawtoaces_cameras():
        world, other = World.default(name), World.default(name, seed=7)
        sensors = np.asarray(world.camera.sensors, np.float64)
        lights = np.concatenate([np.asarray(world.train_illuminants), np.asarray(world.test_illuminants)])
        for family in (lights, np.asarray(other.test_illuminants)):
            check = cameras.curve_check(family.astype(np.float64) @ sensors, world)
            assert check.passed, check.message()


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
    # Without the external data its cameras are listed too, each saying what it needs.
    rows = [line for line in lines[1:] if "needs the external data, not found" not in line]
    assert len(rows) == len(names)
    for line, name in zip(rows, names, strict=True):
        assert line[:start].rstrip() == name
    for line in lines[1:]:
        assert line[start - 2 : start] == "  " and line[start] != " "


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
