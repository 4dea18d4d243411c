"""Fuzzing the public readers and the command line (hypothesis, derandomised: the same cases on
every run): generated CSV files, image files (truncated, bit-flipped, mislabelled, odd modes and
bit depths, huge headers), model records, cache entries, and option values at and past their
limits. Each gives a result or a clean refusal (a ``ValueError``; in the command line one error
line with exit status 2), never a traceback; each command's peak memory (``os.wait4`` through
``tests/fork_server.py``) stays under 2 GB."""

from __future__ import annotations

import argparse
import io as stdlib_io
import json
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
import tifffile
from fork_client import ForkServer
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from PIL import Image

from ccjax import _entries, io, limits
from ccjax.cli import common
from ccjax.experiments import sweeps
from ccjax.io import writing
from ccjax.runs import store

MEMORY_CAP_KB = 2 * 1024 * 1024
"""Peak resident memory allowed to one command (2 GB)."""

FUZZ = settings(
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow, HealthCheck.data_too_large],
)

TALLY = {"cases": 0, "exit 0": 0, "exit 2": 0, "tracebacks": 0, "over_memory": 0, "peak_mb": 0}
"""What the command-line cases gave (printed by the last test, for the closing note)."""


# ---------------------------------------------------------------------------------------------
# generated files


def _png16(rng) -> bytes:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "linear.png"
        writing.write_linear(path, rng.uniform(0.05, 0.9, (12, 16, 3)))
        return path.read_bytes()


def _pillow(rng, mode: str, format: str, **options) -> bytes:
    channels = {"RGB": 3, "RGBA": 4, "L": 1, "LA": 2, "P": 1, "I;16": 1, "CMYK": 4}[mode]
    codes = rng.integers(0, 255, (12, 16, channels), dtype=np.uint8)
    image = Image.fromarray(codes[..., 0] if channels == 1 else codes[..., :3]).convert(mode)
    buffer = stdlib_io.BytesIO()
    image.save(buffer, format=format, **options)
    return buffer.getvalue()


def _tiff(rng, dtype, samples: int) -> bytes:
    buffer = stdlib_io.BytesIO()
    data = rng.uniform(0, 1, (12, 16, samples))
    data = (data * np.iinfo(dtype).max).astype(dtype) if np.dtype(dtype).kind == "u" else data.astype(dtype)
    tifffile.imwrite(buffer, data, photometric="rgb" if samples == 3 else "minisblack", planarconfig="contig")
    return buffer.getvalue()


def base_images() -> dict[str, tuple[str, bytes]]:
    """Small valid files of many modes and depths: name -> (suffix, bytes)."""
    rng = np.random.default_rng(0)
    return {
        "png16": (".png", _png16(rng)),
        "png8": (".png", _pillow(rng, "RGB", "PNG")),
        "png-grey": (".png", _pillow(rng, "L", "PNG")),
        "png-rgba": (".png", _pillow(rng, "RGBA", "PNG")),
        "png-palette": (".png", _pillow(rng, "P", "PNG")),
        "jpeg": (".jpg", _pillow(rng, "RGB", "JPEG", quality=90)),
        "jpeg-grey": (".jpg", _pillow(rng, "L", "JPEG")),
        "jpeg-cmyk": (".jpg", _pillow(rng, "CMYK", "JPEG")),
        "tiff16": (".tif", _tiff(rng, np.uint16, 3)),
        "tiff-float": (".tif", _tiff(rng, np.float32, 3)),
        "tiff-float64": (".tif", _tiff(rng, np.float64, 3)),
        "tiff-2-samples": (".tif", _tiff(rng, np.uint16, 2)),
    }


BASES = base_images()


@st.composite
def image_files(draw) -> tuple[str, bytes]:
    """A base file, maybe truncated, bit-flipped, with a header claiming a huge size, or
    mislabelled by its suffix."""
    suffix, blob = BASES[draw(st.sampled_from(sorted(BASES)))]
    how = draw(st.sampled_from(["as is", "truncated", "flipped", "huge header", "mislabelled", "empty"]))
    if how == "truncated":
        blob = blob[: draw(st.integers(0, len(blob) - 1))]
    elif how == "flipped":
        data = bytearray(blob)
        for _ in range(draw(st.integers(1, 4))):
            data[draw(st.integers(0, len(data) - 1))] ^= 1 << draw(st.integers(0, 7))
        blob = bytes(data)
    elif how == "huge header":
        side = draw(st.sampled_from([10_000, 65_535, 100_000, 2**31 - 1]))
        if suffix == ".png":
            blob = blob[:16] + side.to_bytes(4, "big") + side.to_bytes(4, "big") + blob[24:]
        elif suffix == ".jpg" and b"\xff\xc0" in blob:
            at = blob.index(b"\xff\xc0")
            small = min(side, 65_535)
            blob = blob[: at + 5] + small.to_bytes(2, "big") + small.to_bytes(2, "big") + blob[at + 9 :]
    elif how == "mislabelled":
        suffix = draw(st.sampled_from([s for s in (".png", ".jpg", ".tif") if s != suffix]))
    elif how == "empty":
        blob = b""
    return suffix, blob


@given(image_files(), st.sampled_from(["linear", "decode", "assume"]))
@settings(FUZZ, max_examples=120)
def test_image_files_are_read_or_refused(tmp_path, file, reading):
    suffix, blob = file
    path = tmp_path / f"image{suffix}"
    path.write_bytes(blob)
    options = {"decode": {"decode_srgb": True}, "assume": {"assume_linear": True}}.get(reading, {})
    try:
        info = io.probe_image(path, **options)
        image = io.read_image(path, **options)
    except (ValueError, FileNotFoundError) as error:
        assert "\n" not in str(error) and str(path) in str(error)
        return
    rgb = np.asarray(image.rgb)
    assert rgb.shape == (info.height, info.width, 3) and rgb.dtype == np.float32
    assert np.all(np.isfinite(rgb)) and np.all(rgb >= 0)


number_texts = st.one_of(
    st.sampled_from(["0", "1", "0.5", "-1", "nan", "inf", "-inf", "1e-40", "1e38", "1e31", "", " ", "0x10", "1,5"]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.text(max_size=6),
)


@st.composite
def ground_truth_texts(draw) -> str:
    header = draw(st.sampled_from(["image,r,g,b", "file,r,g,b", "image,r,g,b,fold", "image,g,r,b", "x", ""]))
    rows = []
    for index in range(draw(st.integers(0, 6))):
        name = draw(st.one_of(st.just(f"img{index}.png"), st.text(max_size=8)))
        fields = [name, *(draw(number_texts) for _ in range(3))]
        fields += draw(st.lists(number_texts, max_size=2))
        rows.append(",".join(fields))
    return "\n".join([header, *rows]) + draw(st.sampled_from(["", "\n", "\r\n"]))


@given(ground_truth_texts(), st.sampled_from(["utf-8", "utf-8-sig", "utf-16", "latin-1"]))
@settings(FUZZ, max_examples=150)
def test_ground_truth_files_are_read_or_refused(tmp_path, text, encoding):
    path = tmp_path / "gt.csv"
    try:
        path.write_bytes(text.encode(encoding))
    except UnicodeEncodeError:
        return
    try:
        truth = io.read_ground_truth(path)
    except ValueError as error:
        assert "\n" not in str(error)
        return
    for rgb in truth.values():
        assert np.all(np.isfinite(rgb)) and np.all(rgb >= 0) and rgb.sum() > 0
        nonzero = np.abs(rgb[rgb != 0])
        assert np.all(nonzero >= limits.SMALLEST_NORMAL) and np.all(nonzero <= limits.VALUE.value)


json_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(), st.floats(allow_nan=False), st.text(max_size=8)),
    lambda inner: st.one_of(st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=12,
)


@st.composite
def model_records(draw) -> bytes:
    kind = draw(st.sampled_from(["json", "record", "deep", "bytes", "huge"]))
    if kind == "json":
        return json.dumps(draw(json_values)).encode()
    if kind == "record":
        record = {
            "format": draw(st.sampled_from([1, 2, "1", None])),
            "kind": draw(st.sampled_from(["trained-estimator", "other", 3])),
            "label": draw(st.sampled_from(["GW", "grey-edge-1-6-2", "NOPE", 5, None])),
            "camera": draw(st.sampled_from(["Canon EOS 5D Mark II", "No Such Camera", 7])),
            "world_seed": draw(st.sampled_from([0, -1, 2**40, "0", True, 1.5])),
        }
        return json.dumps(record).encode()
    if kind == "deep":
        depth = draw(st.sampled_from([65, 1000, 100_000]))
        return b"[" * depth + b"]" * depth
    if kind == "huge":
        return b'{"a": "' + b"x" * (int(limits.RECORD_BYTES.value) + 1) + b'"}'
    return draw(st.binary(max_size=64))


@given(model_records(), st.sampled_from([b"", b"\0" * 64, b"not a model"]))
@settings(FUZZ, max_examples=60)
def test_model_records_are_refused_in_one_line(tmp_path, record, leaves):
    (tmp_path / "model.json").write_bytes(record)
    (tmp_path / "model.eqx").write_bytes(leaves)
    with pytest.raises(ValueError) as caught:
        store.load_model(tmp_path / "model.eqx")
    assert "\n" not in str(caught.value) and "model" in str(caught.value)


@pytest.fixture(scope="module")
def grey_world_model(small_test_world):
    """A fitted grey-world model (its ``fallback`` is the light edited below)."""
    return store.fit("GW", small_test_world)


light_values = st.one_of(
    st.sampled_from([0.0, -0.0, 1.0, -1.0, 1e-30, 1e30, -1e-30, float("nan"), float("inf"), float("-inf")]),
    st.floats(allow_nan=True, allow_infinity=True, width=32),
)


@given(st.lists(light_values, min_size=3, max_size=3))
@example([-1.0, -1.0, -1.0])
@example([0.0, 0.0, 0.0])
@example([0.0, 0.0, 1.0])
@settings(FUZZ, max_examples=60)
def test_model_files_with_any_fallback_light_load_it_or_are_refused(tmp_path, grey_world_model, light):
    import equinox as eqx
    import jax.numpy as jnp

    from ccjax import _cache

    edited = eqx.tree_at(lambda m: m.fallback, grey_world_model, jnp.asarray(light, jnp.float32))
    path = _cache.save_model(tmp_path / "model.eqx", edited, {"label": "GW"})
    stored = np.asarray(light, np.float32).astype(np.float64)
    is_light = np.all(np.isfinite(stored)) and np.all(stored >= 0) and np.any(stored > 0)
    try:
        loaded = _cache.load_model(path, grey_world_model)
    except ValueError as error:
        assert not is_light and "\n" not in str(error) and str(path) in str(error)
        return
    assert is_light
    np.testing.assert_array_equal(np.asarray(loaded.fallback), stored.astype(np.float32))  # pyright: ignore[reportAttributeAccessIssue]


# ---------------------------------------------------------------------------------------------
# cache entries


@given(
    st.sampled_from(["the cache", "a kind's folder"]),
    st.lists(st.sampled_from(["fits", "world", "sweeps", "neural"]), min_size=1, max_size=6),
)
@settings(FUZZ, max_examples=30)
def test_a_file_in_place_of_a_cache_folder_is_said_once(where, kinds):
    import warnings

    # A fresh folder per example: the warning is said once per process and file in the way.
    with tempfile.TemporaryDirectory() as root:
        cache = Path(root) / "cache"
        blocker = cache if where == "the cache" else cache / kinds[0]
        if where != "the cache":
            cache.mkdir()
        blocker.write_text("a file")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for index, kind in enumerate(kinds):
                path = cache / kind / f"k{index}.json"
                try:
                    assert _entries.read_entry(path, kind, f"k{index}") is None
                except _entries.Rejected:
                    raise AssertionError(f"{path}: an entry that cannot exist is not a rejected one") from None
        assert [w.category for w in caught] == [_entries.CacheFolderUnusable]
        assert str(blocker) in str(caught[0].message) and "not cached" in str(caught[0].message)


@given(st.lists(st.tuples(st.sampled_from(["-cache", "-atime", ".lockfile", ""]), st.integers(0, 3)), max_size=8))
@settings(FUZZ, max_examples=40)
def test_only_empty_compiled_programs_are_removed(entries):
    from ccjax import _cache

    with tempfile.TemporaryDirectory() as root:
        folder = Path(root)
        for index, (ending, size) in enumerate(entries):
            (folder / f"jit_f{index}{ending}").write_bytes(b"x" * int(size))
        removed = {path.name for path in _cache.remove_empty_programs(folder)}
        empty = {f"jit_f{i}-cache" for i, (ending, size) in enumerate(entries) if ending == "-cache" and size == 0}
        assert removed == empty
        kept = {f"jit_f{i}{ending}" for i, (ending, _) in enumerate(entries)} - empty
        assert {path.name for path in folder.iterdir()} == kept


@pytest.fixture(scope="module")
def cached_entry(tmp_path_factory, small_test_world):
    """One real results entry of a small sweep: its record and arrays, and what a reader asks."""
    import jax

    folder = tmp_path_factory.mktemp("cache")
    previous = os.environ.get("CCJAX_CACHE")
    os.environ["CCJAX_CACHE"] = str(folder)
    try:
        model = store.fit("GW", small_test_world)
        sweeps.sweep(small_test_world, ["GW"], [4], n_scenes=20, key=jax.random.key(1), cache=True, progress=False)
    finally:
        if previous is None:
            del os.environ["CCJAX_CACHE"]
        else:
            os.environ["CCJAX_CACHE"] = previous
    (record,) = (folder / "sweeps").glob("*.json")
    from ccjax.runs.synthetic import cell_layout

    return record.read_bytes(), record.with_suffix(".npz").read_bytes(), record.stem, cell_layout(model, 20)


@given(st.data())
@settings(FUZZ, max_examples=150)
def test_cache_entries_verify_or_are_rejected(tmp_path, cached_entry, data):
    record, arrays, key, layout = cached_entry
    how = data.draw(st.sampled_from(["flip record", "flip arrays", "cut arrays", "cut record", "fields", "as is"]))
    if how.startswith("flip"):
        blob = bytearray(record if how == "flip record" else arrays)
        at = data.draw(st.integers(0, len(blob) - 1))
        blob[at] ^= 1 << data.draw(st.integers(0, 7))
        record, arrays = (bytes(blob), arrays) if how == "flip record" else (record, bytes(blob))
    elif how.startswith("cut"):
        target = arrays if how == "cut arrays" else record
        cut = target[: data.draw(st.integers(0, len(target) - 1))]
        record, arrays = (record, cut) if how == "cut arrays" else (cut, arrays)
    elif how == "fields":
        parsed = json.loads(record)
        parsed[data.draw(st.sampled_from(sorted(parsed)))] = data.draw(json_values)
        record = json.dumps(parsed).encode()
    path = tmp_path / f"{key}.json"
    path.write_bytes(record)
    path.with_suffix(".npz").write_bytes(arrays)
    try:
        entry = _entries.read_entry(path, "sweeps", key, layout)
    except _entries.Rejected as why:
        assert "\n" not in str(why)
        return
    assert entry is not None
    for name, want in layout.items():
        assert entry[1][name].shape == want.shape and np.all(np.isfinite(entry[1][name].astype(float)))


# ---------------------------------------------------------------------------------------------
# option values at and past their limits


@given(
    st.sampled_from(
        [(common.count_within(limits.SCENES), limits.SCENES), (common.seed, limits.SEED)]
        + [(common.count_within(limits.OBJECTS), limits.OBJECTS)]
    ),
    st.one_of(
        st.integers(-(2**70), 2**70).map(str),
        st.sampled_from(["0", "1", "1e6", "1e9", "1.5", "nan", "inf", "", "-0", "4294967295", "4294967296"]),
        st.text(max_size=6),
    ),
)
@settings(FUZZ, max_examples=200)
def test_count_options_give_a_value_in_range_or_one_message(parse_limit, text):
    parse, limit = parse_limit
    try:
        value = parse(text)
    except argparse.ArgumentTypeError as error:
        assert "\n" not in str(error)
        return
    assert isinstance(value, int) and 0 <= value <= limit.value


@given(st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr), st.text(max_size=6)))
@settings(FUZZ, max_examples=100)
def test_number_options_give_a_finite_value_in_range_or_one_message(text):
    try:
        value = common.number_within(limits.SHARPENING_PENALTY)(text)
    except argparse.ArgumentTypeError as error:
        assert "\n" not in str(error)
        return
    assert np.isfinite(value) and 0 <= value <= limits.SHARPENING_PENALTY.value


# ---------------------------------------------------------------------------------------------
# the command line, through the fork server


@pytest.fixture(scope="module")
def commands(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fork")
    server = ForkServer(folder, CCJAX_CACHE=str(folder / "cache"))
    yield server
    server.close()


def _check_run(commands: ForkServer, argv: list[str]) -> int:
    code, err, peak = commands.run(argv)
    TALLY["cases"] += 1
    TALLY["tracebacks"] += "Traceback" in err
    TALLY["over_memory"] += peak > MEMORY_CAP_KB
    TALLY["peak_mb"] = max(TALLY["peak_mb"], peak // 1024)
    TALLY[f"exit {code}"] = TALLY.get(f"exit {code}", 0) + 1
    assert "Traceback" not in err, (argv, err)
    assert peak <= MEMORY_CAP_KB, (argv, peak)
    assert code in (0, 2), (argv, code, err)
    if code == 2:
        errors = [line for line in err.splitlines() if ": error:" in line]
        assert len(errors) == 1 and errors[0].startswith("ccjax "), (argv, err)
    return code


PAST_LIMITS = {
    ("compare", "--scenes"): ["", "0", "-1", "nan", "1.5", "1e9", "1000001", "x"],
    ("compare", "--seed"): ["-1", "4294967296", str(2**64), "1e400", "x", ""],
    ("compare", "--surfaces"): ["", ",", "x", "1.5"],
    ("compare", "--methods"): ["", ",", " , "],
    ("sharpen", "--lambda-p"): ["nan", "inf", "-inf", "-1", "1e9", "x", ""],
    ("sharpen", "--scenes"): ["0", "1000001", "1e400"],
    ("indexing", "--objects"): ["0", "10001", "1e9"],
    ("evaluate", "--methods"): ["", ","],
}
"""Option values past a limit or malformed, per command and option."""


@given(st.sampled_from([(*option, value) for option, values in PAST_LIMITS.items() for value in values]))
@settings(FUZZ, max_examples=40)
def test_the_command_line_refuses_options_past_their_limits(commands, case):
    command, option, value = case
    # Every value here is past a limit or malformed: the command stops before any work.
    folder = ["."] if command == "evaluate" else []
    assert _check_run(commands, [command, *folder, option, value]) == 2


@pytest.mark.slow
@given(
    image_files(),
    st.sampled_from(["GW", "shades-of-grey-p6", "grey-edge-1-6-2", "grey-edge-1-6-65", "NOPE"]),
    st.sampled_from([[], ["--decode-srgb"], ["--assume-linear"]]),
    st.sampled_from([[], ["--max-pixels", "100"], ["--max-pixels", "0"], ["--max-pixels", "1e12"]]),
)
@example(BASES["png16"], "GW", [], [])
@example(BASES["jpeg"], "grey-edge-1-6-2", ["--decode-srgb"], [])
@example(BASES["tiff-float"], "shades-of-grey-p6", [], ["--max-pixels", "192"])
@settings(FUZZ, max_examples=20)
def test_estimate_on_generated_files_gives_a_result_or_one_line(commands, tmp_path, file, method, reading, budget):
    suffix, blob = file
    path = tmp_path / f"photo{suffix}"
    path.write_bytes(blob)
    _check_run(commands, ["estimate", str(path), "--method", method, "--no-progress", *reading, *budget])


def test_zz_tally(capsys):
    """The command-line cases' tally (run last in this module; printed for the closing note)."""
    with capsys.disabled():
        print(f"\nfuzz command-line cases: {TALLY}")
    assert TALLY["tracebacks"] == 0 and TALLY["over_memory"] == 0
