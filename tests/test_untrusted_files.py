"""Nothing from a file is trusted: a header's size is checked against the pixel budget before
anything is allocated (a bad header is one file's failure, the run goes on), option files
(sharpening matrices, trained models) are checked and bounded, and odd files are named."""

from __future__ import annotations

import json
import struct
import zlib

import jax.numpy as jnp
import numpy as np
import pytest
import tifffile
from image_files import textured_image

from ccjax import cli, io
from ccjax.io import reading, writing
from ccjax.runs import folders, sources

SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(data, zlib.crc32(kind)))


def claiming_png(path, width: int, height: int, idat: bytes = b"") -> None:
    """A 16-bit RGB PNG whose header claims ``width x height`` pixels, with ``idat`` as its data."""
    header = struct.pack(">IIBBBBB", width, height, 16, 2, 0, 0, 0)
    path.write_bytes(SIGNATURE + _chunk(b"IHDR", header) + _chunk(b"IDAT", idat) + _chunk(b"IEND", b""))


def png_bomb(path, side: int) -> None:
    """A real, valid ``side x side`` 16-bit RGB PNG of zeros: a small file that decodes to
    ``6 side^2`` bytes (12000: 144 MP, 864 MB of samples)."""
    compressor = zlib.compressobj(9)
    row = bytes(1 + 6 * side)  # filter byte 0 + the samples
    parts = [compressor.compress(row) for _ in range(side)]
    parts.append(compressor.flush())
    claiming_png(path, side, side, b"".join(parts))


@pytest.fixture
def setup(plain_preview_commands):
    return plain_preview_commands


_image = textured_image


# ---------------------------------------------------------------------------------------------
# the pixel budget


def test_a_74_byte_header_claiming_100000_squared_is_refused_from_the_header(tmp_path, monkeypatch):
    claiming_png(tmp_path / "claim.png", 100_000, 100_000, zlib.compress(b"\0" * 7))
    assert (tmp_path / "claim.png").stat().st_size < 100
    monkeypatch.setattr(reading, "_read_pixels", lambda *a: pytest.fail("pixels decoded past the budget"))
    for call in (io.probe_image, io.read_image):
        with pytest.raises(ValueError, match=r"claim\.png claims 100000x100000 pixels \(10000\.0 MP\).*100 MP"):
            call(tmp_path / "claim.png")


def test_the_12000_squared_png_bomb_is_refused_from_its_header(tmp_path, monkeypatch):
    png_bomb(tmp_path / "bomb.png", 12000)
    assert (tmp_path / "bomb.png").stat().st_size < 2_000_000  # 864 MB of samples in under 2 MB
    assert io.png_header(tmp_path / "bomb.png").width == 12000
    monkeypatch.setattr(reading, "_read_pixels", lambda *a: pytest.fail("pixels decoded past the budget"))
    with pytest.raises(ValueError, match=r"bomb\.png claims 12000x12000 pixels \(144\.0 MP\)"):
        io.read_image(tmp_path / "bomb.png")
    source = sources.image_folder([tmp_path / "bomb.png"])
    assert source.usable() == [] and "144.0 MP" in source.failures[str(tmp_path / "bomb.png")]


def test_the_budget_is_an_option_and_a_48_mp_header_passes(tmp_path, small_test_world):
    claiming_png(tmp_path / "camera.png", 8000, 6000)
    assert io.probe_image(tmp_path / "camera.png").width == 8000  # 48 MP: inside the default budget
    with pytest.raises(ValueError, match=r"48\.0 MP\), more than the pixel budget of 40 MP"):
        io.probe_image(tmp_path / "camera.png", max_pixels=40_000_000)
    tifffile.imwrite(tmp_path / "small.tif", np.ones((10, 10, 3), np.uint16), photometric="rgb")
    assert io.read_image(tmp_path / "small.tif", max_pixels=100).shape == (10, 10)
    with pytest.raises(ValueError, match=r"small\.tif claims 10x10 pixels"):
        io.read_image(tmp_path / "small.tif", max_pixels=99)
    run = folders.estimate_folder(tmp_path / "small.tif", "GW", world=small_test_world, max_pixels=99)
    assert run.done.tolist() == [False] and "claims 10x10 pixels" in run.failures[str(tmp_path / "small.tif")]
    assert folders.estimate_folder(tmp_path / "small.tif", "GW", world=small_test_world).done.tolist() == [True]


def test_a_mask_is_checked_from_its_header_before_decoding(tmp_path, monkeypatch):
    claiming_png(tmp_path / "mask.png", 100_000, 100_000)
    monkeypatch.setattr(reading, "_read_pixels", lambda *a: pytest.fail("a mask of the wrong size was decoded"))
    with pytest.raises(ValueError, match=r"mask: .*mask\.png is 100000x100000 pixels .* its image is 8x6"):
        io.read_mask(tmp_path / "mask.png", (6, 8))


@pytest.mark.parametrize("command", ["estimate", "evaluate"])
def test_a_folder_with_a_bomb_header_reports_the_good_image_and_exits_2(setup, capsys, command):
    folder = setup / "set"
    folder.mkdir()
    _image(folder / "good.png")
    claiming_png(folder / "claim.png", 100_000, 100_000, zlib.compress(b"\0" * 7))
    (folder / "gt.csv").write_text("image,r,g,b\ngood.png,1,1,1\nclaim.png,1,1,1\n")
    if command == "estimate":
        argv = ["estimate", str(folder), "--method", "GW", "--no-progress"]
    else:
        argv = ["evaluate", str(folder), "--ground-truth", str(folder / "gt.csv"), "--methods", "GW", "--no-progress"]
    assert cli.main(argv) == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err and "RESOURCE_EXHAUSTED" not in captured.err
    assert "1 of 2 images cannot be used" in captured.err and "claim.png claims 100000x100000" in captured.err
    if command == "estimate":
        assert "good.png" in captured.out and "claim.png" not in captured.out
    else:
        assert "GW" in captured.out, captured.out


def test_the_warm_up_compiles_only_the_sizes_that_pass_the_budget(tmp_path, monkeypatch, small_test_world):
    from ccjax.runs import images as run_images
    from ccjax.runs import store

    _image(tmp_path / "good.png")
    claiming_png(tmp_path / "big.png", 9, 9)  # passes only without a budget of 50
    shapes = []
    real = run_images._timed

    def timed(model, rgb, mask):
        shapes.append(tuple(rgb.shape))
        return real(model, rgb, mask)

    monkeypatch.setattr(run_images, "_timed", timed)
    source = sources.image_folder(tmp_path, max_pixels=50)
    run = run_images.run_models(source, {"GW": [store.fit("GW", small_test_world)]})
    assert shapes and all(shape[0] * shape[1] <= 36 for shape in shapes), shapes
    assert run.done.tolist() == [False, True] and "big.png claims 9x9" in run.failures[str(tmp_path / "big.png")]


# ---------------------------------------------------------------------------------------------
# odd files


def test_a_multi_page_tiff_is_refused_not_read_as_its_first_page(tmp_path):
    codes = np.full((8, 8, 3), 20000, np.uint16)
    with tifffile.TiffWriter(tmp_path / "pages.tif") as tif:
        tif.write(codes, photometric="rgb")
        tif.write(codes[:4], photometric="rgb")
    with pytest.raises(ValueError, match=r"pages\.tif.*holds 2 images \(pages\)"):
        io.read_image(tmp_path / "pages.tif")
    tifffile.imwrite(tmp_path / "stack.tif", np.stack([codes] * 3), photometric="rgb")
    with pytest.raises(ValueError, match=r"stack\.tif"):
        io.probe_image(tmp_path / "stack.tif")


def _png_with(blob: bytes, kind: bytes, data: bytes) -> bytes:
    at = len(SIGNATURE) + 25  # after IHDR
    return blob[:at] + _chunk(kind, data) + blob[at:]


@pytest.mark.parametrize(
    ("kind", "data", "refused"),
    [
        (b"sRGB", b"\x00", "sRGB"),
        (b"gAMA", struct.pack(">I", 45455), "gAMA 0.45455"),
        (b"gAMA", struct.pack(">I", 100000), None),
    ],
)
def test_a_16_bit_png_tagged_as_gamma_encoded_is_refused(tmp_path, kind, data, refused):
    writing.write_png(tmp_path / "plain.png", np.full((4, 4, 3), 30000, np.uint16))
    (tmp_path / "tagged.png").write_bytes(_png_with((tmp_path / "plain.png").read_bytes(), kind, data))
    if refused is None:  # gamma 1.0 declares linear data
        assert io.read_image(tmp_path / "tagged.png").shape == (4, 4)
        return
    with pytest.raises(ValueError, match=rf"tagged\.png is tagged {refused}: .*--assume-linear"):
        io.read_image(tmp_path / "tagged.png")
    image = io.read_image(tmp_path / "tagged.png", assume_linear=True)
    np.testing.assert_allclose(image.rgb, 30000 / 65535, rtol=1e-6)


def test_a_device_is_not_a_regular_file_and_not_missing(tmp_path):
    for call in (io.probe_image, io.read_image):
        with pytest.raises(ValueError, match=r"image: /dev/zero is not a regular file"):
            call("/dev/zero")
        with pytest.raises(FileNotFoundError, match="no such file"):
            call(tmp_path / "absent.png")


def test_a_newline_in_a_file_name_stays_on_its_row_and_numbers_stay_apart(setup, capsys):
    folder = setup / "set"
    folder.mkdir()
    _image(folder / "two\nlines.png")
    assert cli.main(["estimate", str(folder), "--method", "GW", "--no-progress"]) == 0
    rows = capsys.readouterr().out.strip().splitlines()
    assert len(rows) == 2 and rows[1].startswith(str(folder / "two\\nlines.png"))
    from ccjax.cli import estimate as estimate_command

    assert estimate_command.printable("a\tb\x1bc") == "a\\tb\\x1bc" and estimate_command.printable("ä b") == "ä b"


def test_the_estimate_table_separates_large_numbers(setup, capsys, monkeypatch):
    from ccjax.runs.images import ImageRun

    _image(setup / "a.png")
    run = ImageRun(
        paths=[str(setup / "a.png")],
        items=np.array([0]),
        done=np.array([True]),
        estimates={"GW": np.array([[123.45678, 1000.5, 0.5]], np.float32)},
        ok={"GW": np.array([True])},
        status={"GW": np.array([0], np.int32)},
    )
    monkeypatch.setattr("ccjax.runs.estimate_folder", lambda *a, **k: run)
    assert cli.main(["estimate", str(setup / "a.png"), "--method", "GW", "--no-progress"]) == 0
    row = capsys.readouterr().out.strip().splitlines()[1].split()
    # A light in the hundreds (a relaxed solution's raw magnitude) is printed with its largest channel 1.
    want = [123.45678 / 1000.5, 1.0, 0.5 / 1000.5]
    assert [float(value) for value in row[1:4]] == pytest.approx(want, abs=6e-6)


def test_grey_world_with_an_all_zero_channel_falls_back(small_test_world):
    from ccjax.runs import store

    model = store.fit("GW", small_test_world)
    rgb = np.array([[0.2, 0.3, 0.0], [0.4, 0.1, 0.0]], np.float32)
    estimate = model(jnp.asarray(rgb), jnp.ones(2, bool))
    assert not bool(estimate.ok)
    np.testing.assert_allclose(estimate.illuminant, np.asarray(model.fallback), rtol=1e-6)


def test_grey_edge_on_a_pixel_list_and_estimate_batch_on_lists_are_clear(small_test_world):
    import jaxtyping

    from ccjax.estimators.base import estimate_batch
    from ccjax.runs import store

    model = store.fit("grey-edge-1-6-2", small_test_world)
    # The library runs without the suite's runtime type checks: the model's own check speaks.
    jaxtyping.config.update("jaxtyping_disable", True)
    try:
        with pytest.raises(ValueError, match=r"grey edge takes an image \(H, W, 3\).*\(5, 3\)"):
            model(jnp.ones((5, 3)), jnp.ones(5, bool))
        listed = estimate_batch(store.fit("GW", small_test_world), [[[0.5, 0.4, 0.3]]], [[True]])
    finally:
        jaxtyping.config.update("jaxtyping_disable", False)
    np.testing.assert_allclose(np.asarray(listed.illuminant)[0] / np.max(listed.illuminant), [1.0, 0.8, 0.6], rtol=1e-5)


# ---------------------------------------------------------------------------------------------
# option files


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("npz", "not a single .npy array"),
        ("dev", "is not a regular file"),
        ("big", "over 65536 bytes"),
        ("text", "invertible 3x3"),
        ("binary", "cannot read"),
    ],
)
def test_bad_sharpening_files_are_one_line_errors(setup, capsys, content, message):
    source = _image(setup / "in.png")
    path = {"dev": "/dev/zero"}.get(content, str(setup / "t.npy"))
    if content == "npz":
        np.savez(setup / "t.npz", a=np.eye(3))
        (setup / "t.npz").rename(path)
    elif content == "big":
        (setup / "t.npy").write_bytes(b"0" * 70000)
    elif content == "text":
        path = str(setup / "t.txt")
        (setup / "t.txt").write_text("1 0\n0 1\n")
    elif content == "binary":
        path = str(setup / "t.txt")
        (setup / "t.txt").write_bytes(b"\xff\xfe\x00garbage")
    argv = ["correct", str(source), str(setup / "o.png"), "--method", "GW", "--sharpening", path, "--no-progress"]
    assert cli.main(argv) == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err and "--sharpening" in captured.err and message in captured.err
    assert not (setup / "o.png").exists()


@pytest.mark.parametrize(
    ("record", "message"),
    [
        ([1, 2], "is a JSON list, not an object"),
        ({"kind": "trained-estimator", "label": "GW"}, "gives camera None; expected a str"),
        ({"kind": "trained-estimator", "label": ["GW"], "camera": "x"}, "gives label ['GW']; expected a str"),
        ({"kind": "trained-estimator", "label": "GW", "camera": "x", "world_seed": "0"}, "world_seed '0'"),
    ],
)
def test_bad_model_records_are_one_line_errors(setup, capsys, record, message):
    from ccjax._cache import FORMAT_VERSION

    if isinstance(record, dict):
        record = {"format": FORMAT_VERSION, **record}
    (setup / "m.eqx").write_bytes(b"")
    (setup / "m.json").write_text(json.dumps(record))
    source = _image(setup / "in.png")
    assert cli.main(["estimate", str(source), "--model", str(setup / "m.eqx"), "--no-progress"]) == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err and message in captured.err, captured.err


# ---------------------------------------------------------------------------------------------
# tiles


@pytest.mark.slow
def test_tiled_grey_edge_equals_the_whole_image(monkeypatch):
    from ccjax.estimators import spatial, tiles
    from ccjax.estimators.spatial import GreyEdge

    rng = np.random.default_rng(3)
    pixels = rng.uniform(0.0, 1.0, (97, 61, 3)).astype(np.float32)
    pixels[:, 30:] *= np.array([1.0, 0.7, 0.4], np.float32)  # an edge with colour
    image, mask = jnp.asarray(pixels), jnp.asarray(rng.uniform(size=(97, 61)) > 0.02)
    # Each setting against two tilings; across the settings every tiling is tried twice: one row
    # a tile, a height that does not divide the image's, a few tiles, exactly one, one past it.
    tilings = (
        ((1, 2.0, 6.0), (1, 200)),
        ((2, 1.0, 2.0), (5, 97)),
        ((0, 0.0, 1.0), (40, 1)),
        ((1, 0.0, np.inf), (97, 5)),
        ((0, 1.0, 8.0), (200, 40)),
    )
    for (order, sigma, p), rows_tried in tilings:
        whole = spatial.edge_norms(image, mask, order, sigma, p)
        for rows in rows_tried:
            tiled = spatial.edge_norms(image, mask, order, sigma, p, rows=rows)
            np.testing.assert_allclose(tiled[0], whole[0], rtol=2e-6, err_msg=str((order, sigma, p, rows)))
            assert bool(tiled[1]) == bool(whole[1]) and float(tiled[2]) == float(whole[2])
    model = GreyEdge(p=6.0, fallback=jnp.ones(3), order=1, sigma=2.0)
    untiled = model(image, mask)
    monkeypatch.setattr(tiles, "TILE_PIXELS", 61 * 8)  # 8-row tiles
    assert tiles.tile_rows(97, 61) == 8
    np.testing.assert_allclose(model(image, mask).illuminant, untiled.illuminant, rtol=2e-6)


def test_tiled_masked_mean_equals_numpy(monkeypatch):
    from ccjax.estimators import tiles
    from ccjax.preprocessing import masked_mean

    rng = np.random.default_rng(4)
    pixels = rng.uniform(0.0, 1.0, (53, 17, 3)).astype(np.float32)
    usable = rng.uniform(size=(53, 17)) > 0.3
    want = pixels[usable].astype(np.float64).mean(axis=0)
    image, mask = jnp.asarray(pixels), jnp.asarray(usable)
    np.testing.assert_allclose(masked_mean(image, mask), want, rtol=1e-6)
    monkeypatch.setattr(tiles, "TILE_PIXELS", 17 * 5)
    np.testing.assert_allclose(masked_mean(image, mask), want, rtol=1e-6)


def test_pieces_of_rows_give_the_whole_images_codes_and_preview(tmp_path, monkeypatch):
    rng = np.random.default_rng(5)
    rgb = rng.uniform(-0.1, 1.2, (31, 9, 3)).astype(np.float32)
    want = np.round(np.clip(rgb.astype(np.float64), 0.0, 1.0) * 65535).astype(np.uint16)
    monkeypatch.setattr(writing, "CHUNK_VALUES", 27 * 4)
    assert len(writing.row_slices(rgb.shape)) == 8
    np.testing.assert_array_equal(io.quantise(rgb), want)
    matrix = np.array([[1.2, -0.1, -0.1], [-0.2, 1.1, 0.1], [0.0, -0.3, 1.3]], np.float32)
    linear = rgb @ matrix.T
    scale = np.percentile(linear.max(axis=-1), 99.0)
    clipped = np.clip(linear / scale, 0.0, 1.0)
    curve = np.where(clipped <= 0.0031308, 12.92 * clipped, 1.055 * np.power(clipped, 1 / 2.4) - 0.055)
    np.testing.assert_array_equal(io.srgb_preview(rgb, matrix), np.round(curve * 255).astype(np.uint8))
