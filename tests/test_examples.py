"""Every example runs from a fresh interpreter: its ``--quick`` mode in the default suite (numbers in
its output are checked, not just the exit status), the full runs marked slow."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def run_example(name: str, *args: str, timeout: float = 600) -> str:
    env = dict(os.environ)
    env.pop("XLA_FLAGS", None)  # the sharded example sets its own
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / name), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        cwd=EXAMPLES.parent,
    )
    assert done.returncode == 0, f"{name} {args} failed:\n{done.stdout}\n{done.stderr[-3000:]}"
    return done.stdout


def table_rows(text: str, pattern: str) -> list[list[float]]:
    """Numbers of every line matching ``pattern`` (a regular expression at the line start)."""
    rows = []
    for line in text.splitlines():
        if re.match(pattern, line):
            rows.append([float(v) for v in re.findall(r"[-+]?\d+\.\d+(?:e[-+]\d+)?", line)])
    return rows


@pytest.mark.slow
def test_sharded_sweep_quick():
    out = run_example("sharded_sweep.py", "--quick")
    assert "4 cpu devices" in out
    rows = table_rows(out, r"\s+[14]\s")
    assert len(rows) == 2
    assert all(row[-1] <= 1e-6 for row in rows)  # max relative difference to the 1-device run
    assert "agree" in out and "DISAGREE" not in out


CAMERA_ROW = r"(ARRI|Arashi|Canon|Nikon|Sony|Fuji|Panasonic|Olympus|Leica|Hasselblad)"


def camera_medians(out: str, n_methods: int) -> list[list[float]]:
    rows = table_rows(out, CAMERA_ROW)
    assert rows and all(len(row) == n_methods for row in rows), out
    # Median angular errors of real estimators on 8-surface scenes: degrees, not 0, not 90.
    assert all(0.3 < value < 20 for row in rows for value in row)
    return rows


@pytest.mark.slow
def test_camera_sweep_quick():
    rows = camera_medians(run_example("camera_sweep.py", "--quick"), 6)
    assert len(rows) == 4
    # The thesis' ranking (Barnard 1999 Table 4.2: C-by-C-MMSE far ahead of GW on 8 surfaces) holds
    # for every camera: column 0 is GW, the last C-by-C-MMSE.
    assert all(row[-1] < row[0] for row in rows)


def check_learn_correlation(out: str, gamut: tuple[str, ...]) -> None:
    loss = re.search(r"training angular loss .* ([\d.]+) -> ([\d.]+) deg", out)
    assert loss is not None and 0 < float(loss.group(2)) < 20
    # The matrix kept never has a higher validation loss than the counted one it starts from.
    validation = re.search(r"validation \(\d+ images, lights held out of training\): ([\d.]+) -> ([\d.]+) deg", out)
    assert validation is not None and float(validation.group(2)) <= float(validation.group(1))
    # The held-out table: every method's median, mean and worst-25 % mean (degrees, in that order).
    for method in ("C-by-C-MMSE (learned)", "C-by-C-MMSE (counted)", "GW", "grey-edge-1-6-2", *gamut):
        row = table_rows(out, rf"{re.escape(method)}\s+\d")
        assert len(row) == 1 and len(row[0]) == 3, method
        median, mean, worst = row[0]
        assert 0 < median < 30 and mean <= worst, method


@pytest.mark.slow  # over 30 s on 2 cores: the default run stays under 10 minutes
def test_learn_correlation_quick():
    # --quick leaves the gamut methods out (their kernel's compilation is a third of the run).
    check_learn_correlation(run_example("learn_correlation.py", "--quick"), ())


def check_learned_sharpening(out: str) -> None:
    rows = table_rows(out, r"(GW|soft-RETINEX\S*)\s+\w+\s+(none|new|learned)\s")
    assert len(rows) == 6  # two estimators x (none, new, learned)
    assert out.count("learned T =") == 2
    # Gradient descent lowers the objective it descends: on a fixed batch of training scenes the
    # learned T's loss is below the identity's, for both estimators.
    fixed = re.findall(r"fixed batch of \d+ training scenes: T = I ([\d.]+) -> learned ([\d.]+)", out)
    assert len(fixed) == 2
    assert all(float(after) < float(before) for before, after in fixed), fixed
    # GW's chromaticity does not depend on T (Barnard 1999 §5.6): its angle is the same for every T.
    gw_angles = [row[1] for row in rows[:3]]
    assert max(gw_angles) - min(gw_angles) < 1e-2, gw_angles


@pytest.mark.slow  # over 30 s on 2 cores: the default run stays under 10 minutes
def test_learned_sharpening_quick():
    check_learned_sharpening(run_example("learned_sharpening.py", "--quick"))


@pytest.mark.slow
def test_synthetic_raw_evaluation_quick():
    out = run_example("synthetic_raw_evaluation.py", "--quick")
    assert "wrote 60 images of 64x64" in out
    rows = table_rows(out, r"(GW|grey-edge-1-6-2)\s")[:2]  # the first table: mean, median, ...
    assert len(rows) == 2 and all(0 < row[0] < 30 for row in rows)


@pytest.mark.manual  # about 125 s on 2 cores; FFCC trained on synthetic scenes is tested in the slow suite
def test_ffcc_quick():
    out = run_example("ffcc_quick.py", "--quick")
    assert "wrote 120 images of 32x32" in out
    summary = re.findall(r"^(GW|shades-of-grey-p6|FFCC trained) +(\d+\.\d+) +(\d+\.\d+)$", out, re.MULTILINE)
    means = {method: float(mean) for method, mean, _ in summary}
    assert len(summary) == 3 and len(means) == 3, out
    # FFCC trains without a stopping split: its training rows and line say so instead of printing NaN.
    assert not re.search(r"\bnan\b", out, re.IGNORECASE), out
    assert re.search(r"^FFCC: trained on 120 images \(\d+ L-BFGS passes", out, re.MULTILINE), out
    # Trained within folds on scenes whose lights it has seen, FFCC beats the untrained statistics.
    assert 0 < means["FFCC trained"] < means["shades-of-grey-p6"] < 30, out
    uncertainty = table_rows(out, r"image-\d{4}\.png")
    assert len(uncertainty) == 5, out
    # error (deg), two standard deviations (log-chroma) and a confidence in (0, 1]
    assert all(row[0] >= 0 and row[1] > 0 and row[2] > 0 and 0 < row[3] <= 1 for row in uncertainty), out


@pytest.mark.slow  # about 40 s on 2 cores (two cameras' worlds, maps and compilation)
def test_any_camera_quick():
    out = run_example("any_camera.py", "--quick")
    assert "rendered 40 images of 32 x 32" in out, out
    # Leave-one-camera-out: each folder's rows, then the geometric mean of each method over both.
    for method in ("GW", "shades-of-grey-p6", "grey-edge-1-6-2 trained"):
        rows = {folder: table_rows(out, rf"{folder} \(\d+\)\s+{re.escape(method)}\s") for folder in ("canon", "nikon")}
        mean = table_rows(out, rf"geometric mean \(2\)\s+{re.escape(method)}\s")
        assert all(len(r) == 1 for r in rows.values()) and len(mean) == 1, out
        expected = (rows["canon"][0][0] * rows["nikon"][0][0]) ** 0.5
        assert abs(mean[0][0] - expected) < 2e-3 and 0 < expected < 30, out
    assert re.search(
        r"^canon: grey-edge-1-6-2 trained on 40 images of nikon \(Nikon D5300, mapped per-light\)", out, re.M
    )
    # The model trained for the Nikon from the Canon's images alone, scored on the Nikon's folder.
    assert re.search(r"trained on 40 images \(canon 40; per-light maps\)", out), out
    scored = table_rows(out, r"\S*for-nikon\.eqx\s")
    assert len(scored) >= 1 and 0 < scored[0][0] < 30, out


@pytest.mark.slow
def test_calibrate_synthetic_quick():
    out = run_example("calibrate_synthetic.py", "--quick")
    assert "RMS relative error" in out and "pseudo-inverse" in out


@pytest.mark.manual  # about 160 s on 2 cores; --quick runs by default
def test_camera_sweep_full():
    # Every embedded camera, 2000 scenes, both looped methods (C-by-C-MMSE, ECRULE-MV).
    rows = camera_medians(run_example("camera_sweep.py", timeout=1500), 7)
    assert len(rows) >= 40
    assert all(row[-2] < row[0] and row[-1] < row[0] for row in rows)  # both beat GW on every camera


@pytest.mark.slow
def test_sharded_sweep_full():
    out = run_example("sharded_sweep.py", timeout=1500)
    rows = table_rows(out, r"\s+[124]\s")
    assert len(rows) == 3
    assert all(row[-1] <= 1e-6 for row in rows)
    assert "agree" in out and "DISAGREE" not in out


@pytest.mark.manual  # about 80 s on 2 cores; --quick is in the slow suite
def test_learn_correlation_full():
    check_learn_correlation(run_example("learn_correlation.py", timeout=1500), ("ECRULE-MV", "ND-ECRULE-SCWIA-12"))


@pytest.mark.manual  # about 50 s on 2 cores; --quick is in the slow suite
def test_learned_sharpening_full():
    check_learned_sharpening(run_example("learned_sharpening.py", "--world", "default", timeout=1500))
