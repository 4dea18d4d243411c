"""``ccjax estimate``, ``ccjax correct`` and ``ccjax evaluate``: linear images (Barnard 1999 §4.4)."""

from __future__ import annotations

import argparse
import json
import sys
import time

from ccjax.cli.common import (
    check_camera_option,
    check_distinct,
    check_output_file,
    check_output_folder,
    label_list,
    path_key,
    world_arguments,
    write,
)

OUTPUT_SUFFIXES = (".png", ".tif", ".tiff")


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


def check_labels(labels) -> None:
    """Refuse unknown method labels before any image is read.

    Arguments:
        labels: estimator labels.

    Returns:
        None.

    Raises:
        ValueError: naming the first unknown label and the known grammars.
    """
    from ccjax.estimators import registry

    for label in labels:
        registry.lookup(label)


def check_images(paths, args) -> None:
    """Read every input once before anything is computed or written (bad files -> no output).

    Every file is tried, so one run reports all the bad ones.

    Arguments:
        paths: the image files.
        args: the parsed arguments (preprocessing and read options).

    Returns:
        None.

    Raises:
        ValueError: no files, or one line per unreadable file.
    """
    from ccjax import io
    from ccjax.preprocessing import Preprocessing

    Preprocessing.parse(args.preprocessing)
    if not paths:
        raise ValueError("images: no image files given (folders are searched for .png, .tif, .tiff and raw files)")
    problems = []
    for path in paths:
        try:
            io.read_image(path, **read_options(args))
        except (ValueError, OSError) as error:
            problems.append(f"{error}" if str(path) in str(error) else f"{path}: {error}")
    if len(problems) == 1:
        raise ValueError(problems[0])
    if problems:
        raise ValueError(f"{len(problems)} of {len(paths)} images cannot be used:\n  " + "\n  ".join(problems))


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

    check_labels([args.method])
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
        "is created). Inputs are never replaced; existing outputs need --overwrite; every file is written "
        "to a temporary name and renamed into place.",
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
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace existing output images and previews (they are refused otherwise; inputs are never replaced)",
    )
    world_arguments(p)
    image_arguments(p)
    p.set_defaults(func=run_correct)


def folder_outputs(paths, target):
    """Output and preview paths in folder ``target`` for each input, no two alike (case-insensitively).

    ``a.png`` gives ``a.png`` and ``a_preview.png``; a later input whose names are taken (``a.tif``,
    ``A.PNG`` beside it) gets its original suffix in the stem: ``a_tif.tif``, ``a_tif_preview.png``,
    then a number (``A_PNG-2.png``).

    Arguments:
        paths: the input files.
        target: the output folder.

    Returns:
        ``(outputs, previews)``, lists of paths.
    """
    from pathlib import Path

    target = Path(target)
    used: set[str] = set()
    outputs, previews = [], []
    for path in paths:
        suffix = path.suffix.lower() if path.suffix.lower() in OUTPUT_SUFFIXES else ".tiff"
        tags = ["", f"_{path.suffix.lstrip('.')}"]
        tags += [f"_{path.suffix.lstrip('.')}-{number}" for number in range(2, len(paths) + 3)]
        for tag in tags:
            output, preview = target / f"{path.stem}{tag}{suffix}", target / f"{path.stem}{tag}_preview.png"
            if path_key(output) not in used and path_key(preview) not in used:
                break
        used.update((path_key(output), path_key(preview)))
        outputs.append(output)
        previews.append(preview)
    return outputs, previews


def correct_outputs(args):
    """Validate ``ccjax correct``'s inputs and outputs before any work.

    Arguments:
        args: the parsed arguments (``input``, ``output``, ``preview``, ``overwrite``).

    Returns:
        ``(paths, outputs, previews)``: the input files and, for each, its output and preview.

    Raises:
        ValueError: an output would replace an input or another output, exists without
            ``--overwrite``, is a folder, or cannot be written.
    """
    from pathlib import Path

    from ccjax import io

    source, target = Path(args.input), Path(args.output)
    if source.is_dir():
        if path_key(source) == path_key(target):
            raise ValueError(f"output: {args.output} is the input folder {args.input}; its images would be replaced")
        if target.exists() and not target.is_dir():
            raise ValueError(f"output: {target} exists and is not a folder")
        if args.preview:
            raise ValueError("--preview: names one image's preview; with a folder the previews go beside the outputs")
        paths = io.list_images([source])
        outputs, previews = folder_outputs(paths, target)
        check_output_folder(target, "output")
    else:
        if not source.exists():
            raise FileNotFoundError(f"input: {source} does not exist")
        paths, outputs = [source], [target]
        previews = [Path(args.preview) if args.preview else target.with_name(f"{target.stem}_preview.png")]
        if target.is_dir():
            raise ValueError(f"output: {target} is a folder; give a .png, .tif or .tiff file name")
        if target.suffix.lower() not in OUTPUT_SUFFIXES:
            raise ValueError(f"output: {target} must end in .png, .tif or .tiff")
        if not target.parent.is_dir():
            raise ValueError(f"output: folder {target.parent} does not exist")
        if previews[0].suffix.lower() != ".png":
            raise ValueError(f"--preview: {previews[0]} must end in .png")
    check_distinct(paths, [("output", output) for output in outputs] + [("--preview", preview) for preview in previews])
    for output, preview in zip(outputs, previews, strict=True):
        check_output_file(output, "output", overwrite=args.overwrite)
        check_output_file(preview, "--preview", overwrite=args.overwrite)
    return paths, outputs, previews


def run_correct(args) -> int:
    from pathlib import Path

    import numpy as np
    from tqdm.auto import tqdm

    from ccjax import correction, io, preprocessing

    check_labels([args.method])
    paths, outputs, previews = correct_outputs(args)
    target = Path(args.output)
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
    if Path(args.input).is_dir():
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
    check_labels(args.methods)
    for option, path in (("--json", args.json), ("--csv", args.csv)):
        if path:
            check_output_file(path, option)
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
