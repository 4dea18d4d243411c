"""The store (``ccjax.runs.store``): one memory-plus-disk cache of worlds and fitted models whose
files are data only. A cache entry that does not verify (a planted class name, a damaged or edited
file) runs nothing, is refitted with one ``CacheEntryRejected`` warning and replaced; a second
process reads what the first fitted.

The digests below are computed here from the documented layout (sha256 of the skeleton's canonical
JSON, then each array's name, dtype, shape and bytes in name order), independently of the store."""

from __future__ import annotations

import hashlib
import io
import json
import os
import subprocess
import sys
import textwrap
import warnings
from typing import ClassVar

import equinox as eqx
import jax
import numpy as np
import pytest

import ccjax
from ccjax import cli
from ccjax.estimators import registry
from ccjax.estimators.base import AbstractWorldSurfaceEstimator
from ccjax.runs import store
from ccjax.world import World


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A private, empty cache and an empty memory."""
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path / "cache"))
    store.clear_memory()
    yield tmp_path / "cache"
    store.clear_memory()


@pytest.fixture
def fits(monkeypatch):
    """Count the fits the store runs (``registry.fit``, which the store calls for every miss)."""
    calls: list[str] = []
    original = registry.fit

    def counting(label, world, **options):
        calls.append(label)
        return original(label, world, **options)

    monkeypatch.setattr(registry, "fit", counting)
    return calls


def _digest(kind, key, skeleton, arrays) -> str:
    # The documented rule, written as one byte string: the kind and key lines, the skeleton's compact
    # sorted JSON, then per array (sorted by name) a header line and its C-order bytes.
    parts = [f"{kind}\n{key}\n".encode(), json.dumps(skeleton, sort_keys=True, separators=(",", ":")).encode()]
    parts += [
        f"\n{name} {np.asarray(arrays[name]).dtype.str} {np.shape(arrays[name])}\n".encode()
        + np.asarray(arrays[name]).tobytes(order="C")
        for name in sorted(arrays)
    ]
    return hashlib.sha256(b"".join(parts)).hexdigest()


def _entry(cache, kind="fits"):
    (record,) = (cache / kind).glob("*.json")
    return record, record.with_suffix(".npz")


def _arrays(path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as stored:
        return {name: stored[name] for name in stored.files}


def _rewrite(cache, skeleton=None, arrays=None, kind="fits", **record_changes) -> None:
    """Replace the entry's skeleton and/or arrays and give it the digest they have (so only the
    store's other checks can refuse it)."""
    record_path, npz_path = _entry(cache, kind)
    record = json.loads(record_path.read_text())
    if skeleton is not None:
        record["skeleton"] = skeleton
    if arrays is not None:
        buffer = io.BytesIO()
        np.savez(buffer, **arrays)  # pyright: ignore[reportArgumentType]
        npz_path.write_bytes(buffer.getvalue())
    record.update(record_changes)
    record["digest"] = _digest(record["kind"], record["key"], record["skeleton"], _arrays(npz_path))
    record_path.write_text(json.dumps(record))


def _same_leaves(a, b) -> None:
    assert jax.tree_util.tree_structure(a) == jax.tree_util.tree_structure(b)
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True):
        assert type(x) is type(y)
        if isinstance(x, jax.Array | np.ndarray | np.generic):
            assert x.dtype == y.dtype and getattr(x, "weak_type", None) == getattr(y, "weak_type", None)
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
        else:
            assert x == y


# ---------------------------------------------------------------------------------------------
# round trips and memory


@pytest.mark.parametrize("label", ["GW", "DB-GW", "ECRULE-MV", "CIP-MV", "C-by-C-MMSE", "log-chroma-mlp"])
def test_round_trip_gives_identical_leaves(cache, fits, small_test_world, label):
    fresh = registry.fit(label, small_test_world)  # the uncached fit, for comparison
    first, hit = store.fit_with_source(label, small_test_world)
    store.clear_memory()
    again, hit_again = store.fit_with_source(label, small_test_world)
    assert (hit, hit_again) == (False, True) and fits == [label, label]  # fitted once by the store
    _same_leaves(first, fresh)  # types, dtypes, weak types (GW's scale) and values
    _same_leaves(again, fresh)
    assert type(again) is type(fresh)


def test_memory_returns_the_same_object_and_options_are_keys(cache, fits, small_test_world):
    first = store.fit("shades-of-grey-p6", small_test_world)
    equal_content = eqx.tree_at(lambda w: w.reflectances, small_test_world, small_test_world.reflectances + 0)
    assert store.fit("shades-of-grey-p6", equal_content) is first and fits == ["shades-of-grey-p6"]
    softer = store.fit("RETINEX", small_test_world, temperature=0.5)
    assert softer is not store.fit("RETINEX", small_test_world, temperature=0.25)
    assert softer is store.fit("RETINEX", small_test_world, temperature=0.5)
    assert float(softer.temperature) == 0.5  # pyright: ignore[reportAttributeAccessIssue]
    other = eqx.tree_at(lambda w: w.train_illuminants, small_test_world, small_test_world.train_illuminants[:5])
    assert store.fit("shades-of-grey-p6", other) is not first  # another world: fitted again
    with pytest.raises(ValueError, match="NO-SUCH-METHOD"):
        store.fit("NO-SUCH-METHOD", small_test_world)
    assert len(fits) == 4
    assert ccjax.fit is store.fit


def test_a_model_that_is_not_data_stays_in_memory(cache, monkeypatch, small_test_world):
    class Holder(AbstractWorldSurfaceEstimator):
        function: object = eqx.field(static=True)
        estimates_brightness: ClassVar[bool] = False

        def __call__(self, rgb, mask):
            raise NotImplementedError

    calls = []
    monkeypatch.setattr(registry, "fit", lambda label, world: calls.append(1) or Holder(function=len))
    first, hit = store.fit_with_source("GW", small_test_world)
    assert store.fit("GW", small_test_world) is first and not hit
    assert not (cache / "fits").exists()  # a function cannot be written as data
    store.clear_memory()
    assert store.fit_with_source("GW", small_test_world)[1] is False and len(calls) == 2


def test_world_is_stored_as_named_arrays_and_rebuilt(cache, monkeypatch, small_test_world):
    monkeypatch.setattr(World, "default", classmethod(lambda cls, camera, seed=0: small_test_world))
    first = store.world("default", seed=3)
    assert store.world("default", seed=3) is first
    _, npz = _entry(cache, "world")
    arrays = _arrays(npz)
    assert sorted(arrays) == ["canonical", "reflectances", "sensors", "test_illuminants", "train_illuminants"]
    np.testing.assert_array_equal(arrays["sensors"], np.asarray(small_test_world.camera.sensors))
    store.clear_memory()
    monkeypatch.setattr(World, "default", classmethod(lambda cls, camera, seed=0: pytest.fail("rebuilt")))
    second = store.world("default", seed=3)
    for rebuilt in (first, second):
        assert rebuilt.name == small_test_world.name and rebuilt.camera.name == small_test_world.camera.name
        _same_leaves(rebuilt, small_test_world)
    with pytest.raises(ValueError, match="world"):
        store.world("thesis")
    # A damaged world is built again, with the warning, and replaced.
    arrays["reflectances"] = arrays["reflectances"] * 2
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)  # pyright: ignore[reportArgumentType]
    npz.write_bytes(buffer.getvalue())
    store.clear_memory()
    monkeypatch.setattr(World, "default", classmethod(lambda cls, camera, seed=0: small_test_world))
    with pytest.warns(store.CacheEntryRejected, match="digest"):
        _same_leaves(store.world("default", seed=3), small_test_world)
    store.clear_memory()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _same_leaves(store.world("default", seed=3), small_test_world)


# ---------------------------------------------------------------------------------------------
# files are data only


def _planted(tmp_path):
    sentinel = tmp_path / "sentinel.txt"
    sentinel.write_text("keep me")
    marker = tmp_path / "marker"
    return (
        sentinel,
        marker,
        {
            # What a file could name to run code at the next load if class names were imported:
            "subprocess": {"$dataclass": "subprocess:Popen", "fields": {"args": ["touch", str(marker)]}},
            "io": {"$dataclass": "io:FileIO", "fields": {"file": str(sentinel), "mode": "w"}},
            "chain": {"$dataclass": "ccjax._cache:io.FileIO", "fields": {"file": str(sentinel), "mode": "w"}},
            "module": {"$module": "io:FileIO", "fields": {"file": str(sentinel), "mode": "w"}},
            "enum": {"$enum": "ccjax._cache:io.FileIO", "value": str(sentinel)},
        },
    )


@pytest.mark.parametrize("where", ["top", "nested"])
@pytest.mark.parametrize("plant", ["subprocess", "io", "chain", "module", "enum"])
def test_planted_class_names_run_nothing_and_are_refitted(cache, fits, tmp_path, small_test_world, plant, where):
    model = store.fit("ECRULE-MV", small_test_world)
    sentinel, marker, nodes = _planted(tmp_path)
    skeleton = json.loads(_entry(cache)[0].read_text())["skeleton"]
    if where == "top":
        skeleton = nodes[plant]
    else:
        skeleton["fields"]["model"]["fields"]["options"] = nodes[plant]
    _rewrite(cache, skeleton)  # a valid digest: only the allow-list stands in the way
    store.clear_memory()
    with pytest.warns(store.CacheEntryRejected, match="not a class fitted models are rebuilt from") as caught:
        again, hit = store.fit_with_source("ECRULE-MV", small_test_world)
    assert len(caught) == 1 and not hit and fits == ["ECRULE-MV", "ECRULE-MV"]
    assert sentinel.read_text() == "keep me" and not marker.exists()
    _same_leaves(again, model)
    # ... and replaced by a good entry.
    store.clear_memory()
    assert store.fit_with_source("ECRULE-MV", small_test_world)[1] is True


def _truncate(cache):
    npz = _entry(cache)[1]
    npz.write_bytes(npz.read_bytes()[: npz.stat().st_size // 2])


def _edit_field(cache):
    record_path = _entry(cache)[0]
    record = json.loads(record_path.read_text())
    record["skeleton"]["fields"]["selector"] = "AVE"
    record_path.write_text(json.dumps(record))


def _edit_array(cache):
    arrays = _arrays(_entry(cache)[1])
    name = sorted(arrays)[0]
    arrays[name] = arrays[name] + 1
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)  # pyright: ignore[reportArgumentType]
    _entry(cache)[1].write_bytes(buffer.getvalue())


def _rename_field(cache):
    skeleton = json.loads(_entry(cache)[0].read_text())["skeleton"]
    skeleton["fields"]["chooser"] = skeleton["fields"].pop("selector")
    _rewrite(cache, skeleton)


def _extra_field(cache):
    skeleton = json.loads(_entry(cache)[0].read_text())["skeleton"]
    skeleton["fields"]["__class__"] = "x"
    _rewrite(cache, skeleton)


DAMAGE = {
    "truncated npz": (_truncate, "unreadable arrays"),
    "edited json field": (_edit_field, "digest"),
    "edited array": (_edit_array, "digest"),
    "renamed field": (_rename_field, "fields"),
    "extra field": (_extra_field, "fields"),
    "schema": (lambda cache: _rewrite(cache, schema=99), "schema"),
    "wrong key": (lambda cache: _rewrite(cache, key="0" * 24), "expected"),
    "not json": (lambda cache: _entry(cache)[0].write_text("{not json"), "not JSON"),
    "no arrays": (lambda cache: _entry(cache)[1].unlink(), "unreadable arrays"),
}


@pytest.mark.parametrize("damage", list(DAMAGE))
def test_damaged_entries_are_refitted_with_one_warning(cache, fits, small_test_world, damage):
    model = store.fit("ECRULE-MV", small_test_world)
    spoil, reason = DAMAGE[damage]
    spoil(cache)
    store.clear_memory()
    with pytest.warns(store.CacheEntryRejected, match=reason) as caught:
        again, hit = store.fit_with_source("ECRULE-MV", small_test_world)
    assert len(caught) == 1 and "\n" not in str(caught[0].message)
    assert not hit and fits == ["ECRULE-MV", "ECRULE-MV"]
    _same_leaves(again, model)
    store.clear_memory()
    assert store.fit_with_source("ECRULE-MV", small_test_world)[1] is True  # replaced


def test_an_entry_moved_under_another_key_is_refitted(cache, fits, small_test_world):
    """Another method's fit copied under this method's key, its record relabelled with this key
    (the digest left as written): the digest covers the kind and the key, so it is rejected and
    refitted, never read as this method's model."""
    store.fit("GW", small_test_world)
    (gw_record,) = (cache / "fits").glob("*.json")
    store.fit("DB-GW", small_test_world)
    (db_record,) = [path for path in (cache / "fits").glob("*.json") if path != gw_record]
    record = json.loads(db_record.read_text())
    record["key"] = json.loads(gw_record.read_text())["key"]
    gw_record.write_text(json.dumps(record))
    gw_record.with_suffix(".npz").write_bytes(db_record.with_suffix(".npz").read_bytes())
    store.clear_memory()
    with pytest.warns(store.CacheEntryRejected, match="digest"):
        model, hit = store.fit_with_source("GW", small_test_world)
    assert not hit and fits == ["GW", "DB-GW", "GW"]
    _same_leaves(model, registry.fit("GW", small_test_world))


def test_model_classes_are_an_allow_list():
    allowed = registry.model_classes()
    assert allowed[registry.qualified_name(eqx.nn.Linear)] is eqx.nn.Linear  # held by the nets
    for name, cls in allowed.items():
        assert name == registry.qualified_name(cls)
        assert name.startswith(("ccjax.", "equinox.")), name
        assert not name.startswith(("ccjax.runs", "ccjax.experiments", "ccjax.training", "ccjax.cli")), name
    assert "subprocess:Popen" not in allowed and "io:FileIO" not in allowed


def test_cli_shows_ccjax_warnings_as_one_line():
    format_warning = cli.one_line_warnings("compare", warnings.formatwarning)
    text = format_warning(store.CacheEntryRejected("x.json does not verify"), store.CacheEntryRejected, "f.py", 3)
    assert text == "ccjax compare: warning: x.json does not verify\n"
    assert format_warning(UserWarning("other"), UserWarning, "f.py", 3).count("\n") >= 1


# ---------------------------------------------------------------------------------------------
# a second process


SCRIPT = textwrap.dedent(
    """
    import sys
    import numpy as np
    import ccjax
    from ccjax.estimators import registry
    from ccjax.runs import store

    if sys.argv[1] == "second":
        def refuse(*args, **options):
            raise SystemExit("fitted in the second process")
        registry.fit = refuse
    estimate = ccjax.estimate("DB-GW", np.full((4, 3), 0.5, np.float32))
    model, hit = store.fit_with_source("DB-GW", store.world())
    print(hit, ccjax.fit("DB-GW", store.world()) is model, np.asarray(estimate.illuminant).tolist())
    """
)


@pytest.mark.slow
def test_a_second_process_fits_nothing(tmp_path):
    env = {**os.environ, "CCJAX_CACHE": str(tmp_path / "cache")}
    runs = [
        subprocess.run(
            [sys.executable, "-c", SCRIPT, which], env=env, capture_output=True, text=True, timeout=300, check=False
        )
        for which in ("first", "second")
    ]
    for run in runs:
        assert run.returncode == 0, run.stderr
    first, second = (run.stdout.split(maxsplit=2) for run in runs)
    assert first[:2] == ["True", "True"]  # ccjax.estimate fitted it, the store's memory had it
    assert second[:2] == ["True", "True"]
    assert first[2] == second[2]  # the same estimate
    assert len(list((tmp_path / "cache" / "fits").glob("*.npz"))) == 1
