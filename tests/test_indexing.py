"""Colour indexing (Barnard 1999 ch. 11; ccjax.experiments.indexing): histograms, intersection,
ranks and scores against NumPy references and Table 11.1, and a small run of the experiment."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from small_world import small_world

from ccjax.experiments import indexing


def test_histogram_matches_numpy():
    rng = np.random.default_rng(0)
    rgb = rng.random((20, 30, 3)).astype(np.float32)
    rgb[0, 0] = 0.0  # black: never counted
    mask = rng.random((20, 30)) > 0.2
    total = rgb.sum(-1)
    keep = mask & (total > 0)
    r, g = rgb[..., 0][keep] / total[keep], rgb[..., 1][keep] / total[keep]
    want, _, _ = np.histogram2d(r, g, bins=16, range=[[0, 1], [0, 1]])
    got = np.asarray(jax.jit(indexing.rg_histogram)(jnp.asarray(rgb), jnp.asarray(mask)))
    np.testing.assert_allclose(got, want / want.sum(), atol=1e-7)


def test_intersection_and_ranks_reference():
    rng = np.random.default_rng(1)
    tests = rng.random((5, 4, 4))
    models = rng.random((3, 4, 4))
    want = np.array([[np.minimum(t, m).sum() / m.sum() for m in models] for t in tests])
    got = np.asarray(jax.jit(indexing.intersection)(jnp.asarray(tests), jnp.asarray(models)))
    np.testing.assert_allclose(got, want, rtol=1e-6)
    truth = np.array([0, 1, 2, 0, 1])
    ranks = [1 + sum(want[q, m] > want[q, truth[q]] for m in range(3)) for q in range(5)]
    np.testing.assert_array_equal(
        np.asarray(jax.jit(indexing.correct_ranks)(jnp.asarray(want), jnp.asarray(truth))), ranks
    )


@pytest.mark.parametrize(
    "counts, scores",
    [
        ((193, 23, 3), (0.877, 0.930, 0.934)),
        ((93, 31, 13), (0.423, 0.493, 0.513)),
        ((178, 23, 3), (0.809, 0.861, 0.866)),
    ],
)
def test_rank_scores_reproduce_table_11_1(counts, scores):
    """Table 11.1 (220 images): ACTUAL, NOTHING and ND-CRULE-AVE rank counts give the printed scores."""
    ranks = np.concatenate([np.full(n, k + 1) for k, n in enumerate(counts)] + [np.full(220 - sum(counts), 7)])
    got, n = indexing.rank_scores(ranks)
    assert n == counts
    np.testing.assert_allclose(got, scores, atol=5e-4)


@pytest.mark.slow
def test_small_experiment():
    world = small_world()
    result = indexing.run_indexing(
        world,
        ["ACTUAL", "NOTHING", "RETINEX"],
        jax.random.key(0),
        n_objects=8,
        n_lights=4,
        size=32,
        n_surfaces=6,
        fit=lambda label, w: __import__("ccjax").fit(label, w),
    )
    rows = result.rows
    assert result.n_queries == 32
    assert rows["ACTUAL"]["rg_error"] < 1e-6
    assert rows["ACTUAL"]["score1"] >= max(rows["NOTHING"]["score1"], rows["RETINEX"]["score1"])
    assert rows["NOTHING"]["rg_error"] > 0.01
    for row in rows.values():
        assert row["n1"] + row["n2"] + row["n3"] <= 32 and 0 <= row["score3"] <= 1
    assert -1 <= result.spearman() <= 1
