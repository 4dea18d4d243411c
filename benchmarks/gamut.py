"""Benchmark: 3-D gamut mapping (CRULE-AVE, ECRULE-MV, ECRULE-SCWIA-12) against the per-scene SciPy oracle.

Prints, on World.barnard1999 with compiled (warm) functions, in one run:
* the device, jax version, cores and the load average (before each size: other load on the
  machine shows in the wall figures; the CPU figures divide by this process's CPU seconds);
* throughput in scenes/s at 8, 64, 256 and 1024 surfaces: wall clock, and per CPU-second of
  this process times the core count, with the CPU cost per observed point (us per scene per
  surface) so the scaling with the scene size is visible; beside it the achieved FLOP/s and
  bytes/s from XLA's cost analysis of the compiled program (``compiled.cost_analysis()``; it
  counts a loop's body once, so these are lower bounds) and, where the device's float32 peak is
  known (or given with ``--peak-tflops``), the fraction of it. Batches are the library's shapes
  for the backend: ``--blocks`` blocks of :func:`ccjax.backends.block_scenes` at 8 surfaces,
  proportionally fewer (at least one) at larger sizes, so a run lasts about as long at every
  size;
* the exact SciPy oracle of tests/gamut_oracle.py (Qhull halfspace intersection and exact
  centroid, i.e. CRULE-AVE) on the first ``--oracle-scenes`` scenes of the same batches (one
  core), and the ratios ccjax CRULE-AVE / oracle, wall and CPU-normalised;
* a real-image-sized case: 64x64 Mondrian images (16 surfaces in 16x16 tiles) through the default
  preprocessing (ave5 block averages, padded surface lists), scenes/s;
* peak resident memory after a chunked ECRULE-SCWIA-12 sweep at 64 surfaces (bounded by the chunk);
* with ``--extended``: the extended labels (SP-, MET-, FL-, SP-ND-, ND-ECRULE-SCWIA-N)
  beside their base method (the label without its extension prefix) at 8 and 64 surfaces, with the
  ratio of their CPU-normalised throughputs (acceptance: within 2x).

Usage: python benchmarks/gamut.py [--repeats 3] [--surfaces 8,64,256,1024] [--oracle-scenes 100]
       [--sweep-scenes 100000] [--extended] [--extended-surfaces 8,64] [--blocks 32]
       [--peak-tflops X]
       (``--surfaces ''`` skips the main table)
"""

from __future__ import annotations

import argparse
import os
import pathlib
import re
import resource
import sys
import time

import equinox as eqx
import jax
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))

import gamut_oracle as oracle  # pyright: ignore[reportMissingImports]  (tests/ on sys.path above)

from ccjax import experiments, preprocessing, scenes
from ccjax.backends import block_scenes
from ccjax.estimators import registry
from ccjax.estimators.base import estimate_batch
from ccjax.io.reading import LinearImage
from ccjax.world import World

LABELS = ("CRULE-AVE", "ECRULE-MV", "ECRULE-SCWIA-12")
EXTENDED = (
    "SP-ECRULE-SCWIA-12",
    "MET-ECRULE-SCWIA-12",
    "FL-ECRULE-SCWIA-12",
    "SP-ND-ECRULE-SCWIA-6",
    "ND-ECRULE-SCWIA-12",
)
# float32 peak (no tensor cores) of the devices ccjax was measured on, FLOP/s (vendor figures).
PEAK_FLOPS = {"NVIDIA H200": 67e12, "NVIDIA H100 80GB HBM3": 67e12, "NVIDIA H100": 67e12}


def batch_scenes(n_surfaces: int, blocks: int) -> int:
    """Scenes per timed batch: ``blocks`` of the library's blocks at 8 surfaces, proportionally
    fewer at larger sizes (at least one block)."""
    return block_scenes(jax.default_backend()) * max(1, blocks * 8 // n_surfaces)


def cost_rates(model, rgb, mask, seconds: float, peak: float | None) -> str:
    """Achieved FLOP/s and bytes/s of one compiled batch (XLA's cost analysis), and the fraction
    of the float32 peak."""
    analysis = _estimate.lower(model, rgb, mask).compile().compiled.cost_analysis()
    if isinstance(analysis, list):  # older jax: one dict per program
        analysis = analysis[0]
    flops, moved = float(analysis.get("flops", 0.0)), float(analysis.get("bytes accessed", 0.0))
    line = f"{flops / seconds / 1e9:8.2f} GFLOP/s, {moved / seconds / 1e9:7.2f} GB/s"
    return line + (f" ({flops / seconds / peak:.2e} of fp32 peak)" if peak else "")


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


def _load() -> str:
    one, five, _ = os.getloadavg()
    loaded = " (LOADED: other processes share the cores; wall figures are pessimistic)" if one > 1.5 else ""
    return f"load average {one:.1f} / {five:.1f}{loaded}"


def _oracle(A, b, white, rgb, mask, count):
    """The exact CRULE-AVE answers of the first ``count`` scenes: (wall s, CPU s)."""
    wall, cpu = time.perf_counter(), time.process_time()
    for k in range(count):
        Ad, bd = oracle.scene_constraints(A, b, rgb[k][mask[k]])
        poly = oracle.polytope(Ad, bd)
        if poly is not None:
            white / poly.centroid
    return time.perf_counter() - wall, time.process_time() - cpu


def _base_label(label: str) -> str:
    """The method without its canonical-gamut extension prefix: SP-ND-ECRULE-SCWIA-6 -> ECRULE-SCWIA-6."""
    match = re.search(r"(?:^|-)(E?CRULE-.*)$", label)
    if match is None:
        raise ValueError(f"--extended-labels: {label!r} is not a CRULE/ECRULE label")
    return match.group(1)


def _extended(world, labels, surfaces, repeats, cores, blocks):
    """Throughput of each extended label beside its base method (within 2x)."""
    bases = sorted({_base_label(label) for label in labels})
    models = {label: registry.fit(label, world) for label in [*bases, *labels]}
    print(f"extended labels beside their base method (median of {repeats} warm runs):")
    for n in surfaces:
        print(f"-- {n} surfaces, {_load()}")
        size = batch_scenes(n, blocks)
        batch = scenes.sample(jax.random.key(1000 + n), world, size, n)
        cpu_rates = {}
        for label in [*bases, *labels]:
            model = models[label]
            jax.block_until_ready(_estimate(model, batch.rgb, batch.mask))
            wall, cpu = _timed(lambda model=model, batch=batch: _estimate(model, batch.rgb, batch.mask), repeats)
            cpu_rates[label] = size / cpu * cores
            line = (
                f"  {label:<22}{n:>6} surfaces: {size / wall:>8.0f} scenes/s wall, "
                f"{cpu_rates[label]:>8.0f} scenes/s cpu"
            )
            if label in labels:
                base = _base_label(label)
                ratio = cpu_rates[base] / cpu_rates[label]
                verdict = "ok" if ratio <= 2.0 else "MISS"
                line += f"  ({base} / this = {ratio:.2f}x per CPU-second: {verdict}, must be <= 2)"
            print(line, flush=True)


def _mondrian_images(world, count, key):
    """``count`` 64x64 linear images of 16 surfaces in 16x16 tiles, as surface lists through the
    default preprocessing (ave5 block averages, padded)."""
    batch = scenes.sample(key, world, count, 16)
    rgb = np.asarray(batch.rgb, np.float32).reshape(count, 4, 4, 3)
    rgb = rgb / rgb.max(axis=(1, 2, 3), keepdims=True) * 0.9
    images = np.repeat(np.repeat(rgb, 16, axis=1), 16, axis=2)
    lists = [
        preprocessing.surfaces(LinearImage(rgb=image, clipped=np.zeros(image.shape[:2], bool)), pad=False)[0]
        for image in images
    ]
    # The dark rule drops a different number of blocks per image: one batch needs one padded
    # length, the size class of the longest list (as ccjax evaluate groups images by size class).
    size = preprocessing.padded_size(max(len(r) for r in lists))
    rgb = np.zeros((count, size, 3), np.float32)
    mask = np.zeros((count, size), bool)
    for index, rows in enumerate(lists):
        rgb[index, : len(rows)] = rows
        mask[index, : len(rows)] = True
    return rgb, mask


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--surfaces", default="8,64,256,1024")
    parser.add_argument("--labels", default=",".join(LABELS))
    parser.add_argument("--oracle-scenes", type=int, default=100)
    parser.add_argument("--images", type=int, default=256, help="64x64 images of the image case (0: skip)")
    parser.add_argument("--sweep-scenes", type=int, default=100_000, help="scenes of the memory sweep (0: skip)")
    parser.add_argument("--extended", action="store_true", help="also the extended labels beside their base method")
    parser.add_argument("--extended-labels", default=",".join(EXTENDED))
    parser.add_argument("--extended-surfaces", default="8,64")
    parser.add_argument("--blocks", type=int, default=32, help="blocks of the library's size per batch at 8 surfaces")
    parser.add_argument(
        "--peak-tflops", type=float, default=None, help="the device float32 peak (default: known devices)"
    )
    args = parser.parse_args()
    surfaces = [int(n) for n in args.surfaces.split(",") if n]
    for n in surfaces + [int(n) for n in args.extended_surfaces.split(",") if n]:
        if n < 1:
            raise ValueError(f"--surfaces: each count must be positive, got {n}")
    if args.blocks < 1:
        raise ValueError(f"--blocks: must be positive, got {args.blocks}")
    labels = args.labels.split(",")
    cores = os.cpu_count() or 1
    kind = jax.devices()[0].device_kind
    peak = args.peak_tflops * 1e12 if args.peak_tflops else PEAK_FLOPS.get(kind)

    print(f"jax {jax.__version__}, device {kind} ({jax.default_backend()}), cpus {cores}")
    print(f"block {block_scenes(jax.default_backend())} scenes (ccjax.backends); fp32 peak {peak or 'unknown'} FLOP/s")
    print(_load())
    world = World.barnard1999()
    start = time.perf_counter()
    models = {label: registry.fit(label, world) for label in labels}
    print(f"world: {world.name} {world.sizes()}; fit {len(models)} models in {time.perf_counter() - start:.2f} s")

    A, b = oracle.hull_halfspaces(np.asarray(world.canonical_rgb, np.float64))
    white = np.asarray(world.canonical_white, np.float64)
    print(
        f"throughput, median of {args.repeats} warm runs (cpu = scenes per CPU-second of this process x {cores}"
        " cores; per point = CPU us per scene per surface):"
    )
    for n in surfaces:
        print(f"-- {n} surfaces, {_load()}")
        size = batch_scenes(n, args.blocks)
        batch = scenes.sample(jax.random.key(n), world, size, n)
        rates = {}
        for label, model in models.items():
            start = time.perf_counter()
            jax.block_until_ready(_estimate(model, batch.rgb, batch.mask))
            first = time.perf_counter() - start
            wall, cpu = _timed(lambda model=model, batch=batch: _estimate(model, batch.rgb, batch.mask), args.repeats)
            rates[label] = (size / wall, size / cpu)
            print(
                f"  {label:<16}{n:>6} surfaces: {size / wall:>8.0f} scenes/s wall, "
                f"{size / cpu * cores:>8.0f} scenes/s cpu, {cpu / size / n * 1e6:>7.2f} us/point, "
                f"{cost_rates(model, batch.rgb, batch.mask, wall, peak)} (batch {size}, first call {first:.1f} s)",
                flush=True,
            )
        count = args.oracle_scenes
        if count:
            wall, cpu = _oracle(A, b, white, np.asarray(batch.rgb, np.float64), np.asarray(batch.mask), count)
            line = (
                f"  SciPy oracle CRULE-AVE{n:>6} surfaces: {count / wall:>8.1f} scenes/s wall, "
                f"{count / cpu:>8.1f} per CPU-second (one core, {count} scenes), {cpu / count / n * 1e6:.0f} us/point"
            )
            if "CRULE-AVE" in rates:
                line += (
                    f" -> ccjax CRULE-AVE / oracle {rates['CRULE-AVE'][0] * wall / count:.1f}x wall, "
                    f"{rates['CRULE-AVE'][1] * cpu / count:.1f}x per CPU-second"
                )
            print(line)

    if args.images:
        print(f"-- 64x64 images through the default preprocessing ({args.images} images), {_load()}")
        rgb, mask = _mondrian_images(world, args.images, jax.random.key(64))
        print(f"  surface lists: {int(mask.sum(axis=1).mean())} blocks per image, padded to {rgb.shape[1]}")
        for label, model in models.items():
            jax.block_until_ready(_estimate(model, rgb, mask))
            wall, cpu = _timed(lambda model=model: _estimate(model, rgb, mask), args.repeats)
            print(
                f"  {label:<16} 64x64 images: {args.images / wall:>8.0f} images/s wall, "
                f"{args.images / cpu * cores:>8.0f} images/s cpu"
            )

    if args.extended:
        extended_surfaces = [int(n) for n in args.extended_surfaces.split(",") if n]
        _extended(world, args.extended_labels.split(","), extended_surfaces, args.repeats, cores, args.blocks)

    if args.sweep_scenes:
        label = "ECRULE-SCWIA-12"
        model = models.get(label) or registry.fit(label, world)
        before = _peak_mb()
        start = time.perf_counter()
        result = experiments.sweep(world, [(label, model)], [64], args.sweep_scenes, chunk_size=8192, progress=False)
        elapsed = time.perf_counter() - start
        print(
            f"sweep of {args.sweep_scenes} scenes ({label}, 64 surfaces, chunks of 8192): {elapsed:.1f} s, "
            f"rg RMS {result.value(label, 64, 'rg'):.4f}, ok {result.ok_fraction(label, 64):.2%}; "
            f"peak resident memory {before:.0f} MB before, {_peak_mb():.0f} MB after; {_load()}"
        )
    print(f"peak resident memory: {_peak_mb():.0f} MB")


if __name__ == "__main__":
    main()
