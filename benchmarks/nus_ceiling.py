"""In-camera FFCC on NUS-8 thumbnails: what separates ccjax's 3-fold FFCC from the figures of FFCC's
paper (Barron & Tsai 2017) and of its reference code (google/ffcc), measured by changing one
thing at a time (docs/camera-without-labels.md, "The in-camera ceiling on NUS").

Each folder (a NUS-8 camera: 64 x 64 16-bit PNG thumbnails, ``groundtruth.csv``) is read exactly
as ``ccjax evaluate DIR --ground-truth-name groundtruth.csv --saturation 64224 --folds 3 --train
FFCC --seed S`` reads it, split into the same seeded folds, and each fold's FFCC is trained on the
other two folds and scored on it. Variants:

Hyperparameters (``--settings``):
  choose   ccjax's default: the setting chosen among the reference's NUS thumbnail settings by
           two-fold validation inside the training folds (:func:`ccjax.estimators.ffcc.choose`).
  camera   the reference code's own tuned setting for that camera (``Cheng<camera>ThumbHyperparams``,
           tuned by its authors on that camera's images), fixed.

Input (``--inputs``):
  shipped  the loader's mask (not clipped, no zero channel).
  pool2    2 x 2 masked means (32 x 32; a block with no usable pixel is masked): a quarter of the
           pixels, each the mean of up to four, as the reference code's masked, antialiased
           downsampling to 32 x 48 does on the originals.
  pool4    the same with 4 x 4 blocks (16 x 16).
  blur3    3 x 3 masked means at every pixel (64 x 64 kept): averaging without pool2's loss of
           pixels.
  sat<f>   also mask every pixel with a channel at or above ``f`` of the image's maximum (``sat0.5``).
  dark<f>  also mask every pixel with a channel below ``f`` of the image's maximum (``dark0.02``).

Run: ``python benchmarks/nus_ceiling.py photosets/nus8-C1 --seeds 0 --settings camera --inputs
shipped,pool2,blur3`` (one line per folder, variant, setting and seed; each variant after the first
also with the paired bootstrap 95 % interval of its change of the mean and the median against the
first input with the same setting and seed; ``--json`` appends the per-image errors).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from ccjax.estimators.base import estimate_batch
from ccjax.estimators.ffcc import CANDIDATES, Hyperparameters, choose, init_ffcc, train
from ccjax.io import match_ground_truth, read_ground_truth
from ccjax.metrics import angular_error
from ccjax.training import assign_folds, read_examples

SATURATION = 64224
"""The clip level of the development thumbnails, in file codes (0.98 of 65535)."""

CAMERA_SETTINGS = {
    "Canon600D": CANDIDATES[0],
    "C1": CANDIDATES[1],  # Canon 1Ds Mark III
    "NikonD5200": CANDIDATES[2],
    "Olympus": CANDIDATES[3],
    "Panasonic": CANDIDATES[4],
    "Samsung": CANDIDATES[5],
    "Sony": CANDIDATES[6],
    # ChengFujifilmXM1ThumbHyperparams (google/ffcc); left out of ccjax's candidates (its filter L2
    # of 2^-73.5 makes float32 L-BFGS crawl), given here for the comparison only.
    "Fuji": Hyperparameters(
        crossent=2**-11.0,
        vonmises=2**-1.5,
        filter_tv=(2**-23.75, 2**-26.75),
        filter_l2=(2**-73.5, 2**-33.0),
        bias_tv=2**-21.5,
        bias_l2=2**-45.0,
    ),
}


def load(folder: Path):
    """The folder's thumbnails as ``ccjax evaluate`` prepares them for FFCC."""
    truth = read_ground_truth(folder / "groundtruth.csv")
    pairs = match_ground_truth(truth, folder)
    names = list(truth)
    lights = np.stack([light for _, light in pairs]).astype(np.float32)
    examples, failures = read_examples(
        [path for path, _ in pairs], lights, names, init_ffcc(), read_options={"saturation": SATURATION}
    )
    if failures:
        raise SystemExit(f"{folder}: unreadable {failures}")
    return np.asarray(examples.x), np.asarray(examples.mask), np.asarray(examples.illuminant), list(examples.names)


def pooled(x: np.ndarray, mask: np.ndarray, block: int) -> tuple[np.ndarray, np.ndarray]:
    """Masked ``block x block`` means (a block with no usable pixel is masked)."""
    n, h, w, _ = x.shape
    weight = mask[..., None].astype(np.float64)
    shape = (n, h // block, block, w // block, block)
    total = (x * weight).reshape(*shape, 3).sum(axis=(2, 4))
    count = weight.reshape(*shape, 1).sum(axis=(2, 4))
    return (total / np.maximum(count, 1)).astype(np.float32), count[..., 0] > 0


def blurred(x: np.ndarray, mask: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Masked ``size x size`` means centred on every pixel (edges replicated); the mask is kept."""
    weight = mask[..., None].astype(np.float64)
    low, high = (size - 1) // 2, size // 2
    pad = ((0, 0), (low, high), (low, high), (0, 0))
    total, count = np.pad(x * weight, pad, mode="edge"), np.pad(weight, pad, mode="edge")
    h, w = mask.shape[1:]
    sums = sum(total[:, i : i + h, j : j + w] for i in range(size) for j in range(size))
    counts = sum(count[:, i : i + h, j : j + w] for i in range(size) for j in range(size))
    return (sums / np.maximum(counts, 1)).astype(np.float32), mask


def prepared(x: np.ndarray, mask: np.ndarray, variant: str) -> tuple[np.ndarray, np.ndarray]:
    """The input of one variant (module docstring)."""
    if variant == "shipped":
        return x, mask
    if variant.startswith("pool"):
        return pooled(x, mask, int(variant[4:]))
    if variant.startswith("blur"):
        return blurred(x, mask, int(variant[4:]))
    peak = x.reshape(len(x), -1).max(axis=1)[:, None, None]
    if variant.startswith("sat"):
        return x, mask & np.all(x < float(variant[3:]) * peak[..., None], axis=-1)
    if variant.startswith("dark"):
        return x, mask & np.all(x >= float(variant[4:]) * peak[..., None], axis=-1)
    raise SystemExit(f"--inputs: unknown variant {variant!r}")


def cross_validate(x, mask, lights, names, seed: int, settings: Hyperparameters | None) -> np.ndarray:
    """Per-image errors of 3-fold FFCC (the folds of ``ccjax evaluate --folds 3 --seed seed``)."""
    folds = assign_folds(names, 3, seed=seed)
    errors = np.empty(len(names))
    for fold in range(3):
        fit, held = folds != fold, folds == fold
        chosen = settings
        if chosen is None:
            chosen, _ = choose(init_ffcc(), x[fit], mask[fit], lights[fit], seed=seed)
        model, _ = train(init_ffcc(), x[fit], mask[fit], lights[fit], chosen)
        estimate = estimate_batch(model, jnp.asarray(x[held]), jnp.asarray(mask[held]))
        errors[held] = np.asarray(angular_error(estimate.illuminant, jnp.asarray(lights[held])))
    return errors


def paired_change(before: np.ndarray, after: np.ndarray, draws: int = 2000) -> str:
    """The paired bootstrap 95 % intervals of the change of the mean and of the median."""
    pick = np.random.default_rng(0).integers(0, len(before), (draws, len(before)))
    mean = np.percentile(after[pick].mean(axis=1) - before[pick].mean(axis=1), [2.5, 97.5])
    median = np.percentile(np.median(after[pick], axis=1) - np.median(before[pick], axis=1), [2.5, 97.5])
    return f"change: mean {mean[0]:+.2f} to {mean[1]:+.2f}, median {median[0]:+.2f} to {median[1]:+.2f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("folders", nargs="+", type=Path, help="NUS-8 camera folders (nus8-<camera>)")
    parser.add_argument("--seeds", default="0", help="comma-separated fold seeds")
    parser.add_argument("--settings", default="choose", help="comma-separated: choose, camera")
    parser.add_argument("--inputs", default="shipped", help="comma-separated input variants")
    parser.add_argument("--json", type=Path, help="append one JSON line per run (per-image errors)")
    args = parser.parse_args()
    for folder in args.folders:
        camera = folder.name.removeprefix("nus8-")
        x0, mask0, lights, names = load(folder)
        first: dict[tuple[str, int], np.ndarray] = {}
        for variant in args.inputs.split(","):
            x, mask = prepared(x0, mask0, variant)
            for setting in args.settings.split(","):
                fixed = None if setting == "choose" else CAMERA_SETTINGS[camera]
                for seed in (int(s) for s in args.seeds.split(",")):
                    start = time.perf_counter()
                    errors = cross_validate(x, mask, lights, names, seed, fixed)
                    base = first.setdefault((setting, seed), errors)
                    change = "" if base is errors else "; " + paired_change(base, errors)
                    print(
                        f"{camera:11s} {variant:9s} {setting:7s} seed {seed}: mean {errors.mean():.2f} "
                        f"median {np.median(errors):.2f} ({len(errors)} images, "
                        f"usable px {mask.mean():.3f}, {time.perf_counter() - start:.0f} s{change})",
                        flush=True,
                    )
                    if args.json:
                        row = {"camera": camera, "input": variant, "settings": setting, "seed": seed}
                        row["errors"] = dict(zip(names, errors.round(4).tolist(), strict=True))
                        with args.json.open("a") as out:
                            out.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
