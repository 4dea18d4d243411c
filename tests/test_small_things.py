"""Small things users notice: ``ccjax --version``, progress bars that count what is done, numbers
printed with the digits that matter, close camera names, the external-data cameras listed, methods
told apart in ``compare.png``, and a warning for training sets too small to learn from."""

from __future__ import annotations

import re

import numpy as np
import pytest

import ccjax
from ccjax import cli, io

CAMERA = "Canon EOS 5D Mark II"


def test_version(capsys):
    with pytest.raises(SystemExit) as stop:
        cli.main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out.strip() == f"ccjax {ccjax.__version__}"


def test_the_fit_bar_counts_the_fits_done(capsys, default_world):
    """The bar names the method being fitted with the count of those already fitted (it stayed at
    0 of N while naming each method)."""
    from ccjax.experiments import resolve_methods

    resolve_methods(default_world, ["GW", "RETINEX", "DB-GW"], progress=True)
    err = capsys.readouterr().err
    assert re.search(r"fit: +33%.*1/3 .*RETINEX", err) and re.search(r"fit: +67%.*2/3 .*DB-GW", err), err


def test_corrects_bar_reaches_n_of_n_once_after_the_last_line(tmp_path, capsys):
    rng = np.random.default_rng(0)
    for index in range(3):
        io.write_png(tmp_path / f"in/{index}.png", io.quantise(rng.uniform(0.1, 0.8, (16, 16, 3))))
    assert cli.main(["correct", str(tmp_path / "in"), str(tmp_path / "out"), "--method", "GW"]) == 0
    captured = capsys.readouterr()
    assert captured.err.count("3/3") == 1 and "0/3" in captured.err
    assert len(captured.out.strip().splitlines()) == 3


@pytest.mark.slow
def test_world_and_sharpen_print_the_digits_that_matter(capsys):
    assert cli.main(["world"]) == 0
    out = capsys.readouterr().out
    white = np.asarray(ccjax.World.default().canonical_white, np.float64)
    assert f"canonical white RGB   [{', '.join(f'{v:.4f}' for v in white)}]" in out
    assert cli.main(["sharpen", "--scenes", "20"]) == 0
    out = capsys.readouterr().out
    assert "tried lambda_P" in out and not re.search(r"\.\d{9,}", out), out  # no float64 noise


def test_an_unknown_camera_suggests_the_close_names(capsys):
    assert cli.main(["compare", "--camera", "Nikon D510", "--scenes", "5", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "unknown name 'Nikon D510'. Did you mean 'Nikon D5100'" in err and "ARRI" not in err


def test_the_listing_names_the_cameras_that_need_external_data(tmp_path):
    from ccjax.experiments import camera_listing

    rows = {row["camera"]: row["source"] for row in camera_listing(tmp_path).rows}  # no data there
    assert CAMERA in rows
    for name in ("Sony DXC-930", "Jiang: <model>"):
        assert "needs the external data, not found (--data-dir or $CCJAX_DATA)" in rows[name]


def test_every_method_of_compare_png_has_its_own_colour_and_marker():
    from ccjax.cli.synthetic import DEFAULT_COMPARE_METHODS
    from ccjax.experiments.plots import method_styles

    styles = dict(zip(DEFAULT_COMPARE_METHODS, method_styles(len(DEFAULT_COMPARE_METHODS)), strict=True))
    assert styles["DB-GW"]["marker"] != styles["ND-ECRULE-MV"]["marker"]
    many = method_styles(30)
    assert len({(s["color"], s["marker"], s["linestyle"]) for s in many}) == 30


def test_training_on_few_images_warns_naming_the_size(tmp_path, capsys, monkeypatch):
    from ccjax import training

    rng = np.random.default_rng(1)
    lights = {}
    for index in range(6):
        io.write_png(tmp_path / f"set/{index}.png", io.quantise(rng.uniform(0.1, 0.8, (16, 16, 3))))
        lights[f"{index}.png"] = [1.0, 1.0, 1.0]
    (tmp_path / "set" / "groundtruth.csv").write_text("image,r,g,b\n" + "".join(f"{name},1,1,1\n" for name in lights))

    def stop(*args, **kwargs):
        raise ValueError("stopped before training")

    monkeypatch.setattr(training, "train_on_images", stop)
    assert cli.main(["train", str(tmp_path / "set"), "--method", "FFCC", "--folds", "3", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert (
        "ccjax train: warning: FFCC trains on 4 per fold images, fewer than 50: a model learned from so few "
        "photographs is unreliable" in err
    )
    assert cli.main(["train", str(tmp_path / "set"), "--method", "C-by-C-MMSE", "--no-progress"]) == 2
    assert "warning" not in capsys.readouterr().err  # a start from the camera's physics
    with pytest.raises(SystemExit):
        cli.main(["train", "--help"])
    assert "with fewer than 50 training images (per fold with --folds) a warning" in " ".join(
        capsys.readouterr().out.split()
    )
