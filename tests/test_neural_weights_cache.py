"""The nets' cached weights go through the cache's one verified reader: the entry is bound to its
key by its digest, its arrays have the net's names and shapes and finite values, and a truncated
or edited entry is removed with one warning and then reported missing (with the command that
trains the weights) instead of failing every run or loading unchecked."""

from __future__ import annotations

import json

import jax
import numpy as np
import pytest

from ccjax.estimators import neural
from ccjax.runs import store

LABEL = "NEURAL-NET"


@pytest.fixture
def saved(tmp_path, monkeypatch, small_test_world):
    """Random weights of the thesis net saved for the small world in a private cache."""
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path / "cache"))
    store.clear_memory()
    recipe = neural.RECIPES[LABEL]
    net = neural.Mlp(jax.random.key(3), recipe.sizes())
    path = neural.save(net, small_test_world, LABEL, recipe, neural.Schedule(), neural.TrainingLog([0.25], 1.5))
    yield net, path
    store.clear_memory()


def _leaves(net):
    import equinox as eqx

    return jax.tree_util.tree_leaves(eqx.filter(net, eqx.is_array))


def test_saved_weights_load_as_saved(saved, small_test_world):
    net, path = saved
    assert path.is_file() and path.with_suffix(".npz").is_file()
    assert json.loads(path.read_text())["final_rms_rg"] == 0.5  # sqrt of the last loss, for people
    for a, b in zip(_leaves(neural.load(small_test_world, LABEL)), _leaves(net), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.parametrize("damage", ["truncated", "edited weight", "nan weight"])
def test_a_damaged_entry_is_removed_with_a_warning_and_reported_missing(saved, small_test_world, damage):
    _, path = saved
    arrays_path = path.with_suffix(".npz")
    if damage == "truncated":
        arrays_path.write_bytes(arrays_path.read_bytes()[:1000])
    else:
        with np.load(arrays_path) as stored:
            arrays = {name: stored[name] for name in stored.files}
        arrays["leaf000"] = arrays["leaf000"].copy()
        arrays["leaf000"][0, 0] = np.nan if damage == "nan weight" else arrays["leaf000"][0, 0] + 1.0
        np.savez(arrays_path, **arrays)
    with (
        pytest.warns(store.CacheEntryRejected, match="does not verify"),
        pytest.raises(neural.MissingWeightsError) as missing,
    ):
        neural.load(small_test_world, LABEL)
    assert "train them with `" in str(missing.value)
    assert not path.exists()  # removed: the next run trains or reports missing, never fails on it again
