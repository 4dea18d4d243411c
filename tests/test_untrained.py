"""A learned method ccjax ships no trained parameters for (FFCC, the log-chroma MLP, any-camera) is
refused at estimation, by the API and by every command that would answer with its initial
parameters, naming how to train it; fitting it stays allowed (training starts there). And an image
on the wrong scale is refused by the API as by the command line, not answered with the fallback."""

from __future__ import annotations

import numpy as np
import pytest

import ccjax
from ccjax import cli, io

UNTRAINED = ["FFCC", "log-chroma-mlp", "any-camera"]


@pytest.fixture(scope="module")
def photo(tmp_path_factory):
    """A 16-bit linear photograph of smooth coloured surfaces under a warm light."""
    folder = tmp_path_factory.mktemp("untrained")
    rng = np.random.default_rng(3)
    albedo = rng.uniform(0.1, 0.9, (6, 8, 3)).repeat(6, 0).repeat(6, 1)
    codes = np.round(0.5 * albedo * np.array([1.0, 0.75, 0.45]) * 65535).astype(np.uint16)
    io.write_png(folder / "photo.png", codes)
    return folder


@pytest.mark.parametrize("label", UNTRAINED)
def test_the_api_refuses_an_untrained_label_and_says_how_to_train_it(label, photo):
    image = io.read_image(photo / "photo.png").rgb
    with pytest.raises(ValueError, match=rf"method: {label} is learned .*ccjax train --method {label}") as error:
        ccjax.estimate(label, image)
    assert "ccjax.load_model" in str(error.value)


def test_fitting_an_untrained_label_stays_allowed():
    model = ccjax.fit("FFCC", ccjax.World.default())
    assert type(model).__name__ == "FFCC"


@pytest.mark.parametrize("command", ["estimate", "correct"])
@pytest.mark.parametrize("label", UNTRAINED)
def test_estimate_and_correct_refuse_an_untrained_method_before_any_output(command, label, photo, capsys):
    output = photo / f"{command}-{label}.png"
    argv = [command, str(photo / "photo.png"), *([str(output)] if command == "correct" else [])]
    assert cli.main([*argv, "--method", label, "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert f"--method: {label} is learned from labelled photographs" in err and "--model" in err
    assert not output.exists()


def test_evaluate_refuses_an_untrained_method_unless_it_is_trained_in_the_folds(photo, capsys):
    (photo / "groundtruth.csv").write_text("image,r,g,b\nphoto.png,1.0,0.75,0.45\n")
    argv = ["evaluate", str(photo), "--ground-truth", str(photo / "groundtruth.csv"), "--no-progress"]
    assert cli.main([*argv, "--methods", "GW,FFCC"]) == 2
    assert "--methods: FFCC is learned" in capsys.readouterr().err


def test_compare_refuses_an_untrained_surface_method(capsys):
    assert cli.main(["compare", "--methods", "GW,log-chroma-mlp", "--scenes", "10", "--no-progress"]) == 2
    assert "--methods: log-chroma-mlp is learned" in capsys.readouterr().err


def test_every_untrained_family_is_flagged_and_no_other():
    from ccjax.estimators import registry

    flagged = sorted(entry.example for entry in registry.available() if entry.untrained)
    assert flagged == sorted(UNTRAINED)


def test_an_image_on_its_files_scale_is_refused_by_the_api_as_by_the_command_line(tmp_path, capsys):
    """Float data in 0..65535 (every pixel above the unit scale's clip level 0.98): the API says so
    as reading a float TIFF of the same values does, where it used to answer with the fallback."""
    import tifffile

    values = np.full((8, 8, 3), 30000.0, np.float32)
    values[::2] = 12000.0
    with pytest.raises(ValueError, match=r"every pixel of the image is clipped .*saturation=0.98"):
        ccjax.estimate("GW", values)
    tifffile.imwrite(tmp_path / "float.tif", values, photometric="rgb")
    assert cli.main(["estimate", str(tmp_path / "float.tif"), "--method", "GW", "--no-progress"]) == 2
    assert "every pixel of" in capsys.readouterr().err
    # The same data on the unit scale is estimated.
    assert bool(ccjax.estimate("GW", values / 65535).ok)
