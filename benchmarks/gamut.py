"""Benchmark: 3-D gamut mapping (ECRULE-SCWIA-12 and CRULE-AVE) against the per-scene SciPy oracle.

Prints, on World.barnard1999 with compiled (warm) functions on this machine:
* throughput in scenes/s at 8, 64 and 1024 surfaces (wall clock, and per CPU-second of this
  process so that other load on the machine shows);
* the exact SciPy oracle of tests/gamut_oracle.py (Qhull halfspace intersection and exact
  centroid, i.e. CRULE-AVE) on scenes from the same batches, and the ratio;
* peak resident memory after a chunked sweep of many scenes (memory is bounded by the chunk).

Usage: python benchmarks/gamut.py [--repeats 3] [--sweep-scenes 100000]
"""

from __future__ import annotations

import argparse
import os
import pathlib
import resource
import sys
import time

import equinox as eqx
import jax
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))

import gamut_oracle as oracle

from ccjax import experiments, scenes
from ccjax.estimators import registry
from ccjax.estimators.base import estimate_batch
from ccjax.world import World

BATCH = {8: 4096, 64: 1024, 1024: 128}
ORACLE_SCENES = {8: 100, 64: 40, 1024: 5}


@eqx.filter_jit
def _estimate(model, rgb, mask):
    # The library's batched path: vmapped blocks of model.block_size scenes (cache-sized).
    return estimate_batch(model, rgb, mask).illuminant


def _timed(fn, repeats):
    walls, cpus = [], []
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        jax.block_until_ready(fn())
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return float(np.median(walls)), float(np.median(cpus))


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--surfaces", default="8,64,1024")
    parser.add_argument("--sweep-scenes", type=int, default=100_000, help="scenes of the memory sweep (0: skip)")
    args = parser.parse_args()
    surfaces = [int(n) for n in args.surfaces.split(",")]

    print(
        f"jax {jax.__version__}, backend {jax.default_backend()}, "
        f"cpus {os.cpu_count()}, load average {os.getloadavg()[0]:.1f}"
    )
    world = World.barnard1999()
    labels = ("ECRULE-SCWIA-12", "CRULE-AVE")
    start = time.perf_counter()
    models = {label: registry.fit(label, world) for label in labels}
    print(f"world: {world.name} {world.sizes()}; fit both models in {time.perf_counter() - start:.2f} s")

    A, b = oracle.hull_halfspaces(np.asarray(world.canonical_rgb, np.float64))
    white = np.asarray(world.canonical_white, np.float64)
    print(
        f"throughput, median of {args.repeats} warm runs (cpu "
        f"= scenes per CPU-second of this process x {os.cpu_count()} cores):"
    )
    for n in surfaces:
        batch = scenes.sample(jax.random.key(n), world, BATCH[n], n)
        rates = {}
        for label, model in models.items():
            start = time.perf_counter()
            jax.block_until_ready(_estimate(model, batch.rgb, batch.mask))
            first = time.perf_counter() - start
            wall, cpu = _timed(lambda model=model, batch=batch: _estimate(model, batch.rgb, batch.mask), args.repeats)
            rates[label] = BATCH[n] / wall
            print(
                f"  {label:<16}{n:>6} surfaces: {BATCH[n] / wall:>8.0f} scenes/s wall, "
                f"{BATCH[n] / cpu * os.cpu_count():>8.0f} scenes/s cpu (batch {BATCH[n]} "
                f"in vmapped blocks of {type(model).block_size}, first call {first:.1f} s)"
            )
        # The exact oracle (CRULE-AVE: halfspace intersection + exact centroid) on the same scenes.
        rgb, mask = np.asarray(batch.rgb, np.float64), np.asarray(batch.mask)
        count = ORACLE_SCENES[n]
        start = time.perf_counter()
        for k in range(count):
            Ad, bd = oracle.scene_constraints(A, b, rgb[k][mask[k]])
            poly = oracle.polytope(Ad, bd)
            if poly is not None:
                white / poly.centroid
        rate = count / (time.perf_counter() - start)
        print(
            f"  SciPy oracle CRULE-AVE{n:>6} surfaces: {rate:>8.1f} scenes/s "
            f"(one core) -> ccjax CRULE-AVE / oracle {rates['CRULE-AVE'] / rate:.0f}x"
        )

    if args.sweep_scenes:
        before = _peak_mb()
        start = time.perf_counter()
        result = experiments.sweep(
            world,
            [("ECRULE-SCWIA-12", models["ECRULE-SCWIA-12"])],
            [8],
            args.sweep_scenes,
            chunk_size=8192,
            progress=False,
        )
        elapsed = time.perf_counter() - start
        print(
            f"sweep of {args.sweep_scenes} scenes (8 surfaces, chunks of 8192): {elapsed:.1f} s, "
            f"rg RMS {result.value('ECRULE-SCWIA-12', 8, 'rg'):.4f}, "
            f"ok {result.ok_fraction('ECRULE-SCWIA-12', 8):.2%}; "
            f"peak resident memory {before:.0f} MB before, {_peak_mb():.0f} MB after"
        )
    print(f"peak resident memory: {_peak_mb():.0f} MB")


if __name__ == "__main__":
    main()
