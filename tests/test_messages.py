"""Messages for bad inputs: a CSV line past Python's field limit or an image name with a NUL byte
names the file and the line (a NUL byte in an argument is named too); an option's value or a
contradiction of options found after parsing exits 2 with the command's usage line;
``--data-dir`` must be a folder; a complex ``--sharpening`` array is refused by its dtype; an
output that appears during a folder run fails that image only."""

from __future__ import annotations

import csv
import warnings

import numpy as np
import pytest
from image_files import textured_image

from ccjax import cli
from ccjax.runs import folders

CAMERA = "Canon EOS 5D Mark II"
"""An embedded camera (``ccjax cameras --check`` needs one)."""


def _no_bug(err: str) -> None:
    assert "Traceback" not in err and "ccjax bug" not in err and "unexpected" not in err, err


def _error_line(err: str) -> str:
    """The one error line of stderr (usage lines aside), checked to be free of tracebacks."""
    _no_bug(err)
    lines = [line for line in err.strip().splitlines() if ": error: " in line]
    assert len(lines) == 1, err
    return lines[0]


def _truth_with(tmp_path, third_row: str):
    path = tmp_path / "truth.csv"
    path.write_text(f"image,r,g,b\na.png,1,1,1\n{third_row}\n", encoding="utf-8")
    return path


@pytest.mark.parametrize(
    ("row", "needle"),
    [
        # One past Python's csv.field_size_limit() (131,072 characters by default).
        ("b" * (csv.field_size_limit() + 1) + ".png,1,1,1", "longer than 131,072 characters"),
        ("b\0c.png,1,1,1", "NUL byte"),
    ],
    ids=["field-limit", "nul-byte"],
)
def test_a_bad_ground_truth_line_names_the_file_and_the_line(tmp_path, capsys, row, needle):
    truth = _truth_with(tmp_path, row)
    assert cli.main(["cameras", "--check", str(truth), "--camera", CAMERA]) == 2
    line = _error_line(capsys.readouterr().err)
    assert str(truth) in line and "line 3" in line and needle in line, line


def test_a_ground_truth_row_with_a_nul_byte_is_refused_by_the_folder_match(tmp_path):
    from ccjax.io import match_ground_truth

    with pytest.raises(ValueError, match="NUL byte") as refused:
        match_ground_truth({"a\0b.png": np.ones(3)}, tmp_path)
    assert str(tmp_path) in str(refused.value)


def test_a_nul_byte_in_an_argument_is_refused_with_the_usage_line(tmp_path, capsys):
    # Only an in-process call can pass one (process arguments are C strings).
    given = str(tmp_path / "gt\0.csv")
    with pytest.raises(SystemExit) as stop:
        cli.main(["cameras", "--check", given, "--camera", CAMERA])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and err.startswith("usage: ccjax cameras "), err
    line = _error_line(err)
    assert repr(given) in line and "NUL byte" in line and "embedded null byte" not in line, line


def test_a_calibration_line_past_the_field_limit_names_the_file_and_the_line(tmp_path, capsys):
    data = tmp_path / "measured.csv"
    data.write_text("# a comment\n" + "7" * (csv.field_size_limit() + 1) + "\n", encoding="utf-8")
    assert cli.main(["calibrate", str(data)]) == 2
    line = _error_line(capsys.readouterr().err)
    assert str(data) in line and "line 2" in line and "131,072" in line, line


def _folder(tmp_path, name="set"):
    folder = tmp_path / name
    folder.mkdir()
    return str(folder)


@pytest.mark.parametrize(
    ("argv", "command", "option"),
    [
        (["train", "--method", "FFCC"], "train", "train: give an image folder"),
        (["train", "{set}", "--method", "FFCC", "--world", "barnard1999"], "train", "--world: applies"),
        (["train", "{set}", "--method", "FFCC", "--pretrain-images", "64"], "train", "--pretrain-images: applies"),
        (["world", "--world", "barnard1999", "--camera", CAMERA], "world", "--camera: applies"),
        (
            ["evaluate", "{set}", "--ground-truth", "{set}/gt.csv", "--methods", "GW", "--pretrain-camera", CAMERA],
            "evaluate",
            "--pretrain-camera: applies to --train",
        ),
    ],
    ids=["train-no-folder", "train-world", "pretrain-images-alone", "world-camera", "evaluate-pretrain"],
)
def test_option_errors_found_after_parsing_exit_2_with_the_usage_line(tmp_path, capsys, argv, command, option):
    folder = _folder(tmp_path)
    assert cli.main([word.replace("{set}", folder) for word in argv]) == 2
    err = capsys.readouterr().err
    line = _error_line(err)
    assert err.startswith(f"usage: ccjax {command} "), err
    assert line.startswith(f"ccjax {command}: error: {option}"), line


def test_an_unknown_pretraining_camera_is_named_by_its_option(tmp_path, capsys):
    folder = _folder(tmp_path)
    assert cli.main(["train", folder, "--method", "FFCC", "--pretrain-camera", "No Such Camera 1"]) == 2
    line = _error_line(capsys.readouterr().err)
    assert line.startswith("ccjax train: error: --pretrain-camera: unknown camera 'No Such Camera 1';"), line


@pytest.mark.parametrize(("kind", "needle"), [("file", "is not a folder"), ("missing", "no such folder")])
@pytest.mark.parametrize("command", ["cameras", "calibrate", "reproduce"])
def test_data_dir_must_be_a_folder(tmp_path, capsys, kind, needle, command):
    given = tmp_path / kind
    if kind == "file":
        given.write_text("not a folder")
    with pytest.raises(SystemExit) as stop:
        cli.main([command, "--data-dir", str(given)])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and err.startswith(f"usage: ccjax {command} "), err
    line = _error_line(err)
    assert "argument --data-dir" in line and str(given) in line and needle in line, line


def test_a_complex_sharpening_array_is_refused_naming_its_dtype(plain_preview_commands, capsys):
    setup = plain_preview_commands
    image = textured_image(setup / "in.png")
    sharpening = setup / "complex.npy"
    np.save(sharpening, np.eye(3, dtype=np.complex128) * (1 + 1j))
    argv = ["correct", str(image), str(setup / "out.png"), "--method", "GW", "--sharpening", str(sharpening)]
    with warnings.catch_warnings():
        # The cast that drops the imaginary part warns with ComplexWarning: it must not be reached.
        warnings.simplefilter("error", np.exceptions.ComplexWarning)
        assert cli.main([*argv, "--no-progress"]) == 2
    line = _error_line(capsys.readouterr().err)
    assert "--sharpening" in line and str(sharpening) in line and "complex128" in line, line
    assert not (setup / "out.png").exists()


def test_an_output_that_appears_during_a_folder_run_fails_that_image_only(plain_preview_commands, monkeypatch, capsys):
    setup = plain_preview_commands
    source = setup / "in"
    source.mkdir()
    for name, colour in (("a", (0.5, 0.4, 0.3)), ("b", (0.3, 0.4, 0.5)), ("c", (0.4, 0.5, 0.3))):
        textured_image(source / f"{name}.png", colour)
    out = setup / "out"
    out.mkdir()
    real = folders.fitted

    def fitted_then_appear(*args, **kwargs):
        # Another process writes b's output after the command checked the outputs.
        (out / "b.png").write_bytes(b"someone else's file")
        return real(*args, **kwargs)

    monkeypatch.setattr(folders, "fitted", fitted_then_appear)
    assert cli.main(["correct", str(source), str(out), "--method", "GW", "--no-progress"]) == 2
    err = capsys.readouterr().err
    _no_bug(err)
    assert "1 of 3 images cannot be used:" in err, err
    (line,) = [line for line in err.splitlines() if "appeared while ccjax was working" in line]
    assert str(source / "b.png") in line and str(out / "b.png") in line, line
    assert (out / "b.png").read_bytes() == b"someone else's file"
    assert (out / "a.png").is_file() and (out / "c.png").is_file()  # the others were corrected
