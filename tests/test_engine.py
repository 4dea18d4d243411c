"""The engine of synthetic runs (``ccjax.runs``): per-scene errors equal whatever the chunking,
padding (from the models' padding hook) and sharding, and equal to the scene primitives' own."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from typing import ClassVar

import equinox as eqx
import jax
import numpy as np
import pytest
from jax.sharding import Mesh

from ccjax import experiments, scenes
from ccjax.estimators import registry
from ccjax.estimators.base import AbstractSurfaceEstimator, Estimate, Padding
from ccjax.experiments import table_protocols as protocols
from ccjax.runs import engine, store, synthetic
from ccjax.runs.synthetic import SyntheticSource, padded_sizes, run_synthetic
from ccjax.scenes import SceneOptions

LABELS = ("NOTHING", "GW", "RETINEX", "shades-of-grey-p6")


@pytest.fixture(scope="module")
def models(default_world):
    return [store.fit(label, default_world) for label in LABELS]


def _assert_same_errors(got: dict, expected: dict, approximate: bool = False) -> None:
    """Equal statuses; errors equal, or with ``approximate`` within float32 rounding of programs of
    other shapes: a few ulps, which the angle (degrees, through arccos) amplifies to ~1e-5."""
    assert got.keys() == expected.keys()
    for name, values in expected.items():
        if name in ("ok", "status") or not approximate:
            np.testing.assert_array_equal(got[name], values, err_msg=name)
        else:
            atol = 1e-5 if name == "angular" else 1e-7
            np.testing.assert_allclose(got[name], values, rtol=1e-6, atol=atol, err_msg=name)


def test_errors_equal_the_primitives_on_the_same_scenes(default_world, models):
    """The engine's cells are the jitted scene_errors of sample_batch on the sweep's keys (a path
    through the scene primitives alone), with the brightness statistics only for 3-D methods:
    statuses bitwise, errors to float32 rounding (the engine computes a group of models'
    statistics in one program, which XLA fuses, and so rounds, otherwise)."""
    key = jax.random.key(11)
    options = SceneOptions(scenes.Specular(), clip=300 / 255, metallic=scenes.Metallic())
    run = run_synthetic(default_world, models, [SyntheticSource(key, (8,), 50, options)], progress=False)
    tables = scenes.SceneTables.from_world(default_world, metals=True)
    batch = scenes.sample_batch(
        scenes.sweep_keys(key, 8, 0, 50), tables, 8, options.specular, None, options.clip, options.metallic
    )
    for position, model in enumerate(models):
        expected = jax.device_get(eqx.filter_jit(engine.scene_errors)(model, batch, tables.canonical_white))
        got = run.errors[0][8][position]
        if not model.estimates_brightness:
            assert set(got) == {"angular", "rg", "map_rg", "ok", "status"}
            expected = {name: value for name, value in expected.items() if name in got}
        _assert_same_errors(got, expected, approximate=True)


def test_chunk_size_does_not_change_the_errors(default_world, models):
    source = SyntheticSource(jax.random.key(2), (16,), 100, SceneOptions(scenes.Specular()))
    whole = run_synthetic(default_world, models, [source], progress=False)
    for chunk in (7, 64):
        chunked = run_synthetic(default_world, models, [source], chunk_size=chunk, progress=False)
        for n in (16,):
            for position in range(len(models)):
                assert len(chunked.errors[0][n][position]["rg"]) == 100
                # Same scenes; only float32 rounding of differently shaped batches may differ.
                _assert_same_errors(chunked.errors[0][n][position], whole.errors[0][n][position], approximate=True)


def test_chunking_bounds_and_rounds():
    assert engine.chunking(1000, 8) == (1000, 1)
    assert engine.chunking(100_000, 8) == (16384, 7)
    assert engine.chunking(100_000, 1024) == (4096, 25)
    assert engine.chunking(100, 8, requested=7) == (7, 15)
    assert engine.chunking(100, 8, requested=7, n_devices=4) == (8, 13)


class Budgeted(AbstractSurfaceEstimator):
    """A statistics method that declares gamut-like size branches (budgets at 32 and 64, counted
    slots from 16), so the engine pads its scenes; its answers ignore padding by construction."""

    inner: AbstractSurfaceEstimator
    padding: ClassVar[Padding] = Padding((32, 64), 16)
    world_based: ClassVar[bool] = False
    default_preprocessing: ClassVar[str] = "pixels"
    pools_pixels: ClassVar[bool] = False

    @property
    def estimates_brightness(self) -> bool:  # pyright: ignore[reportIncompatibleVariableOverride]
        return self.inner.estimates_brightness

    def block_size(self, backend: str) -> int | None:
        return None

    def __call__(self, rgb, mask) -> Estimate:
        return self.inner(rgb, mask)


def test_padding_follows_the_padding_hook(models):
    budgeted = [Budgeted(model) for model in models]
    # Below the smallest budget, counted: one size; between budgets, buckets within MAX_PADDING.
    assert padded_sizes([4, 8, 16, 40, 48, 100], budgeted) == {4: 16, 8: 16, 16: 16, 40: 48, 48: 48, 100: 100}
    # Below the counted threshold nothing is gained by padding to it: buckets within a factor 2.
    assert padded_sizes([4, 8, 12], budgeted) == {4: 8, 8: 8, 12: 12}
    # Without a size branch nothing is padded.
    assert padded_sizes([4, 8, 16], models) == {4: 4, 8: 8, 16: 16}


def test_padded_scenes_give_the_unpadded_errors(default_world, models):
    source = SyntheticSource(jax.random.key(4), (4, 8, 16), 40, SceneOptions(scenes.Specular(), scenes.ShotNoise()))
    plain = run_synthetic(default_world, models, [source], progress=False)
    budgeted = [Budgeted(model) for model in models]
    padded = run_synthetic(default_world, budgeted, [source], progress=False)
    for n in (4, 8, 16):
        for position in range(len(models)):
            # float32 sums over a longer (zero-padded) axis: a few ulps at most.
            _assert_same_errors(padded.errors[0][n][position], plain.errors[0][n][position], approximate=True)


@pytest.mark.parametrize(
    "options",
    [
        SceneOptions(metallic=scenes.Metallic()),
        SceneOptions(fluorescent=scenes.Fluorescent(probability=0.15)),
        SceneOptions(scenes.Specular(), clip=300 / 255),
    ],
    ids=["metallic", "fluorescent", "specular+clip"],
)
def test_sweep_material_options_equal_the_protocol(default_world, options):
    """``sweep`` with scene options and ``run_conditions`` with the same options are one engine:
    the same scenes (metals, the characterised fluorescent surfaces), the same numbers."""
    key = jax.random.key(6)
    methods = ["GW", "NOTHING"]
    swept = experiments.sweep(
        default_world,
        methods,
        [4, 8],
        60,
        key,
        specular=options.specular,
        clip=options.clip,
        metallic=options.metallic,
        fluorescent=options.fluorescent,
        progress=False,
    )
    fitted = experiments.resolve_methods(default_world, methods)
    conditions = [protocols.Condition(n, {"rg": "rg"}, options) for n in (4, 8)]
    for condition, result in zip(
        conditions, protocols.run_conditions(default_world, fitted, conditions, 60, key, False)
    ):
        n = condition.n_surfaces
        for method in methods:
            _assert_same_errors(swept.errors[method][n], result.errors[method][n])
    matte = experiments.sweep(default_world, methods, [8], 60, key, progress=False)
    assert not np.array_equal(matte.errors["GW"][8]["rg"], swept.errors["GW"][8]["rg"])  # the options act


def test_refusals(default_world, models):
    source = SyntheticSource(jax.random.key(0), (4,), 5)
    with pytest.raises(ValueError, match="labels"):
        run_synthetic(default_world, models, [source], labels=["GW"], progress=False)
    with pytest.raises(ValueError, match=r"'edges'.* is an image estimator"):
        run_synthetic(default_world, [registry.fit("grey-edge-1-6-2", default_world)], [source], labels=["edges"])
    with pytest.raises(ValueError, match="n_surfaces"):
        run_synthetic(default_world, models, [SyntheticSource(jax.random.key(0), (10**6,), 5)], progress=False)
    with pytest.raises(ValueError, match="n_scenes"):
        SyntheticSource(jax.random.key(0), (4,), 0)
    devices = np.array(jax.devices()[:1]).reshape(1, 1)
    with pytest.raises(ValueError, match="mesh"):
        engine.Placement(Mesh(devices, ("a", "b")))
    assert synthetic.MAX_PADDING == 2


SHARDED = r"""
import json
import jax, numpy as np
from jax.sharding import Mesh
from ccjax.runs import store
from ccjax.runs.synthetic import SyntheticSource, run_synthetic
from ccjax.scenes import SceneOptions
from ccjax.world import World
assert len(jax.devices()) == 4, jax.devices()
world = World.default()
models = [store.fit(label, world) for label in ("GW", "NOTHING")]
mesh = Mesh(np.array(jax.devices()), ("scenes",))
sources = [SyntheticSource(jax.random.key(7), (8,), 64, SceneOptions.resolve(specular=True, metallic=True))]
one = run_synthetic(world, models, sources, chunk_size=32, progress=False)
four = run_synthetic(world, models, sources, chunk_size=32, mesh=mesh, progress=False)
worst, same_status = 0.0, True
for n in (8,):
    for a, b in zip(one.errors[0][n], four.errors[0][n]):
        assert a.keys() == b.keys()
        for name in a:
            if name in ("ok", "status"):
                same_status &= bool(np.array_equal(a[name], b[name]))
                continue
            scale = np.maximum(np.abs(a[name]), 1e-6)
            worst = max(worst, float(np.max(np.abs(a[name] - b[name]) / scale)))
print(json.dumps({"worst": worst, "same_status": same_status}))
"""


@pytest.mark.slow
def test_sharded_run_equals_one_device():
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    out = subprocess.run([sys.executable, "-c", SHARDED], env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["same_status"] and result["worst"] <= 1e-6, result
