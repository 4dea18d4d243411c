"""For ``calibrate``, ``sharpen`` and ``indexing``, output paths (``--plot``,
``--save``, ``--robustness``, ``--json``) are checked before any work; and every plot is written
atomically (a temporary file in the same folder renamed into place)."""

from __future__ import annotations

import io
import os

import numpy as np
import pytest
from image_files import one_line_error
from small_world import small_world

from ccjax import cli
from ccjax.calibration import _files as files
from ccjax.calibration import experiment, plots
from ccjax.calibration.robustness import Robustness
from ccjax.cli import indexing, sharpen
from ccjax.experiments import plots as experiment_plots
from ccjax.io import files as io_files

PNG = b"\x89PNG\r\n\x1a\n"


_one_line_error = one_line_error


def _no_work(monkeypatch):
    """Any of the commands' first steps fails the test: the check must come before them."""

    def work(*args, **kwargs):
        pytest.fail("work started before the output paths were checked")

    monkeypatch.setattr(experiment, "synthetic_experiment", work)
    monkeypatch.setattr(files, "read_calibration_csv", work)
    monkeypatch.setattr(sharpen, "build_world", work)
    monkeypatch.setattr(indexing, "image_world", work)


def _bad_targets(tmp_path):
    (tmp_path / "afile").write_text("x")
    return {
        "a folder": (tmp_path, "is a folder"),
        "under a file": (tmp_path / "afile" / "p.png", "not a folder"),
        "no png suffix": (tmp_path / "p.txt", ".png"),
    }


@pytest.mark.parametrize("problem", ["a folder", "under a file", "no png suffix"])
@pytest.mark.parametrize("option", ["--plot", "--robustness"])
def test_calibrate_plot_paths_are_checked_first(tmp_path, monkeypatch, capsys, problem, option):
    target, message = _bad_targets(tmp_path)[problem]
    _no_work(monkeypatch)
    assert cli.main(["calibrate", "--synthetic", option, str(target)]) == 2
    _one_line_error(capsys.readouterr(), option, target, message)


def test_calibrate_save_path_and_clashes_are_checked_first(tmp_path, monkeypatch, capsys):
    data = tmp_path / "data.csv"
    data.write_text("380\n")
    _no_work(monkeypatch)
    assert cli.main(["calibrate", str(data), "--save", str(tmp_path)]) == 2
    _one_line_error(capsys.readouterr(), "--save", "is a folder")
    assert cli.main(["calibrate", str(data), "--save", str(data)]) == 2
    _one_line_error(capsys.readouterr(), "--save", "would overwrite the input", data)
    plot = tmp_path / "p.png"
    assert cli.main(["calibrate", str(data), "--plot", str(plot), "--robustness", str(plot)]) == 2
    _one_line_error(capsys.readouterr(), "--robustness", "same file")
    # The robustness numbers go beside the plot, as r.json: a --save of that name would be replaced.
    argv = ["calibrate", str(data), "--robustness", str(tmp_path / "r.png"), "--save", str(tmp_path / "r.json")]
    assert cli.main(argv) == 2
    _one_line_error(capsys.readouterr(), "r.json", "same file")
    assert data.read_text() == "380\n" and sorted(p.name for p in tmp_path.iterdir()) == ["data.csv"]


@pytest.mark.parametrize("problem", ["a folder", "under a file", "no png suffix"])
def test_sharpen_plot_is_checked_first(tmp_path, monkeypatch, capsys, problem):
    target, message = _bad_targets(tmp_path)[problem]
    _no_work(monkeypatch)
    assert cli.main(["sharpen", "--plot", str(target)]) == 2
    _one_line_error(capsys.readouterr(), "--plot", target, message)


def test_sharpen_refuses_a_plot_it_would_not_write(tmp_path, monkeypatch, capsys):
    _no_work(monkeypatch)
    monkeypatch.setattr(sharpen, "run_rank_cameras", lambda args: pytest.fail("ran"))
    assert cli.main(["sharpen", "--rank-cameras", "--plot", str(tmp_path / "p.png")]) == 2
    _one_line_error(capsys.readouterr(), "--plot", "--rank-cameras")


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--json", "{tmp}/folder.json"], "is a folder"),
        (["--json", "{tmp}/afile/r.json"], "not a folder"),
        (["--methods", "GW,GWW"], "'GWW'"),
        (["--preprocessing", "ave5-nonsense"], "nonsense"),
    ],
)
def test_indexing_checks_everything_first(tmp_path, monkeypatch, capsys, argv, needle):
    (tmp_path / "afile").write_text("x")
    (tmp_path / "folder.json").mkdir()
    _no_work(monkeypatch)
    assert cli.main(["indexing", "--no-progress", *[a.format(tmp=tmp_path) for a in argv]]) == 2
    _one_line_error(capsys.readouterr(), needle)


def test_indexing_objects_outside_the_limits_are_refused_by_the_parser(tmp_path, monkeypatch, capsys):
    """``--objects`` is bounded by the limits table: argparse refuses 0 (exit 2, naming the option
    and the range) before any work."""
    _no_work(monkeypatch)
    with pytest.raises(SystemExit) as stopped:
        cli.main(["indexing", "--no-progress", "--objects", "0"])
    assert stopped.value.code == 2
    error = capsys.readouterr().err
    assert "Traceback" not in error and "argument --objects: expected an integer in [1, 10000], got 0" in error


# ---------------------------------------------------------------------------------------------
# Atomic plots


def _interrupt_replace(monkeypatch):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", interrupted)


def _robustness():
    errors = {label: np.full((2, 3), 0.1 * (k + 1)) for k, label in enumerate(("joint", "pseudo-inverse"))}
    return Robustness(sizes=(50, 25), n_subsets=3, errors=errors, converged={label: 1.0 for label in errors})


def _figure():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure = plt.figure(figsize=(2, 2))
    figure.gca().plot([0, 1], [1, 0])
    return figure


@pytest.mark.parametrize("draw", ["write_figure", "plot_world", "plot_robustness"])
def test_interrupted_plot_keeps_the_old_file_and_leaves_no_temporary(tmp_path, monkeypatch, draw):
    path = tmp_path / "p.png"
    path.write_bytes(b"old plot")
    write = {
        "write_figure": lambda: io_files.write_figure(_figure(), path, dpi=50),
        "plot_world": lambda: experiment_plots.plot_world(small_world(), path),
        "plot_robustness": lambda: plots.plot_robustness(_robustness(), path),
    }[draw]
    with monkeypatch.context() as patch:
        _interrupt_replace(patch)
        with pytest.raises(KeyboardInterrupt):
            write()
    assert path.read_bytes() == b"old plot" and [p.name for p in tmp_path.iterdir()] == ["p.png"]
    write()
    assert path.read_bytes().startswith(PNG) and [p.name for p in tmp_path.iterdir()] == ["p.png"]


def test_write_figure_takes_the_format_from_the_suffix_or_a_file_object(tmp_path):
    io_files.write_figure(_figure(), tmp_path / "p.svg")
    assert b"<svg" in (tmp_path / "p.svg").read_bytes()[:500]
    io_files.write_figure(_figure(), tmp_path / "p.PDF")
    assert (tmp_path / "p.PDF").read_bytes().startswith(b"%PDF")
    buffer = io.BytesIO()
    io_files.write_figure(_figure(), buffer)
    assert buffer.getvalue().startswith(PNG)
    with pytest.raises(ValueError, match="no suffix"):
        io_files.write_figure(_figure(), tmp_path / "p")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.PDF", "p.svg"]
