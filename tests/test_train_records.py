"""``ccjax train``'s model records: strict JSON, naming only what was used (the camera only when
given or used, FFCC's own solver instead of Adam's schedule), and a help that gives each family's
real defaults."""

from __future__ import annotations

import json
import re

import jax
import numpy as np
import pytest

from ccjax import cli, io, training
from ccjax.scenes import sample_mondrians
from ccjax.world import World

DEFAULT_CAMERA = "Canon EOS 5D Mark II"


def strict_json(text: str):
    """``json.loads`` that refuses NaN, Infinity and -Infinity (Python's parser accepts them; JSON
    does not, RFC 8259 §6)."""

    def refuse(constant):
        raise ValueError(f"not JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    root = tmp_path_factory.mktemp("train")
    images = sample_mondrians(jax.random.key(3), World.default(), 6, height=48, width=48)
    io.write_dataset(root / "set", images.image, images.illuminant)
    return root


def _train(folder, name, *options, capsys):
    out = folder / f"{name}.eqx"
    argv = ["train", str(folder / "set"), "--out", str(out), "--overwrite", "--no-progress", *options]
    assert cli.main(argv) == 0
    first = capsys.readouterr().err.splitlines()[0]
    return strict_json(out.with_suffix(".json").read_text()), first


@pytest.mark.slow  # about 25 s on 2 shared cores: FFCC's choice of settings compiles seven fits
def test_ffcc_records_no_camera_and_its_own_solver_not_adams_schedule(folder, capsys):
    record, first = _train(folder, "ffcc", "--method", "FFCC", capsys=capsys)
    assert record["camera"] is None and "camera" not in first and "spectral fit" not in first
    assert record["procedure"].startswith("FFCC: L-BFGS") and "schedule" not in record
    assert set(record["log"]) == {"train_loss", "seconds", "cpu_seconds", "n_train"}
    assert record["log"]["n_train"] == 6


def test_an_adam_family_records_its_schedule_and_a_given_camera(folder, capsys):
    record, first = _train(
        folder, "edge", "--method", "grey-edge-1-6-2", "--epochs", "2", "--camera", "Nikon D5100", capsys=capsys
    )
    assert record["camera"] == "Nikon D5100" and "uses no camera's curves" in first
    assert record["procedure"] == "Adam" and record["schedule"]["epochs"] == 2
    assert np.isfinite(record["log"]["initial_median"]) and record["log"]["n_heldout"] >= 1
    record, first = _train(folder, "edge", "--method", "grey-edge-1-6-2", "--epochs", "1", capsys=capsys)
    assert record["camera"] is None and "camera" not in first


def test_a_world_based_family_needs_the_camera_and_records_it(folder, capsys):
    """Without --camera a world-based family is refused before any work, as ``estimate`` refuses it
    (it would be bound to the default camera and then refuse the right one); given, it is recorded."""
    out = folder / "cbc-nocamera.eqx"
    argv = ["train", str(folder / "set"), "--method", "C-by-C-MMSE", "--epochs", "1", "--out", str(out)]
    assert cli.main([*argv, "--no-progress"]) == 2
    assert "--camera: C-by-C-MMSE is fitted to a world seen through a camera's curves" in capsys.readouterr().err
    assert not out.exists() and not out.with_suffix(".json").exists()
    record, first = _train(
        folder, "cbc", "--method", "C-by-C-MMSE", "--epochs", "1", "--camera", DEFAULT_CAMERA, capsys=capsys
    )
    assert record["camera"] == DEFAULT_CAMERA and f"camera {DEFAULT_CAMERA}; start: its spectral fit" in first


def test_adam_options_for_ffcc_are_refused(folder, capsys):
    argv = ["train", str(folder / "set"), "--method", "FFCC", "--epochs", "5", "--learning-rate", "0.1"]
    assert cli.main([*argv, "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        "ccjax train: error: --epochs, --learning-rate: FFCC trains by its own L-BFGS fit, with no epochs, batches "
        "or steps"
    )


def test_the_help_gives_each_familys_real_defaults(capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "400")  # argparse wraps at hyphens: "log-" / "chroma-mlp" on a narrow terminal
    with pytest.raises(SystemExit):
        cli.main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "FFCC" in text and "log-chroma-mlp" in text
    adam, mlp = training.Schedule(), training.LOG_CHROMA_SCHEDULE
    for option, name in (("--epochs", "epochs"), ("--learning-rate", "learning_rate"), ("--patience", "patience")):
        match = re.search(
            re.escape(option) + r" \S+ Adam: [^(]*\(default: ([\d.]+); log-chroma-mlp: ([\d.]+); not FFCC\)", text
        )
        assert match, option
        assert float(match[1]) == getattr(adam, name) and float(match[2]) == getattr(mlp, name), option
    match = re.search(r"--batch-size \S+ Adam: images per step \(default: (\d+);", text)
    assert match and int(match[1]) == adam.batch_size
