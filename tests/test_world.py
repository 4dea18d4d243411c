"""Spectra, data loaders, cameras and worlds."""

import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from conftest import require_external_data
from jaxtyping import TypeCheckError

from ccjax import data, spectra
from ccjax.camera import Camera, cameras
from ccjax.metrics import angular_error
from ccjax.world import build_illuminant_set, normalise_illuminants


def test_runtime_shape_checks_reach_ccjax():
    """The suite runs with jaxtyping + beartype checks on ccjax (pyproject ``--jaxtyping-packages``):
    a wrongly shaped signal is rejected by its annotation, not by the matrix product inside."""
    camera = Camera.from_name("Canon EOS 5D Mark II")
    with pytest.raises(TypeCheckError, match="signal"):
        camera.response(np.ones((4, 100)))


def test_strict_dtype_promotion_is_on():
    """The suite runs with ``jax_numpy_dtype_promotion="strict"`` (tests/conftest.py)."""
    import jax
    import jax.numpy as jnp

    with pytest.raises(jax.dtypes.TypePromotionError, match="strict"):
        jnp.ones(2, jnp.float32) + jnp.ones(2, jnp.int32)


def test_grid():
    assert spectra.WAVELENGTHS.shape == (101,)
    assert spectra.WAVELENGTHS[0] == 380 and spectra.WAVELENGTHS[-1] == 780


def test_resample_sensor_zero_outside_spectrum_edge_held():
    wl = np.array([400.0, 500.0, 600.0])
    values = np.array([1.0, 2.0, 3.0])
    sensor = spectra.resample(wl, values, kind="sensor")
    spectrum = spectra.resample(wl, values, kind="spectrum")
    at = lambda x: int(np.flatnonzero(spectra.WAVELENGTHS == x)[0])
    assert sensor[at(380)] == 0 and sensor[at(700)] == 0
    assert spectrum[at(380)] == 1 and spectrum[at(700)] == 3
    assert sensor[at(448)] == pytest.approx(1.48) and spectrum[at(552)] == pytest.approx(2.52)


def test_resample_rejects_bad_input():
    with pytest.raises(ValueError, match="increasing"):
        spectra.resample(np.array([500.0, 400.0]), np.array([1.0, 2.0]), kind="sensor")
    with pytest.raises(ValueError, match="NaN"):
        spectra.resample(np.array([400.0, 500.0]), np.array([1.0, np.nan]), kind="sensor")
    # Under the test suite's runtime checks the Literal annotation rejects the kind first.
    with pytest.raises((ValueError, TypeCheckError), match="kind"):
        spectra.resample(np.array([400.0, 500.0]), np.array([1.0, 2.0]), kind="other")


def test_embedded_data():
    refl = data.sfu_reflectances()
    assert refl.values.shape == (1993, 101)
    counts = {name: int(np.sum(refl.categories == name)) for name in set(refl.categories)}
    assert counts == {"macbeth": 24, "munsell": 1269, "dupont": 120, "krinov": 355, "objects": 170, "additional": 55}
    cams = data.rawtoaces_cameras()
    assert len(cams) == 52 and "Canon EOS 5D Mark II" in cams
    assert all(c.shape == (101, 3) and c.min() >= 0 for c in cams.values())


def test_camera_validation_and_lookup():
    cam = Camera.from_name("Canon EOS 5D Mark II")
    assert cam.sensors.shape == (101, 3)
    with pytest.raises(ValueError, match="camera: unknown"):
        Camera.from_name("No Such Camera")
    with pytest.raises(ValueError, match="sensors"):
        Camera.from_array(np.ones((100, 3)))
    with pytest.raises(ValueError, match="negative"):
        Camera.from_array(-np.ones((101, 3)))
    assert "Canon EOS 5D Mark II" in cameras()


def test_missing_external_data_error_names_the_file(tmp_path):
    with pytest.raises(data.DataNotFoundError, match=r"sony_dxc930.*CCJAX_DATA"):
        data.sony_dxc930(tmp_path)


@pytest.mark.parametrize(("ci", "outcome"), [("", "1 skipped"), ("true", "1 error")])
def test_external_data_marker_skips_when_the_data_is_absent(tmp_path, ci, outcome):
    """A test marked ``external_data`` skips (errors under CI=true) when the data cannot be found,
    before its body runs: the suite's conftest in a folder of its own, with the data look-up made
    to fail as it does on a fresh clone without ../shared."""
    conftest = pathlib.Path(__file__).with_name("conftest.py").read_text()
    missing = "def _missing(*args, **kwargs):\n    raise data.DataNotFoundError('no data here')\n"
    (tmp_path / "conftest.py").write_text(f"{conftest}\n{missing}\ndata.find_data_file = _missing\n")
    (tmp_path / "test_marked.py").write_text(
        "import pytest\n\n\n@pytest.mark.external_data\ndef test_needs_data():\n    raise AssertionError\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "CI"} | {"CI": ci}
    env["PYTHONPATH"] = os.pathsep.join([str(pathlib.Path(__file__).parent.parent), env.get("PYTHONPATH", "")])
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:cacheprovider",
            "-p",
            "no:xdist",
            "-o",
            "markers=external_data",
            ".",
        ],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert outcome in run.stdout.splitlines()[-1], run.stdout + run.stderr
    assert "AssertionError" not in run.stdout


def test_normalisation_puts_brightest_white_channel_at_one(default_world):
    for whites in (default_world.train_whites, default_world.test_whites, default_world.canonical_white[None]):
        np.testing.assert_allclose(np.max(np.asarray(whites), axis=-1), 1.0, rtol=1e-5)


def test_illuminant_set_one_per_cell_except_priority():
    rng = np.random.default_rng(0)
    sensors = np.abs(rng.normal(size=(101, 3)))
    sources = np.abs(rng.normal(1.0, 0.5, size=(12, 101)))
    built = build_illuminant_set(sources, sensors, n_priority=3, cell=0.02, seed=4, n_candidates=20_000)
    rgb = built.spectra @ sensors
    rg = rgb[:, :2] / rgb.sum(axis=-1, keepdims=True)
    cells = [tuple(c) for c in np.floor(rg / 0.02).astype(int)]
    non_priority = [c for c, o in zip(cells, built.origin) if o != "priority"]
    assert len(set(non_priority)) == len(non_priority)
    assert not set(non_priority) & {c for c, o in zip(cells, built.origin) if o == "priority"}
    np.testing.assert_allclose((built.spectra @ sensors).max(axis=1), 1.0)
    again = build_illuminant_set(sources, sensors, n_priority=3, cell=0.02, seed=4, n_candidates=20_000)
    np.testing.assert_array_equal(built.spectra, again.spectra)


def test_default_world_layout(default_world):
    sizes = default_world.sizes()
    assert sizes["reflectances"] == 1993
    # Test set: cells four times denser, so clearly more lights than the training set.
    assert sizes["test illuminants"] > 2.5 * sizes["training illuminants"] > 100
    # D65 canonical: the Canon's white under D65 is green-dominant, as for any Bayer camera.
    assert int(np.argmax(np.asarray(default_world.canonical_white))) == 1


def test_barnard_world_matches_sfu321_groundtruth(barnard_world):
    """A perfect white under each lab light matches the mean SFU-321 ground truth within 3 degrees."""
    truth = data.sfu321_groundtruth()
    lights = data.sfu_illuminants()
    errors = {}
    for code, name in data.SFU_LAB_LIGHTS.items():
        mean_truth = truth.rgb[[i for i, label in enumerate(truth.labels) if label == code]].mean(axis=0)
        white = np.asarray(barnard_world.camera.response(lights.values[lights.names.index(name)]))
        errors[code] = float(angular_error(white, mean_truth))
    print(errors)
    assert len(errors) == 11 and max(errors.values()) < 3.0


def test_barnard_world_training_set_places_lab_lights_first(barnard_world):
    require_external_data()
    lights = data.sfu_illuminants()
    lab = normalise_illuminants(
        lights.values[[lights.names.index(n) for n in data.SFU_LAB_LIGHTS.values()]],
        np.asarray(barnard_world.camera.sensors),
    )
    np.testing.assert_allclose(np.asarray(barnard_world.train_illuminants[:11]), lab, rtol=1e-5)
    # one light per reachable 0.02 (r,g) cell (Barnard 1999 §4.4): about 90 for this camera and these lights
    assert 80 <= barnard_world.sizes()["training illuminants"] <= 100


def test_world_responses_are_the_image_formation_sum():
    """``World.responses``: rho_k = sum_lambda E S R_k for every light and surface (Barnard 1999
    eq. 4.1), checked against a float64 loop; any leading shape of lights."""
    from small_world import small_world

    world = small_world()
    lights = np.asarray(world.train_illuminants[:3], np.float64)
    reflectances = np.asarray(world.reflectances, np.float64)
    sensors = np.asarray(world.camera.sensors, np.float64)
    expected = np.zeros((3, len(reflectances), 3))
    for j, light in enumerate(lights):
        for s, surface in enumerate(reflectances):
            for k in range(3):
                expected[j, s, k] = np.sum(light * surface * sensors[:, k])
    got = world.responses(world.train_illuminants[:3])
    assert got.shape == (3, len(reflectances), 3)
    np.testing.assert_allclose(np.asarray(got), expected, rtol=2e-5)
    np.testing.assert_array_equal(np.asarray(world.responses(world.canonical)), np.asarray(world.canonical_rgb))
    assert world.responses(np.stack([lights[:2], lights[1:]])).shape == (2, 2, len(reflectances), 3)
