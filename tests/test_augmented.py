"""The any-camera augmentation's copies: each copy's matrix is the bank camera's map into the
reference space after the per-light map of the image's own light (the map's ``matrix_for``, one
light at a time, composed in NumPy float64), whatever the batching of the lights."""

from __future__ import annotations

import numpy as np

from ccjax.camera import Camera
from ccjax.estimators.conditioned import reference_matrix
from ccjax.runs import augmented, store
from ccjax.transfer import fit_camera_map


def test_each_copy_is_the_bank_cameras_map_after_the_per_light_map_of_its_own_light():
    augmentation = augmented.Augmentation(copies=2, database=2, sampled=0, seed=3)
    bank = augmented.augmentation_cameras(["Canon EOS 600D"], augmentation)
    rng = np.random.default_rng(0)
    lights = rng.uniform(0.3, 1.0, (11, 3)).astype(np.float32)
    sources = ["Nikon D5300"] * 5 + ["Sony ILCE-7M3"] * 6
    entries = augmented.augment(lights, sources, bank, augmentation)
    assert len(entries.index) == 11 * 3
    np.testing.assert_array_equal(entries.index[:11], np.arange(11))
    maps = {}
    for k in range(11, len(entries.index)):
        image, camera = int(entries.index[k]), Camera.from_name(entries.cameras[k])
        source = sources[image]
        if (source, camera.name) not in maps:
            world = store.world("default", source, seed=0)
            maps[source, camera.name] = fit_camera_map(source, camera, world=world)
        per_light = np.asarray(maps[source, camera.name].matrix_for(lights[image]), np.float64)
        expected = np.asarray(reference_matrix(camera), np.float64) @ per_light
        np.testing.assert_allclose(entries.matrices[k], expected.astype(np.float32), rtol=2e-6, atol=1e-7)
