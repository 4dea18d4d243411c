"""``ccjax estimate``'s output: every row and JSON object carries its status, lights are scaled
as documented (largest channel 1, never a relaxed solution's raw magnitude), and one warning line
counts the images that were not estimated."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ccjax import cli, io

CAMERA = "Canon EOS 5D Mark II"


@pytest.fixture
def folder(tmp_path):
    """``good.png``: grey-ish surfaces under a warm light; ``odd.png``: three saturated primaries,
    which no light maps into the canonical gamut (a gamut method relaxes); ``dark.png``: black."""
    rng = np.random.default_rng(0)
    good = rng.uniform(0.2, 0.8, (32, 32, 3)) * np.array([0.9, 0.7, 0.4])
    odd = np.zeros((32, 32, 3))
    odd[:16] = [0.9, 0.02, 0.02]
    odd[16:] = [0.02, 0.05, 0.9]
    odd[:, :10] = [0.02, 0.9, 0.05]
    for name, image in (("good", good), ("odd", odd), ("dark", np.zeros((32, 32, 3)))):
        io.write_png(tmp_path / f"{name}.png", np.round(image * 65535).astype(np.uint16))
    return tmp_path


def test_relaxed_and_empty_estimates_say_so_in_the_table_the_json_and_one_warning(folder, capsys):
    argv = ["estimate", str(folder), "--method", "ECRULE-MV", "--camera", CAMERA, "--no-progress"]
    assert cli.main([*argv, "--json"]) == 0
    captured = capsys.readouterr()
    records = {r["path"].rsplit("/", 1)[-1]: r for r in json.loads(captured.out)}
    assert {name: r["status"] for name, r in records.items()} == {
        "dark.png": "no usable pixels",
        "good.png": "estimated",
        "odd.png": "relaxed",
    }
    assert [records[name]["ok"] for name in ("dark.png", "good.png", "odd.png")] == [False, True, False]
    for record in records.values():
        assert max(record["illuminant"]) == pytest.approx(1.0, abs=1e-12), record
    warning = [line for line in captured.err.splitlines() if "warning" in line]
    assert warning == [
        "ccjax estimate: warning: 2 of 3 images not estimated (no usable pixels 1, relaxed 1); see the status "
        "column (`ccjax estimate --help` says what each means)"
    ]
    assert cli.main(argv) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].split()[-1] == "status"
    rows = {line.split()[0].rsplit("/", 1)[-1]: line for line in table[1:]}
    assert rows["odd.png"].endswith("  relaxed") and rows["dark.png"].endswith("  no usable pixels")
    assert all(max(float(v) for v in line.split()[1:4]) == 1.0 for line in rows.values())


def test_grey_world_json_is_the_numpy_mean_scaled_to_a_largest_channel_of_1(folder, capsys):
    (folder / "odd.png").unlink()
    (folder / "dark.png").unlink()
    assert cli.main(["estimate", str(folder / "good.png"), "--method", "GW", "--json", "--no-progress"]) == 0
    captured = capsys.readouterr()
    (record,) = json.loads(captured.out)
    codes = io.read_png(folder / "good.png").astype(np.float64)
    mean = codes.reshape(-1, 3).mean(axis=0)
    np.testing.assert_allclose(record["illuminant"], mean / mean.max(), rtol=1e-5)
    assert record["status"] == "estimated" and record["ok"] is True
    assert "warning" not in captured.err
