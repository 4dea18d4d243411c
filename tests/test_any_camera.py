"""The any-camera estimator: trained once on renders of a few cameras, bound to other cameras by
their curves alone. The renders are NumPy's (Planck lights times SFU reflectances through each
camera's curves), the oracle of every error here; shades of grey and FFCC trained on the camera's
own renders are the two independent yardsticks."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest
from small_world import planck

from ccjax import data
from ccjax.camera import Camera
from ccjax.estimators import conditioned, ffcc
from ccjax.estimators.base import estimate_batch

TRAIN = ("Canon EOS 5D Mark II", "Nikon D700", "Sony ILCE-7M3", "Fujifilm X-T3")
ASKED = ("Canon EOS 600D", "Nikon D5300", "Panasonic DC-GX9", "Sony DSC-RX100M4", "Hasselblad L2D-20c")
SETTINGS = ffcc.Hyperparameters(pretrain_iterations=8, iterations=24)
BINS = 32


def renders(camera: str, count: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``count`` 16x16 Mondrians (4x4 patches of random SFU reflectances) under random mixes of two
    Planck lights (2500-10000 K) through ``camera``'s curves, brightest pixel 0.8, and the
    camera's RGB of white under each light."""
    rng = np.random.default_rng(seed)
    sensors = np.asarray(Camera.from_name(camera).sensors, np.float64)
    reflectances = np.asarray(data.sfu_reflectances().values, np.float64)
    kelvin = rng.uniform(2500.0, 10000.0, (count, 2))
    mix = rng.uniform(0.0, 1.0, (count, 1))
    spectra = np.stack([planck(t) for t in kelvin.reshape(-1)]).reshape(count, 2, -1)
    spectra = spectra / spectra.mean(axis=-1, keepdims=True)
    lights = mix * spectra[:, 0] + (1 - mix) * spectra[:, 1]  # (count, 101)
    patches = reflectances[rng.integers(0, len(reflectances), (count, 16))]  # (count, 16, 101)
    rgb = (patches * lights[:, None]) @ sensors  # (count, 16, 3)
    rgb = rgb / rgb.max(axis=(1, 2), keepdims=True) * 0.8
    images = np.repeat(np.repeat(rgb.reshape(count, 4, 4, 3), 4, axis=1), 4, axis=2)
    images = images * rng.uniform(0.97, 1.03, images.shape)  # texture inside the patches
    return images.astype(np.float32), np.ones(images.shape[:3], bool), (lights @ sensors).astype(np.float32)


def angles(estimates: np.ndarray, truth: np.ndarray) -> np.ndarray:
    a = estimates / np.linalg.norm(estimates, axis=1, keepdims=True)
    b = truth / np.linalg.norm(truth, axis=1, keepdims=True)
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=1), -1.0, 1.0)))


@pytest.fixture(scope="module")
def any_camera_model() -> conditioned.AnyCamera:
    parts = [renders(camera, 48, seed) for seed, camera in enumerate(TRAIN)]
    images, masks, lights = (np.concatenate([part[k] for part in parts]) for k in range(3))
    matrices = np.concatenate(
        [np.repeat(conditioned.reference_matrix(Camera.from_name(c))[None], 48, axis=0) for c in TRAIN]
    )
    model, _ = conditioned.train(images, masks, lights, matrices, SETTINGS, bins=BINS)
    return model


@pytest.mark.slow
def test_one_model_serves_cameras_it_never_saw_by_their_curves(any_camera_model):
    for index, camera in enumerate(ASKED):
        images, masks, lights = renders(camera, 48, 100 + index)
        bound = any_camera_model.bind(Camera.from_name(camera))
        errors = angles(np.asarray(estimate_batch(bound, jnp.asarray(images), jnp.asarray(masks)).illuminant), lights)
        grey = angles(np.sum(images.astype(np.float64) ** 6, axis=(1, 2)) ** (1 / 6), lights)  # shades of grey p 6
        own_images, own_masks, own_lights = renders(camera, 192, 200 + index)  # as many as the pool
        own, _ = ffcc.train(ffcc.init_ffcc(BINS), own_images, own_masks, own_lights, SETTINGS)
        own_errors = angles(np.asarray(estimate_batch(own, jnp.asarray(images), jnp.asarray(masks)).illuminant), lights)
        assert np.median(errors) < np.median(grey), camera
        assert np.median(errors) <= 1.5 * np.median(own_errors), camera


@pytest.mark.slow
def test_binding_is_a_map_from_the_curves_and_a_file_holds_none(any_camera_model):
    camera = Camera.from_name(ASKED[0])
    bound = any_camera_model.bind(camera)
    assert bound.camera == ASKED[0] and any_camera_model.camera is None
    np.testing.assert_array_equal(np.asarray(bound.unbound().matrix), np.eye(3))
    # The map takes the camera's whites under the bank of lights onto the reference camera's
    # (least squares over surfaces and a heavily weighted white): within a degree.
    bank = conditioned.light_bank()
    whites = bank @ np.asarray(camera.sensors, np.float64)
    reference = bank @ conditioned.reference_sensors()
    mapped = whites @ conditioned.reference_matrix(camera).T
    assert np.max(angles(mapped, reference)) < 1.0


def test_twins_are_the_same_model_or_a_fingerprint_within_half_a_degree():
    cameras = {name: Camera.from_name(name) for name in ("Canon EOS 600D", "Canon EOS M", "Nikon D5300")}
    assert conditioned.model_name("Jiang: Canon 600D") == conditioned.model_name("Canon EOS 600D") == "canon 600d"
    assert conditioned.twins(cameras["Canon EOS 600D"], cameras) == ["Canon EOS 600D"]
    blend = Camera.from_array(
        0.99 * np.asarray(cameras["Nikon D5300"].sensors) + 0.01 * np.asarray(cameras["Canon EOS M"].sensors), "blend"
    )
    assert conditioned.twins(blend, cameras) == ["Nikon D5300"]
    assert conditioned.fingerprint_distance(cameras["Canon EOS 600D"], cameras["Nikon D5300"]) > 0.5


@pytest.mark.slow
def test_a_fold_never_sees_the_scored_folders_ground_truth(
    small_world_commands, small_test_world, tmp_path, monkeypatch
):
    """Leave-one-camera-out with any-camera on two folders, twice: the second time the canon
    folder's ground truth is replaced by random lights from another region of the chromaticity
    plane (green-blue, far from any Planck light). The model trained for the canon fold (a spy on
    the trainer keeps it) is bit-identical and its estimates on the canon folder do not move."""
    import functools

    import jax

    from ccjax import evaluation, io, scenes
    from ccjax.runs import augmented

    monkeypatch.setattr(augmented, "Augmentation", functools.partial(augmented.Augmentation, database=2, sampled=1))
    kept = []
    real = conditioned.train

    def spy(*args, **kwargs):  # the small settings of the test above
        model, record = real(*args[:4], SETTINGS, bins=BINS, index=kwargs.get("index"))
        kept.append(model)
        return model, record

    monkeypatch.setattr(conditioned, "train", spy)
    folders, images = [], []
    for index, (name, camera) in enumerate((("canon", "Canon EOS 600D"), ("nikon", "Nikon D5300"))):
        batch = scenes.sample_mondrians(
            jax.random.key(11 + index), small_test_world, 12, height=12, width=12, n_patches=5
        )
        images.append(np.asarray(batch.image))
        truth = io.write_dataset(tmp_path / name, images[-1], np.asarray(batch.illuminant))
        folders.append(evaluation.FolderSet(tmp_path / name, truth, camera))
    protocol = evaluation.LeaveOneCameraOut(("any-camera",), copies=1)
    label = "any-camera trained"
    first = evaluation.evaluate(folders, ["GW"], protocol).sets[0].evaluation.results
    rng = np.random.default_rng(5)
    poisoned = np.stack([rng.uniform(0.05, 0.2, 12), np.ones(12), rng.uniform(0.8, 1.0, 12)], axis=1)
    io.write_dataset(tmp_path / "canon", images[0], poisoned)
    second = evaluation.evaluate(folders, ["GW"], protocol).sets[0].evaluation.results
    assert len(kept) == 4  # canon's fold, then nikon's, twice
    for a, b in zip(jax.tree_util.tree_leaves(kept[0]), jax.tree_util.tree_leaves(kept[2]), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    np.testing.assert_array_equal(first.estimates[label], second.estimates[label])
    assert np.abs(np.asarray(first.truth) - np.asarray(second.truth)).max() > 0.1  # the poison is in place
    assert not np.array_equal(np.asarray(kept[1].core.bias), np.asarray(kept[3].core.bias))  # ...and reached nikon's


@pytest.mark.slow
def test_the_commands_train_once_and_bind_the_camera_named(small_world_commands, small_test_world, monkeypatch, capsys):
    """``ccjax train --method any-camera`` records no camera, ``conditioned: true``, the cameras seen
    and the folders; estimate needs --camera and gives, for the camera named, what the model bound
    to that camera's curves gives; --target-camera is refused in one line."""
    import functools
    import json

    import jax
    from image_files import one_line_error

    from ccjax import cli, io, scenes
    from ccjax.runs import augmented, store

    monkeypatch.setattr(augmented, "Augmentation", functools.partial(augmented.Augmentation, database=2, sampled=1))
    real = conditioned.train
    monkeypatch.setattr(conditioned, "train", lambda *a, **k: real(*a[:4], SETTINGS, bins=BINS, index=k.get("index")))
    small = conditioned.AnyCamera(
        core=ffcc.init_ffcc(BINS), grey=conditioned.no_grey_observation(), matrix=jnp.eye(3, dtype=jnp.float32)
    )
    monkeypatch.setattr(conditioned, "init_any_camera", lambda: small)  # the skeleton a model file is read into
    root = small_world_commands
    for index, name in enumerate(("canon", "nikon")):
        batch = scenes.sample_mondrians(jax.random.key(21 + index), small_test_world, 8, height=12, width=12)
        io.write_dataset(root / name, np.asarray(batch.image), np.asarray(batch.illuminant))
    cameras = ["--camera-for", "canon=Canon EOS 600D", "--camera-for", "nikon=Nikon D5300"]
    base = ["train", str(root / "canon"), str(root / "nikon"), *cameras, "--method", "any-camera", "--no-progress"]
    assert cli.main([*base, "--target-camera", "Sony ILCE-7M3"]) == 2
    one_line_error(capsys.readouterr(), "--target-camera", "any-camera")
    assert cli.main([*base, "--out", str(root / "any.eqx")]) == 0
    record = json.loads((root / "any.json").read_text())
    assert record["camera"] is None and record["conditioned"] is True and record["label"] == "any-camera"
    assert record["cameras_seen"] == ["Canon EOS 600D", "Nikon D5300"] and set(record["folders"]) == {"canon", "nikon"}
    capsys.readouterr()
    image = str(root / "canon" / "image-0000.png")
    assert cli.main(["estimate", image, "--model", str(root / "any.eqx")]) == 2
    one_line_error(capsys.readouterr(), "--camera")
    assert cli.main(["estimate", image, "--model", str(root / "any.eqx"), "--camera", "Sony ILCE-7M3", "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    bound = store.load_model(root / "any.eqx", camera="Sony ILCE-7M3")
    assert bound.camera == "Sony ILCE-7M3"
    photo = io.read_image(image)
    rgb = np.asarray(bound(jnp.asarray(photo.rgb), ~jnp.asarray(photo.clipped)).illuminant)
    found = np.asarray(printed[0]["illuminant"] if isinstance(printed, list) else printed["illuminant"])
    np.testing.assert_allclose(found / found.sum(), rgb / rgb.sum(), rtol=1e-5)


def test_the_window_holds_every_plausible_light_whatever_the_training_cameras_saw():
    """Trained on lights of 5000-6000 K only, the model's histogram still holds a sodium lamp's
    white (CIE HP1, through the reference camera's curves, integrated here) and every light of
    the bank: none wraps onto the far side of the torus."""
    import colour

    rng = np.random.default_rng(3)
    sensors = np.asarray(Camera.from_name(TRAIN[0]).sensors, np.float64)
    reflectances = np.asarray(data.sfu_reflectances().values, np.float64)
    lights = np.stack([planck(t) for t in rng.uniform(5000.0, 6000.0, 8)])
    rgb = (reflectances[rng.integers(0, len(reflectances), (8, 16))] * lights[:, None]) @ sensors
    images = np.repeat(np.repeat((rgb / rgb.max() * 0.8).reshape(8, 4, 4, 3), 2, axis=1), 2, axis=2)
    no_iterations = ffcc.Hyperparameters(pretrain_iterations=0, iterations=0)
    matrices = np.repeat(conditioned.reference_matrix(Camera.from_name(TRAIN[0]))[None], 8, axis=0)
    model, _ = conditioned.train(
        images.astype(np.float32),
        np.ones((8, 8, 8), bool),
        (lights @ sensors).astype(np.float32),
        matrices,
        no_iterations,
    )
    sodium = colour.SDS_ILLUMINANTS["HP1"]
    grid = np.arange(380.0, 781.0, 4.0)
    spectrum = np.interp(grid, np.asarray(sodium.wavelengths), np.asarray(sodium.values))
    whites = np.concatenate([conditioned.window_lights(), (spectrum @ conditioned.reference_sensors())[None]])
    uv = np.stack([np.log(whites[:, 1] / whites[:, 0]), np.log(whites[:, 1] / whites[:, 2])], axis=1)
    bins = (uv - np.asarray(model.core.origin, np.float64)) / float(model.core.bin_size)
    assert np.all(bins >= 0) and np.all(bins < model.core.bins)
