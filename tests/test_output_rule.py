"""The one output rule of every command that writes (:mod:`ccjax.io.outputs`): outputs never name
an input or each other and are refused before any work, every input unchanged; a file that
appears after the check is never replaced without ``--overwrite``; never through a symbolic link."""

from __future__ import annotations

import os

import numpy as np
import pytest
from image_files import one_line_error

import ccjax.io
from ccjax import cli, io
from ccjax.calibration import _files as calibration_files
from ccjax.io import outputs, writing
from ccjax.runs import folders


@pytest.fixture
def setup(plain_preview_commands):
    return plain_preview_commands


def _image_set(folder):
    return io.write_dataset(
        folder, np.full((2, 4, 4, 3), 0.4) * [[[[1.0, 0.8, 0.6]]], [[[0.6, 0.8, 1.0]]]], np.ones((2, 3))
    )


def _snapshot(folder):
    return {path.name: path.read_bytes() for path in sorted(folder.iterdir()) if path.is_file()}


def _refused(capsys, *needles):
    one_line_error(capsys.readouterr(), *needles)


def _no_work(monkeypatch):
    def fail(*args, **kwargs):
        raise AssertionError("work started before the outputs were checked")

    monkeypatch.setattr(ccjax.io, "read_image", fail)
    monkeypatch.setattr(ccjax.io, "probe_image", fail)
    monkeypatch.setattr("ccjax.evaluation.evaluate_folder", fail)
    monkeypatch.setattr("ccjax.training.train_on_images", fail)
    monkeypatch.setattr("ccjax.experiments.sweep", fail)
    monkeypatch.setattr("ccjax.calibration.experiment.synthetic_experiment", fail)


@pytest.mark.parametrize("target", ["gt", "image"])
@pytest.mark.parametrize("option", ["--csv", "--json"])
def test_evaluate_refuses_a_report_that_names_an_input(setup, monkeypatch, capsys, option, target):
    gt = _image_set(setup / "set")
    before = _snapshot(setup / "set")
    named = {"gt": gt, "image": setup / "set" / "image-0000.png"}[target]
    _no_work(monkeypatch)
    argv = ["evaluate", str(setup / "set"), "--ground-truth", str(gt), "--methods", "GW", f"{option}={named}"]
    if named.suffix != "." + option[2:]:
        # A report's name ends in .json / .csv: the parser refuses any other before the check.
        with pytest.raises(SystemExit) as exit:
            cli.main([*argv, "--overwrite", "--no-progress"])
        assert exit.value.code == 2 and f"argument {option}:" in capsys.readouterr().err
    else:
        assert cli.main([*argv, "--overwrite", "--no-progress"]) == 2
        _refused(capsys, option, named, "would overwrite the input")
    assert _snapshot(setup / "set") == before


def test_evaluate_refuses_an_existing_report_without_overwrite(setup, monkeypatch, capsys):
    gt = _image_set(setup / "set")
    (setup / "r.csv").write_text("old")
    _no_work(monkeypatch)
    argv = ["evaluate", str(setup / "set"), "--ground-truth", str(gt), "--methods", "GW", "--csv", str(setup / "r.csv")]
    assert cli.main([*argv, "--no-progress"]) == 2
    _refused(capsys, "--csv", "exists (use --overwrite")
    assert (setup / "r.csv").read_text() == "old"


def test_train_refuses_an_out_that_names_an_input_before_training(setup, monkeypatch, capsys):
    _image_set(setup / "set")
    before = _snapshot(setup / "set")
    _no_work(monkeypatch)
    for out in (setup / "set" / "image-0000.png", setup / "set" / "groundtruth.csv"):
        argv = ["train", str(setup / "set"), "--method", "GW", "--out", str(out), "--overwrite"]
        assert cli.main([*argv, "--no-progress"]) == 2
        _refused(capsys, "--out", out, "would overwrite the input")
    assert _snapshot(setup / "set") == before


def test_train_refuses_an_out_whose_record_is_itself(setup, monkeypatch, capsys):
    _image_set(setup / "set")
    _no_work(monkeypatch)
    argv = ["train", str(setup / "set"), "--method", "GW", "--out", str(setup / "model.json"), "--no-progress"]
    assert cli.main(argv) == 2
    _refused(capsys, "--out", "are the same file")


def test_train_refuses_an_unwritable_out_folder_before_training(setup, monkeypatch, capsys):
    _image_set(setup / "set")
    (setup / "afile").write_text("x")
    _no_work(monkeypatch)
    argv = ["train", str(setup / "set"), "--method", "GW", "--out", str(setup / "afile" / "m.eqx"), "--no-progress"]
    assert cli.main(argv) == 2
    _refused(capsys, "--out", "is not a folder")


def test_calibrate_save_refuses_a_symbolic_link(setup, monkeypatch, capsys):
    target = setup / "precious.csv"
    target.write_text("keep me")
    (setup / "link.csv").symlink_to(target)
    _no_work(monkeypatch)
    for extra in ([], ["--overwrite"]):
        assert cli.main(["calibrate", "--synthetic", "--save", str(setup / "link.csv"), *extra]) == 2
        _refused(capsys, "--save", "symbolic link")
    assert target.read_text() == "keep me" and (setup / "link.csv").is_symlink()


def test_compare_refuses_one_file_for_json_and_csv(setup, monkeypatch, capsys):
    _no_work(monkeypatch)
    same = setup / "x.json"
    # One name cannot serve both: --csv's must end in .csv (the parser refuses it first).
    with pytest.raises(SystemExit) as exit:
        cli.main(["compare", "--json", str(same), f"--csv={same}", "--no-progress"])
    assert exit.value.code == 2 and "argument --csv:" in capsys.readouterr().err
    assert not same.exists()


def test_calibrate_sensors_csv_header_has_no_stray_space(tmp_path):
    calibration_files.write_sensors_csv(tmp_path / "s.csv", np.ones((101, 3)))
    assert (tmp_path / "s.csv").read_text().splitlines()[0] == "wavelength_nm,R,G,B"


# ---------------------------------------------------------------------------------------------
# putting in place


def test_put_in_place_never_replaces_without_overwrite(tmp_path):
    (tmp_path / "out.txt").write_text("appeared")
    (tmp_path / ".tmp").write_text("new")
    with pytest.raises(FileExistsError, match="appeared while ccjax was working"):
        outputs.put_in_place(tmp_path / ".tmp", tmp_path / "out.txt", overwrite=False)
    assert (tmp_path / "out.txt").read_text() == "appeared" and not (tmp_path / ".tmp").exists()
    (tmp_path / ".tmp").write_text("new")
    outputs.put_in_place(tmp_path / ".tmp", tmp_path / "out.txt", overwrite=True)
    assert (tmp_path / "out.txt").read_text() == "new" and not (tmp_path / ".tmp").exists()


def test_put_in_place_replaces_a_link_and_not_its_target(tmp_path):
    (tmp_path / "target").write_text("keep")
    (tmp_path / "link").symlink_to(tmp_path / "target")
    (tmp_path / ".tmp").write_text("new")
    with pytest.raises(FileExistsError):
        outputs.put_in_place(tmp_path / ".tmp", tmp_path / "link", overwrite=False)
    (tmp_path / ".tmp").write_text("new")
    outputs.put_in_place(tmp_path / ".tmp", tmp_path / "link", overwrite=True)
    assert (tmp_path / "target").read_text() == "keep" and not (tmp_path / "link").is_symlink()


def test_put_in_place_without_hard_links_checks_again(tmp_path, monkeypatch):
    def no_links(source, target):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "link", no_links)
    (tmp_path / ".tmp").write_text("new")
    outputs.put_in_place(tmp_path / ".tmp", tmp_path / "out", overwrite=False)
    assert (tmp_path / "out").read_text() == "new"
    (tmp_path / ".tmp").write_text("newer")
    with pytest.raises(FileExistsError):
        outputs.put_in_place(tmp_path / ".tmp", tmp_path / "out", overwrite=False)
    assert (tmp_path / "out").read_text() == "new"


def test_correct_keeps_an_output_that_appears_after_its_check(setup, monkeypatch, capsys):
    writing.write_linear(setup / "in.png", np.full((6, 6, 3), 0.4))
    real = folders.fitted

    def fitted_then_appear(*args, **kwargs):
        (setup / "out.png").write_bytes(b"someone else's file")
        return real(*args, **kwargs)

    monkeypatch.setattr(folders, "fitted", fitted_then_appear)
    assert cli.main(["correct", str(setup / "in.png"), str(setup / "out.png"), "--method", "GW", "--no-progress"]) == 2
    _refused(capsys, "out.png", "appeared while ccjax was working")
    assert (setup / "out.png").read_bytes() == b"someone else's file"
    assert sorted(path.name for path in setup.iterdir() if path.name.startswith((".out", "out"))) == ["out.png"]


def test_a_full_disk_names_the_file_and_leaves_no_output_without_its_preview(setup, monkeypatch, capsys):
    writing.write_linear(setup / "in.png", np.full((6, 6, 3), 0.4))
    # The preview's bytes do not fit on the disk (the error has no file name, as ENOSPC from write()).
    monkeypatch.setattr("builtins.open", _full_disk_open(setup / "out_tif_preview.png"))
    assert cli.main(["correct", str(setup / "in.png"), str(setup / "out.tif"), "--method", "GW", "--no-progress"]) == 2
    _refused(capsys, "No space left on device", "out_tif_preview.png")
    assert not (setup / "out.tif").exists() and not (setup / "out_tif_preview.png").exists()


def _full_disk_open(victim):
    real = open

    class Full:
        def __init__(self, handle):
            self.handle = handle

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.handle.close()
            return False

        def write(self, blob):
            raise OSError(28, "No space left on device")

    def opened(file, mode="r", *args, **kwargs):
        handle = real(file, mode, *args, **kwargs)
        return Full(handle) if "w" in mode and os.path.basename(str(file)).startswith(f".{victim.name}.") else handle

    return opened
