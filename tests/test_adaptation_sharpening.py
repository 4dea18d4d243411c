"""The standard chromatic adaptation transforms as sharpening transforms
(ccjax.sharpening.adaptation_sharpening): checked against colour-science's own von Kries
adaptation on XYZ, NumPy's least squares, and the closed form for a camera that sees XYZ."""

from __future__ import annotations

import json

import colour
import jax.numpy as jnp
import numpy as np
import pytest

from ccjax import precision, sharpening
from ccjax.camera import Camera
from ccjax.cli import main as cli_main
from ccjax.experiments import chapter5
from ccjax.spectra import resample
from ccjax.world import World


@pytest.fixture(scope="module")
def world(small_test_world) -> World:
    """The small world of the command tests (Planck lights, every 8th SFU reflectance)."""
    return small_test_world


def _cmfs() -> np.ndarray:
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    return resample(np.asarray(cmfs.wavelengths), np.asarray(cmfs.values), kind="sensor")


def test_camera_to_xyz_is_the_least_squares_fit(world):
    """NumPy's float64 least squares on the same colour signals (surfaces under the canonical and
    each training light; XYZ with the canonical white's Y at 1)."""
    reflectances = np.asarray(world.reflectances, np.float64)
    lights = np.concatenate([np.asarray(world.canonical, np.float64)[None], np.asarray(world.train_illuminants)])
    signals = reflectances[None] * lights[:, None, :]
    camera = (signals @ np.asarray(world.camera.sensors, np.float64)).reshape(-1, 3)
    xyz = (signals @ _cmfs()).reshape(-1, 3) / (lights[0] @ _cmfs())[1]
    expected = np.linalg.lstsq(camera, xyz, rcond=None)[0]
    np.testing.assert_allclose(np.asarray(sharpening.camera_to_xyz(world)), expected, rtol=2e-3, atol=2e-4)


@pytest.mark.parametrize("name", sharpening.ADAPTATION_TRANSFORMS)
def test_diagonal_map_in_the_transform_is_colour_sciences_von_kries(world, name):
    """``rgb T diag(d) T^-1`` with ``d = (w_c T) / (w T)``, taken to XYZ with ``C``, is
    ``colour.adaptation.chromatic_adaptation_VonKries`` of the XYZ for the white pair (w, w_c)."""
    transform = np.asarray(sharpening.adaptation_sharpening(world, name), np.float64)
    to_xyz = np.asarray(sharpening.camera_to_xyz(world), np.float64)
    rgb = np.asarray(world.responses(world.test_illuminants[5]), np.float64)[:25]
    white = np.asarray(world.test_whites[5], np.float64)
    canonical_white = np.asarray(world.canonical_white, np.float64)
    diagonal = (canonical_white @ transform) / (white @ transform)
    adapted = rgb @ transform @ np.diag(diagonal) @ np.linalg.inv(transform)
    oracle = colour.adaptation.chromatic_adaptation_VonKries(
        rgb @ to_xyz, white @ to_xyz, canonical_white @ to_xyz, transform=name
    )
    np.testing.assert_allclose(adapted @ to_xyz, oracle, rtol=1e-5, atol=1e-7)


def test_a_camera_that_sees_xyz_gets_the_matrix_itself(world):
    """Sensors equal to the CIE colour matching functions: the camera -> XYZ map is a multiple of
    the identity, so ``T`` is the transform's matrix (transposed, for rows) up to scale."""
    xyz_world = World(
        reflectances=world.reflectances,
        train_illuminants=world.train_illuminants,
        test_illuminants=world.test_illuminants,
        canonical=world.canonical,
        camera=Camera.from_array(_cmfs(), name="CIE 1931"),
    )
    to_xyz = np.asarray(sharpening.camera_to_xyz(xyz_world), np.float64)
    # float32 normal equations (the thesis least squares, precision HIGHEST): exact up to ~1e-4.
    np.testing.assert_allclose(to_xyz / to_xyz[0, 0], np.eye(3), atol=5e-4)
    for name in sharpening.ADAPTATION_TRANSFORMS:
        transform = np.asarray(sharpening.adaptation_sharpening(xyz_world, name), np.float64)
        matrix = np.asarray(colour.adaptation.CHROMATIC_ADAPTATION_TRANSFORMS[name], np.float64).T
        np.testing.assert_allclose(transform / to_xyz[0, 0], matrix, atol=1e-3)


def test_unknown_transform_names_the_argument(world):
    with pytest.raises(ValueError, match="name: unknown adaptation transform 'CAT99'"):
        sharpening.adaptation_sharpening(world, "CAT99")


def test_chapter5_compares_them_with_the_sharpenings(world):
    """Grey world is invariant to any sharpening (its estimate is the mean, mapped by T and back):
    under an adaptation transform its angles are those without one, while the mapping error, which
    uses the diagonal map in the transform's space, changes."""
    assert set(chapter5.ADAPTATIONS) == {"bradford", "cat02", "cat16"}
    result = chapter5.chapter5_errors(world, ["GW"], ("none", "cat02"), n_scenes=16)
    none_mapping, none_angle, _ = result.errors[("GW", "none")]
    mapping, angle, reverted = result.errors[("GW", "cat02")]
    np.testing.assert_allclose(angle, none_angle, atol=2e-3)
    assert not np.allclose(mapping, none_mapping)
    assert not reverted.any()
    with pytest.raises(ValueError, match="sharpenings: unknown"):
        chapter5.chapter5_errors(world, ["GW"], ("cat97",), n_scenes=2)


def test_sharpen_command_prints_the_transform(small_world_commands, small_test_world, capsys):
    assert cli_main(["sharpen", "--method", "cat16", "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    expected = sharpening.adaptation_sharpening(small_test_world, "CAT16")
    np.testing.assert_allclose(np.asarray(printed["T"]), np.asarray(expected), rtol=1e-6)
    assert printed["method"] == "cat16"
    assert jnp.isfinite(printed["actual_sharpened"])


def test_the_fit_takes_its_products_at_highest_precision(world):
    assert precision.low_precision_products(sharpening.camera_to_xyz, world) == []


def test_the_transform_is_numpy_float64_as_every_sharpening_methods(world):
    transform = sharpening.adaptation_sharpening(world, "CAT16")
    others = [sharpening.average_sharpening(world), sharpening.optimal_sharpening(world)[0]]
    assert all(type(t) is np.ndarray and t.dtype == np.float64 for t in [transform, *others])
    camera = np.asarray(sharpening.camera_to_xyz(world), np.float64)
    np.testing.assert_allclose(transform, camera @ sharpening.cat_matrix("CAT16").T, rtol=1e-13)
