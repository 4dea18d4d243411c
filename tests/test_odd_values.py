"""Odd values give the exact answer or a clear refusal, never a quiet wrong one: float32 values
near the top of the range, subnormal lights, a JPEG cut short, NaN or negative penalty weights, a
model file whose leaves break its class's rules; and every refusal of the command line is one
line with exit status 2 (an empty method list, a seed or count past its limit, a record nested
100,000 deep)."""

from __future__ import annotations

import struct

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from image_files import one_line_error
from PIL import Image

import ccjax
from ccjax import cli, io, metrics
from ccjax.runs import store


def _angle(a, b) -> float:
    """The angle in degrees between two vectors, in float64 (the oracle)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    a, b = a / np.abs(a).max(), b / np.abs(b).max()
    return float(np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b)), a @ b)))


@pytest.mark.parametrize(
    ("estimate", "truth"),
    [
        ([1e38, 0, 0], [0, 1e38, 0]),
        ([1, 1, 1], [1e38, 1e38, 1e38]),
        ([1, 2, 1], [3e38, 3e38, 3e38]),
        ([3e38, 1e38, 2e38], [1, 0.5, 0.7]),
        ([1e-30, 2e-30, 1e-30], [3e37, 3e37, 1e37]),
    ],
)
def test_angular_error_is_exact_at_the_top_of_the_float32_range(estimate, truth):
    got = float(metrics.angular_error(jnp.asarray(estimate, jnp.float32), jnp.asarray(truth, jnp.float32)))
    np.testing.assert_allclose(got, _angle(estimate, truth), atol=1e-3)


@pytest.mark.parametrize("scale", [1e-30, 1.0, 1e30])
def test_shades_of_grey_is_scale_covariant_up_to_the_value_limit(scale):
    rgb = np.random.default_rng(0).uniform(0.01, 1.0, (64, 3)).astype(np.float32)
    # The oracle: 2 (mean rho^6)^(1/6) per channel, in float64.
    oracle = 2.0 * np.mean(rgb.astype(np.float64) ** 6, axis=0) ** (1 / 6)
    got = ccjax.estimate("shades-of-grey-p6", rgb * np.float32(scale))
    assert bool(got.ok)
    np.testing.assert_allclose(np.asarray(got.illuminant, np.float64) / scale, oracle, rtol=1e-5)


def test_shades_of_grey_model_near_float32_max_is_not_zero(small_test_world):
    model = store.fit("shades-of-grey-p6", small_test_world)
    rgb = np.random.default_rng(1).uniform(0.1, 1.0, (64, 3)) * 1e38
    oracle = 2.0 * np.mean((rgb / 1e38) ** 6, axis=0) ** (1 / 6) * 1e38
    got = model(jnp.asarray(rgb, jnp.float32), jnp.ones(64, bool))
    np.testing.assert_allclose(np.asarray(got.illuminant, np.float64), oracle, rtol=1e-5)


def test_values_past_the_limit_are_refused_naming_the_argument():
    with pytest.raises(ValueError, match=r"rgb: 3e\+38 is over the limit of 1e\+30"):
        ccjax.estimate("shades-of-grey-p6", np.full((8, 3), 3e38, np.float32))


@pytest.mark.parametrize(
    ("value", "message"), [("1e-40", "below float32's smallest normal"), ("1e31", "over the limit")]
)
def test_ground_truth_outside_the_normal_float32_range_is_refused(tmp_path, value, message):
    path = tmp_path / "gt.csv"
    path.write_text(f"image,r,g,b\na.png,0.5,0.4,0.3\nb.png,{value},{value},{value}\n")
    with pytest.raises(ValueError, match=rf"line 3: r,g,b: .*{message}"):
        io.read_ground_truth(path)


def _jpeg(path, size=(48, 64), **options) -> np.ndarray:
    rng = np.random.default_rng(2)
    pixels = (rng.uniform(0.2, 0.8, (*size, 3)) * 255).astype(np.uint8)
    Image.fromarray(pixels).save(path, quality=95, **options)
    return pixels


def test_a_jpeg_cut_short_is_an_error_not_a_grey_filled_image(tmp_path):
    _jpeg(tmp_path / "whole.jpg")
    blob = (tmp_path / "whole.jpg").read_bytes()
    (tmp_path / "half.jpg").write_bytes(blob[: len(blob) // 2])
    assert io.read_image(tmp_path / "whole.jpg", decode_srgb=True).rgb.shape == (48, 64, 3)
    with pytest.raises(ValueError, match=r"half\.jpg.*cut short"):
        io.read_image(tmp_path / "half.jpg", decode_srgb=True)


def test_a_folder_with_a_jpeg_cut_short_names_it_and_exits_2(tmp_path, plain_preview_commands, capsys):
    folder = tmp_path / "photos"
    folder.mkdir()
    _jpeg(folder / "whole.jpg")
    blob = (folder / "whole.jpg").read_bytes()
    (folder / "half.jpg").write_bytes(blob[: len(blob) // 2])
    assert cli.main(["estimate", str(folder), "--method", "GW", "--decode-srgb", "--no-progress"]) == 2
    captured = capsys.readouterr()
    assert "whole.jpg" in captured.out and "Traceback" not in captured.err
    assert "half.jpg" in captured.err and "cut short" in captured.err


def _sof_patched(blob: bytes, height: int, width: int) -> bytes:
    """The JPEG with its frame header (SOF0) claiming ``height x width``."""
    at = blob.index(b"\xff\xc0")
    return blob[: at + 5] + struct.pack(">HH", height, width) + blob[at + 9 :]


def test_the_pixel_budget_not_pillows_own_limit_decides(tmp_path):
    _jpeg(tmp_path / "small.jpg")
    (tmp_path / "claim.jpg").write_bytes(_sof_patched((tmp_path / "small.jpg").read_bytes(), 15000, 15000))
    # 225 MP: over Pillow's 179 MP, under a raised budget; the header is read, not refused by Pillow.
    info = io.probe_image(tmp_path / "claim.jpg", decode_srgb=True, max_pixels=300_000_000)
    assert (info.height, info.width) == (15000, 15000)
    with pytest.raises(ValueError, match="--max-pixels"):
        io.probe_image(tmp_path / "claim.jpg", decode_srgb=True)
    # Within the raised budget, its few kilobytes cannot hold 225 MP: refused before decoding
    # (libjpeg would fill the missing blocks with grey and only warn).
    with pytest.raises(ValueError, match=r"more than its .* bytes can hold"):
        io.read_image(tmp_path / "claim.jpg", decode_srgb=True, max_pixels=300_000_000)


def test_a_jpeg_whose_header_claims_more_than_its_data_is_refused(tmp_path):
    _jpeg(tmp_path / "small.jpg", size=(8, 8))
    (tmp_path / "claim.jpg").write_bytes(_sof_patched((tmp_path / "small.jpg").read_bytes(), 10000, 10000))
    with pytest.raises(ValueError, match=r"claims 100,000,000 pixels, more than its \d+ bytes can hold"):
        io.read_image(tmp_path / "claim.jpg", decode_srgb=True)


@pytest.mark.parametrize("weight", [float("nan"), float("inf"), -5.0, 1e9])
def test_sharpening_penalty_weights_are_checked(small_test_world, weight):
    from ccjax import sharpening

    with pytest.raises(ValueError, match="lambda_p"):
        sharpening.new_sharpening(small_test_world, lambda_p=weight)


@pytest.mark.parametrize("p", [-5.0, 0.5, float("nan")])
def test_a_model_file_with_a_broken_minkowski_p_is_refused(tmp_path, p):
    model = store.fit("grey-edge-1-6-2", store.world("default", "Canon EOS 5D Mark II"))
    broken = eqx.tree_at(lambda m: m.p, model, jnp.asarray(p, model.p.dtype))
    path = store.save_trained(tmp_path / "edge.eqx", broken, label="grey-edge-1-6-2", camera="Canon EOS 5D Mark II")
    with pytest.raises(ValueError, match=r"edge\.eqx.*(Minkowski|non-finite)"):
        store.load_model(path)


def test_grey_edge_sigma_has_a_limit():
    with pytest.raises(ValueError, match=r"sigma: 2000 is over the limit of 64"):
        ccjax.estimate("grey-edge-1-6-2000", np.ones((64, 48, 3), np.float32))


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["compare", "--methods", ""], ["--methods", "expected comma-separated labels"]),
        (["evaluate", ".", "--methods", ""], ["--methods", "expected comma-separated labels"]),
        (["compare", "--seed", str(10**23)], ["--seed", "over the limit"]),
        (["compare", "--scenes", str(10**9)], ["--scenes", "over the limit"]),
        (["indexing", "--objects", str(10**9)], ["--objects", "over the limit"]),
        (["sharpen", "--lambda-p", "nan"], ["--lambda-p", "finite"]),
        (["sharpen", "--lambda-p", "-5"], ["--lambda-p", ">= 0"]),
    ],
)
def test_options_past_their_limits_are_one_error_line_with_exit_2(argv, needles, capsys):
    with pytest.raises(SystemExit) as exit:
        cli.main(argv)
    assert exit.value.code == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    errors = [line for line in captured.err.splitlines() if "error:" in line]
    assert len(errors) == 1 and all(needle in errors[0] for needle in needles), captured.err


def test_a_model_record_nested_100000_deep_is_one_line(tmp_path, plain_preview_commands, capsys):
    (tmp_path / "deep.eqx").write_bytes(b"")
    (tmp_path / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    image = tmp_path / "a.png"
    from image_files import textured_image

    textured_image(image)
    assert cli.main(["estimate", str(image), "--model", str(tmp_path / "deep.eqx")]) == 2
    one_line_error(capsys.readouterr(), "deep.json", "nested")
