"""Benchmark: Colour by Correlation estimators (2-D C-by-C-MMSE and 3-D RGB-C-by-C-MMSE).

Prints, on World.barnard1999 with compiled (warm) functions on this machine:
* throughput in scenes/s of the vmapped estimators on batches of synthetic scenes, for several
  numbers of surfaces (the thesis' headline is 8);
* the NumPy loop oracle of tests/correlation_oracle.py on a few scenes, and the ratio;
* fit times (2-D matrix, 3-D matrix cold; cached fits are loaded from disk);
* peak resident memory.

Usage: python benchmarks/correlation.py [--scenes 4096] [--repeats 5] [--surfaces 8,32]
"""

from __future__ import annotations

import argparse
import os
import pathlib
import resource
import sys
import tempfile
import time

import equinox as eqx
import jax
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))

import correlation_oracle as oracle

from ccjax import scenes
from ccjax.estimators import correlation, registry
from ccjax.world import World


@eqx.filter_jit
def _estimate(model, rgb, mask):
    return jax.vmap(model)(rgb, mask).illuminant


def _timed(fn, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - start)
    return float(np.median(times)), float(np.min(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=4096)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--surfaces", default="8,32")
    args = parser.parse_args()
    surfaces = [int(n) for n in args.surfaces.split(",")]

    print(
        f"jax {jax.__version__}, backend {jax.default_backend()}, devices {jax.device_count()}, cpus {os.cpu_count()}"
    )
    world = World.barnard1999()
    print(f"world: {world.name} {world.sizes()}")

    # Fit times with an empty cache (the 3-D matrix and the MLM width are cached on disk).
    with tempfile.TemporaryDirectory() as cache:
        os.environ["CCJAX_CACHE"] = cache
        start = time.perf_counter()
        correlation.chromaticity_matrix(world)
        print(f"fit: 2-D matrix {time.perf_counter() - start:.2f} s", end="")
        start = time.perf_counter()
        three_d = registry.fit("RGB-C-by-C-MMSE", world)
        print(f", 3-D matrix (cold) {time.perf_counter() - start:.2f} s", end="")
        start = time.perf_counter()
        registry.fit("RGB-C-by-C-MMSE", world)
        print(f", 3-D (from the cache) {time.perf_counter() - start:.2f} s")
        models = {"C-by-C-MMSE": registry.fit("C-by-C-MMSE", world), "RGB-C-by-C-MMSE": three_d}

    print(f"throughput, {args.scenes} scenes per batch, median of {args.repeats} warm runs:")
    for n in surfaces:
        batch = scenes.sample(jax.random.key(n), world, args.scenes, n)
        for label, model in models.items():
            start = time.perf_counter()
            jax.block_until_ready(_estimate(model, batch.rgb, batch.mask))
            compile_time = time.perf_counter() - start
            median, best = _timed(
                lambda model=model, batch=batch: _estimate(model, batch.rgb, batch.mask), args.repeats
            )
            print(
                f"  {label:<18}{n:>5} surfaces: {args.scenes / median:>10.0f} scenes/s "
                f"(best {args.scenes / best:.0f}; first call {compile_time:.1f} s)"
            )

    # The loop oracle on a few scenes, for the ratio.
    batch = scenes.sample(jax.random.key(0), world, 20, 8)
    rgb, mask = np.asarray(batch.rgb, np.float64), np.asarray(batch.mask)
    sensors = np.asarray(world.camera.sensors, np.float64)
    lights = np.asarray(world.train_illuminants, np.float64)
    reflectances = np.asarray(world.reflectances, np.float64)
    light_rgb = lights @ sensors  # every training light has a positive response: no black rule needed
    rg = light_rgb[:, :2] / light_rgb.sum(axis=1, keepdims=True)
    log_2d = oracle.chromaticity_log_probability(reflectances, lights, sensors)
    log_3d = oracle.brightness_log_probability(reflectances, lights, sensors)
    big = scenes.sample(jax.random.key(8), world, args.scenes, 8)
    for label, run_oracle in [
        ("C-by-C-MMSE", lambda k: oracle.estimate_2d("MMSE", log_2d, rg, rgb[k], mask[k])),
        ("RGB-C-by-C-MMSE", lambda k: oracle.estimate_3d("MMSE", log_3d, rg, rgb[k], mask[k])),
    ]:
        start = time.perf_counter()
        for k in range(len(rgb)):
            run_oracle(k)
        oracle_rate = len(rgb) / (time.perf_counter() - start)
        median, _ = _timed(lambda model=models[label]: _estimate(model, big.rgb, big.mask), args.repeats)
        print(
            f"  NumPy loop oracle {label:<18} 8 surfaces: {oracle_rate:>8.1f} scenes/s -> ccjax / oracle "
            f"{args.scenes / median / oracle_rate:.0f}x"
        )

    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak resident memory: {peak:.0f} MB")


if __name__ == "__main__":
    main()
