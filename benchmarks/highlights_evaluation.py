"""Highlights on files: specular gamut mapping against matte gamut mapping and grey edge on
synthetic raw images with clipped dielectric highlights (thesis ch. 8).

The images (:func:`generate`) are the Mondrian renderer's (:func:`ccjax.scenes.mondrian_batch`)
with the lights of ``examples/synthetic_raw_evaluation.py`` (70 % CIE daylight 4000–10000 K,
20 % blackbody 2500–3500 K, 10 % FL2 / FL7 / FL11) and the camera's embedded curves:

* 16 patches of distinct SFU reflectances on 128 x 128 pixels, shading U(0.3, 1);
* dielectric highlights on 25 % of the patches (a Gaussian blob of peak U(0, 2) x shading x the
  white, :class:`ccjax.scenes.Specular`, §4.7);
* an exposure that puts the saturation level at ``--headroom`` (default 1.5) times the brightest
  channel of a perfect white under the image's light: the brighter highlights clip there, as a raw
  file's do (per channel, at the file maximum);
* Gaussian noise of variance 1e-4 x value (on the file's unit scale), then the clip at 1;
* seed 0; written as 16-bit PNGs with ``groundtruth.csv`` to a temporary folder.

``ccjax evaluate`` (a subprocess, its default reading: pixels with a channel at or above 0.98 of
the file maximum are unusable; each method's default input) scores the methods and the table of
mean, median and worst-25 % angular errors is printed, then the acceptance check: the median of
SP-ND-ECRULE-SCWIA-6 below ND-ECRULE-SCWIA-12's and grey edge (1, 6, 2)'s.

Usage: ``python benchmarks/highlights_evaluation.py [--images 200] [--headroom 1.5] [--out DIR]``
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ccjax import io, metrics, scenes
from ccjax.world import World

METHODS = ("SP-ND-ECRULE-SCWIA-6", "ND-ECRULE-SCWIA-12", "grey-edge-1-6-2")
CAMERA = "Canon EOS 5D Mark II"
HIGHLIGHTS = scenes.Specular(probability=0.25, max_amount=2.0)
"""Dielectric highlights on 25 % of the patches, peak U(0, 2) x shading x the white (§4.7)."""


def _example_light_table():
    """The example's light table (imported from its file: ``examples`` is not a package)."""
    path = Path(__file__).resolve().parent.parent / "examples" / "synthetic_raw_evaluation.py"
    spec = importlib.util.spec_from_file_location("synthetic_raw_evaluation", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.light_table


def generate(
    out: Path,
    *,
    n_images: int = 200,
    size: int = 128,
    n_patches: int = 16,
    headroom: float = 1.5,
    specular: scenes.Specular = HIGHLIGHTS,
    noise: float = 1e-4,
    camera: str = CAMERA,
    seed: int = 0,
) -> tuple[Path, float]:
    """Write the image set of the module docstring to ``out``.

    Arguments:
        out: folder (created).
        n_images, size, n_patches: how many images, their side in pixels, patches per image.
        headroom: saturation level in units of the brightest channel of the image's white.
        specular: the highlights' probability per patch and peak strength (units of a white).
        noise: Gaussian noise variance per unit value on the file scale.
        camera: embedded camera.
        seed: image ``i`` uses ``fold_in(key(seed), i)``.

    Returns:
        ``(ground-truth CSV, fraction of pixels with a clipped channel)``.
    """
    if not headroom > 0:
        raise ValueError(f"headroom: expected a positive number, got {headroom!r}")
    base = World.default(camera=camera)
    lights = _example_light_table()(np.asarray(base.camera.sensors, np.float64))
    world = World(
        reflectances=base.reflectances,
        train_illuminants=base.train_illuminants,
        test_illuminants=jnp.asarray(lights, jnp.float32),
        canonical=base.canonical,
        camera=base.camera,
        name=f"highlights-{camera}",
    )
    tables = scenes.SceneTables.from_world(world)
    images, whites, clipped = [], [], []
    for begin in range(0, n_images, 50):  # chunks bound the patch maps' memory
        count = min(50, n_images - begin)
        keys = scenes.scene_keys(jax.random.key(seed), begin, count)
        batch = scenes.mondrian_batch(keys, tables, size, size, n_patches, (0.3, 1.0), specular, None, None, False)
        # Exposure: the saturation level (file value 1) at `headroom` x the white's brightest channel.
        scale = 1.0 / (headroom * jnp.max(batch.illuminant, axis=-1))
        image = batch.image * scale[:, None, None, None]
        noisy = image + jnp.sqrt(noise * image) * jax.random.normal(jax.random.key(seed + 1 + begin), image.shape)
        image = jnp.clip(noisy, 0.0, 1.0)
        clipped.append(np.asarray(jnp.any(image >= 0.98, axis=-1)).mean(axis=(1, 2)))
        images.append(np.asarray(image))
        whites.append(np.asarray(batch.illuminant * scale[:, None]))
    truth = io.write_dataset(out, np.concatenate(images), np.concatenate(whites))
    return truth, float(np.mean(np.concatenate(clipped)))


def evaluate(folder: Path, truth: Path, methods: tuple[str, ...], camera: str, report: Path) -> dict:
    """``ccjax evaluate`` in a subprocess; returns its JSON (summaries and per-image records)."""
    command = [
        sys.executable,
        "-m",
        "ccjax",
        "evaluate",
        str(folder),
        "--ground-truth",
        str(truth),
        "--methods",
        ",".join(methods),
        "--camera",
        camera,
        "--json",
        str(report),
    ]
    print("$ ccjax " + " ".join(command[3:]), flush=True)
    completed = subprocess.run(command, check=False)
    if completed.returncode != 0:
        raise SystemExit(f"ccjax evaluate exited with status {completed.returncode}")
    return json.loads(report.read_text())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--images", type=int, default=200)
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--headroom", type=float, default=1.5, help="saturation / brightest channel of the white")
    parser.add_argument("--max-amount", type=float, default=2.0, help="peak highlight strength (units of a white)")
    parser.add_argument("--methods", default=",".join(METHODS))
    parser.add_argument("--camera", default=CAMERA)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None, help="folder for the images (default: a temporary one)")
    args = parser.parse_args(argv)
    methods = tuple(args.methods.split(","))

    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(args.out or scratch) / "images"
        start, cpu = time.perf_counter(), time.process_time()
        truth, clipped = generate(
            folder,
            n_images=args.images,
            size=args.size,
            headroom=args.headroom,
            specular=scenes.Specular(probability=0.25, max_amount=args.max_amount),
            camera=args.camera,
            seed=args.seed,
        )
        print(
            f"wrote {args.images} images of {args.size}x{args.size} ({args.camera}, saturation at "
            f"{args.headroom:g} x white, {clipped:.2%} of pixels with a clipped channel) to {folder} in "
            f"{time.perf_counter() - start:.0f} s wall, {time.process_time() - cpu:.0f} s CPU",
            flush=True,
        )
        start = time.perf_counter()
        result = evaluate(folder, truth, methods, args.camera, Path(scratch) / "evaluate.json")
        load = os.getloadavg()
        print(f"evaluate: {time.perf_counter() - start:.0f} s wall; load average {load[0]:.1f} {load[1]:.1f}")
    errors = {m: np.array([r["angular"] for r in result["images"] if r["method"] == m], float) for m in methods}
    print(f"\nangular error (degrees)\n{'method':<24}{'n':>5}{'mean':>8}{'median':>8}{'worst 25%':>11}")
    for m in methods:
        row = metrics.error_statistics(errors[m])
        print(f"{m:<24}{len(errors[m]):>5}{row['mean']:>8.3f}{row['median']:>8.3f}{row['worst25']:>11.3f}")
    if all(m in errors for m in METHODS):
        sp = np.median(errors[METHODS[0]])
        for other in METHODS[1:]:
            ok = sp < np.median(errors[other])
            print(f"{'ok  ' if ok else 'MISS'} median {METHODS[0]} {sp:.3f} < {other} {np.median(errors[other]):.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
