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
from ccjax import io, limits
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
    n = limits.SAMPLE_SCENES.value + 1
    with pytest.raises(ValueError, match=r"n_scenes: 100,001 is over the limit of 100,000"):
        ccjax.sample(jax.random.key(0), small_test_world, n, 4)


def test_a_synthetic_run_refuses_more_scenes_than_the_limit():
    with pytest.raises(ValueError, match=r"n_scenes: 1,000,001 is over the limit of 1,000,000 .*--scenes"):
        synthetic.SyntheticSource(jax.random.key(0), (4,), limits.SCENES.value + 1)


def test_a_ground_truth_file_past_the_row_limit_is_refused(tmp_path):
    path = tmp_path / "gt.csv"
    rows = "".join(f"i{i}.png,0.5,0.4,0.3\n" for i in range(limits.CSV_ROWS.value + 1))
    path.write_text("image,r,g,b\n" + rows)
    with pytest.raises(ValueError, match=r"gt\.csv: line 100002 is past the limit of 100,000"):
        io.read_ground_truth(path)


def test_a_ground_truth_file_past_the_byte_limit_is_refused_from_its_size(tmp_path, monkeypatch):
    path = tmp_path / "gt.csv"
    with open(path, "wb") as handle:
        handle.truncate(limits.CSV_BYTES.value + 1)  # sparse: no disk used
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
