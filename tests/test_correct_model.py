"""``ccjax correct --model``: the trained model's light (the one ``estimate --model`` prints)
corrects the image; a ``--camera`` that is not the model's is refused; JPEG output for
``--srgb 8``; a single output's missing folder is created; the line says what the output is."""

from __future__ import annotations

import json

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

from ccjax import cli, io
from ccjax.runs import store

CAMERA = "Canon EOS 5D Mark II"
OTHER = "Nikon D5100"


@pytest.fixture
def setup(tmp_path):
    """A 16-bit photograph of smooth surfaces under a warm light, and a trained model file: grey
    edge with its Minkowski norm moved from 6 to 2 (as training would move it), recorded for
    ``CAMERA``; and the same model recorded with no camera."""
    rng = np.random.default_rng(5)
    from scipy import ndimage

    albedo = ndimage.gaussian_filter(rng.uniform(0.1, 1.0, (48, 64, 3)), (2, 2, 0))
    image = 0.6 * albedo * np.array([1.0, 0.7, 0.4])
    io.write_png(tmp_path / "photo.png", np.round(image * 65535).astype(np.uint16))
    model = store.fit("grey-edge-1-6-2", store.world("default", CAMERA))
    model = eqx.tree_at(lambda m: m.p, model, jnp.asarray(2.0, model.p.dtype))
    store.save_trained(tmp_path / "edge.eqx", model, label="grey-edge-1-6-2", camera=CAMERA)
    store.save_trained(tmp_path / "any.eqx", model, label="grey-edge-1-6-2", camera=None)
    return tmp_path


def _estimate(argv, capsys) -> np.ndarray:
    assert cli.main([*argv, "--json", "--no-progress"]) == 0
    return np.array(json.loads(capsys.readouterr().out)[0]["illuminant"])


def test_correct_with_a_model_applies_the_light_estimate_prints(setup, capsys):
    """The corrected file's per-pixel gains (output / input codes) point along canonical white /
    the light ``estimate --model`` prints (a diagonal map), not along the label's untrained light."""
    light = _estimate(["estimate", str(setup / "photo.png"), "--model", str(setup / "edge.eqx")], capsys)
    untrained = _estimate(["estimate", str(setup / "photo.png"), "--method", "grey-edge-1-6-2"], capsys)
    assert np.degrees(np.arccos(light @ untrained / np.linalg.norm(light) / np.linalg.norm(untrained))) > 0.3
    out = setup / "new" / "folder" / "photo.png"  # the folder does not exist: it is created
    argv = ["correct", str(setup / "photo.png"), str(out), "--model", str(setup / "edge.eqx"), "--no-progress"]
    assert cli.main(argv) == 0
    printed = capsys.readouterr().out
    assert "(linear 16-bit camera RGB under the canonical light)" in printed and "(sRGB preview)" in printed
    assert f"light [{', '.join(f'{v:.5f}' for v in light)}] (estimated)" in printed
    before = io.read_png(setup / "photo.png").astype(np.float64)
    after = io.read_png(out).astype(np.float64)
    usable = np.all(before > 2000, axis=-1) & np.all(after < 65000, axis=-1)
    gains = np.median(after[usable] / before[usable], axis=0)
    canonical = np.asarray(store.world("default", CAMERA).canonical_white, np.float64)
    want = canonical / light
    cosine = gains @ want / np.linalg.norm(gains) / np.linalg.norm(want)
    assert np.degrees(np.arccos(min(cosine, 1.0))) < 0.05


def test_jpeg_output_for_srgb_8_matches_the_png(setup, capsys):
    base = ["correct", str(setup / "photo.png")]
    model = ["--model", str(setup / "edge.eqx"), "--srgb", "8", "--no-progress"]
    assert cli.main([*base, str(setup / "a.jpg"), *model]) == 0
    assert "(8-bit sRGB)" in capsys.readouterr().out
    assert cli.main([*base, str(setup / "a.png"), *model, "--preview", str(setup / "p.png")]) == 0
    assert (setup / "a.jpg").read_bytes()[:3] == b"\xff\xd8\xff"
    jpeg = io.read_image(setup / "a.jpg", assume_linear=True)  # the codes, undecoded
    png = io.read_image(setup / "a.png", assume_linear=True)
    assert jpeg.rgb.shape == png.rgb.shape == (48, 64, 3)
    assert float(np.mean(np.abs(jpeg.rgb - png.rgb))) * 255 < 2.0
    assert cli.main([*base, str(setup / "b.jpg"), "--method", "GW", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert f"output: {setup / 'b.jpg'} is a JPEG" in err and "give --srgb 8" in err


@pytest.mark.parametrize("command", ["estimate", "correct"])
def test_a_camera_other_than_the_models_is_one_line_naming_both(setup, capsys, command):
    tail = [str(setup / "out.png")] if command == "correct" else []
    argv = [command, str(setup / "photo.png"), *tail, "--model", str(setup / "edge.eqx"), "--no-progress"]
    assert cli.main([*argv, "--camera", OTHER]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"ccjax {command}: error: --camera: ")
    assert f"{OTHER!r} is not the camera of the model" in err and CAMERA in err
    assert not (setup / "out.png").exists()
    assert cli.main([*argv, "--camera", CAMERA]) == 0  # the model's own camera is accepted
    capsys.readouterr()
    any_camera = [a if a != str(setup / "edge.eqx") else str(setup / "any.eqx") for a in argv]
    extra = ["--overwrite"] if command == "correct" else []
    assert cli.main([*any_camera, "--camera", OTHER, *extra]) == 0  # a model with no camera takes any
