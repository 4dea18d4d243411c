"""Numbers in options and CSV cells are parsed strictly: Python's ``float``/``int`` read ``0_8`` as
8.0 (a ground truth's 0_8 moved grey world's mean error from 2.63 to 12.48 degrees), ``6_4224`` as a
saturation of 64224, and take ``nan``, ``inf`` and hexadecimal-looking text; ccjax refuses each,
naming the option, or the file and line."""

from __future__ import annotations

import numpy as np
import pytest

from ccjax import cli, io
from ccjax._numbers import decimal, whole


@pytest.mark.parametrize("text", ["0.8", "-5", "1e-3", ".5", "5.", " 2.5 ", "+3", "1E+2"])
def test_plain_decimals_are_read_as_python_reads_them(text):
    assert decimal(text) == float(text)


@pytest.mark.parametrize("text", ["0_8", "6_4224", "nan", "inf", "-Infinity", "0x10", "1e999", "", "1,5", "٣"])
def test_anything_else_is_not_a_decimal(text):
    with pytest.raises(ValueError):
        decimal(text)


@pytest.mark.parametrize("text", ["1_0", "3.0", "0x10", "", "1e3", "٣"])
def test_whole_numbers_are_digits_only(text):
    with pytest.raises(ValueError):
        whole(text)
    assert whole(" 42 ") == 42 and whole("-1") == -1


@pytest.fixture
def folder(tmp_path):
    rng = np.random.default_rng(1)
    for name in ("a.png", "b.png"):
        io.write_png(tmp_path / name, np.round(rng.uniform(0.1, 0.5, (8, 8, 3)) * 65535).astype(np.uint16))
    return tmp_path


def test_a_ground_truth_value_with_an_underscore_is_refused_naming_file_and_line(folder, capsys):
    (folder / "gt.csv").write_text("image,r,g,b\na.png,1,0.7,0.4\nb.png,1,0_8,0.4\n")
    argv = ["evaluate", str(folder), "--ground-truth", str(folder / "gt.csv"), "--methods", "GW", "--no-progress"]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert "gt.csv line 3: r,g,b must be decimal numbers" in err and "0_8" in err


def test_a_fold_with_an_underscore_is_refused(folder, capsys):
    (folder / "gt.csv").write_text("image,r,g,b,fold\na.png,1,0.7,0.4,0\nb.png,1,0.8,0.4,1_0\n")
    argv = ["evaluate", str(folder), "--ground-truth", str(folder / "gt.csv"), "--methods", "GW", "--folds", "2"]
    assert cli.main([*argv, "--no-progress"]) == 2
    assert "line 3: fold must be an integer" in capsys.readouterr().err


@pytest.mark.parametrize("option, value", [("--saturation", "6_4224"), ("--black-level", "nan"), ("--seed", "1_0")])
def test_an_option_with_a_loose_number_is_refused_with_the_usage(folder, option, value, capsys):
    with pytest.raises(SystemExit) as stop:
        cli.main(["estimate", str(folder / "a.png"), "--method", "GW", option, value])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and err.startswith("usage: ccjax estimate") and f"argument {option}" in err


def test_a_negative_black_level_is_refused_with_the_usage(folder, capsys):
    with pytest.raises(SystemExit) as stop:
        cli.main(["estimate", str(folder / "a.png"), "--method", "GW", "--black-level", "-5"])
    assert stop.value.code == 2 and "argument --black-level: expected a level at or above 0" in capsys.readouterr().err


def test_options_that_contradict_or_do_not_apply_are_refused(folder, capsys):
    argv = ["estimate", str(folder / "a.png"), "--method", "GW", "--assume-linear", "--decode-srgb", "--no-progress"]
    assert cli.main(argv) == 2
    assert "--assume-linear, --decode-srgb: give one" in capsys.readouterr().err
    (folder / "groundtruth.csv").write_text("image,r,g,b\na.png,1,0.7,0.4\nb.png,1,0.8,0.4\n")
    assert cli.main(["train", str(folder), "--method", "grey-edge-1-6-2", "--steps", "5", "--no-progress"]) == 2
    assert "--steps: applies to the nets' synthetic training" in capsys.readouterr().err


def test_csv_report_text_cells_that_a_spreadsheet_would_run_are_neutralised(tmp_path, capsys):
    """An image named ``=1+2.png`` and ``@SUM(A1).png``: evaluate's CSV writes those names with a
    leading ``'`` (spreadsheets show them as text instead of evaluating them), the other cells
    unchanged and numbers as numbers."""
    import csv

    rng = np.random.default_rng(2)
    names = ["=1+2.png", "@SUM(A1).png", "plain.png"]
    for name in names:
        io.write_png(tmp_path / name, np.round(rng.uniform(0.1, 0.5, (8, 8, 3)) * 65535).astype(np.uint16))
    (tmp_path / "gt.csv").write_text("image,r,g,b\n" + "".join(f"{name},1,0.7,0.4\n" for name in names))
    argv = ["evaluate", str(tmp_path), "--ground-truth", str(tmp_path / "gt.csv"), "--methods", "GW"]
    assert cli.main([*argv, "--csv", str(tmp_path / "out.csv"), "--no-progress"]) == 0
    with open(tmp_path / "out.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    paths = sorted(row["path"].rsplit("/", 1)[-1] for row in rows)
    assert paths == sorted(names)  # the folder prefix: the path cell starts with "/", not a formula
    assert all(float(row["angular"]) >= 0 for row in rows)
    from ccjax.io.files import csv_text_cell

    assert [csv_text_cell(v) for v in ["=1+2", "+x", "-x", "@x", "x", -5.0]] == [
        "'=1+2",
        "'+x",
        "'-x",
        "'@x",
        "x",
        -5.0,
    ]
