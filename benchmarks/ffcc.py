"""FFCC throughput and training time (Barron & Tsai 2017).

Inference: thumbnails per second of a trained-size FFCC (64 x 64 bins) on 64 x 64 images through
:func:`ccjax.estimators.base.estimate_batch` (one ``vmap`` per block of the batch; warm, compiled;
the histograms, convolution, softmax and von Mises fit included). Training: seconds of
:func:`ccjax.estimators.ffcc.train` on ``--train`` synthetic thumbnails (compilation included,
then a second, warm fit of the same shape).

Run: ``python benchmarks/ffcc.py [--images 4096] [--train 1140]``.
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

from ccjax.estimators.base import estimate_batch
from ccjax.estimators.ffcc import init_ffcc, train


def thumbnails(count: int, seed: int = 0, size: int = 64) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mondrians of 8 x 8 patches under random lights, with some clipped pixels masked out."""
    rng = np.random.default_rng(seed)
    lights = np.exp(rng.normal(0, 0.3, (count, 3))) * np.array([0.5, 1.0, 0.6])
    patches = rng.uniform(0.02, 0.9, (count, 8, 8, 3))
    images = np.repeat(np.repeat(patches, size // 8, axis=1), size // 8, axis=2) * lights[:, None, None, :]
    images = images + rng.normal(0, 0.002, images.shape)
    masks = np.all((images > 0) & (images < 1), axis=-1)
    return images.clip(0, 1).astype(np.float32), masks, lights.astype(np.float32)


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--images", type=int, default=4096, help="thumbnails in the inference batch")
    parser.add_argument("--train", type=int, default=1140, help="training thumbnails (one Cube+ fold)")
    args = parser.parse_args()
    print(f"backend: {jax.default_backend()}, devices: {jax.device_count()}")

    images, masks, lights = thumbnails(args.train)
    for run in ("cold (compiles)", "warm"):
        start, cpu = time.perf_counter(), time.process_time()
        model, record = train(init_ffcc(), images, masks, lights)
        print(
            f"training on {args.train} thumbnails, {run}: {time.perf_counter() - start:.1f} s wall, "
            f"{time.process_time() - cpu:.1f} s CPU (losses {record.losses[0]:.3g}, {record.losses[-1]:.3g})"
        )

    images, masks, _ = thumbnails(args.images, seed=1)
    x, m = jnp.asarray(images), jnp.asarray(masks)
    run = jax.jit(estimate_batch)
    jax.block_until_ready(run(model, x, m))
    best, best_cpu = np.inf, np.inf
    for _ in range(3):
        start, cpu = time.perf_counter(), time.process_time()
        jax.block_until_ready(run(model, x, m))
        best, best_cpu = min(best, time.perf_counter() - start), min(best_cpu, time.process_time() - cpu)
    # On a shared machine the wall clock counts other processes' time; CPU seconds do not.
    print(
        f"inference: {args.images / best:,.0f} thumbnails/s wall ({1e3 * best / args.images:.3f} ms/image, 64 x 64), "
        f"{args.images / best_cpu:,.0f} thumbnails per CPU second"
    )


if __name__ == "__main__":
    main()
