"""``ccjax evaluate DIR DIR ...``: the field's per-camera protocol over several folders (each
folder cross-validated on its own, then the geometric mean of each statistic over the folders),
checked against NumPy from the per-image estimates the report gives; per-folder cameras, the fold
models written, clear errors and exit codes."""

from __future__ import annotations

import json

import jax
import numpy as np
import pytest

from ccjax import cli, io, scenes
from ccjax.evaluation import geometric_mean

N = 9
FOLDERS = ("alpha", "beta", "gamma")
STATISTICS = ("mean", "median", "trimean", "best25", "worst25")


@pytest.fixture(scope="module")
def folder_sets(small_test_world, tmp_path_factory):
    """Three folders of 9 small Mondrians each, under different draws of the small world's lights."""
    root = tmp_path_factory.mktemp("folder_sets")
    for index, name in enumerate(FOLDERS):
        batch = scenes.sample_mondrians(
            jax.random.key(11 + index), small_test_world, N, height=16, width=16, n_patches=5
        )
        io.write_dataset(root / name, np.asarray(batch.image), np.asarray(batch.illuminant))
    return root


@pytest.fixture
def setup(small_world_commands):
    return small_world_commands


def _angles(estimates, truths):
    """Recovery angular error in degrees, row by row (the oracle)."""
    a, b = np.asarray(estimates, np.float64), np.asarray(truths, np.float64)
    cosine = np.sum(a * b, axis=1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def _statistic(errors, name):
    """The field's statistics from their definitions (Hordley & Finlayson 2006)."""
    e = np.sort(np.asarray(errors, np.float64))
    quarter = max(1, int(round(len(e) / 4)))
    q1, q2, q3 = np.percentile(e, [25, 50, 75])
    return {
        "mean": np.mean(e),
        "median": np.median(e),
        "trimean": (q1 + 2 * q2 + q3) / 4,
        "best25": np.mean(e[:quarter]),
        "worst25": np.mean(e[-quarter:]),
    }[name]


def _argv(root, *extra):
    folders = [str(root / name) for name in FOLDERS]
    return ["evaluate", *folders, "--ground-truth-name", "groundtruth.csv", "--no-progress", *extra]


@pytest.mark.parametrize("values", [[2.0, 8.0], [1.5, 2.5, 3.5, 4.5], [0.3], [1e-3, 1e3, 7.0]])
def test_geometric_mean_matches_numpy(values):
    assert geometric_mean(values) == pytest.approx(np.prod(values) ** (1 / len(values)), rel=1e-12)


def test_geometric_mean_of_a_zero_is_zero_and_bad_values_are_refused():
    assert geometric_mean([0.0, 3.0]) == 0.0
    for bad in ([], [1.0, -1.0], [1.0, float("nan")]):
        with pytest.raises(ValueError, match="values"):
            geometric_mean(bad)


@pytest.mark.slow
def test_rows_and_geometric_means_match_numpy(setup, folder_sets, capsys):
    report_file = setup / "sets.json"
    argv = _argv(folder_sets, "--methods", "GW,shades-of-grey-p6", "--folds", "3", "--train", "grey-edge-1-6-2")
    argv += ["--epochs", "1", "--json", str(report_file), "--models", str(setup / "models")]
    assert cli.main(argv) == 0
    out = capsys.readouterr().out
    report = json.loads(report_file.read_text())
    labels = ("GW", "shades-of-grey-p6", "grey-edge-1-6-2 trained")
    assert list(report["sets"]) == list(FOLDERS)
    per_folder = {label: {name: [] for name in STATISTICS} for label in labels}
    for name in FOLDERS:
        entry = report["sets"][name]
        truth = io.read_ground_truth(folder_sets / name / "groundtruth.csv")
        assert entry["images"] == N and set(entry["methods"]) == set(labels)
        for label in labels:
            records = [r for r in entry["evaluation"]["images"] if r["method"] == label]
            estimates = [r["illuminant"] for r in records]
            truths = [truth[r["path"].rsplit("/", 1)[-1]] for r in records]
            errors = _angles(estimates, truths)
            assert len(errors) == N
            row = entry["methods"][label]
            for statistic in STATISTICS:
                expected = _statistic(errors, statistic)
                assert row[statistic] == pytest.approx(expected, rel=1e-5, abs=1e-5)
                per_folder[label][statistic].append(expected)
            assert np.isfinite(row["ms_per_image"]) and row["ms_per_image"] >= 0
        assert entry["methods"]["grey-edge-1-6-2 trained"]["train_seconds"] >= 0
        assert "train_seconds" not in entry["methods"]["GW"]
        # Each folder's table row is printed, with its image count.
        assert f"{name} ({N})" in out
    means = report["geometric_mean"]["methods"]
    assert report["geometric_mean"]["folders"] == len(FOLDERS)
    for label in labels:
        for statistic in STATISTICS:
            values = per_folder[label][statistic]
            assert means[label][statistic] == pytest.approx(np.prod(values) ** (1 / len(values)), rel=1e-4)
        printed = [line for line in out.splitlines() if line.startswith("geometric mean (3)") and f" {label} " in line]
        assert len(printed) == 1
        # Five statistics, mean first; no training seconds or ms/image on a geometric-mean row.
        assert float(printed[0].split()[-5]) == pytest.approx(means[label]["mean"], abs=6e-4)
    # One model file per folder and fold, each readable and scoring like the evaluation did.
    import ccjax

    for name in FOLDERS:
        files = sorted((setup / "models" / name).glob("*.eqx"))
        assert [f.name for f in files] == [f"grey-edge-1-6-2-fold{k}.eqx" for k in range(3)]
        for file in files:
            model = ccjax.load_model(file)
            assert float(model.p) >= 1.0
            record = json.loads(file.with_suffix(".json").read_text())
            assert not set(record["train_images"]) & set(record["test_images"])
        assert f"wrote {setup / 'models' / name / 'grey-edge-1-6-2-fold0.eqx'}" in out


def test_world_based_methods_run_only_where_a_camera_is_given(setup, folder_sets, capsys):
    argv = _argv(folder_sets, "--methods", "GW,AVE-ILLUM", "--camera-for", "beta=Canon EOS 5D Mark II")
    assert cli.main([*argv, "--json", str(setup / "r.json")]) == 0
    out = capsys.readouterr().out
    report = json.loads((setup / "r.json").read_text())
    assert set(report["sets"]["beta"]["methods"]) == {"GW", "AVE-ILLUM"}
    assert report["sets"]["beta"]["camera"] == "Canon EOS 5D Mark II"
    for name in ("alpha", "gamma"):
        assert set(report["sets"][name]["methods"]) == {"GW"}
        assert report["sets"][name]["left_out"] == ["AVE-ILLUM"]
        assert f"{name}: no camera given, world-based AVE-ILLUM left out" in out
    # The geometric mean covers the methods scored in every folder only.
    assert set(report["geometric_mean"]["methods"]) == {"GW"}


@pytest.mark.slow
def test_the_log_chroma_mlp_needs_no_camera(setup, folder_sets):
    # It learns everything from the photographs: trained in every folder, none of which has a camera.
    argv = _argv(folder_sets, "--methods", "GW", "--folds", "3", "--train", "log-chroma-mlp", "--epochs", "1")
    assert cli.main([*argv, "--json", str(setup / "mlp.json")]) == 0
    report = json.loads((setup / "mlp.json").read_text())
    for name in FOLDERS:
        assert report["sets"][name]["left_out"] == []
        assert report["sets"][name]["methods"]["log-chroma-mlp trained"]["train_seconds"] >= 0
    assert set(report["geometric_mean"]["methods"]) == {"GW", "log-chroma-mlp trained"}


@pytest.mark.slow
def test_models_of_one_folder(setup, folder_sets, capsys):
    folder = folder_sets / "alpha"
    argv = ["evaluate", str(folder), "--ground-truth-name", "groundtruth.csv", "--methods", "GW", "--folds", "3"]
    argv += ["--train", "grey-edge-1-6-2", "--epochs", "1", "--no-progress", "--models", str(setup / "one")]
    assert cli.main(argv) == 0
    assert sorted(f.name for f in (setup / "one").glob("*.eqx")) == [f"grey-edge-1-6-2-fold{k}.eqx" for k in range(3)]
    # Refused without --overwrite the second time (exit 2), before any training.
    capsys.readouterr()
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert f"--models: {setup / 'one' / 'grey-edge-1-6-2-fold0.eqx'} exists" in err and "training" not in err


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--ground-truth", "x.csv"], "--ground-truth: give either"),
        (["--csv", "out.csv"], "--csv: applies to one folder"),
        (["--plot", "out.png"], "--plot: applies to one folder"),
        (["--models", "m"], "--models: writes the models trained within the folds"),
        (["--camera-for", "delta=Canon EOS 5D Mark II"], "--camera-for: expected FOLDER=CAMERA"),
        (["--camera-for", "alpha"], "--camera-for: expected FOLDER=CAMERA"),
        (["--camera-for", "alpha=No Such Camera"], "No Such Camera"),
        (["--methods", "AVE-ILLUM"], "--camera:"),
    ],
)
def test_errors_name_the_option(setup, folder_sets, capsys, extra, message):
    methods = [] if "--methods" in extra else ["--methods", "GW"]
    assert cli.main([*_argv(folder_sets, *methods), *extra]) == 2
    assert message in capsys.readouterr().err


def test_one_csv_for_several_folders_is_refused(setup, folder_sets, capsys):
    folders = [str(folder_sets / name) for name in FOLDERS]
    argv = ["evaluate", *folders, "--ground-truth", str(folder_sets / "alpha" / "groundtruth.csv"), "--methods", "GW"]
    assert cli.main(argv) == 2
    assert "--ground-truth: one CSV cannot serve 3 folders" in capsys.readouterr().err


def test_two_folders_with_one_name_are_refused(setup, folder_sets, tmp_path, capsys):
    twin = tmp_path / "elsewhere" / "alpha"
    twin.mkdir(parents=True)
    for file in (folder_sets / "alpha").iterdir():
        (twin / file.name).write_bytes(file.read_bytes())
    argv = ["evaluate", str(folder_sets / "alpha"), str(twin), "--ground-truth-name", "groundtruth.csv"]
    assert cli.main([*argv, "--methods", "GW", "--no-progress"]) == 2
    assert "folders: each folder needs its own name, got alpha" in capsys.readouterr().err


def test_an_unreadable_image_in_one_folder_exits_2_after_the_table(setup, folder_sets, tmp_path, capsys):
    broken = tmp_path / "broken"
    broken.mkdir()
    for file in (folder_sets / "gamma").iterdir():
        (broken / file.name).write_bytes(file.read_bytes())
    (broken / "image-0003.png").write_bytes(b"not a png")
    argv = ["evaluate", str(folder_sets / "alpha"), str(broken), "--ground-truth-name", "groundtruth.csv"]
    assert cli.main([*argv, "--methods", "GW", "--no-progress"]) == 2
    captured = capsys.readouterr()
    assert f"broken ({N - 1})" in captured.out and "geometric mean (2)" in captured.out
    assert "1 of 18 images cannot be used" in captured.err and "image-0003.png" in captured.err
