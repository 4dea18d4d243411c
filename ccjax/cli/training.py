"""``ccjax train``: train an estimator on photographs with ground truth (optionally cross-validated)
or, for the thesis' nets, on synthetic scenes (Barnard 1999 §4.5.5; what ``train-net`` did, kept
as an alias)."""

from __future__ import annotations

import json
import os
import sys

from ccjax import limits
from ccjax._numbers import decimal, whole
from ccjax.cli import image_options
from ccjax.cli.common import (
    build_world,
    check_outputs,
    count_within,
    overwrite_argument,
    pretrain_arguments,
    pretraining_setting,
    start_processes,
    world_arguments,
)
from ccjax.cli.image_options import file_arguments, read_options
from ccjax.cli.option_checks import OptionError

NETS = ("NEURAL-NET", "SP-NEURAL-NET")

FEW_IMAGES = 50
"""Below this many training images (per fold with ``--folds``) ``ccjax train`` warns for the
families that learn many parameters from the photographs alone (:data:`FROM_PHOTOGRAPHS`): FFCC
trained on 4 images per fold scored 23 degrees. A guide, not a measured boundary; the development
sets train on 130 (a NUS-8 camera's folds) to 1,100 images (Cube+)."""

FROM_PHOTOGRAPHS = ("FFCC", "log-chroma-mlp")
"""The families with thousands of parameters and no start from the camera's physics."""


def add_train(sub) -> None:
    p = sub.add_parser(
        "train",
        help="train an estimator on images with ground truth (or the thesis nets on synthetic scenes)",
        description="Train the learnable parameters of an estimator on a folder of images with ground truth: "
        "FFCC (its own L-BFGS fit on every training image, its settings chosen within them; no epochs or "
        "learning rate), the log-chroma MLP (log-chroma-mlp), the Colour by Correlation matrices (C-by-C-MMSE, "
        "RGB-C-by-C-MMSE, soft- variants; started from the spectral fit of --camera), grey edge's Minkowski norm, "
        "or the nets. The families other than FFCC: Adam (optax) on the angular error, von Kries relighting to "
        "other training lights, held-out error per epoch and early stopping. --folds K first reports K-fold "
        "cross-validated errors (folds from the CSV's fold column when it has one). The model's .json record "
        "names the camera only when one was given or used (the world-based families). FFCC and log-chroma-mlp learn "
        f"thousands of parameters from the photographs alone: with fewer than {FEW_IMAGES} training images (per "
        "fold with --folds) a warning says so (FFCC on 4 images per fold scored 23 degrees). Without DIR, --method "
        "NEURAL-NET / SP-NEURAL-NET trains the thesis net on synthetic scenes and caches its weights (what "
        "train-net does).",
    )
    p.add_argument(
        "directory",
        nargs="*",
        default=[],
        help="image folder (omit for the nets' synthetic training); several with --target-camera: each "
        "folder's images mapped into that camera through the curves (--camera-for DIR=CAMERA each)",
    )
    p.add_argument(
        "--target-camera",
        default=None,
        metavar="CAMERA",
        help="train a model for this camera (embedded name, see `ccjax cameras`) from folders taken with other "
        "cameras: each folder's images and ground truth mapped into its raw space (ccjax.transfer); no "
        "photograph of it is needed",
    )
    p.add_argument(
        "--camera-for",
        action="append",
        default=[],
        metavar="FOLDER=CAMERA",
        help="with --target-camera: the camera of one folder (its name or path as given); repeat per folder",
    )
    p.add_argument(
        "--ground-truth-name",
        default=None,
        metavar="NAME",
        help="the ground truth's file name inside each folder (default groundtruth.csv)",
    )
    p.add_argument(
        "--camera-map",
        choices=["per-light", "global"],
        default="per-light",
        help="with --target-camera: the camera-to-camera map (default: %(default)s)",
    )
    p.add_argument(
        "--rendered",
        type=count_within(limits.RENDERED_IMAGES, low=0),
        default=0,
        metavar="N",
        help="with --target-camera: also train on N images rendered through its curves (default 0)",
    )
    p.add_argument(
        "--adapt-on",
        default=None,
        metavar="DIR",
        help="with --target-camera and --method FFCC: adapt the light prior to this folder of the target "
        "camera's unlabelled images (EM on their estimates, blended with the camera's loci); no labels read",
    )
    p.add_argument("--ground-truth", default=None, help="CSV image,r,g,b[,fold] (default: DIR/groundtruth.csv)")
    p.add_argument("--method", required=True, help="registry label, e.g. RGB-C-by-C-MMSE")
    p.add_argument("--folds", type=whole, default=None, help="cross-validate with K folds first")
    p.add_argument("--out", default=None, help="model file to write (.eqx, with a .json record beside it)")
    p.add_argument(
        "--epochs", type=whole, default=None, help="Adam: epochs at most (default: 30; log-chroma-mlp: 200; not FFCC)"
    )
    p.add_argument(
        "--batch-size", type=whole, default=None, help="Adam: images per step (default: 32; nets: 256 scenes; not FFCC)"
    )
    p.add_argument(
        "--learning-rate",
        type=decimal,
        default=None,
        help="Adam: step size (default: 0.05; log-chroma-mlp: 0.005; not FFCC)",
    )
    p.add_argument(
        "--patience",
        type=whole,
        default=None,
        help="Adam: epochs without improvement before stopping (default: 4; log-chroma-mlp: 20; not FFCC)",
    )
    p.add_argument("--steps", type=whole, default=None, help="nets only: optimiser steps (default: 3000)")
    p.add_argument("--specular", action="store_true", help="nets only: same as --method SP-NEURAL-NET")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    pretrain_arguments(p)
    file_arguments(p)
    overwrite_argument(p, "--out model file and its .json record")
    world_arguments(p)
    p.set_defaults(func=run_train)


def add_train_net(sub) -> None:
    p = sub.add_parser(
        "train-net",
        help="train the neural-net estimator for a world and cache its weights (alias of train --method NEURAL-NET)",
        description="Train NEURAL-NET (or SP-NEURAL-NET with --specular) on synthetic scenes of the world's training "
        "illuminants (Barnard 1999 §4.5.5) and save the weights in the cache ($CCJAX_CACHE, else the user "
        "cache directory). Same as `ccjax train --method NEURAL-NET`.",
    )
    world_arguments(p)
    p.add_argument("--specular", action="store_true", help="train SP-NEURAL-NET instead of NEURAL-NET")
    p.add_argument("--steps", type=whole, default=None, help="optimiser steps (default: 3000)")
    p.add_argument("--batch-size", type=whole, default=None, help="training scenes per step (default: 256)")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=run_train_net)


def run_train_net(args) -> int:
    import dataclasses

    from ccjax.estimators import neural

    label = "SP-NEURAL-NET" if args.specular else "NEURAL-NET"
    world = build_world(args)
    changes = {"seed": args.seed}
    if args.steps is not None:
        changes["steps"] = args.steps
    if args.batch_size is not None:
        changes["batch_size"] = args.batch_size
    schedule = dataclasses.replace(neural.Schedule(), **changes)
    print(
        f"training {label} for world {world.name}: {schedule.steps} steps x {schedule.batch_size} scenes",
        file=sys.stderr,
    )
    path, log = neural.train_and_save(world, label, schedule, progress=not args.no_progress)
    print(f"{label}: final training RMS (r,g) error {log.losses[-1] ** 0.5:.4f}; trained in {log.seconds:.1f} s")
    print(f"saved {path}")
    return 0


def run_train(args) -> int:
    from pathlib import Path

    if args.method == "any-camera":
        return run_train_any_camera(args)
    if args.target_camera is not None or len(args.directory) > 1:
        return run_train_for_camera(args)
    if args.camera_for or args.ground_truth_name or args.camera_map != "per-light" or args.rendered or args.adapt_on:
        raise ValueError(
            "--camera-for, --ground-truth-name, --camera-map, --rendered, --adapt-on: apply with --target-camera"
        )
    args.directory = args.directory[0] if args.directory else None
    if args.directory is None:
        if args.method not in NETS and not args.specular:
            raise OptionError(
                f"train: give an image folder to train {args.method} (only {', '.join(NETS)} train without one)"
            )
        args.specular = args.specular or args.method == "SP-NEURAL-NET"
        return run_train_net(args)
    if args.world != "default":
        raise OptionError(
            "--world: applies to the nets' synthetic training; images train from --camera's default world"
        )
    if args.steps is not None:
        raise ValueError("--steps: applies to the nets' synthetic training (no DIR); with a folder, give --epochs")
    pretraining = pretraining_setting(args)
    start_processes()
    from ccjax import training
    from ccjax.estimators import registry

    registry.lookup(args.method)  # an unknown label fails before any image is read
    # As estimate does: a model fitted to a world is bound to its camera, which is never guessed.
    image_options.require_camera([args.method], args, other_world=False)
    directory = Path(args.directory)
    truth = Path(args.ground_truth) if args.ground_truth else directory / "groundtruth.csv"
    check_outputs(train_inputs(directory, truth), train_outputs(args.out), overwrite=args.overwrite)
    changes = {
        name: value
        for name, value in (
            ("epochs", args.epochs),
            ("batch_size", args.batch_size),
            ("learning_rate", args.learning_rate),
            ("patience", args.patience),
        )
        if value is not None
    }
    from ccjax.runs import store

    world = store.world("default", args.camera)
    start = store.fit(args.method, world)  # train_on_images' start (world seed 0)
    if changes and not training.uses_schedule(start):
        options = ", ".join("--" + name.replace("_", "-") for name in changes)
        raise ValueError(f"{options}: {args.method} trains by its own L-BFGS fit, with no epochs, batches or steps")
    schedule = training.default_schedule(start, seed=args.seed, **changes)
    print(f"training {args.method} on {directory}{start_words(start, args.camera, world)}", file=sys.stderr)
    warn_few_images(args.method, len(train_inputs(directory, truth)) - 1, args.folds)
    model, log, folds = training.train_on_images(
        directory,
        truth,
        args.method,
        camera=args.camera,
        folds=args.folds,
        fold_seed=args.seed,
        schedule=schedule,
        out=args.out,
        progress=not args.no_progress,
        read_options=read_options(args),
        overwrite=args.overwrite,
        pretraining=pretraining,
    )
    del model
    if folds is not None:
        print(folds.table())
    if log.n_heldout == 0:  # FFCC: regularised L-BFGS, no stopping split to report on
        print(
            f"{args.method}: trained on {log.n_train} images ({len(log.train_loss)} L-BFGS passes, "
            f"final loss {log.train_loss[-1]:.4g}) in {log.seconds:.1f} s"
            if log.train_loss
            else f"{args.method}: trained on {log.n_train} images in {log.seconds:.1f} s"
        )
    else:
        print(
            f"{args.method}: held-out median angular error {log.initial_median:.3f} -> "
            f"{min([log.initial_median, *log.heldout_median]):.3f} deg (best epoch {log.best_epoch} of "
            f"{len(log.heldout_median)}{', stopped early' if log.stopped_early else ''}; {log.n_train} training, "
            f"{log.n_heldout} held-out images) in {log.seconds:.1f} s"
        )
    if args.out:
        print(f"saved {args.out}")
    return 0


def run_train_for_camera(args) -> int:
    """``ccjax train DIR [DIR ...] --target-camera C``: a model for a camera none of the folders was
    taken with (:func:`ccjax.evaluation.train_for_camera`)."""
    from pathlib import Path

    from ccjax import evaluation
    from ccjax.cli.common import check_camera

    if args.target_camera is None:
        raise ValueError("--target-camera: several folders train a model for one camera; name it")
    if not args.directory:
        raise ValueError("train: give the labelled folders to train on")
    if args.world != "default" or args.folds is not None or args.pretrain_camera is not None:
        raise ValueError(
            "--target-camera: trains one model on every folder; leave out --world, --folds, --pretrain-camera"
        )
    if args.rendered < 0:
        raise ValueError(f"--rendered: expected a non-negative number of images, got {args.rendered}")
    if args.adapt_on is not None:
        if args.method != "FFCC":
            raise ValueError(f"--adapt-on: adapts FFCC's light prior; got --method {args.method}")
        if not Path(args.adapt_on).is_dir():
            raise ValueError(f"--adapt-on: not a folder: {args.adapt_on}")
    start_processes()
    check_camera(args.target_camera, args.data_dir, "--target-camera")
    for entry in args.camera_for:
        check_camera(entry.partition("=")[2].strip() or None, args.data_dir, "--camera-for")
    cameras = folder_cameras(args.directory, args.camera_for, args.camera)
    name = args.ground_truth_name or "groundtruth.csv"
    if args.ground_truth is not None:
        raise ValueError("--ground-truth: with several folders give --ground-truth-name NAME (the file in each folder)")
    folders = [evaluation.FolderSet(Path(d), Path(d) / name, cameras[d]) for d in args.directory]
    inputs = [path for folder in folders for path in train_inputs(folder.directory, folder.ground_truth)]
    check_outputs(inputs, train_outputs(args.out), overwrite=args.overwrite)
    read = evaluation.ReadOptions(image=read_options(args))
    options = evaluation.TrainingOptions(seed=args.seed, epochs=args.epochs)
    try:
        model, log, record = evaluation.train_for_camera(
            folders,
            args.method,
            args.target_camera,
            camera_map=args.camera_map,
            rendered=args.rendered,
            read=read,
            options=options,
            adapt_on=args.adapt_on,
            progress=not args.no_progress,
            log=lambda line: print(line, file=sys.stderr),
        )
    except ValueError as error:
        raise image_options.as_option_error(error) from None
    print(
        f"{args.method} for the {args.target_camera}: trained on {record['images']} images "
        f"({', '.join(f'{k} {v}' for k, v in record['source_images'].items())}; {args.camera_map} maps) "
        f"in {log.seconds:.1f} s"
        + (f"; light prior adapted to {record['adapted_on']['images']} unlabelled images" if args.adapt_on else "")
    )
    if args.out:
        from ccjax.runs import store

        return save_or_print(args, model, args.method, args.target_camera, record, store.save_trained)
    return save_or_print(args, model, args.method, args.target_camera, record, None)


def save_or_print(args, model, label: str, camera: str | None, record: dict, save) -> int:
    """A trained model written to ``--out`` with its record (``save``: the store's writer), or,
    without ``--out`` (``save`` None), its record printed as JSON; the command's exit status."""
    if save is None:
        print(json.dumps(record, indent=1))
        return 0
    save(args.out, model, label=label, camera=camera, world_seed=args.seed, record=record, overwrite=args.overwrite)
    print(f"saved {args.out}")
    return 0


def folder_cameras(directories, entries, default) -> dict:
    """``{folder: camera}`` from ``--camera-for FOLDER=CAMERA`` entries (``--camera`` for the others);
    a folder without a camera is refused (its images cannot be mapped)."""
    import os

    cameras = {directory: default for directory in directories}
    names = {os.path.basename(os.path.normpath(directory)): directory for directory in directories}
    for entry in entries:
        folder, equals, camera = entry.partition("=")
        target = folder if folder in cameras else names.get(folder)
        if not equals or not camera.strip() or target is None:
            raise ValueError(
                f"--camera-for: expected FOLDER=CAMERA with FOLDER one of {', '.join(sorted(names))}, got {entry!r}"
            )
        cameras[target] = camera.strip()
    missing = [directory for directory, camera in cameras.items() if not camera]
    if missing:
        raise ValueError(
            f"--camera-for: no camera for {', '.join(missing)}; give --camera-for DIR=CAMERA (its curves map its "
            "images into the target camera)"
        )
    return cameras


def warn_few_images(method: str, count: int, folds: int | None, command: str = "train") -> None:
    """One warning line when a family of :data:`FROM_PHOTOGRAPHS` gets fewer than
    :data:`FEW_IMAGES` training images (per fold: ``count * (K - 1) / K``).

    Arguments:
        method: the label.
        count: the folder's images.
        folds: ``--folds``, or None.
        command: the command that warns (``train``, ``evaluate``).
    """
    per_fold = count if folds is None or folds < 2 else count * (folds - 1) // folds
    if method in FROM_PHOTOGRAPHS and per_fold < FEW_IMAGES:
        where = f"{per_fold} per fold" if per_fold != count else f"{count}"
        print(
            f"ccjax {command}: warning: {method} trains on {where} images, fewer than {FEW_IMAGES}: a model learned "
            "from so few photographs is unreliable (FFCC on 4 images per fold scored 23 degrees); see `ccjax train "
            "--help`",
            file=sys.stderr,
        )


def start_words(start, camera: str | None, world) -> str:
    """What ``ccjax train``'s first line says of the camera and the start: the camera only when it
    is given or used (a world-based family's start is that camera's spectral fit).

    Arguments:
        start: the fitted start.
        camera: ``--camera``, or None.
        world: the world the start was fitted to.

    Returns:
        The words, with a leading space, or nothing.
    """
    if start.world_based:  # the camera is given: train refuses a world-based family without it
        return f" (camera {world.camera.name}; start: its spectral fit)"
    return f" (camera {camera}, recorded; the method uses no camera's curves)" if camera is not None else ""


def train_inputs(directory, truth) -> list:
    """Every file ``ccjax train`` reads from: the ground truth and the folder's images."""
    from ccjax import io

    return [truth, *(io.list_images([directory]) if directory.is_dir() else [])]


def train_outputs(out) -> list[tuple[str, str | os.PathLike | None]]:
    """``ccjax train``'s outputs: the ``--out`` model file and the JSON record written beside it
    (:func:`ccjax.training.save_trained`)."""
    if out is None:
        return []
    from pathlib import Path

    return [("--out", out), ("--out", Path(out).with_suffix(".json"))]


def run_train_any_camera(args) -> int:
    """``ccjax train DIR... --camera-for DIR=CAMERA ... --method any-camera``: one model for every camera
    (:mod:`ccjax.estimators.conditioned`); its record says ``camera: null, conditioned: true`` and
    lists the cameras seen and the folders.

    Arguments:
        args: the parsed ``ccjax train`` arguments.

    Returns:
        The exit status (0).

    Raises:
        ValueError: ``--target-camera`` or another option that does not apply, a folder without a
            camera, or what reading a folder refuses.
    """
    from pathlib import Path

    from ccjax import evaluation
    from ccjax.cli.common import check_camera
    from ccjax.evaluation.any_camera import train_any_camera
    from ccjax.evaluation.scored_folder import read_folder

    if args.target_camera is not None:
        raise ValueError(
            "--target-camera: any-camera serves every camera and is bound to one when used "
            "(ccjax estimate --model M.eqx --camera CAMERA); leave it out"
        )
    if not args.directory:
        raise ValueError("train: give the labelled folders to train any-camera on")
    if args.world != "default" or args.folds is not None or args.pretrain_camera is not None:
        raise ValueError(
            "--method any-camera: trains one model on every folder; leave out --world, --folds, --pretrain-camera"
        )
    if args.rendered or args.adapt_on is not None or args.camera_map != "per-light":
        raise ValueError("--rendered, --adapt-on, --camera-map: apply with --target-camera, not with any-camera")
    if args.ground_truth is not None:
        raise ValueError("--ground-truth: with any-camera give --ground-truth-name NAME (the file in each folder)")
    for entry in args.camera_for:
        check_camera(entry.partition("=")[2].strip() or None, args.data_dir, "--camera-for")
    cameras = folder_cameras(args.directory, args.camera_for, args.camera)
    name = args.ground_truth_name or "groundtruth.csv"
    folders = [evaluation.FolderSet(Path(d), Path(d) / name, cameras[d]) for d in args.directory]
    inputs = [path for folder in folders for path in train_inputs(folder.directory, folder.ground_truth)]
    check_outputs(inputs, train_outputs(args.out), overwrite=args.overwrite)
    read = evaluation.ReadOptions(image=read_options(args))
    options = evaluation.TrainingOptions(seed=args.seed)
    try:
        data = [read_folder(f.directory, f.ground_truth, read, camera=f.camera, label=f.label) for f in folders]
        model, log, record = train_any_camera(
            data, read, options, progress=not args.no_progress, log=lambda line: print(line, file=sys.stderr)
        )
    except ValueError as error:
        raise image_options.as_option_error(error) from None
    print(
        f"any-camera: trained on {record['images']} images of {', '.join(record['cameras_seen'])} and "
        f"{record['entries'] - record['images']} augmented copies in {record['seconds']:.1f} s"
    )
    if args.out:
        from ccjax.runs import store

        record = {**record, "procedure": "FFCC in the reference space: L-BFGS", "losses": log.losses}
        record.pop("camera")
        return save_or_print(args, model, "any-camera", None, record, store.save_trained)
    return save_or_print(args, model, "any-camera", None, record, None)


COMMANDS = [add_train, add_train_net]
