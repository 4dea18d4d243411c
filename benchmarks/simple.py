"""Throughput of scene sampling and of the simple estimators (warm, compiled functions).

Prints, for batches of 10^5 scenes at 8 and 1024 surfaces: scene sampling (scenes/s) and GW,
shades of grey (p = 6) and RETINEX throughput in RGB triplets per second with the achieved
memory bandwidth (GB/s of input read: 12 bytes of RGB + 1 byte of mask per triplet), the peak
resident memory, and a NumPy reference of the same estimators on the same data for comparison.

Run: ``python benchmarks/simple.py [--scenes 100000]``.
"""

from __future__ import annotations

import argparse
import resource
import time

import jax
import jax.numpy as jnp
import numpy as np

from ccjax.estimators import registry
from ccjax.scenes import SceneTables, sample_batch, scene_keys
from ccjax.world import World


def timed(fn, *args, repeats=3):
    jax.block_until_ready(fn(*args))  # warm-up / compile
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn(*args))
        best = min(best, time.perf_counter() - start)
    return best


def numpy_references(rgb: np.ndarray, mask: np.ndarray) -> dict:
    """The estimators in plain NumPy on the same data, masking included (as the JAX kernels do)."""
    return {
        "GW": lambda: 2 * np.where(mask[..., None], rgb, 0).sum(1) / mask.sum(1, keepdims=True),
        "shades-of-grey-p6": lambda: 2 * (np.where(mask[..., None], rgb, 0) ** 6).mean(1) ** (1 / 6),
        "RETINEX": lambda: np.where(mask[..., None], rgb, 0).max(1),
    }


def run_surfaces(n_surfaces: int, n_scenes: int, tables: SceneTables, models: dict) -> None:
    """Sampling and estimator throughput at one number of surfaces (one row per task)."""
    # Sampling at 1024 surfaces is chunked so the batch fits comfortably in memory.
    chunk = n_scenes if n_surfaces <= 64 else 8192
    keys = scene_keys(jax.random.key(0), 0, chunk)
    sampler = jax.jit(lambda k: sample_batch(k, tables, n_surfaces).rgb)
    seconds = timed(sampler, keys) * n_scenes / chunk
    print(f"{n_surfaces:>8}  {'sample scenes':<20}{seconds:>10.3f}{n_scenes / seconds:>12.3g} sc/s{'':>8}")

    rgb = jnp.concatenate(
        [sampler(scene_keys(jax.random.key(1), i * chunk, chunk)) for i in range(max(1, n_scenes // chunk))]
    )
    rgb = rgb[:n_scenes]
    mask = jnp.ones(rgb.shape[:2], bool)
    triplets = rgb.shape[0] * rgb.shape[1]
    references = numpy_references(np.asarray(rgb), np.asarray(mask))
    for label, model in models.items():
        run = jax.jit(lambda r, m, model=model: jax.vmap(model)(r, m).illuminant)
        seconds = timed(run, rgb, mask)
        gbps = triplets * 13 / seconds / 1e9
        start = time.perf_counter()
        references[label]()
        numpy_seconds = time.perf_counter() - start
        print(
            f"{n_surfaces:>8}  {label:<20}{seconds:>10.4f}{triplets / seconds:>12.3g} rgb/s{gbps:>8.2f}"
            f"{numpy_seconds:>11.4f}{numpy_seconds / seconds:>8.1f}x"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=100_000)
    args = parser.parse_args()
    world = World.default()
    tables = SceneTables.from_world(world)
    models = {label: registry.fit(label, world) for label in ("GW", "shades-of-grey-p6", "RETINEX")}
    print(f"jax {jax.__version__} on {jax.devices()[0].platform}, {args.scenes} scenes per batch\n")
    print(f"{'surfaces':>8}  {'task':<20}{'time (s)':>10}{'throughput':>16}{'GB/s':>8}{'numpy (s)':>11}{'speed-up':>9}")
    for n_surfaces in (8, 1024):
        run_surfaces(n_surfaces, args.scenes, tables, models)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"\npeak resident memory: {peak:.0f} MB")


if __name__ == "__main__":
    main()
