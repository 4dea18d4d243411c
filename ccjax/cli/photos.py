"""``ccjax estimate``, ``ccjax correct`` and ``ccjax evaluate``: linear images (Barnard 1999 §4.4)."""

from __future__ import annotations

import argparse
import json
import sys
import time

from ccjax.cli.common import (
    check_camera_name,
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
    """The image options of ``estimate``, ``correct`` and ``evaluate``: preparation, pixel rules,
    masks, file levels, progress."""
    parser.add_argument(
        "--preprocessing",
        default=None,
        help="input preparation for every method: pixels (every usable pixel), ave<b>[-edges][-cluster|-hull] "
        "(block averages, Table 4.6), seg-<min>-<rg>-<rel>[-hull], generic (default: each method's own: pixels "
        "for grey world, shades of grey, max-RGB and grey edge, ave5 for the world-based methods)",
    )
    parser.add_argument(
        "--dark",
        type=float,
        default=None,
        help="surface-list preprocessing: drop pixels with R+G+B below this fraction of the 99th percentile "
        "of the usable pixels' (default: 0.02; pixels inputs have no dark rule)",
    )
    parser.add_argument(
        "--mask",
        default=None,
        metavar="DIR",
        help="folder of mask images, one per image named by its stem (DIR/<stem>.png, .tif or .tiff); "
        "nonzero = usable pixel, zero = excluded (e.g. the colour checker)",
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
        help="saturation level in file units: pixels with a channel at or above it are clipped (default: 0.98 "
        "of the format maximum, e.g. 64224 for 16-bit)",
    )
    parser.add_argument(
        "--assume-linear",
        action="store_true",
        help="accept 8-bit files as linear data (they are refused otherwise)",
    )
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def read_options(args) -> dict:
    """The keyword arguments of :func:`ccjax.io.read_image` given on the command line."""
    return {
        "black_level": args.black_level,
        "saturation": args.saturation,
        "assume_linear": args.assume_linear,
    }


def dark_fraction(args) -> float:
    """``--dark``, or the library default."""
    from ccjax.preprocessing import DEFAULT_DARK

    return DEFAULT_DARK if args.dark is None else args.dark


def fit_cached(label: str, world):
    """The fitted estimator, through the store (:func:`ccjax.runs.store.fit`)."""
    from ccjax.runs import store

    return store.fit(label, world)


def image_world(args):
    """The world of the image commands (cached on disk)."""
    from ccjax import _cache
    from ccjax.runs import store

    check_camera_option(args)
    _cache.enable_compilation_cache()
    return store.world(args.world, args.camera, seed=args.seed, data_dir=args.data_dir)


def check_labels(labels, args=None) -> None:
    """Refuse unknown method labels, and world-based methods without a camera, before any image is read.

    Arguments:
        labels: estimator labels.
        args: the parsed arguments (``--world``, ``--camera``, ``--preprocessing``, ``--dark``);
            None checks the labels only.

    Returns:
        None.

    Raises:
        ValueError: naming the first unknown label and the known grammars; or the world-based
            methods and ``--camera`` / ``ccjax cameras`` when the camera is not given.
    """
    from ccjax.estimators import registry
    from ccjax.experiments.evaluation import world_based
    from ccjax.preprocessing import as_preprocessing

    for label in labels:
        registry.lookup(label)
    if args is None:
        return
    if args.preprocessing is not None:
        as_preprocessing(args.preprocessing)
    if args.dark is not None and not 0 <= args.dark < 1:
        raise ValueError(f"--dark: expected a fraction in [0, 1), got {args.dark!r}")
    fitted = [label for label in labels if world_based(label)]
    if fitted and args.world == "default" and args.camera is None:
        raise ValueError(
            f"--camera: {', '.join(fitted)} {'is' if len(fitted) == 1 else 'are'} fitted to a world seen through "
            "a camera's curves; give the camera that took the images with --camera NAME (`ccjax cameras` lists "
            "the names, `ccjax cameras --check GT.csv --camera NAME` tests a guess against the ground truth) or "
            "use --world barnard1999"
        )
    check_camera_name(args)


def check_images(paths, args) -> dict[str, str]:
    """Check every input from its header (:func:`ccjax.io.probe_image`) before any work; decoding
    and pixel-level problems (NaN, every pixel clipped, corrupt data) surface in the work pass.

    Arguments:
        paths: the image files.
        args: the parsed arguments (read options).

    Returns:
        ``{path: line}`` for each file that cannot be used (empty when all can).

    Raises:
        ValueError: no files, or not one of them can be used (one line per file).
    """
    from ccjax import io

    if not paths:
        raise ValueError("images: no image files given (folders are searched for .png, .tif, .tiff and raw files)")
    problems = {}
    for path in paths:
        try:
            io.probe_image(path, **read_options(args))
        except (ValueError, OSError) as error:
            problems[str(path)] = f"{error}" if str(path) in str(error) else f"{path}: {error}"
    if len(problems) == len(paths):
        raise_problems(list(problems.values()), len(paths))
    return problems


def raise_problems(problems, total: int) -> None:
    """Raise one ``ValueError`` naming every image that could not be used (nothing if none).

    Arguments:
        problems: one line per bad image.
        total: how many images the command was given.

    Returns:
        None.

    Raises:
        ValueError: when ``problems`` is not empty (``main`` prints it and exits 2).
    """
    if len(problems) == 1 and total == 1:
        raise ValueError(problems[0])
    if problems:
        raise ValueError(f"{len(problems)} of {total} images cannot be used:\n  " + "\n  ".join(problems))


MASK_SUFFIXES = (".png", ".tif", ".tiff")


def mask_files(paths, folder) -> list | None:
    """The mask file of each image: ``folder/<stem>.png`` (or ``.tif``, ``.tiff``).

    Arguments:
        paths: the image files.
        folder: ``--mask`` (None: no masks).

    Returns:
        One path per image, or None without ``folder``.

    Raises:
        ValueError: ``folder`` is not a folder, or an image has no mask (every such image named),
            or two mask files fit one image.
    """
    from pathlib import Path

    if folder is None:
        return None
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"--mask: {folder} is not a folder")
    found, missing = [], []
    for path in paths:
        candidates = [folder / f"{Path(path).stem}{suffix}" for suffix in MASK_SUFFIXES]
        present = [candidate for candidate in candidates if candidate.is_file()]
        if len(present) > 1:
            raise ValueError(f"--mask: {' and '.join(map(str, present))} both fit image {path}; keep one")
        if not present:
            missing.append(str(path))
        else:
            found.append(present[0])
    if missing:
        names = ", ".join(missing[:5]) + (f" and {len(missing) - 5} more" if len(missing) > 5 else "")
        raise ValueError(f"--mask: no mask in {folder} for {names} (looked for <stem>.png, <stem>.tif, <stem>.tiff)")
    return found


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
    p.add_argument("--method", default=None, help="estimator label (see `ccjax methods`); or --model")
    p.add_argument(
        "--model",
        default=None,
        help="a trained model file (`ccjax train --out`, ccjax.training.save_trained) instead of --method: the "
        "method and camera it was trained for come from its record",
    )
    world_arguments(p)
    image_arguments(p)
    p.add_argument(
        "--json",
        action="store_true",
        help="print a JSON list with one object per image: path, illuminant [R,G,B], rg, ok",
    )
    p.set_defaults(func=run_estimate)


def estimate_model(args):
    """``(label, model)`` of ``ccjax estimate``: ``--method`` fitted to the world, or the trained
    ``--model`` file (:func:`ccjax.load_model`).

    Raises:
        ValueError: neither or both given; a model file that cannot be read.
    """
    if (args.method is None) == (args.model is None):
        raise ValueError("--method, --model: give exactly one (a method label, or a trained model file)")
    if args.model is None:
        check_labels([args.method], args)
        return args.method, None
    from pathlib import Path

    from ccjax.training import load_model

    if not Path(args.model).is_file():
        raise ValueError(f"--model: no such model file: {args.model}")
    if args.world != "default" or args.camera is not None:
        raise ValueError("--model: the model's world comes from its file; leave out --world and --camera")
    check_labels([], args)
    model = load_model(args.model)
    return f"{Path(args.model).name}", model


def run_estimate(args) -> int:
    from ccjax import io
    from ccjax.experiments import evaluation

    label, model = estimate_model(args)
    paths = io.list_images(args.images)
    masks = mask_files(paths, args.mask)
    problems = check_images(paths, args)
    good, good_masks = usable(paths, masks, problems)
    if model is None:
        model = fit_cached(label, image_world(args))
    results = evaluation.run_images(
        good,
        {label: [model]},
        preprocessing=args.preprocessing,
        dark=dark_fraction(args),
        read_options=read_options(args),
        masks=good_masks,
        progress=not args.no_progress,
        keep_going=True,
    )
    records = [{k: r[k] for k in ("path", "illuminant", "rg", "ok")} for r in results.records()]
    if args.json:
        print(json.dumps(records, indent=1))
    else:
        width = max([40, *(len(r["path"]) + 2 for r in records)])
        print(f"{'image':<{width}}{'R':>9}{'G':>9}{'B':>9}{'r':>8}{'g':>8}  ok")
        for r in records:
            print(
                f"{r['path']:<{width}}"
                + "".join(f"{v:9.5f}" for v in r["illuminant"])
                + "".join(f"{v:8.4f}" for v in r["rg"])
                + f"  {'yes' if r['ok'] else 'no'}"
            )
    raise_problems(bad_images(paths, problems, results.failures), len(paths))
    return 0


def usable(paths, masks, problems):
    """The paths (and their masks) that passed :func:`check_images`."""
    keep = [index for index, path in enumerate(paths) if str(path) not in problems]
    return [paths[i] for i in keep], None if masks is None else [masks[i] for i in keep]


def bad_images(paths, *found) -> list[str]:
    """Every problem of ``found`` (``{path: line}`` dicts: header checks, then the work pass), in
    the order of ``paths``."""
    merged = {}
    for problems in found:
        merged.update({path: line for path, line in problems.items() if path not in merged})
    return [merged[str(path)] for path in paths if str(path) in merged]


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

    import jax.numpy as jnp
    import numpy as np
    from tqdm.auto import tqdm

    from ccjax import correction, io, preprocessing

    check_labels([args.method], args)
    paths, outputs, previews = correct_outputs(args)
    masks = mask_files(paths, args.mask)
    target = Path(args.output)
    sharpening = None
    if args.sharpening:
        sharpening = np.load(args.sharpening) if args.sharpening.endswith(".npy") else np.loadtxt(args.sharpening)
        if sharpening.shape != (3, 3) or not np.all(np.isfinite(sharpening)) or abs(np.linalg.det(sharpening)) < 1e-9:
            raise ValueError(f"sharpening: {args.sharpening} must hold an invertible 3x3 matrix")
    problems = check_images(paths, args)
    world = image_world(args)
    model = fit_cached(args.method, world)
    canonical = world.canonical_white
    matrix = io.preview_matrix_cached(world)
    failures = {}
    bar = tqdm(range(len(paths)), desc="images", unit="image", disable=args.no_progress, file=sys.stderr)
    for index in bar:
        path, output, preview = paths[index], outputs[index], previews[index]
        if str(path) in problems:
            continue
        try:
            image = io.read_image(path, **read_options(args))
            mask = None if masks is None else io.read_mask(masks[index], image.shape)
            rgb, valid = preprocessing.prepare(model, image, args.preprocessing, dark=dark_fraction(args), mask=mask)
        except ValueError as error:  # pixel-level problems (decoding, NaN, every pixel clipped)
            failures[str(path)] = f"{error}" if str(path) in str(error) else f"{path}: {error}"
            continue
        estimate = preprocessing.run_model(model, jnp.asarray(rgb), jnp.asarray(valid))
        corrected = np.asarray(correction.correct(image.rgb, estimate.illuminant, canonical, sharpening))
        if Path(args.input).is_dir():
            target.mkdir(parents=True, exist_ok=True)
        io.write_linear(output, corrected)
        io.write_preview(preview, corrected, matrix)
        illuminant = np.asarray(estimate.illuminant)
        print(f"{path}: illuminant {np.round(illuminant, 5).tolist()} (ok: {bool(estimate.ok)}) -> {output}, {preview}")
    raise_problems(bad_images(paths, problems, failures), len(paths))
    return 0


def add_evaluate(sub) -> None:
    p = sub.add_parser(
        "evaluate",
        help="evaluate methods on a folder of images with ground truth",
        description="Run each method on every image listed in the ground truth and print the angular error "
        "statistics (mean, median, trimean, best 25%, worst 25%, 95th percentile, max, bootstrap 95% "
        "confidence intervals of mean and median), each method's input, seconds (compilation apart) and the "
        "images where it fell back or relaxed, with the reasons. Ground truth: CSV with header image,r,g,b (file "
        "name in DIR; r,g,b = camera RGB of the light, any scale). World-based methods need --camera; the ground "
        "truth is checked against that camera's whites (see `ccjax cameras --check`). Unreadable images are "
        "reported and skipped (exit status 2).",
    )
    p.add_argument("directory", help="folder of linear images")
    p.add_argument("--ground-truth", required=True, help="CSV with header image,r,g,b")
    p.add_argument("--methods", type=label_list, required=True, help="comma-separated labels")
    p.add_argument(
        "--folds",
        type=int,
        default=None,
        help="K-fold cross-validation (K >= 2). Alone: each fold's models learn the expected lights from the other "
        "folds' ground truth (the CSV's fold column when it has one, else image i in fold i mod K). "
        "With --train: the folds of training (below)",
    )
    p.add_argument(
        "--train",
        type=label_list,
        default=None,
        metavar="METHODS",
        help="comma-separated trainable labels (e.g. RGB-C-by-C-MMSE, grey-edge-1-6-2): with --folds K, each is "
        "started from its fit to the world and trained (ccjax.training) on the other folds' images for each fold, "
        "never on the fold it scores, and reported as '<label> trained' beside --methods (which are then fitted "
        "to the world as without --folds). Folds come from the ground truth's fold column when it has one, else "
        "a random assignment seeded by --seed; statistics per fold and pooled",
    )
    p.add_argument(
        "--epochs",
        type=int,
        default=None,
        help="with --train: training epochs at most (default: ccjax.training.Schedule's, with early stopping)",
    )
    p.add_argument(
        "--json",
        default=None,
        help="write summaries and per-image results as JSON ('-' for stdout)",
    )
    p.add_argument(
        "--csv",
        default=None,
        help="write one row per image and method (estimate, ok, status, angular error) as CSV ('-' for stdout)",
    )
    world_arguments(p)
    image_arguments(p)
    p.set_defaults(func=run_evaluate)


CSV_FIELDS = ("path", "method", "preprocessing", "R", "G", "B", "r", "g", "ok", "status", "angular")


def results_csv(results) -> str:
    """One CSV row per image and method (:data:`CSV_FIELDS`)."""
    import csv
    import io

    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(CSV_FIELDS)
    for r in results.records():
        writer.writerow(
            [
                r["path"],
                r["method"],
                results.preprocessing.get(r["method"], ""),
                *(f"{v:.9g}" for v in r["illuminant"] + r["rg"]),
                str(r["ok"]),
                r.get("status", ""),
                f"{r['angular']:.9g}",
            ]
        )
    return buffer.getvalue()


TRAINED_SUFFIX = " trained"
"""Suffix of a method trained within folds (``evaluate --train``) in the tables and outputs."""


def check_folds(args) -> None:
    """Refuse ``--folds`` below 2, ``--train`` without ``--folds`` and ``--epochs`` without
    ``--train``, before any work."""
    if args.folds is not None and (isinstance(args.folds, bool) or args.folds < 2):
        raise ValueError(f"--folds: expected an integer >= 2 (the number of folds), got {args.folds}")
    if args.train is not None:
        if not args.train:
            raise ValueError("--train: expected comma-separated method labels, got none")
        if args.folds is None:
            raise ValueError("--train: needs --folds K (each method is trained on the other folds' images)")
        if len(set(args.train)) != len(args.train):
            raise ValueError(f"--train: a label is given twice ({', '.join(args.train)})")
    if args.epochs is not None:
        if args.train is None:
            raise ValueError("--epochs: applies to --train only")
        if args.epochs < 1:
            raise ValueError(f"--epochs: expected a positive integer, got {args.epochs}")


def trainable_starts(labels, world) -> dict:
    """``{label: its fit to world}`` for ``evaluate --train``, refusing labels with nothing to learn.

    Raises:
        ValueError: naming ``--train``, the label and the trainable families.
    """
    from ccjax import training

    starts = {}
    for label in labels:
        model = fit_cached(label, world)
        try:
            training.learnable(model)
        except ValueError:
            raise ValueError(
                f"--train: {label} ({type(model).__name__}) has no learnable parameters; trainable families: "
                f"{', '.join(training.learnable_types())} (e.g. C-by-C-MMSE, RGB-C-by-C-MMSE, grey-edge-1-6-2)"
            ) from None
        starts[label] = model
    return starts


def train_in_folds(args, starts, paths, truth, names, fold_of, masks):
    """``evaluate --train``: each start trained within the folds (:func:`ccjax.training.cross_validate`,
    never on the fold it scores) on exactly the inputs evaluate gives it.

    Returns:
        ``({"<label> trained": [model of fold 0, ...]}, {label: CrossValidation})``.
    """
    import dataclasses

    import numpy as np

    from ccjax import training

    schedule = training.Schedule(seed=args.seed)
    if args.epochs is not None:
        schedule = dataclasses.replace(schedule, epochs=args.epochs)
    models, validations = {}, {}
    for label, start in starts.items():
        examples, failed = training.read_examples(
            paths,
            truth,
            names,
            start,
            preprocessing=args.preprocessing,
            dark=dark_fraction(args),
            read_options=read_options(args),
            masks=masks,
            progress=not args.no_progress,
        )
        del failed  # the evaluation pass reports them
        assignment = dict(zip(names, fold_of, strict=True))
        folds = np.array([assignment[name] for name in examples.names])
        for fold in range(args.folds):
            trained_on = int(np.sum(folds != fold))
            if trained_on < 4:
                raise ValueError(
                    f"--folds: fold {fold}'s training set (the other folds) has {trained_on} usable images; training "
                    "needs at least 4 (fewer folds or more images)"
                )
        print(
            f"training {label} within {args.folds} folds on {len(examples)} images (start: its fit to the world)",
            file=sys.stderr,
        )
        validation, fold_models = training.cross_validate(
            start, examples, folds, schedule, method=label, progress=not args.no_progress
        )
        models[label + TRAINED_SUFFIX], validations[label] = fold_models, validation
    return models, validations


def fold_table(results, fold_of) -> str:
    """The field's statistics (degrees) of every method per fold and pooled."""
    from ccjax.metrics import FIELD_STATISTICS, summarise

    width = max([24, *(len(method) + 2 for method in results.estimates)])
    lines = [
        "angular error (degrees) per fold and pooled",
        f"{'method':<{width}}{'fold':>7}{'images':>8}" + "".join(f"{name:>9}" for name in FIELD_STATISTICS),
    ]
    folds = sorted(set(fold_of.tolist()))
    for method in results.estimates:
        errors = results.angular(method)
        for fold in [*folds, None]:
            chosen = errors if fold is None else errors[fold_of == fold]
            if not len(chosen):
                continue
            lines.append(
                f"{method:<{width}}{'pooled' if fold is None else fold:>7}{len(chosen):>8}"
                + "".join(f"{summarise(chosen, name):9.3f}" for name in FIELD_STATISTICS)
            )
    return "\n".join(lines)


def training_table(validations) -> str:
    """What each fold's training did: images trained on and scored, epochs, seconds."""
    lines = [
        "training within folds (each fold's model never sees the fold it scores)",
        f"{'method':<24}{'fold':>5}{'trained on':>12}{'scored':>8}{'epochs':>8}{'best':>6}{'wall s':>9}{'cpu s':>9}"
        f"{'stop-split median: start':>26}{'best':>7}",
    ]
    for label, validation in validations.items():
        for result in validation.folds:
            row, log = result.summary(), result.log
            lines.append(
                f"{label:<24}{row['fold']:>5}{row['n_train']:>12}{row['n_test']:>8}{row['epochs']:>8}"
                f"{row['best_epoch']:>6}{row['train_seconds']:>9.1f}{row['train_cpu_seconds']:>9.1f}"
                f"{log.initial_median:>26.3f}{min([log.initial_median, *log.heldout_median]):>7.3f}"
            )
    lines.append(
        "(trained on: the other folds' images, an early-stopping split of them included; stop-split median: "
        "angular error on that split before training and at the best epoch)"
    )
    return "\n".join(lines)


def run_evaluate(args) -> int:
    import numpy as np

    from ccjax import io
    from ccjax.experiments import cameras, evaluation

    start = time.perf_counter()
    check_folds(args)
    check_labels(args.methods + (args.train or []), args)
    for option, path in (("--json", args.json), ("--csv", args.csv)):
        if path:
            check_output_file(path, option)
    rows = io.read_ground_truth(args.ground_truth)
    pairs = io.match_ground_truth(rows, args.directory)
    names = list(rows)
    assigned = None
    if args.folds is not None:
        from ccjax import training

        try:
            given = training.read_folds(args.ground_truth)
            if args.train:
                # Folds of training: the CSV's fold column, else seeded; assigned in ground-truth
                # order (as ``ccjax train --folds``), so the same file and seed give the same folds.
                assigned = dict(zip(names, training.assign_folds(names, args.folds, seed=args.seed, given=given)))
            elif given is not None:
                # Fold worlds follow a published split when the CSV has one (else image i in fold i mod K).
                assigned = dict(zip(names, training.assign_folds(names, args.folds, given=given)))
        except ValueError as error:
            raise ValueError(f"--folds: {error}") from None
    order = sorted(range(len(pairs)), key=lambda index: str(pairs[index][0]))
    pairs, names = [pairs[i] for i in order], [names[i] for i in order]
    paths, truth = [p for p, _ in pairs], np.stack([t for _, t in pairs])
    masks = mask_files(paths, args.mask)
    problems = check_images(paths, args)
    world = image_world(args)
    starts = trainable_starts(args.train, world) if args.train else {}
    check = None
    labels = args.methods + list(starts)
    if args.camera or args.world != "default" or any(evaluation.world_based(label) for label in labels):
        check = cameras.curve_check(truth, world)
        if not check.passed:
            print(
                f"warning: {check.message()}; try `ccjax cameras --check {args.ground_truth} --camera NAME`",
                file=sys.stderr,
            )
    fold_of, validations = None, {}
    if assigned is not None and args.train and args.folds is not None:
        fold_of = np.array([assigned[name] for name in names])
        models = {label: [fit_cached(label, world)] * args.folds for label in args.methods}
    elif args.folds is not None:
        given_folds = None if assigned is None else np.array([assigned[name] for name in names])
        fold_of, worlds = evaluation.fold_worlds(world, truth, args.folds, given_folds)
        models = {label: [fit_cached(label, w) for w in worlds] for label in args.methods}
    else:
        models = {label: [fit_cached(label, world)] for label in args.methods}
    keep = [index for index, path in enumerate(paths) if str(path) not in problems]
    if args.folds is not None and len(keep) < args.folds:
        raise ValueError(f"--folds: {args.folds} folds need at least {args.folds} usable images, got {len(keep)}")
    if starts:
        assert fold_of is not None  # --train needs --folds (check_folds)
        trained, validations = train_in_folds(
            args,
            starts,
            [paths[i] for i in keep],
            truth[keep],
            [names[i] for i in keep],
            fold_of[keep],
            None if masks is None else [masks[i] for i in keep],
        )
        models.update(trained)
    results = evaluation.run_images(
        [paths[i] for i in keep],
        models,
        fold_of=None if fold_of is None else fold_of[keep],
        preprocessing=args.preprocessing,
        dark=dark_fraction(args),
        read_options=read_options(args),
        masks=None if masks is None else [masks[i] for i in keep],
        progress=not args.no_progress,
        truth=truth[keep],
        keep_going=True,
    )
    if args.train:
        source = "the ground truth's fold column" if training.read_folds(args.ground_truth) else f"seed {args.seed}"
        folds = f"; {args.folds} folds ({source}): {', '.join(args.train)} trained within them, --methods not"
    elif args.folds is not None:
        source = "the ground truth's fold column" if assigned is not None else "image i in fold i mod K"
        folds = f"; {args.folds}-fold cross-validation ({source})"
    else:
        folds = ""
    preparation = args.preprocessing or "each method's default"
    print(f"world: {world.name}; preprocessing: {preparation}{folds}")
    if check is not None:
        print(check.message())
    print(results.table(), flush=True)
    used = {path: index for index, path in enumerate(map(str, paths))}
    scored_folds = None if fold_of is None else fold_of[[used[path] for path in results.paths]]
    if scored_folds is not None and len(results.paths):
        print("\n" + fold_table(results, scored_folds))
    if validations:
        print("\n" + training_table(validations))
    bad = bad_images(paths, problems, results.failures)
    if args.json:
        summary = {label: results.summary(label) for label in models}
        report = {"summary": summary, "images": results.records(), "failures": bad}
        if check is not None:
            report["camera_check"] = {"camera": check.camera, "distance": check.distance, "threshold": check.threshold}
        if scored_folds is not None:
            report["folds"] = {
                "fold_of": dict(zip(results.paths, scored_folds.tolist(), strict=True)),
                "training": {
                    label + TRAINED_SUFFIX: [
                        {
                            **result.summary(),
                            "heldout_median_per_epoch": result.log.heldout_median,
                            "train_images": result.train_names,
                            "test_images": result.test_names,
                        }
                        for result in validation.folds
                    ]
                    for label, validation in validations.items()
                },
            }
        write(args.json, json.dumps(report, indent=1))
    if args.csv:
        write(args.csv, results_csv(results))
    print(f"done in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    raise_problems(bad, len(paths))
    return 0


COMMANDS = [add_estimate, add_correct, add_evaluate]
