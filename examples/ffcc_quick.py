"""Train FFCC (Barron & Tsai, "Fast Fourier Color Constancy", CVPR 2017) on a folder of images with
ground truth, end to end on files: the folder is made here, so nothing needs downloading.

1. A folder of 16-bit PNG Mondrians rendered from spectra with a real camera's curves (the
   documented generator of ``synthetic_raw_evaluation.py``: daylight, blackbody and fluorescent
   lights, highlights, noise, clipping) with its ``groundtruth.csv``.
2. ``ccjax evaluate DIR --ground-truth DIR/groundtruth.csv --folds 3 --train FFCC --methods
   GW,shades-of-grey-p6``: FFCC trained within 3 folds (never on the fold it scores) beside two
   untrained methods, with the training seconds.
3. ``ccjax train DIR --method FFCC --out DIR/ffcc.eqx``: one model on every image, written to a
   file.
4. The file read back (:func:`ccjax.runs.store.load_model`) and run on a few images: each estimate
   with its uncertainty (:meth:`ccjax.estimators.ffcc.FFCC.posterior`: the covariance of the
   light's log-chroma and a confidence in (0, 1]), beside the error it turned out to have.

On photographs the same commands apply to your own folder (see docs/photographs.md, "Training on
your photographs").

Run: ``python examples/ffcc_quick.py [--images 600] [--size 64] [--out DIR]``; ``--quick`` makes
120 images of 32 x 32 (about 2.2 CPU-minutes: 7.6 minutes measured on 2 CPU cores shared with
other work, about 130 s on a quiet machine; FFCC pads a training set to a multiple of 128 images,
so the folds' training sets and the whole set share one compiled solver).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from synthetic_raw_evaluation import generate

from ccjax import cli, io, metrics
from ccjax.estimators.ffcc import FFCC
from ccjax.preprocessing import prepare
from ccjax.runs import store

CAMERA = "Canon EOS 5D Mark II"
METHODS = ("GW", "shades-of-grey-p6")


def cross_validate(folder: Path, truth: Path, scratch: Path) -> dict[str, np.ndarray]:
    """``ccjax evaluate --folds 3 --train FFCC`` on the folder; each method's angular errors."""
    report = scratch / "evaluate.json"
    status = cli.main(
        ["evaluate", str(folder), "--ground-truth", str(truth), "--methods", ",".join(METHODS), "--camera", CAMERA]
        + ["--folds", "3", "--train", "FFCC", "--json", str(report), "--no-progress"]
    )
    if status != 0:
        raise SystemExit(status)
    records = json.loads(report.read_text())["images"]
    return {m: np.array([r["angular"] for r in records if r["method"] == m]) for m in (*METHODS, "FFCC trained")}


def show_uncertainty(model: FFCC, folder: Path, truth: Path, count: int) -> None:
    """Each of the first ``count`` images' estimate, its uncertainty and its error."""
    lights = io.read_ground_truth_file(truth, with_folds=False).lights
    print(f"\n{'image':<16}{'error (deg)':>12}{'sd u':>8}{'sd v':>8}{'confidence':>12}")
    for name in sorted(lights)[:count]:
        image = io.read_image(folder / name)
        rgb, mask = prepare(model, image)
        posterior = model.posterior(jnp.asarray(rgb), jnp.asarray(mask))
        estimate = model(jnp.asarray(rgb), jnp.asarray(mask)).illuminant
        error = float(metrics.angular_error(estimate, jnp.asarray(lights[name], jnp.float32)))
        sd = np.sqrt(np.diag(np.asarray(posterior.covariance)))
        print(f"{name:<16}{error:>12.2f}{sd[0]:>8.3f}{sd[1]:>8.3f}{float(posterior.confidence):>12.3f}")
    print("(sd u, sd v: standard deviations of the light's log(G/R) and log(G/B) under the fitted distribution)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--images", type=int, default=600)
    parser.add_argument("--size", type=int, default=64, help="image side in pixels")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None, help="folder for the images and the model (default: a temporary one)")
    parser.add_argument("--quick", action="store_true", help="120 images of 32 x 32 (a smoke test)")
    args = parser.parse_args(argv)
    if args.quick:
        args.images, args.size = 120, 32

    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(args.out or scratch) / "images"
        start = time.perf_counter()
        truth = generate(folder, n_images=args.images, size=args.size, camera=CAMERA, seed=args.seed)
        seconds = time.perf_counter() - start
        print(f"wrote {args.images} images of {args.size}x{args.size} ({CAMERA}) in {seconds:.0f} s")

        errors = cross_validate(folder, truth, Path(scratch))
        print(f"\n{'method':<22}{'mean (deg)':>12}{'median':>8}")
        for method, values in errors.items():
            print(f"{method:<22}{np.mean(values):>12.2f}{np.median(values):>8.2f}")

        model_file = Path(args.out or scratch) / "ffcc.eqx"
        argv_train = ["train", str(folder), "--method", "FFCC", "--camera", CAMERA, "--out", str(model_file)]
        status = cli.main([*argv_train, "--overwrite", "--no-progress"])
        if status != 0:
            raise SystemExit(status)
        model = store.load_model(model_file)
        if not isinstance(model, FFCC):
            raise SystemExit(f"{model_file}: expected an FFCC model, got {type(model).__name__}")
        where = model_file if args.out else "a temporary file"
        print(f"\nwrote the model trained on all {args.images} images to {where}")
        show_uncertainty(model, folder, truth, 5)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
