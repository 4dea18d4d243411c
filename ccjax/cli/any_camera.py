"""``ccjax train DIR... --camera-for DIR=CAMERA ... --method any-camera --out M.eqx``: one model for
every camera (:mod:`ccjax.estimators.conditioned`), trained on several cameras' labelled folders;
its record says ``camera: null, conditioned: true`` and lists the cameras seen and the folders."""

from __future__ import annotations

import json
import sys


def run_train_any_camera(args) -> int:
    """Train and save the any-camera model (module docstring).

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
    from ccjax.cli import image_options
    from ccjax.cli.common import check_camera, check_outputs
    from ccjax.cli.image_options import read_options
    from ccjax.cli.training import folder_cameras, train_inputs, train_outputs
    from ccjax.evaluation.any_camera import train_any_camera
    from ccjax.evaluation.folders import read_folder

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
        store.save_trained(
            args.out,
            model,
            label="any-camera",
            camera=None,
            world_seed=args.seed,
            record=record,
            overwrite=args.overwrite,
        )
        print(f"saved {args.out}")
    else:
        print(json.dumps(record, indent=1))
    return 0
