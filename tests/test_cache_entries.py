"""Every kind of cache entry is read through one verified path: a truncated, bit-flipped or edited
entry of compare's results, correct's previews or the pretraining renders, or one whose facts,
shapes, dtypes or values are not what the caller asked for, is recomputed with one warning line and
replaced; never raised as ``BadZipFile``, never printed as results.

Forged entries follow the documented layout with an independently computed digest (sha256 of the
facts' canonical JSON, then each array's name, dtype, shape and bytes), so the checks tested are
the ones a recomputed checksum does not pass."""

from __future__ import annotations

import hashlib
import io
import json
import shutil
import warnings
import zipfile

import jax
import numpy as np
import pytest

from ccjax.experiments import sweeps
from ccjax.io import preview
from ccjax.preprocessing import Preprocessing
from ccjax.training import Pretraining, render_examples

N_SCENES = 50


def _digest(kind, key, skeleton, arrays) -> str:
    hasher = hashlib.sha256(f"{kind}\n{key}\n".encode())
    hasher.update(json.dumps(skeleton, sort_keys=True, separators=(",", ":")).encode())
    for name in sorted(arrays):
        array = np.ascontiguousarray(arrays[name])
        hasher.update(f"\n{name} {array.dtype.str} {array.shape}\n".encode())
        hasher.update(array.tobytes())
    return hasher.hexdigest()


def _forge(record_path, arrays, **changes) -> None:
    """Rewrite an entry's arrays (and record fields) with a digest recomputed to match."""
    record = json.loads(record_path.read_text())
    record.update(changes)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    record_path.with_suffix(".npz").write_bytes(buffer.getvalue())
    record["digest"] = _digest(record["kind"], record["key"], record["skeleton"], arrays)
    record_path.write_text(json.dumps(record))


def _arrays(record_path) -> dict[str, np.ndarray]:
    with np.load(record_path.with_suffix(".npz")) as stored:
        return {name: stored[name] for name in stored.files}


def _sweep(world, labels=("GW",)):
    return sweeps.sweep(world, list(labels), [4], n_scenes=N_SCENES, key=jax.random.key(5), cache=True, progress=False)


def _one_rejection(call):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = call()
    rejected = [w for w in caught if type(w.message).__name__ == "CacheEntryRejected"]
    assert len(rejected) == 1, [str(w.message) for w in caught]
    assert "does not verify" in str(rejected[0].message) and "\n" not in str(rejected[0].message)
    return result, str(rejected[0].message)


@pytest.fixture
def cached_cell(tmp_path, monkeypatch, small_test_world):
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path))
    fresh = _sweep(small_test_world)
    (record,) = (tmp_path / "sweeps").glob("*.json")
    return small_test_world, fresh.errors["GW"][4], record


def _damage(record, how: str, other=None) -> None:
    blob = record.with_suffix(".npz").read_bytes()
    if how == "truncated":
        record.with_suffix(".npz").write_bytes(blob[: len(blob) // 2])
    elif how == "bit flip":
        flipped = bytearray(blob)
        flipped[len(blob) // 3] ^= 0x04
        record.with_suffix(".npz").write_bytes(bytes(flipped))
    elif how == "empty":
        record.with_suffix(".npz").write_bytes(b"")
    elif how == "record not an object":
        record.write_text("[1, 2]")
    elif how == "wrong field types":
        text = json.loads(record.read_text())
        record.write_text(json.dumps({**text, "schema": "1", "key": [text["key"]], "digest": 3}))
    elif how == "nested record":
        record.write_text("[" * 100_000 + "]" * 100_000)


@pytest.mark.parametrize(
    "how", ["truncated", "bit flip", "empty", "record not an object", "wrong field types", "nested record"]
)
def test_a_damaged_results_entry_is_recomputed_with_one_warning(cached_cell, how):
    world, fresh, record = cached_cell
    _damage(record, how)
    again, _ = _one_rejection(lambda: _sweep(world))
    assert again.cells_from_cache == 0
    for name, values in fresh.items():
        np.testing.assert_array_equal(again.errors["GW"][4][name], values)
    # Replaced: the next run reads it without a word.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _sweep(world).cells_from_cache == 1


def _ten_of_fifty(arrays):
    return {name: value[:10] for name, value in arrays.items()}


def _nan(arrays):
    return {**arrays, "angular": np.full_like(arrays["angular"], np.nan)}


def _over_180(arrays):
    return {**arrays, "angular": arrays["angular"] + 200.0}


def _float_status(arrays):
    return {**arrays, "status": np.zeros(N_SCENES, np.float32), "ok": np.zeros(N_SCENES, np.float32)}


def _missing_statistic(arrays):
    return {name: value for name, value in arrays.items() if name != "rg"}


@pytest.mark.parametrize(
    ("forge", "reason"),
    [
        (_ten_of_fifty, "shape"),
        (_nan, "non-finite"),
        (_over_180, "outside"),
        (_float_status, "expected kind"),
        (_missing_statistic, "arrays"),
    ],
)
def test_a_results_entry_with_a_recomputed_digest_but_other_arrays_is_recomputed(cached_cell, forge, reason):
    world, fresh, record = cached_cell
    _forge(record, forge(_arrays(record)))
    again, message = _one_rejection(lambda: _sweep(world))
    assert reason in message
    assert again.cells_from_cache == 0
    np.testing.assert_array_equal(again.errors["GW"][4]["angular"], fresh["angular"])


def test_another_methods_results_under_this_key_are_recomputed(tmp_path, monkeypatch, small_test_world):
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path))
    fresh = _sweep(small_test_world, ("GW", "RETINEX"))
    records = sorted((tmp_path / "sweeps").glob("*.json"))
    by_label = {json.loads(r.read_text())["label"]: r for r in records}
    assert not np.array_equal(fresh.errors["GW"][4]["angular"], fresh.errors["RETINEX"][4]["angular"])
    # RETINEX's files copied over GW's (both the arrays and the record, or the arrays alone).
    for suffixes in ((".npz",), (".npz", ".json")):
        for suffix in suffixes:
            shutil.copy(by_label["RETINEX"].with_suffix(suffix), by_label["GW"].with_suffix(suffix))
        again, _ = _one_rejection(lambda: _sweep(small_test_world, ("GW",)))
        np.testing.assert_array_equal(again.errors["GW"][4]["angular"], fresh.errors["GW"][4]["angular"])
    # Its arrays with GW's key and a recomputed digest, but RETINEX's facts: refused by the facts.
    _forge(
        by_label["GW"],
        _arrays(by_label["RETINEX"]),
        skeleton={**json.loads(by_label["RETINEX"].read_text())["skeleton"]},
    )
    again, message = _one_rejection(lambda: _sweep(small_test_world, ("GW",)))
    assert "facts" in message
    np.testing.assert_array_equal(again.errors["GW"][4]["angular"], fresh.errors["GW"][4]["angular"])


def test_a_header_claiming_more_than_its_bytes_is_refused_before_allocating(cached_cell, monkeypatch):
    world, fresh, record = cached_cell
    arrays = _arrays(record)
    with zipfile.ZipFile(record.with_suffix(".npz"), "w", zipfile.ZIP_STORED) as archive:
        for name, value in arrays.items():
            header = io.BytesIO()
            shape = (10**12,) if name == "angular" else value.shape  # 8 TB claimed, 200 bytes held
            np.lib.format.write_array_header_1_0(
                header, {"descr": value.dtype.str, "fortran_order": False, "shape": shape}
            )
            archive.writestr(f"{name}.npy", header.getvalue() + value.tobytes())
    monkeypatch.setattr(np.lib.format, "read_array", lambda *a, **k: pytest.fail("an array was read"))
    again, message = _one_rejection(lambda: _sweep(world))
    assert "header claims" in message
    np.testing.assert_array_equal(again.errors["GW"][4]["angular"], fresh["angular"])


@pytest.mark.parametrize("how", ["truncated", "bit flip", "wrong field types"])
def test_a_damaged_preview_entry_is_recomputed(tmp_path, monkeypatch, small_test_world, how):
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path))
    fresh = preview.preview_matrix_cached(small_test_world)
    (record,) = (tmp_path / "preview").glob("*.json")
    _damage(record, how)
    again, _ = _one_rejection(lambda: preview.preview_matrix_cached(small_test_world))
    np.testing.assert_array_equal(again, fresh)


def test_a_preview_entry_with_a_recomputed_digest_and_zeros_of_another_shape_is_recomputed(
    tmp_path, monkeypatch, small_test_world
):
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path))
    fresh = preview.preview_matrix_cached(small_test_world)
    (record,) = (tmp_path / "preview").glob("*.json")
    _forge(record, {"matrix": np.zeros((3, 4), np.float32)})
    again, _ = _one_rejection(lambda: preview.preview_matrix_cached(small_test_world))
    np.testing.assert_array_equal(again, fresh)


@pytest.mark.parametrize("how", ["truncated", "bit flip", "forged: 1 of 3 images"])
def test_a_damaged_pretraining_entry_is_rendered_again(tmp_path, monkeypatch, how):
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path))
    setting = Pretraining("Canon EOS 600D", images=3, height=8, width=8, patches=4)
    rule = Preprocessing.parse("pixels")
    fresh = render_examples(setting, rule, "image")
    (record,) = (tmp_path / "pretraining").glob("*.json")
    if how.startswith("forged"):
        _forge(record, {name: value[:1] for name, value in _arrays(record).items()})
    else:
        _damage(record, how)
    again, _ = _one_rejection(lambda: render_examples(setting, rule, "image"))
    np.testing.assert_array_equal(np.asarray(again.x), np.asarray(fresh.x))
    np.testing.assert_array_equal(np.asarray(again.illuminant), np.asarray(fresh.illuminant))
