"""``ccjax estimate``, ``ccjax correct`` and ``ccjax evaluate``: linear images (Barnard 1999 §4.4)."""

from __future__ import annotations

import argparse
import json
import sys
import time

from ccjax.cli.common import check_camera_option, label_list, world_arguments, write


def image_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--preprocessing",
        default="ave5",
        help="surface-list preprocessing (Table 4.6): ave<b>, ave<b>-cluster, ave<b>-hull, "
        "seg-<min>-<rg>-<rel>[-hull], generic (default: %(default)s)",
    )
    parser.add_argument(
        "--dark",
        type=float,
        default=0.02,
        help="drop pixels with R+G+B below this fraction of the brightest usable pixel's (default: %(default)s)",
    )
    parser.add_argument(
        "--black-level",
        type=float,
        default=0.0,
        help="black level in file units (default: 0)",
    )
    parser.add_argument(
        "--saturation",
        type=float,
        default=None,
        help="saturation level in file units (default: the format maximum, 65535 for 16-bit)",
    )
    parser.add_argument(
        "--assume-linear",
        action="store_true",
        help="accept 8-bit files as linear data (they are refused otherwise)",
    )
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def read_options(args) -> dict:
    return {
        "black_level": args.black_level,
        "saturation": args.saturation,
        "assume_linear": args.assume_linear,
    }


def fit_cached(label: str, world):
    """The fitted estimator, memoised (``registry.fit_cached``)."""
    from ccjax.estimators import registry

    return registry.fit_cached(label, world)


def image_world(args):
    from ccjax import _cache
    from ccjax.experiments import evaluation

    check_camera_option(args)
    _cache.enable_compilation_cache()
    return evaluation.cached_world(args.world, args.camera, seed=args.seed, data_dir=args.data_dir)


def check_images(paths, args) -> None:
    """Read every input once before anything is computed or written (bad files -> no output)."""
    from ccjax import io
    from ccjax.preprocessing import Preprocessing

    Preprocessing.parse(args.preprocessing)
    if not paths:
        raise ValueError("images: no image files given (folders are searched for .png, .tif, .tiff and raw files)")
    for path in paths:
        io.read_image(path, **read_options(args))


def add_estimate(sub) -> None:
    p = sub.add_parser(
        "estimate",
        help="estimate the light of linear images",
        description="Estimate the illuminant of each image (files or folders); print its camera RGB (unit scale: "
        "saturation = 1) and (r,g).",
    )
    p.add_argument(
        "images",
        nargs="+",
        help="16-bit PNG/TIFF files, raw files (raw extra), or folders of them",
    )
    p.add_argument("--method", required=True, help="estimator label (see `ccjax methods`)")
    world_arguments(p)
    image_arguments(p)
    p.add_argument(
        "--json",
        action="store_true",
        help="print a JSON list with one object per image: path, illuminant [R,G,B], rg, ok",
    )
    p.set_defaults(func=run_estimate)


def run_estimate(args) -> int:
    from ccjax import io
    from ccjax.experiments import evaluation

    paths = io.list_images(args.images)
    check_images(paths, args)
    world = image_world(args)
    model = fit_cached(args.method, world)
    results = evaluation.run_images(
        paths,
        {args.method: [model]},
        preprocessing=args.preprocessing,
        dark=args.dark,
        read_options=read_options(args),
        progress=not args.no_progress,
    )
    records = [{k: r[k] for k in ("path", "illuminant", "rg", "ok")} for r in results.records()]
    if args.json:
        print(json.dumps(records, indent=1))
    else:
        print(f"{'image':<40}{'R':>9}{'G':>9}{'B':>9}{'r':>8}{'g':>8}  ok")
        for r in records:
            print(
                f"{r['path']:<40}"
                + "".join(f"{v:9.5f}" for v in r["illuminant"])
                + "".join(f"{v:8.4f}" for v in r["rg"])
                + f"  {'yes' if r['ok'] else 'no'}"
            )
    return 0


def add_correct(sub) -> None:
    p = sub.add_parser(
        "correct",
        help="correct linear images to the canonical light",
        description="Estimate each image's light, map it to the canonical light with a diagonal map and write the "
        "corrected linear 16-bit image and an 8-bit sRGB preview. IN and OUT are files, or folders (OUT "
        "is created).",
    )
    p.add_argument("input", help="a linear image or a folder of them")
    p.add_argument("output", help="output .png/.tif/.tiff file, or a folder when INPUT is a folder")
    p.add_argument("--method", required=True, help="estimator label (see `ccjax methods`)")
    p.add_argument(
        "--preview",
        default=None,
        help="preview path for a single image (default: OUTPUT stem + '_preview.png')",
    )
    p.add_argument(
        "--sharpening",
        default=None,
        help="3x3 sharpening transform T (text or .npy; rows = sharpened sensors) for a sharpened-diagonal map T^-1 "
        "diag(T w_C / T e) T",
    )
    world_arguments(p)
    image_arguments(p)
    p.set_defaults(func=run_correct)


def run_correct(args) -> int:
    from pathlib import Path

    import numpy as np
    from tqdm.auto import tqdm

    from ccjax import correction, io, preprocessing

    source, target = Path(args.input), Path(args.output)
    if source.is_dir():
        paths = io.list_images([source])
        outputs = [
            target / f"{p.stem}{p.suffix.lower() if p.suffix.lower() in ('.png', '.tif', '.tiff') else '.tiff'}"
            for p in paths
        ]
        previews = [target / f"{p.stem}_preview.png" for p in paths]
        if target.exists() and not target.is_dir():
            raise ValueError(f"output: {target} exists and is not a folder")
    else:
        paths, outputs = [source], [target]
        previews = [Path(args.preview) if args.preview else target.with_name(f"{target.stem}_preview.png")]
        if target.suffix.lower() not in (".png", ".tif", ".tiff"):
            raise ValueError(f"output: {target} must end in .png, .tif or .tiff")
        if not target.parent.is_dir():
            raise ValueError(f"output: folder {target.parent} does not exist")
    sharpening = None
    if args.sharpening:
        sharpening = np.load(args.sharpening) if args.sharpening.endswith(".npy") else np.loadtxt(args.sharpening)
        if sharpening.shape != (3, 3) or not np.all(np.isfinite(sharpening)) or abs(np.linalg.det(sharpening)) < 1e-9:
            raise ValueError(f"sharpening: {args.sharpening} must hold an invertible 3x3 matrix")
    check_images(paths, args)
    world = image_world(args)
    model = fit_cached(args.method, world)
    canonical = world.canonical_white
    matrix = io.preview_matrix_cached(world)
    if source.is_dir():
        target.mkdir(parents=True, exist_ok=True)
    for path, output, preview in zip(
        tqdm(
            paths,
            desc="images",
            unit="image",
            disable=args.no_progress,
            file=sys.stderr,
        ),
        outputs,
        previews,
    ):
        image = io.read_image(path, **read_options(args))
        estimate = preprocessing.estimate_image(model, image, args.preprocessing, dark=args.dark)
        corrected = np.asarray(correction.correct(image.rgb, estimate.illuminant, canonical, sharpening))
        io.write_linear(output, corrected)
        io.write_preview(preview, corrected, matrix)
        rgb = np.asarray(estimate.illuminant)
        print(f"{path}: illuminant {np.round(rgb, 5).tolist()} (ok: {bool(estimate.ok)}) -> {output}, {preview}")
    return 0


def add_evaluate(sub) -> None:
    p = sub.add_parser(
        "evaluate",
        help="evaluate methods on a folder of images with ground truth",
        description="Run each method on every image listed in the ground truth and print angular error statistics "
        "(mean, median, trimean, best 25%%, worst 25%%, max) and the share of images where a method fell "
        "back or relaxed (not ok). Ground truth: CSV with header image,r,g,b (file name in DIR; r,g,b = "
        "camera RGB of the light, any scale).",
    )
    p.add_argument("directory", help="folder of linear images")
    p.add_argument("--ground-truth", required=True, help="CSV with header image,r,g,b")
    p.add_argument("--methods", type=label_list, required=True, help="comma-separated labels")
    p.add_argument(
        "--folds",
        type=int,
        default=None,
        help="K-fold cross-validation: each fold's models learn the expected lights from the other folds' ground truth",
    )
    p.add_argument(
        "--json",
        default=None,
        help="write summaries and per-image results as JSON ('-' for stdout)",
    )
    p.add_argument("--csv", default=None, help="write per-image results as CSV ('-' for stdout)")
    world_arguments(p)
    image_arguments(p)
    p.set_defaults(func=run_evaluate)


def run_evaluate(args) -> int:
    import numpy as np

    from ccjax import io
    from ccjax.experiments import evaluation

    start = time.perf_counter()
    pairs = io.match_ground_truth(io.read_ground_truth(args.ground_truth), args.directory)
    pairs.sort(key=lambda pair: str(pair[0]))
    paths, truth = [p for p, _ in pairs], np.stack([t for _, t in pairs])
    check_images(paths, args)
    world = image_world(args)
    fold_of = None
    if args.folds:
        fold_of, worlds = evaluation.fold_worlds(world, truth, args.folds)
        models = {label: [fit_cached(label, w) for w in worlds] for label in args.methods}
    else:
        models = {label: [fit_cached(label, world)] for label in args.methods}
    results = evaluation.run_images(
        paths,
        models,
        fold_of=fold_of,
        preprocessing=args.preprocessing,
        dark=args.dark,
        read_options=read_options(args),
        progress=not args.no_progress,
        truth=truth,
    )
    folds = f"; {args.folds}-fold cross-validation" if args.folds else ""
    print(f"world: {world.name}; preprocessing: {args.preprocessing}{folds}")
    print(results.table(), flush=True)
    if args.json:
        summary = {label: results.summary(label) for label in args.methods}
        write(
            args.json,
            json.dumps({"summary": summary, "images": results.records()}, indent=1),
        )
    if args.csv:
        lines = ["path,method,R,G,B,r,g,ok,angular"] + [
            ",".join(
                [
                    r["path"],
                    r["method"],
                    *(f"{v:.9g}" for v in r["illuminant"] + r["rg"]),
                    str(r["ok"]),
                    f"{r['angular']:.9g}",
                ]
            )
            for r in results.records()
        ]
        write(args.csv, "\n".join(lines) + "\n")
    print(f"done in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


COMMANDS = [add_estimate, add_correct, add_evaluate]
