"""One limits table (:mod:`ccjax.limits`), consulted by the readers, the samplers and the command
line: within a limit the memory is bounded, past it the refusal comes up front, naming the limit."""

from __future__ import annotations

import re
import tracemalloc
from pathlib import Path

import colour
import jax
import numpy as np
import pytest
from PIL import Image

import ccjax
from ccjax import experiments, io, limits
from ccjax.runs import synthetic

DOCS = Path(__file__).resolve().parents[1] / "docs"


def _jpeg(path, height: int, width: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    pixels = rng.integers(0, 256, (height, width, 3), dtype=np.uint8)
    Image.fromarray(pixels).save(path, quality=100, subsampling=0)
    with Image.open(path) as image:
        return np.asarray(image)


def test_decoding_srgb_costs_a_few_bytes_per_pixel(tmp_path):
    codes = _jpeg(tmp_path / "photo.jpg", 1000, 2000)  # 2 MP
    io.read_image(tmp_path / "photo.jpg", decode_srgb=True)  # imports and tables first
    tracemalloc.start()
    try:
        image = io.read_image(tmp_path / "photo.jpg", decode_srgb=True)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # The decoded codes (3 B/px), the float32 image (12 B/px), the clip mask: about 16 B/px; a
    # whole-image float64 decode cost about 175.
    assert peak / codes.shape[0] / codes.shape[1] < 40
    # The same numbers as colour-science's curve on the whole image, in float64.
    oracle = colour.cctf_decoding(codes / 255.0, function="sRGB")
    np.testing.assert_allclose(np.asarray(image.rgb), oracle, rtol=1e-6, atol=1e-7)


def test_sample_refuses_more_scenes_than_it_can_hold(small_test_world):
    n = int(limits.SAMPLE_SCENES.value) + 1
    with pytest.raises(ValueError, match=r"n_scenes: 100,001 is over the limit of 100,000"):
        ccjax.sample(jax.random.key(0), small_test_world, n, 4)


def test_a_synthetic_run_refuses_more_scenes_than_the_limit():
    with pytest.raises(ValueError, match=r"n_scenes: 1,000,001 is over the limit of 1,000,000 .*--scenes"):
        synthetic.SyntheticSource(jax.random.key(0), (4,), int(limits.SCENES.value) + 1)


def test_a_ground_truth_file_past_the_row_limit_is_refused(tmp_path):
    path = tmp_path / "gt.csv"
    rows = "".join(f"i{i}.png,0.5,0.4,0.3\n" for i in range(int(limits.CSV_ROWS.value) + 1))
    path.write_text("image,r,g,b\n" + rows)
    with pytest.raises(ValueError, match=r"gt\.csv: line 100002 is past the limit of 100,000"):
        io.read_ground_truth(path)


def test_a_ground_truth_file_past_the_byte_limit_is_refused_from_its_size(tmp_path, monkeypatch):
    path = tmp_path / "gt.csv"
    with open(path, "wb") as handle:
        handle.truncate(int(limits.CSV_BYTES.value) + 1)  # sparse: no disk used
    with pytest.raises(ValueError, match=r"over the limit of 67,108,864"):
        io.read_ground_truth(path)


def test_the_docs_list_every_limit_with_its_value():
    text = (DOCS / "limits.md").read_text()
    for limit in limits.TABLE:
        value = f"{limit.value:,}" if isinstance(limit.value, int) else f"{limit.value:g}"
        row = [line for line in text.splitlines() if line.startswith("|") and line.split("|")[1].strip() == limit.what]
        assert len(row) == 1, limit.what
        assert re.search(rf"\b{re.escape(value)}\b", row[0]), (limit.what, value)


def test_rendered_training_images_are_bounded_up_front(capsys):
    """``--pretrain-images 1e9`` reached 13.2 GB before failing: refused by the parser now, as is
    ``Pretraining`` past the limit."""
    from ccjax import cli
    from ccjax.training import Pretraining

    with pytest.raises(SystemExit) as stop:
        cli.main(["train", ".", "--method", "FFCC", "--pretrain-camera", "Canon EOS 600D", "--pretrain-images", "1e9"])
    assert stop.value.code == 2 and "over the limit of 20,000" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        cli.main(["evaluate", ".", "--methods", "GW", "--rendered", "1e9"])
    with pytest.raises(ValueError, match="over the limit of 20,000"):
        Pretraining("Canon EOS 600D", images=10**9)


def test_sample_refuses_more_surfaces_than_it_can_hold(small_test_world):
    """100,000 scenes of every reflectance peaked at 6.7 GB: the scenes times their surfaces are
    bounded too, before anything is drawn."""
    held = 100_000 * 65  # over 6,400,000 = 100,000 scenes of 64 surfaces
    message = rf"n_scenes: 100,000 scenes x 65 surfaces = {held:,} is over the limit of 6,400,000"
    with pytest.raises(ValueError, match=message):
        ccjax.sample(jax.random.key(0), small_test_world, 100_000, 65)
    assert limits.SAMPLE_SURFACES.value == 100_000 * 64


def _refused(capsys, argv: list[str]) -> str:
    """The one error line of a command refused by its parser (usage, then the line; exit 2)."""
    from ccjax import cli

    with pytest.raises(SystemExit) as stop:
        cli.main(argv)
    err = capsys.readouterr().err
    assert stop.value.code == 2
    assert err.startswith(f"usage: ccjax {argv[0]} ")
    lines = [line for line in err.splitlines() if line.startswith(f"ccjax {argv[0]}: error: ")]
    assert len(lines) == 1, err
    return lines[0]


def test_a_comparison_refuses_more_scene_results_than_it_can_hold(capsys, small_test_world):
    """``compare --surfaces 1..300 --scenes 1000000`` grew past 1.95 GB: the scenes times the
    surface counts times the methods are bounded, refused as an option past its limit (and by
    the API, before anything is fitted)."""
    methods = ["NOTHING", "AVE-ILLUM", "GW", "DB-GW", "RETINEX", "shades-of-grey-p6", "ND-ECRULE-MV", "C-by-C-MMSE"]
    methods.append("RGB-C-by-C-MMSE")
    surfaces = "4,8,16,32,64,4"  # a repeated count is one cell
    surfaces += ",1,2,3,5,6,7"  # 11 counts
    line = _refused(capsys, ["compare", "--scenes", "1e6", "--surfaces", surfaces, "--methods", ",".join(methods)])
    held = 10**6 * 11 * len(methods)
    assert line == (
        f"ccjax compare: error: --scenes: 1,000,000 scenes x 11 surface counts x 9 methods = {held:,} is over the "
        "limit of 50,000,000 (per-scene results held by one comparison (scenes x surface counts x methods)) "
        "(see --scenes, --surfaces, --methods / n_scenes, n_surfaces, methods)"
    )
    with pytest.raises(ValueError, match=r"n_scenes: 1,000,000 scenes x 51 surface counts x 1 methods = 51,000,000"):
        experiments.sweep(small_test_world, ["GW"], list(range(1, 52)), 10**6, progress=False)


def test_indexing_refuses_images_past_the_size_limit_and_objects_past_theirs(capsys, small_test_world):
    """``indexing --size`` was unbounded (and ``--objects 10000`` tried 29.5 GB before the
    experiment went in blocks): both are refused up front, by the parser and by the API."""
    from ccjax.experiments import indexing

    line = _refused(capsys, ["indexing", "--size", "1025"])
    assert line == (
        "ccjax indexing: error: argument --size: 1,025 is over the limit of 1,024 "
        "(image side of an indexing experiment, in pixels) (see --size / size)"
    )
    assert "over the limit of 10,000" in _refused(capsys, ["indexing", "--objects", "10001"])
    with pytest.raises(ValueError, match=r"^size: 1,025 is over the limit of 1,024"):
        indexing.run_indexing(small_test_world, ["ACTUAL"], jax.random.key(0), size=1025)
    with pytest.raises(ValueError, match=r"^n_objects: 10,001 is over the limit of 10,000"):
        indexing.run_indexing(small_test_world, ["ACTUAL"], jax.random.key(0), n_objects=10_001)


def test_indexing_blocks_cover_every_image_once_in_one_shape(monkeypatch):
    from ccjax.experiments import indexing

    monkeypatch.setattr(indexing, "BLOCK_PIXELS", 3 * 16 * 16)
    got = indexing.blocks(7, 16)
    assert [len(block) for block in got] == [3, 3, 3]
    kept = np.concatenate([block[: 7 - block[0]] for block in got])
    np.testing.assert_array_equal(kept, np.arange(7))
    assert len(indexing.blocks(7, 64)) == 7  # an image larger than a block: one per block


@pytest.mark.slow
def test_the_indexing_result_does_not_depend_on_its_blocks(monkeypatch, small_test_world):
    """The experiment's images are drawn per object and per query, so blocks of 2 images (the
    last one padded) give the ranks of one block of all 6."""
    from ccjax.experiments import indexing

    def run():
        return indexing.run_indexing(
            small_test_world,
            ["ACTUAL", "NOTHING"],
            jax.random.key(1),
            n_objects=3,
            n_lights=2,
            size=16,
            n_surfaces=4,
            fit=lambda label, world: ccjax.fit(label, world),
        ).rows

    whole = run()
    monkeypatch.setattr(indexing, "BLOCK_PIXELS", 2 * 16 * 16)
    blocked = run()
    for label in whole:
        counts = [whole[label][name] for name in ("n1", "n2", "n3")]
        assert counts == [blocked[label][name] for name in ("n1", "n2", "n3")]
        assert whole[label]["rg_error"] == pytest.approx(blocked[label]["rg_error"], abs=1e-6)
    assert whole["ACTUAL"]["rg_error"] < 1e-6  # the true light: the rg error of the light itself
