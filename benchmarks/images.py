"""Image pipeline throughput against OpenCV (warm, compiled functions; file I/O excluded).

Prints, per image: grey world estimate + diagonal correction of a 16-bit image (uint16 in, uint16
out, pixels with a channel at or above 90 % of full scale left out of the estimate, as OpenCV's
default saturation threshold does) with ccjax (jit) and with OpenCV's ``xphoto`` GrayworldWB, on
one 1-megapixel image and on a batch of 64 (ccjax: one vmapped call; OpenCV: a loop), their ratio
(ccjax time / OpenCV time; <= 1 means ccjax is at least as fast), grey edge (n=1, p=6, sigma=2) on
1 MP, the machine's load average and the peak resident memory.

Run: ``python benchmarks/images.py [--side 1000] [--batch 64]`` (needs the ``bench`` extra:
``pip install 'ccjax[bench]'`` for opencv-contrib-python-headless).
"""

from __future__ import annotations

import argparse
import os
import resource
import time

import jax
import jax.numpy as jnp
import numpy as np

from ccjax.correction import correct
from ccjax.estimators.simple import GreyWorld
from ccjax.estimators.spatial import GreyEdge
from ccjax.preprocessing import estimate_pixels

SATURATION = 0.9  # OpenCV GrayworldWB's default threshold, as a fraction of full scale


def best_time(fn, *args, repeats=15):
    jax.block_until_ready(fn(*args))  # warm-up / compile
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn(*args))
        best = min(best, time.perf_counter() - start)
    return best


GREY_WORLD = GreyWorld(scale=jnp.full(3, 2.0), fallback=jnp.ones(3))


def grey_world_correct(codes: jax.Array) -> jax.Array:
    """uint16 (H, W, 3) -> ccjax GW estimate on unsaturated pixels -> diagonal correction -> uint16."""
    mask = jnp.max(codes, axis=-1) < int(SATURATION * 65535)
    rgb = codes.astype(jnp.float32) * (1.0 / 65535.0)
    estimate = estimate_pixels(GREY_WORLD, rgb, mask)
    # Canonical white = grey (1, 1, 1): the target of OpenCV's grey world too.
    corrected = correct(rgb, estimate.illuminant, jnp.ones(3, jnp.float32))
    return jnp.minimum(corrected * 65535.0 + 0.5, 65535.0).astype(jnp.uint16)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--side", type=int, default=1000, help="image side (default 1000: 1 MP)")
    parser.add_argument("--batch", type=int, default=64)
    args = parser.parse_args()
    import cv2

    rng = np.random.default_rng(0)
    side = args.side
    # A smooth colour-cast image with texture and a few saturated pixels.
    y, x = np.mgrid[:side, :side] / side
    base = np.stack([0.6 + 0.3 * np.sin(6 * x), 0.45 + 0.3 * np.cos(5 * y), 0.3 + 0.2 * np.sin(4 * (x + y))], -1)
    image = np.clip(base * (0.7 + 0.3 * rng.random((side, side, 1))), 0, 1)
    image[:10, :10] = 1.0
    codes = np.round(image * 65535).astype(np.uint16)
    batch = np.stack([np.roll(codes, 17 * i, axis=1) for i in range(args.batch)])
    print(
        f"jax {jax.__version__} on {jax.devices()[0].platform}, OpenCV {cv2.__version__}; "
        f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs"
    )

    single = jax.jit(grey_world_correct)
    # One compiled call over the batch, image after image (lax.map): a 1-MP working set stays in
    # cache, where vmap would materialise every intermediate for the whole batch at once.
    batched = jax.jit(lambda b: jax.lax.map(grey_world_correct, b))
    device_codes, device_batch = jnp.asarray(codes), jnp.asarray(batch)
    ours_1 = best_time(single, device_codes)
    ours_b = best_time(batched, device_batch, repeats=5) / args.batch
    device_images = [jnp.asarray(b) for b in batch]
    ours_loop = best_time(lambda: [single(b) for b in device_images], repeats=5) / args.batch

    wb = cv2.xphoto.createGrayworldWB()
    wb.setSaturationThreshold(SATURATION)
    bgr = np.ascontiguousarray(codes[..., ::-1])
    bgr_batch = [np.ascontiguousarray(b[..., ::-1]) for b in batch]

    def opencv_single():
        return wb.balanceWhite(bgr)

    def opencv_batch():
        return [wb.balanceWhite(b) for b in bgr_batch]

    theirs_1 = best_time(opencv_single)
    theirs_b = best_time(opencv_batch, repeats=5) / args.batch

    # Agreement of the two grey worlds (same saturation rule; OpenCV estimates in its own way).
    ours = np.asarray(single(device_codes)).astype(np.float64).reshape(-1, 3)
    theirs = np.asarray(opencv_single())[..., ::-1].astype(np.float64).reshape(-1, 3)
    cos = np.sum(ours.mean(0) * theirs.mean(0)) / np.linalg.norm(ours.mean(0)) / np.linalg.norm(theirs.mean(0))
    angle = np.degrees(np.arccos(min(1.0, cos)))

    megapixels = side * side / 1e6
    print(f"grey world estimate + correction, {side}x{side} ({megapixels:.2f} MP) uint16:")
    single_line = f"ccjax {1e3 * ours_1:8.2f} ms   OpenCV {1e3 * theirs_1:8.2f} ms   ratio {ours_1 / theirs_1:5.2f}"
    print(f"  single image : {single_line}")
    batch_line = f"ccjax {1e3 * ours_b:8.2f} ms   OpenCV {1e3 * theirs_b:8.2f} ms   ratio {ours_b / theirs_b:5.2f}"
    print(f"  batch of {args.batch:<3} : {batch_line}   (per image; one compiled lax.map call)")
    loop_line = f"ccjax {1e3 * ours_loop:8.2f} ms   OpenCV {1e3 * theirs_b:8.2f} ms   ratio {ours_loop / theirs_b:5.2f}"
    print(f"  batch of {args.batch:<3} : {loop_line}   (per image; loop of the compiled single-image call)")
    print(f"  mean corrected colour, ccjax vs OpenCV: {angle:.3f} degrees apart")

    edge = GreyEdge(order=1, p=6.0, sigma=2.0, fallback=jnp.ones(3))
    image_f32 = jnp.asarray(codes, jnp.float32) / 65535.0
    mask = jnp.all(image_f32 < SATURATION, axis=-1)
    edge_fn = jax.jit(lambda x, m: edge(x, m).illuminant)
    edge_time = best_time(edge_fn, image_f32, mask)
    print(f"grey edge n=1 p=6 sigma=2, {megapixels:.2f} MP float32: {1e3 * edge_time:8.2f} ms (target < 50 ms)")
    print(f"peak resident memory: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
