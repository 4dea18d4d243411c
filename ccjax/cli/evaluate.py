"""``ccjax evaluate``: methods scored on a folder of images with ground truth, optionally
cross-validated and trained within folds (:func:`ccjax.experiments.folders.evaluate_folder`)."""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import sys
import time

from ccjax.cli import image_options
from ccjax.cli.common import (
    check_camera_option,
    check_outputs,
    check_plot,
    label_list,
    overwrite_argument,
    pretrain_arguments,
    pretraining_setting,
    start_processes,
    world_arguments,
    write,
    write_plot,
)


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
    p.add_argument(
        "directories",
        nargs="+",
        metavar="DIR",
        help="folder of linear images; several folders (e.g. the eight NUS-8 cameras' sets) are each evaluated "
        "on their own (the field's protocol: per-folder rows, then the geometric mean of each statistic over the "
        "folders, training seconds per fold and inference ms/image)",
    )
    p.add_argument("--ground-truth", default=None, help="CSV with header image,r,g,b (one folder)")
    p.add_argument(
        "--ground-truth-name",
        default=None,
        metavar="NAME",
        help="the ground truth's file name inside each folder (e.g. groundtruth.csv), instead of --ground-truth",
    )
    p.add_argument(
        "--camera-for",
        action="append",
        default=[],
        metavar="FOLDER=CAMERA",
        help="the camera of one folder (its name or its path as given), overriding --camera for it; repeat for "
        "each folder. World-based methods are left out of folders without a camera (noted under the table)",
    )
    p.add_argument(
        "--models",
        default=None,
        metavar="DIR",
        help="with --train: write each fold's trained model as DIR/<label>-fold<k>.eqx (several folders: "
        "DIR/<folder>/<label>-fold<k>.eqx; `ccjax.load_model` reads them)",
    )
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
        "--allow-missing",
        action="store_true",
        help="score the images the ground truth lists when other images of DIR have no row (they are named); "
        "without it such images are an error (exit 2)",
    )
    p.add_argument(
        "--plot",
        default=None,
        help="write a figure of the per-image angular errors (their cumulative distribution and each image's)",
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
    overwrite_argument(p, "--json and --csv files")
    world_arguments(p)
    pretrain_arguments(p)
    image_options.image_arguments(p)
    p.set_defaults(func=run_evaluate)


def evaluate_inputs(args) -> list:
    """Every file ``ccjax evaluate`` reads: the ground truth, the folder's images and the masks
    (outputs must replace none of them)."""
    from ccjax import io

    folders = [*args.directories] + ([args.mask] if args.mask else [])
    return [*ground_truths(args), *io.list_images(folder for folder in folders if os.path.isdir(folder))]


def ground_truths(args) -> list[str]:
    """The ground-truth file of each folder: ``--ground-truth``, or ``--ground-truth-name`` inside it."""
    if args.ground_truth is not None:
        return [args.ground_truth]
    return [os.path.join(directory, args.ground_truth_name) for directory in args.directories]


def model_outputs(args) -> list[tuple[str, str]]:
    """``("--models", file)`` of every model file and record ``--models`` will write."""
    if args.models is None or not args.train or args.folds is None:
        return []
    from ccjax.experiments.folder_sets import fold_model_file

    several = len(args.directories) > 1
    folders = [
        os.path.join(args.models, os.path.basename(os.path.normpath(directory))) if several else args.models
        for directory in args.directories
    ]
    files = [fold_model_file(folder, label, k) for folder in folders for label in args.train for k in range(args.folds)]
    return [("--models", str(path.with_suffix(suffix))) for path in files for suffix in (".eqx", ".json")]


def check_folders(args) -> dict[str, str | None]:
    """Refuse a missing or doubled ground truth, the one-folder outputs with several folders,
    ``--camera-for`` naming no folder or an unknown camera, and ``--models`` without ``--train``,
    before any work.

    Returns:
        ``{folder as given: its camera or None}``.
    """
    from ccjax.cli.common import check_camera_name

    several = len(args.directories) > 1
    if (args.ground_truth is None) == (args.ground_truth_name is None):
        raise ValueError("--ground-truth: give either --ground-truth CSV (one folder) or --ground-truth-name NAME")
    if several and args.ground_truth is not None:
        raise ValueError(
            f"--ground-truth: one CSV cannot serve {len(args.directories)} folders; give --ground-truth-name NAME, "
            "the file's name inside each folder"
        )
    if several:
        for option, value in (("--csv", args.csv), ("--plot", args.plot), ("--mask", args.mask)):
            if value is not None:
                raise ValueError(f"{option}: applies to one folder; with several, use --json")
    if args.models is not None and args.train is None:
        raise ValueError("--models: writes the models trained within the folds; give --train METHODS")
    cameras: dict[str, str | None] = {directory: args.camera for directory in args.directories}
    names = {os.path.basename(os.path.normpath(directory)): directory for directory in args.directories}
    for entry in args.camera_for:
        folder, equals, camera = entry.partition("=")
        target = folder if folder in cameras else names.get(folder)
        if not equals or not camera.strip() or target is None:
            raise ValueError(
                f"--camera-for: expected FOLDER=CAMERA with FOLDER one of {', '.join(sorted(names))}, got {entry!r}"
            )
        check_camera_name(argparse.Namespace(camera=camera.strip(), data_dir=args.data_dir))
        cameras[target] = camera.strip()
    if args.camera_for and args.world != "default":
        raise ValueError("--camera-for: applies to --world default only")
    return cameras


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


def header(evaluation, args) -> str:
    """The first line: the world, the inputs and the folds."""
    if evaluation.trained:
        folds = (
            f"; {evaluation.folds} folds ({evaluation.fold_source}): {', '.join(evaluation.trained)} trained within "
            "them, --methods not"
        )
    elif evaluation.folds is not None:
        folds = f"; {evaluation.folds}-fold cross-validation ({evaluation.fold_source})"
    else:
        folds = ""
    preparation = args.preprocessing or "each method's default"
    # Without --camera (or --world) only methods that use no camera run (require_camera): naming
    # the default world's camera would claim a camera the images were never matched to.
    given = args.camera is not None or args.world != "default"
    world = f"world: {evaluation.world}" if given else "camera: none given (these methods use none)"
    return f"{world}; preprocessing: {preparation}{folds}"


def evaluation_options(args) -> dict:
    """The keyword arguments one folder's and several folders' evaluations share."""
    shared = {name: getattr(args, name) for name in ("folds", "train", "epochs", "seed", "preprocessing")}
    return shared | {
        "dark": image_options.dark_fraction(args),
        "read_options": image_options.read_options(args),
        "allow_missing": args.allow_missing,
        "progress": not args.no_progress,
        "log": lambda line: print(line, file=sys.stderr),
    }


def run_evaluate(args) -> int:
    from ccjax.experiments.folders import evaluate_folder
    from ccjax.runs.sources import raise_failures

    start = time.perf_counter()
    writer = start_processes()
    check_folds(args)
    cameras = check_folders(args)
    image_options.check_labels(args.methods + (args.train or []), args)
    check_outputs(
        evaluate_inputs(args),
        [("--json", args.json), ("--csv", args.csv), ("--plot", args.plot), *model_outputs(args)],
        overwrite=args.overwrite,
    )
    check_plot(args.plot)
    pretraining = pretraining_setting(args)
    if pretraining is not None and args.train is None:
        raise SystemExit("--pretrain-camera: applies to --train (the labels trained within the folds)")
    if pretraining is not None and len(args.directories) > 1:
        raise SystemExit("--pretrain-camera: applies to one folder (its camera's curves render the images)")
    if len(args.directories) > 1:
        return run_folder_sets(args, cameras, writer, start)
    args.camera = cameras[args.directories[0]]
    image_options.require_camera(args.methods + (args.train or []), args)
    try:
        evaluation = evaluate_folder(
            args.directories[0],
            ground_truths(args)[0],
            args.methods,
            world=image_options.image_world(args),
            masks=args.mask,
            check_camera=args.camera is not None or args.world != "default",
            **evaluation_options(args),
            pretraining=pretraining,
        )
    except ValueError as error:
        raise image_options.as_option_error(error) from None
    if not writer:  # under jax.distributed every process holds the pooled results; one reports them
        return 0
    print(header(evaluation, args))
    if evaluation.unlisted:
        print(f"not scored, no ground-truth row ({len(evaluation.unlisted)}): {', '.join(evaluation.unlisted)}")
    if evaluation.check is not None:
        print(evaluation.check.message())
    print(evaluation.tables(), flush=True)
    if args.json:
        write(args.json, json.dumps(evaluation.report(), indent=1), overwrite=args.overwrite)
    if args.csv:
        write(args.csv, evaluation.csv(), overwrite=args.overwrite)
    if args.plot:
        from ccjax.experiments.plots import plot_image_errors

        write_plot(args.plot, lambda file: plot_image_errors(evaluation.results, file), overwrite=args.overwrite)
    if args.models:
        from ccjax.experiments.folder_sets import save_fold_models

        camera = image_options.image_world(args).camera.name
        for path in save_fold_models(evaluation, args.models, camera, world_seed=args.seed, overwrite=args.overwrite):
            print(f"wrote {path}")
    print(f"done in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    raise_failures(evaluation.failures, evaluation.total)
    return 0


def run_folder_sets(args, cameras: dict, writer: bool, start: float) -> int:
    """Several folders: each evaluated on its own with its camera, then the geometric means
    (:func:`ccjax.experiments.folder_sets.evaluate_folder_sets`)."""
    from ccjax import _cache
    from ccjax.experiments.folder_sets import FolderSet, evaluate_folder_sets
    from ccjax.runs.sources import raise_failures

    check_camera_option(args)
    labels = args.methods + (args.train or [])
    if not any(cameras.values()) and args.world == "default":
        # No folder has a camera: world-based methods would be left out of every folder.
        image_options.require_camera(labels, args)
    _cache.enable_compilation_cache()
    folders = [
        FolderSet(pathlib.Path(directory), pathlib.Path(truth), cameras[directory])
        for directory, truth in zip(args.directories, ground_truths(args), strict=True)
    ]
    try:
        evaluation = evaluate_folder_sets(
            folders,
            args.methods,
            world_kind=args.world,
            data_dir=args.data_dir,
            **evaluation_options(args),
        )
    except ValueError as error:
        raise image_options.as_option_error(error) from None
    if not writer:
        return 0
    preparation = args.preprocessing or "each method's default"
    folds = f"; {args.folds} folds in each folder" if args.folds else ""
    print(f"{len(folders)} folders; preprocessing: {preparation}{folds}")
    for result in evaluation.sets:
        if result.evaluation.check is not None:
            print(f"{result.folder.label}: {result.evaluation.check.message()}")
    print(evaluation.table(), flush=True)
    if args.json:
        write(args.json, json.dumps(evaluation.report(), indent=1), overwrite=args.overwrite)
    if args.models:
        for path in evaluation.save_models(args.models, seed=args.seed, overwrite=args.overwrite):
            print(f"wrote {path}")
    print(f"done in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    failures = [line for result in evaluation.sets for line in result.evaluation.failures]
    raise_failures(failures, sum(result.evaluation.total for result in evaluation.sets))
    return 0


COMMANDS = [add_evaluate]
