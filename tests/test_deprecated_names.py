"""The deprecated aliases of "one name per idea": each warns, naming its replacement, and returns
the same numbers as that replacement (and as an independent NumPy oracle)."""

from __future__ import annotations

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ccjax
from ccjax import estimators, losses, metrics


def _numpy_angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles in degrees by the textbook formula, in float64."""
    cosine = np.sum(a * b, axis=-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def test_angular_errors_warns_and_matches_the_metric():
    key_a, key_b = jax.random.split(jax.random.key(3))
    estimate = jax.random.uniform(key_a, (16, 3), minval=0.05, maxval=1.0)
    truth = jax.random.uniform(key_b, (16, 3), minval=0.05, maxval=1.0)
    with pytest.warns(DeprecationWarning, match=r"ccjax\.metrics\.angular_error"):
        old = losses.angular_errors(estimate, truth)
    new = metrics.angular_error(estimate, truth)
    np.testing.assert_array_equal(np.asarray(old), np.asarray(new))
    oracle = _numpy_angles(np.asarray(estimate, np.float64), np.asarray(truth, np.float64))
    np.testing.assert_allclose(np.asarray(new), oracle, atol=2e-3)
    # The loss is still the mean of the per-item angles, with no warning on the way.
    np.testing.assert_allclose(float(losses.angular_loss(estimate, truth)), oracle.mean(), atol=2e-3)


def test_estimators_fit_warns_and_matches_fit_uncached(small_test_world):
    with pytest.warns(DeprecationWarning, match=r"ccjax\.estimators\.fit_uncached"):
        old = estimators.fit("GW", small_test_world)
    new = estimators.fit_uncached("GW", small_test_world)
    assert type(old) is type(new)
    rgb = jnp.asarray([[0.2, 0.4, 0.1], [0.6, 0.3, 0.2], [0.1, 0.1, 0.5]])
    mask = jnp.ones(3, bool)
    # Grey world's answer points along the mean of the surfaces (its closed form, up to scale).
    answer = np.asarray(new(rgb, mask).illuminant, np.float64)
    assert _numpy_angles(answer, np.asarray(rgb, np.float64).mean(axis=0)) < 1e-3
    np.testing.assert_array_equal(np.asarray(old(rgb, mask).illuminant), np.asarray(new(rgb, mask).illuminant))


def test_the_cached_fit_keeps_its_name():
    assert "fit" in ccjax.__all__
    assert "fit" not in estimators.__all__ and "fit_uncached" in estimators.__all__


# Deprecated module paths: photo evaluation has one home, ccjax.evaluation, and the modules named
# folders / protocols / results were renamed for what they hold. (old module, name, replacement).
MOVED = [
    ("ccjax.experiments.folders", "evaluate_folder", "ccjax.evaluation.evaluate_folder"),
    ("ccjax.experiments.folders", "protocol_for", "ccjax.evaluation.protocol_for"),
    ("ccjax.experiments.folders", "FolderEvaluation", "ccjax.evaluation.FolderEvaluation"),
    ("ccjax.experiments.folders", "check_fold_options", "ccjax.evaluation.photo_protocols.check_fold_options"),
    ("ccjax.experiments.folders", "CSV_FIELDS", "ccjax.evaluation.scored_folder.CSV_FIELDS"),
    ("ccjax.experiments.folder_sets", "evaluate_folder_sets", "ccjax.evaluation.evaluate_folder_sets"),
    ("ccjax.experiments.folder_sets", "FolderSet", "ccjax.evaluation.FolderSet"),
    ("ccjax.experiments.folder_sets", "geometric_means", "ccjax.evaluation.geometric_means"),
    ("ccjax.experiments.folder_sets", "fold_model_file", "ccjax.evaluation.sets.fold_model_file"),
    ("ccjax.experiments.evaluation", "ImageResults", "ccjax.evaluation.ImageResults"),
    ("ccjax.experiments.evaluation", "run_images", "ccjax.evaluation.run_images"),
    ("ccjax.experiments.evaluation", "fold_worlds", "ccjax.evaluation.fold_worlds"),
    ("ccjax.evaluation.folders", "read_folder", "ccjax.evaluation.scored_folder.read_folder"),
    ("ccjax.evaluation.protocols", "KFolds", "ccjax.evaluation.photo_protocols.KFolds"),
    ("ccjax.evaluation.results", "ImageResults", "ccjax.evaluation.image_results.ImageResults"),
    ("ccjax.experiments.protocols", "reproduce", "ccjax.experiments.table_protocols.reproduce"),
    ("ccjax.experiments.results", "SweepResult", "ccjax.experiments.sweep_results.SweepResult"),
]


def _fresh_import(name: str):
    """Import ``name`` anew, so that its import-time warning is raised again."""
    import importlib
    import sys

    sys.modules.pop(name, None)
    return importlib.import_module(name)


@pytest.mark.parametrize(("old", "name", "new"), MOVED, ids=lambda value: str(value).rsplit(".", 1)[-1])
def test_a_moved_name_warns_naming_its_replacement_and_is_the_same_object(old, name, new):
    import importlib

    module_name, _, attribute = new.rpartition(".")
    replacement = getattr(importlib.import_module(module_name), attribute)
    with pytest.warns(DeprecationWarning, match=rf"^{re.escape(old)} is deprecated: use "):
        module = _fresh_import(old)
    with pytest.warns(DeprecationWarning, match=rf"^{re.escape(old)}\.{name} is deprecated: use {re.escape(new)}$"):
        assert getattr(module, name) is replacement
    assert name in dir(module)


@pytest.mark.parametrize("old", sorted({old for old, _, _ in MOVED}))
def test_a_deprecated_module_refuses_a_name_it_never_had(old):
    with pytest.warns(DeprecationWarning):
        module = _fresh_import(old)
    with pytest.raises(AttributeError, match=rf"{re.escape(old)}.*'no_such_name'"):
        module.no_such_name  # noqa: B018 (the attribute access is the test)
