"""``ccjax train`` reads photographs as ``ccjax evaluate`` does: the black level and saturation
given on its command line reach the training images."""

import numpy as np
import pytest

from ccjax import cli, io
from ccjax.runs import store

BLACK = 2048
SATURATION = 60000


@pytest.mark.slow
def test_black_level_and_saturation_reach_the_training_images(tmp_path):
    """Files offset by a black level and read with ``--black-level`` train the model that the same
    files without the offset train (both at one saturation level on the linear scale)."""
    rng = np.random.default_rng(0)
    lights = rng.uniform(0.3, 1.0, (6, 3))
    surfaces = rng.uniform(0.05, 1.0, (6, 12, 12, 3))
    codes = np.round(surfaces * lights[:, None, None, :] * 40000 + 1000).astype(np.uint16)
    names = [f"{index}.png" for index in range(len(codes))]
    for folder, offset in (("plain", 0), ("offset", BLACK)):
        (tmp_path / folder).mkdir()
        for name, image in zip(names, codes, strict=True):
            io.write_png(tmp_path / folder / name, image + np.uint16(offset))
        io.write_ground_truth(tmp_path / folder / "groundtruth.csv", names, lights)
    # The offset files read without their black level are other images: the check can fail.
    assert not np.allclose(
        io.read_image(tmp_path / "offset" / names[0], saturation=SATURATION + BLACK).rgb,
        io.read_image(tmp_path / "plain" / names[0], saturation=SATURATION).rgb,
    )
    base = ["train", "--method", "FFCC", "--no-progress"]
    plain, offset = tmp_path / "plain.eqx", tmp_path / "offset.eqx"
    assert cli.main([*base, str(tmp_path / "plain"), "--saturation", str(SATURATION), "--out", str(plain)]) == 0
    options = ["--black-level", str(BLACK), "--saturation", str(SATURATION + BLACK)]
    assert cli.main([*base, str(tmp_path / "offset"), *options, "--out", str(offset)]) == 0
    first, second = store.load_model(plain), store.load_model(offset)
    np.testing.assert_allclose(np.asarray(second.filters), np.asarray(first.filters), rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(np.asarray(second.bias), np.asarray(first.bias), rtol=1e-5, atol=1e-7)
