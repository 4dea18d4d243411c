"""The degenerate-input sweep: finite estimates and honest ``ok`` on every degenerate scene."""

from typing import ClassVar

import jax.numpy as jnp
import numpy as np
import pytest

from ccjax.estimators import registry
from ccjax.estimators.base import (
    AbstractEstimator,
    AbstractWorldSurfaceEstimator,
    Estimate,
    Status,
)
from ccjax.experiments.degenerate import (
    CASES,
    NO_DATA_CASES,
    as_image,
    degenerate_inputs,
    degenerate_sweep,
    run_label,
    sweep_labels,
)

CHEAP_LABELS = [
    "NOTHING",
    "AVE-ILLUM",
    "GW",
    "DB-GW",
    "RETINEX",
    "soft-RETINEX-t0.01",
    "shades-of-grey-p6",
    "shades-of-grey-p1000",
    "grey-edge-1-6-2",
    "C-by-C-MMSE",
    "C-by-C-01",
    "CRULE-MV",
]


def check(result, labels):
    assert {row.label for row in result.rows} == set(labels)
    assert len(result.rows) == len(labels) * len(CASES)
    for row in result.rows:
        assert row.finite, row
        assert row.fallback_honest, row
        if row.case in NO_DATA_CASES:
            assert not row.ok, row
    assert result.failures() == []


@pytest.mark.slow
def test_cheap_families_are_finite_and_honest(default_world):
    result = degenerate_sweep(default_world, CHEAP_LABELS, n_surfaces=8)
    check(result, CHEAP_LABELS)
    table = result.table()
    assert all(label in table for label in CHEAP_LABELS)
    # Scale-free methods estimate a scene scaled by 1e-12 as they estimate the original.
    cells = {(row.label, row.case): row for row in result.rows}
    for label in ["GW", "RETINEX", "soft-RETINEX-t0.01", "shades-of-grey-p6", "shades-of-grey-p1000"]:
        assert cells[(label, "x1e-12")].ok and cells[(label, "x1e6")].ok, label


def test_inputs_are_the_promised_degenerations(default_world):
    inputs = degenerate_inputs(default_world, 8)
    assert list(inputs) == list(CASES)
    base, _ = inputs["x1e6"]
    assert not inputs["zeros"][0].any() and inputs["zeros"][1].all()
    assert not inputs["all masked"][1].any()
    assert inputs["one surface"][1].sum() == 1
    assert (inputs["identical surfaces"][0] == inputs["identical surfaces"][0][0]).all()
    assert not inputs["one zero channel"][0][:, 0].any() and inputs["one zero channel"][0][:, 1:].all()
    np.testing.assert_allclose(inputs["x1e-12"][0] * 1e18, base, rtol=1e-5)
    image, mask = as_image(*inputs["one surface"], block=3)
    assert image.shape == (3, 24, 3) and mask.sum() == 9
    with pytest.raises(ValueError, match="n_surfaces"):
        degenerate_inputs(default_world, 1)


def test_a_dishonest_model_is_caught(default_world):
    """The sweep can fail: a constant that claims ok on every scene is reported on the no-data cases."""
    rows = run_label("liar", _AlwaysOk(registry.fit("NOTHING", default_world)), degenerate_inputs(default_world, 8))
    assert {row.case for row in rows if not row.passed} == set(NO_DATA_CASES)
    assert all(row.finite and row.fallback_honest for row in rows)


class _AlwaysOk(AbstractWorldSurfaceEstimator):
    """Claims ESTIMATED whatever the scene (a deliberately broken estimator)."""

    inner: AbstractEstimator
    estimates_brightness: ClassVar[bool] = False

    def __call__(self, rgb, mask):
        return Estimate(illuminant=self.inner(rgb, mask).illuminant, status=jnp.asarray(int(Status.ESTIMATED)))


@pytest.mark.slow
def test_every_label_is_finite_and_honest(default_world):
    result = degenerate_sweep(default_world)
    built = [label for label in sweep_labels() if label not in dict(result.skipped)]
    check(result, built)
