"""``ccjax compare``: fits and result cells from the disk cache on a second run, and padded scene
sizes (one compiled program for several surface counts) that leave every estimate as it is
unpadded."""

from __future__ import annotations

import re
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ccjax import cli
from ccjax.estimators import gamut
from ccjax.estimators.base import (
    AbstractStatisticsSurfaceEstimator,
    Estimate,
    Status,
)
from ccjax.estimators.gamut._engine import GridOptions
from ccjax.experiments import sweeps
from ccjax.runs import store, synthetic


def _fits_line(out: str) -> tuple[int, int]:
    match = re.search(r"^fits: (\d+) from cache, (\d+) fitted", out, re.MULTILINE)
    assert match, out
    return int(match.group(1)), int(match.group(2))


def _results_line(out: str) -> tuple[int, int, int]:
    match = re.search(r"^results: (\d+) of (\d+) \(method, surfaces\) cells from cache, (\d+) computed", out, re.M)
    assert match, out
    return int(match.group(1)), int(match.group(2)), int(match.group(3))


@pytest.mark.slow
def test_second_compare_reads_its_fits_from_the_cache(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path))
    argv = ["compare", "--scenes", "20", "--surfaces", "4,8", "--methods", "GW,ECRULE-MV", "--no-progress"]
    assert cli.main(argv) == 0
    first = capsys.readouterr().out
    assert _fits_line(first) == (0, 2)
    assert _results_line(first) == (0, 4, 4)
    assert len(list((tmp_path / "fits").glob("*.npz"))) == 2
    assert cli.main(argv) == 0
    second = capsys.readouterr().out
    assert _fits_line(second) == (2, 0)
    assert _results_line(second) == (4, 4, 0)
    # --recompute computes every cell again, with the cached fits.
    assert cli.main([*argv, "--recompute"]) == 0
    third = capsys.readouterr().out
    assert _fits_line(third) == (2, 0)
    assert _results_line(third) == (0, 4, 4)
    # The same tables every time (everything after the results line).
    assert first.split("\n", 3)[3] == second.split("\n", 3)[3] == third.split("\n", 3)[3]


def test_sweep_cache_reads_equal_cells_and_computes_only_new_ones(tmp_path, monkeypatch, default_world):
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path))
    key = jax.random.key(3)
    options = {"n_scenes": 12, "key": key, "progress": False}
    computed = sweeps.sweep(default_world, ["GW", "RETINEX"], [4, 8], **options)
    assert computed.cells_from_cache == 0 and not (tmp_path / "sweeps").exists()  # cache is opt-in
    first = sweeps.sweep(default_world, ["GW", "RETINEX"], [4, 8], cache=True, **options)
    assert first.cells_from_cache == 0
    # A new method beside cached ones: only its cells are computed, the others read back equal.
    second = sweeps.sweep(default_world, ["GW", "RETINEX", "DB-GW"], [4, 8], cache=True, **options)
    assert second.cells_from_cache == 4
    for label in ("GW", "RETINEX"):
        for n in (4, 8):
            assert computed.errors[label][n].keys() == second.errors[label][n].keys()
            for name, values in computed.errors[label][n].items():
                np.testing.assert_array_equal(second.errors[label][n][name], values)
    alone = sweeps.sweep(default_world, ["DB-GW"], [4, 8], **options)
    for n in (4, 8):
        np.testing.assert_array_equal(second.errors["DB-GW"][n]["rg"], alone.errors["DB-GW"][n]["rg"])
    # Anything the numbers depend on is in the key: other scenes, another seed, another count.
    assert sweeps.sweep(default_world, ["GW"], [4], cache=True, **{**options, "n_scenes": 13}).cells_from_cache == 0
    other_key = {**options, "key": jax.random.key(4)}
    assert sweeps.sweep(default_world, ["GW"], [4], cache=True, **other_key).cells_from_cache == 0
    assert sweeps.sweep(default_world, ["GW"], [4], cache=True, specular=True, **options).cells_from_cache == 0
    assert sweeps.sweep(default_world, ["GW"], [4, 16], cache=True, **options).cells_from_cache == 1


def test_padded_sizes_never_cross_an_engine_budget(default_world):
    options = GridOptions()
    budgets = (options.fine_observations, options.locate_observations, options.large_scene)
    engine = store.fit("ECRULE-MV", default_world)
    cip = gamut.cip.fit(default_world, "MV", coarse=8, fine=9)
    surfaces = [1, 4, 8, 16, 32, 33, 48, 64, 128, 256, 1024]
    for models in ([engine], [engine, cip]):
        sizes = synthetic.padded_sizes(surfaces, models)
        for n, size in sizes.items():
            assert size >= n
            for budget in budgets:
                assert (n <= budget) == (size <= budget), (n, size, budget)
        assert sizes[33] == sizes[48] == 48 and sizes[64] == sizes[128] == 128
        assert sizes[256] == 256 and sizes[1024] == 1024
    # Below the smallest budget the 3-D engine reads only the usable observations: one program.
    alone = synthetic.padded_sizes(surfaces, [engine])
    assert {alone[n] for n in (1, 4, 8, 16, 32)} == {32}
    # ... in scenes of at least COUNTED_SLOTS slots; below, padding costs what it adds.
    assert synthetic.padded_sizes([4, 8, 12], [engine]) == {4: 8, 8: 8, 12: 12}
    # CIP reads every slot: buckets within a factor MAX_PADDING.
    mixed = synthetic.padded_sizes(surfaces, [engine, cip])
    assert all(size <= synthetic.MAX_PADDING * n for n, size in mixed.items())
    assert mixed[1] == 1 and mixed[4] == mixed[8] == 8 and mixed[16] == mixed[32] == 32
    # Without a model that branches on the scene size nothing is padded.
    assert synthetic.padded_sizes([4, 8], []) == {4: 4, 8: 8}


@pytest.mark.slow  # compiles the gamut engine for three scene sizes (about 40 s under load)
def test_padded_sweep_equals_unpadded(default_world, monkeypatch, tmp_path):
    # With a gamut model in the sweep, 4, 8 and 32 surfaces share one program of 32 slots.
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path))
    methods = ("GW", "shades-of-grey-p6", "RETINEX", "C-by-C-MMSE", "ND-ECRULE-MV")
    counts = (4, 8, 32)
    key = jax.random.key(3)
    models = [store.fit(method, default_world) for method in methods]
    assert {synthetic.padded_sizes(counts, models)[n] for n in counts} == {32}
    padded = sweeps.sweep(default_world, list(methods), counts, 24, key, progress=False)
    monkeypatch.setattr(synthetic, "padded_sizes", lambda surfaces, models: {n: n for n in surfaces})
    plain = sweeps.sweep(default_world, list(methods), counts, 24, key, progress=False)
    for method in methods:
        for n in counts:
            for name, value in plain.errors[method][n].items():
                got = padded.errors[method][n][name]
                if name in ("ok", "status"):
                    np.testing.assert_array_equal(got, value)
                elif method.startswith("ND-"):
                    # Programs of other shapes round differently in the last bit, and MV's pattern
                    # search can follow another path from there (measured on 1,000 scenes: up to
                    # 4e-5 in (r,g), 0.006 degrees).
                    atol = 0.02 if name == "angular" else 1e-4
                    np.testing.assert_allclose(got, value, rtol=0, atol=atol, err_msg=f"{method} {n} {name}")
                else:
                    # float32 sums over a longer (zero-padded) axis: a few ulps at most; the angle
                    # (degrees, through arccos) amplifies them to ~2e-6 degrees.
                    atol = 1e-5 if name == "angular" else 1e-7
                    np.testing.assert_allclose(got, value, rtol=1e-6, atol=atol, err_msg=f"{method} {n} {name}")


class _FailsAtSixteen(AbstractStatisticsSurfaceEstimator):
    """Grey world, except that tracing it on 16-surface scenes raises (a model that cannot compile)."""

    estimates_brightness: ClassVar[bool] = True

    def __call__(self, rgb, mask):
        if rgb.shape[0] == 16:
            raise ValueError("cannot trace 16 surfaces")
        weights = mask.astype(rgb.dtype)[:, None]
        return Estimate(illuminant=jnp.sum(rgb * weights, axis=0), status=jnp.asarray(int(Status.ESTIMATED)))


@pytest.mark.slow
def test_sweep_compiles_ahead_and_reports_a_failing_compile(default_world):
    # Programs are compiled on a worker thread ahead of the counts that run them: results are
    # the ones a sweep of each count alone gives, and an error raised while compiling reaches
    # the caller as itself.
    key = jax.random.key(5)
    model = _FailsAtSixteen()
    together = sweeps.sweep(default_world, [("grey", model)], (4, 8), 32, key, progress=False)
    for n in (4, 8):
        alone = sweeps.sweep(default_world, [("grey", model)], (n,), 32, key, progress=False)
        np.testing.assert_array_equal(together.errors["grey"][n]["rg"], alone.errors["grey"][n]["rg"])
    with pytest.raises(ValueError, match="cannot trace 16 surfaces"):
        sweeps.sweep(default_world, [("grey", model)], (4, 16), 32, key, progress=False)
