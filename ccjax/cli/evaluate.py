"""``ccjax evaluate``: methods scored on folders of images with ground truth under a protocol (fitted
to the world, K folds, trained within folds, leave-one-camera-out): the arguments become the
values of :mod:`ccjax.evaluation` and one :func:`ccjax.evaluation.evaluate` call runs them."""

from __future__ import annotations

import json
import os
import pathlib
import sys
import time

from ccjax import limits
from ccjax._numbers import whole
from ccjax.cli import image_options
from ccjax.cli.common import (
    check_camera_option,
    check_outputs,
    check_plot,
    count_within,
    data_output_argument,
    label_list,
    overwrite_argument,
    pretrain_arguments,
    pretraining_setting,
    start_processes,
    table_stream,
    world_arguments,
    write,
    write_plot,
)
from ccjax.cli.option_checks import OptionError


def add_evaluate(sub) -> None:
    p = sub.add_parser(
        "evaluate",
        help="evaluate methods on a folder of images with ground truth",
        description="Run each method on every image listed in the ground truth and print the angular error "
        "statistics (mean, median, trimean, best 25%, worst 25%, 95th percentile, max, bootstrap 95% "
        "confidence intervals of mean and median), each method's input, seconds (compilation apart) and the "
        "images where it fell back or relaxed, with the reasons. Ground truth: CSV with header image,r,g,b (file "
        "name in DIR; r,g,b = camera RGB of the light, any scale). World-based methods need --camera; the ground "
        "truth is checked against that camera's Planckian/daylight locus (see `ccjax cameras --check`). "
        "Unreadable images are reported and skipped (exit status 2).",
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
    p.add_argument(
        "--methods",
        type=label_list,
        required=True,
        help="comma-separated labels and trained model files (.eqx, `ccjax train --out`; a model trained for "
        "another camera than a folder's is refused)",
    )
    p.add_argument(
        "--folds",
        type=whole,
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
        "a random assignment seeded by --seed; statistics per fold and pooled. FFCC and log-chroma-mlp warn below "
        "50 training images per fold (FFCC on 4 images per fold scored 23 degrees)",
    )
    p.add_argument(
        "--leave-one-camera-out",
        action="store_true",
        help="with --train and several folders, each with a camera (--camera-for): score each folder by models "
        "trained only on the OTHER folders, their images and ground truth mapped into its camera through the two "
        "cameras' curves (ccjax.transfer); one row per folder, then the geometric mean. Folders without a camera "
        "are named and left out",
    )
    p.add_argument(
        "--camera-map",
        choices=["per-light", "global"],
        default="per-light",
        help="with --leave-one-camera-out: the camera-to-camera map (per-light: the 3x3 of each image's own light, "
        "interpolated between the world's lights; global: one 3x3). Default: %(default)s",
    )
    p.add_argument(
        "--rendered",
        type=count_within(limits.RENDERED_IMAGES, low=0),
        default=0,
        metavar="N",
        help="with --leave-one-camera-out: also pool N images rendered through the scored camera's curves "
        "(ccjax.training.render_examples; default 0)",
    )
    p.add_argument(
        "--adapt",
        action="store_true",
        help="with --leave-one-camera-out --train FFCC: also score 'FFCC adapted', its light prior adapted to the "
        "scored folder's unlabelled images (EM on its estimates, blended with the camera's loci through its "
        "curves); the scored folder's ground truth is never read for it",
    )
    p.add_argument(
        "--twins-out",
        action="store_true",
        help="with --leave-one-camera-out: also keep out of each fold the folders whose camera is the scored "
        "folder's camera or its twin (the same model from another source, or a fingerprint within 0.5 degrees)",
    )
    p.add_argument(
        "--copies",
        type=whole,
        default=2,
        metavar="N",
        help="with --leave-one-camera-out --train any-camera: augmented copies of each training image, seen "
        "through other cameras of the database and sampled ones, never the scored camera or its twins "
        "(default %(default)s)",
    )
    p.add_argument(
        "--epochs",
        type=whole,
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
    data_output_argument(p, "--json", "the summaries and per-image results")
    data_output_argument(p, "--csv", "one row per image and method (estimate, ok, status, angular error)")
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
    from ccjax.evaluation.sets import fold_model_file

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
    from ccjax.cli.common import check_camera

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
        check_camera(camera.strip(), args.data_dir, "--camera-for")
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
        if args.folds is None and not args.leave_one_camera_out:
            raise ValueError(
                "--train: needs --folds K (each method is trained on the other folds' images) or "
                "--leave-one-camera-out (on the other cameras' folders)"
            )
        if len(set(args.train)) != len(args.train):
            raise ValueError(f"--train: a label is given twice ({', '.join(args.train)})")
    if args.leave_one_camera_out:
        if args.train is None:
            raise ValueError("--leave-one-camera-out: give --train METHODS (trained on the other cameras' folders)")
        if args.folds is not None:
            raise ValueError("--leave-one-camera-out: each folder is scored whole; leave out --folds")
        if len(args.directories) < 2:
            raise ValueError("--leave-one-camera-out: needs at least two folders, each with --camera-for DIR=CAMERA")
        if args.models is not None:
            raise ValueError("--models: writes the fold models of --folds K --train; not with --leave-one-camera-out")
        if args.adapt and "FFCC" not in args.train:
            raise ValueError("--adapt: adapts FFCC's light prior; give --train FFCC")
        if args.rendered and "any-camera" in args.train:
            raise ValueError("--rendered: images rendered through the scored camera are refused with any-camera")
    elif args.camera_map != "per-light" or args.rendered or args.adapt or args.twins_out:
        raise ValueError("--camera-map, --rendered, --adapt, --twins-out: apply to --leave-one-camera-out only")
    if args.copies < 0:
        raise ValueError(f"--copies: expected a non-negative number of copies, got {args.copies}")
    if args.rendered < 0:
        raise ValueError(f"--rendered: expected a non-negative number of images, got {args.rendered}")
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
    # Without --camera (or --world) only methods that use no camera run (refuse_without_camera): naming
    # the default world's camera would claim a camera the images were never matched to.
    given = args.camera is not None or args.world != "default"
    world = f"world: {evaluation.world}" if given else "camera: none given (these methods use none)"
    return f"{world}; preprocessing: {preparation}{folds}"


def evaluation_values(args, cameras: dict[str, str | None], pretraining):
    """The evaluation the arguments ask for, as values: the folders, the protocol, the read options
    and the training options (:mod:`ccjax.evaluation`).

    Returns:
        ``(folders, protocol, ReadOptions, TrainingOptions)``.
    """
    from ccjax import evaluation

    folders = [
        evaluation.FolderSet(pathlib.Path(directory), pathlib.Path(truth), cameras[directory])
        for directory, truth in zip(args.directories, ground_truths(args), strict=True)
    ]
    if args.leave_one_camera_out:
        protocol = evaluation.LeaveOneCameraOut(
            tuple(args.train), args.camera_map, args.rendered, args.adapt, args.twins_out, args.copies
        )
    elif args.train:
        protocol = evaluation.TrainedInFolds(args.folds, tuple(args.train))
    else:
        protocol = evaluation.FittedToWorld() if args.folds is None else evaluation.KFolds(args.folds)
    read = evaluation.ReadOptions(
        image=image_options.read_options(args),
        masks=args.mask,
        allow_missing=args.allow_missing,
        preprocessing=args.preprocessing,
        dark=image_options.dark_fraction(args),
    )
    options = evaluation.TrainingOptions(seed=args.seed, epochs=args.epochs, pretraining=pretraining)
    return folders, protocol, read, options


def run_evaluate(args) -> int:
    from ccjax import _cache, evaluation
    from ccjax.estimators import registry
    from ccjax.runs.sources import raise_failures

    start = time.perf_counter()
    writer = start_processes()
    check_folds(args)
    cameras = check_folders(args)
    image_options.check_labels(labels_of(args.methods) + (args.train or []), args)
    registry.refuse_untrained(labels_of(args.methods), "--methods")
    check_outputs(
        evaluate_inputs(args),
        [("--json", args.json), ("--csv", args.csv), ("--plot", args.plot), *model_outputs(args)],
        overwrite=args.overwrite,
    )
    check_plot(args.plot)
    table_stream(args)  # --json - and --csv - at once: refused before any work
    pretraining = pretraining_setting(args)
    if pretraining is not None and args.train is None:
        raise OptionError("--pretrain-camera: applies to --train (the labels trained within the folds)")
    if pretraining is not None and len(args.directories) > 1:
        raise OptionError("--pretrain-camera: applies to one folder (its camera's curves render the images)")
    check_camera_option(args)
    several = len(args.directories) > 1
    # One folder, or no folder with a camera: world-based methods would run on curves the images
    # were never matched to (several folders with some cameras: they are left out of the others).
    refuse = not several or not any(cameras.values())
    if not several:
        args.camera = cameras[args.directories[0]]  # --camera-for of the one folder names its camera
    _cache.enable_compilation_cache()
    folders, protocol, read, options = evaluation_values(args, cameras, pretraining)
    if args.train and not args.leave_one_camera_out:
        from ccjax.cli.training import warn_few_images

        for folder in folders:
            for label in args.train:
                warn_few_images(label, len(ground_truth_rows(folder.ground_truth)), args.folds, "evaluate")
    try:
        result = evaluation.evaluate(
            folders,
            args.methods,
            protocol,
            read=read,
            options=options,
            world_kind=args.world,
            data_dir=args.data_dir,
            progress=not args.no_progress,
            log=lambda line: print(line, file=sys.stderr),
            refuse_without_camera=refuse,
        )
    except ValueError as error:
        raise image_options.as_option_error(error) from None
    if not writer:  # under jax.distributed every process holds the pooled results; one reports them
        return 0
    if several:
        report_sets(result, args)
    else:
        report_folder(result.sets[0], args)
    print(f"done in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    failures = [line for scored in result.sets for line in scored.evaluation.failures]
    raise_failures(failures, sum(scored.evaluation.total for scored in result.sets))
    return 0


def ground_truth_rows(path) -> list[str]:
    """The image names a ground-truth CSV lists (for the small-training-set warning; a file that
    cannot be read gives none here and its error when the evaluation reads it)."""
    from ccjax import io

    try:
        return list(io.read_ground_truth(path))
    except (ValueError, OSError):
        return []


def labels_of(methods: list[str]) -> list[str]:
    """The registry labels among ``--methods`` (model files are checked when they are read)."""
    return [method for method in methods if not method.endswith(".eqx")]


def report_folder(scored, args) -> None:
    """One folder's header, tables and outputs (``--json``, ``--csv``, ``--plot``, ``--models``)."""
    evaluation, out = scored.evaluation, table_stream(args)
    print(header(evaluation, args), file=out)
    if evaluation.unlisted:
        print(
            f"not scored, no ground-truth row ({len(evaluation.unlisted)}): {', '.join(evaluation.unlisted)}", file=out
        )
    if evaluation.check is not None:
        print(evaluation.check.message(), file=out)
    print(evaluation.tables(), file=out, flush=True)
    if args.json:
        write(args.json, json.dumps(evaluation.report(), indent=1), overwrite=args.overwrite)
    if args.csv:
        write(args.csv, evaluation.csv(), overwrite=args.overwrite)
    if args.plot:
        from ccjax.experiments.plots import plot_image_errors

        write_plot(args.plot, lambda file: plot_image_errors(evaluation.results, file), overwrite=args.overwrite)
    if args.models:
        from ccjax.evaluation import save_fold_models

        for path in save_fold_models(
            evaluation, args.models, scored.world_camera, world_seed=args.seed, overwrite=args.overwrite
        ):
            print(f"wrote {path}", file=out)


def report_sets(result, args) -> None:
    """Several folders: the per-folder rows and the geometric means, ``--json``, ``--models``."""
    preparation = args.preprocessing or "each method's default"
    folds = f"; {args.folds} folds in each folder" if args.folds else ""
    if args.leave_one_camera_out:
        folds = f"; leave-one-camera-out: {', '.join(args.train)} trained on the other folders ({args.camera_map} maps)"
    out = table_stream(args)
    print(f"{len(args.directories)} folders; preprocessing: {preparation}{folds}", file=out)
    for scored in result.sets:
        if scored.evaluation.check is not None:
            print(f"{scored.folder.label}: {scored.evaluation.check.message()}", file=out)
    print(result.table(), file=out, flush=True)
    if args.json:
        write(args.json, json.dumps(result.report(), indent=1), overwrite=args.overwrite)
    if args.models:
        for path in result.save_models(args.models, seed=args.seed, overwrite=args.overwrite):
            print(f"wrote {path}", file=out)


COMMANDS = [add_evaluate]
