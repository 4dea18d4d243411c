"""End to end on files: synthetic raw images of a real camera, evaluated and trained on.

The generator is fixed and documented (:func:`generate`): Mondrian images rendered from spectra with
a real camera's curves (default the embedded Canon EOS 5D Mark II) and the embedded SFU
reflectances —

* 1,500 images of 128 x 128 pixels, 16 patches each (distinct reflectances), shading U(0.3, 1);
* dielectric highlights on 25 % of the patches (a Gaussian blob of up to 2 x the white);
* Gaussian noise of variance 1e-4 rho, brightest pixel scaled to 1 (as ``ccjax synthetic``);
* lights: 70 % CIE daylight with a correlated colour temperature uniform on 4000–10000 K, 20 %
  blackbody 2500–3500 K, 10 % fluorescent FL2 / FL7 / FL11 (a table of 1,000 lights in exactly
  those shares, drawn uniformly per image);
* seed 0 (image ``i`` is drawn from ``fold_in(key(seed), i)``, so the set does not depend on
  how it is chunked); written as 16-bit PNGs ``image-0000.png ...`` with ``groundtruth.csv``
  (header ``image,r,g,b``: the camera RGB of each image's light).

Then ``ccjax evaluate`` runs on the folder (file reading, the default preprocessing, cached fits)
and prints each method's median angular error against grey world's. With ``--train METHOD``, the
run is ``ccjax evaluate --folds 3 --train METHOD``: the method is trained within 3 seeded folds
(``ccjax.training.cross_validate``: never on the fold it scores) and reported as ``METHOD trained``
beside the untrained fit, per fold and pooled.

Run: ``python examples/synthetic_raw_evaluation.py [--images 1500] [--train RGB-C-by-C-MMSE] [--out DIR]``;
``--generate-only --out DIR`` only writes ``DIR/images`` (then run ``ccjax evaluate DIR/images
--ground-truth DIR/images/groundtruth.csv --camera "Canon EOS 5D Mark II" --folds 3 --train
RGB-C-by-C-MMSE --methods RGB-C-by-C-MMSE,grey-edge-1-6-2,GW``: the trained model's pooled median
should be at least 30 % below the untrained fit's and below grey edge (1, 6, 2)'s);
``--quick`` makes 60 images of 64 x 64 (a smoke test).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import jax
import numpy as np

from ccjax import cli, io, scenes
from ccjax.world import World, normalise_illuminants

DEFAULT_METHODS = ("GW", "ND-ECRULE-SCWIA-12", "RGB-C-by-C-MMSE", "C-by-C-MMSE", "shades-of-grey-p6", "grey-edge-1-6-2")
LIGHT_SHARES = {"daylight": 700, "blackbody": 200, "fluorescent": 100}
"""The light table: 1,000 lights in the documented shares (70 / 20 / 10 %)."""


def light_table(sensors: np.ndarray) -> np.ndarray:
    """``(1000, 101)`` the generator's lights on ccjax's scale: daylight at 700 temperatures evenly
    spaced on 4000–10000 K, blackbody at 200 on 2500–3500 K, FL2, FL7 and FL11 (34, 33, 33 copies)."""
    import colour

    from ccjax.spectra import resample

    def grid(sd) -> np.ndarray:
        return resample(np.asarray(sd.wavelengths), np.asarray(sd.values), kind="spectrum")

    spectra = []
    for cct in np.linspace(4000.0, 10000.0, LIGHT_SHARES["daylight"]):
        spectra.append(grid(colour.sd_CIE_illuminant_D_series(colour.temperature.CCT_to_xy_CIE_D(cct))))
    shape = colour.SpectralShape(380, 780, 5)
    for kelvin in np.linspace(2500.0, 3500.0, LIGHT_SHARES["blackbody"]):
        spectra.append(grid(colour.sd_blackbody(kelvin, shape)))
    cie = colour.SDS_ILLUMINANTS
    for name, copies in (("FL2", 34), ("FL7", 33), ("FL11", 33)):
        spectra += [grid(cie[name])] * copies
    return normalise_illuminants(np.stack(spectra), sensors)


def generate(
    out: str | Path,
    *,
    n_images: int = 1500,
    size: int = 128,
    n_patches: int = 16,
    camera: str = "Canon EOS 5D Mark II",
    seed: int = 0,
) -> Path:
    """Write the documented image set (module docstring) to ``out``; returns the ground-truth CSV."""
    base = World.default(camera=camera)
    lights = light_table(np.asarray(base.camera.sensors, np.float64))
    world = World(
        reflectances=base.reflectances,
        train_illuminants=base.train_illuminants,
        test_illuminants=jax.numpy.asarray(lights, jax.numpy.float32),  # the images' lights
        canonical=base.canonical,
        camera=base.camera,
        name=f"synthetic-raw-{camera}",
    )
    # In chunks of 100 (image i always uses fold_in(key, i), so the set does not depend on the
    # chunking): highlights need a patch map per image, which would not fit in memory all at once.
    tables = scenes.SceneTables.from_world(world)
    images, whites = [], []
    for begin in range(0, n_images, 100):
        count = min(100, n_images - begin)
        batch = scenes.mondrian_batch(
            scenes.scene_keys(jax.random.key(seed), begin, count),
            tables,
            size,
            size,
            n_patches,
            (0.3, 1.0),
            scenes.Specular(probability=0.25, max_amount=2.0),
            scenes.ShotNoise(a=1e-4, b=0.0),
        )
        images.append(np.asarray(batch.image))
        whites.append(np.asarray(batch.illuminant))
    return io.write_dataset(Path(out), np.concatenate(images), np.concatenate(whites))


def evaluate(
    folder: Path,
    truth: Path,
    methods: Sequence[str],
    camera: str,
    scratch: Path,
    *,
    train: str | None = None,
    epochs: int | None = None,
) -> dict[str, np.ndarray]:
    """``ccjax evaluate`` on the folder (with ``train``: ``--folds 3 --train train``); per-method
    angular errors (the trained method as ``"<train> trained"``)."""
    report = scratch / "evaluate.json"
    argv = ["evaluate", str(folder), "--ground-truth", str(truth), "--methods", ",".join(methods)]
    argv += ["--camera", camera, "--json", str(report)]
    if train:
        argv += ["--folds", "3", "--train", train] + (["--epochs", str(epochs)] if epochs else [])
    status = cli.main([*argv, *([] if train and sys.stderr.isatty() else ["--no-progress"])])
    if status != 0:
        raise SystemExit(status)
    records = json.loads(report.read_text())["images"]
    labels = [*methods, *([f"{train} trained"] if train else [])]
    return {m: np.array([r["angular"] for r in records if r["method"] == m]) for m in labels}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--images", type=int, default=1500)
    parser.add_argument("--size", type=int, default=128, help="image side in pixels")
    parser.add_argument("--patches", type=int, default=16)
    parser.add_argument("--camera", default="Canon EOS 5D Mark II")
    parser.add_argument("--methods", default=",".join(DEFAULT_METHODS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--train", default=None, help="also train this method with 3-fold cross-validation")
    parser.add_argument("--epochs", type=int, default=None, help="training epochs at most (default: the schedule's)")
    parser.add_argument("--out", default=None, help="folder for the images (default: a temporary one)")
    parser.add_argument("--generate-only", action="store_true", help="write OUT/images and stop (needs --out)")
    parser.add_argument("--quick", action="store_true", help="60 images of 64 x 64, two methods (smoke test)")
    args = parser.parse_args(argv)
    if args.quick:
        args.images, args.size, args.methods = 60, 64, "GW,grey-edge-1-6-2"
    if args.generate_only and not args.out:
        parser.error("--generate-only: give --out DIR (the images would go to a temporary folder)")
    methods: list[str] = [str(label) for label in args.methods.split(",")]

    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(args.out or scratch) / "images"
        start = time.perf_counter()
        truth = generate(
            folder, n_images=args.images, size=args.size, n_patches=args.patches, camera=args.camera, seed=args.seed
        )
        # Without --out the folder is removed at the end: naming it would point at nothing.
        where = folder if args.out else "a temporary folder (removed at the end; --out DIR keeps them)"
        print(
            f"wrote {args.images} images of {args.size}x{args.size} ({args.camera}) to {where} "
            f"in {time.perf_counter() - start:.0f} s"
        )
        if args.generate_only:
            return 0
        errors = evaluate(folder, truth, methods, args.camera, Path(scratch), train=args.train, epochs=args.epochs)
        baseline = np.median(errors["GW"]) if "GW" in errors else np.nan
        print(f"\n{'method':<26}{'median (deg)':>14}{'mean':>8}{'vs GW':>10}")
        for m, values in errors.items():
            median = np.median(values)
            print(f"{m:<26}{median:>14.3f}{np.mean(values):>8.3f}{(median / baseline - 1) * 100:>+9.1f}%")
        if args.train and args.train in errors:
            trained, untrained = np.median(errors[f"{args.train} trained"]), np.median(errors[args.train])
            print(
                f"{args.train}: trained within folds {trained:.3f} vs untrained {untrained:.3f} deg median "
                f"({(trained / untrained - 1) * 100:+.1f}%)"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
