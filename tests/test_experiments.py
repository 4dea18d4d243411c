"""Sweep engine, reports, reproduction of the thesis tables, sharding, CLI."""

import json
import os
import subprocess
import sys

import jax
import numpy as np
import pytest

from ccjax import cli, experiments
from ccjax.experiments import reproduce, sweep
from ccjax.runs import engine

SIMPLE = ["NOTHING", "AVE-ILLUM", "GW", "DB-GW", "RETINEX"]


METHODS = ["NOTHING", "GW", "RETINEX"]


@pytest.fixture(scope="module")
def small_sweep(default_world):
    return sweep(default_world, METHODS, [4, 64], 400, jax.random.key(1), progress=False)


def test_sweep_is_independent_of_chunk_size(default_world, small_sweep):
    chunked = sweep(default_world, METHODS, [4], 400, jax.random.key(1), chunk_size=100, progress=False)
    for method in METHODS:
        for stat in small_sweep.errors[method][4]:
            # Same scenes; only float32 rounding of differently shaped batches may differ.
            np.testing.assert_allclose(
                chunked.errors[method][4][stat], small_sweep.errors[method][4][stat], rtol=1e-4, atol=1e-6
            )
    assert len(chunked.errors["GW"][4]["rg"]) == 400


def test_sweep_rows_and_outputs(small_sweep, tmp_path):
    rows = small_sweep.rows(("rms", "median"))
    # NOTHING is a chromaticity method: no RGB-valued statistics.
    assert {r["statistic"] for r in rows if r["method"] == "NOTHING"} == {"angular", "rg", "map_rg"}
    assert {r["statistic"] for r in rows if r["method"] == "GW"} == set(engine.STATISTICS)
    gw_rms = next(
        r
        for r in rows
        if r["method"] == "GW" and r["surfaces"] == 4 and r["statistic"] == "rg" and r["summary"] == "rms"
    )
    assert gw_rms["value"] == pytest.approx(float(np.sqrt(np.mean(small_sweep.errors["GW"][4]["rg"] ** 2))))
    assert json.loads(small_sweep.to_json())["rows"][0]["method"] == "NOTHING"
    assert small_sweep.to_csv().splitlines()[0].startswith("method,surfaces,statistic")
    table = small_sweep.table("rgb")
    assert "NOTHING" in table and "*" in table  # not applicable to a chromaticity method
    experiments.plot_sweep(small_sweep, tmp_path / "plot.png")
    assert (tmp_path / "plot.png").stat().st_size > 10_000


def test_more_surfaces_help(small_sweep):
    for method in ("GW", "RETINEX"):
        assert small_sweep.value(method, 64, "rg") < 0.7 * small_sweep.value(method, 4, "rg")
    # NOTHING ignores the data: its error does not depend on the number of surfaces.
    assert small_sweep.value("NOTHING", 64, "rg") == pytest.approx(small_sweep.value("NOTHING", 4, "rg"), rel=0.1)


@pytest.mark.external_data
def test_reproduce_table_4_2_simple_rows(barnard_world):
    """Thesis Table 4.2: angular and (r,g) within 10 %, RGB-valued columns within 15 %."""
    result = reproduce("4.2", barnard_world, SIMPLE, 1000, jax.random.key(0), progress=False)
    assert len(result.rows) == 3 + 3 + 6 * 3
    for row in result.rows:
        limit = 0.10 if row["column"] in ("angular", "rg") else 0.15
        assert abs(row["relative_difference"]) <= limit, row


@pytest.mark.slow
@pytest.mark.external_data
def test_reproduce_table_4_3_simple_rows(barnard_world):
    result = reproduce("4.3", barnard_world, SIMPLE, 1000, jax.random.key(0), progress=False)
    for row in result.rows:
        assert abs(row["relative_difference"]) <= 0.15, row


def test_reproduce_rejects_unknown(default_world):
    with pytest.raises(ValueError, match="table"):
        reproduce("9.9", default_world)
    with pytest.raises(ValueError, match="methods"):
        reproduce("4.2", default_world, ["GREY-WORLD-X"])


SHARDING_SCRIPT = r"""
import os, sys, json
import jax, numpy as np
from jax.sharding import Mesh
from ccjax.world import World
from ccjax.experiments import sweep
assert len(jax.devices()) == 4, jax.devices()
world = World.default()
mesh = Mesh(np.array(jax.devices()), ("scenes",))
one = sweep(world, ["GW", "RETINEX", "shades-of-grey-p6"], [8, 64], 1000, jax.random.key(7), progress=False)
four = sweep(world, ["GW", "RETINEX", "shades-of-grey-p6"], [8, 64], 1000, jax.random.key(7), mesh=mesh, progress=False)
worst = 0.0
for m in one.methods:
    for n in one.surfaces:
        for s, v in one.errors[m][n].items():
            if s == "ok":
                assert (v == four.errors[m][n][s]).all()
                continue
            a, b = one.value(m, n, s), four.value(m, n, s)
            worst = max(worst, abs(a - b) / max(abs(a), 1e-12))
print(json.dumps({"worst": worst}))
"""


@pytest.mark.slow
def test_sharded_sweep_matches_single_device():
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    out = subprocess.run([sys.executable, "-c", SHARDING_SCRIPT], env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    worst = json.loads(out.stdout.strip().splitlines()[-1])["worst"]
    assert worst <= 1e-6


def test_cli_compare_writes_outputs(small_sweep, tmp_path, capsys):
    code = cli.main(
        [
            "compare",
            "--methods",
            "NOTHING,GW,RETINEX",
            "--surfaces",
            "4,64",
            "--scenes",
            "400",
            "--seed",
            "1",
            "--no-progress",
            "--plot",
            str(tmp_path / "c.png"),
            "--json",
            str(tmp_path / "c.json"),
            "--csv",
            str(tmp_path / "c.csv"),
        ]
    )
    assert code == 0
    printed = capsys.readouterr().out
    assert "GW" in printed and "RETINEX" in printed and "rg (rms)" in printed
    assert (tmp_path / "c.png").exists()
    assert {r["method"] for r in json.loads((tmp_path / "c.json").read_text())["rows"]} == {"NOTHING", "GW", "RETINEX"}


def test_cli_errors_are_clear(capsys):
    assert cli.main(["compare", "--methods", "NO-SUCH", "--scenes", "5", "--no-progress"]) == 2
    assert "unknown label 'NO-SUCH'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        cli.main(["compare", "--surfaces", "a,b"])


@pytest.mark.external_data
def test_cli_reproduce_json(barnard_world, capsys):
    assert cli.main(["reproduce", "4.2", "--methods", "GW", "--scenes", "200", "--json", "--no-progress"]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["table"] == "4.2" and {r["column"] for r in payload["rows"]} == set(engine.STATISTICS)
    assert all(set(r) >= {"method", "column", "ours", "thesis"} for r in payload["rows"])


def test_reproduction_text_counts_bands_and_checks_orderings():
    def row(method, column, ours, thesis):
        return {
            "method": method,
            "column": column,
            "ours": ours,
            "thesis": thesis,
            "relative_difference": ours / thesis - 1,
            "ok_fraction": 1.0,
        }

    rows = [
        row("ECRULE-MV", "rg@8", 0.044, 0.044),  # 0 %
        row("ECRULE-ICA", "rg@8", 0.0585, 0.050),  # +17 %
        row("ECRULE-SCWIA-12", "rg@8", 0.0459, 0.040),  # +14.75 %, and worse than MV
    ]
    text = experiments.Reproduction("6.1", rows).text()
    assert "1/3 within ±10%, 2/3 within ±15%, 3/3 within ±20%" in text
    assert "ECRULE-MV 0.044 < ECRULE-ICA 0.0585 at rg@8: holds" in text
    assert "ECRULE-SCWIA-12 0.0459 < ECRULE-MV 0.044 at rg@8: FAILS" in text
    # Orderings whose rows were not run are not reported.
    assert "SCWIA-9" not in text


def test_reproduction_text_and_json_layout():
    """The text view keeps the layout ``ccjax reproduce`` printed, with each cell's sampling error
    (``s.e.``) before ``ok``; JSON keeps {"table", "rows"}."""
    rows = [
        {"method": "GW", "column": "rg", "ours": 0.0571, "thesis": 0.058, "relative_difference": -0.0155,
         "sampling_error": 0.0012, "ok_fraction": 1.0},
        {"method": "ECRULE-SCWIA-12", "column": "map_rgb", "ours": 51.25, "thesis": 51.1,
         "relative_difference": 0.00293, "sampling_error": 1.234, "ok_fraction": 0.987},
    ]  # fmt: skip
    lines = experiments.Reproduction("4.2", rows).text().splitlines()
    assert lines[0] == "Table 4.2: ours vs thesis (RGB-valued errors in thesis units, white = 255)"
    assert lines[1] == "method                column              ours    thesis     diff     s.e.  ok"
    assert lines[2] == "GW                    rg                0.0571     0.058    -1.6%   0.0012  100%"
    assert lines[3] == "ECRULE-SCWIA-12       map_rgb            51.25      51.1    +0.3%      1.2  99%"
    assert lines[4] == "cells: 2/2 within ±10%, 2/2 within ±15%, 2/2 within ±20%; largest |diff| 1.6%"
    assert lines[5] == "s.e.: standard error of ours over the scenes (delta method for the RMS)"
    payload = json.loads(experiments.Reproduction("4.2", rows).to_json())
    assert list(payload) == ["table", "rows"] and payload["rows"] == rows
    # A label longer than the method column widens it and keeps a space before the column name.
    long = [{**rows[0], "method": "MET-ND-ECRULE-SCWIA-12"}, rows[1]]
    lines = experiments.Reproduction("8.2", long).text().splitlines()
    assert lines[2].startswith("MET-ND-ECRULE-SCWIA-12 rg ")
    assert lines[3].startswith("ECRULE-SCWIA-12        map_rgb ")
    assert lines[1].index("column") == lines[2].index("rg") == lines[3].index("map_rgb")


def test_report_columns_never_touch():
    report = experiments.Report(
        [{"name": "a-very-long-camera-name-indeed-longer-than-any-fixed-width", "source": "embedded"},
         {"name": "short", "source": None}],
        [experiments.Column("name"), experiments.Column("source", gap=2)],
    )  # fmt: skip
    head, first, second = report.text().splitlines()
    start = head.index("source")
    assert first[start:] == "embedded" and first[start - 2 : start] == "  "
    assert second[start:] == "-" and second[:start].rstrip() == "short"
    assert report.to_csv().splitlines() == [
        "name,source",
        "a-very-long-camera-name-indeed-longer-than-any-fixed-width,embedded",
        "short,",
    ]
    assert json.loads(report.to_json())["rows"][1] == {"name": "short", "source": None}


def test_sweep_refuses_image_estimators(default_world):
    with pytest.raises(ValueError, match=r"'grey-edge-1-6-2'.* is an image estimator"):
        sweep(default_world, ["GW", "grey-edge-1-6-2"], [4], 10, progress=False)
    from ccjax.estimators import registry

    model = registry.fit("grey-edge-1-6-2", default_world)
    with pytest.raises(ValueError, match=r"'edges'.* is an image estimator"):
        sweep(default_world, [("edges", model)], [4], 10, progress=False)


def test_experiments_import_is_cheap():
    """Importing ccjax.experiments does not import the chapter-specific experiments or matplotlib."""
    script = (
        "import sys, ccjax.experiments, ccjax.cli\n"
        "heavy = [m for m in sys.modules if m.startswith(('ccjax.experiments.chapter5', 'ccjax.experiments.indexing',"
        " 'matplotlib'))]\n"
        "print(heavy)\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "[]"


def _commands() -> list[str]:
    import argparse

    sub = argparse.ArgumentParser(prog="ccjax").add_subparsers()
    for add in cli.COMMANDS:
        add(sub)
    return list(sub.choices)


def test_every_command_group_builds_and_has_help(capsys):
    commands = _commands()
    # One group module per command group, every command reachable from the one parser.
    assert {group.__name__.rsplit(".", 1)[1] for group in cli.GROUPS} == {
        "synthetic", "catalogue", "photos", "indexing", "training", "sharpen", "calibrate"
    }  # fmt: skip
    assert set(commands) == {
        "compare", "reproduce", "world", "cameras", "methods", "estimate", "correct", "evaluate", "indexing",
        "train", "train-net", "sharpen", "calibrate",
    }  # fmt: skip
    for command in commands:
        with pytest.raises(SystemExit) as exit_:
            cli.main([command, "--help"])
        assert exit_.value.code == 0
        assert f"usage: ccjax {command}" in capsys.readouterr().out


def test_cli_methods_lists_every_family_in_columns(capsys):
    from ccjax.cli.catalogue import registered_families

    assert cli.main(["methods"]) == 0
    head, *lines = capsys.readouterr().out.rstrip("\n").splitlines()
    examples = [entry.example for entry in registered_families()]
    assert len(lines) == len(examples)
    for heading in ("label grammar", "example", "input", "traceable fit", "description"):
        assert heading in head
    starts = [head.index(name) for name in ("example", "input", "traceable fit", "description")]
    for line, example in zip(lines, examples, strict=True):
        assert line[starts[0] :].startswith(example + " ")
        for start in starts:
            assert line[start - 2 : start] == "  " and line[start] != " "  # columns never run together
    for line, entry in zip(lines, registered_families(), strict=True):
        assert line[starts[1] :].startswith(getattr(entry, "input_kind", "?") + " ")
    assert cli.main(["methods", "--json"]) == 0
    assert [row["example"] for row in json.loads(capsys.readouterr().out)["rows"]] == examples


def test_cli_cameras_columns(capsys):
    assert cli.main(["cameras"]) == 0
    head, *lines = capsys.readouterr().out.rstrip("\n").splitlines()
    start = head.index("source")
    assert len(lines) > 10
    for line in lines:
        assert line[start - 2 : start] == "  " and line[start] != " "


def test_cli_world_plot(tmp_path, capsys):
    assert cli.main(["world", "--plot", str(tmp_path / "w.png")]) == 0
    assert "canonical white RGB" in capsys.readouterr().out
    assert (tmp_path / "w.png").stat().st_size > 10_000


@pytest.mark.external_data
def test_sfu321_camera_check(barnard_world):
    """The Sony DXC-930 curves against SFU-321: every lab light within a few degrees (§4.4)."""
    check = experiments.sfu321_check(barnard_world)
    assert len(check.rows) == 11 and sum(row["images"] for row in check.rows) == 321
    assert all(0.0 <= row["angular"] < 5.0 for row in check.rows), check.text()


def test_plot_sweep_draws_the_rms_of_each_cell(small_sweep, tmp_path, monkeypatch):
    """Each line of the figure is the RMS of the per-scene errors (NumPy, the thesis' aggregate),
    one point per surface count; the deprecated ``plot`` warns and draws the same figure."""
    from ccjax.experiments import plots

    figures = []
    monkeypatch.setattr(plots, "write_figure", lambda fig, path, **options: figures.append(fig))
    experiments.plot_sweep(small_sweep, tmp_path / "one.png", statistics="angular")
    with pytest.warns(DeprecationWarning, match="plot_sweep"):
        experiments.plot(small_sweep, tmp_path / "two.png", statistics=["angular"])
    for fig in figures:
        (ax,) = [ax for ax in fig.axes if ax.lines]
        for line in ax.lines:
            method = line.get_label()
            expected = [np.sqrt(np.mean(small_sweep.errors[method][n]["angular"] ** 2)) for n in small_sweep.surfaces]
            np.testing.assert_allclose(line.get_ydata(), expected, rtol=1e-6)
            np.testing.assert_allclose(line.get_xdata(), np.log2(small_sweep.surfaces))
        assert sorted(line.get_label() for line in ax.lines) == sorted(small_sweep.methods)
    with pytest.raises(ValueError, match="statistics"):
        experiments.plot_sweep(small_sweep, tmp_path / "three.png", statistics="angle")
