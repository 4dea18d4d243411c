"""``ccjax evaluate``'s machine-readable outputs: with ``--json -`` or ``--csv -`` standard output
holds only the data (a script parses it), the tables go to standard error; and its ``--plot``
names every method in both panels and each image under its errors."""

from __future__ import annotations

import csv
import io as text_io
import json

import jax
import numpy as np
import pytest

from ccjax import cli, io, scenes
from ccjax.evaluation import ImageResults
from ccjax.experiments.plots import plot_image_errors


@pytest.fixture
def folder(small_world_commands, small_test_world):
    batch = scenes.sample_mondrians(jax.random.key(5), small_test_world, 6, height=12, width=12, n_patches=4)
    io.write_dataset(small_world_commands / "set", np.asarray(batch.image), np.asarray(batch.illuminant))
    return small_world_commands / "set"


def _argv(folder, *extra):
    gt = str(folder / "groundtruth.csv")
    return ["evaluate", str(folder), "--ground-truth", gt, "--methods", "GW,shades-of-grey-p6", "--no-progress", *extra]


def test_json_to_standard_output_is_only_the_data(folder, capsys):
    assert cli.main(_argv(folder, "--json", "-")) == 0
    captured = capsys.readouterr()
    report = json.loads(captured.out)  # fails at char 0 when a table comes first
    assert set(report["summary"]) == {"GW", "shades-of-grey-p6"} and len(report["images"]) == 12
    assert "angular error (degrees)" in captured.err


def test_csv_to_standard_output_is_only_the_data(folder, capsys):
    assert cli.main(_argv(folder, "--csv", "-")) == 0
    captured = capsys.readouterr()
    rows = list(csv.DictReader(text_io.StringIO(captured.out)))
    assert len(rows) == 12 and {row["method"] for row in rows} == {"GW", "shades-of-grey-p6"}
    assert all(float(row["angular"]) >= 0 for row in rows)


def test_json_and_csv_cannot_share_standard_output(folder, capsys):
    assert cli.main(_argv(folder, "--json", "-", "--csv", "-")) == 2
    assert "--json, --csv" in capsys.readouterr().err


def test_the_error_plot_has_a_legend_in_both_panels_and_names_the_images(tmp_path, monkeypatch):
    from ccjax.experiments import plots

    figures = []
    write = plots.write_figure
    monkeypatch.setattr(
        plots, "write_figure", lambda fig, *args, **kwargs: (figures.append(fig), write(fig, *args, **kwargs))
    )
    truth = np.array([[1.0, 1.0, 1.0], [1.0, 0.8, 0.6], [0.5, 1.0, 0.9]])
    results = ImageResults(
        paths=["a.png", "b.png", "c.png"],
        estimates={"GW": truth * [1.0, 1.1, 1.0], "DB-GW": truth * [1.2, 1.0, 1.0]},
        ok={"GW": np.ones(3, bool), "DB-GW": np.array([True, False, True])},
        truth=truth,
    )
    plot_image_errors(results, tmp_path / "errors.png")
    assert (tmp_path / "errors.png").stat().st_size > 0
    axes = [fig for fig in figures if fig is not None][-1].axes
    assert len(axes) == 2
    for ax in axes:
        legend = ax.get_legend()
        assert legend is not None and [t.get_text() for t in legend.get_texts()] == ["GW", "DB-GW"]
    ticks = [t.get_text() for t in axes[1].get_xticklabels()]
    assert sorted(ticks) == ["a.png", "b.png", "c.png"]


@pytest.mark.slow
def test_training_within_folds_on_few_images_warns_once_per_method(folder, capsys):
    """6 images in 3 folds: 4 training images per fold, below the size ``--help`` names (50)."""
    argv = _argv(folder, "--folds", "3", "--train", "log-chroma-mlp", "--epochs", "1")
    assert cli.main(argv) == 0
    warnings = [line for line in capsys.readouterr().err.splitlines() if "warning: log-chroma-mlp" in line]
    assert len(warnings) == 1 and "4 per fold" in warnings[0] and "fewer than 50" in warnings[0]


def test_one_light_scale_in_estimate_json_evaluate_json_and_csv(small_world_commands, capsys):
    """The same image's grey-world light, printed by ``estimate --json`` and written by ``evaluate
    --json`` and ``--csv``: one scale, the largest channel 1, equal to the NumPy grey world (mean
    of the pixels) scaled so."""
    import csv
    import json

    folder = small_world_commands / "scale"
    rng = np.random.default_rng(8)
    codes = np.round(rng.uniform(0.05, 0.5, (20, 30, 3)) * np.array([1.0, 0.7, 0.4]) * 65535).astype(np.uint16)
    io.write_png(folder / "a.png", codes)
    (folder / "groundtruth.csv").write_text("image,r,g,b\na.png,1,0.7,0.4\n")
    mean = codes.reshape(-1, 3).astype(np.float64).mean(axis=0)
    want = mean / mean.max()
    assert cli.main(["estimate", str(folder / "a.png"), "--method", "GW", "--json", "--no-progress"]) == 0
    printed = json.loads(capsys.readouterr().out)[0]["illuminant"]
    argv = ["evaluate", str(folder), "--ground-truth", str(folder / "groundtruth.csv"), "--methods", "GW"]
    out = small_world_commands / "scale-out"
    assert cli.main([*argv, "--json", str(out) + ".json", "--csv", str(out) + ".csv", "--no-progress"]) == 0
    written = json.loads((small_world_commands / "scale-out.json").read_text())["images"][0]["illuminant"]
    with open(small_world_commands / "scale-out.csv", newline="") as handle:
        row = next(csv.DictReader(handle))
    tabled = [float(row[channel]) for channel in "RGB"]
    for light in (printed, written, tabled):
        np.testing.assert_allclose(light, want, rtol=1e-5)
