"""Programs shared by several models and several surface counts (``ccjax.runs``): one statistics
program serves every model, a stream reads its own padded width of a wider draw, and the counts
that can share one sampler do so only where its draws are bitwise their own."""

from __future__ import annotations

import equinox as eqx
import jax
import numpy as np
import pytest
from test_engine import Budgeted

from ccjax import scenes
from ccjax.runs import engine, store, synthetic
from ccjax.runs.synthetic import SyntheticSource, run_synthetic
from ccjax.scenes import SceneOptions

LABELS = ("NOTHING", "GW", "shades-of-grey-p6", "C-by-C-MMSE")


@pytest.fixture(scope="module")
def models(default_world):
    return [store.fit(label, default_world) for label in LABELS]


def test_the_estimate_and_statistics_programs_read_a_streams_own_width(default_world, models):
    """The engine's two programs on a 16-slot draw read at 8 slots give ``scene_errors`` on the
    8-slot draw of the same keys, model by model (statuses bitwise; errors to float32 rounding:
    estimates and statistics are two programs, which XLA fuses, and so rounds, otherwise)."""
    tables = scenes.SceneTables.from_world(default_world)
    keys = scenes.sweep_keys(jax.random.key(3), 6, 0, 40)
    wide = scenes.sample_batch_slots(keys, tables, 6, 16)
    narrow = scenes.sample_batch_slots(keys, tables, 6, 8)
    for model in models:
        illuminant, ok, status = eqx.filter_jit(engine.estimate_scenes)(model, wide.rgb, wide.mask, 8)
        got = eqx.filter_jit(engine.scene_statistics)(illuminant, wide, tables.canonical_white, 8)
        got = jax.device_get({**got, "ok": ok, "status": status})
        expected = jax.device_get(eqx.filter_jit(engine.scene_errors)(model, narrow, tables.canonical_white))
        assert set(got) == set(expected)
        for name, values in expected.items():
            assert got[name].shape == (40,)
            if name in ("ok", "status"):
                np.testing.assert_array_equal(got[name], values, err_msg=name)
            else:
                atol = 1e-5 if name == "angular" else 1e-6
                np.testing.assert_allclose(got[name], values, rtol=1e-6, atol=atol, err_msg=name)


def test_size_branched_models_compile_first_then_the_statistics_then_the_others(models):
    budgeted = Budgeted(models[1])
    everyone = [models[0], budgeted, models[1], models[2], budgeted, models[3]]
    # The size-branched programs first (the largest), then the statistics (None), then the others.
    assert engine.compile_order(everyone, range(6)) == [1, 4, None, 0, 2, 3, 5]
    # A stream runs the models it has not read from the cache: its programs are of those only.
    assert engine.compile_order(everyone, (3, 1)) == [1, None, 3]


@pytest.mark.parametrize(
    ("options", "shared"),
    [
        (SceneOptions(), True),
        (SceneOptions(scenes.Specular()), True),
        # Two options: another width may round the scenes' sums otherwise, so each count keeps its own.
        (SceneOptions(scenes.Specular(), scenes.ShotNoise()), False),
    ],
    ids=["plain", "one option", "two options"],
)
def test_small_counts_share_one_sampler_only_where_its_draws_are_bitwise_theirs(options, shared):
    source = SyntheticSource(jax.random.key(0), (4, 8, 16, 64, 100), 10, options)
    sizes = {4: 16, 8: 16, 16: 16, 64: 64, 100: 100}
    chunks = dict.fromkeys(sizes, 10)
    widths = synthetic.sampler_widths(source, sizes, chunks)
    if shared:
        # Up to SHARED_SAMPLER_SLOTS slots: one width, the widest; above it each count keeps its own.
        assert widths == {4: 64, 8: 64, 16: 64, 64: 64, 100: 100}
    else:
        assert widths == sizes
    # Counts cut into chunks of other sizes never share (each sampler program has one batch shape).
    assert synthetic.sampler_widths(source, sizes, {**chunks, 4: 7})[4] == 16


@pytest.mark.slow
def test_a_wide_sampler_gives_each_count_its_own_scenes(default_world, models):
    """Counts 4 and 8 run with 16 and 64 (one 64-slot sampler) give, cell by cell, what each count
    run alone gives (its own sampler at its own width): the same scenes, so statuses bitwise and
    errors to float32 rounding."""
    budgeted = [Budgeted(model) for model in models[:2]]
    together = run_synthetic(
        default_world, budgeted, [SyntheticSource(jax.random.key(5), (4, 8, 16, 64), 30)], progress=False
    )
    for n in (4, 8, 64):
        alone = run_synthetic(default_world, budgeted, [SyntheticSource(jax.random.key(5), (n,), 30)], progress=False)
        for position in range(len(budgeted)):
            got, expected = together.errors[0][n][position], alone.errors[0][n][position]
            assert got.keys() == expected.keys()
            for name, values in expected.items():
                if name in ("ok", "status"):
                    np.testing.assert_array_equal(got[name], values, err_msg=name)
                else:
                    atol = 1e-5 if name == "angular" else 1e-6
                    np.testing.assert_allclose(got[name], values, rtol=1e-6, atol=atol, err_msg=f"{n} {name}")
