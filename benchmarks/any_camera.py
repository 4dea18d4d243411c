"""Benchmark: the any-camera estimator's training time on labelled folders and its inference per
thumbnail, beside FFCC's.

Trains one any-camera model on every given folder (each with its camera: its curves or a
stand-in's), as ``ccjax train DIR... --method any-camera`` does, and prints the seconds (what
depends only on a camera, its map into the reference space, is computed once per camera); then
times the bound model and an FFCC of the same size on the first folder's images, one jitted
``vmap`` over blocks of images, after a warm-up (median of 5 runs, milliseconds per image).
Run it on an otherwise idle machine for numbers to quote (``taskset -c 0,1`` for 2 cores).

Usage: python benchmarks/any_camera.py FOLDER=CAMERA [FOLDER=CAMERA ...]
       [--ground-truth-name groundtruth.csv] [--saturation 64224] [--copies 2] [--seed 0]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ccjax import evaluation
from ccjax.estimators.base import estimate_batch
from ccjax.evaluation.any_camera import train_any_camera
from ccjax.evaluation.scored_folder import read_folder


def per_image_ms(model, images, masks, repeats: int = 5) -> float:
    """Median milliseconds per image of ``model`` over ``images`` (compiled once first)."""
    run = eqx.filter_jit(estimate_batch)
    jax.block_until_ready(run(model, images, masks))
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(run(model, images, masks))
        times.append(time.perf_counter() - start)
    return 1000.0 * float(np.median(times)) / len(images)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="+", help="FOLDER=CAMERA")
    parser.add_argument("--ground-truth-name", default="groundtruth.csv")
    parser.add_argument("--saturation", type=float, default=None)
    parser.add_argument("--copies", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    read = evaluation.ReadOptions(image={} if args.saturation is None else {"saturation": args.saturation})
    data = []
    for entry in args.folders:
        folder, _, camera = entry.partition("=")
        directory = Path(folder)
        data.append(
            read_folder(directory, directory / args.ground_truth_name, read, camera=camera, label=directory.name)
        )
    start = time.perf_counter()
    model, log, record = train_any_camera(data, read, evaluation.TrainingOptions(seed=args.seed), copies=args.copies)
    seconds = time.perf_counter() - start
    print(
        f"any-camera: trained on {record['images']} images of {len(record['cameras_seen'])} cameras and "
        f"{record['entries'] - record['images']} copies in {seconds:.1f} s (FFCC fit {log.seconds:.1f} s)"
    )
    from ccjax import training
    from ccjax.camera import Camera
    from ccjax.estimators import ffcc
    from ccjax.preprocessing import resolve

    first = data[0]
    rule = resolve(model, read.preprocessing)
    examples, _ = training.source_examples(
        first.source, first.truth, first.path_names, "image", rule, items=first.source.usable()[:256]
    )
    bound = model.bind(Camera.from_name(str(first.camera)))
    plain = ffcc.FFCC(model.core.filters, model.core.bias, model.core.origin, model.core.bin_size)
    images, masks = jnp.asarray(examples.x), jnp.asarray(examples.mask)
    shape = "x".join(str(n) for n in images.shape[1:3])
    print(f"inference on {len(images)} {shape} images of {first.label}, ms per image (median of 5):")
    print(f"  any-camera (bound to {first.camera}): {per_image_ms(bound, images, masks):.3f}")
    print(f"  FFCC of the same size:                {per_image_ms(plain, images, masks):.3f}")


if __name__ == "__main__":
    main()
