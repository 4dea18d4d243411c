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


def test_sharded_sweep_quick():
    out = run_example("sharded_sweep.py", "--quick")
    assert "4 cpu devices" in out
    rows = table_rows(out, r"\s+[14]\s")
    assert len(rows) == 2
    assert all(row[-1] <= 1e-6 for row in rows)  # max relative difference to the 1-device run
    assert "agree" in out and "DISAGREE" not in out


def test_camera_sweep_quick():
    out = run_example("camera_sweep.py", "--quick")
    rows = table_rows(out, r"(ARRI|Arashi|Canon|Nikon|Sony|Fuji|Panasonic|Olympus|Leica|Hasselblad)")
    assert len(rows) == 4 and all(len(row) == 6 for row in rows)
    # Median angular errors of real estimators on 8-surface scenes: degrees, not 0, not 90.
    assert all(0.3 < value < 20 for row in rows for value in row)


def test_learn_correlation_quick():
    out = run_example("learn_correlation.py", "--quick")
    loss = re.search(r"training angular loss .* ([\d.]+) -> ([\d.]+) deg", out)
    assert loss is not None and 0 < float(loss.group(2)) < 20
    for method in ("C-by-C-MMSE (learned)", "C-by-C-MMSE (counted)", "GW", "grey-edge-1-6-2", "ECRULE-MV"):
        assert re.search(rf"^{re.escape(method)}\s+\d+\.\d+", out, re.M), method


def test_learned_sharpening_quick():
    out = run_example("learned_sharpening.py", "--quick")
    rows = table_rows(out, r"(GW|soft-RETINEX\S*)\s+\w+\s+(none|new|learned)\s")
    assert len(rows) == 6  # two estimators x (none, new, learned)
    assert "learned T =" in out


def test_synthetic_raw_evaluation_quick():
    out = run_example("synthetic_raw_evaluation.py", "--quick")
    assert "wrote 60 images of 64x64" in out
    rows = table_rows(out, r"(GW|grey-edge-1-6-2)\s")[:2]  # the first table: mean, median, ...
    assert len(rows) == 2 and all(0 < row[0] < 30 for row in rows)


def test_calibrate_synthetic_quick():
    out = run_example("calibrate_synthetic.py", "--quick")
    assert "RMS relative error" in out and "pseudo-inverse" in out


@pytest.mark.slow
@pytest.mark.parametrize(
    # camera_sweep.py's full run (every camera at once, 2000 scenes) peaks at 24 GB and is killed on
    # a 24 GiB machine (measured): left out until its memory is bounded; its --quick run is tested.
    "name",
    ["sharded_sweep.py", "learn_correlation.py", "learned_sharpening.py"],
)
def test_full_runs(name):
    args = ("--world", "default") if name == "learned_sharpening.py" else ()
    assert run_example(name, *args, timeout=1500)
